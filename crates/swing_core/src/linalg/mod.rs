//! Dense linear algebra the other layers share, at the bottom of the crate: the matrix
//! exponential, zero-order-hold discretisation, bounded eigenvalue computation and the
//! Riccati solvers ([`riccati`]). It knows nothing of vehicles, models or controllers.

pub mod riccati;

pub use riccati::{care, dare, dare_with_cross, sampled_lqr, RiccatiSolution};

use nalgebra::DMatrix;
use thiserror::Error;

use crate::error::{Categorized, Category};

/// Errors of the linear-algebra routines.
#[derive(Debug, Error)]
pub enum LinalgError {
    /// Matrices of the wrong shape or with non-finite entries, a bad period …
    #[error("model: {0}")]
    Shape(String),
    /// A well-posed problem without a (stabilising) solution.
    #[error("synthesis failed: {0}")]
    NoSolution(String),
}

impl Categorized for LinalgError {
    fn category(&self) -> Category {
        match self {
            LinalgError::Shape(_) => Category::Model,
            LinalgError::NoSolution(_) => Category::Control,
        }
    }
}

/// Largest entry magnitude [`expm`] accepts. nalgebra's `exp` squares 2^s times with s from
/// a norm of A⁸ or A¹⁰; entries near 1e31 overflow that norm to ∞, s saturates to u64::MAX
/// and the call never returns. A physical model scaled by a sample time is nowhere near.
pub const EXPM_MAX_ENTRY: f64 = 1e15;

/// Matrix exponential, or `None` for a matrix with a non-finite or huge entry (see
/// [`EXPM_MAX_ENTRY`]) instead of nalgebra's endless squaring.
pub fn expm(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    if m.iter().all(|v| v.is_finite() && v.abs() <= EXPM_MAX_ENTRY) {
        Some(m.exp())
    } else {
        None
    }
}

/// Eigenvalues of a square matrix (faer's Hessenberg–Schur QR, which bounds its sweeps), or
/// `None` when it has a non-finite entry or the iteration does not converge. faer, not
/// nalgebra's `Schur`: on the 100–200-state closed loops of the control check it is several
/// times faster, and nalgebra's `complex_eigenvalues` loops without bound on some badly
/// scaled inputs.
pub fn eigenvalues(m: &DMatrix<f64>) -> Option<Vec<nalgebra::Complex<f64>>> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let n = m.nrows();
    if n == 0 {
        return Some(Vec::new());
    }
    let ev = to_faer(m).eigenvalues().ok()?;
    Some(
        ev.iter()
            .map(|z| nalgebra::Complex::new(z.re, z.im))
            .collect(),
    )
}

/// `m` as a faer matrix.
pub(crate) fn to_faer(m: &DMatrix<f64>) -> faer::Mat<f64> {
    faer::Mat::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

/// Largest eigenvalue modulus of a square matrix (0 for an empty one), or `None` as
/// [`eigenvalues`].
pub fn spectral_radius(m: &DMatrix<f64>) -> Option<f64> {
    Some(eigenvalues(m)?.iter().map(|z| z.norm()).fold(0.0, f64::max))
}

/// Zero-order-hold discretisation of ẋ = Ax + Bu over `dt`: (A_d, B_d) = blocks of
/// exp([A B; 0 0] dt).
pub fn c2d_zoh(a: &DMatrix<f64>, b: &DMatrix<f64>, dt: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = a.nrows();
    let m = b.ncols();
    let mut f = DMatrix::<f64>::zeros(n + m, n + m);
    f.view_mut((0, 0), (n, n)).copy_from(a);
    f.view_mut((0, n), (n, m)).copy_from(b);
    // Out of range (see `expm`): NaN blocks, which every caller's finiteness check refuses.
    let e = expm(&(f * dt)).unwrap_or_else(|| DMatrix::from_element(n + m, n + m, f64::NAN));
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, m)).into_owned(),
    )
}
