"""``swingrt collect``: fly the random-step training flight and record it."""

from __future__ import annotations

import argparse
import math

from swingrt.commands._common import add_scenario_args, check_duration, check_output


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the subcommand."""
    p = sub.add_parser(
        "collect",
        help="fly the random velocity-step training flight (table 4.1) and record it",
        description="Default: 0.2 kg on 1 m, 300 s of random North velocity steps "
        "(0–3 m/s, held 10–25 s) under PX4 PID. With --connect the same mission is flown "
        "over MAVLink against a real or simulated PX4 vehicle.",
    )
    add_scenario_args(p)
    p.add_argument("-o", "--output", default="train.parquet", help="trace file (.parquet|.csv)")
    p.add_argument(
        "--axes",
        choices=("n", "ne"),
        default=None,
        help="axes of the random steps: n (default) or ne (North and East, for two-axis models)",
    )
    p.add_argument("--connect", help="MAVLink URL: fly the mission on a vehicle instead")
    p.add_argument(
        "--swing-source",
        choices=("sensor", "body", "imu"),
        default=None,
        help="how the record measures the swing: the swing sensor (default; over MAVLink its "
        "DEBUG_VECT 'SWING'), the cable sensor on the airframe (its ADC counts, over MAVLink "
        "DEBUG_VECT 'SWBODY', composed with the attitude) or none on the cable, the swing "
        "estimated from the IMU (over MAVLink PX4's HIGHRES_IMU, with the scenario's "
        "estimator settings)",
    )
    return p


def run(args) -> int:
    """Run the subcommand."""
    check_duration(args.duration)
    check_output(args.output)
    from swingrt.scenario import resolve

    config = resolve(args.scenario, default="training")
    if args.swing_source is not None:
        config = config.with_overrides({"sensors": {"swing": args.swing_source}})
    if args.connect:
        from swingrt.mavlink import collect_over_mavlink

        sensors = config.to_dict()["sensors"]
        imu = sensors["swing"] == "imu"
        collect_over_mavlink(
            args.connect,
            duration=args.duration or 300.0,
            seed=args.seed or 0,
            out=args.output,
            axes=args.axes or "n",
            swing_estimator=dict(sensors["estimator"]) if imu else None,
            body_sensor=dict(sensors["body"]) if sensors["swing"] == "body" else None,
        )
        return 0
    from swingrt.sim import collect

    if args.axes == "ne":
        config = config.with_overrides(
            {
                "random_steps": {"axes": "ne"},
                "setpoints": [{"t": 0.0, "vn": 0.0, "ve": 0.0}],
            }
        )
    trace = collect(config, duration=args.duration, seed=args.seed, progress=None)
    trace.save(args.output)
    vsp = trace["vel_sp_n"]
    steps = int((abs(vsp[1:] - vsp[:-1]) > 1e-9).sum())
    print(
        f"wrote {args.output}: {len(trace)} rows, {trace.t[-1]:.1f} s, "
        f"{steps} velocity steps, peak swing {math.degrees(abs(trace['swing_n']).max()):.1f}°"
    )
    return 0
