"""swingrt: data-driven identification and swing-damping MPC for a multirotor with an
unknown suspended payload.

The numerical core is Rust (``swingrt._core``); this package adds configuration, data
loading, the command line, experiments and the MAVLink link.
"""

from __future__ import annotations

from swingrt import errors
from swingrt._core import __version__

__all__ = ["__version__", "errors"]
