//! Scenarios built from a base and overrides, settings merges, and the linear-model drag.

use swing_core::plant::VehicleParams;
use swing_core::sim::Scenario;
use swing_core::sysid::{IdentifySettings, LinearModel};

#[test]
fn overrides_merge_key_by_key_over_a_builtin() {
    let sc = Scenario::from_toml_over("[payload]\nmass = 0.3\n", "training").unwrap();
    let base = Scenario::builtin("training").unwrap();
    assert_eq!(sc.payload.mass, 0.3);
    // Everything else keeps the base's value, the other payload fields included.
    assert_eq!(sc.payload.length, base.payload.length);
    assert_eq!(sc.random_steps, base.random_steps);
    assert_eq!(sc.duration, base.duration);
    let hover = Scenario::builtin("hover").unwrap();
    assert!(hover.setpoints.is_empty() && hover.duration == 3600.0);
    assert!(Scenario::builtin("orbit").is_err());
}

#[test]
fn override_errors_name_the_dotted_field() {
    let e = Scenario::from_toml_over("[payload]\nmasss = 0.3\n", "step").unwrap_err();
    assert!(e.field.starts_with("payload"), "{e}");
    let e = Scenario::from_toml_over("[payload]\nmass = -0.3\n", "step").unwrap_err();
    assert_eq!(e.field, "payload.mass");
    let e = Scenario::from_toml_over("duration = nan\n", "step").unwrap_err();
    assert_eq!(e.field, "duration");
    let e = Scenario::from_toml_over("[wind\n", "step").unwrap_err();
    assert!(
        e.problem.contains("wind") || e.problem.contains("expected"),
        "{e}"
    );
}

#[test]
fn hover_thrust_balances_the_weight() {
    let sc = Scenario::builtin("step").unwrap();
    let cmd = sc.hover_thrust();
    let per_motor = sc.vehicle.thrust_at(cmd);
    let weight = (sc.vehicle.mass + sc.payload.total_mass()) * swing_core::plant::params::GRAVITY;
    assert!(
        (4.0 * per_motor - weight).abs() < 1e-9 * weight,
        "{per_motor}"
    );
}

#[test]
fn velocity_drag_changes_only_the_velocity_diagonals() {
    let text = r#"{"format": "swingrt-model/1", "method": "dmdc", "dt": 0.03, "delays": 1,
        "rank": 2, "states": ["vn", "swing_n"], "inputs": ["acc_sp_n"], "offset": "none",
        "input_mean": [0.0], "A": [[1.0, 0.2], [0.1, 0.9]], "B": [[0.03], [-0.01]],
        "c": [0.0, 0.0], "fingerprint": "abc"}"#;
    let m = LinearModel::from_json(text).unwrap();
    let d = m.with_velocity_drag(0.5).unwrap();
    assert!((d.a[(0, 0)] - (1.0 - 0.5 * 0.03)).abs() < 1e-15);
    assert_eq!((d.a[(0, 1)], d.a[(1, 0)], d.a[(1, 1)]), (0.2, 0.1, 0.9));
    assert_eq!(d.b, m.b);
    assert!(d.fingerprint.is_empty());
    assert!(m.with_velocity_drag(f64::NAN).is_err());
    assert!(m.with_velocity_drag(-1.0).is_err());
}

#[test]
fn identify_settings_roundtrip_through_json() {
    let s = IdentifySettings::default();
    let text = serde_json::to_string(&s).unwrap();
    assert_eq!(IdentifySettings::from_json(&text).unwrap(), s);
}

#[test]
fn overshoot_is_the_excursion_beyond_the_new_setpoint_in_steps() {
    use swing_core::design::check::{excursion, overshoot};
    // A 2 m/s step up that peaks at 2.5: 25 % of the step beyond the setpoint.
    assert_eq!(overshoot(&[0.5, 1.9, 2.5, 2.1], 0.0, 2.0), 0.25);
    // A step down from 2 to 0 that dips to −0.4: 20 %; never reaching it: negative.
    assert!((overshoot(&[1.0, -0.4, 0.1], 2.0, 0.0) - 0.2).abs() < 1e-15);
    assert!(overshoot(&[0.0, 1.0, 1.5], 0.0, 2.0) < 0.0);
    assert_eq!(excursion(3.0, 1.0, 1.0), 0.0);
    assert_eq!(overshoot(&[], 0.0, 1.0), f64::NEG_INFINITY);
}

#[test]
fn default_selection_check_covers_the_drag_of_a_step_into_strong_wind() {
    use swing_core::design::selection::SelectionSettings;
    use swing_core::plant::VehicleParams;
    // Quadratic drag ½ ρ C_Q w|w| linearised at airspeed w: ρ C_Q w / m per second. A 2 m/s
    // step into a 2 m/s headwind with a 0.5 kg payload must be among the plants checked, or
    // models that only hold light air pass and then cycle in flight.
    let v = VehicleParams::default();
    let airspeed = 4.0;
    let needed = v.air_density * v.drag[0] * airspeed / (v.mass + 0.5);
    let s = SelectionSettings::default();
    let most = s.vehicle_drag.iter().copied().fold(0.0, f64::max);
    assert!(most >= needed, "largest check drag {most} /s < {needed} /s");
    assert!(
        s.vehicle_drag.iter().any(|k| *k < needed / 2.0),
        "{:?}",
        s.vehicle_drag
    );
    s.validate().unwrap();
}

#[test]
fn naming_an_airframe_replaces_the_vehicle_then_the_file_applies() {
    let sc =
        Scenario::from_toml_over("[vehicle]\nairframe = \"x500\"\nmass = 2.4\n", "step").unwrap();
    let x500 = VehicleParams::x500();
    assert_eq!(sc.vehicle.mass, 2.4);
    assert_eq!(sc.vehicle.inertia, x500.inertia);
    assert_eq!(sc.vehicle.rotor_xy, x500.rotor_xy);
    // Naming the airframe a scenario already has changes nothing.
    let again = sc.with_overrides(toml::from_str("[vehicle]\nairframe = \"x500\"").unwrap());
    assert_eq!(again.unwrap().vehicle.mass, 2.4);
    let e = Scenario::from_toml_over("[vehicle]\nairframe = \"x600\"\n", "step").unwrap_err();
    assert_eq!(e.field, "vehicle.airframe");
    assert!(e.to_string().contains("honeybee, x500"), "{e}");
    let e = Scenario::from_toml_over("[vehicle]\nrotor_xy = [0.1, 0.2]\n", "step").unwrap_err();
    assert_eq!(e.field, "vehicle.arm");
}
