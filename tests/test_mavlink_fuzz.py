"""MAVLink fault injection: ``swingrt fly`` against ``swingrt sitl`` through a
hostile loopback proxy.

The node connects to the proxy, the proxy to the vehicle; both run as real subprocesses in
real time on 127.0.0.1. Per test the proxy forwards every datagram and, seeded, adds one kind
of fault: random bytes, truncated frames and bad CRCs (both directions), valid messages with
absurd values (NaN position, 1e30 velocity, zero-norm quaternions, NaN swing, NaN/1e30
setpoints to the vehicle), replayed and reordered packets, a 10 kHz flood, a second vehicle
with another system id. Properties: no crash and no hang (every process ends within its
bound); the node either flies the mission (exit 0) or fails safe - hands back within about
one watchdog period and says why in one line (exit 2); both traces load as valid flights.

Each test is bounded (< ~20 s). Run alone with ``pytest -m realtime``.
"""

from __future__ import annotations

import random
import re
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from swingrt.io import load_flight
from swingrt.mavlink.link import mavlink

pytestmark = pytest.mark.realtime

MISSION = "duration = 3.0\n[[step]]\nt = 0\nvn = 0\n[[step]]\nt = 1.0\nvn = 1.0\n"
TS = 0.03


@pytest.fixture(scope="module")
def model_file(tmp_path_factory) -> Path:
    """A white-box model of the default payload (no search: fast)."""
    import swingrt

    d = tmp_path_factory.mktemp("model")
    tr = swingrt.simulate(duration=12.0)
    model = swingrt.identify(
        tr, method="whitebox", payload_mass=0.2, cable_length=1.0, test_span=0.0, dt=TS
    )
    path = d / "model.json"
    model.save(path)
    return path


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Proxy(threading.Thread):
    """UDP man in the middle between the node (front) and the vehicle (back)."""

    def __init__(self, vehicle_port: int, fault: str, seed: int):
        super().__init__(daemon=True)
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind(("127.0.0.1", 0))
        self.port = self.front.getsockname()[1]
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.bind(("127.0.0.1", 0))
        self.vehicle = ("127.0.0.1", vehicle_port)
        self.node: tuple[str, int] | None = None
        self.fault = fault
        self.rng = random.Random(seed)
        self.halt = threading.Event()
        self.injected = 0
        self.started = time.monotonic()
        #: Monotonic time the persistent fault started (after the node engaged).
        self.persistent_since: float | None = None
        self._seen: list[bytes] = []
        self._held: bytes | None = None
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        self._enc = {sid: mavlink.MAVLink(None, srcSystem=sid, srcComponent=1) for sid in (1, 2)}
        self._enc_node = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self._stamp = 10**8  # far in the future of the vehicle's clock: always "new"
        self._offboard_since: float | None = None

    # ------------------------------------------------------------- helpers

    def _pack(self, msg, sid: int = 1) -> bytes:
        return msg.pack(self._enc[sid])

    def _kind(self, data: bytes) -> str | None:
        try:
            msgs = self._parser.parse_buffer(data) or []
        except Exception:
            return None
        return msgs[0].get_type() if msgs else None

    def _absurd(self, kind: str | None, sid: int = 1) -> bytes | None:
        self._stamp += 1
        nan, big = float("nan"), 1e30
        r = self.rng.random()
        if kind == "LOCAL_POSITION_NED":
            vals = [nan, 0.0, -10.0, 0.0, 0.0, 0.0] if r < 0.5 else [0.0, 0.0, -10.0, big, 0, 0]
            return self._pack(mavlink.MAVLink_local_position_ned_message(self._stamp, *vals), sid)
        if kind == "ATTITUDE_QUATERNION":
            return self._pack(
                mavlink.MAVLink_attitude_quaternion_message(
                    self._stamp, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, [0.0] * 4
                ),
                sid,
            )
        if kind == "DEBUG_VECT":
            return self._pack(
                mavlink.MAVLink_debug_vect_message(b"SWING", self._stamp * 1000, nan, big, 0.0),
                sid,
            )
        return None

    def _to_vehicle_junk(self) -> bytes:
        r = self.rng.random()
        if r < 0.3:
            return bytes(self.rng.getrandbits(8) for _ in range(self.rng.randint(1, 300)))
        v = float("nan") if r < 0.6 else 1e30
        msg = mavlink.MAVLink_set_position_target_local_ned_message(
            0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0x0C3F,  # accelerations only
            0, 0, 0, 0, 0, 0, v, v, 0, 0, 0,
        )  # fmt: skip
        frame = bytearray(msg.pack(self._enc_node))
        if r > 0.8:
            frame[-1] ^= 0xFF  # bad CRC
        return bytes(frame)

    def _engaged(self) -> bool:
        """Whether the vehicle has been in OFFBOARD for 0.3 s (the node's loop runs)."""
        return self._offboard_since is not None and time.monotonic() - self._offboard_since > 0.3

    def _watch_mode(self, data: bytes) -> None:
        try:
            msgs = self._parser.parse_buffer(data) or []
        except Exception:
            return
        for m in msgs:
            if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1:
                offboard = (m.custom_mode >> 16) & 0xFF == 6
                if offboard and self._offboard_since is None:
                    self._offboard_since = time.monotonic()

    # ------------------------------------------------------------- faults

    def to_node(self, data: bytes) -> list[bytes]:
        """The datagrams the node receives instead of the vehicle's ``data``."""
        f, rng = self.fault, self.rng
        kind = self._kind(data)
        if kind == "HEARTBEAT":
            self._watch_mode(data)
        out = [data]
        if f == "garbage" and rng.random() < 0.3:
            self.injected += 1
            junk = bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 280)))
            cut = data[: rng.randint(1, max(1, len(data) - 1))]
            bad = bytearray(data)
            bad[rng.randrange(len(bad))] ^= 0xFF
            out = [junk, cut, bytes(bad), data, b"\xfd" + junk[:20]]
        elif f == "absurd" and rng.random() < 0.25:
            fake = self._absurd(kind)
            if fake is not None:
                self.injected += 1
                out = [fake]  # the good message is lost: the next one comes 10 ms later
        elif f == "absurd_persistent" and self._engaged() and kind == "LOCAL_POSITION_NED":
            if self.persistent_since is None:
                self.persistent_since = time.monotonic()
            self.injected += 1
            out = [self._absurd(kind) or data]
        elif f == "replay":
            self._seen.append(data)
            if len(self._seen) > 200:
                self._seen.pop(0)
            if rng.random() < 0.3 and len(self._seen) > 50:
                self.injected += 1
                out = [data, self._seen[rng.randrange(len(self._seen) - 40)]]  # 0.4 s+ old
            elif rng.random() < 0.3:
                self.injected += 1
                held, self._held = self._held, data  # swap with the next one: reordered
                out = [held] if held is not None else []
            elif self._held is not None:
                out = [data, self._held]
                self._held = None
        elif f == "flood" and kind == "LOCAL_POSITION_NED" and self._engaged():
            if self.persistent_since is None:
                self.persistent_since = time.monotonic()
                # 10 kHz for 0.3 s: 3000 copies of a valid message (replays of this stamp).
                self.injected += 3000
                return [data] * 3000
        elif f == "intruder" and rng.random() < 0.3:
            self.injected += 1
            hb = mavlink.MAVLink_heartbeat_message(
                mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 1, 4 << 16, 3, 3
            )
            ack = mavlink.MAVLink_command_ack_message(mavlink.MAV_CMD_DO_SET_MODE, 4)
            fake = self._absurd(kind, sid=2)
            out = [data, self._pack(hb, 2), self._pack(ack, 2)] + ([fake] if fake else [])
        return out

    def to_vehicle(self, data: bytes) -> list[bytes]:
        if self.fault in ("garbage", "absurd") and self.rng.random() < 0.3:
            self.injected += 1
            return [data, self._to_vehicle_junk()]
        return [data]

    # ------------------------------------------------------------- loop

    def run(self) -> None:
        socks = [self.front, self.back]
        while not self.halt.is_set():
            ready, _, _ = select.select(socks, [], [], 0.01)
            for s in ready:
                try:
                    data, addr = s.recvfrom(65536)
                except OSError:
                    continue
                if s is self.front:
                    self.node = addr
                    for d in self.to_vehicle(data):
                        self.back.sendto(d, self.vehicle)
                elif self.node is not None:
                    for d in self.to_node(data):
                        try:
                            self.front.sendto(d, self.node)
                        except OSError:
                            pass  # the node's socket buffer is full (flood): dropped

    def close(self) -> None:
        self.halt.set()
        self.join(2.0)
        self.front.close()
        self.back.close()


def _stop(proc: subprocess.Popen, sig=signal.SIGINT, timeout: float = 10.0) -> str:
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
        pytest.fail(f"process did not stop within {timeout} s:\n{out}")
    return out or ""


#: Simulated vehicles the proxy can stand in front of: name -> argv(port, log). Another
#: vehicle (``swingrt hil``) slots in here; every fault test then runs against it too.
VEHICLES = {
    "sitl": lambda port, log: [
        sys.executable, "-m", "swingrt", "sitl", "--listen", f"udp:127.0.0.1:{port}",
        "--log", str(log),
    ],
}  # fmt: skip


def _flight(tmp_path: Path, model: Path, fault: str, seed: int = 13, vehicle: str = "sitl"):
    vport = _free_port()
    vlog, nlog = tmp_path / "vehicle.parquet", tmp_path / "node.parquet"
    sitl = subprocess.Popen(
        VEHICLES[vehicle](vport, vlog), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    proxy = Proxy(vport, fault, seed)
    proxy.start()
    mission = tmp_path / "mission.toml"
    mission.write_text(MISSION)
    try:
        time.sleep(1.0)  # the vehicle's interpreter start
        node = subprocess.run(
            [sys.executable, "-m", "swingrt", "fly", "--connect", f"udp:127.0.0.1:{proxy.port}",
             "--model", str(model), "--mission", str(mission), "--log", str(nlog),
             "--system-id", "1", "--timeout", "8"],
            capture_output=True, text=True, timeout=30,
        )  # fmt: skip
    finally:
        proxy.close()
        vout = _stop(sitl)
    assert "Traceback" not in vout, vout
    assert "Traceback" not in node.stderr, node.stderr
    # The vehicle's trace: complete and valid whatever it was sent.
    vtr = load_flight(vlog, columns=["t", "pn", "vn", "swing_n"])
    assert len(vtr["t"]) > 100
    return node, proxy, vtr, nlog


def _node_trace(nlog: Path):
    tr = load_flight(nlog, columns=["t", "vn", "swing_n", "acc_sp_n"])
    assert np.all(np.diff(tr["t"]) > 0)
    return tr


def _failed_safe(node) -> str:
    """The node's one error line, checked to be a fail-safe hand-back within about one
    watchdog period (stale_factor × Ts = 90 ms) that says why."""
    assert node.returncode == 2, node.stdout + node.stderr
    lines = [ln for ln in node.stderr.splitlines() if ln.startswith("swingrt: error:")]
    assert len(lines) == 1, node.stderr
    line = lines[0]
    assert "control handed back" in line, line
    m = re.search(r"is (\d+) ms old \(limit (\d+) ms", line)
    if m:
        age, limit = map(float, m.groups())
        assert age <= limit + 3 * TS * 1e3, line
    return line


@pytest.mark.parametrize("fault", ["garbage", "absurd", "replay", "intruder"])
def test_node_keeps_flying_through_faults(tmp_path, model_file, fault):
    """Random bytes, truncated frames and bad CRCs (both ways; before the fix one garbage
    datagram ended the node's read of the tick and the backlog went stale), intermittent
    absurd values, replays/reordering and a second vehicle: all dropped, and the good data
    in between keeps the flight going."""
    node, proxy, _, nlog = _flight(tmp_path, model_file, fault)
    assert proxy.injected > 0
    assert node.returncode == 0, node.stdout + node.stderr
    tr = _node_trace(nlog)
    assert tr["t"][-1] > 2.5  # the whole 3 s mission was flown
    assert np.all(np.abs(tr["swing_n"]) < 0.5)


def test_node_fails_safe_on_persistently_absurd_position(tmp_path, model_file):
    node, proxy, _, nlog = _flight(tmp_path, model_file, "absurd_persistent")
    assert proxy.persistent_since is not None
    line = _failed_safe(node)
    assert "stale telemetry: LOCAL_POSITION_NED" in line and "absurd values" in line, line
    _node_trace(nlog)  # written on abort too, valid


def test_node_survives_a_10khz_flood(tmp_path, model_file):
    node, proxy, _, nlog = _flight(tmp_path, model_file, "flood")
    assert proxy.persistent_since is not None
    # Flying on, or failing safe with a reason: never a hang or a crash.
    if node.returncode != 0:
        _failed_safe(node)
    _node_trace(nlog)


class _QuietConn:
    """A connection with nothing to read and every send swallowed."""

    target_system = target_component = 1
    swingrt_bytes_read = 0

    def __init__(self):
        class _Mav:
            def __getattr__(self, name):
                return lambda *a, **k: None

        self.mav = _Mav()

    def recv_msg(self):
        return None


def test_skipped_deadlines_leave_no_nan_rows(tmp_path):
    """Regression: rows of missed deadlines stayed NaN in the node's trace, and
    ``load_flight`` refused its non-finite ``t``. They are left out now."""
    from swingrt.mavlink.offboard import OffboardSession, Watchdog

    session = OffboardSession(
        _QuietConn(), ts=0.02, watchdog=Watchdog(0.02, stale_factor=1e9, link_timeout=1e9)
    )
    session.alt_hold, session.yaw_hold = -10.0, 0.0
    session._engage = lambda: None
    session._hand_back = lambda **_: None
    tel = session.tel
    tel.pos, tel.vel, tel.swing, tel.acc_sp = [0.0] * 3, [0.0] * 3, [0.0, 0.0], [0.0] * 3
    tel.t_pos = tel.t_swing = tel.t_heartbeat = time.monotonic()

    def policy(k, t, tel, rate):
        if k == 5:
            time.sleep(0.09)  # misses about four deadlines
        return 0, (0.0, 0.0, -10.0), (0.0,) * 3, (0.0,) * 3, (0.0, 0.0)

    report = session.run(policy, 0.4)
    assert report.missed_deadlines >= 3 and report.aborted is None
    t = report.columns["t"]
    assert np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)
    assert len(t) == report.ticks
    from swingrt.io.flight import write_columns

    write_columns(report.columns, tmp_path / "node.parquet")
    tr = load_flight(tmp_path / "node.parquet", columns=["t", "vn"])
    assert len(tr["t"]) == report.ticks
