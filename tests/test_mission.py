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
    assert main([*args, "-o", str(tmp_path / "r.json")]) == 0
    capsys.readouterr()
    report = json.loads((tmp_path / "r.json").read_text())
    px4, mpc = report["px4"]["waypoints"], report["mpc"]["waypoints"]
    assert [r["item"] for r in mpc] == [0, 1, 2]
    for a, b in zip(px4[1:], mpc[1:], strict=True):
        assert b["leg_swing_max_deg"] < a["leg_swing_max_deg"]
