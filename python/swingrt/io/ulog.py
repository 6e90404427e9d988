"""PX4 ULog logs in: :func:`load_ulog` (used by :func:`swingrt.io.flight.load_flight`).

PX4 ULog mapping (uORB topics, timestamps in microseconds):

==========================================  ==============================================
``vehicle_local_position``                  ``pn pe pd`` <- ``x y z``; ``vn ve vd`` <- ``vx vy vz``
``vehicle_local_position_setpoint``         ``acc_sp_*`` <- ``acceleration[0..2]`` (PX4 >= 1.11)
                                            or ``acc_x acc_y acc_z`` (older firmware);
                                            ``vel_sp_*`` <- ``vx vy vz``;
                                            ``thrust_sp`` <- ``|thrust[0..2]|`` (normalised)
``vehicle_attitude``                        ``roll pitch yaw`` <- ``q[0..3]`` (scalar first,
                                            body FRD -> NED), Euler ZYX
``sensor_combined``                         ``imu_ax imu_ay imu_az`` <- ``accelerometer_m_s2[0..2]``
                                            (body FRD specific force, PX4's 250 Hz IMU);
                                            ``imu_gx imu_gy imu_gz`` <- ``gyro_rad[0..2]``
swing sensor (configurable, see below)      ``swing_n swing_e`` = scale * raw + offset
==========================================  ==============================================

The swing from the IMU: with ``sensor_combined``, ``vehicle_attitude`` and the velocity in the
log, ``swing_est_n swing_est_e`` are the swing estimated from the vehicle's own IMU
(``_core.estimate_swing``, the simulator's estimator: the accelerometer's body-horizontal
specific force as the cable's pull, composed with the attitude), fed block means of
``sensor_combined`` at the estimator's rate from the start of the flight segment (its tare),
with ``estimator`` settings (``sensors.estimator`` of a scenario; default: the core's, its
low-pass lowered where the log's own vibration would pass more than 0.3° of angle noise
through it, ``meta["swing_vibration"]``: :mod:`swingrt.io.vibration`). A log
without a swing sensor is then identified on the IMU (:func:`swingrt.sysid.swing_source`);
``meta["swing_estimator"]`` holds the settings, which the model carries and the flight must
use.

Timeline: each topic keeps its own timestamps. Everything is merged onto the timeline of
``vehicle_local_position`` (the state estimate, the densest topic the identification needs),
cropped to the span where every loaded topic has samples, by linear interpolation of each
topic in its own time. Attitude is interpolated as a quaternion (sign-continuous, then
normalised) so that yaw does not jump at +-pi. A topic that falls silent for longer than
``max(0.5 s, 10 x its median period)`` leaves NaN inside the hole instead of a straight
line, so that :func:`require` reports the gap with its time.

Flight segment: when ``vehicle_status`` shows OFFBOARD flight of at least 10 s, the trace is
cropped to the longest such stretch (the training flight flown by the offboard computer;
boot, take-off and hover around it are not identification data); ``meta["segment"]`` says so.

Cable sensor on the airframe (the thesis's rig, 6.1.2): with ``ulog_swing = {"topic":
"adc_report"}`` the swing is read from the two potentiometers' ADC channels of
``adc_report`` (``channel_id[12]`` / ``raw_data[12]``; ``adc_x adc_y`` in counts), each
through its calibration and composed with ``vehicle_attitude`` into the world-frame
``swing_n swing_e`` (``_core.body_swing``, the simulator's own rule). ``body`` describes the
sensor: the fields of a scenario's ``[sensors.body]`` (``channels``, ``calibration_x``,
``calibration_y``, or ``zero``/``gain``; default: the core's). ``meta["swing_source"]`` is
then ``"body"``.

Swing sensor: ``ulog_swing = {"topic": "debug_vect", "name": "SWING", "n": "x", "e": "y",
"scale": 1.0, "offset": 0.0}`` (the default; ``name`` filters the rows of a ``debug_vect``
topic by its ``name`` field, our DEBUG_VECT convention documented in docs/flying.md).
``scale``/``offset`` are the linear calibration of the sensor (thesis 6.1.2: ADC reading to
angle by a best-fit straight line); a pair ``{"n": s, "e": s}`` sets them per axis.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from swingrt.errors import ConfigError, DataError
from swingrt.io.flight import Trace
from swingrt.io.vibration import choose_cutoff

__all__ = ["DEFAULT_ULOG_SWING", "euler_to_quat", "load_ulog", "quat_to_euler"]

#: Default swing-sensor source in a ULog: DEBUG_VECT rows named "SWING", x = swing_n, y = swing_e.
DEFAULT_ULOG_SWING: dict = {
    "topic": "debug_vect",
    "name": "SWING",
    "n": "x",
    "e": "y",
    "scale": 1.0,
    "offset": 0.0,
}


def quat_to_euler(q0, q1, q2, q3):
    """ZYX Euler angles (roll, pitch, yaw) of a scalar-first unit quaternion (body -> NED)."""
    roll = np.arctan2(2.0 * (q0 * q1 + q2 * q3), 1.0 - 2.0 * (q1 * q1 + q2 * q2))
    pitch = np.arcsin(np.clip(2.0 * (q0 * q2 - q3 * q1), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))
    return roll, pitch, yaw


def euler_to_quat(roll, pitch, yaw):
    """Scalar-first quaternion (q0, q1, q2, q3) of ZYX Euler angles (inverse of quat_to_euler)."""
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def _first_field(fields: Mapping[str, np.ndarray], *names: str):
    for n in names:
        if n in fields:
            return n
    return None


def _decode_name(fields: Mapping[str, np.ndarray]) -> np.ndarray:
    """Decode a ``char[N] name`` field (pyulog splits it into ``name[0]`` ... columns)."""
    parts = []
    i = 0
    while f"name[{i}]" in fields:
        parts.append(np.asarray(fields[f"name[{i}]"]).astype(np.uint8))
        i += 1
    if not parts:
        return np.array([], dtype=object)
    chars = np.stack(parts, axis=1)
    return np.array([bytes(row).split(b"\0", 1)[0].decode("ascii", "replace") for row in chars])


def _interp_topic(t_base: np.ndarray, t_src: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Linear interpolation of one topic onto the base timeline; NaN inside long silences."""
    out = np.interp(t_base, t_src, y)
    if len(t_src) > 2:
        dt = np.diff(t_src)
        limit = max(0.5, 10.0 * float(np.median(dt)))
        for k in np.flatnonzero(dt > limit):
            out[(t_base > t_src[k]) & (t_base < t_src[k + 1])] = np.nan
    return out


#: PX4's navigation state while an offboard computer flies (vehicle_status.nav_state).
NAV_STATE_OFFBOARD = 14
#: Shortest OFFBOARD stretch [s] taken as the flight to identify from.
MIN_OFFBOARD_SECONDS = 10.0


def _offboard_segment(status) -> tuple[float, float] | None:
    """The longest stretch of OFFBOARD flight in ``vehicle_status`` [µs], if it lasts
    at least :data:`MIN_OFFBOARD_SECONDS`: a PX4 log holds boot, take-off and hover around
    the training flight, and only the flight itself is identification data."""
    if status is None:
        return None
    t, fields = status
    if "nav_state" not in fields or len(t) < 2:
        return None
    on = np.asarray(fields["nav_state"]) == NAV_STATE_OFFBOARD
    if not on.any():
        return None
    edges = np.diff(np.r_[0, on.astype(np.int8), 0])
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1
    best = int(np.argmax(t[ends] - t[starts]))
    lo, hi = float(t[starts[best]]), float(t[ends[best]])
    return (lo, hi) if hi - lo >= MIN_OFFBOARD_SECONDS * 1e6 else None


def load_ulog(
    p: Path,
    ulog_swing: Mapping | None = None,
    estimator: Mapping | None = None,
    body: Mapping | None = None,
) -> Trace:
    """Read a PX4 ULog into trace columns on the local-position timeline (module doc);
    ``estimator`` sets the swing estimate from the IMU (``ImuSwingSettings`` fields),
    ``body`` the cable sensor on the airframe read from ``adc_report``."""
    try:
        from pyulog import ULog
    except ImportError:  # pragma: no cover - pyulog is a declared dependency
        raise DataError(f"{p}: reading .ulg needs pyulog (pip install pyulog)", path=p) from None

    swing = dict(DEFAULT_ULOG_SWING)
    explicit_swing = ulog_swing is not None
    if ulog_swing is not None:
        unknown = set(ulog_swing) - set(DEFAULT_ULOG_SWING)
        if unknown:
            raise DataError(f"ulog_swing: unknown key(s) {', '.join(sorted(unknown))}")
        swing.update(ulog_swing)
        if ulog_swing.get("topic", "debug_vect") != "debug_vect" and "name" not in ulog_swing:
            swing["name"] = None
    try:
        # Our own handle, so that it is closed when pyulog fails half-way through the file.
        with open(p, "rb") as fh:
            log = ULog(fh)
    except Exception as exc:  # pyulog raises bare Exception / struct.error on bad files
        raise DataError(f"{p}: not a readable ULog file ({exc})", path=p) from None

    try:
        return _trace_from_ulog(p, log, swing, explicit_swing, estimator, body)
    except (DataError, ConfigError):
        raise
    except (KeyError, IndexError, ValueError, TypeError, OverflowError) as exc:
        # A corrupted file can parse into topics without the fields PX4 always writes.
        raise DataError(
            f"{p}: malformed ULog content ({type(exc).__name__}: {exc})", path=p
        ) from None


def _trace_from_ulog(
    p: Path,
    log: Any,
    swing: dict,
    explicit_swing: bool,
    estimator: Mapping | None = None,
    body: Mapping | None = None,
) -> Trace:
    """The trace columns of a parsed ULog (see :func:`load_ulog`)."""
    topics: dict[str, list] = {}
    for d in log.data_list:
        topics.setdefault(d.name, []).append(d)

    def topic(name: str):
        ds = topics.get(name)
        if not ds:
            return None
        d = min(ds, key=lambda x: x.multi_id)  # instance 0 (the primary estimator/controller)
        ts = np.asarray(d.data["timestamp"], dtype=np.float64)
        order = np.argsort(ts, kind="stable")
        fields = {k: np.asarray(v)[order] for k, v in d.data.items()}
        return ts[order], fields

    pos = topic("vehicle_local_position")
    if pos is None:
        raise DataError(
            f"{p}: ULog has no vehicle_local_position topic (the state estimate)", path=p
        )
    t_pos, fpos = pos
    if len(t_pos) < 2:
        raise DataError(f"{p}: vehicle_local_position holds fewer than 2 samples", path=p)
    for f in ("x", "y", "z", "vx", "vy", "vz"):
        if f not in fpos:
            raise DataError(f"{p}: vehicle_local_position has no field {f}", path=p)

    # Collect every topic as (t_us, {column: values}) first, then crop and interpolate.
    sources: list[tuple[np.ndarray, dict[str, np.ndarray]]] = []
    notes: dict[str, str] = {}

    sp = topic("vehicle_local_position_setpoint")
    if sp is None:
        for c in ("acc_sp_n", "acc_sp_e", "acc_sp_d", "vel_sp_n", "vel_sp_e", "vel_sp_d"):
            notes[c] = "ULog has no vehicle_local_position_setpoint topic"
    else:
        t_sp, fsp = sp
        cols: dict[str, np.ndarray] = {}
        acc = [_first_field(fsp, f"acceleration[{i}]", f"acc_{a}") for i, a in enumerate("xyz")]
        for c, f in zip(("acc_sp_n", "acc_sp_e", "acc_sp_d"), acc, strict=True):
            if f is None:
                notes[c] = (
                    "vehicle_local_position_setpoint has neither acceleration[0..2] "
                    "nor acc_x/acc_y/acc_z"
                )
            else:
                cols[c] = fsp[f].astype(float)
        for c, f in zip(("vel_sp_n", "vel_sp_e", "vel_sp_d"), ("vx", "vy", "vz"), strict=True):
            if f in fsp:
                cols[c] = fsp[f].astype(float)
            else:
                notes[c] = f"vehicle_local_position_setpoint has no field {f}"
        if all(f"thrust[{i}]" in fsp for i in range(3)):
            th = np.stack([fsp[f"thrust[{i}]"].astype(float) for i in range(3)])
            # PX4's normalised collective thrust, not Newtons: `sysid.with_thrust` turns it
            # into the trace's ``thrust`` [N] with the vehicle's motors.
            cols["thrust_sp"] = np.sqrt((th * th).sum(axis=0))
        if cols:
            sources.append((t_sp, cols))

    att = topic("vehicle_attitude")
    if att is None:
        for c in ("roll", "pitch", "yaw"):
            notes[c] = "ULog has no vehicle_attitude topic"
    else:
        t_att, fatt = att
        if not all(f"q[{i}]" in fatt for i in range(4)):
            raise DataError(f"{p}: vehicle_attitude has no field q[0..3]", path=p)
        q = np.stack([fatt[f"q[{i}]"].astype(float) for i in range(4)])
        # Sign continuity: q and -q are the same attitude; interpolate along the short path.
        flip = np.cumsum(np.r_[0, (np.einsum("ij,ij->j", q[:, 1:], q[:, :-1]) < 0)]) % 2 == 1
        q[:, flip] *= -1.0
        sources.append((t_att, {f"_q{i}": q[i] for i in range(4)}))

    imu = topic("sensor_combined")
    imu_fields = [f"accelerometer_m_s2[{i}]" for i in range(3)] + [
        f"gyro_rad[{i}]" for i in range(3)
    ]
    imu_cols = ("imu_ax", "imu_ay", "imu_az", "imu_gx", "imu_gy", "imu_gz")
    if imu is None or not all(f in imu[1] for f in imu_fields):
        why = "ULog has no sensor_combined accelerometer/gyro (the IMU)"
        for c in (*imu_cols, "swing_est_n", "swing_est_e"):
            notes[c] = why
        imu = None
    else:
        sources.append(
            (
                imu[0],
                {c: imu[1][f].astype(float) for c, f in zip(imu_cols, imu_fields, strict=True)},
            )
        )

    st = topic(swing["topic"])
    swing_why = None
    on_body = swing["topic"] == ADC_TOPIC
    if st is None:
        swing_why = f"ULog has no {swing['topic']} topic (swing sensor)"
    elif on_body:
        if att is None:
            swing_why = "the cable sensor's body angles need vehicle_attitude"
        else:
            swing_why = _adc_counts(st, body, sources)
    else:
        t_sw, fsw = st
        if swing.get("name"):
            names = _decode_name(fsw)
            if len(names) == 0:
                swing_why = f"{swing['topic']} has no name field to select '{swing['name']}'"
            else:
                keep = names == swing["name"]
                counts = names == BODY_VECT_NAME
                if not keep.any() and counts.any() and not explicit_swing:
                    # No world-frame sensor but a cable sensor on the airframe whose counts
                    # came in over MAVLink (``swingrt hil``): read as its ADC would be.
                    on_body = True
                    if att is None:
                        swing_why = "the cable sensor's body angles need vehicle_attitude"
                    else:
                        from swingrt import _core

                        _core.body_swing(np.zeros((0, 2)), np.zeros((0, 4)), dict(body or {}))
                        adc = {"adc_x": fsw["x"][counts], "adc_y": fsw["y"][counts]}
                        sources.append((t_sw[counts], {k: v.astype(float) for k, v in adc.items()}))
                elif not keep.any():
                    swing_why = f"no {swing['topic']} rows named '{swing['name']}' (swing sensor)"
                else:
                    t_sw = t_sw[keep]
                    fsw = {k: v[keep] for k, v in fsw.items()}
        if swing_why is None and not on_body:
            cols = {}
            for axis in ("n", "e"):
                field = swing[axis]
                if field not in fsw:
                    swing_why = f"{swing['topic']} has no field {field} (swing_{axis})"
                    break
                scale = (
                    swing["scale"][axis] if isinstance(swing["scale"], Mapping) else swing["scale"]
                )
                offset = (
                    swing["offset"][axis]
                    if isinstance(swing["offset"], Mapping)
                    else swing["offset"]
                )
                cols[f"swing_{axis}"] = float(scale) * fsw[field].astype(float) + float(offset)
            if swing_why is None:
                sources.append((t_sw, cols))
    if swing_why is not None:
        if explicit_swing:
            raise DataError(f"{p}: {swing_why}", path=p)
        notes["swing_n"] = notes["swing_e"] = swing_why

    # Crop the base timeline to where every loaded topic has data (no extrapolation).
    lo = max([t_pos[0]] + [s[0][0] for s in sources])
    hi = min([t_pos[-1]] + [s[0][-1] for s in sources])
    segment = _offboard_segment(topic("vehicle_status"))
    if segment is not None:
        lo, hi = max(lo, segment[0]), min(hi, segment[1])
    # The IMU estimate's tare wants the payload hanging still: the hover before the flight
    # segment, where the log has one (as the offboard node tares in PX4's hold).
    t_data_start = max([t_pos[0]] + [s[0][0] for s in sources])
    keep = (t_pos >= lo) & (t_pos <= hi)
    if keep.sum() < 2:
        raise DataError(f"{p}: the logged topics do not overlap in time", path=p)
    t_base = t_pos[keep]
    out = Trace(source=str(p), notes=notes)
    if segment is not None:
        out.meta["segment"] = (
            f"the longest OFFBOARD stretch, {segment[0] * 1e-6:.1f}–{segment[1] * 1e-6:.1f} s "
            "of PX4's clock"
        )
    out["t"] = (t_base - t_base[0]) * 1e-6
    pos_fields = zip(
        ("pn", "pe", "pd", "vn", "ve", "vd"), ("x", "y", "z", "vx", "vy", "vz"), strict=True
    )
    for c, f in pos_fields:
        out[c] = fpos[f][keep].astype(float)
    for t_src, cols in sources:
        for c, y in cols.items():
            out[c] = _interp_topic(t_base, t_src, y)
    if imu is not None and att is not None:
        settings, choice, est = _imu_swing(imu, att, t_pos, fpos, t_base, estimator, t_data_start)
        out["swing_est_n"], out["swing_est_e"] = est
        out.meta["swing_estimator"] = settings
        if choice is not None:
            out.meta["swing_vibration"] = choice.as_dict()
    if "_q0" in out:
        q = np.stack([out.pop(f"_q{i}") for i in range(4)])
        q /= np.linalg.norm(q, axis=0)
        out["roll"], out["pitch"], out["yaw"] = quat_to_euler(*q)
        if on_body and "adc_x" in out:
            from swingrt import _core

            counts = np.column_stack([out["adc_x"], out["adc_y"]])
            world = _core.body_swing(counts, np.ascontiguousarray(q.T), dict(body or {}))
            out["swing_n"], out["swing_e"] = world[:, 0], world[:, 1]
            out.meta["swing_source"] = "body"
            out.meta["body_sensor"] = dict(body or {})
    return out


#: The uORB topic of the flight controller's ADC, where a cable sensor on the airframe is read.
ADC_TOPIC = "adc_report"
#: ``debug_vect`` rows of a cable sensor on the airframe whose counts reached PX4 over MAVLink
#: (``swingrt.mavlink.link.BODY_NAME``; ``swingrt.io`` sits below ``swingrt.mavlink``).
BODY_VECT_NAME = "SWBODY"


def _adc_counts(st, body: Mapping | None, sources: list) -> str | None:
    """Add the cable sensor's two ADC channels of ``adc_report`` rows ``st`` to ``sources``
    as ``adc_x adc_y`` [counts] (NaN where a row lacks the channel); the reason when the
    log does not have them."""
    from swingrt import _core

    # The core checks the settings (it names a bad field) and holds the defaults.
    _core.body_swing(np.zeros((0, 2)), np.zeros((0, 4)), dict(body or {}))
    sensor = _core.Scenario.builtin("step").to_dict()["sensors"]["body"]
    sensor.update(body or {})
    wanted = [int(c) for c in sensor["channels"]]
    t_adc, f = st
    slots = [i for i in range(32) if f"channel_id[{i}]" in f and f"raw_data[{i}]" in f]
    if not slots:
        return f"{ADC_TOPIC} has no channel_id[]/raw_data[] fields"
    ids = np.stack([f[f"channel_id[{i}]"].astype(np.int64) for i in slots])
    raw = np.stack([f[f"raw_data[{i}]"].astype(float) for i in slots])
    cols = {}
    for axis, ch in zip(("x", "y"), wanted, strict=True):
        hit = ids == ch
        if not hit.any():
            seen = sorted({int(c) for c in np.unique(ids) if c >= 0})
            return (
                f"{ADC_TOPIC} has no channel {ch} (the cable sensor's {axis} potentiometer; "
                f"channels logged: {seen})"
            )
        cols[f"adc_{axis}"] = np.where(hit.any(axis=0), (raw * hit).sum(axis=0), np.nan)
    sources.append((t_adc, cols))
    return None


def _imu_swing(imu, att, t_pos, fpos, t_base, estimator, t_data_start=None):
    """The estimator's settings, the cutoff chosen from the log's vibration (None where the
    settings fix it; :mod:`swingrt.io.vibration`) and the swing estimated from the log's IMU
    on ``t_base`` [µs] (N, E): block means of ``sensor_combined`` over each 1/rate s (a
    decimation: what PX4's integration already folded stays folded, the rest does not fold
    again), the attitude and velocity interpolated, fed to the core's estimator, then
    interpolated back. The estimator starts its ``tare`` seconds
    before ``t_base[0]`` when the log reaches back so far (``t_data_start``): the tare is
    then the hover before the flight segment, not its first manoeuvre."""
    from swingrt import _core

    probe = _core.ImuSwingEstimator(dict(estimator) if estimator else None)
    settings = dict(probe.settings)
    choice = None
    period = 1e6 / float(settings["rate"])
    start = t_base[0]
    if t_data_start is not None:
        start = max(float(t_data_start), t_base[0] - float(settings["tare"]) * 1e6)
    grid = np.arange(start + period, t_base[-1] + 0.5 * period, period)
    if len(grid) < 2:
        nan = np.full(len(t_base), np.nan)
        return settings, choice, (nan, nan)
    t_imu, f_imu = imu
    acc = np.stack([f_imu[f"accelerometer_m_s2[{i}]"].astype(float) for i in range(3)], axis=1)
    # Block means of the samples in (t - period, t]; a block with none takes the nearest.
    csum = np.vstack([np.zeros((1, 3)), np.cumsum(acc, axis=0)])
    hi = np.searchsorted(t_imu, grid, side="right")
    lo = np.searchsorted(t_imu, grid - period, side="right")
    count = (hi - lo)[:, None]
    nearest = acc[np.clip(hi - 1, 0, len(acc) - 1)]
    accel = np.where(count > 0, (csum[hi] - csum[lo]) / np.maximum(count, 1), nearest)
    if "cutoff" not in (estimator or {}):
        # The log's own vibration sets the low-pass where the settings leave it open.
        rate, scale = float(settings["rate"]), float(settings["scale"])
        choice = choose_cutoff(accel[:, :2], rate, scale, float(settings["cutoff"]))
        settings["cutoff"] = choice.cutoff
    t_att, f_att = att
    q = np.stack([f_att[f"q[{i}]"].astype(float) for i in range(4)])
    flip = np.cumsum(np.r_[0, (np.einsum("ij,ij->j", q[:, 1:], q[:, :-1]) < 0)]) % 2 == 1
    q[:, flip] *= -1.0
    qg = np.stack([np.interp(grid, t_att, q[i]) for i in range(4)], axis=1)
    qg /= np.linalg.norm(qg, axis=1, keepdims=True)
    vel = np.stack(
        [np.interp(grid, t_pos, fpos[f].astype(float)) for f in ("vx", "vy", "vz")], axis=1
    )
    est = _core.estimate_swing(
        np.ascontiguousarray(accel), np.ascontiguousarray(qg), np.ascontiguousarray(vel), settings
    )
    return (
        settings,
        choice,
        (np.interp(t_base, grid, est[:, 0]), np.interp(t_base, grid, est[:, 1])),
    )
