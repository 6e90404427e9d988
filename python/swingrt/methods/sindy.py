"""SINDy with control (pysindy) of the training flight, flown by the nonlinear MPC: the
SINDy-MPC of Kaiser, Kutz & Brunton ("Sparse identification of nonlinear dynamics for
model predictive control in the low-data limit", Proc. R. Soc. A 474, 2018).

Per axis the state x = [v, θ, θ̇] (velocity, swing, swing rate) and the input u (the
acceleration setpoint), resampled at the model's Ts, give ẋ = Ξᵀ Θ(x, u) with Θ the
polynomials of (x, u) up to a degree and Ξ sparse, found by sequentially thresholded
least squares (STLSQ, the paper's algorithm) with derivatives by finite differences.
The degree and the threshold are chosen on the part of the flight identification holds
out too: each
candidate is rolled out (RK4 at Ts) with the inputs flown from ``starts`` start points
over ``rollout`` seconds, and of those whose mean NMAE of v and θ is within
``parsimony`` of the best, the one with the fewest terms is taken.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from swingrt.errors import ConfigError, IdentificationError

__all__ = ["SindySettings", "SindyModel", "fit_sindy"]

#: State names of one axis, in the order of x.
STATE_NAMES = ("v", "s", "w")


@dataclass
class SindySettings:
    """SINDy settings (units in the field docs). Build with :meth:`from_dict`."""

    #: Candidate polynomial degrees of the library Θ(x, u) [-].
    degrees: tuple[int, ...] = (1, 2)
    #: Candidate STLSQ thresholds on the raw coefficients (smaller ones are zeroed) [-].
    thresholds: tuple[float, ...] = (0.01, 0.03, 0.1, 0.3, 1.0)
    #: Parsimony: the sparsest candidate whose held-out NMAE is within this factor of the
    #: best is taken [-].
    parsimony: float = 1.05
    #: Ridge weight of STLSQ [-].
    alpha: float = 1e-5
    #: Held-out rollout length for the threshold choice [s].
    rollout: float = 3.0
    #: Held-out start points [-].
    starts: int = 10

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None, section: str = "sindy") -> SindySettings:
        """Settings from a dict; unknown keys and bad values raise ConfigError naming the
        field."""
        d = dict(d or {})
        known = {f.name for f in fields(cls)}
        s = cls()
        for k, v in d.items():
            if k not in known:
                raise ConfigError(f"{section}.{k}: unknown setting", field=f"{section}.{k}")
            if k == "degrees":
                if not isinstance(v, (list, tuple)) or not v:
                    raise ConfigError(
                        f"{section}.degrees: must be a non-empty list of integers",
                        field=f"{section}.degrees",
                    )
                v = tuple(v)
            elif k == "thresholds":
                if not isinstance(v, (list, tuple)) or not v:
                    raise ConfigError(
                        f"{section}.thresholds: must be a non-empty list of numbers",
                        field=f"{section}.thresholds",
                    )
                v = tuple(float(x) for x in v)
            elif isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ConfigError(
                    f"{section}.{k}: must be a number (got {v!r})", field=f"{section}.{k}"
                )
            setattr(s, k, v)
        s.validate(section)
        return s

    def validate(self, section: str = "sindy") -> None:
        """Check ranges; the error names ``section.field``."""

        def bad(name: str, why: str) -> ConfigError:
            return ConfigError(
                f"{section}.{name}: {why} (got {getattr(self, name)!r})", field=f"{section}.{name}"
            )

        if not all(isinstance(d, int) and not isinstance(d, bool) and 1 <= d <= 4
                   for d in self.degrees):  # fmt: skip
            raise bad("degrees", "must be integers between 1 and 4")
        if not all(math.isfinite(t) and t >= 0 for t in self.thresholds):
            raise bad("thresholds", "must be finite and >= 0")
        if not (math.isfinite(self.parsimony) and self.parsimony >= 1):
            raise bad("parsimony", "must be >= 1")
        if not (math.isfinite(self.alpha) and self.alpha >= 0):
            raise bad("alpha", "must be >= 0")
        if not (math.isfinite(self.rollout) and self.rollout > 0):
            raise bad("rollout", "must be > 0")
        if not (isinstance(self.starts, int) and self.starts >= 1):
            raise bad("starts", "must be an integer >= 1")

    def to_dict(self) -> dict[str, Any]:
        """Every field as a dict."""
        d = asdict(self)
        d["thresholds"] = list(self.thresholds)
        d["degrees"] = list(self.degrees)
        return d


@dataclass
class SindyModel:
    """A fitted SINDYc model of one axis: ẋ = Ξᵀ Θ(x, u)."""

    #: Exponents of each library term over (v, θ, θ̇, u), (terms, 4).
    powers: np.ndarray
    #: Coefficients Ξ, (3, terms): rows v̇, θ̇, θ̈.
    coefficients: np.ndarray
    #: Sample time of the data [s].
    dt: float
    #: The threshold chosen and the held-out NMAE of each candidate (degree, threshold).
    threshold: float
    holdout_nmae: dict[tuple[int, float], float]
    #: Seconds of training flight and of fitting (threshold choice included).
    training_seconds: float
    fit_seconds: float
    #: Polynomial degree of the library [-].
    degree: int = 0

    def terms(self) -> list[str]:
        """The library's term names, e.g. ``s u`` or ``w^2``."""
        names = ("v", "s", "w", "u")
        out = []
        for row in self.powers:
            parts = [n if p == 1 else f"{n}^{p}" for n, p in zip(names, row, strict=True) if p]
            out.append(" ".join(parts) or "1")
        return out

    def coefficient(self, equation: int, term: str) -> float:
        """Coefficient of ``term`` in equation 0 (v̇), 1 (θ̇) or 2 (θ̈)."""
        return float(self.coefficients[equation, self.terms().index(term)])

    def active_terms(self, equation: int) -> list[str]:
        """Terms with a non-zero coefficient in an equation."""
        return [t for t, c in zip(self.terms(), self.coefficients[equation], strict=True) if c]

    def rhs_batch(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """ẋ for a batch: x (B, 3), u (B,) → (B, 3) (numpy)."""
        z = np.column_stack([x, u])
        feats = np.prod(z[:, None, :] ** self.powers[None, :, :], axis=2)
        return feats @ self.coefficients.T

    def rhs(self, x: Any, u: Any) -> Any:
        """ẋ for x = [v, θ, θ̇] and input u, on numpy or CasADi values."""
        import casadi as ca

        z = [x[0], x[1], x[2], u]
        feats = []
        for row in self.powers:
            f: Any = 1.0
            for var, p in zip(z, row, strict=True):
                if p:
                    f = f * var**p
            feats.append(f)
        out = []
        for eq in range(3):
            acc: Any = 0.0
            for c, f in zip(self.coefficients[eq], feats, strict=True):
                if c:
                    acc = acc + float(c) * f
            out.append(acc)
        if isinstance(x, np.ndarray):
            return np.asarray([float(o) for o in out])
        return ca.vertcat(*out)

    def to_dict(self) -> dict[str, Any]:
        """The model as plain data (terms, coefficients, threshold, timings)."""
        return {
            "terms": self.terms(),
            "coefficients": self.coefficients.tolist(),
            "dt": self.dt,
            "threshold": self.threshold,
            "degree": self.degree,
            "holdout_nmae": {f"{d}/{t:g}": v for (d, t), v in self.holdout_nmae.items()},
            "training_seconds": self.training_seconds,
            "fit_seconds": self.fit_seconds,
        }


def _rollout_nmae(
    model: SindyModel, x: np.ndarray, u: np.ndarray, steps: int, starts: int
) -> float:
    """Mean NMAE of v and θ of RK4 rollouts with the flown inputs (inf if one blows up)."""
    dt = model.dt
    n = len(x)
    if n < steps + 2:
        raise IdentificationError(f"held-out data of {n} samples shorter than one rollout")
    first = np.linspace(0, n - steps - 1, starts).astype(int)
    rng = np.ptp(x[:, :2], axis=0)
    rng = np.where(rng > 1e-9, rng, 1e-9)
    xk = x[first].copy()
    err = np.zeros(2)
    f = model.rhs_batch
    with np.errstate(all="ignore"):
        for i in range(steps):
            uk = u[first + i]
            k1 = f(xk, uk)
            k2 = f(xk + dt / 2 * k1, uk)
            k3 = f(xk + dt / 2 * k2, uk)
            k4 = f(xk + dt * k3, uk)
            xk = xk + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            if not np.all(np.isfinite(xk)) or np.max(np.abs(xk)) > 1e3:
                return math.inf
            err += np.abs(xk[:, :2] - x[first + i + 1, :2]).sum(axis=0)
    return float(np.mean(err / (len(first) * steps) / rng))


def fit_sindy(
    x_train: np.ndarray,
    u_train: np.ndarray,
    x_test: np.ndarray,
    u_test: np.ndarray,
    dt: float,
    settings: SindySettings | dict[str, Any] | None = None,
) -> SindyModel:
    """Fit the SINDYc model of one axis (module docs): ``x_*`` (N, 3) of [v, θ, θ̇],
    ``u_*`` (N,) acceleration setpoints at ``dt`` [s]."""
    import pysindy as ps

    s = settings if isinstance(settings, SindySettings) else SindySettings.from_dict(settings)
    t0 = time.perf_counter()
    x_train = np.asarray(x_train, dtype=float)
    u_train = np.asarray(u_train, dtype=float).reshape(-1, 1)
    if x_train.ndim != 2 or x_train.shape[1] != 3 or len(u_train) != len(x_train):
        raise IdentificationError("SINDy needs x (N, 3) of [v, swing, swing_rate] and u (N,)")
    if len(x_train) < 50 or not (np.all(np.isfinite(x_train)) and np.all(np.isfinite(u_train))):
        raise IdentificationError("SINDy needs at least 50 finite samples")
    steps = max(1, int(round(s.rollout / dt)))
    scores: dict[tuple[int, float], float] = {}
    cands: list[SindyModel] = []
    for deg, thr in ((d, t) for d in s.degrees for t in s.thresholds):
        lib = ps.PolynomialLibrary(degree=deg)
        opt = ps.STLSQ(threshold=thr, alpha=s.alpha)
        m = ps.SINDy(feature_library=lib, optimizer=opt)
        with warnings.catch_warnings():
            # A threshold that zeroes every term is a candidate like any other (it scores
            # badly); pysindy warns about it.
            warnings.simplefilter("ignore", UserWarning)
            m.fit(x_train, t=dt, u=u_train)
        cand = SindyModel(
            powers=np.asarray(lib.powers_, dtype=int),
            coefficients=np.asarray(m.coefficients(), dtype=float),
            dt=dt,
            threshold=thr,
            holdout_nmae={},
            training_seconds=len(x_train) * dt,
            fit_seconds=0.0,
        )
        cand.degree = deg
        scores[(deg, thr)] = _rollout_nmae(cand, x_test, u_test, steps, s.starts)
        cands.append(cand)
    top = min(scores.values())
    if not math.isfinite(top):
        raise IdentificationError("every SINDy candidate's held-out rollout diverged")

    def score(c: SindyModel) -> float:
        return scores[(c.degree, c.threshold)]

    near = [c for c in cands if score(c) <= s.parsimony * top]
    best = min(near, key=lambda c: (int(np.count_nonzero(c.coefficients)), score(c)))
    best.holdout_nmae = scores
    best.fit_seconds = time.perf_counter() - t0
    return best
