//! The IMU swing estimator's cost per sample, as the offboard node and the simulator pay it
//! at 100 Hz: the low-passed estimate alone, and with the pendulum observer that tells the
//! swing from drag (`sensors::pendulum`). Budget: a few µs, against the 10 ms between samples.

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Matrix3, Rotation3};
use std::hint::black_box;
use swing_core::sensors::{ImuSwingEstimator, ImuSwingSettings};

fn per_sample(c: &mut Criterion) {
    let mut group = c.benchmark_group("imu_estimator");
    // A second of a swinging flight at 100 Hz: tilting, accelerating, pulled by the cable.
    let samples: Vec<([f64; 3], Matrix3<f64>, [f64; 3])> = (0..100)
        .map(|k| {
            let t = k as f64 * 0.01;
            let s = (3.0 * t).sin();
            let rot = Rotation3::from_euler_angles(0.05 * s, -0.1 * s, 0.3).into_inner();
            ([0.4 * s, -0.2 * s, -9.8], rot, [2.0 * t, 0.1 * s, 0.0])
        })
        .collect();
    for (name, length) in [("low_pass", 0.0), ("pendulum_observer", 1.0)] {
        let settings = ImuSwingSettings {
            length,
            damping: 0.02,
            tare: 0.0,
            ..ImuSwingSettings::default()
        };
        let mut est = ImuSwingEstimator::new(settings).expect("valid settings");
        group.bench_function(name, |b| {
            let mut k = 0;
            b.iter(|| {
                let (a, rot, v) = &samples[k % samples.len()];
                k += 1;
                black_box(est.update(black_box(*a), rot, black_box(*v)))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, per_sample);
criterion_main!(benches);
