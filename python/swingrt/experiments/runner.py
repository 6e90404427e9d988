"""Experiment runner: training flight → identification → PID / LQR / MPC on a step → report.

Writes to the output folder: ``metrics.csv`` (columns :data:`swingrt.reports.CSV_COLUMNS`),
``metrics.md``, one Parquet trace per run named ``<scenario>__<controller>.parquet``,
per-scenario PNG figures (velocity, swing angle and acceleration setpoint against time,
controllers overlaid, as the thesis's figures 5.11–5.22), the identified models, and for
the double pendulum the MPC's predicted trajectory at the step against the one flown
(figures 5.20–5.21).
"""

from __future__ import annotations

import copy
import itertools
import math
import os
import sys
import time
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import numpy as np

from swingrt.errors import ConfigError
from swingrt.io.flight import Trace
from swingrt.methods import METHODS
from swingrt.methods import SECTIONS as METHOD_SECTIONS
from swingrt.metrics import step_metrics, swing_iae_floor
from swingrt.reports import plot_case, plot_prediction, write_metrics
from swingrt.scenario import Scenario, read_toml
from swingrt.sysid import LinearModel


def _defs() -> Traversable:
    """The folder of built-in experiment definitions (``swingrt/experiments/defs/*.toml``)."""
    return resources.files("swingrt.experiments").joinpath("defs")


_KNOWN_KEYS = {
    "name",
    "description",
    "axes",
    "controllers",
    "step",
    "duration",
    "prediction_figure",
    "common",
    "training",
    "evaluation",
    "grid",
    "identify",
    "mpc",
    "lqr",
    "training_duration",
    "adaptive",
    "cases",
    "tick_budget",
    *METHOD_SECTIONS,
}

#: Controllers an experiment can compare.
CONTROLLERS = ("pid", "lqr", "mpc", "mpc_adaptive", "mpc_oracle", *METHODS)

#: Keys of one entry of an experiment's ``[cases.<name>]`` table.
_CASE_KEYS = {"description", "common", "evaluation", "oracle", "step"}


@dataclass
class Experiment:
    """A parsed experiment definition (see ``swingrt.experiments``)."""

    name: str
    description: str = ""
    axes: str = "n"
    controllers: list[str] = field(default_factory=lambda: ["pid", "lqr", "mpc"])
    step: dict[str, float] = field(default_factory=lambda: {"t": 2.0, "vn": 2.0})
    duration: float = 30.0
    training_duration: float = 300.0
    prediction_figure: bool = False
    common: dict[str, Any] = field(default_factory=dict)
    training: dict[str, Any] = field(default_factory=dict)
    evaluation: dict[str, Any] = field(default_factory=dict)
    grid: dict[str, list[Any]] = field(default_factory=dict)
    identify: dict[str, Any] = field(default_factory=dict)
    mpc: dict[str, Any] = field(default_factory=dict)
    lqr: dict[str, Any] = field(default_factory=dict)
    adaptive: dict[str, Any] = field(default_factory=dict)
    cases: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Compute time a controller tick may take before the hand-back to PX4 [s] (None: its
    #: period, as in flight; a study that scores control apart from timing sets more).
    tick_budget: float | None = None
    shaper: dict[str, Any] = field(default_factory=dict)
    payload_p: dict[str, Any] = field(default_factory=dict)
    deepc: dict[str, Any] = field(default_factory=dict)
    nmpc: dict[str, Any] = field(default_factory=dict)
    sindy: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str) -> Experiment:
        """Validate a definition; errors name the key and the file."""
        unknown = sorted(set(d) - _KNOWN_KEYS)
        if unknown:
            raise ConfigError(f"{source}: unknown key {unknown[0]!r}")
        if "name" not in d:
            raise ConfigError(f"{source}: name: missing")
        exp = cls(**d)
        if exp.axes not in ("n", "ne"):
            raise ConfigError(f"{source}: axes: must be 'n' or 'ne' (got {exp.axes!r})")
        for c in exp.controllers:
            if c not in CONTROLLERS:
                raise ConfigError(f"{source}: controllers: unknown controller {c!r}")
        if exp.cases and exp.grid:
            raise ConfigError(f"{source}: cases: cannot be combined with grid")
        for name, spec in exp.cases.items():
            if not isinstance(spec, dict):
                raise ConfigError(f"{source}: cases.{name}: must be a table")
            bad = sorted(set(spec) - _CASE_KEYS)
            if bad:
                raise ConfigError(f"{source}: cases.{name}: unknown key {bad[0]!r}")
            if "mpc_oracle" in exp.controllers and "oracle" not in spec:
                raise ConfigError(
                    f"{source}: cases.{name}.oracle: needed for mpc_oracle (the training "
                    "flight's overrides after the change)"
                )
        if not (isinstance(exp.duration, (int, float)) and exp.duration > exp.step.get("t", 0)):
            raise ConfigError(f"{source}: duration: must be longer than the step time")
        for k, v in exp.grid.items():
            if not isinstance(v, list) or not v:
                raise ConfigError(f"{source}: grid.{k}: must be a non-empty list")
        exp.check(source)
        return exp

    def check(self, source: str) -> None:
        """Validate every settings section and every case's scenarios in the core, so a typo
        fails before anything flies; errors name the file and the dotted field."""
        from swingrt import _core

        try:
            ident = {k: v for k, v in self.identify.items() if k != "search"}
            if not isinstance(self.identify.get("search", True), bool):
                raise ConfigError("identify.search: must be true or false", field="identify.search")
            _core.check_settings("identify", ident)
            _core.check_settings("mpc", self.mpc)
            _core.check_settings("lqr", self.lqr)
            _core.check_settings("adaptive", self.adaptive)
            from swingrt.methods import check_settings as check_method

            for sec in METHOD_SECTIONS:
                check_method(sec, getattr(self, sec))
            tb = self.tick_budget
            if tb is not None and not (
                isinstance(tb, (int, float)) and not isinstance(tb, bool) and 0 < tb <= 60
            ):
                raise ConfigError(
                    f"tick_budget: must be a number of seconds in (0, 60] (got {tb!r})",
                    field="tick_budget",
                )
            for case, over in cases(self):
                try:
                    train = training_scenario(self, over, 0)
                    evaluation_scenario(self, over, 0, train, case=case)
                    if "oracle" in self.cases.get(case, {}):
                        oracle_training_scenario(self, case, over, 0)
                except ConfigError as exc:
                    raise ConfigError(f"case {case}: {exc}", field=exc.field) from None
        except ConfigError as exc:
            raise ConfigError(f"{source}: {exc}", field=exc.field) from None


def list_experiments() -> dict[str, str]:
    """Built-in experiment names and descriptions."""
    out = {}
    for f in sorted(_defs().iterdir(), key=lambda p: p.name):
        if f.name.endswith(".toml"):
            d = tomllib.loads(f.read_text(encoding="utf-8"))
            out[d["name"]] = d.get("description", "")
    return out


def load_experiment(name_or_path: str) -> Experiment:
    """A built-in experiment by name, or a TOML file."""
    p = Path(name_or_path)
    if name_or_path.endswith(".toml") or p.is_file():
        return Experiment.from_dict(read_toml(p), str(p))
    f = _defs() / f"{name_or_path}.toml"
    if not f.is_file():
        names = ", ".join(list_experiments())
        raise ConfigError(f"unknown experiment {name_or_path!r} (built in: {names})")
    return Experiment.from_dict(tomllib.loads(f.read_text(encoding="utf-8")), f.name)


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


class _Log:
    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.t0 = time.perf_counter()

    def __call__(self, msg: str) -> None:
        if not self.quiet:
            print(f"[{time.perf_counter() - self.t0:6.1f} s] {msg}", file=sys.stderr, flush=True)


def simulate_controller(
    scenario: Scenario,
    controller: str,
    *,
    axes: str = "n",
    model: LinearModel | None = None,
    lqr_params: dict[str, float] | None = None,
    mpc_settings: dict[str, Any] | None = None,
    lqr_settings: dict[str, Any] | None = None,
    adaptive_settings: dict[str, Any] | None = None,
    engage_at: float = 0.0,
    prediction_at: float | None = None,
    twin: Scenario | None = None,
    method: Any = None,
    budget: float | None = None,
) -> tuple[Trace, dict[str, Any]]:
    """Fly one scenario with a controller of :data:`CONTROLLERS` on the given axes
    (``mpc_oracle`` is the MPC on whatever ``model`` it is given). ``twin`` (the training
    flight's scenario) lets ``mpc_adaptive`` re-identify on the vehicle's twin for the
    payload it measures, starting from the white-box ``lqr_params`` (``m_q``, ``m_p``,
    ``l``) of the training flight, when ``adaptive_settings`` enable it.

    The controllers of :mod:`swingrt.methods` fly what ``method`` (their
    :class:`~swingrt.methods.Trained`) learned. ``budget`` [s] is the compute time a tick
    may take before the hand-back to PX4 (default: the controller's period).

    Returns the trace and extras: fallback reason, tick timings, the controller's events
    (time [s], what, value) and (``prediction_at``) the MPC's predicted outputs from the
    first tick at or after that time.
    """
    from swingrt import _core

    sim = _core.Simulator(scenario)
    n_axes = len(axes)
    extras: dict[str, Any] = {}
    if controller in ("mpc", "mpc_oracle", "mpc_adaptive"):
        if model is None:
            raise ConfigError(f"{controller} needs an identified model", field="model")
        # The budget of one tick is its period.
        if controller == "mpc_adaptive":
            use_twin = bool((adaptive_settings or {}).get("twin", {}).get("enabled", False))
            if use_twin and (twin is None or lqr_params is None):
                raise ConfigError(
                    "adaptive.twin.enabled needs the training scenario and the white-box "
                    "estimate of the training payload",
                    field="adaptive.twin",
                )
            prior = (
                (float(lqr_params["m_p"]), float(lqr_params["l"]), float(lqr_params["m_q"]))
                if use_twin and lqr_params is not None
                else None
            )
            sim.attach_adaptive_mpc(
                model,
                mpc_settings or None,
                adaptive_settings or None,
                engage_at,
                budget or model.dt,
                twin if use_twin else None,
                prior,
            )
        else:
            sim.attach_mpc(model, mpc_settings or None, engage_at, budget or model.dt)
    elif controller in METHODS:
        from swingrt.methods import attach

        if method is None or method.name != controller:
            raise ConfigError(f"{controller} needs what it learned from the training flight")
        attach(sim, method, engage_at, budget)
    elif controller == "lqr":
        if lqr_params is None:
            raise ConfigError("lqr needs the white-box parameters", field="lqr_params")
        lqr = _core.check_settings("lqr", lqr_settings or None)
        # The budget of one tick is its period.
        sim.attach_lqr(lqr_params, n_axes, lqr, engage_at, budget or lqr["period"])
    elif controller != "pid":
        raise ConfigError(f"unknown controller {controller!r}", field="controller")
    if prediction_at is not None and model is not None and controller.startswith("mpc"):
        sim.advance(prediction_at)
        sim.advance(model.dt)
        pred = sim.controller_prediction()
        if pred is not None:
            extras["prediction"] = {"t0": sim.t, "outputs": np.asarray(pred)}
    sim.run_to_end()
    trace = Trace(sim.take_trace(), {"scenario": scenario.to_dict(), "controller": controller})
    extras["fallback"] = sim.fallback_reason
    extras["events"] = sim.controller_events()
    ticks = np.asarray(sim.tick_times())
    if len(ticks):
        extras["tick_us_median"] = float(np.median(ticks))
        extras["tick_us_p99"] = float(np.percentile(ticks, 99))
        extras["constrained_ticks"] = int(sim.constrained_ticks)
    return trace, extras


def identify_case(
    train: Trace, exp: Experiment, plots: Path | None = None, twin: Scenario | None = None
) -> tuple[Any, Any, dict[str, float]]:
    """DMDc (with search) for the MPC, white-box estimates for the LQR; with ``plots`` the
    search's error-vs-q plot (the Pareto elbow) is written there. ``twin`` (the training
    flight's scenario) adds the twin step flight to the control-relevant selection."""
    from swingrt.reports import plot_pareto
    from swingrt.sysid import identify, search, select_for_control

    opts = {"method": "dmdc", **exp.identify}
    if opts.pop("search", True) and "delays" not in opts:
        result = search(train, axes=exp.axes, **opts)
        if "mpc" in exp.controllers and result.settings["select"] == "control":
            result = select_for_control(
                train, result, axes=exp.axes, mpc_settings=exp.mpc or None, twin=twin
            )
        model = result.model
        if plots is not None:
            plot_pareto(result, plots)
    else:
        model = identify(train, axes=exp.axes, **opts)
    wb = identify(train, method="whitebox", axes=exp.axes)
    est = wb.diagnostics["whitebox"]
    lqr = {
        "m_q": float(est["vehicle_mass"]),
        "m_p": float(est["payload_mass"]),
        "l": float(est["length"]),
        "c": float(est.get("friction", 0.0)),
    }
    return model, wb, lqr


def train_methods(
    train: Trace, exp: Experiment, model: Any, lqr: dict[str, float], twin: Scenario | None
) -> dict[str, Any]:
    """What each controller of :mod:`swingrt.methods` in ``exp.controllers`` learns from
    the training flight (:func:`swingrt.methods.train`), by name."""
    from swingrt.methods import train as train_method

    px4 = twin.to_dict().get("controller") if twin is not None else None
    sections = {s: getattr(exp, s) for s in METHOD_SECTIONS}
    return {
        c: train_method(
            c,
            train,
            axes=exp.axes,
            sections=sections,
            model=model,
            whitebox=lqr,
            px4=px4,
            identify=exp.identify,
            mpc_settings=exp.mpc or None,
            twin=twin,
        )
        for c in exp.controllers
        if c in METHODS
    }


def run_experiment(
    exp: Experiment, out: str | os.PathLike, *, seed: int = 0, quiet: bool = False
) -> list[dict[str, Any]]:
    """Run every case and controller of ``exp`` and write the report into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    log = _Log(quiet)
    rows: list[dict[str, Any]] = []
    notes: list[str] = []
    all_cases = cases(exp)
    for i, (case, over) in enumerate(all_cases, 1):
        log(f"{exp.name} [{i}/{len(all_cases)}] {case}: training flight")
        train_sc = training_scenario(exp, over, seed)
        from swingrt.sim import _run

        train = _run(train_sc, False, "collect")
        log(f"{exp.name} [{i}/{len(all_cases)}] {case}: identification")
        model, wb, lqr = identify_case(
            train, exp, out / f"{case}__error_vs_delays.png", twin=train_sc
        )
        trained = train_methods(train, exp, model, lqr, train_sc)
        train.to_parquet(out / f"{case}__training.parquet")
        model.save(out / f"{case}__model.json")
        wb.save(out / f"{case}__whitebox.json")
        ev_sc = evaluation_scenario(exp, over, seed + 1, train_sc, case=case)
        step = case_step(exp, case)
        oracle = None
        if "mpc_oracle" in exp.controllers:
            log(f"{exp.name} [{i}/{len(all_cases)}] {case}: oracle training flight")
            oracle_sc = oracle_training_scenario(exp, case, over, seed)
            oracle, _, _ = identify_case(_run(oracle_sc, False, "collect"), exp, twin=oracle_sc)
            oracle.save(out / f"{case}__oracle_model.json")
        traces: dict[str, Trace] = {}
        prediction = None
        for ctrl in exp.controllers:
            log(f"{exp.name} [{i}/{len(all_cases)}] {case}: {ctrl}")
            trace, extras = simulate_controller(
                ev_sc,
                ctrl,
                axes=exp.axes,
                model=oracle if ctrl == "mpc_oracle" else model,
                lqr_params=lqr,
                mpc_settings=exp.mpc or None,
                lqr_settings=exp.lqr or None,
                adaptive_settings=exp.adaptive or None,
                prediction_at=step["t"] if exp.prediction_figure else None,
                twin=train_sc,
                method=trained.get(ctrl),
                budget=exp.tick_budget,
            )
            if ctrl == "mpc_adaptive":
                notes.append(f"{case}: {adaptation_note(ev_sc, extras['events'])}")
            trace.to_parquet(out / f"{case}__{ctrl}.parquet")
            traces[ctrl] = trace
            axis = "ne" if exp.axes == "ne" else "n"
            m = step_metrics(trace, t0=step["t"], axis=axis)
            rows.append({"scenario": case, "controller": ctrl, **m})
            if extras.get("fallback"):
                notes.append(f"{case} {ctrl}: fell back to PX4 PID ({extras['fallback']})")
            if "prediction" in extras:
                prediction = extras["prediction"]
        floors = {
            c: swing_iae_floor(tr, t0=step["t"], axis="ne" if exp.axes == "ne" else "n")
            for c, tr in traces.items()
        }
        notes.append(
            f"{case}: swing IAE floor |∫(swing − final) dt| (the payload's Δv/g and drag, "
            "any controller; swing_excess_iae_deg_s is the IAE above it) "
            + ", ".join(f"{c} {floors[c]:.2f}" for c in traces)
            + " deg·s"
        )
        case_rows = {r["controller"]: r for r in rows if r["scenario"] == case}
        if "lqr" in case_rows and "mpc" in case_rows:
            notes.append(f"{case}: {compare_mpc_lqr(case_rows['mpc'], case_rows['lqr'])}")
        cc = model.diagnostics.get("control_check")
        if cc is not None and not cc.get("passed", True):
            notes.append(
                f"{case}: no searched model passed the closed-loop check; the least "
                "violating one was flown"
            )
        # An unscored model (test span shorter than the rollout) has test_nmae None.
        test_nmae = model.diagnostics.get("test_nmae")
        notes.append(
            f"{case}: DMDc q = {model.delays}, p = {model.rank}, "
            f"test NMAE {float('nan') if test_nmae is None else test_nmae:.4f}"
            + (f" ({len(cc['checked'])} candidate(s) flown in the closed-loop check)" if cc else "")
            + f"; white-box m_p = {lqr['m_p']:.3f} kg, l = {lqr['l']:.3f} m"
        )
        plot_case(out / f"{case}.png", case, traces, exp.axes)
        if prediction is not None and "mpc" in traces:
            plot_prediction(out / f"{case}__prediction.png", prediction, traces["mpc"], model)
    write_metrics(out, exp, rows, notes)
    log(f"{exp.name}: wrote {out}")
    return rows


def adaptation_note(scenario: Scenario, events: list[tuple[float, str, float]]) -> str:
    """When the adaptive MPC noticed the change (online detector, or the twin path's mass
    step / new cable length) and re-adopted a model, relative to the scenario's first
    payload event (``adopted … s after the change``)."""
    changes = scenario.to_dict().get("payload", {}).get("events", [])
    t_change = float(changes[0]["t"]) if changes else 0.0
    first: dict[str, tuple[float, float]] = {}
    for t, what, value in events:
        if t >= t_change:
            first.setdefault(what, (t, value))
    rejected = sum(1 for t, w, _ in events if w == "rejected" and t >= t_change)
    parts = [f"adaptive MPC, change at {t_change:.2f} s:"]
    noticed = [first[w][0] for w in ("detected", "mass_changed", "requested") if w in first]
    if noticed:
        parts.append(f"noticed after {min(noticed) - t_change:.2f} s")
    else:
        parts.append("not noticed")
    if "mass_changed" in first:
        parts.append(f"(thrust: total mass {first['mass_changed'][1]:.3f} kg)")
    lengths = [v for t, w, v in events if w == "requested" and t >= t_change and v > 0]
    if lengths and "detected" not in first:
        parts.append(
            "twin re-identified for cable length(s) " + ", ".join(f"{v:.2f} m" for v in lengths)
        )
    if "adopted" in first:
        parts.append(f"model re-adopted after {first['adopted'][0] - t_change:.2f} s")
    else:
        parts.append("no model re-adopted")
    if rejected:
        parts.append(f"{rejected} candidate(s) rejected by the check")
    return " ".join(parts)


#: Metrics :func:`compare_mpc_lqr` reads (lower is better for each).
COMPARED = (
    "peak_swing_deg",
    "swing_excess_iae_deg_s",
    "residual_swing_deg",
    "swing_free_s",
    "v_settle_s",
    "ss_error",
    "acc_sp_tv",
)


def compare_mpc_lqr(mpc: dict[str, Any], lqr: dict[str, Any], *, alike: float = 0.2) -> str:
    """Where the MPC and the LQR differ on one case: each metric of :data:`COMPARED` whose
    values differ by more than ``alike`` (relative, and more than 0.05 absolute) is named
    with the better controller; the rest are listed as alike."""
    better: list[str] = []
    same: list[str] = []
    for k in COMPARED:
        a, b = float(mpc[k]), float(lqr[k])
        if math.isclose(a, b, rel_tol=alike, abs_tol=0.05):
            same.append(k)
            continue
        who = "MPC" if a < b else "LQR"
        better.append(f"{k} {who} ({a:.3g} MPC vs {b:.3g} LQR)")
    out = "MPC vs LQR: better " + ("; ".join(better) if better else "on nothing")
    return out + (f"; alike (within {alike:.0%}): {', '.join(same)}" if same else "")
