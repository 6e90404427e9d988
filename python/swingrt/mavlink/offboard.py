"""The offboard node (``swingrt fly``): swing-damping control over MAVLink at 1/Ts.

Sequence (PX4 offboard rules, docs.px4.io "Offboard Mode"):

1. wait for the autopilot's HEARTBEAT; request telemetry at 100 Hz with
   MAV_CMD_SET_MESSAGE_INTERVAL (LOCAL_POSITION_NED, ATTITUDE_QUATERNION, DEBUG_VECT,
   POSITION_TARGET_LOCAL_NED; HIGHRES_IMU when the swing comes from the IMU); wait until
   position and the swing arrive: the swing sensor (DEBUG_VECT "SWING"), or with a model
   identified on the IMU (``swing_source = "imu"``) the swing estimated from PX4's own IMU
   (HIGHRES_IMU's body specific force, block means at the estimator's rate, composed with
   ATTITUDE_QUATERNION by ``_core.ImuSwingEstimator`` with the model's settings), once its
   tare (the payload hanging still in PX4's hold) is over;
2. latch the altitude and heading; stream neutral setpoints for ``prestream`` seconds (PX4
   refuses OFFBOARD without a > 2 Hz stream), then request OFFBOARD (MAV_CMD_DO_SET_MODE,
   custom main mode 6), retrying while TEMPORARILY_REJECTED;
3. at every tick k (absolute deadline t0 + k Ts; no drift, missed deadlines are skipped and
   counted): read the newest telemetry, build the controller state per axis
   ``[v, swing, swing_rate]`` (swing rate by backward difference over Ts, as the MPC's model
   uses, thesis 5.4), ``a = controller.step(state, vel_ref)``, clip to the MPC's own bound, send
   SET_POSITION_TARGET_LOCAL_NED with :data:`MASK_ACC_ALT_HOLD` (North/East acceleration,
   altitude by position z, yaw held);
4. at the end of the mission: switch to the hold mode (AUTO.LOITER by default) while still
   streaming, and stop once the vehicle confirms.

Watchdogs (checked every tick before computing): telemetry older than ``stale_factor`` Ts,
``overrun_ticks`` consecutive ticks whose compute time exceeds ``budget`` (default Ts/2),
no autopilot heartbeat for ``link_timeout``, or the vehicle leaving OFFBOARD by itself. On any
of them the node sends a zero-velocity setpoint (PX4's own velocity hold), requests the hold
mode and ends with a :class:`FlightAbort` naming the cause; ``swingrt fly`` prints it as one
line and exits non-zero.

Loop timing is recorded per tick: period jitter (start minus deadline) and compute time
(telemetry snapshot to setpoint sent); :class:`FlightReport` gives median / p99 / max.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swingrt import _core
from swingrt._core import AdaptiveMpc, Controller, ImuSwingEstimator, Mpc, check_settings
from swingrt.errors import (
    ConfigError,
    ControlError,
    FlightAbort,
    LinkError,
    ModelError,
    SwingrtError,
)
from swingrt.io.flight import TRACE_COLUMNS, write_columns
from swingrt.mavlink.link import (
    BODY_NAME,
    PX4_MAIN_MODE,
    PX4_SUB_MODE_AUTO,
    SWING_NAME,
    TRUTH_NAME,
    decode_px4_mode,
    mavlink,
    mode_name,
    send_heartbeat,
    wait_heartbeat,
)
from swingrt.mavlink.vehicle import TYPE_MASK

__all__ = [
    "MASK_ACC_ALT_HOLD",
    "MASK_VEL_ALT_HOLD",
    "Mission",
    "Telemetry",
    "Watchdog",
    "FlightAbort",
    "FlightReport",
    "OffboardSession",
    "fly",
    "load_controller",
    "model_body_sensor",
    "model_swing_estimator",
]

log = logging.getLogger("swingrt.mavlink.offboard")

_M = TYPE_MASK
#: North/East acceleration, altitude by position z, yaw angle used (yaw rate ignored).
MASK_ACC_ALT_HOLD = _M["X"] | _M["Y"] | _M["VX"] | _M["VY"] | _M["VZ"] | _M["AZ"] | _M["YAW_RATE"]
#: North/East velocity, altitude by position z, yaw angle used: PX4's own velocity control.
MASK_VEL_ALT_HOLD = _M["X"] | _M["Y"] | _M["VZ"] | _M["AX"] | _M["AY"] | _M["AZ"] | _M["YAW_RATE"]

HOLD_MODES = {
    "loiter": (PX4_MAIN_MODE["AUTO"], PX4_SUB_MODE_AUTO["LOITER"]),
    "posctl": (PX4_MAIN_MODE["POSCTL"], 0),
}
OFFBOARD_MAIN = PX4_MAIN_MODE["OFFBOARD"]


# ----------------------------------------------------------------------------- mission


@dataclass
class Mission:
    """Piecewise-constant velocity references: ``steps`` of (t [s], vn [m/s], ve [m/s])."""

    steps: list[tuple[float, float, float]]
    duration: float

    @classmethod
    def default(cls) -> Mission:
        """The 2 m/s North step at t = 2 s, held 10 s, then back to 0 for 10 s."""
        return cls([(0.0, 0.0, 0.0), (2.0, 2.0, 0.0), (12.0, 0.0, 0.0)], 22.0)

    @classmethod
    def from_toml(cls, path) -> Mission:
        """``duration = S`` (optional) and ``[[step]]`` tables (or ``steps = [...]``) of
        ``{t, vn, ve}``; ``ve`` defaults to 0. Errors name the field."""
        import tomllib

        p = Path(path)
        try:
            doc = tomllib.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ConfigError(f"{p}: no such mission file") from None
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{p}: invalid TOML: {exc}") from None
        unknown = set(doc) - {"step", "steps", "duration"}
        if unknown:
            raise ConfigError(f"{p}: unknown key(s) {', '.join(sorted(unknown))}")
        raw = doc.get("step", doc.get("steps"))
        if not isinstance(raw, list) or not raw:
            raise ConfigError(f"{p}: a mission needs [[step]] entries with t, vn, ve")
        steps = []
        for i, st in enumerate(raw):
            if not isinstance(st, dict):
                raise ConfigError(f"{p}: step[{i}] must be a table {{t, vn, ve}}")
            bad = set(st) - {"t", "vn", "ve"}
            if bad:
                raise ConfigError(f"{p}: step[{i}]: unknown key(s) {', '.join(sorted(bad))}")
            try:
                t, vn, ve = float(st["t"]), float(st.get("vn", 0.0)), float(st.get("ve", 0.0))
            except KeyError:
                raise ConfigError(f"{p}: step[{i}].t is missing") from None
            except (TypeError, ValueError):
                raise ConfigError(f"{p}: step[{i}]: t, vn, ve must be numbers") from None
            if not all(map(math.isfinite, (t, vn, ve))) or t < 0:
                raise ConfigError(f"{p}: step[{i}]: t must be >= 0 and values finite")
            if abs(vn) > 15 or abs(ve) > 15:
                raise ConfigError(f"{p}: step[{i}]: |vn|, |ve| must be <= 15 m/s")
            steps.append((t, vn, ve))
        ts = [s[0] for s in steps]
        if ts != sorted(ts) or len(set(ts)) != len(ts):
            raise ConfigError(f"{p}: step times must increase")
        duration = float(doc.get("duration", ts[-1] + 10.0))
        if not math.isfinite(duration) or duration <= ts[-1]:
            raise ConfigError(f"{p}: duration must be after the last step time")
        return cls(steps, duration)

    def reference(self, t: float) -> tuple[float, float]:
        """(vn, ve) in force at time t."""
        vn = ve = 0.0
        for ts, a, b in self.steps:
            if ts <= t + 1e-12:
                vn, ve = a, b
            else:
                break
        return vn, ve


# ----------------------------------------------------------------------------- telemetry

#: Magnitude limits beyond which a telemetry message is dropped as absurd (not finite, or a
#: corrupted value that passed the CRC): position [m] and velocity [m/s]; quaternion entries
#: and the tolerance on its norm; swing angles [rad]; acceleration setpoints [m/s²].
TELEMETRY_LIMITS: dict[str, tuple[float, ...]] = {
    "LOCAL_POSITION_NED": (1e5, 100.0),
    "ATTITUDE_QUATERNION": (1.5, 0.1),
    "DEBUG_VECT": (math.pi,),
    "POSITION_TARGET_LOCAL_NED": (100.0,),
    "HIGHRES_IMU": (1000.0,),
}

#: Largest ADC count a cable sensor on the airframe may send (a 24-bit ADC's range, the
#: most ``[sensors.body] adc_bits`` allows).
BODY_COUNTS_LIMIT = float(2**24)

#: A time stamp this far back (ms; µs for DEBUG_VECT) is a reboot, not a replay.
REBOOT_JUMP: dict[str, int] = {
    "LOCAL_POSITION_NED": 10_000,
    "ATTITUDE_QUATERNION": 10_000,
    "DEBUG_VECT": 10_000_000,
    "POSITION_TARGET_LOCAL_NED": 10_000,
    "HIGHRES_IMU": 10_000_000,
}

#: A gap in the IMU stream longer than this [µs] restarts the estimator's sample grid
#: instead of feeding the held sample for every missed period.
IMU_GAP_US = 100_000


class Telemetry:
    """Newest vehicle state from MAVLink, with the local receive time of each part. With an
    ``estimator`` (``_core.ImuSwingEstimator``) the swing is the one it estimates from
    HIGHRES_IMU, not a swing sensor's."""

    def __init__(
        self, estimator: ImuSwingEstimator | None = None, body: dict | None = None
    ) -> None:
        nan = math.nan
        if body is not None:
            # The core checks the settings once (a bad field is named here, not mid-flight).
            body = dict(body)
            _core.body_swing(np.zeros((0, 2)), np.zeros((0, 4)), body)
        #: The cable sensor on the airframe (its ADC and calibration, ``[sensors.body]``):
        #: the swing is DEBUG_VECT :data:`BODY_NAME`'s counts composed with the attitude.
        self.body = body
        self.pos = [nan] * 3
        self.vel = [nan] * 3
        self.q = [1.0, 0.0, 0.0, 0.0]
        self.swing = [nan, nan]
        #: A simulator's true swing (DEBUG_VECT :data:`TRUTH_NAME`), for the metrics only.
        self.swing_true = [nan, nan]
        self.estimator = estimator
        self.t_imu = -math.inf
        self._imu_sum = [0.0, 0.0, 0.0]
        self._imu_count = 0
        self._imu_last: list[float] | None = None
        self._imu_next: float | None = None
        self._imu_period = 1e6 / float(estimator.settings["rate"]) if estimator else math.inf
        self.acc_sp = [nan] * 3
        #: PX4's clock [s] of the newest LOCAL_POSITION_NED (under ``swingrt hil``: the
        #: physics trace's time), to line the node's log up with the vehicle's.
        self.px4_time = nan
        #: Mission items PX4 reported reached (MISSION_ITEM_REACHED) as (receive time, seq).
        self.reached: list[tuple[float, int]] = []
        self.t_pos = self.t_att = self.t_swing = self.t_heartbeat = self.t_target = -math.inf
        self.mode: tuple[int, int] | None = None
        self.seen_offboard = False
        self.acks: list[tuple[int, int]] = []
        self.vehicle_sysid: int | None = None
        #: Why the newest telemetry message of a kind was dropped (absurd values, replayed).
        self.rejected: dict[str, str] = {}
        self._stamp: dict[str, int] = {}

    def _fresh(self, kind: str, stamp: int) -> bool:
        """Drop a message not newer than the last accepted one of its kind (a replayed or
        reordered packet); a jump back of more than 10 s is a vehicle reboot, accepted."""
        last = self._stamp.get(kind)
        if last is not None and stamp <= last and last - stamp < REBOOT_JUMP[kind]:
            self.rejected[kind] = f"replayed or reordered (stamp {stamp} <= {last})"
            return False
        self._stamp[kind] = stamp
        return True

    def _sane(self, kind: str, values, limit: float) -> bool:
        """Drop a message whose values are not finite or beyond ``limit`` in magnitude."""
        if all(math.isfinite(v) and abs(v) <= limit for v in values):
            return True
        shown = ", ".join(f"{v:.6g}" for v in values)
        self.rejected[kind] = f"absurd values ({shown}; limit {limit:g})"
        return False

    def update(self, msg, now: float) -> None:
        kind = msg.get_type()
        if self.vehicle_sysid is not None and msg.get_srcSystem() != self.vehicle_sysid:
            return
        if kind in TELEMETRY_LIMITS and not self._check(kind, msg):
            return
        if kind == "LOCAL_POSITION_NED":
            self.pos = [msg.x, msg.y, msg.z]
            self.vel = [msg.vx, msg.vy, msg.vz]
            self.px4_time = msg.time_boot_ms * 1e-3
            self.t_pos = now
        elif kind == "ATTITUDE_QUATERNION":
            self.q = [msg.q1, msg.q2, msg.q3, msg.q4]
            self.t_att = now
        elif kind == "DEBUG_VECT":
            name = msg.name
            if isinstance(name, bytes):
                name = name.decode("ascii", "replace")
            name = name.rstrip("\0")
            if name == SWING_NAME and self.estimator is None and self.body is None:
                self.swing = [msg.x, msg.y]
                self.t_swing = now
            elif name == BODY_NAME and self.body is not None:
                counts = np.array([[msg.x, msg.y]])
                world = _core.body_swing(counts, np.array([self.q]), self.body)[0]
                self.swing = [float(world[0]), float(world[1])]
                self.t_swing = now
            elif name == TRUTH_NAME:
                self.swing_true = [msg.x, msg.y]
        elif kind == "HIGHRES_IMU":
            self.t_imu = now
            if self.estimator is not None:
                self._feed_imu(msg, now)
        elif kind == "POSITION_TARGET_LOCAL_NED":
            self.acc_sp = [msg.afx, msg.afy, msg.afz]
            self.t_target = now
        elif kind == "HEARTBEAT":
            if msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID:
                self.t_heartbeat = now
                self.mode = decode_px4_mode(msg.custom_mode)
                if self.mode[0] == OFFBOARD_MAIN:
                    self.seen_offboard = True
        elif kind == "COMMAND_ACK":
            self.acks.append((msg.command, msg.result))
        elif kind == "MISSION_ITEM_REACHED":
            self.reached.append((now, int(msg.seq)))
        elif kind == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode("ascii", "replace")
            log.info("vehicle: %s", text.rstrip("\0"))

    def _feed_imu(self, msg, now: float) -> None:
        """Block means of the IMU's specific force over each estimator period of PX4's
        clock, each fed with the newest attitude and velocity (as a ULog's are,
        :mod:`swingrt.io.ulog`); the swing is the estimate once the tare is over."""
        est = self.estimator
        if est is None or not all(math.isfinite(v) for v in self.vel):
            return
        t = float(msg.time_usec)
        acc = (msg.xacc, msg.yacc, msg.zacc)
        period = self._imu_period
        if self._imu_next is None or t - self._imu_next > IMU_GAP_US:
            self._imu_next = t + period
            self._imu_sum, self._imu_count = [0.0, 0.0, 0.0], 0
        if t <= self._imu_next:
            for i in range(3):
                self._imu_sum[i] += acc[i]
            self._imu_count += 1
            return
        while t > self._imu_next:
            if self._imu_count:
                mean = [x / self._imu_count for x in self._imu_sum]
                self._imu_last = mean
            else:
                mean = self._imu_last or list(acc)
            est.update(mean, self.q, self.vel)
            self._imu_sum, self._imu_count = [0.0, 0.0, 0.0], 0
            self._imu_next += period
        for i in range(3):
            self._imu_sum[i] += acc[i]
        self._imu_count += 1
        if est.tared:
            self.swing = list(est.estimate)
            self.t_swing = now

    @property
    def swing_label(self) -> str:
        """Where the swing comes from, for messages."""
        if self.estimator is not None:
            return "HIGHRES_IMU (the swing estimated from the IMU)"
        if self.body is not None:
            return f"DEBUG_VECT '{BODY_NAME}' (the cable sensor on the airframe)"
        return f"DEBUG_VECT '{SWING_NAME}' (swing sensor)"

    def _check(self, kind: str, msg) -> bool:
        """Whether a telemetry message is sane and new (else noted in :attr:`rejected`)."""
        limit = TELEMETRY_LIMITS[kind]
        if kind == "LOCAL_POSITION_NED":
            ok = self._sane(kind, (msg.x, msg.y, msg.z), limit[0]) and self._sane(
                kind, (msg.vx, msg.vy, msg.vz), limit[1]
            )
            return ok and self._fresh(kind, msg.time_boot_ms)
        if kind == "ATTITUDE_QUATERNION":
            q = (msg.q1, msg.q2, msg.q3, msg.q4)
            if not self._sane(kind, q, limit[0]):
                return False
            norm = math.sqrt(sum(v * v for v in q))
            if abs(norm - 1.0) > limit[1]:
                self.rejected[kind] = f"quaternion of norm {norm:.6g}, not 1"
                return False
            return self._fresh(kind, msg.time_boot_ms)
        if kind == "DEBUG_VECT":
            name = msg.name.decode("ascii", "replace") if isinstance(msg.name, bytes) else msg.name
            if name.rstrip("\0") == BODY_NAME:
                return self._sane(kind, (msg.x, msg.y), BODY_COUNTS_LIMIT) and self._fresh(
                    kind, msg.time_usec
                )
            if name.rstrip("\0") != SWING_NAME:
                # The truth is only logged: sane values or NaN, never a freshness record.
                return name.rstrip("\0") != TRUTH_NAME or self._sane(kind, (msg.x, msg.y), limit[0])
            return self._sane(kind, (msg.x, msg.y), limit[0]) and self._fresh(kind, msg.time_usec)
        if kind == "HIGHRES_IMU":
            return self._sane(kind, (msg.xacc, msg.yacc, msg.zacc), limit[0]) and self._fresh(
                kind, msg.time_usec
            )
        # POSITION_TARGET_LOCAL_NED: only the acceleration is read (position/velocity may
        # be NaN by design: the fields the type mask leaves out).
        return self._sane(kind, (msg.afx, msg.afy, msg.afz), limit[0]) and self._fresh(
            kind, msg.time_boot_ms
        )

    def euler(self) -> tuple[float, float, float]:
        q0, q1, q2, q3 = self.q
        roll = math.atan2(2 * (q0 * q1 + q2 * q3), 1 - 2 * (q1 * q1 + q2 * q2))
        pitch = math.asin(max(-1.0, min(1.0, 2 * (q0 * q2 - q3 * q1))))
        yaw = math.atan2(2 * (q0 * q3 + q1 * q2), 1 - 2 * (q2 * q2 + q3 * q3))
        return roll, pitch, yaw


@dataclass
class Watchdog:
    """Decides when the node must hand control back (module doc); times in seconds."""

    ts: float
    stale_factor: float = 3.0
    budget: float | None = None
    overrun_ticks: int = 3
    link_timeout: float = 3.0
    #: Largest swing angle [rad] the controller may leave the payload in before PX4 takes
    #: back over (None: no limit). A model that no longer fits the payload (a winch, a
    #: pick-up) can drive a growing swing that no other watchdog sees.
    swing_limit: float | None = None
    _overruns: int = 0

    def check_inputs(self, tel: Telemetry, now: float) -> str | None:
        """Reason to abort before computing, or None."""
        limit = self.stale_factor * self.ts
        swing_kind = "DEBUG_VECT" if tel.estimator is None else "HIGHRES_IMU"
        for name, kind, t in (
            ("LOCAL_POSITION_NED", "LOCAL_POSITION_NED", tel.t_pos),
            (tel.swing_label, swing_kind, tel.t_swing),
        ):
            if now - t > limit:
                age, lim = (now - t) * 1e3, limit * 1e3
                why = tel.rejected.get(kind)
                dropped = f"; last one dropped: {why}" if why else ""
                return f"stale telemetry: {name} is {age:.0f} ms old (limit {lim:.0f} ms{dropped})"
        if now - tel.t_heartbeat > self.link_timeout:
            return f"dead link: no heartbeat for {now - tel.t_heartbeat:.1f} s"
        if self.swing_limit is not None:
            swing = max(abs(tel.swing[0]), abs(tel.swing[1]))
            if swing > self.swing_limit:
                return (
                    f"swing {math.degrees(swing):.1f}° beyond the limit of "
                    f"{math.degrees(self.swing_limit):.0f}°"
                )
        return None

    def check_compute(self, compute: float) -> str | None:
        """Reason to abort after a tick that took ``compute`` seconds, or None."""
        budget = self.budget if self.budget is not None else 0.5 * self.ts
        if compute > budget:
            self._overruns += 1
            if self._overruns >= self.overrun_ticks:
                return (
                    f"solver overrun: {self._overruns} ticks over budget "
                    f"(last {compute * 1e3:.1f} ms > {budget * 1e3:.1f} ms)"
                )
        else:
            self._overruns = 0
        return None


# ----------------------------------------------------------------------------- report


def _stats(x: np.ndarray) -> dict[str, float]:
    if len(x) == 0:
        return {"median": math.nan, "p99": math.nan, "max": math.nan}
    return {
        "median": float(np.median(x)),
        "p99": float(np.percentile(x, 99)),
        "max": float(np.max(x)),
    }


@dataclass
class FlightReport:
    """Outcome and loop timing of one offboard flight (times in seconds)."""

    ts: float
    ticks: int
    missed_deadlines: int
    jitter: dict[str, float]
    compute: dict[str, float]
    columns: dict[str, np.ndarray] = field(repr=False)
    aborted: str | None = None

    def summary(self) -> str:
        j, c = self.jitter, self.compute
        text = (
            f"{self.ticks} ticks at {self.ts * 1e3:.1f} ms, {self.missed_deadlines} missed; "
            f"period jitter median {j['median'] * 1e3:.3f} ms p99 {j['p99'] * 1e3:.3f} ms "
            f"max {j['max'] * 1e3:.3f} ms"
        )
        if math.isnan(c["median"]):  # a watch: the vehicle flew itself, nothing computed
            return text
        return (
            f"{text}; compute median {c['median'] * 1e3:.3f} ms "
            f"p99 {c['p99'] * 1e3:.3f} ms max {c['max'] * 1e3:.3f} ms"
        )


# ----------------------------------------------------------------------------- session

#: Columns the node logs: the trace columns (:data:`swingrt.io.TRACE_COLUMNS`) + loop timing.
NODE_COLUMNS = (
    *TRACE_COLUMNS,
    "swing_true_n",
    "swing_true_e",
    "px4_time_s",
    "jitter_s",
    "compute_s",
)


#: Most messages read per drain (one tick); the rest wait in the socket (or are dropped by it).
MAX_DRAIN = 500


class OffboardSession:
    """One offboard flight over an open connection: handshake, fixed-rate loop, handback.

    ``policy(k, t, tel, swing_rate) -> (type_mask, (x, y, z), (vx, vy, vz), (ax, ay, az),
    (vel_ref_n, vel_ref_e))`` computes the setpoint of tick k; it is the only thing that
    differs between ``fly`` (MPC on acceleration) and ``collect`` (PX4 velocity control).
    """

    def __init__(
        self,
        conn,
        *,
        ts: float,
        system_id: int | None = None,
        hold: str = "loiter",
        prestream: float = 1.5,
        heartbeat_timeout: float = 5.0,
        telemetry_timeout: float = 5.0,
        telemetry_hz: float = 100.0,
        watchdog: Watchdog | None = None,
        swing_estimator: dict | None = None,
        body_sensor: dict | None = None,
    ):
        if not (ts > 0 and math.isfinite(ts)):
            raise ConfigError(f"sample time must be positive, not {ts}")
        if hold not in HOLD_MODES:
            raise ConfigError(f"hold mode must be one of {', '.join(HOLD_MODES)}, not {hold}")
        self.conn = conn
        self.ts = ts
        self.system_id = system_id
        self.hold = HOLD_MODES[hold]
        self.prestream = prestream
        self.heartbeat_timeout = heartbeat_timeout
        self.telemetry_timeout = telemetry_timeout
        self.telemetry_hz = telemetry_hz
        self.watchdog = watchdog or Watchdog(ts)
        if swing_estimator is not None and body_sensor is not None:
            raise ConfigError("one swing source per flight: the IMU estimate or the body sensor")
        self.tel = Telemetry(
            None if swing_estimator is None else ImuSwingEstimator(dict(swing_estimator)),
            body_sensor,
        )
        #: What the node's log says of its swing columns (Parquet metadata): with the cable
        #: sensor on the airframe, the source and its settings, so that a model identified on
        #: the log knows what to fly with (its swing columns are the world-frame angles).
        self.log_meta: dict | None = None
        if body_sensor is not None:
            self.log_meta = {"swing_source": "body", "body_sensor": dict(body_sensor)}
        self._next_beat = 0.0

    def set_mode(self, mode: tuple[int, int], timeout: float = 5.0) -> None:
        """Ask for PX4 ``mode`` (main, sub) until the heartbeat shows it; FlightAbort after
        ``timeout`` s."""
        deadline = time.monotonic() + timeout
        next_try = 0.0
        while time.monotonic() < deadline:
            now = time.monotonic()
            if now >= next_try:
                self._request_mode(*mode)
                next_try = now + 0.5
            time.sleep(0.02)
            self._drain()
            if self.tel.mode == mode:
                log.info("vehicle in %s", mode_name(*mode))
                return
        now_in = mode_name(*self.tel.mode) if self.tel.mode else "no mode"
        raise FlightAbort(
            f"vehicle did not enter {mode_name(*mode)} within {timeout:g} s ({now_in})"
        )

    def poll(self) -> None:
        """Read what the vehicle sent into the telemetry (bounded) and keep the heartbeat."""
        self._drain()

    # -------------------------------------------------------------- plumbing

    def _drain(self) -> None:
        now = time.monotonic()
        for _ in range(MAX_DRAIN):  # bounded: a flood cannot starve the control loop
            try:
                msg = self.conn.recv_msg()
            except Exception as exc:  # garbage on the wire: drop, keep flying
                log.warning("dropped unparsable input (%s)", exc)
                continue
            if msg is None:
                # A datagram of garbage parses to nothing too: read on unless the link was
                # empty (else one bad datagram would hold the good ones back a whole tick).
                if getattr(self.conn, "swingrt_bytes_read", 0) > 0:
                    continue
                break
            self.tel.update(msg, now)
        if now >= self._next_beat:
            send_heartbeat(self.conn)
            self._next_beat = now + 1.0

    def _command(self, command: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(
            self.conn.target_system, self.conn.target_component, command, 0, *p
        )

    def _request_mode(self, main: int, sub: int) -> None:
        self._command(
            mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub
        )

    def _setpoint(self, mask: int, pos, vel, acc) -> None:
        self.conn.mav.set_position_target_local_ned_send(
            int(time.monotonic() * 1000) & 0xFFFFFFFF,
            self.conn.target_system,
            self.conn.target_component,
            mavlink.MAV_FRAME_LOCAL_NED,
            mask,
            *pos,
            *vel,
            *acc,
            self.yaw_hold,
            0.0,
        )

    def _drop_acks(self, command: int) -> None:
        self.tel.acks[:] = [a for a in self.tel.acks if a[0] != command]

    def _take_ack(self, command: int) -> int | None:
        for i, (cmd, result) in enumerate(self.tel.acks):
            if cmd == command:
                del self.tel.acks[i]
                return result
        return None

    # -------------------------------------------------------------- phases

    def connect(self, *, swing: bool = True) -> None:
        """Heartbeat, telemetry rates, first telemetry (the position, and with ``swing`` the
        swing); raises LinkError with one line."""
        hb = wait_heartbeat(self.conn, timeout=self.heartbeat_timeout, system_id=self.system_id)
        self.tel.vehicle_sysid = hb.get_srcSystem()
        self.tel.update(hb, time.monotonic())
        interval_us = 1e6 / self.telemetry_hz
        for msg_id in (
            mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
            mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
            mavlink.MAVLINK_MSG_ID_DEBUG_VECT,
            mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED,
        ):
            self._command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval_us)
        est = self.tel.estimator
        if est is not None:
            imu_us = 1e6 / float(est.settings["rate"])
            self._command(
                mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_HIGHRES_IMU, imu_us
            )
        # The estimate's tare must fit in the wait for the first swing.
        wait = self.telemetry_timeout + (0.0 if est is None else float(est.settings["tare"]))
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline:
            self._drain()
            if math.isfinite(self.tel.t_pos) and (not swing or math.isfinite(self.tel.t_swing)):
                break
            time.sleep(0.005)
        else:
            url = getattr(self.conn, "swingrt_url", "the link")
            missing = []
            if not math.isfinite(self.tel.t_pos):
                missing.append("LOCAL_POSITION_NED")
            hint = ""
            if swing and not math.isfinite(self.tel.t_swing):
                missing.append(self.tel.swing_label)
                if est is None:
                    hint = (
                        " (nothing on the cable? `collect --swing-source imu` records the "
                        "swing from PX4's IMU)"
                    )
            raise LinkError(f"no {' and no '.join(missing)} from {url} within {wait:g} s{hint}")
        self.tel.acks.clear()
        self.alt_hold = self.tel.pos[2]
        self.yaw_hold = self.tel.euler()[2]

    def run(
        self,
        policy: Callable,
        duration: float,
        *,
        reset: Callable | None = None,
        until: Callable[[], bool] | None = None,
    ):
        """Pre-stream, engage OFFBOARD, run ``policy`` for ``duration`` s (or until
        ``until()`` holds after a tick), hand back."""
        n_max = int(math.ceil(duration / self.ts)) + 1
        cols = {c: np.full(n_max, np.nan) for c in NODE_COLUMNS}
        aborted = None
        k = 0
        missed = 0
        try:
            self._engage()
            prev_swing = list(self.tel.swing)
            t0 = time.perf_counter()
            if reset is not None:
                reset(self.tel)
            while k < n_max:
                k, deadline, now, skipped = self._await_tick(t0, k)
                missed += skipped
                if k >= n_max:
                    break
                jitter = now - deadline
                self._drain()
                mono = time.monotonic()
                reason = self.watchdog.check_inputs(self.tel, mono)
                mode = self.tel.mode  # set with seen_offboard, from the first HEARTBEAT
                if reason is None and self.tel.seen_offboard and mode and mode[0] != OFFBOARD_MAIN:
                    reason = f"vehicle left OFFBOARD (now {mode_name(*mode)})"
                if reason is not None:
                    aborted = f"{reason} at t = {k * self.ts:.2f} s"
                    break
                c0 = time.perf_counter()
                sw = self.tel.swing
                rate = ((sw[0] - prev_swing[0]) / self.ts, (sw[1] - prev_swing[1]) / self.ts)
                if k == 0:
                    rate = (0.0, 0.0)
                prev_swing = list(sw)
                try:
                    mask, pos, vel, acc, ref = policy(k, k * self.ts, self.tel, rate)
                except SwingrtError as exc:  # the controller refused the state: fail safe
                    aborted = f"controller error: {exc} at t = {k * self.ts:.2f} s"
                    break
                self._setpoint(mask, pos, vel, acc)
                compute = time.perf_counter() - c0
                self._log(cols, k, jitter, compute, rate, acc, ref)
                k += 1
                reason = self.watchdog.check_compute(compute)
                if reason is not None:
                    aborted = f"{reason} at t = {(k - 1) * self.ts:.2f} s"
                    break
                if until is not None and until():
                    break
        finally:
            self._hand_back(emergency=aborted is not None)
        return self._report(cols, k, n_max, missed, aborted)

    def watch(self, duration: float, until: Callable[[], bool]) -> FlightReport:
        """Log the telemetry at 1/Ts while the vehicle flies itself (PX4's own mode, no
        setpoint sent) for up to ``duration`` s, until ``until()`` holds; a stale position
        or a dead link ends the watch early (``aborted`` names it)."""
        n_max = int(math.ceil(duration / self.ts)) + 1
        cols = {c: np.full(n_max, np.nan) for c in NODE_COLUMNS}
        nan2 = (math.nan, math.nan)
        aborted = None
        missed = k = 0
        t0 = time.perf_counter()
        prev = list(self.tel.swing)
        while k < n_max:
            k, deadline, now, skipped = self._await_tick(t0, k)
            missed += skipped
            if k >= n_max:
                break
            self._drain()
            mono = time.monotonic()
            if mono - self.tel.t_pos > self.watchdog.stale_factor * self.ts:
                aborted = f"stale telemetry: LOCAL_POSITION_NED at t = {k * self.ts:.2f} s"
                break
            if mono - self.tel.t_heartbeat > self.watchdog.link_timeout:
                aborted = f"dead link: no heartbeat at t = {k * self.ts:.2f} s"
                break
            sw = self.tel.swing
            rate = ((sw[0] - prev[0]) / self.ts, (sw[1] - prev[1]) / self.ts) if k else (0, 0)
            prev = list(sw)
            acc = (self.tel.acc_sp[0], self.tel.acc_sp[1], 0.0)
            self._log(cols, k, now - deadline, math.nan, rate, acc, nan2)
            k += 1
            if until():
                break
        return self._report(cols, k, n_max, missed, aborted)

    def _await_tick(self, t0: float, k: int) -> tuple[int, float, float, int]:
        """Sleep until tick ``k``'s deadline t0 + k Ts; from a tick already a whole period
        late, skip to the newest due one (keeping the grid: no drift). Returns the tick, its
        deadline, the time now and how many ticks were skipped."""
        deadline = t0 + k * self.ts
        now = time.perf_counter()
        if deadline > now:
            time.sleep(deadline - now)
            return k, deadline, time.perf_counter(), 0
        if now - deadline < self.ts:
            return k, deadline, now, 0
        skip = int((now - deadline) / self.ts)
        return k + skip, t0 + (k + skip) * self.ts, now, skip

    def _report(self, cols, k, n_max, missed, aborted) -> FlightReport:
        """The report of a loop that logged ``k`` ticks into ``cols``."""
        n = min(k, n_max)
        # Rows of skipped (missed) deadlines were never logged: leave them out, so the trace
        # has a strictly increasing, finite t (with a gap) instead of NaN rows.
        logged = np.isfinite(cols["t"][:n])
        out = {c: v[:n][logged] for c, v in cols.items()}
        # A real vehicle has no true swing to log; only a simulator behind PX4 sends one.
        if not np.isfinite(out["swing_true_n"]).any():
            del out["swing_true_n"], out["swing_true_e"]
        ok = np.isfinite(out["jitter_s"])
        report = FlightReport(
            ts=self.ts,
            ticks=int(ok.sum()),
            missed_deadlines=missed,
            jitter=_stats(out["jitter_s"][ok]),
            compute=_stats(out["compute_s"][ok & np.isfinite(out["compute_s"])]),
            columns=out,
            aborted=aborted,
        )
        return report

    def _neutral(self) -> None:
        self._setpoint(
            MASK_ACC_ALT_HOLD, (0.0, 0.0, self.alt_hold), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        )

    def _engage(self) -> None:
        """Stream neutral setpoints, then request OFFBOARD (only while the telemetry is
        fresh) until accepted."""
        t_end = time.monotonic() + self.prestream
        while time.monotonic() < t_end:
            self._drain()
            self._neutral()
            time.sleep(self.ts)
        tries = 0
        next_try = 0.0
        give_up = time.monotonic() + 5.0
        self._drop_acks(mavlink.MAV_CMD_DO_SET_MODE)
        while True:
            now = time.monotonic()
            self._drain()
            self._neutral()
            result = self._take_ack(mavlink.MAV_CMD_DO_SET_MODE)
            if result == mavlink.MAV_RESULT_ACCEPTED:
                log.info("OFFBOARD accepted after %d request(s)", tries)
                return
            if result is not None and result != mavlink.MAV_RESULT_TEMPORARILY_REJECTED:
                raise FlightAbort(f"vehicle refused OFFBOARD (MAV_RESULT {result})")
            # Never take over on stale telemetry: the first tick would act on it.
            stale = self.watchdog.check_inputs(self.tel, now)
            if now >= give_up:
                why = f" (telemetry: {stale})" if stale and not tries else ""
                raise FlightAbort(f"vehicle did not accept OFFBOARD within 5 s{why}")
            if now >= next_try and stale is None:
                self._request_mode(OFFBOARD_MAIN, 0)
                tries += 1
                next_try = now + 0.5
            time.sleep(self.ts)

    def _hand_back(self, *, emergency: bool) -> None:
        """Request the hold mode while streaming a safe setpoint; wait for the ack."""
        if not hasattr(self, "alt_hold"):
            return  # never engaged
        main, sub = self.hold
        deadline = time.monotonic() + 3.0
        next_try = 0.0
        accepted = False
        try:
            # PX4 acknowledges a mode command on every link it came in on, so acks of the
            # OFFBOARD request can still be queued: only an ack that follows our request
            # counts, and the hand-back is done when the heartbeat shows the hold mode.
            self._drain()
            self._drop_acks(mavlink.MAV_CMD_DO_SET_MODE)
            self.tel.mode = None
            while time.monotonic() < deadline:
                now = time.monotonic()
                if now >= next_try:
                    self._request_mode(main, sub)
                    next_try = now + 0.3
                # zero velocity = PX4's own velocity hold: safe whatever the swing state
                self._setpoint(
                    MASK_VEL_ALT_HOLD, (0.0, 0.0, self.alt_hold), (0.0, 0.0, 0.0), (0.0,) * 3
                )
                time.sleep(self.ts)
                self._drain()
                if self._take_ack(mavlink.MAV_CMD_DO_SET_MODE) == mavlink.MAV_RESULT_ACCEPTED:
                    accepted = True
                if accepted and self.tel.mode is not None and self.tel.mode[0] != OFFBOARD_MAIN:
                    log.info("handed back to %s", mode_name(*self.tel.mode))
                    return
            log.warning(
                "no ack for %s; PX4's offboard-loss failsafe takes over", mode_name(main, sub)
            )
        except OSError as exc:
            log.warning("could not hand back (%s); PX4's offboard-loss failsafe takes over", exc)

    def _log(self, cols, k, jitter, compute, rate, acc, ref) -> None:
        tel = self.tel
        roll, pitch, yaw = tel.euler()
        row = {
            "t": k * self.ts,
            "pn": tel.pos[0], "pe": tel.pos[1], "pd": tel.pos[2],
            "vn": tel.vel[0], "ve": tel.vel[1], "vd": tel.vel[2],
            "roll": roll, "pitch": pitch, "yaw": yaw,
            "swing_n": tel.swing[0], "swing_e": tel.swing[1],
            "swing_rate_n": rate[0], "swing_rate_e": rate[1],
            "swing_true_n": tel.swing_true[0], "swing_true_e": tel.swing_true[1],
            "px4_time_s": tel.px4_time,
            "acc_sp_n": acc[0], "acc_sp_e": acc[1], "acc_sp_d": tel.acc_sp[2],
            "vel_sp_n": ref[0], "vel_sp_e": ref[1], "vel_sp_d": 0.0,
            "jitter_s": jitter, "compute_s": compute,
        }  # fmt: skip
        for c in NODE_COLUMNS:
            cols[c][k] = row[c]


# ----------------------------------------------------------------------------- controllers


def load_controller(
    model_path, settings=None, *, adapt: bool = False, adaptive=None, twin: bool = True
):
    """Build what a model file flies: the MPC (``swingrt._core.Mpc``), or the law its
    selection took where no MPC passed (``Controller.flown``, a velocity setpoint law), or
    with ``adapt`` the
    adaptive MPC (``swingrt._core.AdaptiveMpc``, re-synthesis on a worker thread unless
    ``adaptive`` says otherwise); returns (ctrl, ts, axes). With ``twin`` (default) and a
    model selected on a vehicle twin (:func:`swingrt.sysid.model_twin`), the adaptive MPC
    re-identifies on that twin for the cable length it measures in flight (the twin path);
    without, on the online DMDc alone."""
    from swingrt.sysid import LinearModel, model_twin

    p = Path(model_path)
    model = LinearModel.load(p)
    axes = len(model.inputs)
    if axes not in (1, 2):
        raise ModelError(f"{p}: model has {axes} inputs; fly supports 1 (North) or 2 (N, E)")
    if adapt:
        opts = {"synthesis": "thread", **(adaptive or {})}
        try:
            prior = model_twin(model) if twin else None
        except ModelError as exc:
            raise ModelError(f"{p}: {exc}") from None
        if prior is None:
            return AdaptiveMpc(model, settings, opts), model.dt, axes
        opts["twin"] = {**opts.get("twin", {}), "enabled": True}
        vehicle, payload = prior
        return AdaptiveMpc(model, settings, opts, vehicle, payload), model.dt, axes
    law = Controller.flown(model)
    if law is not None:
        # The selection took another law where no MPC passed (a velocity setpoint law).
        return law, law.period, axes
    return Mpc(model, settings), model.dt, axes


def model_swing_estimator(model_path) -> dict | None:
    """The swing estimator a flight on the model at ``model_path`` needs
    (:func:`swingrt.sysid.model_estimator`): the calibrated settings of a model identified
    on the IMU's swing estimate, else None (a swing sensor)."""
    from swingrt.sysid import LinearModel, model_estimator

    p = Path(model_path)
    try:
        return model_estimator(LinearModel.load(p))
    except ModelError as exc:
        raise ModelError(f"{p}: {exc}") from None


def model_body_sensor(model_path) -> dict | None:
    """The cable sensor on the airframe a flight on the model at ``model_path`` reads
    (:func:`swingrt.sysid.model_body_sensor`): its settings when the model was identified
    on it, else None."""
    from swingrt.sysid import LinearModel, model_body_sensor

    p = Path(model_path)
    try:
        return model_body_sensor(LinearModel.load(p))
    except ModelError as exc:
        raise ModelError(f"{p}: {exc}") from None


#: P gain [1/s] of the East velocity hold while a one-axis controller flies North.
EAST_HOLD_GAIN = 1.0


def command_bound(controller, settings=None) -> float:
    """The node's clip on |a| per axis [m/s²]: the MPC's own ``acc_max``, read from the
    controller (``Mpc.settings()``) or from the MPC ``settings`` it was built with, so the
    node neither cuts what the MPC planned within its bound nor passes more. A controller
    without a bound of its own (the LQR) gets the MPC's default."""
    read = getattr(controller, "settings", None)
    own = read() if callable(read) else check_settings("mpc", settings)
    bound = own.get("acc_max")
    if bound is None:
        bound = check_settings("mpc", None)["acc_max"]
    return float(bound)


def fly(
    conn,
    controller,
    *,
    ts: float,
    axes: int = 2,
    mission: Mission | None = None,
    acc_limit: float | None = None,
    log_path=None,
    **session_options,
) -> FlightReport:
    """Fly ``mission`` with ``controller`` (any object with ``step``/``reset``) over ``conn``.

    A controller whose ``output`` is ``"velocity"`` (the input shaper, the payload feedback
    of :mod:`swingrt.methods`) commands PX4's velocity loop: its output goes out as North/East
    velocity setpoints; any other commands acceleration.
    ``acc_limit`` [m/s²] clips the acceleration per axis (default: :func:`command_bound`).
    With one axis the controller flies North and East is held by a velocity P law
    (a_e = -:data:`EAST_HOLD_GAIN` ve), since PX4 needs North and East setpoints of the same kind.
    Raises :class:`FlightAbort` (after handing back) when a watchdog fires; the trace and
    timing are written to ``log_path`` in any case.
    """
    mission = mission or Mission.default()
    limit = command_bound(controller) if acc_limit is None else float(acc_limit)
    if axes not in (1, 2):
        raise ConfigError(f"axes must be 1 or 2, not {axes}")
    velocity = getattr(controller, "output", "acceleration") == "velocity"
    session = OffboardSession(conn, ts=ts, **session_options)
    session.connect()
    state = np.zeros((axes, 3))
    ref = np.zeros(axes)

    def fill(tel, rate):
        state[0] = (tel.vel[0], tel.swing[0], rate[0])
        if axes == 2:
            state[1] = (tel.vel[1], tel.swing[1], rate[1])

    def reset(tel):
        fill(tel, (0.0, 0.0))
        controller.reset(state.copy(), np.zeros(axes))

    def policy(k, t, tel, rate):
        fill(tel, rate)
        vn, ve = mission.reference(t)
        ref[0] = vn
        if axes == 2:
            ref[1] = ve
        a = np.asarray(controller.step(state, ref), dtype=float).reshape(-1)
        if a.shape != (axes,) or not np.all(np.isfinite(a)):
            raise ControlError(f"controller returned {a!r}, expected {axes} finite values")
        if velocity:
            # PX4's velocity loop flies it (East held at zero by PX4 with one axis).
            v_e = float(a[1]) if axes == 2 else 0.0
            return (
                MASK_VEL_ALT_HOLD,
                (0.0, 0.0, session.alt_hold),
                (float(a[0]), v_e, 0.0),
                (tel.acc_sp[0], tel.acc_sp[1], 0.0),
                (float(a[0]), v_e),
            )
        an = float(np.clip(a[0], -limit, limit))
        ae = float(np.clip(a[1], -limit, limit)) if axes == 2 else -EAST_HOLD_GAIN * tel.vel[1]
        return (
            MASK_ACC_ALT_HOLD,
            (0.0, 0.0, session.alt_hold),
            (0.0, 0.0, 0.0),
            (an, ae, 0.0),
            (vn, ve),
        )

    report = session.run(policy, mission.duration, reset=reset)
    _finish(report, log_path, session.log_meta)
    return report


def _finish(report: FlightReport, log_path, meta: dict | None = None) -> None:
    if log_path is not None:
        write_columns(report.columns, log_path, meta=meta)
    log.info("loop: %s", report.summary())
    if report.aborted:
        exc = FlightAbort(f"{report.aborted}; control handed back to the flight controller")
        exc.report = report
        raise exc
