"""The ``swingrt`` command line (the subcommands are listed in the README).

Each subcommand lives in ``swingrt.commands.<name>`` and exposes ``add_parser(subparsers)``
and ``run(args) -> int``. Every user mistake ends with one line on stderr and a non-zero
exit status, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import NoReturn

from swingrt.errors import SwingrtError

#: Subcommand modules, in the order ``swingrt --help`` lists them.
COMMANDS = (
    "run",
    "simulate",
    "collect",
    "identify",
    "evaluate",
    "experiment",
    "campaign",
    "sitl",
    "hil",
    "vehicle",
    "fly",
    "mission",
    "bench",
)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (and exit status 2), like every
    other user mistake; ``--help`` still shows the usage."""

    def error(self, message: str) -> NoReturn:
        message = " ".join(message.split())
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser with every subcommand."""
    from swingrt import __version__

    parser = _Parser(
        prog="swingrt",
        description="Identify and damp the swing of an unknown suspended payload.",
    )
    parser.add_argument("--version", action="version", version=f"swingrt {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        module = importlib.import_module(f"swingrt.commands.{name}")
        p = module.add_parser(sub)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except SwingrtError as exc:
        print(f"swingrt: error: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"swingrt: error: no such file: {exc.filename}", file=sys.stderr)
        return 2
    except OSError as exc:  # a directory for a file, no permission, a full disk, ...
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"swingrt: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("swingrt: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
