"""Speech: an advisory's message as WAV bytes, with pyttsx3 (the espeak-ng driver on Linux).

pyttsx3 engines are not thread-safe, so one worker thread owns the engine and renders one text at a
time; results are cached by text (advisories repeat). Without a speech engine (espeak-ng missing, see
``scripts/system-deps.sh``) :attr:`Speech.available` is False and :attr:`Speech.reason` says why; the
route answers 503 with that reason.
"""

from __future__ import annotations

import asyncio
import logging
import os
import shutil
import tempfile
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor

log = logging.getLogger("server.audio")

MAX_TEXT_CHARS = 500
WAV_HEADER_BYTES = 44  # a PCM WAV's RIFF + fmt + data headers: a file this long holds no sound
RENDER_TRIES = 3


class SpeechUnavailable(RuntimeError):
    pass


class Speech:
    """Renders text to WAV in one worker thread. Call :meth:`start` once (from the event loop's thread or any)."""

    def __init__(self, enabled: bool = True, cache_size: int = 256) -> None:
        self.enabled = enabled
        self.cache_size = cache_size
        self.available = False
        self.reason = "speech disabled (ECO_SPEECH=false)" if not enabled else "speech engine not started"
        self._engine = None
        self._executor: ThreadPoolExecutor | None = None
        self._cache: OrderedDict[str, bytes] = OrderedDict()
        self._dir: str | None = None  # made when the engine starts, removed when it stops

    def _init_engine(self) -> None:
        try:
            self._dir = tempfile.mkdtemp(prefix="ecodrive-tts-")
            import pyttsx3

            self._engine = pyttsx3.init("espeak")
            self._render("Ready.")  # proves the whole chain works
            self.available, self.reason = True, "ok"
        except Exception as exc:  # pyttsx3 raises assorted errors when espeak-ng is missing
            self._engine = None
            self.available = False
            self.reason = f"no speech engine: {type(exc).__name__}: {exc}. Install espeak-ng (scripts/system-deps.sh)"
            log.warning("speech unavailable: %s", self.reason)

    def _render(self, text: str) -> bytes:
        """WAV bytes of ``text``. pyttsx3's espeak driver now and then writes a header and no samples (seen
        under load; pyttsx3 issues #142, #242): such a file is rendered again, and never cached."""
        for _ in range(RENDER_TRIES):
            data = self._render_once(text)
            if len(data) > WAV_HEADER_BYTES:
                return data
        raise SpeechUnavailable(f"the speech engine wrote no audio ({RENDER_TRIES} tries)")

    def _render_once(self, text: str) -> bytes:
        path = os.path.join(self._dir, "advice.wav")
        if os.path.exists(path):
            os.remove(path)
        self._engine.save_to_file(text, path)
        self._engine.runAndWait()
        with open(path, "rb") as f:
            data = f.read()
        if data[:4] != b"RIFF" or data[8:12] != b"WAVE":
            raise SpeechUnavailable("the speech engine did not write a WAV file")
        return data

    async def start(self) -> None:
        if not self.enabled:
            return
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="tts")
        await asyncio.get_running_loop().run_in_executor(self._executor, self._init_engine)

    async def wav(self, text: str) -> bytes:
        """WAV bytes of ``text``; :class:`SpeechUnavailable` without an engine."""
        if not self.available or self._executor is None:
            raise SpeechUnavailable(self.reason)
        text = text[:MAX_TEXT_CHARS]
        if (hit := self._cache.get(text)) is not None:
            self._cache.move_to_end(text)
            return hit
        data = await asyncio.get_running_loop().run_in_executor(self._executor, self._render, text)
        if self.cache_size:
            self._cache[text] = data
            while len(self._cache) > self.cache_size:
                self._cache.popitem(last=False)
        return data

    async def stop(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None
