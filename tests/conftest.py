"""Shared fixtures: run the CLI in-process or as a subprocess of the installed wheel."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.fixture
def cli():
    """Run ``swingrt ARGS`` as a subprocess; returns the CompletedProcess."""

    def run(*args: str, timeout: float = 300.0, cwd=None) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "swingrt", *map(str, args)],
            capture_output=True,
            text=True,
            timeout=timeout,
            cwd=cwd,
        )

    return run
