"""Why ArduPilot's slung-payload feedback (``payload_p``) does not damp on PX4's velocity
loop: the swing mode's damping ratio with the feedback gain K_v = SLUP_VEL_P, three ways.

1. Ideal velocity tracking (the vehicle flies the commanded velocity exactly, as ArduPilot's
   position controller nearly does: it shapes the offset into a kinematic path and feeds its
   acceleration forward): θ̈ + (K_v g/l) θ̇ + (g/l) θ = 0, ζ = K_v √(g/l) / 2.
2. The linearised loop swingrt flies: the offset enters PX4's velocity setpoint, PX4's
   velocity PID (the scenario's gains, D on the measured acceleration) makes the
   acceleration setpoint, the attitude loop follows it with a first-order lag τ (estimated
   from a training flight, :func:`swingrt.methods.nmpc.estimate_lag`), and the vehicle +
   pendulum of thesis eq. 5.7 (PX4's hover thrust carries vehicle and payload). The
   eigenvalues of the closed loop give the swing mode's ζ and ω.
3. The simulator: the default 2 m/s step flown with the core ``payload_p`` at each K_v
   (residual swing, swing excess IAE, velocity settling time).

Then way 2 by cable length at ArduPilot's default K_v = 0.5 s.

Run:  python benches/payload_p_loop.py
"""

from __future__ import annotations

import math

import numpy as np

from swingrt import _core
from swingrt.io import Trace
from swingrt.metrics import step_metrics
from swingrt.scenario import Scenario, resolve

GAINS = (0.0, 0.05, 0.1, 0.25, 0.5)
CABLES = (0.3, 0.6, 1.0, 2.0, 3.0)


def _loop(k_v: float, m_q: float, m_p: float, l: float, px4: dict, tau: float) -> np.ndarray:
    """Closed-loop matrix of x = [v, θ, θ̇, a, ∫e] (module docs, way 2)."""
    g = _core.GRAVITY
    kp, ki, kd = px4["vel_p"][0], px4["vel_i"][0], px4["vel_d"][0]
    s = (m_q + m_p) / m_q  # PX4's hover thrust lifts both: force per unit setpoint
    vdot = np.array([0.0, g * m_p / m_q, 0.0, s, 0.0])  # v̇ = s a + (g m_p/m_q) θ
    e = np.array([-1.0, k_v * g, 0.0, 0.0, 0.0])  # e = v_ref + K_v g θ − v, v_ref = 0
    acc_sp = kp * e + ki * np.eye(5)[4] - kd * vdot
    a = np.zeros((5, 5))
    a[0] = vdot
    a[1, 2] = 1.0
    a[2] = -vdot / l
    a[2, 1] -= g / l  # θ̈ = −(g/l) θ − v̇ / l
    a[3] = (acc_sp - np.eye(5)[3]) / tau
    a[4] = e
    return a


def _swing_mode(a: np.ndarray, near: float) -> tuple[float, float]:
    """(ζ, ω) of the oscillatory eigenvalue nearest the free swing frequency."""
    ev = [e for e in np.linalg.eigvals(a) if e.imag > 0.1]
    e = min(ev, key=lambda z: abs(abs(z) - near))
    return -e.real / abs(e), abs(e)


def main() -> None:
    from swingrt.methods.nmpc import estimate_lag
    from swingrt.sysid import _columns, resample

    sc = resolve(None, duration=25.0)
    d = sc.to_dict()
    m_q, m_p, l = d["vehicle"]["mass"], d["payload"]["mass"], d["payload"]["length"]
    px4 = d["controller"]
    train = _core.Simulator(Scenario.builtin("training").with_overrides({"duration": 90.0}))
    train.run_to_end()
    c = resample(_columns(train.take_trace()), 0.03, ["vn", "swing_n", "acc_sp_n"])
    tau = estimate_lag(c["vn"], c["swing_n"], c["acc_sp_n"], 0.03)
    w_free = math.sqrt(_core.GRAVITY * (m_q + m_p) / (m_q * l))
    print(f"vehicle {m_q} kg, payload {m_p} kg on {l} m; PX4 velocity P/I/D "
          f"{px4['vel_p'][0]}/{px4['vel_i'][0]}/{px4['vel_d'][0]}; attitude lag τ = {tau:.2f} s "
          f"(from a 90 s training flight); free swing ω = {w_free:.2f} rad/s\n")  # fmt: skip
    print("| K_v [s] | ζ ideal tracking | ζ, ω on PX4's loop | residual swing [deg] "
          "| swing excess IAE [deg·s] | v settle [s] |")  # fmt: skip
    print("|---:|---:|---:|---:|---:|---:|")
    for k in GAINS:
        ideal = k * math.sqrt(_core.GRAVITY / l) / 2
        z, w = _swing_mode(_loop(k, m_q, m_p, l, px4, tau), w_free)
        sim = _core.Simulator(sc)
        if k > 0:
            sim.attach(_core.Controller.payload_p(l, 1, {"vel_p": k}), 1.0, 0.02)
        sim.run_to_end()
        m = step_metrics(Trace(sim.take_trace(), {}), t0=2.0)
        print(f"| {k:g} | {ideal:.3f} | {z:.3f}, {w:.2f} rad/s | {m['residual_swing_deg']:.2f} "
              f"| {m['swing_excess_iae_deg_s']:.1f} | {m['v_settle_s']:.2f} |")  # fmt: skip
    # The shorter the cable, the faster the swing and the more of PX4's lag it sees.
    k = 0.5
    print(f"\nOn PX4's loop by cable length, {m_p} kg payload (linearised):\n")
    print("| cable [m] | ζ without | ζ with K_v = 0.5 s | ζ ideal tracking (> 1: overdamped) |")
    print("|---:|---:|---:|---:|")
    for length in CABLES:
        w_l = math.sqrt(_core.GRAVITY * (m_q + m_p) / (m_q * length))
        z0, _ = _swing_mode(_loop(0.0, m_q, m_p, length, px4, tau), w_l)
        z1, _ = _swing_mode(_loop(k, m_q, m_p, length, px4, tau), w_l)
        ideal = k * math.sqrt(_core.GRAVITY / length) / 2
        print(f"| {length:g} | {z0:.3f} | {z1:.3f} | {ideal:.2f} |")


if __name__ == "__main__":
    main()
