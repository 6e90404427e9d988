//! Identification budgets (DESIGN §8): one DMDc fit (q = 50, 120 s at 0.03 s, one axis)
//! < 5 ms, and the 366-candidate reference grid (q = 2…60 step 2 × p = 5…(2q+1) step 5,
//! 10 rollouts of 20 s) < 0.5 s, on one core.
//!
//! Data: a seeded pendulum-like flight — the white-box vehicle + payload model (0.2 kg on
//! 1 m) under a velocity P loop tracking random steps (table 4.1 ranges), with a little
//! velocity and swing noise, sampled at 0.03 s.

#![allow(clippy::needless_range_loop)]

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use swing_core::sysid::dmdc::{self, DmdcSettings};
use swing_core::sysid::search::{grid_search, Grid, SearchSettings};
use swing_core::sysid::whitebox::WhiteboxParams;
use swing_core::sysid::{Offset, Trajectory};

const DT: f64 = 0.03;

/// SplitMix64 uniform in [−1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// (x time-major [v, swing], u) for `seconds` of flight.
fn flight(seconds: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let params = WhiteboxParams {
        friction: 0.002,
        ..Default::default()
    };
    let (ad, bd) = params.discrete(DT);
    let mut rng = Rng(seed);
    let steps = (seconds / DT) as usize;
    let mut s = nalgebra::Vector3::<f64>::zeros();
    let (mut vref, mut next_change) = (0.0, 0usize);
    let (mut x, mut u) = (Vec::with_capacity(2 * steps), Vec::with_capacity(steps));
    for k in 0..steps {
        if k >= next_change {
            vref = 1.5 * (rng.next() + 1.0);
            next_change = k + ((17.5 + 7.5 * rng.next()) / DT) as usize;
        }
        let acc = (1.8 * (vref - s[0])).clamp(-4.0, 4.0) + 0.05 * rng.next();
        x.push(s[0] + 0.002 * rng.next());
        x.push(s[2] + 0.001 * rng.next());
        u.push(acc + 0.1); // an IMU-like offset on the setpoint channel
        s = ad * s + bd * acc;
    }
    (x, u)
}

/// Noise-free, smooth flight like the simulator's: a nonlinear floating pendulum
/// (0.2 kg on 1 m under a 0.952 kg vehicle, sin/cos kept) whose vehicle acceleration follows
/// the command through a 0.1 s first-order lag, a PID velocity loop at `DT` tracking seeded
/// random steps, RK4 with 10 sub-steps per sample. Returns (x time-major [v, θ], u).
fn smooth_flight(seconds: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let (mq, mp, l, g, fric, tau) = (0.952, 0.2, 1.0, 9.81, 0.05, 0.1);
    // s = [v, a, θ, θ̇], input the acceleration command.
    let deriv = |s: [f64; 4], cmd: f64| -> [f64; 4] {
        let (sin, cos) = s[2].sin_cos();
        [
            s[1] + g * mp / mq * sin * cos,
            (cmd - s[1]) / tau,
            s[3],
            -g * (mq + mp) / (mq * l) * sin - s[1] / l * cos - fric * s[3],
        ]
    };
    let mut rng = Rng(seed);
    let steps = (seconds / DT) as usize;
    let mut s = [0.0; 4];
    let (mut vref, mut next_change, mut integ, mut prev_e) = (0.0, 0usize, 0.0, 0.0);
    let (mut x, mut u) = (Vec::with_capacity(2 * steps), Vec::with_capacity(steps));
    let h = DT / 10.0;
    for k in 0..steps {
        if k >= next_change {
            vref = 1.5 * (rng.next() + 1.0);
            next_change = k + ((17.5 + 7.5 * rng.next()) / DT) as usize;
        }
        let e = vref - s[0];
        integ += e * DT;
        let cmd = (1.8 * e + 0.2 * integ + 0.05 * (e - prev_e) / DT).clamp(-4.0, 4.0);
        prev_e = e;
        x.push(s[0]);
        x.push(s[2]);
        u.push(cmd);
        for _ in 0..10 {
            let add = |a: [f64; 4], b: [f64; 4], c: f64| std::array::from_fn(|i| a[i] + c * b[i]);
            let k1 = deriv(s, cmd);
            let k2 = deriv(add(s, k1, h / 2.0), cmd);
            let k3 = deriv(add(s, k2, h / 2.0), cmd);
            let k4 = deriv(add(s, k3, h), cmd);
            s = std::array::from_fn(|i| s[i] + h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]));
        }
    }
    (x, u)
}

fn bench(c: &mut Criterion) {
    let (xs, us) = smooth_flight(120.0, 7);
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
