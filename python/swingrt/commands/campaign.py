"""``swingrt campaign``: a Monte Carlo study on Dask (see :mod:`swingrt.campaign`)."""

from __future__ import annotations

import argparse
import math
import statistics
from pathlib import Path


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the subcommand."""
    p = sub.add_parser(
        "campaign",
        help="Monte Carlo study: sampled payloads, wind, noise, settings; on Dask",
        description="Fly every sample of SPEC.toml (training flight, identification, each "
        "controller on the step) on an embedded Dask cluster or an existing scheduler, into "
        "a resumable Parquet dataset with a report. Rerunning the same command resumes.",
    )
    p.add_argument("spec", nargs="?", help="campaign spec (TOML)")
    p.add_argument("--out", help="output folder (default: runs/campaign-<name>)")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers", type=int, help="worker processes of the embedded cluster (default: cores)"
    )
    where.add_argument("--scheduler", metavar="ADDRESS", help="existing Dask scheduler (tcp://…)")
    p.add_argument(
        "--rerun",
        nargs=2,
        metavar=("DIR", "INDEX"),
        help="replay sample INDEX of the campaign in DIR with its traces and figures",
    )
    p.add_argument(
        "--draws",
        type=int,
        metavar="N",
        help="with --rerun: also fly the sample's evaluation on N noise realisations (draw 0 "
        "the campaign's own) and say how often each controller fails (draws.csv)",
    )
    p.add_argument("--no-report", action="store_true", help="skip writing report.md")
    return p


def _report_draws(flown: list[list[dict]], index: int, out: Path, mission: bool) -> None:
    """Print each controller's failures among the noise draws ``flown`` and its swing
    ratio's spread; write ``draws.csv``."""
    from swingrt.campaign.flight import RATIO
    from swingrt.io.atomic import write_text_atomic
    from swingrt.reports.tables import csv_text

    draws = len(flown)
    rows = [{"draw": k, **r} for k, draw in enumerate(flown) for r in draw]
    write_text_atomic(out / "draws.csv", csv_text(rows, list(rows[0])))
    for ctrl in dict.fromkeys(r["controller"] for r in rows):
        mine = [r for r in rows if r["controller"] == ctrl]
        why = [r["failure"] for r in mine if r["failure"]]
        reasons = ", ".join(f"{w} {why.count(w)}" for w in dict.fromkeys(why))
        line = f"sample {index} {ctrl:4s} fails {len(why)} of {draws} noise draws"
        line += f" ({reasons})" if why else ""
        ratios = [r[RATIO] for r in mine if not mission and not math.isnan(r.get(RATIO, math.nan))]
        if ratios and ctrl != "pid":
            line += (
                f"; swing excess vs PID median {statistics.median(ratios):.3g}, "
                f"range {min(ratios):.3g}-{max(ratios):.3g}"
            )
        print(line)
    print(f"wrote {out}/draws.csv")


def _rerun(folder: str, index_text: str, draws: int | None = None) -> int:
    from swingrt.campaign.flight import fly_noise_draws, metric_columns
    from swingrt.campaign.results import read_rows, stored_spec
    from swingrt.campaign.spec import parse_spec
    from swingrt.errors import ConfigError
    from swingrt.reports.plots import plot_case, plot_mission

    try:
        index = int(index_text)
    except ValueError:
        raise ConfigError(f"--rerun: INDEX must be an integer (got {index_text!r})") from None
    raw = stored_spec(folder)
    spec = parse_spec(raw, f"{folder}/campaign.json")
    if not 0 <= index < spec.samples:
        raise ConfigError(f"--rerun: INDEX must be in 0..{spec.samples - 1} (got {index})")
    out = Path(folder) / "rerun" / f"sample-{index:06d}"
    flown, traces = fly_noise_draws(raw, index, 1 if draws is None else draws, out)
    rows = flown[0]
    exp_axes = spec.base.get("axes", "n")
    plan = spec.mission(spec.draw(index), index)
    if traces and plan is not None:
        flights = {c: (tr.columns, tr.meta["mission_events"]) for c, tr in traces.items()}
        plot_mission(out / "sample.png", f"{spec.name} sample {index}", plan.items, flights)
    elif traces:
        plot_case(out / "sample.png", f"{spec.name} sample {index}", traces, exp_axes)
    from swingrt.reports.tables import csv_text

    cols = list(rows[0])
    (out / "rows.csv").write_text(csv_text(rows, cols), encoding="utf-8")
    stored = {r["controller"]: r for r in read_rows(folder) if r["sample"] == index}
    for r in rows:
        print(
            f"sample {index} {r['controller']:4s} "
            + ", ".join(f"{m} {r[m]:.4g}" for m in metric_columns(spec.is_mission))
            + (f"  FAIL ({r['failure']})" if r["failure"] else "")
        )
        old = stored.get(r["controller"])
        if old is not None:
            same = all(
                (old.get(k) == v)
                or (isinstance(v, float) and math.isnan(v) and math.isnan(old.get(k) or 0.0))
                for k, v in r.items()
            )
            print(f"  {'matches' if same else 'DIFFERS FROM'} the dataset's row")
    print(f"wrote {out}/")
    if draws is not None:
        _report_draws(flown, index, out, spec.is_mission)
    return 0


def run(args) -> int:
    """Run the subcommand."""
    from swingrt.errors import ConfigError

    if args.rerun:
        if args.spec:
            raise ConfigError("--rerun DIR INDEX takes no SPEC (the folder holds it)")
        folder, index = args.rerun
        return _rerun(folder, index, draws=args.draws)
    if args.draws is not None:
        raise ConfigError("--draws: only with --rerun DIR INDEX")
    if not args.spec:
        raise ConfigError("campaign: give SPEC.toml (or --rerun DIR INDEX)")
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers: must be >= 1 (got {args.workers})")
    from swingrt.campaign.runner import run_campaign
    from swingrt.campaign.spec import load_spec
    from swingrt.scenario import read_text

    spec = load_spec(args.spec)
    out = args.out or f"runs/campaign-{spec.name}"
    s = run_campaign(
        spec,
        out,
        workers=args.workers,
        scheduler=args.scheduler,
        spec_text=read_text(args.spec),
        report=not args.no_report,
    )
    rate = s["flown"] / s["seconds"] if s["seconds"] > 0 else 0.0
    print(
        f"{spec.name}: {s['flown']} samples flown, {s['skipped']} already done, "
        f"{s['rows']} rows; {rate:.2f} samples/s on {s['workers']} worker(s)"
        + (
            f", batches of {s['batch']}, workers busy {s['utilisation']:.0%} of the time"
            if s["flown"]
            else ""
        )
    )
    print(f"wrote {out}/" + ("" if args.no_report else " (report.md)"))
    return 0
