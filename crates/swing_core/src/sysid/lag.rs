//! The attitude loop as the velocity loop sees it: the first-order lag between the
//! acceleration command and the vehicle's acceleration, identified from a flight.
//!
//! PX4 turns an acceleration setpoint into a tilt through its attitude and rate loops and the
//! motors; from the velocity loop that is, to first order, a lag τ. The white-box plant has
//! no attitude loop, so the model selection flies its candidates behind input lags: the lag
//! the flight shows is the one that matters. Per axis, the velocity's change over one sample
//! is regressed on the lagged command's mean over that sample, a constant, the velocity
//! (drag) and the swing (the cable's pull); τ is the grid point of least residual over all
//! axes. Both nuisance terms are what a point-mass vehicle on a pendulum adds to its
//! acceleration, so the lag is not asked to explain them.

use nalgebra::{Matrix4, Vector4};

use super::hankel::Trajectory;

/// Largest lag the fit looks for [s]: five times PX4's default attitude time constant.
pub const MAX_LAG: f64 = 0.5;
/// Step of the lag grid [s]: one PX4 velocity-loop tick is 20 ms, and a fifth of it is below
/// what a lag check can tell apart.
pub const LAG_STEP: f64 = 0.005;
/// Smallest share of the acceleration's variance the fit must explain for its lag to be
/// taken: below it the flight does not excite the loop enough to tell its lag.
pub const MIN_R2: f64 = 0.5;

/// A lag identified from a flight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagFit {
    /// The lag τ [s].
    pub tau: f64,
    /// Share of the acceleration's variance the fit explains (1 = all).
    pub r2: f64,
}

/// The lag between the command (input `axis` of `train`) and the acceleration of its
/// velocity (state `axis`), with the swing (state `axes + axis`) as a nuisance regressor,
/// fitted jointly over those of the `axes` axes (sampled every `dt` seconds) that were
/// excited; `None` when the flight does not tell it (too short, no axis excited, the fit
/// explains less than [`MIN_R2`], or its least residual lies at the grid's end [`MAX_LAG`]).
pub fn attitude_lag(train: &Trajectory<'_>, axes: usize, dt: f64) -> Option<LagFit> {
    let dt_ok = dt.is_finite() && dt > 0.0;
    if axes == 0 || train.m < axes || train.n < 2 * axes || train.len < 50 || !dt_ok {
        return None;
    }
    // An axis whose command never moves has no regression; the others still tell the lag.
    // The total sum of squares is the acceleration's alone, the same at every lag.
    let mut excited = Vec::with_capacity(axes);
    let mut total = 0.0;
    for ax in 0..axes {
        if let Some((_, t)) = axis_residual(train, axes, ax, 0.0, dt) {
            excited.push(ax);
            total += t;
        }
    }
    if excited.is_empty() {
        return None;
    }
    let steps = (MAX_LAG / LAG_STEP).round() as usize;
    let mut best: Option<(f64, f64)> = None;
    for i in 0..=steps {
        let tau = i as f64 * LAG_STEP;
        let mut residual = 0.0;
        for &ax in &excited {
            residual += axis_residual(train, axes, ax, tau, dt)?.0;
        }
        if best.is_none_or(|(_, r)| residual < r) {
            best = Some((tau, residual));
        }
    }
    let (tau, residual) = best?;
    let r2 = 1.0 - residual / total;
    // A least residual at the grid's last point is a bound, not a fit.
    let inside = ((tau / LAG_STEP).round() as usize) < steps;
    (total > 0.0 && r2 >= MIN_R2 && inside).then_some(LagFit { tau, r2 })
}

/// Residual and total sum of squares of one axis's regression at lag `tau`.
fn axis_residual(
    train: &Trajectory<'_>,
    axes: usize,
    ax: usize,
    tau: f64,
    dt: f64,
) -> Option<(f64, f64)> {
    // Exact for a first-order lag under a zero-order-hold command: the lag's state f moves
    // as f⁺ = αf + (1 − α)u, and its mean over the sample is u + (f − u)·τ(1 − α)/dt.
    let alpha = crate::linalg::lag_factor(tau, dt);
    let share = if tau > 0.0 {
        tau * (1.0 - alpha) / dt
    } else {
        0.0
    };
    let mut f = train.input(0)[ax];
    let mut gram = Matrix4::<f64>::zeros();
    let mut rhs = Vector4::<f64>::zeros();
    let (mut sum_y, mut sum_yy, mut count) = (0.0, 0.0, 0.0);
    for k in 0..train.len - 1 {
        let u = train.input(k)[ax];
        let (v, theta) = (train.state(k)[ax], train.state(k)[axes + ax]);
        let y = (train.state(k + 1)[ax] - v) / dt;
        let x = Vector4::new(u + (f - u) * share, 1.0, v, theta);
        gram += x * x.transpose();
        rhs += x * y;
        sum_y += y;
        sum_yy += y * y;
        count += 1.0;
        f = alpha * f + (1.0 - alpha) * u;
    }
    let coef = gram.cholesky()?.solve(&rhs);
    // ‖y − Xβ‖² = yᵀy − βᵀXᵀy at the least-squares β.
    let residual = (sum_yy - coef.dot(&rhs)).max(0.0);
    let total = sum_yy - sum_y * sum_y / count;
    (residual.is_finite() && total.is_finite()).then_some((residual, total))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A flight of `len` samples: random command steps every `hold` samples, the velocity
    /// behind an exact first-order lag `tau` with drag and a swing's pull, states [v, θ].
    fn flight(tau: f64, dt: f64, len: usize, noise: f64) -> (Vec<f64>, Vec<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (drag, pull, bias) = (0.15, -1.3, 0.05);
        let (mut x, mut u) = (Vec::new(), Vec::new());
        let (mut v, mut f, mut cmd) = (0.0f64, 0.0f64, 0.0f64);
        // Fine substeps integrate the continuous lag; the swing is an independent pendulum.
        let sub = 50;
        let h = dt / sub as f64;
        for k in 0..len {
            if k % 37 == 0 {
                cmd = rng.random_range(-3.0..3.0);
            }
            let theta = 0.1 * (1.9 * k as f64 * dt).sin();
            x.push(v + noise * rng.random_range(-1.0..1.0));
            x.push(theta);
            u.push(cmd);
            for _ in 0..sub {
                let acc = f + bias - drag * v + pull * theta;
                if tau > 0.0 {
                    f += h * (cmd - f) / tau;
                } else {
                    f = cmd;
                }
                v += h * acc;
            }
        }
        (x, u)
    }

    #[test]
    fn the_lag_of_a_first_order_loop_is_found_with_drag_and_a_swing_beside_it() {
        let dt = 0.02;
        for tau in [0.0, 0.06, 0.13, 0.21] {
            let (x, u) = flight(tau, dt, 3000, 0.0);
            let train = Trajectory::new(&x, 2, &u, 1).unwrap();
            let fit = attitude_lag(&train, 1, dt).unwrap();
            assert!((fit.tau - tau).abs() <= LAG_STEP, "τ {tau}: {fit:?}");
            assert!(fit.r2 > 0.99, "{fit:?}");
        }
    }

    #[test]
    fn measurement_noise_leaves_the_lag_within_two_grid_steps() {
        let dt = 0.02;
        let (x, u) = flight(0.15, dt, 6000, 0.002);
        let train = Trajectory::new(&x, 2, &u, 1).unwrap();
        let fit = attitude_lag(&train, 1, dt).unwrap();
        assert!((fit.tau - 0.15).abs() <= 2.0 * LAG_STEP, "{fit:?}");
    }

    #[test]
    fn an_axis_never_commanded_leaves_the_other_axis_s_lag() {
        let dt = 0.02;
        let (x1, u1) = flight(0.13, dt, 3000, 0.0);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        // States [v_n, v_e, θ_n, θ_e], inputs [u_n, u_e]; east holds still, commanded 0.
        let mut x = Vec::new();
        let mut u = Vec::new();
        for k in 0..u1.len() {
            x.extend([x1[2 * k], rng.random_range(-1e-3..1e-3), x1[2 * k + 1], 0.0]);
            u.extend([u1[k], 0.0]);
        }
        let train = Trajectory::new(&x, 4, &u, 2).unwrap();
        let fit = attitude_lag(&train, 2, dt).unwrap();
        assert!((fit.tau - 0.13).abs() <= LAG_STEP, "{fit:?}");
    }

    #[test]
    fn a_flight_that_does_not_tell_the_lag_gives_none() {
        let dt = 0.02;
        // A lag beyond the grid: the least residual lies at its end.
        let (x, u) = flight(1.5, dt, 3000, 0.0);
        let train = Trajectory::new(&x, 2, &u, 1).unwrap();
        assert_eq!(attitude_lag(&train, 1, dt), None);
        // A constant command: no excitation, only noise to explain.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x: Vec<f64> = (0..1000)
            .flat_map(|_| [rng.random_range(-0.01..0.01), 0.0])
            .collect();
        let u = vec![1.0; 1000];
        let train = Trajectory::new(&x, 2, &u, 1).unwrap();
        assert_eq!(attitude_lag(&train, 1, dt), None);
        // Too short a flight.
        let (x, u) = flight(0.1, dt, 20, 0.0);
        let train = Trajectory::new(&x, 2, &u, 1).unwrap();
        assert_eq!(attitude_lag(&train, 1, dt), None);
    }
}
