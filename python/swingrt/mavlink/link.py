"""MAVLink connections (pymavlink ``mavutil``) with the project's URL rules and timeouts.

URLs (the same strings pymavlink takes, with one rule made explicit per role):

- ``udp:HOST:PORT``: the *vehicle* (``swingrt sitl --listen``) binds HOST:PORT and answers
  every peer that talks to it; the *node* (``swingrt fly --connect``) sends to HOST:PORT
  (its own heartbeat makes the vehicle learn its address).
- ``udpin:HOST:PORT`` / ``udpout:HOST:PORT``: listen / send explicitly, for either role.
  A real PX4 SITL pushes its onboard link to port 14540, so a node talks to it with
  ``--connect udpin:0.0.0.0:14540``.
- ``serial:DEVICE:BAUD`` or ``DEVICE:BAUD`` (e.g. ``/dev/ttyTHS1:921600``): a serial port to
  the flight controller's TELEM port.

MAVLink 2 and the ``common`` dialect are used throughout (PX4 speaks MAVLink 2).
"""

from __future__ import annotations

import os
import time

os.environ.setdefault("MAVLINK20", "1")  # must precede pymavlink's dialect loading

from pymavlink import mavutil  # noqa: E402

from swingrt.errors import ConfigError, LinkError  # noqa: E402
from swingrt.io.ulog import BODY_VECT_NAME  # noqa: E402

__all__ = [
    "BODY_NAME",
    "SWING_NAME",
    "TRUTH_NAME",
    "mavlink",
    "PX4_MAIN_MODE",
    "PX4_SUB_MODE_AUTO",
    "px4_custom_mode",
    "decode_px4_mode",
    "mode_name",
    "connect",
    "wait_heartbeat",
    "send_heartbeat",
]

#: The generated MAVLink module (messages, enums) of the common dialect, MAVLink 2.
mavlink = mavutil.mavlink

#: PX4 main modes (PX4-Autopilot src/modules/commander/px4_custom_mode.h).
#: DEBUG_VECT name of the swing sensor's reading (x = N, y = E [rad]), which PX4 publishes,
#: streams to the offboard computer and logs, and the controller flies on.
SWING_NAME = "SWING"
#: DEBUG_VECT name of a cable sensor on the airframe's reading (x, y = its two ADC channels
#: [counts], thesis 6.1.2): the node calibrates it and composes it with the attitude into the
#: world-frame swing by the model's sensor settings (:func:`swingrt._core.body_swing`).
BODY_NAME = BODY_VECT_NAME
#: DEBUG_VECT name of a simulator's true swing (``swingrt hil`` without a swing sensor): the
#: offboard node logs it as ``swing_true_*`` for the flight's metrics, never flies on it.
TRUTH_NAME = "SWTRUE"

PX4_MAIN_MODE = {
    "MANUAL": 1,
    "ALTCTL": 2,
    "POSCTL": 3,
    "AUTO": 4,
    "ACRO": 5,
    "OFFBOARD": 6,
    "STABILIZED": 7,
}
#: PX4 sub modes of the AUTO main mode (same header).
PX4_SUB_MODE_AUTO = {
    "READY": 1,
    "TAKEOFF": 2,
    "LOITER": 3,
    "MISSION": 4,
    "RTL": 5,
    "LAND": 6,
}


def px4_custom_mode(main: int, sub: int = 0) -> int:
    """HEARTBEAT/SET_MODE ``custom_mode`` as PX4 encodes it.

    PX4's ``union px4_custom_mode`` is ``{uint16 reserved; uint8 main_mode; uint8 sub_mode}``
    over a little-endian uint32, i.e. ``(main << 16) | (sub << 24)``.
    """
    return ((main & 0xFF) << 16) | ((sub & 0xFF) << 24)


def decode_px4_mode(custom_mode: int) -> tuple[int, int]:
    """(main, sub) of a PX4 ``custom_mode`` (inverse of :func:`px4_custom_mode`)."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


def mode_name(main: int, sub: int = 0) -> str:
    """Human name of a PX4 mode, e.g. ``OFFBOARD`` or ``AUTO.LOITER``."""
    mains = {v: k for k, v in PX4_MAIN_MODE.items()}
    name = mains.get(main, f"MODE{main}")
    if main == PX4_MAIN_MODE["AUTO"]:
        subs = {v: k for k, v in PX4_SUB_MODE_AUTO.items()}
        return f"AUTO.{subs.get(sub, sub)}"
    return name


class _MultiPeerUDP(mavutil.mavudp):
    """A listening UDP endpoint that serves every peer, like a PX4 mavlink instance.

    pymavlink's own multi-client write stops at the first failing ``sendto`` and, with a
    timeout, drops peers that merely listen. Here each peer is sent to on its own, and a peer
    is dropped only after ``peer_timeout`` s without a single message from it (MAVLink peers
    send a HEARTBEAT every second).
    """

    peer_timeout = 30.0

    def write(self, buf):
        now = time.time()
        for addr in list(self.clients):
            alive = self.clients_last_alive.get(addr, now)
            if len(self.clients) > 1 and now - alive > self.peer_timeout:
                self.clients.discard(addr)
                self.clients_last_alive.pop(addr, None)
                continue
            try:
                self.port.sendto(buf, addr)
            except OSError:
                pass  # that peer is gone or its buffer is full; the others still get theirs


def _device(url: str, role: str) -> tuple[str, dict]:
    """pymavlink device string and options for ``url`` in ``role`` ('vehicle' or 'node')."""
    if url.startswith("udp:"):
        rest = url[len("udp:") :]
        return ("udpin:" if role == "vehicle" else "udpout:") + rest, {}
    if url.startswith(("udpin:", "udpout:", "tcp:", "tcpin:")):
        return url, {}
    if url.startswith("serial:"):
        url = url[len("serial:") :]
    dev, sep, baud = url.rpartition(":")
    if sep and baud.isdigit() and dev:
        return dev, {"baud": int(baud)}
    if url.startswith("/dev/") or url.upper().startswith("COM"):
        return url, {"baud": 57600}
    raise LinkError(
        f"cannot understand link URL '{url}' (use udp:HOST:PORT, udpin:, udpout: or "
        "serial:DEVICE:BAUD)"
    )


def connect(
    url: str,
    *,
    role: str = "node",
    system_id: int = 245,
    component_id: int = 191,
):
    """Open a MAVLink connection; raise :class:`LinkError` with one line if it cannot open.

    ``role`` chooses what a bare ``udp:`` URL means (module doc). The default ids are those of
    an onboard computer (component MAV_COMP_ID_ONBOARD_COMPUTER = 191).
    """
    if role not in ("node", "vehicle"):
        raise ConfigError(f"role: must be 'node' or 'vehicle', not {role!r}")
    device, opts = _device(url, role)
    try:
        if device.startswith("udpin:"):
            mavutil.set_dialect("common")
            conn = _MultiPeerUDP(
                device[len("udpin:") :],
                input=True,
                source_system=system_id,
                source_component=component_id,
            )
            conn.swingrt_url = url
            _track_reads(conn)
            return conn
        conn = mavutil.mavlink_connection(
            device,
            source_system=system_id,
            source_component=component_id,
            dialect="common",
            robust_parsing=True,
            udp_timeout=5 if role == "vehicle" else 0,
            **opts,
        )
    except (OSError, ValueError) as exc:
        raise LinkError(f"cannot open {url}: {exc}") from None
    conn.swingrt_url = url
    _track_reads(conn)
    return conn


def _track_reads(conn) -> None:
    """Record how many bytes each read returned (``conn.swingrt_bytes_read``), so that a
    reader can tell "nothing arrived" from "a datagram arrived that held no message" (pymavlink
    returns None for both); on UDP, drop a partial frame left by an earlier datagram when a
    new one arrives: a frame never spans datagrams, and a truncated one that declares a long
    payload would otherwise swallow the good datagrams after it."""
    inner = conn.recv
    udp = isinstance(conn, mavutil.mavudp)

    def recv(n=None):
        data = inner() if n is None else inner(n)
        conn.swingrt_bytes_read = len(data)
        if data and udp:
            mav = conn.mav
            if 0 < mav.buf_len() < mav.expected_length:
                mav.buf = bytearray()
                mav.buf_index = 0
                mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        return data

    conn.swingrt_bytes_read = 0
    conn.recv = recv


def send_heartbeat(conn, *, onboard: bool = True) -> None:
    """Send the heartbeat of an onboard controller (no autopilot)."""
    conn.mav.heartbeat_send(
        mavlink.MAV_TYPE_ONBOARD_CONTROLLER if onboard else mavlink.MAV_TYPE_GCS,
        mavlink.MAV_AUTOPILOT_INVALID,
        0,
        0,
        mavlink.MAV_STATE_ACTIVE,
    )


def wait_heartbeat(conn, *, timeout: float = 5.0, system_id: int | None = None):
    """Wait for an autopilot's HEARTBEAT; return it.

    Sends our own heartbeat once a second meanwhile (a UDP vehicle learns our address from
    it). Heartbeats of non-autopilots (ground stations, other onboard computers) are skipped.
    With ``system_id``, an autopilot with another id gives a :class:`LinkError` naming both.
    After ``timeout`` seconds of silence: ``LinkError("no heartbeat from URL within T s")``.
    """
    url = getattr(conn, "swingrt_url", str(getattr(conn, "address", "link")))
    deadline = time.monotonic() + timeout
    next_beat = 0.0
    others: set[int] = set()
    while True:
        now = time.monotonic()
        if now >= next_beat:
            send_heartbeat(conn)
            next_beat = now + 1.0
        remaining = deadline - now
        if remaining <= 0:
            break
        msg = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=min(remaining, 0.2))
        if msg is None:
            continue
        if msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID or msg.type in (
            mavlink.MAV_TYPE_GCS,
            mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
        ):
            continue
        sysid = msg.get_srcSystem()
        if system_id is not None and sysid != system_id:
            others.add(sysid)
            continue
        conn.target_system = sysid
        conn.target_component = msg.get_srcComponent()
        return msg
    if others:
        ids = ", ".join(str(s) for s in sorted(others))
        raise LinkError(
            f"heartbeat from system {ids} on {url}, but system {system_id} was expected"
        )
    raise LinkError(f"no heartbeat from {url} within {timeout:g} s")
