//! One MPC tick (Kalman update included) at q = 50, Np = 120, Nc = 20, one and two axes,
//! unconstrained (the precomputed law) and constrained (a 1 m/s² acceleration bound made
//! active by ±4 m/s velocity steps; only ticks that solved the QP are timed) with Clarabel
//! and the dense active set. Model: the white-box pendulum (m_p 0.2 kg, l 1 m) discretised
//! at 0.03 s and fitted in 50 delay coordinates (dense top rows, exact shifts below),
//! seed 7. After criterion's runs the median / p99 per tick are printed from
//! `swing_bench::tick_timing` (the budgets of docs/architecture.md, "Budgets").
//!
//! `tracking_step`: one tick of the position-tracking MPC with preview (position states
//! added, the reference's future over the horizon, both axes, the 1.6 m/s² leg bound)
//! flying swingrt's legs of a two-leg plan with a 90° turn, guidance update and preview
//! fill included, on the same model with 0.3 kg on 1.5 m; the median and p99 per tick
//! are printed after criterion's runs.

#![allow(clippy::needless_range_loop)]

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use swing_bench::tick_timing;
use swing_core::control::mpc::{MpcController, MpcSettings, QpSolverKind};
use swing_core::control::{
    AxisState, LinearPlant, SwingController, TickKind, TrackingMpc, TrackingSettings,
};
use swing_core::mission::{GuidanceSettings, Mission, PreviewBuffer};
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

/// The plan the tracking bench flies: 30 m North, then 20 m East, 2 s holds.
const PLAN: &str = "acceptance_radius = 0.3\nhold = 2.0\nspeed = 5.0\n\
    [[waypoint]]\nn = 0\ne = 0\nd = -10\n[[waypoint]]\nn = 30\ne = 0\nd = -10\n\
    [[waypoint]]\nn = 30\ne = 20\nd = -10\n";

/// Per-tick durations of the tracking MPC over `ticks` ticks of the plan (restarted when it
/// ends), guidance update and preview fill included, with the model as plant.
fn tracking_ticks(m: &LinearModel, ticks: usize) -> Vec<Duration> {
    let mission = Mission::from_toml(PLAN).expect("plan");
    let settings = TrackingSettings {
        mpc: MpcSettings {
            acc_max: Some(1.6),
            ..swing_core::control::mpc::tracking::tracking_mpc_defaults()
        },
        ..TrackingSettings::default()
    };
    let mut ctrl = TrackingMpc::new(m, settings).expect("tracking controller");
    let mut buf = PreviewBuffer::new(ctrl.reference_steps(), 2);
    let ts = m.dt;
    let mut out = Vec::with_capacity(ticks);
    while out.len() < ticks {
        let mut g = GuidanceSettings::default()
            .build(&mission)
            .expect("guidance");
        let mut plant = LinearPlant::new(m).expect("plant");
        let mut pos = [0.0, 0.0];
        g.start(0.0, &[0.0, 0.0, -10.0], &[0.0; 3]);
        ctrl.reset(&plant.state(), &[0.0, 0.0]);
        let mut k = 0usize;
        while !g.done() && out.len() < ticks && k < 20_000 {
            let t = k as f64 * ts;
            let st = plant.state();
            let mut u = [0.0; 2];
            let t0 = Instant::now();
            g.update(t, ts, &[pos[0], pos[1], -10.0], &[st[0].v, st[1].v, 0.0]);
            let view = buf.fill(g.as_ref(), t, ts);
            ctrl.observe_reference(black_box(&pos), &view);
            ctrl.step(black_box(&st), &[0.0, 0.0], &mut u)
                .expect("tick");
            out.push(t0.elapsed());
            plant.step(&u);
            let after = plant.state();
            for a in 0..2 {
                pos[a] += 0.5 * ts * (st[a].v + after[a].v);
            }
            k += 1;
        }
    }
    out
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
    let p = PendulumModel {
        m_q: 0.952,
        m_p: 0.3,
        l: 1.5,
        c: 0.002,
    };
    let m = pendulum_delay_model(&p, 0.03, 50, 2, 7).expect("bench model");
    let mut g = c.benchmark_group("tracking_step");
    g.measurement_time(Duration::from_secs(3)).sample_size(20);
    g.bench_function("2axis/preview", |b| {
        b.iter_custom(|iters| tracking_ticks(&m, iters as usize).into_iter().sum())
    });
    g.finish();
    let mut t = tracking_ticks(&m, 3000);
    t.sort();
    let us = |d: Duration| d.as_secs_f64() * 1e6;
    println!(
        "\ntracking MPC with preview (q = 50, 2 axes, guidance and preview included): \
         median {:.2} µs  p99 {:.2} µs  max {:.2} µs ({} ticks)",
        us(t[t.len() / 2]),
        us(t[t.len() * 99 / 100]),
        us(t[t.len() - 1]),
        t.len()
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
