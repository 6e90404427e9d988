//! Fixtures for tests, benchmarks and `swingrt bench`: seeded linear models and flights
//! with known dynamics. Not for flight code; public so that the integration tests, the
//! criterion benches and the Python binding (`_core.pendulum_model_json`) share one copy.

use nalgebra::{DMatrix, DVector};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::plant::{PendulumModel, GRAVITY};
use crate::sysid::{LinearModel, Offset, SysidError};

/// A delay-embedded [`LinearModel`] over x = [v, θ] (one axis, input `acc_sp_n`) fitted
/// by least squares to a seeded random-step simulation of the exact ZOH discretisation
/// of [`PendulumModel::continuous`]: the physical dynamics fill the top n rows of A, exact
/// shifts the rows below (the structure DMDc produces). For tests and benchmarks.
pub fn delay_model(
    model: &PendulumModel,
    dt: f64,
    delays: usize,
    seed: u64,
) -> Result<LinearModel, SysidError> {
    model.validate()?;
    if !(dt.is_finite() && dt > 0.0) || delays == 0 {
        return Err(SysidError::Model(format!(
            "delay model: need dt > 0 and delays ≥ 1 (got {dt}, {delays})"
        )));
    }
    let (ad, bd) = model.discrete(dt);
    let n = 2;
    let nz = n * delays;
    let samples = (nz + 1) * 6 + 400;
    // Seeded random steps of table 4.1's kind (levels ±2 m/s², holds 0.3–1.5 s).
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut x = DVector::<f64>::zeros(3);
    let mut xs = Vec::with_capacity(samples + 1);
    let mut us = Vec::with_capacity(samples);
    let mut level = 0.0;
    let mut hold = 0usize;
    for _ in 0..samples {
        if hold == 0 {
            level = rng.random_range(-2.0..2.0);
            hold = (rng.random_range(0.3..1.5) / dt) as usize + 1;
            // pull velocity back toward zero so the data stay bounded
            level -= 0.5 * x[0];
        }
        hold -= 1;
        xs.push([x[0], x[1]]);
        us.push(level);
        x = &ad * &x + &bd * level;
    }
    xs.push([x[0], x[1]]);
    // Regression z_{k+1}[0..n] = [A_top | B] [z_k; u_k] over k = q-1 .. samples-1.
    let cols = samples - (delays - 1);
    let mut omega = DMatrix::<f64>::zeros(nz + 1, cols);
    let mut target = DMatrix::<f64>::zeros(n, cols);
    for (j, k) in ((delays - 1)..samples).enumerate() {
        for d in 0..delays {
            omega[(d * n, j)] = xs[k - d][0];
            omega[(d * n + 1, j)] = xs[k - d][1];
        }
        omega[(nz, j)] = us[k];
        target[(0, j)] = xs[k + 1][0];
        target[(1, j)] = xs[k + 1][1];
    }
    let svd = omega.transpose().svd(true, true);
    let sol = svd
        .solve(&target.transpose(), 1e-10)
        .map_err(|e| SysidError::Model(format!("delay model fit: {e}")))?;
    let top = sol.transpose(); // n × (nz + 1)
    let mut a = DMatrix::<f64>::zeros(nz, nz);
    a.view_mut((0, 0), (n, nz))
        .copy_from(&top.view((0, 0), (n, nz)));
    for i in n..nz {
        a[(i, i - n)] = 1.0;
    }
    let mut b = DMatrix::<f64>::zeros(nz, 1);
    b.view_mut((0, 0), (n, 1))
        .copy_from(&top.view((0, nz), (n, 1)));
    Ok(LinearModel {
        method: "whitebox".into(),
        dt,
        delays,
        rank: 0,
        states: vec!["vn".into(), "swing_n".into()],
        inputs: vec!["acc_sp_n".into()],
        offset: Offset::None,
        input_mean: vec![0.0],
        a,
        b,
        c: DVector::zeros(nz),
        fingerprint: String::new(),
        diagnostics: Default::default(),
    })
}

/// [`delay_model`] for `axes` = 1 or 2 identical decoupled axes: for two
/// axes the frame is [vn, ve, swing_n, swing_e] and the inputs `acc_sp_n`, `acc_sp_e`.
pub fn pendulum_delay_model(
    model: &PendulumModel,
    dt: f64,
    delays: usize,
    axes: usize,
    seed: u64,
) -> Result<LinearModel, SysidError> {
    let one = delay_model(model, dt, delays, seed)?;
    match axes {
        1 => Ok(one),
        2 => {
            let nz = 4 * delays;
            let mut a = DMatrix::zeros(nz, nz);
            let mut b = DMatrix::zeros(nz, 2);
            // one-axis index k = 2·frame + (0: v, 1: swing) → two-axis 4·frame + 2·kind + axis
            let map = |axis: usize, k: usize| (k / 2) * 4 + (k % 2) * 2 + axis;
            for axis in 0..2 {
                for i in 0..2 * delays {
                    for j in 0..2 * delays {
                        a[(map(axis, i), map(axis, j))] = one.a[(i, j)];
                    }
                    b[(map(axis, i), axis)] = one.b[(i, 0)];
                }
            }
            Ok(LinearModel {
                states: vec!["vn".into(), "ve".into(), "swing_n".into(), "swing_e".into()],
                inputs: vec!["acc_sp_n".into(), "acc_sp_e".into()],
                input_mean: vec![0.0; 2],
                a,
                b,
                c: DVector::zeros(nz),
                ..one
            })
        }
        _ => Err(SysidError::Model(format!(
            "axes must be 1 or 2 (got {axes})"
        ))),
    }
}

/// Noise-free smooth flight like the simulator's, sampled every `dt` [s]: a *nonlinear*
/// floating pendulum (0.2 kg on 1 m under a 0.952 kg vehicle, sin/cos kept, swing friction
/// 0.05 /s) whose vehicle acceleration follows the command through a 0.1 s first-order lag,
/// a PID velocity loop tracking `vel_ref(k)` at sample k, RK4 with 10 sub-steps per sample.
/// Returns (x time-major [v, θ], u).
pub fn smooth_pendulum_flight(
    samples: usize,
    dt: f64,
    mut vel_ref: impl FnMut(usize) -> f64,
) -> (Vec<f64>, Vec<f64>) {
    let (mq, mp, l, g, fric, tau) = (0.952, 0.2, 1.0, GRAVITY, 0.05, 0.1);
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
    let mut s = [0.0; 4];
    let (mut integ, mut prev_e) = (0.0_f64, 0.0_f64);
    let (mut x, mut u) = (Vec::with_capacity(2 * samples), Vec::with_capacity(samples));
    let h = dt / 10.0;
    for k in 0..samples {
        let e = vel_ref(k) - s[0];
        integ += e * dt;
        let cmd = (1.8 * e + 0.2 * integ + 0.05 * (e - prev_e) / dt).clamp(-4.0, 4.0);
        prev_e = e;
        x.extend([s[0], s[2]]);
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

/// Seeded random velocity steps for [`smooth_pendulum_flight`]: levels uniform in [0, 3) m/s
/// held 10–25 s (table 4.1 ranges), sampled every `dt` [s].
pub fn random_velocity_steps(dt: f64, seed: u64) -> impl FnMut(usize) -> f64 {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut vref, mut next_change) = (0.0, 0usize);
    move |k| {
        if k >= next_change {
            vref = 1.5 * (rng.random_range(-1.0..1.0) + 1.0);
            next_change = k + ((17.5 + 7.5 * rng.random_range(-1.0..1.0)) / dt) as usize;
        }
        vref
    }
}
