//! HAVOKc: Hankel alternative view of Koopman with control (thesis eq. 4.16–4.23).
//!
//! The extended state a_k = [x_{k−q+1}; …; x_{k−1}; x_k] (4.16, oldest first) obeys
//! a_{k+1} = A_H a_k + B_H u_k (4.17). The Hankel matrix with the inputs appended,
//! Π = [a_q … a_{w+q−1}; u_q … u_{w+q−1}] (4.18) (plus a constant-1 row for the affine
//! offset), is truncated to rank p: Π ≈ Ũ Σ̃ Ṽᵀ (4.19). The rows of Ṽ are the pseudo-state
//! v_k; the best-fit v_{k+1} = Λ v_k (4.20) over V₁ = [v_q … v_{w−1}], V₂ = [v_{q+1} … v_w]
//! (4.21) is Λ = V₂ V₁⁺ (4.22 — the thesis prints V₁V₁⁺, a slip). Mapped back,
//! [a_{k+1}; u_{k+1}] ≈ (ŨΣ̃) Λ (ŨΣ̃)⁺ [a_k; u_k] (4.23), with (ŨΣ̃)⁺ = Σ̃⁻¹Ũᵀ.
//! A_H, B_H (and c) are the rows of that matrix belonging to a_{k+1} (figure 4.3); the
//! rows mapping u_k → u_{k+1} are discarded.
//!
//! Figure 4.4: the first (q−1)·n rows of A_H only shift the delay frames, so they are
//! forced to exactly 0/1 and the same rows of B_H and c to 0. Only the last n rows
//! (x_{k+1}) stay fitted. The result is re-ordered newest first into the common delay form
//! of the model file (`sysid::model`). Since V₁V₁ᵀ = I − v_w v_wᵀ (Ṽ has orthonormal columns), Λ needs only a
//! p × p solve.

use faer::Mat;
use nalgebra::{DMatrix, DVector};

use super::dmdc::delay_form;
use super::error::{config, data, SysidError};
use super::hankel::Trajectory;
use super::metrics::one_step_nmae;
use super::model::{LinearModel, Offset};

/// Dense top rows of a delay-form model: (A_top, B_top, c_top, largest forced change).
pub type TopRows = (DMatrix<f64>, DMatrix<f64>, DVector<f64>, f64);

/// Settings of one HAVOKc fit.
#[derive(Clone, Debug, PartialEq)]
pub struct HavokcSettings {
    /// Number of stacked frames q (≥ 1).
    pub delays: usize,
    /// SVD truncation rank p; `None` = full rank (n·q + m (+1)).
    pub rank: Option<usize>,
    /// Offset handling.
    pub offset: Offset,
    /// Sample time [s].
    pub dt: f64,
}

/// The extended model in the thesis's oldest-first coordinates (after forcing).
#[derive(Clone, Debug)]
pub struct HavokcRaw {
    /// A_H, (n·q) × (n·q), oldest-first blocks.
    pub a_h: DMatrix<f64>,
    /// B_H, (n·q) × m.
    pub b_h: DMatrix<f64>,
    /// Constant column (zeros unless affine).
    pub c_h: DVector<f64>,
    /// Largest change made by forcing the structural entries (figure 4.4).
    pub forced_max_change: f64,
}

/// SVD of the Hankel matrix Π for one q, ready to produce a model for any rank p.
pub struct HavokcSvd {
    n: usize,
    m: usize,
    q: usize,
    affine: bool,
    input_mean: Vec<f64>,
    /// Ũ of Π (r × r).
    u: Mat<f64>,
    /// Singular values, descending.
    pub sigma: Vec<f64>,
    /// Ṽ of Π (w × r), one row per sample.
    v: Mat<f64>,
    /// Number of singular values above the numerical-rank tolerance.
    pub numerical_rank: usize,
}

impl HavokcSvd {
    /// Build Π (4.18) for `q` delays and take its thin SVD (4.19).
    pub fn new(traj: &Trajectory<'_>, q: usize, offset: Offset) -> Result<Self, SysidError> {
        if q == 0 {
            return Err(config("delays must be at least 1"));
        }
        let (n, m) = (traj.n, traj.m);
        let affine = offset == Offset::Affine;
        let r = n * q + m + usize::from(affine);
        traj.require(q, r + 1)?;
        let input_mean = if offset == Offset::Mean {
            traj.input_mean()
        } else {
            vec![0.0; m]
        };
        let w = traj.len - (q - 1);
        // Πᵀ: one row per sample k = q−1 … N−1.
        let pt = Mat::<f64>::from_fn(w, r, |row, col| {
            let k = row + q - 1;
            if col < n * q {
                let (blk, s) = (col / n, col % n);
                traj.x[(k + 1 + blk - q) * n + s]
            } else if col < n * q + m {
                let j = col - n * q;
                traj.u[k * m + j] - input_mean[j]
            } else {
                1.0
            }
        });
        let svd = pt
            .thin_svd()
            .map_err(|e| SysidError::Identification(format!("SVD did not converge: {e:?}")))?;
        // Πᵀ = U' S V'ᵀ ⇒ Π = V' S U'ᵀ: Π's Ũ is V', its Ṽ is U'.
        let sigma: Vec<f64> = (0..r).map(|i| svd.S()[i]).collect();
        let tol = sigma.first().copied().unwrap_or(0.0) * f64::EPSILON * (w.max(r) as f64);
        let numerical_rank = sigma.iter().take_while(|s| **s > tol).count();
        Ok(Self {
            n,
            m,
            q,
            affine,
            input_mean,
            u: svd.V().to_owned(),
            sigma,
            v: svd.U().to_owned(),
            numerical_rank,
        })
    }

    /// Number of rows of Π.
    pub fn rows(&self) -> usize {
        self.n * self.q + self.m + usize::from(self.affine)
    }

    /// A_H, B_H, c for rank p, with the structural entries forced (eq. 4.20–4.23, fig. 4.4).
    pub fn raw(&self, p: usize) -> Result<HavokcRaw, SysidError> {
        let p = p.min(self.numerical_rank);
        if p == 0 {
            return Err(data(
                "the Hankel matrix is zero: states and inputs never vary",
            ));
        }
        let w = self.v.nrows();
        let (n, m, q, r) = (self.n, self.m, self.q, self.rows());
        // Gram = V₁ᵀV₁ = I − v_w v_wᵀ; cross = V₁ᵀ V₂ (row-sample convention: V₂ = V₁ Λᵀ).
        let mut gram = DMatrix::<f64>::identity(p, p);
        for i in 0..p {
            for j in 0..p {
                gram[(i, j)] -= self.v[(w - 1, i)] * self.v[(w - 1, j)];
            }
        }
        let mut cross = DMatrix::<f64>::zeros(p, p);
        for k in 0..w - 1 {
            for i in 0..p {
                let a = self.v[(k, i)];
                for j in 0..p {
                    cross[(i, j)] += a * self.v[(k + 1, j)];
                }
            }
        }
        let lam_t = gram.clone().lu().solve(&cross).ok_or_else(|| {
            SysidError::Identification("V₁V₁ᵀ is singular: too little data".into())
        })?;
        let lam = lam_t.transpose();
        // M = Ũ Σ Λ Σ⁻¹ Ũᵀ, only the a-rows are needed.
        let us = DMatrix::<f64>::from_fn(r, p, |i, j| self.u[(i, j)] * self.sigma[j]);
        let uinv = DMatrix::<f64>::from_fn(p, r, |i, j| self.u[(j, i)] / self.sigma[i]);
        let mfull = &us * lam * uinv;
        let nz = n * q;
        let mut a_h = mfull.view((0, 0), (nz, nz)).into_owned();
        let mut b_h = mfull.view((0, nz), (nz, m)).into_owned();
        let mut c_h = if self.affine {
            mfull.view((0, nz + m), (nz, 1)).column(0).into_owned()
        } else {
            DVector::zeros(nz)
        };
        // Figure 4.4: force the delay-shift rows.
        let mut change: f64 = 0.0;
        for i in 0..nz - n {
            for j in 0..nz {
                let want = if j == i + n { 1.0 } else { 0.0 };
                change = change.max((a_h[(i, j)] - want).abs());
                a_h[(i, j)] = want;
            }
            for j in 0..m {
                change = change.max(b_h[(i, j)].abs());
                b_h[(i, j)] = 0.0;
            }
            change = change.max(c_h[i].abs());
            c_h[i] = 0.0;
        }
        Ok(HavokcRaw {
            a_h,
            b_h,
            c_h,
            forced_max_change: change,
        })
    }

    /// Top rows (newest-first delay form) for rank p: (A_top, B_top, c_top, forced change).
    pub fn top(&self, p: usize) -> Result<TopRows, SysidError> {
        let raw = self.raw(p)?;
        let (n, m, q) = (self.n, self.m, self.q);
        let last = (q - 1) * n;
        // a-block b (oldest first) holds x_{k−(q−1−b)}: newest-first column (q−1−b)·n + s.
        let a_top = DMatrix::from_fn(n, n * q, |i, j| {
            let (lag, s) = (j / n, j % n);
            raw.a_h[(last + i, (q - 1 - lag) * n + s)]
        });
        let b_top = DMatrix::from_fn(n, m, |i, j| raw.b_h[(last + i, j)]);
        let c_top = DVector::from_fn(n, |i, _| raw.c_h[last + i]);
        Ok((a_top, b_top, c_top, raw.forced_max_change))
    }

    /// Input mean subtracted from u.
    pub fn input_mean(&self) -> &[f64] {
        &self.input_mean
    }
}

/// Fit one HAVOKc model (eq. 4.16–4.23, figure 4.4) in the common delay form.
pub fn fit(traj: &Trajectory<'_>, settings: &HavokcSettings) -> Result<LinearModel, SysidError> {
    if !(settings.dt.is_finite() && settings.dt > 0.0) {
        return Err(config(format!("dt must be positive, not {}", settings.dt)));
    }
    let q = settings.delays;
    let svd = HavokcSvd::new(traj, q, settings.offset)?;
    let full = svd.rows();
    let p = settings.rank.unwrap_or(full);
    if p == 0 || p > full {
        return Err(config(format!("rank {p} outside 1..={full} for q = {q}")));
    }
    let (a_top, b_top, c_top, change) = svd.top(p)?;
    let mut model = delay_form(
        "havokc",
        settings.dt,
        q,
        p,
        settings.offset,
        svd.input_mean().to_vec(),
        &a_top,
        &b_top,
        &c_top,
    );
    model.fingerprint = traj.fingerprint();
    model.diagnostics.singular_values = svd.sigma.clone();
    model.diagnostics.fit_nmae = Some(one_step_nmae(&model, traj)?);
    model
        .diagnostics
        .extra
        .insert("forced_max_change".into(), serde_json::json!(change));
    Ok(model)
}
