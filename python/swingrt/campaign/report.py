"""The campaign report: ``DIR/report.md`` and its figures.

- failure rates per controller with 95 % Wilson intervals (failure: see
  :mod:`swingrt.campaign.flight`), and the count of each reason;
- metric distributions per controller (``metrics.png``, percentiles in the text);
- each metric that matters for the swing against every numeric sampled parameter
  (``vs_<parameter>.png``);
- the 10 worst samples with the command that replays each one.
"""

from __future__ import annotations

import math
import os
import re
import shlex
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from swingrt.campaign.flight import (
    DATA_COLUMNS,
    DIVERGED_SWING_DEG,
    IDENT_COLUMNS,
    SS_ERROR_LIMIT,
    SWING_EXCESS_MIN,
    SWING_EXCESS_RATIO,
    metric_columns,
)
from swingrt.campaign.results import read_rows
from swingrt.campaign.spec import CampaignSpec
from swingrt.io.atomic import write_text_atomic

_NOT_PARAMS = {"sample", "controller", "flight_seed", "fallback", "error", "failure"}
#: How many worst samples the report lists.
WORST = 10


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval of a proportion k/n (95 % for z = 1.96)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return (max(0.0, centre - half), min(1.0, centre + half))


def param_names(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The sampled parameter columns of the rows, in column order."""
    skip = _NOT_PARAMS | set(IDENT_COLUMNS) | set(DATA_COLUMNS)
    skip |= set(metric_columns()) | set(metric_columns(True))
    return [k for k in (rows[0] if rows else {}) if k not in skip]


def _swing_metric(mission: bool = False) -> str:
    if mission:
        return "leg_swing_max_deg"
    cols = metric_columns()
    return "swing_excess_iae_deg_s" if "swing_excess_iae_deg_s" in cols else "swing_iae_deg_s"


def _settle_metric(mission: bool) -> str:
    return "settle_1deg_s" if mission else "v_settle_s"


def worst_samples(
    rows: Sequence[dict[str, Any]], n: int = WORST, mission: bool = False
) -> list[dict[str, Any]]:
    """The ``n`` worst samples: most failed controllers first (PID counted only when it was
    the only one flown), then the largest swing metric among those controllers."""
    ctrls = {r["controller"] for r in rows}
    judged = ctrls - {"pid"} or ctrls
    metric = _swing_metric(mission)
    by: dict[int, dict[str, Any]] = {}
    for r in rows:
        if r["controller"] not in judged:
            continue
        s = by.setdefault(r["sample"], {"sample": r["sample"], "failed": [], "swing": -math.inf})
        if r.get("failure"):
            s["failed"].append(f"{r['controller']} ({r['failure']})")
        v = r.get(metric)
        if v is not None and not (isinstance(v, float) and math.isnan(v)):
            s["swing"] = max(s["swing"], float(v))
        elif r.get("failure"):
            s["swing"] = math.inf
    ranked = sorted(by.values(), key=lambda s: (-len(s["failed"]), -s["swing"], s["sample"]))
    return ranked[:n]


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _plots(
    out: Path,
    rows: list[dict[str, Any]],
    ctrls: list[str],
    params: list[str],
    logs: set[str],
    mission: bool = False,
) -> list[str]:
    """Write the figures; ``logs``: the parameters drawn log-uniformly (log axis)."""
    from swingrt.reports.plots import _STYLE, _pyplot, save_figure

    plt = _pyplot()
    from matplotlib.ticker import NullFormatter

    written = []
    metrics = list(metric_columns(mission))
    ncol = 3
    nrow = math.ceil(len(metrics) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.2 * nrow), squeeze=False)
    for ax, m in zip(axes.flat, metrics, strict=False):
        data = []
        for c in ctrls:
            v = np.asarray([r[m] for r in rows if r["controller"] == c], dtype=float)
            data.append(v[np.isfinite(v)])
        if any(len(d) for d in data):
            ax.boxplot([d if len(d) else [np.nan] for d in data])
            ax.set_xticks(range(1, len(ctrls) + 1), ctrls)
        ax.set_title(m, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(metrics) :]:
        ax.set_visible(False)
    fig.suptitle("metric distributions per controller (finite values)")
    fig.tight_layout()
    save_figure(fig, out / "metrics.png", dpi=100, tight=False)
    written.append("metrics.png")
    swing = _swing_metric(mission)
    for p in params:
        vals = [r.get(p) for r in rows]
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
            continue
        if len({float(v) for v in vals if v is not None}) < 2:
            continue
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), squeeze=False)
        for j, m in enumerate((swing, _settle_metric(mission))):
            ax = axes[0, j]
            for c in ctrls:
                sel = [r for r in rows if r["controller"] == c]
                x = np.asarray([r[p] for r in sel], dtype=float)
                y = np.asarray([r[m] for r in sel], dtype=float)
                color, label = _STYLE.get(c, (None, c))
                ax.scatter(x, np.where(np.isfinite(y), y, np.nan), s=10, color=color, label=label)
            ax.set_xlabel(p)
            if p.split("[")[0] in logs:
                ax.set_xscale("log")
                ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_ylabel(m)
            ax.grid(alpha=0.3)
        axes[0, 0].legend(fontsize=8)
        fig.tight_layout()
        name = "vs_" + re.sub(r"[^A-Za-z0-9_.-]+", "_", p) + ".png"
        save_figure(fig, out / name, dpi=100, tight=False)
        written.append(name)
    return written


def _rules(mission: bool) -> str:
    """The failure rules the report's rates count, in one paragraph."""
    if not mission:
        return (
            "A flight **fails** when the sample raised an error, the controller fell back to "
            "PX4 PID, it diverged (a NaN metric or a peak swing above "
            f"{DIVERGED_SWING_DEG:g}°), the velocity never settled within 5 % of the step, "
            f"the steady-state error is ≥ {SS_ERROR_LIMIT} m/s, or (LQR, MPC) the swing IAE's "
            f"excess above its floor is ≥ {SWING_EXCESS_RATIO:g}× PID's in the same sample and "
            f"≥ {SWING_EXCESS_MIN:g} deg·s. Intervals: 95 % Wilson."
        )
    from swingrt import mission as ms

    return (
        "The evaluation flight is the sample's random plan; `pid` is PX4's mission mode. A "
        "flight **fails** when the sample raised an error, the controller fell back to PX4, "
        f"it diverged (a peak swing above {ms.DIVERGED_SWING_DEG:g}°), after some arrival the "
        f"swing was not within {ms.SETTLED_DEG:g}° within {ms.SETTLE_LIMIT_S:g} s for the "
        f"rest of the hold (`settle`), the vehicle left {ms.HOLD_LIMIT_M:g} m of a waypoint "
        f"during its hold (`hold`), or (MPC) the plan took more than "
        f"{ms.TIME_RATIO_LIMIT:g}× PX4's time (`slow`) or some leg's largest swing was more "
        f"than {ms.LEG_SWING_RATIO:g}× PX4's on that leg (`swing`). Intervals: 95 % Wilson."
    )


def write_report(out: str | os.PathLike[str], spec: CampaignSpec, figures: bool = True) -> Path:
    """Write ``report.md`` (and the figures) from the dataset in ``out``."""
    out = Path(out)
    rows = read_rows(out)
    mission = spec.is_mission
    ctrls = [c for c in spec.controllers if any(r["controller"] == c for r in rows)]
    params = param_names(rows)
    done = len({r["sample"] for r in rows})
    lines = [
        f"# Campaign {spec.name}",
        "",
        spec.description or "",
        "",
        f"{done} of {spec.samples} samples finished ({len(rows)} flights), seed {spec.seed}, "
        f"spec SHA-256 `{spec.digest()[:16]}…`.",
        "",
        "## Failure rates",
        "",
        _rules(mission),
        "",
        "| controller | flights | failed | rate | 95 % CI | reasons |",
        "|---|---:|---:|---:|---|---|",
    ]
    for c in ctrls:
        sel = [r for r in rows if r["controller"] == c]
        k = sum(1 for r in sel if r.get("failure"))
        lo, hi = wilson(k, len(sel))
        reasons: dict[str, int] = {}
        for r in sel:
            if r.get("failure"):
                reasons[r["failure"]] = reasons.get(r["failure"], 0) + 1
        why = ", ".join(f"{w} {n}" for w, n in sorted(reasons.items())) or "—"
        lines.append(
            f"| {c} | {len(sel)} | {k} | {k / max(len(sel), 1):.1%} | "
            f"[{lo:.1%}, {hi:.1%}] | {why} |"
        )
    lines += [
        "",
        "## Metric distributions",
        "",
        "Median [10th, 90th percentile] over the finite values (∞ = never settled).",
        "",
        "| metric | " + " | ".join(ctrls) + " |",
        "|---|" + "---|" * len(ctrls),
    ]
    for m in metric_columns(mission):
        cells = []
        for c in ctrls:
            v = np.asarray([r[m] for r in rows if r["controller"] == c], dtype=float)
            fin = v[np.isfinite(v)]
            inf = int(np.isinf(v).sum())
            cell = (
                f"{np.median(fin):.3g} [{np.percentile(fin, 10):.3g}, {np.percentile(fin, 90):.3g}]"
                if len(fin)
                else "—"
            )
            cells.append(cell + (f" (∞ ×{inf})" if inf else ""))
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    logs = {k for k, d in spec.vary.items() if d.kind == "loguniform"}
    figs = _plots(out, rows, ctrls, params, logs, mission) if figures and rows else []
    if figs:
        lines += ["", "## Figures", ""]
        lines += [f"![{f}]({f})" for f in figs]
    worst = worst_samples(rows, mission=mission)
    lines += [
        "",
        f"## The {len(worst)} worst samples",
        "",
        f"Most failed controllers first, then the largest {_swing_metric(mission)}.",
        "",
        "| sample | failed | " + _swing_metric(mission) + " | parameters | replay |",
        "|---:|---|---:|---|---|",
    ]
    by_sample = {r["sample"]: r for r in rows}
    for s in worst:
        r = by_sample[s["sample"]]
        pv = ", ".join(f"{p} = {_fmt(r.get(p))}" for p in params)
        cmd = f"swingrt campaign --rerun {shlex.quote(str(out))} {s['sample']}"
        lines.append(
            f"| {s['sample']} | {'; '.join(s['failed']) or '—'} | {_fmt(s['swing'])} | {pv} | "
            f"`{cmd}` |"
        )
    path = out / "report.md"
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path
