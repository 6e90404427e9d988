//! PX4's in-flight hover-thrust estimator (`mc_hover_thrust_estimator`, on by `MPC_USE_HTE`).
//!
//! One state, the normalised collective thrust that holds the vehicle's weight, driven by
//! noise alone. Each position-loop tick it reads the vertical acceleration a the vehicle had
//! and the vertical thrust T that was commanded, and fuses a = g·T/Th − g (an extended
//! Kalman filter: H = −g·T/Th²). The acceleration noise is learnt from the residuals
//! (Akhlaghi et al. 2017), measurements beyond a 3σ gate are refused, and a long run of
//! refusals on one side re-opens the state's variance. The estimate counts as valid once
//! its variance stays below 0.001 for 2 s; then the position controller adopts it
//! ([`crate::control::px4::Px4Cascade`] moves its vertical integrator so the thrust does not
//! jump).
//!
//! Why the cascade needs it: PX4's horizontal tracking anti-windup compares the acceleration
//! asked for with the one the thrust vector produces, g/Th times its horizontal part. With a
//! hover thrust that is off by a fraction ε the two differ by ε·a even when nothing
//! saturates, and the velocity integrator then settles at an error of (2/K_p)·a·ε. PX4 keeps
//! ε near zero by estimating Th in flight; a fixed Th leaves that error standing.

use crate::plant::params::GRAVITY;

/// Process noise of the hover thrust (HTE_HT_NOISE) [normalised/s].
const PROCESS_NOISE: f64 = 0.0036;
/// Gate of the innovation test (HTE_ACC_GATE) [standard deviations].
const GATE: f64 = 3.0;
/// Initial 1-σ uncertainty of the hover thrust (HTE_HT_ERR_INIT) [normalised].
const INITIAL_STD: f64 = 0.1;
/// Horizontal speed above which measurements are trusted less (HTE_VXY_THR) [m/s].
const SPEED_XY_THRESHOLD: f64 = 10.0;
/// Vertical speed above which measurements are trusted less (HTE_VZ_THR) [m/s].
const SPEED_Z_THRESHOLD: f64 = 2.0;
/// Largest departure from the configured hover thrust (HTE_THR_RANGE) [normalised].
const RANGE: f64 = 0.2;
/// Acceleration noise variance at start [(m/s²)²].
const INITIAL_ACC_VAR: f64 = 5.0;
/// Bounds of the learnt acceleration noise variance [(m/s²)²].
const ACC_VAR_BOUNDS: (f64, f64) = (1.0, 400.0);
/// Time constant of the noise learning [s].
const NOISE_LEARNING_TAU: f64 = 2.0;
/// Time constant of the residual and signed test-ratio low-passes [s].
const LPF_TAU: f64 = 1.0;
/// Variance below which the estimate is usable [normalised²].
const VALID_VAR: f64 = 0.001;
/// How long the estimate must be usable before it is adopted [s].
const VALID_HOLD: f64 = 2.0;

/// State of PX4's hover-thrust estimator between position-loop ticks.
#[derive(Clone, Debug)]
pub struct HoverThrustEstimator {
    hover: f64,
    var: f64,
    acc_var: f64,
    residual_lpf: f64,
    signed_ratio_lpf: f64,
    bounds: (f64, f64),
    valid: bool,
    usable_for: f64,
}

impl HoverThrustEstimator {
    /// An estimator starting, as PX4's does on arming, at the configured hover thrust
    /// (MPC_THR_HOVER) with its initial uncertainty.
    pub fn new(configured: f64) -> Self {
        let bounds = (
            (configured - RANGE).clamp(0.0, 0.8),
            (configured + RANGE).clamp(0.2, 0.9),
        );
        Self {
            hover: configured.clamp(0.1, 0.9),
            var: INITIAL_STD * INITIAL_STD,
            acc_var: INITIAL_ACC_VAR,
            residual_lpf: 0.0,
            signed_ratio_lpf: 0.0,
            bounds,
            valid: false,
            usable_for: 0.0,
        }
    }

    /// The current estimate [normalised].
    pub fn estimate(&self) -> f64 {
        self.hover
    }

    /// Its variance [normalised²].
    pub fn variance(&self) -> f64 {
        self.var
    }

    /// Fuse one tick of `dt` [s]: the vertical acceleration `acc_up` [m/s², up positive]
    /// produced by the vertical thrust `thrust_up` [normalised, up positive], at horizontal
    /// and vertical speeds `speed_xy`, `speed_z` [m/s]. Returns the estimate once it is valid.
    pub fn update(
        &mut self,
        dt: f64,
        acc_up: f64,
        thrust_up: f64,
        speed_xy: f64,
        speed_z: f64,
    ) -> Option<f64> {
        if !(dt > 0.0 && acc_up.is_finite() && thrust_up.is_finite()) {
            return self.valid.then_some(self.hover);
        }
        self.var += PROCESS_NOISE * PROCESS_NOISE * dt * dt;
        // Fast climbs and descents and fast forward flight bias the measurement (drag, prop
        // wash): trust it less beyond the thresholds.
        let scale = ((speed_z.abs() - SPEED_Z_THRESHOLD) + 1.0)
            .max((speed_xy - SPEED_XY_THRESHOLD) + 1.0)
            .max(1.0);
        let predicted = |hover: f64| GRAVITY * thrust_up / hover - GRAVITY;
        let h = -GRAVITY * thrust_up / (self.hover * self.hover);
        let r = self.acc_var * scale * scale;
        let innov_var = (h * self.var * h + r).max(r);
        let innov = acc_up - predicted(self.hover);
        let ratio = innov * innov / (GATE * GATE * innov_var);
        let mut residual = innov;
        if ratio < 1.0 {
            let k = self.var * h / innov_var;
            self.hover = (self.hover + k * innov).clamp(self.bounds.0, self.bounds.1);
            self.var = ((1.0 - k * h) * self.var).clamp(1e-10, 1.0);
            residual = acc_up - predicted(self.hover);
        } else if self.signed_ratio_lpf.abs() > 0.2 {
            // Refused for a while on one side: the hover thrust moved, open the variance.
            self.var += 1e3 * PROCESS_NOISE * PROCESS_NOISE * dt;
        }
        let alpha = dt / (LPF_TAU + dt);
        self.residual_lpf += alpha * (residual - self.residual_lpf);
        let signed_ratio = (innov.signum() * ratio).clamp(-1.0, 1.0);
        self.signed_ratio_lpf += alpha * (signed_ratio - self.signed_ratio_lpf);
        let beta = dt / (NOISE_LEARNING_TAU + dt);
        let unbiased = residual - self.residual_lpf;
        self.acc_var = ((1.0 - beta) * self.acc_var
            + beta * (unbiased * unbiased + h * self.var * h))
            .clamp(ACC_VAR_BOUNDS.0, ACC_VAR_BOUNDS.1);

        let usable = self.var < VALID_VAR && (self.valid || ratio < 1.0);
        self.usable_for = if usable { self.usable_for + dt } else { 0.0 };
        self.valid = usable && (self.valid || self.usable_for >= VALID_HOLD);
        self.valid.then_some(self.hover)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vehicle whose true hover thrust is `truth`, held level by a thrust that follows the
    /// estimate (as PX4's loop does), with the acceleration it then has.
    fn fly(est: &mut HoverThrustEstimator, truth: f64, seconds: f64) -> Option<f64> {
        let dt = 0.02;
        let mut out = None;
        for _ in 0..(seconds / dt) as usize {
            let thrust = est.estimate();
            let acc = GRAVITY * thrust / truth - GRAVITY;
            out = est.update(dt, acc, thrust, 0.0, 0.0);
        }
        out
    }

    #[test]
    fn the_estimate_converges_to_the_true_hover_thrust_and_becomes_valid() {
        let mut est = HoverThrustEstimator::new(0.5);
        assert_eq!(
            est.update(0.02, 0.0, 0.5, 0.0, 0.0),
            None,
            "not valid at once"
        );
        let got = fly(&mut est, 0.56, 20.0).expect("valid after 20 s");
        assert!((got - 0.56).abs() < 2e-3, "estimate {got}");
        assert!(est.variance() < VALID_VAR);
    }

    #[test]
    fn the_estimate_stays_within_its_range_of_the_configured_value() {
        let mut est = HoverThrustEstimator::new(0.4);
        fly(&mut est, 0.75, 60.0);
        assert!((est.estimate() - 0.6).abs() < 1e-12, "{}", est.estimate());
    }

    #[test]
    fn a_correct_hover_thrust_is_kept() {
        let mut est = HoverThrustEstimator::new(0.45);
        let got = fly(&mut est, 0.45, 10.0).expect("valid");
        assert!((got - 0.45).abs() < 1e-9);
    }

    #[test]
    fn bad_numbers_change_nothing() {
        let mut est = HoverThrustEstimator::new(0.45);
        fly(&mut est, 0.45, 10.0);
        let before = (est.estimate(), est.variance());
        assert_eq!(est.update(0.02, f64::NAN, 0.45, 0.0, 0.0), Some(0.45));
        assert_eq!(est.update(0.0, 1.0, 0.45, 0.0, 0.0), Some(0.45));
        assert_eq!((est.estimate(), est.variance()), before);
    }
}
