"""``swingrt hil`` without PX4: the plant's sensor contract, the PX4 parameters, the CLI's
one-line refusals, and the lockstep loop against a scripted flight controller (the real PX4
is in tests/test_px4.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

# The lockstep loop runs on wall time against a scripted flight controller: CI runs these after
# the rest, alone.
pytestmark = pytest.mark.realtime


def test_hil_refuses_bad_arguments_in_one_line(tmp_path):
    import subprocess
    import sys

    for args in (["--speed", "0"], ["--px4", str(tmp_path)], ["--instance", "-1"]):
        r = subprocess.run(
            [sys.executable, "-m", "swingrt", "hil", *args],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert r.returncode == 2, (args, r.stderr)
        assert len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert "Traceback" not in r.stderr


def test_px4_params_match_the_simulated_geometry():
    from swingrt._core import Scenario
    from swingrt.hil import px4_parameters

    sc = Scenario.builtin("hover")
    p = px4_parameters(sc)
    arm = 0.11 / math.sqrt(2)
    assert p["CA_ROTOR0_PX"] == pytest.approx(arm, abs=1e-6)
    assert p["CA_ROTOR1_PY"] == pytest.approx(-arm, abs=1e-6)
    assert p["CA_ROTOR2_KM"] == pytest.approx(-0.007997)
    assert p["MPC_THR_HOVER"] == pytest.approx(sc.hover_thrust(), abs=1e-4)
    assert p["SDLOG_PROFILE"] & 32


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_lockstep_loop_against_a_scripted_flight_controller():
    """The server's side of the lockstep contract, message by message: one HIL_SENSOR per
    step with a strictly increasing clock, a step only after the controls came back, GPS at
    10 Hz, and the plant responds to the motors it is given."""
    import threading

    from swingrt._core import HilPlant, Scenario
    from swingrt.hil import HilServer
    from swingrt.mavlink.link import connect, mavlink

    sc = Scenario.builtin("hover").with_overrides({"setpoints": [], "payload": {"kind": "none"}})
    port = _free_port()
    server = HilServer(HilPlant(sc), f"tcpin:127.0.0.1:{port}", gcs_url=None, speed=20.0)
    seen: list[int] = []
    gps = [0]
    done = threading.Event()
    climb = 0.6  # above the hover command: the vehicle must leave the ground

    def flight_controller():
        conn = connect(f"tcp:127.0.0.1:{port}", system_id=1, component_id=1)
        try:
            while not done.is_set():
                msg = conn.recv_match(type=["HIL_SENSOR", "HIL_GPS"], blocking=True, timeout=1)
                if msg is None:
                    continue
                if msg.get_type() == "HIL_GPS":
                    gps[0] += 1
                    continue
                seen.append(msg.time_usec)
                conn.mav.hil_actuator_controls_send(
                    msg.time_usec,
                    [climb] * 4 + [0.0] * 12,
                    mavlink.MAV_MODE_FLAG_SAFETY_ARMED,
                    0,
                )
        finally:
            conn.close()

    fc = threading.Thread(target=flight_controller, daemon=True)
    fc.start()
    report = server.run(duration=2.0)
    done.set()
    fc.join(timeout=10)
    server.close()
    times = list(seen)
    assert all(b > a for a, b in zip(times, times[1:], strict=False))
    steps = [b - a for a, b in zip(times, times[1:], strict=False)]
    assert set(steps) == {4000}, "one sensor message per 4 ms lockstep step"
    assert report.time_usec_monotonic
    assert report.lockstep_steps >= 480
    assert 18 <= gps[0] <= 22  # 10 Hz over ~2 s
    tr = server.trace()
    assert tr["pd"][-1] < -0.5, "motors above hover did not lift the vehicle"
    assert tr["motor_1"][-1] == pytest.approx(climb)


def test_hil_plant_rejects_bad_settings_and_commands():
    from swingrt._core import HilPlant, Scenario
    from swingrt.errors import ConfigError, SimulationError

    sc = Scenario.builtin("hover")
    with pytest.raises(ConfigError, match="hil.gps_rate"):
        HilPlant(sc, {"gps_rate": 0.0})
    with pytest.raises(ConfigError, match="hil.bogus"):
        HilPlant(sc, {"bogus": 1})
    plant = HilPlant(sc)
    with pytest.raises(SimulationError, match="motor 3"):
        plant.step([0.5, 0.5, math.inf, 0.5])


@pytest.mark.parametrize(
    "fault", ["bytes", "bad_crc", "truncated", "nan", "huge", "flood", "replay", "silent"]
)
def test_hostile_flight_controller_neither_crashes_nor_hangs_the_server(fault):
    """A flight controller that sends garbage, broken frames, absurd motor commands, floods,
    replays or stops answering: the server keeps stepping (a lost answer costs one step of
    stale commands), refuses non-finite commands, and its trace stays physical."""
    import random
    import threading

    from swingrt._core import HilPlant, Scenario
    from swingrt.hil import HilServer
    from swingrt.mavlink.link import connect, mavlink

    sc = Scenario.builtin("hover").with_overrides({"setpoints": []})
    port = _free_port()
    server = HilServer(HilPlant(sc), f"tcpin:127.0.0.1:{port}", gcs_url=None, speed=20.0)
    done = threading.Event()
    rng = random.Random(f"hil-{fault}")
    good = 0.3

    def controls(conn, t, value):
        conn.mav.hil_actuator_controls_send(
            t, [value] * 4 + [0.0] * 12, mavlink.MAV_MODE_FLAG_SAFETY_ARMED, 0
        )

    def flight_controller():
        conn = connect(f"tcp:127.0.0.1:{port}", system_id=1, component_id=1)
        sock = conn.port
        last = None
        k = 0
        try:
            while not done.is_set():
                msg = conn.recv_match(type="HIL_SENSOR", blocking=True, timeout=1)
                if msg is None:
                    continue
                k += 1
                t = msg.time_usec
                # A lost answer costs the server 0.5 s of waiting: only a few of those.
                unanswered = fault in ("bad_crc", "truncated", "silent")
                hostile = k % 7 == 0 and (not unanswered or k < 30)
                if not hostile:
                    controls(conn, t, good)
                    continue
                if fault == "bytes":
                    sock.sendall(bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 300))))
                    controls(conn, t, good)
                elif fault in ("bad_crc", "truncated"):
                    frame = bytearray(
                        mavlink.MAVLink_hil_actuator_controls_message(
                            t, [good] * 16, mavlink.MAV_MODE_FLAG_SAFETY_ARMED, 0
                        ).pack(conn.mav)
                    )
                    if fault == "bad_crc":
                        frame[-1] ^= 0xFF
                    else:
                        frame = frame[: rng.randint(1, len(frame) - 1)]
                    sock.sendall(bytes(frame))  # no valid answer to this step
                elif fault == "nan":
                    controls(conn, t, math.nan)
                elif fault == "huge":
                    controls(conn, t, 1e30)
                elif fault == "flood":
                    for _ in range(300):
                        conn.mav.heartbeat_send(2, 12, 0, 0, 0)
                    controls(conn, t, good)
                elif fault == "replay":
                    if last is not None:
                        sock.sendall(last)
                    controls(conn, t, good)
                elif fault != "silent":  # silent: this step goes unanswered
                    controls(conn, t, good)
                last = bytes(
                    mavlink.MAVLink_hil_actuator_controls_message(
                        t, [good] * 16, mavlink.MAV_MODE_FLAG_SAFETY_ARMED, 0
                    ).pack(conn.mav)
                )
        finally:
            conn.close()

    fc = threading.Thread(target=flight_controller, daemon=True)
    fc.start()
    report = server.run(duration=1.5)
    done.set()
    fc.join(timeout=10)
    server.close()
    assert report.time_usec_monotonic
    assert report.steps >= 370  # 1.5 s at 4 ms, nothing stalled for good
    tr = server.trace()
    for c in ("pn", "pe", "pd", "vn", "vd", "roll", "pitch"):
        assert np.all(np.isfinite(tr[c])), c
    motors = np.stack([tr[f"motor_{i}"] for i in range(1, 5)])
    assert np.all((motors >= 0.0) & (motors <= 1.0))
    if fault == "nan":
        assert report.rejected_controls > 0
    if fault in ("bad_crc", "truncated", "silent"):
        assert report.unanswered_steps > 0
