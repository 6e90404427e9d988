"""``swingrt identify``: learn a linear model from flight data."""

from __future__ import annotations

import argparse
from pathlib import Path

from swingrt.commands._common import options_named
from swingrt.errors import ConfigError, DataError


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the subcommand."""
    p = sub.add_parser(
        "identify",
        help="identify a linear model (DMDc, HAVOKc or white-box) from flight data",
        description="Resamples DATA (.parquet, .csv or PX4 .ulg) to --dt, holds out the first "
        "--test-span seconds for scoring, trains on the rest and writes a swingrt-model/1 "
        "JSON file.",
    )
    p.add_argument("data", metavar="DATA", help="flight log (.parquet, .csv, .ulg)")
    p.add_argument("--method", choices=("dmdc", "havokc", "whitebox"), help="method (default dmdc)")
    p.add_argument("--search", action="store_true", help="search q and p on the held-out span")
    p.add_argument(
        "--search-mode",
        choices=("refine", "exhaustive"),
        help="with --search: 'refine' (default: coarse grid with every low rank, then unit "
        "steps around several winners) or 'exhaustive' (every q = 2…80 and every p; slow)",
    )
    p.add_argument(
        "--select",
        choices=("control", "nmae"),
        help="with --search: 'control' (default) takes the lowest-NMAE candidate whose MPC "
        "passes a closed-loop step check on the white-box model of the same flight; 'nmae' "
        "the lowest NMAE alone",
    )
    p.add_argument("--axes", choices=("n", "ne"), default="n", help="North, or North + East")
    p.add_argument("--delays", type=int, metavar="Q", help="delay count q (default 20)")
    p.add_argument("--rank", type=int, metavar="P", help="SVD truncation rank p (default full)")
    p.add_argument(
        "--offset", choices=("none", "mean", "affine"), help="input offset (default affine)"
    )
    p.add_argument("--dt", type=float, help="model sample time [s] (default 0.03)")
    p.add_argument("--test-span", type=float, help="held-out span [s] (default 40)")
    p.add_argument("--smooth", action="store_true", help="smooth states and inputs (4.6.6)")
    p.add_argument(
        "--payload-mass",
        type=float,
        metavar="KG",
        help="white-box payload mass (default: RLS on the log's thrust column)",
    )
    p.add_argument(
        "--vehicle-mass",
        type=float,
        metavar="KG",
        help="white-box vehicle mass (default: the --twin scenario's, else the built-in 0.952)",
    )
    p.add_argument(
        "--cable-length",
        type=float,
        metavar="M",
        help="white-box cable length (default: from the swing's answer to the vehicle's motion)",
    )
    g = p.add_argument_group(
        "ULog swing sensor",
        "where a PX4 .ulg holds the swing angles, and their linear calibration "
        "(angle = scale · raw + offset); default: debug_vect rows named SWING, x = north, y = east",
    )
    g.add_argument(
        "--ulog-swing-topic",
        metavar="TOPIC",
        help="uORB topic (default debug_vect); adc_report: a cable sensor on the airframe, "
        "its channels and calibration from the --twin scenario's [sensors.body]",
    )
    g.add_argument(
        "--ulog-swing-name", metavar="NAME", help="debug_vect row name to keep (default SWING)"
    )
    g.add_argument(
        "--ulog-swing-fields",
        metavar="N,E",
        help="fields holding the north and east swing (default x,y)",
    )
    g.add_argument("--ulog-swing-scale", type=float, metavar="S", help="rad per raw unit (1)")
    g.add_argument("--ulog-swing-offset", type=float, metavar="RAD", help="offset [rad] (0)")
    p.add_argument("--plots", metavar="DIR", help="write diagnostic plots into DIR")
    p.add_argument(
        "--twin",
        metavar="SCENARIO",
        default="builtin",
        help="with --select control: also fly each candidate's MPC on swingrt's simulator of "
        "this vehicle (a scenario TOML: airframe and PX4 gains, e.g. from swingrt vehicle) "
        "carrying the white-box payload, and take only models that settle there; default "
        "'builtin', the built-in vehicle at --vehicle-mass, under the PX4 gains a ULog's "
        "parameters give (what a twin adds is PX4's cascade and its lag more than the "
        "exact airframe); 'none' flies no twin",
    )
    p.add_argument(
        "--sweep",
        choices=("length", "dt", "noise"),
        help="also sweep training length (4.6.8), sample time (4.6.4) or sensor noise on/off "
        "(4.6.6): table on stdout, CSV and plot into --plots DIR",
    )
    p.add_argument("-o", "--output", default="model.json", help="model file (.json)")
    return p


def run(args) -> int:
    """Run the subcommand."""
    from swingrt import sysid
    from swingrt.experiments.notes import swing_drag_note
    from swingrt.io import load_flight
    from swingrt.reports import plot_pareto

    settings = dict(
        method=args.method,
        offset=args.offset,
        dt=args.dt,
        test_span=args.test_span,
        smooth=args.smooth,
        search=args.search,
        search_mode=args.search_mode,
        select=args.select,
        delays=args.delays,
        rank=args.rank,
        payload_mass=args.payload_mass,
        vehicle_mass=args.vehicle_mass,
        cable_length=args.cable_length,
    )
    # The vehicle's description, read before the search: a bad file fails at once.
    described = None
    if args.twin not in ("none", "builtin"):
        from swingrt.scenario import resolve

        described = resolve(args.twin, default="step")
        if settings["vehicle_mass"] is None:
            # The vehicle's description weighs it for the white-box.
            settings["vehicle_mass"] = float(described.to_dict()["vehicle"]["mass"])
    # "builtin" is weighed at the identification's vehicle mass (sysid.builtin_twin).
    twin = {"none": None, "builtin": "builtin"}.get(args.twin, described)
    with options_named():
        checked = sysid.identify_settings(**settings)
    if twin == "builtin" and str(args.data).endswith(".ulg"):
        # A ULog names the PX4 gains the vehicle flew with: the twin flies them too.
        twin = sysid.builtin_twin(checked["vehicle_mass"], _logged_gains(args.data))
    ulog_swing = _ulog_swing(args)
    body = None
    if described is not None and str(args.data).endswith(".ulg"):
        # The cable sensor on the airframe is part of the vehicle's description (read from
        # adc_report or from "SWBODY" rows).
        body = described.to_dict()["sensors"]["body"]
    data = load_flight(args.data, ulog_swing=ulog_swing, body=body)
    if described is not None:
        # PX4 logs its thrust normalised: the described vehicle's motors make it Newtons.
        data = sysid.with_thrust(data, described)
    result = None
    if args.search:
        search_opts = {k: v for k, v in checked.items() if k not in ("delays", "rank")}
        result = sysid.search(data, axes=args.axes, **search_opts)
        if checked["select"] == "control":
            result = sysid.select_for_control(data, result, axes=args.axes, twin=twin)
            cc = result.model.diagnostics["control_check"]
            law = (cc.get("law") or {}).get("kind", "mpc")
            if law != "mpc":
                verdict = f"no candidate's MPC passed; the {law} passed and flies"
            elif cc["passed"]:
                verdict = "passed"
            else:
                verdict = "no candidate passed; least violating kept"
            print(f"closed-loop check: {verdict} ({len(cc['checked'])} candidate(s) flown)")
            print(f"  checked on: {cc['plant']}")
            if cc.get("twin"):
                print(f"  and first on: {cc['twin']['plant']}")
            elif twin is not None:
                print("  twin not flown: no white-box payload to carry (model-only check)")
            choice = result.model.diagnostics.get("swing_drag_choice")
            if choice is not None:
                print(f"  {swing_drag_note(choice)}")
        model = result.model
    else:
        model = sysid.identify(data, axes=args.axes, **checked)
    model.save(args.output)
    nm = model.diagnostics.get("test_nmae")
    score = f"{nm:.4f}" if isinstance(nm, (int, float)) else "n/a"
    line = f"{model.method}: q = {model.delays}, p = {model.rank}, test NMAE {score}"
    wb = model.diagnostics.get("whitebox")
    if wb:
        lag = wb.get("attitude_lag")
        shown = "" if lag is None else f", attitude lag {lag:.3f} s"
        line += f" (m_p {wb['payload_mass']:.3f} kg, l {wb['length']:.3f} m{shown})"
    print(line)
    vib = model.diagnostics.get("swing_vibration")
    if vib and vib["cutoff"] < vib["given"]:
        print(
            f"IMU swing low-pass: {vib['cutoff']:.2f} Hz, not {vib['given']:g}: the log's "
            f"vibration passes {vib['noise_given_deg']:.2f}° of angle noise at "
            f"{vib['given']:g} Hz, {vib['noise_deg']:.2f}° at {vib['cutoff']:.2f}"
        )
    if args.plots:
        out = Path(args.plots)
        if result is not None:
            plot_pareto(result, out / "error_vs_delays.png")
            print(f"wrote {out / 'error_vs_delays.png'}")
    if args.sweep:
        _sweep(args, data, checked)
    print(f"wrote {args.output}")
    return 0


def _logged_gains(path) -> dict | None:
    """PX4's cascade gains in the ULog at ``path`` (:data:`swingrt.sysid.PX4_GAINS`; the
    built-in vehicle's where the log has no such parameter); ``None`` when the log holds no
    parameters at all (a log not written by PX4), whose reading fails later if it is no log."""
    from swingrt import _core, sysid
    from swingrt.hil.params import controller_from_px4
    from swingrt.io.px4_params import read_px4_parameters

    try:
        params = read_px4_parameters(path)
    except DataError:
        return None
    nominal = _core.Scenario.builtin("step").to_dict()["controller"]
    controller, _ = controller_from_px4(params, nominal)
    return {k: controller[k] for k in sysid.PX4_GAINS}


def _ulog_swing(args) -> dict | None:
    """The ``ulog_swing`` mapping of the --ulog-swing-* options, or None (the default)."""
    out: dict = {}
    if args.ulog_swing_topic is not None:
        out["topic"] = args.ulog_swing_topic
    if args.ulog_swing_name is not None:
        out["name"] = args.ulog_swing_name
    if args.ulog_swing_fields is not None:
        parts = [f.strip() for f in args.ulog_swing_fields.split(",")]
        if len(parts) != 2 or not all(parts):
            raise ConfigError(
                f"--ulog-swing-fields: expected N,E (two field names), not "
                f"{args.ulog_swing_fields!r}",
                field="ulog_swing_fields",
            )
        out["n"], out["e"] = parts
    if args.ulog_swing_scale is not None:
        out["scale"] = args.ulog_swing_scale
    if args.ulog_swing_offset is not None:
        out["offset"] = args.ulog_swing_offset
    if out and not args.data.lower().endswith(".ulg"):
        raise ConfigError("--ulog-swing-*: apply to a .ulg log only", field="ulog_swing")
    return out or None


def _sweep(args, data, common) -> None:
    """Run the chosen sweep, print its table, write CSV and plot (atomic)."""
    import numpy as np

    from swingrt import sysid
    from swingrt.io.atomic import write_text_atomic
    from swingrt.reports import csv_text, plot_sample_time, plot_training_length

    out = Path(args.plots or ".")
    t = np.asarray(data["t"], dtype=float)
    avail = float(t[-1] - t[0]) - common["test_span"]
    lengths = [float(x) for x in np.arange(20.0, avail + 1e-9, 20.0)]
    if not lengths:
        raise ConfigError(f"--sweep: the flight leaves only {avail:.0f} s after the test span")
    kw = {k: v for k, v in common.items() if k in ("method", "offset", "test_span")}
    kw["axes"] = args.axes
    if args.sweep == "length":
        rows = sysid.sweep_training_length(data, lengths, dt=common["dt"], **kw)
        plot_training_length(rows, out / "error_vs_training_length.png")
    elif args.sweep == "noise":
        kw.pop("method", None)
        rows = sysid.sweep_noise(data, lengths, method=common["method"], dt=common["dt"], **kw)
        plot_training_length(rows, out / "error_vs_training_length_noise.png")
    else:
        rows = sysid.sweep_sample_time(data, [0.01, 0.02, 0.03, 0.05, 0.08, 0.1], **kw)
        plot_sample_time(rows, out / "error_vs_sample_time.png")
    keys = list(rows[0]) if rows else []
    text = csv_text(rows, keys)
    write_text_atomic(out / f"sweep_{args.sweep}.csv", text)
    print(text.replace(",", "\t"), end="")
    print(f"wrote {out / f'sweep_{args.sweep}.csv'}")
