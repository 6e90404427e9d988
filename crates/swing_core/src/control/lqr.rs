//! The baseline LQR swing-damping controller (thesis 5.3); the Riccati solvers it uses
//! live in [`crate::linalg::riccati`].
//!
//! # Baseline LQR (eq. 5.12–5.20)
//! Longitudinal pendulum model ([`PendulumModel`], eq. 5.7) with integral state x_A = [∫(v_sp − v), v, θ, θ̇]:
//! ```text
//!        ⎡0  −1      0                    0              ⎤        ⎡ 0  ⎤
//! A_A =  ⎢0   0   m_p g/m_Q               c/(l m_Q)       ⎥  B_A = ⎢ 1  ⎥
//!        ⎢0   0      0                    1              ⎥        ⎢ 0  ⎥
//!        ⎣0   0  −g(m_Q+m_p)/(m_Q l)  −c(m_Q+m_p)/(l² m_Q m_p)⎦        ⎣−1/l⎦
//! ```
//! with the stable-pendulum sign in row 4 (the thesis's eq. 5.16 prints "+"; docs/architecture.md, "The reference"),
//! Q = diag(0.1, 10, 0, 100), R = 13 and the law u = K(x_sp − x), x_sp = [0, v_sp, 0, 0]
//! (eq. 5.18). The thesis designs with the continuous gain; this controller runs at the
//! 50 Hz velocity-loop rate, so it uses the **exact sampled-data LQR** instead: the model
//! and the continuous cost (5.19) are discretised together over one zero-order-hold period
//! (Van Loan 1978), giving A_d, B_d and weights Q_d, R_d, N_d that make the discrete cost
//! equal the continuous one for piecewise-constant inputs; the DARE with cross term then
//! gives the gain that is optimal for the controller actually run at that rate. It
//! converges to the CARE gain as the period → 0 (a test checks this).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::{AxisState, ControlError, SwingController, TickInfo, TickKind};
use crate::config::{non_negative, positive, ConfigError};
use crate::linalg::{sampled_lqr, RiccatiSolution};
use crate::plant::linear::PendulumModel;

/// Settings of the baseline LQR (eq. 5.20); serde with unknown keys refused.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LqrSettings {
    /// State weights on [∫(v_sp − v) [m], v [m/s], θ [rad], θ̇ [rad/s]] (eq. 5.20: 0.1, 10, 0, 100).
    pub q: [f64; 4],
    /// Input weight on the acceleration setpoint [1/(m/s²)²] (eq. 5.20: 13).
    pub r: f64,
    /// Controller period [s] (PX4's velocity loop: 0.02 s = 50 Hz).
    pub period: f64,
    /// Optional bound on |acceleration setpoint| [m/s²]; the integrator stops while saturated.
    pub acc_max: Option<f64>,
}

impl Default for LqrSettings {
    fn default() -> Self {
        Self {
            q: [0.1, 10.0, 0.0, 100.0],
            r: 13.0,
            period: 0.02,
            acc_max: None,
        }
    }
}

impl LqrSettings {
    /// Check weights are non-negative, R and the period positive.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (i, w) in self.q.iter().enumerate() {
            non_negative(&format!("q[{i}]"), *w)?;
        }
        positive("r", self.r)?;
        positive("period", self.period)?;
        if let Some(a) = self.acc_max {
            positive("acc_max", a)?;
        }
        Ok(())
    }
}

/// The baseline LQR (eq. 5.12–5.20) on one or two axes (the same law on North and East).
#[derive(Clone, Debug)]
pub struct LqrController {
    params: PendulumModel,
    settings: LqrSettings,
    axes: usize,
    /// Gain on x_A = [ι, v, θ, θ̇] (u = −K x_A + K₂ v_sp).
    k: [f64; 4],
    /// Integral states ι = ∫(v_sp − v) dt per axis [m].
    integral: [f64; 2],
    /// The Riccati solution behind `k`.
    solution: RiccatiSolution,
}

impl LqrController {
    /// Synthesise the sampled-data LQR for `params` on `axes` (1 or 2) axes.
    pub fn new(
        params: PendulumModel,
        axes: usize,
        settings: LqrSettings,
    ) -> Result<Self, ControlError> {
        params.validate()?;
        settings.validate()?;
        if !(1..=2).contains(&axes) {
            return Err(ConfigError::new("axes", format!("must be 1 or 2 (got {axes})")).into());
        }
        let (a, b) = params.integral_model();
        let q = DMatrix::from_diagonal(&DVector::from_column_slice(&settings.q));
        let r = DMatrix::from_element(1, 1, settings.r);
        let (solution, _, _) = sampled_lqr(&a, &b, &q, &r, settings.period)?;
        let k = [
            solution.k[(0, 0)],
            solution.k[(0, 1)],
            solution.k[(0, 2)],
            solution.k[(0, 3)],
        ];
        Ok(Self {
            params,
            settings,
            axes,
            k,
            integral: [0.0; 2],
            solution,
        })
    }

    /// Gain K on [∫(v_sp − v), v, θ, θ̇] (the law is u = K(x_sp − x), eq. 5.18).
    pub fn gain(&self) -> [f64; 4] {
        self.k
    }

    /// The Riccati solution (K, P, residual) behind the gain.
    pub fn riccati(&self) -> &RiccatiSolution {
        &self.solution
    }

    /// The model parameters the gain was designed for.
    pub fn params(&self) -> PendulumModel {
        self.params
    }
}

impl SwingController for LqrController {
    fn axes(&self) -> usize {
        self.axes
    }

    fn period(&self) -> f64 {
        self.settings.period
    }

    fn reset(&mut self, state: &[AxisState], acc: &[f64]) {
        // Bumpless: choose ι so that the law returns `acc` with v_sp = v.
        for i in 0..self.axes {
            let s = state.get(i).copied().unwrap_or_default();
            let a = acc.get(i).copied().unwrap_or(0.0);
            self.integral[i] = if self.k[0].abs() > 1e-12 && a.is_finite() {
                -(a + self.k[2] * s.swing + self.k[3] * s.swing_rate) / self.k[0]
            } else {
                0.0
            };
            if !self.integral[i].is_finite() {
                self.integral[i] = 0.0;
            }
        }
    }

    fn step(
        &mut self,
        state: &[AxisState],
        vel_ref: &[f64],
        acc_out: &mut [f64],
    ) -> Result<TickInfo, ControlError> {
        super::check_tick_inputs(self.axes, state, vel_ref, acc_out)?;
        let k = self.k;
        for i in 0..self.axes {
            let s = state[i];
            let err = vel_ref[i] - s.v;
            let u = -k[0] * self.integral[i] + k[1] * err - k[2] * s.swing - k[3] * s.swing_rate;
            let (u, saturated) = match self.settings.acc_max {
                Some(lim) if u.abs() > lim => (u.clamp(-lim, lim), true),
                _ => (u, false),
            };
            // Conditional integration (anti-windup): hold ι while the output saturates in
            // the direction the error would push it further.
            if !(saturated && (u * err) > 0.0) {
                self.integral[i] += self.settings.period * err;
            }
            acc_out[i] = u;
        }
        Ok(TickInfo {
            kind: TickKind::Unconstrained,
            iterations: 0,
        })
    }
}
