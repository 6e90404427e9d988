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
