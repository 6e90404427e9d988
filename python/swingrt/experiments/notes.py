"""The notes of an experiment's report: when the adaptive MPC re-adopted a model, where
the MPC and the LQR differ, and which drag removal of the IMU's swing the selection
chose."""

from __future__ import annotations

import math
from typing import Any

from swingrt.scenario import Scenario


def adaptation_note(scenario: Scenario, events: list[tuple[float, str, float]]) -> str:
    """When the adaptive MPC noticed the change (online detector, or the twin path's mass
    step / new cable length) and re-adopted a model, relative to the scenario's first
    payload event (``adopted … s after the change``)."""
    changes = scenario.to_dict().get("payload", {}).get("events", [])
    t_change = float(changes[0]["t"]) if changes else 0.0
    first: dict[str, tuple[float, float]] = {}
    for t, what, value in events:
        if t >= t_change:
            first.setdefault(what, (t, value))
    rejected = sum(1 for t, w, _ in events if w == "rejected" and t >= t_change)
    parts = [f"adaptive MPC, change at {t_change:.2f} s:"]
    noticed = [first[w][0] for w in ("detected", "mass_changed", "requested") if w in first]
    if noticed:
        parts.append(f"noticed after {min(noticed) - t_change:.2f} s")
    else:
        parts.append("not noticed")
    if "mass_changed" in first:
        parts.append(f"(thrust: total mass {first['mass_changed'][1]:.3f} kg)")
    lengths = [v for t, w, v in events if w == "requested" and t >= t_change and v > 0]
    if lengths and "detected" not in first:
        parts.append(
            "twin re-identified for cable length(s) " + ", ".join(f"{v:.2f} m" for v in lengths)
        )
    if "adopted" in first:
        parts.append(f"model re-adopted after {first['adopted'][0] - t_change:.2f} s")
    else:
        parts.append("no model re-adopted")
    if rejected:
        parts.append(f"{rejected} candidate(s) rejected by the check")
    return " ".join(parts)


#: Metrics :func:`compare_mpc_lqr` reads (lower is better for each).
COMPARED = (
    "peak_swing_deg",
    "swing_excess_iae_deg_s",
    "residual_swing_deg",
    "swing_free_s",
    "v_settle_s",
    "ss_error",
    "acc_sp_tv",
)


def compare_mpc_lqr(mpc: dict[str, Any], lqr: dict[str, Any], *, alike: float = 0.2) -> str:
    """Where the MPC and the LQR differ on one case: each metric of :data:`COMPARED` whose
    values differ by more than ``alike`` (relative, and more than 0.05 absolute) is named
    with the better controller; the rest are listed as alike."""
    better: list[str] = []
    same: list[str] = []
    for k in COMPARED:
        a, b = float(mpc[k]), float(lqr[k])
        if math.isclose(a, b, rel_tol=alike, abs_tol=0.05):
            same.append(k)
            continue
        who = "MPC" if a < b else "LQR"
        better.append(f"{k} {who} ({a:.3g} MPC vs {b:.3g} LQR)")
    out = "MPC vs LQR: better " + ("; ".join(better) if better else "on nothing")
    return out + (f"; alike (within {alike:.0%}): {', '.join(same)}" if same else "")


def swing_drag_note(choice: dict[str, Any]) -> str:
    """What the report says of the drag removals the selection weighed on the IMU's swing
    (``diagnostics['swing_drag_choice']``, :func:`swingrt.sysid.select_for_control`): each
    one's pick and its swing on the twin's step against PX4's, and which flies."""

    def one(w: dict[str, Any]) -> str:
        swing = w["twin_swing_vs_pid"]
        on_twin = "no twin" if swing is None else f"{swing:.3f}× PX4's swing on the twin"
        return f"{w['drag']} (q = {w['q']}, p = {w['p']}, {w['law']}, {on_twin})"

    weighed = "; ".join(one(w) for w in choice["weighed"])
    return f"drag removal weighed by the selection: {weighed}; flown: {choice['chosen']}"
