"""Simulation from Python: ``simulate``, ``collect`` and the steppable ``Simulator``.

:class:`Simulator` is the public steppable simulator (named per-axis setpoints, a
:class:`~swingrt.io.Trace` out). ``_core.Simulator`` is the binding underneath it: whole-run
helpers inside the package (:func:`simulate`, :func:`collect`,
:func:`swingrt.experiments.simulate_controller`) drive it directly because they need its
run-to-end, progress and controller-attachment calls, which the wrapper does not expose.
"""

from __future__ import annotations

import sys
import time
from typing import Any

from swingrt import _core
from swingrt.io.flight import Trace
from swingrt.scenario import Scenario, ScenarioLike, resolve

_MODES = {"pos", "vel", "acc"}
_AXES = {"n": 0, "e": 1, "d": 2}


class _Progress:
    """A one-line progress bar on stderr, shown only on a terminal."""

    def __init__(self, total: float, label: str, enabled: bool | None = None):
        self.total = total
        self.label = label
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.t0 = time.perf_counter()

    def update(self, done: float) -> None:
        if not self.enabled:
            return
        frac = min(done / self.total, 1.0) if self.total > 0 else 1.0
        bar = "#" * int(frac * 30)
        rate = done / max(time.perf_counter() - self.t0, 1e-9)
        sys.stderr.write(f"\r{self.label} [{bar:<30}] {frac * 100:5.1f} %  {rate:7.0f}× real time")
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")
            sys.stderr.flush()


class Simulator:
    """Steppable closed loop of vehicle, payload, PX4 cascade and wind.

    ``config`` is a scenario (None, dict, TOML path or string) merged onto the built-in
    ``hover`` scenario (hold the start position, one hour long); a schedule in the scenario
    still applies, and :meth:`set_setpoint` overrides it per axis from then on.
    """

    def __init__(self, config: ScenarioLike = None, *, default: str = "hover", **overrides: Any):
        self.scenario = resolve(config, default=default, **overrides)
        self._sim = _core.Simulator(self.scenario)

    @property
    def t(self) -> float:
        """Simulated time [s]."""
        return self._sim.t

    def advance(self, dt: float) -> None:
        """Advance physics and PX4 cascade by ``dt`` seconds."""
        self._sim.advance(float(dt))

    def set_setpoint(self, **axes: tuple[str, float]) -> None:
        """Set axes by keyword, e.g. ``n=("vel", 2.0), d=("pos", -10.0)`` (NED, SI)."""
        from swingrt.errors import ConfigError

        for name, spec in axes.items():
            if name not in _AXES:
                raise ConfigError(f"axis: must be n, e or d (got {name!r})")
            try:
                mode, value = spec
            except (TypeError, ValueError):
                raise ConfigError(f"{name}: expected (mode, value), got {spec!r}") from None
            if mode not in _MODES:
                raise ConfigError(f"{name}: mode must be pos, vel or acc (got {mode!r})")
            self._sim.set_setpoint(_AXES[name], mode, float(value))

    def state(self) -> dict[str, float]:
        """Current state: position, velocity, attitude, rates, swing, setpoints."""
        return self._sim.state()

    def trace(self) -> Trace:
        """The trace logged so far."""
        return Trace(self._sim.trace(), {"scenario": self.scenario.to_dict()})


def _run(scenario: Scenario, progress: bool | None, label: str) -> Trace:
    sim = _core.Simulator(scenario)
    bar = _Progress(scenario.duration, label, progress)
    chunk = 5.0
    while sim.steps_left > 0:
        sim.advance(min(chunk, sim.steps_left * scenario.physics_dt))
        bar.update(sim.t)
    sim.run_to_end()
    bar.close()
    return Trace(sim.take_trace(), {"scenario": scenario.to_dict()})


def simulate(
    config: ScenarioLike = None,
    *,
    duration: float | None = None,
    seed: int | None = None,
    progress: bool | None = False,
) -> Trace:
    """Run a scenario (default: 0.2 kg on 1 m, 2 m/s North step at t = 2 s under PX4 PID)."""
    sc = resolve(config, default="step", duration=duration, seed=seed)
    return _run(sc, progress, "simulate")


def collect(
    config: ScenarioLike = None,
    *,
    duration: float | None = None,
    seed: int | None = None,
    progress: bool | None = False,
) -> Trace:
    """Fly the random-step training flight of table 4.1 (default 300 s) and return its trace."""
    sc = resolve(config, default="training", duration=duration, seed=seed)
    return _run(sc, progress, "collect")
