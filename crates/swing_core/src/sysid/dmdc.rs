//! DMDc with delay coordinates (thesis eq. 4.9–4.15).
//!
//! Model (4.10): x_{k+1} = A_dmd x_k + A_d d_k + B_d u_k (+ c with the affine offset), with
//! d_k = [x_{k−1}; …; x_{k−q+1}] (4.9). The data matrices (4.11) give X' = G Ω with
//! Ω = [X; X_d; Υ] (4.13); the rank-p truncated SVD Ω ≈ Ũ Σ̃ Ṽᵀ (4.14) yields
//! G ≈ X' Ṽ Σ̃⁻¹ Ũᵀ (4.15), which splits into [A_dmd A_d B_d (c)].
//!
//! Computation. Ω is never decomposed directly: with the samples as rows, the matrix
//! F = [Υᵀ 1 Xᵀ X_dᵀ X'ᵀ] (inputs first, see `hankel::feature_matrix`) has a thin QR
//! F = Q R. For any q ≤ q_max, Ωᵀ is a column prefix of F, so Ωᵀ = Q_q R_q with
//! R_q the leading block of R, and X'ᵀ = Q_q S_q + (part orthogonal to Q_q) with S_q the
//! matching rows of R's last n columns. The SVD R_qᵀ = U Σ Wᵀ (size r × r, r = n·q + m
//! (+1)) gives Ω = U Σ (Q_q W)ᵀ, so U and Σ are exactly Ω's and
//! X' Ṽ = S_qᵀ W̃. Hence G_p = Σ_{i<p} (S_qᵀ w_i / σ_i) u_iᵀ: one QR serves every q and
//! one small SVD per q serves every p — the same numbers as (4.14)–(4.15), computed in
//! O(N r²) once instead of once per candidate. All q share the samples k ≥ q_max − 1.
//!
//! The triangular factor (budget: one fit with q = 50, 120 s at 0.03 s, F ≈ 3950 × 104, in
//! < 5 ms on one core). Only R is needed, never Q, and any R with RᵀR = FᵀF serves (row
//! signs drop out of U, Σ and X'V). On smooth, noise-free flight data cond(F) ≈ 1e8–1e11,
//! so the f64 Gram FᵀF (cond squared, beyond 1/u) cannot be factored, and a Householder QR
//! of F is accurate but O(N·C²), over budget. Instead (`gram` module) FᵀF is formed in
//! double-double arithmetic (error-free TwoProd/TwoSum,
//! ≈ 106-bit significand) and factored by a double-double Cholesky; squaring the condition
//! number is harmless at that precision, and R rounded to f64 is at least as accurate as the
//! Householder R (backward error ≈ u‖F‖). The Gram is cheap because F is block-Hankel: along
//! a lag diagonal an entry follows from its predecessor by adding one product and removing
//! another (the sample window slides by one), so only the entries with the target, input and
//! constant columns are full dot products — O(N·C·(n+m+1) + C³) instead of O(N·C²), and F
//! itself is not built. The Householder QR of F remains the fallback when the regressor
//! columns are numerically rank deficient (the double-double Cholesky meets a non-positive
//! pivot or a pivot ratio below 1e-14). Alternatives considered: shifted CholeskyQR3 (three
//! Gram products and triangular solves over F, ≈ 3× the flops of one Householder QR) and a
//! tuned tall-skinny QR both stay O(N·C²); the structured Gram is the only route well under
//! budget. Checked against faer's Householder R on cond ≈ 5e10 data (singular values of the
//! regressor block to ≈ 3e-9 relative, G at p = 40 to ≈ 3e-13; at full rank G differs by
//! ≈ 1e-6, within Householder's own u·σ₁/σ_p sensitivity).
//!
//! Offsets (4.6.6): `mean` subtracts the training input mean from u (stored as
//! `input_mean`); `affine` appends a constant-1 feature whose coefficient is `c`; `none`
//! does neither. The returned [`LinearModel`] is in the delay form of the model file (`sysid::model`): the top n
//! rows of `A` are [A_dmd A_d], the rows below are the delay shift.

use faer::Mat;
use nalgebra::{DMatrix, DVector};

use super::error::{config, data, SysidError};
use super::gram::{cholesky_dd, feature_gram};
use super::hankel::{feature_matrix, Features, Trajectory};
use super::metrics::one_step_nmae;
use super::model::{Diagnostics, LinearModel, Offset};

/// Settings of one DMDc fit.
#[derive(Clone, Debug, PartialEq)]
pub struct DmdcSettings {
    /// Number of stacked frames q (≥ 1).
    pub delays: usize,
    /// SVD truncation rank p; `None` = full rank (n·q + m (+1)).
    pub rank: Option<usize>,
    /// Offset handling.
    pub offset: Offset,
    /// Sample time of the data and the model [s].
    pub dt: f64,
}

impl Default for DmdcSettings {
    fn default() -> Self {
        Self {
            delays: super::settings::DEFAULT_DELAYS,
            rank: None,
            offset: Offset::Affine,
            dt: super::settings::DEFAULT_DT,
        }
    }
}

/// The QR of the regression data for every q ≤ q_max (see module docs).
pub struct DmdcBasis {
    n: usize,
    m: usize,
    q_max: usize,
    affine: bool,
    input_mean: Vec<f64>,
    /// Upper-triangular R of the thin QR of F, C × C.
    r: Mat<f64>,
    /// Regression columns (samples) w.
    samples: usize,
}

/// SVD of Ω for one q, ready to produce G for any rank p.
pub struct DmdcSvd {
    /// Feature layout of this q.
    pub features: Features,
    /// Left singular vectors U (r × r), rows in feature order.
    pub u: Mat<f64>,
    /// Singular values σ, descending.
    pub sigma: Vec<f64>,
    /// T = X' V (n × r): column i is S_qᵀ w_i.
    t: Mat<f64>,
    /// Number of singular values above the numerical-rank tolerance.
    pub numerical_rank: usize,
}

impl DmdcBasis {
    /// Factor the training data for all delay counts up to `q_max`.
    pub fn new(traj: &Trajectory<'_>, q_max: usize, offset: Offset) -> Result<Self, SysidError> {
        if q_max == 0 {
            return Err(config("delays must be at least 1"));
        }
        let (n, m) = (traj.n, traj.m);
        let affine = offset == Offset::Affine;
        let cols = m + usize::from(affine) + n * q_max + n;
        // Need at least as many samples as unknowns per output row.
        traj.require(q_max, cols)?;
        let input_mean = if offset == Offset::Mean {
            traj.input_mean()
        } else {
            vec![0.0; m]
        };
        let samples = traj.len - q_max;
        let r = triangular_factor(traj, q_max, affine, &input_mean);
        Ok(Self {
            n,
            m,
            q_max,
            affine,
            input_mean,
            r,
            samples,
        })
    }

    /// A basis from a triangular factor R (C × C, RᵀR the Gram of the feature columns in the
    /// order of `hankel::feature_matrix`) computed elsewhere, e.g. the online estimator's.
    pub(crate) fn from_factor(
        r: Mat<f64>,
        n: usize,
        m: usize,
        q_max: usize,
        affine: bool,
        input_mean: Vec<f64>,
        samples: usize,
    ) -> Self {
        Self {
            n,
            m,
            q_max,
            affine,
            input_mean,
            r,
            samples,
        }
    }

    /// Largest q this basis serves.
    pub fn q_max(&self) -> usize {
        self.q_max
    }

    /// Number of regression samples w.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// Input mean subtracted from u (zeros unless the offset is `mean`).
    pub fn input_mean(&self) -> &[f64] {
        &self.input_mean
    }

    /// The SVD of Ω for `q` delays (q ≤ q_max).
    pub fn svd(&self, q: usize) -> Result<DmdcSvd, SysidError> {
        if q == 0 || q > self.q_max {
            return Err(config(format!("delays {q} outside 1..={}", self.q_max)));
        }
        let features = Features {
            n: self.n,
            m: self.m,
            q,
            affine: self.affine,
        };
        let rq = features.rows();
        let total = self.r.ncols();
        // R_qᵀ (r × r, lower triangular) and S_q (r × n).
        let rt = Mat::<f64>::from_fn(rq, rq, |i, j| self.r[(j, i)]);
        let svd = rt
            .thin_svd()
            .map_err(|e| SysidError::Identification(format!("SVD did not converge: {e:?}")))?;
        let u = svd.U().to_owned();
        let w = svd.V();
        let sigma: Vec<f64> = (0..rq).map(|i| svd.S()[i]).collect();
        // T = S_qᵀ W: (n × r).
        let mut t = Mat::<f64>::zeros(self.n, rq);
        for s in 0..self.n {
            let col = total - self.n + s;
            for i in 0..rq {
                let mut acc = 0.0;
                for k in 0..rq {
                    acc += self.r[(k, col)] * w[(k, i)];
                }
                t[(s, i)] = acc;
            }
        }
        let tol =
            sigma.first().copied().unwrap_or(0.0) * f64::EPSILON * (self.samples.max(rq) as f64);
        let numerical_rank = sigma.iter().take_while(|s| **s > tol).count();
        Ok(DmdcSvd {
            features,
            u,
            sigma,
            t,
            numerical_rank,
        })
    }
}

/// Upper-triangular R with Rᵀ R = Fᵀ F (R of the thin QR of F, up to row signs).
///
/// Main path (`gram`): the Gram FᵀF in double-double by the block-Hankel sliding-window
/// recurrence, then a double-double Cholesky — O(N·C·(n+m+1) + C³) and accurate for
/// cond(F) up to ≈ 1e14 (see the module doc). When the regressor columns are numerically
/// rank deficient the Cholesky declines and the Householder QR of F (faer) is used.
/// Row signs of R do not matter: U, Σ and X'V of the SVD below are invariant to them.
fn triangular_factor(
    traj: &Trajectory<'_>,
    q_max: usize,
    affine: bool,
    input_mean: &[f64],
) -> Mat<f64> {
    let g = feature_gram(traj, q_max, affine, input_mean);
    let c = traj.m + usize::from(affine) + traj.n * q_max + traj.n;
    if let Some(r) = cholesky_dd(&g, c, traj.n) {
        return Mat::from_fn(c, c, |i, j| r[i * c + j]);
    }
    householder_r(traj, q_max, affine, input_mean)
}

/// R of the Householder QR of the feature matrix (the reference and the fallback).
pub(crate) fn householder_r(
    traj: &Trajectory<'_>,
    q_max: usize,
    affine: bool,
    input_mean: &[f64],
) -> Mat<f64> {
    feature_matrix(traj, q_max, affine, input_mean)
        .qr()
        .thin_R()
        .to_owned()
}

impl DmdcSvd {
    /// Number of features r.
    pub fn rows(&self) -> usize {
        self.features.rows()
    }

    /// Add modes p0..p1 to `g` (n × r, feature order): G_p = Σ_{i<p} (t_i/σ_i) u_iᵀ.
    ///
    /// Modes at or beyond the numerical rank are skipped (pseudo-inverse convention).
    pub fn accumulate(&self, g: &mut Mat<f64>, p0: usize, p1: usize) {
        let r = self.rows();
        for i in p0..p1.min(self.numerical_rank) {
            let inv = 1.0 / self.sigma[i];
            for s in 0..self.features.n {
                let coef = self.t[(s, i)] * inv;
                for j in 0..r {
                    g[(s, j)] += coef * self.u[(j, i)];
                }
            }
        }
    }

    /// G for rank p (n × r, feature order).
    pub fn g(&self, p: usize) -> Mat<f64> {
        let mut g = Mat::<f64>::zeros(self.features.n, self.rows());
        self.accumulate(&mut g, 0, p);
        g
    }
}

/// Top rows of a delay model from G in feature order: (A_top n × nq newest first, B_top, c_top).
pub(crate) fn split_g(g: &Mat<f64>, f: &Features) -> (DMatrix<f64>, DMatrix<f64>, DVector<f64>) {
    let (n, m, q) = (f.n, f.m, f.q);
    let lead = m + usize::from(f.affine);
    let a_top = DMatrix::from_fn(n, n * q, |i, j| g[(i, lead + j)]);
    let b_top = DMatrix::from_fn(n, m, |i, j| g[(i, j)]);
    let c_top = DVector::from_fn(n, |i, _| if f.affine { g[(i, m)] } else { 0.0 });
    (a_top, b_top, c_top)
}

/// Assemble the full delay-form model from its dense top rows (lower rows = shift).
#[allow(clippy::too_many_arguments)]
pub fn delay_form(
    method: &str,
    dt: f64,
    q: usize,
    rank: usize,
    offset: Offset,
    input_mean: Vec<f64>,
    a_top: &DMatrix<f64>,
    b_top: &DMatrix<f64>,
    c_top: &DVector<f64>,
) -> LinearModel {
    let (n, m) = (a_top.nrows(), b_top.ncols());
    let nz = n * q;
    let mut a = DMatrix::<f64>::zeros(nz, nz);
    a.view_mut((0, 0), (n, nz)).copy_from(a_top);
    for i in n..nz {
        a[(i, i - n)] = 1.0;
    }
    let mut b = DMatrix::<f64>::zeros(nz, m);
    b.view_mut((0, 0), (n, m)).copy_from(b_top);
    let mut c = DVector::<f64>::zeros(nz);
    c.rows_mut(0, n).copy_from(c_top);
    LinearModel {
        method: method.to_string(),
        dt,
        delays: q,
        rank,
        states: (0..n).map(|i| format!("x{i}")).collect(),
        inputs: (0..m).map(|j| format!("u{j}")).collect(),
        offset,
        input_mean,
        a,
        b,
        c,
        fingerprint: String::new(),
        diagnostics: Diagnostics::default(),
    }
}

/// Fit one DMDc model (eq. 4.9–4.15) to a trajectory sampled at `settings.dt`.
pub fn fit(traj: &Trajectory<'_>, settings: &DmdcSettings) -> Result<LinearModel, SysidError> {
    if !(settings.dt.is_finite() && settings.dt > 0.0) {
        return Err(config(format!("dt must be positive, not {}", settings.dt)));
    }
    let q = settings.delays;
    let basis = DmdcBasis::new(traj, q, settings.offset)?;
    let svd = basis.svd(q)?;
    let full = svd.rows();
    let p = settings.rank.unwrap_or(full);
    if p == 0 || p > full {
        return Err(config(format!(
            "rank {p} outside 1..={full} (n·q + m{} for q = {q})",
            if settings.offset == Offset::Affine {
                " + 1"
            } else {
                ""
            }
        )));
    }
    if svd.numerical_rank == 0 {
        return Err(data(
            "the data matrix is zero: states and inputs never vary",
        ));
    }
    let g = svd.g(p);
    let (a_top, b_top, c_top) = split_g(&g, &svd.features);
    let mut model = delay_form(
        "dmdc",
        settings.dt,
        q,
        p,
        settings.offset,
        basis.input_mean().to_vec(),
        &a_top,
        &b_top,
        &c_top,
    );
    model.fingerprint = traj.fingerprint();
    model.diagnostics.singular_values = svd.sigma.clone();
    model.diagnostics.fit_nmae = Some(one_step_nmae(&model, traj)?);
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Noise-free smooth flight (nonlinear pendulum, lagged vehicle, PID, RK4) like the bench.
    fn smooth_flight(samples: usize) -> (Vec<f64>, Vec<f64>) {
        let refs = [1.2, 0.3, 2.5, -1.0, 1.7, 0.0, 2.9, 0.8];
        crate::testing::smooth_pendulum_flight(samples, 0.03, |k| refs[(k / 523) % refs.len()])
    }

    fn singular_values(r: &Mat<f64>, k: usize) -> Vec<f64> {
        let block = Mat::<f64>::from_fn(k, k, |i, j| r[(i, j)]);
        block.singular_values().unwrap()
    }

    /// The double-double Gram + Cholesky factor matches faer's Householder R on
    /// ill-conditioned (cond ≈ 1e8) smooth data: singular values of the regressor block,
    /// and G at full rank and at p = 40.
    #[test]
    fn gram_factor_matches_householder_on_ill_conditioned_data() {
        let (x, u) = smooth_flight(4000);
        let traj = Trajectory::new(&x, 2, &u, 1).unwrap();
        compare_with_householder(&traj, 1e7);
    }

    /// The same check on recorded data: a CSV of rows `x0,x1,u` named by the environment
    /// variable `SWINGRT_DMDC_DATA` (e.g. the `swingrt bench` training flight).
    #[test]
    #[ignore = "needs SWINGRT_DMDC_DATA"]
    fn gram_factor_matches_householder_on_file_data() {
        let path = std::env::var("SWINGRT_DMDC_DATA").expect("set SWINGRT_DMDC_DATA");
        let text = std::fs::read_to_string(path).unwrap();
        let (mut x, mut u) = (Vec::new(), Vec::new());
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let v: Vec<f64> = line.split(',').map(|t| t.trim().parse().unwrap()).collect();
            x.extend([v[0], v[1]]);
            u.push(v[2]);
        }
        let traj = Trajectory::new(&x, 2, &u, 1).unwrap();
        compare_with_householder(&traj, 1.0);
    }

    fn compare_with_householder(traj: &Trajectory<'_>, min_cond: f64) {
        let traj = traj.clone();
        for offset in [Offset::Affine, Offset::Mean] {
            let basis = DmdcBasis::new(&traj, 50, offset).unwrap();
            let reference = DmdcBasis {
                r: householder_r(&traj, 50, basis.affine, &basis.input_mean),
                input_mean: basis.input_mean.clone(),
                ..basis
            };
            let basis = DmdcBasis::new(&traj, 50, offset).unwrap();
            let c = basis.r.ncols() - 2;
            let (sa, sb) = (
                singular_values(&basis.r, c),
                singular_values(&reference.r, c),
            );
            let cond = sb[0] / sb[c - 1];
            eprintln!("{offset:?}: cond(F regressors) = {cond:.3e}");
            assert!(
                cond > min_cond,
                "test data should be ill conditioned, cond {cond:e}"
            );
            let mut worst = 0.0_f64;
            for i in 0..c {
                if sb[i] > 1e-10 * sb[0] {
                    worst = worst.max((sa[i] - sb[i]).abs() / sb[i]);
                }
            }
            eprintln!("  max relative singular value difference {worst:.3e}");
            assert!(worst < 1e-8, "singular values differ by {worst:e}");
            for q in [50, 20] {
                let (ga, gb) = (basis.svd(q).unwrap(), reference.svd(q).unwrap());
                for p in [ga.rows(), 40.min(ga.rows())] {
                    let (a, b) = (ga.g(p), gb.g(p));
                    let scale = b.norm_max();
                    let diff = (&a - &b).norm_max() / scale;
                    // Householder's own backward error u‖F‖ moves G_p by ≈ u·σ₁/σ_p
                    // (relative); the comparison cannot be sharper than that.
                    let kappa = gb.sigma[0] / gb.sigma[p - 1];
                    let bound = 1e-8_f64.max(10.0 * f64::EPSILON * kappa);
                    eprintln!(
                        "  q {q} p {p}: max |ΔG| / max |G| = {diff:.3e} (σ₁/σ_p = {kappa:.2e}, bound {bound:.1e})"
                    );
                    assert!(diff < bound, "G differs by {diff:e} at q {q} p {p}");
                }
            }
        }
    }
}
