//! Simulation speed: simulated seconds per wall second of the full closed loop (vehicle +
//! single payload + PX4 cascade + 100 Hz logging) at the 1 ms RK4 step, on one core.
//! Budget (docs/architecture.md, "Budgets"): ≥ 1000× real time, stretch 5000×.

#![allow(clippy::needless_range_loop)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use swing_core::plant::PayloadKind;
use swing_core::sim::{Scenario, Simulator};

fn one_second(c: &mut Criterion) {
    let mut group = c.benchmark_group("sim_step");
    // Throughput in physics steps: elements/s ÷ 1000 = real-time factor.
    group.throughput(Throughput::Elements(1000));
    for (name, kind) in [
        ("single_payload_1s", PayloadKind::Single),
        ("double_payload_1s", PayloadKind::Double),
        ("no_payload_1s", PayloadKind::None),
    ] {
        let mut sc = Scenario::default_step();
        sc.payload.kind = kind;
        sc.duration = 1.0e6;
        let mut sim = Simulator::new(sc).expect("valid scenario");
        // Warm past the step so the benchmark sees a swinging payload.
        sim.advance(5.0).expect("runs");
        group.bench_function(name, |b| {
            b.iter(|| {
                sim.advance(black_box(1.0)).expect("runs");
                // Keep memory flat over millions of iterations.
                if sim.trace().len() > 100_000 {
                    sim.take_trace();
                }
            })
        });
    }
    group.finish();
}

criterion_group!(benches, one_second);
criterion_main!(benches);
