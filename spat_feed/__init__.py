"""Signal timing for the advisor: plans, J2735-aligned SPaT messages, corridors, a simulated feed and a client.

Layers (imports point down):

* ``plans``, ``timemark``: pure schedules and J2735 TimeMark arithmetic (no clock, no I/O);
* ``messages``: the SPaT JSON schema (pydantic) and J2735 conversion;
* ``corridors``, ``scenarios``: corridor files, the paper's presets, scenario -> message;
* ``source``, ``client``: where the advisor reads SPaT (in-process, or a remote feed);
* ``service``, ``__main__``: the simulated feed, ``python -m spat_feed``.

See docs/SPAT.md. ``advisory`` never imports this package; this package never imports ``server`` or ``replay``.
"""

from spat_feed.corridors import TIMING_PRESETS, Corridor, Timing, load_corridor, paper_corridor, preset_names, timing_for_trip
from spat_feed.messages import IntersectionState, SpatMessage, from_j2735, parse_spat_text, plan_from_movement, to_j2735
from spat_feed.plans import (
    ChangeWindow,
    FixedTimePlan,
    MovementPhaseState,
    TimeToChange,
    UncertainPlan,
    next_changes,
    possible_states_at,
    seconds_to_next_green,
    seconds_to_next_red,
    state_at,
    to_fixed_time_signal,
)
from spat_feed.scenarios import FeedScenario, Uncertainty, make_scenario, spat_message_at
from spat_feed.source import InProcessSpatSource, LatestStore, SpatReading, SpatSource, SpatStore, TimeRules
from spat_feed.timemark import timemark_to_unix, unix_to_timemark

__all__ = [
    "TIMING_PRESETS",
    "ChangeWindow",
    "Corridor",
    "FeedScenario",
    "FixedTimePlan",
    "InProcessSpatSource",
    "IntersectionState",
    "LatestStore",
    "MovementPhaseState",
    "SpatMessage",
    "SpatReading",
    "SpatSource",
    "SpatStore",
    "TimeRules",
    "TimeToChange",
    "Timing",
    "UncertainPlan",
    "Uncertainty",
    "from_j2735",
    "load_corridor",
    "make_scenario",
    "next_changes",
    "paper_corridor",
    "parse_spat_text",
    "plan_from_movement",
    "possible_states_at",
    "preset_names",
    "seconds_to_next_green",
    "seconds_to_next_red",
    "spat_message_at",
    "state_at",
    "timemark_to_unix",
    "timing_for_trip",
    "to_fixed_time_signal",
    "to_j2735",
    "unix_to_timemark",
]
