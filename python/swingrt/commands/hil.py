"""``swingrt hil``: swingrt's plant under a real PX4 flight controller (SITL or HITL).

See :mod:`swingrt.hil` for the loop and docs/flying.md for the PX4 side.
"""

from __future__ import annotations

import argparse
import logging
import math
import signal
import sys
import threading

from swingrt.errors import ConfigError


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``swingrt hil``."""
    p = subparsers.add_parser(
        "hil",
        help="serve the simulator to a PX4 flight controller (PX4 SITL or a Pixhawk in HITL)",
        description="Vehicle + payload physics for PX4's simulator interface: HIL_SENSOR at "
        "250 Hz, HIL_GPS, ground truth, lockstep on HIL_ACTUATOR_CONTROLS, the swing sensor "
        "as DEBUG_VECT 'SWING'. With --px4 DIR it also starts PX4 SITL (and with --takeoff "
        "arms it and climbs to the scenario's start altitude). Runs until Ctrl-C or --duration.",
    )
    p.add_argument("scenario", nargs="?", help="scenario TOML (default: built-in hover)")
    p.add_argument(
        "--connect",
        metavar="URL",
        help="simulator link: tcpin:0.0.0.0:PORT for SITL (default port 4560 + instance) or "
        "serial:DEVICE:BAUD for a Pixhawk in HITL mode",
    )
    p.add_argument(
        "--swing-link",
        metavar="URL",
        help="PX4 MAVLink link that receives the swing sensor and the take-off commands "
        "(default for SITL: udpout:127.0.0.1:18570 + instance, PX4's GCS link; for a serial "
        "link: that link)",
    )
    p.add_argument("--px4", metavar="DIR", help="start PX4 SITL from this build folder")
    p.add_argument("--instance", type=int, default=0, help="PX4 instance (shifts every port)")
    p.add_argument("--workdir", metavar="DIR", help="PX4's working folder (default: a new one)")
    p.add_argument("--takeoff", action="store_true", help="arm and take off to the start altitude")
    p.add_argument(
        "--px4-params",
        action="store_true",
        help="print the PX4 parameters that match PX4 to the scenario's vehicle and exit",
    )
    p.add_argument("--speed", type=float, default=1.0, help="simulated s per wall s (default 1)")
    p.add_argument("--duration", type=float, help="stop after S simulated seconds")
    p.add_argument("--seed", type=int, help="seed of every random generator")
    p.add_argument("--log", metavar="FILE", help="write the physics trace (.parquet/.csv) on exit")
    return p


def run(args) -> int:
    """Serve until Ctrl-C / --duration / PX4 exits; print the loop figures."""
    from swingrt.hil import HilServer, Px4Sitl, px4_parameters
    from swingrt.hil.px4 import GCS_PORT, SIM_PORT
    from swingrt.scenario import resolve

    if not (0 < args.speed <= 50):
        raise ConfigError(f"--speed must be in (0, 50], not {args.speed}")
    if args.duration is not None and not (0 < args.duration < math.inf):
        raise ConfigError(f"--duration must be a positive number of seconds, not {args.duration}")
    if not (0 <= args.instance <= 100):
        raise ConfigError(f"--instance must be 0..100, not {args.instance}")
    if args.log and not args.log.endswith((".parquet", ".csv")):
        raise ConfigError(f"--log {args.log}: must end in .parquet or .csv")
    duration = float(args.duration) if args.duration is not None else 86_400.0
    overrides: dict = {"setpoints": [], "duration": duration}
    if args.seed is not None:
        overrides["seed"] = args.seed
    scenario = resolve(args.scenario, default="hover").with_overrides(overrides)
    altitude = -scenario.to_dict()["start"][2]
    if args.takeoff and altitude <= 0.5:
        raise ConfigError(
            f"--takeoff: the scenario's start altitude is {altitude:g} m; give start = "
            "[n, e, d] with d < -0.5 (Down is negative up)",
            field="start",
        )
    params = px4_parameters(scenario, takeoff_altitude=altitude if args.takeoff else None)
    if args.px4_params:
        for name, value in params.items():
            print(f"{name}={value}")
        return 0
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    from swingrt._core import HilPlant

    plant = HilPlant(scenario)
    sim_url = args.connect or f"tcpin:0.0.0.0:{SIM_PORT + args.instance}"
    gcs_url = args.swing_link
    if gcs_url is None and sim_url.startswith(("tcpin:", "tcp:", "udp")):
        gcs_url = f"udpout:127.0.0.1:{GCS_PORT + args.instance}"
    px4 = None
    if args.px4:
        px4 = Px4Sitl(args.px4, instance=args.instance, params=params, workdir=args.workdir)

    def ready(server) -> None:
        print(f"hil: ready, holding at {altitude:g} m", flush=True)

    server = HilServer(
        plant,
        sim_url,
        gcs_url=gcs_url,
        speed=args.speed,
        takeoff_altitude=altitude if args.takeoff else None,
        on_ready=ready,
        px4=px4,
    )
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    report = None
    try:
        if px4 is not None:
            px4.start()
            print(f"hil: PX4 started in {px4.workdir} (instance {args.instance})", flush=True)
        report = server.run(duration=args.duration, stop=stop)
    finally:
        if px4 is not None:
            px4.stop()
        server.close()
        if args.log:
            server.trace().save(args.log)
            print(f"hil: wrote {args.log}", flush=True)
        if px4 is not None:
            for path in px4.ulogs():
                print(f"hil: PX4 log {path}", flush=True)
    print(f"hil: {report.summary()}", flush=True)
    return 0
