"""Flight data in and out: swingrt traces (Parquet, CSV) and PX4 ULog logs.

Every loader returns raw columns named as in DESIGN section 2 (``t`` in seconds from the
first sample, NED positions/velocities, ZYX Euler angles, swing angles, acceleration and
velocity setpoints); resampling to the identification sample time Ts is the caller's job
(thesis 4.6.1: the logs come at uneven rates, identification works on a uniform grid).
Only the columns a caller asks for are required: :func:`require` checks them and names what
is missing or broken (column, file, time of the first NaN).

PX4 ULog mapping (uORB topics, timestamps in microseconds):

==========================================  ==============================================
``vehicle_local_position``                  ``pn pe pd`` <- ``x y z``; ``vn ve vd`` <- ``vx vy vz``
``vehicle_local_position_setpoint``         ``acc_sp_*`` <- ``acceleration[0..2]`` (PX4 >= 1.11)
                                            or ``acc_x acc_y acc_z`` (older firmware);
                                            ``vel_sp_*`` <- ``vx vy vz``;
                                            ``thrust`` <- ``|thrust[0..2]|`` (normalised)
``vehicle_attitude``                        ``roll pitch yaw`` <- ``q[0..3]`` (scalar first,
                                            body FRD -> NED), Euler ZYX
swing sensor (configurable, see below)      ``swing_n swing_e`` = scale * raw + offset
==========================================  ==============================================

Timeline: each topic keeps its own timestamps. Everything is merged onto the timeline of
``vehicle_local_position`` (the state estimate, the densest topic the identification needs),
cropped to the span where every loaded topic has samples, by linear interpolation of each
topic in its own time. Attitude is interpolated as a quaternion (sign-continuous, then
normalised) so that yaw does not jump at +-pi. A topic that falls silent for longer than
``max(0.5 s, 10 x its median period)`` leaves NaN inside the hole instead of a straight
line, so that :func:`require` reports the gap with its time.

Swing sensor: ``ulog_swing = {"topic": "debug_vect", "name": "SWING", "n": "x", "e": "y",
"scale": 1.0, "offset": 0.0}`` (the default; ``name`` filters the rows of a ``debug_vect``
topic by its ``name`` field, our DEBUG_VECT convention documented in docs/flying.md).
``scale``/``offset`` are the linear calibration of the sensor (thesis 6.1.2: ADC reading to
angle by a best-fit straight line); a pair ``{"n": s, "e": s}`` sets them per axis.

:func:`write_ulog` writes a valid ULog file (format spec: docs.px4.io "ULog File Format")
from a trace so that the ULog path can be exercised end to end without a flight log.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from swingrt.io.atomic import atomic_path
from swingrt.errors import DataError

__all__ = [
    "TRACE_COLUMNS",
    "FlightData",
    "DEFAULT_ULOG_SWING",
    "load_flight",
    "require",
    "write_columns",
    "write_ulog",
    "quat_to_euler",
    "euler_to_quat",
]

#: Column names of a swingrt trace (DESIGN section 2), in their canonical order.
TRACE_COLUMNS = (
    "t",
    "pn",
    "pe",
    "pd",
    "vn",
    "ve",
    "vd",
    "roll",
    "pitch",
    "yaw",
    "swing_n",
    "swing_e",
    "swing_rate_n",
    "swing_rate_e",
    "acc_sp_n",
    "acc_sp_e",
    "acc_sp_d",
    "vel_sp_n",
    "vel_sp_e",
    "vel_sp_d",
)

#: Default swing-sensor source in a ULog: DEBUG_VECT rows named "SWING", x = swing_n, y = swing_e.
DEFAULT_ULOG_SWING: dict = {
    "topic": "debug_vect",
    "name": "SWING",
    "n": "x",
    "e": "y",
    "scale": 1.0,
    "offset": 0.0,
}

_SUFFIXES = (".parquet", ".csv", ".ulg")


class FlightData(dict):
    """Columns of one flight (``dict[str, np.ndarray]``, float64, equal length).

    ``notes`` maps a column that could not be loaded to the reason (e.g. the ULog topic that
    was absent), so that :func:`require` can say why it is missing.
    """

    def __init__(self, columns=(), *, source: str = "", notes: Mapping[str, str] | None = None):
        super().__init__(columns)
        #: Where the data came from (file path), used in error messages.
        self.source = source
        #: Why an expected column is absent, by column name.
        self.notes = dict(notes or {})


def load_flight(
    path: str | os.PathLike[str],
    *,
    ulog_swing: Mapping | None = None,
    columns: Iterable[str] | None = None,
) -> FlightData:
    """Load a flight from ``.parquet``, ``.csv`` or a PX4 ``.ulg`` into raw trace columns.

    ``ulog_swing`` configures the swing sensor topic of a ULog (module doc); it is ignored for
    the other formats. ``columns``, if given, are checked with :func:`require`.
    Raises :class:`DataError` with one line for an unknown extension, an empty or unreadable
    file, non-increasing time, or (with ``columns``) a missing column or NaN gap.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in _SUFFIXES:
        raise DataError(
            f"{p}: unknown data format '{p.suffix or '(none)'}' (expected .parquet, .csv or .ulg)"
        )
    if not p.is_file():
        raise DataError(f"{p}: no such file")
    if p.stat().st_size == 0:
        raise DataError(f"{p}: file is empty")
    if suffix == ".ulg":
        data = _load_ulog(p, ulog_swing)
    else:
        data = _load_table(p, suffix)
    _finish_time(data, str(p))
    if columns is not None:
        require(data, columns, str(p))
    return data


def require(columns: Mapping[str, np.ndarray], names: Iterable[str], source: str) -> None:
    """Check that every column in ``names`` is present and finite.

    Raises :class:`DataError` naming the missing column(s) and ``source`` (with the reason if
    the loader recorded one), or the first column holding NaN and the time where it starts.
    """
    names = list(names)
    notes = getattr(columns, "notes", {})
    missing = [n for n in names if n not in columns]
    if missing:
        why = "; ".join(sorted({notes[n] for n in missing if n in notes}))
        plural = "s" if len(missing) > 1 else ""
        msg = f"{source}: missing column{plural} {', '.join(missing)}"
        raise DataError(msg + (f" ({why})" if why else ""))
    t = columns.get("t")
    for n in names:
        bad = ~np.isfinite(np.asarray(columns[n], dtype=float))
        if bad.any():
            i = int(np.argmax(bad))
            j = i + int(np.argmin(bad[i:])) if not bad[i:].all() else len(bad)
            where = (
                f"t = {float(t[i]):.3f} s" if t is not None and np.isfinite(t[i]) else f"row {i}"
            )
            raise DataError(f"{source}: column {n} has a NaN gap at {where} ({j - i} sample(s))")


def write_columns(columns: Mapping[str, np.ndarray], path: str | os.PathLike[str]) -> None:
    """Write columns to ``.parquet`` or ``.csv`` atomically (a failed write leaves no file)."""
    p = Path(path)
    suffix = p.suffix.lower()
    arrays = {k: np.asarray(v, dtype=float) for k, v in columns.items()}
    lengths = {len(v) for v in arrays.values()}
    if len(lengths) > 1:
        raise DataError(f"{p}: columns have different lengths {sorted(lengths)}")
    import pyarrow as pa

    table = pa.table(arrays)
    with atomic_path(p) as tmp:
        if suffix == ".parquet":
            import pyarrow.parquet as pq

            pq.write_table(table, tmp)
        elif suffix == ".csv":
            import pyarrow.csv as pcsv

            pcsv.write_csv(table, tmp)
        else:
            raise DataError(f"{p}: cannot write '{p.suffix}' (use .parquet or .csv)")


# --------------------------------------------------------------------------- tables


def _load_table(p: Path, suffix: str) -> FlightData:
    import pyarrow as pa

    try:
        if suffix == ".parquet":
            import pyarrow.parquet as pq

            table = pq.read_table(p)
        else:
            import pyarrow.csv as pcsv

            table = pcsv.read_csv(p)
    except (pa.ArrowInvalid, pa.ArrowException, OSError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if "Empty CSV file" in first:
            raise DataError(f"{p}: file is empty") from None
        raise DataError(f"{p}: cannot read {suffix[1:]} file: {first}") from None
    if table.num_rows == 0:
        raise DataError(f"{p}: file holds no rows")
    out = FlightData(source=str(p))
    for name in table.column_names:
        col = table.column(name)
        if pa.types.is_integer(col.type) or pa.types.is_floating(col.type):
            out[name] = col.to_numpy(zero_copy_only=False).astype(float)
        elif pa.types.is_boolean(col.type):
            out[name] = col.to_numpy(zero_copy_only=False).astype(float)
        elif pa.types.is_null(col.type):
            out[name] = np.full(table.num_rows, np.nan)
        else:
            out.notes[name] = f"column {name} is not numeric ({col.type})"
    return out


def _finish_time(data: FlightData, source: str) -> None:
    """Shift ``t`` to start at 0 and check it increases strictly."""
    if "t" not in data:
        return
    t = data["t"]
    if len(t) == 0:
        raise DataError(f"{source}: file holds no samples")
    if not np.all(np.isfinite(t)):
        i = int(np.argmax(~np.isfinite(t)))
        raise DataError(f"{source}: column t is not finite at row {i}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0)) + 1
        raise DataError(f"{source}: time does not increase at row {i} (t = {t[i]:.6g} s)")
    data["t"] = t - t[0]


# --------------------------------------------------------------------------- ULog reading


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


def _load_ulog(p: Path, ulog_swing: Mapping | None) -> FlightData:
    try:
        from pyulog import ULog
    except ImportError:  # pragma: no cover - pyulog is a declared dependency
        raise DataError(f"{p}: reading .ulg needs pyulog (pip install pyulog)") from None

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
        log = ULog(str(p))
    except Exception as exc:  # pyulog raises bare Exception / struct.error on bad files
        raise DataError(f"{p}: not a readable ULog file ({exc})") from None

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
        raise DataError(f"{p}: ULog has no vehicle_local_position topic (the state estimate)")
    t_pos, fpos = pos
    if len(t_pos) < 2:
        raise DataError(f"{p}: vehicle_local_position holds fewer than 2 samples")
    for f in ("x", "y", "z", "vx", "vy", "vz"):
        if f not in fpos:
            raise DataError(f"{p}: vehicle_local_position has no field {f}")

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
            cols["thrust"] = np.sqrt((th * th).sum(axis=0))
        if cols:
            sources.append((t_sp, cols))

    att = topic("vehicle_attitude")
    if att is None:
        for c in ("roll", "pitch", "yaw"):
            notes[c] = "ULog has no vehicle_attitude topic"
    else:
        t_att, fatt = att
        if not all(f"q[{i}]" in fatt for i in range(4)):
            raise DataError(f"{p}: vehicle_attitude has no field q[0..3]")
        q = np.stack([fatt[f"q[{i}]"].astype(float) for i in range(4)])
        # Sign continuity: q and -q are the same attitude; interpolate along the short path.
        flip = np.cumsum(np.r_[0, (np.einsum("ij,ij->j", q[:, 1:], q[:, :-1]) < 0)]) % 2 == 1
        q[:, flip] *= -1.0
        sources.append((t_att, {f"_q{i}": q[i] for i in range(4)}))

    st = topic(swing["topic"])
    swing_why = None
    if st is None:
        swing_why = f"ULog has no {swing['topic']} topic (swing sensor)"
    else:
        t_sw, fsw = st
        if swing.get("name"):
            names = _decode_name(fsw)
            if len(names) == 0:
                swing_why = f"{swing['topic']} has no name field to select '{swing['name']}'"
            else:
                keep = names == swing["name"]
                if not keep.any():
                    swing_why = f"no {swing['topic']} rows named '{swing['name']}' (swing sensor)"
                else:
                    t_sw = t_sw[keep]
                    fsw = {k: v[keep] for k, v in fsw.items()}
        if swing_why is None:
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
            raise DataError(f"{p}: {swing_why}")
        notes["swing_n"] = notes["swing_e"] = swing_why

    # Crop the base timeline to where every loaded topic has data (no extrapolation).
    lo = max([t_pos[0]] + [s[0][0] for s in sources])
    hi = min([t_pos[-1]] + [s[0][-1] for s in sources])
    keep = (t_pos >= lo) & (t_pos <= hi)
    if keep.sum() < 2:
        raise DataError(f"{p}: the logged topics do not overlap in time")
    t_base = t_pos[keep]
    out = FlightData(source=str(p), notes=notes)
    out["t"] = (t_base - t_base[0]) * 1e-6
    pos_fields = zip(
        ("pn", "pe", "pd", "vn", "ve", "vd"), ("x", "y", "z", "vx", "vy", "vz"), strict=True
    )
    for c, f in pos_fields:
        out[c] = fpos[f][keep].astype(float)
    for t_src, cols in sources:
        for c, y in cols.items():
            out[c] = _interp_topic(t_base, t_src, y)
    if "_q0" in out:
        q = np.stack([out.pop(f"_q{i}") for i in range(4)])
        q /= np.linalg.norm(q, axis=0)
        out["roll"], out["pitch"], out["yaw"] = quat_to_euler(*q)
    return out


# --------------------------------------------------------------------------- ULog writing

_ULOG_MAGIC = b"ULog\x01\x12\x35"
_ULOG_TYPES = {"uint64_t": "Q", "float": "f", "char": "c", "uint8_t": "B"}


class _ULogWriter:
    """Minimal ULog (version 1) writer: header, flag bits, formats, info, subscriptions, data."""

    def __init__(self, fh, t0_us: int):
        self.fh = fh
        fh.write(_ULOG_MAGIC + bytes([1]) + struct.pack("<Q", t0_us))
        # 'B' flag bits: no compat/incompat flags, no appended data.
        self._msg(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
        self.formats: dict[str, list[tuple[str, int, str]]] = {}
        self.ids: dict[tuple[str, int], int] = {}

    def _msg(self, kind: bytes, payload: bytes) -> None:
        if len(payload) > 0xFFFF:
            raise DataError("ULog message too long")
        self.fh.write(struct.pack("<HB", len(payload), kind[0]) + payload)

    def info(self, key_type: str, key: str, value: bytes) -> None:
        k = f"{key_type} {key}".encode()
        self._msg(b"I", bytes([len(k)]) + k + value)

    def format(self, name: str, fields: list[tuple[str, int, str]]) -> None:
        """Declare a message format; fields are (type, array length or 0, name)."""
        parts = [f"{ty}[{n}] {fn}" if n else f"{ty} {fn}" for ty, n, fn in fields]
        self._msg(b"F", f"{name}:{';'.join(parts)};".encode())
        self.formats[name] = fields

    def subscribe(self, name: str, multi_id: int = 0) -> int:
        msg_id = len(self.ids)
        self.ids[(name, multi_id)] = msg_id
        self._msg(b"A", struct.pack("<BH", multi_id, msg_id) + name.encode())
        return msg_id

    def data(self, msg_id: int, name: str, values: list) -> None:
        fmt = "<" + "".join(
            (f"{n}s" if ty == "char" else _ULOG_TYPES[ty] * n) if n else _ULOG_TYPES[ty]
            for ty, n, _ in self.formats[name]
        )
        self._msg(b"D", struct.pack("<H", msg_id) + struct.pack(fmt, *values))


def write_ulog(
    trace_columns: Mapping[str, np.ndarray],
    path: str | os.PathLike[str],
    *,
    old_spelling: bool = False,
    rates_hz: Mapping[str, float] | None = None,
    swing_scale: float = 1.0,
    swing_offset: float = 0.0,
) -> None:
    """Write a trace as a PX4 ULog with the topics :func:`load_flight` reads.

    Topics: ``vehicle_local_position`` (x, y, z, vx, vy, vz), ``vehicle_local_position_setpoint``
    (vx, vy, vz and ``acceleration[3]``, or ``acc_x/acc_y/acc_z`` with ``old_spelling``),
    ``vehicle_attitude`` (``q[4]`` from roll/pitch/yaw), ``debug_vect`` named ``SWING`` (x, y =
    the raw sensor value ``(swing - offset) / scale``, z = 0). Each topic is sampled from the
    trace at its own rate (``rates_hz``; defaults 50, 50, 100, 40 Hz, like PX4's logger), so
    the reader's merge of separate timelines is exercised. The file is written atomically.
    """
    rates = {
        "vehicle_local_position": 50.0,
        "vehicle_local_position_setpoint": 50.0,
        "vehicle_attitude": 100.0,
        "debug_vect": 40.0,
    }
    rates.update(rates_hz or {})
    need = ["t", "pn", "pe", "pd", "vn", "ve", "vd", "roll", "pitch", "yaw", "swing_n", "swing_e"]
    need += ["acc_sp_n", "acc_sp_e", "acc_sp_d"]
    require(trace_columns, need, "write_ulog")
    t = np.asarray(trace_columns["t"], dtype=float)
    if len(t) < 2:
        raise DataError("write_ulog: the trace needs at least 2 samples")

    def col(name: str) -> np.ndarray:
        if name in trace_columns:
            return np.asarray(trace_columns[name], dtype=float)
        return np.zeros_like(t)

    t0_us = 1_000_000  # PX4 time since boot: the log starts 1 s after boot

    def sample(rate: float):
        ts = np.arange(t[0], t[-1] + 1e-12, 1.0 / rate)
        return ts, (t0_us + np.round((ts - t[0]) * 1e6)).astype(np.int64)

    acc_fields = (
        [("float", 0, "acc_x"), ("float", 0, "acc_y"), ("float", 0, "acc_z")]
        if old_spelling
        else [("float", 3, "acceleration")]
    )
    formats = {
        "vehicle_local_position": [("uint64_t", 0, "timestamp")]
        + [("float", 0, f) for f in ("x", "y", "z", "vx", "vy", "vz")],
        "vehicle_local_position_setpoint": [("uint64_t", 0, "timestamp")]
        + [("float", 0, f) for f in ("x", "y", "z", "vx", "vy", "vz")]
        + acc_fields
        + [("float", 3, "thrust")],
        "vehicle_attitude": [("uint64_t", 0, "timestamp"), ("float", 4, "q")],
        "debug_vect": [
            ("uint64_t", 0, "timestamp"),
            ("char", 10, "name"),
            ("float", 0, "x"),
            ("float", 0, "y"),
            ("float", 0, "z"),
        ],
    }
    rows: list[tuple[int, str, list]] = []  # (timestamp_us, topic, values)

    ts, us = sample(rates["vehicle_local_position"])
    cols = [np.interp(ts, t, col(c)) for c in ("pn", "pe", "pd", "vn", "ve", "vd")]
    rows += [
        (int(u), "vehicle_local_position", [int(u)] + [float(c[i]) for c in cols])
        for i, u in enumerate(us)
    ]

    ts, us = sample(rates["vehicle_local_position_setpoint"])
    nan = float("nan")
    vel = [np.interp(ts, t, col(c)) for c in ("vel_sp_n", "vel_sp_e", "vel_sp_d")]
    acc = [np.interp(ts, t, col(c)) for c in ("acc_sp_n", "acc_sp_e", "acc_sp_d")]
    # Normalised thrust vector as PX4 logs it: along the commanded specific force, hover = 0.5.
    g = 9.80665
    for i, u in enumerate(us):
        f = np.array([acc[0][i], acc[1][i], acc[2][i] - g]) * (0.5 / g)
        vals = [int(u), nan, nan, nan] + [float(v[i]) for v in vel]
        vals += [float(a[i]) for a in acc] + [float(x) for x in f]
        rows.append((int(u), "vehicle_local_position_setpoint", vals))

    ts, us = sample(rates["vehicle_attitude"])
    q = euler_to_quat(
        np.interp(ts, t, col("roll")),
        np.interp(ts, t, col("pitch")),
        np.interp(ts, t, np.unwrap(col("yaw"))),
    )
    rows += [
        (int(u), "vehicle_attitude", [int(u)] + [float(c[i]) for c in q]) for i, u in enumerate(us)
    ]

    ts, us = sample(rates["debug_vect"])
    sn = (np.interp(ts, t, col("swing_n")) - swing_offset) / swing_scale
    se = (np.interp(ts, t, col("swing_e")) - swing_offset) / swing_scale
    rows += [
        (int(u), "debug_vect", [int(u), b"SWING", float(sn[i]), float(se[i]), 0.0])
        for i, u in enumerate(us)
    ]
    rows.sort(key=lambda r: r[0])

    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        w = _ULogWriter(fh, t0_us)
        w.info("char[4]", "ver_sw", b"none")
        w.info("char[14]", "sys_name", b"swingrt sitl\0\0")
        w.info("char[9]", "sys_toolchain", b"swingrt\0\0")
        for name, fields in formats.items():
            w.format(name, fields)
        ids = {name: w.subscribe(name) for name in formats}
        for _, name, vals in rows:
            w.data(ids[name], name, vals)
