"""``swingrt run --px4 DIR``: the main job on real PX4 firmware with swingrt's physics.

As ``swingrt run`` on the built-in simulator, with PX4 in the loop of every flight:

1. training flight: PX4 SITL + ``swingrt hil`` (its own process), take-off, then the
   table-4.1 random velocity steps through PX4's offboard *velocity* setpoints (PX4's velocity
   PID flies them); PX4 is shut down and its ULog kept;
2. identification from **PX4's own ULog** (the OFFBOARD stretch of it), with the search and
   the closed-loop check of ``swingrt identify --search``;
3. a fresh PX4 session flies the default 2 m/s North step twice: PX4's velocity control (the
   PID baseline) and the MPC on the identified model (acceleration setpoints);
4. the report folder: ``metrics.csv`` / ``metrics.md`` with the columns of ``swingrt run``,
   one Parquet trace per controller (the offboard node's view, named as ``swingrt run``
   names them), the physics traces, the figures, the model and both PX4 ULogs.
"""

from __future__ import annotations

import math
import shutil
import sys
import time
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from swingrt.errors import ConfigError, FlightAbort

__all__ = ["run_on_px4", "STEP_MISSION", "fly_offboard", "judge_on_truth"]

#: The evaluation flight: hover 2 s, 2 m/s North for 18 s, back to 0 for 10 s, as
#: (t, vn, ve) steps; the metrics count from the first step to the second.
STEP_MISSION: list[tuple[float, float, float]] = [
    (0.0, 0.0, 0.0),
    (2.0, 2.0, 0.0),
    (20.0, 0.0, 0.0),
]
#: Length of the evaluation flight [s].
STEP_DURATION = 30.0
#: Time of the return step (the end of the metrics window) [s].
STEP_END = 20.0
#: Wall seconds to let the payload settle in PX4's hold between two flights.
SETTLE_S = 12.0
#: The offboard node's swing watchdog on PX4 [deg]: the last resort of every flight.
SWING_LIMIT_DEG = 30.0


def _say(quiet: bool, text: str) -> None:
    if not quiet:
        print(text, file=sys.stderr, flush=True)


def run_on_px4(
    px4_dir,
    out,
    *,
    seed: int = 0,
    instance: int = 0,
    training: float = 300.0,
    scenario=None,
    quiet: bool = False,
    twin: bool = True,
    swing_source: str = "sensor",
    airframe: str = "honeybee",
    methods: Sequence[str] = (),
) -> list[dict[str, Any]]:
    """Run the whole comparison on PX4 (module doc); returns the metrics rows. With
    ``twin`` the model selection flies each candidate first on the vehicle PX4's
    parameters describe, read from its own ULog (:func:`~swingrt.hil.params.vehicle_from_px4`,
    the mass it hovers at ``MPC_THR_HOVER``): what swingrt knows of a vehicle it has only
    the log of. ``swing_source = "imu"``: no sensor on the cable (the simulator sends PX4 no
    swing); the model is identified on the swing estimated from PX4's own IMU in its ULog,
    and every flight's node estimates it the same way from HIGHRES_IMU; the metrics read
    the simulator's true swing (every flight is judged on the physics trace's true swing,
    whatever its controller measured). ``airframe``: the built-in vehicle swingrt's physics flies
    under PX4 (its geometry, gains and hover thrust written to PX4's parameters).
    ``methods``: controllers of :mod:`swingrt.methods` trained on the same ULog and flown by
    the offboard node after the MPC in the same PX4 session (a method whose flight the node
    aborts, e.g. a tick over its period, gets a row that says why)."""
    from swingrt import sysid
    from swingrt.experiments.notes import swing_drag_note
    from swingrt.experiments.schema import Experiment
    from swingrt.hil.session import HilSession
    from swingrt.io import load_flight
    from swingrt.io.flight import Trace
    from swingrt.mavlink.offboard import (
        Mission,
        load_controller,
        model_body_sensor,
        model_swing_estimator,
    )
    from swingrt.mavlink.training import collect_over_mavlink, fly_velocity_mission
    from swingrt.metrics import step_metrics, swing_iae_floor
    from swingrt.reports import plot_pareto
    from swingrt.reports.plots import plot_case
    from swingrt.reports.tables import write_metrics

    if not (30.0 <= training < 86_400.0):
        raise ConfigError(f"--training must be 30 s or more, not {training}", field="training")
    if swing_source not in ("sensor", "body", "imu"):
        raise ConfigError(
            f"--swing-source: PX4 SITL flies 'sensor', 'body' or 'imu', not {swing_source!r}",
            field="swing_source",
        )
    from swingrt.hil.px4 import check_px4_dir
    from swingrt.methods import METHODS

    check_px4_dir(px4_dir)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise ConfigError(
            f"--methods: unknown {', '.join(unknown)} (one of {', '.join(METHODS)})",
            field="methods",
        )
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    node: dict[str, Any] = {}
    estimator = body = None
    if swing_source != "sensor" or airframe != "honeybee":
        if scenario is not None:
            raise ConfigError(
                "--swing-source and --airframe: the built-in scenario only", field="scenario"
            )
        from swingrt.io.atomic import write_text_atomic
        from swingrt.scenario import resolve

        scenario = out / "scenario.toml"
        text = f'[vehicle]\nairframe = "{airframe}"\n\n[sensors]\nswing = "{swing_source}"\n'
        sensors = resolve(tomllib.loads(text), default="hover").to_dict()["sensors"]
        write_text_atomic(scenario, text)
        if swing_source == "imu":
            estimator = sensors["estimator"]
            # Every flight's node estimates the swing from HIGHRES_IMU as the model expects.
            node["swing_estimator"] = estimator
        if swing_source == "body":
            # The cable sensor's counts reach PX4 (its log) and the node as DEBUG_VECT SWBODY.
            body = sensors["body"]
            node["body_sensor"] = body
    case = "default-step"
    echo = None if quiet else (lambda line: print(line, file=sys.stderr, flush=True))

    # 1. training flight on PX4
    _say(quiet, f"[ px4 ] training flight ({training:g} s of random velocity steps)")
    with HilSession(
        px4_dir,
        scenario=scenario,
        instance=instance,
        workdir=out / "px4-training",
        log=out / f"{case}__training_physics.parquet",
        seed=seed,
        echo=echo,
    ) as hil:
        collect_over_mavlink(
            hil.onboard_url,
            duration=training,
            seed=seed,
            out=out / f"{case}__node_training.parquet",
            **node,
        )
    if not hil.ulogs:
        raise ConfigError(f"PX4 wrote no ULog in {out / 'px4-training'}")
    ulog = out / "px4_training.ulg"
    shutil.copyfile(hil.ulogs[-1], ulog)
    summaries = [f"training session: {hil.summary}"]

    # 2. identification from PX4's own log
    _say(quiet, f"[ identification ] from PX4's ULog {ulog.name}")
    # The scenario fixes none of the estimator's settings (it is the built-in one), so the
    # log's own vibration chooses the low-pass (swingrt.io.vibration); the model carries it.
    data = load_flight(ulog, body=body)
    data.to_parquet(out / f"{case}__training.parquet")
    result = sysid.search(data)
    twin_sc = None
    check = None
    if twin:
        from swingrt.hil.params import vehicle_from_px4
        from swingrt.io.px4_params import read_px4_parameters

        # PX4's hover thrust holds the payload too: the twin's vehicle is the take-off
        # mass less the payload the white-box estimates, which the twin then carries.
        check = sysid.check_plant(data, result, settings=sysid.identify_settings(**result.settings))
        wb = check[0].diagnostics.get("whitebox")
        carried = float(wb["payload_mass"]) if isinstance(wb, dict) else None
        twin_sc, twin_notes = vehicle_from_px4(read_px4_parameters(ulog), payload=carried)
        summaries.append(
            "twin of the model selection: the vehicle of PX4's parameters in its ULog ("
            + "; ".join(twin_notes)
            + ")"
        )
    result = sysid.select_for_control(data, result, twin=twin_sc, check=check)
    model = result.model
    model.save(out / f"{case}__model.json")
    plot_pareto(result, out / f"{case}__error_vs_delays.png")
    controller, ts, axes = load_controller(out / f"{case}__model.json")
    trained = _train_methods(methods, data, model, scenario, twin_sc, summaries, quiet)

    # 3. PID (PX4's velocity control) and MPC on the same step, one PX4 session
    mission = Mission(list(STEP_MISSION), STEP_DURATION)
    traces: dict[str, Trace] = {}
    with HilSession(
        px4_dir,
        scenario=scenario,
        instance=instance,
        workdir=out / "px4-flights",
        log=out / f"{case}__flights_physics.parquet",
        seed=seed + 1,
        echo=echo,
    ) as hil:
        _say(quiet, "[ px4 ] pid: PX4's velocity control on the 2 m/s step")
        path = out / f"{case}__pid.parquet"
        fly_velocity_mission(hil.onboard_url, mission, out=path, **node)
        traces["pid"] = Trace.from_parquet(path)
        time.sleep(SETTLE_S)
        _say(quiet, "[ px4 ] mpc: the MPC on the model from PX4's log")
        path = out / f"{case}__mpc.parquet"
        why = fly_offboard(
            hil.onboard_url,
            controller,
            ts=ts,
            axes=axes,
            mission=mission,
            path=path,
            swing_estimator=model_swing_estimator(out / f"{case}__model.json"),
            body_sensor=model_body_sensor(out / f"{case}__model.json"),
        )
        if why is not None:
            raise FlightAbort(f"the MPC's flight on PX4: {why}")
        traces["mpc"] = Trace.from_parquet(path)
        aborted: dict[str, str] = {}
        for name, t in trained.items():
            time.sleep(SETTLE_S)
            _say(quiet, f"[ px4 ] {name}: trained on PX4's log, flown by the offboard node")
            path = out / f"{case}__{name}.parquet"
            why = _fly_method(hil.onboard_url, t, mission, path, node)
            if why is not None:
                aborted[name] = why
                summaries.append(f"{name}: the node aborted the flight ({why})")
            if path.exists():
                traces[name] = Trace.from_parquet(path)
    for p in hil.ulogs[-1:]:
        shutil.copyfile(p, out / "px4_flights.ulg")
    summaries.append(f"flight session: {hil.summary}")
    physics = Trace.from_parquet(out / f"{case}__flights_physics.parquet")
    for tr in traces.values():
        judge_on_truth(tr, physics)

    # 4. report
    rows = []
    notes = []
    t0 = 2.0
    for ctrl, tr in traces.items():
        m = step_metrics(tr, t0=t0, axis="n", t_end=STEP_END)
        rows.append({"scenario": case, "controller": ctrl, **m})
    floors = {c: swing_iae_floor(tr, t0=t0, axis="n", t_end=STEP_END) for c, tr in traces.items()}
    notes.append(
        "flown on PX4 SITL with swingrt's physics in the loop (`swingrt hil`); PID = PX4's "
        "own velocity control, MPC = swingrt's offboard node on acceleration setpoints"
    )
    notes.append(
        "swing IAE floor (any controller): " + ", ".join(f"{c} {v:.2f}" for c, v in floors.items())
    )
    nm = model.diagnostics.get("test_nmae")
    notes.append(
        f"model from PX4's ULog ({data.meta.get('segment', 'whole log')}): DMDc q = "
        f"{model.delays}, p = {model.rank}, test NMAE {float('nan') if nm is None else nm:.4f}"
        f"; swing source {model.diagnostics.get('swing_source', 'sensor')}"
    )
    choice = model.diagnostics.get("swing_drag_choice")
    if choice is not None:
        notes.append(swing_drag_note(choice))
    notes += summaries
    exp = Experiment(
        name="px4-default-step",
        description="PX4 SITL in the loop with swingrt's physics: 0.2 kg on 1 m, 2 m/s North "
        "step at t = 2 s after a random-step training flight flown by PX4's velocity control.",
        controllers=["pid", "mpc", *trained],
    )
    write_metrics(out, exp, rows, notes)
    plot_case(out / f"{case}.png", case, traces, "n")
    return rows


def _train_methods(methods, data, model, scenario, twin_sc, summaries, quiet) -> dict[str, Any]:
    """Train each of ``methods`` on PX4's training log as the campaigns do
    (:func:`swingrt.methods.train`): the DMDc model, the white-box estimate with the vehicle
    mass of its description (the scenario's), PX4's gains from the twin read from PX4's
    ULog (else the scenario's) and the twin for HAVOKc's selection."""
    if not methods:
        return {}
    from swingrt import sysid
    from swingrt.errors import DataError, IdentificationError
    from swingrt.methods import needs_whitebox
    from swingrt.methods import train as train_method
    from swingrt.scenario import resolve

    _say(quiet, f"[ identification ] methods {', '.join(methods)} from PX4's ULog")
    vehicle = resolve(scenario, default="hover")
    described = vehicle.to_dict()
    lqr = None
    try:
        # PX4 logs its thrust normalised; the vehicle's motors make it Newtons.
        wb = sysid.identify(
            sysid.with_thrust(data, vehicle),
            method="whitebox",
            vehicle_mass=float(described["vehicle"]["mass"]),
        )
        lqr = sysid.lqr_parameters(wb)
    except (DataError, IdentificationError) as exc:
        summaries.append(f"white-box not estimated ({exc}): methods that need it not flown")
    px4 = (twin_sc.to_dict() if twin_sc is not None else described)["controller"]
    trained = {}
    for name in methods:
        if lqr is None and needs_whitebox(name):
            continue
        t = train_method(name, data, model=model, whitebox=lqr, px4=px4, twin=twin_sc)
        summaries.append(
            f"{name}: trained in {t.ident_seconds:.2f} s on {t.training_seconds:.0f} s of flight"
        )
        trained[name] = t
    return trained


def fly_offboard(url: str, ctrl, *, ts: float, axes: int, mission, path, **node: Any) -> str | None:
    """Fly ``ctrl`` by the offboard node over ``url`` (a fresh link, the 30° swing
    watchdog, ``node``'s sensor options), logging to ``path``; the reason when the node
    aborted the flight, else None."""
    from swingrt.errors import FlightAbort
    from swingrt.mavlink.link import connect
    from swingrt.mavlink.offboard import Watchdog, fly

    conn = connect(url)
    try:
        fly(
            conn,
            ctrl,
            ts=ts,
            axes=axes,
            mission=mission,
            log_path=path,
            watchdog=Watchdog(ts, swing_limit=math.radians(SWING_LIMIT_DEG)),
            **node,
        )
    except FlightAbort as exc:
        return str(exc)
    finally:
        conn.close()
    return None


def _fly_method(url: str, trained, mission, path, node: dict[str, Any]) -> str | None:
    """Fly one trained method by the offboard node; the reason when the node aborted."""
    from swingrt.methods import controller

    ctrl = controller(trained)
    return fly_offboard(
        url, ctrl, ts=float(ctrl.period), axes=int(ctrl.axes), mission=mission, path=path, **node
    )


def judge_on_truth(node: Any, physics: Any) -> None:
    """Put the simulator's true swing into a node log's ``swing_true_*`` (what the metrics
    read), from the physics trace at the node's PX4 time (PX4's clock is the physics'
    clock under ``swingrt hil``): every flight is judged on the payload's own swing, not on
    what its controller measured (a cable sensor on the airframe composed with PX4's
    attitude estimate carries the estimate's error, about 1° here)."""
    import numpy as np

    at = np.asarray(node["px4_time_s"], dtype=float)
    t = np.asarray(physics["t"], dtype=float)
    for a in ("n", "e"):
        truth = np.interp(at, t, np.asarray(physics[f"swing_true_{a}"], dtype=float))
        node[f"swing_true_{a}"] = np.where(np.isfinite(at), truth, np.nan)
