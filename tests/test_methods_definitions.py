"""Each method pinned to its definition by an independent reference: SINDy recovers the
pendulum's equation of motion from a clean simulated flight, the NMPC plans the linear
MPC's inputs for a small step (with and without the attitude lag), and DeePC on
noise-free data of a linear plant flies the model-based MPC's input sequence. Seconds
each."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.linalg import expm

from swingrt import _core

G = _core.GRAVITY
DT = 0.03
# Vehicle + pendulum of the MPC tests: m_Q, m_p, cable l, joint friction c.
MQ, MP, L, C = 1.0, 0.3, 1.2, 0.01
# Cost shared by the MPCs compared here (the rest at the defaults they share).
COST = {"horizon": 40, "control_horizon": 10, "w_swing": 1.0}
W_V, W_SR, W_TH, W_DU = 1.0, 6.0, 1.0, 6.0


def _linearised(dt: float, force: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation of the vehicle + pendulum linearised about hanging
    still (thesis eq. 5.7 with friction), x = [v, θ, θ̇], u the acceleration command;
    ``force`` (an ẋ held over the tick) replaces the input column."""
    a = np.array(
        [
            [0.0, MP * G / MQ, C / (MQ * L)],
            [0.0, 0.0, 1.0],
            [0.0, -(MQ + MP) * G / (MQ * L), -(MQ + MP) * C / (MQ * MP * L * L)],
        ]
    )
    b = np.array([1.0, 0.0, -1.0 / L]) if force is None else force
    m = np.zeros((4, 4))
    m[:3, :3], m[:3, 3] = a, b
    e = expm(m * dt)
    return e[:3, :3], e[:3, 3]


def _with_lag(ad: np.ndarray, bd: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """The plant behind a first-order lag a⁺ = a + α(u − a) whose exact mean over the tick
    under a held u, u + s(a − u) with s = τα/Ts, drives the mechanics; state [v, θ, θ̇, a]."""
    al = 1.0 - math.exp(-DT / tau)
    share = tau * al / DT
    a = np.zeros((4, 4))
    a[:3, :3], a[:3, 3], a[3, 3] = ad, bd * share, 1 - al
    b = np.zeros(4)
    b[:3], b[3] = bd * (1 - share), al
    return a, b


def _condensed_mpc(ad, bd, x0, swing_prev, u_prev, ref, n=40, nc=10) -> np.ndarray:
    """The unconstrained linear MPC solved by least squares: over n ticks
    w_v (v_i − ref), w_s' (θ_i − θ_{i−2})/(2 Ts), w_θ θ_i, and w_Δu Δu over the nc moves,
    the last move held (states 0 and 1 are v and θ)."""
    x = np.asarray(x0, dtype=float)
    xu = np.zeros((len(x), nc))
    rows, rhs = [], []
    swings = [(np.zeros(nc), swing_prev), (np.zeros(nc), x[1])]
    gr = W_SR / (2 * DT)
    for i in range(n):
        x = ad @ x
        xu = ad @ xu
        xu[:, min(i, nc - 1)] += bd
        prev = swings[-2]
        rows += [W_V * xu[0], gr * (xu[1] - prev[0]), W_TH * xu[1]]
        rhs += [W_V * (x[0] - ref), gr * (x[1] - prev[1]), W_TH * x[1]]
        swings.append((xu[1].copy(), x[1]))
    for j in range(nc):
        row = np.zeros(nc)
        row[j] = W_DU
        if j:
            row[j - 1] = -W_DU
        rows.append(row)
        rhs.append(-W_DU * u_prev if j == 0 else 0.0)
    return -np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]


def _true_model(ad: np.ndarray, bd: np.ndarray) -> _core.LinearModel:
    """The exact discrete plant as a model the core MPC flies."""
    return _core.LinearModel.from_json(
        json.dumps(
            {
                "format": "swingrt-model/1",
                "method": "whitebox",
                "dt": DT,
                "delays": 1,
                "rank": 0,
                "states": ["vn", "swing_n", "swing_rate_n"],
                "inputs": ["acc_sp_n"],
                "offset": "none",
                "input_mean": [0.0],
                "A": ad.tolist(),
                "B": bd.reshape(3, 1).tolist(),
                "c": [0.0, 0.0, 0.0],
            }
        )
    )


def test_sindy_recovers_the_pendulum_equation_from_a_clean_flight():
    from swingrt.methods.sindy import fit_sindy
    from swingrt.scenario import Scenario
    from swingrt.sysid import _columns, resample

    length = 1.3
    sc = Scenario.builtin("training").with_overrides(
        {"duration": 60.0, "seed": 1, "payload": {"mass": 0.3, "length": length}}
    )
    sim = _core.Simulator(sc)
    sim.run_to_end()
    c = resample(_columns(sim.take_trace()), DT, ["vn", "swing_n", "swing_rate_n"])
    x = np.column_stack([c["vn"], c["swing_n"], c["swing_rate_n"]])
    acc = np.gradient(c["vn"], DT)  # the vehicle's acceleration: the cable's hanging point
    k = int(20.0 / DT)
    m = fit_sindy(x[k:], acc[k:], x[:k], acc[:k], DT)  # the default candidates and choice
    # A pendulum hanging from a point accelerating at a: θ̈ = −(g/l) sin θ − (a/l) cos θ,
    # linearised θ̈ = −(g/l) θ − a/l; and v̇ = a, θ̇ = θ̇.
    assert m.coefficient(2, "s") == pytest.approx(-G / length, rel=0.03)
    assert m.coefficient(2, "u") == pytest.approx(-1.0 / length, rel=0.03)
    assert m.coefficient(0, "u") == pytest.approx(1.0, rel=0.01)
    assert m.coefficient(1, "w") == pytest.approx(1.0, rel=0.01)
    # Every other term (payload drag, joint friction, the cable's stretch, the expansion
    # of sin/cos) moves θ̈ by under 5 % of its range over the flight.
    z = np.column_stack([x, acc])
    feats = np.prod(z[:, None, :] ** m.powers[None, :, :], axis=2)
    terms = m.terms()
    keep = [terms.index("s"), terms.index("u")]
    rest = np.delete(feats * m.coefficients[2], keep, axis=1).sum(axis=1)
    thdd = feats @ m.coefficients[2]
    assert np.max(np.abs(rest)) < 0.05 * np.ptp(thdd)


def test_nmpc_plans_the_linear_mpcs_inputs_for_a_small_step():
    from swingrt.methods.nmpc import Nmpc, pendulum_dynamics

    ad, bd = _linearised(DT)
    x0 = np.array([[0.1, 0.02, -0.05]])  # 1° of swing: the nonlinear terms ~1e-4
    settings = {**COST, "acc_max": 1e3, "max_iter": 5}
    f = pendulum_dynamics(MQ, MP, L, C)
    # Without a lag: the core MPC on the exact discrete plant.
    mpc = _core.Mpc(_true_model(ad, bd), {**COST, "acc_max": 1e3, "measured_state": True})
    nmpc = Nmpc(f, settings, 1, lag=0.0)
    for c in (mpc, nmpc):
        c.reset(x0, [0.0])
        c.step(x0, [0.15])
    want = np.asarray(mpc.predicted_inputs()).reshape(-1)[:10]
    got = nmpc.predicted_inputs().reshape(-1)
    assert np.max(np.abs(got - want)) < 1e-3 * np.max(np.abs(want)), (got, want)
    # The same as the least-squares MPC by hand (the hand oracle is the core MPC's cost).
    by_hand = _condensed_mpc(ad, bd, x0[0], x0[0, 1], 0.0, 0.15)
    assert np.max(np.abs(by_hand - want)) < 1e-6 * np.max(np.abs(want))
    # With the attitude loop's lag: the linear MPC of the plant behind the lag.
    tau = 0.1
    nmpc = Nmpc(f, settings, 1, lag=tau)
    nmpc.reset(x0, [0.0])
    nmpc.step(x0, [0.15])
    got = nmpc.predicted_inputs().reshape(-1)
    al, bl = _with_lag(ad, bd, tau)
    want = _condensed_mpc(al, bl, np.r_[x0[0], 0.0], x0[0, 1], 0.0, 0.15)
    assert np.max(np.abs(got - want)) < 1e-3 * np.max(np.abs(want)), (got, want)
    # A lag left out (or twice as long) moves the plan by far more than the tolerance.
    for wrong in (by_hand, _condensed_mpc(*_with_lag(ad, bd, 2 * tau), np.r_[x0[0], 0.0],
                                          x0[0, 1], 0.0, 0.15)):  # fmt: skip
        assert np.max(np.abs(wrong - want)) > 0.05 * np.max(np.abs(want))


def test_nmpc_is_offset_free_for_steady_forces_on_vehicle_and_payload():
    from swingrt.methods.nmpc import Nmpc, pendulum_dynamics

    # Lagrange with a horizontal force F_v on the vehicle and F_p on the payload,
    # linearised: ẍ = u + F_v/m_Q + (m_p g/m_Q) θ and
    # θ̈ = −ẍ/l − (g/l) θ + F_p/(m_p l) (F_p leaves ẍ alone: the cable passes it on). In
    # steady flight the payload hangs at θ = F_p/(m_p g) and u = −(F_v + F_p)/m_Q. The
    # plant is the exact discretisation; the NMPC knows neither force.
    f_v, f_p = -0.3, 0.25  # [N]: drag on the vehicle, wind on the payload
    ad, bd = _linearised(DT)
    _, cd = _linearised(DT, np.array([f_v / MQ, 0.0, f_p / (MP * L) - f_v / (MQ * L)]))
    # Offset-free is where the loop ends up; the swing disturbance adapting as fast as the
    # velocity one (not a tenth, the default) gets there within the test's 15 s.
    settings = {"acc_max": 1e3, "kf_swing_disturbance_scale": 1.0}
    nmpc = Nmpc(pendulum_dynamics(MQ, MP, L, C), settings, 1, lag=0.0)
    x = np.zeros(3)
    nmpc.reset(x[None], [0.0])
    for _ in range(int(15.0 / DT)):
        u = float(nmpc.step(x[None], [1.0])[0])
        x = ad @ x + bd * u + cd
    assert abs(x[0] - 1.0) < 1e-3, x
    assert x[1] == pytest.approx(f_p / (MP * G), rel=0.01)
    assert u == pytest.approx(-(f_v + f_p) / MQ, rel=0.02)


def _linear_data(ad: np.ndarray, bd: np.ndarray, t: int, seed: int):
    """Noise-free outputs (v, θ) of the discrete plant under inputs held 3 ticks (with a
    little velocity feedback, so the data stay bounded): persistently exciting."""
    rng = np.random.default_rng(seed)
    x = np.zeros(3)
    u, y = np.zeros((t, 1)), np.zeros((t, 2))
    hold = 0.0
    for k in range(t):
        y[k] = x[:2]
        if k % 3 == 0:
            hold = rng.standard_normal() - 0.3 * x[0]
        u[k, 0] = hold
        x = ad @ x + bd * hold
    return u, y


def test_deepc_on_noise_free_linear_data_flies_the_model_based_mpcs_inputs():
    # The core's deepc.rs test compares one plan with a hand-condensed MPC after feeding
    # DeePC's window by hand; this one goes through the binding and flies the plant in
    # closed loop, DeePC and the core MPC on the exact model side by side.
    ad, bd = _linearised(DT)
    u, y = _linear_data(ad, bd, 1500, 3)
    u_test, y_test = _linear_data(ad, bd, 400, 4)
    regs = {"t_ini": 6, "lambda_g": 1e-9, "lambda_y": 1e9}
    deepc = _core.Controller.deepc(u, y, u_test, y_test, DT, {**COST, "acc_max": None, **regs})
    assert deepc.info()["fit"]["holdout_nmae"] < 1e-5
    mpc = _core.Mpc(_true_model(ad, bd), {**COST, "acc_max": 1e3, "measured_state": True})
    x = np.zeros(3)
    for c in (deepc, mpc):
        c.reset(x[None], [0.0])
    flown, planned = [], []
    for _ in range(40):
        flown.append(deepc.step(x[None], [1.0])[0])
        planned.append(mpc.step(x[None], [1.0])[0])
        x = ad @ x + bd * flown[-1]
    flown_a, planned_a = np.array(flown), np.array(planned)
    assert np.max(np.abs(flown_a - planned_a)) < 1e-4 * np.max(np.abs(planned_a))
    assert x[0] > 0.2  # the step was flown, not a trivial zero sequence


def _payload_p_decay(length: float, vel_p: float, seconds: float = 12.0) -> float:
    """Decay rate [1/s] of the swing under the core payload feedback when the cable hangs
    from a point that flies exactly the commanded velocity (held over each tick): the
    velocity change at a tick kicks θ̇ by −Δv cos θ / l, in between the pendulum swings
    freely (RK4). From 0.1 rad; the rate is the slope of log(peak swing) over time."""
    ctrl = _core.Controller.payload_p(length, 1, {"vel_p": vel_p, "wp_pos_p": 0.0})
    dt, sub = ctrl.period, 10
    h = dt / sub
    th, w, v = 0.1, 0.0, 0.0
    ctrl.reset(np.array([[v, th, w]]), [0.0])

    def f(th: float, w: float) -> np.ndarray:
        return np.array([w, -(G / length) * math.sin(th)])

    swings = []
    for _ in range(int(seconds / dt)):
        swings.append(th)
        nv = float(ctrl.step(np.array([[v, th, w]]), [0.0])[0])
        w -= (nv - v) * math.cos(th) / length
        v = nv
        z = np.array([th, w])
        for _ in range(sub):
            k1 = f(*z)
            k2 = f(*(z + h / 2 * k1))
            k3 = f(*(z + h / 2 * k2))
            k4 = f(*(z + h * k3))
            z = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        th, w = float(z[0]), float(z[1])
    s = np.array(swings)
    peaks = [i for i in range(1, len(s) - 1) if s[i - 1] < s[i] >= s[i + 1] and s[i] > 0]
    assert len(peaks) >= 4
    return -float(np.polyfit(dt * np.array(peaks), np.log(s[peaks]), 1)[0])


@pytest.mark.parametrize(("length", "vel_p"), [(1.0, 0.1), (1.5, 0.2)])
def test_payload_p_damps_the_swing_at_the_closed_form_rate(length, vel_p):
    # ArduPilot's law moves the vehicle by v = −K_v a_p with the payload's acceleration
    # a_p = −g tan θ (payload North of the vehicle: it accelerates South, the vehicle goes
    # North). A hanging point that follows it exactly makes θ̈ + (K_v g / l) θ̇ + (g/l) θ = 0
    # (linearised): the swing decays at K_v g / (2 l), whatever ω. A flipped sign grows
    # instead, a lost g or a swing in degrees is off by an order of magnitude.
    assert _payload_p_decay(length, vel_p) == pytest.approx(vel_p * G / (2 * length), rel=0.05)
