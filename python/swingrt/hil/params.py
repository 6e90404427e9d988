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
from collections.abc import Mapping
from typing import Any

from swingrt._core import Scenario
from swingrt.errors import ConfigError
from swingrt.scenario import scaled_inertia

__all__ = [
    "HIL_RATE_GAIN_SCALE",
    "PX4_CONTROLLER",
    "SDLOG_PROFILE_WITH_DEBUG",
    "hil_rate_gain_scale",
    "px4_parameters",
    "vehicle_from_px4",
]

#: Scale of the roll and pitch rate gains on PX4 in the loop, for a vehicle with more rate
#: authority (:meth:`Scenario.rate_authority`) than PX4's reference x500, the airframe PX4's
#: default gains are tuned for. In lockstep PX4's rate loop runs at the 250 Hz sensor rate
#: behind its gyro filter; with the Honeybee's small inertia (2.7x the x500's authority in
#: roll, 6.6x in pitch) the cascade's gains then limit-cycle at ~20 Hz on PX4 (pitch
#: ±2.8 rad/s, torque saturated, measured), while half of them hold attitude to 0.03° (the
#: built-in cascade runs at 500 Hz unfiltered and needs no scaling). The x500 itself flies
#: PX4's gains unscaled, as PX4's own Gazebo SITL does.
HIL_RATE_GAIN_SCALE = 0.5

#: PX4's default log profile (131) plus the debug-topics bit (32): logs ``debug_vect``.
SDLOG_PROFILE_WITH_DEBUG = 163

# Rotor order of PX4's quad X (front-right, rear-left, front-left, rear-right) and the sign
# of each rotor's position (x forward, y right) and of its yaw moment (CCW rotors positive).
_ROTORS = ((1, 1, 1), (-1, -1, 1), (1, -1, -1), (-1, 1, -1))

_AXES = ("ROLL", "PITCH", "YAW")

#: The cascade's parameters written for PX4 in the loop, through :data:`PX4_CONTROLLER`'s
#: mapping; the rest of that table (rate limits, filter cut-offs, velocity limits, the xy
#: thrust margin) is left at PX4's defaults, which are the built-in cascade's but for two
#: that the horizontal step does not meet: IMU_DGYRO_CUTOFF (PX4 20 Hz, built-in 30) and
#: MPC_Z_VEL_MAX_DN (PX4 1.5 m/s, built-in 1.0).
_WRITTEN = (
    *(f"MC_{a}RATE_{g}" for a in _AXES for g in "PID"),
    *(f"MC_{a[0]}R_INT_LIM" for a in _AXES),
    *(f"MC_{a}_P" for a in _AXES),
    "MPC_XY_VEL_P_ACC",
    "MPC_XY_VEL_I_ACC",
    "MPC_XY_VEL_D_ACC",
    "MPC_Z_VEL_P_ACC",
    "MPC_Z_VEL_I_ACC",
    "MPC_XY_P",
    "MPC_Z_P",
    "MPC_THR_MIN",
    "MPC_THR_MAX",
    "MPC_TILTMAX_AIR",
)

#: The roll and pitch rate gains, scaled by :data:`HIL_RATE_GAIN_SCALE` on PX4.
_HIL_SCALED = frozenset(f"MC_{a}RATE_{g}" for a in _AXES[:2] for g in "PID")


def px4_parameters(scenario: Scenario, *, takeoff_altitude: float | None = None) -> dict:
    """``{PX4 parameter name: value}`` for flying ``scenario``'s vehicle on PX4.

    The allocation places motor i at (±x, ±y), the vehicle's ``rotor_xy`` (a square X:
    ±d/√2 both), with yaw moment ratio ±R_N (table 6.1);
    PX4's linear thrust model (``THR_MDL_FAC`` 0) and ``MPC_THR_HOVER`` = the command of
    eq. 6.1 that carries vehicle + payload, as in the built-in cascade; the cascade's gains.
    """
    d = scenario.to_dict()
    v, c = d["vehicle"], d["controller"]
    x, y = v.get("rotor_xy") or (v["arm"] / math.sqrt(2.0),) * 2
    params: dict[str, float | int] = {"CA_AIRFRAME": 0, "CA_ROTOR_COUNT": 4}
    for i, (sx, sy, sk) in enumerate(_ROTORS):
        params[f"CA_ROTOR{i}_PX"] = round(sx * x, 6)
        params[f"CA_ROTOR{i}_PY"] = round(sy * y, 6)
        params[f"CA_ROTOR{i}_PZ"] = 0.0
        params[f"CA_ROTOR{i}_KM"] = round(sk * v["yaw_arm"], 6)
    params["THR_MDL_FAC"] = 0.0
    params["MPC_THR_HOVER"] = round(scenario.hover_thrust(), 4)
    scale = hil_rate_gain_scale(scenario)
    for name in _WRITTEN:
        field, index, factor = PX4_CONTROLLER[name]
        value = c[field] if index is None else c[field][index]
        if name in _HIL_SCALED:
            value *= scale
        params[name] = round(value / factor, 6)
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


def hil_rate_gain_scale(scenario: Scenario) -> float:
    """The factor on ``scenario``'s roll and pitch rate gains on PX4 in the loop:
    :data:`HIL_RATE_GAIN_SCALE` when its vehicle has more rate authority on either axis than
    the x500 with the same payload, else 1."""
    payload = scenario.to_dict()["payload"]
    reference = Scenario.from_dict(
        {"vehicle": {"airframe": "x500"}, "payload": payload}, base="hover"
    )
    if max(scenario.rate_authority()) > max(reference.rate_authority()):
        return HIL_RATE_GAIN_SCALE
    return 1.0


# ---------------------------------------------------------------------- PX4 -> scenario

#: PX4 parameter → (controller field, index or None, factor to the field's unit): the one
#: mapping of the cascade both ways (:func:`px4_parameters` writes its ``_WRITTEN`` part
#: through it, :func:`vehicle_from_px4` reads all of it).
PX4_CONTROLLER: dict[str, tuple[str, int | None, float]] = {
    **{f"MC_{a}RATE_P": ("rate_p", i, 1.0) for i, a in enumerate(_AXES)},
    **{f"MC_{a}RATE_I": ("rate_i", i, 1.0) for i, a in enumerate(_AXES)},
    **{f"MC_{a}RATE_D": ("rate_d", i, 1.0) for i, a in enumerate(_AXES)},
    **{f"MC_{a[0]}R_INT_LIM": ("rate_int_limit", i, 1.0) for i, a in enumerate(_AXES)},
    **{f"MC_{a}RATE_MAX": ("rate_max", i, math.pi / 180.0) for i, a in enumerate(_AXES)},
    **{f"MC_{a}_P": ("att_p", i, 1.0) for i, a in enumerate(_AXES)},
    "IMU_DGYRO_CUTOFF": ("dgyro_cutoff", None, 1.0),
    "MPC_XY_VEL_P_ACC": ("vel_p", 0, 1.0),
    "MPC_Z_VEL_P_ACC": ("vel_p", 2, 1.0),
    "MPC_XY_VEL_I_ACC": ("vel_i", 0, 1.0),
    "MPC_Z_VEL_I_ACC": ("vel_i", 2, 1.0),
    "MPC_XY_VEL_D_ACC": ("vel_d", 0, 1.0),
    "MPC_Z_VEL_D_ACC": ("vel_d", 2, 1.0),
    "MPC_VELD_LP": ("veld_cutoff", None, 1.0),
    "MPC_XY_P": ("pos_p", 0, 1.0),
    "MPC_Z_P": ("pos_p", 2, 1.0),
    "MPC_XY_VEL_MAX": ("vel_max_xy", None, 1.0),
    "MPC_Z_VEL_MAX_UP": ("vel_max_up", None, 1.0),
    "MPC_Z_VEL_MAX_DN": ("vel_max_down", None, 1.0),
    "MPC_TILTMAX_AIR": ("tilt_max", None, math.pi / 180.0),
    "MPC_THR_MIN": ("thrust_min", None, 1.0),
    "MPC_THR_MAX": ("thrust_max", None, 1.0),
    "MPC_THR_XY_MARG": ("thrust_xy_margin", None, 1.0),
    # Read from an older PX4's log; current PX4 has no such parameter and always adopts its
    # hover-thrust estimate, so it is never written.
    "MPC_USE_HTE": ("hover_thrust_estimator", None, 1.0),
}

#: Controller fields PX4 holds as an integer switch (0 off, otherwise on).
_SWITCHES = frozenset({"hover_thrust_estimator"})

#: Spread of the rotors' |x| or |y|, as a fraction of the arm, beyond which the notes say
#: that the frame was flown as a rectangle at their mean.
_X_TOLERANCE = 0.05


def controller_from_px4(
    params: Mapping[str, float], controller: Mapping[str, Any]
) -> tuple[dict[str, Any], list[str]]:
    """``controller`` (a scenario's ``controller`` table) with what PX4's ``params`` set of
    it (:data:`PX4_CONTROLLER`; PX4's one horizontal velocity and position gain goes to North
    and East alike), and the names read."""
    controller = dict(controller)
    read = []
    for name, (field, index, factor) in PX4_CONTROLLER.items():
        if name not in params:
            continue
        value: float | bool = float(params[name]) * factor
        if field in _SWITCHES:
            value = value != 0.0
        if index is None:
            controller[field] = value
        else:
            controller[field] = list(controller[field])
            controller[field][index] = value
            if field.startswith("vel") or field == "pos_p":
                if index == 0:  # PX4 has one horizontal gain: North and East alike
                    controller[field][1] = value
        read.append(name)
    return controller, read


def vehicle_from_px4(
    params: dict[str, float],
    *,
    mass: float | None = None,
    payload: float | None = None,
    base: Scenario | None = None,
) -> tuple[Scenario, list[str]]:
    """The scenario of the vehicle PX4's ``params`` describe, and what it could not know.

    Read: the rotor geometry of the control allocation (a quad X in PX4's rotor order: the
    rotors' |x|, |y| and yaw moment ratio), the cascade's gains, rates and limits
    (:data:`PX4_CONTROLLER`; the North/East velocity gains are PX4's one horizontal gain),
    and the hover thrust ``MPC_THR_HOVER``: with the take-off ``mass`` [kg] given, the motors'
    thrust curve is the nominal one scaled so that this mass hovers there; without, the
    take-off mass is the one the nominal curve hovers there (stated). The hover thrust holds
    the vehicle and the ``payload`` [kg] it carried (PX4's hover-thrust estimate learns both;
    by default ``base``'s payload): the scenario carries that payload and its vehicle is the
    take-off mass less it, so a twin that swaps in another payload does not carry this one
    too. Not in PX4's parameters and left nominal
    (``base``'s, the built-in Honeybee by default), stated: the drag, the motor lag, the
    loop rates; the
    inertia is the nominal one scaled with the mass and the arm squared."""
    base = base or Scenario.builtin("step")
    b = base.to_dict()
    vehicle = dict(b["vehicle"])
    controller = dict(b["controller"])
    rotor_xy, yaw_arm, notes = _quad_x(params)
    arm = math.hypot(*rotor_xy)
    vehicle["arm"], vehicle["yaw_arm"] = arm, yaw_arm
    vehicle["rotor_xy"] = list(rotor_xy)
    controller, read = controller_from_px4(params, controller)
    missing = sorted(set(PX4_CONTROLLER) - set(read))
    if missing:
        notes.append(f"not in the parameters, nominal: {', '.join(missing)}")
    hover = params.get("MPC_THR_HOVER")
    if hover is None or not (0.0 < hover < 1.0):
        raise ConfigError(
            f"MPC_THR_HOVER must be in (0, 1), not {hover}: the hover thrust sets the motors",
            field="MPC_THR_HOVER",
        )
    nominal = _mass_hovering_at(base, float(hover))
    carried = _payload(base, payload)
    if mass is None:
        takeoff = nominal
        notes.append(
            f"take-off mass {nominal:.3f} kg estimated: what the nominal motors hover at "
            f"MPC_THR_HOVER {hover:g} (give --mass: the motors are then scaled to it)"
        )
    else:
        if not (math.isfinite(mass) and mass > 0.0):
            raise ConfigError(f"mass must be a positive number of kg, not {mass}", field="mass")
        takeoff = float(mass)
        vehicle["thrust_poly"] = [c * mass / nominal for c in vehicle["thrust_poly"]]
        notes.append(
            f"motors: the nominal thrust curve x {mass / nominal:.3f}, so that {mass:g} kg "
            f"hovers at MPC_THR_HOVER {hover:g}"
        )
    if not takeoff > sum(carried.values()):
        raise ConfigError(
            f"payload: {sum(carried.values()):g} kg leaves no vehicle of the take-off mass "
            f"{takeoff:.3f} kg",
            field="payload",
        )
    vehicle["mass"] = takeoff - sum(carried.values())
    notes.append(
        f"vehicle {vehicle['mass']:.3f} kg: the take-off mass less the "
        f"{sum(carried.values()):.3f} kg payload it hovered with"
    )
    vehicle["inertia"] = scaled_inertia(b["vehicle"], vehicle["mass"], arm)
    scale = vehicle["inertia"][0] / float(b["vehicle"]["inertia"][0])
    notes.append(
        f"inertia nominal x {scale:.3f} (mass x arm^2); drag, motor lag "
        f"{vehicle['motor_tau'] * 1e3:.0f} ms and loop rates nominal: not in PX4's parameters"
    )
    sc = base.with_overrides({"vehicle": vehicle, "controller": controller, "payload": carried})
    return sc, notes


def _payload(base: Scenario, payload: float | None) -> dict[str, float]:
    """The payload masses [kg] of ``base`` (``mass``, and ``mass2`` of a double pendulum),
    scaled to a total of ``payload`` when given."""
    d = base.to_dict()["payload"]
    masses = {"mass": float(d["mass"])}
    if d["kind"] == "double":
        masses["mass2"] = float(d["mass2"])
    if payload is None:
        return masses
    if not (math.isfinite(payload) and payload > 0.0):
        raise ConfigError(
            f"payload must be a positive number of kg, not {payload}", field="payload"
        )
    scale = payload / sum(masses.values())
    return {k: m * scale for k, m in masses.items()}


def _quad_x(params: dict[str, float]) -> tuple[tuple[float, float], float, list[str]]:
    """((|x|, |y|) of the rotors [m], yaw moment ratio [m], notes) of PX4's allocation,
    checked to be a quadrotor in PX4's X rotor order (:data:`_ROTORS`). swingrt flies a
    rectangular X: rotors at unequal |x| or |y| (the x500's |y| is 0.20 and 0.22) are flown
    at their mean, and the notes say so."""
    count = params.get("CA_ROTOR_COUNT")
    if count != 4:
        raise ConfigError(
            f"swingrt simulates a quadrotor X; CA_ROTOR_COUNT is {count}", field="CA_ROTOR_COUNT"
        )
    xs, ys, moments = [], [], []
    for i, (sx, sy, sk) in enumerate(_ROTORS):
        try:
            px, py, km = (float(params[f"CA_ROTOR{i}_{k}"]) for k in ("PX", "PY", "KM"))
        except KeyError as exc:
            raise ConfigError(f"rotor {i}: {exc.args[0]} missing", field=exc.args[0]) from None
        if not (px * sx > 0 and py * sy > 0 and km * sk > 0):
            raise ConfigError(
                f"rotor {i} at ({px:g}, {py:g}) with KM {km:g} is not PX4's quad X order "
                f"(expected signs {sx:+d}, {sy:+d}, {sk:+d})",
                field=f"CA_ROTOR{i}_PX",
            )
        xs.append(abs(px))
        ys.append(abs(py))
        moments.append(abs(km))
    x, y = sum(xs) / 4.0, sum(ys) / 4.0
    notes = []
    spread = max(max(xs) - min(xs), max(ys) - min(ys))
    if spread > _X_TOLERANCE * math.hypot(x, y):
        notes.append(
            f"rotors not a rectangle (|x| {min(xs):.3f}-{max(xs):.3f} m, |y| "
            f"{min(ys):.3f}-{max(ys):.3f} m): flown at their mean |x| {x:.3f} m, |y| {y:.3f} m"
        )
    return (x, y), sum(moments) / 4.0, notes


def _mass_hovering_at(base: Scenario, hover: float) -> float:
    """The total mass [kg] ``base``'s motors hold at the normalised ``hover`` thrust (the
    core's inverse of its hover thrust), refused when the vehicle left under the payload it
    carries would not be one the motors can fly."""
    payload = sum(_payload(base, None).values())
    total = base.mass_hovering_at(hover)
    try:
        if not total > payload:
            raise ConfigError("no vehicle left under the payload")
        base.with_overrides({"vehicle": {"mass": total - payload}})
    except ConfigError as e:
        raise ConfigError(
            f"MPC_THR_HOVER {hover:g} is outside what the motors can hover ({e})",
            field="MPC_THR_HOVER",
        ) from None
    return total
