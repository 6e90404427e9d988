"""``swingrt campaign``: spec validation, reproducible sampling, resume, kill -9, the
report, and a hand-started Dask scheduler giving the same rows as the local cluster.

The studies are tiny (60 s training flights, 8 s steps, a few samples) and share one
reference run: resume starts from a copy of it, the scheduler flies two of its samples, and
a sample flown in-process is compared with its row. The CLI runs in subprocesses so Dask's
processes never share pytest's.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swingrt._core import Scenario
from swingrt.campaign import failure_reason, fly_sample, load_spec, parse_spec, read_rows
from swingrt.campaign.report import wilson, worst_samples
from swingrt.campaign.sampling import draw, parse_distribution
from swingrt.errors import ConfigError

# Seed 5: its six samples identify in a few seconds each. On seed 3, sample 1 (0.23 kg on
# 2.6 m with swing noise) flies all 600 candidates of both selection passes, none passing
# (40 s), and the runs here fly a study's samples five times over.
STUDY = """
name = "tiny"
samples = {samples}
seed = 5
controllers = ["pid", "lqr", "mpc"]
{extra}
[base]
step = {{ t = 2.0, vn = 2.0 }}
duration = 8.0
training_duration = 60.0

[vary]
"payload.mass" = {{ dist = "uniform", low = 0.05, high = 0.5 }}
"payload.length" = {{ dist = "loguniform", low = 0.3, high = 3.0 }}
"payload.kind" = {{ dist = "choice", values = ["single", "double"], weights = [0.8, 0.2] }}
"wind.velocity" = {{ dist = "normal", mean = [0, 0, 0], std = [1, 1, 0] }}
"noise.swing_std" = {{ dist = "grid", values = [0.0, 0.005] }}
"""


def write_study(path: Path, samples: int = 4, extra: str = "") -> Path:
    path.write_text(STUDY.format(samples=samples, extra=extra), encoding="utf-8")
    return path


def rows_equal(a: list[dict], b: list[dict]) -> bool:
    """Row for row, NaN equal to NaN."""
    if len(a) != len(b):
        return False
    for ra, rb in zip(a, b, strict=True):
        if set(ra) != set(rb):
            return False
        for k, v in ra.items():
            w = rb[k]
            if isinstance(v, float) and isinstance(w, float) and math.isnan(v) and math.isnan(w):
                continue
            if v != w:
                return False
    return True


def keys(rows: list[dict]) -> list[tuple[int, str]]:
    return [(r["sample"], r["controller"]) for r in rows]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted 6-sample run on 2 local workers: (spec file, output folder)."""
    d = tmp_path_factory.mktemp("campaign-ref")
    spec = write_study(d / "study.toml", samples=6, extra="batch_size = 1")
    out = d / "out"
    r = subprocess.run(
        [sys.executable, "-m", "swingrt", "campaign", spec, "--out", out, "--workers", "2"],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert r.returncode == 0, r.stderr
    return spec, out


# --- spec validation -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("extra", "vary", "named"),
    [
        ("colour = 1", "", "unknown key 'colour'"),
        ("", '"payload.mas" = { dist = "uniform", low = 0.1, high = 0.2 }', "mas"),
        ("", '"payload.mass" = { dist = "gaussian", mean = 0.2 }', "vary.payload.mass"),
        ("", '"payload.mass" = { dist = "uniform", low = 0.5, high = 0.1 }', "low must not"),
        ("", '"payload.mass" = { dist = "uniform", low = 0.1 }', "needs 'high'"),
        ("", '"payload.mass" = { dist = "loguniform", low = 0.0, high = 1.0 }', "low > 0"),
        ("", '"payload.kind" = { dist = "choice", values = ["single"], weights = [1, 2] }', "wei"),
        ("", '"mpc.horizon_typo" = { dist = "fixed", value = 3 }', "horizon_typo"),
        ("", '"payload.mass" = { dist = "uniform", low = -1.0, high = 0.2 }', "payload.mass"),
    ],
)
def test_spec_errors_name_the_key(tmp_path, extra, vary, named):
    text = f'name = "x"\nsamples = 2\n{extra}\n[base]\nduration = 8.0\n[vary]\n{vary}\n'
    p = tmp_path / "bad.toml"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as err:
        load_spec(p)
    msg = str(err.value)
    assert named in msg and "\n" not in msg


def test_cli_bad_spec_one_line_exit_2_before_flying(cli, tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(
        'name = "x"\nsamples = 2\n[vary]\n"payload.mass" = { dist = "gaussian" }\n',
        encoding="utf-8",
    )
    r = cli("campaign", p, "--out", tmp_path / "out", "--workers", "1")
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "vary.payload.mass" in r.stderr
    assert "unknown distribution 'gaussian'" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists()


# --- sampling ------------------------------------------------------------------------------


def test_the_sensor_study_flies_the_imu_studys_samples_with_the_swing_sensor():
    """`robustness-imu-vehicle-sensor.toml` is compared with `robustness-imu-vehicle.toml`
    sample for sample (README): the same seed, base and draws, but for the swing source and
    the sensor's noise, whose draw must not move any other."""
    root = Path(__file__).resolve().parents[1] / "examples/campaigns"
    imu = load_spec(root / "robustness-imu-vehicle.toml")
    sensor = load_spec(root / "robustness-imu-vehicle-sensor.toml")
    assert (imu.seed, imu.samples, imu.controllers) == (
        sensor.seed,
        sensor.samples,
        sensor.controllers,
    )
    assert imu.base["common"] == {"sensors": {"swing": "imu"}}
    assert {k: v for k, v in imu.base.items() if k != "common"} == sensor.base
    assert set(sensor.vary) - set(imu.vary) == {"noise.swing_std"}
    for i in (0, 13, 126, imu.samples - 1):
        drawn = sensor.draw(i)
        assert 0.0005 <= drawn.pop("noise.swing_std") <= 0.01
        assert drawn == imu.draw(i)


def test_draws_depend_on_seed_and_index_alone(tmp_path):
    spec = load_spec(write_study(tmp_path / "s.toml", samples=50))
    other = load_spec(write_study(tmp_path / "t.toml", samples=7))
    assert spec.draw(5) == other.draw(5)
    assert spec.draw(5) != spec.draw(6)
    kinds = [spec.draw(i)["payload.kind"] for i in range(50)]
    assert set(kinds) == {"single", "double"}
    for i in range(50):
        v = spec.draw(i)
        assert 0.05 <= v["payload.mass"] <= 0.5 and 0.3 <= v["payload.length"] <= 3.0
        assert len(v["wind.velocity"]) == 3 and v["wind.velocity"][2] == 0.0
        assert v["noise.swing_std"] == [0.0, 0.005][i % 2]


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    index=st.integers(0, 10**9),
    low=st.floats(1e-3, 10.0),
    span=st.floats(0.0, 100.0),
)
def test_draws_stay_in_their_bounds_and_repeat(seed, index, low, span):
    vary = {
        "u": parse_distribution({"dist": "uniform", "low": low, "high": low + span}, "vary.u"),
        "l": parse_distribution(
            {"dist": "loguniform", "low": [low, low], "high": [low + span] * 2}, "vary.l"
        ),
        "n": parse_distribution(
            {"dist": "normal", "mean": 0.0, "std": span, "low": -low, "high": low}, "vary.n"
        ),
        "c": parse_distribution({"dist": "choice", "values": [1, 2], "weights": [0, 1]}, "vary.c"),
    }
    a = draw(vary, seed, index)
    assert a == draw(vary, seed, index)
    assert low <= a["u"] <= low + span
    assert all(low * (1 - 1e-12) <= x <= (low + span) * (1 + 1e-12) for x in a["l"])
    assert -low <= a["n"] <= low and a["c"] == 2


def test_grid_is_a_full_product():
    vary = {
        "a": parse_distribution({"dist": "grid", "values": [1, 2, 3]}, "vary.a"),
        "b": parse_distribution({"dist": "grid", "values": ["x", "y"]}, "vary.b"),
        "c": parse_distribution(0.5, "vary.c"),
    }
    pts = [(draw(vary, 0, i)["a"], draw(vary, 0, i)["b"]) for i in range(6)]
    assert pts == [(1, "x"), (1, "y"), (2, "x"), (2, "y"), (3, "x"), (3, "y")]
    assert draw(vary, 0, 4)["c"] == 0.5


def test_same_seed_and_index_fly_the_same_row(reference):
    """A sample flown here, from the spec reparsed, gives the rows a Dask worker process
    wrote for it in the reference run."""
    spec_file, out = reference
    spec = load_spec(spec_file)
    a, _ = fly_sample(parse_spec(spec.raw).raw, 1)
    assert [r["controller"] for r in a] == ["pid", "lqr", "mpc"]
    assert a[0]["q"] is not None and a[0]["p"] is not None and a[0]["test_nmae"] > 0
    stored = {r["controller"]: r for r in read_rows(out) if r["sample"] == 1}
    # The stored table carries every batch's columns; the sample's own must match.
    assert rows_equal(a, [{k: stored[r["controller"]][k] for k in r} for r in a])


def test_a_sample_that_cannot_be_identified_is_a_row_not_a_crash():
    raw = {"name": "e", "samples": 1, "base": {"duration": 8.0, "training_duration": 3.0}}
    rows, _ = fly_sample(raw, 0)
    by = {r["controller"]: r for r in rows}
    assert by["pid"]["error"] == "" and math.isfinite(by["pid"]["peak_swing_deg"])
    for c in ("lqr", "mpc"):
        assert by[c]["failure"] == "error" and "DataError" in by[c]["error"]
        assert math.isnan(by[c]["peak_swing_deg"]) and by[c]["q"] is None


def _vehicle(
    identify: dict | None = None,
    scale: float = 0.7,
    payload: float = 0.05,
    selection: dict | None = None,
) -> dict:
    """A vehicle of ``scale`` x the built-in mass carrying ``payload`` kg on 1 m, in both
    flights (default: the lightest payload of the robustness study under a 0.7x vehicle)."""
    return {
        "name": "light",
        "samples": 1,
        "controllers": ["pid", "lqr", "mpc"],
        "base": {
            "step": {"t": 2.0, "vn": 2.0},
            "duration": 20.0,
            "training_duration": 120.0,
            **({"identify": identify} if identify else {}),
            **({"selection": selection} if selection else {}),
        },
        "vary": {
            "vehicle.mass": {"dist": "fixed", "value": scale * 0.952},
            "payload.mass": {"dist": "fixed", "value": payload},
            "payload.length": {"dist": "fixed", "value": 1.0},
        },
    }


@pytest.mark.parametrize("scale, payload", [(0.7, 0.05), (1.5, 0.5)])
def test_a_vehicle_is_weighed_from_its_description(scale, payload):
    """The white-box takes the vehicle's mass from its scenario, so a light payload under a
    light vehicle is estimated, not refused, and a heavy vehicle does not inflate it."""
    rows, _ = fly_sample(_vehicle(scale=scale, payload=payload), 0)
    by = {r["controller"]: r for r in rows}
    assert by["mpc"]["error"] == "" and failure_reason(by["mpc"]) == "", by["mpc"]["error"]
    # The LQR flies on it (without integral action it may keep a steady-state error).
    assert by["lqr"]["error"] == "" and math.isfinite(by["lqr"]["peak_swing_deg"])
    assert by["mpc"]["wb_payload_mass"] == pytest.approx(payload, rel=0.1)


def test_a_white_box_that_fails_does_not_stop_the_data_driven_model():
    """Told the built-in vehicle's mass (0.952 kg for a 0.666 kg vehicle), the thrust gives a
    negative payload: the LQR's row says so and the MPC on the DMDc model still flies."""
    rows, _ = fly_sample(_vehicle({"vehicle_mass": 0.952}), 0)
    by = {r["controller"]: r for r in rows}
    assert by["mpc"]["error"] == "" and failure_reason(by["mpc"]) == "", by["mpc"]["error"]
    assert by["mpc"]["wb_payload_mass"] is None
    assert "white-box not estimated with vehicle mass 0.952 kg" in by["lqr"]["error"]
    assert "not positive" in by["lqr"]["error"] and math.isnan(by["lqr"]["peak_swing_deg"])


@pytest.mark.parametrize("twin", ["off", "builtin"])
def test_a_study_says_which_twin_its_selection_flies(tmp_path, twin):
    """``[identify] twin``: ``off`` flies none, ``builtin`` the built-in vehicle at the mass
    the study describes, under the PX4 gains of its training flight (a twin that is not the
    0.7x vehicle flown: its motors, inertia and drag are the built-in's), and the
    selection's diagnostics say which; the study's ``[selection]`` settings reach the
    selection (here a dead time at the acceleration input and one lag, where the defaults
    have no dead time and two lags)."""
    selection = {"input_delays": [0.12], "input_lags": [0.05]} if twin == "builtin" else None
    spec = _vehicle({"twin": twin}, selection=selection)
    att_p = [6.0, 5.8, 2.8]
    spec["vary"]["controller.att_p"] = {"dist": "fixed", "value": att_p}
    rows, _ = fly_sample(spec, 0, out=tmp_path)
    by = {r["controller"]: r for r in rows}
    assert by["mpc"]["error"] == "", by["mpc"]["error"]
    cc = json.loads((tmp_path / "model.json").read_text())["diagnostics"]["control_check"]
    if twin == "off":
        assert cc["twin"] is None
        assert cc["input_delays"] == []
    else:
        assert f"{0.7 * 0.952:.3f} kg vehicle" in cc["twin"]["plant"], cc["twin"]["plant"]
        assert cc["input_delays"] == [0.12] and cc["input_lags"] == [0.05], cc
        flown = json.loads((tmp_path / "model.json").read_text())["diagnostics"]["twin"]
        builtin = Scenario.builtin("step").to_dict()
        assert flown["scenario"]["controller"]["att_p"] == pytest.approx(att_p)
        assert flown["scenario"]["vehicle"]["motor_tau"] == builtin["vehicle"]["motor_tau"]


def test_an_unknown_selection_setting_is_refused_by_name(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(
        'name = "x"\nsamples = 2\n[base]\nselection = { input_delay = [0.1] }\n[vary]\n'
        '"payload.mass" = { dist = "uniform", low = 0.1, high = 0.2 }\n',
        encoding="utf-8",
    )
    with pytest.raises(ConfigError, match=r"selection\.input_delay: unknown field"):
        load_spec(p)


def test_an_unknown_twin_is_refused_by_name(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(
        'name = "x"\nsamples = 2\n[base]\nidentify = { twin = "nominal" }\n[vary]\n'
        '"payload.mass" = { dist = "uniform", low = 0.1, high = 0.2 }\n',
        encoding="utf-8",
    )
    with pytest.raises(
        ConfigError, match=r"identify\.twin: one of exact, builtin, off, not 'nominal'"
    ):
        load_spec(p)


def test_failure_rule():
    ok = {
        "controller": "mpc",
        "error": "",
        "fallback": "",
        "peak_swing_deg": 10.0,
        "v_settle_s": 3.0,
        "ss_error": 0.01,
        "swing_excess_iae_deg_s": 0.5,
        "swing_excess_vs_pid": 0.05,
    }
    assert failure_reason(ok) == ""
    assert failure_reason({**ok, "fallback": "solver"}) == "fallback"
    assert failure_reason({**ok, "v_settle_s": math.inf}) == "v_not_settled"
    assert failure_reason({**ok, "ss_error": 0.02}) == "ss_error"
    assert failure_reason({**ok, "peak_swing_deg": 80.0}) == "diverged"
    assert (
        failure_reason({**ok, "swing_excess_iae_deg_s": 5.0, "swing_excess_vs_pid": 0.5}) == "swing"
    )
    assert failure_reason({**ok, "swing_excess_vs_pid": 0.5}) == ""  # excess below 1 deg·s
    pid = {**ok, "controller": "pid", "swing_excess_iae_deg_s": 5.0, "swing_excess_vs_pid": 1.0}
    assert failure_reason(pid) == ""


def test_wilson_interval():
    lo, hi = wilson(0, 10)
    assert lo == 0.0 and 0.25 < hi < 0.35
    lo, hi = wilson(5, 10)
    assert lo < 0.5 < hi and math.isclose(lo + hi, 1.0)


# --- runs ----------------------------------------------------------------------------------


def test_report_names_the_worst_samples(reference):
    _, out = reference
    rows = read_rows(out)
    assert keys(rows) == [(s, c) for s in range(6) for c in ("lqr", "mpc", "pid")]
    report = (out / "report.md").read_text(encoding="utf-8")
    assert (out / "metrics.png").is_file() and (out / "vs_payload.length.png").is_file()
    worst = worst_samples(rows)
    assert f"swingrt campaign --rerun {out} {worst[0]['sample']}" in report
    assert "Wilson" in report and "| mpc |" in report


def test_resume_skips_finished_samples_and_never_duplicates(cli, reference, tmp_path):
    spec, ref = reference
    out = tmp_path / "out"
    shutil.copytree(ref, out)
    batches = sorted((out / "results").glob("batch-*.parquet"))
    for f in batches[1::2]:
        f.unlink()
    r = cli("campaign", spec, "--out", out, "--workers", "2")
    assert r.returncode == 0, r.stderr
    assert f"{len(batches[1::2])} samples flown, {6 - len(batches[1::2])} already done" in r.stdout
    assert rows_equal(read_rows(out), read_rows(ref))


def test_kill_9_then_rerun_matches_an_uninterrupted_run(cli, reference, tmp_path):
    spec, ref = reference
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "swingrt", "campaign", spec, "--out", out, "--workers", "1"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            if len(list((out / "results").glob("batch-*.parquet"))) >= 2:
                break
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    done = len(list((out / "results").glob("batch-*.parquet")))
    assert 1 <= done < 6, "the run ended before it could be killed"
    r = cli("campaign", spec, "--out", out, "--workers", "2")
    assert r.returncode == 0, r.stderr
    assert rows_equal(read_rows(out), read_rows(ref))
    assert not list((out / "results").glob(".*"))


def test_changed_spec_is_refused_with_the_difference(cli, reference, tmp_path):
    spec, ref = reference
    changed = tmp_path / "changed.toml"
    changed.write_text(
        spec.read_text(encoding="utf-8").replace("high = 0.5", "high = 0.6"), encoding="utf-8"
    )
    r = cli("campaign", changed, "--out", ref, "--workers", "1")
    assert r.returncode == 2
    assert "vary.payload.mass.high changed from 0.5 to 0.6" in r.stderr
    assert r.stderr.count("\n") == 1


def test_rerun_replays_one_sample_with_traces(cli, reference):
    _, out = reference
    r = cli("campaign", "--rerun", out, "3")
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("matches the dataset's row") == 3
    d = out / "rerun" / "sample-000003"
    for f in ("training.parquet", "pid.parquet", "mpc.parquet", "sample.png", "model.json"):
        assert (d / f).is_file()


def test_rerun_draws_fly_the_campaigns_flight_then_other_noise(cli, reference):
    _, out = reference
    r = cli("campaign", "--rerun", out, "3", "--draws", "3")
    assert r.returncode == 0, r.stderr
    with open(out / "rerun" / "sample-000003" / "draws.csv", encoding="utf-8") as f:
        draws = list(csv.DictReader(f))
    assert sorted({int(d["draw"]) for d in draws}) == [0, 1, 2]
    stored = {r["controller"]: r for r in read_rows(out) if r["sample"] == 3}
    excess = {}
    for ctrl, row in stored.items():
        mine = sorted((d for d in draws if d["controller"] == ctrl), key=lambda d: d["draw"])
        assert len(mine) == 3
        # Draw 0 is the campaign's own flight.
        for m in ("swing_excess_iae_deg_s", "ss_error", "v_settle_s"):
            assert float(mine[0][m]) == pytest.approx(row[m], rel=1e-6), (ctrl, m)
        n_failed = sum(bool(d["failure"]) for d in mine)
        assert f"sample 3 {ctrl:4s} fails {n_failed} of 3 noise draws" in r.stdout
        excess[ctrl] = [float(d["swing_excess_iae_deg_s"]) for d in mine]
    # The sample's swing sensor is noisy: the MPC, which reads it, flies each draw its own
    # way; PX4 PID never reads it and flies them alike.
    assert len({round(x, 9) for x in excess["mpc"]}) == 3
    assert max(excess["pid"]) - min(excess["pid"]) < 1e-9


def test_draws_are_refused_below_one_or_without_a_rerun(cli, reference):
    spec, out = reference
    for args, named in (
        (["--rerun", out, "3", "--draws", "0"], "--draws: must be >= 1 (got 0)"),
        ([spec, "--out", out, "--draws", "2"], "--draws: only with --rerun DIR INDEX"),
    ):
        r = cli("campaign", *args)
        assert r.returncode == 2
        assert named in r.stderr and r.stderr.count("\n") == 1


def test_hand_started_scheduler_gives_the_same_rows(cli, reference, tmp_path):
    spec, ref = reference
    sched_file = tmp_path / "scheduler.json"
    bin_dir = Path(sys.executable).parent
    procs = [
        subprocess.Popen(
            [
                bin_dir / "dask",
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                sched_file,
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
    ]
    try:
        deadline = time.monotonic() + 30
        while not sched_file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        import json

        address = json.loads(sched_file.read_text(encoding="utf-8"))["address"]
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        bin_dir / "dask",
                        "worker",
                        address,
                        "--nthreads",
                        "1",
                        "--nworkers",
                        "1",
                        "--host",
                        "127.0.0.1",
                        "--no-dashboard",
                    ],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    start_new_session=True,
                )
            )
        # The first two of the reference's samples (a sample's rows depend on the seed and
        # its index alone), so the scheduler's two workers fly one each.
        two = tmp_path / "two.toml"
        two.write_text(
            spec.read_text(encoding="utf-8").replace("samples = 6", "samples = 2"),
            encoding="utf-8",
        )
        out = tmp_path / "out"
        r = cli("campaign", two, "--out", out, "--scheduler", address, timeout=120)
        assert r.returncode == 0, r.stderr
        assert rows_equal(read_rows(out), [r for r in read_rows(ref) if r["sample"] < 2])
    finally:
        for p in reversed(procs):
            os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


# --- missions as the evaluation flight ------------------------------------------------------

MISSION_PLAN = {"waypoints": 2, "leg_min": 15.0, "leg_max": 25.0, "acceptance_radius": 0.3}


def _mission_study(**over) -> dict:
    base = {"axes": "ne", "training_duration": 150.0, "identify": {"twin": "off"}}
    base["mission"] = dict(MISSION_PLAN)
    return {
        "name": "m",
        "samples": 2,
        "controllers": ["pid", "mpc", "lqr"],
        "base": base,
        "vary": {"payload.length": {"dist": "uniform", "low": 0.8, "high": 1.6}},
    } | over


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ({"controllers": ["pid", "deepc", "mpc"]}, "'deepc' does not fly missions"),
        ({"base": {"mission": dict(MISSION_PLAN)}}, 'axes = "ne"'),
        ({"base": {"axes": "ne", "mission": {**MISSION_PLAN, "seed": 1}}}, "seed is the sample"),
        ({"base": {"axes": "ne", "mission": {**MISSION_PLAN, "leg_max": 5.0}}}, "mission.leg_max"),
    ],
)
def test_a_mission_study_is_refused_by_name_before_flying(change, named):
    from swingrt.campaign.spec import check_spec

    with pytest.raises(ConfigError) as err:
        check_spec(parse_spec(_mission_study(**change)))
    assert named in str(err.value) and "\n" not in str(err.value)


def test_a_mission_sample_flies_the_plan_with_px4_and_the_mpc_and_judges_it():
    from swingrt import mission as ms

    spec = parse_spec(_mission_study())
    rows, traces = fly_sample(spec.raw, 0)
    by = {r["controller"]: r for r in rows}
    assert set(by) == {"pid", "mpc", "lqr"} and not by["mpc"]["error"], by["mpc"]["error"]
    assert not by["lqr"]["error"], by["lqr"]["error"]
    for r in rows:
        assert set(ms.SUMMARY_COLUMNS) <= set(r) and "_waypoints" not in r
        assert r["failure"] == ms.mission_failure(r, judged=r["controller"] != "pid")
    # The plan is the sample's: both flew the same waypoints, each finishing it.
    plan = spec.mission(spec.draw(0), 0)
    for c in ("pid", "mpc", "lqr"):
        reached = [i for _, i, k in traces[c].meta["mission_events"] if k == "reached"]
        assert reached == list(range(len(plan)))
    assert by["pid"]["time_vs_px4"] == 1.0
    assert by["mpc"]["time_vs_px4"] == pytest.approx(by["mpc"]["total_s"] / by["pid"]["total_s"])
    # The MPC damps the legs: below half of PX4's largest swing on every leg.
    assert by["mpc"]["leg_swing_vs_px4"] < 0.5
    # Another sample draws another plan.
    assert spec.mission(spec.draw(1), 1) != plan
