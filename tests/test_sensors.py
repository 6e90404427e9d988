"""The simulated IMU and the swing estimated from it, from Python: what a stock PX4 vehicle
measures of a payload it has no sensor on."""

from __future__ import annotations

import math

import numpy as np

import swingrt
from swingrt import _core


def test_hover_imu_reads_minus_g_and_the_estimate_follows_the_true_swing():
    # g·m_p/m_Q of the default rig (0.2 kg under 0.952 kg): the pull scale of the estimate.
    k = _core.GRAVITY * 0.2 / 0.952
    tr = swingrt.simulate(
        {"sensors": {"swing": "imu", "estimator": {"scale": k}}}, duration=20.0, seed=1
    )
    t = tr.t
    hover = t < 2.0
    # The turn-on bias (0.2 m/s² per axis) is the only offset at hover: the estimate tares it.
    flat = swingrt.simulate({"sensors": {"imu": {"accel_turn_on_bias": 0.0}}}, duration=2.0, seed=1)
    assert abs(np.mean(flat["imu_az"]) + _core.GRAVITY) < 0.02
    assert abs(np.mean(tr["imu_az"][hover]) + _core.GRAVITY) > 0.05
    # No sensor on the cable: the flight's swing columns are empty, the truth is logged.
    assert np.isnan(tr["swing_n"]).all()
    step = t > 2.0
    true, est = tr["swing_true_n"][step], tr["swing_est_n"][step]
    assert np.corrcoef(true, est)[0, 1] > 0.9
    assert abs(math.degrees(est.min()) / math.degrees(true.min()) - 1.0) < 0.25
    # A scale twice too large halves the swing it reports: the scale is the mass ratio's.
    tr2 = swingrt.simulate(
        {"sensors": {"swing": "imu", "estimator": {"scale": 2 * k}}}, duration=20.0, seed=1
    )
    ratio = tr2["swing_est_n"][step].min() / est.min()
    assert 0.4 < ratio < 0.75
