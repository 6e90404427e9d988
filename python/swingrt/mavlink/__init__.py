"""MAVLink flight integration (DESIGN section 6, issue 5): a simulated PX4 vehicle
(:mod:`.vehicle`), connection helpers (:mod:`.link`), the offboard node (:mod:`.offboard`) and
training-data collection (:mod:`.collect`). pymavlink only, no ROS.
"""

from __future__ import annotations

from swingrt.mavlink.collect import collect_over_mavlink, random_step_mission
from swingrt.mavlink.link import connect, wait_heartbeat
from swingrt.mavlink.offboard import FlightAbort, FlightReport, Mission, PDSwingDamper, fly
from swingrt.mavlink.vehicle import Vehicle, run_vehicle

__all__ = [
    "collect_over_mavlink",
    "random_step_mission",
    "connect",
    "wait_heartbeat",
    "FlightAbort",
    "FlightReport",
    "Mission",
    "PDSwingDamper",
    "fly",
    "Vehicle",
    "run_vehicle",
]
