"""Nonlinear MPC (CasADi) on a continuous model of one axis, x = [v, θ, θ̇], input the
acceleration setpoint: ``nmpc`` flies the white-box pendulum (:func:`pendulum_dynamics`),
``sindy_mpc`` the SINDy model (:mod:`swingrt.methods.sindy`).

**Cost** — the identified MPC's (``swing_core::control::mpc``), so that the methods differ
only in their model: over Np ticks of Ts, velocity tracking w_v (v − v_ref), the swing
rate by the two-tick difference w_s' (θ_{i} − θ_{i−2})/(2Ts), the swing angle w_θ θ, the
input increments w_Δu Δu over the control horizon Nc, the input held after it, and
|u| ≤ acc_max. The prediction integrates the model by one RK4 step per tick.

**Attitude lag.** PX4's attitude loop makes the vehicle's acceleration follow the setpoint
with a lag the white-box model leaves out; a first-order lag τ estimated from the training
flight (:func:`estimate_lag`) is part of the prediction (0 leaves it out).

**Offset-free.** A constant acceleration disturbance d [m/s²] adds to the acceleration the
vehicle sees (drag, wind on the vehicle, a thrust or hover-thrust error): the pendulum feels
it too, as it feels every acceleration of its hanging point. (Added to v̇ alone, the
prediction had the payload swing towards the setpoint's acceleration while the vehicle held
its speed, and the swing-rate cost then kept the plan from closing a steady velocity error:
0.29 m/s on a 0.31 m cable in 0.7 m/s wind.) A second one, d_θ [rad/s²], adds to θ̈: a
steady force on the payload (wind) holds it off the vertical, and without d_θ the prediction
swings it back, which the plan then fights with a steady acceleration (a velocity error
again). Each is estimated by the steady-state Kalman filter of its pair, (v, d) and
(θ̇, d_θ), with the MPC's noise settings (``kf_process_noise``, ``kf_disturbance_noise``,
``kf_measurement_noise``; d_θ ``kf_swing_disturbance_scale`` times as fast, as the MPC's
swing disturbances), the measured state taken as the prediction's start (as
``measured_state = true`` in the MPC).

**Solver.** Single shooting over the Nc moves: CasADi builds the residual vector of the
cost (a sum of squares) and its Jacobian once, with the start state, disturbance, last
input, last swing and reference as parameters; each tick runs ``max_iter`` Gauss–Newton SQP
steps (each a bounded linear least-squares problem, BVLS) from the previous solution
shifted by one tick, stopping early when a step moves no input by 1e-7. The default, one
step per tick, is the real-time iteration of Diehl, Bock et al. (2005), the standard way
to fly an NMPC at a fixed rate: the optimisation converges over the ticks.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from swingrt.errors import ConfigError, ControlError

__all__ = ["NmpcSettings", "Nmpc", "estimate_lag", "lag_share", "lagged", "pendulum_dynamics"]


@dataclass
class NmpcSettings:
    """Settings of the nonlinear MPC (the identified MPC's defaults; units in the field
    docs). Build with :meth:`from_dict`, which checks every field and names a bad one."""

    #: Prediction horizon Np [ticks].
    horizon: int = 100
    #: Control horizon Nc [ticks].
    control_horizon: int = 20
    #: Tick period Ts [s].
    period: float = 0.03
    #: Velocity tracking weight [1/(m/s)].
    w_velocity: float = 1.0
    #: Swing-rate weight [1/(rad/s)].
    w_swing_rate: float = 6.0
    #: Swing-angle weight [1/rad].
    w_swing: float = 0.0
    #: Input-increment weight [1/(m/s²)].
    w_acc_rate: float = 6.0
    #: Bound on |acceleration setpoint| [m/s²].
    acc_max: float = 4.0
    #: Kalman process noise of the velocity per tick [m/s].
    kf_process_noise: float = 0.01
    #: Kalman process noise of the disturbance per tick [m/s²].
    kf_disturbance_noise: float = 0.02
    #: Kalman measurement noise of the velocity [m/s] (and of the swing rate [rad/s]).
    kf_measurement_noise: float = 0.01
    #: The swing disturbance's process noise relative to the velocity one's [-].
    kf_swing_disturbance_scale: float = 0.1
    #: Gauss–Newton iterations per tick [-] (1: the real-time iteration).
    max_iter: int = 1

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None, section: str = "nmpc") -> NmpcSettings:
        """Settings from a dict (unknown keys, wrong types and out-of-range values raise
        :class:`~swingrt.errors.ConfigError` naming ``section.field``)."""
        d = dict(d or {})
        known = {f.name: f for f in fields(cls)}
        for k in d:
            if k not in known:
                raise ConfigError(f"{section}.{k}: unknown setting", field=f"{section}.{k}")
        s = cls()
        for k, v in d.items():
            want = int if known[k].type == "int" else float
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ConfigError(
                    f"{section}.{k}: must be a number (got {v!r})", field=f"{section}.{k}"
                )
            if want is int and not float(v).is_integer():
                raise ConfigError(
                    f"{section}.{k}: must be an integer (got {v!r})", field=f"{section}.{k}"
                )
            setattr(s, k, want(v))
        s.validate(section)
        return s

    def validate(self, section: str = "nmpc") -> None:
        """Check ranges; the error names ``section.field``."""

        def bad(name: str, why: str) -> ConfigError:
            return ConfigError(
                f"{section}.{name}: {why} (got {getattr(self, name)!r})", field=f"{section}.{name}"
            )

        if not 1 <= self.horizon <= 1000:
            raise bad("horizon", "must be between 1 and 1000 ticks")
        if not 1 <= self.control_horizon <= self.horizon:
            raise bad("control_horizon", "must be between 1 and horizon")
        for name in ("period", "acc_max", "w_acc_rate", "kf_process_noise",
                     "kf_disturbance_noise", "kf_measurement_noise",
                     "kf_swing_disturbance_scale"):  # fmt: skip
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise bad(name, "must be > 0")
        for name in ("w_velocity", "w_swing_rate", "w_swing"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise bad(name, "must be >= 0")
        if self.max_iter < 1:
            raise bad("max_iter", "must be >= 1")

    def to_dict(self) -> dict[str, Any]:
        """Every field as a dict."""
        return asdict(self)


def pendulum_dynamics(m_q: float, m_p: float, l: float, c: float) -> Callable[[Any, Any], Any]:
    """The planar vehicle + pendulum of the white-box model, nonlinear: a vehicle of mass
    m_Q driven by the force m_Q u, a point payload m_p on a rigid cable l, joint friction c
    (the Lagrange equations whose linearisation is thesis eq. 5.7):

        (m_Q + m_p) ẍ + m_p l (θ̈ cos θ − θ̇² sin θ) = m_Q u
        m_p l² θ̈ + m_p l ẍ cos θ + m_p g l sin θ = −c θ̇

    Returns f(x, u) → ẋ for x = [v, θ, θ̇] on CasADi or numpy values."""
    from swingrt import _core

    g = _core.GRAVITY

    def f(x: Any, u: Any) -> Any:
        import casadi as ca

        v, th, w = x[0], x[1], x[2]
        s, co = ca.sin(th), ca.cos(th)
        a11, a12, a22 = m_q + m_p, m_p * l * co, m_p * l * l
        b1 = m_q * u + m_p * l * w * w * s
        b2 = -m_p * g * l * s - c * w
        det = a11 * a22 - a12 * a12
        xdd = (a22 * b1 - a12 * b2) / det
        thdd = (a11 * b2 - a12 * b1) / det
        del v
        return ca.vertcat(xdd, w, thdd)

    return f


def estimate_lag(v: np.ndarray, swing: np.ndarray, u: np.ndarray, dt: float) -> float:
    """The attitude loop's lag τ [s] from one axis of a flight at sample time ``dt``: the
    core's fit (``swing_core::sysid::lag``, the one the model selection flies behind), the
    velocity's increments regressed on the lagged setpoint u with drag, the swing's pull and
    a constant beside it; 0 (no lag in the prediction) when the flight does not tell it."""
    from swingrt import _core

    def column(x: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(x, dtype=float)

    tau = _core.sysid_attitude_lag(column(v), column(swing), column(u), dt)
    return 0.0 if tau is None else float(tau)


def lag_share(dt: float, tau: float) -> tuple[float, float]:
    """(α, s) of a first-order lag τ under a setpoint held for ``dt``: the lag state moves
    as a⁺ = a + α(u − a) and its exact mean over the tick is u + s·(a − u), the
    discretisation the core's lag fit (``swing_core::sysid::lag``) uses; τ = 0: (1, 0)."""
    if tau <= 0:
        return 1.0, 0.0
    alpha = -math.expm1(-dt / tau)
    return alpha, tau * alpha / dt


def lagged(u: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """The acceleration the vehicle sees over each tick, as the prediction models it: the
    exact mean over the tick of the lag state a⁺ = a + α(u − a) (:func:`lag_share`;
    τ = 0: u itself)."""
    u = np.asarray(u, dtype=float)
    if tau <= 0:
        return u.copy()
    alpha, share = lag_share(dt, tau)
    out = np.empty_like(u)
    a = u[0]
    for k, uk in enumerate(u):
        out[k] = uk + share * (a - uk)
        a = a + alpha * (uk - a)
    return out


def _kalman_gain(dt: float, q_v: float, q_d: float, r_v: float) -> np.ndarray:
    """Steady-state gain of the filter of (v, d): v⁺ = v + Ts d (+ model), d⁺ = d, y = v."""
    a = np.array([[1.0, dt], [0.0, 1.0]])
    c = np.array([[1.0, 0.0]])
    q = np.diag([q_v**2, q_d**2])
    p = np.eye(2)
    for _ in range(10_000):
        pp = a @ p @ a.T + q
        k = pp @ c.T / (c @ pp @ c.T + r_v**2)
        p_new = (np.eye(2) - k @ c) @ pp
        if np.max(np.abs(p_new - p)) < 1e-14:
            break
        p = p_new
    pp = a @ p @ a.T + q
    return (pp @ c.T / (c @ pp @ c.T + r_v**2)).reshape(2)


class Nmpc:
    """Nonlinear MPC of one or two decoupled axes on ``dynamics`` (see module docs).

    ``dynamics(x, u)`` maps x = [v, θ, θ̇] and the acceleration setpoint to ẋ with CasADi
    operations. ``reset(state, acc)`` / ``step(state, vel_ref)`` as every controller:
    ``state`` (axes, 3) of [v, swing, swing_rate]; ``step`` returns the acceleration
    setpoint per axis.
    """

    output = "acceleration"

    def __init__(
        self,
        dynamics: Callable[[Any, Any], Any],
        settings: NmpcSettings | dict[str, Any] | None = None,
        axes: int = 1,
        lag: float = 0.0,
    ):
        import casadi as ca

        s = settings if isinstance(settings, NmpcSettings) else NmpcSettings.from_dict(settings)
        s.validate()
        if axes not in (1, 2):
            raise ConfigError(f"axes: must be 1 or 2 (got {axes!r})", field="axes")
        if not (math.isfinite(lag) and 0.0 <= lag <= 2.0):
            raise ConfigError(f"lag: must be in [0, 2] s (got {lag!r})", field="lag")
        self.settings = s
        self.axes = axes
        self.period = s.period
        ts, np_, nc = s.period, s.horizon, s.control_horizon
        # The attitude loop as a first-order lag: the acceleration reaching the vehicle a
        # follows the setpoint u, a⁺ = a + α (u − a), α = 1 − exp(−Ts/τ); the mechanics
        # see the tick's exact mean u + s (a − u) (lag_share). State [v, θ, θ̇, a];
        # τ = 0: a = u.
        self.alpha, share = lag_share(ts, lag)
        x = ca.SX.sym("x", 4)
        u = ca.SX.sym("u")
        d = ca.SX.sym("d", 2)

        def rhs(xx, uu, dd):
            f = dynamics(xx, uu + dd[0])
            return ca.vertcat(f[0], f[1], f[2] + dd[1])

        a_next = x[3] + self.alpha * (u - x[3])
        a_mean = u + share * (x[3] - u)
        xm = x[0:3]
        k1 = rhs(xm, a_mean, d)
        k2 = rhs(xm + ts / 2 * k1, a_mean, d)
        k3 = rhs(xm + ts / 2 * k2, a_mean, d)
        k4 = rhs(xm + ts * k3, a_mean, d)
        nxt = ca.vertcat(xm + ts / 6 * (k1 + 2 * k2 + 2 * k3 + k4), a_next)
        self._step_fn = ca.Function("step", [x, u, d], [nxt])
        uu = ca.SX.sym("U", nc)
        # Parameters: x0 (3), u_prev, swing one tick back, v_ref, lagged acceleration,
        # d (2).
        par = ca.SX.sym("p", 9)
        xk = ca.vertcat(par[0:3], par[6])
        swings = [par[4], par[1]]  # θ_{k−1}, θ_k
        res = []
        g_rate = s.w_swing_rate / (2 * ts)
        for i in range(np_):
            xk = self._step_fn(xk, uu[min(i, nc - 1)], par[7:9])
            res.append(s.w_velocity * (xk[0] - par[5]))
            res.append(g_rate * (xk[1] - swings[-2]))
            if s.w_swing > 0:
                res.append(s.w_swing * xk[1])
            swings.append(xk[1])
        for j in range(nc):
            prev = par[3] if j == 0 else uu[j - 1]
            res.append(s.w_acc_rate * (uu[j] - prev))
        r = ca.vertcat(*res)
        self._residual = ca.Function("residual", [uu, par], [r, ca.jacobian(r, uu)])
        self._nc = nc
        q_v, q_d, r_v = s.kf_process_noise, s.kf_disturbance_noise, s.kf_measurement_noise
        self._gain = _kalman_gain(ts, q_v, q_d, r_v)
        self._gain_swing = _kalman_gain(ts, q_v, s.kf_swing_disturbance_scale * q_d, r_v)
        self._u = np.zeros((axes, nc))
        self._d = np.zeros((axes, 2))
        self._u_prev = np.zeros(axes)
        self._swing_prev = np.zeros(axes)
        self._v_pred = np.full((axes, 2), math.nan)  # predicted v, θ̇
        self._a = np.zeros(axes)
        self.last_iterations = 0
        # The first solve imports SciPy's solver and runs CasADi's first evaluation (most
        # of a second): done here, so that the first tick in flight is like the others.
        self._gauss_newton(np.zeros(nc), [0.0] * 9)

    def reset(self, state: Any, acc: Any = None) -> None:
        """Start from a measured state (axes, 3) and acceleration setpoint (bumpless)."""
        st = np.asarray(state, dtype=float).reshape(self.axes, 3)
        a = np.zeros(self.axes) if acc is None else np.asarray(acc, dtype=float).reshape(-1)
        a = np.where(np.isfinite(a), a, 0.0)
        self._u_prev = a[: self.axes].copy()
        self._u = np.repeat(self._u_prev[:, None], self._nc, axis=1)
        self._swing_prev = st[:, 1].copy()
        self._d = np.zeros((self.axes, 2))
        self._a = self._u_prev.copy()
        self._v_pred = np.full((self.axes, 2), math.nan)

    def step(self, state: Any, vel_ref: Any) -> np.ndarray:
        """One tick: the acceleration setpoint per axis [m/s²]."""
        st = np.asarray(state, dtype=float).reshape(self.axes, 3)
        ref = np.asarray(vel_ref, dtype=float).reshape(-1)
        if not (np.all(np.isfinite(st)) and np.all(np.isfinite(ref)) and len(ref) == self.axes):
            raise ControlError(f"state {st!r} or reference {ref!r} not finite or wrong length")
        s = self.settings
        out = np.zeros(self.axes)
        for a in range(self.axes):
            if math.isfinite(self._v_pred[a, 0]):
                innov = st[a, [0, 2]] - self._v_pred[a]
                self._d[a] += (self._gain[1], self._gain_swing[1]) * innov
            x0 = st[a]
            par = [*x0, self._u_prev[a], self._swing_prev[a], ref[a], self._a[a], *self._d[a]]
            uu = np.concatenate([self._u[a, 1:], self._u[a, -1:]])
            uu = np.clip(uu, -s.acc_max, s.acc_max)
            uu, self.last_iterations = self._gauss_newton(uu, par)
            self._u[a] = uu
            out[a] = uu[0]
            x4 = [*x0, self._a[a]]
            nxt = np.asarray(self._step_fn(x4, uu[0], self._d[a]), dtype=float).reshape(-1)
            self._v_pred[a] = nxt[[0, 2]]
            self._a[a] = nxt[3]
            self._swing_prev[a] = x0[1]
            self._u_prev[a] = uu[0]
        return out

    def _gauss_newton(self, uu: np.ndarray, par: list[float]) -> tuple[np.ndarray, int]:
        """Minimise ‖r(U)‖² over |U| ≤ acc_max by Gauss–Newton steps, each a bounded
        linear least-squares problem (BVLS); stops when a step moves no input by 1e-7."""
        from scipy.optimize import lsq_linear

        lim = self.settings.acc_max
        for it in range(1, self.settings.max_iter + 1):
            r, jac = self._residual(uu, par)
            r = np.asarray(r, dtype=float).reshape(-1)
            jac = np.asarray(jac, dtype=float)
            if not (np.all(np.isfinite(r)) and np.all(np.isfinite(jac))):
                raise ControlError("NMPC: the model's prediction is not finite")
            lo, hi = -lim - uu, lim - uu
            step = lsq_linear(
                jac, -r, bounds=(np.minimum(lo, 0.0), np.maximum(hi, 0.0)), method="bvls"
            ).x
            uu = np.clip(uu + step, -lim, lim)
            if np.max(np.abs(step)) < 1e-7:
                return uu, it
        return uu, self.settings.max_iter

    def predicted_inputs(self) -> np.ndarray:
        """The Nc planned inputs of the last tick, (Nc, axes)."""
        return self._u.T.copy()
