//! Regression tests for the fuzz findings (`fuzz/`): each input once made the
//! core panic, hang or allocate without bound; now each is a typed error.

use nalgebra::{DMatrix, DVector};
use swing_core::control::MpcSettings;
use swing_core::design::{mpc_step_check, StepCheckSettings};
use swing_core::linalg::{c2d_zoh, eigenvalues, expm, sampled_lqr};
use swing_core::sim::{Scenario, Simulator};
use swing_core::sysid::metrics::start_points;
use swing_core::sysid::{Diagnostics, LinearModel, Offset};

fn small_model() -> LinearModel {
    LinearModel {
        method: "dmdc".into(),
        dt: 0.03,
        delays: 1,
        rank: 3,
        states: vec!["vn".into(), "swing_n".into(), "swing_rate_n".into()],
        inputs: vec!["acc_n".into()],
        offset: Offset::Affine,
        input_mean: vec![0.0],
        a: DMatrix::from_row_slice(3, 3, &[0.98, 0.0, 0.0, 0.0, 0.99, 0.03, 0.0, -0.3, 0.99]),
        b: DMatrix::from_row_slice(3, 1, &[0.03, -0.003, -0.1]),
        c: DVector::zeros(3),
        fingerprint: String::new(),
        diagnostics: Diagnostics::default(),
    }
}

/// fuzz/artifacts/scenario_toml/alloc-4cd64ecb4ee9795b: the trace was preallocated for
/// duration × log_rate rows (3.4 TB).
#[test]
fn huge_duration_is_refused_not_allocated() {
    let e = Scenario::from_toml("duration = 4294967296\n").unwrap_err();
    assert_eq!(e.field, "duration");
    assert!(e.to_string().contains("at most"), "{e}");
    // The longest allowed scenario builds without reserving its whole trace.
    let sc = Scenario::from_toml_over("duration = 86400.0\nlog_rate = 1000.0\n", "step").unwrap();
    Simulator::new(sc).unwrap();
}

/// A near-zero random-step hold time drew steps without end (loop + allocation).
#[test]
fn random_steps_that_never_end_are_refused() {
    let e = Scenario::from_toml_over(
        "[random_steps]\ninterval_min = 1e-300\ninterval_max = 1.0\n",
        "step",
    )
    .unwrap_err();
    assert_eq!(e.field, "random_steps.interval_min");
}

/// fuzz/artifacts/model_json/crash-*: `"delays": 18446744073709551615` overflowed n·q
/// (a panic with overflow checks, a wrapped dimension without).
#[test]
fn model_json_with_huge_declared_dimensions_is_refused() {
    let mut text = small_model().to_json().unwrap();
    text = text.replace("\"delays\": 1", "\"delays\": 18446744073709551615");
    let e = LinearModel::from_json(&text).unwrap_err();
    assert!(e.to_string().contains("largest model order"), "{e}");
    let text = small_model()
        .to_json()
        .unwrap()
        .replace("\"delays\": 1", "\"delays\": 1048576");
    let e = LinearModel::from_json(&text).unwrap_err();
    assert!(e.to_string().contains("largest model order"), "{e}");
}

/// The settings target: a step check with a duration of 1e300 s looped for ever.
#[test]
fn step_check_with_absurd_duration_is_refused() {
    let model = small_model();
    let settings = MpcSettings {
        horizon: 10,
        control_horizon: 3,
        ..MpcSettings::default()
    };
    let check = StepCheckSettings {
        duration: 1e300,
        ..StepCheckSettings::default()
    };
    let e = mpc_step_check(&model, settings, &model, &check).unwrap_err();
    assert!(e.to_string().contains("ticks"), "{e}");
}

/// fuzz/artifacts/identify/hang-*: nalgebra's `exp` of a matrix with entries near 1e40
/// squared 2^64 times (the white-box with a near-zero payload mass).
#[test]
fn matrix_exponential_of_huge_entries_is_refused() {
    let big = DMatrix::from_element(3, 3, 1e40);
    assert!(expm(&big).is_none());
    let mut nan = DMatrix::<f64>::identity(2, 2);
    nan[(0, 1)] = f64::NAN;
    assert!(expm(&nan).is_none());
    let (ad, _) = c2d_zoh(&big, &DMatrix::from_element(3, 1, 1.0), 0.03);
    assert!(ad.iter().all(|v| v.is_nan()));
    let q = DMatrix::<f64>::identity(3, 3);
    let r = DMatrix::<f64>::identity(1, 1);
    let e = sampled_lqr(&big, &DMatrix::from_element(3, 1, 1.0), &q, &r, 0.03).unwrap_err();
    assert!(e.to_string().contains("period"), "{e}");
    assert!((expm(&DMatrix::zeros(2, 2)).unwrap() - DMatrix::identity(2, 2)).norm() < 1e-15);
}

/// fuzz/artifacts/mpc/hang-*: the Kalman design's DARE called nalgebra's
/// `complex_eigenvalues`, whose Schur iteration has no bound.
#[test]
fn eigenvalues_are_bounded_and_refuse_non_finite() {
    let mut m = DMatrix::<f64>::identity(3, 3);
    m[(2, 0)] = f64::INFINITY;
    assert!(eigenvalues(&m).is_none());
    let ev = eigenvalues(&DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -1.0, 0.0])).unwrap();
    assert!(ev.iter().all(|l| (l.norm() - 1.0).abs() < 1e-12));
    assert!(eigenvalues(&DMatrix::zeros(0, 0)).unwrap().is_empty());
    // The companion matrix of (z − 0.5)(z + 0.3)(z² − 1.8z + 0.85): its roots, each once.
    let (a1, a2, a3, a4) = (
        -1.8 - 0.2,
        0.85 + 0.36 - 0.15,
        0.15 * 1.8 - 0.2 * 0.85,
        0.85 * -0.15,
    );
    let c = DMatrix::from_row_slice(
        4,
        4,
        &[
            -a1, -a2, -a3, -a4, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0,
        ],
    );
    let mut ev = eigenvalues(&c).unwrap();
    ev.sort_by(|x, y| (x.re, x.im).partial_cmp(&(y.re, y.im)).unwrap());
    let want = [(-0.3, 0.0), (0.5, 0.0), (0.9, -0.2), (0.9, 0.2)];
    for (l, (re, im)) in ev.iter().zip(want) {
        assert!(
            (l.re - re).abs() < 1e-9 && (l.im - im).abs() < 1e-9,
            "{ev:?}"
        );
    }
}

/// fuzz/artifacts/identify/crash-*: a rollout of 1e300 s is usize::MAX samples and the
/// length check `lo + horizon + 1` overflowed.
#[test]
fn rollout_start_points_do_not_overflow() {
    let e = start_points(100, 3, usize::MAX, 10).unwrap_err();
    assert!(e.to_string().contains("too short"), "{e}");
}

/// fuzz/artifacts/scenario_json/crash-e1def5e57f1f9f45: a JSON seed above i64::MAX was
/// accepted, and the scenario's TOML (`to_toml`) then did not parse back.
#[test]
fn seeds_beyond_toml_integers_are_refused() {
    let mut json = serde_json::to_value(Scenario::default_step()).unwrap();
    json["seed"] = serde_json::json!(u64::MAX);
    let e = Scenario::from_json(&json.to_string()).unwrap_err();
    assert_eq!(e.field, "seed");
    let sc = Scenario::from_json(
        &serde_json::to_string(&Scenario {
            seed: i64::MAX as u64,
            ..Scenario::default_step()
        })
        .unwrap(),
    )
    .unwrap();
    assert_eq!(Scenario::from_toml(&sc.to_toml().unwrap()).unwrap(), sc);
}

/// fuzz/artifacts/identify/crash-e834407164bf3d22 (and three more, all white-box): finite
/// inputs of f64::MAX overflowed the input mean (or the offset) to ∞, and `identify`
/// returned a model that does not validate.
#[test]
fn identify_refuses_data_that_overflows_the_model() {
    use swing_core::sysid::pipeline::identify;
    use swing_core::sysid::{IdentifyMethod, IdentifySettings, Trajectory};
    let x = vec![0.1; 32];
    let u = [
        3.428,
        -16.262,
        -3.272,
        -5.944,
        -30.386,
        -0.0,
        -7.467,
        0.0,
        3.1e-305,
        10.965,
        -7.433,
        -22.418,
        f64::MAX,
        3.506,
        -8.979,
        f64::MAX,
    ];
    let traj = Trajectory::new(&x, 2, &u, 1).unwrap();
    let settings = IdentifySettings {
        method: IdentifyMethod::Whitebox,
        offset: Offset::Mean,
        test_span: 0.1056,
        payload_mass: Some(3.858),
        vehicle_mass: 20.685,
        swing_band: [0.259, 48.33],
        ..IdentifySettings::default()
    };
    let states = vec!["vn".to_string(), "swing_n".to_string()];
    let e = identify(&traj, &states, &["acc_n".to_string()], &settings, None)
        .expect_err("a model with an infinite input mean");
    assert!(e.to_string().contains("no usable model"), "{e}");
}
