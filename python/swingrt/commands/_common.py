"""Shared argument helpers of the subcommands."""

from __future__ import annotations

import argparse
import contextlib
import math
from collections.abc import Iterator

from swingrt.errors import ConfigError


def add_scenario_args(p: argparse.ArgumentParser) -> None:
    """SCENARIO positional plus --duration and --seed."""
    p.add_argument("scenario", nargs="?", help="scenario TOML (default: built-in)")
    p.add_argument("--duration", type=float, help="simulated duration [s]")
    p.add_argument("--seed", type=int, help="seed of every random generator")


def check_duration(value: float | None) -> None:
    """Reject a non-positive or non-finite --duration with a clear message."""
    if value is not None and (not math.isfinite(value) or value <= 0):
        raise ConfigError(f"--duration: must be a positive number of seconds (got {value})")


def check_output(path: str) -> None:
    """Only .parquet and .csv outputs are supported."""
    if not (path.endswith(".parquet") or path.endswith(".csv")):
        raise ConfigError(f"-o {path}: output must end in .parquet or .csv")


@contextlib.contextmanager
def options_named() -> Iterator[None]:
    """Re-raise a settings ``ConfigError`` naming the command-line option, not the field
    (``identify.delays: ...`` → ``--delays: ...``)."""
    try:
        yield
    except ConfigError as exc:
        if not exc.field:
            raise
        flag = "--" + exc.field.split(".")[-1].replace("_", "-")
        problem = str(exc).split(": ", 1)[-1]
        raise ConfigError(f"{flag}: {problem}", field=exc.field) from None
