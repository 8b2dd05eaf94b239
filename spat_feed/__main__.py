"""``python -m spat_feed``: run the simulated SPaT feed (FastAPI + uvicorn) on loopback by default."""

from __future__ import annotations

import argparse
import logging
import os
import time
from collections.abc import Sequence

import uvicorn

from spat_feed.road.corridors import preset_names
from spat_feed.timing.paper import TIMING_PRESETS
from spat_feed.transport.service import FeedSettings, create_app
from spat_feed.transport.store import Clock


def offset_clock(start_unix_s: float) -> Clock:
    """A clock that reads ``start_unix_s`` now and then runs at real rate (monotonic)."""
    t0 = time.monotonic()
    return lambda: start_unix_s + (time.monotonic() - t0)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m spat_feed", description="Simulated SPaT feed (SAE J2735-aligned JSON).")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8765)
    parser.add_argument("--corridor", default="paper_s400", help=f"preset ({', '.join(preset_names())}) or a corridor JSON path")
    parser.add_argument("--timing", default="15_15", help="preset (x_y, e.g. -15_15; field_test) or 'trip'", choices=[*TIMING_PRESETS, "trip"])
    parser.add_argument("--entry-unix-s", type=float, default=None, help="zone-entry instant the timing is relative to (default: feed start)")
    parser.add_argument("--early-s", type=float, default=0.0, help="actuated windows: change may come this much earlier [s]")
    parser.add_argument("--late-s", type=float, default=0.0, help="actuated windows: change may come this much later [s]")
    parser.add_argument("--confidence", type=float, default=1.0, help="probability the change falls in its window [-]")
    parser.add_argument("--rate-hz", type=float, default=10.0)
    parser.add_argument("--n-events", type=int, default=3, help="events per signal group (current + coming)")
    parser.add_argument("--clock-start-unix-s", type=float, default=None, help="test hook: the feed's clock starts here")
    parser.add_argument("--fault-every", type=int, default=0, help="test hook: corrupt every N-th streamed message")
    shared = parser.add_argument_group("the per-intersection stream (/spat/intersections/stream, MQTT)")
    shared.add_argument("--corridors", default=None, help="comma-separated corridors whose intersections are simulated (default: every preset; 'none': none)")
    shared.add_argument("--log", default=None, help="play a recorded SPaT log (.csv[.gz] as in ../shared/data/spat, or .jsonl[.gz] of our messages)")
    shared.add_argument("--speedup", type=float, default=1.0, help="recorded seconds per second of play")
    shared.add_argument("--loop", action="store_true", help="play the log again after its end, forever")
    shared.add_argument("--mqtt", default=os.environ.get("SPAT_MQTT_URL") or None,
                        help="publish every intersection's state to mqtt://[user:password@]host[:port][/prefix] (topic <prefix>/<intersection id>); "
                             "default $SPAT_MQTT_URL (keeps the password off the command line)")
    shared.add_argument("--record", default=None, help="append every intersection's state to a .jsonl[.gz] log")
    parser.add_argument("--log-level", default="warning")
    args = parser.parse_args(argv)

    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s")
    settings = FeedSettings(
        corridor=args.corridor,
        timing=args.timing,
        entry_unix_s=args.entry_unix_s,
        early_s=args.early_s,
        late_s=args.late_s,
        confidence_frac=args.confidence,
        rate_hz=args.rate_hz,
        n_events=args.n_events,
        fault_every=args.fault_every,
        corridors=None if args.corridors is None else tuple(c for c in args.corridors.split(",") if c.strip() and c.strip() != "none"),
        log=args.log,
        speedup=args.speedup,
        loop=args.loop,
        mqtt=args.mqtt,
        record=args.record,
    )
    clock = offset_clock(args.clock_start_unix_s) if args.clock_start_unix_s is not None else time.time
    app = create_app(settings, clock=clock)
    uvicorn.run(app, host=args.host, port=args.port, log_level=args.log_level, ws_per_message_deflate=False, access_log=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
