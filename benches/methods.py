"""The methods benchmark table (issue 27): every controller of a campaign side by side.

From the rows of a finished campaign (``swingrt campaign examples/campaigns/methods.toml
--out DIR``): per controller the failure rate with its 95 % Wilson interval (the campaign's
failure rule), and the medians of the swing IAE's excess above its floor, the residual
swing, the velocity settling time and the acceleration command's total variation, with the
seconds of training flight each design read; the failures by reason and how often each
controller had the least swing of a sample; and the medians and failure rates on subsets of
the samples (light or strong wind, short or long cable, heavy payload, double pendulum).

With ``--timing N`` it also trains every method on the training flights of the first N
samples and flies each sample's evaluation with the real budget (a tick may take one
period before the hand-back to PX4): the wall-clock identification / training time and the
median and p99 tick time on this machine. A method whose p99 misses its period is marked.

Run:  python benches/methods.py DIR [--timing N] [--out table.md]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from swingrt.campaign import load_spec, read_rows
from swingrt.campaign.report import wilson
from swingrt.io.atomic import write_text_atomic

#: Medians the table shows: (column, heading).
MEDIANS = (
    ("swing_excess_iae_deg_s", "swing excess IAE [deg·s]"),
    ("residual_swing_deg", "residual swing [deg]"),
    ("v_settle_s", "v settle [s]"),
    ("acc_sp_tv", "command TV [m/s²]"),
)


def _median(v: list[float]) -> str:
    a = np.asarray(v, dtype=float)
    fin = a[np.isfinite(a)]
    if not len(fin):
        return "—"
    inf = int(np.isinf(a).sum())
    return f"{np.median(fin):.3g}" + (f" (∞ ×{inf})" if inf else "")


def table(rows: list[dict[str, Any]], ctrls: list[str]) -> list[str]:
    """The failure and metric table of the campaign rows, one line per controller."""
    head = "| controller | flights | failed | rate [95 % CI] | " + " | ".join(h for _, h in MEDIANS)
    lines = [head + " | training flight [s] |", "|---|" + "---:|" * (len(MEDIANS) + 4)]
    for c in ctrls:
        sel = [r for r in rows if r["controller"] == c]
        if not sel:
            continue
        k = sum(1 for r in sel if r.get("failure"))
        lo, hi = wilson(k, len(sel))
        ok = [r for r in sel if not r.get("error")]
        cells = [_median([r[m] for r in ok]) for m, _ in MEDIANS]
        data = _median([r.get("training_s", math.nan) for r in ok])
        lines.append(
            f"| {c} | {len(sel)} | {k} | {k / len(sel):.1%} [{lo:.1%}, {hi:.1%}] | "
            + " | ".join(cells)
            + f" | {data} |"
        )
    return lines


#: Subsets of the samples the slice table compares on: (heading, predicate on a row).
SLICES: tuple[tuple[str, Any], ...] = (
    ("all", lambda r: True),
    ("wind < 1 m/s", lambda r: _wind(r) < 1.0),
    ("wind ≥ 2 m/s", lambda r: _wind(r) >= 2.0),
    ("cable < 0.6 m", lambda r: r["payload.length"] < 0.6),
    ("cable > 1.5 m", lambda r: r["payload.length"] > 1.5),
    ("payload > 0.3 kg", lambda r: r["payload.mass"] > 0.3),
    ("double pendulum", lambda r: r["payload.kind"] == "double"),
)


def _wind(r: dict[str, Any]) -> float:
    return math.hypot(r["wind.velocity[0]"], r["wind.velocity[1]"])


def reasons(rows: list[dict[str, Any]], ctrls: list[str]) -> list[str]:
    """Per controller its failures by reason (the campaign's failure rule), and how often
    it had the least swing excess IAE of the sample's flights that did not fail."""
    by_sample: dict[int, list[dict[str, Any]]] = {}
    for r in rows:
        by_sample.setdefault(r["sample"], []).append(r)
    wins = dict.fromkeys(ctrls, 0)
    for sel in by_sample.values():
        ok = [r for r in sel if not r.get("failure") and r["controller"] in wins]
        if ok:
            wins[min(ok, key=lambda r: r["swing_excess_iae_deg_s"])["controller"]] += 1
    lines = ["| controller | failures by reason | least swing excess in |", "|---|---|---:|"]
    for c in ctrls:
        fails: dict[str, int] = {}
        for r in rows:
            if r["controller"] == c and r.get("failure"):
                fails[r["failure"]] = fails.get(r["failure"], 0) + 1
        text = ", ".join(f"{k} {v}" for k, v in sorted(fails.items(), key=lambda kv: -kv[1]))
        lines.append(f"| {c} | {text or '—'} | {wins[c] / max(len(by_sample), 1):.0%} |")
    return lines


def slices(rows: list[dict[str, Any]], ctrls: list[str]) -> list[str]:
    """Median swing excess IAE [deg·s] / failure rate per controller on subsets of the
    samples (:data:`SLICES`; the sample count under each heading)."""
    usable = [(h, f) for h, f in SLICES if all(_has(r, f) for r in rows[:1])]
    sets = [(h, {r["sample"] for r in rows if f(r)}) for h, f in usable]
    head = "| controller | " + " | ".join(f"{h} (n={len(s)})" for h, s in sets) + " |"
    lines = [head, "|---|" + "---:|" * len(sets)]
    for c in ctrls:
        cells = []
        for _, samples in sets:
            sel = [r for r in rows if r["controller"] == c and r["sample"] in samples]
            if not sel:
                cells.append("—")
                continue
            k = sum(1 for r in sel if r.get("failure"))
            med = _median([r["swing_excess_iae_deg_s"] for r in sel if not r.get("error")])
            cells.append(f"{med} / {k / len(sel):.0%}")
        lines.append(f"| {c} | " + " | ".join(cells) + " |")
    return lines


def _has(row: dict[str, Any], pred: Any) -> bool:
    try:
        pred(row)
    except KeyError:
        return False
    return True


def timing(spec: Any, samples: int) -> list[str]:
    """Train every controller of ``spec`` on the first ``samples`` samples and fly their
    evaluations with the real tick budget; the identification and tick-time table."""
    from swingrt.experiments import (
        evaluation_scenario,
        identify_case,
        simulate_controller,
        train_methods,
        training_scenario,
    )
    from swingrt.methods import METHODS
    from swingrt.sim import _run

    ident: dict[str, list[float]] = {c: [] for c in spec.controllers}
    med: dict[str, list[float]] = {c: [] for c in spec.controllers}
    p99: dict[str, list[float]] = {c: [] for c in spec.controllers}
    period: dict[str, float] = {}
    for i in range(samples):
        exp = spec.experiment(spec.draw(i), label=f"{spec.name} #{i}")
        seed = spec.flight_seed(i)
        train_sc = training_scenario(exp, {}, seed)
        ev_sc = evaluation_scenario(exp, {}, seed + 1, train_sc)
        train = _run(train_sc, False, "collect")
        t0 = time.perf_counter()
        model, _, lqr = identify_case(train, exp, None, twin=train_sc)
        dmdc_s = time.perf_counter() - t0
        for c in spec.controllers:
            trained = None
            if c in METHODS:
                trained = train_methods(train, _one(exp, c), model, lqr, train_sc)[c]
                ident[c].append(trained.ident_seconds)
            else:
                ident[c].append(0.0 if c == "pid" else dmdc_s)
            _, extras = simulate_controller(
                ev_sc,
                c,
                model=model,
                lqr_params=lqr,
                mpc_settings=exp.mpc or None,
                lqr_settings=exp.lqr or None,
                method=trained,
            )
            if "tick_us_median" in extras:
                med[c].append(extras["tick_us_median"])
                p99[c].append(extras["tick_us_p99"])
            period[c] = _period(c, trained, model, exp)
    lines = [
        "| controller | identification / training [s] | tick median [µs] | tick p99 [µs] "
        "| period [ms] | p99 fits |",
        "|---|---:|---:|---:|---:|---|",
    ]
    for c in spec.controllers:
        if c == "pid":
            lines.append("| pid | 0 | — | — | — | (PX4) |")
            continue
        m = statistics.median(med[c]) if med[c] else math.nan
        p = max(p99[c]) if p99[c] else math.nan
        per = period[c] * 1e3
        fits = "yes" if p <= per * 1e3 else f"NO ({p / (per * 1e3):.1f}× the period)"
        lines.append(
            f"| {c} | {statistics.median(ident[c]):.2f} | {m:.0f} | {p:.0f} | {per:g} | {fits} |"
        )
    return lines


def _one(exp: Any, ctrl: str) -> Any:
    import copy

    e = copy.copy(exp)
    e.controllers = [ctrl]
    return e


def _period(c: str, trained: Any, model: Any, exp: Any) -> float:
    """A controller's tick period [s]."""
    if trained is not None:
        from swingrt.methods import controller

        return float(controller(trained).period)
    if c == "lqr":
        from swingrt import _core

        return float(_core.check_settings("lqr", exp.lqr or None)["period"])
    return float(model.dt)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a finished campaign's output folder")
    ap.add_argument("--timing", type=int, default=0, help="samples to time (0: none)")
    ap.add_argument("--out", type=Path, help="also write the tables (Markdown) here")
    a = ap.parse_args()
    spec = load_spec(a.run / "spec.toml")
    rows = read_rows(a.run)
    n = len({r["sample"] for r in rows})
    lines = [f"Campaign {spec.name}: {n} samples, seed {spec.seed}.", ""]
    lines += table(rows, list(spec.controllers))
    lines += ["", "Failures by reason; share of samples where each had the least swing excess "
              "of the flights that did not fail:", ""]  # fmt: skip
    lines += reasons(rows, list(spec.controllers))
    lines += ["", "Median swing excess IAE [deg·s] / failure rate, by subset of the samples:", ""]
    lines += slices(rows, list(spec.controllers))
    if a.timing:
        lines += ["", f"Timing over {a.timing} sample(s), real tick budget:", ""]
        lines += timing(spec, a.timing)
    text = "\n".join(lines) + "\n"
    print(text, end="")
    if a.out:
        write_text_atomic(a.out, text)


if __name__ == "__main__":
    main()
