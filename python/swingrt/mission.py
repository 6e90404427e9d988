"""Missions flown in the built-in simulator and what a user reads after the flight: one row
per waypoint (arrival, overshoot, swing on the leg and after arrival, settling below 1°,
vehicle and payload error during the hold)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from swingrt import _core
from swingrt.errors import ConfigError

#: Swing below which the payload counts as settled [deg].
SETTLED_DEG = 1.0

#: Columns of the per-waypoint report, in order.
COLUMNS = (
    "item",
    "arrival_s",
    "overshoot_m",
    "leg_swing_max_deg",
    "residual_swing_deg",
    "settle_1deg_s",
    "hold_error_m",
    "payload_hold_error_m",
)


def load(path: str) -> _core.Mission:
    """Read a QGroundControl ``.plan`` or a TOML mission, chosen by the file's extension."""
    kinds = {".plan": "plan", ".toml": "toml"}
    kind = kinds.get(Path(path).suffix.lower())
    if kind is None:
        raise ConfigError(f"{path}: a mission must end in .plan or .toml")
    return _core.Mission.from_text(Path(path).read_text(encoding="utf-8"), kind)


def fly(
    mission: _core.Mission,
    guidance: str,
    scenario: dict[str, Any] | None = None,
    seed: int = 0,
    model: _core.LinearModel | None = None,
) -> tuple[dict[str, np.ndarray], list[tuple[float, int, str]]]:
    """Fly ``mission`` in the simulator under PX4's cascade with ``guidance`` (``px4``: PX4's
    mission behaviour; ``smooth``: swingrt's jerk-limited legs), tracked by the position MPC
    with preview on ``model`` when one is given; returns the trace and the mission's events.
    The flight ends at the last hold's end (or fails after a time limit)."""
    from swingrt.scenario import resolve

    items = mission.items
    legs = sum(
        math.dist(a["position"], b["position"]) / max(b["speed"] or 1.0, 0.1)
        for a, b in zip(items, items[1:], strict=False)
    )
    limit = 1.0 + 3.0 * legs + sum(it["hold"] for it in items) + 30.0
    cfg = dict(scenario or {})
    cfg["start"] = list(mission.start)
    sim = _core.Simulator(resolve(cfg, duration=limit, seed=seed))
    sim.fly_mission(mission, {"mode": guidance}, 1.0)
    if model is not None:
        # The budget is wall-clock per tick; the simulator is not real-time, so a loaded
        # machine must not hand the axes back to PX4.
        sim.attach_tracking_mpc(model, None, 1.0, 1.0)
    while not sim.mission_done and sim.t < limit - 0.5:
        sim.advance(0.5)
    if not sim.mission_done:
        raise ConfigError(f"mission {mission.name!r}: not finished after {limit:.0f} s")
    return {k: np.asarray(v) for k, v in sim.trace().items()}, sim.mission_events()


def waypoint_report(
    mission: _core.Mission,
    trace: dict[str, np.ndarray],
    events: list[tuple[float, int, str]],
) -> list[dict[str, float]]:
    """One row per waypoint (see ``COLUMNS``): the leg is the flight from leaving the previous
    item to reaching this one, the hold from reaching it to leaving it; distances are
    horizontal; the swing is the true cable angle from vertical."""
    t = trace["t"]
    sn = trace.get("swing_true_n", trace["swing_n"])
    se = trace.get("swing_true_e", trace["swing_e"])
    swing = np.degrees(np.hypot(sn, se))
    pos = np.stack([trace["pn"], trace["pe"]], axis=1)
    pay = np.stack([trace["payload_pn"], trace["payload_pe"]], axis=1)
    reached = {i: ti for ti, i, k in events if k == "reached"}
    left = {i: ti for ti, i, k in events if k in ("left", "completed")}
    items = mission.items
    rows = []
    for i, it in enumerate(items):
        if i not in reached:
            continue
        wp = np.asarray(it["position"][:2], dtype=float)
        t_in = reached[i]
        t_out = left.get(i, float(t[-1]))
        t_from = left.get(i - 1, float(t[0]))
        leg = (t >= t_from) & (t <= t_in)
        hold = (t >= t_in) & (t <= t_out)
        after = t >= t_in
        overshoot = 0.0
        if i > 0:
            d = wp - np.asarray(items[i - 1]["position"][:2], dtype=float)
            if np.linalg.norm(d) > 1e-9:
                ahead = (pos[after] - wp) @ (d / np.linalg.norm(d))
                overshoot = float(max(0.0, ahead[t[after] <= t_out].max(initial=0.0)))
        # Settled from the first instant after which the swing stays below 1° to the end of
        # the hold; NaN when it is still above at the hold's end.
        above = np.nonzero(hold & (swing > SETTLED_DEG))[0]
        last = np.nonzero(hold)[0]
        if above.size == 0:
            settle = 0.0
        elif last.size and above[-1] < last[-1]:
            settle = float(t[above[-1] + 1] - t_in)
        else:
            settle = math.nan
        rows.append(
            {
                "item": float(i),
                "arrival_s": float(t_in),
                "overshoot_m": overshoot,
                "leg_swing_max_deg": float(swing[leg].max(initial=0.0)),
                "residual_swing_deg": float(swing[hold].max(initial=0.0)),
                "settle_1deg_s": settle,
                "hold_error_m": float(np.linalg.norm(pos[hold] - wp, axis=1).max(initial=0.0)),
                "payload_hold_error_m": float(
                    np.linalg.norm(pay[hold] - wp, axis=1).max(initial=0.0)
                ),
            }
        )
    return rows


def format_report(name: str, rows: list[dict[str, float]], total: float) -> str:
    """The per-waypoint table as text, headed by the guidance's name and total time."""
    lines = [f"{name}: mission finished at {total:.2f} s", "  " + "  ".join(COLUMNS)]
    for r in rows:
        cells = [f"{int(r['item']):>4d}"] + [f"{r[c]:>{len(c)}.2f}" for c in COLUMNS[1:]]
        lines.append("  " + "  ".join(cells))
    return "\n".join(lines)
