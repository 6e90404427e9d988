"""Serve swingrt's plant to a PX4 flight controller over PX4's simulator interface.

The loop of one lockstep step (PX4's simulator_mavlink contract):

1. the plant's sensors at the current time go out as HIL_SENSOR (every step), HIL_GPS (when
   a fix is due) and HIL_STATE_QUATERNION (ground truth, with the magnetometer frames);
2. the swing sensor goes to PX4 as DEBUG_VECT "SWING" over a PX4 MAVLink link (the GCS
   link of SITL, or the same serial link on a Pixhawk in HITL), so PX4 publishes it, streams
   it to the offboard computer and logs it, as on the real vehicle; with no sensor on the
   cable (swing source ``imu``) no "SWING" goes out, and the true swing goes as DEBUG_VECT
   "SWTRUE", which the offboard node logs for the metrics and never flies on;
3. once PX4 has answered a first HIL_ACTUATOR_CONTROLS, the plant advances one step only
   after PX4's motor commands for the last step arrived (PX4's clock is the sensor time, so
   it never starves and never runs ahead);
4. the loop is paced to wall time / ``speed`` (the offboard node runs on wall time).

With ``takeoff`` the server also arms PX4 and takes off to the scenario's start altitude over
the GCS link, and calls ``on_ready`` once the vehicle holds there; the scenario's payload
events (``[[payload.events]]``: a winch, a drop) then count from that moment.
"""

from __future__ import annotations

import logging
import math
import select
import time
from dataclasses import dataclass, field

import numpy as np

from swingrt._core import GRAVITY
from swingrt.errors import FlightAbort, LinkError
from swingrt.io.flight import Trace
from swingrt.mavlink.link import (
    BODY_NAME,
    PX4_MAIN_MODE,
    PX4_SUB_MODE_AUTO,
    SWING_NAME,
    TRUTH_NAME,
    connect,
    decode_px4_mode,
    mavlink,
)

__all__ = ["HilServer", "HilReport"]

log = logging.getLogger("swingrt.hil")

#: Wall seconds of silence from PX4 (no motor commands at all) before the link counts as dead.
ACTUATOR_TIMEOUT = 10.0
#: Wall seconds to wait for the answer to one step: a frame lost on a serial link would
#: otherwise stall both sides for ever (each waiting for the other); after this the step is
#: taken with the last motor commands and counted as unanswered.
STEP_ANSWER_TIMEOUT = 0.5
#: Wall seconds to wait for PX4 to connect to the simulator port.
CONNECT_TIMEOUT = 60.0
#: Wall seconds to wait for PX4 to arm (its preflight checks need the estimator converged).
ARM_TIMEOUT = 90.0
#: Wall seconds for the take-off climb.
CLIMB_TIMEOUT = 90.0


_PHASE_TEXT = {
    "arm": "arming",
    "takeoff": "taking off",
    "climb": "climbing",
    "done": "holding at take-off altitude",
}


@dataclass
class HilReport:
    """What one HIL session did, with the real-time figures of the loop."""

    steps: int = 0
    lockstep_steps: int = 0
    sim_seconds: float = 0.0
    wall_seconds: float = 0.0
    late_steps: int = 0
    px4_latency_ms: dict = field(default_factory=dict)
    gps_fixes: int = 0
    swing_messages: int = 0
    statustext: list = field(default_factory=list)
    time_usec_monotonic: bool = True
    unanswered_steps: int = 0
    rejected_controls: int = 0

    @property
    def speed(self) -> float:
        """Simulated seconds per wall second achieved."""
        return self.sim_seconds / self.wall_seconds if self.wall_seconds > 0 else math.nan

    def summary(self) -> str:
        """One line for the console."""
        lat = self.px4_latency_ms
        return (
            f"{self.sim_seconds:.1f} s simulated in {self.wall_seconds:.1f} s wall "
            f"(×{self.speed:.2f}), {self.lockstep_steps} lockstep steps, PX4 answered in "
            f"{lat.get('median', math.nan):.2f} ms median / {lat.get('p99', math.nan):.2f} ms "
            f"p99, {self.late_steps} steps behind wall time, {self.gps_fixes} GPS fixes, "
            f"{self.swing_messages} swing messages, {self.unanswered_steps} unanswered steps, "
            f"{self.rejected_controls} rejected motor commands"
        )


class HilServer:
    """The HIL loop around a :class:`swingrt._core.HilPlant` (module doc)."""

    def __init__(
        self,
        plant,
        sim_url: str,
        *,
        gcs_url: str | None = None,
        speed: float = 1.0,
        swing_rate: float = 100.0,
        takeoff_altitude: float | None = None,
        on_ready=None,
        px4=None,
    ):
        if not (0 < speed < math.inf):
            raise LinkError(f"speed must be a positive number, not {speed}")
        self.plant = plant
        self.speed = float(speed)
        self.sim = connect(sim_url, role="vehicle", system_id=1, component_id=51)
        self.gcs = (
            connect(gcs_url, role="node", system_id=255, component_id=190) if gcs_url else self.sim
        )
        dt = plant.step_dt
        self.swing_every = max(1, round(1.0 / (swing_rate * dt)))
        self.takeoff_altitude = takeoff_altitude
        self.on_ready = on_ready
        self.px4 = px4
        self.report = HilReport()
        self._latency: list[float] = []
        self._armed = False
        self._mode: tuple[int, int] | None = None
        self._px4_sysid: int | None = None
        self._phase = "wait" if takeoff_altitude is not None else "done"
        self._phase_since = time.monotonic()
        self._next_try = 0.0
        self._next_beat = 0.0
        self._last_time_usec = 0
        self._height = 0.0
        self._motors = [0.0] * 4
        self.ready = False

    # ------------------------------------------------------------------ messages out

    def _send_sensors(self, f: dict, k: int) -> None:
        mav = self.sim.mav
        t = f["time_usec"]
        if t <= self._last_time_usec:
            self.report.time_usec_monotonic = False
        self._last_time_usec = t
        a, g, m = f["accel"], f["gyro"], f["mag"]
        mav.hil_sensor_send(
            t, a[0], a[1], a[2], g[0], g[1], g[2], m[0], m[1], m[2],
            f["abs_pressure"], 0.0, f["pressure_alt"], f["temperature"],
            f["fields_updated"], 0,
        )  # fmt: skip
        gps = f["gps"]
        if gps is not None:
            vn, ve, vd = gps["vel_ned"]
            mav.hil_gps_send(
                t, 3, gps["lat"], gps["lon"], gps["alt"], gps["eph"], gps["epv"],
                gps["vel"], vn, ve, vd, gps["cog"], gps["satellites"],
            )  # fmt: skip
            self.report.gps_fixes += 1
            q = f["attitude"]
            vel = f["velocity"]
            acc = f["acceleration"]
            mav.hil_state_quaternion_send(
                t, q, g[0], g[1], g[2], gps["lat"], gps["lon"], gps["alt"],
                *(int(np.clip(round(x * 100), -32767, 32767)) for x in vel),
                0, 0,
                *(int(np.clip(round(x / GRAVITY * 1000), -32767, 32767)) for x in acc),
            )  # fmt: skip
        if k % self.swing_every == 0:
            sn, se = f["swing"]
            cx, cy = f["adc"]
            if math.isfinite(cx) and math.isfinite(cy):
                # A cable sensor on the airframe: its raw counts, as the flight controller's
                # ADC reads them (calibrated and composed with the attitude by the reader).
                # Alone: PX4 keeps the newest debug_vect and streams that, so a truth sent
                # beside it would hide it (the truth is in the physics log).
                self.gcs.mav.debug_vect_send(BODY_NAME.encode(), t, cx, cy, 0.0)
                self.report.swing_messages += 1
            elif math.isfinite(sn) and math.isfinite(se):
                self.gcs.mav.debug_vect_send(SWING_NAME.encode(), t, sn, se, 0.0)
                self.report.swing_messages += 1
            else:
                # No sensor on the cable: nothing for PX4 to publish. The true swing goes
                # under another name, for the flight's metrics only (the node never flies
                # on it).
                tn, te = f["swing_true"]
                self.gcs.mav.debug_vect_send(TRUTH_NAME.encode(), t, tn, te, 0.0)

    # ------------------------------------------------------------------ messages in

    def _read_actuators(self, timeout: float):
        """The next HIL_ACTUATOR_CONTROLS within ``timeout`` wall s, or None."""
        deadline = time.monotonic() + timeout
        while True:
            msg = self.sim.recv_msg()
            if msg is not None:
                if msg.get_type() == "HIL_ACTUATOR_CONTROLS":
                    return msg
                if self.gcs is self.sim:
                    self._on_gcs(msg)
                continue
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            fd = getattr(self.sim, "fd", None)
            if fd is None:
                time.sleep(min(remaining, 0.001))
            else:
                select.select([fd], [], [], min(remaining, 0.05))

    def _newest_actuators(self, msg):
        """``msg`` or the newest HIL_ACTUATOR_CONTROLS already waiting behind it."""
        while (later := self._read_actuators(0.0)) is not None:
            msg = later
        return msg

    def _poll_gcs(self) -> None:
        if self.gcs is self.sim:
            return
        for _ in range(50):
            try:
                msg = self.gcs.recv_msg()
            except Exception:  # noqa: BLE001 - garbage on the GCS link is dropped
                continue
            if msg is None:
                break
            self._on_gcs(msg)

    def _on_gcs(self, msg) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT" and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID:
            self._px4_sysid = msg.get_srcSystem()
            self.gcs.target_system = self._px4_sysid
            self.gcs.target_component = msg.get_srcComponent()
            self._armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            self._mode = decode_px4_mode(msg.custom_mode)
        elif kind == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
            self.report.statustext.append(text.strip("\x00"))
            log.info("PX4: %s", text.strip("\x00"))

    def _take_controls(self, msg) -> None:
        """PX4's motor commands; zero while disarmed. A command that is not a finite number
        is refused (the last good one stays): the plant is physics, not an input validator
        for whatever arrives on the link."""
        if not msg.mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
            self._motors = [0.0] * 4
            return
        motors = [float(x) for x in msg.controls[:4]]
        if all(math.isfinite(m) for m in motors):
            self._motors = motors
            return
        if self.report.rejected_controls == 0:
            log.warning("hil: refused non-finite motor commands %s (kept the last ones)", motors)
        self.report.rejected_controls += 1

    # ------------------------------------------------------------------ take-off

    def _command(self, command: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self.gcs.mav.command_long_send(self._px4_sysid or 1, 1, command, 0, *p)

    def _takeoff_step(self) -> None:
        now = time.monotonic()
        if now >= self._next_beat:
            self.gcs.mav.heartbeat_send(
                mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE
            )
            self._next_beat = now + 1.0
        if self._phase == "done":
            return
        elapsed = now - self._phase_since
        last = self.report.statustext[-1] if self.report.statustext else "no message"
        if self._phase == "wait":
            if self._px4_sysid is not None:
                self._enter("arm")
            elif elapsed > CONNECT_TIMEOUT:
                raise LinkError(
                    f"no heartbeat from PX4 on its GCS link within {CONNECT_TIMEOUT:g} s"
                )
        elif self._phase == "arm":
            if self._armed:
                self._enter("takeoff")
            elif elapsed > ARM_TIMEOUT:
                raise FlightAbort(f"PX4 did not arm within {ARM_TIMEOUT:g} s (last: {last})")
            elif now >= self._next_try:
                self._command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
                self._next_try = now + 2.0
        elif self._phase == "takeoff":
            takeoff = (PX4_MAIN_MODE["AUTO"], PX4_SUB_MODE_AUTO["TAKEOFF"])
            if self._mode == takeoff or self.plant.payload_lifted:
                self._enter("climb")
            elif not self._armed and elapsed > 3.0:
                self._enter("arm")  # PX4 disarmed again before the take-off command took
            elif now >= self._next_try:
                nan = math.nan
                self._command(mavlink.MAV_CMD_NAV_TAKEOFF, nan, 0, 0, nan, nan, nan, nan)
                self._next_try = now + 1.0
        elif self._phase == "climb":
            assert self.takeoff_altitude is not None
            loiter = (PX4_MAIN_MODE["AUTO"], PX4_SUB_MODE_AUTO["LOITER"])
            if self._mode == loiter and self._height >= 0.9 * self.takeoff_altitude:
                self._enter("done")
                # A take-off's boot and climb take an unknown time: the payload changes
                # (a winch, a drop) count from the hold.
                self.plant.count_payload_events_from(self.plant.t)
                self.ready = True
                if self.on_ready is not None:
                    self.on_ready(self)
            elif elapsed > CLIMB_TIMEOUT:
                raise FlightAbort(
                    f"take-off to {self.takeoff_altitude:g} m not done in {CLIMB_TIMEOUT:g} s "
                    f"(height {self._height:.1f} m, last: {last})"
                )

    def _enter(self, phase: str) -> None:
        log.info("hil: %s", _PHASE_TEXT.get(phase, phase))
        self._phase = phase
        self._phase_since = time.monotonic()
        self._next_try = 0.0

    # ------------------------------------------------------------------ the loop

    def run(self, duration: float | None = None, stop=None) -> HilReport:
        """Serve until ``duration`` simulated s, ``stop.is_set()`` or PX4 exits."""
        plant = self.plant
        dt = plant.step_dt
        lockstep = False
        t_wall0 = time.perf_counter()
        t_sim0 = plant.t
        k = 0
        stopping_since: float | None = None
        last_answer = time.monotonic()
        self._height = 0.0
        try:
            while True:
                if stopping_since is None and (
                    (duration is not None and plant.t - t_sim0 >= duration)
                    or (stop is not None and stop.is_set())
                ):
                    if self.px4 is None or not self.px4.alive():
                        break
                    self.px4.request_stop()  # PX4 needs its clock to shut down cleanly
                    stopping_since = time.monotonic()
                if self.px4 is not None and not self.px4.alive():
                    if stopping_since is None:
                        raise LinkError(f"PX4 exited during the flight: {self.px4.output_tail()}")
                    break
                if stopping_since is not None and time.monotonic() - stopping_since > 10.0:
                    break
                f = plant.sensors()
                self._height = -f["position"][2]
                c0 = time.perf_counter()
                self._send_sensors(f, k)
                if lockstep:
                    msg = self._read_actuators(STEP_ANSWER_TIMEOUT)
                    if msg is None:
                        if stopping_since is not None:
                            break
                        self.report.unanswered_steps += 1
                        if time.monotonic() - last_answer > ACTUATOR_TIMEOUT:
                            raise LinkError(
                                f"PX4 sent no HIL_ACTUATOR_CONTROLS for {ACTUATOR_TIMEOUT:g} s "
                                f"at t = {plant.t:.2f} s"
                            )
                    else:
                        last_answer = time.monotonic()
                        self._latency.append(time.perf_counter() - c0)
                        self.report.lockstep_steps += 1
                else:
                    msg = self._read_actuators(0.0)
                    if msg is not None:
                        lockstep = True
                        last_answer = time.monotonic()
                        log.info("hil: PX4 connected, lockstep from t = %.2f s", plant.t)
                    elif plant.t - t_sim0 > CONNECT_TIMEOUT * self.speed:
                        tail = self.px4.output_tail() if self.px4 is not None else ""
                        raise LinkError(
                            f"PX4 did not connect to the simulator port within "
                            f"{CONNECT_TIMEOUT:g} s{': ' + tail if tail else ''}"
                        )
                if msg is not None:
                    # Answers to sensor frames sent before lockstep began (or a doubled
                    # answer) would otherwise queue up and delay every later step's motors
                    # by the queue's length: fly on the newest.
                    msg = self._newest_actuators(msg)
                    self._take_controls(msg)
                plant.step(self._motors)
                k += 1
                self._poll_gcs()
                if stopping_since is None:
                    self._takeoff_step()
                target = t_wall0 + (plant.t - t_sim0) / self.speed
                now = time.perf_counter()
                if target > now:
                    time.sleep(target - now)
                elif now - target > dt:
                    self.report.late_steps += 1
        finally:
            self.report.steps = k
            self.report.sim_seconds = plant.t - t_sim0
            self.report.wall_seconds = time.perf_counter() - t_wall0
            if self._latency:
                ms = np.asarray(self._latency) * 1e3
                self.report.px4_latency_ms = {
                    "median": float(np.median(ms)),
                    "p99": float(np.percentile(ms, 99)),
                    "max": float(ms.max()),
                }
        return self.report

    def trace(self) -> Trace:
        """The physics trace logged so far (taken out of the plant)."""
        return Trace(self.plant.take_trace(), {"source": "hil"})

    def close(self) -> None:
        """Close the links."""
        self.sim.close()
        if self.gcs is not self.sim:
            self.gcs.close()
