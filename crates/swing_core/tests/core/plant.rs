//! Physics checks of the plant and the closed loop against closed forms and invariants.

#![allow(clippy::needless_range_loop)]

use std::sync::{Arc, Mutex};

use nalgebra::{Quaternion, Vector3};
use swing_core::control::px4::AxisSetpoint;
use swing_core::control::{AxisState, ControlError, ControlOutput, SwingController, TickInfo};
use swing_core::plant::dynamics::swing_angles;
use swing_core::plant::{
    Effects, Model, PayloadKind, PayloadParams, PlantState, StepInput, VehicleParams, GRAVITY,
};
use swing_core::sensors::{ImuParams, SwingSource};
use swing_core::sim::{Scenario, SetpointEntry, Simulator};

const IDEAL: Effects = Effects {
    drag: false,
    friction: false,
    rotors: false,
};

fn payload(m: f64, l: f64) -> PayloadParams {
    PayloadParams {
        kind: PayloadKind::Single,
        mass: m,
        length: l,
        drag: 0.0,
        friction: 0.0,
        ..Default::default()
    }
}

/// Constant thrust equal to the total weight, straight up, no rotation.
fn weight_compensation(model: &Model) -> StepInput {
    StepInput {
        external_force: Vector3::new(0.0, 0.0, -model.total_mass() * GRAVITY),
        ..Default::default()
    }
}

/// Times of upward zero crossings of `x` sampled every `h` (linear interpolation).
fn up_crossings(x: &[f64], h: f64) -> Vec<f64> {
    let mut out = Vec::new();
    for k in 1..x.len() {
        if x[k - 1] < 0.0 && x[k] >= 0.0 {
            let frac = -x[k - 1] / (x[k] - x[k - 1]);
            out.push((k as f64 - 1.0 + frac) * h);
        }
    }
    out
}

fn mean_period(crossings: &[f64]) -> f64 {
    (crossings[crossings.len() - 1] - crossings[0]) / (crossings.len() - 1) as f64
}

#[test]
fn free_swing_frequency_matches_the_free_floating_pendulum() {
    let mq = VehicleParams::default().mass;
    for (mp, l) in [(0.1, 0.5), (0.2, 1.0), (0.3, 2.0)] {
        let model = Model::new(VehicleParams::default(), payload(mp, l));
        let u = weight_compensation(&model);
        let mut s = PlantState::at_rest(Vector3::zeros(), 0.0, 0.01, 0.0);
        let h = 1e-3;
        let mut swing = Vec::new();
        for _ in 0..30_000 {
            swing.push(swing_angles(&s.n[0], &s.ndot[0])[0]);
            s = model.rk4(&s, &u, h, IDEAL);
        }
        let period = mean_period(&up_crossings(&swing, h));
        let omega = 2.0 * std::f64::consts::PI / period;
        let expected = (GRAVITY / l * (mq + mp) / mq).sqrt();
        let rel = (omega - expected).abs() / expected;
        assert!(
            rel < 0.01,
            "m_p {mp} l {l}: ω {omega} vs {expected} ({rel:e})"
        );
        // The pinned pendulum is clearly different, so the test discriminates.
        let pinned = (GRAVITY / l).sqrt();
        assert!((omega - pinned).abs() / pinned > 0.04);
    }
}

#[test]
fn energy_is_conserved_and_the_cable_keeps_its_length() {
    for kind in [PayloadKind::Single, PayloadKind::Double] {
        let mut p = payload(0.2, 1.0);
        p.kind = kind;
        p.mass2 = 0.15;
        p.length2 = 0.4;
        let model = Model::new(VehicleParams::default(), p.clone());
        let u = weight_compensation(&model);
        let mut s = PlantState::at_rest(Vector3::new(0.0, 0.0, -10.0), 0.0, 0.5, -0.3);
        s.vel = Vector3::new(0.3, -0.2, 0.1);
        s.n[1] = Vector3::new(0.4, 0.1, 1.0).normalize();
        let e0 = model.energy(&s, &u.external_force);
        let h = 1e-3;
        let mut worst_len: f64 = 0.0;
        let mut worst_e: f64 = 0.0;
        for _ in 0..60_000 {
            s = model.rk4(&s, &u, h, IDEAL);
            let r = s.payload_position(&p, 0) - s.pos;
            worst_len = worst_len.max((r.norm() - p.length).abs());
            let e = model.energy(&s, &u.external_force);
            worst_e = worst_e.max(((e - e0) / e0).abs());
        }
        assert!(
            worst_e <= 1e-6,
            "{kind:?}: relative energy drift {worst_e:e}"
        );
        assert!(
            worst_len <= 1e-12,
            "{kind:?}: cable length error {worst_len:e}"
        );
    }
}

#[test]
fn energy_falls_when_friction_and_drag_are_on() {
    let mut p = payload(0.2, 1.0);
    p.friction = 0.01;
    p.drag = 0.01;
    let model = Model::new(VehicleParams::default(), p);
    let u = weight_compensation(&model);
    let mut s = PlantState::at_rest(Vector3::zeros(), 0.0, 0.5, 0.0);
    let e0 = model.energy(&s, &u.external_force);
    let fx = Effects {
        rotors: false,
        ..Effects::default()
    };
    let mut prev = e0;
    for _ in 0..5_000 {
        s = model.rk4(&s, &u, 1e-3, fx);
        let e = model.energy(&s, &u.external_force);
        assert!(e <= prev + 1e-9, "energy rose with dissipation on");
        prev = e;
    }
    assert!(prev < e0 - 1e-3);
}

fn run_double(h: f64, t_end: f64) -> PlantState {
    let mut p = payload(0.2, 1.0);
    p.kind = PayloadKind::Double;
    p.mass2 = 0.15;
    p.length2 = 0.4;
    let model = Model::new(VehicleParams::default(), p);
    let u = weight_compensation(&model);
    let mut s = PlantState::at_rest(Vector3::zeros(), 0.0, 0.6, 0.2);
    s.n[1] = Vector3::new(-0.5, 0.3, 1.0).normalize();
    let n = (t_end / h).round() as usize;
    for _ in 0..n {
        s = model.rk4(&s, &u, h, IDEAL);
    }
    s
}

fn state_error(a: &PlantState, b: &PlantState) -> f64 {
    (a.pos - b.pos).norm()
        + (a.vel - b.vel).norm()
        + (a.n[0] - b.n[0]).norm()
        + (a.n[1] - b.n[1]).norm()
        + (a.ndot[0] - b.ndot[0]).norm()
        + (a.ndot[1] - b.ndot[1]).norm()
}

#[test]
fn rk4_global_error_falls_sixteenfold_when_the_step_halves() {
    let t_end = 2.0;
    let reference = run_double(0.25e-3, t_end);
    let e1 = state_error(&run_double(8e-3, t_end), &reference);
    let e2 = state_error(&run_double(4e-3, t_end), &reference);
    let e3 = state_error(&run_double(2e-3, t_end), &reference);
    for (coarse, fine) in [(e1, e2), (e2, e3)] {
        let ratio = coarse / fine;
        assert!(
            (12.0..=20.0).contains(&ratio),
            "ratio {ratio} ({coarse:e} / {fine:e})"
        );
    }
}

#[test]
fn quaternion_stays_unit() {
    // The attitude derivative is tangent to the unit sphere for any body rate …
    let q = Quaternion::new(0.8, 0.1, -0.3, 0.5).normalize();
    let model = Model::new(VehicleParams::default(), payload(0.2, 1.0));
    let mut s = PlantState::at_rest(Vector3::zeros(), 2.5, 0.0, 0.0);
    s.att = q;
    s.rate = Vector3::new(3.0, -2.0, 5.0);
    let d = model.derivative(&s, &StepInput::default(), Effects::default());
    assert!(q.dot(&d.att).abs() < 1e-15);
    // … and the norm holds to round-off through an aggressive closed-loop flight.
    let mut sc = Scenario::default_step();
    sc.setpoints.push(SetpointEntry {
        t: 4.0,
        vn: Some(-3.0),
        ve: Some(3.0),
        yaw: Some(1.5),
        ..Default::default()
    });
    sc.duration = 10.0;
    let mut sim = Simulator::new(sc).unwrap();
    for _ in 0..1000 {
        sim.advance(0.01).unwrap();
        assert!((sim.state().att.norm() - 1.0).abs() < 1e-12);
    }
}

fn hold_error(kind: PayloadKind) -> (f64, f64) {
    let mut sc = Scenario {
        duration: 40.0,
        ..Default::default()
    };
    sc.payload.kind = kind;
    sc.payload.initial_swing_n = 0.1;
    sc.setpoints = vec![SetpointEntry {
        t: 0.0,
        pn: Some(1.0),
        pe: Some(-1.0),
        pd: Some(-11.0),
        ..Default::default()
    }];
    let mut sim = Simulator::new(sc).unwrap();
    sim.run_to_end().unwrap();
    let s = sim.state();
    let err = (s.pos - Vector3::new(1.0, -1.0, -11.0)).norm();
    (err, s.vel.norm())
}

#[test]
fn hover_holds_position_without_steady_state_error() {
    for kind in [PayloadKind::None, PayloadKind::Single] {
        let (err, speed) = hold_error(kind);
        assert!(err < 5e-3, "{kind:?}: position error {err}");
        assert!(speed < 5e-3, "{kind:?}: residual speed {speed}");
    }
}

#[test]
fn swing_period_under_px4_lies_between_free_and_pinned() {
    let sc = Scenario {
        duration: 40.0,
        ..Scenario::default_step()
    };
    let (mp, l, mq) = (sc.payload.mass, sc.payload.length, sc.vehicle.mass);
    let trace = Simulator::run(sc).unwrap();
    let t = trace.column("t").unwrap();
    let sw = trace.column("swing_n").unwrap();
    let dt = t[1] - t[0];
    // The swing after the step settles around a small drag angle; take the oscillation.
    let start = (12.0 / dt) as usize;
    let tail = &sw[start..];
    let mean = tail.iter().sum::<f64>() / tail.len() as f64;
    let centred: Vec<f64> = tail.iter().map(|x| x - mean).collect();
    let crossings = up_crossings(&centred, dt);
    assert!(crossings.len() >= 5, "swing did not oscillate");
    let period = mean_period(&crossings);
    let free = 2.0 * std::f64::consts::PI / (GRAVITY / l * (mq + mp) / mq).sqrt();
    let pinned = 2.0 * std::f64::consts::PI * (l / GRAVITY).sqrt();
    assert!(
        period > free && period < pinned,
        "period {period} outside ({free}, {pinned})"
    );
    // And the step did make it swing.
    let peak = sw.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(peak > 0.05, "peak swing {peak}");
}

#[test]
fn linearisation_around_hover_matches_the_white_box_model() {
    let (mp, l, c) = (0.25, 1.3, 0.004);
    let vehicle = VehicleParams::default();
    let mq = vehicle.mass;
    let mut p = payload(mp, l);
    p.friction = c;
    let model = Model::new(vehicle, p);
    let fx = Effects {
        drag: false,
        friction: true,
        rotors: false,
    };
    // f(θ, θ̇, a_N) → (v̇_N, θ̈) with the vehicle pushed by m_Q a_N North.
    let f = |theta: f64, theta_dot: f64, a_n: f64| -> [f64; 2] {
        let mut s = PlantState::at_rest(Vector3::zeros(), 0.0, theta, 0.0);
        s.ndot[0] = Vector3::new(theta.cos(), 0.0, -theta.sin()) * theta_dot;
        let u = StepInput {
            external_force: Vector3::new(mq * a_n, 0.0, -model.total_mass() * GRAVITY),
            ..Default::default()
        };
        let d = model.derivative(&s, &u, fx);
        let n = s.n[0];
        let nd = s.ndot[0];
        let ndd = d.ndot[0];
        // θ = atan2(n_x, n_z) ⇒ θ̈ from n, ṅ, n̈.
        let r = n.x * n.x + n.z * n.z;
        let num = nd.x * n.z - n.x * nd.z;
        let num_dot = ndd.x * n.z - n.x * ndd.z;
        let r_dot = 2.0 * (n.x * nd.x + n.z * nd.z);
        [d.vel.x, (num_dot * r - num * r_dot) / (r * r)]
    };
    let eps = 1e-6;
    let jac = |k: usize| -> [f64; 2] {
        let mut a = [0.0; 3];
        let mut b = [0.0; 3];
        a[k] = eps;
        b[k] = -eps;
        let fa = f(a[0], a[1], a[2]);
        let fb = f(b[0], b[1], b[2]);
        [(fa[0] - fb[0]) / (2.0 * eps), (fa[1] - fb[1]) / (2.0 * eps)]
    };
    let (d_theta, d_rate, d_acc) = (jac(0), jac(1), jac(2));
    // Eq. 5.7 with the stable sign (docs/architecture.md, "The reference"), 5.8.
    let expected = [
        (d_theta[0], GRAVITY * mp / mq),
        (d_theta[1], -GRAVITY * (mq + mp) / (l * mq)),
        (d_rate[0], c / (l * mq)),
        (d_rate[1], -c * (mq + mp) / (l * l * mq * mp)),
        (d_acc[0], 1.0),
        (d_acc[1], -1.0 / l),
    ];
    for (i, (got, want)) in expected.iter().enumerate() {
        assert!(
            (got - want).abs() <= 1e-6 * want.abs().max(1.0),
            "entry {i}: {got} vs {want}"
        );
    }
}

#[test]
fn acceleration_setpoint_axis_bypasses_the_velocity_pid() {
    let sc = Scenario {
        duration: 6.0,
        ..Default::default()
    };
    let mut sim = Simulator::new(sc).unwrap();
    sim.set_setpoint(0, AxisSetpoint::Acceleration(0.5));
    sim.advance(4.0).unwrap();
    assert!((sim.cascade().acc_sp.x - 0.5).abs() < 1e-12);
    // Total system accelerates at about 0.5·(m_Q+m_p)/(m_Q+m_p) m/s² North.
    let v = sim.state().vel.x;
    assert!(v > 1.2 && v < 2.4, "v_N after 4 s: {v}");
}

/// A controller that flies PX4's own velocity reference (so the flight is PX4's) and
/// records what it is told at every tick: (swing N, swing rate N).
struct Recorder(Arc<Mutex<Vec<[f64; 2]>>>);

impl SwingController for Recorder {
    fn axes(&self) -> usize {
        1
    }
    fn period(&self) -> f64 {
        0.01
    }
    fn output(&self) -> ControlOutput {
        ControlOutput::Velocity
    }
    fn reset(&mut self, _state: &[AxisState], _acc: &[f64]) {}
    fn step(
        &mut self,
        state: &[AxisState],
        vel_ref: &[f64],
        out: &mut [f64],
    ) -> Result<TickInfo, ControlError> {
        self.0
            .lock()
            .unwrap()
            .push([state[0].swing, state[0].swing_rate]);
        out[0] = vel_ref[0];
        Ok(TickInfo::default())
    }
}

/// The default step (2 m/s North at 2 s) flown with the swing source `source`, an ideal IMU,
/// no airframe drag and the estimator's exact pull scale, so that what separates the rate a
/// controller is told from the true one is the measurement chain's lag. Returns per
/// controller tick (every 10 ms, the trace's rows, from the tick it engages on to the end):
/// (told swing, told rate, true rate).
fn told_swing(source: SwingSource, cutoff: f64) -> Vec<[f64; 3]> {
    let mut sc = Scenario::builtin("step").unwrap();
    sc.duration = 8.0;
    sc.sensors.swing = source;
    sc.sensors.imu = ImuParams::ideal();
    sc.sensors.estimator.cutoff = cutoff;
    sc.sensors.estimator.scale = GRAVITY * sc.payload.mass / sc.vehicle.mass;
    let mut sim = Simulator::new(sc).unwrap();
    sim.set_effects(Effects {
        drag: false,
        ..Effects::default()
    });
    let seen = Arc::new(Mutex::new(Vec::new()));
    sim.attach_controller(Box::new(Recorder(seen.clone())), 0.0, 1.0)
        .unwrap();
    sim.run_to_end().unwrap();
    let tr = sim.take_trace();
    let truth = tr.column("swing_rate_n").unwrap();
    let seen = seen.lock().unwrap();
    // The last tick is the last row but one (the final row is logged after the run); a
    // controller on the IMU engages only after the estimator's tare.
    let first = truth.len() - 1 - seen.len();
    seen.iter()
        .zip(&truth[first..])
        .map(|(s, r)| [s[0], s[1], *r])
        .collect()
}

/// The delay [s] (1 ms grid, 0–150 ms) that best aligns `told` rates with the `truth`
/// (10 ms samples, interpolated) over the last 4.5 s (after the step), and the RMS errors at
/// it and at 0 [rad/s].
fn best_lag(rows: &[[f64; 3]]) -> (f64, f64, f64) {
    let rms = |lag: f64| {
        let (mut s, mut n) = (0.0, 0.0);
        for k in rows.len() - 450..rows.len() {
            let x = k as f64 - lag / 0.01;
            let (i, f) = (x.floor() as usize, x - x.floor());
            let r = rows[i][2] * (1.0 - f) + rows[(i + 1).min(k)][2] * f;
            s += (rows[k][1] - r).powi(2);
            n += 1.0;
        }
        (s / n).sqrt()
    };
    let lag = (0..=150)
        .map(|ms| ms as f64 * 1e-3)
        .min_by(|a, b| rms(*a).total_cmp(&rms(*b)))
        .unwrap();
    (lag, rms(lag), rms(0.0))
}

#[test]
fn controllers_are_told_the_swing_rate_of_their_own_swing_source_not_the_truth() {
    // A swing sensor's rate is the true one, from the first tick on.
    let rows = told_swing(SwingSource::Sensor, 5.0);
    assert_eq!(rows.len(), 800);
    for r in rows {
        assert_eq!(r[1], r[2]);
    }
    // Without a sensor on the cable, the rate is the estimate's own filtered derivative: the
    // backward difference of the swing the controller is told (tick = estimator sample) ...
    let fs = 100.0;
    let cutoff = 5.0;
    let rows = told_swing(SwingSource::Imu, cutoff);
    // (the controller engages at 1 s, once the estimator's 1 s tare is over)
    assert_eq!(rows.len(), 700);
    for k in 201..rows.len() {
        let d = (rows[k][0] - rows[k - 1][0]) * fs;
        assert!((rows[k][1] - d).abs() < 1e-9, "{k}: {} vs {d}", rows[k][1]);
    }
    // ... so it lags the true rate by the estimator's low-pass (its group delay at DC plus
    // half a sample, τ = 49.6 ms), one sample of staleness (the controller runs before the
    // IMU sample of its step, 10 ms) and PX4's 30 Hz accelerometer filter (7.5 ms at 1 kHz):
    // 67 ms here.
    let pi = std::f64::consts::PI;
    let tau = std::f64::consts::SQRT_2 / (2.0 * fs * (pi * cutoff / fs).tan()) + 0.5 / fs;
    let (lag, at_lag, at_zero) = best_lag(&rows);
    assert!(
        lag > tau + 0.01 && lag < tau + 0.03,
        "imu lag {lag} s, filter {tau} s"
    );
    assert!(at_lag < 0.5 * at_zero, "{at_lag} vs {at_zero}");
    // The body sensor's reading is differentiated through the same low-pass: τ plus the stale
    // sample, 59.6 ms.
    let rows = told_swing(SwingSource::Body, cutoff);
    let (lag, at_lag, at_zero) = best_lag(&rows);
    assert!(
        lag > tau + 0.005 && lag < tau + 0.015,
        "body lag {lag} s, filter {tau} s"
    );
    assert!(at_lag < 0.5 * at_zero, "{at_lag} vs {at_zero}");
}

#[test]
fn a_rectangular_x_turns_with_each_rotors_position_cross_its_thrust() {
    // The x500's rotors, in PX4's order (front-right, rear-left, front-left, rear-right):
    // the body moment is Σ r_i × (0, 0, −T_i) = (−Σ y_i T_i, Σ x_i T_i, ·).
    let vehicle = VehicleParams::x500();
    let [x, y] = vehicle.rotor_xy.unwrap();
    let rotors = [(x, y), (-x, -y), (x, -y), (-x, y)];
    let inertia = Vector3::from(vehicle.inertia);
    let model = Model::new(vehicle, payload(0.2, 1.0));
    let fx = Effects {
        drag: false,
        ..Effects::default()
    };
    let thrust = nalgebra::Vector4::new(5.3, 4.1, 4.6, 5.0);
    let mut s = PlantState::at_rest(Vector3::zeros(), 0.0, 0.0, 0.0);
    s.thrust = thrust;
    let u = StepInput {
        thrust_sp: thrust,
        ..Default::default()
    };
    let d = model.derivative(&s, &u, fx);
    let roll: f64 = (0..4).map(|i| -rotors[i].1 * thrust[i]).sum();
    let pitch: f64 = (0..4).map(|i| rotors[i].0 * thrust[i]).sum();
    assert!((d.rate.x * inertia.x - roll).abs() < 1e-12, "roll");
    assert!((d.rate.y * inertia.y - pitch).abs() < 1e-12, "pitch");
    // A square X is the same rule with both arms d/√2.
    let square = VehicleParams::default();
    assert_eq!(square.moment_arms(), [square.arm / 2f64.sqrt(); 2]);
}

#[test]
fn the_x500_hovers_and_steps_under_the_cascade() {
    // Built from its own airframe name over the default step, as a scenario file does.
    let sc = Scenario::from_toml_over("[vehicle]\nairframe = \"x500\"\n", "step").unwrap();
    assert_eq!(sc.vehicle, VehicleParams::x500());
    let hover = sc.hover_thrust();
    assert!((0.3..0.8).contains(&hover), "hover thrust {hover}");
    let mut sim = Simulator::new(Scenario {
        duration: 20.0,
        ..sc
    })
    .unwrap();
    sim.run_to_end().unwrap();
    let s = sim.state();
    // The payload still swings the vehicle's speed a little after 18 s (PX4 PID).
    assert!((s.vel.x - 2.0).abs() < 0.1, "north speed {}", s.vel.x);
    assert!(
        (s.pos.z + 10.0).abs() < 0.1,
        "altitude error {}",
        s.pos.z + 10.0
    );
    assert!(s.vel.y.abs() < 0.02 && s.rate.norm() < 0.05);
}

/// The default step into a 2 m/s headwind, flown to a steady state under PX4's cascade that
/// believes the hover thrust is `believed` times the true one: the North speed error, the
/// cascade's North and Down acceleration setpoints, and the relative error of the hover
/// thrust it ends with.
fn headwind_cruise(believed: f64, estimator: bool) -> (f64, f64, f64, f64) {
    let mut sc = Scenario::default_step();
    sc.duration = 60.0;
    sc.wind.velocity = [-2.0, 0.0, 0.0];
    let truth = sc.hover_thrust();
    sc.controller.hover_thrust = Some(truth * believed);
    sc.controller.hover_thrust_estimator = estimator;
    let mut sim = Simulator::new(sc).unwrap();
    sim.run_to_end().unwrap();
    let fc = sim.cascade();
    (
        2.0 - sim.state().vel.x,
        fc.acc_sp.x,
        fc.acc_sp.z,
        fc.hover_thrust() / truth - 1.0,
    )
}

#[test]
fn a_wrong_hover_thrust_costs_the_closed_form_speed_error_without_px4_s_estimator_and_none_with_it()
{
    let vel_p = Scenario::default_step().controller.vel_p[0];
    // Believed too high: the loop holds a downward a_z, the thrust vector then makes only
    // (1 − a_z/g) of the horizontal acceleration asked, and the tracking anti-windup holds
    // the integrator where that shortfall balances the error: e = (2/K_p)·a·a_z/g.
    let (err, acc, acc_z, _) = headwind_cruise(1.05, false);
    assert!(
        acc > 0.5,
        "the headwind's drag needs a forward acceleration setpoint: {acc}"
    );
    assert!(
        acc_z > 0.3,
        "a believed-high hover thrust is held by a downward a_z: {acc_z}"
    );
    let closed = 2.0 / vel_p * acc * acc_z / GRAVITY;
    assert!(
        (err - closed).abs() < 0.02 * closed,
        "error {err}, closed form {closed}"
    );
    // Believed too low: the thrust vector makes more than was asked, nothing saturates and
    // PX4 leaves the integrator alone.
    let (err, _, acc_z, _) = headwind_cruise(0.95, false);
    assert!(acc_z < -0.3, "{acc_z}");
    assert!(err.abs() < 1e-3, "error {err}");
    // With PX4's estimator the hover thrust is learnt in flight and both errors go.
    for believed in [1.05, 0.95] {
        let (err, _, acc_z, ht) = headwind_cruise(believed, true);
        println!("believed x{believed}: error {err}, a_z {acc_z}, hover thrust off by {ht}");
        assert!(err.abs() < 2e-3, "believed ×{believed}: error {err}");
        assert!(acc_z.abs() < 0.05, "believed ×{believed}: a_z {acc_z}");
        assert!(
            ht.abs() < 0.03,
            "believed ×{believed}: hover thrust off by {ht}"
        );
    }
}
