"""``swingrt vehicle``: describe a PX4 vehicle as a scenario from its parameters."""

from __future__ import annotations

import argparse
import sys

from swingrt.errors import ConfigError


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the subcommand."""
    p = sub.add_parser(
        "vehicle",
        help="a scenario of the vehicle PX4's parameters describe (from a ULog or a .params)",
        description="Reads the rotor geometry of PX4's control allocation, the cascade's "
        "gains, rates and limits, and the hover thrust, into a scenario's vehicle and "
        "controller sections; says what it could not know (inertia, drag, motor lag: "
        "nominal). The scenario flies the default step with the default payload; its "
        "vehicle is the twin wherever one is flown (swingrt simulate/identify --twin/hil).",
    )
    p.add_argument("source", help="PX4 ULog (.ulg) or parameter file (QGroundControl .params)")
    p.add_argument(
        "--mass",
        type=float,
        metavar="KG",
        help="take-off mass (vehicle and payload); the motors are scaled so that it hovers "
        "at MPC_THR_HOVER (default: the mass the nominal motors hover there, stated)",
    )
    p.add_argument(
        "--payload",
        type=float,
        metavar="KG",
        help="payload the vehicle hovered with at MPC_THR_HOVER; the vehicle is the take-off "
        "mass less it (default: the default payload, 0.2 kg)",
    )
    p.add_argument("-o", "--output", default="vehicle.toml", help="scenario TOML to write")
    return p


def run(args) -> int:
    """Run the subcommand."""
    if not args.output.endswith(".toml"):
        raise ConfigError(f"-o {args.output}: output must end in .toml")
    from swingrt.hil.params import vehicle_from_px4
    from swingrt.io.atomic import write_text_atomic
    from swingrt.io.px4_params import read_px4_parameters

    params = read_px4_parameters(args.source)
    sc, notes = vehicle_from_px4(params, mass=args.mass, payload=args.payload)
    header = [f"# The vehicle of {args.source}, read by swingrt vehicle from PX4's parameters."]
    header += [f"# {n}" for n in notes]
    write_text_atomic(args.output, "\n".join(header) + "\n" + sc.to_toml())
    v = sc.to_dict()["vehicle"]
    print(
        f"wrote {args.output}: mass {v['mass']:.3f} kg, arm {v['arm']:.3f} m, "
        f"yaw moment arm {v['yaw_arm']:.4f} m"
    )
    for n in notes:
        print(f"  {n}", file=sys.stderr)
    return 0
