"""The MPC flown without a swing sensor on the default step, against PX4 PID and the MPC
flown on the swing sensor (issue: no swing sensor).

Training: the random-step flight (``--training`` s). Two models are identified by DMDc with
the search: ``sensor`` (the swing column of the world-frame sensor) and ``imu`` (no swing
sensor: the swing output is the angle estimated from the IMU, ``swing_est_n``, put in the
swing column). Evaluation: the default step (0.2 kg on 1 m, 2 m/s North at t = 2 s) with
IMU noise, bias and vibration on, flown by PX4 PID, the MPC on the sensor, and the MPC on
the IMU estimate (``swing = "imu"``). Prints the step metrics; the acceptance asks for the
sensorless MPC's swing excess IAE ≤ 1/5 of PID's and ≤ 2× the sensor MPC's, and a residual
swing ≤ 1° from 4 s after the step.

    python benches/imu_mpc.py [--training 150] [--drag]
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

import swingrt
from swingrt import _core
from swingrt.experiments import simulate_controller
from swingrt.io.flight import Trace
from swingrt.metrics import step_metrics
from swingrt.scenario import Scenario
from swingrt.sysid import identify, search

RHO = 1.225


def estimator(drag: bool) -> dict[str, Any]:
    """The IMU swing estimate of the default rig (scale g·m_p/m_Q)."""
    mq = 0.952
    est: dict[str, Any] = {"scale": _core.GRAVITY * 0.2 / mq}
    if drag:
        c = 0.5 * RHO * 0.096 / mq
        est["drag_quadratic"] = [c, c]
    return est


def train(training: float, est: dict[str, Any]) -> tuple[dict[str, Any], dict[str, float]]:
    """The models identified from the random-step flight (seed 0): DMDc on the sensor and on
    the IMU estimate as the swing column, by name, and the white-box LQR parameters."""
    flight = swingrt.collect({"sensors": {"estimator": est}}, duration=training, seed=0)
    models = {"sensor": search(flight, axes="n").model}
    blind = Trace({k: np.asarray(flight[k]) for k in flight.columns}, dict(flight.meta))
    blind["swing_n"] = np.asarray(flight["swing_est_n"])
    blind["swing_e"] = np.asarray(flight["swing_est_e"])
    models["imu"] = search(blind, axes="n").model
    wb = identify(flight, method="whitebox", axes="n").diagnostics["whitebox"]
    lqr = {k: float(wb[w]) for k, w in (("m_q", "vehicle_mass"), ("m_p", "payload_mass"))}
    lqr["l"] = float(wb["length"])
    lqr["c"] = float(wb.get("friction", 0.0))
    return models, lqr


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--training", type=float, default=150.0)
    ap.add_argument("--drag", action="store_true", help="the estimator removes modelled drag")
    a = ap.parse_args()
    est = estimator(a.drag)
    models, lqr = train(a.training, est)
    for k, m in models.items():
        print(
            f"model {k}: q = {m.delays}, p = {m.rank}, test NMAE {m.diagnostics.get('test_nmae')}"
        )
    base = Scenario.builtin("step").with_overrides({"seed": 1})
    imu = base.with_overrides({"sensors": {"swing": "imu", "estimator": est}})
    runs = [
        ("pid (sensor)", base, "pid", None),
        ("mpc sensor model, sensor", base, "mpc", models["sensor"]),
        ("mpc sensor model, imu", imu, "mpc", models["sensor"]),
        ("mpc imu model, imu", imu, "mpc", models["imu"]),
        ("lqr, sensor", base, "lqr", None),
        ("lqr, imu", imu, "lqr", None),
    ]
    keys = ("swing_excess_iae_deg_s", "residual_swing_deg", "peak_swing_deg", "v_settle_s")
    print(f"{'run':28s} " + " ".join(f"{k:>22s}" for k in keys) + "  fallback")
    for name, sc, ctrl, model in runs:
        tr, extras = simulate_controller(sc, ctrl, axes="n", model=model, lqr_params=lqr)
        m = step_metrics(tr, t0=2.0, axis="n")
        print(
            f"{name:28s} " + " ".join(f"{m[k]:22.3f}" for k in keys) + f"  {extras.get('fallback')}"
        )


if __name__ == "__main__":
    main()
