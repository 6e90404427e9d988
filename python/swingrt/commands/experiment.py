"""``swingrt experiment``: run one of the thesis's experiments (or a TOML definition)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the subcommand."""
    p = sub.add_parser(
        "experiment",
        help="run a chapter-5 experiment: PID vs LQR vs MPC, identification included",
    )
    p.add_argument("name", nargs="?", help="built-in experiment name or FILE.toml")
    p.add_argument("--list", action="store_true", help="list the built-in experiments")
    p.add_argument("--out", help="output folder (default: runs/<name>)")
    p.add_argument("--seed", type=int, default=0, help="seed of training and evaluation")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    return p


def run(args) -> int:
    """Run the subcommand."""
    from swingrt.errors import ConfigError
    from swingrt.experiments import list_experiments, load_experiment, run_experiment

    if args.list:
        for name, desc in list_experiments().items():
            print(f"{name:18s} {desc}")
        return 0
    if not args.name:
        raise ConfigError("experiment: give a NAME or FILE.toml (see --list)")
    exp = load_experiment(args.name)
    out = args.out or f"runs/{exp.name}"
    rows = run_experiment(exp, out, seed=args.seed, quiet=args.quiet)
    print(Path(out, "metrics.md").read_text(encoding="utf-8"))
    print(f"wrote {out}/ ({len(rows)} runs)")
    return 0
