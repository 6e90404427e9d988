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
        })
    }

    /// Filter gain L (nx × ny).
    pub fn gain(&self) -> &DMatrix<f64> {
        &self.gain
    }

    /// A-priori steady-state covariance P (nx × nx).
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.p
    }

    /// Overwrite the a-priori estimate (used on reset).
    pub fn set_prior(&mut self, xi: &[f64]) {
        self.prior.copy_from_slice(xi);
        self.post.copy_from_slice(xi);
    }

    /// Measurement update with y (its first ny entries are the measurement); returns the a-posteriori estimate ξ̂_{k|k}.
    pub fn correct(&mut self, y: &DVector<f64>) -> &DVector<f64> {
        for i in 0..self.ny {
            self.innov[i] = y[i] - self.prior[i];
        }
        self.post.copy_from(&self.prior);
        self.post.gemv(1.0, &self.gain, &self.innov, 1.0);
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
