//! Time series and delay embedding (thesis eq. 4.9, 4.11, 4.16, 4.18).
//!
//! A [`Trajectory`] holds N samples of n states and m inputs, time-major
//! (`x[k·n + i]` is state i at sample k), already resampled to the model's sample time.
//! The delay-embedded state of frame k with q delays is
//! z_k = [x_k; x_{k−1}; …; x_{k−q+1}] (newest first, as in the model file, `sysid::model`); the thesis's d_k (4.9) is
//! the part below x_k, and its a_k (4.16) is the same stack oldest first.
//! [`feature_matrix`] builds the regression data Ω = [X; X_d; Υ] (4.11–4.13), transposed
//! so that each row is one time sample.

use faer::Mat;

use super::error::{data, SysidError};

/// A uniformly sampled multivariate time series of states and inputs (borrowed).
#[derive(Clone, Debug)]
pub struct Trajectory<'a> {
    /// States, time-major: `x[k·n + i]`.
    pub x: &'a [f64],
    /// Inputs, time-major: `u[k·m + j]`.
    pub u: &'a [f64],
    /// Number of states n.
    pub n: usize,
    /// Number of inputs m.
    pub m: usize,
    /// Number of samples N.
    pub len: usize,
}

impl<'a> Trajectory<'a> {
    /// Wrap time-major state and input buffers; checks shapes and finiteness.
    pub fn new(x: &'a [f64], n: usize, u: &'a [f64], m: usize) -> Result<Self, SysidError> {
        if n == 0 {
            return Err(data("at least one state is needed"));
        }
        if m == 0 {
            return Err(data("at least one input is needed"));
        }
        if x.len() % n != 0 {
            return Err(data(format!(
                "state buffer of {} values is not a multiple of {n} states",
                x.len()
            )));
        }
        let len = x.len() / n;
        if u.len() != len * m {
            return Err(data(format!(
                "{} state samples but {} input samples",
                len,
                u.len() as f64 / m as f64
            )));
        }
        if let Some(k) = x.iter().position(|v| !v.is_finite()) {
            return Err(data(format!(
                "state {} is not finite at sample {}",
                k % n,
                k / n
            )));
        }
        if let Some(k) = u.iter().position(|v| !v.is_finite()) {
            return Err(data(format!(
                "input {} is not finite at sample {}",
                k % m,
                k / m
            )));
        }
        Ok(Self { x, u, n, m, len })
    }

    /// State vector at sample k.
    pub fn state(&self, k: usize) -> &'a [f64] {
        &self.x[k * self.n..(k + 1) * self.n]
    }

    /// Input vector at sample k.
    pub fn input(&self, k: usize) -> &'a [f64] {
        &self.u[k * self.m..(k + 1) * self.m]
    }

    /// Samples k0..k1 as a new trajectory (k0 < k1 ≤ N).
    pub fn slice(&self, k0: usize, k1: usize) -> Trajectory<'a> {
        Trajectory {
            x: &self.x[k0 * self.n..k1 * self.n],
            u: &self.u[k0 * self.m..k1 * self.m],
            n: self.n,
            m: self.m,
            len: k1 - k0,
        }
    }

    /// Mean of every input over the whole trajectory.
    pub fn input_mean(&self) -> Vec<f64> {
        let mut mean = vec![0.0; self.m];
        for k in 0..self.len {
            for (acc, v) in mean.iter_mut().zip(self.input(k)) {
                *acc += v;
            }
        }
        mean.iter_mut().for_each(|v| *v /= self.len.max(1) as f64);
        mean
    }

    /// A 64-bit FNV-1a hash of shapes and values (hex), identifying the training data.
    pub fn fingerprint(&self) -> String {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |bytes: &[u8]| {
            for b in bytes {
                h ^= u64::from(*b);
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        };
        eat(&(self.n as u64).to_le_bytes());
        eat(&(self.m as u64).to_le_bytes());
        eat(&(self.len as u64).to_le_bytes());
        for v in self.x.iter().chain(self.u) {
            eat(&v.to_bits().to_le_bytes());
        }
        format!("fnv1a64:{h:016x}")
    }

    /// Check that there are enough samples for `q` delays and `min_cols` regression columns.
    pub fn require(&self, q: usize, min_cols: usize) -> Result<(), SysidError> {
        if q == 0 {
            return Err(super::error::config("delays must be at least 1"));
        }
        let need = q + min_cols;
        if self.len < need {
            return Err(data(format!(
                "{} samples are too few for {q} delays: at least {need} are needed",
                self.len
            )));
        }
        Ok(())
    }
}

/// Layout of the regression features of one delay count q.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Features {
    /// States n.
    pub n: usize,
    /// Inputs m.
    pub m: usize,
    /// Delays q.
    pub q: usize,
    /// Whether a constant-1 feature is appended (affine offset).
    pub affine: bool,
}

impl Features {
    /// Number of features r = n·q + m (+1 when affine).
    pub fn rows(&self) -> usize {
        self.n * self.q + self.m + usize::from(self.affine)
    }
}

/// Regression data of eq. 4.11–4.13, one row per time sample, in QR-friendly column order.
///
/// Rows are the samples k = first..N−1 (first = `q_max − 1`, so that every q ≤ q_max uses
/// the same samples). Columns: the m inputs (minus `input_mean`), the constant 1 when
/// `affine`, then x_k, x_{k−1}, …, x_{k−q_max+1}, and finally the target x_{k+1}
/// (n columns). Putting inputs and the constant first makes every q ≤ q_max a column
/// prefix, so one QR of this matrix serves every q (see `dmdc`).
pub fn feature_matrix(
    traj: &Trajectory<'_>,
    q_max: usize,
    affine: bool,
    input_mean: &[f64],
) -> Mat<f64> {
    let (n, m) = (traj.n, traj.m);
    let first = q_max - 1;
    let rows = traj.len - 1 - first;
    let lead = m + usize::from(affine);
    let cols = lead + n * q_max + n;
    let mut out = Mat::<f64>::zeros(rows, cols);
    for j in 0..m {
        for (r, v) in out.col_as_slice_mut(j).iter_mut().enumerate() {
            *v = traj.u[(first + r) * m + j] - input_mean[j];
        }
    }
    if affine {
        out.col_as_slice_mut(m).fill(1.0);
    }
    for lag in 0..=q_max {
        // lag == q_max encodes the target x_{k+1}; others x_{k−lag}.
        for i in 0..n {
            let c = if lag == q_max {
                lead + n * q_max + i
            } else {
                lead + lag * n + i
            };
            for (r, v) in out.col_as_slice_mut(c).iter_mut().enumerate() {
                let k = first + r;
                let t = if lag == q_max { k + 1 } else { k - lag };
                *v = traj.x[t * n + i];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feature_matrix_layout() {
        // n = 1, m = 1: x_k = k, u_k = 10 k.
        let x: Vec<f64> = (0..6).map(|k| k as f64).collect();
        let u: Vec<f64> = (0..6).map(|k| 10.0 * k as f64).collect();
        let traj = Trajectory::new(&x, 1, &u, 1).unwrap();
        let f = feature_matrix(&traj, 2, true, &[5.0]);
        // Samples k = 1..4; columns [u − 5, 1, x_k, x_{k−1}, x_{k+1}].
        assert_eq!(f.nrows(), 4);
        for r in 0..4 {
            let k = (r + 1) as f64;
            let row: Vec<f64> = (0..5).map(|c| f[(r, c)]).collect();
            assert_eq!(row, vec![10.0 * k - 5.0, 1.0, k, k - 1.0, k + 1.0]);
        }
    }

    #[test]
    fn fingerprint_changes_with_data() {
        let x = [1.0, 2.0];
        let u = [0.0];
        let a = Trajectory::new(&x, 2, &u, 1).unwrap().fingerprint();
        let y = [1.0, 2.0000001];
        let b = Trajectory::new(&y, 2, &u, 1).unwrap().fingerprint();
        assert_ne!(a, b);
        assert!(a.starts_with("fnv1a64:"));
    }
}
