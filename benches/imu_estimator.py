"""The IMU swing estimator's settings swept on the default step: which low-pass cutoff and
tare its defaults should have (issue: no swing sensor).

For each (cutoff, tare) of the grid, over IMU seeds (noise, turn-on bias and its drift drawn
per seed), the default step (0.2 kg on 1 m, 2 m/s North at t = 2 s) is flown on the IMU
estimate by the MPC (model identified from the sensor flight, as in ``imu_mpc.py``) and by
the white-box LQR (which also reads the swing rate, the estimate's filtered derivative),
and by PX4 PID to see the estimate itself: its RMS error against the true swing after the
step. Prints medians over the seeds of the swing excess IAE [deg·s] and the residual swing
from 4 s after the step [deg]; references: PX4 PID, and the MPC and LQR on the sensor.

    python benches/imu_estimator.py [--training 150] [--drag] [--seeds 3]
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from imu_mpc import estimator, train

from swingrt.experiments.controllers import simulate_controller
from swingrt.metrics import step_metrics
from swingrt.scenario import Scenario

CUTOFFS = (5.0, 10.0, 15.0, 20.0, 30.0, 40.0)
TARES = (0.5, 1.0, 1.5)


def fly(sc: Scenario, ctrl: str, model: Any, lqr: dict[str, float]) -> dict[str, float]:
    """Step metrics of one flight, plus the estimate's RMS error after the step [deg]."""
    tr, extras = simulate_controller(sc, ctrl, axes="n", model=model, lqr_params=lqr)
    m = step_metrics(tr, t0=2.0, axis="n")
    after = np.asarray(tr.t) > 2.0
    err = np.asarray(tr["swing_est_n"])[after] - np.asarray(tr["swing_true_n"])[after]
    m["est_rms_deg"] = float(np.degrees(np.sqrt(np.mean(err**2))))
    m["fell_back"] = float(extras.get("fallback") is not None)
    return m


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--training", type=float, default=150.0)
    ap.add_argument("--drag", action="store_true", help="the estimator removes modelled drag")
    ap.add_argument("--seeds", type=int, default=3, help="IMU seeds per setting (1, 2, ...)")
    a = ap.parse_args()
    est = estimator(a.drag)
    models, lqr = train(a.training, est)
    mpc = models["sensor"]
    seeds = range(1, a.seeds + 1)
    keys = ("swing_excess_iae_deg_s", "residual_swing_deg")

    def row(name: str, runs: list[dict[str, float]], extra: str = "") -> None:
        med = {k: float(np.median([r[k] for r in runs])) for k in (*keys, "est_rms_deg")}
        fb = int(sum(r["fell_back"] for r in runs))
        print(
            f"{name:34s} {med[keys[0]]:10.3f} {med[keys[1]]:10.3f} {med['est_rms_deg']:10.3f}"
            f" {fb:4d}{extra}"
        )

    print(f"drag removed: {a.drag}; medians over seeds {list(seeds)}")
    print(f"{'run':34s} {'excessIAE':>10s} {'residual':>10s} {'est RMS':>10s} {'fb':>4s}")
    for ctrl in ("pid", "mpc", "lqr"):
        runs = [
            fly(Scenario.builtin("step").with_overrides({"seed": s}), ctrl, mpc, lqr) for s in seeds
        ]
        row(f"{ctrl} on the sensor", runs)
    for tare in TARES:
        for cutoff in CUTOFFS:
            e = {**est, "cutoff": cutoff, "tare": tare}
            for ctrl in ("pid", "mpc", "lqr"):
                runs = [
                    fly(
                        Scenario.builtin("step").with_overrides(
                            {"seed": s, "sensors": {"swing": "imu", "estimator": e}}
                        ),
                        ctrl,
                        mpc,
                        lqr,
                    )
                    for s in seeds
                ]
                row(f"{ctrl} imu cutoff {cutoff:4.0f} Hz tare {tare} s", runs)


if __name__ == "__main__":
    main()
