"""The scenarios of an experiment: its cases (grid points or ``[cases]`` entries), the
training flight, the evaluation step flight and the oracle's training flight."""

from __future__ import annotations

import copy
import itertools
from typing import TYPE_CHECKING, Any

from swingrt.scenario import Scenario

if TYPE_CHECKING:
    from swingrt.experiments.schema import Experiment


def _set_dotted(d: dict[str, Any], key: str, value: Any) -> None:
    parts = key.split(".")
    for p in parts[:-1]:
        d = d.setdefault(p, {})
    d[parts[-1]] = value


def cases(exp: Experiment) -> list[tuple[str, dict[str, Any]]]:
    """(case name, scenario overrides) for every point of the grid, or every entry of
    ``[cases]`` (its ``common`` overrides); one case without either."""
    if exp.cases:
        return [(name, dict(c.get("common", {}))) for name, c in exp.cases.items()]
    if not exp.grid:
        return [(exp.name, {})]
    keys = list(exp.grid)
    out = []
    for values in itertools.product(*(exp.grid[k] for k in keys)):
        over: dict[str, Any] = {}
        label = []
        for k, v in zip(keys, values, strict=True):
            _set_dotted(over, k, v)
            short = k.split(".")[-1]
            short = {"mass": "mp", "length": "l"}.get(short, short)
            label.append(f"{short}{v:g}" if isinstance(v, (int, float)) else f"{short}{v}")
        out.append(("_".join(label), over))
    return out


def _step_setpoints(step: dict[str, float]) -> list[dict[str, float]]:
    start = {"t": 0.0, **{k: 0.0 for k in step if k != "t"}}
    return [start, dict(step)]


def training_scenario(exp: Experiment, over: dict[str, Any], seed: int) -> Scenario:
    """The random-step training flight of a case."""
    sc = Scenario.builtin("training").with_overrides(exp.common).with_overrides(over)
    if exp.axes == "ne":
        sc = sc.with_overrides(
            {"random_steps": {"axes": "ne"}, "setpoints": [{"t": 0.0, "vn": 0.0, "ve": 0.0}]}
        )
    return sc.with_overrides(exp.training).with_overrides(
        {"duration": float(exp.training_duration), "name": "training", "seed": seed}
    )


def case_step(exp: Experiment, case: str | None) -> dict[str, float]:
    """The step the metrics of ``case`` count from (the case's own ``step``, else the
    experiment's)."""
    return dict(exp.cases.get(case or "", {}).get("step", exp.step))


def oracle_training_scenario(
    exp: Experiment, case: str, over: dict[str, Any], seed: int
) -> Scenario:
    """The training flight of ``mpc_oracle``: the case's flight with its ``oracle``
    overrides (the configuration after the change) on top."""
    return training_scenario(exp, over, seed).with_overrides(exp.cases[case]["oracle"])


def evaluation_scenario(
    exp: Experiment,
    over: dict[str, Any],
    seed: int,
    training: Scenario,
    *,
    case: str | None = None,
) -> Scenario:
    """The step flight of a case; PX4 keeps the training flight's hover thrust if the
    evaluation changes the vehicle (nobody is told). A ``[cases]`` entry's ``step`` and
    ``evaluation`` overrides apply on top of the experiment's."""
    sc = Scenario.builtin("step").with_overrides(exp.common).with_overrides(over)
    sc = sc.with_overrides(
        {"setpoints": _step_setpoints(case_step(exp, case)), "duration": float(exp.duration)}
    )
    ev = copy.deepcopy(exp.evaluation)
    for k, v in exp.cases.get(case or "", {}).get("evaluation", {}).items():
        ev[k] = copy.deepcopy(v)
    if "vehicle" in ev and "hover_thrust" not in ev.get("controller", {}):
        ev.setdefault("controller", {})["hover_thrust"] = training.hover_thrust()
    return sc.with_overrides(ev).with_overrides({"seed": seed})
