"""The field's other swing controllers from Python: the input shaper on the swing mode PX4's
loop leaves, flown under the supervisor on the default step, against PX4 PID alone."""

from __future__ import annotations

import math

import pytest

from swingrt import _core
from swingrt.errors import SwingrtError
from swingrt.io import Trace
from swingrt.metrics import step_metrics
from swingrt.scenario import resolve

RIG = {"m_q": 1.5, "m_p": 0.2, "l": 1.0, "c": 0.0}


def _fly(attach=None) -> dict:
    sim = _core.Simulator(resolve(None, duration=25.0))
    if attach is not None:
        attach(sim)
    sim.run_to_end()
    assert sim.fallback_reason is None
    return step_metrics(Trace(sim.take_trace(), {}), t0=2.0)


def test_swing_mode_without_px4_gains_is_the_free_pendulum():
    w, z = _core.swing_mode(
        params=RIG, px4={"vel_p": [0, 0, 0], "vel_i": [0, 0, 0], "vel_d": [0, 0, 0]}
    )
    assert w == pytest.approx(math.sqrt(_core.GRAVITY * 1.7 / 1.5), rel=1e-6)
    assert z == pytest.approx(0.0, abs=1e-6)
    with pytest.raises(SwingrtError, match="model"):
        _core.swing_mode()


def test_shaper_cancels_the_swing_left_by_px4_even_on_a_mistuned_mode():
    px4 = _fly()
    for params in (RIG, {"m_q": 1.2, "m_p": 0.35, "l": 1.3, "c": 0.0}):
        w, z = _core.swing_mode(params=params)
        ctrl = _core.Controller.shaper(w, z, axes=2)
        assert ctrl.kind == "shaper" and ctrl.output == "velocity"
        shaped = _fly(lambda sim, c=ctrl: sim.attach(c, 1.0, 0.02))
        # 7.4° of residual swing under PX4 alone; the shaper leaves a few tenths of a degree,
        # with the mode off by 8 % (a model of another vehicle and cable) too.
        assert shaped["residual_swing_deg"] < 0.1 * px4["residual_swing_deg"]
        assert shaped["swing_excess_iae_deg_s"] < 0.1 * px4["swing_excess_iae_deg_s"]
        assert shaped["ss_error"] < 0.01


# One campaign sample with every method: trained on the same 90 s flight, flown on a
# vehicle 15 % heavier with a slower motor than the one they were trained on (and whose twin
# DeePC's λ_g and HAVOKc's selection flew), with wind and swing-sensor noise.
METHODS_STUDY = {
    "name": "methods-tiny",
    "samples": 1,
    "seed": 5,
    "controllers": [
        "pid",
        "shaper",
        "shaper_zv",
        "payload_p",
        "deepc",
        "havokc_mpc",
        "sindy_mpc",
        "nmpc",
    ],
    "base": {
        "step": {"t": 2.0, "vn": 2.0},
        "duration": 25.0,
        "training_duration": 90.0,
        "tick_budget": 1.0,
        "evaluation": {"vehicle": {"mass": 1.1, "motor_tau": 0.025}},
    },
    "vary": {
        "payload.mass": {"dist": "fixed", "value": 0.3},
        "payload.length": {"dist": "fixed", "value": 1.2},
        "wind.velocity": {"dist": "fixed", "value": [1.0, -0.5, 0.0]},
        "noise.swing_std": {"dist": "fixed", "value": 0.002},
    },
}


def test_every_method_flies_a_campaign_sample_on_a_vehicle_not_its_twin():
    from swingrt.campaign import failure_reason, fly_sample

    rows, _ = fly_sample(METHODS_STUDY, 0)
    by = {r["controller"]: r for r in rows}
    assert list(by) == METHODS_STUDY["controllers"]
    for c, r in by.items():
        assert r["error"] == "" and r["fallback"] == "", (c, r["error"], r["fallback"])
    pid = by["pid"]
    # Each damps the swing PX4 leaves (the shapers without a swing sensor) and passes the
    # campaign's failure rule. ArduPilot's payload feedback flies but does not damp this
    # 1.2 m cable on the heavier vehicle (the benchmark table shows where it does).
    for c in ("shaper", "shaper_zv", "deepc", "havokc_mpc", "sindy_mpc", "nmpc"):
        assert failure_reason(by[c]) == "", (c, failure_reason(by[c]))
        assert by[c]["residual_swing_deg"] < 0.1 * pid["residual_swing_deg"], c
        assert by[c]["swing_excess_iae_deg_s"] < 0.1 * pid["swing_excess_iae_deg_s"], c
    assert by["pid"]["training_s"] == 0.0
    # DeePC and SINDy read the flight minus the held-out part; the shaper all of it.
    assert 0 < by["deepc"]["training_s"] < by["shaper"]["training_s"] <= 90.0
    assert by["sindy_mpc"]["training_s"] < by["nmpc"]["training_s"] == 90.0


def test_methods_spec_errors_name_the_method_field():
    from swingrt.campaign import parse_spec
    from swingrt.campaign.spec import check_spec
    from swingrt.errors import ConfigError

    bad = {**METHODS_STUDY, "controllers": ["pid", "shaper_zvdd"]}
    with pytest.raises(ConfigError, match="shaper_zvdd"):
        parse_spec(bad)
    bad = {**METHODS_STUDY, "base": {**METHODS_STUDY["base"], "deepc": {"lambda_gg": 1.0}}}
    with pytest.raises(ConfigError, match="deepc.lambda_gg"):
        check_spec(parse_spec(bad))


def test_a_flight_logged_without_the_swing_rate_trains_on_the_nodes_difference():
    # A PX4 ULog logs the angle only; the methods read the rate the node computes in flight,
    # the backward difference over one tick. Against the simulator's own rate on a 300 s
    # flight it agrees to the difference's half-tick lag.
    import numpy as np

    import swingrt
    from swingrt.methods import _columns

    flight = swingrt.collect(None, duration=120.0, seed=2)
    cols = {k: v for k, v in flight.columns.items() if not k.startswith("swing_rate")}
    dt = 0.03
    got = _columns(Trace(cols), dt, ["vn", "swing_n", "swing_rate_n"])
    want = _columns(flight, dt, ["swing_rate_n"])["swing_rate_n"]
    assert np.corrcoef(got["swing_rate_n"][1:], want[1:])[0, 1] > 0.99
    np.testing.assert_allclose(
        got["swing_rate_n"][1:], np.diff(got["swing_n"]) / dt, rtol=0, atol=1e-12
    )


def test_px4s_normalised_thrust_becomes_newtons_through_the_vehicles_motors():
    # At PX4's hover command the motors carry vehicle and payload: thrust = total mass * g.
    import numpy as np

    from swingrt.sysid import with_thrust

    for airframe in ("honeybee", "x500"):
        sc = resolve({"vehicle": {"airframe": airframe}}, default="hover")
        d = sc.to_dict()
        total = d["vehicle"]["mass"] + d["payload"]["mass"]
        hover = sc.hover_thrust()
        data = Trace({"t": [0.0, 0.1, 0.2], "thrust_sp": [hover, hover, np.nan]})
        out = with_thrust(data, sc)
        assert out["thrust"][:2] == pytest.approx([total * _core.GRAVITY] * 2, rel=1e-9)
        assert np.isnan(out["thrust"][2]) and "thrust" not in data.columns
        # A flight that has Newtons already is left as it is.
        assert with_thrust(out, sc) is out
