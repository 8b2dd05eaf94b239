"""The current advisory as speech (WAV)."""

from __future__ import annotations

from fastapi import APIRouter, Response

from server.audio import SpeechUnavailable
from server.deps import EngineDep, SpeechDep, TripDep
from server.web.errors import ApiError
from server.routes.trips import ERRORS
from server.schemas import ErrorOut

router = APIRouter(prefix="/v1/trips", tags=["audio"])


@router.get(
    "/{trip_id}/advice.wav",
    response_class=Response,
    responses={200: {"content": {"audio/wav": {}}, "description": "the advisory's message, spoken"}, 503: {"model": ErrorOut}, **ERRORS},
)
async def advice_audio(trip: TripDep, engine: EngineDep, speech: SpeechDep) -> Response:
    """The latest advisory's message as a WAV file (espeak-ng via pyttsx3); 503 without a speech engine."""
    text = engine.latest(trip)["message"] or "No advice."
    try:
        data = await speech.wav(text)
    except SpeechUnavailable as exc:
        raise ApiError(503, "speech_unavailable", str(exc)) from None
    return Response(data, media_type="audio/wav", headers={"Cache-Control": "no-store"})
