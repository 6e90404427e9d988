"""Missions from Python: TOML and QGroundControl .plan files read into the same mission, and
flown in the simulator by PX4's mission behaviour and by swingrt's smooth legs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from swingrt import _core
from swingrt.errors import ConfigError
from swingrt.scenario import resolve

SQUARE = """name = "square"
speed = 3.0
acceptance_radius = 0.5
hold = 2.0
[[waypoint]]
n = 0.0
e = 0.0
d = -10.0
[[waypoint]]
n = 20.0
e = 0.0
d = -10.0
[[waypoint]]
n = 20.0
e = 15.0
d = -12.0
"""


def _plan(items: list[list[float]]) -> str:
    home = [47.3977, 8.5456, 488.0]
    simple = [
        {"type": "SimpleItem", "command": 16, "frame": 3, "autoContinue": True, "params": p}
        for p in items
    ]
    return json.dumps(
        {
            "fileType": "Plan",
            "version": 1,
            "mission": {"items": simple, "plannedHomePosition": home},
        }
    )


def test_a_plan_file_lands_in_local_ned_about_its_home():
    # 0.001° of latitude North of home is 111.2 m (PX4's projection, spherical Earth).
    wp = [0, 0, 0, 0, 47.3987, 8.5456, 15.0]
    m = _core.Mission.from_text(_plan([wp]), "plan")
    n, e = _core.geo_project(47.3977, 8.5456, 47.3987, 8.5456)
    assert n == pytest.approx(111.19, rel=1e-3) and e == pytest.approx(0.0, abs=1e-6)
    item = m.items[0]
    assert item["position"] == pytest.approx([n, e, -15.0], abs=1e-6)
    assert _core.geo_reproject(47.3977, 8.5456, n, e) == pytest.approx((47.3987, 8.5456))
    rtl = json.loads(_plan([wp]))
    rtl["mission"]["items"].append(dict(rtl["mission"]["items"][0], command=20))
    with pytest.raises(ConfigError, match=r"items\[1\].*20"):
        _core.Mission.from_text(json.dumps(rtl), "plan")
    with pytest.raises(ConfigError, match="speed"):
        _core.Mission.from_text(SQUARE.replace("speed = 3.0", "speed = -1.0"), "toml")


@pytest.mark.parametrize("mode", ["px4", "smooth"])
def test_both_guidances_fly_every_waypoint_and_hold_on_the_last(mode):
    m = _core.Mission.from_text(SQUARE, "toml")
    assert _core.Mission.from_text(m.to_toml(), "toml") == m
    sim = _core.Simulator(resolve({"start": list(m.start)}, duration=80.0))
    sim.fly_mission(m, {"mode": mode}, 1.0)
    while not sim.mission_done and sim.t < 75.0:
        sim.advance(0.5)
    assert sim.mission_done
    reached = [i for _, i, kind in sim.mission_events() if kind == "reached"]
    assert reached == [0, 1, 2]
    tr = sim.trace()
    end = np.array([tr["pn"][-1], tr["pe"][-1], tr["pd"][-1]])
    assert np.linalg.norm(end - np.array(m.items[-1]["position"])) < 0.5
    peak = math.degrees(np.abs(np.hypot(tr["swing_n"], tr["swing_e"])).max())
    # PX4's mission legs start and stop hard (28° of swing on this rig); swingrt's
    # jerk-limited legs leave about half.
    assert peak < (20.0 if mode == "smooth" else 40.0)


def test_swingrt_mission_prints_one_row_per_waypoint(tmp_path, capsys):
    from swingrt.cli import main

    plan = tmp_path / "square.toml"
    plan.write_text(SQUARE)
    out = tmp_path / "report.json"
    scenario = tmp_path / "payload.toml"
    scenario.write_text("[payload]\nmass = 0.3\nlength = 1.5\n")
    args = ["mission", str(plan), "--guidance", "smooth", "--scenario", str(scenario)]
    assert main([*args, "-o", str(out)]) == 0
    report = json.loads(out.read_text())["smooth"]
    rows = report["waypoints"]
    assert [r["item"] for r in rows] == [0, 1, 2]
    assert "smooth: mission finished" in capsys.readouterr().out
    for r in rows[1:]:
        # Arrivals in order, inside the acceptance radius for the whole hold, the leg's
        # swing bounds the swing left once there, settling (if any) happens within the hold.
        assert r["hold_error_m"] < 0.5 + 0.3
        assert r["residual_swing_deg"] <= r["leg_swing_max_deg"] + 1e-9
        assert 0.0 < r["leg_swing_max_deg"] < 20.0
        assert math.isnan(r["settle_1deg_s"]) or 0.0 <= r["settle_1deg_s"] <= 2.0
    assert rows[1]["arrival_s"] < rows[2]["arrival_s"] <= report["total_s"]
    bad = tmp_path / "square.txt"
    bad.write_text(SQUARE)
    assert main(["mission", str(bad)]) == 2
    assert "must end in .plan or .toml" in capsys.readouterr().err


def test_swingrt_mission_flies_the_position_mpc_on_a_model(tmp_path, capsys):
    from swingrt import mission as ms
    from swingrt.cli import main
    from swingrt.sysid import identify

    # The model is the white-box pendulum identified from a PX4-guided flight of the plan
    # (its cable length is estimated from the swing, not copied from the plant).
    m = _core.Mission.from_text(SQUARE, "toml")
    scenario = {"payload": {"mass": 0.3, "length": 1.5}}
    trace, _ = ms.fly(m, "px4", scenario)
    model = identify(trace, axes="ne", method="whitebox", payload_mass=0.3, test_span=8.0)
    model.save(str(tmp_path / "model.json"))
    (tmp_path / "square.toml").write_text(SQUARE)
    (tmp_path / "payload.toml").write_text("[payload]\nmass = 0.3\nlength = 1.5\n")
    args = ["mission", str(tmp_path / "square.toml"), "--guidance", "px4"]
    args += ["--scenario", str(tmp_path / "payload.toml"), "--model", str(tmp_path / "model.json")]
    # The same white-box model's pendulum flies the thesis's LQR in place of PX4's velocity
    # loop (PX4's position loop on the legs gives it the velocity reference).
    args += ["--lqr", str(tmp_path / "model.json")]
    assert main([*args, "-o", str(tmp_path / "r.json")]) == 0
    capsys.readouterr()
    report = json.loads((tmp_path / "r.json").read_text())
    px4, mpc, lqr = (report[k]["waypoints"] for k in ("px4", "mpc", "lqr"))
    assert [r["item"] for r in mpc] == [r["item"] for r in lqr] == [0, 1, 2]
    for a, b, c in zip(px4[1:], mpc[1:], lqr[1:], strict=True):
        assert b["leg_swing_max_deg"] < a["leg_swing_max_deg"]
        assert c["leg_swing_max_deg"] < a["leg_swing_max_deg"]
    # A data-driven model carries no pendulum for the LQR: refused in one line.
    dmdc = identify(trace, axes="ne", delays=10, test_span=8.0)
    dmdc.save(str(tmp_path / "dmdc.json"))
    bad = ["mission", str(tmp_path / "square.toml"), "--lqr", str(tmp_path / "dmdc.json")]
    assert main(bad) == 2
    assert "needs a white-box model" in capsys.readouterr().err


# --- what a mission flight is judged by ------------------------------------------------------


def test_a_flown_path_is_judged_by_px4s_navigator_rule():
    """Replayed events of a straight path at constant speed: an item is reached where the
    path enters its acceptance radius ((L - r) / v), held for its hold from then, and the
    next one is only the target after that (a path that passes it early does not count)."""
    from swingrt import mission as ms

    plan = """speed = 2.0
acceptance_radius = 0.5
hold = 3.0
[[waypoint]]
n = 0.0
e = 0.0
d = -10.0
[[waypoint]]
n = 10.0
e = 0.0
d = -10.0
[[waypoint]]
n = 10.0
e = 4.0
d = -10.0
"""
    m = _core.Mission.from_text(plan, "toml")
    dt = 0.01
    t = np.arange(0.0, 20.0, dt)
    # Hover 3 s, 10 m North at 2 m/s (3 -> 8 s), hover, 4 m East at 2 m/s (11 -> 13 s).
    pn = np.clip((t - 3.0) * 2.0, 0.0, 10.0)
    pe = np.clip((t - 11.0) * 2.0, 0.0, 4.0)
    zero = np.zeros_like(t)
    trace = {"t": t, "pn": pn, "pe": pe, "pd": zero - 10.0, "vn": zero, "ve": zero, "vd": zero}
    events = ms.replay_events(m, trace)
    got = {(i, k): ti for ti, i, k in events}
    assert got[(0, "reached")] == pytest.approx(0.0)
    assert got[(0, "left")] == pytest.approx(3.0, abs=dt)
    assert got[(1, "reached")] == pytest.approx(3.0 + 9.5 / 2.0, abs=dt)
    assert got[(1, "left")] == pytest.approx(3.0 + 9.5 / 2.0 + 3.0, abs=dt)
    assert got[(2, "reached")] == pytest.approx(11.0 + 3.5 / 2.0, abs=dt)
    assert got[(2, "completed")] == pytest.approx(11.0 + 3.5 / 2.0 + 3.0, abs=dt)
    # Through item 2's radius before item 1's hold is over: not reached until it is again.
    early = dict(trace, pe=np.where((t > 8.0) & (t < 9.0), 4.0, pe), pn=pn)
    early["pn"] = np.where((t > 8.0) & (t < 9.0), 10.0, pn)
    late = {(i, k): ti for ti, i, k in ms.replay_events(m, early)}
    assert late[(2, "reached")] == pytest.approx(got[(2, "reached")], abs=dt)


def _passing() -> dict:
    """A mission flight's summary that passes every rule with room to spare."""
    return {
        "total_s": 50.0,
        "leg_swing_max_deg": 10.0,
        "residual_swing_deg": 5.0,
        "settle_1deg_s": 1.0,
        "hold_error_m": 0.1,
        "payload_hold_error_m": 0.2,
        "overshoot_m": 0.1,
        "peak_swing_deg": 10.0,
        "time_vs_px4": 1.0,
        "leg_swing_vs_px4": 0.3,
    }


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"error": "DataError: x"}, "error"),
        ({"fallback": "handed back to PX4"}, "fallback"),
        ({"peak_swing_deg": 61.0}, "diverged"),
        ({"hold_error_m": math.nan}, "diverged"),
        ({"settle_1deg_s": math.inf}, "settle"),
        ({"settle_1deg_s": 2.01}, "settle"),
        ({"hold_error_m": 0.31}, "hold"),
        ({"time_vs_px4": 1.16}, "slow"),
        ({"leg_swing_vs_px4": 0.51}, "swing"),
    ],
)
def test_a_mission_flight_that_breaks_one_rule_fails_for_that_rule(change, reason):
    from swingrt import mission as ms

    assert ms.mission_failure(_passing()) == ""
    assert ms.mission_failure({**_passing(), **change}) == reason
    # PX4's own flight is not compared with itself.
    if reason in ("slow", "swing"):
        assert ms.mission_failure({**_passing(), **change}, judged=False) == ""


def test_the_comparison_with_px4_takes_the_worst_leg_not_the_worst_swing():
    from swingrt import mission as ms

    px4 = [{"item": 0.0, "leg_swing_max_deg": 0.0}, {"item": 1.0, "leg_swing_max_deg": 40.0}]
    px4.append({"item": 2.0, "leg_swing_max_deg": 10.0})
    mine = [{"item": 0.0, "leg_swing_max_deg": 0.0}, {"item": 1.0, "leg_swing_max_deg": 12.0}]
    mine.append({"item": 2.0, "leg_swing_max_deg": 6.0})
    r = ms.compare({"total_s": 60.0}, mine, {"total_s": 50.0}, px4)
    # Leg 1: 12/40 = 0.3; leg 2: 6/10 = 0.6, though its swing is the smaller one.
    assert r == {"time_vs_px4": pytest.approx(1.2), "leg_swing_vs_px4": pytest.approx(0.6)}
    none = ms.compare({"total_s": 60.0}, mine, None, None)
    assert math.isnan(none["time_vs_px4"]) and math.isnan(none["leg_swing_vs_px4"])


def test_a_steady_lean_in_the_wind_is_not_residual_swing():
    from swingrt import mission as ms

    m = _core.Mission.from_text(SQUARE, "toml")
    t = np.arange(0.0, 40.0, 0.01)
    wp = np.array([it["position"] for it in m.items])
    # At rest on each waypoint in turn, the payload leaning a steady 3° North and swinging
    # 0.5° about that lean at 0.6 Hz.
    k = np.minimum((t // 10).astype(int), 2)
    lean, wobble = math.radians(3.0), math.radians(0.5) * np.sin(2 * math.pi * 0.6 * t)
    tr = {"t": t, "pn": wp[k, 0], "pe": wp[k, 1], "swing_n": lean + wobble}
    tr["swing_e"] = np.zeros_like(t)
    tr["payload_pn"], tr["payload_pe"] = tr["pn"] + 0.05, tr["pe"]
    events = [(0.0, 0, "reached"), (5.0, 0, "left"), (10.0, 1, "reached"), (15.0, 1, "left")]
    events += [(20.0, 2, "reached"), (25.0, 2, "completed")]
    rows = ms.waypoint_report(m, tr, events)
    for r in rows[1:]:
        assert r["leg_swing_max_deg"] == pytest.approx(3.5, abs=0.01)
        # The hang is the mean over the hold's last 2.5 s, 1.5 periods of the wobble: it is
        # off by at most the wobble over π × 1.5.
        assert r["residual_swing_deg"] == pytest.approx(0.5, abs=0.5 / (math.pi * 1.5))
        assert r["settle_1deg_s"] == 0.0 and r["hold_error_m"] == 0.0
    s = ms.summary(rows, 25.0, tr)
    assert s["peak_swing_deg"] == pytest.approx(3.5, abs=0.01) and s["total_s"] == 25.0


def test_the_swing_period_of_an_identified_model_is_the_payloads():
    from swingrt import mission as ms
    from swingrt.sysid import identify, swing_period

    # The coupled period of vehicle and payload lies between the pendulum's own 2π√(l/g)
    # (vehicle held) and 2π√(l/(g (1 + m_p/m_Q))) (vehicle free).
    m = _core.Mission.from_text(SQUARE, "toml")
    for length in (0.6, 1.5):
        trace, _ = ms.fly(m, "px4", {"payload": {"mass": 0.3, "length": length}})
        model = identify(trace, axes="ne", method="whitebox", payload_mass=0.3, test_span=8.0)
        period = swing_period(model)
        free = 2 * math.pi * math.sqrt(length / (9.81 * (1 + 0.3 / 0.952)))
        held = 2 * math.pi * math.sqrt(length / 9.81)
        assert period is not None and 0.95 * free <= period <= 1.05 * held
        legs = ms.shaped_legs(model)
        assert legs["jerk_max"] == pytest.approx(min(1.6, legs["acc_max"] / period))
        dmdc = identify(trace, axes="ne", delays=10, test_span=8.0)
        assert swing_period(dmdc) == pytest.approx(period, rel=0.1)


def test_swingrt_mission_draws_the_paths_and_the_swing(tmp_path, capsys):
    from swingrt.cli import main

    (tmp_path / "square.toml").write_text(SQUARE)
    fig = tmp_path / "mission.png"
    args = ["mission", str(tmp_path / "square.toml"), "--figure", str(fig)]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "against PX4's mission mode" in out and f"wrote {fig}" in out
    assert fig.stat().st_size > 20_000 and fig.read_bytes()[:4] == b"\x89PNG"


def test_swingrt_mission_refuses_a_one_axis_model_and_an_unknown_figure_format(tmp_path, capsys):
    from swingrt.cli import main
    from swingrt.sysid import identify

    (tmp_path / "square.toml").write_text(SQUARE)
    fig = tmp_path / "mission.xyz"
    assert main(["mission", str(tmp_path / "square.toml"), "--figure", str(fig)]) == 2
    assert "--figure" in capsys.readouterr().err and not fig.exists()
    from swingrt import mission as ms

    trace, _ = ms.fly(_core.Mission.from_text(SQUARE, "toml"), "px4")
    north = identify(trace, axes="n", delays=10, test_span=8.0)
    north.save(str(tmp_path / "north.json"))
    args = ["mission", str(tmp_path / "square.toml"), "--model", str(tmp_path / "north.json")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "a mission flies both axes" in err and "acc_sp_n" in err and err.count("\n") == 1


def test_the_payload_target_takes_the_cable_length_from_what_is_known(tmp_path, capsys):
    """--target payload: a given length is used as is; a white-box model's identified length
    next; else the pendulum length of the model's swing period, which lies between the
    length over 1 + m_p/m_Q (vehicle free) and the length (vehicle held)."""
    from swingrt import mission as ms
    from swingrt.cli import main
    from swingrt.sysid import identify

    m = _core.Mission.from_text(SQUARE, "toml")
    trace, _ = ms.fly(m, "px4", {"payload": {"mass": 0.3, "length": 1.5}})
    white = identify(trace, axes="ne", method="whitebox", payload_mass=0.3, test_span=8.0)
    dmdc = identify(trace, axes="ne", delays=10, test_span=8.0)
    assert ms.target_tracking(dmdc) == (None, "the vehicle over the waypoints")
    given, _ = ms.target_tracking(dmdc, "payload", 2.0)
    assert given == {"target": "payload", "cable_length": 2.0}
    wb, why = ms.target_tracking(white, "payload")
    assert wb["cable_length"] == pytest.approx(white.diagnostics["whitebox"]["length"])
    assert "white-box" in why
    est, why = ms.target_tracking(dmdc, "payload")
    assert 0.95 * 1.5 / (1 + 0.3 / 0.952) <= est["cable_length"] <= 1.5
    assert "lower bound" in why
    with pytest.raises(ConfigError, match="payload target only"):
        ms.target_tracking(dmdc, "vehicle", 1.0)
    (tmp_path / "square.toml").write_text(SQUARE)
    assert main(["mission", str(tmp_path / "square.toml"), "--target", "payload"]) == 2
    assert "give --model" in capsys.readouterr().err
