"""swingrt: data-driven identification and swing-damping MPC for a multirotor with an
unknown suspended payload.

The numerical core is Rust (``swingrt._core``); this package adds configuration, data
loading, the command line, experiments and the MAVLink link.
"""

from __future__ import annotations

from swingrt import errors
from swingrt._core import __version__
from swingrt.io.flight import Trace
from swingrt.metrics import step_metrics
from swingrt.scenario import Scenario
from swingrt.scenario import resolve as resolve_scenario
from swingrt.sim import Simulator, collect, simulate
from swingrt.sysid import LinearModel, evaluate, identify

__all__ = [
    "__version__",
    "errors",
    "LinearModel",
    "Scenario",
    "Simulator",
    "Trace",
    "collect",
    "evaluate",
    "identify",
    "resolve_scenario",
    "simulate",
    "step_metrics",
]
