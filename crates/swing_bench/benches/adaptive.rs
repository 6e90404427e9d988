//! The adaptive MPC: one tick with the online DMDc update (square-root forgetting step,
//! excitation window, detector free run) and the MPC step, and one re-synthesis (rank-p
//! model from the factor, MPC design, closed-loop check). Model: the white-box pendulum
//! (m_p 0.2 kg, l 1 m) at 0.03 s in 20 delay coordinates (the default q), seed 7, default
//! MPC and adaptive settings; the plant is the model itself under ±2 m/s velocity steps, so
//! every sample is excited and enters the estimate. After criterion's runs the median / p99
//! are printed from `swing_bench::adaptive_timing`. The twin path's re-identification
//! (`design::reidentify`: a twin training flight with 0.3 kg on 1.5 m, then DMDc of the same
//! form, or the default rank search at the model's q = 20 with the control-relevant
//! selection) is timed too; the MPC design of the swap costs what the re-synthesis does.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use swing_bench::adaptive_timing;
use swing_core::control::{AxisState, LinearPlant, MpcSettings, SwingController};
use swing_core::design::reidentify::Twin;
use swing_core::design::{AdaptiveMpc, AdaptiveSettings};
use swing_core::plant::PendulumModel;
use swing_core::sim::Scenario;
use swing_core::sysid::LinearModel;
use swing_core::testing::pendulum_delay_model;

fn model() -> LinearModel {
    let p = PendulumModel {
        m_q: 0.952,
        m_p: 0.2,
        l: 1.0,
        c: 0.002,
    };
    pendulum_delay_model(&p, 0.03, 20, 1, 7).expect("bench model")
}

/// A controller that has flown `warm` ticks (its factor full of data) and its plant.
fn flown(m: &LinearModel, warm: usize) -> (AdaptiveMpc, LinearPlant, usize) {
    let mut ctrl =
        AdaptiveMpc::new(m, MpcSettings::default(), AdaptiveSettings::default()).expect("ctrl");
    let mut plant = LinearPlant::new(m).expect("plant");
    let st = [AxisState::default()];
    ctrl.reset(&st, &[0.0]);
    let mut k = 0;
    for _ in 0..warm {
        tick(&mut ctrl, &mut plant, k);
        k += 1;
    }
    (ctrl, plant, k)
}

fn tick(ctrl: &mut AdaptiveMpc, plant: &mut LinearPlant, k: usize) {
    let r = [if (k / 133) % 2 == 0 { 2.0 } else { -2.0 }];
    let st = plant.state();
    let mut u = [0.0];
    ctrl.step(&st, &r, &mut u).expect("tick");
    ctrl.between_ticks();
    plant.step(&u);
}

fn bench(c: &mut Criterion) {
    let m = model();
    let mut g = c.benchmark_group("adaptive");
    g.measurement_time(Duration::from_secs(5));
    g.bench_function("tick_with_update_q20", |b| {
        let (mut ctrl, mut plant, mut k) = flown(&m, 400);
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            for _ in 0..iters {
                let r = [if (k / 133) % 2 == 0 { 2.0 } else { -2.0 }];
                let st = plant.state();
                let mut u = [0.0];
                let t0 = Instant::now();
                ctrl.step(black_box(&st), &r, &mut u).expect("tick");
                total += t0.elapsed();
                ctrl.between_ticks();
                plant.step(&u);
                k += 1;
            }
            total
        });
    });
    g.sample_size(10);
    g.bench_function("resynthesis_q20", |b| {
        let (ctrl, _, _) = flown(&m, 600);
        // Time the whole path: the candidate must get through every test.
        if let Err(e) = ctrl.synthesize_now() {
            panic!("bench candidate refused: {e}");
        }
        b.iter(|| black_box(ctrl.synthesize_now()));
    });
    let training = Scenario::builtin("training").expect("scenario");
    let fixed = Twin::new(&training, 60.0, 0.952, false).expect("twin");
    let searched = Twin::new(&training, 120.0, 0.952, true).expect("twin");
    let mut template = m.clone();
    template.method = "dmdc".into();
    template.offset = swing_core::sysid::Offset::Affine;
    let mpc = MpcSettings::default();
    g.bench_function("twin_reidentify_search_120s_q20", |b| {
        b.iter(|| {
            black_box(
                searched
                    .identify(&template, 0.3, 1.5, &mpc)
                    .expect("twin model"),
            )
        });
    });
    g.finish();
    for (label, twin) in [
        ("60 s flight, DMDc at the model's q and p", &fixed),
        ("120 s flight, rank search at q = 20 + selection", &searched),
    ] {
        let mut ms: Vec<f64> = (0..10)
            .map(|_| {
                let t0 = Instant::now();
                black_box(
                    twin.identify(&template, 0.3, 1.5, &mpc)
                        .expect("twin model"),
                );
                t0.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        ms.sort_by(f64::total_cmp);
        println!(
            "twin re-identification ({label}): median {:.1} ms, max {:.1} ms",
            ms[5], ms[9]
        );
    }
    let (tick, build) = adaptive_timing(
        &m,
        &MpcSettings::default(),
        &AdaptiveSettings::default(),
        3000,
        10,
    )
    .expect("timing");
    println!(
        "adaptive tick with update (q = 20): median {:.1} µs, p99 {:.1} µs; \
         re-synthesis: median {:.1} ms, max {:.1} ms",
        tick.median_us, tick.p99_us, build.median_us, build.max_us
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
