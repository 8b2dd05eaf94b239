"""The SPaT store on a real controller: what learning each intersection costs per message.

Offers every snapshot of a shared Antwerp recording (K648, 10 signal groups, 1 Hz) to a
:class:`~spat_feed.transport.store.SpatStore` and reads one group's :meth:`~spat_feed.transport.store.SpatStore.plan_reading` after each,
as the service does for a car. Prints the microseconds per message, against the same messages only parsed
(``plan_from_movement`` for each group: the store's floor), measured in the same run, and what was learnt: the
groups whose phases a link ends (:class:`~spat_feed.prediction.history.ChangeLinks`) and the share of red readings a link speaks in.

    .venv/bin/python bench/bench_spat_store.py [LOG.csv.gz]   (default: the 2019-05-01 recording)
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from spat_feed.transport.actuated import recordings  # noqa: E402
from spat_feed.timing.messages import plan_from_movement, to_unix_s  # noqa: E402
from spat_feed.timing.plans import PhaseClass  # noqa: E402
from spat_feed.transport.recorded import read_spat_csv  # noqa: E402
from spat_feed.transport.store import SpatStore, TimeRules  # noqa: E402
from bench._procs import best_of  # noqa: E402


def main() -> None:
    logs = [a for a in sys.argv[1:] if not a.startswith("-")] or [p for p in recordings() if "05-01" in p][:1]
    if not logs:
        sys.exit("no recording: pass a SPaT CSV (../shared/data/spat format)")
    snapshots = read_spat_csv(logs[0])
    stamps = [to_unix_s(s.timestamp) for s in snapshots]
    group = snapshots[0].states[0].signal_group
    clock = [0.0]
    state = {}

    def store_run() -> None:
        store = state["store"] = SpatStore(TimeRules(clock_tolerance_s=5.0), lambda: clock[0])
        for snap, stamp in zip(snapshots, stamps):
            clock[0] = stamp
            store.offer(snap)
            store.plan_reading(snap.id, group)

    def parse_only() -> None:
        for snap, stamp in zip(snapshots, stamps):
            for movement in snap.states:
                plan_from_movement(movement, stamp)

    store_s, parse_s = best_of(store_run), best_of(parse_only)
    n = len(snapshots)
    print(f"{Path(logs[0]).name}: {n:,} messages, {len(snapshots[0].states)} signal groups each")
    print(f"SpatStore offer + plan_reading: {1e6 * store_s / n:.1f} us per message; parsing alone {1e6 * parse_s / n:.1f} us "
          f"(ratio {store_s / parse_s:.2f}: what the store adds, learning included)")

    # what was learnt: replay once more, counting red readings with a link
    store, reds, linked, groups = SpatStore(TimeRules(clock_tolerance_s=5.0), lambda: clock[0]), 0, 0, set()
    for snap, stamp in zip(snapshots, stamps):
        clock[0] = stamp
        store.offer(snap)
        for movement in snap.states:
            cycle = store.plan_reading(snap.id, movement.signal_group).cycle
            if cycle is not None and cycle.current is PhaseClass.RED:
                reds += 1
                if cycle.linked_end_unix_s is not None and cycle.linked_end_unix_s[1] >= stamp:
                    linked += 1
                    groups.add(movement.signal_group)
    print(f"links: {len(groups)} groups have reds a link ends; a link speaks in {100 * linked / max(reds, 1):.0f} % of {reds:,} red readings")


if __name__ == "__main__":
    main()
