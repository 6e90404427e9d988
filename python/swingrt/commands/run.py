"""``swingrt run``: the main job, end to end on the built-in simulator.

Training flight under PX4 PID → identification with search (DMDc for the MPC, white-box
for the LQR) → PID, LQR and MPC on the default 2 m/s North step → report folder with the
metrics, figures, traces and the model. ``--swing-source`` sets how every flight of the run
measures the swing (``imu``: no sensor on the cable, the model identified on the IMU's
estimate); the model and the report record it.
"""

from __future__ import annotations

import argparse


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the subcommand."""
    p = sub.add_parser(
        "run",
        help="main job: training flight → identify → LQR/MPC → compare on the default step",
    )
    p.add_argument("--out", default="report", help="report folder (default: report)")
    p.add_argument("--seed", type=int, default=0, help="seed of the flights")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument(
        "--px4",
        metavar="DIR",
        help="run the comparison on PX4 SITL from this build folder, swingrt's physics in "
        "the loop (`swingrt hil`): PX4's ULog is the training data, PID is PX4's own",
    )
    p.add_argument(
        "--swing-source",
        choices=("sensor", "body", "imu"),
        default="sensor",
        help="how every flight measures the swing: a world-frame swing sensor (default), a "
        "cable-angle sensor on the airframe, or none (the IMU estimate)",
    )
    p.add_argument(
        "--airframe",
        default="honeybee",
        metavar="NAME",
        help="the built-in vehicle every flight flies: honeybee (the thesis's, default) or "
        "x500 (PX4's reference quadrotor of its SITL)",
    )
    p.add_argument(
        "--methods",
        metavar="NAMES",
        help="also fly these of the field's methods (comma-separated: shaper, shaper_zv, "
        "payload_p, deepc, sindy_mpc, nmpc, havokc_mpc; `all`), trained on the same flight",
    )
    p.add_argument(
        "--no-twin",
        action="store_true",
        help="with --px4: select the model without flying it first on the vehicle PX4's "
        "parameters describe (the twin, read from PX4's ULog)",
    )
    p.add_argument("--instance", type=int, default=0, help="PX4 instance with --px4")
    p.add_argument(
        "--training",
        type=float,
        default=300.0,
        metavar="S",
        help="training flight length with --px4 (default 300 s)",
    )
    return p


def run(args) -> int:
    """Run the subcommand."""
    import sys
    from pathlib import Path

    from swingrt.experiments import Experiment, run_experiment

    methods = _methods(args.methods)
    if args.px4:
        from swingrt.hil.pipeline import run_on_px4

        rows = run_on_px4(
            args.px4,
            args.out,
            seed=args.seed,
            instance=args.instance,
            training=args.training,
            quiet=args.quiet,
            twin=not args.no_twin,
            swing_source=args.swing_source,
            airframe=args.airframe,
            methods=methods,
        )
        print((Path(args.out) / "metrics.md").read_text(encoding="utf-8"))
        by = {r["controller"]: r for r in rows}
        excess = "swing_excess_iae_deg_s"
        ratio = by["mpc"][excess] / max(by["pid"][excess], 1e-12)
        print(f"MPC swing IAE above the momentum floor is {ratio:.3f}× PX4 PID's")
        print(f"report: {args.out}/ (metrics, figures, traces, model, PX4 ULogs)")
        return 0
    if args.no_twin:
        from swingrt.errors import ConfigError

        raise ConfigError(
            "--no-twin: applies with --px4 (on the built-in simulator the training flight's "
            "vehicle is the twin)"
        )
    exp = Experiment(
        name="default-step",
        description=f"{args.airframe} with 0.2 kg on 1 m: 2 m/s North velocity step at "
        "t = 2 s after a 300 s random-step training flight (thesis table 4.1); swing source "
        f"{args.swing_source}.",
        duration=30.0,
        controllers=["pid", "lqr", "mpc", *methods],
        common={"sensors": {"swing": args.swing_source}, "vehicle": {"airframe": args.airframe}},
    )
    rows = run_experiment(exp, args.out, seed=args.seed, quiet=args.quiet)
    out = Path(args.out)
    # The double descent of thesis 4.6.8 on this very training flight.
    from swingrt import sysid
    from swingrt.io.flight import Trace
    from swingrt.reports import plot_training_length

    train = Trace.from_parquet(out / "default-step__training.parquet")
    if not args.quiet:
        print("[ identification ] error vs training length", file=sys.stderr, flush=True)
    lengths = [float(x) for x in range(20, 261, 20)]
    sweep = sysid.sweep_training_length(train, lengths)
    plot_training_length(sweep, out / "error_vs_training_length.png")
    print((out / "metrics.md").read_text(encoding="utf-8"))
    pid = next(r for r in rows if r["controller"] == "pid")
    mpc = next((r for r in rows if r["controller"] == "mpc"), None)
    if mpc:
        ratio = mpc["swing_iae_deg_s"] / max(pid["swing_iae_deg_s"], 1e-12)
        print(f"MPC swing IAE is {ratio:.2f}× PX4 PID's")
    print(f"vehicle: {args.airframe}; swing source: {args.swing_source} (every flight)")
    print(f"report: {out}/ (metrics.csv, metrics.md, figures, traces, model)")
    return 0


def _methods(names: str | None) -> list[str]:
    """The ``--methods`` list (``all``: every method), each name checked."""
    from swingrt.errors import ConfigError
    from swingrt.methods import METHODS

    if not names:
        return []
    picked = list(METHODS) if names.strip() == "all" else [n.strip() for n in names.split(",")]
    unknown = [n for n in picked if n not in METHODS]
    if unknown or not picked:
        raise ConfigError(
            f"--methods: unknown {', '.join(unknown) or '(none given)'} "
            f"(one of {', '.join(METHODS)}, or all)",
            field="methods",
        )
    return picked
