"""The notes of an experiment's report: when the adaptive MPC re-adopted a model, and
where the MPC and the LQR differ."""

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
