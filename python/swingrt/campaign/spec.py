"""A campaign specification (``swingrt campaign SPEC.toml``): parse, validate, and apply.

Top-level keys:

- ``name`` (required), ``description``;
- ``samples`` (number of samples, > 0), ``seed`` (int, default 0);
- ``controllers``: subset of ``pid``, ``lqr``, ``mpc`` and the methods of
  :mod:`swingrt.methods` (default ``pid``, ``lqr``, ``mpc``);
- ``batch_size``: samples per Dask task (default: chosen from the study size);
- ``[base]``: an experiment's keys (see :mod:`swingrt.experiments`): ``step``,
  ``duration``, ``axes``, ``training_duration``, ``[common]``, ``[training]``,
  ``[evaluation]``, ``[identify]``, ``[selection]``, ``[mpc]``, ``[lqr]``, the methods'
  sections
  (``[shaper]``, ``[payload_p]``, ``[deepc]``, ``[nmpc]``, ``[sindy]``), ``tick_budget`` (no
  ``name``, ``controllers``,
  ``grid``: the campaign owns those);
- ``[base.mission]``: the evaluation flight is a mission instead of the step: a random
  delivery plan per sample (the fields of ``_core.Mission.random``: ``waypoints``,
  ``leg_min``, ``leg_max``, ``speed``, ``hold``, ``acceptance_radius``, ``altitude``,
  ``turn_max``; its seed is the sample's), flown by PX4's mission mode (``pid``), the LQR
  (``lqr``, under PX4's position loop) and by the
  position MPC along legs shaped against the model's swing (``mpc``); ``axes`` must be
  ``ne``, and the rows carry :data:`swingrt.mission.SUMMARY_COLUMNS`;
- ``[vary]``: dotted field → distribution (:mod:`swingrt.campaign.sampling`).

A dotted ``[vary]`` key addresses:

- ``identify.X``, ``selection.X``, ``mpc.X``, ``lqr.X``, ``mission.X``: those settings
  sections;
- ``training.X`` / ``evaluation.X``: a scenario field of that flight only;
- ``duration``, ``training_duration``, ``step.X``: the experiment's own keys;
- anything else (``payload.mass``, ``wind.velocity``, ``noise.swing_std``, …): a scenario
  field in ``[common]``, i.e. both the training and the evaluation flight.

A numeric component indexes a list of the base (``wind.gusts.0.amplitude``).

Every mistake is a :class:`~swingrt.errors.ConfigError` naming the key, raised by
:func:`load_spec` before anything flies: the spec's keys and distributions are checked
here, and the experiments of a few draws (and of the distributions' bounds) are checked by
the core through :meth:`Experiment.check`.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from swingrt.campaign.sampling import Distribution, parse_distribution
from swingrt.errors import ConfigError
from swingrt.experiments.schema import CONTROLLERS, Experiment
from swingrt.methods import SECTIONS as METHOD_SECTIONS

_TOP_KEYS = {"name", "description", "samples", "seed", "controllers", "batch_size", "base", "vary"}
_BASE_KEYS = {
    "axes",
    "step",
    "duration",
    "training_duration",
    "prediction_figure",
    "common",
    "training",
    "evaluation",
    "identify",
    "selection",
    "mpc",
    "lqr",
    "tick_budget",
    "mission",
    *METHOD_SECTIONS,
}
_SECTIONS = (
    "identify",
    "selection",
    "mpc",
    "lqr",
    "training",
    "evaluation",
    "step",
    "mission",
    *METHOD_SECTIONS,
)
#: The controllers a mission campaign flies: PX4's mission mode, the position MPC and the
#: thesis's LQR under PX4's position loop.
MISSION_CONTROLLERS = ("pid", "mpc", "lqr")
_SCALARS = ("duration", "training_duration")
#: How many draws :func:`load_spec` validates in the core besides the bounds.
CHECK_DRAWS = 4


@dataclass
class CampaignSpec:
    """A validated campaign (see the module docs)."""

    name: str
    samples: int
    seed: int = 0
    controllers: list[str] = field(default_factory=lambda: ["pid", "lqr", "mpc"])
    description: str = ""
    batch_size: int | None = None
    base: dict[str, Any] = field(default_factory=dict)
    vary: dict[str, Distribution] = field(default_factory=dict)
    #: The spec as read (plain TOML data), stored with the results.
    raw: dict[str, Any] = field(default_factory=dict)

    def canonical(self) -> dict[str, Any]:
        """The spec as plain data with every default filled in; what the results depend on
        (``batch_size`` aside, which only changes how the work is cut)."""
        d = {k: v for k, v in self.raw.items() if k not in ("batch_size", "description")}
        d["seed"] = self.seed
        d["controllers"] = list(self.controllers)
        d.setdefault("base", {})
        d.setdefault("vary", {})
        return json.loads(json.dumps(d, sort_keys=True))

    def digest(self) -> str:
        """SHA-256 of :meth:`canonical` (hex)."""
        text = json.dumps(self.canonical(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    def draw(self, index: int) -> dict[str, Any]:
        """The sampled values of sample ``index`` (dotted key → value), from (seed, index)
        alone (:func:`swingrt.campaign.sampling.draw`)."""
        from swingrt.campaign.sampling import draw

        return draw(self.vary, self.seed, index)

    @property
    def is_mission(self) -> bool:
        """Whether the evaluation flight is a mission (``[base.mission]``)."""
        return "mission" in self.base

    def mission(self, values: dict[str, Any], index: int) -> Any:
        """The random plan of sample ``index`` (``[base.mission]`` with ``values`` applied,
        seeded by the sample), or None when the evaluation is the step."""
        if not self.is_mission:
            return None
        from swingrt import _core

        plan = dict(apply_values(self.base, values)["mission"])
        plan["seed"] = self.flight_seed(index)
        try:
            return _core.Mission.random(plan)
        except ConfigError as exc:
            msg = str(exc).replace("random.", "mission.", 1)
            field = (exc.field or "").replace("random", "mission", 1)
            raise ConfigError(msg, field=field) from None

    def experiment(self, values: dict[str, Any], label: str = "") -> Experiment:
        """The experiment of one sample: ``values`` (dotted) applied to ``[base]``."""
        d = apply_values(self.base, values)
        d.pop("mission", None)
        d["name"] = label or self.name
        d["controllers"] = list(self.controllers)
        return Experiment.from_dict(d, label or self.name)

    def flight_seed(self, index: int) -> int:
        """The training flight's seed of sample ``index`` (the evaluation uses it + 1)."""
        import numpy as np

        return int(np.random.default_rng([self.seed, index, 1]).integers(0, 2**31 - 1))

    def noise_seed(self, index: int, draw: int) -> int:
        """The evaluation flight's seed of sample ``index`` on noise draw ``draw``: draw 0 is
        the campaign's own (``flight_seed + 1``), the others independent streams of the
        campaign's seed (``swingrt campaign --rerun DIR INDEX --draws N``)."""
        import numpy as np

        if draw == 0:
            return self.flight_seed(index) + 1
        return int(np.random.default_rng([self.seed, index, 2, draw]).integers(0, 2**31 - 1))


def _target(key: str) -> tuple[str, list[str]]:
    """(section of the experiment dict, path inside it) a dotted ``[vary]`` key sets."""
    parts = key.split(".")
    if any(p == "" for p in parts):
        raise ConfigError(f"vary.{key}: empty component in the dotted name", field=f"vary.{key}")
    if parts[0] in _SCALARS:
        if len(parts) != 1:
            raise ConfigError(f"vary.{key}: {parts[0]} has no fields", field=f"vary.{key}")
        return parts[0], []
    if parts[0] in _SECTIONS:
        if len(parts) < 2:
            raise ConfigError(f"vary.{key}: name a field of [{parts[0]}]", field=f"vary.{key}")
        return parts[0], parts[1:]
    return "common", parts


def _set_path(d: Any, path: list[str], value: Any, key: str) -> None:
    for i, p in enumerate(path):
        last = i == len(path) - 1
        if isinstance(d, list):
            if not p.isdigit() or int(p) >= len(d):
                raise ConfigError(
                    f"vary.{key}: {p!r} is not an index of the base's list of {len(d)}",
                    field=f"vary.{key}",
                )
            if last:
                d[int(p)] = value
            else:
                d = d[int(p)]
        elif isinstance(d, dict):
            if last:
                d[p] = value
            else:
                d = d.setdefault(p, {})
        else:
            raise ConfigError(f"vary.{key}: {p!r} is inside a plain value", field=f"vary.{key}")


def apply_values(base: dict[str, Any], values: dict[str, Any]) -> dict[str, Any]:
    """A deep copy of the ``[base]`` table with the dotted ``values`` set in it."""
    d = copy.deepcopy(base)
    for key, value in values.items():
        section, path = _target(key)
        if not path:
            d[section] = value
        else:
            _set_path(d.setdefault(section, {}), path, value, key)
    return d


def _int(d: dict[str, Any], key: str, default: int | None, minimum: int) -> int | None:
    v = d.get(key, default)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
        raise ConfigError(f"{key}: must be an integer >= {minimum} (got {v!r})", field=key)
    return v


def parse_spec(d: dict[str, Any], source: str = "spec") -> CampaignSpec:
    """Validate a spec's structure and distributions (not yet the core settings)."""
    try:
        unknown = sorted(set(d) - _TOP_KEYS)
        if unknown:
            raise ConfigError(f"unknown key {unknown[0]!r}", field=unknown[0])
        if not isinstance(d.get("name"), str) or not d["name"]:
            raise ConfigError("name: missing (a non-empty string)", field="name")
        samples = _int(d, "samples", None, 1)
        if samples is None:
            raise ConfigError("samples: missing", field="samples")
        seed = _int(d, "seed", 0, 0) or 0
        batch = _int(d, "batch_size", None, 1)
        ctrls = d.get("controllers", ["pid", "lqr", "mpc"])
        if not isinstance(ctrls, list) or not ctrls:
            raise ConfigError("controllers: must be a non-empty list", field="controllers")
        for c in ctrls:
            if c not in CONTROLLERS or c in ("mpc_adaptive", "mpc_oracle"):
                raise ConfigError(f"controllers: unknown controller {c!r}", field="controllers")
        if len(set(ctrls)) != len(ctrls):
            raise ConfigError("controllers: listed twice", field="controllers")
        base = d.get("base", {})
        if not isinstance(base, dict):
            raise ConfigError("base: must be a table", field="base")
        bad = sorted(set(base) - _BASE_KEYS)
        if bad:
            raise ConfigError(f"base.{bad[0]}: unknown key", field=f"base.{bad[0]}")
        mission = base.get("mission")
        if mission is not None:
            if not isinstance(mission, dict) or "seed" in mission:
                raise ConfigError(
                    "base.mission: a table of the random plan's fields (its seed is the sample's)",
                    field="base.mission",
                )
            if base.get("axes") != "ne":
                raise ConfigError(
                    'base.axes: a mission flies both axes; set axes = "ne"', field="base.axes"
                )
            for c in ctrls:
                if c not in MISSION_CONTROLLERS:
                    raise ConfigError(
                        f"controllers: {c!r} does not fly missions (they fly "
                        f"{', '.join(MISSION_CONTROLLERS)})",
                        field="controllers",
                    )
        vary_raw = d.get("vary", {})
        if not isinstance(vary_raw, dict):
            raise ConfigError("vary: must be a table of dotted keys", field="vary")
        vary: dict[str, Distribution] = {}
        for key, spec in vary_raw.items():
            _target(key)
            vary[key] = parse_distribution(spec, f"vary.{key}")
        return CampaignSpec(
            name=d["name"],
            samples=samples,
            seed=seed,
            controllers=list(ctrls),
            description=str(d.get("description", "")),
            batch_size=batch,
            base=base,
            vary=vary,
            raw=copy.deepcopy(d),
        )
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}", field=exc.field) from None


def check_spec(spec: CampaignSpec, source: str = "spec", draws: int = CHECK_DRAWS) -> None:
    """Build and check in the core the experiment of the distributions' lower and upper
    bounds and of the first ``draws`` samples, so a typo or an impossible value fails
    before anything flies; the error names the dotted key."""
    from swingrt.campaign.sampling import bound

    trials: list[tuple[str, dict[str, Any]]] = []
    for which in ("low", "high"):
        trials.append((f"the {which} bounds", {k: bound(v, which) for k, v in spec.vary.items()}))
    for i in range(min(draws, spec.samples)):
        trials.append((f"sample {i}", spec.draw(i)))
    for i, (what, values) in enumerate(trials):
        try:
            spec.experiment(values, label=what)
            spec.mission(values, i)
        except ConfigError as exc:
            msg = str(exc)
            for prefix in (f"{what}: ", f"case {what}: "):
                msg = msg.removeprefix(prefix)
            key = next((k for k in spec.vary if exc.field and exc.field.startswith(k)), None)
            where = f"vary.{key} at {what}" if key else what
            raise ConfigError(f"{source}: {msg} ({where})", field=exc.field) from None


def load_spec(path: str | os.PathLike[str]) -> CampaignSpec:
    """Read, parse and check a spec file."""
    from swingrt.scenario import read_toml

    p = Path(path)
    spec = parse_spec(read_toml(p), str(p))
    check_spec(spec, str(p))
    return spec


def spec_difference(old: dict[str, Any], new: dict[str, Any], prefix: str = "") -> str | None:
    """The first dotted key at which two canonical specs differ, with both values."""
    for k in sorted(set(old) | set(new)):
        name = f"{prefix}{k}"
        if k not in old:
            return f"{name} added ({new[k]!r})"
        if k not in new:
            return f"{name} removed (was {old[k]!r})"
        a, b = old[k], new[k]
        if isinstance(a, dict) and isinstance(b, dict):
            sub = spec_difference(a, b, f"{name}.")
            if sub:
                return sub
        elif a != b:
            return f"{name} changed from {a!r} to {b!r}"
    return None
