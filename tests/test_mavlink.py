"""MAVLink loopback tests: the simulated PX4 vehicle, the offboard node, and their failures.

Vehicle and node run as separate processes (this file doubles as their launcher: see
``__main__`` at the bottom) on random free ports of 127.0.0.1; every wait is bounded.
The protocol tests fly :class:`PointMassPendulum`, a test double (point mass with a
first-order acceleration lag, linear pendulum, P/PI-like position and velocity loops) that
keeps them fast and independent of the physics; the end-to-end tests fly ``swingrt sitl``
(swingrt's simulator under PX4's cascade) and ``swingrt fly`` with the core's MPC.
"""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from swingrt.errors import ConfigError, LinkError
from swingrt.mavlink import link
from swingrt.mavlink.link import (
    PX4_MAIN_MODE,
    connect,
    decode_px4_mode,
    mavlink,
    px4_custom_mode,
    wait_heartbeat,
)

# On wall time (sockets, a paced vehicle, timeouts): CI runs these after the rest, alone.
pytestmark = pytest.mark.realtime

HERE = Path(__file__).resolve()
OFFBOARD = PX4_MAIN_MODE["OFFBOARD"]


# ----------------------------------------------------------------------------- test double


class _Trace:
    def __init__(self, columns):
        self.columns = columns


class PointMassPendulum:
    """TEST DOUBLE of ``swingrt.Simulator``: per axis a point mass whose acceleration follows
    the command with a 0.1 s lag, a linear pendulum θ'' = -(g/l) θ - a/l - c θ', and PX4-like
    loops (position P 0.95 -> velocity P 1.8 -> acceleration). Not the project's physics."""

    G, L, TAU, DAMP = 9.81, 1.0, 0.1, 0.05

    def __init__(self, config=None):
        self.t = 0.0
        self.p = np.array([0.0, 0.0, -10.0])
        self.v = np.zeros(3)
        self.a = np.zeros(3)
        self.a_cmd = np.zeros(3)
        self.th = np.zeros(2)
        self.om = np.zeros(2)
        self.sp = {"n": ("pos", 0.0), "e": ("pos", 0.0), "d": ("pos", -10.0)}
        self._log = {
            k: []
            for k in (
                "t",
                "pn",
                "pe",
                "pd",
                "vn",
                "ve",
                "vd",
                "swing_n",
                "swing_e",
                "acc_sp_n",
                "acc_sp_e",
                "acc_sp_d",
            )
        }
        self._next_log = 0.0

    def set_setpoint(self, n, e, d):
        for axis, (mode, value) in (("n", n), ("e", e), ("d", d)):
            if mode not in ("pos", "vel", "acc") or not math.isfinite(value):
                raise ValueError(f"bad setpoint {axis}={mode, value}")
        self.sp = {"n": n, "e": e, "d": d}

    def _command(self):
        for i, axis in enumerate("ned"):
            mode, value = self.sp[axis]
            if mode == "pos":
                value, mode = 0.95 * (value - self.p[i]), "vel"
            if mode == "vel":
                value = 1.8 * (value - self.v[i])
            self.a_cmd[i] = max(-8.0, min(8.0, value))

    def advance(self, dt):
        n = max(1, int(round(dt / 0.001)))
        h = dt / n
        for _ in range(n):
            self._command()
            self.a += h * (self.a_cmd - self.a) / self.TAU
            alpha = -(self.G / self.L) * self.th - self.a[:2] / self.L - self.DAMP * self.om
            self.om += h * alpha
            self.th += h * self.om
            self.v += h * self.a
            self.p += h * self.v
            self.t += h
            if self.t + 1e-9 >= self._next_log:
                s = self.state()
                for k, col in self._log.items():
                    col.append(s[k])
                self._next_log += 0.01

    def state(self):
        return {
            "t": self.t, "pn": self.p[0], "pe": self.p[1], "pd": self.p[2],
            "vn": self.v[0], "ve": self.v[1], "vd": self.v[2],
            "roll": 0.0, "pitch": 0.0, "yaw": 0.0, "q0": 1.0, "q1": 0.0, "q2": 0.0, "q3": 0.0,
            "p": 0.0, "q": 0.0, "r": 0.0,
            "swing_n": self.th[0], "swing_e": self.th[1],
            "swing_rate_n": self.om[0], "swing_rate_e": self.om[1],
            "acc_sp_n": self.a_cmd[0], "acc_sp_e": self.a_cmd[1], "acc_sp_d": self.a_cmd[2],
        }  # fmt: skip

    def trace(self):
        return _Trace({k: np.array(v) for k, v in self._log.items()})


# ----------------------------------------------------------------------------- helpers


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def spawn(*args: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen(
        [sys.executable, str(HERE), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )


def stop(proc: subprocess.Popen, sig=signal.SIGTERM, timeout: float = 10.0) -> str:
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out or ""


@pytest.fixture
def vehicle(tmp_path):
    """A simulated vehicle (test double physics) on a random port; yields (url, proc)."""
    port = free_port()
    url = f"udp:127.0.0.1:{port}"
    proc = spawn("vehicle", url, str(tmp_path / "vehicle.parquet"))
    yield url, proc
    out = stop(proc)
    assert "Traceback" not in out, out


def observer(url: str):
    conn = connect(url)
    wait_heartbeat(conn, timeout=10.0)
    return conn


def fresh(conn, kind: str, timeout: float = 2.0):
    """The next ``kind`` message sent after now (older, queued ones are dropped)."""
    while conn.recv_match(blocking=False) is not None:
        pass
    return conn.recv_match(type=kind, blocking=True, timeout=timeout)


def current_mode(conn, timeout: float = 2.0) -> tuple[int, int]:
    msg = fresh(conn, "HEARTBEAT", timeout)
    assert msg is not None, "vehicle heartbeat stopped"
    return decode_px4_mode(msg.custom_mode)


def set_mode(conn, main, sub=0, timeout: float = 2.0) -> int:
    while conn.recv_match(type="COMMAND_ACK", blocking=False) is not None:
        pass  # answers to earlier requests are no answer to this one
    conn.mav.command_long_send(
        1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        main, sub, 0, 0, 0, 0,
    )  # fmt: skip
    ack = ack_for(conn, mavlink.MAV_CMD_DO_SET_MODE, timeout)
    assert ack is not None, "no ack for DO_SET_MODE"
    return ack.result


def ack_for(conn, command: int, timeout: float = 2.0):
    """The next COMMAND_ACK for ``command``; others (PX4 and the sitl ack a mode command
    twice: the second copy of an earlier answer) are skipped."""
    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=left)
        if ack is not None and ack.command == command:
            return ack
    return None


def acc_setpoint(conn, an=0.0, ae=0.0, z=-10.0, target=1):
    from swingrt.mavlink.offboard import MASK_ACC_ALT_HOLD

    conn.mav.set_position_target_local_ned_send(
        0, target, 1, mavlink.MAV_FRAME_LOCAL_NED, MASK_ACC_ALT_HOLD,
        0, 0, z, 0, 0, 0, an, ae, 0, 0, 0,
    )  # fmt: skip


# ----------------------------------------------------------------------------- unit level


def test_px4_custom_mode_encoding():
    # px4_custom_mode.h: {uint16 reserved; uint8 main_mode; uint8 sub_mode} little endian
    raw = bytes([0, 0, 4, 3])  # AUTO.LOITER
    assert px4_custom_mode(4, 3) == int.from_bytes(raw, "little") == 0x03040000
    assert decode_px4_mode(px4_custom_mode(6, 0)) == (6, 0)
    assert link.mode_name(4, 3) == "AUTO.LOITER"


def test_a_link_of_an_unknown_role_is_refused_before_any_socket_opens():
    with pytest.raises(ConfigError, match="role: must be 'node' or 'vehicle'") as err:
        link.connect("udpin:127.0.0.1:0", role="autopilot")
    assert err.value.field == "role"


def _sp(mask, x=0.0, y=0.0, z=0.0, vx=0.0, vy=0.0, vz=0.0, ax=0.0, ay=0.0, az=0.0, frame=1):
    return mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, frame, mask, x, y, z, vx, vy, vz, ax, ay, az, 0.0, 0.0
    )


def test_setpoint_type_masks_follow_px4():
    from swingrt.mavlink.offboard import MASK_ACC_ALT_HOLD, MASK_VEL_ALT_HOLD
    from swingrt.mavlink.vehicle import SetpointError, parse_setpoint

    mixed = parse_setpoint(_sp(MASK_ACC_ALT_HOLD, z=-7.0, ax=1.5, ay=-0.5))
    assert mixed == {"n": ("acc", 1.5), "e": ("acc", -0.5), "d": ("pos", -7.0)}
    acc_only = parse_setpoint(_sp(0b110000111111, ax=1.0, ay=2.0, az=-0.5))  # 3135
    assert acc_only == {"n": ("acc", 1.0), "e": ("acc", 2.0), "d": ("acc", -0.5)}
    vel = parse_setpoint(_sp(0b110111000111, vx=2.0, vy=0.0, vz=0.1))  # velocity only
    assert vel == {"n": ("vel", 2.0), "e": ("vel", 0.0), "d": ("vel", 0.1)}
    assert parse_setpoint(_sp(MASK_VEL_ALT_HOLD, z=-5, vx=1.0))["d"] == ("pos", -5.0)
    with pytest.raises(SetpointError, match="same kind"):
        parse_setpoint(_sp(0b110111000110, x=1.0, vy=1.0))  # x position, y velocity
    with pytest.raises(SetpointError, match="force"):
        parse_setpoint(_sp(MASK_ACC_ALT_HOLD | 512))
    with pytest.raises(SetpointError, match="frame"):
        parse_setpoint(_sp(MASK_ACC_ALT_HOLD, frame=8))
    with pytest.raises(SetpointError, match="not finite"):
        parse_setpoint(_sp(MASK_ACC_ALT_HOLD, ax=float("nan")))
    with pytest.raises(SetpointError, match="axis n"):
        parse_setpoint(_sp(0b110111111111))


def test_the_node_clips_at_the_mpcs_own_bound():
    """The offboard clip is the MPC's acc_max (its settings, else the core's default), not a
    second constant of the node's."""
    from swingrt import _core
    from swingrt.mavlink.offboard import command_bound

    model = _core.pendulum_model(delays=4, axes=1)
    default = _core.check_settings("mpc", None)["acc_max"]
    assert command_bound(_core.Mpc(model)) == default
    assert command_bound(_core.Mpc(model, {"acc_max": 2.5})) == 2.5
    adaptive = _core.AdaptiveMpc(model, {"acc_max": 3.0}, {"synthesis": "deferred"})
    assert command_bound(adaptive, {"acc_max": 3.0}) == 3.0
    assert command_bound(object()) == default


def test_watchdog_rules():
    from swingrt.mavlink.offboard import Telemetry, Watchdog

    wd = Watchdog(ts=0.03)
    tel = Telemetry()
    tel.t_pos = tel.t_swing = tel.t_heartbeat = 100.0
    assert wd.check_inputs(tel, 100.089) is None  # limit 3 Ts = 90 ms
    tel.t_swing = 99.909
    assert "DEBUG_VECT 'SWING' (swing sensor) is 91 ms old (limit 90 ms)" in wd.check_inputs(
        tel, 100.0
    )
    tel.t_swing, tel.t_pos = 100.0, 99.9
    assert "stale telemetry: LOCAL_POSITION_NED" in wd.check_inputs(tel, 100.0)
    tel.t_pos = tel.t_swing = 103.5  # telemetry fresh but no heartbeat for 3.5 s
    assert "dead link: no heartbeat for 3.5 s" in wd.check_inputs(tel, 103.5)
    # overrun: three consecutive ticks over Ts/2 = 15 ms; a good tick resets the count
    assert wd.check_compute(0.02) is None and wd.check_compute(0.02) is None
    assert wd.check_compute(0.001) is None
    assert wd.check_compute(0.02) is None and wd.check_compute(0.02) is None
    assert "solver overrun: 3 ticks" in wd.check_compute(0.02)
    # swing envelope: off by default, and with a limit either axis trips it
    tel.t_pos = tel.t_swing = tel.t_heartbeat = 200.0
    tel.swing = [0.0, -math.radians(40.0)]
    assert wd.check_inputs(tel, 200.0) is None
    wd = Watchdog(ts=0.03, swing_limit=math.radians(30.0))
    assert "swing 40.0° beyond the limit of 30°" in wd.check_inputs(tel, 200.0)
    tel.swing = [math.radians(29.0), 0.0]
    assert wd.check_inputs(tel, 200.0) is None


def test_mission_file(tmp_path):
    from swingrt.errors import ConfigError
    from swingrt.mavlink.offboard import Mission

    f = tmp_path / "m.toml"
    f.write_text("duration = 9\n[[step]]\nt = 0\nvn = 0\n[[step]]\nt = 1\nvn = 2\nve = -1\n")
    m = Mission.from_toml(f)
    assert m.duration == 9 and m.reference(0.99) == (0.0, 0.0) and m.reference(1.0) == (2, -1)
    f.write_text("[[step]]\nt = 0\nvn = 0\nspeed = 3\n")
    with pytest.raises(ConfigError, match=r"step\[0\]: unknown key\(s\) speed"):
        Mission.from_toml(f)
    f.write_text("[[step]]\nt = 2\n[[step]]\nt = 1\n")
    with pytest.raises(ConfigError, match="increase"):
        Mission.from_toml(f)


def test_random_step_mission_is_seeded_and_in_table_4_1_ranges():
    from swingrt.mavlink.training import random_step_mission

    a, b = random_step_mission(600, 7), random_step_mission(600, 7)
    assert a.steps == b.steps and a.steps != random_step_mission(600, 8).steps
    gaps = np.diff([s[0] for s in a.steps[1:]])
    assert np.all((gaps >= 10) & (gaps <= 25))
    assert all(0 <= s[1] <= 3 and s[2] == 0 for s in a.steps)


# ----------------------------------------------------------------------------- loopback


def test_silent_link_gives_clear_error():
    url = f"udp:127.0.0.1:{free_port()}"
    conn = connect(url)
    t0 = time.monotonic()
    with pytest.raises(LinkError, match=rf"^no heartbeat from {url} within 1 s$"):
        wait_heartbeat(conn, timeout=1.0)
    assert time.monotonic() - t0 < 2.0
    conn.close()
    with pytest.raises(LinkError, match="cannot understand link URL"):
        connect("carrier-pigeon")


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--auto"], "--auto flies a waypoint plan"),
        (["--mission", "PLAN"], "--model is required"),
        (["--mission", "PLAN", "--auto", "--model", "m.json"], "--model and --adapt do not"),
        (["--model", "m.json", "--target", "payload"], "apply to a waypoint plan"),
        (["--mission", "steps.toml", "--model", "m.json"], "m.json"),
        (["--mission", "plan.txt", "--model", "m.json"], "must end in .toml or .plan"),
        (["--model", "m.json", "--no-twin"], "--no-twin applies to --adapt"),
    ],
)
def test_fly_refuses_a_wrong_plan_request_in_one_line(tmp_path, capsys, extra, message):
    """Which flight ``fly`` makes is decided before any link is opened: a waypoint plan
    (TOML with [[waypoint]]s or .plan), velocity steps, or PX4's own mission (--auto)."""
    from swingrt.cli import main

    plan = tmp_path / "plan.toml"
    plan.write_text("speed = 3.0\n[[waypoint]]\nn = 0.0\ne = 0.0\nd = -10.0\n")
    (tmp_path / "steps.toml").write_text("[[step]]\nt = 0\nvn = 1\n")
    (tmp_path / "plan.txt").write_text("")
    args = [str(plan) if a == "PLAN" else str(tmp_path / a) if "." in a else a for a in extra]
    url = f"udp:127.0.0.1:{free_port()}"
    assert main(["fly", "--connect", url, "--timeout", "0.5", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_offboard_refused_before_stream_and_accepted_after(vehicle):
    url, _ = vehicle
    conn = observer(url)
    assert current_mode(conn) == (4, 3)  # starts in AUTO.LOITER
    assert set_mode(conn, OFFBOARD) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    t_end = time.monotonic() + 0.5
    while time.monotonic() < t_end:  # half a second is not enough
        acc_setpoint(conn)
        time.sleep(0.05)
    assert set_mode(conn, OFFBOARD) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    t_end = time.monotonic() + 0.8
    while time.monotonic() < t_end:
        acc_setpoint(conn)
        time.sleep(0.05)
    assert set_mode(conn, OFFBOARD) == mavlink.MAV_RESULT_ACCEPTED
    # North acceleration 1 m/s^2 for 1 s is obeyed (the vehicle is in OFFBOARD)
    t_end = time.monotonic() + 1.0
    while time.monotonic() < t_end:
        acc_setpoint(conn, an=1.0)
        time.sleep(0.02)
    lp = fresh(conn, "LOCAL_POSITION_NED")
    assert 0.5 < lp.vx < 1.5
    # stop streaming: COM_OF_LOSS_T = 1 s later the vehicle holds position by itself
    t_stop = time.monotonic()
    while True:
        msg = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
        if msg is not None and decode_px4_mode(msg.custom_mode) == (4, 3):
            break
        assert time.monotonic() - t_stop < 2.5, "vehicle stayed in OFFBOARD"
    assert 0.9 < time.monotonic() - t_stop < 1.6
    conn.close()


def test_garbage_unknown_messages_and_wrong_system_do_not_crash(vehicle):
    url, proc = vehicle
    conn = observer(url)
    host, port = url.split(":")[1], int(url.split(":")[2])
    rng = np.random.default_rng(1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
        for _ in range(20):
            raw.sendto(rng.integers(0, 256, 300, dtype=np.uint8).tobytes(), (host, port))
        raw.sendto(b"\xfd\x09\x00\x00\x00\xff\xbe\x60\xea\x00" + bytes(11), (host, port))
        # a stream parser (PX4's too) may hold a partial frame from the garbage: 300 zero
        # bytes (no start marker) complete any pending frame so that it fails its CRC and
        # resyncs
        raw.sendto(bytes(300), (host, port))
    time.sleep(0.1)
    # well-formed messages this vehicle does not handle
    conn.mav.param_request_read_send(1, 1, b"COM_OF_LOSS_T", -1)
    conn.mav.manual_control_send(1, 0, 0, 500, 0, 0)
    # wrong target system: must be ignored (no ack, no effect)
    conn.mav.command_long_send(42, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, OFFBOARD, 0, 0, 0, 0, 0)
    for _ in range(30):
        acc_setpoint(conn, an=3.0, target=42)
        time.sleep(0.02)
    assert conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.5) is None
    # ... so the stream of our own system has not started: OFFBOARD still refused
    assert set_mode(conn, OFFBOARD) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    # unknown command: UNSUPPORTED; vehicle alive and answering
    conn.mav.command_long_send(1, 1, 31337, 0, 0, 0, 0, 0, 0, 0, 0)
    ack = ack_for(conn, 31337)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_UNSUPPORTED
    assert current_mode(conn) == (4, 3)
    assert proc.poll() is None
    conn.close()
    out = stop(proc, signal.SIGINT)
    assert "dropped bytes that are not MAVLink" in out
    assert "ignored COMMAND_LONG for system 42" in out
    assert "ignored SET_POSITION_TARGET_LOCAL_NED for system 42" in out
    assert "ignored unsupported message MANUAL_CONTROL" in out
    # SIGINT flushed the flight trace atomically (no temporary file left behind)
    from swingrt.io import load_flight

    trace = proc.args[-1]
    assert load_flight(trace, columns=["t", "vn", "swing_n"])["t"][-1] > 2.0
    assert [p.name for p in Path(trace).parent.iterdir() if p.suffix == ".tmp"] == []


def test_wrong_system_id_is_detected(vehicle):
    url, _ = vehicle
    # Up first (the vehicle's process may take seconds to start on a loaded machine), then
    # asked for a system it is not.
    conn = observer(url)
    with pytest.raises(LinkError, match="heartbeat from system 1 .* system 7 was expected"):
        wait_heartbeat(conn, timeout=2.5, system_id=7)
    conn.close()


def write_mission(path: Path, step_at=1.0, back_at=5.0, duration=8.0) -> Path:
    path.write_text(
        f"duration = {duration}\n[[step]]\nt = 0\nvn = 0\n[[step]]\nt = {step_at}\nvn = 2\n"
        f"[[step]]\nt = {back_at}\nvn = 0\n"
    )
    return path


def test_fly_mission_with_pd_double_and_clean_handback(vehicle, tmp_path):
    from swingrt.io import load_flight

    url, sitl = vehicle
    mission = write_mission(tmp_path / "m.toml")
    node = spawn("node", url, str(mission), str(tmp_path / "node.parquet"))
    node.wait(timeout=30.0)
    out = stop(node)
    assert node.returncode == 0, out
    assert "period jitter median" in out
    tr = load_flight(tmp_path / "node.parquet", columns=["vn", "swing_n", "acc_sp_n"])
    t, vn = tr["t"], tr["vn"]
    assert np.all(np.diff(t) > 0) and abs(np.median(np.diff(t)) - 0.03) < 1e-9
    # the double follows the mission: ~2 m/s by the end of the step, ~0 at the end
    assert 1.6 < np.mean(vn[(t > 4.0) & (t < 5.0)]) < 2.3
    assert abs(np.mean(vn[t > 7.5])) < 0.4
    assert np.max(np.abs(tr["swing_n"])) > 0.01  # the step swung the payload ...
    time.sleep(1.5)  # past the vehicle's offboard-loss timeout
    obs = observer(url)
    assert current_mode(obs) == (4, 3)  # ... and the node handed back to hold
    obs.close()
    # by its own request, not by the vehicle's offboard-loss failsafe (the vehicle acks a
    # mode command twice, as PX4 does: the OFFBOARD request's second ack is no answer)
    vehicle_log = stop(sitl)
    assert "AUTO.LOITER (requested)" in vehicle_log, vehicle_log
    assert "no setpoint for" not in vehicle_log, vehicle_log


def test_a_velocity_output_method_flies_px4s_velocity_loop_over_mavlink(vehicle, tmp_path):
    """A method that commands PX4's velocity loop (the ZVD input shaper, undamped mode of
    ω = π rad/s: impulses 1/4, 1/2, 1/4 a half period, 1 s, apart) goes out as velocity
    setpoints: the node's command is the shaped staircase and the vehicle follows it."""
    from swingrt import _core
    from swingrt.io import load_flight
    from swingrt.mavlink.offboard import Mission, fly

    url, _ = vehicle
    shaper = _core.Controller.shaper(math.pi, 0.0, 1)
    assert shaper.output == "velocity"
    mission = Mission.from_toml(write_mission(tmp_path / "m.toml", 1.0, 7.0, 8.0))
    conn = connect(url)
    try:
        fly(conn, shaper, ts=shaper.period, axes=1, mission=mission,
            log_path=tmp_path / "node.parquet")  # fmt: skip
    finally:
        conn.close()
    tr = load_flight(tmp_path / "node.parquet", columns=["vn", "vel_sp_n"])
    t, sp, vn = tr["t"], tr["vel_sp_n"], tr["vn"]
    for lo, hi, want in ((1.15, 1.85, 0.5), (2.15, 2.85, 1.5), (3.15, 6.9, 2.0)):
        held = sp[(t > lo) & (t < hi)]
        assert np.allclose(held, want, atol=1e-9), (lo, hi, np.unique(held))
    assert 1.8 < np.mean(vn[(t > 5.5) & (t < 7.0)]) < 2.2


def test_failsafe_when_node_is_killed(vehicle, tmp_path):
    url, _ = vehicle
    obs = observer(url)
    mission = write_mission(tmp_path / "m.toml", duration=60.0)
    node = spawn("node", url, str(mission), str(tmp_path / "node.parquet"))
    t0 = time.monotonic()
    while True:
        msg = obs.recv_match(type="HEARTBEAT", blocking=True, timeout=1.0)
        if msg is not None and decode_px4_mode(msg.custom_mode)[0] == OFFBOARD:
            break
        assert time.monotonic() - t0 < 15, "node never engaged OFFBOARD: " + stop(node)
    time.sleep(1.0)
    node.kill()
    t_kill = time.monotonic()
    node.wait(timeout=5)
    node.stdout.close()
    while True:
        msg = obs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
        if msg is not None and decode_px4_mode(msg.custom_mode) == (4, 3):
            break
        assert time.monotonic() - t_kill < 3.0, "vehicle stayed in OFFBOARD"
    assert time.monotonic() - t_kill < 1.5
    obs.close()


def test_overrun_hands_back_and_exits_nonzero(vehicle, tmp_path):
    url, _ = vehicle
    mission = write_mission(tmp_path / "m.toml", duration=30.0)
    node = spawn("node", url, str(mission), str(tmp_path / "node.parquet"), "--slow")
    try:
        node.wait(timeout=30.0)
    finally:
        out = stop(node)
    assert node.returncode == 2, out
    last = out.strip().splitlines()[-1]
    assert last.startswith("swingrt: error: solver overrun: 3 ticks over budget"), out
    assert "control handed back" in last
    assert (tmp_path / "node.parquet").exists()  # trace written even on abort
    obs = observer(url)
    assert current_mode(obs) == (4, 3)
    obs.close()


def test_collect_over_mavlink_records_px4_velocity_control(vehicle, tmp_path):
    from swingrt.io import load_flight
    from swingrt.mavlink import collect_over_mavlink, random_step_mission

    url, _ = vehicle
    out = tmp_path / "train.parquet"
    report = collect_over_mavlink(url, duration=6.0, seed=3, out=out)
    assert report.aborted is None and report.ticks >= 550  # 100 Hz for 6 s
    need = ["t", "vn", "swing_n", "acc_sp_n", "vel_sp_n", "pd"]
    tr = load_flight(out, columns=need)
    step = random_step_mission(6.0, 3).steps[1]
    assert step[0] == 2.0 and 0 <= step[1] <= 3
    t = tr["t"]
    np.testing.assert_array_equal(tr["vel_sp_n"], np.where(t >= 2.0 - 1e-9, step[1], 0.0))
    # acc_sp is PX4's (the double's) velocity-loop output, streamed back: 1.8 (v_sp - v)
    late = t > 3.0
    np.testing.assert_allclose(
        tr["acc_sp_n"][late], 1.8 * (tr["vel_sp_n"] - tr["vn"])[late], atol=0.15
    )
    assert abs(tr["vn"][-1] - step[1]) < 0.3  # PX4 velocity control tracked the step


# ----------------------------------------------------------------------------- real physics


def pure_simulation_iae(ctrl, axes: int, mission, ts: float) -> float:
    """Swing IAE (North) of ``ctrl`` flying ``mission`` on the simulator directly at Ts,
    with the same state construction as the node (backward-difference swing rate)."""
    import swingrt

    # As ``swingrt sitl``: hold the start point until commanded.
    sc = swingrt.resolve_scenario(None).with_overrides({"setpoints": []})
    sim = swingrt.Simulator(sc)
    pd0 = sim.state()["pd"]
    sim.advance(2.0)  # the node's handshake: hover before engaging
    state = np.zeros((axes, 3))
    prev = np.zeros(2)
    iae = 0.0
    for k in range(int(round(mission.duration / ts)) + 1):
        s = sim.state()
        sw = np.array([s["swing_n"], s["swing_e"]])
        rate = (sw - prev) / ts if k else np.zeros(2)
        prev = sw
        state[0] = (s["vn"], sw[0], rate[0])
        if axes == 2:
            state[1] = (s["ve"], sw[1], rate[1])
        if k == 0:
            ctrl.reset(state.copy(), np.zeros(axes))
        a = np.clip(ctrl.step(state, np.array(mission.reference(k * ts)[:axes])), -5, 5)
        ae = a[1] if axes == 2 else -s["ve"]
        sim.set_setpoint(n=("acc", a[0]), e=("acc", ae), d=("pos", pd0))
        sim.advance(ts)
        iae += abs(sw[0]) * ts
    return iae


def sitl_flight(tmp_path, node_cmd) -> dict:
    """Run ``swingrt sitl`` on a free port and ``node_cmd(url)`` against it; the node's log."""
    from swingrt.io import load_flight

    url = f"udp:127.0.0.1:{free_port()}"
    sitl = subprocess.Popen(
        [sys.executable, "-m", "swingrt", "sitl", "--listen", url],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        res = subprocess.run(node_cmd(url), timeout=90, capture_output=True, text=True)
    finally:
        out = stop(sitl, signal.SIGINT)
    assert res.returncode == 0, res.stdout + res.stderr + out
    assert "Traceback" not in out, out
    return load_flight(tmp_path / "fly.parquet", columns=["t", "vn", "swing_n"])


def test_sitl_loop_matches_pure_simulation(tmp_path):
    """The MAVLink loop (``swingrt sitl`` + node, separate processes, real time) flies a
    controller like the same controller stepped on the simulator directly: swing IAE within
    20 %. The controller here is the PD stand-in; the MPC version is the next test."""
    from swingrt.mavlink.offboard import Mission
    from swingrt.testing import PDSwingDamper

    mission = write_mission(tmp_path / "m.toml", step_at=1.0, back_at=6.0, duration=10.0)
    iae_sim = pure_simulation_iae(PDSwingDamper(), 2, Mission.from_toml(mission), 0.03)
    log = tmp_path / "fly.parquet"
    tr = sitl_flight(tmp_path, lambda url: [sys.executable, str(HERE), "node", url,
                                            str(mission), str(log)])  # fmt: skip
    iae_fly = float(np.sum(np.abs(tr["swing_n"])) * 0.03)
    assert iae_sim > 0.05  # the step does swing the payload
    assert abs(iae_fly - iae_sim) <= 0.2 * iae_sim, (iae_fly, iae_sim)
    assert 1.6 < np.mean(tr["vn"][(tr["t"] > 5.0) & (tr["t"] < 6.0)]) < 2.3


def test_fly_against_sitl_damps_swing_like_pure_simulation(tmp_path):
    """The default mission flown by ``swingrt fly`` against ``swingrt sitl`` damps the swing
    within 20 % of the same MPC flown in pure simulation (swing IAE)."""
    from swingrt.mavlink.offboard import Mission, load_controller

    train = tmp_path / "train.parquet"
    model = tmp_path / "model.json"
    for args in (
        # Both axes stepped: a two-axis model needs both inputs to vary (sysid refuses one
        # whose East response would be fitted to rounding noise).
        ["collect", "--duration", "240", "--axes", "ne", "-o", str(train)],
        ["identify", str(train), "--axes", "ne", "-o", str(model)],
    ):
        subprocess.run([sys.executable, "-m", "swingrt", *args], check=True, timeout=120)
    ctrl, ts, axes = load_controller(model)
    iae_sim = pure_simulation_iae(ctrl, axes, Mission.default(), ts)
    log = tmp_path / "fly.parquet"
    tr = sitl_flight(
        tmp_path,
        lambda url: [sys.executable, "-m", "swingrt", "fly", "--connect", url, "--model",
                     str(model), "--log", str(log)],
    )  # fmt: skip
    iae_fly = float(np.sum(np.abs(tr["swing_n"])) * ts)
    assert abs(iae_fly - iae_sim) <= 0.2 * iae_sim, (iae_fly, iae_sim)


def fly_sensor_chain(tmp_path, source: str, look) -> tuple:
    """The chain a swing source flies over MAVLink: collect a 240 s training flight with
    ``[sensors] swing = source``, identify, serve it with ``swingrt sitl`` (physics logged),
    call ``look(conn)`` on an observer link, then ``swingrt fly`` the model; returns (what
    ``look`` saw, the scenario file)."""
    scenario = tmp_path / f"{source}.toml"
    scenario.write_text(f'[sensors]\nswing = "{source}"\n')
    train, model = tmp_path / "train.parquet", tmp_path / "model.json"
    for args, dest in (
        (["collect", str(scenario), "--duration", "240", "--swing-source", source], train),
        (["identify", str(train)], model),
    ):
        subprocess.run(
            [sys.executable, "-m", "swingrt", *args, "-o", str(dest)],
            check=True, timeout=120, capture_output=True,
        )  # fmt: skip
    url = f"udp:127.0.0.1:{free_port()}"
    sitl = subprocess.Popen(
        [sys.executable, "-m", "swingrt", "sitl", str(scenario), "--listen", url, "--log",
         str(tmp_path / "physics.parquet")],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        conn = observer(url)
        seen = look(conn)
        conn.close()
        res = subprocess.run(
            [sys.executable, "-m", "swingrt", "fly", "--connect", url, "--model", str(model),
             "--log", str(tmp_path / "fly.parquet")],
            timeout=90, capture_output=True, text=True,
        )  # fmt: skip
    finally:
        out = stop(sitl, signal.SIGINT)
    assert res.returncode == 0, res.stdout + res.stderr + out
    return seen, scenario


def test_fly_without_a_swing_sensor_on_the_imu_that_sitl_streams(tmp_path):
    """Nothing on the cable: ``swingrt sitl`` streams HIGHRES_IMU (the simulator's IMU) and
    the true swing only as DEBUG_VECT "SWTRUE"; ``swingrt fly`` on a model identified on the
    IMU asks for HIGHRES_IMU, flies on the swing it estimates from it (the same estimate as
    the model's estimator makes from the simulator's IMU), and logs the truth beside it; the
    true swing stays well under PX4 PID's. (The estimate is not the truth in steady flight:
    the drag the model's estimator keeps reads as a lean of a few degrees, which the model
    carries.)"""
    from swingrt import _core
    from swingrt.io.flight import Trace
    from swingrt.sim import simulate
    from swingrt.sysid import model_columns

    seen, imu = fly_sensor_chain(
        tmp_path,
        "imu",
        lambda conn: {k: fresh(conn, k, timeout=3.0) for k in ("HIGHRES_IMU", "DEBUG_VECT")},
    )
    hr, dv = seen["HIGHRES_IMU"], seen["DEBUG_VECT"]
    assert hr is not None and dv is not None
    # Hovering: the accelerometer reads about -g on the body z axis.
    assert hr.zacc == pytest.approx(-9.81, abs=0.5) and hr.fields_updated == 0b111111
    name = dv.name if isinstance(dv.name, str) else dv.name.decode("ascii")
    assert name.rstrip("\0") == "SWTRUE"
    node = Trace.from_parquet(tmp_path / "fly.parquet")
    physics = Trace.from_parquet(tmp_path / "physics.parquet")
    # The node's estimate from HIGHRES_IMU against the model's estimator (its scale and the
    # drag it removes) run on the simulator's own IMU, lined up on the vehicle's clock.
    model = _core.LinearModel.load(tmp_path / "model.json")
    at = np.asarray(node["px4_time_s"])
    sim_est = np.interp(at, physics.t, np.asarray(model_columns(model, physics)["swing_n"]))
    est, truth = np.asarray(node["swing_n"]), np.asarray(node["swing_true_n"])
    assert np.corrcoef(est, sim_est)[0, 1] > 0.95
    assert np.degrees(np.median(np.abs(est - sim_est))) < 0.5
    pid = simulate(str(imu), duration=14.0)
    assert np.abs(truth).max() < 0.5 * np.abs(np.asarray(pid["swing_true_n"])).max()


def test_the_cable_sensor_on_the_airframe_is_composed_with_the_attitude():
    """DEBUG_VECT "SWBODY" carries the sensor's two ADC counts; the node calibrates them and
    turns them into the world-frame swing with the vehicle's attitude. Closed form: pitched
    by θ with the cable at β in the body x-z plane, the world angle North is β + θ."""
    from swingrt.errors import ConfigError
    from swingrt.mavlink.offboard import Telemetry

    mav = mavlink.MAVLink(None)
    sensor = {"zero": [2000.0, 2100.0], "gain": [2200.0, 2500.0]}
    tel = Telemetry(body=sensor)
    theta, beta = 0.05, 0.1
    q = (math.cos(theta / 2), 0.0, math.sin(theta / 2), 0.0)
    tel.update(mav.attitude_quaternion_encode(1, *q, 0.0, 0.0, 0.0), 0.0)
    counts = (2000.0 + 2200.0 * beta, 2100.0)
    tel.update(mav.debug_vect_encode(b"SWBODY", 10, *counts, 0.0), 0.1)
    assert tel.swing == pytest.approx([beta + theta, 0.0], abs=1e-9)
    assert tel.t_swing == 0.1
    # A world-frame sensor's message is not what this node flies on, and absurd counts drop.
    tel.update(mav.debug_vect_encode(b"SWING", 20, 0.3, 0.3, 0.0), 0.2)
    tel.update(mav.debug_vect_encode(b"SWBODY", 30, 1e12, 0.0, 0.0), 0.3)
    assert tel.swing == pytest.approx([beta + theta, 0.0], abs=1e-9)
    assert "absurd" in tel.rejected["DEBUG_VECT"]
    with pytest.raises(ConfigError, match="gains"):
        Telemetry(body={"gains": [1.0, 1.0]})


def test_fly_on_the_cable_sensor_on_the_airframe_over_mavlink(tmp_path):
    """The thesis's rig over MAVLink: ``swingrt sitl`` with the cable sensor on the airframe
    sends its counts as DEBUG_VECT "SWBODY" (and the truth as "SWTRUE"); ``swingrt fly`` on
    a model identified on that sensor reads the model's sensor settings, composes the counts
    with the attitude, and flies: the composed swing is the true one within the ADC's step,
    and the true swing stays well under PX4 PID's."""
    from swingrt.io.flight import Trace
    from swingrt.sim import simulate

    def names_of(conn) -> set:
        # Every DEBUG_VECT of a second (the sensor's and the truth's go out together).
        names = set()
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            dv = conn.recv_match(type="DEBUG_VECT", blocking=True, timeout=0.5)
            if dv is not None:
                name = dv.name if isinstance(dv.name, str) else dv.name.decode("ascii")
                names.add(name.rstrip("\0"))
        return names

    names, body = fly_sensor_chain(tmp_path, "body", names_of)
    assert names == {"SWBODY", "SWTRUE"}, names
    node = Trace.from_parquet(tmp_path / "fly.parquet")
    assert node.meta["swing_source"] == "body"
    composed, truth = np.asarray(node["swing_n"]), np.asarray(node["swing_true_n"])
    ok = np.isfinite(composed) & np.isfinite(truth)
    # One ADC count is 1/2400 rad; the sensor's noise and the attitude's lag add a little.
    assert np.degrees(np.median(np.abs(composed[ok] - truth[ok]))) < 0.2
    assert np.corrcoef(composed[ok], truth[ok])[0, 1] > 0.99
    pid = simulate(str(body), duration=14.0)
    assert np.abs(truth).max() < 0.5 * np.abs(np.asarray(pid["swing_true_n"])).max()


def test_fly_a_waypoint_plan_against_sitl_like_pure_simulation(tmp_path):
    """``swingrt fly --mission PLAN`` (the position MPC with preview over MAVLink, against
    ``swingrt sitl`` in real time) flies a waypoint plan as the same MPC on the same legs
    does in pure simulation: every item reached, each leg's largest swing within 25 % and
    the plan's time within 1.5 s; the per-waypoint rows are printed."""
    from swingrt import mission as ms
    from swingrt.io.flight import Trace
    from swingrt.sysid import identify

    plan = tmp_path / "plan.toml"
    plan.write_text(
        'name = "ell"\nspeed = 4.0\nacceptance_radius = 0.3\nhold = 3.0\n'
        "[[waypoint]]\nn = 0.0\ne = 0.0\nd = -10.0\nhold = 1.0\n"
        "[[waypoint]]\nn = 12.0\ne = 0.0\nd = -10.0\n"
        "[[waypoint]]\nn = 12.0\ne = 8.0\nd = -10.0\n"
    )
    payload = {"payload": {"mass": 0.3, "length": 1.5}}
    (tmp_path / "payload.toml").write_text("[payload]\nmass = 0.3\nlength = 1.5\n")
    m = ms.load(str(plan))
    # The model: the white-box pendulum identified from PX4's mission mode flying the plan.
    trace, _ = ms.fly(m, "px4", payload)
    model = identify(trace, axes="ne", method="whitebox", payload_mass=0.3, test_span=8.0)
    model.save(str(tmp_path / "model.json"))
    sim_trace, sim_events = ms.fly(m, ms.shaped_legs(model), payload, model=model)
    sim_rows = ms.waypoint_report(m, sim_trace, sim_events)
    sim_total = max(t for t, _, k in sim_events if k == "completed")

    url = f"udp:127.0.0.1:{free_port()}"
    physics = tmp_path / "physics.parquet"
    sitl = subprocess.Popen(
        [sys.executable, "-m", "swingrt", "sitl", str(tmp_path / "payload.toml"),
         "--listen", url, "--log", str(physics)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        res = subprocess.run(
            [sys.executable, "-m", "swingrt", "fly", "--connect", url, "--model",
             str(tmp_path / "model.json"), "--mission", str(plan), "--log",
             str(tmp_path / "fly.parquet")],
            timeout=120, capture_output=True, text=True,
        )  # fmt: skip
    finally:
        out = stop(sitl, signal.SIGINT)
    assert res.returncode == 0, res.stdout + res.stderr + out
    assert "Traceback" not in out, out
    assert "mpc: mission finished at" in res.stdout
    node = Trace.from_parquet(tmp_path / "fly.parquet")
    # Judged alike: both paths by PX4's navigator rule from the mission's start (the
    # node's first tick; the simulator's "started" event), true swing where there is one.
    t0 = next(t for t, _, k in sim_events if k == "started")
    keep = sim_trace["t"] >= t0
    sim_path = {c: v[keep] for c, v in sim_trace.items()}
    sim_path["t"] = sim_path["t"] - t0
    sim_judged = ms.waypoint_report(m, sim_path, ms.replay_events(m, sim_path))
    fly_events = ms.replay_events(m, node)
    fly_rows = ms.waypoint_report(m, node, fly_events)
    assert [r["item"] for r in fly_rows] == [0.0, 1.0, 2.0]
    for a, b in zip(sim_judged[1:], fly_rows[1:], strict=True):
        assert b["leg_swing_max_deg"] == pytest.approx(a["leg_swing_max_deg"], rel=0.25)
    fly_total = max(t for t, _, k in fly_events if k == "completed")
    assert fly_total == pytest.approx(sim_total - t0, abs=1.5)
    assert [r["item"] for r in sim_rows] == [0.0, 1.0, 2.0]


# ----------------------------------------------------------------------------- launcher


def _main(argv: list[str]) -> int:
    import logging

    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s", stream=sys.stderr)
    import faulthandler

    faulthandler.register(signal.SIGUSR1)
    if argv[0] == "vehicle":
        from swingrt.mavlink.vehicle import run_vehicle

        run_vehicle(PointMassPendulum(), argv[1], log_path=argv[2])
        return 0
    if argv[0] == "node":
        from swingrt.errors import SwingrtError
        from swingrt.mavlink.offboard import Mission, fly
        from swingrt.testing import PDSwingDamper

        ctrl = PDSwingDamper()
        if "--slow" in argv:
            inner = ctrl.step

            def slow_step(state, ref):
                time.sleep(0.02)  # > Ts/2 = 15 ms budget
                return inner(state, ref)

            ctrl.step = slow_step
        conn = connect(argv[1])
        try:
            report = fly(conn, ctrl, ts=0.03, mission=Mission.from_toml(argv[2]), log_path=argv[3])
            print(f"fly: {report.summary()}")
        except SwingrtError as exc:
            print(f"swingrt: error: {exc}", file=sys.stderr)
            return 2
        return 0
    raise SystemExit(f"unknown role {argv[0]}")


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
