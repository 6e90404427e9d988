"""Hardware-in-the-loop: swingrt's plant under a real PX4 flight controller.

:mod:`.server` runs the lockstep loop of PX4's simulator interface around the core's
``HilPlant``; :mod:`.px4` starts and stops PX4 SITL; :mod:`.params` holds the PX4
parameters that match PX4 to the simulated vehicle.
"""

from __future__ import annotations

from swingrt.hil.params import px4_parameters
from swingrt.hil.px4 import Px4Sitl
from swingrt.hil.server import HilReport, HilServer

__all__ = ["HilServer", "HilReport", "Px4Sitl", "px4_parameters"]
