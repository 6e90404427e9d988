"""How well the swing estimated from the IMU alone follows the true swing, and what moves it.

Flies the default step (0.2 kg on 1 m, 2 m/s North at t = 2 s) under PX4's PID with the
swing source ``imu`` and prints, per case, the correlation of the estimate with the true
swing after the step, the ratio of their peaks, and the RMS error [deg]. The estimate's
scale is g·m_p/m_Q of the case (the calibrated one); the drag column says whether the
estimator removes the modelled airframe drag (0.5·ρ·C_Q/m_Q, quadratic in body x/y).

    python benches/imu_swing.py
"""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

import swingrt
from swingrt import _core

RHO = 1.225


def main() -> None:
    cases: list[tuple[str, dict[str, Any], dict[str, Any]]] = [
        ("default IMU (noise, bias, vibration)", {}, {}),
        ("ideal IMU", {"sensors_imu": "ideal"}, {}),
        ("vibration ×5", {"sensors_imu": {"vibration_accel": [10.0, 10.0, 20.0]}}, {}),
        ("PX4 accel LPF off", {"sensors_imu": {"accel_cutoff": 0.0}}, {}),
        ("steady wind 3 m/s N", {"wind": {"velocity": [3.0, 0.0, 0.0]}}, {}),
        ("turbulence 1 m/s", {"wind": {"turbulence": 1.0, "turbulence_time": 2.0}}, {}),
        ("light payload 0.05 kg", {"payload": {"mass": 0.05}}, {"mp": 0.05}),
        ("heavy vehicle 1.6 kg", {"vehicle": {"mass": 1.6}}, {"mq": 1.6}),
        (
            "double pendulum 0.2+0.1 kg, 1.5+0.5 m",
            {
                "payload": {
                    "kind": "double",
                    "mass": 0.2,
                    "length": 1.5,
                    "mass2": 0.1,
                    "length2": 0.5,
                }
            },
            {"mp": 0.3},
        ),
    ]
    print(f"{'case':40s} {'drag':>5s} {'corr':>6s} {'peak':>6s} {'rms°':>6s}", flush=True)
    for name, over, kw in cases:
        over = dict(over)
        imu = over.pop("sensors_imu", None)
        for drag in (False, True):
            r, peak, rms = run(dict(over), imu, drag, kw)
            print(f"{name:40s} {str(drag):>5s} {r:6.3f} {peak:6.2f} {rms:6.2f}", flush=True)


IDEAL = {
    "accel_noise_density": 0.0,
    "accel_random_walk": 0.0,
    "accel_turn_on_bias": 0.0,
    "gyro_noise_density": 0.0,
    "gyro_random_walk": 0.0,
    "gyro_turn_on_bias": 0.0,
    "vibration_accel": [0.0, 0.0, 0.0],
    "vibration_gyro": [0.0, 0.0, 0.0],
}


def run(
    cfg: dict[str, Any], imu: Any, drag: bool, kw: dict[str, float]
) -> tuple[float, float, float]:
    sensors_imu = IDEAL if imu == "ideal" else (imu or {})
    est: dict[str, Any] = {"scale": _core.GRAVITY * kw.get("mp", 0.2) / kw.get("mq", 0.952)}
    if drag:
        c = 0.5 * RHO * 0.096 / kw.get("mq", 0.952)
        est["drag_quadratic"] = [c, c]
    full = {"sensors": {"swing": "imu", "estimator": est, "imu": sensors_imu}, **cfg}
    tr = swingrt.simulate(full, duration=20.0, seed=1)
    keep = tr.t > 2.0
    true, e = tr["swing_true_n"][keep], tr["swing_est_n"][keep]
    r = float(np.corrcoef(true, e)[0, 1])
    i = int(np.argmax(abs(true)))
    rms = math.degrees(float(np.sqrt(np.mean((e - true) ** 2))))
    return r, float(e[i] / true[i]), rms


if __name__ == "__main__":
    sys.exit(main())
