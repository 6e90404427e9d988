"""The field's other ways to stop a payload swinging, trained on the same flight and flown
through the same supervisor as PID, the LQR and the MPC (``swingrt experiment`` /
``swingrt campaign`` controller names):

- ``shaper`` / ``shaper_zv``: ZVD / ZV input shaping of PX4's velocity setpoint for the
  swing mode PX4's loop leaves in the identified model (``[shaper] source = "whitebox"``:
  in the estimated pendulum), no feedback (core ``control::shaper``);
- ``payload_p``: ArduPilot's slung-payload feedback on the velocity setpoint with the
  estimated cable length (core ``control::payload_p``);
- ``deepc``: DeePC on the Hankel matrices of the training flight (core ``control::deepc``);
- ``sindy_mpc``: the nonlinear MPC on a SINDYc model of the flight
  (:mod:`swingrt.methods.sindy`, :mod:`swingrt.methods.nmpc`);
- ``nmpc``: the nonlinear MPC on the white-box pendulum with the estimated parameters;
- ``havokc_mpc``: the MPC on the HAVOKc model (searched from the DMDc model's q and
  selected like the DMDc one).

:func:`train` learns what a method needs from the training flight (timed: the
identification time of the benchmark); :func:`attach` flies it in the simulator (core
controllers through ``Simulator.attach``, Python ones through ``Simulator.attach_python``);
:func:`controller` builds it for ``mavlink.offboard.fly``. Settings sections of an
experiment: ``[shaper]``, ``[payload_p]``, ``[deepc]`` (checked by the core),
``[nmpc]`` (also the SINDy-MPC's controller) and ``[sindy]`` (checked here).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swingrt.errors import ConfigError

__all__ = [
    "METHODS",
    "SECTIONS",
    "Trained",
    "attach",
    "check_settings",
    "needs_whitebox",
    "controller",
    "train",
]

#: Controller names this package adds.
METHODS = ("shaper", "shaper_zv", "payload_p", "deepc", "sindy_mpc", "nmpc", "havokc_mpc")
#: Experiment settings sections of the methods.
SECTIONS = ("shaper", "payload_p", "deepc", "nmpc", "sindy")
_CORE_SECTIONS = ("shaper", "payload_p", "deepc")


def needs_whitebox(name: str, sections: dict[str, dict[str, Any]] | None = None) -> bool:
    """Whether method ``name``, set by ``sections``, is trained on the white-box estimate
    (the payload-P law's cable length, the NMPC's pendulum, a shaper told to read it)."""
    if name in ("payload_p", "nmpc"):
        return True
    if name in ("shaper", "shaper_zv"):
        return check_settings("shaper", (sections or {}).get("shaper"))["source"] == "whitebox"
    return False


def check_settings(section: str, settings: dict[str, Any] | None) -> dict[str, Any]:
    """Check one methods section and return it with its defaults filled in
    (:class:`~swingrt.errors.ConfigError` naming ``section.field``)."""
    from swingrt import _core

    if section in _CORE_SECTIONS:
        return dict(_core.check_settings(section, settings or None))
    if section == "nmpc":
        from swingrt.methods.nmpc import NmpcSettings

        return NmpcSettings.from_dict(settings, section).to_dict()
    if section == "sindy":
        from swingrt.methods.sindy import SindySettings

        return SindySettings.from_dict(settings, section).to_dict()
    raise ConfigError(f"unknown methods section {section!r}", field=section)


@dataclass
class Trained:
    """What a method learned from the training flight."""

    #: Controller name (:data:`METHODS`).
    name: str
    #: Axes flown (1 or 2).
    axes: int
    #: The learned object: a ``LinearModel`` (havokc_mpc), the swing mode, the cable
    #: length, the DeePC data, the white-box parameters or the SINDy models.
    learned: Any
    #: Settings of the controller (checked).
    settings: dict[str, Any]
    #: Seconds of training flight the method read.
    training_seconds: float
    #: Wall-clock seconds the training took.
    ident_seconds: float
    #: What to report (mode, chosen regularisation, SINDy terms …).
    info: dict[str, Any] = field(default_factory=dict)


def _columns(train: Any, dt: float, names: list[str]) -> dict[str, np.ndarray]:
    """``names`` of a flight on a grid of ``dt``. A flight without the swing rate (a PX4
    ULog logs the angle only) gets it as the node computes it in flight: the backward
    difference of the swing over one tick."""
    from swingrt.sysid import _columns as cols
    from swingrt.sysid import resample

    have = cols(train)
    derived = [n for n in names if n.startswith("swing_rate_") and n not in have]
    wanted = [n for n in names if n not in derived]
    wanted += [f"swing_{n[-1]}" for n in derived if f"swing_{n[-1]}" not in wanted]
    out = resample(have, dt, wanted)
    for n in derived:
        swing = out[f"swing_{n[-1]}"]
        out[n] = np.r_[0.0, np.diff(swing)] / dt
    return out


def _split(n: int, dt: float) -> int:
    """Samples held out at the start (identification's ``test_span``)."""
    from swingrt.sysid import identify_settings

    return int(round(float(identify_settings()["test_span"]) / dt))


def _sample_time(identify: dict[str, Any] | None) -> float:
    """The identification's sample time [s]: ``identify``'s ``dt``, else the core's default
    (the white-box model's, which the selection's fallback shaper is closed at)."""
    from swingrt.sysid import identify_settings

    given = (identify or {}).get("dt")
    return float(given if given is not None else identify_settings()["dt"])


def _suffixes(axes: str) -> list[str]:
    return ["n"] if axes == "n" else ["n", "e"]


def train(
    name: str,
    flight: Any,
    *,
    axes: str = "n",
    sections: dict[str, dict[str, Any]] | None = None,
    model: Any = None,
    whitebox: dict[str, float] | None = None,
    px4: dict[str, Any] | None = None,
    identify: dict[str, Any] | None = None,
    mpc_settings: dict[str, Any] | None = None,
    twin: Any = None,
) -> Trained:
    """Learn what method ``name`` needs from the training ``flight`` (a Trace or columns):
    ``model`` is the DMDc model the MPC flies (the shaper's default mode source),
    ``whitebox`` the white-box estimate (``m_q``, ``m_p``, ``l``, ``c``), ``px4`` PX4's
    parameters of the training flight (the scenario's ``controller``), ``identify`` and
    ``mpc_settings`` the experiment's sections and ``twin`` its training scenario (for
    HAVOKc's selection, as the DMDc one)."""
    from swingrt import _core

    if name not in METHODS:
        raise ConfigError(f"unknown method {name!r} (one of {', '.join(METHODS)})", field=name)
    sections = sections or {}
    n_axes = len(_suffixes(axes))
    t_len = float(np.ptp(np.asarray(_cols_of(flight)["t"], dtype=float)))
    t0 = time.perf_counter()
    info: dict[str, Any] = {}
    if name in ("shaper", "shaper_zv"):
        s = check_settings("shaper", sections.get("shaper"))
        if name == "shaper_zv":
            s["kind"] = "zv"
        if s["source"] == "model":
            if model is None:
                raise ConfigError(
                    "shaper: source 'model' needs the identified model", field="model"
                )
            omega, zeta = _core.swing_mode(model=model, px4=px4)
        else:
            if whitebox is None:
                raise ConfigError("shaper: source 'whitebox' needs the white-box estimate")
            omega, zeta = _core.swing_mode(
                params=_pendulum(whitebox), dt=_sample_time(identify), px4=px4
            )
        learned: Any = (omega, zeta)
        info = {"omega": omega, "zeta": zeta, "kind": s["kind"], "source": s["source"]}
        used = t_len
    elif name == "payload_p":
        s = check_settings("payload_p", sections.get("payload_p"))
        if whitebox is None:
            raise ConfigError("payload_p needs the white-box cable length")
        learned = float(whitebox["l"])
        info = {"length": learned}
        used = t_len
    elif name == "nmpc":
        s = check_settings("nmpc", sections.get("nmpc"))
        if whitebox is None:
            raise ConfigError("nmpc needs the white-box estimate")
        lag = _lag(flight, axes, float(s["period"]))
        learned = (_pendulum(whitebox), lag)
        info = {**learned[0], "lag": lag}
        used = t_len
    elif name == "deepc":
        s = check_settings("deepc", sections.get("deepc"))
        dt = _sample_time(identify)
        names = []
        for a in _suffixes(axes):
            names += [f"acc_sp_{a}", f"v{a}", f"swing_{a}"]
        c = _columns(flight, dt, names)
        u = np.column_stack([c[f"acc_sp_{a}"] for a in _suffixes(axes)])
        y = np.column_stack([c[k] for a in _suffixes(axes) for k in (f"v{a}", f"swing_{a}")])
        k = _split(len(u), dt)
        learned = (u[k:], y[k:], u[:k], y[:k], dt)
        s, info = _deepc_choose(learned, s, whitebox, twin, axes)
        used = len(u[k:]) * dt
    elif name == "sindy_mpc":
        from swingrt.methods.sindy import fit_sindy

        s = check_settings("nmpc", sections.get("nmpc"))
        ss = check_settings("sindy", sections.get("sindy"))
        from swingrt.methods.nmpc import lagged

        dt = float(s["period"])
        lag = _lag(flight, axes, dt)
        models = []
        for a in _suffixes(axes):
            c = _columns(flight, dt, [f"v{a}", f"swing_{a}", f"swing_rate_{a}", f"acc_sp_{a}"])
            x = np.column_stack([c[f"v{a}"], c[f"swing_{a}"], c[f"swing_rate_{a}"]])
            # SINDy learns the mechanics from the acceleration the vehicle sees (the
            # setpoint through the attitude loop's lag, as the NMPC predicts it).
            u = lagged(c[f"acc_sp_{a}"], dt, lag)
            k = _split(len(u), dt)
            models.append(fit_sindy(x[k:], u[k:], x[:k], u[:k], dt, ss))
        learned = (models, lag)
        info = {
            "threshold": [m.threshold for m in models],
            "degree": [m.degree for m in models],
            "terms": [int(np.count_nonzero(m.coefficients)) for m in models],
            "lag": lag,
        }
        used = models[0].training_seconds
    else:  # havokc_mpc
        from swingrt.sysid import PLAN_KEYS, search, select_for_control

        s = dict(_core.check_settings("mpc", mpc_settings or None))
        opts = {k: v for k, v in (identify or {}).items() if k != "method" and k not in PLAN_KEYS}
        opts.pop("delays", None)
        # HAVOKc has no one-factorisation-per-q path: its full q grid costs ~30 s a flight.
        # It shares the delay embedding with DMDc, so its search starts from the DMDc
        # model's q (refined around it) and searches the rank there.
        start = [int(model.delays)] if model is not None else None
        result = search(flight, axes=axes, method="havokc", delays=start, **opts)
        if result.settings["select"] == "control":
            # The method is HAVOKc's MPC: where none passes it flies the least violating
            # one, not the selection's fallback shaper (a method of its own here).
            result = select_for_control(
                flight,
                result,
                axes=axes,
                mpc_settings=mpc_settings or None,
                twin=twin,
                fallback="none",
            )
        learned = result.model
        info = {"q": int(learned.delays), "p": int(learned.rank)}
        used = t_len - float(result.settings.get("test_span", 40.0))
    return Trained(name, n_axes, learned, s, used, time.perf_counter() - t0, info)


def _cols_of(flight: Any) -> Any:
    from swingrt.sysid import _columns as cols

    return cols(flight)


def _deepc_choose(
    data: tuple[Any, ...],
    s: dict[str, Any],
    whitebox: dict[str, float] | None,
    twin: Any,
    axes: str,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """DeePC's T_ini and λ_y by the held-out prediction error (core), λ_g by the step flight
    on the vehicle's twin: a held-out prediction with the future inputs given cannot see
    the optimiser exploit the data's noise directions (small λ_g predicts best and flies
    worst), a closed-loop flight does. Each λ_g of ``lambda_g_grid`` (``lambda_g`` when
    set) flies a 2 m/s step on the training flight's vehicle and PX4 carrying the
    white-box payload in still air; of those that settle (velocity within 5 % for good)
    the one with the least swing excess is taken, else the largest λ_g."""
    from swingrt import _core
    from swingrt.metrics import step_metrics

    grid = [s["lambda_g"]] if s.get("lambda_g") is not None else list(s["lambda_g_grid"])
    # T_ini and λ_y from the prediction error, at the most regularised λ_g.
    probe = _deepc(data, {**s, "lambda_g": max(grid)})
    fit = dict(probe.info()["fit"])
    base = {**s, "t_ini": fit["t_ini"], "lambda_y": fit["lambda_y"]}
    if len(grid) == 1 or twin is None or whitebox is None:
        return {**base, "lambda_g": max(grid)}, fit
    sc = _twin_step(twin, whitebox, axes)
    flown: dict[float, float] = {}
    for lg in grid:
        ctrl = _deepc(data, {**base, "lambda_g": lg})
        sim = _core.Simulator(sc)
        sim.attach(ctrl, 0.0, 1.0)
        sim.run_to_end()
        from swingrt.io.flight import Trace

        m = step_metrics(Trace(sim.take_trace(), {}), t0=2.0, axis="n" if axes == "n" else "ne")
        ok = np.isfinite(m["v_settle_s"]) and sim.fallback_reason is None
        flown[lg] = float(m["swing_excess_iae_deg_s"]) if ok else math.inf
    settled = [lg for lg in grid if math.isfinite(flown[lg])]
    lg = min(settled, key=lambda x: (flown[x], -x)) if settled else max(grid)
    probe = _deepc(data, {**base, "lambda_g": lg})
    fit = dict(probe.info()["fit"])
    fit["twin_swing_excess"] = {f"{k:g}": v for k, v in flown.items()}
    return {**base, "lambda_g": lg}, fit


def _deepc(data: tuple[Any, ...], settings: dict[str, Any]) -> Any:
    """The core DeePC controller on ``data`` = (u, y, u_test, y_test, dt)."""
    from swingrt import _core

    u, y, u_test, y_test, dt = data
    return _core.Controller.deepc(u, y, u_test, y_test, dt, settings)


def _twin_step(twin: Any, whitebox: dict[str, float], axes: str) -> Any:
    """The 2 m/s step on the training flight's vehicle and PX4 with the white-box payload,
    still air, no sensor noise, 20 s."""
    from swingrt.scenario import Scenario

    d = twin.to_dict()
    step = {"t": 2.0, "vn": 2.0, **({"ve": 0.0} if axes == "ne" else {})}
    start = {k: 0.0 for k in step} | {"t": 0.0}
    return Scenario.builtin("step").with_overrides(
        {
            "vehicle": d["vehicle"],
            "controller": d["controller"],
            "payload": {"kind": "single", "mass": whitebox["m_p"], "length": whitebox["l"]},
            "duration": 20.0,
            "seed": 0,
            "setpoints": [start, step],
        }
    )


def _lag(flight: Any, axes: str, dt: float) -> float:
    """The attitude loop's lag τ [s] from the training flight's first axis
    (:func:`swingrt.methods.nmpc.estimate_lag`)."""
    from swingrt.methods.nmpc import estimate_lag

    a = _suffixes(axes)[0]
    c = _columns(flight, dt, [f"v{a}", f"swing_{a}", f"acc_sp_{a}"])
    return estimate_lag(c[f"v{a}"], c[f"swing_{a}"], c[f"acc_sp_{a}"], dt)


def _pendulum(wb: dict[str, float]) -> dict[str, float]:
    return {k: float(wb[k]) for k in ("m_q", "m_p", "l", "c")}


def controller(trained: Trained) -> Any:
    """A fresh controller of ``trained`` with ``reset`` / ``step`` (and ``period``,
    ``axes``, ``output``): a core ``Controller``, the core ``Mpc`` (havokc_mpc) or the
    Python :class:`~swingrt.methods.nmpc.Nmpc`."""
    from swingrt import _core

    t = trained
    if t.name in ("shaper", "shaper_zv"):
        omega, zeta = t.learned
        return _core.Controller.shaper(omega, zeta, t.axes, t.settings)
    if t.name == "payload_p":
        return _core.Controller.payload_p(t.learned, t.axes, t.settings)
    if t.name == "deepc":
        return _deepc(t.learned, t.settings)
    if t.name == "havokc_mpc":
        return _core.Mpc(t.learned, t.settings)
    from swingrt.methods.nmpc import Nmpc, pendulum_dynamics

    if t.name == "nmpc":
        p, lag = t.learned
        f = pendulum_dynamics(p["m_q"], p["m_p"], p["l"], p["c"])
        return Nmpc(f, t.settings, t.axes, lag=lag)
    models, lag = t.learned
    if t.axes != 1:
        # One SINDy model per axis, each its own NMPC.
        return _PerAxis([Nmpc(m.rhs, t.settings, 1, lag=lag) for m in models])
    return Nmpc(models[0].rhs, t.settings, 1, lag=lag)


class _PerAxis:
    """Independent one-axis controllers side by side (two SINDy models)."""

    output = "acceleration"

    def __init__(self, ctrls: list[Any]):
        self.ctrls = ctrls
        self.axes = len(ctrls)
        self.period = ctrls[0].period

    def reset(self, state: Any, acc: Any = None) -> None:
        st = np.asarray(state, dtype=float).reshape(self.axes, 3)
        a = np.zeros(self.axes) if acc is None else np.asarray(acc, dtype=float).reshape(-1)
        for i, c in enumerate(self.ctrls):
            c.reset(st[i : i + 1], a[i : i + 1])

    def step(self, state: Any, vel_ref: Any) -> np.ndarray:
        st = np.asarray(state, dtype=float).reshape(self.axes, 3)
        r = np.asarray(vel_ref, dtype=float).reshape(-1)
        return np.concatenate(
            [c.step(st[i : i + 1], r[i : i + 1]) for i, c in enumerate(self.ctrls)]
        )


def attach(sim: Any, trained: Trained, engage_at: float, budget: float | None = None) -> None:
    """Fly ``trained`` in the core simulator from ``engage_at`` [s] under the supervisor;
    ``budget`` [s] per tick before the hand-back to PX4 (default: the tick period)."""
    from swingrt import _core

    ctrl = controller(trained)
    if isinstance(ctrl, _core.Mpc):
        period = trained.learned.dt
        sim.attach_mpc(trained.learned, trained.settings, engage_at, budget or period)
    elif isinstance(ctrl, _core.Controller):
        sim.attach(ctrl, engage_at, budget or ctrl.period)
    else:
        sim.attach_python(
            ctrl, ctrl.axes, ctrl.period, ctrl.output, engage_at, budget or ctrl.period
        )
