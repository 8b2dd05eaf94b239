"""Signal timing for the advisor: plans, J2735-aligned SPaT messages, corridors, a simulated feed and a client.

Four subpackages in layers, imports pointing down only (no cycles between modules or subpackages):

1. ``timing``: pure schedules (``plans``), J2735 TimeMark (``timemark``), the SPaT schema and J2735
   conversion (``messages``), the paper's timings (``paper``) and signal-plan files (``signal_plans``);
2. ``road``: corridor files and the paper's corridors (``corridors``), the OSM import (``osm``), DP tables
   for a corridor's plans (``corridor_tables``); imports ``timing``;
3. ``prediction``: each signal group's learnt history (``history``), the phase-end forecast (``predictor``), a
   matched position + SPaT plans -> the advisor's observation (``observe``); imports ``timing`` and ``road``;
4. ``transport``: the SPaT store and its time rules (``store``), scenario -> message (``scenarios``), the
   simulator, recorded logs, player, MQTT, pump, the remote-feed client, the feed's app (``service``) and
   the simulated actuated controllers (``actuated``); imports the three below it.

Beside them: ``files`` (file reading shared by the layers) and ``__main__`` (the feed, ``python -m
spat_feed``). See docs/SPAT.md. ``advisory`` never imports this package; this package never imports
``server`` or ``replay``.
"""

from spat_feed.road.corridors import Corridor, load_corridor, paper_corridor, preset_names
from spat_feed.timing.messages import IntersectionState, SpatMessage, from_j2735, parse_spat_text, plan_from_movement, to_j2735
from spat_feed.timing.paper import TIMING_PRESETS, Timing, timing_for_trip
from spat_feed.timing.plans import (
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
from spat_feed.timing.timemark import timemark_to_unix, unix_to_timemark
from spat_feed.transport.scenarios import FeedScenario, Uncertainty, make_scenario, spat_message_at
from spat_feed.transport.store import InProcessSpatSource, LatestStore, SpatReading, SpatSource, SpatStore, TimeRules

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
