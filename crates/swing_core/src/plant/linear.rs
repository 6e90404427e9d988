//! The linearised floating pendulum (thesis eq. 5.7–5.8): one horizontal axis of vehicle +
//! suspended payload, the model behind the baseline LQR and the white-box identification.
//!
//! State s = [v, θ, θ̇] (velocity [m/s], swing angle [rad], swing rate [rad/s]), input
//! u = acceleration setpoint [m/s²], with the *stable* sign of the swing stiffness (eq. 4.6
//! and 5.16 of the thesis print the other; docs/architecture.md, "The reference"):
//! ```text
//!   v̇ = (g m_p/m_Q) θ + (c/(l m_Q)) θ̇ + u
//!   θ̈ = −(g (m_Q+m_p)/(m_Q l)) θ − (c (m_Q+m_p)/(l² m_Q m_p)) θ̇ − u/l
//! ```
//! with g = [`GRAVITY`]. The discrete model is the zero-order hold
//! [A_d B_d; 0 I] = exp([A B; 0 0]·dt) ([`crate::linalg::c2d_zoh`]).

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::params::GRAVITY;
use crate::config::{non_negative, positive, ConfigError};
use crate::linalg::c2d_zoh;

/// Physical parameters of the longitudinal vehicle + payload model (eq. 5.7).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PendulumModel {
    /// Vehicle mass m_Q [kg].
    pub m_q: f64,
    /// Payload mass m_p [kg].
    pub m_p: f64,
    /// Cable length l [m].
    pub l: f64,
    /// Joint friction coefficient c [N m s/rad].
    pub c: f64,
}

impl Default for PendulumModel {
    fn default() -> Self {
        Self {
            m_q: 0.952,
            m_p: 0.2,
            l: 1.0,
            c: 0.0,
        }
    }
}

impl PendulumModel {
    /// Check every parameter is physical; the error names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("m_q", self.m_q)?;
        positive("m_p", self.m_p)?;
        positive("l", self.l)?;
        non_negative("c", self.c)?;
        Ok(())
    }

    /// Continuous (A, B) over [v, θ, θ̇] with input a (eq. 5.7 with the stable sign, 5.8).
    pub fn continuous(&self) -> (DMatrix<f64>, DMatrix<f64>) {
        let (mq, mp, l, c, g) = (self.m_q, self.m_p, self.l, self.c, GRAVITY);
        #[rustfmt::skip]
        let a = DMatrix::from_row_slice(3, 3, &[
            0.0, mp * g / mq, c / (l * mq),
            0.0, 0.0, 1.0,
            0.0, -g * (mq + mp) / (mq * l), -c * (mq + mp) / (l * l * mq * mp),
        ]);
        let b = DMatrix::from_row_slice(3, 1, &[1.0, 0.0, -1.0 / l]);
        (a, b)
    }

    /// Zero-order-hold discretisation of [`Self::continuous`] at `dt` [s].
    pub fn discrete(&self, dt: f64) -> (DMatrix<f64>, DMatrix<f64>) {
        let (a, b) = self.continuous();
        c2d_zoh(&a, &b, dt)
    }

    /// Augmented model over x_A = [∫(v_sp − v), v, θ, θ̇] (eq. 5.13–5.17, stable sign).
    pub fn integral_model(&self) -> (DMatrix<f64>, DMatrix<f64>) {
        let (a3, b3) = self.continuous();
        let mut a = DMatrix::<f64>::zeros(4, 4);
        a[(0, 1)] = -1.0;
        a.view_mut((1, 1), (3, 3)).copy_from(&a3);
        let mut b = DMatrix::<f64>::zeros(4, 1);
        b.view_mut((1, 0), (3, 1)).copy_from(&b3);
        (a, b)
    }

    /// Undamped swing frequency ω_n = √(g/l · (m_Q+m_p)/m_Q) [rad/s] (eq. 4.8).
    pub fn swing_frequency(&self) -> f64 {
        (GRAVITY / self.l * (self.m_q + self.m_p) / self.m_q).sqrt()
    }
}
