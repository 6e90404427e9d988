"""Experiment runner: training flight → identification → PID / LQR / MPC on a step → report.

Writes to the output folder: ``metrics.csv`` (columns :data:`swingrt.reports.CSV_COLUMNS`),
``metrics.md``, one Parquet trace per run named ``<scenario>__<controller>.parquet``,
per-scenario PNG figures (velocity, swing angle and acceleration setpoint against time,
controllers overlaid, as the thesis's figures 5.11–5.22), the identified models, and for
the double pendulum the MPC's predicted trajectory at the step against the one flown
(figures 5.20–5.21).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Any

from swingrt.experiments.controllers import simulate_controller
from swingrt.experiments.identification import identify_case, train_methods, without_whitebox
from swingrt.experiments.notes import adaptation_note, compare_mpc_lqr, swing_drag_note
from swingrt.experiments.scenarios import (
    case_step,
    cases,
    evaluation_scenario,
    oracle_training_scenario,
    training_scenario,
)
from swingrt.experiments.schema import Experiment
from swingrt.io.flight import Trace
from swingrt.metrics import step_metrics, swing_iae_floor
from swingrt.reports import plot_case, plot_prediction, write_metrics
from swingrt.sysid import flies_measured_scale


class _Log:
    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.t0 = time.perf_counter()

    def __call__(self, msg: str) -> None:
        if not self.quiet:
            print(f"[{time.perf_counter() - self.t0:6.1f} s] {msg}", file=sys.stderr, flush=True)


def swing_scale_note(scale: dict[str, Any]) -> str:
    """What the report says of a model identified on the IMU's swing estimate: the scale
    measured from the training flight against the one the estimator assumed, and which the
    model flies (:func:`swingrt.sysid.flown_estimator`: the smaller), or why the
    measurement was refused (the assumed scale is flown then), and the drag read as swing
    it removes (``swing_core::sysid::swing_scale::DragRemoval``)."""
    fit = scale.get("fit")
    assumed = scale["assumed_scale"]
    if fit is None:
        return (
            f"swing from the IMU at the assumed scale {assumed:.3f} m/s²; not measured from "
            f"the flight: {scale['reason']}"
        )
    flown = "measured" if flies_measured_scale(scale) else "assumed"
    return (
        f"swing from the IMU at the {flown} scale: measured from the training flight "
        f"{scale['scale']:.3f} m/s² (g·m_p/m_Q, a pendulum of {fit['length']:.2f} m "
        f"explaining {100 * fit['explained']:.0f} % of the estimate), assumed {assumed:.3f} m/s²"
        + _drag_note(fit)
    )


def _drag_note(fit: dict[str, Any]) -> str:
    """The fit's drag terms the estimate flown loses, as the note says them."""
    removed = fit.get("drag_removed", "keep")
    if removed == "keep":
        return "; the drag it reads as swing is kept"
    terms = {"quadratic": "its quadratic drag", "all": "its drag"}[removed]
    return (
        f"; {terms} removed ({fit['drag_quadratic']:.4f} rad per (m/s)²"
        + (f", {fit['drag_linear']:.4f} rad per m/s" if removed == "all" else "")
        + ")"
    )


def run_experiment(
    exp: Experiment, out: str | os.PathLike, *, seed: int = 0, quiet: bool = False
) -> list[dict[str, Any]]:
    """Run every case and controller of ``exp`` and write the report into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    log = _Log(quiet)
    rows: list[dict[str, Any]] = []
    notes: list[str] = []
    all_cases = cases(exp)
    for i, (case, over) in enumerate(all_cases, 1):
        log(f"{exp.name} [{i}/{len(all_cases)}] {case}: training flight")
        train_sc = training_scenario(exp, over, seed)
        from swingrt.sim import _run

        train = _run(train_sc, False, "collect")
        log(f"{exp.name} [{i}/{len(all_cases)}] {case}: identification")
        model, wb, lqr = identify_case(
            train, exp, out / f"{case}__error_vs_delays.png", vehicle=train_sc
        )
        skipped = without_whitebox(exp, model, lqr)
        flown = [c for c in exp.controllers if c not in skipped]
        trained = train_methods(train, exp.with_controllers(flown), model, lqr, train_sc)
        notes += [f"{case} {c}: not flown ({why})" for c, why in skipped.items()]
        train.to_parquet(out / f"{case}__training.parquet")
        model.save(out / f"{case}__model.json")
        if wb is not None:
            wb.save(out / f"{case}__whitebox.json")
        ev_sc = evaluation_scenario(exp, over, seed + 1, train_sc, case=case)
        step = case_step(exp, case)
        oracle = None
        if "mpc_oracle" in exp.controllers:
            log(f"{exp.name} [{i}/{len(all_cases)}] {case}: oracle training flight")
            oracle_sc = oracle_training_scenario(exp, case, over, seed)
            oracle, _, _ = identify_case(_run(oracle_sc, False, "collect"), exp, vehicle=oracle_sc)
            oracle.save(out / f"{case}__oracle_model.json")
        traces: dict[str, Trace] = {}
        prediction = None
        for ctrl in flown:
            log(f"{exp.name} [{i}/{len(all_cases)}] {case}: {ctrl}")
            trace, extras = simulate_controller(
                ev_sc,
                ctrl,
                axes=exp.axes,
                model=oracle if ctrl == "mpc_oracle" else model,
                lqr_params=lqr,
                mpc_settings=exp.mpc or None,
                lqr_settings=exp.lqr or None,
                adaptive_settings=exp.adaptive or None,
                prediction_at=step["t"] if exp.prediction_figure else None,
                twin=train_sc,
                method=trained.get(ctrl),
                budget=exp.tick_budget,
            )
            if ctrl == "mpc_adaptive":
                notes.append(f"{case}: {adaptation_note(ev_sc, extras['events'])}")
            trace.to_parquet(out / f"{case}__{ctrl}.parquet")
            traces[ctrl] = trace
            axis = "ne" if exp.axes == "ne" else "n"
            m = step_metrics(trace, t0=step["t"], axis=axis)
            rows.append({"scenario": case, "controller": ctrl, **m})
            if extras.get("fallback"):
                notes.append(f"{case} {ctrl}: fell back to PX4 PID ({extras['fallback']})")
            if "prediction" in extras:
                prediction = extras["prediction"]
        floors = {
            c: swing_iae_floor(tr, t0=step["t"], axis="ne" if exp.axes == "ne" else "n")
            for c, tr in traces.items()
        }
        notes.append(
            f"{case}: swing IAE floor |∫(swing − final) dt| (the payload's Δv/g and drag, "
            "any controller; swing_excess_iae_deg_s is the IAE above it) "
            + ", ".join(f"{c} {floors[c]:.2f}" for c in traces)
            + " deg·s"
        )
        case_rows = {r["controller"]: r for r in rows if r["scenario"] == case}
        if "lqr" in case_rows and "mpc" in case_rows:
            notes.append(f"{case}: {compare_mpc_lqr(case_rows['mpc'], case_rows['lqr'])}")
        cc = model.diagnostics.get("control_check")
        if cc is not None and not cc.get("passed", True):
            notes.append(
                f"{case}: no searched model passed the closed-loop check; the least "
                "violating one was flown"
            )
        # An unscored model (test span shorter than the rollout) has test_nmae None.
        test_nmae = model.diagnostics.get("test_nmae")
        notes.append(
            f"{case}: DMDc q = {model.delays}, p = {model.rank}, "
            f"test NMAE {float('nan') if test_nmae is None else test_nmae:.4f}"
            + (f" ({len(cc['checked'])} candidate(s) flown in the closed-loop check)" if cc else "")
            + (
                f"; white-box m_p = {lqr['m_p']:.3f} kg, l = {lqr['l']:.3f} m"
                if lqr is not None
                else f"; {model.diagnostics['whitebox_skipped']}"
            )
        )
        scale = model.diagnostics.get("swing_scale")
        if scale is not None:
            notes.append(f"{case}: {swing_scale_note(scale)}")
        choice = model.diagnostics.get("swing_drag_choice")
        if choice is not None:
            notes.append(f"{case}: {swing_drag_note(choice)}")
        plot_case(out / f"{case}.png", case, traces, exp.axes)
        if prediction is not None and "mpc" in traces:
            plot_prediction(out / f"{case}__prediction.png", prediction, traces["mpc"], model)
    write_metrics(out, exp, rows, notes)
    log(f"{exp.name}: wrote {out}")
    return rows
