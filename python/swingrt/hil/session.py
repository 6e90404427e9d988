"""A HIL session in its own process: PX4 SITL + ``swingrt hil``, airborne, for the length of
a ``with`` block.

The HIL loop is real-time work; running it in a child process keeps it off the interpreter
that flies the offboard node (one GIL each), as on the real rig where the simulator and the
companion computer are different machines.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from swingrt.errors import LinkError

__all__ = ["HilSession"]

#: Wall seconds from start to "ready" (PX4 boot, estimator convergence, take-off climb).
READY_TIMEOUT = 180.0


class HilSession:
    """``swingrt hil --px4 DIR --takeoff`` as a child process; ``with`` waits until the
    vehicle holds at the take-off altitude and, on exit, stops PX4 cleanly and collects the
    ULog paths (:attr:`ulogs`) and the loop summary (:attr:`summary`)."""

    def __init__(
        self,
        px4_dir,
        *,
        scenario=None,
        instance: int = 0,
        workdir=None,
        log=None,
        seed: int | None = None,
        echo=None,
    ):
        cmd = [sys.executable, "-m", "swingrt", "hil", "--px4", str(px4_dir), "--takeoff"]
        cmd += ["--instance", str(instance)]
        if scenario is not None:
            cmd.append(str(scenario))
        if workdir is not None:
            cmd += ["--workdir", str(workdir)]
        if log is not None:
            cmd += ["--log", str(log)]
        if seed is not None:
            cmd += ["--seed", str(seed)]
        self.cmd = cmd
        self.instance = instance
        self.echo = echo
        self.lines: list[str] = []
        self.ulogs: list[Path] = []
        self.summary = ""
        self._ready = threading.Event()
        self._thread: threading.Thread | None = None
        self.proc: subprocess.Popen | None = None

    @property
    def onboard_url(self) -> str:
        """Where the offboard node listens for this PX4."""
        return f"udpin:0.0.0.0:{14540 + self.instance}"

    def _reader(self) -> None:
        assert self.proc is not None and self.proc.stdout is not None
        for raw in self.proc.stdout:
            line = raw.rstrip("\n")
            self.lines.append(line)
            if self.echo is not None and line.startswith("hil:"):
                self.echo(line)
            if line.startswith("hil: ready"):
                self._ready.set()
            m = re.match(r"hil: PX4 log (.+)$", line)
            if m:
                self.ulogs.append(Path(m.group(1)))
            if line.startswith("hil: ") and "simulated in" in line:
                self.summary = line[len("hil: ") :]

    def __enter__(self) -> HilSession:
        self.proc = subprocess.Popen(
            self.cmd,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        self._thread = threading.Thread(target=self._reader, daemon=True)
        self._thread.start()
        deadline = time.monotonic() + READY_TIMEOUT
        while not self._ready.wait(0.2):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.stop()
                tail = " | ".join(self.lines[-4:])
                raise LinkError(f"PX4 in the loop did not get airborne: {tail}")
        return self

    def stop(self) -> None:
        """SIGINT the session (it lands nothing: PX4 is shut down in the air, its log
        closed) and wait for it."""
        if self.proc is None:
            return
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=40.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5.0)
        if self._thread is not None:
            self._thread.join(timeout=5.0)  # the reader takes the last lines
        if self.proc.stdout is not None:
            self.proc.stdout.close()

    def __exit__(self, *exc) -> None:
        self.stop()
