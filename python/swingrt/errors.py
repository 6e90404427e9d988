"""Typed exceptions raised by swingrt.

Every user mistake surfaces as one of these; each also subclasses the fitting built-in
so that ``except ValueError`` keeps working for callers that do not know swingrt.
The Rust core's errors reach Python by *category*: every core error variant belongs to one
category (configuration, data, model, identification, control, solver, simulation), and the
binding (``crates/swing_py/src/errors.rs``) raises the class of that category below with
the core's one-line message.

Structured fields: :attr:`ConfigError.field` is the dotted name of the offending setting
when known (the core's messages start with it: ``payload.mass: must be > 0``), and
:attr:`DataError.path` the file the data came from when known.
"""

from __future__ import annotations

import os
import re
from typing import Any

__all__ = [
    "SwingrtError",
    "ConfigError",
    "DataError",
    "MissingColumnError",
    "ModelError",
    "IdentificationError",
    "ControlError",
    "SolverError",
    "SimulationError",
    "LinkError",
    "FlightAbort",
    "SetpointError",
]

#: A dotted setting name such as ``payload.mass`` or ``setpoints[1].vn``.
_FIELD = re.compile(r"[A-Za-z_]\w*(?:\[\d+\])*(?:\.[A-Za-z_]\w*(?:\[\d+\])*)*")
_FILE_SUFFIXES = (".toml", ".json", ".csv", ".parquet", ".ulg")


def _leading_field(message: str) -> str | None:
    """The dotted field name a ``field: problem`` message starts with (after a file name
    prefix such as ``exp.toml: axes: ...``), or None."""
    parts = message.split(": ")
    for head in parts[:-1]:
        if "/" in head or head.endswith(_FILE_SUFFIXES):
            continue  # a file name, not a field
        return head if _FIELD.fullmatch(head) else None
    return None


class SwingrtError(Exception):
    """Base class of every error swingrt raises on purpose."""


class ConfigError(SwingrtError, ValueError):
    """A scenario, experiment or setting is invalid; the message names the field.

    ``field`` is the dotted name of the offending setting (e.g. ``payload.mass``); if not
    given it is taken from the message's leading ``name:``, and is None when there is none.
    """

    def __init__(self, message: str = "", *args: Any, field: str | None = None):
        super().__init__(message, *args)
        #: Dotted name of the offending setting, or None when the message names none.
        self.field: str | None = field if field is not None else _leading_field(str(message))


class DataError(SwingrtError, ValueError):
    """Flight data cannot be used: missing column or topic, NaN gap, too short, bad shape.

    ``path`` is the file the data came from, when known.
    """

    def __init__(self, message: str = "", *args: Any, path: str | os.PathLike[str] | None = None):
        super().__init__(message, *args)
        #: The data file concerned, or None.
        self.path: str | None = os.fspath(path) if path is not None else None


class MissingColumnError(DataError, KeyError):
    """A trace has no column of the requested name (also a ``KeyError``, as for a dict)."""

    __str__ = DataError.__str__  # the message, not KeyError's repr of it


class ModelError(SwingrtError, ValueError):
    """A model file or model object is malformed or does not fit the data it is used with."""


class IdentificationError(SwingrtError, RuntimeError):
    """Identification failed although its inputs were valid (e.g. no stable candidate)."""


class ControlError(SwingrtError, RuntimeError):
    """A controller could not be built or stepped (e.g. Riccati equation without solution)."""


class SolverError(ControlError):
    """The QP solver failed or ran out of its budget."""


class SimulationError(SwingrtError, RuntimeError):
    """The simulation diverged or produced a non-finite state."""


class LinkError(SwingrtError, ConnectionError):
    """A MAVLink connection could not be opened, went silent or spoke nonsense."""


class FlightAbort(SwingrtError, RuntimeError):
    """The flight was handed back to the flight controller early; the message says why.

    ``report`` (a :class:`swingrt.mavlink.offboard.FlightReport`) is attached when the
    flight produced one.
    """

    report: Any = None


class SetpointError(SwingrtError, ValueError):
    """A SET_POSITION_TARGET_LOCAL_NED that PX4 would not accept; the message says why."""
