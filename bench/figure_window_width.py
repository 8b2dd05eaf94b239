"""Figure for docs/ADVISOR.md: cost saving against the regular driver as the published windows widen.

Run: .venv/bin/python bench/figure_window_width.py [--draws N] [SPAT_EVAL_JSON ...]

The 64 paper timings with fixed-time lights (a perfect feed), then actuated with windows of ±5, ±10 and ±15 s
(``spat_feed.transport.actuated``: the real switch anywhere inside and up to 10 % beyond; ``--draws`` truths per timing),
and the recorded days from ``ecodrive spat-eval LOG --json`` outputs given as arguments (another geometry: an
urban approach at 50 km/h; their own regular driver and hindsight DP). Per setting: the advisor's mean saving,
the regular driver's (0 by definition: every saving is against it on the same truth) and the hindsight DP's
(it knows the truth). Writes docs/figures/advisor_window_width.png and prints the numbers.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _figures import save  # noqa: E402
from bench_advisor import window_sweep  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "advisor_window_width.png"


def main() -> None:
    args = sys.argv[1:]
    draws = int(args[args.index("--draws") + 1]) if "--draws" in args else 1
    logs = [a for a in args if a.endswith(".json")]
    sweep = window_sweep((0.0, 5.0, 10.0, 15.0), draws=draws)
    labels, advised, hindsight = [], [], []
    for w, rows in sweep.items():
        labels.append("fixed" if w == 0 else f"±{w:g} s")
        advised.append(100 * np.mean(1 - rows[:, 0] / rows[:, 1]))
        hindsight.append(100 * np.nanmean(1 - rows[:, 2] / rows[:, 1]))
        print(f"{labels[-1]:>8}: advisor {advised[-1]:5.1f} %, hindsight DP {hindsight[-1]:5.1f} %, worst advised "
              f"{100 * np.max(rows[:, 0] / rows[:, 1] - 1):+.1f} %, time lost mean {np.mean(rows[:, 3]):+.1f} s, red entries {int(rows[:, 4].sum())}")
    for path in logs:
        d = json.loads(Path(path).read_text())
        labels.append(Path(d["log"]).name.split(".")[0].replace("antwerp-", "Antwerp\n"))
        advised.append(100 * d["saving_frac"])
        hindsight.append(100 * d["hindsight_saving_frac"])
        print(f"{labels[-1]!r}: advisor {advised[-1]:5.1f} %, hindsight DP {hindsight[-1]:5.1f} % ({d['approaches']} approaches)")
    x = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(8, 4.2))
    ax.plot(x, hindsight, "s-", color="tab:green", label="hindsight DP (knows the real switches)")
    ax.plot(x, advised, "o-", color="tab:blue", label="advisor (sees what is published)")
    ax.plot(x, np.zeros(len(x)), "k--", lw=1, label="regular driver (the reference)")
    if logs:
        ax.axvspan(len(sweep) - 0.5, len(labels) - 0.5, color="0.92", zorder=0)
        ax.text(len(sweep) - 0.4, max(hindsight) * 0.97, "recorded controller\n(urban, 50 km/h)", va="top", fontsize=8)
    ax.set_xticks(x, labels)
    ax.set_ylabel("mean cost saving vs regular driver [%]")
    ax.set_xlabel("published change windows (paper's 64 timings) / recorded days")
    ax.set_title("Saving against window width")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    save(fig, OUT, dpi=120)


if __name__ == "__main__":
    main()
