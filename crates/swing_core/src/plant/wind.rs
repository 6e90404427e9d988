//! Wind: a constant base, scheduled steps, "1 − cos" gusts and seeded turbulence.
//!
//! Turbulence is a first-order Gauss–Markov process per axis (a Dryden-like low-pass of white
//! noise) with standard deviation σ and correlation time T_c, advanced once per physics step:
//! w ← w·e^{−h/T_c} + σ·sqrt(1 − e^{−2h/T_c})·N(0, 1).

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::config::{all_finite, non_negative, positive, ConfigError};

/// A step change of the base wind at time `t`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindStep {
    /// Time of the step [s].
    pub t: f64,
    /// New base wind velocity, NED [m/s].
    pub velocity: [f64; 3],
}

/// A "1 − cos" gust added on top of the base wind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gust {
    /// Start time [s].
    pub t: f64,
    /// Duration [s].
    pub duration: f64,
    /// Peak gust velocity, NED [m/s].
    pub amplitude: [f64; 3],
}

/// Wind settings (none by default).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WindParams {
    /// Base wind velocity from t = 0, NED [m/s] (the air moves this way).
    pub velocity: [f64; 3],
    /// Scheduled steps of the base wind.
    pub steps: Vec<WindStep>,
    /// Discrete gusts.
    pub gusts: Vec<Gust>,
    /// Turbulence standard deviation per axis [m/s] (0 = off).
    pub turbulence: f64,
    /// Turbulence correlation time [s].
    pub turbulence_time: f64,
}

impl WindParams {
    /// Check the settings; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        all_finite("velocity", &self.velocity)?;
        for (i, s) in self.steps.iter().enumerate() {
            non_negative(&format!("steps[{i}].t"), s.t)?;
            all_finite(&format!("steps[{i}].velocity"), &s.velocity)?;
        }
        for (i, g) in self.gusts.iter().enumerate() {
            non_negative(&format!("gusts[{i}].t"), g.t)?;
            positive(&format!("gusts[{i}].duration"), g.duration)?;
            all_finite(&format!("gusts[{i}].amplitude"), &g.amplitude)?;
        }
        non_negative("turbulence", self.turbulence)?;
        if self.turbulence > 0.0 {
            positive("turbulence_time", self.turbulence_time)?;
        }
        Ok(())
    }
}

/// The wind field in time, with its own seeded turbulence state.
#[derive(Clone, Debug)]
pub struct Wind {
    p: WindParams,
    turb: Vector3<f64>,
    rng: ChaCha8Rng,
}

impl Wind {
    /// Wind from validated settings; `seed` drives the turbulence.
    pub fn new(mut p: WindParams, seed: u64) -> Self {
        p.steps
            .sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
        Self {
            p,
            turb: Vector3::zeros(),
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5749_4e44),
        }
    }

    /// Advance the turbulence by `h` seconds.
    pub fn advance(&mut self, h: f64) {
        if self.p.turbulence <= 0.0 {
            return;
        }
        let phi = (-h / self.p.turbulence_time).exp();
        let s = self.p.turbulence * (1.0 - phi * phi).sqrt();
        for i in 0..3 {
            let z: f64 = StandardNormal.sample(&mut self.rng);
            self.turb[i] = self.turb[i] * phi + s * z;
        }
    }

    /// Wind velocity at time `t`, NED [m/s].
    pub fn at(&self, t: f64) -> Vector3<f64> {
        if self.p.steps.is_empty() && self.p.gusts.is_empty() {
            return Vector3::from(self.p.velocity) + self.turb;
        }
        let mut w = Vector3::from(self.p.velocity);
        for s in &self.p.steps {
            if t >= s.t {
                w = Vector3::from(s.velocity);
            }
        }
        for g in &self.p.gusts {
            if t >= g.t && t <= g.t + g.duration {
                let k = 0.5 * (1.0 - (2.0 * std::f64::consts::PI * (t - g.t) / g.duration).cos());
                w += Vector3::from(g.amplitude) * k;
            }
        }
        w + self.turb
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_and_gusts_follow_the_schedule() {
        let p = WindParams {
            velocity: [1.0, 0.0, 0.0],
            steps: vec![WindStep {
                t: 8.0,
                velocity: [2.0, 0.0, 0.0],
            }],
            gusts: vec![Gust {
                t: 10.0,
                duration: 2.0,
                amplitude: [0.0, 3.0, 0.0],
            }],
            ..Default::default()
        };
        let w = Wind::new(p, 0);
        assert_eq!(w.at(7.99).x, 1.0);
        assert_eq!(w.at(8.0).x, 2.0);
        assert!((w.at(11.0).y - 3.0).abs() < 1e-12);
        assert_eq!(w.at(12.5).y, 0.0);
    }

    #[test]
    fn turbulence_is_seeded_and_has_the_set_spread() {
        let p = WindParams {
            turbulence: 0.5,
            turbulence_time: 0.5,
            ..Default::default()
        };
        let mut a = Wind::new(p.clone(), 7);
        let mut b = Wind::new(p, 7);
        let mut sum2 = 0.0;
        let n = 200_000;
        for _ in 0..n {
            a.advance(0.01);
            b.advance(0.01);
            sum2 += a.at(0.0).x.powi(2);
        }
        assert_eq!(a.at(0.0), b.at(0.0));
        let std = (sum2 / n as f64).sqrt();
        assert!((std - 0.5).abs() < 0.05, "std {std}");
    }
}
