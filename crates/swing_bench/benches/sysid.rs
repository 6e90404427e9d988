//! Identification budgets (docs/architecture.md, "Budgets"): one DMDc fit (q = 50, 120 s at 0.03 s, one axis)
//! < 5 ms, and the 366-candidate reference grid (q = 2…60 step 2 × p = 5…(2q+1) step 5,
//! 10 rollouts of 20 s) < 0.5 s, on one core.
//!
//! Data: seeded pendulum flights sampled at 0.03 s — the linear vehicle + payload model
//! (0.2 kg on 1 m) under a velocity P loop tracking random steps (table 4.1 ranges), with a
//! little velocity and swing noise, and the smooth nonlinear flight of
//! [`swing_core::testing::smooth_pendulum_flight`].

#![allow(clippy::needless_range_loop)]

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::DVector;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use swing_core::plant::PendulumModel;
use swing_core::sysid::dmdc::{self, DmdcSettings};
use swing_core::sysid::search::{grid_search, Grid, SearchSettings};
use swing_core::sysid::{Offset, Trajectory};
use swing_core::testing::{random_velocity_steps, smooth_pendulum_flight};

const DT: f64 = 0.03;

/// (x time-major [v, swing], u) for `seconds` of flight.
fn flight(seconds: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let params = PendulumModel {
        c: 0.002,
        ..Default::default()
    };
    let (ad, bd) = params.discrete(DT);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut noise = move || rng.random_range(-1.0..1.0);
    let steps = (seconds / DT) as usize;
    let mut vel_ref = random_velocity_steps(DT, seed ^ 0x5354_4550);
    // s = [v, θ, θ̇]
    let mut s = DVector::<f64>::zeros(3);
    let (mut x, mut u) = (Vec::with_capacity(2 * steps), Vec::with_capacity(steps));
    for k in 0..steps {
        let acc = (1.8 * (vel_ref(k) - s[0])).clamp(-4.0, 4.0) + 0.05 * noise();
        x.push(s[0] + 0.002 * noise());
        x.push(s[1] + 0.001 * noise());
        u.push(acc + 0.1); // an IMU-like offset on the setpoint channel
        s = &ad * &s + &bd * acc;
    }
    (x, u)
}

fn bench(c: &mut Criterion) {
    let (xs, us) = smooth_pendulum_flight((120.0 / DT) as usize, DT, random_velocity_steps(DT, 7));
    let smooth = Trajectory::new(&xs, 2, &us, 1).unwrap();
    let affine = DmdcSettings {
        delays: 50,
        rank: Some(40),
        offset: Offset::Affine,
        dt: DT,
    };
    c.bench_function("dmdc_fit_q50_120s_smooth_affine", |b| {
        b.iter(|| dmdc::fit(black_box(&smooth), &affine).unwrap())
    });

    // Optional: recorded data (CSV rows `x0,x1,u`, e.g. the simulator flight that
    // `swingrt bench` uses), named by SWINGRT_DMDC_DATA.
    if let Ok(path) = std::env::var("SWINGRT_DMDC_DATA") {
        let text = std::fs::read_to_string(&path).expect("SWINGRT_DMDC_DATA is readable");
        let (mut xf, mut uf) = (Vec::new(), Vec::new());
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let v: Vec<f64> = line.split(',').map(|t| t.trim().parse().unwrap()).collect();
            xf.extend([v[0], v[1]]);
            uf.push(v[2]);
        }
        let file = Trajectory::new(&xf, 2, &uf, 1).unwrap();
        c.bench_function("dmdc_fit_q50_file_affine", |b| {
            b.iter(|| dmdc::fit(black_box(&file), &affine).unwrap())
        });
    }

    let (x, u) = flight(120.0, 1);
    let traj = Trajectory::new(&x, 2, &u, 1).unwrap();
    let settings = DmdcSettings {
        delays: 50,
        rank: Some(40),
        offset: Offset::Mean,
        dt: DT,
    };
    c.bench_function("dmdc_fit_q50_120s", |b| {
        b.iter(|| dmdc::fit(black_box(&traj), &settings).unwrap())
    });

    let (x2, u2) = flight(160.0, 2);
    let all = Trajectory::new(&x2, 2, &u2, 1).unwrap();
    let split = (40.0 / DT) as usize;
    let (test, train) = (all.slice(0, split), all.slice(split, all.len));
    let grid = Grid::reference();
    let count: usize = grid
        .delays
        .iter()
        .map(|q| grid.ranks(*q, 2, 1, 0, usize::MAX).len())
        .sum();
    assert_eq!(count, 366);
    let search = SearchSettings {
        offset: Offset::Mean,
        horizon: (20.0 / DT).round() as usize,
        ..SearchSettings::default()
    };
    let mut group = c.benchmark_group("search");
    group.sample_size(10);
    group.bench_function("reference_grid_366", |b| {
        b.iter(|| grid_search(black_box(&train), &test, &grid, &search).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
