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
        "mission with the swing-damping MPC at 1/Ts, hand back to hold at the end. With a "
        "waypoint plan (--mission PLAN.plan or a TOML of [[waypoint]]s) the position MPC with "
        "preview flies it along legs shaped against the model's swing; with --auto PX4's own "
        "AUTO.MISSION flies it (uploaded by the MAVLink mission protocol), the baseline.",
    )
    p.add_argument(
        "--connect",
        required=True,
        metavar="URL",
        help="udp:HOST:PORT (send to a sitl), udpin:0.0.0.0:14540 (PX4 SITL), "
        "serial:/dev/ttyTHS1:921600",
    )
    p.add_argument("--model", help="model JSON from `swingrt identify` (not with --auto)")
    p.add_argument(
        "--mission",
        help="velocity steps (TOML of [[step]] t, vn, ve; duration) or a waypoint plan "
        "(QGroundControl .plan, or TOML of [[waypoint]] n, e, d in PX4's local frame)",
    )
    p.add_argument(
        "--auto",
        action="store_true",
        help="with a waypoint plan: upload it and let PX4's AUTO.MISSION fly it (the baseline), "
        "logging the flight; no model",
    )
    p.add_argument(
        "--adapt",
        action="store_true",
        help="fly the adaptive MPC: the model follows the payload in flight (online DMDc, "
        "change detector, checked re-synthesis on a worker thread); a model selected on a "
        "vehicle twin is re-identified on that twin for the cable length measured in flight",
    )
    p.add_argument(
        "--no-twin",
        action="store_true",
        help="with --adapt: re-identify on the online DMDc alone, not on the model's twin",
    )
    p.add_argument(
        "--target",
        choices=("vehicle", "payload"),
        default="vehicle",
        help="with a waypoint plan: what the MPC puts over each waypoint (as `swingrt mission`)",
    )
    p.add_argument(
        "--cable-length", type=float, metavar="M", help="cable length for --target payload"
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
        model_body_sensor,
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
    plan = _waypoint_plan(args.mission)
    if args.auto and plan is None:
        raise ConfigError("--auto flies a waypoint plan: give --mission PLAN (.plan or TOML)")
    if args.auto and (args.model or args.adapt):
        raise ConfigError("--auto: PX4 flies its own mission; --model and --adapt do not apply")
    if not args.auto and not args.model:
        raise ConfigError("--model is required (a model JSON from `swingrt identify`)")
    if plan is None and (args.target != "vehicle" or args.cable_length is not None):
        raise ConfigError("--target and --cable-length apply to a waypoint plan (--mission PLAN)")
    if plan is not None and args.adapt:
        raise ConfigError("--adapt flies velocity steps; a waypoint plan flies the position MPC")
    if args.no_twin and not args.adapt:
        raise ConfigError("--no-twin applies to --adapt")
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    if plan is not None:
        return _fly_plan(args, plan)
    mission = Mission.from_toml(args.mission) if args.mission else Mission.default()
    controller, ts, axes = load_controller(args.model, adapt=args.adapt, twin=not args.no_twin)
    from swingrt.sysid import LinearModel, model_twin, unchecked_warning

    model = LinearModel.load(args.model)
    warning = unchecked_warning(model)
    if warning is not None:
        print(f"fly: {warning}", flush=True)
    law = (model.diagnostics.get("control_check") or {}).get("law") or {}
    if law.get("kind", "mpc") != "mpc" and not args.adapt:
        print(
            f"fly: no candidate's MPC passed the check; flying the {law['kind']} the selection "
            "took on PX4's velocity setpoint",
            flush=True,
        )
    if args.adapt:
        path = "off (--no-twin)" if args.no_twin else "the model's own"
        if not args.no_twin and model_twin(model) is None:
            path = "none (the model was selected without one): online DMDc alone"
        print(f"fly: adaptive MPC, twin {path}", flush=True)
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
            body_sensor=model_body_sensor(args.model),
        )
    finally:
        conn.close()
    print(f"fly: {report.summary()}")
    if args.adapt:
        adopted = sum(1 for _, what, _ in controller.events() if what == "adopted")
        print(f"fly: adaptive MPC adopted {adopted} re-identified model(s)")
    return 0


def _waypoint_plan(path):
    """The waypoint plan at ``path`` (``swingrt.mission.load``), or None for velocity steps
    (no path, or a TOML without ``[[waypoint]]``)."""
    from pathlib import Path

    from swingrt import mission as ms
    from swingrt.scenario import read_toml

    if path is None:
        return None
    p = Path(path)
    if p.suffix.lower() == ".toml":
        if "waypoint" not in read_toml(p):
            return None
    elif p.suffix.lower() != ".plan":
        raise ConfigError(f"--mission {p}: must end in .toml or .plan")
    try:
        return ms.load(str(p))
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such mission file") from None


def _fly_plan(args, plan) -> int:
    """Fly a waypoint plan over MAVLink (the MPC, or with --auto PX4's AUTO.MISSION) and
    print one row per waypoint from the node's log (the measured swing; a simulator behind
    PX4 also sends the true one, which the rows then use)."""
    from swingrt import _core
    from swingrt import mission as ms
    from swingrt.mavlink.link import connect
    from swingrt.mavlink.mission import fly_mission, fly_px4_mission
    from swingrt.mavlink.offboard import Watchdog

    model = None
    tracking = None
    if not args.auto:
        model = _core.LinearModel.load(args.model)
        ms.check_model(model)
        tracking, what = ms.target_tracking(model, args.target, args.cable_length)
        print(f"fly: {what}")
    elif args.target != "vehicle" or args.cable_length is not None:
        raise ConfigError("--auto: PX4 flies its own mission; --target does not apply")
    ts = 0.02 if model is None else model.dt
    watchdog = Watchdog(
        ts,
        stale_factor=args.stale_factor,
        budget=args.budget * 1e-3 if args.budget is not None else None,
        swing_limit=math.radians(args.swing_limit),
    )
    options = {
        "log_path": args.log,
        "system_id": args.system_id,
        "hold": args.hold,
        "heartbeat_timeout": args.timeout,
        "telemetry_timeout": args.timeout,
        "watchdog": watchdog,
    }
    conn = connect(args.connect)
    try:
        if model is None:
            flight = fly_px4_mission(conn, plan, ts=ts, **options)
        else:
            flight = fly_mission(
                conn, model, plan, tracking=tracking, acc_limit=args.acc_limit, **options
            )
    finally:
        conn.close()
    cols = flight.report.columns
    rows = ms.waypoint_report(flight.mission, cols, flight.events)
    total = max((t for t, _, k in flight.events if k == "completed"), default=math.nan)
    print(ms.format_report("px4" if model is None else "mpc", rows, total))
    if flight.reported is not None:
        done = ", ".join(f"{k} at {t:.2f} s" for t, k in flight.reported)
        print(f"fly: PX4 reported the items done (holds over): {done}")
    print(f"fly: {flight.report.summary()}")
    return 0
