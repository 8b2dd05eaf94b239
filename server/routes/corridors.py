"""The corridors the service advises on, and their signalised intersections."""

from __future__ import annotations

from fastapi import APIRouter, Path
from typing import Annotated

from spat_feed.road.corridors import Corridor, IntersectionSpec

from server.deps import EngineDep
from server.web.errors import not_found
from server.schemas import CorridorSummary, ErrorOut

router = APIRouter(prefix="/v1/corridors", tags=["corridors"])
CorridorName = Annotated[str, Path(max_length=200)]


def _corridor(engine, name: str) -> Corridor:
    corridor = engine.corridors.get(name)
    if corridor is None:
        raise not_found(f"unknown corridor {name!r}; choose from {sorted(engine.corridors)}")
    return corridor


@router.get("", response_model=list[CorridorSummary])
async def list_corridors(engine: EngineDep) -> list[CorridorSummary]:
    """The served corridors: the shipped presets and the files of ``ECO_CORRIDOR_DIR``, with their plans."""
    return [
        CorridorSummary(
            name=c.name, description=c.description, length_m=c.length_m, intersection_ids=[ix.id for ix in c.intersections],
            units=c.units, plans=[p.name for p in c.plans], default_plan=(p.name if (p := c.plan()) is not None else None),
        )
        for c in engine.corridors.values()
    ]  # fmt: skip


@router.get("/{name}", response_model=Corridor, responses={404: {"model": ErrorOut}})
async def get_corridor(name: CorridorName, engine: EngineDep) -> Corridor:
    """The corridor file: route polyline (WGS 84, stations) and intersections with their stop lines."""
    return _corridor(engine, name)


@router.get("/{name}/intersections", response_model=list[IntersectionSpec], responses={404: {"model": ErrorOut}})
async def list_intersections(name: CorridorName, engine: EngineDep) -> list[IntersectionSpec]:
    return list(_corridor(engine, name).intersections)
