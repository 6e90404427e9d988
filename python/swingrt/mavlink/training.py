"""Training-data collection over MAVLink (``swingrt collect --connect URL``).

Flies the thesis's random velocity-step mission (table 4.1: step values uniform in
[0, 3] m/s, held for intervals uniform in [10, 25] s, seeded) under PX4's *own* velocity
controller (SET_POSITION_TARGET_LOCAL_NED with :data:`MASK_VEL_ALT_HOLD`: North/East
velocity, altitude by position), and records what identification needs at the loop rate:
the vehicle state, the swing sensor, and PX4's acceleration setpoint (the identification
input, from POSITION_TARGET_LOCAL_NED ``afx afy afz``).
"""

from __future__ import annotations

import math

from swingrt.errors import ConfigError
from swingrt.mavlink.link import connect
from swingrt.mavlink.offboard import (
    MASK_VEL_ALT_HOLD,
    Mission,
    OffboardSession,
    Watchdog,
    _finish,
)
from swingrt.scenario import Scenario

__all__ = ["random_step_mission", "collect_over_mavlink", "fly_velocity_mission"]


def random_step_mission(
    duration: float,
    seed: int,
    *,
    v_range: tuple[float, float] = (0.0, 3.0),
    interval_range: tuple[float, float] = (10.0, 25.0),
    axes: str = "n",
) -> Mission:
    """Table 4.1 schedule: each interval U(interval_range) s holds a step U(v_range) m/s
    (North; with ``axes="ne"`` an independent East step too), from the seeded generator of
    the simulator's training flight, so one seed flies one mission in simulation and over
    MAVLink."""
    if not (isinstance(duration, (int, float)) and duration > 0 and math.isfinite(duration)):
        raise ConfigError(f"duration: must be positive, not {duration}", field="duration")
    steps_cfg = {
        "axes": axes,
        "v_min": float(v_range[0]),
        "v_max": float(v_range[1]),
        "interval_min": float(interval_range[0]),
        "interval_max": float(interval_range[1]),
    }
    sc = Scenario.builtin("training").with_overrides(
        {"duration": float(duration), "seed": int(seed), "random_steps": steps_cfg}
    )
    steps = [(0.0, 0.0, 0.0)]
    for e in sc.schedule():
        if e["t"] > 0.0:
            steps.append((float(e["t"]), float(e["vn"] or 0.0), float(e["ve"] or 0.0)))
    return Mission(steps, float(duration))


def collect_over_mavlink(
    url: str,
    *,
    duration: float,
    seed: int,
    out,
    axes: str = "n",
    sample_time: float = 0.01,
    system_id: int | None = None,
    **session_options,
):
    """Fly the random-step mission over ``url`` and write the record to ``out``.

    ``out`` is ``.parquet`` or ``.csv`` (trace columns, ``acc_sp_*`` = PX4's
    acceleration setpoint, ``vel_sp_*`` = the commanded velocity) written atomically, also
    when a watchdog ends the flight early (then :class:`FlightAbort` is raised after).
    Returns the :class:`FlightReport`.
    """
    mission = random_step_mission(duration, seed, axes=axes)
    return fly_velocity_mission(
        url, mission, out=out, sample_time=sample_time, system_id=system_id, **session_options
    )


def fly_velocity_mission(
    url: str,
    mission: Mission,
    *,
    out,
    sample_time: float = 0.01,
    system_id: int | None = None,
    **session_options,
):
    """Fly ``mission``'s velocity steps under PX4's own velocity control (the PID
    baseline; the training flight) and write the record to ``out`` (as
    :func:`collect_over_mavlink`)."""
    conn = connect(url)
    try:
        # PX4's own velocity control flies this mission, so old telemetry only thins the
        # record: the stale limit is half of PX4's offboard timeout (COM_OF_LOSS_T, 1 s), not
        # a few ticks (PX4 SITL on a loaded machine delays a packet by 0.1 s now and then).
        session_options.setdefault(
            "watchdog", Watchdog(sample_time, stale_factor=max(3.0, 0.5 / sample_time))
        )
        session = OffboardSession(conn, ts=sample_time, system_id=system_id, **session_options)
        session.connect()

        def policy(k, t, tel, rate):
            vn, ve = mission.reference(t)
            return (
                MASK_VEL_ALT_HOLD,
                (0.0, 0.0, session.alt_hold),
                (vn, ve, 0.0),
                (tel.acc_sp[0], tel.acc_sp[1], 0.0),
                (vn, ve),
            )

        report = session.run(policy, mission.duration)
        _finish(report, out, session.log_meta)
        return report
    finally:
        conn.close()
