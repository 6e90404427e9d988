"""The PX4 parameters that make a PX4 flight controller fly swingrt's simulated vehicle.

PX4's control allocation must know the simulated geometry (rotor positions and yaw moment
ratios), its hover thrust must match the simulated motors, and its gains should be those of
the scenario's cascade, so that PX4 in the loop and the built-in look-alike fly the same
vehicle alike (the roll/pitch rate gains are scaled for PX4's 250 Hz lockstep rate
loop). Logging and failsafe parameters make the flight usable as training
data: the swing sensor's DEBUG_VECT is logged, and the loss of a ground station or of RC
(there is none in the loop) is not a failsafe.
"""

from __future__ import annotations

import math

from swingrt._core import Scenario

__all__ = ["px4_parameters", "SDLOG_PROFILE_WITH_DEBUG", "HIL_RATE_GAIN_SCALE"]

#: Scale of the roll and pitch rate gains on PX4 in the loop. In lockstep PX4's rate loop runs
#: at the 250 Hz sensor rate behind its gyro filter; with the Honeybee's small inertia the
#: cascade's gains then limit-cycle at ~20 Hz on PX4 (pitch ±2.8 rad/s, torque saturated,
#: measured), while half of them hold attitude to 0.03° (the built-in cascade runs at 500 Hz
#: unfiltered and needs no scaling).
HIL_RATE_GAIN_SCALE = 0.5

#: PX4's default log profile (131) plus the debug-topics bit (32): logs ``debug_vect``.
SDLOG_PROFILE_WITH_DEBUG = 163

# Rotor order of PX4's quad X (front-right, rear-left, front-left, rear-right) and the sign
# of each rotor's position (x forward, y right) and of its yaw moment (CCW rotors positive).
_ROTORS = ((1, 1, 1), (-1, -1, 1), (1, -1, -1), (-1, 1, -1))


def px4_parameters(scenario: Scenario, *, takeoff_altitude: float | None = None) -> dict:
    """``{PX4 parameter name: value}`` for flying ``scenario``'s vehicle on PX4.

    The allocation places motor i at (±d/√2, ±d/√2) with yaw moment ratio ±R_N (table 6.1);
    PX4's linear thrust model (``THR_MDL_FAC`` 0) and ``MPC_THR_HOVER`` = the command of
    eq. 6.1 that carries vehicle + payload, as in the built-in cascade; the cascade's gains.
    """
    d = scenario.to_dict()
    v, c = d["vehicle"], d["controller"]
    arm = v["arm"] / math.sqrt(2.0)
    params: dict[str, float | int] = {"CA_AIRFRAME": 0, "CA_ROTOR_COUNT": 4}
    for i, (sx, sy, sk) in enumerate(_ROTORS):
        params[f"CA_ROTOR{i}_PX"] = round(sx * arm, 6)
        params[f"CA_ROTOR{i}_PY"] = round(sy * arm, 6)
        params[f"CA_ROTOR{i}_PZ"] = 0.0
        params[f"CA_ROTOR{i}_KM"] = round(sk * v["yaw_arm"], 6)
    params["THR_MDL_FAC"] = 0.0
    params["MPC_THR_HOVER"] = round(scenario.hover_thrust(), 4)
    params["MPC_THR_MIN"] = c["thrust_min"]
    params["MPC_THR_MAX"] = c["thrust_max"]
    params["MPC_TILTMAX_AIR"] = round(math.degrees(c["tilt_max"]), 3)
    for i, axis in enumerate(("ROLL", "PITCH", "YAW")):
        scale = HIL_RATE_GAIN_SCALE if axis != "YAW" else 1.0
        params[f"MC_{axis}RATE_P"] = round(c["rate_p"][i] * scale, 6)
        params[f"MC_{axis}RATE_I"] = round(c["rate_i"][i] * scale, 6)
        params[f"MC_{axis}RATE_D"] = round(c["rate_d"][i] * scale, 6)
        params[f"MC_{axis[0]}R_INT_LIM"] = c["rate_int_limit"][i]
        params[f"MC_{axis}_P"] = c["att_p"][i]
    params["MPC_XY_VEL_P_ACC"] = c["vel_p"][0]
    params["MPC_XY_VEL_I_ACC"] = c["vel_i"][0]
    params["MPC_XY_VEL_D_ACC"] = c["vel_d"][0]
    params["MPC_Z_VEL_P_ACC"] = c["vel_p"][2]
    params["MPC_Z_VEL_I_ACC"] = c["vel_i"][2]
    params["MPC_XY_P"] = c["pos_p"][0]
    params["MPC_Z_P"] = c["pos_p"][2]
    # Flight data: log the swing sensor (debug topics) from arming on.
    params["SDLOG_PROFILE"] = SDLOG_PROFILE_WITH_DEBUG
    # No RC and no ground station in the loop: neither loss is a failsafe; the offboard
    # node's loss is (COM_OBL_RC_ACT 5 = Hold: a swinging payload is safest held in place).
    params["COM_RC_IN_MODE"] = 4
    params["NAV_RCL_ACT"] = 0
    params["NAV_DLL_ACT"] = 0
    params["COM_OBL_RC_ACT"] = 5
    params["COM_ARM_WO_GPS"] = 0
    if takeoff_altitude is not None:
        params["MIS_TAKEOFF_ALT"] = round(float(takeoff_altitude), 2)
    return params
