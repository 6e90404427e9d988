"""One sample of a campaign, flown exactly as an experiment case is.

Training flight under PX4 PID → identification (:func:`~swingrt.experiments.identify_case`)
→ every controller on the evaluation step (:func:`~swingrt.experiments.simulate_controller`)
→ :func:`~swingrt.metrics.step_metrics`. This module runs on the Dask workers: it takes the
spec as plain data and returns plain rows.

**Failure.** A flight fails when any of these holds (:func:`failure_reason`):

- ``error``: the sample raised (identification or simulation error);
- ``fallback``: the MPC or LQR handed over to PX4 PID during the flight;
- ``diverged``: a metric is NaN, or the peak swing exceeds 60° (the simulator's payload
  left the useful range);
- ``v_not_settled``: the velocity never stayed within 5 % of the step (``v_settle_s`` = ∞);
- ``ss_error``: the steady-state velocity error is >= 0.02 m/s;
- ``swing``: (LQR, MPC, when PID is flown too) the swing IAE's excess above its floor
  (:func:`~swingrt.metrics.swing_iae_floor`, what no controller can remove) is >= 0.4× PID's
  excess in the same sample and >= 1 deg·s: the controller does not damp the swing.

PX4 PID is flown as the reference; it is held to the rules but the last.

A mission campaign (``[base.mission]``) flies the sample's random plan instead of the step:
``pid`` is PX4's mission mode, ``mpc`` the position MPC along legs shaped against the model's
swing (:func:`swingrt.mission.shaped_legs`); the rows carry the mission's summary
(:data:`swingrt.mission.SUMMARY_COLUMNS`) and fail by :func:`swingrt.mission.mission_failure`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from swingrt.errors import ConfigError, IdentificationError
from swingrt.methods import METHODS
from swingrt.metrics import METRICS, step_metrics

#: ss_error at or above which a flight fails [m/s].
SS_ERROR_LIMIT = 0.02
#: Peak swing above which a flight counts as diverged [deg].
DIVERGED_SWING_DEG = 60.0
#: Swing IAE excess, as a fraction of PID's, at or above which a flight fails.
SWING_EXCESS_RATIO = 0.4
#: ... unless the excess is below this [deg·s].
SWING_EXCESS_MIN = 1.0

#: Identification columns of a row.
IDENT_COLUMNS = (
    "q",
    "p",
    "test_nmae",
    "control_check_passed",
    "law",
    "wb_payload_mass",
    "wb_length",
    "wb_attitude_lag",
    "spillover",
)
#: The swing IAE's excess above its momentum floor (a ``metrics.csv`` column).
EXCESS = "swing_excess_iae_deg_s"
#: The swing IAE excess over PID's in the same sample (NaN when PID is not flown).
RATIO = "swing_excess_vs_pid"


def metric_columns(mission: bool = False) -> tuple[str, ...]:
    """Every metric column: ``metrics.csv``'s, then the excess relative to PID's; for a
    mission campaign the mission's summary columns."""
    if mission:
        from swingrt.mission import SUMMARY_COLUMNS

        return SUMMARY_COLUMNS
    return (*METRICS, RATIO)


def _cell(v: Any) -> Any:
    """One column value: numbers as float (so a grid of 0 and 0.5 is one column type),
    booleans and strings as they are, anything else as its repr."""
    if isinstance(v, (bool, str)) or v is None:
        return v
    if isinstance(v, (int, float)):
        return float(v)
    return repr(v)


def param_columns(values: dict[str, Any]) -> dict[str, Any]:
    """Flatten sampled values into columns: vectors ``key[i]``, numbers as float, strings
    and booleans as they are."""
    out: dict[str, Any] = {}
    for k, v in values.items():
        if isinstance(v, list):
            for i, x in enumerate(v):
                out[f"{k}[{i}]"] = _cell(x)
        else:
            out[k] = _cell(v)
    return out


def _attitude_lag(whitebox: Any) -> float | None:
    """The attitude lag [s] the white-box read from the training flight, if it told one."""
    lag = whitebox.diagnostics.get("whitebox", {}).get("attitude_lag")
    return None if lag is None else float(lag)


def _fatal(exc: BaseException) -> bool:
    """Whether an exception must stop the campaign rather than become an error row (a Rust
    panic surfaces as a BaseException and is a row)."""
    return isinstance(exc, (KeyboardInterrupt, SystemExit, GeneratorExit, MemoryError))


def failure_reason(row: dict[str, Any]) -> str:
    """Why a row's flight failed ('' when it did not); see the module docs."""
    if row.get("error"):
        return "error"
    if row.get("fallback"):
        return "fallback"
    vals = [row.get(m) for m in METRICS]
    if any(isinstance(v, float) and math.isnan(v) for v in vals) or (
        row.get("peak_swing_deg", 0.0) > DIVERGED_SWING_DEG
    ):
        return "diverged"
    if math.isinf(row.get("v_settle_s", 0.0)):
        return "v_not_settled"
    if row.get("ss_error", 0.0) >= SS_ERROR_LIMIT:
        return "ss_error"
    ratio = row.get(RATIO, math.nan)
    if (
        row.get("controller") != "pid"
        and ratio is not None
        and ratio >= SWING_EXCESS_RATIO
        and row.get(EXCESS, 0.0) >= SWING_EXCESS_MIN
    ):
        return "swing"
    return ""


@dataclass
class _Prepared:
    """A sample made ready to fly its evaluation: drawn, trained and identified (or the
    error that stopped it)."""

    spec: Any
    index: int
    common: dict[str, Any]
    ident: dict[str, Any]
    exp: Any = None
    plan: Any = None
    train_sc: Any = None
    train: Any = None
    model: Any = None
    lqr: Any = None
    trained: dict[str, Any] = field(default_factory=dict)
    setup_error: str = ""
    ident_error: str = ""
    method_errors: dict[str, str] = field(default_factory=dict)


def _prepare(raw: dict[str, Any], index: int, out: Path | None) -> _Prepared:
    """Draw sample ``index``, fly its training flight and identify it; with ``out``, write
    the training trace and the models there."""
    from swingrt.campaign.spec import parse_spec
    from swingrt.experiments import (
        evaluation_scenario,
        identify_case,
        train_methods,
        training_scenario,
        without_whitebox,
    )
    from swingrt.sim import _run

    spec = parse_spec(raw)
    values = spec.draw(index)
    seed = spec.flight_seed(index)
    s = _Prepared(
        spec,
        index,
        {"sample": index, "flight_seed": seed, **param_columns(values)},
        {c: None for c in IDENT_COLUMNS},
    )
    try:
        s.exp = spec.experiment(values, label=f"{spec.name} #{index}")
        s.plan = spec.mission(values, index)
        s.train_sc = training_scenario(s.exp, {}, seed)
        # A broken evaluation stops the sample before it trains, as a broken training does.
        evaluation_scenario(s.exp, {}, seed + 1, s.train_sc)
    except BaseException as exc:  # a broken sample is a result, not a crash
        if _fatal(exc):
            raise
        s.setup_error = f"{type(exc).__name__}: {exc}"
        return s
    try:
        s.train = _run(s.train_sc, False, "collect")
        plots = None if out is None else out / "error_vs_delays.png"
        s.model, wb, s.lqr = identify_case(s.train, s.exp, plots, vehicle=s.train_sc)
        cc = s.model.diagnostics.get("control_check")
        s.ident = {
            "q": int(s.model.delays),
            "p": int(s.model.rank),
            "test_nmae": float(s.model.diagnostics.get("test_nmae", math.nan)),
            "control_check_passed": None if cc is None else bool(cc.get("passed", True)),
            # What the model flies as `mpc` (design::law): its MPC, or the fallback law.
            "law": None if cc is None else (cc.get("law") or {}).get("kind", "mpc"),
            "wb_payload_mass": None if s.lqr is None else s.lqr["m_p"],
            "wb_length": None if s.lqr is None else s.lqr["l"],
            "wb_attitude_lag": None if wb is None else _attitude_lag(wb),
            "spillover": _spillover(cc),
        }
        if out is not None:
            s.train.to_parquet(out / "training.parquet")
            s.model.save(out / "model.json")
            if wb is not None:
                wb.save(out / "whitebox.json")
    except BaseException as exc:  # PID still flies without a model
        if _fatal(exc):
            raise
        s.ident_error = f"{type(exc).__name__}: {exc}"
        return s
    # Without a white-box estimate the LQR and the methods trained on it do not fly; their
    # rows say why and the rest fly as usual.
    s.method_errors.update(without_whitebox(s.exp, s.model, s.lqr))
    for ctrl in spec.controllers:
        if ctrl not in METHODS or ctrl in s.method_errors:
            continue
        try:
            s.trained.update(
                train_methods(s.train, s.exp.with_controllers([ctrl]), s.model, s.lqr, s.train_sc)
            )
        except BaseException as exc:  # one method failing to train is its row's error
            if _fatal(exc):
                raise
            s.method_errors[ctrl] = f"{type(exc).__name__}: {exc}"
    return s


def _spillover(cc: dict[str, Any] | None) -> str | None:
    """What the selection's second link (``control_check.spillover``) did to the pick:
    ``"kept"`` (flown as chosen) or ``"smoothed"``; None where no second link was flown."""
    report = None if cc is None else cc.get("spillover")
    if report is None:
        return None
    return "smoothed" if report.get("smoothed") else "kept"


def _fly_evaluation(
    s: _Prepared, seed: int, traces: dict[str, Any], out: Path | None
) -> list[dict[str, Any]]:
    """Every controller of the sample on its evaluation flight with noise seed ``seed``,
    judged against PX4 PID's flight of the same seed; one row per controller."""
    from swingrt.experiments import evaluation_scenario, simulate_controller

    nan_metrics = {m: math.nan for m in metric_columns(s.spec.is_mission)}
    ev_sc = None
    setup_error = s.setup_error
    if not setup_error:
        try:
            ev_sc = evaluation_scenario(s.exp, {}, seed, s.train_sc)
        except BaseException as exc:  # as in _prepare
            if _fatal(exc):
                raise
            setup_error = f"{type(exc).__name__}: {exc}"
    rows = []
    for ctrl in s.spec.controllers:
        row: dict[str, Any] = {
            **s.common,
            "controller": ctrl,
            **s.ident,
            "fallback": "",
            "error": "",
            "training_s": math.nan,
        }
        blocked = (
            setup_error or (s.ident_error if ctrl != "pid" else "") or s.method_errors.get(ctrl, "")
        )
        if blocked:
            rows.append({**row, **nan_metrics, "error": blocked})
            continue
        if s.plan is not None:
            tracking = {"mpc": s.exp.mpc} if s.exp.mpc else None
            row.update(
                _fly_mission(s.plan, ctrl, ev_sc, seed, (s.model, s.lqr), tracking, traces, out)
            )
            rows.append(row)
            continue
        assert ev_sc is not None  # a failed evaluation setup blocked every row above
        try:
            trace, extras = simulate_controller(
                ev_sc,
                ctrl,
                axes=s.exp.axes,
                model=s.model,
                lqr_params=s.lqr,
                mpc_settings=s.exp.mpc or None,
                lqr_settings=s.exp.lqr or None,
                method=s.trained.get(ctrl),
                budget=s.exp.tick_budget,
            )
            axis = "ne" if s.exp.axes == "ne" else "n"
            m = step_metrics(trace, t0=s.exp.step["t"], axis=axis)
            row.update({c: float(m.get(c, math.nan)) for c in METRICS})
            row["fallback"] = str(extras.get("fallback") or "")
            row["training_s"] = _training_seconds(ctrl, s.trained, s.train)
            traces[ctrl] = trace
            if out is not None:
                trace.to_parquet(out / f"{ctrl}.parquet")
        except BaseException as exc:  # as above
            if _fatal(exc):
                raise
            row.update(nan_metrics)
            row["error"] = f"{type(exc).__name__}: {exc}"
        rows.append(row)
    pid = next((r for r in rows if r["controller"] == "pid"), None)
    if s.plan is not None:
        _judge_missions(rows, pid)
        return rows
    for row in rows:
        ref = math.nan if pid is None else pid.get(EXCESS, math.nan)
        row[RATIO] = row[EXCESS] / ref if ref and ref > 0 else math.nan
        row["failure"] = failure_reason(row)
    return rows


def fly_sample(
    raw: dict[str, Any], index: int, out: Path | None = None
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Fly sample ``index`` of the spec ``raw``; returns one row per controller and, with
    ``out``, writes the traces, models and figures there (``--rerun``)."""
    flown, traces = fly_noise_draws(raw, index, 1, out)
    return flown[0], traces


def fly_noise_draws(
    raw: dict[str, Any], index: int, draws: int, out: Path | None = None
) -> tuple[list[list[dict[str, Any]]], dict[str, Any]]:
    """Sample ``index`` trained and identified once, its evaluation flown on ``draws`` noise
    realisations (:meth:`~swingrt.campaign.spec.CampaignSpec.noise_seed`; draw 0 is the
    campaign's own flight): the rows of each draw, every controller judged against PX4
    PID's flight of the same draw, and draw 0's traces (with ``out``, a folder made if need
    be, written there with the training flight and the models, as :func:`fly_sample` does).
    Everything the spec draws (payload, wind, gust, noise levels) and the identified model
    stay; only the sensors' noise and the vibration's phase change. Tells a failure that is
    a coin at its bound from one the sample forces (``--rerun --draws``)."""
    if draws < 1:
        raise ConfigError(f"--draws: must be >= 1 (got {draws})", field="draws")
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    s = _prepare(raw, index, out)
    traces: dict[str, Any] = {}
    flown = [
        _fly_evaluation(
            s, s.spec.noise_seed(index, k), traces if k == 0 else {}, out if k == 0 else None
        )
        for k in range(draws)
    ]
    return flown, traces


def _fly_mission(
    plan: Any,
    ctrl: str,
    scenario: Any,
    seed: int,
    identified: tuple[Any, dict[str, float] | None],
    tracking: dict[str, Any] | None,
    traces: dict[str, Any],
    out: Path | None,
) -> dict[str, Any]:
    """Fly a mission sample's plan with ``ctrl`` (PX4's mission mode for ``pid``; on legs
    shaped against the identified model's swing, the position MPC with ``tracking`` settings
    for ``mpc`` and the LQR on the white-box pendulum for ``lqr``); ``identified`` is the
    (model, LQR pendulum or None); its summary columns, with the per-waypoint rows under
    ``_waypoints`` for :func:`_judge_missions`."""
    from swingrt import mission as ms
    from swingrt.io.flight import Trace

    model, lqr = identified
    try:
        if ctrl == "pid":
            trace, events = ms.fly(plan, "px4", scenario, seed=seed)
        elif ctrl == "lqr":
            if lqr is None:
                why = model.diagnostics.get("whitebox_skipped", "no white-box estimate")
                raise IdentificationError(f"lqr: {why}")
            trace, events = ms.fly(plan, ms.shaped_legs(model), scenario, seed=seed, lqr=lqr)
        else:
            legs = ms.shaped_legs(model)
            trace, events = ms.fly(plan, legs, scenario, seed=seed, model=model, tracking=tracking)
        rows = ms.waypoint_report(plan, trace, events)
        total = max(t for t, _, k in events if k == "completed")
        cols: dict[str, Any] = ms.summary(rows, total, trace)
        cols["fallback"] = "handed back to PX4" if np.any(trace.get("fallback", 0) > 0) else ""
        traces[ctrl] = Trace(trace, meta={"mission_events": [list(e) for e in events]})
        if out is not None:
            traces[ctrl].to_parquet(out / f"{ctrl}.parquet")
        return {**cols, "_waypoints": rows}
    except BaseException as exc:  # a mission that fails is its row's error
        if _fatal(exc):
            raise
        return {c: math.nan for c in metric_columns(True)} | {
            "error": f"{type(exc).__name__}: {exc}",
            "_waypoints": [],
        }


def _judge_missions(rows: list[dict[str, Any]], pid: dict[str, Any] | None) -> None:
    """Each mission row's ratios to PX4's own flight of the sample, and its failure."""
    from swingrt import mission as ms

    legs = {r["controller"]: r.pop("_waypoints", []) for r in rows}
    theirs = None if pid is None or pid.get("error") else pid
    for row in rows:
        ref = None if theirs is None else legs["pid"]
        row.update(ms.compare(row, legs[row["controller"]], theirs, ref))
        row["failure"] = ms.mission_failure(row, judged=row["controller"] != "pid")


#: Seconds of training flight a controller's design read (PID: none); wall-clock times
#: are kept out of the rows, which must not vary (``benches/methods.py`` measures them).
DATA_COLUMNS = ("training_s",)


def _training_seconds(ctrl: str, trained: dict[str, Any], train: Any) -> float:
    """Seconds of training flight ``ctrl`` read: a method's own count, the whole flight for
    the DMDc MPC and the white-box LQR, none for PID."""
    t = trained.get(ctrl)
    if t is not None:
        return float(t.training_seconds)
    if ctrl == "pid":
        return 0.0
    tt = train.columns["t"]
    return float(tt[-1] - tt[0])


def fly_batch(raw: dict[str, Any], indices: list[int]) -> tuple[list[dict[str, Any]], float]:
    """Fly the samples ``indices`` (one Dask task); the rows of all of them and the
    seconds the worker spent on them (kept out of the rows, which must not vary)."""
    import time

    t0 = time.perf_counter()
    rows: list[dict[str, Any]] = []
    for i in indices:
        rows.extend(fly_sample(raw, i)[0])
    return rows, time.perf_counter() - t0
