"""``swingrt sitl``: the project's simulator as a MAVLink vehicle speaking like PX4.

See :mod:`swingrt.mavlink.vehicle` for what it sends and accepts, and docs/flying.md.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys

from swingrt.errors import ConfigError


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``swingrt sitl``."""
    p = subparsers.add_parser(
        "sitl",
        help="run the simulator behind a PX4-like MAVLink endpoint (real time)",
        description="Serve a simulated PX4 vehicle (HEARTBEAT, LOCAL_POSITION_NED, "
        "ATTITUDE_QUATERNION, DEBUG_VECT 'SWING', offboard setpoints) until Ctrl-C.",
    )
    p.add_argument("scenario", nargs="?", help="scenario TOML (default: built-in)")
    p.add_argument(
        "--listen",
        action="append",
        metavar="URL",
        help="endpoint to serve, repeatable (default udp:127.0.0.1:14540)",
    )
    p.add_argument("--log", metavar="FILE", help="write the flight trace (.parquet/.csv) on exit")
    p.add_argument("--speed", type=float, default=1.0, help="simulated s per wall s (default 1)")
    p.add_argument("--rate", type=float, default=100.0, help="loop rate in Hz (default 100)")
    p.add_argument("--duration", type=float, help="stop after S simulated seconds")
    p.add_argument("--system-id", type=int, default=1, help="MAVLink system id (default 1)")
    p.add_argument(
        "--offboard-loss",
        type=float,
        default=1.0,
        metavar="S",
        help="PX4 COM_OF_LOSS_T: hold after S s without setpoints (default 1)",
    )
    return p


def run(args) -> int:
    """Run the vehicle until SIGINT/SIGTERM (or --duration); the trace is flushed on exit."""
    if not (0 < args.speed < math.inf):
        raise ConfigError(f"--speed must be a positive number, not {args.speed}")
    if not (0 < args.rate <= 1000):
        raise ConfigError(f"--rate must be in (0, 1000] Hz, not {args.rate}")
    if not (1 <= args.system_id <= 255):
        raise ConfigError(f"--system-id must be 1..255, not {args.system_id}")
    if not (0 < args.offboard_loss < math.inf):
        raise ConfigError(f"--offboard-loss must be a positive number, not {args.offboard_loss}")
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    from swingrt.mavlink.vehicle import run_vehicle
    from swingrt.scenario import resolve
    from swingrt.sim import Simulator

    # The vehicle is commanded over MAVLink only: a setpoint schedule in the scenario would
    # fight the offboard node, so it is dropped (the vehicle starts holding its start point).
    duration = float(args.duration) if args.duration is not None else 3600.0
    scenario = resolve(args.scenario, default="hover", duration=duration).with_overrides(
        {"setpoints": []}
    )
    sim = Simulator(scenario)
    run_vehicle(
        sim,
        args.listen or ["udp:127.0.0.1:14540"],
        log_path=args.log,
        rate_hz=args.rate,
        speed=args.speed,
        duration=args.duration,
        system_id=args.system_id,
        offboard_loss_timeout=args.offboard_loss,
    )
    return 0
