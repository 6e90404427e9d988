"""The thesis's chapter-5 experiments: definitions and the runner (``swingrt experiment``).

Each ``defs/*.toml`` defines: the controlled ``axes``; the ``controllers`` compared
(``pid``, ``lqr``, ``mpc``, ``mpc_adaptive``, ``mpc_oracle``); the velocity ``step``; the run
``duration``; scenario overrides ``[common]`` (training and evaluation), ``[training]`` and
``[evaluation]``; settings ``[identify]``, ``[selection]`` (the control-relevant
selection's), ``[mpc]``, ``[lqr]`` and ``[adaptive]``; and
either an optional ``[grid]`` of dotted scenario keys whose product makes the cases, or
named ``[cases.<name>]`` tables with their own ``common``, ``evaluation`` and ``step`` and,
for ``mpc_oracle``, ``oracle`` (the overrides of a second training flight, the configuration
after an in-flight change, on which the oracle's model is identified). For every case the runner
(:mod:`swingrt.experiments.runner`) flies the training flight under PX4 PID, identifies the
DMDc model (search) for the MPC and the white-box parameters for the LQR, then flies the
step with every controller (:func:`simulate_controller`) and writes the report
(:mod:`swingrt.reports`).
"""

from __future__ import annotations

from swingrt.experiments.controllers import simulate_controller
from swingrt.experiments.identification import identify_case, train_methods, without_whitebox
from swingrt.experiments.runner import run_experiment
from swingrt.experiments.scenarios import cases, evaluation_scenario, training_scenario
from swingrt.experiments.schema import Experiment, list_experiments, load_experiment

__all__ = [
    "Experiment",
    "cases",
    "evaluation_scenario",
    "identify_case",
    "list_experiments",
    "load_experiment",
    "run_experiment",
    "simulate_controller",
    "train_methods",
    "training_scenario",
    "without_whitebox",
]
