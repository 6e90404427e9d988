"""Swing-damping control from Python: bindings, closed loop, experiments, run."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest

import swingrt
from swingrt import _core
from swingrt.errors import ConfigError, ControlError, ModelError
from swingrt.experiments import simulate_controller
from swingrt.metrics import step_metrics
from swingrt.scenario import resolve


@pytest.fixture(scope="module")
def default_models():
    """The main job's identification: 300 s training flight, DMDc search, white box."""
    train = swingrt.collect(seed=0)
    model = swingrt.identify(train, search=True)
    wb = swingrt.identify(train, method="whitebox")
    est = wb.diagnostics["whitebox"]
    lqr = {"m_q": est["vehicle_mass"], "m_p": est["payload_mass"], "l": est["length"], "c": 0.0}
    return model, lqr


def test_mpc_damps_the_default_step_to_a_third_of_pid(default_models):
    model, lqr = default_models
    sc = resolve({"duration": 30.0}, default="step", seed=1)
    runs = {
        c: simulate_controller(sc, c, model=model, lqr_params=lqr)[0] for c in ("pid", "lqr", "mpc")
    }
    m = {c: step_metrics(tr, t0=2.0) for c, tr in runs.items()}
    assert m["mpc"]["swing_iae_deg_s"] <= m["pid"]["swing_iae_deg_s"] / 3
    assert m["lqr"]["swing_iae_deg_s"] <= m["pid"]["swing_iae_deg_s"] / 3
    assert m["mpc"]["ss_error"] <= 0.02
    # The MPC commanded the axis for the whole run and never fell back.
    assert runs["mpc"]["ctrl_active"][-1] == 1.0 and runs["mpc"]["fallback"].max() == 0.0


def test_wind_step_has_no_steady_state_error_with_mpc(default_models):
    model, lqr = default_models
    sc = resolve(
        {"duration": 40.0, "wind": {"steps": [{"t": 8.0, "velocity": [2.0, 0.0, 0.0]}]}},
        default="step",
        seed=2,
    )
    tr, extras = simulate_controller(sc, "mpc", model=model)
    assert extras["fallback"] is None
    assert step_metrics(tr, t0=2.0)["ss_error"] <= 0.02


def test_mpc_binding_steps_and_checks_its_inputs(default_models):
    model, _ = default_models
    mpc = _core.Mpc(model, {"horizon": 100, "control_horizon": 20})
    assert mpc.axes == 1 and mpc.period == pytest.approx(model.dt)
    state = np.array([[0.0, 0.0, 0.0]])
    mpc.reset(state, np.array([0.0]))
    a = mpc.step(state, np.array([2.0]))
    # Accelerates towards the 2 m/s reference; the input-rate weight spreads the first
    # move (about 0.4 m/s²) over the next ticks.
    assert a.shape == (1,) and a[0] > 0.3
    pred = mpc.predicted()
    assert pred.shape == (100, 1, 3)
    with pytest.raises(swingrt.errors.DataError):
        mpc.step(np.array([[np.nan, 0.0, 0.0]]), np.array([1.0]))
    with pytest.raises(ConfigError, match="horizon"):
        _core.Mpc(model, {"horizon": 0})
    with pytest.raises(ConfigError, match="settings.w_swnig"):
        _core.Mpc(model, {"w_swnig": 1.0})
    with pytest.raises(ModelError):
        swingrt.LinearModel.from_json("{}")


def test_riccati_bindings_solve_their_equations():
    a = np.array([[0.0, 1.0], [-2.0, -0.1]])
    b = np.array([[0.0], [1.0]])
    q, r = np.diag([3.0, 1.0]), np.array([[0.5]])
    k, p = _core.care(a, b, q, r)
    res = a.T @ p + p @ a - p @ b @ np.linalg.solve(r, b.T) @ p + q
    assert np.abs(res).max() < 1e-9 * np.abs(p).max()
    assert np.allclose(k, np.linalg.solve(r, b.T @ p))
    ad = np.eye(2) + 0.05 * a
    bd = 0.05 * b
    kd, pd = _core.dare(ad, bd, q, r)
    s = r + bd.T @ pd @ bd
    res = ad.T @ pd @ ad - pd - ad.T @ pd @ bd @ np.linalg.solve(s, bd.T @ pd @ ad) + q
    assert np.abs(res).max() < 1e-8 * np.abs(pd).max()
    assert np.all(np.abs(np.linalg.eigvals(ad - bd @ kd)) < 1.0)
    with pytest.raises((ControlError, ConfigError)):
        _core.care(np.zeros((2, 2)), np.zeros((2, 1)), q, r)  # not stabilisable


def test_experiment_list_and_a_small_experiment(tmp_path, cli):
    r = cli("experiment", "--list")
    assert r.returncode == 0
    for name in ("payload-grid", "wind-step", "double-pendulum", "mass-change", "diagonal-step"):
        assert name in r.stdout
    spec = tmp_path / "mini.toml"
    spec.write_text(
        'name = "mini"\ncontrollers = ["pid", "mpc"]\nduration = 12.0\n'
        "training_duration = 200.0\nprediction_figure = true\n"
        'step = { t = 2.0, vn = 1.5 }\n[grid]\n"payload.length" = [0.8]\n'
    )
    out = tmp_path / "out"
    r = cli("experiment", spec, "--out", out, "--quiet")
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(io.StringIO((out / "metrics.csv").read_text())))
    assert list(rows[0]) == [
        "scenario",
        "controller",
        "peak_swing_deg",
        "swing_settle_s",
        "swing_iae_deg_s",
        "overshoot_pct",
        "v_settle_s",
        "ss_error",
        "effort",
        "swing_excess_iae_deg_s",
        "residual_swing_deg",
        "residual_oscillation_deg",
        "swing_free_s",
        "acc_sp_tv",
    ]
    assert [(x["scenario"], x["controller"]) for x in rows] == [("l0.8", "pid"), ("l0.8", "mpc")]
    for f in ("l0.8__pid.parquet", "l0.8__mpc.parquet", "l0.8.png", "metrics.md"):
        assert (out / f).is_file(), f
    assert (out / "l0.8__prediction.png").is_file()
    tr = swingrt.Trace.from_parquet(out / "l0.8__mpc.parquet")
    assert tr.meta["controller"] == "mpc"


def test_bad_experiment_definitions_name_the_key(tmp_path, cli):
    spec = tmp_path / "bad.toml"
    spec.write_text('name = "x"\ncontrolers = ["pid"]\n')
    r = cli("experiment", spec)
    assert r.returncode == 2 and "controlers" in r.stderr and "Traceback" not in r.stderr
    r = cli("experiment", "no-such-experiment")
    assert r.returncode == 2 and "payload-grid" in r.stderr


def test_controller_settings_errors_are_config_errors(default_models):
    model, _ = default_models
    sc = resolve({"duration": 5.0}, default="step")
    with pytest.raises(ConfigError, match="mpc.horizon"):
        simulate_controller(sc, "mpc", model=model, mpc_settings={"horizon": "long"})
    json.loads(model.to_json())  # the model itself stays valid


def test_a_typo_in_an_experiment_fails_before_anything_flies(tmp_path, cli):
    """Every section is checked by the core when the file is loaded: a misspelt field of
    [identify], [mpc], [lqr] or a scenario section fails in well under a second with one line
    naming the file and the dotted field."""
    import time

    from swingrt.experiments import load_experiment

    for section, line, field in [
        ("identify", "serch = true", "identify.serch"),
        ("mpc", "horizn = 100", "mpc.horizn"),
        ("lqr", "r = -1.0", "lqr.r"),
        ("common.payload", "masss = 0.3", "payload.masss"),
        ("training.wind", "velocity = [1.0, 0.0]", "wind.velocity"),
    ]:
        spec = tmp_path / f"{section}.toml"
        spec.write_text(f'name = "typo"\n[{section}]\n{line}\n')
        t0 = time.perf_counter()
        with pytest.raises(ConfigError) as info:
            load_experiment(str(spec))
        assert time.perf_counter() - t0 < 1.0
        assert str(spec) in str(info.value) and field in str(info.value), info.value
        assert info.value.field is not None and info.value.field.endswith(field.split(".")[-1])
    r = cli("experiment", tmp_path / "identify.toml")
    assert r.returncode == 2 and "identify.serch" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


def test_compare_mpc_lqr_names_the_better_controller_and_the_alike_metrics():
    from swingrt.experiments.notes import COMPARED, compare_mpc_lqr

    lqr = dict.fromkeys(COMPARED, 1.0)
    mpc = {**lqr, "peak_swing_deg": 0.5, "acc_sp_tv": 3.0}
    text = compare_mpc_lqr(mpc, lqr)
    assert "peak_swing_deg MPC (0.5 MPC vs 1 LQR)" in text
    assert "acc_sp_tv LQR (3 MPC vs 1 LQR)" in text
    assert "alike (within 20%): swing_excess_iae_deg_s" in text
