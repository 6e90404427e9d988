//! Online (recursive) delay-coordinate DMDc with forgetting, a change detector and a
//! persistence-of-excitation gate.
//!
//! Regression. The batch fit (`dmdc`, eq. 4.11–4.15) solves x_{k+1} = G φ_k in the least
//! squares sense, with the feature row φ_k = [u_k − ū; 1; x_k; x_{k−1}; …; x_{k−q+1}]
//! (inputs first, the constant only with the affine offset, lags newest first: the column
//! order of `hankel::feature_matrix`). Both fits only need an upper-triangular R with
//! RᵀR = FᵀF for the augmented rows a_k = [φ_k; x_{k+1}]: the batch one builds it once from
//! the structured Gram, this one keeps it current.
//!
//! Forgetting in square-root form. With forgetting factor λ ∈ (0, 1] the weighted Gram is
//! S_N = λ^N δ·I_φ + Σ_k λ^{N−1−k} a_k a_kᵀ (δ: a small prior on the regressor diagonal so
//! that the first estimates exist), and each accepted sample does
//!   R ← triangularise([√λ R; a_kᵀ])
//! by C Givens rotations (C = r + n columns), O(C²) flops and no allocation. Orthogonal
//! updates are backward stable, so the factor does not drift over hours the way a recursive
//! inverse-covariance (RLS P-matrix) update does: no periodic refactorisation is needed, and
//! the estimate equals the batch least-squares fit of the same weighted rows to rounding
//! (checked over an hour of samples in the tests). From R = [[R₁₁, R₁₂], [0, R₂₂]] (regressor
//! block r × r, target block n columns): the full-rank estimate is Gᵀ = R₁₁⁻¹ R₁₂, the
//! weighted residual Gram R₂₂ᵀR₂₂, and a rank-p estimate is the truncated SVD of R₁₁ᵀ exactly
//! as in the batch fit ([`model_from_factor`] goes through `dmdc::DmdcBasis`).
//!
//! Persistence of excitation. Over a sliding window of the last W samples of the
//! input-state vector w_k = [u_k; x_k] (m + n values) the gate asks (i) the standard
//! deviation of every input to reach `pe_input_std` and (ii) the smallest eigenvalue of the
//! window's correlation matrix (covariance scaled to a unit diagonal) to reach `pe_min_eig`,
//! tested without an eigen-solver as positive definiteness of (corr − τ I) by Cholesky.
//! Samples the gate refuses do not enter R (and are not forgotten against): steady hover or
//! a constant input leaves the estimate untouched instead of slowly replacing it with a
//! fit to noise.
//!
//! Change detection. The adopted model (the one the controller flies) runs free on the
//! applied inputs from the measured history for h = `detector_horizon` samples; its error
//! e = x_{k+h} − x̂_{k+h|k} (a one-step residual is too forgiving for delay models, whose
//! recent history already carries most of the next sample) is normalised by σ²_i, the larger of `residual_floor`²,
//! the fit's weighted residual variance at adoption, and the mean e_i² over quiet samples
//! (full window, gate closed; a running mean over the last ≈ W of them):
//! z_k = (1/n) Σ_i e_{k,i}² / σ²_i. In quiet flight a wrong model predicts about as well as a
//! right one, so quiet samples measure the noise the fit never saw (hover on a noisy
//! velocity estimate), and only excited samples feed the detector. A one-sided CUSUM s_k = max(0, s_{k−1} + z_k − 1 − ν) fires
//! (once per comparison) when s_k > H (ν = `cusum_drift`, H = `cusum_threshold`). On a fire the past information
//! is discounted once by `change_discount` (covariance resetting) so that the post-change
//! data dominate the estimate after a few hundred samples instead of 1/(1 − λ).

use faer::Mat;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::dmdc::{delay_form, split_g, DmdcBasis};
use super::error::{data, model as model_err, SysidError};
use super::model::{LinearModel, Offset};
use crate::config::{in_range, non_negative, positive, ConfigError};

/// Settings of the online identification.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OnlineSettings {
    /// Forgetting factor λ per accepted sample, (0, 1]; the memory is ≈ 1/(1 − λ) samples
    /// [dimensionless].
    pub forgetting: f64,
    /// Prior information δ on each regressor before any data [feature units²]; keeps the
    /// first estimates defined and decays with the forgetting.
    pub prior: f64,
    /// Length of the persistence-of-excitation window [samples].
    pub pe_window: usize,
    /// Least standard deviation of every input over the window [input units, m/s²]
    /// (0 = no input check); must sit above what noise alone makes the controller do in
    /// hover (≈ 0.17 m/s² for the default MPC on 0.01 m/s of velocity noise).
    pub pe_input_std: f64,
    /// Least eigenvalue of the window's input-state correlation matrix [dimensionless, 0–1]
    /// (0 = no conditioning check).
    pub pe_min_eig: f64,
    /// Samples h the adopted model runs free on the applied inputs before its prediction is
    /// compared with the measurement [samples] (1 = one-step residual).
    pub detector_horizon: usize,
    /// CUSUM drift ν on the normalised squared residual [dimensionless].
    pub cusum_drift: f64,
    /// CUSUM threshold h [dimensionless]; 0 disables the detector.
    pub cusum_threshold: f64,
    /// Floor of the residual standard deviation the detector normalises by [state units:
    /// m/s, rad]; keeps a near-perfect fit from making the detector hair-triggered.
    pub residual_floor: f64,
    /// Weight kept on the past information when the detector fires [dimensionless, 0–1]
    /// (1 = no reset).
    pub change_discount: f64,
}

impl Default for OnlineSettings {
    fn default() -> Self {
        Self {
            forgetting: 0.998,
            prior: 1e-6,
            pe_window: 100,
            pe_input_std: 0.3,
            pe_min_eig: 1e-3,
            detector_horizon: 10,
            cusum_drift: 2.0,
            cusum_threshold: 30.0,
            residual_floor: 1e-3,
            change_discount: 0.01,
        }
    }
}

impl OnlineSettings {
    /// Check every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("forgetting", self.forgetting)?;
        if self.forgetting > 1.0 {
            return Err(ConfigError::new(
                "forgetting",
                format!("must be in (0, 1] (got {})", self.forgetting),
            ));
        }
        non_negative("prior", self.prior)?;
        if self.pe_window < 2 || self.pe_window > 100_000 {
            return Err(ConfigError::new(
                "pe_window",
                format!(
                    "must be between 2 and 100000 samples (got {})",
                    self.pe_window
                ),
            ));
        }
        non_negative("pe_input_std", self.pe_input_std)?;
        in_range("pe_min_eig", self.pe_min_eig, 0.0, 1.0)?;
        if self.detector_horizon == 0 || self.detector_horizon > 10_000 {
            return Err(ConfigError::new(
                "detector_horizon",
                format!(
                    "must be between 1 and 10000 samples (got {})",
                    self.detector_horizon
                ),
            ));
        }
        non_negative("cusum_drift", self.cusum_drift)?;
        non_negative("cusum_threshold", self.cusum_threshold)?;
        positive("residual_floor", self.residual_floor)?;
        in_range("change_discount", self.change_discount, 0.0, 1.0)?;
        Ok(())
    }
}

/// What one [`OnlineDmdc::update`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OnlineStep {
    /// A regression row was formed (the history holds q frames).
    pub regressed: bool,
    /// The excitation gate held for the window ending at this sample.
    pub excited: bool,
    /// The row entered the factor (regressed and excited).
    pub accepted: bool,
    /// The detector fired at this sample (first crossing only).
    pub fired: bool,
    /// Normalised squared residual z of the adopted model (0 before a row is formed).
    pub residual: f64,
    /// CUSUM statistic s after this sample.
    pub statistic: f64,
}

/// Recursive delay-coordinate DMDc (see module docs). Every buffer is allocated in
/// [`OnlineDmdc::new`]; [`OnlineDmdc::update`] allocates nothing.
#[derive(Clone, Debug)]
pub struct OnlineDmdc {
    settings: OnlineSettings,
    n: usize,
    m: usize,
    q: usize,
    affine: bool,
    input_mean: Vec<f64>,
    /// Regressors r and columns C = r + n.
    r: usize,
    c: usize,
    /// Upper-triangular factor, row-major C × C.
    factor: Vec<f64>,
    /// Σ of the weights of the accepted rows (λ-discounted).
    weight: f64,
    /// Newest q frames, newest first (q·n).
    history: Vec<f64>,
    frames: usize,
    /// Work row a = [φ; x⁺].
    row: Vec<f64>,
    /// Adopted G (n × r, row-major, feature order).
    adopted: Vec<f64>,
    has_adopted: bool,
    /// Residual standard deviation per state at adoption.
    sigma: Vec<f64>,
    cusum: f64,
    /// Residual level of the fit at adoption (floored), per state.
    sigma_fit: Vec<f64>,
    /// Running mean of e² over quiet samples, and how many it has seen.
    quiet_ms: Vec<f64>,
    quiet_count: usize,
    /// The adopted model's free run: its history (newest first), regressor and age.
    sim_hist: Vec<f64>,
    sim_row: Vec<f64>,
    sim_count: usize,
    sim_valid: bool,
    fired: bool,
    since_fire: usize,
    accepted: u64,
    // Excitation window over w = [u; x] (d = m + n).
    ring: Vec<f64>,
    ring_len: usize,
    ring_pos: usize,
    since_recompute: usize,
    sum: Vec<f64>,
    sum2: Vec<f64>,
    chol: Vec<f64>,
    excited: bool,
}

impl OnlineDmdc {
    /// An empty estimator for n states, m inputs and q delays (see module docs).
    pub fn new(
        n: usize,
        m: usize,
        q: usize,
        offset: Offset,
        input_mean: &[f64],
        settings: OnlineSettings,
    ) -> Result<Self, SysidError> {
        settings.validate()?;
        if n == 0 || m == 0 || q == 0 {
            return Err(data(format!(
                "online DMDc needs ≥ 1 state, input and delay (got n = {n}, m = {m}, q = {q})"
            )));
        }
        if n * q > 4096 {
            return Err(data(format!("{n} states × {q} delays is too large")));
        }
        let input_mean = if offset == Offset::Mean {
            if input_mean.len() != m || !input_mean.iter().all(|v| v.is_finite()) {
                return Err(data(format!(
                    "input_mean must hold {m} finite values (got {:?})",
                    input_mean
                )));
            }
            input_mean.to_vec()
        } else {
            vec![0.0; m]
        };
        let affine = offset == Offset::Affine;
        let r = m + usize::from(affine) + n * q;
        let c = r + n;
        let mut factor = vec![0.0; c * c];
        let root = settings.prior.sqrt();
        for i in 0..r {
            factor[i * c + i] = root;
        }
        let d = m + n;
        Ok(Self {
            n,
            m,
            q,
            affine,
            input_mean,
            r,
            c,
            factor,
            weight: 0.0,
            history: vec![0.0; n * q],
            frames: 0,
            row: vec![0.0; c],
            adopted: vec![0.0; n * r],
            has_adopted: false,
            sigma: vec![settings.residual_floor; n],
            cusum: 0.0,
            sigma_fit: vec![settings.residual_floor; n],
            quiet_ms: vec![0.0; n],
            quiet_count: 0,
            sim_hist: vec![0.0; n * q],
            sim_row: vec![0.0; m + usize::from(offset == Offset::Affine) + n * q],
            sim_count: 0,
            sim_valid: false,
            fired: false,
            since_fire: 0,
            accepted: 0,
            ring: vec![0.0; settings.pe_window * d],
            ring_len: 0,
            ring_pos: 0,
            since_recompute: 0,
            sum: vec![0.0; d],
            sum2: vec![0.0; d * d],
            chol: vec![0.0; d * d],
            excited: false,
            settings,
        })
    }

    /// An estimator with the layout (n, m, q, offset, input mean) of `model`, adopting it.
    pub fn for_model(model: &LinearModel, settings: OnlineSettings) -> Result<Self, SysidError> {
        model.validate()?;
        let mut est = Self::new(
            model.n(),
            model.m(),
            model.delays,
            model.offset,
            &model.input_mean,
            settings,
        )?;
        est.adopt(model)?;
        Ok(est)
    }

    /// The settings in use.
    pub fn settings(&self) -> &OnlineSettings {
        &self.settings
    }

    /// Number of regressors r = m (+1) + n·q.
    pub fn regressors(&self) -> usize {
        self.r
    }

    /// Columns C = r + n of the factor.
    pub fn columns(&self) -> usize {
        self.c
    }

    /// The triangular factor R (row-major C × C) with RᵀR the weighted Gram of [φ; x⁺].
    pub fn factor(&self) -> &[f64] {
        &self.factor
    }

    /// Sum of the λ-discounted weights of the accepted rows (the effective sample count).
    pub fn weight(&self) -> f64 {
        self.weight
    }

    /// Rows accepted so far.
    pub fn accepted(&self) -> u64 {
        self.accepted
    }

    /// Whether the excitation gate holds for the latest window.
    pub fn excited(&self) -> bool {
        self.excited
    }

    /// Whether the detector has fired since the last adoption.
    pub fn fired(&self) -> bool {
        self.fired
    }

    /// Rows accepted since the detector fired (0 when it has not).
    pub fn accepted_since_fire(&self) -> usize {
        self.since_fire
    }

    /// The CUSUM statistic.
    pub fn statistic(&self) -> f64 {
        self.cusum
    }

    /// Residual standard deviation per state the detector normalises by [state units].
    pub fn residual_scale(&self) -> &[f64] {
        &self.sigma
    }

    /// Forget the history of states (e.g. after a gap in the data); the factor is kept.
    pub fn restart_history(&mut self) {
        self.frames = 0;
        self.sim_valid = false;
        self.ring_len = 0;
        self.ring_pos = 0;
        self.excited = false;
        self.sum.fill(0.0);
        self.sum2.fill(0.0);
    }

    /// Make `model` the adopted one: the detector compares with it from now on, normalising
    /// by the current fit's residual level, and its statistic restarts.
    pub fn adopt(&mut self, model: &LinearModel) -> Result<(), SysidError> {
        let (n, m, q) = (self.n, self.m, self.q);
        if model.n() != n || model.m() != m || model.delays != q {
            return Err(model_err(format!(
                "model with {} states, {} inputs, {} delays does not fit the online \
                 estimator's {n}, {m}, {q}",
                model.n(),
                model.m(),
                model.delays
            )));
        }
        if (model.offset == Offset::Affine) != self.affine {
            return Err(model_err(
                "model offset differs from the online estimator's",
            ));
        }
        let lead = m + usize::from(self.affine);
        for i in 0..n {
            let g = &mut self.adopted[i * self.r..(i + 1) * self.r];
            for j in 0..m {
                g[j] = model.b[(i, j)];
            }
            if self.affine {
                g[m] = model.c[i];
            }
            for j in 0..n * q {
                g[lead + j] = model.a[(i, j)];
            }
        }
        self.has_adopted = true;
        self.rescale_detector();
        Ok(())
    }

    /// Restart the detector with the residual level of the current fit.
    fn rescale_detector(&mut self) {
        let (r, c) = (self.r, self.c);
        let floor = self.settings.residual_floor;
        for i in 0..self.n {
            let mut rss = 0.0;
            for k in r..=r + i {
                rss += self.factor[k * c + r + i].powi(2);
            }
            let var = if self.weight > 1.0 {
                rss / self.weight
            } else {
                0.0
            };
            self.sigma_fit[i] = var.sqrt().max(floor);
            self.sigma[i] = self.sigma_fit[i].max(self.quiet_ms[i].sqrt());
        }
        self.cusum = 0.0;
        self.fired = false;
        self.since_fire = 0;
        self.sim_valid = false;
    }

    /// One new sample: `x` is the newest state x_{k+1}, `u` the input applied between the
    /// previous sample and this one (u_k). Updates the excitation window, the detector (with
    /// the adopted model) and, when excited, the factor.
    pub fn update(&mut self, x: &[f64], u: &[f64]) -> Result<OnlineStep, SysidError> {
        let (n, m, q, r, c) = (self.n, self.m, self.q, self.r, self.c);
        if x.len() != n || u.len() != m {
            return Err(data(format!(
                "expected {n} states and {m} inputs, got {} and {}",
                x.len(),
                u.len()
            )));
        }
        if !x.iter().chain(u).all(|v| v.is_finite()) {
            return Err(data("state or input is not finite"));
        }
        let mut step = OnlineStep::default();
        if self.frames >= 1 {
            // The excitation window sees (u_k, x_k): the input and the state it acted on.
            self.push_window(u);
            self.excited = self.window_excited();
        }
        step.excited = self.excited;
        if self.frames >= q {
            for j in 0..m {
                self.row[j] = u[j] - self.input_mean[j];
            }
            let lead = m + usize::from(self.affine);
            if self.affine {
                self.row[m] = 1.0;
            }
            self.row[lead..lead + n * q].copy_from_slice(&self.history);
            self.row[r..c].copy_from_slice(x);
            step.regressed = true;
            if self.has_adopted && self.settings.cusum_threshold > 0.0 {
                self.detect(x, u, &mut step);
            }
            step.statistic = self.cusum;
            if self.excited {
                self.accept();
                step.accepted = true;
            }
        }
        // Shift the history and store the new frame.
        if q > 1 {
            self.history.copy_within(0..n * (q - 1), n);
        }
        self.history[..n].copy_from_slice(x);
        self.frames = (self.frames + 1).min(q + 1);
        Ok(step)
    }

    /// The detector's share of an update: advance the adopted model's free run by one
    /// sample with the applied input; every `detector_horizon` samples compare it with the
    /// measurement, update σ (quiet samples) or the CUSUM (excited ones), and restart the
    /// run from the measured history.
    fn detect(&mut self, x: &[f64], u: &[f64], step: &mut OnlineStep) {
        let (n, m, q, r) = (self.n, self.m, self.q, self.r);
        if !self.sim_valid {
            self.sim_hist.copy_from_slice(&self.history);
            self.sim_count = 0;
            self.sim_valid = true;
        }
        for j in 0..m {
            self.sim_row[j] = u[j] - self.input_mean[j];
        }
        let lead = m + usize::from(self.affine);
        if self.affine {
            self.sim_row[m] = 1.0;
        }
        self.sim_row[lead..lead + n * q].copy_from_slice(&self.sim_hist);
        if q > 1 {
            self.sim_hist.copy_within(0..n * (q - 1), n);
        }
        for i in 0..n {
            let g = &self.adopted[i * r..(i + 1) * r];
            self.sim_hist[i] = g.iter().zip(&self.sim_row).map(|(a, b)| a * b).sum();
        }
        self.sim_count += 1;
        if self.sim_count < self.settings.detector_horizon {
            return;
        }
        self.sim_valid = false;
        let quiet = !self.excited && self.ring_len == self.settings.pe_window;
        if quiet {
            self.quiet_count += 1;
        }
        // Quiet comparisons come every `detector_horizon` samples: average over the last
        // ≈ W samples' worth of them.
        let memory = (self.settings.pe_window / self.settings.detector_horizon).max(1);
        let alpha = 1.0 / (self.quiet_count.min(memory).max(1) as f64);
        let mut z = 0.0;
        for i in 0..n {
            let e2 = (x[i] - self.sim_hist[i]).powi(2);
            if quiet {
                self.quiet_ms[i] += alpha * (e2 - self.quiet_ms[i]);
                self.sigma[i] = self.sigma_fit[i].max(self.quiet_ms[i].sqrt());
            }
            z += e2 / (self.sigma[i] * self.sigma[i]);
        }
        z /= n as f64;
        step.residual = z;
        if self.excited {
            self.cusum = (self.cusum + z - 1.0 - self.settings.cusum_drift).max(0.0);
        }
        if !self.fired && self.cusum > self.settings.cusum_threshold {
            self.fired = true;
            self.since_fire = 0;
            step.fired = true;
            self.discount(self.settings.change_discount);
        }
    }

    /// Multiply the past information by `w` (0 < w ≤ 1; the factor by √w).
    pub fn discount(&mut self, w: f64) {
        if !(w > 0.0 && w < 1.0) {
            return;
        }
        let s = w.sqrt();
        self.factor.iter_mut().for_each(|v| *v *= s);
        self.weight *= w;
    }

    /// Forget by λ and rotate the work row into the factor.
    fn accept(&mut self) {
        let c = self.c;
        let lam = self.settings.forgetting;
        if lam < 1.0 {
            let s = lam.sqrt();
            self.factor.iter_mut().for_each(|v| *v *= s);
        }
        self.weight = lam * self.weight + 1.0;
        givens_update(&mut self.factor, c, &mut self.row);
        self.accepted += 1;
        if self.fired {
            self.since_fire += 1;
        }
    }

    /// Push w = [u; x_k] (x_k is the newest history frame) into the excitation window.
    fn push_window(&mut self, u: &[f64]) {
        let (n, m) = (self.n, self.m);
        let d = m + n;
        let cap = self.settings.pe_window;
        let pos = self.ring_pos;
        // Remove the sample about to be overwritten.
        if self.ring_len == cap {
            for a in 0..d {
                let wa = self.ring[pos * d + a];
                self.sum[a] -= wa;
                for b in 0..d {
                    self.sum2[a * d + b] -= wa * self.ring[pos * d + b];
                }
            }
        }
        self.ring[pos * d..pos * d + m].copy_from_slice(u);
        self.ring[pos * d + m..(pos + 1) * d].copy_from_slice(&self.history[..n]);
        for a in 0..d {
            let wa = self.ring[pos * d + a];
            self.sum[a] += wa;
            for b in 0..d {
                self.sum2[a * d + b] += wa * self.ring[pos * d + b];
            }
        }
        self.ring_pos = (pos + 1) % cap;
        self.ring_len = (self.ring_len + 1).min(cap);
        // Running sums lose accuracy by cancellation; recompute them exactly once a window.
        self.since_recompute += 1;
        if self.since_recompute >= cap {
            self.since_recompute = 0;
            self.sum.fill(0.0);
            self.sum2.fill(0.0);
            for k in 0..self.ring_len {
                for a in 0..d {
                    let wa = self.ring[k * d + a];
                    self.sum[a] += wa;
                    for b in 0..d {
                        self.sum2[a * d + b] += wa * self.ring[k * d + b];
                    }
                }
            }
        }
    }

    /// The excitation test of the module docs on the current window.
    fn window_excited(&mut self) -> bool {
        let d = self.m + self.n;
        if self.settings.pe_input_std == 0.0 && self.settings.pe_min_eig == 0.0 {
            // The gate is off: every row enters.
            return true;
        }
        if self.ring_len < self.settings.pe_window {
            return false;
        }
        let w = self.ring_len as f64;
        // Covariance into `chol`.
        for a in 0..d {
            for b in 0..d {
                self.chol[a * d + b] =
                    self.sum2[a * d + b] / w - (self.sum[a] / w) * (self.sum[b] / w);
            }
        }
        let min_std = self.settings.pe_input_std;
        for a in 0..d {
            let var = self.chol[a * d + a];
            // A channel without variance makes the correlation undefined: not excited.
            let scale = self.sum2[a * d + a] / w;
            if var.is_nan() || var <= 1e-14 * scale.max(1e-300) {
                return false;
            }
            if a < self.m && var < min_std * min_std {
                return false;
            }
        }
        let tau = self.settings.pe_min_eig;
        if tau <= 0.0 {
            return true;
        }
        // corr − τ I, then an in-place Cholesky: positive definite ⇔ λ_min(corr) > τ.
        for a in 0..d {
            let sa = self.chol[a * d + a].sqrt();
            for b in 0..d {
                let sb = self.chol[b * d + b].sqrt();
                if a != b {
                    self.chol[a * d + b] /= sa * sb;
                }
            }
        }
        for a in 0..d {
            self.chol[a * d + a] = 1.0 - tau;
        }
        cholesky_in_place(&mut self.chol, d)
    }

    /// The full-rank estimate G (n × r, feature order) from the factor: Gᵀ = R₁₁⁻¹ R₁₂.
    pub fn estimate(&self) -> Result<DMatrix<f64>, SysidError> {
        let (n, r, c) = (self.n, self.r, self.c);
        let diag_max = (0..r)
            .map(|i| self.factor[i * c + i].abs())
            .fold(0.0, f64::max);
        let mut g = DMatrix::<f64>::zeros(n, r);
        for s in 0..n {
            for i in (0..r).rev() {
                let rii = self.factor[i * c + i];
                if rii.abs() <= diag_max * 1e-15 || rii == 0.0 {
                    return Err(SysidError::Identification(
                        "online estimate is rank deficient (too little excitation so far)".into(),
                    ));
                }
                let mut acc = self.factor[i * c + r + s];
                for j in i + 1..r {
                    acc -= self.factor[i * c + j] * g[(s, j)];
                }
                g[(s, i)] = acc / rii;
            }
        }
        Ok(g)
    }

    /// A delay-form model of rank `rank` from the current factor, named like `template`
    /// (see [`model_from_factor`]).
    pub fn model(&self, rank: usize, template: &LinearModel) -> Result<LinearModel, SysidError> {
        model_from_factor(&self.factor, self.weight, rank, template)
    }
}

/// A rank-`rank` delay-form model from a factor R (row-major C × C) of an estimator with the
/// layout of `template` (states, inputs, delays, offset, input mean and dt are taken from
/// it): the truncated SVD of R₁₁ᵀ as in the batch DMDc fit. `weight` is the effective sample
/// count (for the numerical-rank tolerance). Off the real-time path: it allocates.
pub fn model_from_factor(
    factor: &[f64],
    weight: f64,
    rank: usize,
    template: &LinearModel,
) -> Result<LinearModel, SysidError> {
    let (n, m, q) = (template.n(), template.m(), template.delays);
    let affine = template.offset == Offset::Affine;
    let c = m + usize::from(affine) + n * q + n;
    if factor.len() != c * c {
        return Err(model_err(format!(
            "factor of {} values does not fit {c} × {c} columns",
            factor.len()
        )));
    }
    if !factor.iter().all(|v| v.is_finite()) {
        return Err(data("online factor is not finite"));
    }
    let r = Mat::<f64>::from_fn(c, c, |i, j| if j >= i { factor[i * c + j] } else { 0.0 });
    let samples = weight.max(1.0).round() as usize;
    let basis = DmdcBasis::from_factor(r, n, m, q, affine, template.input_mean.clone(), samples);
    let svd = basis.svd(q)?;
    let full = svd.rows();
    if rank == 0 || rank > full {
        return Err(super::error::config(format!(
            "rank {rank} outside 1..={full}"
        )));
    }
    if svd.numerical_rank == 0 {
        return Err(data("the online data matrix is zero"));
    }
    let g = svd.g(rank);
    let (a_top, b_top, c_top) = split_g(&g, &svd.features);
    let mut out = delay_form(
        "dmdc-online",
        template.dt,
        q,
        rank,
        template.offset,
        template.input_mean.clone(),
        &a_top,
        &b_top,
        &c_top,
    );
    out.states = template.states.clone();
    out.inputs = template.inputs.clone();
    out.diagnostics.singular_values = svd.sigma.clone();
    Ok(out)
}

/// Rotate row `a` into the upper-triangular `r` (row-major c × c) by Givens rotations;
/// `a` is left zero.
fn givens_update(r: &mut [f64], c: usize, a: &mut [f64]) {
    for i in 0..c {
        let ai = a[i];
        if ai == 0.0 {
            continue;
        }
        let rii = r[i * c + i];
        let h = rii.hypot(ai);
        let (cs, sn) = (rii / h, ai / h);
        r[i * c + i] = h;
        a[i] = 0.0;
        let row = &mut r[i * c + i + 1..(i + 1) * c];
        for (rij, aj) in row.iter_mut().zip(&mut a[i + 1..c]) {
            let (x, y) = (*rij, *aj);
            *rij = cs * x + sn * y;
            *aj = cs * y - sn * x;
        }
    }
}

/// In-place Cholesky of the symmetric d × d `a`; false when it is not positive definite.
fn cholesky_in_place(a: &mut [f64], d: usize) -> bool {
    for j in 0..d {
        let mut s = a[j * d + j];
        for k in 0..j {
            s -= a[j * d + k] * a[j * d + k];
        }
        if s.is_nan() || s <= 0.0 {
            return false;
        }
        let l = s.sqrt();
        a[j * d + j] = l;
        for i in j + 1..d {
            let mut t = a[i * d + j];
            for k in 0..j {
                t -= a[i * d + k] * a[j * d + k];
            }
            a[i * d + j] = t / l;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// A known stable two-state, one-input, two-delay affine system:
    /// x⁺ = A₀ x + A₁ x₋₁ + B u + c.
    struct Known {
        a0: [[f64; 2]; 2],
        a1: [[f64; 2]; 2],
        b: [f64; 2],
        c: [f64; 2],
    }

    const SYS: Known = Known {
        a0: [[0.9, 0.1], [-0.2, 1.6]],
        a1: [[0.05, 0.0], [0.0, -0.7]],
        b: [0.03, -0.02],
        c: [0.01, 0.002],
    };

    impl Known {
        fn step(&self, x: [f64; 2], xm: [f64; 2], u: f64) -> [f64; 2] {
            let mut out = [0.0; 2];
            for i in 0..2 {
                out[i] = self.a0[i][0] * x[0]
                    + self.a0[i][1] * x[1]
                    + self.a1[i][0] * xm[0]
                    + self.a1[i][1] * xm[1]
                    + self.b[i] * u
                    + self.c[i];
            }
            out
        }

        /// G in feature order [u, 1, x, x₋₁].
        fn g(&self) -> [[f64; 6]; 2] {
            let mut g = [[0.0; 6]; 2];
            for i in 0..2 {
                g[i] = [
                    self.b[i],
                    self.c[i],
                    self.a0[i][0],
                    self.a0[i][1],
                    self.a1[i][0],
                    self.a1[i][1],
                ];
            }
            g
        }
    }

    fn open_settings() -> OnlineSettings {
        OnlineSettings {
            prior: 0.0,
            pe_input_std: 0.0,
            pe_min_eig: 0.0,
            cusum_threshold: 0.0,
            ..OnlineSettings::default()
        }
    }

    /// Drive `sys` with seeded random inputs (held 5 samples) and optional process noise.
    fn drive(
        est: &mut OnlineDmdc,
        sys: &Known,
        x: &mut [[f64; 2]; 2],
        samples: usize,
        noise: f64,
        rng: &mut ChaCha8Rng,
        mut each: impl FnMut(&OnlineStep, &[f64; 2], f64),
    ) {
        let mut u = 0.0;
        for k in 0..samples {
            if k % 5 == 0 {
                let z: f64 = StandardNormal.sample(rng);
                u = z;
            }
            let mut next = sys.step(x[0], x[1], u);
            for v in next.iter_mut() {
                let z: f64 = StandardNormal.sample(rng);
                *v += noise * z;
            }
            let st = est.update(&next, &[u]).unwrap();
            each(&st, &next, u);
            x[1] = x[0];
            x[0] = next;
        }
    }

    /// Noise-free data of a known system: the recursive estimate is the system.
    #[test]
    fn recovers_a_known_linear_system_exactly() {
        let mut est = OnlineDmdc::new(2, 1, 2, Offset::Affine, &[], open_settings()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut x = [[0.0; 2]; 2];
        // Prime the history with the first frame.
        est.update(&x[0], &[0.0]).unwrap();
        drive(&mut est, &SYS, &mut x, 2000, 0.0, &mut rng, |_, _, _| {});
        let g = est.estimate().unwrap();
        let truth = SYS.g();
        for i in 0..2 {
            for j in 0..6 {
                assert!(
                    (g[(i, j)] - truth[i][j]).abs() < 1e-10,
                    "G[{i},{j}] = {} vs {}",
                    g[(i, j)],
                    truth[i][j]
                );
            }
        }
        // The truncated-SVD path at full rank gives the same model.
        let template = delay_form(
            "t",
            0.03,
            2,
            6,
            Offset::Affine,
            vec![0.0],
            &DMatrix::zeros(2, 4),
            &DMatrix::zeros(2, 1),
            &nalgebra::DVector::zeros(2),
        );
        let model = est.model(6, &template).unwrap();
        assert!((model.b[(1, 0)] - SYS.b[1]).abs() < 1e-10);
        assert!((model.a[(1, 3)] - SYS.a1[1][1]).abs() < 1e-10);
        assert!((model.c[0] - SYS.c[0]).abs() < 1e-10);
    }

    /// An hour at 30 ms of noisy data through the square-root update matches the batch
    /// least-squares fit (Householder QR of the λ-weighted rows) of the same data.
    #[test]
    fn hour_long_recursion_matches_the_weighted_batch_fit() {
        let settings = OnlineSettings {
            forgetting: 0.999,
            prior: 1e-3,
            ..open_settings()
        };
        let lam = settings.forgetting;
        let mut est = OnlineDmdc::new(2, 1, 2, Offset::Affine, &[], settings).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut x = [[0.0; 2]; 2];
        // Two zero frames: the history the batch rows below assume.
        est.update(&x[0], &[0.0]).unwrap();
        est.update(&x[0], &[0.0]).unwrap();
        // A slowly varying system so the weighting matters.
        let samples = 120_000;
        let mut rows: Vec<[f64; 8]> = Vec::with_capacity(samples);
        let mut sys = Known { ..SYS };
        let mut prev = x;
        let mut u = 0.0;
        for k in 0..samples {
            if k % 5 == 0 {
                u = StandardNormal.sample(&mut rng);
            }
            sys.b[0] = 0.03 + 0.01 * (k as f64 * 1e-4).sin();
            let mut next = sys.step(prev[0], prev[1], u);
            for v in next.iter_mut() {
                let z: f64 = StandardNormal.sample(&mut rng);
                *v += 1e-3 * z;
            }
            let st = est.update(&next, &[u]).unwrap();
            assert!(st.accepted);
            rows.push([
                u, 1.0, prev[0][0], prev[0][1], prev[1][0], prev[1][1], next[0], next[1],
            ]);
            prev[1] = prev[0];
            prev[0] = next;
        }
        x = prev;
        let _ = x;
        // Rows older than ~λ^(-40000) weigh < 1e-17 relative: leave them out of the batch.
        let keep = 60_000;
        let nrows = rows.len();
        let first = nrows - keep;
        let total = keep + 6;
        let f = Mat::<f64>::from_fn(total, 8, |i, j| {
            if i < keep {
                let k = first + i;
                let w = lam.powf(((nrows - 1 - k) as f64) / 2.0);
                rows[k][j] * w
            } else {
                // The prior, decayed like every row before the first.
                let w = (1e-3 * lam.powf(nrows as f64)).sqrt();
                if j == i - keep {
                    w
                } else {
                    0.0
                }
            }
        });
        let rb = f.qr().thin_R().to_owned();
        let mut gb = [[0.0; 6]; 2];
        for s in 0..2 {
            for i in (0..6).rev() {
                let mut acc = rb[(i, 6 + s)];
                for j in i + 1..6 {
                    acc -= rb[(i, j)] * gb[s][j];
                }
                gb[s][i] = acc / rb[(i, i)];
            }
        }
        let g = est.estimate().unwrap();
        let scale = gb.iter().flatten().fold(0.0_f64, |a, v| a.max(v.abs()));
        let mut worst = 0.0_f64;
        for s in 0..2 {
            for i in 0..6 {
                worst = worst.max((g[(s, i)] - gb[s][i]).abs() / scale);
            }
        }
        eprintln!("recursive vs batch after {samples} samples: max |ΔG|/max|G| = {worst:.2e}");
        assert!(worst < 1e-9, "recursive and batch differ by {worst:e}");
        // And both are near the system of the last ~1000 samples.
        assert!(
            (g[(0, 0)] - sys.b[0]).abs() < 2e-3,
            "{} vs {}",
            g[(0, 0)],
            sys.b[0]
        );
    }

    /// A switched input gain: the detector stays quiet before the switch, fires after it,
    /// and the forgetting estimate tracks the new system.
    #[test]
    fn detector_fires_and_forgetting_tracks_a_switched_system() {
        let settings = OnlineSettings {
            forgetting: 0.99,
            prior: 1e-6,
            pe_input_std: 0.3,
            pe_min_eig: 1e-3,
            pe_window: 50,
            detector_horizon: 1,
            cusum_drift: 2.0,
            cusum_threshold: 50.0,
            residual_floor: 1e-3,
            change_discount: 0.01,
        };
        let mut est = OnlineDmdc::new(2, 1, 2, Offset::Affine, &[], settings).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut x = [[0.0; 2]; 2];
        est.update(&x[0], &[0.0]).unwrap();
        drive(&mut est, &SYS, &mut x, 2000, 1e-3, &mut rng, |st, _, _| {
            assert!(!st.fired)
        });
        // Adopt what was learnt: its G is the system's (to the noise).
        let template = delay_form(
            "t",
            0.03,
            2,
            6,
            Offset::Affine,
            vec![0.0],
            &DMatrix::zeros(2, 4),
            &DMatrix::zeros(2, 1),
            &nalgebra::DVector::zeros(2),
        );
        let first = est.model(6, &template).unwrap();
        est.adopt(&first).unwrap();
        let sigma = est.residual_scale().to_vec();
        assert!(
            sigma.iter().all(|s| (0.5e-3..2e-3).contains(s)),
            "{sigma:?}"
        );
        drive(&mut est, &SYS, &mut x, 1000, 1e-3, &mut rng, |st, _, _| {
            assert!(!st.fired, "false alarm at s = {}", st.statistic)
        });
        let switched = Known {
            b: [0.08, 0.05],
            ..SYS
        };
        let mut fired_at = None;
        let mut k = 0;
        drive(
            &mut est,
            &switched,
            &mut x,
            1500,
            1e-3,
            &mut rng,
            |st, _, _| {
                if st.fired && fired_at.is_none() {
                    fired_at = Some(k);
                }
                k += 1;
            },
        );
        let at = fired_at.expect("the detector must fire after the switch");
        assert!(at < 100, "fired only {at} samples after the switch");
        let g = est.estimate().unwrap();
        assert!((g[(0, 0)] - 0.08).abs() < 2e-3, "b0 = {}", g[(0, 0)]);
        assert!((g[(1, 0)] - 0.05).abs() < 2e-3, "b1 = {}", g[(1, 0)]);
    }

    /// A constant input never passes the gate: nothing enters the factor.
    #[test]
    fn excitation_gate_refuses_a_constant_input() {
        let mut est =
            OnlineDmdc::new(2, 1, 2, Offset::Affine, &[], OnlineSettings::default()).unwrap();
        let before = est.factor().to_vec();
        let mut x = [[0.0; 2]; 2];
        for _ in 0..5000 {
            let next = SYS.step(x[0], x[1], 0.7);
            let st = est.update(&next, &[0.7]).unwrap();
            assert!(!st.excited && !st.accepted);
            x[1] = x[0];
            x[0] = next;
        }
        assert_eq!(est.factor(), &before[..]);
        assert_eq!(est.accepted(), 0);
        // A random input does pass once the window is full.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut accepted = 0;
        drive(&mut est, &SYS, &mut x, 500, 0.0, &mut rng, |st, _, _| {
            accepted += usize::from(st.accepted)
        });
        assert!(accepted > 300, "{accepted}");
    }

    /// Input collinear with a state (u = k·x₀ exactly) fails the conditioning test even
    /// though the input varies.
    #[test]
    fn excitation_gate_refuses_collinear_input_and_state() {
        let mut est =
            OnlineDmdc::new(1, 1, 1, Offset::Affine, &[], OnlineSettings::default()).unwrap();
        for k in 1..500 {
            let (x, x_prev) = ((k as f64 * 0.1).sin(), ((k - 1) as f64 * 0.1).sin());
            // u_{k−1} = 2 x_{k−1}: the input is a multiple of the state it acts on.
            let st = est.update(&[x], &[2.0 * x_prev]).unwrap();
            assert!(!st.excited);
        }
        // The same signals one sample apart are not collinear: the gate opens.
        let mut est =
            OnlineDmdc::new(1, 1, 1, Offset::Affine, &[], OnlineSettings::default()).unwrap();
        let mut opened = false;
        for k in 1..500 {
            let x = (k as f64 * 0.1).sin();
            opened |= est.update(&[x], &[2.0 * x]).unwrap().excited;
        }
        assert!(opened);
    }

    #[test]
    fn bad_settings_and_shapes_are_errors() {
        let bad = OnlineSettings {
            forgetting: 1.5,
            ..OnlineSettings::default()
        };
        let e = OnlineDmdc::new(2, 1, 2, Offset::Affine, &[], bad).unwrap_err();
        assert!(e.to_string().contains("forgetting"), "{e}");
        let mut est =
            OnlineDmdc::new(2, 1, 2, Offset::Affine, &[], OnlineSettings::default()).unwrap();
        assert!(est.update(&[1.0], &[0.0]).is_err());
        assert!(est.update(&[1.0, f64::NAN], &[0.0]).is_err());
        assert!(est.estimate().is_err() || est.weight() == 0.0);
    }
}
