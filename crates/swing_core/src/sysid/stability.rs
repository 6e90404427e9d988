//! The search's stability screen, with the velocity integrator deflated.
//!
//! The plant integrates the commanded acceleration into velocity: its linearisation has an
//! eigenvalue at exactly 1 whose mode is a constant velocity with the cable hanging straight
//! (right eigenvector ∝ [v = 1, swing = 0] in every delay block). An identified model places
//! that eigenvalue at 1 + ε with ε of either sign, a fit error of the order of the noise,
//! and a plain bound ρ(A) ≤ 1 + tol then rejects a good model for a tiny ε > tol.
//!
//! The screen therefore judges two things separately:
//!
//! * the **integrator**: the real eigenvalue λ* nearest 1, if its mode is velocity (the
//!   newest block of its right eigenvector, each state scaled by the standard deviation of its
//!   data column, has at least half of its energy in velocity states) and |λ* − 1| ≤
//!   `integrator_tolerance`. Its open-loop drift is at most (1 + ε)^H over a rollout of H
//!   steps, which the held-out rollout NMAE has already scored, and the MPC's disturbance
//!   estimate absorbs it in closed loop;
//! * **every other eigenvalue** (the spectrum with λ* deflated, i.e. removed once):
//!   |λ| ≤ 1 + `tolerance`.
//!
//! A model with ρ(A) ≤ 1 + `tolerance` passes without the eigenvector (the common case).

use nalgebra::DMatrix;
use serde_json::{json, Value};

use super::error::{model, SysidError};

/// What the screen demands, in words (written into a model's diagnostics).
pub const CRITERION: &str = "every eigenvalue |λ| ≤ 1 + tolerance, except the velocity \
integrator: the real eigenvalue nearest 1 whose eigenvector (newest block, states scaled by \
their data std) has ≥ 50 % of its energy in velocity states may lie within 1 ± \
integrator_tolerance";

/// Settings of the screen.
#[derive(Clone, Debug, PartialEq)]
pub struct Screen {
    /// Bound on |λ| − 1 of every eigenvalue but the integrator's.
    pub tolerance: f64,
    /// Bound on |λ* − 1| of the velocity integrator's eigenvalue.
    pub integrator_tolerance: f64,
    /// Number of states n of one delay block.
    pub states: usize,
    /// Indices (within a block) of the velocity states.
    pub velocity: Vec<usize>,
    /// Scale of each state (its data standard deviation; 1 = unscaled).
    pub scale: Vec<f64>,
}

/// The screen's verdict on one `A`.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    /// Whether the model counts as stable.
    pub stable: bool,
    /// Spectral radius of `A`.
    pub spectral_radius: f64,
    /// The velocity integrator's eigenvalue, when it was identified and deflated.
    pub integrator: Option<f64>,
    /// Spectral radius with the integrator deflated (= `spectral_radius` without one).
    pub deflated_radius: f64,
    /// The screen's `tolerance`.
    pub tolerance: f64,
    /// The screen's `integrator_tolerance`.
    pub integrator_tolerance: f64,
}

impl Verdict {
    /// The verdict as a diagnostics object.
    pub fn to_json(&self) -> Value {
        json!({
            "criterion": CRITERION,
            "tolerance": self.tolerance,
            "integrator_tolerance": self.integrator_tolerance,
            "spectral_radius": self.spectral_radius,
            "integrator_eigenvalue": self.integrator,
            "deflated_radius": self.deflated_radius,
            "stable": self.stable,
        })
    }
}

impl Screen {
    /// Judge `a` (order n·q, delay blocks newest first).
    pub fn judge(&self, a: &DMatrix<f64>) -> Result<Verdict, SysidError> {
        let k = a.nrows();
        if k == 0 {
            return Ok(Verdict {
                stable: true,
                spectral_radius: 0.0,
                integrator: None,
                deflated_radius: 0.0,
                tolerance: self.tolerance,
                integrator_tolerance: self.integrator_tolerance,
            });
        }
        let fa = faer::Mat::<f64>::from_fn(k, k, |i, j| a[(i, j)]);
        let ev = fa
            .eigenvalues()
            .map_err(|e| model(format!("eigenvalues did not converge: {e:?}")))?;
        let abs: Vec<f64> = ev.iter().map(|z| z.re.hypot(z.im)).collect();
        let rho = abs.iter().copied().fold(0.0_f64, f64::max);
        let plain = Verdict {
            stable: rho <= 1.0 + self.tolerance,
            spectral_radius: rho,
            integrator: None,
            deflated_radius: rho,
            tolerance: self.tolerance,
            integrator_tolerance: self.integrator_tolerance,
        };
        if plain.stable || self.velocity.is_empty() {
            return Ok(plain);
        }
        // The real eigenvalue nearest 1 (complex pairs are oscillations, not the integrator).
        let Some((i_star, lambda)) = ev
            .iter()
            .enumerate()
            .filter(|(_, z)| z.im.abs() <= 1e-9 * (1.0 + z.re.abs()))
            .map(|(i, z)| (i, z.re))
            .min_by(|a, b| (a.1 - 1.0).abs().total_cmp(&(b.1 - 1.0).abs()))
        else {
            return Ok(plain);
        };
        if (lambda - 1.0).abs() > self.integrator_tolerance {
            return Ok(plain);
        }
        if self.velocity_share(a, lambda) < 0.5 {
            return Ok(plain);
        }
        let deflated = abs
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != i_star)
            .map(|(_, v)| *v)
            .fold(0.0_f64, f64::max);
        Ok(Verdict {
            stable: deflated <= 1.0 + self.tolerance,
            spectral_radius: rho,
            integrator: Some(lambda),
            deflated_radius: deflated,
            ..plain
        })
    }

    /// Share of the scaled energy of the newest block of the right eigenvector of `lambda`
    /// (the null vector of A − λI, the last right singular vector) in velocity states.
    fn velocity_share(&self, a: &DMatrix<f64>, lambda: f64) -> f64 {
        let k = a.nrows();
        let shifted = a - DMatrix::<f64>::identity(k, k) * lambda;
        let svd = shifted.svd(false, true);
        let Some(vt) = svd.v_t else {
            return 0.0;
        };
        let last = svd
            .singular_values
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, _)| i)
            .unwrap_or(k - 1);
        let n = self.states.min(k);
        let energy = |j: usize| {
            let s = self.scale.get(j).copied().unwrap_or(1.0);
            let s = if s > 0.0 && s.is_finite() { s } else { 1.0 };
            (vt[(last, j)] / s).powi(2)
        };
        let total: f64 = (0..n).map(energy).sum();
        if total <= 0.0 || !total.is_finite() {
            return 0.0;
        }
        self.velocity
            .iter()
            .filter(|j| **j < n)
            .map(|j| energy(*j))
            .sum::<f64>()
            / total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn screen(states: usize) -> Screen {
        Screen {
            tolerance: 1e-3,
            integrator_tolerance: 1e-2,
            states,
            velocity: vec![0],
            scale: vec![1.0; states],
        }
    }

    /// A velocity integrator at 1 + 4e-3 coupled into a damped swing: with states [v, θ],
    /// A = [[1 + ε, b], [0, ρ]], eigenvalues 1 + ε (eigenvector e₁, pure velocity) and ρ.
    #[test]
    fn a_slightly_unstable_velocity_integrator_is_deflated() {
        let eps = 4e-3;
        let a = DMatrix::from_row_slice(2, 2, &[1.0 + eps, 0.3, 0.0, 0.95]);
        let v = screen(2).judge(&a).unwrap();
        assert!(v.stable, "{v:?}");
        assert!((v.spectral_radius - (1.0 + eps)).abs() < 1e-12);
        assert!((v.integrator.unwrap() - (1.0 + eps)).abs() < 1e-12);
        assert!((v.deflated_radius - 0.95).abs() < 1e-12);
        // Beyond the integrator tolerance it is rejected.
        let a = DMatrix::from_row_slice(2, 2, &[1.02, 0.3, 0.0, 0.95]);
        assert!(!screen(2).judge(&a).unwrap().stable);
    }

    /// The same eigenvalue on the swing (eigenvector e₂ of [[0.95, 0], [0.3, 1 + ε]]) is a
    /// growing swing, not the integrator: rejected.
    #[test]
    fn an_unstable_swing_mode_is_not_the_integrator() {
        let a = DMatrix::from_row_slice(2, 2, &[0.95, 0.0, 0.3, 1.004]);
        let v = screen(2).judge(&a).unwrap();
        assert!(!v.stable, "{v:?}");
        assert_eq!(v.integrator, None);
    }

    /// Deflation removes the integrator once: a second unstable eigenvalue still fails, and a
    /// model inside 1 + tolerance passes without any eigenvector.
    #[test]
    fn deflation_removes_one_eigenvalue_only() {
        let a = DMatrix::from_row_slice(2, 2, &[1.003, 0.0, 0.0, 1.004]);
        let v = screen(2).judge(&a).unwrap();
        assert!(!v.stable, "{v:?}");
        assert_eq!(v.integrator, Some(1.003));
        assert!((v.deflated_radius - 1.004).abs() < 1e-12);
        let a = DMatrix::from_row_slice(2, 2, &[1.0005, 0.0, 0.0, 0.5]);
        let v = screen(2).judge(&a).unwrap();
        assert!(v.stable && v.integrator.is_none(), "{v:?}");
    }

    /// In delay coordinates (q = 2, blocks [v_k, θ_k, v_{k−1}, θ_{k−1}]) the integrator's
    /// eigenvector repeats its block scaled by 1/λ; only the newest block is judged.
    #[test]
    fn the_integrator_is_found_in_delay_coordinates() {
        let eps = 3e-3;
        #[rustfmt::skip]
        let a = DMatrix::from_row_slice(4, 4, &[
            1.0 + eps, 0.2, 0.0, 0.0,
            0.0, 1.6, 0.0, -0.8,
            1.0, 0.0, 0.0, 0.0,
            0.0, 1.0, 0.0, 0.0,
        ]);
        let v = screen(2).judge(&a).unwrap();
        assert!(v.stable, "{v:?}");
        assert!((v.integrator.unwrap() - (1.0 + eps)).abs() < 1e-9);
        // The swing's pair: roots of λ² − 1.6λ + 0.8, |λ| = √0.8.
        assert!((v.deflated_radius - 0.8_f64.sqrt()).abs() < 1e-9, "{v:?}");
    }
}
