"""Scenario loading: built-in defaults, TOML files and dicts, validated by the Rust core.

A scenario file or dict overrides the command's built-in default key by key (tables merge,
everything else replaces), so ``[payload]\\nmass = 0.3`` alone keeps the default step. The
merged result is validated by the same serde struct as in Rust; errors name the field.
"""

from __future__ import annotations

import json
import math
import os
import tomllib
from pathlib import Path
from typing import Any

from swingrt import _core
from swingrt.errors import ConfigError

#: What a scenario can be given as.
ScenarioLike = None | str | os.PathLike | dict


def builtin(kind: str) -> dict[str, Any]:
    """A built-in scenario: ``step`` (simulate), ``training`` (collect) or ``hover``
    (the step scenario without a schedule: hold the start position)."""
    if kind == "hover":
        sc = json.loads(_core.default_scenario("step"))
        sc.update(name="hover", setpoints=[], duration=3600.0)
        return sc
    return json.loads(_core.default_scenario(kind))


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


def _check_finite(obj: Any, path: str = "") -> None:
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ConfigError(f"{path or 'value'}: must be a finite number (got {obj})")
    if isinstance(obj, dict):
        for k, v in obj.items():
            _check_finite(v, f"{path}.{k}" if path else str(k))
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _check_finite(v, f"{path}[{i}]")


def read_toml(path: str | os.PathLike) -> dict[str, Any]:
    """Read a TOML file into a dict; syntax errors become ``ConfigError`` with the file name."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"scenario file not found: {p}")
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: {exc}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{p}: not a UTF-8 text file") from None


def resolve(
    config: ScenarioLike,
    *,
    default: str = "step",
    duration: float | None = None,
    seed: int | None = None,
) -> dict[str, Any]:
    """Turn ``config`` into a complete, validated scenario dict.

    ``config`` is None (the built-in ``default``), a path to a TOML file, a TOML string or a
    dict; ``duration`` and ``seed`` override the scenario's own.
    """
    if config is None:
        over: dict[str, Any] = {}
    elif isinstance(config, dict):
        over = config
    elif isinstance(config, (str, os.PathLike)):
        text = str(config)
        if isinstance(config, os.PathLike) or text.endswith(".toml") or Path(text).is_file():
            over = read_toml(text)
        else:
            try:
                over = tomllib.loads(text)
            except tomllib.TOMLDecodeError as exc:
                raise ConfigError(f"scenario: {exc}") from None
    else:
        raise ConfigError(
            f"scenario: expected None, a dict or a TOML path, got {type(config).__name__}"
        )
    merged = _merge(builtin(default), over)
    if duration is not None:
        merged["duration"] = float(duration)
    if seed is not None:
        if int(seed) < 0:
            raise ConfigError(f"seed: must be >= 0 (got {seed})")
        merged["seed"] = int(seed)
    _check_finite(merged)
    return json.loads(_core.scenario_from_json(json.dumps(merged)))
