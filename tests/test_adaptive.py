"""Payload events in scenarios, the adaptive MPC on the simulator, the payload-change
experiment and the adaptive timing, through the installed wheel."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from swingrt import _core
from swingrt.campaign.flight import SWING_EXCESS_MIN
from swingrt.errors import ConfigError
from swingrt.scenario import resolve


def _run(overrides: dict) -> dict[str, np.ndarray]:
    sc = resolve(overrides, default="step")
    sim = _core.Simulator(sc)
    sim.run_to_end()
    return {k: np.asarray(v) for k, v in sim.take_trace().items()}


def _at(trace: dict[str, np.ndarray], col: str, t: float) -> float:
    return float(trace[col][np.searchsorted(trace["t"], t)])


def test_winch_shortens_the_cable_at_its_rate_and_stops_at_the_target():
    tr = _run(
        {
            "duration": 10.0,
            "setpoints": [{"t": 0.0, "vn": 0.0}],
            "payload": {
                "length": 2.0,
                "events": [{"t": 1.0, "action": "winch", "length": 0.5, "rate": 0.3}],
            },
        }
    )
    cable = np.hypot(
        np.hypot(tr["payload_pn"] - tr["pn"], tr["payload_pe"] - tr["pe"]),
        tr["payload_pd"] - tr["pd"],
    )
    assert _at({"t": tr["t"], "c": cable}, "c", 0.5) == pytest.approx(2.0, abs=1e-6)
    # 2 s into the winch: 0.6 m reeled in.
    assert _at({"t": tr["t"], "c": cable}, "c", 3.0) == pytest.approx(1.4, abs=0.01)
    assert cable[-1] == pytest.approx(0.5, abs=1e-6)


def test_a_payload_picked_up_in_hover_then_dropped_swings_only_while_carried():
    tr = _run(
        {
            "duration": 12.0,
            "setpoints": [{"t": 0.0, "vn": 0.0}, {"t": 3.0, "vn": 1.0}, {"t": 6.0, "vn": 0.0}],
            "payload": {
                "kind": "none",
                "events": [
                    {"t": 1.0, "action": "attach", "mass": 0.3, "length": 1.5},
                    {"t": 8.0, "action": "detach"},
                ],
            },
        }
    )
    t, swing = tr["t"], tr["swing_true_n"]
    assert np.all(swing[t < 1.0] == 0.0)
    assert np.max(np.abs(swing[(t > 3.0) & (t < 8.0)])) > np.radians(2.0)
    assert np.all(swing[t > 8.01] == 0.0)
    # Picked up at rest below the vehicle: the cable hangs 1.5 m straight down.
    assert _at(tr, "payload_pd", 1.5) - _at(tr, "pd", 1.5) == pytest.approx(1.5, abs=1e-3)


@pytest.mark.parametrize(
    ("event", "field"),
    [
        ({"t": 1.0, "action": "attach", "length": 1.0}, "payload.events[0].mass"),
        ({"t": 1.0, "action": "winch", "length": -1.0, "rate": 0.3}, "payload.events[0].length"),
        ({"t": 1.0, "action": "detach", "rate": 0.3}, "payload.events[0].rate"),
        ({"t": 1.0, "action": "attach", "mass": 0.3, "length": 1.0}, "payload.events[0].action"),
        ({"t": 1.0, "action": "teleport"}, "payload.events"),
        ({"t": 1.0, "action": "attach", "mass": 9.0, "length": 1.0}, "payload.events"),
    ],
)
def test_bad_payload_events_name_the_field(event, field):
    payload: dict = {"events": [event]}
    if event.get("mass") == 9.0:
        payload["kind"] = "none"
    with pytest.raises(ConfigError) as exc:
        resolve({"payload": payload}, default="step")
    assert exc.value.field is not None and exc.value.field.startswith(field), exc.value


def test_adaptive_settings_have_defaults_and_checked_fields():
    s = _core.check_settings("adaptive")
    assert 0.0 < s["online"]["forgetting"] <= 1.0
    assert s["synthesis"] == "deferred"
    with pytest.raises(ConfigError) as exc:
        _core.check_settings("adaptive", {"online": {"forgetting": 1.5}})
    assert exc.value.field == "adaptive.online.forgetting"
    with pytest.raises(ConfigError) as exc:
        _core.check_settings("adaptive", {"probe_amplitud": 0.1})
    assert "probe_amplitud" in str(exc.value)


def test_adaptive_mpc_without_a_swap_flies_exactly_as_the_fixed_mpc():
    model = _core.pendulum_model(delays=4, axes=1)
    traces = {}
    for kind in ("mpc", "mpc_adaptive"):
        sim = _core.Simulator(resolve({"duration": 15.0}, default="step"))
        if kind == "mpc":
            sim.attach_mpc(model, None, 0.0, model.dt)
        else:
            # Every candidate fails this check: the adaptive MPC keeps its first design.
            strict = {"bounds": {"overshoot": 1e-9, "final_error": 1e-9, "hold_drift": 1e-9}}
            sim.attach_adaptive_mpc(model, None, strict, 0.0, model.dt)
        sim.run_to_end()
        assert sim.fallback_reason is None
        traces[kind] = np.asarray(sim.take_trace()["acc_sp_n"])
        if kind == "mpc_adaptive":
            whats = {w for _, w, _ in sim.controller_events()}
            assert "adopted" not in whats
    # The online identification runs beside the MPC without touching its commands.
    np.testing.assert_array_equal(traces["mpc"], traces["mpc_adaptive"])


@pytest.fixture(scope="module")
def identified():
    """The DMDc model the payload-change experiment identifies for 0.3 kg on 0.5 m."""
    from swingrt.experiments import (
        cases,
        identify_case,
        load_experiment,
        training_scenario,
    )
    from swingrt.sim import collect

    exp = load_experiment("payload-change")
    sc = training_scenario(exp, dict(cases(exp))["vehicle-mass"], 0)
    model, _, _ = identify_case(collect(sc), exp)
    return model


def test_ten_minutes_of_hover_do_not_change_the_model(identified):
    noisy = {
        "duration": 600.0,
        "noise": {"swing_std": 0.002},
        "payload": {"mass": 0.3, "length": 0.5},
    }
    hover = _core.Simulator(resolve(noisy, default="hover"))
    hover.attach_adaptive_mpc(identified, None, None, 0.0, identified.dt)
    hover.run_to_end()
    assert hover.fallback_reason is None
    acc = np.asarray(hover.take_trace()["acc_sp_n"])
    # The noise does move the command, but below the excitation gate's 0.3 m/s².
    assert 0.01 < acc[500:].std() < 0.3
    assert hover.controller_events() == []


def test_adaptive_timing_reports_tick_and_resynthesis():
    model = _core.pendulum_model(delays=10, axes=1)
    t = _core.adaptive_timing(model, n_ticks=300, repeats=2)
    assert t["tick_us"]["count"] == 300
    assert t["resynthesis_ms"]["count"] == 2
    assert 0.0 < t["tick_us"]["median"] <= t["tick_us"]["max"]
    with pytest.raises(ValueError):
        _core.adaptive_timing(model, n_ticks=0)


@pytest.mark.parametrize("case", ["pickup", "winch"])
def test_payload_change_adaptive_mpc_matches_the_oracle(case, tmp_path):
    """The issue's acceptance on the cases where the fixed MPC is far from the oracle: the
    adaptive MPC's swing excess IAE after the change is within 1.5x the oracle's (or below
    the campaign's 1 deg·s floor) and below half the fixed MPC's, and it re-adopted a model
    before the scored step ends."""
    from swingrt.experiments import list_experiments, load_experiment, run_experiment

    assert "payload-change" in list_experiments()
    exp = load_experiment("payload-change")
    assert exp.controllers == ["pid", "lqr", "mpc", "mpc_adaptive", "mpc_oracle"]
    exp = copy.deepcopy(exp)
    exp.cases = {case: exp.cases[case]}
    exp.controllers = ["mpc", "mpc_adaptive", "mpc_oracle"]
    rows = {r["controller"]: r for r in run_experiment(exp, tmp_path, quiet=True)}
    excess = {c: float(r["swing_excess_iae_deg_s"]) for c, r in rows.items()}
    assert excess["mpc"] > 3.0 * excess["mpc_oracle"], excess  # the change matters
    # Within 1.5x the oracle's, or below the floor under which a campaign counts no swing
    # (the winch case: 0.23 vs the oracle's 0.13 deg·s, PX4 PID's 42).
    assert excess["mpc_adaptive"] <= max(1.5 * excess["mpc_oracle"], SWING_EXCESS_MIN), excess
    assert excess["mpc_adaptive"] <= 0.5 * excess["mpc"], excess
    md = (tmp_path / "metrics.md").read_text(encoding="utf-8")
    assert "model re-adopted after" in md
    assert (tmp_path / f"{case}__oracle_model.json").is_file()


def test_twin_path_in_ten_minutes_of_noisy_hover_changes_nothing(identified):
    """With the twin path on, a hover with swing-sensor noise and no payload change neither
    probes nor re-identifies: noise gives no confident length, the thrust no mass step."""
    from swingrt.experiments import cases, load_experiment, training_scenario

    exp = load_experiment("payload-change")
    train = training_scenario(exp, dict(cases(exp))["vehicle-mass"], 0)
    noisy = {
        "duration": 600.0,
        "noise": {"swing_std": 0.002},
        "payload": {"mass": 0.3, "length": 0.5},
    }
    hover = _core.Simulator(resolve(noisy, default="hover"))
    hover.attach_adaptive_mpc(
        identified,
        None,
        {"probe_amplitude": 0.4, "twin": {"enabled": True}},
        0.0,
        identified.dt,
        train,
        (0.3, 0.5, 0.952),
    )
    hover.run_to_end()
    assert hover.fallback_reason is None
    assert hover.controller_events() == []


def test_twin_path_needs_the_twin():
    model = _core.pendulum_model(delays=4, axes=1)
    with pytest.raises(ConfigError, match="twin"):
        _core.AdaptiveMpc(model, None, {"twin": {"enabled": True}})
    sim = _core.Simulator(resolve({}, default="hover"))
    with pytest.raises(ConfigError, match="twin"):
        sim.attach_adaptive_mpc(model, None, None, 0.0, model.dt, None, (0.3, 0.5, 0.952))
    train = resolve({}, default="training")
    for bad in [(float("nan"), 0.5, 0.952), (0.3, -1.0, 0.952), (0.3, 0.5, float("inf"))]:
        with pytest.raises(ConfigError, match="twin"):
            sim.attach_adaptive_mpc(model, None, None, 0.0, model.dt, train, bad)
    with pytest.raises(ConfigError, match="twin.duration"):
        _core.check_settings("adaptive", {"twin": {"duration": 1.0}})


def test_an_oracle_controller_needs_its_case_overrides():
    from swingrt.experiments import Experiment

    with pytest.raises(ConfigError, match="oracle"):
        Experiment.from_dict(
            {
                "name": "x",
                "controllers": ["mpc", "mpc_oracle"],
                "cases": {"a": {"step": {"t": 2.0, "vn": 1.0}}},
            },
            "x.toml",
        )


def test_adaptive_mpc_object_steps_and_reports_events():
    model = _core.pendulum_model(delays=4, axes=1)
    ctrl = _core.AdaptiveMpc(model, None, {"synthesis": "deferred"})
    assert ctrl.axes == 1 and ctrl.period == pytest.approx(model.dt)
    ctrl.reset(np.zeros((1, 3)))
    out = ctrl.step(np.zeros((1, 3)), [1.0])
    assert out.shape == (1,) and np.isfinite(out).all()
    assert ctrl.events() == [] and ctrl.swaps == 0
    with pytest.raises(ConfigError):
        _core.AdaptiveMpc(model, None, {"synthesis": "later"})


@pytest.mark.realtime
def test_fly_adapt_against_sitl(identified, tmp_path):
    """``swingrt fly --adapt`` flies a short mission against ``swingrt sitl`` (real time,
    separate processes) and hands back cleanly."""
    import signal
    import socket
    import subprocess
    import sys

    from swingrt.io import load_flight

    model = tmp_path / "model.json"
    identified.save(model)
    mission = tmp_path / "m.toml"
    mission.write_text("duration = 6.0\n[[step]]\nt = 1.0\nvn = 1.0\n", encoding="utf-8")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        url = f"udp:127.0.0.1:{s.getsockname()[1]}"
    sitl = subprocess.Popen(
        [sys.executable, "-m", "swingrt", "sitl", "--listen", url],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    log = tmp_path / "fly.parquet"
    try:
        res = subprocess.run(
            [sys.executable, "-m", "swingrt", "fly", "--adapt", "--connect", url, "--model",
             str(model), "--mission", str(mission), "--log", str(log)],
            timeout=90,
            capture_output=True,
            text=True,
        )  # fmt: skip
    finally:
        if sitl.poll() is None:
            sitl.send_signal(signal.SIGINT)
        try:
            sitl.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            sitl.kill()
            sitl.communicate()
    assert res.returncode == 0, res.stdout + res.stderr
    assert "adaptive MPC adopted" in res.stdout
    tr = load_flight(log, columns=["t", "vn"])
    assert 0.7 < np.mean(tr["vn"][(tr["t"] > 4.5) & (tr["t"] < 6.0)]) < 1.3


def test_the_offboard_nodes_adaptive_mpc_re_identifies_on_the_models_twin(tmp_path):
    """``fly --adapt``'s controller (``load_controller(adapt=True)``): a model selected on a
    twin carries it (``diagnostics.twin``: the vehicle and the white-box payload), and the
    node's adaptive MPC re-identifies on it for the cable length it measures. Flown in the
    simulator as the node flies it (a controller object on acceleration setpoints): the cable
    is winched 1.0 -> 0.4 m in hover, then a 2 m/s step. With the twin it adopts a model for
    about 0.4 m and damps the swing; with ``twin=False`` (the online DMDc alone) it swings far
    more."""
    from swingrt import sysid
    from swingrt.mavlink.offboard import load_controller
    from swingrt.metrics import step_metrics
    from swingrt.sim import collect

    train = resolve({"payload": {"mass": 0.2, "length": 1.0}}, default="training")
    data = collect(train)
    model = sysid.select_for_control(data, sysid.search(data), twin=train).model
    twin, (m_p, length, m_q) = sysid.model_twin(model)
    assert m_p == pytest.approx(0.2, rel=0.1) and length == pytest.approx(1.0, rel=0.05)
    assert m_q == pytest.approx(train.to_dict()["vehicle"]["mass"])
    assert twin.to_dict()["random_steps"]["axes"] == "n"
    path = tmp_path / "model.json"
    model.save(path)
    from swingrt.sysid import LinearModel

    assert sysid.model_twin(LinearModel.load(path))[1] == (m_p, length, m_q)

    winch = {
        "duration": 45.0,
        "payload": {
            "mass": 0.2,
            "length": 1.0,
            "events": [{"t": 3.0, "action": "winch", "length": 0.4, "rate": 0.3}],
        },
        "setpoints": [{"t": 0.0, "vn": 0.0}, {"t": 25.0, "vn": 2.0}],
    }
    excess = {}
    for use_twin in (True, False):
        ctrl, ts, axes = load_controller(
            path, adapt=True, adaptive={"synthesis": "deferred"}, twin=use_twin
        )
        sim = _core.Simulator(resolve(winch, default="step"))
        sim.attach_python(ctrl, axes, ts, "acceleration", 0.0, 60.0)
        sim.run_to_end()
        tr = {k: np.asarray(v) for k, v in sim.take_trace().items()}
        excess[use_twin] = step_metrics(tr, t0=25.0, axis="n")["swing_excess_iae_deg_s"]
        adopted = [v for _, what, v in ctrl.events() if what == "adopted"]
        if use_twin:
            requested = [v for _, what, v in ctrl.events() if what == "requested"]
            assert adopted, ctrl.events()
            assert any(abs(v - 0.4) < 0.08 for v in requested), ctrl.events()
    assert excess[True] < 2.0, excess
    assert excess[True] < 0.25 * excess[False], excess


def test_a_twin_record_that_is_not_one_is_a_model_error():
    from swingrt import sysid
    from swingrt.errors import ModelError

    model = _core.pendulum_model(delays=4, axes=1)
    assert sysid.model_twin(model) is None
    bad = model.with_diagnostics({"twin": {"scenario": {}, "payload_mass": "x"}})
    with pytest.raises(ModelError, match="diagnostics.twin"):
        sysid.model_twin(bad)
    with pytest.raises(ConfigError, match="twin"):
        _core.AdaptiveMpc(model, None, None, resolve({}, default="training"), None)
