//! One MPC tick (Kalman update included) at q = 50, Np = 120, Nc = 20, one and two axes,
//! unconstrained (the precomputed law) and constrained (a 1 m/s² acceleration bound made
//! active by ±4 m/s velocity steps; only ticks that solved the QP are timed) with Clarabel
//! and the dense active set. Model: the white-box pendulum (m_p 0.2 kg, l 1 m) discretised
//! at 0.03 s and fitted in 50 delay coordinates (dense top rows, exact shifts below),
//! seed 7. After criterion's runs the median / p99 per tick are printed from
//! `swing_bench::tick_timing` (the budgets of docs/architecture.md, "Budgets").

#![allow(clippy::needless_range_loop)]

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use swing_bench::tick_timing;
use swing_core::control::mpc::{MpcController, MpcSettings, QpSolverKind};
use swing_core::control::{AxisState, LinearPlant, SwingController, TickKind};
use swing_core::plant::PendulumModel;
use swing_core::sysid::LinearModel;
use swing_core::testing::pendulum_delay_model;

fn model(axes: usize) -> LinearModel {
    let p = PendulumModel {
        m_q: 0.952,
        m_p: 0.2,
        l: 1.0,
        c: 0.002,
    };
    pendulum_delay_model(&p, 0.03, 50, axes, 7).expect("bench model")
}

fn settings(solver: QpSolverKind, constrained: bool) -> MpcSettings {
    MpcSettings {
        horizon: 120,
        control_horizon: 20,
        acc_max: constrained.then_some(1.0),
        jerk_max: None,
        solver,
        ..Default::default()
    }
}

/// Total time of `iters` timed ticks in closed loop with the model as plant.
fn timed_ticks(m: &LinearModel, s: &MpcSettings, constrained: bool, iters: u64) -> Duration {
    let mut ctrl = MpcController::new(m, s.clone()).expect("controller");
    let mut plant = LinearPlant::new(m).expect("plant");
    let axes = ctrl.axes();
    let mut st = vec![AxisState::default(); axes];
    let mut u = vec![0.0; axes];
    let mut r = vec![0.0; axes];
    ctrl.reset(&st, &u);
    let amp = if constrained { 4.0 } else { 2.0 };
    let mut total = Duration::ZERO;
    let mut done = 0;
    let mut k = 0usize;
    while done < iters {
        let sign = if (k / 133) % 2 == 0 { 1.0 } else { -1.0 };
        for (a, x) in r.iter_mut().enumerate() {
            *x = sign * amp * if a == 0 { 1.0 } else { -0.7 };
        }
        plant.measure(&mut st);
        let t0 = Instant::now();
        let info = ctrl
            .step(black_box(&st), black_box(&r), &mut u)
            .expect("tick");
        let el = t0.elapsed();
        if !constrained || info.kind == TickKind::Constrained {
            total += el;
            done += 1;
        }
        plant.step(&u);
        k += 1;
    }
    total
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("mpc_step");
    g.measurement_time(Duration::from_secs(3)).sample_size(30);
    let cases = [
        ("unconstrained", QpSolverKind::ActiveSet, false),
        ("constrained_active_set", QpSolverKind::ActiveSet, true),
        ("constrained_clarabel", QpSolverKind::Clarabel, true),
    ];
    let mut report = vec![];
    for axes in [1usize, 2] {
        let m = model(axes);
        for (name, solver, constrained) in cases {
            let s = settings(solver, constrained);
            g.bench_function(format!("{axes}axis/{name}"), |b| {
                b.iter_custom(|iters| timed_ticks(&m, &s, constrained, iters))
            });
            let t = tick_timing(&m, &s, 3000, constrained).expect("timing");
            report.push(format!(
                "{axes} axis {name:<24} median {:8.2} µs  p99 {:8.2} µs  max {:8.2} µs ({} ticks)",
                t.median_us, t.p99_us, t.max_us, t.ticks
            ));
        }
    }
    g.finish();
    println!("\nper-tick timing (q = 50, Np = 120, Nc = 20, Kalman update included):");
    for line in report {
        println!("  {line}");
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
