"""MAVLink flight integration: a simulated PX4 vehicle (:mod:`.vehicle`), connection helpers
(:mod:`.link`), the offboard node (:mod:`.offboard`) and training-data collection over
MAVLink (:mod:`.training`). pymavlink only, no ROS.
"""

from __future__ import annotations

from swingrt.errors import FlightAbort
from swingrt.mavlink.link import connect, wait_heartbeat
from swingrt.mavlink.offboard import FlightReport, Mission, fly
from swingrt.mavlink.training import collect_over_mavlink, random_step_mission
from swingrt.mavlink.vehicle import Vehicle, run_vehicle

__all__ = [
    "collect_over_mavlink",
    "random_step_mission",
    "connect",
    "wait_heartbeat",
    "FlightAbort",
    "FlightReport",
    "Mission",
    "fly",
    "Vehicle",
    "run_vehicle",
]
