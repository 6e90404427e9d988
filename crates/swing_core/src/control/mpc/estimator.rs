//! Steady-state Kalman filter of the disturbance-augmented model (thesis 5.4.4, eq. 5.32–5.34).
//!
//! Model (ξ = [z; s⁻; d], the MPC's augmented state):
//! ξ_{k+1} = A ξ_k + B u_k + c̃ + w_k,  y_k = C ξ_k + v_k,  C = [I_ny 0],
//! w ~ N(0, W), v ~ N(0, V). The MPC measures only the newest frame (ny = n states): the
//! older frames of the delay stack are the same measurements shifted, not new ones, so W is
//! zero on them (the shift is exact) and the filter smooths the whole history from the
//! stream of newest frames. The a-priori covariance P solves the filter DARE
//! P = A P Aᵀ − A P Cᵀ (C P Cᵀ + V)⁻¹ C P Aᵀ + W (the dual of the control DARE, solved by
//! [`crate::linalg::dare`] on (Aᵀ, Cᵀ, W, V)); the filter gain is
//! L = P Cᵀ (C P Cᵀ + V)⁻¹. Each tick: ξ̂_{k|k} = ξ̂_{k|k−1} + L (y_k − C ξ̂_{k|k−1}), and after
//! the input is chosen ξ̂_{k+1|k} = A ξ̂_{k|k} + B u_k + c̃. Both steps are matrix–vector
//! products into preallocated buffers (no allocation per tick). Most rows of A only copy
//! one entry (the delay shift, the lagged swings, the constant disturbances): they are
//! found once and the prediction copies them, so its cost is that of the few dense rows
//! (the newest frame, a position), not of the whole square A.
//!
//! The start. When the controller takes over, the delay stack is a guess (every frame the
//! current measurement): a swing the payload already has is in it at one phase only, and
//! the steady gain, designed for an estimate as good as the filter's own, would learn the
//! rest as slowly as it learns any process noise; the slower the more it trusts the model
//! over the measurement. [`SteadyStateKalman::with_start`] gives the filter a prior that
//! says so, P₀ = P + Σ₀ (Σ₀ diagonal: the spread of the guess), and precomputes the
//! time-varying gains L_k = P_k Cᵀ (C P_k Cᵀ + V)⁻¹ of the Riccati recursion
//! P_{k+1} = A (P_k − L_k C P_k) Aᵀ + W from it, for a given number of ticks or until they
//! are within a tolerance of the steady L. A tick of the start costs what a steady tick
//! costs (another stored matrix in the same product); the recursion runs once, at design,
//! with A applied by its copy and dense rows (O(d·nx²) per step for d dense rows).

use nalgebra::{DMatrix, DVector};

use crate::control::ControlError;
use crate::linalg::dare;

/// A steady-state (constant-gain) Kalman filter with measured block C = [I_ny 0].
#[derive(Clone, Debug)]
pub struct SteadyStateKalman {
    gain: DMatrix<f64>,
    p: DMatrix<f64>,
    ny: usize,
    prior: DVector<f64>,
    post: DVector<f64>,
    innov: DVector<f64>,
    /// Rows of A that copy one entry of ξ unchanged: (row, source).
    copies: Vec<(usize, usize)>,
    /// The other rows, their A, B and c̃ rows, and a buffer for their values.
    dense_rows: Vec<usize>,
    a_dense: DMatrix<f64>,
    b_dense: DMatrix<f64>,
    c_dense: DVector<f64>,
    dense_values: DVector<f64>,
    /// Gains of the start (module docs), first tick first; empty: steady from the start.
    start_gains: Vec<DMatrix<f64>>,
    /// The process and measurement covariances the filter was designed with.
    w: DMatrix<f64>,
    v: DMatrix<f64>,
    /// Corrections made since the last [`SteadyStateKalman::restart`].
    tick: usize,
}

/// Rows of (A, B, c̃) that copy one entry of the state (a single 1 in A, nothing else) as
/// (row, source), and the other rows.
fn split_rows(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &DVector<f64>,
) -> (Vec<(usize, usize)>, Vec<usize>) {
    let mut copies = Vec::new();
    let mut dense = Vec::new();
    for r in 0..a.nrows() {
        let nonzero: Vec<usize> = (0..a.ncols()).filter(|&j| a[(r, j)] != 0.0).collect();
        let is_copy = nonzero.len() == 1
            && a[(r, nonzero[0])] == 1.0
            && c[r] == 0.0
            && b.row(r).iter().all(|x| *x == 0.0);
        if is_copy {
            copies.push((r, nonzero[0]));
        } else {
            dense.push(r);
        }
    }
    (copies, dense)
}

impl SteadyStateKalman {
    /// Design the filter for ξ⁺ = Aξ + Bu + c̃, y = ξ[0..ny], with process covariance `w`
    /// and measurement covariance `v`.
    pub fn new(
        a: DMatrix<f64>,
        b: DMatrix<f64>,
        c_tilde: DVector<f64>,
        ny: usize,
        w: &DMatrix<f64>,
        v: &DMatrix<f64>,
    ) -> Result<Self, ControlError> {
        let nx = a.nrows();
        if ny == 0 || ny > nx || b.nrows() != nx || c_tilde.len() != nx {
            return Err(ControlError::Model(format!(
                "Kalman filter: inconsistent dimensions (nx = {nx}, ny = {ny}, B {}×{}, c {})",
                b.nrows(),
                b.ncols(),
                c_tilde.len()
            )));
        }
        let mut c = DMatrix::<f64>::zeros(ny, nx);
        for i in 0..ny {
            c[(i, i)] = 1.0;
        }
        let sol = dare(&a.transpose(), &c.transpose(), w, v)
            .map_err(|e| ControlError::Synthesis(format!("Kalman filter: {e}")))?;
        let p = sol.p;
        let s = p.view((0, 0), (ny, ny)) + v;
        let pct = p.view((0, 0), (nx, ny)).into_owned();
        // L = P Cᵀ S⁻¹ ⇔ S Lᵀ = C P (S symmetric).
        let lt = s
            .cholesky()
            .ok_or_else(|| {
                ControlError::Synthesis(
                    "Kalman filter: innovation covariance not positive definite".into(),
                )
            })?
            .solve(&pct.transpose());
        let gain = lt.transpose();
        let (copies, dense_rows) = split_rows(&a, &b, &c_tilde);
        let a_dense = a.select_rows(dense_rows.iter());
        let b_dense = b.select_rows(dense_rows.iter());
        let c_dense = c_tilde.select_rows(dense_rows.iter());
        Ok(Self {
            dense_values: DVector::zeros(dense_rows.len()),
            copies,
            dense_rows,
            a_dense,
            b_dense,
            c_dense,
            prior: DVector::zeros(nx),
            post: DVector::zeros(nx),
            innov: DVector::zeros(ny),
            gain,
            p,
            ny,
            start_gains: Vec::new(),
            w: w.clone(),
            v: v.clone(),
            tick: 0,
        })
    }

    /// This filter with a start (module docs): after [`Self::restart`] its gains are those
    /// of the prior P₀ = P + diag(`spread`) (`spread`: the variance of the restart's guess of
    /// each state), for at most `max_ticks` ticks and until every entry is within `tol`
    /// × the largest |entry| of the steady gain; all zeros keeps the steady gain.
    pub fn with_start(
        mut self,
        spread: &[f64],
        max_ticks: usize,
        tol: f64,
    ) -> Result<Self, ControlError> {
        let nx = self.p.nrows();
        let ny = self.ny;
        if spread.len() != nx || spread.iter().any(|s| !(s.is_finite() && *s >= 0.0)) {
            return Err(ControlError::Model(format!(
                "Kalman filter start: the spread needs {nx} finite variances ≥ 0 (got {} entries)",
                spread.len()
            )));
        }
        self.start_gains.clear();
        if spread.iter().all(|s| *s == 0.0) {
            return Ok(self);
        }
        let (w, v) = (self.w.clone(), self.v.clone());
        let scale = self.gain.amax().max(f64::MIN_POSITIVE);
        let mut p = self.p.clone();
        for (i, s) in spread.iter().enumerate() {
            p[(i, i)] += s;
        }
        for _ in 0..max_ticks {
            let s = p.view((0, 0), (ny, ny)) + &v;
            let cp = p.rows(0, ny).into_owned();
            let lt = s
                .cholesky()
                .ok_or_else(|| {
                    ControlError::Synthesis(
                        "Kalman filter start: innovation covariance not positive definite".into(),
                    )
                })?
                .solve(&cp);
            let gain = lt.transpose();
            if (&gain - &self.gain).amax() <= tol * scale {
                break;
            }
            let post = &p - &gain * &cp;
            p = self.a_sandwich(&post) + &w;
            // Round-off keeps P symmetric only to the last bits; the recursion needs it exact.
            p = (&p + p.transpose()) * 0.5;
            self.start_gains.push(gain);
        }
        Ok(self)
    }

    /// A X Aᵀ for a symmetric X, with A applied by its copy and dense rows.
    fn a_sandwich(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        let ax = self.a_times(x);
        self.a_times(&ax.transpose())
    }

    /// A X (X with nx rows), from the copy rows and the dense rows of A.
    fn a_times(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(x.nrows(), x.ncols());
        for &(r, src) in &self.copies {
            out.row_mut(r).copy_from(&x.row(src));
        }
        let dense = &self.a_dense * x;
        for (k, &r) in self.dense_rows.iter().enumerate() {
            out.row_mut(r).copy_from(&dense.row(k));
        }
        out
    }

    /// Number of start gains (0: the filter is steady from its first tick).
    pub fn start_ticks(&self) -> usize {
        self.start_gains.len()
    }

    /// The gain of the start's tick `k` (0 = the first correction after a restart); the
    /// steady gain from [`Self::start_ticks`] on.
    pub fn start_gain(&self, k: usize) -> &DMatrix<f64> {
        self.start_gains.get(k).unwrap_or(&self.gain)
    }

    /// Filter gain L (nx × ny).
    pub fn gain(&self) -> &DMatrix<f64> {
        &self.gain
    }

    /// A-priori steady-state covariance P (nx × nx).
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.p
    }

    /// Overwrite the a-priori estimate and go on at the steady gain (taking over an
    /// estimate as good as the filter's own).
    pub fn set_prior(&mut self, xi: &[f64]) {
        self.prior.copy_from_slice(xi);
        self.post.copy_from_slice(xi);
        self.tick = self.start_gains.len();
    }

    /// Overwrite the a-priori estimate with a guess and run the start (module docs) again.
    pub fn restart(&mut self, xi: &[f64]) {
        self.set_prior(xi);
        self.tick = 0;
    }

    /// Measurement update with y (its first ny entries are the measurement); returns the a-posteriori estimate ξ̂_{k|k}.
    pub fn correct(&mut self, y: &DVector<f64>) -> &DVector<f64> {
        for i in 0..self.ny {
            self.innov[i] = y[i] - self.prior[i];
        }
        self.post.copy_from(&self.prior);
        let gain = self.start_gains.get(self.tick).unwrap_or(&self.gain);
        self.post.gemv(1.0, gain, &self.innov, 1.0);
        self.tick = (self.tick + 1).min(self.start_gains.len());
        &self.post
    }

    /// Replace the measured block (all of `y`: the measured delay stack) of the a-posteriori
    /// estimate by the measurement itself
    /// (after [`Self::correct`]): the state is then the measured delay stack and only the
    /// disturbances are estimated, from the one-step residual of the newest frame.
    pub fn hold_measured(&mut self, y: &DVector<f64>) {
        let k = y.len().min(self.post.len());
        self.post.rows_mut(0, k).copy_from(&y.rows(0, k));
    }

    /// Time update with the applied input u: ξ̂_{k+1|k} = A ξ̂_{k|k} + B u + c̃ (copy rows
    /// copied, dense rows multiplied; module docs).
    pub fn predict(&mut self, u: &DVector<f64>) {
        self.dense_values.copy_from(&self.c_dense);
        self.dense_values.gemv(1.0, &self.a_dense, &self.post, 1.0);
        self.dense_values.gemv(1.0, &self.b_dense, u, 1.0);
        for &(r, src) in &self.copies {
            self.prior[r] = self.post[src];
        }
        for (k, &r) in self.dense_rows.iter().enumerate() {
            self.prior[r] = self.dense_values[k];
        }
    }

    /// The current a-posteriori estimate ξ̂_{k|k}.
    pub fn estimate(&self) -> &DVector<f64> {
        &self.post
    }
}
