"""The identification of an experiment's case: the model for the MPC (search and the
control-relevant selection), the white-box estimates for the LQR, and what each method of
:mod:`swingrt.methods` learns from the same training flight."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from swingrt.io.flight import Trace
from swingrt.methods import METHODS
from swingrt.methods import SECTIONS as METHOD_SECTIONS
from swingrt.scenario import Scenario

if TYPE_CHECKING:
    from swingrt.experiments.schema import Experiment


def identify_case(
    train: Trace, exp: Experiment, plots: Path | None = None, twin: Scenario | None = None
) -> tuple[Any, Any, dict[str, float]]:
    """DMDc (with search) for the MPC, white-box estimates for the LQR; with ``plots`` the
    search's error-vs-q plot (the Pareto elbow) is written there. ``twin`` (the training
    flight's scenario) adds the twin step flight to the control-relevant selection."""
    from swingrt.reports import plot_pareto
    from swingrt.sysid import identify, search, select_for_control

    opts = {"method": "dmdc", **exp.identify}
    if opts.pop("search", True) and "delays" not in opts:
        result = search(train, axes=exp.axes, **opts)
        if "mpc" in exp.controllers and result.settings["select"] == "control":
            result = select_for_control(
                train, result, axes=exp.axes, mpc_settings=exp.mpc or None, twin=twin
            )
        model = result.model
        if plots is not None:
            plot_pareto(result, plots)
    else:
        model = identify(train, axes=exp.axes, **opts)
    wb = identify(train, method="whitebox", axes=exp.axes)
    est = wb.diagnostics["whitebox"]
    lqr = {
        "m_q": float(est["vehicle_mass"]),
        "m_p": float(est["payload_mass"]),
        "l": float(est["length"]),
        "c": float(est.get("friction", 0.0)),
    }
    return model, wb, lqr


def train_methods(
    train: Trace, exp: Experiment, model: Any, lqr: dict[str, float], twin: Scenario | None
) -> dict[str, Any]:
    """What each controller of :mod:`swingrt.methods` in ``exp.controllers`` learns from
    the training flight (:func:`swingrt.methods.train`), by name."""
    from swingrt.methods import train as train_method

    px4 = twin.to_dict().get("controller") if twin is not None else None
    sections = {s: getattr(exp, s) for s in METHOD_SECTIONS}
    return {
        c: train_method(
            c,
            train,
            axes=exp.axes,
            sections=sections,
            model=model,
            whitebox=lqr,
            px4=px4,
            identify=exp.identify,
            mpc_settings=exp.mpc or None,
            twin=twin,
        )
        for c in exp.controllers
        if c in METHODS
    }
