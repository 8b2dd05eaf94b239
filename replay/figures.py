"""The paper's four trajectory panels with matplotlib, shared by `replay --plot` and `ecodrive study`."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from advisory.signals import FixedTimeSignal  # noqa: E402

COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown")


def _red_bars(ax, light: FixedTimeSignal, t_end_s: float, color="red") -> None:
    for start, end in light.red_intervals(0.0, t_end_s):
        ax.plot([max(start, 0.0), min(end, t_end_s)], [light.position_m] * 2, color=color, lw=4, alpha=0.6, solid_capstyle="butt")


def trajectory_panels(
    runs: Sequence[tuple[str, object, object, Sequence[FixedTimeSignal]]],
    title: str,
    path: Path,
    labels: tuple[str, str] = ("eco-driver", "regular driver"),
) -> Path:
    """
    Paper-style four panels: (a) time-distance with red bars, (b) speed, (c) energy, (d) SOH decay.

    ``runs``: (label, solid score series, dashed score series or None, lights) per colour; series are
    ``advisory.evaluation.scoring.TraceSeries``.
    """
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    ax_td, ax_v, ax_e, ax_d = axes.ravel()
    t_end = max(s.t_s[-1] for _, a, b, _ in runs for s in (a, b) if s is not None)
    for n, (label, solid, dashed, lights) in enumerate(runs):
        color = COLORS[n % len(COLORS)]
        for light in lights:
            _red_bars(ax_td, light, t_end)
        for series, style in ((solid, "-"), (dashed, "--")):
            if series is None:
                continue
            x = series.position_m
            ax_td.plot(series.t_s, x, style, color=color)
            ax_v.plot(x, series.speed_mps * 3.6, style, color=color)
            ax_e.plot(x, series.energy_kwh * 1000, style, color=color)
            ax_d.plot(x, series.soh_lost_frac * 1e6, style, color=color)
            ax_td.plot(series.t_s[-1], x[-1], "s", color=color, ms=5)
        ax_v.plot([], [], "-", color=color, label=label)
    ax_v.plot([], [], "k-", label=labels[0])
    ax_v.plot([], [], "k--", label=labels[1])
    ax_td.set(xlabel="time [s]", ylabel="distance [m]", title="(a) trajectories (red: red light)")
    ax_v.set(xlabel="distance [m]", ylabel="speed [km/h]", title="(b) speed")
    ax_e.set(xlabel="distance [m]", ylabel="battery energy [Wh]", title="(c) cumulative energy")
    ax_d.set(xlabel="distance [m]", ylabel="SOH lost [1e-6 of life]", title="(d) battery capacity decay")
    ax_v.legend(fontsize=8, loc="lower left")
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
