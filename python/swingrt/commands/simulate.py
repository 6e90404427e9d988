"""``swingrt simulate``: run a scenario and write its trace."""

from __future__ import annotations

import argparse
import math

from swingrt.commands._common import add_scenario_args, check_duration, check_output


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the subcommand."""
    p = sub.add_parser(
        "simulate",
        help="simulate a scenario under PX4 PID and write the trace",
        description="Default: 0.2 kg on 1 m, 2 m/s North velocity step at t = 2 s.",
    )
    add_scenario_args(p)
    p.add_argument("-o", "--output", default="trace.parquet", help="trace file (.parquet|.csv)")
    return p


def summary_lines(trace) -> list[str]:
    """Peak swing, velocity overshoot and settling of the trace's first North/East step."""
    from swingrt.metrics import step_metrics, step_time

    lines = []
    for axis in ("n", "e"):
        t0 = step_time(trace, axis)
        if t0 is None:
            continue
        m = step_metrics(trace, t0=t0, axis=axis)

        def fmt(x: float) -> str:
            return "not within the run" if math.isinf(x) else f"{x:.2f} s"

        lines.append(
            f"step on {axis.upper()} at t = {t0:.2f} s: "
            f"peak swing {m['peak_swing_deg']:.2f}°, "
            f"velocity overshoot {m['overshoot_pct']:.1f} %, "
            f"velocity settles {fmt(m['v_settle_s'])}, "
            f"swing settles (±1°) {fmt(m['swing_settle_s'])}, "
            f"swing IAE {m['swing_iae_deg_s']:.2f}°·s"
        )
    return lines


def run(args) -> int:
    """Run the subcommand."""
    from swingrt.sim import simulate

    check_duration(args.duration)
    check_output(args.output)
    trace = simulate(args.scenario, duration=args.duration, seed=args.seed, progress=None)
    trace.save(args.output)
    t = trace.t
    print(f"wrote {args.output}: {len(trace)} rows, {t[-1] - t[0]:.1f} s")
    for line in summary_lines(trace):
        print(line)
    return 0
