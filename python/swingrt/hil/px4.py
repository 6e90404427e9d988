"""Start and stop a PX4 SITL flight stack that waits for swingrt's physics.

Two layouts are understood: a folder with a ``run-px4`` launcher (a packaged SITL build) and
PX4's own build folder (``build/px4_sitl_default`` with ``bin/px4`` and ``etc``). PX4 runs
in a fresh working directory (parameters, dataman, ULog files), as airframe 10016 (a generic
quad whose geometry the parameters overwrite), with the simulator interface
(simulator_mavlink) as a TCP client of port 4560 + instance. Its output goes to
``WORKDIR/px4.out``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
from pathlib import Path

from swingrt.errors import ConfigError, LinkError

__all__ = ["Px4Sitl", "SIM_PORT", "GCS_PORT", "ONBOARD_PORT", "check_px4_dir"]

#: Base ports of PX4 SITL (each instance N adds N).
SIM_PORT = 4560
#: The GCS link PX4 listens on.
GCS_PORT = 18570
#: The onboard link PX4 sends to (the offboard node listens here).
ONBOARD_PORT = 14540

#: airframe of a generic quad with the simulator interface.
HIL_AIRFRAME = 10016


def check_px4_dir(px4_dir) -> Path:
    """``px4_dir`` as a folder PX4 SITL starts from (a ``px4_sitl`` build folder with
    ``bin/px4`` and ``etc/``, or a folder with a ``run-px4`` launcher); ConfigError naming
    ``--px4`` otherwise, before anything starts."""
    root = Path(px4_dir).expanduser()
    if not root.is_dir():
        raise ConfigError(f"--px4: {root} is not a folder", field="px4")
    if not (root / "run-px4").is_file() and not (
        (root / "bin" / "px4").is_file() and (root / "etc").is_dir()
    ):
        raise ConfigError(
            f"--px4: {root} is neither a PX4 SITL build folder (bin/px4 and etc/) nor a "
            "folder with a run-px4 launcher",
            field="px4",
        )
    return root


class Px4Sitl:
    """One PX4 SITL process: ``start()``, ``ulogs()``, ``stop()`` (or a ``with`` block)."""

    def __init__(
        self,
        px4_dir,
        *,
        instance: int = 0,
        params: dict | None = None,
        workdir=None,
    ):
        root = check_px4_dir(px4_dir)
        self._launcher: list[str] | None
        if (root / "run-px4").is_file():
            self._launcher = [str(root / "run-px4"), "--airframe", "hil"]
            self._env_params = False
        else:
            self._launcher = None
            self._env_params = True
        if not (0 <= instance <= 100):
            raise ConfigError(f"--instance must be 0..100, not {instance}", field="instance")
        self.root = root
        self.instance = instance
        self.params = dict(params or {})
        self.workdir = Path(workdir) if workdir else Path(tempfile.mkdtemp(prefix="swingrt-px4-"))
        self.proc: subprocess.Popen | None = None

    @property
    def sim_port(self) -> int:
        """TCP port PX4 connects to for its physics."""
        return SIM_PORT + self.instance

    @property
    def gcs_port(self) -> int:
        """UDP port of PX4's GCS link."""
        return GCS_PORT + self.instance

    @property
    def onboard_port(self) -> int:
        """UDP port PX4's onboard link sends to."""
        return ONBOARD_PORT + self.instance

    def start(self) -> None:
        """Start PX4 in the background; it blocks in its boot until the physics connects."""
        self.workdir.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ)
        assignments = [f"{k}={v}" for k, v in self.params.items()]
        if self._launcher is not None:
            cmd = [
                *self._launcher,
                "--instance",
                str(self.instance),
                "--workdir",
                str(self.workdir),
                *assignments,
            ]
        else:
            env.update(
                PX4_SYS_AUTOSTART=str(HIL_AIRFRAME),
                PX4_SIM_MODEL="none_iris",
                PX4_SIMULATOR="none",
                PATH=f"{self.root / 'bin'}{os.pathsep}{env.get('PATH', '')}",
            )
            env.update({f"PX4_PARAM_{k}": str(v) for k, v in self.params.items()})
            (self.workdir / "rootfs").mkdir(exist_ok=True)
            cmd = [
                str(self.root / "bin" / "px4"),
                "-d",
                "-i",
                str(self.instance),
                "-w",
                str(self.workdir / "rootfs"),
                str(self.root / "etc"),
            ]
        out = open(self.workdir / "px4.out", "wb")
        try:
            self.proc = subprocess.Popen(
                cmd,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                env=env,
                start_new_session=True,
            )
        except OSError as exc:
            raise LinkError(f"cannot start PX4 from {self.root}: {exc}") from None
        finally:
            out.close()

    def alive(self) -> bool:
        """Whether the PX4 process still runs."""
        return self.proc is not None and self.proc.poll() is None

    def output_tail(self, lines: int = 5) -> str:
        """The last lines PX4 printed (for error messages)."""
        try:
            text = (self.workdir / "px4.out").read_text(errors="replace")
        except OSError:
            return ""
        return " | ".join(t.strip() for t in text.strip().splitlines()[-lines:])

    def request_stop(self) -> None:
        """Ask PX4 to shut down (SIGINT to its process group); it needs its clock to move to
        finish, so keep serving it until :meth:`alive` turns False."""
        if self.alive():
            assert self.proc is not None
            try:
                os.killpg(self.proc.pid, signal.SIGINT)
            except ProcessLookupError:
                pass

    def stop(self, timeout: float = 5.0) -> None:
        """Stop PX4: SIGINT, then SIGKILL after ``timeout`` s (a PX4 still waiting for its
        physics ignores SIGINT)."""
        if self.proc is None:
            return
        self.request_stop()
        try:
            self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait(timeout=5.0)

    def ulogs(self) -> list[Path]:
        """PX4's ULog files of this run, oldest first."""
        return sorted((self.workdir / "rootfs" / "log").glob("*/*.ulg"), key=os.path.getmtime)

    def __enter__(self) -> Px4Sitl:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
