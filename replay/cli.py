"""`replay trace.csv`: score a recorded drive with the EV energy and battery-wear model."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

from advisory.params import DEFAULT_VEHICLE, VEHICLE_PRESETS, model_params
from advisory.scoring import DriveScore, score_trace
from replay.trace_io import TraceError, read_speed_trace


def render_score(score: DriveScore, title: str) -> str:
    rows = [
        ("distance", f"{score.distance_m / 1000:.3f} km"),
        ("duration", f"{score.duration_s:.0f} s"),
        ("battery energy out", f"{score.battery_out_kwh:.4f} kWh"),
        ("regen energy in", f"{score.regen_in_kwh:.4f} kWh"),
        ("net battery energy", f"{score.net_kwh:.4f} kWh"),
        ("consumption", f"{score.wh_per_km:.1f} Wh/km ({score.wh_per_km * 1.609344:.1f} Wh/mi)"),
        ("SOH lost", f"{score.soh_lost_frac:.3e} of life ({score.capacity_loss_pct:.3e} % capacity)"),
        ("electricity cost", f"${score.electricity_usd:.5f}"),
        ("battery wear cost", f"${score.wear_usd:.5f}"),
        ("total cost", f"${score.total_usd:.5f}"),
        ("energy audit residual", f"{score.audit.residual_j:.2e} J"),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join([title] + [f"  {k:<{width}}  {v}" for k, v in rows])


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="replay", description="Score a recorded drive (CSV of time and speed).")
    parser.add_argument("trace", help="CSV with columns t_s (or time) and speed_mps (or speed_kmh / speed_mph)")
    parser.add_argument("--vehicle", default=DEFAULT_VEHICLE, choices=sorted(VEHICLE_PRESETS))
    parser.add_argument("--decay-multiplier", type=float, default=1.0, help="battery decay-rate multiplier (10 = NCA)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = parser.parse_args(argv)
    try:
        trace = read_speed_trace(args.trace)
        params = model_params(args.vehicle, args.decay_multiplier)
        score = score_trace(trace.t_s, trace.speed_mps, params, trace.grade_frac)
    except (TraceError, ValueError) as exc:
        print(f"replay: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps({"trace": trace.source, "vehicle": args.vehicle, **score.as_dict()}, indent=2))
    else:
        print(render_score(score, f"{trace.source} ({args.vehicle}, decay x{args.decay_multiplier:g})"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
