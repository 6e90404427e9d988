"""The whole pipeline as a user runs it: collect → identify (search, sweeps) → evaluate, and
the main job ``swingrt run``."""

from __future__ import annotations

import csv
import io
import json

import pytest

import swingrt


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    d = tmp_path_factory.mktemp("flights")
    swingrt.collect(duration=160.0, seed=3).to_parquet(d / "train.parquet")
    swingrt.collect(duration=100.0, seed=4).to_parquet(d / "other.parquet")
    return d


def test_collect_identify_evaluate_on_another_flight(flights, cli):
    model = flights / "m.json"
    r = cli("identify", flights / "train.parquet", "--search", "--plots", flights, "-o", model)
    assert r.returncode == 0, r.stderr
    assert "test NMAE" in r.stdout and (flights / "error_vs_delays.png").is_file()
    r = cli("evaluate", model, flights / "other.parquet", "--json")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert res["nmae"] < 0.05 and set(res["per_state"]) == {"vn", "swing_n"}


def test_training_length_sweep_writes_table_and_plot(flights, cli):
    out = flights / "sweep"
    r = cli(
        "identify", flights / "train.parquet", "--sweep", "length", "--plots", out,
        "-o", flights / "m2.json",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(io.StringIO((out / "sweep_length.csv").read_text())))
    assert [float(x["train_length"]) for x in rows] == [20.0, 40.0, 60.0, 80.0, 100.0, 120.0]
    assert all(0 < float(x["nmae"]) < 0.2 for x in rows)
    assert (out / "error_vs_training_length.png").is_file()


def test_main_job_writes_the_report(tmp_path, cli):
    out = tmp_path / "report"
    r = cli("run", "--out", out, "--quiet")
    assert r.returncode == 0, r.stderr
    text = (out / "metrics.csv").read_text()
    rows = {x["controller"]: x for x in csv.DictReader(io.StringIO(text))}
    assert set(rows) == {"pid", "lqr", "mpc"}
    pid = float(rows["pid"]["swing_iae_deg_s"])
    assert float(rows["mpc"]["swing_iae_deg_s"]) <= pid / 3
    assert float(rows["lqr"]["swing_iae_deg_s"]) <= pid / 3
    for f in (
        "metrics.md",
        "default-step.png",
        "default-step__model.json",
        "default-step__error_vs_delays.png",
        "error_vs_training_length.png",
        "default-step__mpc.parquet",
    ):
        assert (out / f).is_file(), f
    model = swingrt.LinearModel.load(out / "default-step__model.json")
    assert model.states == ["vn", "swing_n"] and model.inputs == ["acc_sp_n"]


# ------------------------------------------------------------- real logs without thrust

#: The columns a real flight export has (the thesis vehicle's CSV logs): no thrust.
REAL_LOG_COLUMNS = (
    "t", "vn", "ve", "vd", "swing_n", "swing_e",
    "acc_sp_n", "acc_sp_e", "acc_sp_d", "vel_sp_n", "vel_sp_e", "vel_sp_d",
)  # fmt: skip


@pytest.fixture(scope="module")
def real_logs(tmp_path_factory):
    """A simulated flight with noise, an IMU offset and wind, as a thrust-less CSV and a
    ULog whose swing sensor reads 2·angle + 0.01 on its own topic field names."""
    import numpy as np

    from swingrt.io import write_columns
    from swingrt.testing import write_ulog

    d = tmp_path_factory.mktemp("real")
    sc = {
        "noise": {"swing_std": 0.004, "velocity_std": 0.01, "acc_sp_bias": [0.1, 0.0]},
        "wind": {"velocity": [0.8, 0.0, 0.0]},
    }
    tr = swingrt.collect(sc, duration=150.0, seed=5)
    cols = {k: np.asarray(tr[k]) for k in REAL_LOG_COLUMNS}
    write_columns(cols, d / "flight.csv")
    write_ulog(tr.columns, d / "flight.ulg", swing_scale=0.5, swing_offset=0.01)
    return d


def test_identify_search_works_on_a_log_without_thrust(real_logs, cli):
    """The documented default on a thrust-less log: the closed-loop check flies a white-box
    with the default payload mass and says so; a given mass is used and named."""
    out = real_logs / "csv.json"
    r = cli("identify", real_logs / "flight.csv", "--search", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "default payload mass 0.2 kg, not estimated" in r.stdout
    model = swingrt.LinearModel.load(out)
    cc = model.diagnostics["control_check"]
    assert cc["plant"].startswith("whitebox(default payload mass 0.2 kg, not estimated")
    assert "no 'thrust' column" in cc["plant"] and "--payload-mass" in cc["plant"]
    screen = model.diagnostics["stability_screen"]
    assert "velocity integrator" in screen["criterion"] and screen["stable"] is True
    # The wander the linear analysis predicts for the pick: the flight's swing noise (0.004
    # rad) through each checked loop, the worst of them; the first loop (the white-box as
    # identified, no lag) is the one the core's velocity_wander computes from the same parts.
    w = cc["wander"]
    assert abs(w["swing_noise"] / 0.004 - 1) < 0.25, w
    assert len(w["per_loop"]) == len(cc["input_lags"]) * (1 + len(cc["vehicle_drag"]))
    assert w["worst"] == max(w["per_loop"]) and 0 < w["worst"] < 0.02, w
    from swingrt import _core
    from swingrt.io import load_flight

    plant = swingrt.sysid.identify(
        load_flight(real_logs / "flight.csv"), method="whitebox", payload_mass=0.2
    )
    direct = _core.velocity_wander(
        model, plant, None, cc["input_lags"][0], w["swing_noise"], span=w["span"]
    )
    assert abs(direct / cc["step"] - w["per_loop"][0]) < 1e-9 * w["per_loop"][0], (direct, w)
    r = cli("identify", real_logs / "flight.csv", "--search", "--payload-mass", "0.3", "-o", out)
    assert r.returncode == 0, r.stderr
    plant = swingrt.LinearModel.load(out).diagnostics["control_check"]["plant"]
    assert plant.startswith("whitebox(payload mass 0.3 kg given")


def test_identify_search_works_on_a_ulog_with_its_swing_calibration(real_logs, cli):
    """A ULog's thrust is normalised (not newtons): without the vehicle's description the
    check says why it has no payload mass and uses the default; the swing calibration comes
    from the CLI."""
    out = real_logs / "ulg.json"
    r = cli(
        "identify", real_logs / "flight.ulg", "--search", "--ulog-swing-scale", "0.5",
        "--ulog-swing-offset", "0.01", "--ulog-swing-fields", "x,y", "-o", out,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    d = swingrt.LinearModel.load(out).diagnostics
    assert "PX4's normalised setpoint, not newtons" in d["control_check"]["plant"]
    assert d["test_nmae"] < 0.05
    # The calibration matters: read raw, the swing is 2x off and offset.
    r = cli("identify", real_logs / "flight.ulg", "--ulog-swing-topic", "nope", "-o", out)
    assert r.returncode == 2 and "nope" in r.stderr and "Traceback" not in r.stderr
    r = cli("identify", real_logs / "flight.csv", "--ulog-swing-scale", "2", "-o", out)
    assert r.returncode == 2 and ".ulg" in r.stderr


def test_a_missing_identification_column_names_the_column_and_the_option(real_logs, cli):
    import numpy as np

    from swingrt.io import load_flight, write_columns

    cols = dict(load_flight(real_logs / "flight.csv").columns)
    del cols["swing_n"]
    write_columns({k: np.asarray(v) for k, v in cols.items()}, real_logs / "noswing.csv")
    r = cli("identify", real_logs / "noswing.csv", "--search", "-o", real_logs / "x.json")
    assert r.returncode == 2, r.stderr
    assert "'swing_n'" in r.stderr and "--ulog-swing-topic" in r.stderr


def test_exhaustive_search_mode_and_a_shared_scoring(flights):
    """The exhaustive search tries every (q, p) and scores on the same starts and training
    rows as the default search, so a candidate scores the same in both tables."""
    tr = swingrt.Trace.from_parquet(flights / "train.parquet")
    common = dict(select="nmae", test_span=40.0)
    default = swingrt.sysid.search(tr, **common)
    ex = swingrt.sysid.search(tr, search_mode="exhaustive", search_delays=list(range(2, 31)))
    sd, se = default.model.diagnostics["selected"], ex.model.diagnostics["selected"]
    assert {(r["delays"], r["rank"]) for r in ex.table} >= {
        (q, p) for q in range(2, 31) for p in range(1, 2 * q + 2)
    }
    same = [r for r in ex.table if (r["delays"], r["rank"]) == (sd["delays"], sd["rank"])]
    if same:
        assert same[0]["nmae"] == pytest.approx(sd["nmae"], rel=1e-9)
    common_pairs = {(r["delays"], r["rank"]): r["nmae"] for r in default.table}
    shared = [r for r in ex.table if (r["delays"], r["rank"]) in common_pairs]
    assert len(shared) > 50
    for r in shared:
        assert r["nmae"] == pytest.approx(common_pairs[(r["delays"], r["rank"])], rel=1e-9)
    assert se["nmae"] <= min(r["nmae"] for r in shared if r["stable"]) + 1e-12
