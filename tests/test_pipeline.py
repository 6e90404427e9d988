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
