"""System identification through the built extension.

Synthetic tests use numpy-generated linear systems with closed-form answers; the
acceptance tests identify flights of swingrt's simulator (``swingrt.collect``) and predict
other flights.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

import swingrt
from swingrt import _core, sysid
from swingrt.errors import ConfigError, DataError, IdentificationError, ModelError
from swingrt.reports import plots

DT = 0.03


def _random_stable(rng, n, rho):
    a = rng.standard_normal((n, n))
    return a * (rho / max(abs(np.linalg.eigvals(a))))


def _linear_flight(seconds=120.0, seed=0, a=None, b=None, c=None):
    """A two-state, one-input linear system named like one axis of a flight."""
    rng = np.random.default_rng(seed)
    a = _random_stable(rng, 2, 0.95) if a is None else a
    b = rng.standard_normal((2, 1)) if b is None else b
    c = np.zeros(2) if c is None else c
    steps = int(round(seconds / DT))
    x = np.zeros((steps, 2))
    u = rng.standard_normal((steps, 1))
    for k in range(steps - 1):
        x[k + 1] = a @ x[k] + b @ u[k] + c
    cols = {
        "t": DT * np.arange(steps),
        "vn": x[:, 0],
        "swing_n": x[:, 1],
        "acc_sp_n": u[:, 0],
    }
    return cols, a, b


def _pendulum_flight(seconds=200.0, seed=0, mp=0.2, length=1.0, offset=0.1):
    """Vehicle + pendulum (eq. 5.7, stable sign) under a velocity P loop with random steps,
    sampled at 100 Hz, with a constant offset on the setpoint channel."""
    g, mq = 9.81, 0.952
    dt = 0.01
    a = np.array(
        [[0, 0, g * mp / mq], [0, -0.02, -g * (mq + mp) / (length * mq)], [0, 1, 0]], float
    )
    b = np.array([1.0, -1.0 / length, 0.0])
    rng = np.random.default_rng(seed)
    steps = int(seconds / dt)
    s = np.zeros(3)
    vref, change = 0.0, 0
    rows, us = [], []
    for k in range(steps):
        if k >= change:
            vref = rng.uniform(0, 3)
            change = k + int(rng.uniform(10, 25) / dt)
        acc = 1.8 * (vref - s[0])
        rows.append((s[0], s[2]))
        us.append(acc + offset)

        # RK4 of the continuous model under a held input.
        def f(z, acc=acc):
            return a @ z + b * acc

        k1 = f(s)
        k2 = f(s + 0.5 * dt * k1)
        k3 = f(s + 0.5 * dt * k2)
        k4 = f(s + dt * k3)
        s = s + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    x = np.array(rows)
    return {"t": dt * np.arange(steps), "vn": x[:, 0], "swing_n": x[:, 1], "acc_sp_n": np.array(us)}


# ----------------------------------------------------------------- synthetic systems


def test_dmdc_recovers_linear_system_exactly():
    cols, a, b = _linear_flight()
    m = sysid.identify(cols, delays=1, offset="none", test_span=40.0)
    assert m.method == "dmdc" and m.delays == 1 and m.rank == 3
    np.testing.assert_allclose(m.A, a, atol=1e-9)
    np.testing.assert_allclose(m.B, b, atol=1e-9)
    assert m.states == ["vn", "swing_n"] and m.inputs == ["acc_sp_n"]
    assert m.diagnostics["test_nmae"] < 1e-9


def test_a_model_that_passed_no_closed_loop_check_warns_whoever_flies_it():
    cols, _, _ = _linear_flight()
    m = sysid.identify(cols, delays=1, offset="none", test_span=40.0)
    assert sysid.unchecked_warning(m) is None
    assert sysid.unchecked_warning(m.with_diagnostics({"control_check": {"passed": True}})) is None
    pick = "none settled: the candidate that misses its bounds least"
    failed = m.with_diagnostics({"control_check": {"passed": False, "pick": pick}})
    text = sysid.unchecked_warning(failed)
    assert text is not None and text.startswith("warning:") and pick in text


def test_a_model_whose_selection_took_the_shaper_flies_it_wherever_it_is_loaded(tmp_path):
    """The law a selection records (``control_check.law``) is what every path that builds a
    controller from the model file builds: the offboard node's (``swingrt fly``, ``run
    --px4``) the same shaper, impulse for impulse, as one made by hand for that mode; a
    model that records none flies its MPC; a damaged record is refused by name."""
    from swingrt.mavlink.offboard import load_controller

    cols, _, _ = _linear_flight()
    m = sysid.identify(cols, delays=1, offset="none", test_span=40.0)
    mode = {"omega": 2.1, "zeta": 0.03}
    law = {"kind": "shaper", "mode": mode, "settings": {"kind": "zvd", "period": 0.02}}
    shaped = m.with_diagnostics({"control_check": {"passed": True, "law": law}})
    shaped.save(tmp_path / "shaped.json")
    ctrl, ts, axes = load_controller(tmp_path / "shaped.json")
    assert (ctrl.kind, ctrl.output, ts, axes) == ("shaper", "velocity", 0.02, 1)
    by_hand = _core.Controller.shaper(mode["omega"], mode["zeta"], 1, {"kind": "zvd"})
    state = np.zeros((1, 3))
    for c in (ctrl, by_hand):
        c.reset(state)
    out = [(ctrl.step(state, [1.0])[0], by_hand.step(state, [1.0])[0]) for _ in range(200)]
    # ZVD's first impulse is 1 / (1 + K)² with K = exp(-ζπ / √(1 - ζ²)); the step ends whole.
    k = math.exp(-mode["zeta"] * math.pi / math.sqrt(1 - mode["zeta"] ** 2))
    assert all(a == b for a, b in out), out[:3]
    assert math.isclose(out[0][0], 1 / (1 + k) ** 2) and math.isclose(out[-1][0], 1.0)
    m.with_diagnostics({"control_check": {"passed": True}}).save(tmp_path / "mpc.json")
    ctrl, ts, _ = load_controller(tmp_path / "mpc.json")
    assert type(ctrl).__name__ == "Mpc" and ts == m.dt
    bad = m.with_diagnostics({"control_check": {"passed": True, "law": {"kind": "pid"}}})
    bad.save(tmp_path / "bad.json")
    with pytest.raises(swingrt.errors.SwingrtError, match="control_check.law"):
        load_controller(tmp_path / "bad.json")


def test_affine_offset_learns_constant_and_mean_offset_subtracts_mean():
    c = np.array([0.02, -0.01])
    cols, a, b = _linear_flight(c=c, seed=3)
    m = sysid.identify(cols, delays=1, offset="affine")
    np.testing.assert_allclose(m.c, c, atol=1e-9)
    mm = sysid.identify(cols, delays=1, offset="mean")
    np.testing.assert_allclose(mm.input_mean, [cols["acc_sp_n"][int(40 / DT) :].mean()])
    assert np.all(mm.c == 0)


def test_havokc_reproduces_linear_system_and_forces_structure():
    cols, a, b = _linear_flight(seed=5)
    m = sysid.identify(cols, method="havokc", delays=3, offset="none")
    n = 2
    # Lower rows: exact delay shift (figure 4.4).
    lower = m.A[n:]
    expect = np.zeros_like(lower)
    expect[:, : 2 * n] = np.eye(2 * n)
    assert np.array_equal(lower, expect)
    assert np.all(m.B[n:] == 0)
    assert m.diagnostics["test_nmae"] < 1e-7


def test_search_on_pendulum_like_system_predicts_held_out_data():
    cols = _pendulum_flight(seed=1)
    res = sysid.search(cols, fine=None, delays=[2, 4, 8, 12, 16])
    sel = res.model.diagnostics["selected"]
    assert sel["stable"] is True
    assert res.model.spectral_radius <= 1.0 + 1e-3
    assert sel["nmae"] < 0.01
    # Same flight dynamics, another seed: still predicted well.
    other = _pendulum_flight(seed=2, seconds=100.0)
    score = sysid.evaluate(res.model, other)
    assert score["nmae"] < 0.02
    assert set(score["per_state"]) == {"vn", "swing_n"}
    # The table covers the grid and the error-vs-q curve falls from q = 2.
    curve = res.best_per_delay()
    assert curve[0]["delays"] == 2 and curve[0]["nmae"] > min(r["nmae"] for r in curve)


def test_whitebox_model_on_its_own_dynamics():
    cols = _pendulum_flight(seed=4, offset=0.0)
    m = sysid.identify(
        cols, method="whitebox", payload_mass=0.2, offset="none", friction=0.0, test_span=40.0
    )
    wb = m.diagnostics["whitebox"]
    # The closed loop pulls the swing frequency from eq. 4.8's free-floating value; the
    # FFT estimate is within the thesis's ~5 % class, and the model is stable.
    assert wb["frequency_hz"] > 0 and 0.8 < wb["length"] < 1.35
    assert m.delays == 2 and m.spectral_radius <= 1 + 1e-9


def test_whitebox_delay_form_matches_continuous_model_exactly():
    settings = {
        "method": "whitebox",
        "payload_mass": 0.3,
        "cable_length": 0.8,
        "dt": DT,
        "friction": 0.01,
        "offset": "none",
        "test_span": 0.0,
    }
    quiet = np.zeros((400, 2)), np.zeros((400, 1))
    model, _ = _core.identify(*quiet, ["vn", "swing_n"], ["acc_sp_n"], settings)
    import scipy.linalg  # noqa: PLC0415

    g, mq, mp, length, c = _core.GRAVITY, 0.952, 0.3, 0.8, 0.01
    a = np.array(
        [
            [0, c / (length * mq), g * mp / mq],
            [0, -c * (mq + mp) / (length**2 * mq * mp), -g * (mq + mp) / (length * mq)],
            [0, 1, 0],
        ]
    )
    b = np.array([[1.0], [-1.0 / length], [0.0]])
    aug = np.zeros((4, 4))
    aug[:3, :3], aug[:3, 3:] = a * DT, b * DT
    e = scipy.linalg.expm(aug)
    ad, bd = e[:3, :3], e[:3, 3:]
    rng = np.random.default_rng(0)
    u = rng.standard_normal(200)
    s = np.array([0.1, 0.2, -0.05])
    ys = []
    for k in range(200):
        ys.append((s[0], s[2]))
        s = ad @ s + bd[:, 0] * u[k]
    ys = np.array(ys)
    pred = model.predict(ys[:2], u[1:199, None])
    np.testing.assert_allclose(pred, ys[2:], atol=1e-9)


def test_fft_recovers_frequency_and_length():
    t = np.arange(0, 40, 0.01)
    f = 0.52
    sig = 0.1 * np.exp(-0.03 * t) * np.sin(2 * np.pi * f * t)
    est = _core.sysid_fft_peak(sig, 0.01, 0.1, 3.0)
    assert abs(est - f) / f < 0.005
    mq, mp, length = 0.952, 0.3, 1.0
    w = math.sqrt(_core.GRAVITY / length * (mq + mp) / mq)
    assert abs(_core.sysid_cable_length(w / 2 / math.pi, mq, mp) - length) < 1e-12


def test_link_modes_are_the_pinned_double_pendulum_s_and_bad_links_are_refused():
    # Independent reference: the linearised double pendulum on a fixed pivot, M θ'' + K θ = 0.
    g = _core.GRAVITY
    for l1, l2, mu in [(0.4, 0.78, 0.37), (1.0, 0.3, 2.0), (0.33, 0.7, 0.45)]:
        m1, m2 = 1.0, mu
        mass = np.array([[(m1 + m2) * l1**2, m2 * l1 * l2], [m2 * l1 * l2, m2 * l2**2]])
        stiff = np.diag([(m1 + m2) * g * l1, m2 * g * l2])
        omega = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(mass, stiff)).real))
        w1, w2, share = _core.sysid_link_modes(l1, l2, mu)
        np.testing.assert_allclose([w1, w2], omega, rtol=1e-12)
        assert share > 0.0
    # A vanishing lower mass under a longer upper link: the upper link swings as one
    # pendulum at √(g/l₁), and the faster mode (the lower link's own, √(g/l₂)) has no share
    # of its answer.
    w1, w2, share = _core.sysid_link_modes(1.0, 0.5, 1e-9)
    np.testing.assert_allclose([w1, w2], [math.sqrt(g / 1.0), math.sqrt(g / 0.5)], rtol=1e-6)
    assert share < 1e-6
    for bad in [(0.0, 0.5, 0.3), (0.5, -1.0, 0.3), (0.5, 0.5, math.nan)]:
        with pytest.raises(ConfigError, match="l1|l2|mu"):
            _core.sysid_link_modes(*bad)


def test_nmae_hand_computed():
    text = json.dumps(
        {
            "format": "swingrt-model/1",
            "method": "dmdc",
            "dt": 1.0,
            "delays": 1,
            "rank": 2,
            "states": ["vn"],
            "inputs": ["acc_sp_n"],
            "offset": "none",
            "input_mean": [0.0],
            "A": [[0.5]],
            "B": [[1.0]],
            "c": [0.0],
        }
    )
    model = sysid.LinearModel.from_json(text)
    data = {
        "t": np.arange(5.0),
        "vn": np.array([0.0, 1.0, 3.0, 2.0, 4.0]),
        "acc_sp_n": np.array([1.0, 2.0, 0.0, 1.0, 0.0]),
    }
    # Start 0 over 3 steps: predictions 1, 2.5, 1.25 → MAE 5/12, range 4 → 5/48.
    res = sysid.evaluate(model, data, rollout=3.0, starts=1)
    assert res["nmae"] == pytest.approx(5 / 48, abs=1e-15)
    assert res["per_state"]["vn"] == pytest.approx(5 / 48, abs=1e-15)


def test_predict_matches_numpy_rollout():
    cols = _pendulum_flight(seed=6, seconds=120.0)
    m = sysid.identify(cols, delays=6, rank=10)
    q = m.delays
    hist = np.column_stack([cols["vn"][:q], cols["swing_n"][:q]])
    u = np.linspace(-1, 1, 50)[:, None]
    pred = m.predict(hist, u)
    z = hist[::-1].reshape(-1)
    out = []
    for k in range(50):
        z = m.A @ z + m.B @ (u[k] - m.input_mean) + m.c
        out.append(z[:2])
    np.testing.assert_allclose(pred, np.array(out), rtol=1e-10, atol=1e-12)


# ----------------------------------------------------------------- model files


def test_json_round_trip_save_load(tmp_path):
    cols, _, _ = _linear_flight(seed=2)
    m = sysid.identify(cols, delays=4, rank=6)
    path = tmp_path / "m.json"
    m.save(path)
    d = json.loads(path.read_text())
    assert d["format"] == "swingrt-model/1"
    for key in (
        "method",
        "dt",
        "delays",
        "rank",
        "states",
        "inputs",
        "offset",
        "input_mean",
        "A",
        "B",
        "c",
        "fingerprint",
        "diagnostics",
    ):
        assert key in d
    assert d["fingerprint"].startswith("fnv1a64:")
    assert d["diagnostics"]["singular_values"]
    back = sysid.LinearModel.load(path)
    np.testing.assert_array_equal(back.A, m.A)
    np.testing.assert_array_equal(back.B, m.B)
    assert back.to_json() == m.to_json()
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]


def test_to_statespace():
    control = pytest.importorskip("control")
    cols, a, b = _linear_flight(seed=8)
    m = sysid.identify(cols, delays=2)
    ss = sysid.to_statespace(m)
    assert isinstance(ss, control.StateSpace)
    assert ss.dt == DT
    np.testing.assert_array_equal(ss.A, m.A)
    assert ss.noutputs == 2 and ss.ninputs == 1


@pytest.mark.parametrize(
    "mutate, needle",
    [
        (lambda d: d.update(A=[[1.0]]), "A has 1 rows"),
        (lambda d: d.update(c=[0.0]), "c has 1"),
        (lambda d: d.update(format="x"), "format"),
        (lambda d: d.update(offset="sideways"), "invalid model JSON"),
        (lambda d: d["B"][0].append(1.0), "B row 0"),
        (lambda d: d["diagnostics"].update(measurement_noise=-0.1), "measurement_noise"),
    ],
)
def test_bad_model_json_is_model_error(mutate, needle):
    cols, _, _ = _linear_flight(seed=2)
    d = json.loads(sysid.identify(cols, delays=2).to_json())
    mutate(d)
    with pytest.raises(ModelError, match=needle):
        sysid.LinearModel.from_json(json.dumps(d))


def test_model_json_nan_rejected():
    cols, _, _ = _linear_flight(seed=2)
    text = (
        sysid.identify(cols, delays=1)
        .to_json()
        .replace('"A": [\n    [\n      ', '"A": [[1e999, ', 1)
    )
    with pytest.raises(ModelError):
        sysid.LinearModel.from_json(text)


# ----------------------------------------------------------------- data errors


def test_resample_is_linear_and_checks_nan():
    t = np.array([0.0, 0.01, 0.025, 0.05, 0.08, 0.1])
    cols = {"t": t, "vn": 3 * t + 1}
    r = sysid.resample(cols, 0.02)
    np.testing.assert_allclose(r["t"], [0, 0.02, 0.04, 0.06, 0.08, 0.1])
    np.testing.assert_allclose(r["vn"], 3 * r["t"] + 1)
    bad = {"t": t, "vn": np.array([0, 1, np.nan, 2, 3, 4.0])}
    with pytest.raises(DataError, match=r"'vn'.*t = 0\.025"):
        sysid.resample(bad, 0.02)
    with pytest.raises(DataError, match="increasing"):
        sysid.resample({"t": t[::-1], "vn": t}, 0.02)
    with pytest.raises(ConfigError):
        sysid.resample(cols, -1.0)


def test_missing_column_and_short_data_are_data_errors():
    cols, _, _ = _linear_flight(seconds=60.0)
    no_swing = {k: v for k, v in cols.items() if k != "swing_n"}
    with pytest.raises(DataError, match="swing_n"):
        sysid.identify(no_swing)
    with pytest.raises(DataError, match="too few"):
        sysid.identify(cols, delays=400)
    with pytest.raises(DataError, match="test span"):
        sysid.identify(cols, test_span=100.0)
    with pytest.raises(ConfigError):
        sysid.identify(cols, offset="sideways")
    with pytest.raises(ConfigError):
        sysid.identify(cols, delays=2, rank=99)
    with pytest.raises(DataError):
        sysid.identify(["not", "a", "dict"])


def test_binding_checks_shapes_and_dtypes():
    x = np.zeros((100, 2))
    u = np.zeros((100, 1))
    fit = {"delays": 2, "test_span": 0.0}
    with pytest.raises(DataError, match="x must be a 2-D"):
        _core.identify(x.astype(np.float32), u, ["a", "b"], ["c"], fit)
    with pytest.raises(DataError, match="x must be a 2-D"):
        _core.identify(np.zeros(100), u, ["a", "b"], ["c"], fit)
    with pytest.raises(DataError, match="contiguous"):
        _core.identify(np.zeros((2, 100)).T, u, ["a", "b"], ["c"], fit)
    with pytest.raises(DataError, match="input samples"):
        _core.identify(x, np.zeros((99, 1)), ["a", "b"], ["c"], fit)


def test_no_stable_candidate_is_identification_error():
    # An exploding first-order system: every candidate is unstable or diverges (1.02 grows
    # 7× over the 3 s horizon, and is beyond the velocity integrator's tolerance too).
    steps = 4000
    rng = np.random.default_rng(1)
    u = rng.standard_normal(steps)
    v = np.zeros(steps)
    v[0] = 1e-3
    for k in range(steps - 1):
        v[k + 1] = 1.02 * v[k] + 0.01 * u[k]
    cols = {"t": DT * np.arange(steps), "vn": v, "swing_n": 0.5 * v + 1e-3 * u, "acc_sp_n": u}
    with pytest.raises(IdentificationError, match="no stable candidate"):
        sysid.search(cols, delays=[1, 2], rank_start=1, rank_step=1, fine=None, offset="none")


def _antidamped_swing_flight(seed, seconds=300.0, zeta=-0.02, noise=0.005):
    """A flight whose swing, open loop, grows slowly, as real flights identify it.

    The linearised vehicle + pendulum (v' = a + (m_p/m_Q)·g·θ, l·θ'' = −g(1 + m_p/m_Q)·θ
    − a − 2ζωl·θ', the acceleration a behind an 80 ms lag of the command) with damping
    ratio ``zeta`` < 0: at ζ = −0.02 the pendulum's pair lies at |λ| = 1.0015 per 0.03 s (a
    growth time of 20 s), what the best models of a real flight's nearly undamped swing
    show. A velocity loop (P = 1.8, ±4 m/s²) flies random steps (0–3 m/s, held 10–25 s) as
    ``collect`` does and keeps the swing bounded; discretised by python-control (ZOH).
    """
    import control

    g, mp, mq, length, lag, dt = 9.80665, 0.2, 0.952, 1.0, 0.08, 0.01
    w2 = g * (1 + mp / mq) / length
    a = [
        [0, mp / mq * g, 0, 1],
        [0, 0, 1, 0],
        [0, -w2, -2 * zeta * math.sqrt(w2), -1 / length],
        [0, 0, 0, -1 / lag],
    ]
    d = control.c2d(control.ss(a, [[0], [0], [0], [1 / lag]], np.eye(4), 0), dt)
    ad, bd = np.asarray(d.A), np.asarray(d.B)[:, 0]
    rng = np.random.default_rng(seed)
    steps = int(round(seconds / dt))
    x, out = np.zeros(4), np.zeros((steps, 3))
    setpoint, change = 0.0, 2.0
    for k in range(steps):
        if k * dt >= change:
            setpoint, change = rng.uniform(0, 3), k * dt + rng.uniform(10, 25)
        u = float(np.clip(1.8 * (setpoint - x[0]), -4, 4))
        out[k] = x[0], x[1], u
        x = ad @ x + bd * u
    return {
        "t": dt * np.arange(steps),
        "vn": out[:, 0] + rng.normal(0, 0.02, steps),
        "swing_n": out[:, 1] + rng.normal(0, noise, steps),
        "acc_sp_n": out[:, 2],
    }


def test_a_slowly_growing_swing_model_is_judged_by_its_growth_over_the_horizon():
    # Issue 26: a fixed |λ| ≤ 1.001 refused the best models of such a flight (|λ| ≈ 1.0015)
    # and picked one 20–150 % worse. The growth rule (no mode more than doubles over the
    # MPC's 3 s horizon) keeps the search within 2 % of the unscreened exhaustive grid's
    # best NMAE on the held-out span, and within 5 % on another flight.
    train, other = _antidamped_swing_flight(1), _antidamped_swing_flight(1001)
    picked = sysid.search(train, select="nmae").model
    best = sysid.search(train, select="nmae", search_mode="exhaustive", growth_limit=1e300).model
    screen = picked.diagnostics["stability_screen"]
    assert screen["stable"] and screen["reason"] is None
    assert 1.001 < screen["spectral_radius"] <= screen["bound"], screen
    assert screen["growth"] == pytest.approx(screen["spectral_radius"] ** 100, rel=1e-9)
    assert picked.diagnostics["test_nmae"] <= 1.02 * best.diagnostics["test_nmae"]
    held = sysid.evaluate(picked, other)["nmae"]
    assert held <= 1.05 * sysid.evaluate(best, other)["nmae"]
    # The fixed tolerance it replaced (growth 1.001 within one sample) refuses the best
    # rows, says why in the table, and picks a model worse by more than 10 %.
    old = sysid.search(train, select="nmae", growth_limit=1.001, prediction_horizon=DT)
    assert old.model.diagnostics["test_nmae"] > 1.1 * best.diagnostics["test_nmae"]
    refused = [r for r in old.table if r["stable"] is False]
    assert refused and all("grows" in r["stability_screen"]["reason"] for r in refused)


# ----------------------------------------------------------------- sweeps and plots


def test_sweeps_and_plots(tmp_path):
    cols = _pendulum_flight(seed=3, seconds=160.0)
    rows = sysid.sweep_training_length(cols, [30.0, 60.0, 110.0], delays=[2, 6, 10])
    assert [r["train_length"] for r in rows] == [30.0, 60.0, 110.0]
    assert all(math.isfinite(r["nmae"]) for r in rows)
    res = sysid.search(cols, delays=[2, 6, 10], fine=None)
    plots.plot_pareto(res, tmp_path / "pareto.png")
    plots.plot_training_length(rows, tmp_path / "length.png")
    for name in ("pareto.png", "length.png"):
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"
    dts = sysid.sweep_sample_time(cols, [0.03, 0.05], delays=[2, 6])
    assert [r["dt"] for r in dts] == [0.03, 0.05]
    noise = sysid.sweep_noise(cols, [110.0], delays=[4, 8], method="dmdc", noise_std=0.005)
    assert {r["noise"] for r in noise} == {True, False}


def test_smoothing_option_runs():
    cols = _pendulum_flight(seed=5, seconds=120.0)
    m = sysid.identify(cols, delays=8, smooth=True)
    assert m.diagnostics["test_nmae"] < 0.1


# ----------------------------------------------------------------- CLI


def _write_parquet(cols, path):
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    pq.write_table(pa.table({k: np.asarray(v) for k, v in cols.items()}), path)


def test_cli_identify_and_evaluate(tmp_path, capsys):
    from swingrt.cli import main

    train, other = tmp_path / "train.parquet", tmp_path / "other.parquet"
    _write_parquet(_pendulum_flight(seed=1, seconds=160.0), train)
    _write_parquet(_pendulum_flight(seed=2, seconds=80.0), other)
    out = tmp_path / "m.json"
    assert main(["identify", str(train), "--delays", "8", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "q = 8" in text and "test NMAE" in text
    assert main(["evaluate", str(out), str(other), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["nmae"] < 0.05 and set(res["per_state"]) == {"vn", "swing_n"}
    # User mistakes: one line, exit 2.
    assert main(["identify", str(train), "--delays", "0", "-o", str(out)]) == 2
    assert "--delays" in capsys.readouterr().err
    assert main(["identify", str(train), "--axes", "ne", "-o", str(out)]) == 2
    assert "ve" in capsys.readouterr().err
    assert main(["evaluate", str(tmp_path / "missing.json"), str(other)]) == 2


# ----------------------------------------------------------------- simulated flights


@pytest.mark.parametrize("mass", [0.1, 0.2, 0.3])
@pytest.mark.parametrize("length", [0.5, 1.0, 2.0])
def test_sim_models_predict_another_flight(mass, length):
    cfg = {"payload": {"mass": mass, "length": length}}
    train = swingrt.collect(cfg, duration=200.0, seed=1)
    test = swingrt.collect(cfg, duration=100.0, seed=2)
    model = sysid.identify(train, search=True, offset="affine")
    score = sysid.evaluate(model, test)
    assert score["nmae"] < 0.05, (mass, length, model, score)


def test_sim_double_pendulum_dmdc_beats_whitebox():
    cfg = {"payload": {"kind": "double", "mass": 0.2, "length": 1.0, "mass2": 0.1, "length2": 0.3}}
    train = swingrt.collect(cfg, duration=200.0, seed=3)
    test = swingrt.collect(cfg, duration=100.0, seed=4)
    dmdc = sysid.identify(train, search=True)
    white = sysid.identify(train, method="whitebox")
    e_d = sysid.evaluate(dmdc, test)["nmae"]
    e_w = sysid.evaluate(white, test)["nmae"]
    assert e_d < e_w, (e_d, e_w)


@pytest.mark.parametrize("mass, length", [(0.1, 0.5), (0.2, 1.0), (0.3, 2.0)])
def test_sim_fft_length_on_free_swing(mass, length):
    sp = {
        "t": 0.0,
        "pn": None,
        "pe": None,
        "pd": -10.0,
        "vn": None,
        "ve": None,
        "vd": None,
        "an": 0.0,
        "ae": 0.0,
        "ad": None,
        "yaw": None,
    }
    cfg = {
        "payload": {"mass": mass, "length": length, "initial_swing_n": 0.1},
        "setpoints": [sp],
        "duration": 60.0,
    }
    tr = swingrt.simulate(cfg)
    t, swing = tr.columns["t"], tr.columns["swing_n"]
    keep = t > 5.0  # drop the start transient, as section 4.3.3 does
    f = _core.sysid_fft_peak(np.ascontiguousarray(swing[keep]), float(t[1] - t[0]), 0.1, 3.0)
    est = _core.sysid_cable_length(f, 0.952, mass)
    assert abs(est - length) / length < 0.02, (f, est)


def test_the_cable_length_comes_from_the_swings_answer_to_the_vehicles_motion():
    """A heavy short payload (0.46 kg on 0.34 m) under a light, sluggish vehicle (robustness-
    vehicle sample 366): in the training flight the quasi-static lean under the slow
    manoeuvres outweighs the free oscillation, so the swing's spectrum peaks at 0.12 Hz and
    eq. 4.8 reads a cable of about 26 m. The single pendulum fitted to how the swing answers
    the vehicle's velocity (``sysid::links``) finds the length within 2 %, as it does on a
    long cable (where the peak, pulled by the vehicle's loop, is some 20 % off)."""
    cases = [
        (
            {
                "seed": 632582077,
                "vehicle": {
                    "mass": 0.7635,
                    "inertia": [0.002588, 0.001803, 0.003679],
                    "drag": [0.1191, 0.1434, 0.449],
                    "motor_tau": 0.02838,
                },
                "payload": {"mass": 0.4578, "length": 0.336},
            },
            True,
        ),
        ({"seed": 5, "payload": {"mass": 0.3, "length": 2.0}}, False),
    ]
    for cfg, fft_fooled in cases:
        sc = _core.Scenario.builtin("training").to_dict()
        for key, value in cfg.items():
            sc[key] = {**sc[key], **value} if isinstance(value, dict) else value
        sc["duration"] = 300.0
        train = swingrt.simulate(sc)
        length, vm, mp = cfg["payload"]["length"], sc["vehicle"]["mass"], cfg["payload"]["mass"]
        wb = sysid.identify(train, method="whitebox", vehicle_mass=vm, payload_mass=mp)
        est = wb.diagnostics["whitebox"]
        assert abs(est["length"] / length - 1) < 0.02, (cfg, est)
        if fft_fooled:
            assert est["fft_length"] > 10 * length, est


# ----------------------------------------------------------------- control-relevant selection


def _grid_case(case):
    from swingrt.experiments import cases, evaluation_scenario, load_experiment, training_scenario
    from swingrt.sim import _run

    exp = load_experiment("payload-grid")
    over = dict(cases(exp))[case]
    train_sc = training_scenario(exp, over, 0)
    return _run(train_sc, False, "collect"), evaluation_scenario(exp, over, 1, train_sc)


def _chosen(model: sysid.LinearModel) -> dict:
    """The control check's record of the candidate ``model`` is: the one it names as flown,
    which is the model's own (q, p) where its MPC flies."""
    cc = model.diagnostics["control_check"]
    flown = cc["checked"][cc["flown"]]
    if flown["law"] == "mpc":
        assert (flown["delays"], flown["rank"]) == (model.delays, model.rank), flown
    assert (cc["pick_kind"] == "within_bounds") == cc["passed"], cc["pick_kind"]
    return flown


def test_select_for_control_rejects_the_nmae_best_model_that_cannot_fly():
    """payload-grid mp0.3_l1, seed 0: with a coarse grid of p steps of 5 refined around one
    winner (scored from sample 61), the NMAE-best (q, p) leaves the MPC creeping towards the
    setpoint with a slowly settling swing in flight; the closed-loop check rejects it and the
    model it selects tracks the step without offset on the full simulator."""
    from swingrt.experiments import simulate_controller
    from swingrt.metrics import step_metrics

    train, ev = _grid_case("mp0.3_l1")
    coarse = dict(search_delays=list(range(2, 59, 4)), dense_ranks=0, winners=1, fine=(2, 4))
    result = sysid.search(train, **coarse, score_delays=62)
    picked = sysid.select_for_control(train, result, twin=None)
    cc = picked.model.diagnostics["control_check"]
    assert cc["passed"] and _chosen(picked.model)["passed"]
    assert cc["checked"][0]["delays"] == result.model.delays
    assert not cc["checked"][0]["passed"], cc["checked"][0]
    sel = picked.model.diagnostics["selected"]
    assert (sel["delays"], sel["rank"]) == (picked.model.delays, picked.model.rank)
    flown = {}
    for name, m in [("nmae_best", result.model), ("selected", picked.model)]:
        trace, _ = simulate_controller(ev, "mpc", model=m)
        flown[name] = step_metrics(trace, t0=2.0)
    assert flown["selected"]["ss_error"] < 0.02, flown
    assert math.isfinite(flown["selected"]["v_settle_s"]), flown
    # The failure this guards against: the NMAE-best model's MPC creeps (the swing settles
    # four times later and its IAE is nearly three times the selected model's).
    assert flown["nmae_best"]["swing_settle_s"] > 2 * flown["selected"]["swing_settle_s"], flown
    assert flown["nmae_best"]["swing_iae_deg_s"] > 2 * flown["selected"]["swing_iae_deg_s"], flown


def test_readings_of_a_flight_are_weighed_by_the_core_s_pick_order():
    # The drag choice's rule (choose_reading): the better pick, then the least twin swing,
    # then the earlier reading; no pick or no figure ranks last.
    weigh = _core.selection_choose_reading
    assert weigh([]) is None
    assert weigh([("least_swing", 0.01), ("within_bounds", 0.4)]) == 1
    assert weigh([("within_bounds", None), ("within_bounds", 0.3)]) == 1
    assert weigh([(None, 0.0), ("least_miss", None)]) == 1
    assert weigh([("least_miss", 0.2), ("least_miss", 0.2)]) == 0
    with pytest.raises(ConfigError, match='pick_kind: unknown pick "best"'):
        weigh([("within_bounds", 0.1), ("best", 0.1)])


def test_select_for_control_bounds():
    train, _ = _grid_case("mp0.2_l0.5")
    result = sysid.search(train)
    with pytest.raises(ConfigError, match="bound"):
        sysid.select_for_control(train, result, bounds={"settling": 1.0})
    with pytest.raises(ConfigError, match="candidates"):
        sysid.select_for_control(train, result, candidates=0)
    for drags in ([], ["keep", "keep"]):
        with pytest.raises(ConfigError, match="swing_drags: must name one or more distinct"):
            sysid.select_for_control(train, result, swing_drags=drags)
    with pytest.raises(ConfigError, match="swing_drags"):
        sysid.select_for_control(train, result, swing_drags=["both"])
    # Bounds nothing can meet: the least-violating candidate, and the diagnostics say so.
    none = sysid.select_for_control(
        train, result, candidates=3, bounds={"hold_drift": -1.0}, twin=None
    )
    with pytest.raises(ConfigError, match="twin"):
        sysid.select_for_control(train, result, twin="x500")
    cc = none.model.diagnostics["control_check"]
    # `candidates` bounds the distinct (q, p) flown: with none passing, the same three are
    # flown once more with the noise design's strongest filter.
    second = cc["strongest_filter_pass"]
    assert cc["passed"] is False and len({(c["delays"], c["rank"]) for c in cc["checked"]}) == 3
    assert second is not None and len(cc["checked"]) == 3 + second["flown"] == 6, second
    assert any(
        (c["delays"], c["rank"]) == (none.model.delays, none.model.rank) for c in cc["checked"]
    )


def _campaign_spec(campaign: str, seed: int | None):
    """The spec of ``examples/campaigns/<campaign>.toml``, at ``seed`` when given."""
    import tomllib

    from swingrt.campaign.spec import parse_spec

    root = Path(__file__).resolve().parents[1]
    raw = tomllib.loads((root / f"examples/campaigns/{campaign}.toml").read_text())
    return parse_spec(raw if seed is None else {**raw, "seed": seed})


def _campaign_experiment(index: int, campaign: str = "robustness", seed: int | None = None):
    """The experiment of sample ``index`` of a campaign (see :func:`_campaign_sample`)."""
    spec = _campaign_spec(campaign, seed)
    return spec.experiment(spec.draw(index), label=str(index))


def _campaign_sample(index: int, campaign: str = "robustness", seed: int | None = None):
    """Sample ``index`` of the robustness campaign (or of ``examples/campaigns/<campaign>
    .toml``, at ``seed`` when given): its training flight, the training scenario (the
    vehicle's twin) and the evaluation scenario."""
    from swingrt.experiments import evaluation_scenario, training_scenario
    from swingrt.sim import _run

    spec = _campaign_spec(campaign, seed)
    exp = spec.experiment(spec.draw(index), label=str(index))
    seed = spec.flight_seed(index)
    train_sc = training_scenario(exp, {}, seed)
    ev = evaluation_scenario(exp, {}, seed + 1, train_sc)
    return _run(train_sc, False, "collect"), train_sc, ev


def _fly(ev, model=None, controller="mpc", mpc_settings=None):
    """Step metrics of ``controller`` flying the evaluation scenario ``ev``."""
    from swingrt.experiments import simulate_controller
    from swingrt.metrics import step_metrics

    trace, _ = simulate_controller(ev, controller, model=model, mpc_settings=mpc_settings)
    return step_metrics(trace, t0=2.0)


def test_the_twin_step_flight_rejects_a_model_that_limit_cycles_on_the_vehicle():
    """Robustness campaign sample 221 (0.47 kg on 1.65 m, 1.8 m/s headwind): the first
    candidate to pass the linear check has an MPC that rings against the acceleration bound
    on the vehicle (the attitude loop's lag, which the linear plant lacks) for well over
    6 s. Flown first on the twin it is rejected, and the model selected
    settles in the real flight."""
    train, train_sc, ev = _campaign_sample(221)
    result = sysid.search(train)
    flown, flown_models = {}, {}
    for name, twin in [("linear", None), ("twin", train_sc)]:
        picked = sysid.select_for_control(train, result, twin=twin)
        cc = picked.model.diagnostics["control_check"]
        assert cc["passed"], cc
        flown[name] = (cc, _fly(ev, picked.model))
        flown_models[name] = picked.model
    cc, linear = flown["linear"]
    assert cc["twin"] is None and linear["v_settle_s"] > 6.0, linear
    cc, twin = flown["twin"]
    assert "twin" in cc["twin"]["plant"] and cc["twin"]["bounds"]["settle"] == 6.0
    chosen = _chosen(flown_models["twin"])
    assert chosen["passed"] and chosen["twin"]["settle"] <= 6.0, chosen
    # A flight that never settles has settle = ∞, null in JSON.
    unsettled = [c for c in cc["checked"] if (c["twin"]["settle"] or math.inf) > 6.0]
    assert unsettled, cc["checked"]
    assert twin["v_settle_s"] < 6.0 and twin["ss_error"] < 0.02, twin


def test_the_twin_step_flight_rejects_a_model_that_does_not_damp_the_swing():
    """Campaign sample 234 (0.38 kg on 0.54 m): without the swing bound, taking the first
    candidate that settles on the twin, the vehicle moves but keeps most of PX4's swing (in
    flight, more than 0.4 of PID's swing excess); with it, the pick damps the swing on the
    twin and in flight; so does the default selection, and without the bound the least
    swing of five that pass, looking far enough for them."""
    train, train_sc, ev = _campaign_sample(234)
    result = sysid.search(train)
    pid = _fly(ev, controller="pid")["swing_excess_iae_deg_s"]
    loose = sysid.select_for_control(
        train, result, twin=train_sc, twin_bounds={"swing_vs_pid": 100.0}, passers=1
    )
    picked = sysid.select_for_control(train, result, twin=train_sc, passers=1)
    cc = picked.model.diagnostics["control_check"]
    assert cc["passed"] and cc["twin"]["pid"]["swing_excess"] > 10.0, cc["twin"]
    chosen = _chosen(picked.model)
    assert chosen["twin"]["swing_excess"] <= cc["twin"]["swing_bound"], chosen
    # Candidates that settled but swung are on record, not taken.
    assert any(c["settled"] and not c["passed"] for c in cc["checked"]), cc["checked"]
    # Without the bound, the cost alone (of the first five that pass, the one that swings
    # least on the twin) finds a model that damps when it may look far enough: here the
    # five span more than the default ten candidates past the first.
    cheapest = sysid.select_for_control(
        train, result, twin=train_sc, twin_bounds={"swing_vs_pid": 100.0}, look_ahead=300
    )
    assert "swings least" in cheapest.model.diagnostics["control_check"]["pick"]
    default = sysid.select_for_control(train, result, twin=train_sc)
    swing = {
        name: _fly(ev, sel.model)["swing_excess_iae_deg_s"] / pid
        for name, sel in [
            ("loose", loose),
            ("bound", picked),
            ("cheapest", cheapest),
            ("default", default),
        ]
    }
    assert swing["loose"] > 0.4 and swing["bound"] < 0.2 and swing["cheapest"] < 0.2, swing
    assert swing["default"] < 0.2, swing


def test_the_twin_hold_flight_bounds_what_the_sensor_noise_does_to_the_velocity():
    """Campaign sample 201 (a double pendulum, swing-sensor noise 0.0097 rad): the twin flies
    with the noise estimated from the training swing. A candidate that settles there then
    holds the step for 60 s, with the noise and without; the RMS of the 2 s mean difference
    (`wander`, what the noise alone did to the velocity) is bounded, and the estimator is
    designed against the noise first. Without the design and the bound the pick passes the
    noise on to the velocity and ends the real flight at least 0.02 m/s off the setpoint;
    with them, the pick stays on the setpoint."""
    train, train_sc, ev = _campaign_sample(201)
    result = sysid.search(train)
    plant = sysid.check_plant(train, result, settings=result.settings)[0].diagnostics
    assert abs(plant["whitebox"]["swing_noise"] / 0.009745 - 1.0) < 0.05, plant["whitebox"]
    # Without the noise design and the wander bound (nor the slow vehicle, on which such a
    # pick does not settle either) the pick passes the noise on.
    loose = sysid.select_for_control(
        train,
        result,
        twin=train_sc,
        twin_bounds={"wander": 100.0},
        noise_factors=[1.0],
        slow_motor_lag=0.0,
        slow_inertia=1.0,
    )
    picked = sysid.select_for_control(train, result, twin=train_sc)
    cc = picked.model.diagnostics["control_check"]
    assert cc["passed"], cc
    bound = cc["twin"]["bounds"]["wander"]
    held = [c for c in cc["checked"] if c["hold"] is not None]
    assert held and all(c["hold"]["wander"] <= bound for c in held if c["settled"]), held
    loose_cc = loose.model.diagnostics["control_check"]
    assert _chosen(loose.model)["hold"]["wander"] > bound, _chosen(loose.model)
    assert loose_cc["wander"]["worst"] > cc["wander"]["worst"], (loose_cc["wander"], cc["wander"])
    ss = {
        name: _fly(ev, sel.model)["ss_error"] for name, sel in [("loose", loose), ("bound", picked)]
    }
    assert ss["loose"] >= 0.02 and ss["bound"] < 0.01, ss


def test_a_model_whose_mpc_passes_the_noise_on_is_flown_with_an_estimator_that_trusts_it_less():
    """Campaign sample 42 (a double pendulum, swing-sensor noise 0.0055 rad): with the
    estimator as set, the first candidate that passes wanders 0.38 % of the step by the
    linear analysis (0.35 % on the twin's hold) and the real flight ends 0.027 m/s off the
    setpoint. The noise design raises its swing channels' Kalman measurement noise three
    times (the first factor whose predicted wander is within 1 %/3.29); the model carries
    that noise, the MPC built on it assumes it, and the flight ends on the setpoint."""
    train, train_sc, ev = _campaign_sample(42)
    result = sysid.search(train)
    plain = sysid.select_for_control(train, result, twin=train_sc, noise_factors=[1.0], passers=1)
    picked = sysid.select_for_control(train, result, twin=train_sc, passers=1)
    assert "swing_measurement_noise" not in plain.model.diagnostics
    assert picked.model.diagnostics["swing_measurement_noise"] == pytest.approx(0.03)
    cc = picked.model.diagnostics["control_check"]
    chosen = _chosen(picked.model)
    assert cc["passed"] and chosen["swing_measurement_noise"] == pytest.approx(0.03), chosen
    # The design's target: the predicted wander within 1 % / 3.29 of the step, where the
    # estimator as set leaves it above; the twin's hold agrees that it wanders less.
    target = cc["twin"]["bounds"]["late_error"] / 3.29
    wander = {
        n: s.model.diagnostics["control_check"]["wander"]
        for n, s in [("plain", plain), ("picked", picked)]
    }
    assert wander["plain"]["worst"] > target > wander["picked"]["worst"], wander
    assert chosen["hold"]["wander"] < _chosen(plain.model)["hold"]["wander"]
    # The default choice (the least swing of the first five that pass) lands on the
    # setpoint too.
    default = sysid.select_for_control(train, result, twin=train_sc)
    ss = {
        name: _fly(ev, sel.model)["ss_error"]
        for name, sel in [("plain", plain), ("raised", picked), ("default", default)]
    }
    assert ss["plain"] >= 0.02 and ss["raised"] < 0.015 and ss["default"] < 0.015, ss
    # The model file keeps it: a reloaded model flies the same MPC.
    again = sysid.LinearModel.from_json(picked.model.to_json())
    assert again.diagnostics["swing_measurement_noise"] == pytest.approx(0.03)


def test_with_none_passing_as_the_noise_design_chose_the_strongest_filter_is_flown():
    """Sample 245 of the vehicle-varied robustness campaign, seed 9 (0.14 kg on 0.39 m, the
    largest swing-sensor noise, 0.0097 rad): the noise design predicts no wander with the
    estimator as set, and none of the 300 candidates so designed passes; the ones that damp
    end the twin's step 0.55-0.7 % of the step off its setpoint (bound 0.5 %). Taking the
    least-swinging settled one flew a low-rank model at 0.52 of PX4's swing excess in the
    real flight. Flown once more with the design's strongest filter (ten times the swing
    noise), candidates pass, and the pick damps the real flight's swing to under a tenth
    of PX4's and ends on the setpoint."""
    import math

    train, train_sc, ev = _campaign_sample(245, "robustness-vehicle", seed=9)
    # The twin the campaign flies: the built-in vehicle weighed at the sample's mass.
    mass = train_sc.to_dict()["vehicle"]["mass"]
    twin = sysid.builtin_twin(mass)
    result = sysid.search(train, vehicle_mass=mass)
    # The estimator's swing noise and the design's factors as the defaults set them.
    mpc = {"kf_measurement_noise": 0.01}
    picked = sysid.select_for_control(
        train, result, twin=twin, mpc_settings=mpc, noise_factors=[1.0, 3.0, 10.0]
    )
    cc = picked.model.diagnostics["control_check"]
    second = cc["strongest_filter_pass"]
    strongest = 10 * mpc["kf_measurement_noise"]
    assert second is not None and second["flown"] > 0, second
    assert math.isclose(second["swing_measurement_noise"], strongest), second
    assert cc["passed"], cc["pick"]
    assert math.isclose(picked.model.diagnostics["swing_measurement_noise"], strongest)
    # None of the first pass passed: what the second pass is for.
    first = cc["checked"][: len(cc["checked"]) - second["flown"]]
    assert first and not any(c["passed"] for c in first)
    pid = _fly(ev, controller="pid")["swing_excess_iae_deg_s"]
    flown = _fly(ev, picked.model)
    assert flown["swing_excess_iae_deg_s"] < 0.1 * pid and flown["ss_error"] < 0.01, (flown, pid)


def test_the_twin_hold_flight_shows_an_oscillation_that_grows_too_slowly_for_the_step():
    """Campaign sample 349 (0.30 kg on 0.63 m): the first candidate that passes on the
    twin's 20 s step flight has an MPC whose loop slowly grows a ~1 Hz oscillation; in the
    real flight the velocity never stays within 5 % of the step. Held for 60 s without
    noise, the twin shows it (`late_error`, the largest error over the last 20 s, above 1 %
    of the step) and the pick settles in flight."""
    train, train_sc, ev = _campaign_sample(349)
    result = sysid.search(train)
    # Without the hold's bound (and the payload's tolerance and the slow vehicle, whose
    # twins show it too).
    loose = sysid.select_for_control(
        train,
        result,
        twin=train_sc,
        twin_bounds={"late_error": 100.0},
        passers=1,
        payload_tolerance=0.0,
        slow_motor_lag=0.0,
        slow_inertia=1.0,
    )
    picked = sysid.select_for_control(train, result, twin=train_sc)
    cc = picked.model.diagnostics["control_check"]
    assert cc["passed"], cc
    late = [c for c in cc["checked"] if c["hold"] is not None and c["hold"]["late_error"] > 0.01]
    assert late and not any(c["settled"] for c in late), cc["checked"]
    # The step flight alone settled it within the bound.
    assert all(c["twin"]["settle"] <= 6.0 for c in late), late
    flown = {name: _fly(ev, sel.model) for name, sel in [("loose", loose), ("bound", picked)]}
    assert math.isinf(flown["loose"]["v_settle_s"]), flown["loose"]
    assert flown["bound"]["v_settle_s"] < 6.0 and flown["bound"]["ss_error"] < 0.02, flown


def test_where_no_mpc_passes_on_the_imu_the_input_shaper_that_passes_on_the_twin_flies(
    monkeypatch,
):
    """robustness-imu seed 3, sample 132 (0.13 kg on 2.37 m, nothing on the cable: the swing
    from the IMU), with the airframe's drag kept in the estimate: no candidate's MPC passes
    the check, and the MPC's pick leaves the vehicle more than 0.4 of PX4's swing excess (a
    failure). The ZVD shaper of PX4's velocity setpoint on the white-box pendulum passes the
    twin's flights; the selection records it and the model's flight flies it, well within
    the bound and on the setpoint. The flight is the study's own vehicle and payload, not
    the twin: the shaper was judged on an estimate. (With the quadratic drag removed, the
    default, one MPC here passes at 0.95 of the payload bound and flies 0.396 of PX4's
    excess against this shaper's 0.25.)"""
    import functools

    from swingrt.experiments.identification import identify_case

    fit = functools.partial(_core.swing_scale_fit, drag="keep")
    monkeypatch.setattr(_core, "swing_scale_fit", fit)

    exp = _campaign_experiment(132, "robustness-imu", 3)
    train, train_sc, ev = _campaign_sample(132, "robustness-imu", 3)
    model, _, _ = identify_case(train, exp, vehicle=train_sc)
    cc = model.diagnostics["control_check"]
    assert cc["law"]["kind"] == "shaper" and cc["passed"], cc["law"]
    mpcs = [c for c in cc["checked"] if c["law"] == "mpc"]
    assert mpcs and not any(c["passed"] for c in mpcs)
    shaper = cc["checked"][-1]
    # Judged on the twin alone: no linear plant flies a law without feedback on the model.
    assert shaper["law"] == "shaper" and shaper["passed"] and shaper["overshoot"] is None
    assert shaper["payload_miss"] <= 1.0 and shaper["slow_vehicle_miss"] <= 1.0, shaper
    # The mode shaped is the pendulum's under PX4's loop: near sqrt(g / l) of the cable.
    omega = cc["law"]["mode"]["omega"]
    assert abs(omega / math.sqrt(9.81 / 2.37) - 1.0) < 0.15, omega
    pid = _fly(ev, controller="pid")["swing_excess_iae_deg_s"]
    flown = _fly(ev, model)
    without = model.with_diagnostics({"control_check": {**cc, "law": None}})
    mpc = _fly(ev, without)
    assert flown["swing_excess_iae_deg_s"] < 0.4 * pid and flown["ss_error"] < 0.02, flown
    assert mpc["swing_excess_iae_deg_s"] >= 0.4 * pid, (mpc, pid)


def test_the_twin_carries_the_second_link_found_in_the_swing():
    """Campaign sample 377: a double pendulum (0.18 kg on 0.81 m, 0.17 kg 0.80 m below) that
    the white-box, from one FFT peak, takes for a single pendulum of 1.8 m. The links fit of
    the swing finds both links; the twin carries them, and the MPC picked on it settles in
    flight (on the single-pendulum twin the pick never settled)."""
    train, train_sc, ev = _campaign_sample(377)
    result = sysid.search(train)
    plant, _ = sysid.check_plant(train, result, settings=result.settings)
    links = plant.diagnostics["whitebox"]["links"]
    assert abs(links["length"] - 0.807) < 0.08 and abs(links["length2"] - 0.80) < 0.08, links
    assert abs(links["mass_ratio"] - 0.99) < 0.2, links
    picked = sysid.select_for_control(train, result, twin=train_sc)
    cc = picked.model.diagnostics["control_check"]
    assert "double pendulum" in cc["twin"]["plant"], cc["twin"]
    flight = _fly(ev, picked.model)
    assert flight["v_settle_s"] < 6.0 and flight["ss_error"] < 0.02, flight


def _lagged_flight(tau: float, dt: float = 0.02, n: int = 4000) -> tuple[np.ndarray, ...]:
    """An axis of a flight whose acceleration is a command behind an exact first-order lag
    ``tau`` (zero-order hold), with drag, a swing's pull and a constant beside it."""
    rng = np.random.default_rng(5)
    u = np.repeat(rng.uniform(-3.0, 3.0, n // 40 + 1), 40)[:n]
    theta = 0.08 * np.sin(2.1 * dt * np.arange(n))
    alpha = math.exp(-dt / tau) if tau > 0 else 0.0
    share = tau * (1 - alpha) / dt if tau > 0 else 0.0
    v, f = np.zeros(n), u[0]
    for k in range(n - 1):
        acc = u[k] + (f - u[k]) * share
        v[k + 1] = v[k] + dt * (acc - 0.2 * v[k] - 1.1 * theta[k] + 0.03)
        f = alpha * f + (1 - alpha) * u[k]
    return v, theta, u


def test_the_attitude_lag_is_read_from_the_command_against_the_acceleration():
    """The lag the selection flies behind and the NMPC predicts with (one fit, in the core):
    a flight whose acceleration follows the command through a known lag, with drag and a
    swing's pull beside it, gives that lag back; a flight that cannot tell it gives none."""
    from swingrt.methods.nmpc import estimate_lag, lagged

    for tau in (0.0, 0.08, 0.165, 0.3):
        v, theta, u = _lagged_flight(tau)
        assert _core.sysid_attitude_lag(v, theta, u, 0.02) == pytest.approx(tau, abs=1e-9)
        assert estimate_lag(v, theta, u, 0.02) == pytest.approx(tau, abs=1e-9)
        # The NMPC predicts with the fit's discretisation: the acceleration it sees rebuilds
        # the flight's velocity exactly.
        acc = lagged(u, 0.02, tau)
        rebuilt = v[:-1] + 0.02 * (acc[:-1] - 0.2 * v[:-1] - 1.1 * theta[:-1] + 0.03)
        np.testing.assert_allclose(rebuilt, v[1:], rtol=0, atol=1e-12)
    v, theta, u = _lagged_flight(0.1)
    assert _core.sysid_attitude_lag(v, theta, np.ones_like(u), 0.02) is None
    with pytest.raises(DataError, match="swing has 10 samples"):
        _core.sysid_attitude_lag(v, theta[:10], u, 0.02)


def test_the_white_box_carries_the_lag_of_the_flight_and_the_check_flies_behind_it():
    """A training flight of the built-in vehicle (PX4's cascade): the white-box reads an
    attitude lag between 0.1 and 0.25 s from it, and with ``flight_lag`` the control check
    flies its linear plants behind that lag as well as behind 0 and 0.1 s."""
    train, _ = _grid_case("mp0.2_l0.5")
    result = sysid.search(train)
    plant, _ = sysid.check_plant(train, result, settings=result.settings)
    lag = plant.diagnostics["whitebox"]["attitude_lag"]
    assert 0.1 < lag < 0.25, lag
    flown = sysid.select_for_control(train, result, twin=None, flight_lag=True)
    assert flown.model.diagnostics["control_check"]["input_lags"] == [0.0, 0.1, lag]
    fixed = sysid.select_for_control(train, result, twin=None)
    assert fixed.model.diagnostics["control_check"]["input_lags"] == [0.0, 0.1]


@pytest.mark.parametrize("mass", [0.952 * 0.7, 0.952, 0.952 * 1.5])
def test_the_builtin_twin_weighs_the_vehicle_and_hovers_as_the_builtin_does(mass):
    """The built-in twin at a known vehicle mass: that mass, its motors and inertia scaled
    with it (the same hover thrust with the same payload's share of the weight), the rest
    the built-in vehicle's."""
    base = _core.Scenario.builtin("step")
    twin = sysid.builtin_twin(mass)
    b, t = base.to_dict()["vehicle"], twin.to_dict()["vehicle"]
    k = mass / b["mass"]
    assert t["mass"] == pytest.approx(mass)
    assert t["thrust_poly"] == pytest.approx([c * k for c in b["thrust_poly"]])
    assert t["inertia"] == pytest.approx([i * k for i in b["inertia"]])
    assert t["drag"] == b["drag"] and t["motor_tau"] == b["motor_tau"]
    assert twin.to_dict()["controller"] == base.to_dict()["controller"]
    # The payload scaled with the vehicle: the same normalised hover thrust.
    p = twin.to_dict()["payload"]["mass"] * k
    scaled = twin.with_overrides({"payload": {"mass": p}})
    assert scaled.hover_thrust() == pytest.approx(base.hover_thrust(), rel=1e-9)


def test_the_builtin_twin_flies_the_px4_gains_it_is_given_and_refuses_other_fields():
    """Given PX4's gains (a ULog's parameters give them), the built-in twin flies them; every
    other controller field and the airframe stay the built-in's."""
    base = _core.Scenario.builtin("step").to_dict()
    gains = {"att_p": [7.5, 7.1, 2.8], "rate_p": [0.13, 0.12, 0.2], "vel_p": [1.5, 1.5, 4.0]}
    twin = sysid.builtin_twin(base["vehicle"]["mass"], gains).to_dict()
    for k, v in twin["controller"].items():
        expected = gains.get(k, base["controller"][k])
        assert v == pytest.approx(expected), k
    assert twin["vehicle"] == base["vehicle"]
    with pytest.raises(ConfigError, match="gains: tilt_max"):
        sysid.builtin_twin(0.952, {"tilt_max": 0.5})
    with pytest.raises(ConfigError, match="gains"):
        sysid.builtin_twin(0.952, {"att_p": [7.0]})


def test_the_gains_of_a_ulog_s_parameters_are_px4_s_with_one_horizontal_velocity_gain(tmp_path):
    """`swingrt identify LOG.ulg` flies the built-in twin under the log's gains: PX4's
    pitch P is the attitude loop's N-axis gain, its one horizontal velocity gain goes to
    North and East, and what the log lacks is nominal."""
    from swingrt.commands.identify import _logged_gains

    f = tmp_path / "params.txt"
    f.write_text("MC_PITCH_P 7.5\nMPC_XY_VEL_P_ACC 2.1\nMC_ROLLRATE_D 0.004\n")
    gains = _logged_gains(f)
    nominal = _core.Scenario.builtin("step").to_dict()["controller"]
    assert set(gains) == set(sysid.PX4_GAINS)
    assert gains["att_p"] == pytest.approx([nominal["att_p"][0], 7.5, nominal["att_p"][2]])
    assert gains["vel_p"] == pytest.approx([2.1, 2.1, nominal["vel_p"][2]])
    assert gains["rate_d"][0] == pytest.approx(0.004)
    assert gains["rate_i"] == pytest.approx(nominal["rate_i"])


def test_a_builtin_twin_under_the_vehicle_s_gains_refuses_a_loop_its_attitude_loop_excites():
    """Sample 497 of the vehicle-varied robustness campaign, seed 10 (a double pendulum,
    0.11 kg on 0.66 m with 0.10 kg 0.50 m below, under PX4 pitch gains of 5.3 and 0.12 where
    the built-in flies 6.5 and 0.15): the links are found and the twin carries them, yet
    under the built-in's gains the pick's loop, through the vehicle's softer attitude loop,
    grows an oscillation near the second mode and the velocity never settles. The campaign's
    built-in twin flies the training flight's PX4 gains (inertia, motors and drag stay the
    built-in's: a twin that is not the plant); its pick settles and damps the swing."""
    from swingrt.experiments.identification import case_twin

    train, train_sc, ev = _campaign_sample(497, "robustness-vehicle", seed=10)
    exp_twin = case_twin(_campaign_experiment(497, "robustness-vehicle", seed=10), train_sc)
    d, sample = exp_twin.to_dict(), train_sc.to_dict()
    for k in sysid.PX4_GAINS:
        assert d["controller"][k] == pytest.approx(sample["controller"][k]), k
    assert d["vehicle"]["mass"] == pytest.approx(sample["vehicle"]["mass"])
    assert d["vehicle"]["inertia"] != pytest.approx(sample["vehicle"]["inertia"])
    assert d["vehicle"]["motor_tau"] != pytest.approx(sample["vehicle"]["motor_tau"])
    mass = sample["vehicle"]["mass"]
    result = sysid.search(train, vehicle_mass=mass)
    nominal = sysid.select_for_control(train, result, twin=sysid.builtin_twin(mass))
    gains = sysid.select_for_control(train, result, twin=exp_twin)
    pid = _fly(ev, controller="pid")["swing_excess_iae_deg_s"]
    before, after = _fly(ev, nominal.model), _fly(ev, gains.model)
    assert math.isinf(before["v_settle_s"]) and before["swing_excess_iae_deg_s"] > pid
    assert after["v_settle_s"] < 6.0 and after["swing_excess_iae_deg_s"] < 0.2 * pid, after


def test_the_disturbance_rate_designed_on_the_twin_s_gust_takes_up_a_gust_in_flight():
    """Sample 341 of the vehicle-varied robustness campaign, seed 11 (0.46 kg on 0.39 m
    under a 0.78 kg vehicle, a 0.9 m/s headwind gust 12 s after the step): PX4's own swing
    excess is small, and the gust's swing, taken up late by the default disturbance rate,
    puts the MPC past the campaign's 0.4 of it. The pick passed on the twin, so its
    disturbance estimate is designed on the twin's gust: 2.5 times the default rate leaves
    less of the gust's swing there, and with a gust state beside it less again (0.43×
    PX4's swing in flight as set, 0.26× so designed); it passes every flight again, and
    the model carries it; in flight the same model with the default estimate fails the
    bound and with the designed one does not."""
    from swingrt.experiments.identification import case_twin

    train, train_sc, ev = _campaign_sample(341, "robustness-vehicle", seed=11)
    twin = case_twin(_campaign_experiment(341, "robustness-vehicle", seed=11), train_sc)
    result = sysid.search(train, vehicle_mass=train_sc.to_dict()["vehicle"]["mass"])
    model = sysid.select_for_control(train, result, twin=twin).model
    design = model.diagnostics["control_check"]["disturbance_design"]
    tried = {(t["factor"], t["gust_noise"]): t for t in design["tried"]}
    flown, raised = tried[(1.0, None)], tried[(2.5, None)]
    assert raised["passed"] and raised["gust_swing_iae"] < flown["gust_swing_iae"], design
    # With a gust state too, less again: that design is taken.
    both = tried[(2.5, 0.3)]
    assert both["passed"] and both["gust_swing_iae"] < raised["gust_swing_iae"], design
    assert design["factor"] == 2.5 and model.diagnostics["disturbance_noise"] == pytest.approx(0.05)
    assert design["gust_noise"] == 0.3 and model.diagnostics["gust_noise"] == pytest.approx(0.3)
    pid = _fly(ev, controller="pid")["swing_excess_iae_deg_s"]
    default = _fly(ev, model.with_diagnostics({"disturbance_noise": None, "gust_noise": None}))
    designed = _fly(ev, model)
    assert default["swing_excess_iae_deg_s"] > 0.4 * pid, (default, pid)
    assert designed["swing_excess_iae_deg_s"] < 0.35 * pid, (designed, pid)


def test_a_gust_state_keeps_a_late_gust_s_swing_under_the_bound():
    """Sample 395 of the robustness campaign, seed 1 (a 0.40 kg double pendulum on 0.38 m,
    a 1.9 m/s gust at 19.6 s): with the disturbance rate alone designed, the constant
    disturbance estimate answers the gust as lasting and carries its force past its end,
    the MPC brakes the vehicle to 1.8 m/s after it, and the flight ends at 0.405× PX4's
    swing excess (the campaign's bound 0.4). With a gust state, a force the MPC predicts to
    fade, the twin's gust leaves less swing, the design is taken, and the flight is well
    under the bound."""
    from swingrt.experiments.identification import case_twin

    train, train_sc, ev = _campaign_sample(395, "robustness", seed=1)
    twin = case_twin(_campaign_experiment(395, "robustness", seed=1), train_sc)
    result = sysid.search(train, vehicle_mass=train_sc.to_dict()["vehicle"]["mass"])
    model = sysid.select_for_control(train, result, twin=twin).model
    design = model.diagnostics["control_check"]["disturbance_design"]
    assert design["gust_noise"] == 0.3 and model.diagnostics["gust_noise"] == 0.3, design
    swing = {(t["factor"], t["gust_noise"]): t["gust_swing_iae"] for t in design["tried"]}
    rate_alone = min(swing[(f, None)] for f in (1.0, 2.5))
    assert swing[(design["factor"], 0.3)] < 0.9 * rate_alone, design
    pid = _fly(ev, controller="pid")["swing_excess_iae_deg_s"]
    alone = _fly(ev, model.with_diagnostics({"gust_noise": None, "disturbance_noise": 0.05}))
    designed = _fly(ev, model)
    ratio = designed["swing_excess_iae_deg_s"] / pid
    assert ratio < 0.38, (designed, pid)
    assert alone["swing_excess_iae_deg_s"] / pid > ratio + 0.02, (alone, designed, pid)


def test_the_imu_swing_s_trust_designed_on_the_twin_damps_from_the_model_in_flight():
    """The default step without a swing sensor, on sample 21 of the vehicle-varied study
    (a vehicle the built-in twin is not): an MPC that trusts the IMU's swing estimate as a
    measurement feeds its noise into the payload at the swing's own rate (the pick as
    designed leaves 1.5 deg·s of swing excess in flight). With the trust designed on the
    twin (``trust_factors``, off by default), the pick trusts the estimate less (a raised
    swing measurement noise, taken because the twin's step and gust swing less), the model
    carries it, and in flight the same model leaves under half the swing excess (0.3
    deg·s) and a smaller residual swing, within 1° of its final value from 4 s after the
    step. The price, which no twin flight shows: a swing already there when the MPC takes
    over (3.8°) is learned slowly, more swing excess than the pick as designed; the
    filter's start (``kf_start_spread``, off by default) learns it faster."""
    from swingrt.experiments.identification import identify_case

    train, train_sc, ev = _campaign_sample(21, "default-step-imu-vehicle")
    exp = _campaign_experiment(21, "default-step-imu-vehicle")
    exp = dataclasses.replace(exp, selection={**exp.selection, "trust_factors": [1, 10, 30, 100]})
    model, _, _ = identify_case(train, exp, vehicle=train_sc)
    design = model.diagnostics["control_check"]["trust_design"]
    as_designed, taken = (
        design["tried"][0],
        next(t for t in design["tried"] if t["factor"] == design["factor"]),
    )
    assert design["factor"] > 1.0 and taken["passed"], design
    assert taken["cost"] < as_designed["cost"], design
    assert model.diagnostics["swing_measurement_noise"] == pytest.approx(
        design["kf_swing_measurement_noise"]
    )
    pid = _fly(ev, controller="pid")
    trusting_model = model.with_diagnostics(
        {"swing_measurement_noise": as_designed["kf_swing_measurement_noise"]}
    )
    trusting = _fly(ev, trusting_model)
    designed = _fly(ev, model)
    assert designed["swing_excess_iae_deg_s"] < 0.5 * trusting["swing_excess_iae_deg_s"], (
        designed,
        trusting,
    )
    assert designed["residual_swing_deg"] < min(1.0, trusting["residual_swing_deg"])
    assert designed["swing_excess_iae_deg_s"] < 0.05 * pid["swing_excess_iae_deg_s"]
    swinging = ev.with_overrides({"payload": {"initial_swing_n": math.radians(3.8)}})
    slow = _fly(swinging, model)["swing_excess_iae_deg_s"]
    trusting_released = _fly(swinging, trusting_model)["swing_excess_iae_deg_s"]
    assert slow > 1.5 * trusting_released, (slow, trusting_released)
    # (As measured: 2.9 deg·s without the start, 1.5 as designed; with the candidates
    # ranked on the step alone, before `pick_on_gust`, 7.8 and 1.9, and 2.0 with the start.)
    started = _fly(swinging, model, mpc_settings={"kf_start_spread": 3.0})
    assert started["swing_excess_iae_deg_s"] < 1.2 * trusting_released, (started, slow)


def test_a_raised_disturbance_rate_that_needs_the_twin_s_attitude_loop_is_refused():
    """Sample 61 of the vehicle-varied robustness campaign, seed 13: a double pendulum on a
    vehicle with slow motors (38 ms against the twin's 15) and 1.56 times the twin's pitch
    inertia. On the nominal twin the pick's disturbance rate raised 2.5 times passes every
    flight and leaves less of the gust's swing, so it is taken, and on the vehicle the
    velocity never settles. On the slow vehicle (40 ms motors, 1.5 times the inertia) the
    raised rate is refused, and the same pick with the rate as set damps the swing."""
    from swingrt.experiments.identification import case_twin

    train, train_sc, ev = _campaign_sample(61, "robustness-vehicle", seed=13)
    twin = case_twin(_campaign_experiment(61, "robustness-vehicle", seed=13), train_sc)
    result = sysid.search(train, vehicle_mass=train_sc.to_dict()["vehicle"]["mass"])
    # The rate alone designed (no gust state), as when this rule was set.
    nominal = sysid.select_for_control(
        train, result, twin=twin, slow_motor_lag=0.0, slow_inertia=1.0, gust_noise=0.0
    ).model
    assert nominal.diagnostics["control_check"]["disturbance_design"]["factor"] == 2.5
    assert nominal.diagnostics["control_check"]["slow_vehicle"] is None
    model = sysid.select_for_control(train, result, twin=twin, gust_noise=0.0).model
    cc = model.diagnostics["control_check"]
    assert "1.5× its inertia" in cc["slow_vehicle"], cc["slow_vehicle"]
    assert (model.delays, model.rank) == (nominal.delays, nominal.rank)
    flown, raised = cc["disturbance_design"]["tried"]
    assert flown["passed"] and not raised["passed"], cc["disturbance_design"]
    assert cc["disturbance_design"]["factor"] == 1.0
    pid = _fly(ev, controller="pid")["swing_excess_iae_deg_s"]
    picked = _fly(ev, model)
    assert math.isfinite(picked["v_settle_s"]), picked
    assert picked["swing_excess_iae_deg_s"] < 0.1 * pid, (picked, pid)
    assert math.isinf(_fly(ev, nominal)["v_settle_s"])
    # As shipped, the gust state (taken on the nominal twin) is refused on the slow vehicle
    # too, with the rate as set or raised: the pick flies its estimator as designed.
    shipped = sysid.select_for_control(train, result, twin=twin).model
    design = shipped.diagnostics["control_check"]["disturbance_design"]
    assert (design["factor"], design["gust_noise"]) == (1.0, None), design
    assert [t["passed"] for t in design["tried"]] == [True, False, False, False], design
    flown = _fly(ev, shipped)
    assert math.isfinite(flown["v_settle_s"]), flown
    assert flown["swing_excess_iae_deg_s"] < 0.1 * pid, (flown, pid)


@pytest.mark.parametrize("mass", [0.0, -1.0, math.nan, math.inf, 0.05])
def test_a_twin_of_no_mass_is_refused_by_name(mass):
    """No mass, or one so small that the twin's motors, scaled to it, cannot lift even the
    built-in payload: refused naming the vehicle's mass, not a payload field."""
    with pytest.raises(ConfigError, match="vehicle_mass"):
        sysid.builtin_twin(mass)


def test_a_pick_that_hangs_on_the_payload_s_estimated_lengths_is_refused():
    """Sample 49 of the vehicle-varied robustness campaign, seed 12: a double pendulum (0.27
    kg on 0.73 m, 0.19 kg 0.54 m below) whose links the fit finds within 5 % (0.77 / 0.53
    m). On the nominal twin alone the low-order q = 6, p = 6 passes and is picked, and on
    the vehicle it never settles; flown also with the twin's links 10 % shorter and longer
    (the default payload tolerance), it is refused for that, and the pick flies within the
    campaign's bounds. (The slow vehicle refuses it too; it is switched off here so that
    the tolerance is tested alone.)"""
    from swingrt.experiments.identification import case_twin

    train, train_sc, ev = _campaign_sample(49, "robustness-vehicle", seed=12)
    twin = case_twin(_campaign_experiment(49, "robustness-vehicle", seed=12), train_sc)
    result = sysid.search(train, vehicle_mass=train_sc.to_dict()["vehicle"]["mass"])
    fast = {"slow_motor_lag": 0.0, "slow_inertia": 1.0}
    nominal = sysid.select_for_control(
        train, result, twin=twin, payload_tolerance=0.0, **fast
    ).model
    assert (nominal.delays, nominal.rank) == (6, 6)
    model = sysid.select_for_control(train, result, twin=twin, **fast).model
    checked = model.diagnostics["control_check"]["checked"]
    fragile = next(c for c in checked if (c["delays"], c["rank"]) == (6, 6))
    assert fragile["payload_miss"] > 1.0, fragile
    assert len(fragile["refused"]) == 1, fragile
    assert "payload's lengths off by the tolerance" in fragile["refused"][0], fragile
    assert (model.delays, model.rank) != (6, 6)
    pid = _fly(ev, controller="pid")["swing_excess_iae_deg_s"]
    picked = _fly(ev, model)
    assert math.isfinite(picked["v_settle_s"]), picked
    assert picked["swing_excess_iae_deg_s"] < 0.4 * pid, (picked, pid)
    assert math.isinf(_fly(ev, nominal)["v_settle_s"])
