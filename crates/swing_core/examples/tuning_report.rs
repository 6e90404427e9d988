//! Tuning table: a 2 m/s velocity step on the exact (ZOH-discretised) pendulum for the
//! thesis's payload range, the MPC with its default settings and with one setting changed
//! at a time, and the baseline LQR for reference.
//!
//! Run with `cargo run --release -p swing_core --example tuning_report`.

use nalgebra::DVector;
use swing_core::control::lqr::{LqrController, LqrSettings};
use swing_core::control::mpc::{MpcController, MpcSettings};
use swing_core::control::{AxisState, SwingController};
use swing_core::plant::PendulumModel;
use swing_core::testing::delay_model;

/// Sample time of the MPC's model [s].
const TS: f64 = 0.03;

/// Fly `ctrl` on the continuous 3-state pendulum (ZOH at the controller's period) towards
/// `v_ref` for `seconds`; returns the velocity and swing after each tick.
fn simulate(
    p: PendulumModel,
    ctrl: &mut dyn SwingController,
    v_ref: f64,
    seconds: f64,
) -> (Vec<f64>, Vec<f64>) {
    let dt = ctrl.period();
    let (ad, bd) = p.discrete(dt);
    let mut x = DVector::<f64>::zeros(3);
    ctrl.reset(&[AxisState::default()], &[0.0]);
    let (mut vs, mut ss) = (vec![], vec![]);
    let mut u = [0.0];
    for _ in 0..(seconds / dt) as usize {
        let st = AxisState {
            v: x[0],
            swing: x[1],
            swing_rate: x[2],
        };
        ctrl.step(&[st], &[v_ref], &mut u).expect("controller tick");
        x = &ad * &x + &bd * u[0];
        vs.push(x[0]);
        ss.push(x[1]);
    }
    (vs, ss)
}

/// Peak swing, swing IAE, 90 % rise time, overshoot and swing settling time of a 2 m/s step.
fn metrics(vs: &[f64], ss: &[f64], dt: f64) -> String {
    let peak = ss.iter().map(|x| x.abs()).fold(0.0, f64::max).to_degrees();
    let iae = ss.iter().map(|x| x.abs()).sum::<f64>() * dt * 57.2958;
    let rise = vs
        .iter()
        .position(|v| *v >= 1.8)
        .map(|k| k as f64 * dt)
        .unwrap_or(f64::NAN);
    let over = (vs.iter().cloned().fold(f64::MIN, f64::max) - 2.0) / 2.0 * 100.0;
    let settle = ss
        .iter()
        .rposition(|x| x.abs() > 1f64.to_radians())
        .map(|k| (k + 1) as f64 * dt)
        .unwrap_or(0.0);
    format!(
        "peak {peak:5.1}°  IAE {iae:6.2}°s  rise90 {rise:5.2}s  overshoot {over:5.1}%  \
         swing<1° after {settle:5.2}s"
    )
}

fn main() {
    let d = MpcSettings::default();
    let sets: Vec<(&str, MpcSettings)> = vec![
        ("default", d.clone()),
        (
            "w_swing_rate 1",
            MpcSettings {
                w_swing_rate: 1.0,
                ..d.clone()
            },
        ),
        (
            "w_swing_rate 3",
            MpcSettings {
                w_swing_rate: 3.0,
                ..d.clone()
            },
        ),
        (
            "w_acc_rate 0.7",
            MpcSettings {
                w_acc_rate: 0.7,
                ..d.clone()
            },
        ),
        (
            "w_acc_rate 1.5",
            MpcSettings {
                w_acc_rate: 1.5,
                ..d.clone()
            },
        ),
        (
            "horizon 70",
            MpcSettings {
                horizon: 70,
                ..d.clone()
            },
        ),
    ];
    for l in [0.5, 1.0, 2.0] {
        for m_p in [0.1, 0.3] {
            let p = PendulumModel {
                m_q: 0.952,
                m_p,
                l,
                c: 0.002,
            };
            let m = delay_model(&p, TS, 2, 7).expect("delay model");
            println!("l = {l} m, m_p = {m_p} kg");
            for (name, s) in &sets {
                let mut c = MpcController::new(&m, s.clone()).expect("MPC design");
                let (vs, ss) = simulate(p, &mut c, 2.0, 15.0);
                println!("  MPC {name:<18} {}", metrics(&vs, &ss, TS));
            }
            let mut lqr = LqrController::new(p, 1, LqrSettings::default()).expect("LQR design");
            let (vs, ss) = simulate(p, &mut lqr, 2.0, 15.0);
            println!("  LQR {:<18} {}", "default", metrics(&vs, &ss, 0.02));
        }
    }
}
