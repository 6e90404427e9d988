"""Scenario loading: built-in bases, TOML files and dicts, merged and validated by the core.

A scenario file or dict overrides the command's built-in base key by key (tables merge,
everything else replaces), so ``[payload]\\nmass = 0.3`` alone keeps the default step. The
merge, the parsing and the checks are the core's (``_core.Scenario``); errors name the field.
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path
from typing import Any

from swingrt import _core
from swingrt.errors import ConfigError

#: A complete, validated scenario (the core object the simulator takes).
Scenario = _core.Scenario

#: What a scenario can be given as.
ScenarioLike = None | str | os.PathLike | dict | Scenario


def builtin(kind: str) -> Scenario:
    """A built-in scenario: ``step`` (simulate), ``training`` (collect) or ``hover``
    (the step scenario without a schedule: hold the start position)."""
    return Scenario.builtin(kind)


def scaled_inertia(nominal: dict[str, Any], mass: float, arm: float | None = None) -> list[float]:
    """The inertia [kg m²] of a vehicle like ``nominal`` (a scenario's ``vehicle`` table) that
    weighs ``mass`` [kg] on arms of ``arm`` [m] (``nominal``'s by default): the same mass
    distribution, so each moment scales with the mass and the arm squared. The one rule for
    a vehicle whose inertia is not known (a twin weighed at another mass, a vehicle read
    from PX4's parameters)."""
    scale = mass / float(nominal["mass"])
    if arm is not None:
        scale *= (arm / float(nominal["arm"])) ** 2
    return [i * scale for i in nominal["inertia"]]


def read_text(path: str | os.PathLike) -> str:
    """Read a TOML file's text (a scenario, a mission); a missing or undecodable file is a
    ``ConfigError``."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"file not found: {p}")
    try:
        return p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ConfigError(f"{p}: not a UTF-8 text file") from None


def read_toml(path: str | os.PathLike) -> dict[str, Any]:
    """Read a TOML file into a dict; syntax errors become ``ConfigError`` with the file name."""
    p = Path(path)
    try:
        return tomllib.loads(read_text(p))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: {exc}") from None


def resolve(
    config: ScenarioLike,
    *,
    default: str = "step",
    duration: float | None = None,
    seed: int | None = None,
) -> Scenario:
    """Turn ``config`` into a complete, validated scenario.

    ``config`` is None (the built-in ``default``), a :class:`Scenario`, a path to a TOML
    file, a TOML string or a dict (merged over ``default``); ``duration`` and ``seed``
    override the scenario's own.
    """
    if config is None:
        sc = Scenario.builtin(default)
    elif isinstance(config, Scenario):
        sc = config
    elif isinstance(config, dict):
        sc = Scenario.from_dict(config, base=default)
    elif isinstance(config, (str, os.PathLike)):
        text = str(config)
        if isinstance(config, os.PathLike) or text.endswith(".toml") or Path(text).is_file():
            over = read_toml(text)
        else:
            try:
                over = tomllib.loads(text)
            except tomllib.TOMLDecodeError as exc:
                raise ConfigError(f"scenario: {exc}", field="scenario") from None
        sc = Scenario.from_dict(over, base=default)
    else:
        raise ConfigError(
            f"scenario: expected None, a dict or a TOML path, got {type(config).__name__}",
            field="scenario",
        )
    over = {}
    if duration is not None:
        over["duration"] = float(duration)
    if seed is not None:
        if int(seed) < 0:
            raise ConfigError(f"seed: must be >= 0 (got {seed})", field="seed")
        over["seed"] = int(seed)
    return sc.with_overrides(over) if over else sc
