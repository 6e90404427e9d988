"""The simulator from Python and the CLI: API, files, determinism, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

import swingrt
from swingrt.errors import ConfigError, SwingrtError

DESIGN_COLUMNS = (
    "t pn pe pd vn ve vd roll pitch yaw swing_n swing_e swing_rate_n swing_rate_e "
    "acc_sp_n acc_sp_e acc_sp_d vel_sp_n vel_sp_e vel_sp_d"
).split()


def test_simulate_default_step_has_design_columns_and_swings():
    tr = swingrt.simulate(duration=10.0)
    for c in DESIGN_COLUMNS:
        assert c in tr.columns, c
    t = tr.t
    assert np.allclose(np.diff(t), 0.01)
    assert t[-1] == pytest.approx(10.0)
    # The 2 m/s North step at t = 2 s: velocity reaches it, payload swings South of the
    # vehicle (negative swing_n) while accelerating North.
    assert tr["vel_sp_n"][t < 1.9].max() == 0.0
    assert tr["vel_sp_n"][t > 2.1].min() == 2.0
    assert abs(tr["vn"][-1] - 2.0) < 0.1
    assert tr["swing_n"].min() < -math.radians(10)
    assert "swing2_n" not in tr.columns


def test_same_seed_same_trace_other_seed_other_noise():
    cfg = {"noise": {"swing_std": 0.01}}
    a = swingrt.simulate(cfg, duration=3.0, seed=4)
    b = swingrt.simulate(cfg, duration=3.0, seed=4)
    c = swingrt.simulate(cfg, duration=3.0, seed=5)
    for k in a.columns:
        assert np.array_equal(a[k], b[k], equal_nan=True), k
    assert not np.array_equal(a["swing_n"], c["swing_n"])


def test_double_pendulum_logs_the_hidden_link():
    tr = swingrt.simulate({"payload": {"kind": "double"}}, duration=6.0)
    assert "swing2_n" in tr.columns
    assert np.abs(tr["swing2_n"]).max() > 0.05


def test_collect_follows_table_4_1():
    tr = swingrt.collect(duration=120.0, seed=1)
    vsp = tr["vel_sp_n"]
    changes = tr.t[1:][np.abs(np.diff(vsp)) > 1e-9]
    assert len(changes) >= 4
    gaps = np.diff(changes)
    assert gaps.min() >= 10.0 - 0.011 and gaps.max() <= 25.0 + 0.011
    assert vsp.min() >= 0.0 and vsp.max() <= 3.0


def test_parquet_and_csv_round_trip(tmp_path):
    tr = swingrt.simulate(duration=2.0)
    tr.to_parquet(tmp_path / "a.parquet")
    back = swingrt.Trace.from_parquet(tmp_path / "a.parquet")
    for k in tr.columns:
        assert np.array_equal(tr[k], back[k], equal_nan=True)
    assert back.meta["scenario"]["payload"]["mass"] == 0.2
    tr.to_csv(tmp_path / "a.csv")
    data = np.genfromtxt(tmp_path / "a.csv", delimiter=",", names=True)
    assert np.allclose(data["vn"], tr["vn"], rtol=1e-8, atol=1e-12)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "a.parquet"]


def test_steppable_simulator_takes_per_axis_setpoints():
    sim = swingrt.Simulator(duration=100.0)
    sim.set_setpoint(n=("acc", 0.0), e=("vel", 1.0), d=("pos", -12.0))
    sim.advance(8.0)
    s = sim.state()
    assert s["t"] == pytest.approx(8.0)
    assert s["ve"] == pytest.approx(1.0, abs=0.05)
    assert s["pd"] == pytest.approx(-12.0, abs=0.1)
    assert s["acc_sp_n"] == 0.0
    with pytest.raises(ConfigError, match="mode"):
        sim.set_setpoint(n=("jerk", 1.0))
    with pytest.raises(ConfigError, match="axis"):
        sim.set_setpoint(x=("vel", 1.0))
    with pytest.raises(ConfigError, match="dt"):
        sim.advance(float("nan"))
    assert len(sim.trace()) == 800  # samples at 0, 0.01, …, 7.99 s


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("[payload]\nmasss = 0.2\n", "payload.masss"),
        ("[payload]\nmass = -0.1\n", "payload.mass"),
        ("[payload]\nlength = 0.0\n", "payload.length"),
        ("duration = nan\n", "duration"),
        (
            "[wind]\nsteps = [{ t = 1.0, velocity = [1.0, nan, 0.0] }]\n",
            "wind.steps[0].velocity[1]",
        ),
        ("[vehicle]\ninertia = [1e-3, 1e-3]\n", "vehicle.inertia"),
        ("[[setpoints]]\nt = 1.0\nvn = 1.0\nan = 0.5\n", "setpoints[0].an"),
        ("[controller]\nrate_loop_hz = 300.0\n", "controller.rate_loop_hz"),
        ("[payload]\nkind = 'triple'\n", "payload.kind"),
        ("[payload\nmass = 1\n", "bad.toml"),
    ],
)
def test_bad_scenarios_name_the_field_from_python_and_cli(tmp_path, cli, text, field):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as exc:
        swingrt.simulate(path)
    assert field in str(exc.value)
    assert isinstance(exc.value, ValueError) and isinstance(exc.value, SwingrtError)
    out = tmp_path / "out.parquet"
    r = cli("simulate", path, "-o", out)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("swingrt: error:") and field in lines[0]
    assert "Traceback" not in r.stderr
    assert not out.exists() and list(tmp_path.iterdir()) == [path]


def test_cli_simulate_writes_trace_and_summary(tmp_path, cli):
    out = tmp_path / "trace.parquet"
    r = cli("simulate", "--duration", "12", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "peak swing" in r.stdout and "overshoot" in r.stdout
    tr = swingrt.Trace.from_parquet(out)
    assert tr.t[-1] == pytest.approx(12.0)


def test_cli_rejects_bad_output_and_missing_file(tmp_path, cli):
    r = cli("simulate", "-o", tmp_path / "x.txt")
    assert r.returncode == 2 and "parquet" in r.stderr
    r = cli("simulate", tmp_path / "missing.toml")
    assert r.returncode == 2 and "missing.toml" in r.stderr


def test_summary_metrics_match_hand_computation():
    t = np.arange(0, 10.0001, 0.01)
    step = t >= 2.0
    vn = np.where(step, 2.0 * (1 - np.exp(-(t - 2.0))), 0.0)
    swing = np.where(step, np.radians(5.0) * np.exp(-(t - 2.0)), 0.0)
    z = np.zeros_like(t)
    cols = dict(t=t, vn=vn, ve=z, swing_n=swing, swing_e=z, acc_sp_n=z, acc_sp_e=z)
    cols.update(vel_sp_n=np.where(step, 2.0, 0.0), vel_sp_e=z)
    m = swingrt.step_metrics(swingrt.Trace(cols), t0=2.0)
    assert m["peak_swing_deg"] == pytest.approx(5.0, rel=1e-9)
    # |swing| < 1° from t − 2 = ln 5 on.
    assert m["swing_settle_s"] == pytest.approx(math.log(5.0), abs=0.011)
    # IAE of 5° e^{−t} over 8 s minus the final value offset (tiny).
    assert m["swing_iae_deg_s"] == pytest.approx(5.0 * (1 - math.exp(-8.0)), rel=0.02)
    assert m["overshoot_pct"] == 0.0
    assert m["v_settle_s"] == pytest.approx(math.log(20.0), abs=0.011)


def test_swing_iae_floor_is_the_payload_momentum_change():
    """Only the cable accelerates the payload horizontally: ∫(swing − final) dt ≈ Δv_p/g
    (a little less with payload drag), so no controller's swing IAE can go below it."""
    from swingrt.metrics import swing_iae_floor

    trace = swingrt.simulate({}, seed=0)
    t = trace.t
    vp = np.gradient(trace["payload_pn"], t)
    dv = float(np.mean(vp[t > t[-1] - 2.0]) - np.mean(vp[(t > 1.0) & (t < 2.0)]))
    floor = swing_iae_floor(trace, t0=2.0)
    bound = math.degrees(dv / swingrt._core.GRAVITY)
    assert 0.9 * bound < floor < 1.03 * bound, (floor, bound, dv)
    assert swingrt.step_metrics(trace, t0=2.0)["swing_iae_deg_s"] >= floor
    # Hand-computed on a synthetic swing: a 5° bump of 1 s ∫ = 5·(2/π) deg·s, sign dropped.
    tt = np.arange(0, 12.0001, 0.01)
    bump = np.where((tt >= 2.0) & (tt < 3.0), -np.radians(5.0) * np.sin(np.pi * (tt - 2.0)), 0.0)
    z = np.zeros_like(tt)
    cols = dict(t=tt, vn=z, ve=z, swing_n=bump, swing_e=z, acc_sp_n=z, acc_sp_e=z)
    cols.update(vel_sp_n=np.where(tt >= 2.0, 1.0, 0.0), vel_sp_e=z)
    assert swing_iae_floor(swingrt.Trace(cols), t0=2.0) == pytest.approx(10 / math.pi, rel=0.01)


def test_config_error_carries_the_dotted_field():
    with pytest.raises(ConfigError, match="payload.mass") as info:
        swingrt.simulate({"payload": {"mass": -0.1}}, duration=1.0)
    assert info.value.field == "payload.mass"
    assert ConfigError("exp.toml: axes: must be 'n' or 'ne'").field == "axes"
    assert ConfigError("unknown experiment 'x'").field is None
    assert ConfigError("anything", field="mpc.horizon").field == "mpc.horizon"


def _step_trace(t, swing, acc_n=None, acc_e=None):
    z = np.zeros_like(t)
    cols = dict(t=t, vn=np.where(t >= 2.0, 1.0, 0.0), ve=z, swing_n=swing, swing_e=z)
    cols.update(acc_sp_n=z if acc_n is None else acc_n, acc_sp_e=z if acc_e is None else acc_e)
    cols.update(vel_sp_n=np.where(t >= 2.0, 1.0, 0.0), vel_sp_e=z)
    return swingrt.Trace(cols)


def test_residual_swing_and_swing_free_time_of_a_decaying_oscillation():
    """swing = A e^{−s/τ} cos(ω s) after the step (s = t − 2): with a peak at s = 4 exactly
    the residual is A e^{−4/τ}; the last time |swing| ≥ 0.25° lies within half a period
    before τ ln(A / 0.25°) (the envelope's crossing)."""
    a, tau, period = 6.0, 3.0, 1.0  # deg, s, s (s = 4 is a peak: 4 / period is whole)
    t = np.arange(0.0, 40.0001, 0.001)
    s = np.clip(t - 2.0, 0.0, None)
    swing = np.where(t >= 2.0, np.radians(a * np.exp(-s / tau) * np.cos(2 * np.pi * s / period)), 0)
    m = swingrt.step_metrics(_step_trace(t, swing), t0=2.0)
    assert m["residual_swing_deg"] == pytest.approx(a * math.exp(-4.0 / tau), rel=1e-6)
    # The velocity is steady from the step on: no lean, the oscillation is the swing.
    assert m["residual_oscillation_deg"] == pytest.approx(m["residual_swing_deg"], rel=1e-9)
    crossing = tau * math.log(a / 0.25)
    assert crossing - period / 2 - 0.002 <= m["swing_free_s"] <= crossing + 0.002
    # The 1° band of swing_settle_s is reached earlier: the envelope crosses it at τ ln(A).
    assert m["swing_settle_s"] <= tau * math.log(a) + 0.002 < m["swing_free_s"]
    # Swing of both signs: the IAE is above the momentum floor, the excess is the rest.
    from swingrt.metrics import swing_iae_floor

    floor = swing_iae_floor(_step_trace(t, swing), t0=2.0)
    assert m["swing_excess_iae_deg_s"] == pytest.approx(m["swing_iae_deg_s"] - floor)
    assert m["swing_excess_iae_deg_s"] > 0.5 * m["swing_iae_deg_s"]


def test_residual_oscillation_is_the_swing_about_the_lean_the_acceleration_asks():
    """A step approached exponentially, v = 2(1 − e^{−s/τ}) (s = t − 2), leans the payload
    by −atan(a/g), a = (2/τ)e^{−s/τ}. The metric reads a over a centred span 2h, which for
    the exponential is a·sinh(h/τ)/(h/τ): on that lean alone the residual swing from 4 s is
    the lean at s = 4 (0.79° at τ = 2 s) and the residual oscillation only the span's
    reading error there; a swing A e^{−s/5} cos(πs) about the lean (a peak at s = 4) adds
    A e^{−4/5}, whichever way the step goes."""
    from swingrt.metrics import LEAN_SPAN_S

    tau, amp, g = 2.0, 0.5, 9.80665
    t = np.arange(0.0, 40.0001, 0.001)
    s = np.clip(t - 2.0, 0.0, None)
    on = t >= 2.0
    acc = np.where(on, (2.0 / tau) * np.exp(-s / tau), 0.0)
    lean = -np.arctan(acc / g)
    wobble = np.where(on, np.radians(amp * np.exp(-s / 5.0) * np.cos(np.pi * s)), 0.0)
    x = 0.5 * LEAN_SPAN_S / tau
    a4 = (2.0 / tau) * math.exp(-4.0 / tau)
    misread = math.degrees(math.atan(a4 * math.sinh(x) / x / g) - math.atan(a4 / g))
    for sign in (1.0, -1.0):
        for swing, expected in ((lean, misread), (lean + wobble, amp * math.exp(-0.8) + misread)):
            tr = _step_trace(t, sign * swing)
            tr["vn"] = sign * np.where(on, 2.0 * (1.0 - np.exp(-s / tau)), 0.0)
            tr["vel_sp_n"] = sign * np.where(on, 2.0, 0.0)
            m = swingrt.step_metrics(tr, t0=2.0)
            assert m["residual_oscillation_deg"] == pytest.approx(expected, abs=0.001), sign
            if swing is lean:
                # Yet the swing is still the lean's 0.79° away from its final value.
                assert m["residual_swing_deg"] == pytest.approx(
                    math.degrees(math.atan(a4 / g)), abs=0.01
                )


def test_residual_oscillation_does_not_read_a_wobble_the_payload_cannot_follow():
    """The vehicle settled at 2 m/s wobbles by b sin(ωs) at 1.4 Hz. A payload on 1 m
    (ω₀² = g/l) answers its acceleration a_w = bω cos(ωs) with θ = (a_w/g)·ω₀²/(ω² − ω₀²),
    0.15 of the quasi-static lean and the other way round: the swing left is that forced
    answer (0.22° for b = 0.03 m/s), and the metric may add at most the span's leak of the
    quasi-static lean, |sin(ωh)/(ωh)| of it (h half the span). A quasi-static reading would
    count the whole 1.5° lean."""
    from swingrt.metrics import LEAN_SPAN_S

    g, b, w = 9.80665, 0.03, 2.0 * math.pi * 1.4
    w0sq = g / 1.0
    t = np.arange(0.0, 40.0001, 0.001)
    s = np.clip(t - 2.0, 0.0, None)
    on = t >= 2.0
    aw = b * w * np.cos(w * s)
    tr = _step_trace(t, np.where(on, (aw / g) * w0sq / (w**2 - w0sq), 0.0))
    tr["vn"] = np.where(on, 2.0 + b * np.sin(w * s), 0.0)
    tr["vel_sp_n"] = np.where(on, 2.0, 0.0)
    m = swingrt.step_metrics(tr, t0=2.0)
    forced = math.degrees(b * w / g * w0sq / (w**2 - w0sq))
    quasi = math.degrees(b * w / g)
    h = 0.5 * LEAN_SPAN_S
    leak = abs(math.sin(w * h) / (w * h)) * quasi
    # (within the final span's mean of the wobble, which is not a whole number of periods)
    assert m["residual_swing_deg"] == pytest.approx(forced, abs=0.01)
    assert forced - leak - 0.01 <= m["residual_oscillation_deg"] <= forced + leak + 0.01
    assert m["residual_oscillation_deg"] < 0.5 * quasi


def test_a_one_signed_swing_has_no_excess_above_the_floor():
    t = np.arange(0.0, 12.0001, 0.01)
    bump = np.where((t >= 2.0) & (t < 3.0), -np.radians(5.0) * np.sin(np.pi * (t - 2.0)), 0.0)
    m = swingrt.step_metrics(_step_trace(t, bump), t0=2.0)
    assert abs(m["swing_excess_iae_deg_s"]) < 1e-9
    assert m["residual_swing_deg"] == pytest.approx(0.0, abs=1e-12)


def test_acc_sp_tv_of_a_staircase():
    """North 0 → 1 → −0.5 → 0.5, East 0 → 0.3 after the step, and a jump before it that
    does not count: TV = 1 + 1.5 + 1 + 0.3 = 3.8 m/s²."""
    from swingrt.metrics import acc_sp_tv

    t = np.arange(0.0, 12.0001, 0.01)
    an = np.select([t < 1.0, t < 3.0, t < 5.0, t < 7.0], [2.0, 0.0, 1.0, -0.5], 0.5)
    ae = np.where(t >= 8.0, 0.3, 0.0)
    m = swingrt.step_metrics(_step_trace(t, np.zeros_like(t), an, ae), t0=2.0)
    assert m["acc_sp_tv"] == pytest.approx(3.8, rel=1e-12)
    # A simultaneous (N, E) change counts as one vector step.
    assert acc_sp_tv([0.0, 0.3], [0.0, 0.4]) == pytest.approx(0.5)
    assert acc_sp_tv([1.0]) == 0.0
