"""Flight data loading: Parquet/CSV/ULog round trips and the errors a user can hit."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from swingrt.errors import DataError
from swingrt.io import TRACE_COLUMNS, load_flight, require, write_columns
from swingrt.io.ulog import euler_to_quat, quat_to_euler
from swingrt.testing import write_ulog


def synthetic_trace(duration: float = 12.0, dt: float = 0.01) -> dict[str, np.ndarray]:
    """A smooth trace with every trace column, distinct per column."""
    t = np.arange(0.0, duration, dt)
    cols = {
        name: 0.01 * (i + 1) * np.sin((0.3 + 0.05 * i) * t + i)
        for i, name in enumerate(TRACE_COLUMNS)
    }
    cols["t"] = t
    cols["yaw"] = np.angle(np.exp(1j * (0.9 * t - 2.0)))  # wraps through +-pi
    cols["roll"] = 0.2 * np.sin(1.3 * t)
    cols["pitch"] = -0.15 * np.cos(0.7 * t)
    cols["pd"] = -10.0 + 0.1 * np.sin(t)
    return cols


@pytest.mark.parametrize("suffix", [".parquet", ".csv"])
def test_table_round_trip(tmp_path, suffix):
    cols = synthetic_trace()
    cols["t"] = cols["t"] + 5.0  # the loader reports time from the first sample
    path = tmp_path / f"trace{suffix}"
    write_columns(cols, path)
    got = load_flight(path, columns=["t", "vn", "swing_n", "acc_sp_n"])
    assert set(TRACE_COLUMNS) <= set(got)
    np.testing.assert_allclose(got["t"], cols["t"] - 5.0, atol=1e-12)
    for c in TRACE_COLUMNS[1:]:
        np.testing.assert_allclose(got[c], cols[c], rtol=0, atol=1e-12, err_msg=c)


def test_a_parquet_flight_keeps_what_made_it(tmp_path):
    """A flight written with its metadata (the scenario, a swing estimator's settings) reads
    back with it through ``load_flight``, as identification needs (an IMU model must carry
    the estimator it was identified on); metadata that is not a JSON object is one line."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    meta = {"scenario": {"sensors": {"swing": "imu", "estimator": {"rate": 100.0}}}}
    path = tmp_path / "flight.parquet"
    write_columns(synthetic_trace(), path, meta=meta)
    assert load_flight(path).meta == meta
    table = pa.table({"t": [0.0, 0.1], "vn": [0.0, 0.0]})
    for raw, why in ((b"{not json", "is not JSON"), (b"[1, 2]", "not a JSON object")):
        bad = tmp_path / "bad.parquet"
        pq.write_table(table.replace_schema_metadata({b"swingrt": raw}), bad)
        with pytest.raises(DataError, match=why):
            load_flight(bad)


def test_euler_quaternion_inverse():
    rng = np.random.default_rng(3)
    r, p, y = rng.uniform(-3, 3, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-3.1, 3.1, 50)
    q = np.array(euler_to_quat(r, p, y))
    np.testing.assert_allclose(np.linalg.norm(q, axis=0), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.array(quat_to_euler(*q)), [r, p, y], atol=1e-9)
    # Independent check: a pure yaw of 90 deg maps body x onto East.
    q0, q1, q2, q3 = euler_to_quat(0.0, 0.0, np.pi / 2)
    x_east = 2 * (q1 * q2 + q0 * q3)
    assert x_east == pytest.approx(1.0)


@pytest.mark.parametrize("old", [False, True])
def test_ulog_round_trip(tmp_path, old):
    cols = synthetic_trace()
    path = tmp_path / "flight.ulg"
    write_ulog(cols, path, old_spelling=old, swing_scale=2.0, swing_offset=0.05)
    from pyulog import ULog

    log = ULog(str(path))  # an independent reader accepts the file
    names = {d.name for d in log.data_list}
    assert names == {
        "vehicle_local_position",
        "vehicle_local_position_setpoint",
        "vehicle_attitude",
        "debug_vect",
    }
    sp = log.get_dataset("vehicle_local_position_setpoint").data
    assert ("acc_x" in sp) == old and ("acceleration[0]" in sp) == (not old)

    got = load_flight(path, ulog_swing={"scale": 2.0, "offset": 0.05})
    # Base timeline = vehicle_local_position at 50 Hz over the whole trace.
    assert np.median(np.diff(got["t"])) == pytest.approx(0.02, abs=1e-6)
    assert got["t"][0] == 0.0 and got["t"][-1] == pytest.approx(
        cols["t"][-1], abs=0.05
    )  # cropped to overlap
    for c in (
        "pn",
        "pe",
        "pd",
        "vn",
        "ve",
        "vd",
        "acc_sp_n",
        "acc_sp_e",
        "acc_sp_d",
        "vel_sp_n",
        "vel_sp_e",
        "vel_sp_d",
        "roll",
        "pitch",
        "swing_n",
        "swing_e",
    ):
        ref = np.interp(got["t"], cols["t"], cols[c])
        # float32 storage + linear interpolation of topics logged at other rates
        np.testing.assert_allclose(got[c], ref, atol=2e-4, err_msg=c)
    dyaw = np.angle(
        np.exp(1j * (got["yaw"] - np.interp(got["t"], cols["t"], np.unwrap(cols["yaw"]))))
    )
    assert np.max(np.abs(dyaw)) < 2e-4  # no jump where yaw wraps at +-pi
    # Hover thrust: acc_sp_d = 0 gives |thrust| 0.5 exactly; check the formula on data.
    g = 9.80665
    expect = (
        0.5 / g * np.sqrt(got["acc_sp_n"] ** 2 + got["acc_sp_e"] ** 2 + (got["acc_sp_d"] - g) ** 2)
    )
    np.testing.assert_allclose(got["thrust_sp"], expect, atol=1e-4)
    # PX4's thrust is normalised: the white-box's Newtons need the vehicle's motors.
    assert "thrust" not in got.columns


def test_ulog_swing_calibration_is_applied(tmp_path):
    cols = synthetic_trace(4.0)
    path = tmp_path / "f.ulg"
    write_ulog(cols, path, swing_scale=0.01, swing_offset=-0.2)  # raw = ADC-like counts
    raw = load_flight(path, ulog_swing={"scale": 1.0, "offset": 0.0})
    cal = load_flight(path, ulog_swing={"scale": 0.01, "offset": -0.2})
    np.testing.assert_allclose(cal["swing_n"], 0.01 * raw["swing_n"] - 0.2, atol=1e-6)
    per_axis = load_flight(
        path, ulog_swing={"scale": {"n": 0.01, "e": 1.0}, "offset": {"n": -0.2, "e": 0.0}}
    )
    np.testing.assert_allclose(per_axis["swing_n"], cal["swing_n"])
    np.testing.assert_allclose(per_axis["swing_e"], raw["swing_e"])


def test_ulog_missing_swing_topic_is_named(tmp_path):
    cols = synthetic_trace(3.0)
    path = tmp_path / "f.ulg"
    write_ulog(cols, path)
    with pytest.raises(DataError, match="no debug_vect rows named 'PAYLOAD'"):
        load_flight(path, ulog_swing={"name": "PAYLOAD"})
    with pytest.raises(DataError, match="no field w"):
        load_flight(path, ulog_swing={"n": "w"})
    with pytest.raises(DataError, match="no sensor_payload topic"):
        load_flight(path, ulog_swing={"topic": "sensor_payload"})
    with pytest.raises(DataError, match="unknown key"):
        load_flight(path, ulog_swing={"topik": "debug_vect"})


def test_ulog_gap_is_reported_with_time(tmp_path):
    cols = synthetic_trace(10.0)
    path = tmp_path / "gap.ulg"
    write_ulog(cols, path)
    # Drop the DEBUG_VECT samples between 4 and 6 s by rewriting them under an unused msg id.
    data = bytearray(path.read_bytes())
    i = 16
    debug_id = None
    while i < len(data):
        size, kind = struct.unpack_from("<HB", data, i)
        body = i + 3
        if kind == ord("A") and data[body + 3 : body + 3 + size - 3] == b"debug_vect":
            debug_id = struct.unpack_from("<H", data, body + 1)[0]
        if kind == ord("D") and struct.unpack_from("<H", data, body)[0] == debug_id:
            ts = struct.unpack_from("<Q", data, body + 2)[0]
            if 5_000_000 <= ts <= 7_000_000:  # 1 s after boot is t = 0
                data[i + 2] = ord("Q")  # an unknown message type: pyulog skips it
        i = body + size
    path.write_bytes(bytes(data))
    got = load_flight(path)
    with pytest.raises(DataError, match=r"column swing_n has a NaN gap at t = 3\.98\d s"):
        require(got, ["vn", "swing_n"], str(path))
    require(got, ["vn", "acc_sp_n"], str(path))  # other columns are whole


def test_require_names_missing_columns_and_file(tmp_path):
    cols = synthetic_trace(2.0)
    del cols["swing_e"], cols["acc_sp_e"]
    path = tmp_path / "x.parquet"
    write_columns(cols, path)
    with pytest.raises(DataError, match=r"x\.parquet: missing columns swing_e, acc_sp_e"):
        load_flight(path, columns=["vn", "swing_e", "acc_sp_e"])
    load_flight(path, columns=["vn", "swing_n", "acc_sp_n"])  # one axis needs only these


def test_nan_in_csv_is_reported(tmp_path):
    cols = synthetic_trace(2.0)
    cols["vn"][57:60] = np.nan
    path = tmp_path / "n.csv"
    write_columns(cols, path)
    with pytest.raises(DataError, match=r"column vn has a NaN gap at t = 0\.570 s \(3 sample"):
        load_flight(path, columns=["vn"])


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("a.txt", b"t,vn\n0,1\n", "unknown data format '.txt'"),
        ("e.csv", b"", "file is empty"),
        ("e.ulg", b"", "file is empty"),
        ("h.csv", b"t,vn\n", "no rows"),
        ("b.ulg", b"this is not a ulog file at all" * 4, "not a readable ULog"),
        ("b.parquet", b"PAR1 garbage", "cannot read parquet"),
        ("d.csv", b"t,vn\n0,1\n0.1,2\n0.05,3\n", "time does not increase at row 2"),
    ],
)
def test_bad_files_give_one_line_errors(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(DataError, match=message) as info:
        load_flight(path)
    assert "\n" not in str(info.value)


def test_ulog_without_local_position(tmp_path):
    cols = synthetic_trace(2.0)
    path = tmp_path / "f.ulg"
    write_ulog(cols, path)
    data = path.read_bytes().replace(b"vehicle_local_position:", b"vehicle_local_positioX:")
    data = data.replace(b"\x00vehicle_local_position", b"\x00vehicle_local_positioX")
    path.write_bytes(data)
    with pytest.raises(DataError, match="no vehicle_local_position topic"):
        load_flight(path)


def test_missing_file():
    with pytest.raises(DataError, match="no such file"):
        load_flight("/nonexistent/flight.parquet")


def test_identify_from_ulog_matches_parquet(tmp_path):
    """A simulated training flight written as ULog identifies a model as good as from the
    trace itself (held-out NMAE on another seed's flight)."""
    import json
    import subprocess
    import sys

    def swingrt(*args: str) -> str:
        res = subprocess.run(
            [sys.executable, "-m", "swingrt", *args], capture_output=True, text=True, timeout=300
        )
        assert res.returncode == 0, res.stderr
        return res.stdout

    train, test = tmp_path / "train.parquet", tmp_path / "test.parquet"
    swingrt("collect", "--seed", "1", "-o", str(train))
    swingrt("collect", "--seed", "2", "-o", str(test))
    ulg = tmp_path / "train.ulg"
    write_ulog(load_flight(train), ulg)
    scores = {}
    for src in (train, ulg):
        model = tmp_path / f"{src.suffix[1:]}.json"
        swingrt("identify", str(src), "--method", "dmdc", "-o", str(model))
        scores[src.suffix] = json.loads(swingrt("evaluate", str(model), str(test), "--json"))[
            "nmae"
        ]
    assert scores[".ulg"] < 0.05
    assert scores[".ulg"] < 1.5 * scores[".parquet"] + 0.005


def test_trace_is_the_flight_container(tmp_path):
    """One container for simulated and loaded flights: dict-like columns, metadata, files."""
    from swingrt import Trace
    from swingrt.errors import MissingColumnError

    cols = synthetic_trace(1.0)
    tr = Trace(cols, {"scenario": {"name": "x"}})
    assert len(tr) == len(cols["t"]) and "vn" in tr and "nope" not in tr
    assert set(tr) == set(cols) and tr.get("nope") is None
    with pytest.raises(MissingColumnError, match="trace has no column 'nope'") as info:
        tr["nope"]
    assert isinstance(info.value, DataError) and isinstance(info.value, KeyError)
    tr.save(tmp_path / "a.parquet")
    back = load_flight(tmp_path / "a.parquet")
    assert isinstance(back, Trace) and back.source == str(tmp_path / "a.parquet")
    assert Trace.from_parquet(tmp_path / "a.parquet").meta == {"scenario": {"name": "x"}}
    with pytest.raises(DataError, match="differ in length"):
        Trace({"t": [0.0, 1.0], "vn": [1.0]})


def test_data_error_names_the_file(tmp_path):
    path = tmp_path / "d.csv"
    path.write_bytes(b"t,vn\n0,1\n0.1,2\n0.05,3\n")
    with pytest.raises(DataError) as info:
        load_flight(path)
    assert info.value.path == str(path)
