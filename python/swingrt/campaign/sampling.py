"""Distributions of a campaign's ``[vary]`` keys, and the draw of one sample.

Each ``[vary]`` value is a table with ``dist`` and its parameters:

- ``uniform``: ``low``, ``high`` (numbers or equal-length vectors), low <= high;
- ``loguniform``: ``low``, ``high`` > 0 (numbers or vectors); log-uniform between them;
- ``normal``: ``mean``, ``std`` >= 0 (numbers or vectors of one length), optional ``low`` /
  ``high`` clip;
- ``choice``: ``values`` (a non-empty list), optional ``weights`` (one per value, >= 0,
  not all zero);
- ``grid``: ``values``; sample ``i`` takes them in turn, the grid keys together forming a
  full product (the first grid key varies slowest), so ``samples`` = the product's size
  covers it once;
- ``fixed``: ``value``.

A bare list is ``choice`` with equal weights; a bare number, string or boolean is
``fixed``. Every key draws from its own generator ``numpy.random.default_rng([seed, index,
crc32(key)])``, so a sample depends on (seed, index) alone, and adding a key does not
change the values the others draw.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from swingrt.errors import ConfigError

DISTRIBUTIONS = ("uniform", "loguniform", "normal", "choice", "grid", "fixed")


@dataclass(frozen=True)
class Distribution:
    """One parsed ``[vary]`` distribution (``params`` as checked by :func:`parse_distribution`)."""

    kind: str
    params: dict[str, Any]


def _vector(v: Any, name: str, where: str) -> np.ndarray:
    if isinstance(v, bool):
        raise ConfigError(f"{where}: {name} must be a number or a list of numbers", field=where)
    if isinstance(v, (int, float)):
        arr = np.asarray(float(v))
    elif (
        isinstance(v, list)
        and v
        and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
    ):
        arr = np.asarray(v, dtype=float)
    else:
        raise ConfigError(
            f"{where}: {name} must be a number or a list of numbers (got {v!r})", field=where
        )
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{where}: {name} must be finite (got {v!r})", field=where)
    return arr


def _same_shape(where: str, **arrays: np.ndarray) -> None:
    shapes = {a.shape for a in arrays.values() if a.ndim}
    if len(shapes) > 1:
        names = " and ".join(arrays)
        raise ConfigError(f"{where}: {names} must have the same length", field=where)


def parse_distribution(spec: Any, where: str) -> Distribution:
    """Check one ``[vary]`` value; errors name ``where`` (``vary.<key>``)."""
    if isinstance(spec, list):
        spec = {"dist": "choice", "values": spec}
    elif not isinstance(spec, dict):
        spec = {"dist": "fixed", "value": spec}
    kind = spec.get("dist")
    if kind not in DISTRIBUTIONS:
        raise ConfigError(
            f"{where}: unknown distribution {kind!r} (one of {', '.join(DISTRIBUTIONS)})",
            field=where,
        )
    allowed = {
        "uniform": {"low", "high"},
        "loguniform": {"low", "high"},
        "normal": {"mean", "std", "low", "high"},
        "choice": {"values", "weights"},
        "grid": {"values"},
        "fixed": {"value"},
    }[kind]
    required = {
        "uniform": {"low", "high"},
        "loguniform": {"low", "high"},
        "normal": {"mean", "std"},
        "choice": {"values"},
        "grid": {"values"},
        "fixed": {"value"},
    }[kind]
    extra = sorted(set(spec) - allowed - {"dist"})
    if extra:
        raise ConfigError(f"{where}: {kind} has no parameter {extra[0]!r}", field=where)
    missing = sorted(required - set(spec))
    if missing:
        raise ConfigError(f"{where}: {kind} needs {missing[0]!r}", field=where)
    p = {k: v for k, v in spec.items() if k != "dist"}
    if kind in ("uniform", "loguniform"):
        lo, hi = _vector(p["low"], "low", where), _vector(p["high"], "high", where)
        _same_shape(where, low=lo, high=hi)
        if np.any(lo > hi):
            raise ConfigError(f"{where}: low must not exceed high", field=where)
        if kind == "loguniform" and np.any(lo <= 0):
            raise ConfigError(f"{where}: loguniform needs low > 0", field=where)
    elif kind == "normal":
        mean, std = _vector(p["mean"], "mean", where), _vector(p["std"], "std", where)
        _same_shape(where, mean=mean, std=std)
        if np.any(std < 0):
            raise ConfigError(f"{where}: std must be >= 0", field=where)
        for b in ("low", "high"):
            if b in p:
                _same_shape(where, mean=mean, **{b: _vector(p[b], b, where)})
        if (
            "low" in p
            and "high" in p
            and np.any(_vector(p["low"], "low", where) > _vector(p["high"], "high", where))
        ):
            raise ConfigError(f"{where}: low must not exceed high", field=where)
    elif kind in ("choice", "grid"):
        values = p["values"]
        if not isinstance(values, list) or not values:
            raise ConfigError(f"{where}: values must be a non-empty list", field=where)
        if "weights" in p:
            w = p["weights"]
            if (
                not isinstance(w, list)
                or len(w) != len(values)
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in w)
            ):
                raise ConfigError(f"{where}: weights must be one number per value", field=where)
            if any(not math.isfinite(x) or x < 0 for x in w) or sum(w) <= 0:
                raise ConfigError(
                    f"{where}: weights must be finite, >= 0 and not all zero", field=where
                )
    return Distribution(kind, p)


def _native(x: np.ndarray) -> Any:
    return float(x) if x.ndim == 0 else [float(v) for v in x]


def _sample(d: Distribution, rng: np.random.Generator) -> Any:
    p = d.params
    if d.kind == "fixed":
        return p["value"]
    if d.kind == "uniform":
        lo, hi = np.asarray(p["low"], float), np.asarray(p["high"], float)
        shape = np.broadcast(lo, hi).shape
        return _native(lo + (hi - lo) * rng.random(shape))
    if d.kind == "loguniform":
        lo, hi = np.log(np.asarray(p["low"], float)), np.log(np.asarray(p["high"], float))
        shape = np.broadcast(lo, hi).shape
        return _native(np.exp(lo + (hi - lo) * rng.random(shape)))
    if d.kind == "normal":
        mean, std = np.asarray(p["mean"], float), np.asarray(p["std"], float)
        shape = np.broadcast(mean, std).shape
        x = mean + std * rng.standard_normal(shape)
        if "low" in p or "high" in p:
            x = np.clip(x, p.get("low", -np.inf), p.get("high", np.inf))
        return _native(np.asarray(x))
    if d.kind == "choice":
        values = p["values"]
        w = np.asarray(p.get("weights", [1.0] * len(values)), float)
        return values[int(rng.choice(len(values), p=w / w.sum()))]
    raise AssertionError(d.kind)  # grid is drawn by draw()


def draw(vary: dict[str, Distribution], seed: int, index: int) -> dict[str, Any]:
    """The values of sample ``index``: dotted key → value (plain Python: float, list of
    floats, or a ``values`` entry), from (seed, index) alone."""
    out: dict[str, Any] = {}
    stride = 1
    grids = [(k, d) for k, d in vary.items() if d.kind == "grid"]
    for k, d in reversed(grids):
        n = len(d.params["values"])
        out[k] = d.params["values"][(index // stride) % n]
        stride *= n
    for k, d in vary.items():
        if d.kind != "grid":
            rng = np.random.default_rng([seed, index, zlib.crc32(k.encode())])
            out[k] = _sample(d, rng)
    return {k: out[k] for k in vary}


def bound(d: Distribution, which: str) -> Any:
    """The ``low`` or ``high`` end of a distribution (mean ∓ 3 std for ``normal``, the
    first / last value for ``choice`` and ``grid``), for checking settings at load time."""
    p = d.params
    hi = which == "high"
    if d.kind == "fixed":
        return p["value"]
    if d.kind in ("uniform", "loguniform"):
        return _native(np.asarray(p["high" if hi else "low"], float))
    if d.kind == "normal":
        mean, std = np.asarray(p["mean"], float), np.asarray(p["std"], float)
        x = mean + (3.0 if hi else -3.0) * std
        x = np.clip(x, p.get("low", -np.inf), p.get("high", np.inf))
        return _native(np.asarray(x))
    return p["values"][-1 if hi else 0]


def grid_size(vary: dict[str, Distribution]) -> int:
    """The number of points of the product of the ``grid`` keys (1 without any)."""
    n = 1
    for d in vary.values():
        if d.kind == "grid":
            n *= len(d.params["values"])
    return n
