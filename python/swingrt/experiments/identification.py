"""The identification of an experiment's case: the model for the MPC (search and the
control-relevant selection), the white-box estimates for the LQR, and what each method of
:mod:`swingrt.methods` learns from the same training flight."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from swingrt.errors import DataError, IdentificationError
from swingrt.io.flight import Trace
from swingrt.methods import METHODS
from swingrt.methods import SECTIONS as METHOD_SECTIONS
from swingrt.scenario import Scenario

if TYPE_CHECKING:
    from swingrt.experiments.schema import Experiment


def identify_case(
    train: Trace, exp: Experiment, plots: Path | None = None, vehicle: Scenario | None = None
) -> tuple[Any, Any | None, dict[str, float] | None]:
    """DMDc (with search) for the MPC, white-box estimates for the LQR; with ``plots`` the
    search's error-vs-q plot (the Pareto elbow) is written there. ``vehicle`` (the training
    flight's scenario) describes the vehicle: its mass is the white-box's ``vehicle_mass``
    unless ``[identify]`` gives one, and the control-relevant selection flies the twin that
    ``[identify] twin`` names (:func:`case_twin`), with ``[selection]``'s settings.

    The data-driven model never waits on the white-box: when the white-box cannot be
    estimated (a payload mass that comes out non-positive, no swing peak), the white-box
    and the LQR parameters are ``None`` and the model's ``diagnostics['whitebox_skipped']``
    says why."""
    from swingrt.reports import plot_pareto
    from swingrt.sysid import identify, lqr_parameters, search, select_for_control

    known = case_vehicle_mass(exp, vehicle)
    mass = {} if known is None else {"vehicle_mass": known}
    opts = {"method": "dmdc", **exp.identify, **mass}
    opts.pop("twin", None)
    if opts.pop("search", True) and "delays" not in opts:
        result = search(train, axes=exp.axes, **opts)
        if "mpc" in exp.controllers and result.settings["select"] == "control":
            result = select_for_control(
                train,
                result,
                axes=exp.axes,
                mpc_settings=exp.mpc or None,
                twin=case_twin(exp, vehicle),
                **exp.selection,
            )
        model = result.model
        if plots is not None:
            plot_pareto(result, plots)
    else:
        model = identify(train, axes=exp.axes, **opts)
    wb_opts = {k: exp.identify[k] for k in _WHITEBOX_KEYS if k in exp.identify}
    try:
        wb = identify(train, method="whitebox", axes=exp.axes, **{**mass, **wb_opts})
    except (DataError, IdentificationError) as exc:
        assumed = opts.get("vehicle_mass")
        told = "the default vehicle mass" if assumed is None else f"vehicle mass {assumed:g} kg"
        why = f"white-box not estimated with {told}: {exc}"
        return model.with_diagnostics({"whitebox_skipped": why}), None, None
    return model, wb, lqr_parameters(wb)


def without_whitebox(exp: Experiment, model: Any, lqr: dict[str, float] | None) -> dict[str, str]:
    """The controllers of ``exp`` that cannot fly without the white-box estimate when there
    is none (the LQR, and the methods trained on it), with the reason."""
    if lqr is not None:
        return {}
    from swingrt.methods import METHODS, SECTIONS, needs_whitebox

    why = str(model.diagnostics.get("whitebox_skipped", "no white-box estimate"))
    sections = {s: getattr(exp, s) for s in SECTIONS}
    adaptive_twin = bool((exp.adaptive or {}).get("twin", {}).get("enabled", False))
    return {
        c: why
        for c in exp.controllers
        if c == "lqr"
        or (c == "mpc_adaptive" and adaptive_twin)
        or (c in METHODS and needs_whitebox(c, sections))
    }


def case_twin(exp: Experiment, vehicle: Scenario | None) -> Scenario | str | None:
    """The twin the selection of ``exp`` flies, as ``[identify] twin`` says
    (:data:`swingrt.sysid.TWINS`; default ``"exact"``): the training flight's own
    ``vehicle``, the built-in one (``"builtin"``: a twin that is not the plant, as a user
    without a description of the vehicle has: weighed at the identification's vehicle mass
    and flown under the training flight's PX4 gains, which its log's parameters give) or
    none."""
    from swingrt.sysid import PX4_GAINS, builtin_twin, identify_settings

    choice = exp.identify.get("twin", "exact")
    if choice == "off":
        return None
    if choice == "builtin":
        if vehicle is None:
            return "builtin"
        mass = case_vehicle_mass(exp, vehicle)
        if mass is None:
            mass = identify_settings()["vehicle_mass"]
        controller = vehicle.to_dict()["controller"]
        return builtin_twin(mass, {k: controller[k] for k in PX4_GAINS})
    return vehicle


#: What ``[identify]`` may say of the vehicle and payload that the white-box uses too.
_WHITEBOX_KEYS = ("vehicle_mass", "payload_mass", "cable_length")


def case_vehicle_mass(exp: Experiment, vehicle: Scenario | None) -> float | None:
    """The vehicle mass [kg] the identification of ``exp`` knows: ``[identify]
    vehicle_mass`` if given, else the mass ``vehicle`` describes, else none (the
    identification's default then)."""
    given = exp.identify.get("vehicle_mass")
    if given is not None:
        return float(given)
    if vehicle is None:
        return None
    mass = vehicle.to_dict().get("vehicle", {}).get("mass")
    return None if mass is None else float(mass)


def train_methods(
    train: Trace,
    exp: Experiment,
    model: Any,
    lqr: dict[str, float] | None,
    vehicle: Scenario | None,
) -> dict[str, Any]:
    """What each controller of :mod:`swingrt.methods` in ``exp.controllers`` learns from
    the training flight (:func:`swingrt.methods.train`), by name: ``vehicle`` (the training
    flight's scenario) gives PX4's gains, and the selections fly :func:`case_twin`."""
    from swingrt.methods import train as train_method

    px4 = vehicle.to_dict().get("controller") if vehicle is not None else None
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
            twin=case_twin(exp, vehicle),
        )
        for c in exp.controllers
        if c in METHODS
    }
