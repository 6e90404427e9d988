"""``swingrt fly``: the offboard swing-damping MPC over MAVLink (real vehicle or sitl).

See :mod:`swingrt.mavlink.offboard` for the sequence and watchdogs, docs/flying.md for
the PX4 setup and the safety procedure.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys

from swingrt.errors import ConfigError


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``swingrt fly``."""
    p = subparsers.add_parser(
        "fly",
        help="fly the MPC offboard over MAVLink",
        description="Connect to a PX4 vehicle, switch to OFFBOARD, fly a velocity-step "
        "mission with the swing-damping MPC at 1/Ts, hand back to hold at the end.",
    )
    p.add_argument(
        "--connect",
        required=True,
        metavar="URL",
        help="udp:HOST:PORT (send to a sitl), udpin:0.0.0.0:14540 (PX4 SITL), "
        "serial:/dev/ttyTHS1:921600",
    )
    p.add_argument("--model", required=True, help="model JSON from `swingrt identify`")
    p.add_argument("--mission", help="mission TOML ([[step]] t, vn, ve; duration)")
    p.add_argument(
        "--adapt",
        action="store_true",
        help="fly the adaptive MPC: the model follows the payload in flight (online DMDc, "
        "change detector, checked re-synthesis on a worker thread)",
    )
    p.add_argument("--log", metavar="FILE", help="write the flight trace + loop timing")
    p.add_argument("--system-id", type=int, help="expected vehicle system id")
    p.add_argument(
        "--hold", choices=("loiter", "posctl"), default="loiter", help="mode to hand back to"
    )
    p.add_argument(
        "--acc-limit",
        type=float,
        help="clip |a| per axis, m/s^2 (default: the MPC's own acc_max)",
    )
    p.add_argument(
        "--budget", type=float, metavar="MS", help="compute budget per tick (default Ts/2)"
    )
    p.add_argument(
        "--stale-factor",
        type=float,
        default=3.0,
        help="telemetry older than this many Ts aborts (default 3)",
    )
    p.add_argument(
        "--timeout", type=float, default=5.0, help="heartbeat/telemetry wait, s (default 5)"
    )
    p.add_argument(
        "--swing-limit",
        type=float,
        default=30.0,
        metavar="DEG",
        help="hand back to PX4 when the swing exceeds this angle (default 30°)",
    )
    return p


def run(args) -> int:
    """Fly; print the loop timing; any failure is one line and a non-zero exit."""
    from swingrt.mavlink.link import connect
    from swingrt.mavlink.offboard import (
        Mission,
        Watchdog,
        fly,
        load_controller,
        model_swing_estimator,
    )

    # Finite too: an infinite stale factor, budget or acceleration limit switches a safety
    # net off, and an infinite --timeout waits for ever on a silent link.
    if args.acc_limit is not None and not (0 < args.acc_limit < math.inf):
        raise ConfigError(f"--acc-limit must be a positive number, not {args.acc_limit}")
    if args.budget is not None and not (0 < args.budget < math.inf):
        raise ConfigError(f"--budget must be a positive number of ms, not {args.budget}")
    if not (1 <= args.stale_factor < math.inf):
        raise ConfigError(f"--stale-factor must be a number >= 1, not {args.stale_factor}")
    if not (0 < args.timeout < math.inf):
        raise ConfigError(f"--timeout must be a positive number of seconds, not {args.timeout}")
    if not (0 < args.swing_limit < 90):
        raise ConfigError(f"--swing-limit must be in (0, 90) degrees, not {args.swing_limit}")
    if args.system_id is not None and not (1 <= args.system_id <= 255):
        raise ConfigError(f"--system-id must be 1..255, not {args.system_id}")
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    mission = Mission.from_toml(args.mission) if args.mission else Mission.default()
    controller, ts, axes = load_controller(args.model, adapt=args.adapt)
    watchdog = Watchdog(
        ts,
        stale_factor=args.stale_factor,
        budget=args.budget * 1e-3 if args.budget is not None else None,
        swing_limit=math.radians(args.swing_limit),
    )
    conn = connect(args.connect)
    try:
        report = fly(
            conn,
            controller,
            ts=ts,
            axes=axes,
            mission=mission,
            acc_limit=args.acc_limit,
            log_path=args.log,
            system_id=args.system_id,
            hold=args.hold,
            heartbeat_timeout=args.timeout,
            telemetry_timeout=args.timeout,
            watchdog=watchdog,
            swing_estimator=model_swing_estimator(args.model),
        )
    finally:
        conn.close()
    print(f"fly: {report.summary()}")
    if args.adapt:
        adopted = sum(1 for _, what, _ in controller.events() if what == "adopted")
        print(f"fly: adaptive MPC adopted {adopted} re-identified model(s)")
    return 0
