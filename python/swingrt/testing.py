"""Test helpers shipped with the package (not part of the flight path).

* :func:`write_ulog` writes a valid PX4 ULog file (format spec: docs.px4.io "ULog File
  Format") from a trace, so that the ULog reader can be exercised end to end without a
  flight log;
* :class:`PDSwingDamper` is a simple stand-in controller with the MPC's ``reset``/``step``
  interface, for exercising the offboard loop without an identified model.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Mapping

import numpy as np

from swingrt import _core
from swingrt.errors import DataError
from swingrt.io.atomic import atomic_path
from swingrt.io.flight import require
from swingrt.io.ulog import euler_to_quat

__all__ = ["PDSwingDamper", "write_ulog"]

_ULOG_MAGIC = b"ULog\x01\x12\x35"
_ULOG_TYPES = {
    "uint64_t": "Q",
    "float": "f",
    "char": "c",
    "uint8_t": "B",
    "int16_t": "h",
    "int32_t": "i",
    "uint32_t": "I",
}
#: Slots of ``adc_report``'s 12 channels: the flight controller's own channels around the
#: cable sensor's two (written into slots 3 and 7), unused slots -1, as PX4 logs them.
_ADC_OTHER_CHANNELS = {0: 0, 1: 1, 2: 2, 4: 4, 5: 5}


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
    adc_channels: tuple[int, int] | None = None,
    body_vect: bool = False,
) -> None:
    """Write a trace as a PX4 ULog with the topics :func:`load_flight` reads.

    With ``adc_channels`` (the thesis's rig: a cable sensor on the airframe) the swing is
    written as the trace's ``adc_x adc_y`` counts on those channel ids of ``adc_report``
    (12 slots, the flight controller's own channels beside them) instead of a DEBUG_VECT;
    with ``body_vect`` the counts are written as DEBUG_VECT rows named ``SWBODY`` (the
    sensor's counts sent to PX4 over MAVLink, as ``swingrt hil`` sends them).

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
    rates.setdefault("adc_report", 100.0)
    on_adc = adc_channels is not None or body_vect
    swing_cols = ["adc_x", "adc_y"] if on_adc else ["swing_n", "swing_e"]
    need = ["t", "pn", "pe", "pd", "vn", "ve", "vd", "roll", "pitch", "yaw", *swing_cols]
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
    if adc_channels is not None:
        del formats["debug_vect"]
        formats["adc_report"] = [
            ("uint64_t", 0, "timestamp"),
            ("uint32_t", 0, "device_id"),
            ("int16_t", 12, "channel_id"),
            ("int32_t", 12, "raw_data"),
            ("uint32_t", 0, "resolution"),
            ("float", 0, "v_ref"),
        ]
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
    g = _core.GRAVITY
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

    if body_vect:
        ts, us = sample(rates["debug_vect"])
        k = np.clip(np.searchsorted(t, ts + 1e-12, side="right") - 1, 0, len(t) - 1)
        cx, cy = col("adc_x")[k], col("adc_y")[k]
        rows += [
            (int(u), "debug_vect", [int(u), b"SWBODY", float(cx[i]), float(cy[i]), 0.0])
            for i, u in enumerate(us)
        ]
    elif adc_channels is None:
        ts, us = sample(rates["debug_vect"])
        sn = (np.interp(ts, t, col("swing_n")) - swing_offset) / swing_scale
        se = (np.interp(ts, t, col("swing_e")) - swing_offset) / swing_scale
        rows += [
            (int(u), "debug_vect", [int(u), b"SWING", float(sn[i]), float(se[i]), 0.0])
            for i, u in enumerate(us)
        ]
    else:
        # The ADC is sampled, not interpolated: each row holds the counts of the trace's
        # latest sample (they are integers on the converter).
        ts, us = sample(rates["adc_report"])
        k = np.clip(np.searchsorted(t, ts + 1e-12, side="right") - 1, 0, len(t) - 1)
        counts = (col("adc_x")[k], col("adc_y")[k])
        channel_ids = [-1] * 12
        for slot, ch in _ADC_OTHER_CHANNELS.items():
            if ch not in adc_channels:
                channel_ids[slot] = ch
        channel_ids[3], channel_ids[7] = adc_channels
        for i, u in enumerate(us):
            raw = [1000 + 10 * slot for slot in range(12)]
            raw[3], raw[7] = int(counts[0][i]), int(counts[1][i])
            rows.append((int(u), "adc_report", [int(u), 1, *channel_ids, *raw, 4096, 3.3]))
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


class PDSwingDamper:
    """A simple velocity-tracking + swing-damping law, a stand-in for the MPC in tests.

    a = kv (v_ref - v) + kθ θ + kω θ̇  per axis (accelerating towards the payload's side damps
    the linear pendulum θ̈ = -(g/l) θ - a/l); not the thesis's controller (that is the MPC).
    """

    def __init__(self, kv: float = 1.0, k_swing: float = 0.0, k_rate: float = 2.0):
        self.kv, self.k_swing, self.k_rate = kv, k_swing, k_rate

    def reset(self, state, acc) -> None:
        """No internal state."""

    def step(self, state: np.ndarray, vel_ref: np.ndarray) -> np.ndarray:
        """Acceleration setpoints (axes,) for state rows [v, swing, swing_rate]."""
        s = np.asarray(state, dtype=float)
        return (
            self.kv * (np.asarray(vel_ref) - s[:, 0])
            + self.k_swing * s[:, 1]
            + self.k_rate * s[:, 2]
        )
