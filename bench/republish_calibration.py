"""How well the republished ``confidence`` holds: every recording through :class:`~spat_feed.transport.republish.Republisher`.

Each snapshot of a recording (``../shared/data/spat`` CSV) is republished in order, as the feed does; each statement
(a movement's added ``likelyTime`` and ``confidence``) made after the first ``--warm-up-s`` (900 s) is scored against
when the group's phase really ended (the first later snapshot of another phase class, seen with no gap over 2 s;
changes after a gap are not scored). Prints, per J2735 confidence index, the statements, the changes they were
about and the share that came within ``TOLERANCE_S`` of the likely time, at that index and at that index or above,
and the microseconds per movement. The numbers of docs/SPAT.md section 2. ``--raw``: the confidence the forecast's
own share would state (``ChangeForecast.within_frac``, without :class:`~spat_feed.transport.republish.Calibration`).

    .venv/bin/python bench/republish_calibration.py [LOG.csv.gz ...] [--warm-up-s 900] [--raw]   (default: every recording)
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from spat_feed.timing.messages import CONFIDENCE_FRAC, to_unix_s  # noqa: E402
from spat_feed.timing.plans import phase_class  # noqa: E402
from spat_feed.transport.actuated import recordings  # noqa: E402
from spat_feed.transport.recorded import read_spat_csv  # noqa: E402
from spat_feed.transport import republish  # noqa: E402
from spat_feed.transport.republish import MAX_GAP_S, TOLERANCE_S, Republisher  # noqa: E402


def changes(snapshots) -> dict[tuple[int, int, float], float]:
    """(intersection, group, instant) -> when the phase class in progress then ended (nan after a gap)."""
    series = defaultdict(list)
    for ix in snapshots:
        t, seen = to_unix_s(ix.timestamp), set()
        for m in ix.states:
            if m.signal_group not in seen:
                seen.add(m.signal_group)
                series[(ix.id, m.signal_group)].append((t, phase_class(m.state_time_speed[0].event_state)))
    out = {}
    for key, items in series.items():
        change = math.nan
        for i in range(len(items) - 1, -1, -1):
            out[(*key, items[i][0])] = change
            if i and items[i][1] is not items[i - 1][1]:
                change = items[i][0] if items[i][0] - items[i - 1][0] <= MAX_GAP_S else math.nan
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*")
    ap.add_argument("--warm-up-s", type=float, default=900.0)
    ap.add_argument("--raw", action="store_true", help="state the forecast's own share (no calibration)")
    args = ap.parse_args()
    if args.raw:  # a bin's second key is the J2735 index of the forecast's own share (republish._bin)
        republish.Calibration.frac = lambda self, key: CONFIDENCE_FRAC[key[1]]
    for log in args.logs or recordings():
        snapshots = read_spat_csv(log)
        truth = changes(snapshots)
        rep, t_first = Republisher(), to_unix_s(snapshots[0].timestamp)
        start = time.perf_counter()
        out = [rep(s) for s in snapshots]
        us = (time.perf_counter() - start) / sum(len(s.states) for s in snapshots) * 1e6
        rows, movements, stated = [], 0, 0
        for ix in out:
            t = to_unix_s(ix.timestamp)
            if t - t_first < args.warm_up_s:
                continue
            for m in ix.states:
                ev, movements = m.state_time_speed[0], movements + 1
                if ev.timing is None or ev.timing.confidence is None:
                    continue
                stated += 1
                change = truth.get((ix.id, m.signal_group, t), math.nan)
                if not math.isnan(change):
                    rows.append((ev.timing.confidence, abs(change - to_unix_s(ev.timing.likely_time)) <= TOLERANCE_S, (ix.id, m.signal_group, change)))
        print(f"{Path(log).name}: {us:.0f} us a movement; {stated} of {movements} movements stated after {args.warm_up_s:.0f} s, {len(rows)} scored")
        print("  index  level  statements  changes  within     | >= level: statements  changes  within")
        for level in range(16):
            at = [r for r in rows if r[0] == level]
            ge = [r for r in rows if r[0] >= level]
            if not ge:
                break
            share = f"{sum(r[1] for r in at) / len(at):6.3f}" if at else "     -"
            print(f"  {level:5d}  {CONFIDENCE_FRAC[level]:5.2f}  {len(at):10d}  {len({r[2] for r in at}):7d}  {share}     |"
                  f"             {len(ge):10d}  {len({r[2] for r in ge}):7d}  {sum(r[1] for r in ge) / len(ge):6.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
