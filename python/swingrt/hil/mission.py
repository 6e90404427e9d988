"""``swingrt mission PLAN --px4 DIR``: a plan flown on PX4 SITL with swingrt's physics, once
by PX4's own AUTO.MISSION (uploaded by the MAVLink mission protocol) and, with a model, once
by swingrt's position MPC offboard (:mod:`swingrt.mavlink.mission`).

Each flight has a PX4 session of its own (``swingrt hil --takeoff`` in a child process), so
both start alike: the vehicle taken off to the plan's first altitude above the plan's start,
the payload at rest. PX4's local origin is where the simulated vehicle stood, so the plan is
flown shifted by minus its start (a ``.plan``'s home is dropped: on SITL the plan is flown
where the simulated vehicle is). Every flight is judged the same way, on the physics trace
(the true swing and payload) from the moment the node started the flight, with the events of
PX4's navigator rule (:func:`swingrt.mission.replay_events`), so neither controller's own
bookkeeping decides when it arrived.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from swingrt import _core
from swingrt.errors import ConfigError, FlightAbort
from swingrt.scenario import ScenarioLike, resolve

__all__ = ["fly_on_px4", "FLIGHTS"]

#: Flights on PX4: PX4's own mission mode, swingrt's MPC.
FLIGHTS = ("px4", "mpc")
#: Swing [deg] beyond which the MPC's flight is handed back to PX4.
SWING_LIMIT_DEG = 45.0


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def fly_on_px4(
    px4_dir,
    mission: _core.Mission,
    out,
    *,
    scenario: ScenarioLike = None,
    model: _core.LinearModel | None = None,
    tracking: dict[str, Any] | None = None,
    seed: int = 0,
    instance: int = 0,
    flights: tuple[str, ...] = FLIGHTS,
    quiet: bool = False,
) -> dict[str, tuple[dict[str, np.ndarray], list[tuple[float, int, str]]]]:
    """Fly ``mission`` on PX4 SITL (module doc), each of ``flights`` in its own session;
    write the node's log, the physics trace and PX4's ULog of each into ``out`` (``tracking``:
    the MPC's settings, ``TrackingSettings``); return per
    flight the physics trace from the flight's start (time from 0) and its replayed events."""
    from swingrt import mission as ms
    from swingrt.hil.session import HilSession
    from swingrt.io.atomic import write_text_atomic
    from swingrt.io.flight import Trace
    from swingrt.mavlink.link import connect
    from swingrt.mavlink.mission import fly_mission, fly_px4_mission
    from swingrt.mavlink.offboard import Watchdog

    for f in flights:
        if f not in FLIGHTS:
            raise ConfigError(f"flight {f!r} is not flown on PX4 (one of {', '.join(FLIGHTS)})")
    if "mpc" in flights:
        if model is None:
            raise ConfigError("the MPC's flight on PX4 needs a model (--model)", field="model")
        ms.check_model(model)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    start = list(mission.start)
    if start[2] > -0.5:
        raise ConfigError(
            f"mission {mission.name!r}: its first item is at d = {start[2]:g} m; PX4 SITL "
            "takes off to it first, so it must be above -0.5 (Down is negative up)"
        )
    # The plan's NED without its home: flown where the simulated vehicle stands.
    flat = _core.Mission.from_text(mission.to_toml(), "toml")
    sc = resolve(scenario).with_overrides({"start": start})
    sc_path = out / "scenario.toml"
    write_text_atomic(sc_path, sc.to_toml())
    offset = (-start[0], -start[1])
    results = {}
    for name in flights:
        physics = out / f"{name}__physics.parquet"
        node = out / f"{name}__node.parquet"
        if not quiet:
            _say(f"[ px4 ] {name}: " + ("PX4's AUTO.MISSION" if name == "px4" else "swingrt MPC"))
        with HilSession(
            px4_dir,
            scenario=sc_path,
            instance=instance,
            workdir=out / f"px4-{name}",
            log=physics,
            seed=seed,
            echo=None if quiet else _say,
        ) as hil:
            conn = connect(hil.onboard_url)
            try:
                if name == "px4":
                    fly_px4_mission(conn, flat, offset=offset, log_path=node)
                else:
                    assert model is not None
                    fly_mission(
                        conn,
                        model,
                        flat,
                        tracking=tracking,
                        offset=offset,
                        log_path=node,
                        watchdog=Watchdog(model.dt, swing_limit=math.radians(SWING_LIMIT_DEG)),
                    )
            finally:
                conn.close()
        results[name] = _judged(flat, Trace.from_parquet(physics), Trace.from_parquet(node))
    return results


def _judged(
    mission: _core.Mission, physics: Any, node: Any
) -> tuple[dict[str, np.ndarray], list[tuple[float, int, str]]]:
    """The physics trace from the node's first tick (PX4's clock, which is the physics
    trace's) with time from 0, and the events of PX4's navigator rule on it."""
    from swingrt import mission as ms

    stamps = np.asarray(node["px4_time_s"], dtype=float)
    stamps = stamps[np.isfinite(stamps)]
    if stamps.size == 0:
        raise FlightAbort("the node logged no PX4 time: cannot find the flight in the physics")
    t0 = float(stamps[0])
    t = np.asarray(physics["t"], dtype=float)
    keep = t >= t0
    trace = {c: np.asarray(physics[c], dtype=float)[keep] for c in physics}
    trace["t"] = trace["t"] - t0
    return trace, ms.replay_events(mission, trace)
