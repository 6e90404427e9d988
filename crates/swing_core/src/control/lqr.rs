//! The baseline LQR swing-damping controller (thesis 5.3); the Riccati solvers it uses
//! live in [`super::riccati`].
//!
//! # Baseline LQR (eq. 5.12–5.20)
//! Longitudinal white-box model with integral state x_A = [∫(v_sp − v), v, θ, θ̇]:
//! ```text
//!        ⎡0  −1      0                    0              ⎤        ⎡ 0  ⎤
//! A_A =  ⎢0   0   m_p g/m_Q               c/(l m_Q)       ⎥  B_A = ⎢ 1  ⎥
//!        ⎢0   0      0                    1              ⎥        ⎢ 0  ⎥
//!        ⎣0   0  −g(m_Q+m_p)/(m_Q l)  −c(m_Q+m_p)/(l² m_Q m_p)⎦        ⎣−1/l⎦
//! ```
//! with the stable-pendulum sign in row 4 (the seed's eq. 5.16 prints "+"; DESIGN §3),
//! Q = diag(0.1, 10, 0, 100), R = 13 and the law u = K(x_sp − x), x_sp = [0, v_sp, 0, 0]
//! (eq. 5.18). The seed designs with the continuous gain; this controller runs at the
//! 50 Hz velocity-loop rate, so it uses the **exact sampled-data LQR** instead: the model
//! and the continuous cost (5.19) are discretised together over one zero-order-hold period
//! (Van Loan 1978), giving A_d, B_d and weights Q_d, R_d, N_d that make the discrete cost
//! equal the continuous one for piecewise-constant inputs; the DARE with cross term then
//! gives the gain that is optimal for the controller actually run at that rate. It
//! converges to the CARE gain as the period → 0 (a test checks this).

use nalgebra::{DMatrix, DVector};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::riccati::{c2d_zoh, sampled_lqr, RiccatiSolution};
use super::{AxisState, ControlError, SwingController, TickInfo, TickKind};
use crate::config::{non_negative, positive, ConfigError};
use crate::plant::GRAVITY;
use crate::sysid::{LinearModel, Offset};

/// Physical parameters of the longitudinal vehicle + payload model (eq. 5.7).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PendulumParams {
    /// Vehicle mass m_Q [kg].
    pub m_q: f64,
    /// Payload mass m_p [kg].
    pub m_p: f64,
    /// Cable length l [m].
    pub l: f64,
    /// Joint friction coefficient c [N m s/rad].
    pub c: f64,
}

impl Default for PendulumParams {
    fn default() -> Self {
        Self {
            m_q: 0.952,
            m_p: 0.2,
            l: 1.0,
            c: 0.0,
        }
    }
}

impl PendulumParams {
    /// Check every parameter is physical.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("m_q", self.m_q)?;
        positive("m_p", self.m_p)?;
        positive("l", self.l)?;
        non_negative("c", self.c)?;
        Ok(())
    }

    /// Continuous model over [v, θ, θ̇] with input a (eq. 5.7 with the stable sign, 5.8).
    pub fn continuous_model(&self) -> (DMatrix<f64>, DMatrix<f64>) {
        let (mq, mp, l, c, g) = (self.m_q, self.m_p, self.l, self.c, GRAVITY);
        let a = DMatrix::from_row_slice(
            3,
            3,
            &[
                0.0,
                mp * g / mq,
                c / (l * mq),
                0.0,
                0.0,
                1.0,
                0.0,
                -g * (mq + mp) / (mq * l),
                -c * (mq + mp) / (l * l * mq * mp),
            ],
        );
        let b = DMatrix::from_row_slice(3, 1, &[1.0, 0.0, -1.0 / l]);
        (a, b)
    }

    /// Augmented model over x_A = [∫(v_sp − v), v, θ, θ̇] (eq. 5.13–5.17, stable sign).
    pub fn integral_model(&self) -> (DMatrix<f64>, DMatrix<f64>) {
        let (a3, b3) = self.continuous_model();
        let mut a = DMatrix::<f64>::zeros(4, 4);
        a[(0, 1)] = -1.0;
        a.view_mut((1, 1), (3, 3)).copy_from(&a3);
        let mut b = DMatrix::<f64>::zeros(4, 1);
        b.view_mut((1, 0), (3, 1)).copy_from(&b3);
        (a, b)
    }

    /// A delay-embedded [`LinearModel`] over x = [v, θ] (one axis, input `acc_sp_n`) fitted
    /// by least squares to a seeded random-step simulation of the exact ZOH discretisation
    /// of [`Self::continuous_model`]: the physical dynamics fill the top n rows of A, exact
    /// shifts the rows below (the structure DMDc produces). For tests and benchmarks.
    pub fn delay_model(
        &self,
        dt: f64,
        delays: usize,
        seed: u64,
    ) -> Result<LinearModel, ControlError> {
        self.validate()?;
        if !(dt.is_finite() && dt > 0.0) || delays == 0 {
            return Err(ControlError::Model(format!(
                "delay model: need dt > 0 and delays ≥ 1 (got {dt}, {delays})"
            )));
        }
        let (ac, bc) = self.continuous_model();
        let (ad, bd) = c2d_zoh(&ac, &bc, dt);
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
            .map_err(|e| ControlError::Model(format!("delay model fit: {e}")))?;
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
}

/// [`PendulumParams::delay_model`] for `axes` = 1 or 2 identical decoupled axes: for two
/// axes the frame is [vn, ve, swing_n, swing_e] and the inputs `acc_sp_n`, `acc_sp_e`.
pub fn pendulum_delay_model(
    params: &PendulumParams,
    dt: f64,
    delays: usize,
    axes: usize,
    seed: u64,
) -> Result<LinearModel, ControlError> {
    let one = params.delay_model(dt, delays, seed)?;
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
        _ => Err(ControlError::Model(format!(
            "axes must be 1 or 2 (got {axes})"
        ))),
    }
}

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
    params: PendulumParams,
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
        params: PendulumParams,
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
    pub fn params(&self) -> PendulumParams {
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
