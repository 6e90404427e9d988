//! The scenario text format around the typed fields: sentinel values in files map onto
//! enums and options, and writing gives the same text as before.

use swing_core::control::px4::AxisSetpoint;
use swing_core::sim::{Axes, Scenario, SetpointEntry};

#[test]
fn hover_thrust_zero_or_absent_means_estimate_and_is_written_as_zero() {
    let absent = Scenario::from_toml("duration = 5.0\n").unwrap();
    assert_eq!(absent.controller.hover_thrust, None);
    let zero = Scenario::from_toml("[controller]\nhover_thrust = 0.0\n").unwrap();
    assert_eq!(zero.controller.hover_thrust, None);
    let given = Scenario::from_toml("[controller]\nhover_thrust = 0.4\n").unwrap();
    assert_eq!(given.controller.hover_thrust, Some(0.4));
    assert!(absent.to_toml().unwrap().contains("hover_thrust = 0.0"));
    let back = Scenario::from_toml(&given.to_toml().unwrap()).unwrap();
    assert_eq!(back.controller.hover_thrust, Some(0.4));
    assert!(Scenario::from_toml("[controller]\nhover_thrust = -0.1\n").is_err());
}

#[test]
fn random_step_axes_read_and_write_n_e_ne() {
    for (text, axes) in [("n", Axes::N), ("e", Axes::E), ("ne", Axes::Ne)] {
        let sc = Scenario::from_toml(&format!("[random_steps]\naxes = \"{text}\"\n")).unwrap();
        let rs = sc.random_steps.clone().unwrap();
        assert_eq!(rs.axes, axes);
        assert!(sc
            .to_toml()
            .unwrap()
            .contains(&format!("axes = \"{text}\"")));
        let entry = &rs.schedule(60.0, 1)[0];
        assert_eq!(entry.vn.is_some(), axes != Axes::E);
        assert_eq!(entry.ve.is_some(), axes != Axes::N);
    }
    let err = Scenario::from_toml("[random_steps]\naxes = \"x\"\n").unwrap_err();
    assert!(err.to_string().contains("random_steps.axes"), "{err}");
}

#[test]
fn setpoint_entries_give_typed_axis_setpoints() {
    let e = SetpointEntry {
        pn: Some(1.0),
        ve: Some(-0.5),
        ad: Some(0.2),
        ..Default::default()
    };
    assert_eq!(e.axis(0), Some(AxisSetpoint::Position(1.0)));
    assert_eq!(e.axis(1), Some(AxisSetpoint::Velocity(-0.5)));
    assert_eq!(e.axis(2), Some(AxisSetpoint::Acceleration(0.2)));
    assert_eq!(SetpointEntry::default().axis(0), None);
}
