"""``swingrt mission``: fly a mission in the built-in simulator and print one row per
waypoint, for PX4's mission behaviour and for swingrt's jerk-limited legs side by side."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from swingrt.errors import ConfigError

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

    chosen = [g.strip() for g in args.guidance.split(",") if g.strip()]
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
    m = ms.load(args.plan)
    scenario = read_toml(args.scenario) if args.scenario else None
    flights: list[tuple[str, str | dict, _core.LinearModel | None]] = [(g, g, None) for g in chosen]
    if args.model:
        identified = _core.LinearModel.load(args.model)
        ms.check_model(identified)
        flights.append(("mpc", ms.shaped_legs(identified), identified))
    out: dict[str, dict] = {}
    flown = {}
    for name, g, model in flights:
        trace, events = ms.fly(m, g, scenario, seed=args.seed, model=model)
        rows = ms.waypoint_report(m, trace, events)
        total = max(t for t, _, k in events if k == "completed")
        print(ms.format_report(name, rows, total))
        out[name] = {"total_s": total, "waypoints": rows, "summary": ms.summary(rows, total, trace)}
        flown[name] = (trace, events)
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
