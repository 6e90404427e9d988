//! Integration tests of missions: the position-tracking MPC with preview against closed
//! forms and linear plants, and whole missions in the simulator (PX4's behaviour and the
//! tracking MPC) with their events.

#![allow(clippy::needless_range_loop)]

use swing_core::control::mpc::tracking::tracking_mpc_defaults;
use swing_core::control::mpc::MpcSettings;
use swing_core::control::{
    AxisState, LinearPlant, SwingController, TrackTarget, TrackingMpc, TrackingSettings,
};
use swing_core::mission::{
    EventKind, GuidanceMode, GuidanceSettings, Mission, PreviewBuffer, SCurve,
};
use swing_core::sim::{Scenario, Simulator};
use swing_core::testing::pendulum_delay_model;

use crate::fixtures::pendulum;

const TS: f64 = 0.03;

fn one_leg(n: f64, hold: f64) -> Mission {
    Mission::from_toml(&format!(
        "acceptance_radius = 0.3\n[[waypoint]]\nn = {n}\ne = 0\nd = -10\nhold = {hold}\n"
    ))
    .unwrap()
}

/// Fly `mission` on the linear plant of `plant` (its position integrated by the trapezoidal
/// rule) with the tracking MPC designed on `model`; a constant `bias` [m/s²] is added to
/// the commanded acceleration. Returns (time, position N, swing N) per tick.
fn fly_on(
    model: &swing_core::sysid::LinearModel,
    plant: &swing_core::sysid::LinearModel,
    mission: &Mission,
    settings: TrackingSettings,
    bias: f64,
    seconds: f64,
) -> Vec<(f64, f64, f64)> {
    let mut ctrl = TrackingMpc::new(model, settings).unwrap();
    let axes = ctrl.axes();
    let mut g = GuidanceSettings::default().build(mission).unwrap();
    let mut buf = PreviewBuffer::new(ctrl.reference_steps(), axes);
    let mut plant = LinearPlant::new(plant).unwrap();
    let mut pos = [0.0; 2];
    g.start(0.0, &[0.0, 0.0, -10.0], &[0.0; 3]);
    let mut out = Vec::new();
    let mut u = vec![0.0; axes];
    let refs = vec![0.0; axes];
    for k in 0..(seconds / TS) as usize {
        let t = k as f64 * TS;
        let st = plant.state();
        g.update(t, TS, &[pos[0], pos[1], -10.0], &[0.0; 3]);
        let view = buf.fill(g.as_ref(), t, TS);
        ctrl.observe_reference(&pos[..axes], &view);
        ctrl.step(&st, &refs, &mut u).unwrap();
        let applied: Vec<f64> = u.iter().map(|x| x + bias).collect();
        plant.step(&applied);
        let after = plant.state();
        for a in 0..axes {
            pos[a] += 0.5 * TS * (st[a].v + after[a].v);
        }
        out.push((t, pos[0], after[0].swing));
    }
    out
}

/// [`fly_on`] with the model as the plant.
fn fly_linear(
    model: &swing_core::sysid::LinearModel,
    mission: &Mission,
    settings: TrackingSettings,
    bias: f64,
    seconds: f64,
) -> Vec<(f64, f64, f64)> {
    fly_on(model, model, mission, settings, bias, seconds)
}

#[test]
fn predicted_position_is_the_trapezoid_of_the_models_velocity() {
    let m = pendulum_delay_model(&pendulum(0.3, 1.5), TS, 3, 1, 3).unwrap();
    let mut ctrl = TrackingMpc::new(&m, TrackingSettings::default()).unwrap();
    let mission = one_leg(20.0, 5.0);
    let mut g = GuidanceSettings::default().build(&mission).unwrap();
    g.start(0.0, &[0.0, 0.0, -10.0], &[0.0; 3]);
    g.update(1.0, TS, &[0.0, 0.0, -10.0], &[0.0; 3]);
    let mut buf = PreviewBuffer::new(ctrl.reference_steps(), 1);
    let view = buf.fill(g.as_ref(), 1.0, TS);
    let state = [AxisState {
        v: 0.4,
        swing: -0.05,
        swing_rate: 0.0,
    }];
    ctrl.observe_reference(&[1.5], &view);
    ctrl.reset(&state, &[0.3]);
    let mut u = [0.0];
    ctrl.step(&state, &[0.0], &mut u).unwrap();
    // Roll the model forward from the filter's estimate with the decided inputs (held after
    // Nc) and integrate its velocity: the MPC's predicted position must agree.
    let xi = ctrl.state_estimate().to_vec();
    let nz = m.a.nrows();
    let mut z = nalgebra::DVector::from_column_slice(&xi[1..1 + nz]);
    let mut p = xi[0];
    let inputs = ctrl.predicted_inputs().to_vec();
    let pred = ctrl.predicted_outputs();
    let nc = inputs.len();
    // State disturbances enter the newest frame as T_s·d.
    let nd = 2;
    let d = &xi[xi.len() - nd..];
    for i in 0..100 {
        let uk = inputs[i.min(nc - 1)];
        let v0 = z[0];
        let mut next =
            &m.a * &z + &m.b * nalgebra::DVector::from_element(1, uk - m.input_mean[0]) + &m.c;
        next[0] += TS * d[0];
        next[1] += TS * d[1];
        p += 0.5 * TS * (v0 + next[0]);
        z = next;
        // Outputs per step [q, v, ṡ, s]: the tracked point is the vehicle.
        assert!(
            (pred[4 * i] - p).abs() < 1e-9,
            "position at step {}: {} vs {p}",
            i + 1,
            pred[4 * i]
        );
        assert!(
            (pred[4 * i + 1] - z[0]).abs() < 1e-9,
            "velocity at step {}",
            i + 1
        );
    }
}

#[test]
fn a_leg_on_the_linear_plant_ends_on_the_waypoint_and_preview_tracks_closer() {
    let m = pendulum_delay_model(&pendulum(0.3, 1.5), TS, 4, 1, 5).unwrap();
    let mission = one_leg(30.0, 10.0);
    let with = fly_linear(&m, &mission, TrackingSettings::default(), 0.0, 25.0);
    let without = fly_linear(
        &m,
        &mission,
        TrackingSettings {
            preview: false,
            ..TrackingSettings::default()
        },
        0.0,
        25.0,
    );
    let leg = SCurve::new(30.0, 5.0, 1.6, 1.6);
    let err = |run: &[(f64, f64, f64)]| {
        run.iter()
            .map(|(t, p, _)| (p - leg.at(*t).s).abs())
            .fold(0.0, f64::max)
    };
    let (last_with, last_without) = (with.last().unwrap(), without.last().unwrap());
    assert!((last_with.1 - 30.0).abs() < 0.01, "ends at {}", last_with.1);
    assert!(last_with.2.abs() < 1e-3, "swing left {}", last_with.2);
    assert!(
        err(&with) < 0.5 * err(&without),
        "preview {} vs none {}",
        err(&with),
        err(&without)
    );
    assert!((last_without.1 - 30.0).abs() < 0.01);
}

#[test]
fn a_constant_force_leaves_no_position_offset() {
    let m = pendulum_delay_model(&pendulum(0.3, 1.5), TS, 4, 1, 5).unwrap();
    let run = fly_linear(
        &m,
        &one_leg(10.0, 30.0),
        TrackingSettings::default(),
        0.4,
        30.0,
    );
    let (_, p, _) = *run.last().unwrap();
    assert!((p - 10.0).abs() < 0.01, "offset {}", p - 10.0);
}

#[test]
fn bad_tracking_settings_name_the_field() {
    let e = TrackingSettings {
        target: TrackTarget::Payload,
        ..TrackingSettings::default()
    }
    .validate()
    .unwrap_err();
    assert_eq!(e.field, "cable_length");
    let e = TrackingSettings {
        mpc: MpcSettings {
            horizon: 0,
            ..tracking_mpc_defaults()
        },
        ..TrackingSettings::default()
    }
    .validate()
    .unwrap_err();
    assert_eq!(e.field, "mpc.horizon");
    // A tick without a reference is refused (it would track nothing).
    let m = pendulum_delay_model(&pendulum(0.3, 1.5), TS, 2, 1, 5).unwrap();
    let mut ctrl = TrackingMpc::new(&m, TrackingSettings::default()).unwrap();
    let mut u = [0.0];
    assert!(ctrl.step(&[AxisState::default()], &[0.0], &mut u).is_err());
}

/// A mission in the simulator (0.3 kg on 1.5 m) flown by PX4's cascade with `guidance`.
fn fly_sim(mission: &Mission, guidance: GuidanceSettings) -> Simulator {
    let mut sc = Scenario::builtin("hover").unwrap();
    sc.payload.mass = 0.3;
    sc.payload.length = 1.5;
    sc.start = mission.start();
    sc.duration = 200.0;
    let mut sim = Simulator::new(sc).unwrap();
    sim.fly_mission(guidance.build(mission).unwrap(), 1.0)
        .unwrap();
    while !sim.mission_done() && sim.time() < 190.0 {
        sim.advance(0.5).unwrap();
    }
    sim
}

#[test]
fn px4_behaviour_flies_every_item_and_holds_from_the_arrival() {
    let mission = Mission::from_toml(
        "acceptance_radius = 0.5\nhold = 3.0\n[[waypoint]]\nn = 25\ne = 0\nd = -10\n\
         [[waypoint]]\nn = 25\ne = 20\nd = -10\n",
    )
    .unwrap();
    let px4 = GuidanceSettings {
        mode: GuidanceMode::Px4,
        ..GuidanceSettings::default()
    };
    let sim = fly_sim(&mission, px4);
    assert!(sim.mission_done());
    let ev = sim.mission_events();
    let kinds: Vec<_> = ev.iter().map(|e| (e.item, e.kind)).collect();
    use EventKind::*;
    assert_eq!(
        kinds,
        [
            (0, Started),
            (0, Reached),
            (0, Left),
            (1, Reached),
            (1, Completed)
        ]
    );
    // At each arrival the vehicle is within the radius; the hold lasts its time.
    let tr = sim.trace();
    let (t, pn, pe) = (
        tr.column("t").unwrap(),
        tr.column("pn").unwrap(),
        tr.column("pe").unwrap(),
    );
    for pair in ev.windows(2).filter(|w| w[0].kind == Reached) {
        let k = t.iter().position(|x| *x >= pair[0].t - 1e-9).unwrap();
        let wp = mission.items[pair[0].item].position;
        assert!((pn[k] - wp[0]).hypot(pe[k] - wp[1]) <= 0.5 + 0.05);
        assert!((pair[1].t - pair[0].t - 3.0).abs() < 0.03);
    }
}

#[test]
fn the_payload_target_puts_the_payload_over_the_waypoint_under_a_steady_pull() {
    // A constant push on the swing equation (a steady force on the payload alone, as wind on
    // a parcel) holds the payload off the vertical: the vehicle target keeps the vehicle on
    // the waypoint, the payload target the payload (vehicle + ℓ sin s).
    let m = pendulum_delay_model(&pendulum(0.3, 1.5), TS, 4, 1, 5).unwrap();
    let mut pulled = m.clone();
    pulled.c[1] += 5e-4;
    let mission = one_leg(10.0, 40.0);
    let vehicle = fly_on(
        &m,
        &pulled,
        &mission,
        TrackingSettings::default(),
        0.0,
        40.0,
    );
    let payload_target = TrackingSettings {
        target: TrackTarget::Payload,
        cable_length: Some(1.5),
        ..TrackingSettings::default()
    };
    let payload = fly_on(&m, &pulled, &mission, payload_target, 0.0, 40.0);
    let (_, p, s) = *vehicle.last().unwrap();
    assert!((p - 10.0).abs() < 0.005, "vehicle at {p}");
    assert!(s.abs() > 0.03, "the pull does not show ({s} rad)");
    let (_, p, s) = *payload.last().unwrap();
    assert!(
        (p + 1.5 * s - 10.0).abs() < 0.005,
        "payload at {}",
        p + 1.5 * s
    );
    assert!(
        (p - 10.0).abs() > 0.04,
        "the vehicle did not move off the waypoint"
    );
}
