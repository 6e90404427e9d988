"""PX4 parameters from a flight log or a parameter file.

A ULog carries every parameter at the start of logging and each change during the flight;
the values in force at the end are returned. A parameter file is QGroundControl's export
(``#`` comments, then tab-separated vehicle id, component id, name, value, type) or plain
``NAME VALUE`` lines (as ``param show`` prints them, commas allowed).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from swingrt.errors import DataError

__all__ = ["read_px4_parameters"]

_NAME = re.compile(r"^[A-Z][A-Z0-9_]{0,15}$")


def read_px4_parameters(path: str | os.PathLike[str]) -> dict[str, float]:
    """``{name: value}`` of the PX4 parameters in ``path`` (``.ulg``, else a parameter file)."""
    p = Path(path)
    if not p.is_file():
        raise DataError(f"{p}: no such file", path=p)
    if p.suffix.lower() == ".ulg":
        return _from_ulog(p)
    return _from_text(p)


def _from_ulog(p: Path) -> dict[str, float]:
    from pyulog import ULog

    try:
        # Our own handle, closed when pyulog fails half-way; no topics: parameters only.
        with open(p, "rb") as fh:
            log = ULog(fh, [])
    except Exception as exc:  # pyulog raises bare Exception / struct.error on bad files
        raise DataError(f"{p}: not a readable ULog file ({exc})", path=p) from None
    params = {str(k): float(v) for k, v in log.initial_parameters.items()}
    for _, name, value in sorted(log.changed_parameters, key=lambda c: c[0]):
        params[str(name)] = float(value)
    if not params:
        raise DataError(f"{p}: the log holds no parameters", path=p)
    return params


def _from_text(p: Path) -> dict[str, float]:
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{p}: cannot read a parameter file ({exc})", path=p) from None
    params: dict[str, float] = {}
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.replace(",", " ").split()
        # QGroundControl: vehicle id, component id, name, value, type.
        name, value = (fields[2], fields[3]) if len(fields) == 5 else (fields + ["", ""])[:2]
        if len(fields) not in (2, 5) or not _NAME.match(name):
            raise DataError(
                f"{p}:{n}: expected 'NAME VALUE' or QGroundControl's 5 columns, got {raw!r}",
                path=p,
            )
        try:
            params[name] = float(value)
        except ValueError:
            raise DataError(f"{p}:{n}: {name}'s value {value!r} is not a number", path=p) from None
    if not params:
        raise DataError(f"{p}: no parameters in the file", path=p)
    return params
