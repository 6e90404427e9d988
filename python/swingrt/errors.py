"""Typed exceptions raised by swingrt.

Every user mistake surfaces as one of these; each also subclasses the fitting built-in
so that ``except ValueError`` keeps working for callers that do not know swingrt.
The Rust core's error enums map onto these classes one to one (see ``crates/swing_py``).
"""

from __future__ import annotations

__all__ = [
    "SwingrtError",
    "ConfigError",
    "DataError",
    "ModelError",
    "IdentificationError",
    "ControlError",
    "SolverError",
    "SimulationError",
    "LinkError",
]


class SwingrtError(Exception):
    """Base class of every error swingrt raises on purpose."""


class ConfigError(SwingrtError, ValueError):
    """A scenario, experiment or setting is invalid; the message names the field."""


class DataError(SwingrtError, ValueError):
    """Flight data cannot be used: missing column or topic, NaN gap, too short, bad shape."""


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
