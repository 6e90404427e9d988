"""Nothing lost: SIGKILL at seeded random moments, repeatedly.

For ``collect``, ``identify``, ``experiment``, ``sitl --log``, ``hil --log`` and
``fly --log``: every output file is afterwards either the complete old file (left from an
earlier complete run), a complete new file, or absent - never a torn one (every writer goes through
``swingrt.io.atomic`` or the binding's ``write_atomic``). Kill moments are drawn over the
command's whole run, and for the two MAVLink commands also just after the SIGINT that makes
them write their log, so the kill lands inside the write.

``KILL_TARGETS`` is the hook for further commands (``campaign`` adds its resume check there):
a target is a name, a command line builder and a validator of its outputs.

Run alone with ``pytest -m kill``.
"""

from __future__ import annotations

import random
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from swingrt.errors import SwingrtError
from swingrt.io import load_flight

pytestmark = pytest.mark.kill

KILLS = 4  # per command
SEED = 13

TINY_EXPERIMENT = """\
name = "tiny"
description = "kill test: short training and step"
axes = "n"
controllers = ["pid", "lqr", "mpc"]
step = { t = 1.0, vn = 1.0 }
duration = 4.0
training_duration = 80.0

[identify]
search = false
delays = 4
test_span = 20.0
"""


def _swingrt(*args: str) -> list[str]:
    return [sys.executable, "-m", "swingrt", *args]


def _valid_output(path: Path) -> None:
    """Raise unless ``path`` is a complete file of its kind."""
    suffix = path.suffix
    if suffix in (".parquet", ".csv"):
        load_flight(path)
    elif suffix == ".json":
        from swingrt.sysid import LinearModel

        LinearModel.load(path)
    elif suffix == ".png":
        data = path.read_bytes()
        assert data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(b"IEND\xaeB`\x82"), path
    elif suffix == ".md":
        assert path.read_text().endswith("\n"), path
    else:
        raise AssertionError(f"no validator for {path}")


def _check_outputs(out_dir: Path, old: dict[str, bytes]) -> tuple[int, int, int]:
    """Every output is old, complete new, or absent; returns (old, new, absent) counts and
    ignores the hidden temporaries a killed writer leaves behind (never the real name)."""
    counts = [0, 0, 0]
    names = set(old) | {p.name for p in out_dir.iterdir() if not p.name.startswith(".")}
    for name in names:
        p = out_dir / name
        if not p.exists():
            counts[2] += 1
        elif name in old and p.read_bytes() == old[name]:
            counts[0] += 1
        else:
            try:
                _valid_output(p)
            except (SwingrtError, AssertionError, OSError, ValueError) as exc:
                pytest.fail(f"{p} is torn after SIGKILL: {exc}")
            counts[1] += 1
    return counts[0], counts[1], counts[2]


@dataclass
class KillTarget:
    """A command to kill: ``argv(tmp)`` builds its command line writing into ``tmp``;
    ``runtime``: how long a serving command runs before its SIGINT [s]; ``interrupt`` sends
    SIGINT first (the command writes its output on the way out) and kills during that
    write. Other commands are killed at a seeded moment of their measured run time."""

    name: str
    argv: Callable[[Path, dict], list[str]]
    runtime: float
    interrupt: bool = False


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict:
    """Shared inputs: a training flight, a model, the tiny experiment, a mission."""
    import swingrt

    d = tmp_path_factory.mktemp("inputs")
    flight = d / "train.parquet"
    swingrt.collect(duration=60.0).save(flight)
    model = swingrt.identify(
        swingrt.simulate(duration=12.0),
        method="whitebox",
        payload_mass=0.2,
        cable_length=1.0,
        test_span=0.0,
        dt=0.03,
    )
    model.save(d / "model.json")
    (d / "tiny.toml").write_text(TINY_EXPERIMENT)
    (d / "mission.toml").write_text("duration = 2.0\n[[step]]\nt = 0\nvn = 0\n")
    return {
        "seed": "0",  # the kill runs use other seeds, so a new output differs from the old
        "flight": str(flight),
        "model": str(d / "model.json"),
        "experiment": str(d / "tiny.toml"),
        "mission": str(d / "mission.toml"),
    }


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


KILL_TARGETS: list[KillTarget] = [
    KillTarget(
        "collect",
        lambda out, inp: _swingrt(
            "collect", "--duration", "120", "--seed", inp["seed"], "-o", str(out / "c.parquet")
        ),
        runtime=3.0,
    ),
    KillTarget(
        "identify",
        lambda out, inp: _swingrt(
            "identify", inp["flight"], "--test-span", "10", "-o", str(out / "m.json")
        ),
        runtime=3.0,
    ),
    KillTarget(
        "experiment",
        lambda out, inp: _swingrt(
            "experiment", inp["experiment"], "--seed", inp["seed"], "--out", str(out)
        ),
        runtime=6.0,
    ),
    KillTarget(
        "sitl",
        lambda out, inp: _swingrt(
            "sitl", "--listen", f"udp:127.0.0.1:{_free_port()}", "--log", str(out / "v.parquet")
        ),
        runtime=3.0,
        interrupt=True,
    ),
    KillTarget(
        "hil",
        lambda out, inp: _swingrt(
            "hil",
            "--connect",
            f"tcpin:127.0.0.1:{_free_port()}",
            "--swing-link",
            f"udpout:127.0.0.1:{_free_port()}",
            "--speed",
            "5",
            "--seed",
            inp["seed"],
            "--log",
            str(out / "h.parquet"),
        ),
        runtime=3.0,
        interrupt=True,
    ),
]


def _run_complete(target: KillTarget, out: Path, inputs: dict, timeout: float = 120.0) -> float:
    """One uninterrupted run (SIGINT after ``runtime`` for the serving commands); returns
    its wall time [s]."""
    t0 = time.monotonic()
    proc = subprocess.Popen(
        target.argv(out, inputs), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    if target.interrupt:
        time.sleep(target.runtime)
        proc.send_signal(signal.SIGINT)
    text, _ = proc.communicate(timeout=timeout)
    assert proc.returncode == 0, text
    return time.monotonic() - t0


def _kill_loop(target: KillTarget, tmp_path: Path, inputs: dict) -> list[tuple[int, int, int]]:
    out = tmp_path / "out"
    out.mkdir()
    took = _run_complete(target, out, inputs)  # the "old" complete outputs
    old = {p.name: p.read_bytes() for p in out.iterdir() if not p.name.startswith(".")}
    assert old, f"{target.name} wrote nothing"
    rng = random.Random(f"{SEED}-{target.name}")
    results = []
    for i in range(KILLS):
        proc = subprocess.Popen(
            target.argv(out, {**inputs, "seed": str(i + 1)}),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        if target.interrupt:
            time.sleep(rng.uniform(1.0, target.runtime))
            proc.send_signal(signal.SIGINT)
            time.sleep(rng.uniform(0.0, 0.08))  # inside the write on the way out
        else:
            # Over the second half of a run and just past its end: the writes are there.
            time.sleep(rng.uniform(0.5, 1.05) * took)
        proc.kill()
        proc.wait(timeout=10)
        results.append(_check_outputs(out, old))
    # Shown with -s: how the kills landed (outputs old / new / absent after each kill).
    print(f"{target.name}: (old, new, absent) after each kill: {results}")
    return results


@pytest.mark.parametrize("target", KILL_TARGETS, ids=[t.name for t in KILL_TARGETS])
def test_sigkill_leaves_old_new_or_nothing(tmp_path, inputs, target):
    results = _kill_loop(target, tmp_path, inputs)
    assert len(results) == KILLS


def test_sigkill_fly_log(tmp_path, inputs):
    """``fly --log`` killed during its flight or while writing the log on the way out."""
    port = _free_port()
    sitl = subprocess.Popen(
        _swingrt("sitl", "--listen", f"udp:127.0.0.1:{port}"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    target = KillTarget(
        "fly",
        lambda out, inp: _swingrt(
            "fly",
            "--connect",
            f"udp:127.0.0.1:{port}",
            "--model",
            inp["model"],
            "--mission",
            inp["mission"],
            "--log",
            str(out / "f.parquet"),
            "--timeout",
            "8",
        ),  # fmt: skip
        runtime=6.0,
    )
    try:
        time.sleep(1.0)
        out = tmp_path / "out"
        out.mkdir()
        _run_complete(target, out, inputs)
        old = {p.name: p.read_bytes() for p in out.iterdir() if not p.name.startswith(".")}
        assert old == {"f.parquet": old["f.parquet"]}
        rng = random.Random(f"{SEED}-fly")
        for _ in range(KILLS):
            proc = subprocess.Popen(
                target.argv(out, inputs), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
            )
            # The flight ends (and the log is written) about 4-5 s in: kill around there.
            time.sleep(rng.uniform(2.0, 6.0))
            proc.kill()
            proc.wait(timeout=10)
            _check_outputs(out, old)
            time.sleep(1.5)  # the vehicle's offboard-loss failsafe returns it to hold
    finally:
        sitl.send_signal(signal.SIGINT)
        try:
            sitl.wait(timeout=10)
        except subprocess.TimeoutExpired:
            sitl.kill()
            sitl.wait()
