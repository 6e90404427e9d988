"""``swingrt mission``: fly a mission in the built-in simulator and print one row per
waypoint, for PX4's mission behaviour and for swingrt's jerk-limited legs side by side."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from swingrt.errors import ConfigError, FlightAbort

GUIDANCES = ("px4", "smooth")
#: Formats ``--figure`` writes, by the file's suffix.
FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the subcommand."""
    p = sub.add_parser("mission", help="fly a .plan or TOML mission in the simulator")
    p.add_argument("plan", help="QGroundControl .plan or TOML mission")
    p.add_argument(
        "--guidance",
        default=",".join(GUIDANCES),
        help="comma-separated guidances to fly (px4, smooth; default both)",
    )
    p.add_argument(
        "--scenario", help="scenario TOML of the flight (payload, wind, vehicle; default built-in)"
    )
    p.add_argument(
        "--model",
        help="identified model (both axes): also fly the position MPC with preview on it "
        "along swingrt's legs shaped against the model's swing period (reported as mpc)",
    )
    p.add_argument(
        "--lqr",
        metavar="MODEL",
        help="white-box model (`identify --method whitebox`): also fly the thesis's LQR on "
        "its pendulum in place of PX4's velocity loop, along legs shaped against its swing "
        "(reported as lqr)",
    )
    p.add_argument(
        "--target",
        choices=("vehicle", "payload"),
        default="vehicle",
        help="what the MPC puts over each waypoint: the vehicle (default) or the payload "
        "hanging below it (vehicle position + cable length x swing)",
    )
    p.add_argument(
        "--cable-length",
        type=float,
        metavar="M",
        help="cable length for --target payload (default: the white-box model's, else the "
        "pendulum length of the model's swing period)",
    )
    p.add_argument(
        "--px4",
        metavar="DIR",
        help="fly on PX4 SITL from this build folder with swingrt's physics (`swingrt hil`): "
        "PX4's own AUTO.MISSION (the plan uploaded by the MAVLink mission protocol) and, with "
        "--model, swingrt's MPC offboard, each in a fresh PX4 session",
    )
    p.add_argument("--instance", type=int, default=0, help="PX4 SITL instance (with --px4)")
    p.add_argument(
        "--out",
        help="with --px4: folder for each flight's node log, physics trace, scenario and PX4 "
        "ULog (default: a new temporary folder)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of every random generator")
    p.add_argument("-o", "--output", help="write the per-waypoint rows as JSON here")
    p.add_argument(
        "--figure",
        help="write the figure here (.png/.pdf/.svg): the paths seen from above and the "
        "swing against time with the arrivals marked",
    )
    return p


def run(args: argparse.Namespace) -> int:
    """Fly the mission once per guidance and print (and optionally write) the report."""
    from swingrt import _core
    from swingrt import mission as ms
    from swingrt.io.atomic import write_text_atomic
    from swingrt.scenario import read_toml

    guidance = args.guidance
    if args.px4 and guidance == ",".join(GUIDANCES):
        guidance = "px4"
    chosen = [g.strip() for g in guidance.split(",") if g.strip()]
    if not chosen:
        raise ConfigError("--guidance: name at least one of " + ", ".join(GUIDANCES))
    for g in chosen:
        if g not in GUIDANCES:
            raise ConfigError(f"--guidance: {g!r} is not one of {', '.join(GUIDANCES)}")
    if args.figure and Path(args.figure).suffix.lower() not in FIGURE_SUFFIXES:
        raise ConfigError(
            f"--figure: {args.figure!r} must end in {', '.join(FIGURE_SUFFIXES)}",
            field="figure",
        )
    if args.px4 and chosen != ["px4"]:
        raise ConfigError(
            "--guidance: on PX4 (--px4) the flights are PX4's own mission mode (px4) and, with "
            "--model, the MPC; swingrt's legs under PX4 (smooth) fly in the simulator only",
            field="guidance",
        )
    if not (0 <= args.instance <= 100):
        raise ConfigError(f"--instance must be 0..100, not {args.instance}")
    m = ms.load(args.plan)
    scenario = read_toml(args.scenario) if args.scenario else None
    flights: list[tuple[str, str | dict, _core.LinearModel | None]] = [(g, g, None) for g in chosen]
    tracking = None
    if args.model:
        identified = _core.LinearModel.load(args.model)
        ms.check_model(identified)
        tracking, what = ms.target_tracking(identified, args.target, args.cable_length)
        print(f"mpc: {what}")
        flights.append(("mpc", ms.shaped_legs(identified), identified))
    lqr = None
    if args.lqr:
        from swingrt.sysid import lqr_parameters

        pendulum = _core.LinearModel.load(args.lqr)
        lqr = lqr_parameters(pendulum)
        if args.px4:
            raise ConfigError("--lqr flies in the simulator only (not with --px4)", field="lqr")
    if not args.model and (args.target != "vehicle" or args.cable_length is not None):
        raise ConfigError("--target and --cable-length steer the MPC: give --model", field="target")
    if args.px4:
        import tempfile

        from swingrt.hil.mission import fly_on_px4

        folder = args.out or tempfile.mkdtemp(prefix="swingrt-mission-")
        flown = fly_on_px4(
            args.px4,
            m,
            folder,
            scenario=scenario,
            model=flights[-1][2] if args.model else None,
            tracking=tracking,
            seed=args.seed,
            instance=args.instance,
            flights=tuple(name for name, _, _ in flights),
        )
        print(f"flights on PX4 SITL (logs, physics, ULogs) in {folder}")
        # Judged on the plan without its home, as flown there.
        m = _core.Mission.from_text(m.to_toml(), "toml")
    else:
        flown = {
            name: ms.fly(m, g, scenario, seed=args.seed, model=model, tracking=tracking)
            for name, g, model in flights
        }
        if lqr is not None:
            flown["lqr"] = ms.fly(m, ms.shaped_legs(pendulum), scenario, seed=args.seed, lqr=lqr)
    out: dict[str, dict] = {}
    for name, (trace, events) in flown.items():
        rows = ms.waypoint_report(m, trace, events)
        done = [t for t, _, k in events if k == "completed"]
        if not done:
            raise FlightAbort(f"{name}: the flight did not complete the plan {m.name!r}")
        total = max(done)
        print(ms.format_report(name, rows, total))
        out[name] = {"total_s": total, "waypoints": rows, "summary": ms.summary(rows, total, trace)}
    px4 = out.get("px4")
    for name, flight in out.items():
        flight["summary"].update(
            ms.compare(
                flight["summary"],
                flight["waypoints"],
                None if px4 is None else px4["summary"],
                None if px4 is None else px4["waypoints"],
            )
        )
        failure = ms.mission_failure(flight["summary"], judged=name != "px4")
        flight["failure"] = failure
    if px4 is not None and len(out) > 1:
        print(ms.format_comparison(out))
    if args.output:
        write_text_atomic(args.output, json.dumps(out, indent=1))
    if args.figure:
        from swingrt.reports.plots import plot_mission

        plot_mission(args.figure, f"mission {m.name!r}", m.items, flown)
        print(f"wrote {args.figure}")
    return 0
