"""Missions flown in the built-in simulator and what a user reads after the flight: one row
per waypoint (arrival, overshoot, swing on the leg and after arrival, settling below 1°,
vehicle and payload error during the hold), one summary row per flight (the worst
waypoint of each column) and the rules a mission flight is judged by in campaigns.

**Failure** of a mission flight (:func:`mission_failure`), the issue's acceptance per flight:

- ``error``, ``fallback``, ``diverged`` as for a step (:mod:`swingrt.campaign.flight`);
- ``settle``: after some arrival the swing was not within ``SETTLED_DEG`` of vertical
  within ``SETTLE_LIMIT_S`` (and stayed so for the rest of the hold);
- ``hold``: the vehicle left ``HOLD_LIMIT_M`` of a waypoint during its hold;
- ``slow`` (not PX4's own flight): the plan took more than ``TIME_RATIO_LIMIT``× PX4's mission
  mode's time on the same sample;
- ``swing`` (not PX4's): some leg's largest swing was more than ``LEG_SWING_RATIO``× PX4's on
  that leg.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from swingrt import _core
from swingrt.errors import ConfigError
from swingrt.metrics import swing_column
from swingrt.scenario import ScenarioLike, resolve

#: Swing below which the payload counts as settled [deg].
SETTLED_DEG = 1.0

#: Time after an arrival within which the swing must be within ``SETTLED_DEG`` [s].
SETTLE_LIMIT_S = 2.0
#: Largest distance from a waypoint during its hold [m].
HOLD_LIMIT_M = 0.3
#: Mission time, as a multiple of PX4's mission mode's, above which a flight is slow.
TIME_RATIO_LIMIT = 1.15
#: A leg's largest swing, as a fraction of PX4's on the same leg, above which it fails.
LEG_SWING_RATIO = 0.5
#: Peak swing above which a mission flight counts as diverged [deg].
DIVERGED_SWING_DEG = 60.0

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


#: Columns of a mission flight's summary (:func:`summary`): the plan's time, the worst
#: waypoint of each per-waypoint column (a swing that never settled is ∞), the peak swing,
#: and the ratios to PX4's own flight of the same sample (:func:`compare`).
SUMMARY_COLUMNS = (
    "total_s",
    "leg_swing_max_deg",
    "residual_swing_deg",
    "settle_1deg_s",
    "hold_error_m",
    "payload_hold_error_m",
    "overshoot_m",
    "peak_swing_deg",
    "time_vs_px4",
    "leg_swing_vs_px4",
)


def load(path: str) -> _core.Mission:
    """Read a QGroundControl ``.plan`` or a TOML mission, chosen by the file's extension."""
    kinds = {".plan": "plan", ".toml": "toml"}
    kind = kinds.get(Path(path).suffix.lower())
    if kind is None:
        raise ConfigError(f"{path}: a mission must end in .plan or .toml")
    return _core.Mission.from_text(Path(path).read_text(encoding="utf-8"), kind)


def true_swing(trace: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """The cable's true angles (North, East) [rad] of a flight: the simulator's truth where
    the trace has it, else the measured swing."""
    sn, se = (trace[swing_column(trace, a)] for a in ("n", "e"))
    return np.asarray(sn, dtype=float), np.asarray(se, dtype=float)


def check_model(model: _core.LinearModel) -> None:
    """Refuse, naming its inputs, a model that cannot fly a mission (one axis only)."""
    if len(model.inputs) != 2:
        raise ConfigError(
            f"model: a mission flies both axes, and this model has the inputs "
            f"{', '.join(model.inputs)} (identify a two-axis flight with --axes ne)",
            field="model",
        )


def shaped_legs(model: _core.LinearModel) -> dict[str, Any]:
    """swingrt's leg settings shaped against the swing ``model`` identified: the jerk ramps
    of every acceleration change last one swing period (:func:`swingrt.sysid.swing_period`),
    at the core's default acceleration bound. A ramp of acceleration over exactly one period
    is a boxcar of jerk whose spectrum is zero at that period's frequency, so the legs leave
    the payload no residual swing at the ends of their ramps whatever the leg's length; the
    jerk never exceeds the core's default. Without a swing period the defaults stand."""
    from swingrt.sysid import swing_period

    legs = _core.check_settings("guidance", {"mode": "smooth"})
    period = swing_period(model)
    if period is not None:
        legs["jerk_max"] = min(float(legs["jerk_max"]), float(legs["acc_max"]) / period)
    return legs


#: What a mission's reference is for: the vehicle, or the payload hanging below it.
TARGETS = ("vehicle", "payload")


def target_tracking(
    model: _core.LinearModel, target: str = "vehicle", cable_length: float | None = None
) -> tuple[dict[str, Any] | None, str]:
    """The tracking settings that put ``target`` over the waypoints, and where the cable
    length came from. For the payload the length is ``cable_length`` if given, else the
    white-box length the model was identified with, else the pendulum length of the model's
    swing period, g (T/2π)²: a lower bound, since the vehicle pulled by the payload swings
    faster than a pendulum from a fixed point (by √(1 + m_p/m_Q))."""
    if target not in TARGETS:
        raise ConfigError(f"target {target!r} is not one of {', '.join(TARGETS)}", field="target")
    if target == "vehicle":
        if cable_length is not None:
            raise ConfigError("a cable length applies to the payload target only", field="target")
        return None, "the vehicle over the waypoints"
    if cable_length is not None:
        if not (0.01 <= cable_length <= 100.0):
            raise ConfigError(
                f"cable length {cable_length:g} m is not in [0.01, 100]", field="cable_length"
            )
        length, source = float(cable_length), "given"
    else:
        wb = model.diagnostics.get("whitebox") or {}
        if wb.get("length"):
            length, source = float(wb["length"]), "the white-box model's"
        else:
            from swingrt.sysid import swing_period

            period = swing_period(model)
            if period is None:
                raise ConfigError(
                    "the payload target needs the cable's length: the model shows no swing "
                    "period; give it (--cable-length)",
                    field="cable_length",
                )
            length = _core.GRAVITY * (period / (2.0 * math.pi)) ** 2
            source = f"from the swing period {period:.2f} s (a lower bound)"
    return (
        {"target": "payload", "cable_length": length},
        f"the payload over the waypoints, cable {length:.2f} m ({source})",
    )


def time_limit(mission: _core.Mission) -> float:
    """Longest a flight of ``mission`` may take [s], simulated or on a vehicle: three times
    its legs at their speeds, its holds and 30 s."""
    items = mission.items
    legs = sum(
        math.dist(a["position"], b["position"]) / max(b["speed"] or 1.0, 0.1)
        for a, b in zip(items, items[1:], strict=False)
    )
    return 1.0 + 3.0 * legs + sum(it["hold"] for it in items) + 30.0


def fly(
    mission: _core.Mission,
    guidance: str | dict[str, Any],
    scenario: ScenarioLike = None,
    seed: int = 0,
    model: _core.LinearModel | None = None,
    tracking: dict[str, Any] | None = None,
    lqr: dict[str, float] | None = None,
) -> tuple[dict[str, np.ndarray], list[tuple[float, int, str]]]:
    """Fly ``mission`` in the simulator under PX4's cascade with ``guidance`` (``px4``: PX4's
    mission behaviour; ``smooth``: swingrt's jerk-limited legs; or the guidance settings, as
    :func:`shaped_legs` gives), tracked by the position MPC with preview on ``model`` when
    one is given (``tracking``: its settings, ``TrackingSettings``), or by the baseline LQR
    with the pendulum ``lqr`` (:func:`swingrt.sysid.lqr_parameters`) in place of PX4's
    velocity loop, PX4's position loop giving it the velocity reference from the guidance's
    trajectory (as it does to PX4's own PID); returns the trace and the mission's events.
    The flight ends at the last hold's end (or fails after a time limit)."""
    if model is not None:
        check_model(model)
    if model is not None and lqr is not None:
        raise ConfigError("a mission flight has one controller: a model or the LQR", field="lqr")
    limit = time_limit(mission)
    base = resolve(scenario)
    sc = base.with_overrides({"start": list(mission.start)})
    sim = _core.Simulator(resolve(sc, duration=limit, seed=seed))
    sim.fly_mission(mission, {"mode": guidance} if isinstance(guidance, str) else guidance, 1.0)
    if model is not None:
        # The budget is wall-clock per tick; the simulator is not real-time, so a loaded
        # machine must not hand the axes back to PX4.
        sim.attach_tracking_mpc(model, tracking, 1.0, 1.0)
    if lqr is not None:
        sim.attach_lqr(lqr, 2, _core.check_settings("lqr", None), 1.0, 1.0)
    while not sim.mission_done and sim.t < limit - 0.5:
        sim.advance(0.5)
    if not sim.mission_done:
        raise ConfigError(f"mission {mission.name!r}: not finished after {limit:.0f} s")
    return {k: np.asarray(v) for k, v in sim.trace().items()}, sim.mission_events()


def replay_events(mission: _core.Mission, trace: Mapping[str, Any]) -> list[tuple[float, int, str]]:
    """The events of a flown path by PX4's navigator rule (an item is reached inside its
    acceptance radius, held for its hold time from then, and only then is the next one the
    target), whoever flew it: the one judge of flights whose own bookkeeping is not at hand
    (PX4's AUTO.MISSION) or differs (swingrt's guidance), applied to the trace's ``t``,
    position and velocity from its first row."""
    g = _core.Guidance(mission, {"mode": "px4"})
    t = np.asarray(trace["t"], dtype=float)
    pos = np.stack([np.asarray(trace[c], dtype=float) for c in ("pn", "pe", "pd")], axis=1)
    vel = np.stack([np.asarray(trace[c], dtype=float) for c in ("vn", "ve", "vd")], axis=1)
    if t.size == 0:
        return []
    g.start(float(t[0]), pos[0], vel[0])
    for i in range(t.size):
        g.update(float(t[i]), float(t[i] - t[i - 1]) if i else 0.0, pos[i], vel[i])
        if g.done:
            break
    return list(g.events())


def waypoint_report(
    mission: _core.Mission,
    trace: dict[str, np.ndarray],
    events: list[tuple[float, int, str]],
) -> list[dict[str, float]]:
    """One row per waypoint (see ``COLUMNS``): the leg is the flight from leaving the previous
    item to reaching this one, the hold from reaching it to leaving it; distances are
    horizontal; the swing is the true cable angle, from vertical on the leg, and during the
    hold (residual swing, settling) about the payload's hang there: the mean angle over the
    hold's second half, which a steady wind leans off vertical."""
    t = trace["t"]
    sn, se = true_swing(trace)
    swing = np.degrees(np.hypot(sn, se))
    pos = np.stack([trace["pn"], trace["pe"]], axis=1)
    # A flight log of a real vehicle has no payload position: its error is then unknown.
    nan = np.full(t.shape, np.nan)
    pay = np.stack([trace.get("payload_pn", nan), trace.get("payload_pe", nan)], axis=1)
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
        # The swing left after arrival is measured about where the payload hangs at the
        # hold (a steady wind leans it off vertical, which is not swing and no controller
        # removes): the mean angle over the hold's second half.
        calm = hold & (t >= 0.5 * (t_in + t_out))
        hang = np.array([sn[calm].mean(), se[calm].mean()]) if calm.any() else np.zeros(2)
        about = np.degrees(np.hypot(sn - hang[0], se - hang[1]))
        # Settled from the first instant after which that swing stays below 1° to the end
        # of the hold; NaN when it is still above at the hold's end.
        above = np.nonzero(hold & (about > SETTLED_DEG))[0]
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
                "residual_swing_deg": float(about[hold].max(initial=0.0)),
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


def summary(
    rows: list[dict[str, float]], total: float, trace: dict[str, np.ndarray]
) -> dict[str, float]:
    """A mission flight in one row (:data:`SUMMARY_COLUMNS` but the ratios): the worst
    waypoint of each column, ∞ for a swing that did not settle within its hold."""
    legs = rows[1:] or rows

    def worst(col: str) -> float:
        vals = [math.inf if math.isnan(r[col]) else r[col] for r in legs]
        return float(max(vals, default=0.0))

    sn, se = true_swing(trace)
    return {
        "total_s": float(total),
        **{c: worst(c) for c in SUMMARY_COLUMNS[1:7]},
        "peak_swing_deg": float(np.degrees(np.hypot(sn, se)).max(initial=0.0)),
    }


def compare(
    flight: dict[str, float],
    rows: list[dict[str, float]],
    px4: dict[str, float] | None,
    px4_rows: list[dict[str, float]] | None,
) -> dict[str, float]:
    """The ratios of :data:`SUMMARY_COLUMNS` to PX4's own flight of the same plan: the time,
    and the largest over legs of a leg's largest swing over PX4's on that leg (NaN without
    PX4's flight)."""
    if px4 is None or not px4_rows:
        return {"time_vs_px4": math.nan, "leg_swing_vs_px4": math.nan}
    theirs = {int(r["item"]): r["leg_swing_max_deg"] for r in px4_rows}
    ratios = [
        r["leg_swing_max_deg"] / theirs[int(r["item"])]
        for r in rows[1:]
        if theirs.get(int(r["item"]), 0.0) > 0.0
    ]
    return {
        "time_vs_px4": flight["total_s"] / px4["total_s"],
        "leg_swing_vs_px4": float(max(ratios, default=math.nan)),
    }


def mission_failure(row: dict[str, Any], judged: bool = True) -> str:
    """Why a mission flight failed ('' when it did not); the module docs give the rules.
    ``judged``: whether the comparisons with PX4's own flight apply (not to PX4's)."""
    if row.get("error"):
        return "error"
    if row.get("fallback"):
        return "fallback"
    vals = [row.get(c) for c in SUMMARY_COLUMNS[:8]]
    if any(isinstance(v, float) and math.isnan(v) for v in vals) or (
        row.get("peak_swing_deg", 0.0) > DIVERGED_SWING_DEG
    ):
        return "diverged"
    if row.get("settle_1deg_s", 0.0) > SETTLE_LIMIT_S:
        return "settle"
    if row.get("hold_error_m", 0.0) > HOLD_LIMIT_M:
        return "hold"
    if judged and row.get("time_vs_px4", 0.0) > TIME_RATIO_LIMIT:
        return "slow"
    if judged and row.get("leg_swing_vs_px4", 0.0) > LEG_SWING_RATIO:
        return "swing"
    return ""


def format_comparison(flights: dict[str, dict[str, Any]]) -> str:
    """Each flight's summary against PX4's mission mode, and the rules it failed."""
    cols = ("total_s", "time_vs_px4", "leg_swing_vs_px4", "settle_1deg_s", "hold_error_m")
    lines = ["against PX4's mission mode (worst waypoint):", "  flight  " + "  ".join(cols)]
    for name, f in flights.items():
        s = f["summary"]
        cells = [f"{s[c]:>{len(c)}.2f}" for c in cols]
        verdict = f.get("failure") or "passes"
        lines.append(f"  {name:<6}  " + "  ".join(cells) + f"  {verdict}")
    return "\n".join(lines)
