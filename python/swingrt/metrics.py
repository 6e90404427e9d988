"""Step-response metrics of a trace (thesis 5.5; the ``metrics.csv`` columns).

For a velocity step at ``t0`` along ``axis`` (``n``, ``e`` or ``ne``, the last projected on
the step direction), over the window after the step:

- ``peak_swing_deg``: largest |swing| [deg] (swing magnitude for two axes);
- ``swing_settle_s``: time after ``t0`` from which |swing − final| < 1° for good [s];
- ``swing_iae_deg_s``: ∫ |swing − final| dt [deg·s];
- ``overshoot_pct``: largest excursion of the velocity beyond the new setpoint, in % of the
  step (the core's ``step_overshoot``, the definition the closed-loop step check uses too);
- ``v_settle_s``: time after ``t0`` from which |v − v_sp| < 5 % of the step for good [s];
- ``ss_error``: |v_sp − mean v over the last 2 s| [m/s];
- ``effort``: ∫ |a_sp|² dt of the horizontal acceleration setpoint [m²/s³];
- ``swing_excess_iae_deg_s``: ``swing_iae_deg_s`` − :func:`swing_iae_floor` [deg·s]: the part
  of the swing IAE a controller decides (see below);
- ``residual_swing_deg``: largest |swing − final| from 4 s after ``t0`` to the end [deg]: the
  swing left once the velocity transient is over;
- ``residual_oscillation_deg``: the same, less the lean the vehicle's acceleration asks of
  the payload: largest |swing − final − lean| from 4 s after ``t0`` [deg], lean =
  −atan(a/g) with a the vehicle's acceleration along the step (its velocity's change over
  :data:`LEAN_SPAN_S`, centred). A controller still finishing its velocity step at 4 s leans
  the payload by a/g (0.1 m/s² is 0.6°) without any swing about that lean; this is the swing
  about it. The lean is quasi-static: a payload follows the vehicle's acceleration only
  below its own swing rate, so the span averages out the vehicle's faster wobbles (1–2 Hz,
  which a payload on 1 m answers with a third to a fifteenth of the lean, the other way;
  0.15 at 1.4 Hz). It never hides a free
  swing on a cable longer than 0.25 m (a swing rate under 1 Hz, where the span passes the
  pull with a positive gain): the cable's pull on the vehicle is (m_p/m_Q)·g·θ, so a swing
  the controller leaves alone counts more than once;
- ``swing_free_s``: time after ``t0`` from which |swing − final| < 0.25° for good [s] — the
  start of swing-free cruise. It is ``swing_settle_s`` with a band four times narrower: 1°
  is inside the swing that any velocity change needs, so ``swing_settle_s`` ranks every good
  controller alike; 0.25° is what a slowly decaying residual oscillation still exceeds;
- ``acc_sp_tv``: total variation Σ|Δa_sp| of the horizontal acceleration setpoint (vector
  norm of each tick's change) from ``t0`` to the end [m/s²]: command chatter, which the
  swing metrics do not see and the attitude loop and motors do.

"final" is the mean over the last 2 s of the window (the core's ``FINAL_SPAN``). The swing
IAE and its floor are the core's ``swing_iae``, the definition the twin's check uses too.
The swing is the true swing when the trace logs it (``swing_true_*``), else the measured
one.

:func:`swing_iae_floor` gives the part of the swing IAE that no controller can remove:
horizontally the cable is all that accelerates the payload, so g·∫tan(swing) dt equals the
payload's velocity change plus its drag impulse. A step of Δv therefore needs
|∫(swing − final) dt| ≈ Δv/g (11.7 deg·s for 2 m/s, a little less with payload drag), and
∫|swing − final| dt can only exceed it; what a controller decides is the excess.
"""

from __future__ import annotations

import math

import numpy as np

from swingrt import _core
from swingrt.errors import DataError

#: Metric names in ``metrics.csv`` order.
METRICS = (
    "peak_swing_deg",
    "swing_settle_s",
    "swing_iae_deg_s",
    "overshoot_pct",
    "v_settle_s",
    "ss_error",
    "effort",
    "swing_excess_iae_deg_s",
    "residual_swing_deg",
    "residual_oscillation_deg",
    "swing_free_s",
    "acc_sp_tv",
)

#: Band of ``swing_free_s`` [deg].
SWING_FREE_BAND_DEG = 0.25
#: Start of the ``residual_swing_deg`` window after the step [s].
RESIDUAL_AFTER_S = 4.0
#: Span of the velocity change ``residual_oscillation_deg`` reads the vehicle's acceleration
#: from, centred [s]: a low-pass whose first null is at 1 Hz (a 0.25 m cable's swing rate),
#: so the vehicle's own 1–2 Hz wobbles, which a payload does not follow quasi-statically,
#: barely lean it, while a step's approach (a time constant of 1–2 s) is read within 1–4 %.
LEAN_SPAN_S = 1.0


def _col(trace, name: str) -> np.ndarray:
    cols = trace.columns if hasattr(trace, "columns") else trace
    if name not in cols:
        raise DataError(f"trace has no column {name!r}")
    return np.asarray(cols[name], dtype=float)


def _settle(t: np.ndarray, err: np.ndarray, band: float, t0: float) -> float:
    outside = np.nonzero(np.abs(err) >= band)[0]
    if len(outside) == 0:
        return 0.0
    last = outside[-1]
    if last + 1 >= len(t):
        return math.inf
    return float(t[last + 1] - t0)


def swing_column(trace, axis: str) -> str:
    """The column a flight's swing along ``axis`` (``n`` or ``e``) is judged and shown by:
    the simulator's true angle where the trace logs it (a flight on the IMU's estimate, or
    with a noisy sensor), else the measured swing."""
    cols = getattr(trace, "columns", trace)
    return f"swing_true_{axis}" if "swing_true_n" in cols else f"swing_{axis}"


def _step_window(trace, t0: float, axis: str, t_end: float | None):
    """Time, the step window mask and the swing columns (true swing when logged)."""
    t = _col(trace, "t")
    if axis not in ("n", "e", "ne"):
        raise DataError(f"axis must be 'n', 'e' or 'ne' (got {axis!r})")
    sn, se = _col(trace, swing_column(trace, "n")), _col(trace, swing_column(trace, "e"))
    end = float(t[-1]) if t_end is None else t_end
    win = (t >= t0) & (t <= end + 1e-9)
    if win.sum() < 10:
        raise DataError(f"too few samples after the step at t = {t0} s")
    return t, win, sn, se


def step_metrics(
    trace,
    *,
    t0: float,
    axis: str = "n",
    t_end: float | None = None,
    v_before: float | None = None,
    v_after: float | None = None,
) -> dict[str, float]:
    """Metrics of a velocity step at ``t0`` (see module docs); returns a dict of floats."""
    t, win, sn, se = _step_window(trace, t0, axis, t_end)
    vn, ve = _col(trace, "vn"), _col(trace, "ve")
    an, ae = _col(trace, "acc_sp_n"), _col(trace, "acc_sp_e")
    pre = t < t0
    swing, along = _swing_along(trace, win, axis, sn, se)
    if axis == "ne":
        vsp_n, vsp_e = _col(trace, "vel_sp_n"), _col(trace, "vel_sp_e")
        after = np.array([np.nanmedian(vsp_n[win]), np.nanmedian(vsp_e[win])])
        norm = float(np.hypot(*after)) or 1.0
        d = after / norm
        v = vn * d[0] + ve * d[1]
        vb = 0.0 if v_before is None else v_before
        va = norm if v_after is None else v_after
    else:
        v = vn if axis == "n" else ve
        vsp = _col(trace, f"vel_sp_{axis}")
        vb = float(np.nanmedian(vsp[pre])) if v_before is None and pre.any() else (v_before or 0.0)
        va = float(np.nanmedian(vsp[win])) if v_after is None else v_after
    tw, vw, sw = t[win], v[win], swing[win]
    dt = float(np.median(np.diff(tw)))
    tail = tw >= tw[-1] - _core.FINAL_SPAN
    final_swing = float(np.mean(sw[tail]))
    step = va - vb
    overshoot = 100.0 * _core.step_overshoot(np.ascontiguousarray(vw, dtype=float), vb, va)
    a2 = an[win] ** 2 + ae[win] ** 2
    dev = np.degrees(sw - final_swing)
    late = tw >= t0 + RESIDUAL_AFTER_S
    # The swing about the lean: along the step (the signed swing, as the floor reads it).
    half = 0.5 * LEAN_SPAN_S
    acc = (np.interp(tw + half, tw, vw) - np.interp(tw - half, tw, vw)) / LEAN_SPAN_S
    sa = along[win]
    lean = -np.arctan(acc / _core.GRAVITY)
    about = np.degrees(sa - float(np.mean(sa[tail])) - lean)
    iae, floor = _core.swing_iae(tw, sw, along[win])
    return {
        "peak_swing_deg": float(np.degrees(np.max(np.abs(sw)))),
        "swing_settle_s": _settle(tw, np.degrees(sw - final_swing), 1.0, t0),
        "swing_iae_deg_s": iae,
        "overshoot_pct": float(max(overshoot, 0.0)),
        "v_settle_s": _settle(tw, vw - va, 0.05 * abs(step) if step else 0.02, t0),
        "ss_error": float(abs(va - np.mean(vw[tail]))),
        "effort": float(np.sum(a2) * dt),
        "swing_excess_iae_deg_s": iae - floor,
        "residual_swing_deg": float(np.max(np.abs(dev[late]))) if late.any() else math.nan,
        "residual_oscillation_deg": float(np.max(np.abs(about[late]))) if late.any() else math.nan,
        "swing_free_s": _settle(tw, dev, SWING_FREE_BAND_DEG, t0),
        "acc_sp_tv": acc_sp_tv(an[win], ae[win]),
    }


def acc_sp_tv(acc_n, acc_e=None) -> float:
    """Total variation Σ_k |a_{k+1} − a_k| [m/s²] of an acceleration setpoint sequence (the
    horizontal vector (N, E) when ``acc_e`` is given; NaN samples are skipped)."""
    an = np.asarray(acc_n, dtype=float)
    ae = np.zeros_like(an) if acc_e is None else np.asarray(acc_e, dtype=float)
    ok = np.isfinite(an) & np.isfinite(ae)
    an, ae = an[ok], ae[ok]
    if len(an) < 2:
        return 0.0
    return float(np.sum(np.hypot(np.diff(an), np.diff(ae))))


def swing_iae_floor(trace, *, t0: float, axis: str = "n", t_end: float | None = None) -> float:
    """|∫(swing − final) dt| [deg·s] after the step at ``t0``, the swing along the step
    direction for ``ne``: the lower bound of ``swing_iae_deg_s`` (module docs)."""
    t, win, sn, se = _step_window(trace, t0, axis, t_end)
    swing, along = _swing_along(trace, win, axis, sn, se)
    return _core.swing_iae(t[win], swing[win], along[win])[1]


def _swing_along(trace, win, axis: str, sn, se):
    """The swing whose IAE is measured (its magnitude for ``ne``) and the swing along the
    step, whose integral is the floor."""
    if axis == "ne":
        vsp = np.array([np.nanmedian(_col(trace, f"vel_sp_{a}")[win]) for a in "ne"])
        d = vsp / (float(np.hypot(*vsp)) or 1.0)
        return np.hypot(sn, se), sn * d[0] + se * d[1]
    swing = sn if axis == "n" else se
    return swing, swing


def step_time(trace, axis: str = "n") -> float | None:
    """Time of the first change of the velocity setpoint on ``axis`` after t = 0, if any."""
    t = _col(trace, "t")
    vsp = _col(trace, f"vel_sp_{axis[0]}")
    finite = np.isfinite(vsp)
    if finite.sum() < 2:
        return None
    v = np.where(finite, vsp, np.nan)
    first = v[np.argmax(finite)]
    changed = np.nonzero(finite & (np.abs(v - first) > 1e-6))[0]
    return float(t[changed[0]]) if len(changed) else None
