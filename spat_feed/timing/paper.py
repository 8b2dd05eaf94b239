"""The paper's timings: when each light of a corridor turns red, relative to the car's zone entry.

:class:`Timing` gives every light of a corridor a fixed-time plan for a trip entering the zone at an
instant (the paper's x, y: red starts of light 1 and light 2). :data:`TIMING_PRESETS` holds the paper's 16
timings ``"x_y"`` and its field test; :func:`timing_for_trip` picks one of the 16 from a trip's entry time.
A corridor's own timing is a signal-plan file instead (:mod:`spat_feed.timing.signal_plans`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from advisory.signals import PAPER_TIMINGS_S
from spat_feed.timing.plans import FixedTimePlan

if TYPE_CHECKING:  # pragma: no cover
    from spat_feed.road.corridors import Corridor


@dataclass(frozen=True, slots=True)
class Timing:
    """Fixed-time plans for a corridor's lights, relative to the instant a car enters the zone.

    ``red_starts_s[i]``: seconds after entry at which light ``i`` turns red (the paper's x, y). [s]
    """

    name: str
    red_starts_s: tuple[float, ...]
    red_s: float = 30.0
    green_s: float = 30.0
    amber_s: float = 0.0
    description: str = ""

    def check(self, corridor: Corridor) -> None:
        """``ValueError`` unless the timing has one red start per light of ``corridor``."""
        if len(self.red_starts_s) != len(corridor.intersections):
            raise ValueError(f"timing {self.name!r} has {len(self.red_starts_s)} lights, corridor {corridor.name!r} has {len(corridor.intersections)}")

    def fixed_plans(self, corridor: Corridor, entry_unix_s: float) -> dict[tuple[int, int], FixedTimePlan]:
        """(intersection id, signal group) -> fixed-time plan on the Unix axis for a trip entering at ``entry_unix_s``."""
        return {
            (ix.id, sg.id): FixedTimePlan(self.red_s, self.green_s, self.amber_s, entry_unix_s + red_start_s)
            for ix, red_start_s in zip(corridor.intersections, self.red_starts_s)
            for sg in ix.signal_groups
        }


def _paper_timing(x_s: float, y_s: float) -> Timing:
    return Timing(f"{x_s:g}_{y_s:g}", (x_s, y_s), description=f"paper [{x_s:g} {y_s:g}]")


TIMING_PRESETS: dict[str, Timing] = {t.name: t for t in (_paper_timing(x, y) for x in PAPER_TIMINGS_S for y in PAPER_TIMINGS_S)}
"""The paper's 16 timings ``"x_y"`` (e.g. ``"-15_15"``), plus ``"field_test"``."""

TIMING_PRESETS["field_test"] = Timing(
    "field_test",
    (-15.0, 30.0),
    description="paper Sec. 4.4 field test: light 1 turns green 15 s and light 2 turns red 30 s after entry",
)

PAPER_TIMING_NAMES = tuple(f"{x:g}_{y:g}" for x in PAPER_TIMINGS_S for y in PAPER_TIMINGS_S)


def timing_for_trip(entry_unix_s: float, period_s: float = 60.0) -> Timing:
    """One of the paper's 16 timings picked from a trip's entry time: ``floor(entry / period) mod 16``.

    Lets a fleet of test trips cover all 16 cases without configuring each one.

    Examples
    --------
    >>> timing_for_trip(0.0).name, timing_for_trip(61.0).name
    ('-30_-30', '-30_-15')
    """
    return TIMING_PRESETS[PAPER_TIMING_NAMES[int(math.floor(entry_unix_s / period_s)) % len(PAPER_TIMING_NAMES)]]
