"""``swingrt vehicle``: a scenario from PX4's parameters, the inverse of the parameters
``swingrt hil`` gives PX4 (the log PX4 itself writes is read in ``test_px4.py``)."""

from __future__ import annotations

import math

import pytest

from swingrt._core import Scenario
from swingrt.errors import ConfigError, DataError
from swingrt.hil.params import (
    HIL_RATE_GAIN_SCALE,
    hil_rate_gain_scale,
    px4_parameters,
    vehicle_from_px4,
)
from swingrt.io.px4_params import read_px4_parameters

#: A vehicle unlike the built-in one: wider, heavier, other gains.
OTHER = {
    "vehicle": {"arm": 0.25, "yaw_arm": 0.016, "mass": 1.4},
    "controller": {"att_p": [5.5, 5.0, 2.5], "vel_p": [1.6, 1.6, 3.5], "tilt_max": 0.6},
    "payload": {"mass": 0.3},
}


@pytest.mark.parametrize("overrides", [{}, OTHER])
def test_the_scenario_comes_back_from_the_parameters_hil_gives_px4(overrides):
    sc = Scenario.builtin("step").with_overrides(overrides)
    d = sc.to_dict()
    total = d["vehicle"]["mass"] + d["payload"]["mass"]
    # MPC_THR_HOVER is the vehicle + payload's: given that mass, the motors come back.
    back, notes = vehicle_from_px4(px4_parameters(sc), mass=total)
    b = back.to_dict()
    v, c, bv, bc = d["vehicle"], d["controller"], b["vehicle"], b["controller"]
    # The payload it hovered with is the base's (0.2 kg), not the 0.3 kg OTHER carried.
    assert bv["mass"] == pytest.approx(total - 0.2, rel=1e-9)
    assert bv["arm"] == pytest.approx(v["arm"], rel=1e-5)
    assert bv["yaw_arm"] == pytest.approx(v["yaw_arm"], rel=1e-5)
    assert bv["thrust_poly"] == pytest.approx(v["thrust_poly"], rel=2e-3)
    for f in ("att_p", "vel_p", "vel_i", "pos_p"):
        assert bc[f] == pytest.approx(c[f], rel=1e-9), f
    assert bc["vel_d"][:2] == pytest.approx(c["vel_d"][:2])
    assert bc["tilt_max"] == pytest.approx(c["tilt_max"], rel=1e-4)
    for f in ("rate_p", "rate_i", "rate_d"):
        # PX4 in the loop flies the roll and pitch rate gains scaled (hil.params).
        want = [c[f][0] * HIL_RATE_GAIN_SCALE, c[f][1] * HIL_RATE_GAIN_SCALE, c[f][2]]
        assert bc[f] == pytest.approx(want, rel=1e-4), f
    assert any("not in PX4's parameters" in n for n in notes)


def test_the_given_mass_hovers_at_px4s_hover_thrust():
    params = px4_parameters(Scenario.builtin("step").with_overrides(OTHER))
    for mass in (0.7, 2.0):
        for payload in (None, 0.05, 0.5):
            sc, _ = vehicle_from_px4(params, mass=mass, payload=payload)
            d = sc.to_dict()
            carried = d["payload"]["mass"]
            assert carried == pytest.approx(0.2 if payload is None else payload)
            # Vehicle and payload together are the take-off mass, and they hover at the
            # parameter: the motors were scaled to the mass given.
            assert d["vehicle"]["mass"] + carried == pytest.approx(mass, rel=1e-12)
            assert sc.hover_thrust() == pytest.approx(params["MPC_THR_HOVER"], abs=1e-6)


def test_without_a_mass_the_vehicle_is_what_the_nominal_motors_hover_less_its_payload():
    sc = Scenario.builtin("step")
    params = px4_parameters(sc)
    back, notes = vehicle_from_px4(params)
    # The round trip: the built-in vehicle hovers its 0.2 kg at MPC_THR_HOVER, and the
    # vehicle read back is the built-in one, not vehicle and payload together.
    assert back.to_dict()["vehicle"]["mass"] == pytest.approx(
        sc.to_dict()["vehicle"]["mass"], rel=1e-3
    )
    assert back.hover_thrust() == pytest.approx(params["MPC_THR_HOVER"], abs=1e-6)
    assert any("estimated" in n for n in notes)
    # A payload as heavy as the take-off mass leaves no vehicle.
    with pytest.raises(ConfigError) as e:
        vehicle_from_px4(params, payload=5.0)
    assert e.value.field == "payload"


@pytest.mark.parametrize(("use_hte", "on"), [(0, False), (1, True), (None, True)])
def test_px4_s_hover_thrust_estimator_switch_is_read_from_its_parameters(use_hte, on):
    params = px4_parameters(Scenario.builtin("step"))
    if use_hte is not None:
        params["MPC_USE_HTE"] = use_hte
    sc, _ = vehicle_from_px4(params)
    assert sc.to_dict()["controller"]["hover_thrust_estimator"] is on


def test_the_hover_thrust_estimator_switch_is_not_written_for_px4():
    # Current PX4 (the SITL build the tests fly) has no MPC_USE_HTE: its estimate is always
    # adopted, as the cascade's default does.
    params = px4_parameters(Scenario.builtin("step"))
    assert "MPC_USE_HTE" not in params
    sc, _ = vehicle_from_px4(params)
    assert sc.to_dict()["controller"]["hover_thrust_estimator"] is True


def _params(**changes):
    p = px4_parameters(Scenario.builtin("step"))
    p.update(changes)
    return {k: v for k, v in p.items() if v is not None}


@pytest.mark.parametrize(
    "changes, field",
    [
        ({"CA_ROTOR_COUNT": 6}, "CA_ROTOR_COUNT"),
        ({"CA_ROTOR0_PX": -0.1}, "CA_ROTOR0_PX"),
        ({"CA_ROTOR2_KM": 0.02}, "CA_ROTOR2_PX"),
        ({"CA_ROTOR3_KM": None}, "CA_ROTOR3_KM"),
        ({"MPC_THR_HOVER": None}, "MPC_THR_HOVER"),
        ({"MPC_THR_HOVER": 1.5}, "MPC_THR_HOVER"),
    ],
)
def test_a_vehicle_swingrt_cannot_fly_is_refused_by_name(changes, field):
    with pytest.raises(ConfigError) as e:
        vehicle_from_px4(_params(**changes))
    assert e.value.field == field


def test_a_wide_x_keeps_its_roll_and_pitch_arms():
    # PX4's x500 (its SITL airframe): rotors at (±0.13, ±0.22) and (∓0.13, ∓0.20) m.
    geometry = {
        "CA_ROTOR0_PX": 0.13, "CA_ROTOR0_PY": 0.22, "CA_ROTOR0_KM": 0.05,
        "CA_ROTOR1_PX": -0.13, "CA_ROTOR1_PY": -0.20, "CA_ROTOR1_KM": 0.05,
        "CA_ROTOR2_PX": 0.13, "CA_ROTOR2_PY": -0.22, "CA_ROTOR2_KM": -0.05,
        "CA_ROTOR3_PX": -0.13, "CA_ROTOR3_PY": 0.20, "CA_ROTOR3_KM": -0.05,
        "MPC_THR_HOVER": 0.60,
    }  # fmt: skip
    sc, notes = vehicle_from_px4(_params(**geometry), mass=2.0)
    v = sc.to_dict()["vehicle"]
    assert v["rotor_xy"] == pytest.approx([0.13, 0.21])
    assert v["arm"] == pytest.approx(math.hypot(0.13, 0.21)) and v["yaw_arm"] == 0.05
    assert any("|y| 0.200-0.220 m" in n and "|y| 0.210 m" in n for n in notes), notes
    assert sc.with_overrides({"vehicle": {"mass": 2.0 - 0.2}}).hover_thrust() == pytest.approx(
        0.60, abs=1e-6
    )
    # Written back for PX4, the allocation is the rectangle read.
    written = px4_parameters(sc)
    assert [written[f"CA_ROTOR{i}_PY"] for i in range(4)] == [0.21, -0.21, -0.21, 0.21]
    assert [written[f"CA_ROTOR{i}_PX"] for i in range(4)] == [0.13, -0.13, 0.13, -0.13]
    _, notes = vehicle_from_px4(_params())
    assert not any("rectangle" in n for n in notes)


def test_parameter_files(tmp_path):
    qgc = tmp_path / "x.params"
    qgc.write_text(
        "# Onboard parameters for Vehicle 1\n#\n# Vehicle-Id Component-Id Name Value Type\n"
        "1\t1\tMPC_THR_HOVER\t0.42\t9\n1\t1\tCA_ROTOR_COUNT\t4\t6\n"
    )
    assert read_px4_parameters(qgc) == {"MPC_THR_HOVER": 0.42, "CA_ROTOR_COUNT": 4.0}
    plain = tmp_path / "x.txt"
    plain.write_text("MPC_XY_P 0.95\nMC_ROLL_P, 6.5  # comment\n")
    assert read_px4_parameters(plain) == {"MPC_XY_P": 0.95, "MC_ROLL_P": 6.5}
    for text, what in [
        ("MPC_XY_P\n", "expected 'NAME VALUE'"),
        ("MPC_XY_P fast\n", "is not a number"),
        ("# nothing\n", "no parameters"),
    ]:
        bad = tmp_path / "bad.params"
        bad.write_text(text)
        with pytest.raises(DataError, match=what):
            read_px4_parameters(bad)
    with pytest.raises(DataError, match="not a readable ULog"):
        (tmp_path / "x.ulg").write_bytes(b"not a log")
        read_px4_parameters(tmp_path / "x.ulg")


def test_cli_writes_a_scenario_that_flies(cli, tmp_path):
    src = tmp_path / "px4.params"
    params = px4_parameters(Scenario.builtin("step").with_overrides(OTHER))
    src.write_text("".join(f"1\t1\t{k}\t{v}\t9\n" for k, v in params.items()))
    out = tmp_path / "v.toml"
    r = cli("vehicle", src, "--mass", "1.7", "--payload", "0.3", "-o", out)
    assert r.returncode == 0, r.stderr
    sc = Scenario.from_toml(out.read_text())
    assert sc.to_dict()["vehicle"]["mass"] == pytest.approx(1.4)
    assert sc.to_dict()["payload"]["mass"] == pytest.approx(0.3)
    assert math.isclose(sc.to_dict()["vehicle"]["arm"], 0.25, rel_tol=1e-5)
    assert "nominal" in r.stderr and "nominal" in out.read_text()
    r = cli("simulate", out, "--duration", "6", "-o", tmp_path / "t.parquet")
    assert r.returncode == 0, r.stderr
    for args in (["--mass", "-1"], ["--payload", "2"], ["-o", tmp_path / "v.json"]):
        r = cli("vehicle", src, *args)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    r = cli("vehicle", tmp_path / "missing.params")
    assert r.returncode == 2 and "no such file" in r.stderr


def test_rate_authority_scales_with_arm_over_inertia_and_sets_the_hil_gain_scale():
    honeybee = Scenario.builtin("hover")
    roll, pitch = honeybee.rate_authority()
    v = honeybee.to_dict()["vehicle"]
    ix, iy, _ = v["inertia"]
    # Same arms, so roll/pitch authority is the inertia's inverse ratio.
    assert roll / pitch == pytest.approx(iy / ix, rel=1e-9)
    d = v["arm"] / math.sqrt(2.0)
    wide = honeybee.with_overrides(
        {"vehicle": {"rotor_xy": [d, 2 * d], "arm": math.hypot(d, 2 * d)}}
    )
    assert wide.rate_authority() == pytest.approx([2 * roll, pitch], rel=1e-9)
    heavy = honeybee.with_overrides({"vehicle": {"inertia": [2 * ix, 2 * iy, 1e-2]}})
    assert heavy.rate_authority() == pytest.approx([roll / 2, pitch / 2], rel=1e-9)
    # The Honeybee has more authority than PX4's x500 and flies PX4's loop at half gains;
    # the x500 flies PX4's own gains.
    x500 = honeybee.with_overrides({"vehicle": {"airframe": "x500"}})
    assert hil_rate_gain_scale(honeybee) == HIL_RATE_GAIN_SCALE
    assert hil_rate_gain_scale(x500) == 1.0
    assert px4_parameters(x500)["MC_PITCHRATE_P"] == x500.to_dict()["controller"]["rate_p"][1]
