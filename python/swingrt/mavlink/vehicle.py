"""A simulated PX4 vehicle behind a MAVLink endpoint (``swingrt sitl``).

The physics and PX4's control cascade are the simulator's (``swingrt.Simulator``); this
module is the part of PX4 an offboard computer talks to, reproduced from PX4-Autopilot's
commander and mavlink modules:

- HEARTBEAT with ``MAV_AUTOPILOT_PX4``, ``MAV_TYPE_QUADROTOR`` and PX4's custom mode
  ``(main << 16) | (sub << 24)`` (px4_custom_mode.h); the vehicle starts airborne, armed, in
  AUTO.LOITER (hold) at the simulator's initial state.
- Telemetry: ATTITUDE_QUATERNION, LOCAL_POSITION_NED, POSITION_TARGET_LOCAL_NED (the
  acceleration setpoint of PX4's velocity controller in ``afx afy afz``, as PX4 streams
  ``vehicle_local_position_setpoint``), and the swing angles as DEBUG_VECT named ``SWING``:
  ``x = swing_n``, ``y = swing_e``, ``z = 0``, radians, ``time_usec`` = simulator time; with
  no sensor on the cable (the scenario's swing source ``imu``) no ``SWING`` goes out and the
  true swing goes as DEBUG_VECT ``SWTRUE`` instead (for the node's log only, as ``swingrt
  hil`` does); HIGHRES_IMU, the simulator's IMU as PX4 streams ``sensor_combined``: body
  specific force [m/s²] and angular rate [rad/s], FRD, filtered as PX4 filters them
  (``fields_updated`` = accelerometer and gyro).
  Default 50 Hz each, HEARTBEAT 1 Hz; MAV_CMD_SET_MESSAGE_INTERVAL changes any of them.
- Commands (COMMAND_LONG, answered by COMMAND_ACK): MAV_CMD_COMPONENT_ARM_DISARM (arming is
  accepted; disarming in the air is denied: the simulator does not model landing),
  MAV_CMD_SET_MESSAGE_INTERVAL, MAV_CMD_DO_SET_MODE with MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and
  a PX4 main/sub mode: POSCTL and AUTO.LOITER hold the current position; OFFBOARD is
  TEMPORARILY_REJECTED until valid setpoints have streamed (gaps < 0.5 s, i.e. > 2 Hz as PX4
  requires) for ``offboard_min_stream`` (1 s). SET_MODE (legacy) is honoured the same way.
  Like PX4, a mode command is acknowledged twice.
- SET_POSITION_TARGET_LOCAL_NED in MAV_FRAME_LOCAL_NED, read as PX4's mavlink receiver and
  PositionControl do: an ignored field is NaN; per axis the position is used if given,
  else the velocity, else the acceleration (feed-forward terms are not modelled); North and
  East must come in pairs (same kind); force setpoints (bit 10) and other frames are refused.
  So: acceleration (x y z vx vy vz ignored), mixed (z position + North/East acceleration),
  velocity (vx vy [vz] used) and position setpoints all work.
- Offboard loss (PX4's COM_OF_LOSS_T, default 1 s): in OFFBOARD, when no valid setpoint has
  arrived for that long, the vehicle switches to AUTO.LOITER and holds position
  (COM_OBL_RC_ACT's hold fallback with no RC).
- Robustness: bytes that do not parse (BAD_DATA), unknown messages, messages addressed to
  another system/component and non-finite setpoints are dropped with a rate-limited warning.

Time: the loop runs on a fixed schedule of absolute deadlines (``rate_hz``, scaled by
``speed``); all vehicle timing (stream age, offboard loss) is in simulator time.
"""

from __future__ import annotations

import logging
import math
import signal
import threading
import time
from dataclasses import dataclass

import numpy as np

from swingrt.errors import SetpointError
from swingrt.io.flight import write_columns
from swingrt.mavlink.link import (
    BODY_NAME,
    PX4_MAIN_MODE,
    PX4_SUB_MODE_AUTO,
    SWING_NAME,
    TRUTH_NAME,
    connect,
    mavlink,
    mode_name,
    px4_custom_mode,
)

__all__ = ["Vehicle", "run_vehicle", "TYPE_MASK", "parse_setpoint", "SetpointError"]

log = logging.getLogger("swingrt.mavlink.vehicle")

#: POSITION_TARGET_TYPEMASK bits (MAVLink common.xml).
TYPE_MASK = {
    "X": 1,
    "Y": 2,
    "Z": 4,
    "VX": 8,
    "VY": 16,
    "VZ": 32,
    "AX": 64,
    "AY": 128,
    "AZ": 256,
    "FORCE": 512,
    "YAW": 1024,
    "YAW_RATE": 2048,
}

POSCTL = (PX4_MAIN_MODE["POSCTL"], 0)
LOITER = (PX4_MAIN_MODE["AUTO"], PX4_SUB_MODE_AUTO["LOITER"])
OFFBOARD = (PX4_MAIN_MODE["OFFBOARD"], 0)

#: Telemetry messages the vehicle can stream, with their default interval in seconds.
DEFAULT_STREAMS = {
    mavlink.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 0.02,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.02,
    mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 0.02,
    mavlink.MAVLINK_MSG_ID_DEBUG_VECT: 0.02,
    mavlink.MAVLINK_MSG_ID_HIGHRES_IMU: 0.02,
}

#: HIGHRES_IMU ``fields_updated`` bits of the accelerometer (0-2) and gyro (3-5).
IMU_FIELDS = 0b11_1111


def parse_setpoint(msg) -> dict[str, tuple[str, float]]:
    """Per-axis (mode, value) of a SET_POSITION_TARGET_LOCAL_NED, as PX4 interprets it.

    Returns ``{"n": (mode, value), "e": ..., "d": ...}`` with mode ``pos|vel|acc``;
    raises :class:`SetpointError` for what PX4 refuses (module doc).
    """
    if msg.coordinate_frame != mavlink.MAV_FRAME_LOCAL_NED:
        raise SetpointError(f"coordinate frame {msg.coordinate_frame} unsupported (use 1)")
    mask = msg.type_mask
    if mask & TYPE_MASK["FORCE"]:
        raise SetpointError("force setpoints (type_mask bit 10) are not supported")
    fields = {
        "n": (("X", msg.x), ("VX", msg.vx), ("AX", msg.afx)),
        "e": (("Y", msg.y), ("VY", msg.vy), ("AY", msg.afy)),
        "d": (("Z", msg.z), ("VZ", msg.vz), ("AZ", msg.afz)),
    }
    out: dict[str, tuple[str, float]] = {}
    for axis, triple in fields.items():
        for kind, (bit, value) in zip(("pos", "vel", "acc"), triple, strict=True):
            if mask & TYPE_MASK[bit]:
                continue
            if not math.isfinite(value):
                raise SetpointError(f"{bit.lower()} is not finite")
            out[axis] = (kind, float(value))
            break
        else:
            raise SetpointError(f"no position, velocity or acceleration for axis {axis}")
    if out["n"][0] != out["e"][0]:
        raise SetpointError("North and East setpoints must be of the same kind (PX4 pairs x/y)")
    return out


@dataclass
class _Stream:
    interval: float  # s, <= 0: off
    next_due: float = 0.0


class Vehicle:
    """The PX4-like MAVLink side of a simulated vehicle (see the module doc).

    ``sim`` is any object with the ``swingrt.Simulator`` interface (``t``, ``advance``,
    ``set_setpoint``, ``state``, ``trace``); ``conns`` are pymavlink connections to serve.
    Call :meth:`tick` on a fixed schedule, or :meth:`run`.
    """

    def __init__(
        self,
        sim,
        conns,
        *,
        system_id: int = 1,
        component_id: int = 1,
        offboard_loss_timeout: float = 1.0,
        offboard_min_stream: float = 1.0,
        stream_max_gap: float = 0.5,
    ):
        self.sim = sim
        self.conns = list(conns)
        self.system_id = system_id
        self.component_id = component_id
        #: PX4 COM_OF_LOSS_T [s].
        self.offboard_loss_timeout = offboard_loss_timeout
        #: How long a setpoint stream must have run before OFFBOARD is accepted [s].
        self.offboard_min_stream = offboard_min_stream
        #: A longer gap between setpoints restarts the stream (PX4 wants > 2 Hz) [s].
        self.stream_max_gap = stream_max_gap
        self.armed = True
        self.mode = LOITER
        self.streams = {k: _Stream(v) for k, v in DEFAULT_STREAMS.items()}
        self._setpoint: dict[str, tuple[str, float]] | None = None
        self._setpoint_mask = 0
        self._last_sp = -math.inf
        self._stream_start = math.inf
        self._warned: dict[str, float] = {}
        #: Mode changes as (sim time, mode name), for logs and tests.
        self.events: list[tuple[float, str]] = []
        #: Number of malformed or refused inputs, by kind.
        self.rejected: dict[str, int] = {}
        self._hold_here()
        self.events.append((self.sim.t, mode_name(*self.mode)))

    # ---------------------------------------------------------------- modes

    def _hold_here(self) -> None:
        s = self.sim.state()
        self.sim.set_setpoint(n=("pos", s["pn"]), e=("pos", s["pe"]), d=("pos", s["pd"]))
        self._setpoint_mask = TYPE_MASK["VX"] | TYPE_MASK["VY"] | TYPE_MASK["VZ"]
        self._setpoint_mask |= TYPE_MASK["AX"] | TYPE_MASK["AY"] | TYPE_MASK["AZ"]
        self._hold = (s["pn"], s["pe"], s["pd"])

    def _set_mode(self, mode: tuple[int, int], why: str) -> None:
        if mode == self.mode:
            return
        old = mode_name(*self.mode)
        self.mode = mode
        if mode != OFFBOARD:
            self._hold_here()
        elif self._setpoint is not None:
            self.sim.set_setpoint(**self._setpoint)
        name = mode_name(*mode)
        self.events.append((self.sim.t, name))
        log.info("t=%.3f s: mode %s -> %s (%s)", self.sim.t, old, name, why)
        self._statustext(f"mode {name}: {why}", mavlink.MAV_SEVERITY_INFO)
        self._send_heartbeat()  # let peers see the change now, not up to 1 s later

    def _stream_alive_for(self, now: float) -> float:
        if now - self._last_sp > self.stream_max_gap:
            return 0.0
        return now - self._stream_start

    def request_mode(self, main: int, sub: int, now: float) -> int:
        """Try to switch to PX4 mode (main, sub); return the MAV_RESULT."""
        if (main, sub) == OFFBOARD or main == PX4_MAIN_MODE["OFFBOARD"]:
            alive = self._stream_alive_for(now)
            if not self.armed:
                self._statustext("Offboard refused: not armed", mavlink.MAV_SEVERITY_WARNING)
                return mavlink.MAV_RESULT_DENIED
            if alive < self.offboard_min_stream:
                self._statustext(
                    f"Offboard refused: setpoints streamed {alive:.1f} s of "
                    f"{self.offboard_min_stream:.1f} s",
                    mavlink.MAV_SEVERITY_WARNING,
                )
                return mavlink.MAV_RESULT_TEMPORARILY_REJECTED
            self._set_mode(OFFBOARD, "requested")
            return mavlink.MAV_RESULT_ACCEPTED
        if main == PX4_MAIN_MODE["POSCTL"]:
            self._set_mode(POSCTL, "requested")
            return mavlink.MAV_RESULT_ACCEPTED
        if main == PX4_MAIN_MODE["AUTO"] and sub in (0, PX4_SUB_MODE_AUTO["LOITER"]):
            self._set_mode(LOITER, "requested")
            return mavlink.MAV_RESULT_ACCEPTED
        self._statustext(
            f"mode {mode_name(main, sub)} is not simulated", mavlink.MAV_SEVERITY_WARNING
        )
        return mavlink.MAV_RESULT_UNSUPPORTED

    # ---------------------------------------------------------------- input

    def _warn(self, kind: str, text: str) -> None:
        self.rejected[kind] = self.rejected.get(kind, 0) + 1
        now = time.monotonic()
        if now - self._warned.get(kind, -math.inf) >= 1.0:  # at most one line/s per kind
            self._warned[kind] = now
            log.warning("%s (%d so far)", text, self.rejected[kind])

    def _for_us(self, msg, kind: str) -> bool:
        ts, tc = msg.target_system, msg.target_component
        if ts not in (0, self.system_id) or tc not in (0, self.component_id):
            self._warn(
                f"wrong_target_{kind}",
                f"ignored {kind} for system {ts} component {tc} "
                f"(we are {self.system_id}/{self.component_id})",
            )
            return False
        return True

    def handle(self, msg, conn, now: float) -> None:
        """Act on one received message (never raises)."""
        kind = msg.get_type()
        try:
            if kind == "BAD_DATA":
                self._warn("bad_data", "dropped bytes that are not MAVLink")
            elif kind == "SET_POSITION_TARGET_LOCAL_NED":
                if self._for_us(msg, kind):
                    self._on_setpoint(msg, now)
            elif kind == "COMMAND_LONG":
                if self._for_us(msg, kind):
                    self._on_command(msg, conn, now)
            elif kind == "SET_MODE":
                if msg.target_system in (0, self.system_id):
                    if msg.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                        main = (msg.custom_mode >> 16) & 0xFF
                        sub = (msg.custom_mode >> 24) & 0xFF
                        self.request_mode(main, sub, now)
                else:
                    self._warn("wrong_target", f"ignored SET_MODE for system {msg.target_system}")
            elif kind in ("HEARTBEAT", "STATUSTEXT", "PARAM_REQUEST_LIST", "SYSTEM_TIME"):
                pass  # peers' heartbeats etc.: nothing to do
            else:
                self._warn(f"unknown_{kind}", f"ignored unsupported message {kind}")
        except Exception as exc:  # a peer must never crash the vehicle
            self._warn("error", f"error handling {kind}: {exc!r}")

    def _on_setpoint(self, msg, now: float) -> None:
        try:
            sp = parse_setpoint(msg)
        except SetpointError as exc:
            self._warn("bad_setpoint", f"refused SET_POSITION_TARGET_LOCAL_NED: {exc}")
            return
        if now - self._last_sp > self.stream_max_gap:
            self._stream_start = now
        self._last_sp = now
        self._setpoint = sp
        self._setpoint_mask = msg.type_mask
        if self.mode == OFFBOARD:
            self.sim.set_setpoint(**sp)

    def _ack(self, conn, command: int, result: int) -> None:
        conn.mav.command_ack_send(command, result)

    def _on_command(self, msg, conn, now: float) -> None:
        cmd = msg.command
        if cmd == mavlink.MAV_CMD_DO_SET_MODE:
            if not int(msg.param1) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                self._ack(conn, cmd, mavlink.MAV_RESULT_UNSUPPORTED)
                return
            result = self.request_mode(int(msg.param2), int(msg.param3), now)
            # PX4 acknowledges a mode command twice on the link it came in on (seen on PX4
            # SITL): a node must not take the second ack for the answer to its next request.
            self._ack(conn, cmd, result)
            self._ack(conn, cmd, result)
        elif cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if msg.param1 >= 0.5:
                self.armed = True
                self._ack(conn, cmd, mavlink.MAV_RESULT_ACCEPTED)
            else:
                self._statustext("Disarm refused: vehicle in air", mavlink.MAV_SEVERITY_WARNING)
                self._ack(conn, cmd, mavlink.MAV_RESULT_DENIED)
        elif cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            msg_id, interval_us = int(msg.param1), msg.param2
            if msg_id not in self.streams or not math.isfinite(interval_us):
                self._ack(conn, cmd, mavlink.MAV_RESULT_UNSUPPORTED)
                return
            if interval_us < 0:
                self.streams[msg_id].interval = 0.0
            elif interval_us == 0:
                self.streams[msg_id].interval = DEFAULT_STREAMS[msg_id]
            else:
                self.streams[msg_id].interval = interval_us * 1e-6
            self.streams[msg_id].next_due = now
            self._ack(conn, cmd, mavlink.MAV_RESULT_ACCEPTED)
        else:
            self._warn(f"cmd_{cmd}", f"unsupported command {cmd}")
            self._ack(conn, cmd, mavlink.MAV_RESULT_UNSUPPORTED)

    # ---------------------------------------------------------------- output

    def _each(self, fn) -> None:
        for c in self.conns:
            try:
                fn(c.mav)
            except OSError as exc:
                self._warn("send", f"send failed: {exc}")

    def _statustext(self, text: str, severity: int) -> None:
        data = text.encode("ascii", "replace")[:50]
        self._each(lambda m: m.statustext_send(severity, data))

    def _send_heartbeat(self) -> None:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
        if self.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        if self.mode in (OFFBOARD, LOITER, POSCTL):
            base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
        custom = px4_custom_mode(*self.mode)
        self._each(
            lambda m: m.heartbeat_send(
                mavlink.MAV_TYPE_QUADROTOR,
                mavlink.MAV_AUTOPILOT_PX4,
                base,
                custom,
                mavlink.MAV_STATE_ACTIVE,
            )
        )

    def _send(self, msg_id: int, s: dict) -> None:
        ms = int(round(s["t"] * 1000.0)) & 0xFFFFFFFF
        if msg_id == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            self._send_heartbeat()
        elif msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION:
            self._each(
                lambda m: m.attitude_quaternion_send(
                    ms, s["q0"], s["q1"], s["q2"], s["q3"], s["p"], s["q"], s["r"]
                )
            )
        elif msg_id == mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            self._each(
                lambda m: m.local_position_ned_send(
                    ms, s["pn"], s["pe"], s["pd"], s["vn"], s["ve"], s["vd"]
                )
            )
        elif msg_id == mavlink.MAVLINK_MSG_ID_DEBUG_VECT:
            us = int(round(s["t"] * 1e6))
            truth = (s.get("swing_true_n", math.nan), s.get("swing_true_e", math.nan))
            counts = (s.get("adc_x", math.nan), s.get("adc_y", math.nan))
            name, sn, se = SWING_NAME, s["swing_n"], s["swing_e"]
            if all(math.isfinite(c) for c in counts):
                # A cable sensor on the airframe sends its raw counts; the truth beside.
                name, (sn, se) = BODY_NAME, counts
                self._each(lambda m: m.debug_vect_send(TRUTH_NAME.encode(), us, *truth, 0.0))
            elif not (math.isfinite(sn) and math.isfinite(se)):
                name, (sn, se) = TRUTH_NAME, truth
            self._each(lambda m: m.debug_vect_send(name.encode(), us, sn, se, 0.0))
        elif msg_id == mavlink.MAVLINK_MSG_ID_HIGHRES_IMU and "imu_ax" in s:
            # (a simulator without an IMU, such as the tests' stand-ins, sends none)
            us = int(round(s["t"] * 1e6))
            acc = (s["imu_ax"], s["imu_ay"], s["imu_az"])
            gyro = (s["imu_gx"], s["imu_gy"], s["imu_gz"])
            self._each(
                lambda m: m.highres_imu_send(
                    us, *acc, *gyro, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, IMU_FIELDS, 0
                )
            )
        elif msg_id == mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED:
            sp = self._setpoint if self.mode == OFFBOARD and self._setpoint else None
            pos = [math.nan] * 3
            vel = [math.nan] * 3
            if sp is None:
                pos = list(self._hold)
            else:
                for i, axis in enumerate("ned"):
                    kind, value = sp[axis]
                    if kind == "pos":
                        pos[i] = value
                    elif kind == "vel":
                        vel[i] = value
            self._each(
                lambda m: m.position_target_local_ned_send(
                    ms,
                    mavlink.MAV_FRAME_LOCAL_NED,
                    self._setpoint_mask if sp is not None else 0,
                    *pos,
                    *vel,
                    s["acc_sp_n"],
                    s["acc_sp_e"],
                    s["acc_sp_d"],
                    math.nan,
                    math.nan,
                )
            )

    # ---------------------------------------------------------------- loop

    def poll(self, now: float) -> None:
        """Drain every connection's input without blocking."""
        for conn in self.conns:
            for _ in range(1000):  # bounded: a flood cannot starve the physics
                try:
                    msg = conn.recv_msg()
                except Exception as exc:  # pymavlink raises on some garbage; drop it
                    self._warn("bad_data", f"dropped unparsable input ({exc})")
                    continue
                if msg is None:
                    # A datagram of garbage parses to nothing too: read on unless the
                    # link was empty (see ``link._track_reads``).
                    if getattr(conn, "swingrt_bytes_read", 0) > 0:
                        continue
                    break
                self.handle(msg, conn, now)

    def tick(self, dt: float) -> None:
        """One fixed-schedule step: read input, supervise modes, advance dt, stream telemetry."""
        now = self.sim.t
        self.poll(now)
        if self.mode == OFFBOARD and now - self._last_sp > self.offboard_loss_timeout:
            self._statustext("Offboard lost: holding position", mavlink.MAV_SEVERITY_CRITICAL)
            self._set_mode(LOITER, f"no setpoint for {self.offboard_loss_timeout:g} s")
        self.sim.advance(dt)
        s = self.sim.state()
        now = self.sim.t
        for msg_id, st in self.streams.items():
            if st.interval > 0 and now + 1e-9 >= st.next_due:
                self._send(msg_id, s)
                st.next_due = max(st.next_due + st.interval, now)

    def run(
        self,
        *,
        rate_hz: float = 100.0,
        speed: float = 1.0,
        duration: float | None = None,
        stop: threading.Event | None = None,
    ) -> dict:
        """Tick at ``rate_hz`` (simulator time; wall clock scaled by ``speed``) until ``stop``
        is set or ``duration`` simulated seconds passed. Returns loop statistics."""
        dt = 1.0 / rate_hz
        period = dt / speed
        stop = stop or threading.Event()
        t_end = self.sim.t + duration if duration is not None else math.inf
        # per-tick lateness and compute time, in a preallocated ring (last hour at 100 Hz)
        ring = np.zeros((2, 360_000))
        t_wall = time.perf_counter()
        start = t_wall
        k = 0
        late = 0
        while not stop.is_set() and self.sim.t < t_end - 1e-9:
            deadline = start + k * period
            now = time.perf_counter()
            if deadline > now:
                time.sleep(deadline - now)
                now = time.perf_counter()
            elif now - deadline > 0.1:  # fell behind (machine stalled): re-anchor, no burst
                late += 1
                start = now - k * period
                deadline = now
            self.tick(dt)
            i = k % ring.shape[1]
            ring[0, i] = now - deadline
            ring[1, i] = time.perf_counter() - now
            k += 1
        used = ring[:, : min(k, ring.shape[1])]

        def pct(x, q):
            return float(np.percentile(x, q)) if x.size else math.nan

        return {
            "ticks": k,
            "late": late,
            "wall_s": time.perf_counter() - t_wall,
            "lateness_median_s": pct(used[0], 50),
            "lateness_p99_s": pct(used[0], 99),
            "tick_median_s": pct(used[1], 50),
            "tick_p99_s": pct(used[1], 99),
        }


def run_vehicle(
    sim,
    listen,
    *,
    log_path=None,
    rate_hz: float = 100.0,
    speed: float = 1.0,
    duration: float | None = None,
    system_id: int = 1,
    **vehicle_options,
) -> Vehicle:
    """Serve ``sim`` on the ``listen`` URL(s) until SIGINT/SIGTERM or ``duration``.

    On exit (signal included) the simulator's trace is written to ``log_path`` atomically.
    """
    urls = [listen] if isinstance(listen, str) else list(listen)
    conns = [connect(u, role="vehicle", system_id=system_id, component_id=1) for u in urls]
    vehicle = Vehicle(sim, conns, system_id=system_id, **vehicle_options)
    stop = threading.Event()
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda *_: stop.set())
    log.info("sitl: system %d listening on %s", system_id, ", ".join(urls))
    try:
        stats = vehicle.run(rate_hz=rate_hz, speed=speed, duration=duration, stop=stop)
        log.info(
            "sitl: %d ticks in %.1f s wall, %d re-anchors; tick start late median %.3f ms "
            "p99 %.3f ms; tick compute median %.3f ms p99 %.3f ms",
            stats["ticks"],
            stats["wall_s"],
            stats["late"],
            stats["lateness_median_s"] * 1e3,
            stats["lateness_p99_s"] * 1e3,
            stats["tick_median_s"] * 1e3,
            stats["tick_p99_s"] * 1e3,
        )
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if log_path is not None:
            trace = sim.trace()
            # Parquet keeps the trace's metadata (the scenario) when it has any.
            write_columns(trace.columns, log_path, meta=getattr(trace, "meta", None))
            log.info("sitl: trace written to %s", log_path)
        for c in conns:
            c.close()
    return vehicle
