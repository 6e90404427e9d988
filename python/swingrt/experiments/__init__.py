"""The thesis's chapter-5 experiments: definitions and the runner (``swingrt experiment``).

Each ``defs/*.toml`` defines: the controlled ``axes``; the ``controllers`` compared
(``pid``, ``lqr``, ``mpc``); the velocity ``step``; the run ``duration``; scenario overrides
``[common]`` (training and evaluation), ``[training]`` and ``[evaluation]``; and an optional
``[grid]`` of dotted scenario keys whose product makes the cases. For every case the runner
(:mod:`swingrt.experiments.runner`) flies the training flight under PX4 PID, identifies the
DMDc model (search) for the MPC and the white-box parameters for the LQR, then flies the
step with every controller (:func:`simulate_controller`) and writes the report
(:mod:`swingrt.reports`).
"""

from __future__ import annotations

from swingrt.experiments.runner import (
    Experiment,
    cases,
    evaluation_scenario,
    identify_case,
    list_experiments,
    load_experiment,
    run_experiment,
    simulate_controller,
    training_scenario,
)

__all__ = [
    "Experiment",
    "cases",
    "evaluation_scenario",
    "identify_case",
    "list_experiments",
    "load_experiment",
    "run_experiment",
    "simulate_controller",
    "training_scenario",
]
