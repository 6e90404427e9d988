"""Hostile input: property tests of the flight loaders and the command line.

Loaders: a CSV, Parquet or ULog file that is truncated, corrupted, empty, wrong-typed, has
duplicated or non-monotonic timestamps or gigantic values either loads (time finite, strictly
increasing, from 0) or raises ``DataError`` naming the file, never another exception.
CLI: every subcommand with fuzzed arguments ends with exit status 0 or 2 and, on 2, one line
on stderr, never a traceback (in-process through ``swingrt.cli.main``).

Hypothesis is derandomized and bounded, so runs are reproducible and the file stays well
under two minutes. Run alone with ``pytest -m hostile``.
"""

from __future__ import annotations

import functools
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swingrt import cli
from swingrt.errors import DataError
from swingrt.io import load_flight
from swingrt.io.flight import TRACE_COLUMNS, write_columns
from swingrt.testing import write_ulog

pytestmark = pytest.mark.hostile

SETTINGS = settings(
    max_examples=300,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


def _columns(n: int = 60) -> dict[str, np.ndarray]:
    t = np.arange(n) * 0.02
    cols = {c: 0.1 * np.sin(t + i) for i, c in enumerate(TRACE_COLUMNS)}
    cols["t"] = t
    for c in ("roll", "pitch", "yaw"):
        cols[c] = 0.05 * np.sin(t)
    return cols


@functools.cache
def _valid() -> dict[str, bytes]:
    """Bytes of a valid CSV, Parquet and ULog flight, to mutate (not a fixture: Hypothesis
    would print these bytes with every failing example)."""
    d = Path(tempfile.mkdtemp(prefix="swingrt-hostile-"))
    out = {}
    for suffix in (".csv", ".parquet"):
        write_columns(_columns(), d / f"f{suffix}")
        out[suffix] = (d / f"f{suffix}").read_bytes()
    write_ulog(_columns(200), d / "f.ulg")
    out[".ulg"] = (d / "f.ulg").read_bytes()
    shutil.rmtree(d)
    return out


def _check_load(path: Path) -> None:
    try:
        tr = load_flight(path)
    except DataError as exc:
        msg = str(exc)
        assert str(path) in msg, f"DataError does not name the file: {msg}"
        assert "\n" not in msg.strip(), f"DataError is not one line: {msg!r}"
        return
    if "t" in tr:
        t = tr["t"]
        assert np.all(np.isfinite(t)) and t[0] == 0.0
        assert np.all(np.diff(t) > 0)


# ------------------------------------------------------------------ byte-level mutations

mutation = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0.0, 1.0)),
    st.tuples(
        st.just("flip"),
        st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 255)), min_size=1, max_size=20),
    ),
    st.tuples(st.just("insert"), st.floats(0.0, 1.0), st.binary(min_size=1, max_size=64)),
    st.tuples(st.just("replace"), st.binary(max_size=512)),
    st.tuples(st.just("duplicate"), st.floats(0.0, 1.0), st.floats(0.0, 0.3)),
)


def _mutate(data: bytes, m) -> bytes:
    kind = m[0]
    n = len(data)
    if kind == "truncate":
        return data[: int(m[1] * n)]
    if kind == "flip":
        if not n:
            return data
        b = bytearray(data)
        for pos, val in m[1]:
            b[min(int(pos * n), n - 1)] = val
        return bytes(b)
    if kind == "insert":
        i = int(m[1] * n)
        return data[:i] + m[2] + data[i:]
    if kind == "replace":
        return m[1]
    i = int(m[1] * n)
    j = min(n, i + int(m[2] * n))
    return data[:j] + data[i:j] + data[j:]


@pytest.mark.parametrize("suffix", [".csv", ".parquet", ".ulg"])
@SETTINGS
@given(muts=st.lists(mutation, min_size=1, max_size=3))
def test_corrupted_files_give_data_error(tmp_path, suffix, muts):
    data = _valid()[suffix]
    for m in muts:
        data = _mutate(data, m)
    path = tmp_path / f"flight{suffix}"
    path.write_bytes(data)
    _check_load(path)


# ------------------------------------------------------------------ content-level hostility

hostile_float = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e308, -1e308, 1e-320, 1e30]),
)


@st.composite
def hostile_table(draw):
    n = draw(st.integers(0, 30))
    t = np.arange(n) * 0.02
    kind = draw(st.sampled_from(["dup", "reverse", "shuffle", "gigantic", "nan", "ok"]))
    if kind == "dup" and n > 1:
        i = draw(st.integers(1, n - 1))
        t[i] = t[i - 1]
    elif kind == "reverse":
        t = t[::-1].copy()
    elif kind == "shuffle":
        t = np.array(draw(st.permutations(list(t))), dtype=float)
    elif kind in ("gigantic", "nan") and n:
        i = draw(st.integers(0, n - 1))
        t[i] = draw(hostile_float)
    cols: dict[str, object] = {"t": t}
    for c in draw(st.lists(st.sampled_from(TRACE_COLUMNS[1:]), max_size=4, unique=True)):
        cols[c] = np.array(draw(st.lists(hostile_float, min_size=n, max_size=n)), dtype=float)
    return cols


def _write_text_csv(path: Path, cols: dict[str, object], wrong: str | None) -> None:
    names = list(cols)
    rows = zip(*(list(map(repr, np.asarray(cols[c]).tolist())) for c in names), strict=True)
    lines = [",".join(names)] + [",".join(r) for r in rows]
    if wrong and len(lines) > 1:
        lines[1] = wrong + lines[1][lines[1].find(",") :] if "," in lines[1] else wrong
    path.write_text("\n".join(lines) + "\n")


@SETTINGS
@given(
    cols=hostile_table(),
    wrong=st.one_of(st.none(), st.sampled_from(["abc", "", "1e999", "0x10", "nan", "--1", '"'])),
)
def test_hostile_csv_content(tmp_path, cols, wrong):
    path = tmp_path / "hostile.csv"
    _write_text_csv(path, cols, wrong)
    _check_load(path)


@SETTINGS
@given(cols=hostile_table(), as_strings=st.booleans())
def test_hostile_parquet_content(tmp_path, cols, as_strings):
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = {k: np.asarray(v, dtype=float) for k, v in cols.items()}
    table = pa.table(
        {
            k: (pa.array([repr(x) for x in v]) if as_strings and k == "t" else v)
            for k, v in arrays.items()
        }
    )
    path = tmp_path / "hostile.parquet"
    pq.write_table(table, path)
    _check_load(path)


@SETTINGS
@given(
    kind=st.sampled_from(["nan_pos", "huge_vel", "zero_quat", "dup_t", "reverse_t", "gigantic"]),
    n=st.integers(2, 40),
    at=st.floats(0.0, 1.0),
)
def test_hostile_ulog_content(tmp_path, kind, n, at):
    cols = _columns(n)
    i = min(int(at * n), n - 1)
    if kind == "nan_pos":
        cols["pn"][i] = np.nan
    elif kind == "huge_vel":
        cols["vn"][i] = 1e30
    elif kind == "zero_quat":
        # write_ulog makes q from roll/pitch/yaw; patch the file's q afterwards below.
        pass
    elif kind == "dup_t" and i > 0:
        cols["t"][i] = cols["t"][i - 1]
    elif kind == "reverse_t":
        cols["t"] = cols["t"][::-1].copy()
    elif kind == "gigantic":
        cols["swing_n"][i] = 3e38  # near float32 max: the ULog field is float32
    path = tmp_path / "hostile.ulg"
    try:
        write_ulog(cols, path)
    except DataError:
        return  # the writer refuses it (non-finite or too short): nothing to load
    if kind == "zero_quat":
        data = bytearray(path.read_bytes())
        # Zero a stretch in the middle of the data section: quaternions among other fields.
        mid = len(data) // 2
        data[mid : mid + 64] = bytes(64)
        path.write_bytes(bytes(data))
    _check_load(path)


def test_times_far_from_zero_that_collapse_are_refused(tmp_path):
    # Found by test_hostile_csv_content: -1.4e14, 0.02, 0.04 became 0, 1.4e14, 1.4e14.
    p = tmp_path / "far.csv"
    p.write_text("t,vn\n-140737488355328.0,0\n0.02,0\n0.04,0\n")
    with pytest.raises(DataError, match="time does not increase at row 2"):
        load_flight(p)


def test_time_span_beyond_float_is_refused(tmp_path):
    p = tmp_path / "span.csv"
    p.write_text("t,vn\n-1e308,0\n1e308,0\n")
    with pytest.raises(DataError, match="time spans more than a float"):
        load_flight(p)


def test_non_utf8_header_is_a_data_error(tmp_path):
    # Found by test_corrupted_files_give_data_error: pyarrow's column_names raised
    # UnicodeDecodeError.
    p = tmp_path / "header.csv"
    p.write_bytes(b"\x80t,vn\n1,1\n2,3\n")
    with pytest.raises(DataError, match="not UTF-8"):
        load_flight(p)


def test_usage_errors_are_one_line(capsys):
    code, err = _run_cli(capsys, ["simulate", "--duration"])
    assert code == 2
    assert err.count("\n") == 1 and "swingrt simulate: error:" in err and "--help" in err


@pytest.mark.parametrize(
    ("flag", "value"),
    [("--timeout", "inf"), ("--stale-factor", "inf"), ("--budget", "inf"),
     ("--acc-limit", "inf"), ("--timeout", "nan"), ("--system-id", "999")],
)  # fmt: skip
def test_fly_refuses_settings_that_switch_safety_off(capsys, files, flag, value):
    # --timeout inf waited for ever on a silent link; an infinite stale factor or budget
    # switched the watchdog off.
    args = ["fly", "--connect", "udpout:127.0.0.1:9", "--model", files["bad_model"], flag, value]
    code, err = _run_cli(capsys, args)
    assert code == 2 and flag in err and err.count("\n") == 1, err


def test_empty_and_directory_inputs(tmp_path):
    for suffix in (".csv", ".parquet", ".ulg"):
        p = tmp_path / f"empty{suffix}"
        p.write_bytes(b"")
        _check_load(p)
        d = tmp_path / f"dir{suffix}"
        d.mkdir()
        _check_load(d)


# ------------------------------------------------------------------ the command line


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, str]:
    d = tmp_path_factory.mktemp("cli")
    paths = {}
    for suffix, data in _valid().items():
        (d / f"good{suffix}").write_bytes(data)
        (d / f"bad{suffix}").write_bytes(data[: len(data) // 3])
        paths[f"good{suffix}"] = str(d / f"good{suffix}")
        paths[f"bad{suffix}"] = str(d / f"bad{suffix}")
    (d / "bad.toml").write_text("duration = [\n")
    (d / "unknown.toml").write_text("no_such_field = 1\n")
    (d / "model.json").write_text('{"format": "swingrt-model/1", "delays": 1e30}')
    (d / "dir.parquet").mkdir()
    paths.update(
        bad_toml=str(d / "bad.toml"),
        unknown_toml=str(d / "unknown.toml"),
        bad_model=str(d / "model.json"),
        dir=str(d / "dir.parquet"),
        missing=str(d / "missing.parquet"),
        out_in_file=str(d / "good.csv" / "x.parquet"),
    )
    return paths


WORDS = ["", "-1", "0", "nan", "inf", "-inf", "1e309", "abc", "2", "0.05", "--", "-x", "ne", "n"]

# Flags per subcommand that take a value; fuzzing never combines them into a long run (no
# positive --duration beyond 0.05 s, no network URL but unreachable loopback with a tiny
# timeout, `run`/`bench`/`experiment` only with bad arguments).
FLAGS: dict[str, list[str]] = {
    "simulate": ["--duration", "--seed", "-o"],
    "collect": ["--duration", "--seed", "-o", "--axes", "--connect"],
    "identify": [
        "--method",
        "--select",
        "--axes",
        "--delays",
        "--rank",
        "--offset",
        "--dt",
        "--test-span",
        "--payload-mass",
        "--vehicle-mass",
        "--cable-length",
        "--sweep",
        "-o",
    ],
    "evaluate": ["--rollout", "--starts"],
    "experiment": ["--out", "--seed"],
    "sitl": [
        "--listen",
        "--log",
        "--speed",
        "--rate",
        "--duration",
        "--system-id",
        "--offboard-loss",
    ],
    "fly": [
        "--connect",
        "--model",
        "--mission",
        "--log",
        "--system-id",
        "--hold",
        "--acc-limit",
        "--budget",
        "--stale-factor",
        "--timeout",
    ],
    "run": ["--out", "--seed"],
    "bench": [],
}


def _value(draw, files, flag: str) -> str:
    pool = WORDS + [
        files[k]
        for k in (
            "bad.csv",
            "bad.ulg",
            "good.csv",
            "bad_toml",
            "unknown_toml",
            "bad_model",
            "dir",
            "missing",
            "out_in_file",
        )
    ]
    if flag == "--connect":
        pool = ["udpout:127.0.0.1:9", "tcp:127.0.0.1:9", "nonsense:", "udpin:127.0.0.1:x", ""]
    elif flag == "--listen":
        pool = ["nonsense", "udpout:", "udpin:127.0.0.1:99999", "tcp:999.0.0.1:1"]
    return draw(st.sampled_from(pool))


@st.composite
def argv(draw, files, command: str):
    args = [command]
    flags = FLAGS[command]
    for _ in range(draw(st.integers(0, 4))):
        if flags and draw(st.integers(0, 5)):
            f = draw(st.sampled_from(flags))
            args += [f, _value(draw, files, f)]
        else:
            args.append(draw(st.sampled_from(["--nope", "-z", "--help=x", "extra", "--seed"])))
    if command in ("simulate", "collect", "sitl") and draw(st.booleans()):
        args.append(
            draw(
                st.sampled_from(
                    [files["bad_toml"], files["unknown_toml"], files["missing"], "no.toml"]
                )
            )
        )
    if command == "identify":
        args.append(
            draw(
                st.sampled_from(
                    [
                        files["bad.csv"],
                        files["bad.ulg"],
                        files["missing"],
                        files["dir"],
                        files["bad_model"],
                        "x.txt",
                    ]
                )
            )
        )
    if command == "evaluate":
        args += [
            draw(st.sampled_from([files["bad_model"], files["missing"], files["good.csv"]])),
            draw(st.sampled_from([files["bad.csv"], files["missing"], files["good.csv"]])),
        ]
    if command == "experiment":
        args.append(
            draw(st.sampled_from(["no-such-experiment", files["bad_toml"], files["unknown_toml"]]))
        )
    if command == "fly":
        # fly needs --connect and --model; make sure a run cannot reach a real flight.
        if "--connect" not in args:
            args += ["--connect", "udpout:127.0.0.1:9"]
        if "--timeout" not in args:
            args += ["--timeout", "0.2"]
    if command in ("simulate", "collect", "sitl"):
        # Never a long run: any positive duration is replaced by 0.05 s.
        for i, a in enumerate(args[:-1]):
            if a == "--duration":
                try:
                    if float(args[i + 1]) > 0.05:
                        args[i + 1] = "0.05"
                except ValueError:
                    pass
        if command == "sitl" and "--listen" not in args:
            args += ["--listen", "nonsense"]
    if command in ("run", "bench"):
        args.append("--nope")  # never the full reproduction or the benchmarks
    return args


def _run_cli(capsys, args: list[str]) -> tuple[int, str]:
    try:
        code = cli.main(args)
    except SystemExit as exc:
        code = int(exc.code or 0) if not isinstance(exc.code, str) else 2
    err = capsys.readouterr().err
    return code, err


@pytest.mark.parametrize("command", list(FLAGS))
def test_cli_fuzzed_arguments(capsys, files, tmp_path, command):
    cwd = os.getcwd()
    os.chdir(tmp_path)  # outputs a fuzzed run might write land here
    try:

        @settings(
            max_examples=60,
            deadline=None,
            derandomize=True,
            database=None,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
        )
        @given(args=argv(files, command))
        def check(args):
            if "--help" in args or "-h" in args:
                return
            code, err = _run_cli(capsys, args)
            assert "Traceback" not in err, (args, err)
            if code != 0:
                lines = [ln for ln in err.splitlines() if ln.strip()]
                assert code == 2, (args, code, err)
                assert len(lines) == 1, (args, err)

        check()
    finally:
        os.chdir(cwd)
