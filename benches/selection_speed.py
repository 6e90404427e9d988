"""Time of ``identify --search`` (the search, then the control-relevant selection with a twin)
on flights where many candidates must be flown, against another swingrt for comparison.

The flights are samples of the robustness campaign (``examples/campaigns/robustness.toml``)
whose payload is a double pendulum with swing-sensor noise: 201 (0.0097 rad, the first
candidate that passes is the 29th) and 42 (0.0055 rad, the 24th). Each is identified with
the twin ``identify`` flies by default (the built-in vehicle) and with the exact airframe as
a campaign's ``twin = "exact"`` does. For each, prints the number of candidates flown, the
model chosen and the median wall time over ``--repeat`` runs; with ``--baseline DIR`` (the
``python`` directory of another checkout, its ``_core`` built) the same runs in a
subprocess on that swingrt: its candidates flown and model chosen, the ratio of the
medians, and whether both chose the same model with the same figures (relative 1e-6).
``--settings JSON`` passes selection settings (keywords of ``sysid.select_for_control``) to
this swingrt's runs only: e.g. ``'{"look_ahead": 0}'`` to time it without a rule the
baseline does not have. Run it under ``taskset -c 0`` for the one-core figure (the
selection flies independent checks side by side on the cores it may use). Exit status 1
when the choices differ and ``--same`` was given.

    python benches/selection_speed.py [--repeat 5] [--samples 201 42] [--baseline DIR]
        [--settings JSON] [--same]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def sample(index: int):
    """Training flight and training scenario of robustness-campaign sample ``index``."""
    from swingrt.campaign.spec import parse_spec
    from swingrt.experiments import training_scenario
    from swingrt.sim import _run

    spec = parse_spec(tomllib.loads((ROOT / "examples/campaigns/robustness.toml").read_text()))
    exp = spec.experiment(spec.draw(index), label=str(index))
    sc = training_scenario(exp, {}, spec.flight_seed(index))
    return _run(sc, False, "collect"), sc


def measure(samples: list[int], repeat: int, settings: dict) -> dict:
    """Per sample and twin: median seconds, candidates flown, the choice and its figures."""
    from swingrt import sysid
    from swingrt.scenario import resolve

    out = {}
    for index in samples:
        train, exact = sample(index)
        for twin_name, twin in (("builtin", resolve(None, default="step")), ("exact", exact)):
            times = []
            for _ in range(repeat):
                t0 = time.perf_counter()
                result = sysid.search(train)
                picked = sysid.select_for_control(train, result, twin=twin, **settings)
                times.append(time.perf_counter() - t0)
            cc = picked.model.diagnostics["control_check"]
            out[f"{index}/{twin_name}"] = {
                "median_s": statistics.median(times),
                "flown": len(cc["checked"]),
                "chosen": [picked.model.delays, picked.model.rank],
                "checked": cc["checked"],
            }
    return out


def same_figures(a, b, rel: float = 1e-6) -> bool:
    """Whether two JSON trees are equal, floats within ``rel``."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_figures(a[k], b[k], rel) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same_figures(x, y, rel) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return a == b or math.isclose(a, b, rel_tol=rel) or (math.isnan(a) and math.isnan(b))
    return a == b


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--samples", type=int, nargs="+", default=[201, 42])
    ap.add_argument("--baseline", help="python directory of another swingrt to compare with")
    ap.add_argument("--settings", default="{}", help="selection settings of this swingrt")
    ap.add_argument("--same", action="store_true", help="exit 1 when the choices differ")
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    settings = json.loads(args.settings)
    if not isinstance(settings, dict):
        ap.error("--settings: a JSON object of selection settings")
    here = measure(args.samples, args.repeat, settings)
    if args.json:
        json.dump(here, sys.stdout)
        return 0
    base = None
    if args.baseline:
        env = dict(os.environ, PYTHONPATH=str(Path(args.baseline).resolve()))
        cmd = [sys.executable, __file__, "--json", "--repeat", str(args.repeat), "--samples"]
        run = subprocess.run(
            cmd + [str(s) for s in args.samples], env=env, capture_output=True, text=True
        )
        if run.returncode != 0:
            print(run.stderr, file=sys.stderr)
            return 2
        base = json.loads(run.stdout)
    print(f"{'flight/twin':<14} {'flown':>5} {'chosen':>9} {'median s':>9}", end="")
    if base:
        print(f" {'base flown':>10} {'base chose':>10} {'baseline s':>10} {'ratio':>6} {'same':>5}")
    else:
        print()
    differ = False
    for key, r in here.items():
        line = f"{key:<14} {r['flown']:>5} {str(tuple(r['chosen'])):>9} {r['median_s']:>9.2f}"
        if base:
            b = base[key]
            same = b["chosen"] == r["chosen"] and same_figures(b["checked"], r["checked"])
            differ |= not same
            chose = str(tuple(b["chosen"]))
            ratio = b["median_s"] / r["median_s"]
            line += f" {b['flown']:>10} {chose:>10} {b['median_s']:>10.2f}"
            line += f" {ratio:>5.2f}x {same!s:>5}"
        print(line)
    return 1 if differ and args.same else 0


if __name__ == "__main__":
    sys.exit(main())
