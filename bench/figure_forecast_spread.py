"""Figure for docs/ADVISOR.md: the share of the hindsight saving kept against the forecast's spread (issue 31).

Run: .venv/bin/python bench/figure_forecast_spread.py SPAT_EVAL_JSON ...

Each argument is the output of ``ecodrive spat-eval LOG --json [--driver D] --forecast F [--jitter-s S]``; the
``setup`` key of each says its driver, forecast and spread. Per recording and driver: the kept share with the truth
(``truth``, at spread 0), with calibrated forecasts of spread S (``truth-jitter``), centred ones (``truth-spread``,
dashed), and the real predictor as a horizontal line. Writes docs/figures/forecast_spread.png and prints the points.
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _figures import save  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "forecast_spread.png"


def main() -> None:
    points: dict[tuple[str, str], dict[str, list[tuple[float, float]]]] = defaultdict(lambda: defaultdict(list))
    for path in sys.argv[1:]:
        out = json.loads(Path(path).read_text())
        setup, log = out["setup"], Path(out["log"]).name.split(".")[0]
        forecast, kept = setup.get("forecast", "predictor"), 100.0 * out["kept_frac"]
        series = points[(log, setup["driver"])]
        if forecast == "truth":
            series["truth-jitter"].append((0.0, kept))
            series["truth-spread"].append((0.0, kept))
        elif forecast == "predictor":
            series["predictor"].append((0.0, kept))
        else:
            series[forecast].append((setup["jitter_s"], kept))
    drivers = sorted({d for _, d in points})
    fig, axes = plt.subplots(1, len(drivers), figsize=(5.5 * len(drivers), 4.2), sharey=True, squeeze=False)
    for ax, driver in zip(axes[0], drivers):
        for n, (log, _) in enumerate(k for k in sorted(points) if k[1] == driver):
            series, color = points[(log, driver)], f"C{n}"
            for name, style in (("truth-jitter", "-o"), ("truth-spread", "--s")):
                xy = sorted(series.get(name, []))
                if len(xy) > 1:
                    ax.plot(*zip(*xy), style, color=color, label=f"{log}, {name}" if name == "truth-jitter" else None, alpha=1.0 if name == "truth-jitter" else 0.5)
                    print(f"{driver} {log} {name}: " + ", ".join(f"{s:g} s {k:.1f} %" for s, k in xy))
            for _, kept in series.get("predictor", []):
                ax.axhline(kept, color=color, linestyle=":", linewidth=1.2)
                print(f"{driver} {log} predictor: {kept:.1f} %")
        ax.set_title(f"{driver} driver (dotted: the predictor; dashed: centred)")
        ax.set_xlabel("forecast spread S [s] (0: the truth, published exactly)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("share of the hindsight saving kept [%]")
    axes[0][0].legend(fontsize=8, loc="lower left")
    save(fig, OUT, dpi=110)


if __name__ == "__main__":
    main()
