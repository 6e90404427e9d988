"""The experiment definition: its keys, the controllers it may compare, loading a built-in
or a TOML file, and the check of every settings section and scenario before anything flies."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

from swingrt.errors import ConfigError
from swingrt.experiments.scenarios import (
    cases,
    evaluation_scenario,
    oracle_training_scenario,
    training_scenario,
)
from swingrt.methods import METHODS
from swingrt.methods import SECTIONS as METHOD_SECTIONS
from swingrt.scenario import read_toml


def _defs() -> Traversable:
    """The folder of built-in experiment definitions (``swingrt/experiments/defs/*.toml``)."""
    return resources.files("swingrt.experiments").joinpath("defs")


_KNOWN_KEYS = {
    "name",
    "description",
    "axes",
    "controllers",
    "step",
    "duration",
    "prediction_figure",
    "common",
    "training",
    "evaluation",
    "grid",
    "identify",
    "selection",
    "mpc",
    "lqr",
    "training_duration",
    "adaptive",
    "cases",
    "tick_budget",
    *METHOD_SECTIONS,
}

#: Controllers an experiment can compare.
CONTROLLERS = ("pid", "lqr", "mpc", "mpc_adaptive", "mpc_oracle", *METHODS)

#: Keys of one entry of an experiment's ``[cases.<name>]`` table.
_CASE_KEYS = {"description", "common", "evaluation", "oracle", "step"}


@dataclass
class Experiment:
    """A parsed experiment definition (see ``swingrt.experiments``)."""

    name: str
    description: str = ""
    axes: str = "n"
    controllers: list[str] = field(default_factory=lambda: ["pid", "lqr", "mpc"])
    step: dict[str, float] = field(default_factory=lambda: {"t": 2.0, "vn": 2.0})
    duration: float = 30.0
    training_duration: float = 300.0
    prediction_figure: bool = False
    common: dict[str, Any] = field(default_factory=dict)
    training: dict[str, Any] = field(default_factory=dict)
    evaluation: dict[str, Any] = field(default_factory=dict)
    grid: dict[str, list[Any]] = field(default_factory=dict)
    identify: dict[str, Any] = field(default_factory=dict)
    #: The control-relevant selection's settings (``swing_core::design::SelectionSettings``:
    #: ``input_lags``, ``input_delays`` …), passed to :func:`swingrt.sysid.select_for_control`.
    selection: dict[str, Any] = field(default_factory=dict)
    mpc: dict[str, Any] = field(default_factory=dict)
    lqr: dict[str, Any] = field(default_factory=dict)
    adaptive: dict[str, Any] = field(default_factory=dict)
    cases: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Compute time a controller tick may take before the hand-back to PX4 [s] (None: its
    #: period, as in flight; a study that scores control apart from timing sets more).
    tick_budget: float | None = None
    shaper: dict[str, Any] = field(default_factory=dict)
    payload_p: dict[str, Any] = field(default_factory=dict)
    deepc: dict[str, Any] = field(default_factory=dict)
    nmpc: dict[str, Any] = field(default_factory=dict)
    sindy: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str) -> Experiment:
        """Validate a definition; errors name the key and the file."""
        unknown = sorted(set(d) - _KNOWN_KEYS)
        if unknown:
            raise ConfigError(f"{source}: unknown key {unknown[0]!r}")
        if "name" not in d:
            raise ConfigError(f"{source}: name: missing")
        exp = cls(**d)
        if exp.axes not in ("n", "ne"):
            raise ConfigError(f"{source}: axes: must be 'n' or 'ne' (got {exp.axes!r})")
        for c in exp.controllers:
            if c not in CONTROLLERS:
                raise ConfigError(f"{source}: controllers: unknown controller {c!r}")
        if exp.cases and exp.grid:
            raise ConfigError(f"{source}: cases: cannot be combined with grid")
        for name, spec in exp.cases.items():
            if not isinstance(spec, dict):
                raise ConfigError(f"{source}: cases.{name}: must be a table")
            bad = sorted(set(spec) - _CASE_KEYS)
            if bad:
                raise ConfigError(f"{source}: cases.{name}: unknown key {bad[0]!r}")
            if "mpc_oracle" in exp.controllers and "oracle" not in spec:
                raise ConfigError(
                    f"{source}: cases.{name}.oracle: needed for mpc_oracle (the training "
                    "flight's overrides after the change)"
                )
        if not (isinstance(exp.duration, (int, float)) and exp.duration > exp.step.get("t", 0)):
            raise ConfigError(f"{source}: duration: must be longer than the step time")
        for k, v in exp.grid.items():
            if not isinstance(v, list) or not v:
                raise ConfigError(f"{source}: grid.{k}: must be a non-empty list")
        exp.check(source)
        return exp

    def with_controllers(self, controllers: list[str]) -> Experiment:
        """This experiment flying only ``controllers`` (a subset of its own, already checked)."""
        unknown = [c for c in controllers if c not in self.controllers]
        if unknown:
            raise ConfigError(f"{self.name}: controllers: {unknown[0]!r} is not flown here")
        return replace(self, controllers=list(controllers))

    def check(self, source: str) -> None:
        """Validate every settings section and every case's scenarios in the core, so a typo
        fails before anything flies; errors name the file and the dotted field."""
        from swingrt import _core

        try:
            from swingrt.sysid import PLAN_KEYS, TWINS

            ident = {k: v for k, v in self.identify.items() if k not in PLAN_KEYS}
            if not isinstance(self.identify.get("search", True), bool):
                raise ConfigError("identify.search: must be true or false", field="identify.search")
            twin = self.identify.get("twin", "exact")
            if twin not in TWINS:
                raise ConfigError(
                    f"identify.twin: one of {', '.join(TWINS)}, not {twin!r}", field="identify.twin"
                )
            _core.check_settings("identify", ident)
            if "plant_label" in self.selection:
                raise ConfigError(
                    "selection.plant_label: set by the selection, not by a study",
                    field="selection.plant_label",
                )
            _core.check_settings("selection", self.selection)
            _core.check_settings("mpc", self.mpc)
            _core.check_settings("lqr", self.lqr)
            _core.check_settings("adaptive", self.adaptive)
            from swingrt.methods import check_settings as check_method

            for sec in METHOD_SECTIONS:
                check_method(sec, getattr(self, sec))
            tb = self.tick_budget
            if tb is not None and not (
                isinstance(tb, (int, float)) and not isinstance(tb, bool) and 0 < tb <= 60
            ):
                raise ConfigError(
                    f"tick_budget: must be a number of seconds in (0, 60] (got {tb!r})",
                    field="tick_budget",
                )
            for case, over in cases(self):
                try:
                    train = training_scenario(self, over, 0)
                    evaluation_scenario(self, over, 0, train, case=case)
                    if "oracle" in self.cases.get(case, {}):
                        oracle_training_scenario(self, case, over, 0)
                except ConfigError as exc:
                    raise ConfigError(f"case {case}: {exc}", field=exc.field) from None
        except ConfigError as exc:
            raise ConfigError(f"{source}: {exc}", field=exc.field) from None


def list_experiments() -> dict[str, str]:
    """Built-in experiment names and descriptions."""
    out = {}
    for f in sorted(_defs().iterdir(), key=lambda p: p.name):
        if f.name.endswith(".toml"):
            d = tomllib.loads(f.read_text(encoding="utf-8"))
            out[d["name"]] = d.get("description", "")
    return out


def load_experiment(name_or_path: str) -> Experiment:
    """A built-in experiment by name, or a TOML file."""
    p = Path(name_or_path)
    if name_or_path.endswith(".toml") or p.is_file():
        return Experiment.from_dict(read_toml(p), str(p))
    f = _defs() / f"{name_or_path}.toml"
    if not f.is_file():
        names = ", ".join(list_experiments())
        raise ConfigError(f"unknown experiment {name_or_path!r} (built in: {names})")
    return Experiment.from_dict(tomllib.loads(f.read_text(encoding="utf-8")), f.name)
