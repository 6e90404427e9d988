"""One scenario flown with one of an experiment's controllers (PX4 PID, LQR, MPC, adaptive
MPC, oracle MPC, the methods of :mod:`swingrt.methods`): the dispatch from the controller's
name to the simulator's attach call."""

from __future__ import annotations

from typing import Any

import numpy as np

from swingrt.errors import ConfigError
from swingrt.io.flight import Trace
from swingrt.methods import METHODS
from swingrt.scenario import Scenario
from swingrt.sysid import LinearModel


def simulate_controller(
    scenario: Scenario,
    controller: str,
    *,
    axes: str = "n",
    model: LinearModel | None = None,
    lqr_params: dict[str, float] | None = None,
    mpc_settings: dict[str, Any] | None = None,
    lqr_settings: dict[str, Any] | None = None,
    adaptive_settings: dict[str, Any] | None = None,
    engage_at: float = 0.0,
    prediction_at: float | None = None,
    twin: Scenario | None = None,
    method: Any = None,
    budget: float | None = None,
) -> tuple[Trace, dict[str, Any]]:
    """Fly one scenario with a controller of :data:`CONTROLLERS` on the given axes
    (``mpc_oracle`` is the MPC on whatever ``model`` it is given). ``twin`` (the training
    flight's scenario) lets ``mpc_adaptive`` re-identify on the vehicle's twin for the
    payload it measures, starting from the white-box ``lqr_params`` (``m_q``, ``m_p``,
    ``l``) of the training flight, when ``adaptive_settings`` enable it.

    The controllers of :mod:`swingrt.methods` fly what ``method`` (their
    :class:`~swingrt.methods.Trained`) learned. ``budget`` [s] is the compute time a tick
    may take before the hand-back to PX4 (default: the controller's period).

    A scenario without a swing sensor (``sensors.swing = "imu"``) flies with the swing
    estimator the ``model`` was identified with (:func:`swingrt.sysid.model_estimator`).

    Returns the trace and extras: fallback reason, tick timings, the controller's events
    (time [s], what, value) and (``prediction_at``) the MPC's predicted outputs from the
    first tick at or after that time.
    """
    from swingrt import _core
    from swingrt.sysid import model_estimator

    est = None if model is None else model_estimator(model)
    if est is not None and scenario.to_dict()["sensors"]["swing"] == "imu":
        # A flight without a swing sensor estimates the swing as the model's output was
        # estimated (its scale and drag), whichever controller flies it.
        scenario = scenario.with_overrides({"sensors": {"estimator": est}})
    sim = _core.Simulator(scenario)
    n_axes = len(axes)
    extras: dict[str, Any] = {}
    if controller in ("mpc", "mpc_oracle", "mpc_adaptive"):
        if model is None:
            raise ConfigError(f"{controller} needs an identified model", field="model")
        # The budget of one tick is its period.
        if controller == "mpc_adaptive":
            use_twin = bool((adaptive_settings or {}).get("twin", {}).get("enabled", False))
            if use_twin and (twin is None or lqr_params is None):
                raise ConfigError(
                    "adaptive.twin.enabled needs the training scenario and the white-box "
                    "estimate of the training payload",
                    field="adaptive.twin",
                )
            prior = (
                (float(lqr_params["m_p"]), float(lqr_params["l"]), float(lqr_params["m_q"]))
                if use_twin and lqr_params is not None
                else None
            )
            sim.attach_adaptive_mpc(
                model,
                mpc_settings or None,
                adaptive_settings or None,
                engage_at,
                budget or model.dt,
                twin if use_twin else None,
                prior,
            )
        else:
            sim.attach_mpc(model, mpc_settings or None, engage_at, budget or model.dt)
    elif controller in METHODS:
        from swingrt.methods import attach

        if method is None or method.name != controller:
            raise ConfigError(f"{controller} needs what it learned from the training flight")
        attach(sim, method, engage_at, budget)
    elif controller == "lqr":
        if lqr_params is None:
            raise ConfigError("lqr needs the white-box parameters", field="lqr_params")
        lqr = _core.check_settings("lqr", lqr_settings or None)
        # The budget of one tick is its period.
        sim.attach_lqr(lqr_params, n_axes, lqr, engage_at, budget or lqr["period"])
    elif controller != "pid":
        raise ConfigError(f"unknown controller {controller!r}", field="controller")
    if prediction_at is not None and model is not None and controller.startswith("mpc"):
        sim.advance(prediction_at)
        sim.advance(model.dt)
        pred = sim.controller_prediction()
        if pred is not None:
            extras["prediction"] = {"t0": sim.t, "outputs": np.asarray(pred)}
    sim.run_to_end()
    trace = Trace(sim.take_trace(), {"scenario": scenario.to_dict(), "controller": controller})
    extras["fallback"] = sim.fallback_reason
    extras["events"] = sim.controller_events()
    ticks = np.asarray(sim.tick_times())
    if len(ticks):
        extras["tick_us_median"] = float(np.median(ticks))
        extras["tick_us_p99"] = float(np.percentile(ticks, 99))
        extras["constrained_ticks"] = int(sim.constrained_ticks)
    return trace, extras
