"""Missions over MAVLink: where a plan lies in PX4's local frame, PX4's own mission mode flown
on it (the baseline) and swingrt's position MPC with preview flown on it offboard
(``swingrt fly --mission PLAN``).

**Frames.** PX4's local NED frame has its origin where its estimator started
(GPS_GLOBAL_ORIGIN). A QGroundControl plan's north/east are about the plan's home, which lies
at ``geo_project(origin, home)`` in that frame; a TOML plan has no home and its north/east are
the local frame's. ``offset`` [m] (north, east) shifts the plan further (the comparison on PX4
SITL puts the plan where the simulated vehicle started). Altitudes stay as the plan gives
them: Down about the local origin, which PX4's home (the take-off point) shares.

**PX4's own mission** (the baseline): the plan goes to PX4 as MISSION_ITEM_INTs by the MAVLink
mission protocol (mavlink.io, "Mission Protocol": MISSION_COUNT, the vehicle requests each
item by MISSION_REQUEST_INT, a MISSION_ACK closes the upload): a speed change
(MAV_CMD_DO_CHANGE_SPEED) wherever an item's leg speed differs from the one in force, then
the item as NAV_TAKEOFF / NAV_WAYPOINT (hold time, acceptance radius) / NAV_LAND at its
latitude, longitude and altitude above home. Then AUTO.MISSION flies it; the node only
watches and logs until the last item's hold is over, then asks for AUTO.LOITER.

**swingrt's flight**: the guidance (the legs, :class:`swingrt._core.Guidance`) and the
tracking MPC (:class:`swingrt._core.TrackingMpc`) at the model's rate, through the offboard
node's session and watchdogs (:class:`~swingrt.mavlink.offboard.OffboardSession`): North/East
acceleration setpoints (PX4 turns them into tilt; a position or velocity setpoint beside them
would put PX4's own PID on top of the MPC), the altitude by the guidance's position setpoint,
the heading held.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from swingrt import _core
from swingrt.errors import ConfigError, ControlError, FlightAbort, LinkError
from swingrt.mavlink.link import PX4_MAIN_MODE, PX4_SUB_MODE_AUTO, mavlink
from swingrt.mavlink.offboard import (
    MASK_ACC_ALT_HOLD,
    FlightReport,
    OffboardSession,
    _finish,
)
from swingrt.mission import time_limit

__all__ = [
    "MissionFlight",
    "global_origin",
    "plan_offset",
    "px4_items",
    "upload",
    "fly_px4_mission",
    "fly_mission",
]

log = logging.getLogger("swingrt.mavlink.mission")

#: Wall seconds to wait for each answer of the mission protocol before giving up.
PROTOCOL_TIMEOUT = 5.0
#: Times MISSION_COUNT is sent before an unanswered upload fails.
COUNT_TRIES = 3
#: PX4's AUTO.MISSION as (main, sub) mode.
AUTO_MISSION = (PX4_MAIN_MODE["AUTO"], PX4_SUB_MODE_AUTO["MISSION"])
AUTO_LOITER = (PX4_MAIN_MODE["AUTO"], PX4_SUB_MODE_AUTO["LOITER"])
#: Seconds logged after the last item's hold is over.
TAIL_S = 2.0

_NAV = {
    "takeoff": mavlink.MAV_CMD_NAV_TAKEOFF,
    "waypoint": mavlink.MAV_CMD_NAV_WAYPOINT,
    "land": mavlink.MAV_CMD_NAV_LAND,
}


@dataclass
class MissionFlight:
    """One mission flown over MAVLink: the node's log and timing (``report``), the plan as
    flown in PX4's local frame (``mission``) and its events as (node time [s], item, kind):
    the guidance's for swingrt's flight; for PX4's, PX4's navigator rule replayed on the
    logged path (:func:`swingrt.mission.replay_events`), with PX4's own reports of each item
    done (MISSION_ITEM_REACHED, sent when an item's hold is over) in ``reported`` as (node
    time [s], item)."""

    report: FlightReport
    mission: _core.Mission
    events: list[tuple[float, int, str]]
    reported: list[tuple[float, int]] | None = None


def _command(conn, command: int, *params: float) -> None:
    p = list(params) + [0.0] * (7 - len(params))
    conn.mav.command_long_send(conn.target_system, conn.target_component, command, 0, *p)


def global_origin(conn, timeout: float = PROTOCOL_TIMEOUT) -> tuple[float, float, float]:
    """PX4's local origin as (latitude [deg], longitude [deg], altitude AMSL [m]), asked for
    with MAV_CMD_REQUEST_MESSAGE (GPS_GLOBAL_ORIGIN); LinkError when the vehicle has none."""
    deadline = time.monotonic() + timeout
    next_ask = 0.0
    while time.monotonic() < deadline:
        if time.monotonic() >= next_ask:
            _command(
                conn,
                mavlink.MAV_CMD_REQUEST_MESSAGE,
                mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,
            )
            next_ask = time.monotonic() + 1.0
        msg = conn.recv_match(type="GPS_GLOBAL_ORIGIN", blocking=True, timeout=0.2)
        if msg is not None:
            return msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3
    url = getattr(conn, "swingrt_url", "the link")
    raise LinkError(
        f"no GPS_GLOBAL_ORIGIN from {url} within {timeout:g} s: the vehicle's estimator has "
        "no global origin yet (no GPS fix?), so a plan cannot be placed"
    )


def plan_offset(
    mission: _core.Mission,
    origin: tuple[float, float, float] | None,
    offset: tuple[float, float] = (0.0, 0.0),
) -> tuple[float, float]:
    """Where the plan's north/east origin lies in PX4's local frame [m] (module doc)."""
    home = mission.home
    dn, de = float(offset[0]), float(offset[1])
    if home is None:
        return dn, de
    if origin is None:
        raise ConfigError(
            f"mission {mission.name!r}: a plan with a home position needs the vehicle's "
            "global origin to be placed"
        )
    n, e = _core.geo_project(origin[0], origin[1], home[0], home[1])
    return n + dn, e + de


def px4_items(
    mission: _core.Mission, origin: tuple[float, float, float]
) -> tuple[list[dict], list[int]]:
    """The MISSION_ITEM_INT fields of ``mission`` (already in PX4's local frame) for PX4, and
    for each of the plan's items the sequence number PX4 reports it reached by."""
    out: list[dict] = []
    seqs: list[int] = []
    speed = None
    nan = math.nan
    for it in mission.items:
        if it["speed"] and it["speed"] != speed:
            speed = float(it["speed"])
            out.append(
                {
                    "command": mavlink.MAV_CMD_DO_CHANGE_SPEED,
                    "frame": mavlink.MAV_FRAME_MISSION,
                    "params": (1.0, speed, -1.0, 0.0),
                    "x": 0,
                    "y": 0,
                    "z": 0.0,
                }
            )
        n, e, d = it["position"]
        lat, lon = _core.geo_reproject(origin[0], origin[1], n, e)
        kind = it["kind"]
        params = {
            "takeoff": (0.0, 0.0, 0.0, nan),
            "waypoint": (float(it["hold"]), float(it["acceptance_radius"]), 0.0, nan),
            "land": (0.0, 0.0, 0.0, nan),
        }[kind]
        seqs.append(len(out))
        out.append(
            {
                "command": _NAV[kind],
                "frame": mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                "params": params,
                "x": int(round(lat * 1e7)),
                "y": int(round(lon * 1e7)),
                "z": float(-d),
            }
        )
    return out, seqs


def _result_name(value: int) -> str:
    entry = mavlink.enums["MAV_MISSION_RESULT"].get(value)
    return entry.name if entry is not None else str(value)


def upload(conn, items: list[dict], *, timeout: float = PROTOCOL_TIMEOUT) -> None:
    """Send ``items`` (:func:`px4_items`) to the vehicle by the mission protocol; returns
    when it accepts them all, raises LinkError with one line naming its refusal (the
    MAV_MISSION_RESULT) or its silence."""
    url = getattr(conn, "swingrt_url", "the link")
    count = len(items)
    mission_type = mavlink.MAV_MISSION_TYPE_MISSION
    tries = 0
    requested: set[int] = set()
    deadline = 0.0
    while True:
        now = time.monotonic()
        if now >= deadline:
            if requested:
                missing = sorted(set(range(count)) - requested)
                raise LinkError(
                    f"mission upload to {url} stalled: no request for item {missing[0]} "
                    f"within {timeout:g} s"
                )
            if tries >= COUNT_TRIES:
                raise LinkError(
                    f"mission upload to {url}: no answer to MISSION_COUNT after {tries} tries"
                )
            conn.mav.mission_count_send(
                conn.target_system, conn.target_component, count, mission_type
            )
            tries += 1
            deadline = now + timeout / COUNT_TRIES
        msg = conn.recv_match(
            type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"],
            blocking=True,
            timeout=0.1,
        )
        if msg is None or msg.get_srcSystem() != conn.target_system:
            continue
        if getattr(msg, "mission_type", mission_type) != mission_type:
            continue
        if msg.get_type() == "MISSION_ACK":
            if msg.type == mavlink.MAV_MISSION_ACCEPTED and len(requested) == count:
                log.info("mission of %d items accepted", count)
                return
            if msg.type != mavlink.MAV_MISSION_ACCEPTED:
                raise LinkError(f"vehicle refused the mission: {_result_name(msg.type)}")
            continue
        seq = int(msg.seq)
        if not 0 <= seq < count:
            raise LinkError(f"vehicle asked for mission item {seq} of {count}")
        requested.add(seq)
        it = items[seq]
        conn.mav.mission_item_int_send(
            conn.target_system,
            conn.target_component,
            seq,
            it["frame"],
            it["command"],
            0,
            1,
            *it["params"],
            it["x"],
            it["y"],
            it["z"],
            mission_type,
        )
        deadline = time.monotonic() + timeout


def fly_px4_mission(
    conn,
    mission: _core.Mission,
    *,
    offset: tuple[float, float] = (0.0, 0.0),
    ts: float = 0.02,
    log_path=None,
    **session_options,
) -> MissionFlight:
    """Upload ``mission`` to PX4 and fly it by AUTO.MISSION (module doc), logging the
    telemetry at 1/``ts``; the events are the items PX4 reported reached, and each one's
    end of hold. Ends in AUTO.LOITER."""
    session = OffboardSession(conn, ts=ts, **session_options)
    session.connect(swing=False)
    origin = global_origin(conn)
    dn, de = plan_offset(mission, origin, offset)
    local = mission.shifted((dn, de, 0.0))
    items, seqs = px4_items(local, origin)
    upload(conn, items)
    session.poll()
    session.tel.reached.clear()
    limit = time_limit(local)
    last = seqs[-1]
    session.set_mode(AUTO_MISSION)
    t0 = time.monotonic()

    def done() -> bool:
        # PX4 reports an item when it is done with it (its hold over), the last one too.
        return any(seq == last and time.monotonic() >= t + TAIL_S for t, seq in session.tel.reached)

    try:
        report = session.watch(limit, done)
    finally:
        try:
            session.set_mode(AUTO_LOITER)
        except FlightAbort as exc:
            log.warning("%s", exc)
    by_seq = {s: k for k, s in enumerate(seqs)}
    reported: dict[int, float] = {}
    for t, seq in session.tel.reached:  # PX4 may repeat a report: the first one counts
        if seq in by_seq and by_seq[seq] not in reported:
            reported[by_seq[seq]] = t - t0
    _finish(report, log_path, session.log_meta)
    if len(seqs) - 1 not in reported:
        raise FlightAbort(
            f"PX4's mission {mission.name!r} did not finish within {limit:.0f} s "
            f"(PX4 reported {len(reported)} of {len(seqs)} items done)"
        )
    from swingrt.mission import replay_events

    events = replay_events(local, report.columns)
    return MissionFlight(report, local, events, sorted((t, k) for k, t in reported.items()))


def fly_mission(
    conn,
    model: _core.LinearModel,
    mission: _core.Mission,
    *,
    legs: dict | None = None,
    tracking: dict | None = None,
    offset: tuple[float, float] = (0.0, 0.0),
    origin: tuple[float, float, float] | None = None,
    acc_limit: float | None = None,
    log_path=None,
    **session_options,
) -> MissionFlight:
    """Fly ``mission`` offboard with the tracking MPC on ``model`` along the guidance's legs
    (``legs``: guidance settings, default :func:`swingrt.mission.shaped_legs`), module doc.
    ``origin``: PX4's global origin, needed (and else asked for) by a plan with a home."""
    from swingrt import mission as ms

    ms.check_model(model)
    legs = ms.shaped_legs(model) if legs is None else legs
    controller = _core.TrackingMpc(model, tracking)
    own = _core.check_settings("tracking", tracking)["mpc"]["acc_max"]
    limit = float(own) if acc_limit is None else float(acc_limit)
    session = OffboardSession(conn, ts=model.dt, **session_options)
    session.connect()
    if mission.home is not None and origin is None:
        origin = global_origin(conn)
    dn, de = plan_offset(mission, origin, offset)
    local = mission.shifted((dn, de, 0.0))
    guidance = _core.Guidance(local, legs)
    state = np.zeros((2, 3))
    ts = model.dt

    def fill(tel, rate) -> None:
        state[0] = (tel.vel[0], tel.swing[0], rate[0])
        state[1] = (tel.vel[1], tel.swing[1], rate[1])

    def reset(tel) -> None:
        fill(tel, (0.0, 0.0))
        guidance.start(0.0, tel.pos, tel.vel)
        guidance.update(0.0, 0.0, tel.pos, tel.vel)
        controller.reset(state.copy(), tel.pos[:2], guidance, 0.0)

    def policy(k, t, tel, rate):
        fill(tel, rate)
        sp = guidance.update(t, ts if k else 0.0, tel.pos, tel.vel)
        a = np.asarray(controller.step(state, tel.pos[:2], guidance, t), dtype=float)
        if a.shape != (2,) or not np.all(np.isfinite(a)):
            raise ControlError(f"tracking MPC returned {a!r}, expected 2 finite values")
        an, ae = (float(np.clip(x, -limit, limit)) for x in a)
        return (
            MASK_ACC_ALT_HOLD,
            (0.0, 0.0, float(sp[0][2])),
            (0.0, 0.0, 0.0),
            (an, ae, 0.0),
            (float(sp[1][0]), float(sp[1][1])),
        )

    report = session.run(policy, time_limit(local), reset=reset, until=lambda: guidance.done)
    events = list(guidance.events())
    _finish(report, log_path, session.log_meta)
    if not guidance.done:
        raise FlightAbort(
            f"mission {mission.name!r} not finished within {time_limit(local):.0f} s; "
            "control handed back to the flight controller"
        )
    return MissionFlight(report, local, events)
