//! Dense linear algebra the other layers share, at the bottom of the crate: the matrix
//! exponential, zero-order-hold discretisation, bounded eigenvalue computation, a stability
//! test by repeated squaring, the stationary covariance of a stable recursion and the Riccati
//! solvers ([`riccati`]). It knows nothing of
//! vehicles, models or controllers.

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

/// Squarings [`schur_stable`] tries before it computes the eigenvalues: 2²⁰ steps, so a
/// power settles either way unless ρ is within about 1e-5 of 1 (or a transient lasts longer).
const STABILITY_SQUARINGS: usize = 20;

/// Whether every eigenvalue of the square matrix `m` lies strictly inside the unit circle,
/// or `None` as [`eigenvalues`].
///
/// Decided by repeated squaring where that is conclusive, a few matrix products instead of
/// a Schur decomposition: ρ(M)ʲ ≤ ‖Mʲ‖₁ proves ρ < 1 once a power's norm is below ½, and
/// |tr Mʲ| ≤ n ρʲ proves ρ > 1 once a power's trace exceeds 2n (the factors of 2 are margins
/// far above the products' rounding). A matrix whose powers settle neither way within
/// [`STABILITY_SQUARINGS`] squarings falls back to the eigenvalues, so the answer is the
/// eigenvalues' wherever they are not within rounding of the unit circle.
pub fn schur_stable(m: &DMatrix<f64>) -> Option<bool> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let n = m.nrows();
    if n == 0 {
        return Some(true);
    }
    let (stable_below, unstable_above) = (0.5f64.ln(), (2.0 * n as f64).ln());
    // The power Mʲ (j = 2ᵏ) is kept as exp(log_scale) · b with ‖b‖₁ = 1: no overflow.
    let mut b = to_faer(m);
    let mut log_scale = 0.0;
    for k in 0..=STABILITY_SQUARINGS {
        if k > 0 {
            b = &b * &b;
            log_scale *= 2.0;
        }
        let norm = column_sum_norm(&b);
        if norm == 0.0 {
            return Some(true); // nilpotent
        }
        if !norm.is_finite() {
            break;
        }
        b /= faer::Scale(norm);
        log_scale += norm.ln();
        if log_scale < stable_below {
            return Some(true);
        }
        let trace: f64 = (0..n).map(|i| b[(i, i)]).sum();
        if log_scale + trace.abs().ln() > unstable_above {
            return Some(false);
        }
    }
    Some(spectral_radius(m)? < 1.0)
}

/// ‖b‖₁, the largest column sum of magnitudes.
fn column_sum_norm(b: &faer::Mat<f64>) -> f64 {
    (0..b.ncols())
        .map(|j| (0..b.nrows()).map(|i| b[(i, j)].abs()).sum::<f64>())
        .fold(0.0, f64::max)
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

/// What [`stationary_covariance`] found: the covariance, or a recursion that has none.
#[derive(Clone, Debug, PartialEq)]
pub enum Stationary {
    /// ρ(A) < 1: the stationary covariance P.
    Stable(DMatrix<f64>),
    /// ρ(A) ≥ 1: the process has no stationary covariance.
    Unstable,
}

/// Doublings [`stationary_covariance`] tries: 2⁶⁰ steps of the recursion summed.
const COVARIANCE_DOUBLINGS: usize = 60;

/// Stationary covariance P = A P Aᵀ + B Bᵀ of x⁺ = A x + B e with white unit e, when A is
/// stable, or `None` as [`eigenvalues`] (a non-finite entry, no convergence).
///
/// By doubling: P ← P + Aʲ P (Aʲ)ᵀ, Aʲ ← (Aʲ)² (j = 2ᵏ), until the increment is negligible.
/// The powers are the ones [`schur_stable`] squares, so they decide stability on the way
/// with its two certificates (‖Aʲ‖₁ < ½ proves ρ < 1, |tr Aʲ| > 2n proves ρ > 1), and the
/// eigenvalues decide only where neither fires within [`STABILITY_SQUARINGS`] doublings:
/// one pass of products instead of a stability test and then a sum. The increment is
/// symmetric, so only its lower triangle is formed.
pub fn stationary_covariance(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Option<Stationary> {
    let n = a.nrows();
    if !a.iter().chain(b.iter()).all(|v| v.is_finite()) {
        return None;
    }
    if n == 0 {
        return Some(Stationary::Stable(DMatrix::zeros(0, 0)));
    }
    use faer::linalg::matmul::triangular::{matmul, BlockStructure};
    let bf = to_faer(b);
    let mut p = &bf * bf.transpose();
    let mut ak = to_faer(a);
    let mut inc = faer::Mat::<f64>::zeros(n, n);
    let mut stable = false;
    let mut summed = false;
    for k in 0..COVARIANCE_DOUBLINGS {
        if !stable {
            let norm = column_sum_norm(&ak);
            if !norm.is_finite() {
                // Powers past f64 before either certificate: unstable by the eigenvalues,
                // else a transient too large for the sum to mean anything.
                return (spectral_radius(a)? >= 1.0).then_some(Stationary::Unstable);
            }
            let trace: f64 = (0..n).map(|i| ak[(i, i)]).sum();
            if norm < 0.5 {
                stable = true;
            } else if trace.abs() > 2.0 * n as f64 {
                return Some(Stationary::Unstable);
            } else if k == STABILITY_SQUARINGS {
                if spectral_radius(a)? >= 1.0 {
                    return Some(Stationary::Unstable);
                }
                stable = true;
            }
        }
        let t = &ak * &p;
        matmul(
            inc.as_mut(),
            BlockStructure::TriangularLower,
            faer::Accum::Replace,
            t.as_ref(),
            BlockStructure::Rectangular,
            ak.transpose(),
            BlockStructure::Rectangular,
            1.0,
            faer::Par::Seq,
        );
        let (mut inc_max, mut p_max) = (0.0_f64, 0.0_f64);
        for j in 0..n {
            for i in j..n {
                p[(i, j)] += inc[(i, j)];
                p[(j, i)] = p[(i, j)];
                inc_max = inc_max.max(inc[(i, j)].abs());
                p_max = p_max.max(p[(i, j)].abs());
            }
        }
        if stable && inc_max <= 1e-15 * p_max.max(f64::MIN_POSITIVE) {
            summed = true;
            break;
        }
        ak = &ak * &ak;
    }
    // 2⁶⁰ steps without settling: the eigenvalues decide.
    if !summed && spectral_radius(a)? >= 1.0 {
        return Some(Stationary::Unstable);
    }
    let p = DMatrix::from_fn(n, n, |i, j| p[(i, j)]);
    p.iter()
        .all(|v| v.is_finite())
        .then_some(Stationary::Stable(p))
}

/// Standard deviation of the mean of output `c x` over `window` consecutive ticks of the
/// stationary process x⁺ = A x + B e (white unit e, A stable, no feedthrough of e to the
/// output): with the lag covariances γ_k = c Aᵏ P cᵀ,
/// Var(mean) = (N γ₀ + 2 Σ_{k=1}^{N−1} (N − k) γ_k) / N².
pub fn window_mean_std(a: &DMatrix<f64>, p: &DMatrix<f64>, c: &DMatrix<f64>, window: usize) -> f64 {
    let n = window.max(1) as f64;
    // Aᵏ P cᵀ column by column, one product per lag.
    let mut w = p * c.transpose();
    let mut sum = n * (c * &w).trace();
    for k in 1..window {
        w = a * &w;
        sum += 2.0 * (n - k as f64) * (c * &w).trace();
    }
    (sum.max(0.0) / (n * n)).sqrt()
}

/// A's states split in two at `outputs`: those that reach any of the outputs through A's
/// nonzero entries (the outputs included), and the rest, each in ascending order. No state
/// of the first set is moved by the rest, so A is block triangular there: the outputs'
/// statistics are those of the first block alone, and A's eigenvalues are the two blocks'.
pub fn split_reaching(a: &DMatrix<f64>, outputs: &[usize]) -> (Vec<usize>, Vec<usize>) {
    let n = a.nrows();
    let mut reached = vec![false; n];
    let mut stack: Vec<usize> = Vec::new();
    for &i in outputs {
        if i < n && !reached[i] {
            reached[i] = true;
            stack.push(i);
        }
    }
    while let Some(i) = stack.pop() {
        for j in 0..n {
            if !reached[j] && a[(i, j)] != 0.0 {
                reached[j] = true;
                stack.push(j);
            }
        }
    }
    (0..n).partition(|&i| reached[i])
}

/// The square block of `a` on the states `idx`.
pub fn principal_block(a: &DMatrix<f64>, idx: &[usize]) -> DMatrix<f64> {
    a.select_rows(idx).select_columns(idx)
}

/// [`schur_stable`] of A split at [`split_reaching`] `seeds`: A is stable when both
/// diagonal blocks are, and two smaller blocks are squared instead of the whole (a quarter
/// of the products for two halves).
pub fn schur_stable_split(a: &DMatrix<f64>, seeds: &[usize]) -> Option<bool> {
    // A non-finite entry between the blocks would escape both: refused as the whole would be.
    if !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    let (kept, rest) = split_reaching(a, seeds);
    if rest.is_empty() {
        return schur_stable(a);
    }
    Some(schur_stable(&principal_block(a, &kept))? && schur_stable(&principal_block(a, &rest))?)
}

/// Pole of a first-order lag of time constant `tau` [s] sampled at `dt` [s] under a
/// zero-order hold, λ = exp(−dt/τ): x⁺ = λx + (1 − λ)u. 0 (no lag) for `tau` ≤ 0.
pub fn lag_factor(tau: f64, dt: f64) -> f64 {
    if tau > 0.0 {
        (-dt / tau).exp()
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;
    use rand::{RngExt, SeedableRng};

    /// A 2×2 rotation by `angle` scaled by `r`: eigenvalues r·e^{±i·angle}.
    fn rotation(r: f64, angle: f64) -> DMatrix<f64> {
        let (s, c) = angle.sin_cos();
        DMatrix::from_row_slice(2, 2, &[r * c, -r * s, r * s, r * c])
    }

    #[test]
    fn a_state_is_kept_exactly_when_it_reaches_an_output_and_stability_is_both_blocks() {
        // x0 ← x1 ← x2 (x2 reaches x0 through x1); x3 moves x0 but nothing moves x3 from the
        // kept side; x4 is moved by x0 and reaches nothing.
        let mut a = DMatrix::<f64>::zeros(5, 5);
        for (i, j, v) in [
            (0, 0, 0.5),
            (0, 1, 0.2),
            (1, 2, 0.3),
            (0, 3, 0.1),
            (3, 3, 0.4),
            (4, 0, 1.0),
            (4, 4, 0.9),
        ] {
            a[(i, j)] = v;
        }
        assert_eq!(split_reaching(&a, &[0]), (vec![0, 1, 2, 3], vec![4]));
        assert_eq!(split_reaching(&a, &[4]), ((0..5).collect(), vec![]));
        assert_eq!(split_reaching(&a, &[3]), (vec![3], vec![0, 1, 2, 4]));
        assert_eq!(split_reaching(&a, &[]), (vec![], (0..5).collect()));
        assert_eq!(schur_stable_split(&a, &[0]), Some(true));
        // A NaN below the kept block is refused, as the whole matrix's verdict refuses it.
        let mut nan = a.clone();
        nan[(4, 1)] = f64::NAN;
        assert_eq!(schur_stable_split(&nan, &[0]), None);
        assert_eq!(schur_stable(&nan), None);
        // An unstable state in either block makes the whole unstable.
        for (i, v) in [(4, 1.2), (3, -1.1)] {
            let mut b = a.clone();
            b[(i, i)] = v;
            assert_eq!(schur_stable_split(&b, &[0]), Some(false), "{i}");
            assert_eq!(schur_stable(&b), Some(false), "{i}");
        }
        // Random sparse matrices: the split's verdict is the eigenvalues'.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for trial in 0..200 {
            let n = rng.random_range(2..12);
            let scale = rng.random_range(0.3..1.6);
            let m = DMatrix::from_fn(n, n, |_, _| {
                if rng.random_bool(0.3) {
                    rng.random_range(-1.0..1.0) * scale
                } else {
                    0.0
                }
            });
            let rho = spectral_radius(&m).unwrap();
            if (rho - 1.0).abs() < 1e-6 {
                continue;
            }
            let seeds = [rng.random_range(0..n)];
            let (kept, rest) = split_reaching(&m, &seeds);
            // Nothing outside the kept set moves a kept state.
            for &i in &kept {
                for &j in &rest {
                    assert_eq!(m[(i, j)], 0.0, "trial {trial}");
                }
            }
            assert_eq!(
                schur_stable_split(&m, &seeds),
                Some(rho < 1.0),
                "trial {trial}"
            );
        }
    }

    #[test]
    fn the_stationary_covariance_and_the_window_mean_match_closed_forms() {
        // AR(1) x⁺ = a x + b e: P = b²/(1 − a²), γ_k = aᵏ P and
        // Σ_{k=1}^{N−1} (N − k) aᵏ = a (N (1 − a) − (1 − a^N)) / (1 − a)².
        for (a, b, n) in [
            (0.9, 0.5, 67usize),
            (-0.6, 2.0, 10),
            (0.999, 0.1, 1),
            (0.5, 1.0, 2),
        ] {
            let am = DMatrix::from_element(1, 1, a);
            let bm = DMatrix::from_element(1, 1, b);
            let p = covariance(&am, &bm);
            let p0 = b * b / (1.0 - a * a);
            assert!(
                (p[(0, 0)] - p0).abs() < 1e-9 * p0,
                "{a}: {} vs {p0}",
                p[(0, 0)]
            );
            let nf = n as f64;
            let sum = a * (nf * (1.0 - a) - (1.0 - a.powi(n as i32))) / (1.0 - a).powi(2);
            let want = (p0 * (nf + 2.0 * sum) / (nf * nf)).sqrt();
            let c = DMatrix::from_element(1, 1, 1.0);
            let got = window_mean_std(&am, &p, &c, n);
            assert!((got - want).abs() < 1e-9 * want, "{a} {n}: {got} vs {want}");
        }
        // A coupled, non-normal pair against vec(P) = (I − A⊗A)⁻¹ vec(B Bᵀ).
        let a = DMatrix::from_row_slice(2, 2, &[0.8, 0.5, -0.2, 0.6]);
        let b = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.3, 0.4]);
        assert_matches_kronecker(&a, &b, 1e-10);
        // Larger, random and non-normal, with a slow mode (ρ = 0.999) the doubling must sum
        // over about 2¹⁵ steps.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (n, radius) in [(6usize, 0.999), (9, 0.6), (12, 0.95)] {
            let mut a = DMatrix::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
            a *= radius / spectral_radius(&a).unwrap();
            let b = DMatrix::from_fn(n, 2, |_, _| rng.random_range(-1.0..1.0));
            assert_matches_kronecker(&a, &b, 1e-8);
        }
    }

    /// The covariance of a recursion known to be stable.
    fn covariance(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
        match stationary_covariance(a, b) {
            Some(Stationary::Stable(p)) => p,
            other => panic!("{a}: {other:?}"),
        }
    }

    /// [`stationary_covariance`] against vec(P) = (I − A⊗A)⁻¹ vec(B Bᵀ), relative to max |P|.
    fn assert_matches_kronecker(a: &DMatrix<f64>, b: &DMatrix<f64>, tol: f64) {
        let n = a.nrows();
        let p = covariance(a, b);
        let rhs = b * b.transpose();
        let vec_p = (DMatrix::<f64>::identity(n * n, n * n) - a.kronecker(a))
            .lu()
            .solve(&DVector::from_column_slice(rhs.as_slice()))
            .unwrap();
        let scale = vec_p.amax().max(1.0);
        for (got, want) in p.iter().zip(vec_p.iter()) {
            assert!((got - want).abs() < tol * scale, "{p} vs {vec_p}");
        }
    }

    #[test]
    fn the_stationary_covariance_decides_stability_as_schur_stable_does() {
        let stable = |a: &DMatrix<f64>| {
            let b = DMatrix::<f64>::identity(a.nrows(), a.nrows());
            match stationary_covariance(a, &b) {
                Some(Stationary::Stable(p)) => {
                    assert!(p.iter().all(|v| v.is_finite()), "{p}");
                    Some(true)
                }
                Some(Stationary::Unstable) => Some(false),
                None => None,
            }
        };
        let diag = DMatrix::from_diagonal(&DVector::from_vec(vec![0.9, 1.1, 0.2]));
        let jordan = DMatrix::from_row_slice(2, 2, &[0.99, 1e6, 0.0, 0.99]);
        let shift = DMatrix::from_fn(5, 5, |i, j| if i == j + 1 { 1.0 } else { 0.0 });
        let mut bad = rotation(0.5, 0.1);
        bad[(0, 1)] = f64::NAN;
        for m in [
            DMatrix::zeros(0, 0),
            DMatrix::from_diagonal_element(3, 3, 0.0),
            diag,
            rotation(0.999, 0.3),
            rotation(1.001, 0.3),
            rotation(1.0, 0.3),
            rotation(1.0 - 1e-9, 0.3),
            rotation(1.0 + 1e-9, 0.3),
            jordan,
            shift,
            bad,
        ] {
            assert_eq!(stable(&m), schur_stable(&m), "{m}");
        }
        // Noise that does not reach the unstable mode still leaves no stationary process.
        let hidden = DMatrix::from_diagonal(&DVector::from_vec(vec![0.5, 1.2]));
        let b = DMatrix::from_column_slice(2, 1, &[1.0, 0.0]);
        assert_eq!(
            stationary_covariance(&hidden, &b),
            Some(Stationary::Unstable)
        );
        assert_eq!(stable(&rotation(0.5, 0.1)), Some(true));
        // Near the circle, on random matrices, as the eigenvalues say.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for trial in 0..100 {
            let (m, target) = near_circle(&mut rng, 2 + trial % 30, trial % 2 == 0);
            let n = m.nrows();
            let want = spectral_radius(&m).unwrap() < 1.0;
            assert_eq!(stable(&m), Some(want), "trial {trial}, n {n}, ρ {target}");
        }
    }

    /// A random n × n matrix scaled to a spectral radius within 2 % of 1, never closer than
    /// 1e-4, outside the circle or inside it; and that radius.
    fn near_circle(
        rng: &mut rand_chacha::ChaCha8Rng,
        n: usize,
        outside: bool,
    ) -> (DMatrix<f64>, f64) {
        let mut m = DMatrix::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
        let rho = spectral_radius(&m).unwrap();
        let target = 1.0 + rng.random_range(1e-4..0.02) * if outside { 1.0 } else { -1.0 };
        m *= target / rho;
        (m, target)
    }

    #[test]
    fn schur_stable_agrees_with_closed_forms() {
        assert_eq!(schur_stable(&DMatrix::zeros(0, 0)), Some(true));
        assert_eq!(
            schur_stable(&DMatrix::from_diagonal_element(3, 3, 0.0)),
            Some(true)
        );
        let diag = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![0.9, 1.1, 0.2]));
        assert_eq!(schur_stable(&diag), Some(false));
        assert_eq!(schur_stable(&rotation(0.999, 0.3)), Some(true));
        assert_eq!(schur_stable(&rotation(1.001, 0.3)), Some(false));
        // On the circle neither certificate fires: the eigenvalues decide (ρ = 1 is unstable).
        assert_eq!(schur_stable(&rotation(1.0, 0.3)), Some(false));
        // Within 1e-9 of it too; the eigenvalues still tell stable from unstable.
        assert_eq!(schur_stable(&rotation(1.0 - 1e-9, 0.3)), Some(true));
        assert_eq!(schur_stable(&rotation(1.0 + 1e-9, 0.3)), Some(false));
        // A Jordan block's powers grow by 1e6 before they decay: still stable.
        let jordan = DMatrix::from_row_slice(2, 2, &[0.99, 1e6, 0.0, 0.99]);
        assert_eq!(schur_stable(&jordan), Some(true));
        // Nilpotent: the shift.
        let shift = DMatrix::from_fn(5, 5, |i, j| if i == j + 1 { 1.0 } else { 0.0 });
        assert_eq!(schur_stable(&shift), Some(true));
        let mut bad = rotation(0.5, 0.1);
        bad[(0, 1)] = f64::NAN;
        assert_eq!(schur_stable(&bad), None);
    }

    #[test]
    fn schur_stable_agrees_with_the_eigenvalues_near_the_circle() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut seen = [0usize; 2];
        for trial in 0..200 {
            let (m, target) = near_circle(&mut rng, 2 + trial % 40, trial % 2 == 0);
            let n = m.nrows();
            let want = spectral_radius(&m).unwrap() < 1.0;
            assert_eq!(
                schur_stable(&m),
                Some(want),
                "trial {trial}, n {n}, ρ {target}"
            );
            seen[want as usize] += 1;
        }
        assert!(seen[0] > 50 && seen[1] > 50, "{seen:?}");
    }
}
