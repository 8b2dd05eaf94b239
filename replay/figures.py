"""The paper's figures with matplotlib: four trajectory panels, cost bars, battery-size bars, Table 2 maps."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

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


def cost_bars(groups: Sequence[str], bars: Sequence[tuple[str, Sequence[float], Sequence[float]]], title: str, path: Path, note=None) -> Path:
    """
    Stacked electricity + wear cost bars per group (e.g. per spacing s), one bar per series.

    ``bars``: (series label, electricity $ per group, wear $ per group). ``note``: text per group above
    the bars (e.g. the cost saving in %).
    """
    fig, ax = plt.subplots(figsize=(10, 5))
    n = len(bars)
    width = 0.8 / n
    x = np.arange(len(groups))
    for k, (label, elec, wear) in enumerate(bars):
        pos = x - 0.4 + width * (k + 0.5)
        hatch = "//" if "regular" in label else None
        ax.bar(pos, np.array(elec) * 100, width, color="tab:blue", hatch=hatch, edgecolor="k", lw=0.5)
        ax.bar(pos, np.array(wear) * 100, width, bottom=np.array(elec) * 100, color="tab:orange", hatch=hatch, edgecolor="k", lw=0.5)
        for p, e, w in zip(pos, elec, wear, strict=True):
            ax.text(p, (e + w) * 100, label.split()[0], ha="center", va="bottom", fontsize=7, rotation=90)
    if note is not None:
        tops = np.max([np.array(e) + np.array(w) for _, e, w in bars], axis=0) * 100
        for xi, top, text in zip(x, tops, note, strict=True):
            ax.text(xi, top * 1.12, text, ha="center", fontsize=9, fontweight="bold")
    handles = [
        Patch(facecolor="tab:blue", label="electricity"),
        Patch(facecolor="tab:orange", label="battery wear"),
        Patch(facecolor="white", hatch="//", edgecolor="k", label="regular driver (hatched)"),
    ]
    ax.set_xticks(x, groups)
    ax.set_ylabel("cost [US cents]")
    ax.set_title(title)
    ax.set_ylim(0, ax.get_ylim()[1] * 1.25)
    ax.legend(handles=handles, fontsize=8, loc="upper left")
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def grouped_bars(groups, series: Sequence[tuple[str, Sequence[float]]], ylabel: str, title: str, path: Path, note=None) -> Path:
    """Plain grouped bars (e.g. SOH decay per spacing for four driver/battery combinations)."""
    fig, ax = plt.subplots(figsize=(10, 5))
    width = 0.8 / len(series)
    x = np.arange(len(groups))
    for k, (label, values) in enumerate(series):
        ax.bar(x - 0.4 + width * (k + 0.5), values, width, label=label, color=COLORS[k % len(COLORS)])
    if note is not None:
        tops = np.max([v for _, v in series], axis=0)
        for xi, top, text in zip(x, tops, note, strict=True):
            ax.text(xi, top * 1.05, text, ha="center", fontsize=8)
    ax.set_xticks(x, groups)
    ax.set(ylabel=ylabel, title=title)
    ax.set_ylim(0, ax.get_ylim()[1] * 1.15)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def table_maps(row_labels, col_labels, ours: np.ndarray, paper: np.ndarray, title: str, path: Path) -> Path:
    """Table 2 as two heat maps (ours, paper) and their difference, values printed in the cells."""
    fig, axes = plt.subplots(1, 3, figsize=(13, 7))
    vmax = max(np.nanmax(ours), np.nanmax(paper))
    for ax, data, name, cmap, vmin, vmx in (
        (axes[0], ours, "ours", "viridis", 0, vmax),
        (axes[1], paper, "paper", "viridis", 0, vmax),
        (axes[2], ours - paper, "ours - paper", "coolwarm", -vmax / 2, vmax / 2),
    ):
        im = ax.imshow(data, cmap=cmap, vmin=vmin, vmax=vmx, aspect="auto")
        for (r, c), value in np.ndenumerate(data):
            ax.text(c, r, f"{round(value) + 0.0:.0f}", ha="center", va="center", fontsize=8, color="w" if name != "ours - paper" else "k")
        ax.set_xticks(range(len(col_labels)), col_labels)
        ax.set_yticks(range(len(row_labels)), row_labels if ax is axes[0] else [""] * len(row_labels))
        ax.set_title(name)
        fig.colorbar(im, ax=ax, fraction=0.05)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
