//! Integration tests of the adaptive MPC: detection, re-synthesis and swap on linear plants
//! whose dynamics switch, no allocation on the tick, and no adaptation without excitation.

#![allow(clippy::needless_range_loop)]

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use swing_core::control::{AxisState, LinearPlant, MpcSettings, SwingController};
use swing_core::design::{AdaptiveMpc, AdaptiveSettings, SynthesisMode};
use swing_core::sysid::LinearModel;
use swing_core::testing::delay_model;

use crate::fixtures::pendulum;

const TS: f64 = 0.03;

fn model(m_p: f64, l: f64) -> LinearModel {
    delay_model(&pendulum(m_p, l), TS, 3, 7).unwrap()
}

/// Square-wave velocity reference: ±1.5 m/s, 5 s per level.
fn reference(k: usize) -> f64 {
    if (k / 167) % 2 == 0 {
        1.5
    } else {
        -1.5
    }
}

fn fly(
    ctrl: &mut AdaptiveMpc,
    plant: &mut LinearPlant,
    ticks: usize,
    noise: f64,
    refs: impl Fn(usize) -> f64,
    mut each: impl FnMut(usize, &mut AdaptiveMpc),
) -> f64 {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut u = [0.0];
    let mut worst_v = 0.0_f64;
    for k in 0..ticks {
        let mut st = plant.state();
        for s in st.iter_mut() {
            let (a, b): (f64, f64) = (
                StandardNormal.sample(&mut rng),
                StandardNormal.sample(&mut rng),
            );
            s.v += noise * a;
            s.swing += 0.3 * noise * b;
        }
        ctrl.step(&st, &[refs(k)], &mut u).unwrap();
        ctrl.between_ticks();
        plant.step(&u);
        worst_v = worst_v.max(plant.state()[0].v.abs());
        each(k, ctrl);
    }
    worst_v
}

fn settings() -> AdaptiveSettings {
    AdaptiveSettings {
        synthesis: SynthesisMode::Deferred,
        ..AdaptiveSettings::default()
    }
}

/// Designed on a light payload on a short cable, flying a heavy one on a long cable: the
/// detector fires, a model passing the check is adopted, and along the loop flown after the
/// swap it predicts the plant far better than the model it replaced.
#[test]
fn a_switched_plant_is_detected_and_its_model_adopted() {
    let light = model(0.1, 0.5);
    let heavy = model(0.3, 2.0);
    let probing = AdaptiveSettings {
        probe_amplitude: 0.2,
        ..settings()
    };
    let mut ctrl = AdaptiveMpc::new(&light, MpcSettings::default(), probing).unwrap();
    let mut plant = LinearPlant::new(&heavy).unwrap();
    ctrl.reset(&plant.state(), &[0.0]);
    let mut u = [0.0];
    let mut worst_v = 0.0_f64;
    let (mut err_old, mut err_new) = (0.0_f64, 0.0_f64);
    for k in 0..3000 {
        let st = plant.state();
        ctrl.step(&st, &[reference(k)], &mut u).unwrap();
        ctrl.between_ticks();
        let z = plant.z().clone();
        plant.step(&u);
        worst_v = worst_v.max(plant.state()[0].v.abs());
        if ctrl.swaps() > 0 {
            // One-step predictions of the newest frame from the plant's own delay state:
            // delay models of one system differ, their predictions along a trajectory do not.
            let next = plant.z();
            for (m, err) in [(&light, &mut err_old), (ctrl.model(), &mut err_new)] {
                let pred = &m.a * &z + &m.b * u[0] + &m.c;
                for i in 0..2 {
                    *err = err.max((pred[i] - next[i]).abs());
                }
            }
        }
    }
    let events = ctrl.events();
    let detected = events.iter().position(|e| e.what == "detected");
    let adopted = events.iter().position(|e| e.what == "adopted");
    eprintln!(
        "events: {events:?}; last rejection: {}",
        ctrl.last_rejection()
    );
    assert!(detected.is_some(), "the detector must fire");
    assert!(
        adopted > detected,
        "a model must be adopted after the detection"
    );
    eprintln!("one-step error after the swap: replaced model {err_old:.3e}, adopted {err_new:.3e}");
    assert!(
        err_new < 1e-3 * err_old,
        "adopted model does not predict the plant: {err_new:e} vs {err_old:e}"
    );
    assert!(worst_v < 5.0, "loop left the envelope: |v| up to {worst_v}");
}

/// A plant that switches back right after a swap: the new model mispredicts at once, the
/// detector fires within the revert window and the replaced controller takes over again.
#[test]
fn a_swap_that_mispredicts_at_once_is_reverted() {
    let light = model(0.1, 0.5);
    let heavy = model(0.3, 2.0);
    let probing = AdaptiveSettings {
        probe_amplitude: 0.2,
        revert_window: 400,
        ..settings()
    };
    let mut ctrl = AdaptiveMpc::new(&light, MpcSettings::default(), probing).unwrap();
    let mut plant = LinearPlant::new(&heavy).unwrap();
    ctrl.reset(&plant.state(), &[0.0]);
    let mut u = [0.0];
    let mut switched_back = false;
    for k in 0..3000 {
        if ctrl.swaps() == 1 && !switched_back {
            plant = LinearPlant::new(&light).unwrap();
            switched_back = true;
        }
        let st = plant.state();
        ctrl.step(&st, &[reference(k)], &mut u).unwrap();
        ctrl.between_ticks();
        plant.step(&u);
    }
    let events = ctrl.events();
    eprintln!("{events:?}");
    assert!(switched_back, "no swap happened");
    let whats: Vec<&str> = events.iter().map(|e| e.what).collect();
    let adopted = whats.iter().position(|w| *w == "adopted").unwrap();
    let reverted = whats.iter().position(|w| *w == "reverted");
    assert!(reverted > Some(adopted), "{whats:?}");
    assert_eq!(
        ctrl.model().a,
        light.a,
        "the original controller flies again"
    );
    assert_eq!(ctrl.swaps(), 1, "adaptation stops after a revert");
}

/// Ten minutes of hover on the right model with sensor noise: the gate holds the estimate
/// still, the detector stays quiet and the model never changes.
#[test]
fn ten_minutes_of_hover_without_excitation_leave_the_model_alone() {
    let m = model(0.2, 1.0);
    let mut ctrl = AdaptiveMpc::new(&m, MpcSettings::default(), settings()).unwrap();
    let mut plant = LinearPlant::new(&m).unwrap();
    ctrl.reset(&plant.state(), &[0.0]);
    let ticks = (600.0 / TS) as usize;
    let (mut s1, mut s2) = (0.0, 0.0);
    fly(
        &mut ctrl,
        &mut plant,
        ticks,
        0.01,
        |_| 0.0,
        |_, c| {
            let u = c.controller().predicted_inputs()[0];
            s1 += u;
            s2 += u * u;
        },
    );
    let mean = s1 / ticks as f64;
    eprintln!(
        "hover input std {:.4} m/s²",
        (s2 / ticks as f64 - mean * mean).sqrt()
    );
    assert_eq!(ctrl.swaps(), 0);
    assert_eq!(
        ctrl.online().accepted(),
        0,
        "hover samples entered the estimate"
    );
    assert!(ctrl.events().is_empty(), "{:?}", ctrl.events());
    assert_eq!(ctrl.model().a, m.a);
}

/// A candidate that cannot pass the check is rejected and the old controller kept.
#[test]
fn a_candidate_failing_the_check_is_not_swapped_in() {
    let light = model(0.1, 0.5);
    let heavy = model(0.3, 2.0);
    let strict = AdaptiveSettings {
        // No loop reaches zero overshoot and zero final error: every candidate fails.
        bounds: swing_core::design::selection::CheckBounds {
            overshoot: 1e-12,
            final_error: 1e-12,
            hold_drift: 1e-12,
        },
        ..settings()
    };
    let mut ctrl = AdaptiveMpc::new(&light, MpcSettings::default(), strict).unwrap();
    let mut plant = LinearPlant::new(&heavy).unwrap();
    ctrl.reset(&plant.state(), &[0.0]);
    fly(&mut ctrl, &mut plant, 2000, 0.0, reference, |_, _| {});
    assert!(ctrl.rejections() >= 1);
    assert_eq!(ctrl.swaps(), 0);
    assert!(
        ctrl.last_rejection().contains("check"),
        "{}",
        ctrl.last_rejection()
    );
    assert_eq!(ctrl.model().a, light.a);
}

/// The worker-thread synthesis swaps too, and the tick never waits for it.
#[test]
fn thread_synthesis_swaps_without_blocking_the_tick() {
    let light = model(0.1, 0.5);
    let heavy = model(0.3, 2.0);
    let s = AdaptiveSettings {
        synthesis: SynthesisMode::Thread,
        ..AdaptiveSettings::default()
    };
    let mut ctrl = AdaptiveMpc::new(&light, MpcSettings::default(), s).unwrap();
    let mut plant = LinearPlant::new(&heavy).unwrap();
    ctrl.reset(&plant.state(), &[0.0]);
    let mut slowest = 0.0_f64;
    let mut u = [0.0];
    for k in 0..4000 {
        let st = plant.state();
        let t0 = std::time::Instant::now();
        ctrl.step(&st, &[reference(k)], &mut u).unwrap();
        slowest = slowest.max(t0.elapsed().as_secs_f64());
        plant.step(&u);
        // Give the worker wall time, as a real loop's period would.
        std::thread::sleep(std::time::Duration::from_micros(200));
    }
    eprintln!(
        "slowest tick {:.1} µs, swaps {}",
        slowest * 1e6,
        ctrl.swaps()
    );
    assert!(ctrl.swaps() >= 1, "events {:?}", ctrl.events());
    // A build takes milliseconds; a tick that waited for one would show it.
    assert!(slowest < 5e-3, "a tick took {slowest} s");
}

/// Ticks allocate nothing, including the ticks that request a rebuild and swap one in.
#[test]
fn adaptive_ticks_allocate_nothing_even_when_swapping() {
    assert!(crate::counting::count(|| drop(std::hint::black_box(vec![1.0f64; 10]))) > 0);
    let light = model(0.1, 0.5);
    let heavy = model(0.3, 2.0);
    let mut ctrl = AdaptiveMpc::new(&light, MpcSettings::default(), settings()).unwrap();
    let mut plant = LinearPlant::new(&heavy).unwrap();
    ctrl.reset(&plant.state(), &[0.0]);
    let mut u = [0.0];
    for k in 0..3000 {
        let st: Vec<AxisState> = plant.state();
        let r = [reference(k)];
        let n = crate::counting::count(|| {
            ctrl.step(&st, &r, &mut u).unwrap();
        });
        assert_eq!(n, 0, "tick {k} allocated {n} times");
        ctrl.between_ticks();
        plant.step(&u);
    }
    assert!(ctrl.swaps() >= 1, "no swap happened: {:?}", ctrl.events());
}
