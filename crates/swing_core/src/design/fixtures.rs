//! Fixtures of the design layer's tests: a flight of the built-in training scenario, a
//! small model of it and the twin of that vehicle.

use crate::design::twin::TwinPlant;
use crate::sim::{Scenario, Simulator};
use crate::sysid::dmdc::{self, DmdcSettings};
use crate::sysid::hankel::Trajectory;
use crate::sysid::pipeline::{named, whitebox_model};
use crate::sysid::resample::resample;
use crate::sysid::settings::IdentifySettings;
use crate::sysid::LinearModel;

/// The first `seconds` of the flight `sc`: (vn, swing_n) and acc_sp_n at 0.03 s.
pub(crate) fn flight(sc: &Scenario, seconds: f64) -> (Vec<f64>, Vec<f64>) {
    let mut sc = sc.clone();
    sc.duration = seconds;
    let trace = Simulator::run(sc).unwrap();
    let t = trace.column("t").unwrap();
    let col = |n: &str| trace.column(n).unwrap();
    let (x, _) = resample(t, &[col("vn"), col("swing_n")], 0.03);
    let (u, _) = resample(t, &[col("acc_sp_n")], 0.03);
    (x, u)
}

/// The training flight's model as a template: DMDc q = 6 on 30 s of the built-in
/// training flight.
pub(crate) fn template(sc: &Scenario) -> LinearModel {
    let (x, u) = flight(sc, 30.0);
    let traj = Trajectory::new(&x, 2, &u, 1).unwrap();
    let settings = DmdcSettings {
        delays: 6,
        rank: None,
        offset: crate::sysid::Offset::Affine,
        dt: 0.03,
    };
    let model = dmdc::fit(&traj, &settings).unwrap();
    named(
        model,
        &["vn".into(), "swing_n".into()],
        &["acc_sp_n".into()],
    )
    .unwrap()
}

/// The builtin training vehicle's twin: a small delay model of 60 s of its flight, the
/// white-box of that flight (the true cable length) and the twin carrying it.
pub(crate) fn builtin_twin() -> (LinearModel, LinearModel, TwinPlant) {
    let sc = Scenario::builtin("training").unwrap();
    let tpl = template(&sc);
    let (x, u) = flight(&sc, 60.0);
    let traj = Trajectory::new(&x, 2, &u, 1).unwrap();
    let settings = IdentifySettings {
        cable_length: Some(sc.payload.length),
        vehicle_mass: sc.vehicle.mass,
        ..IdentifySettings::default()
    };
    let plant =
        whitebox_model(&traj, &tpl.states, &tpl.inputs, &settings, sc.payload.mass).unwrap();
    let twin = TwinPlant::new(&sc, &plant, 2.0, 1).unwrap();
    (tpl, plant, twin)
}
