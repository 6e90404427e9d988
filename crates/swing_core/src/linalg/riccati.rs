//! Riccati solvers: CARE, DARE (with cross term) and the exact sampled-data LQR. Generic
//! over the model; used by the LQR, the MPC and its estimator.
//!
//! # Riccati equations
//! * CARE: AᵀP + PA − PBR⁻¹BᵀP + Q = 0, K = R⁻¹BᵀP (u = −Kx).
//!   Solved with the **matrix sign function** of the Hamiltonian
//!   Z = [A, −BR⁻¹Bᵀ; −Q, −Aᵀ] (Newton iteration Z ← (Z/γ + γZ⁻¹)/2 with Byers'
//!   determinant scaling γ = |det Z|^{1/2n}); P is the least-squares solution of
//!   [W₁₂; W₂₂ + I] P = −[W₁₁ + I; W₂₁] where W = sign(Z) (Gardiner & Laub 1986,
//!   Byers 1987). It needs no eigenvector ordering, converges quadratically and is backward
//!   stable enough for the small (≤ 50 state) design models used here.
//! * DARE: AᵀPA − P − AᵀPB(R + BᵀPB)⁻¹BᵀPA + Q = 0, K = (R + BᵀPB)⁻¹BᵀPA.
//!   Solved with the **structure-preserving doubling algorithm** (SDA, Chu, Fan & Lin 2005):
//!   A₀ = A, G₀ = BR⁻¹Bᵀ, H₀ = Q; W = I + GₖHₖ; Aₖ₊₁ = AₖW⁻¹Aₖ,
//!   Gₖ₊₁ = Gₖ + AₖW⁻¹GₖAₖᵀ, Hₖ₊₁ = Hₖ + AₖᵀHₖW⁻¹Aₖ, Hₖ → P quadratically. Unlike the
//!   Schur method it needs no invertible A (delay-embedded models have singular A) and
//!   unlike plain value iteration it converges in ~log₂ of the iterations.
//!   A cross term N (cost xᵀQx + 2xᵀNu + uᵀRu) is removed by Ā = A − BR⁻¹Nᵀ, Q̄ = Q − NR⁻¹Nᵀ.
//!
//! Every solution is checked: relative residual of the equation ≤ 1e-8 and a stable closed
//! loop (Re λ(A − BK) < 0, resp. |λ(A − BK)| < 1), otherwise [`LinalgError::NoSolution`].

use faer::linalg::solvers::Solve;
use nalgebra::DMatrix;

use super::{
    eigenvalues, expm, schur_stable, spectral_radius, to_faer, LinalgError, EXPM_MAX_ENTRY,
};

/// A Riccati solution: gain K (u = −Kx), stabilising solution P and its relative residual.
#[derive(Clone, Debug)]
pub struct RiccatiSolution {
    /// Feedback gain, m × n (u = −K x).
    pub k: DMatrix<f64>,
    /// Symmetric positive semi-definite solution, n × n.
    pub p: DMatrix<f64>,
    /// ‖residual‖_F / (1 + ‖Q‖_F + ‖P‖_F-scaled terms); ≤ 1e-8 when accepted.
    pub residual: f64,
}

/// Accepted relative Riccati residual.
const RESIDUAL_TOL: f64 = 1e-8;

/// (M + Mᵀ)/2 in place, for an n × n matrix of nalgebra or faer.
fn symmetrize_n<M: std::ops::IndexMut<(usize, usize), Output = f64>>(m: &mut M, n: usize) {
    for i in 0..n {
        for j in (i + 1)..n {
            let v = 0.5 * (m[(i, j)] + m[(j, i)]);
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
}

/// (M + Mᵀ)/2 in place.
fn symmetrize(m: &mut DMatrix<f64>) {
    let n = m.nrows();
    symmetrize_n(m, n);
}

fn check_dims(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<(), LinalgError> {
    let n = a.nrows();
    let m = b.ncols();
    let bad = |w: &str| Err(LinalgError::Shape(format!("Riccati: {w}")));
    if n == 0 || a.ncols() != n {
        return bad(&format!(
            "A must be square and non-empty (got {}×{})",
            a.nrows(),
            a.ncols()
        ));
    }
    if b.nrows() != n || m == 0 {
        return bad(&format!(
            "B must be {n}×m with m ≥ 1 (got {}×{})",
            b.nrows(),
            b.ncols()
        ));
    }
    if q.nrows() != n || q.ncols() != n {
        return bad(&format!(
            "Q must be {n}×{n} (got {}×{})",
            q.nrows(),
            q.ncols()
        ));
    }
    if r.nrows() != m || r.ncols() != m {
        return bad(&format!(
            "R must be {m}×{m} (got {}×{})",
            r.nrows(),
            r.ncols()
        ));
    }
    for (name, mat) in [("A", a), ("B", b), ("Q", q), ("R", r)] {
        if mat.iter().any(|x| !x.is_finite()) {
            return bad(&format!("{name} has a non-finite entry"));
        }
    }
    for (name, mat) in [("Q", q), ("R", r)] {
        if (mat - mat.transpose()).amax() > 1e-9 * (1.0 + mat.amax()) {
            return bad(&format!("{name} must be symmetric"));
        }
    }
    if r.clone().cholesky().is_none() {
        return bad("R must be positive definite");
    }
    Ok(())
}

/// Solve the continuous algebraic Riccati equation (see module docs) by the matrix sign
/// function; returns K = R⁻¹BᵀP and P, checked by residual and closed-loop stability.
pub fn care(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<RiccatiSolution, LinalgError> {
    check_dims(a, b, q, r)?;
    let n = a.nrows();
    let rinv = r
        .clone()
        .try_inverse()
        .ok_or_else(|| LinalgError::NoSolution("R is singular".into()))?;
    let g = b * &rinv * b.transpose();
    let mut z = DMatrix::<f64>::zeros(2 * n, 2 * n);
    z.view_mut((0, 0), (n, n)).copy_from(a);
    z.view_mut((0, n), (n, n)).copy_from(&(-&g));
    z.view_mut((n, 0), (n, n)).copy_from(&(-q));
    z.view_mut((n, n), (n, n)).copy_from(&(-a.transpose()));
    let fail = || {
        LinalgError::NoSolution(
            "CARE: Hamiltonian has eigenvalues on the imaginary axis (no stabilising solution; \
             check stabilisability of (A, B) and detectability of (A, Q))"
                .into(),
        )
    };
    let mut converged = false;
    for _ in 0..100 {
        let lu = z.clone().lu();
        let logdet: f64 = lu.u().diagonal().iter().map(|d| d.abs().ln()).sum();
        let zinv = lu.try_inverse().ok_or_else(fail)?;
        if !logdet.is_finite() {
            return Err(fail());
        }
        let gamma = (logdet / (2 * n) as f64).exp();
        let znew = (&z / gamma + &zinv * gamma) * 0.5;
        let change = (&znew - &z).norm();
        let scale = znew.norm();
        z = znew;
        if !scale.is_finite() {
            return Err(fail());
        }
        if change <= 1e-13 * scale {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(fail());
    }
    let w11 = z.view((0, 0), (n, n)).into_owned();
    let w12 = z.view((0, n), (n, n)).into_owned();
    let w21 = z.view((n, 0), (n, n)).into_owned();
    let w22 = z.view((n, n), (n, n)).into_owned();
    let id = DMatrix::<f64>::identity(n, n);
    let mut lhs = DMatrix::<f64>::zeros(2 * n, n);
    lhs.view_mut((0, 0), (n, n)).copy_from(&w12);
    lhs.view_mut((n, 0), (n, n)).copy_from(&(w22 + &id));
    let mut rhs = DMatrix::<f64>::zeros(2 * n, n);
    rhs.view_mut((0, 0), (n, n)).copy_from(&(-(w11 + &id)));
    rhs.view_mut((n, 0), (n, n)).copy_from(&(-w21));
    let mut p = lhs
        .svd(true, true)
        .solve(&rhs, 1e-14)
        .map_err(|e| LinalgError::NoSolution(format!("CARE: least squares failed: {e}")))?;
    symmetrize(&mut p);
    let k = &rinv * b.transpose() * &p;
    let res = a.transpose() * &p + &p * a - &p * &g * &p + q;
    let residual =
        res.norm() / (1.0 + q.norm() + 2.0 * (a.norm() * p.norm()) + (&p * &g * &p).norm());
    if residual.is_nan() || residual > RESIDUAL_TOL {
        return Err(LinalgError::NoSolution(format!(
            "CARE residual {residual:.3e} exceeds {RESIDUAL_TOL:.0e}"
        )));
    }
    let acl = a - b * &k;
    let max_re = eigenvalues(&acl)
        .ok_or_else(|| {
            LinalgError::NoSolution("CARE: closed-loop eigenvalues did not converge".into())
        })?
        .iter()
        .map(|l| l.re)
        .fold(f64::NEG_INFINITY, f64::max);
    if max_re >= 0.0 {
        return Err(LinalgError::NoSolution(format!(
            "CARE: closed loop not stable (max Re λ = {max_re:.3e})"
        )));
    }
    Ok(RiccatiSolution { k, p, residual })
}

/// Solve the discrete algebraic Riccati equation (see module docs) by structure-preserving
/// doubling; returns K = (R + BᵀPB)⁻¹BᵀPA and P, checked by residual and stability.
pub fn dare(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<RiccatiSolution, LinalgError> {
    let n_zero = DMatrix::<f64>::zeros(a.nrows(), b.ncols());
    dare_with_cross(a, b, q, r, &n_zero)
}

/// DARE for the cost Σ xᵀQx + 2xᵀNu + uᵀRu; returns K = (R + BᵀPB)⁻¹(BᵀPA + Nᵀ) and P.
pub fn dare_with_cross(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    cross: &DMatrix<f64>,
) -> Result<RiccatiSolution, LinalgError> {
    check_dims(a, b, q, r)?;
    let n = a.nrows();
    if cross.nrows() != n || cross.ncols() != b.ncols() {
        return Err(LinalgError::Shape(format!(
            "Riccati: N must be {n}×{} (got {}×{})",
            b.ncols(),
            cross.nrows(),
            cross.ncols()
        )));
    }
    let rinv = r
        .clone()
        .try_inverse()
        .ok_or_else(|| LinalgError::NoSolution("R is singular".into()))?;
    let abar = a - b * &rinv * cross.transpose();
    let mut qbar = q - cross * &rinv * cross.transpose();
    symmetrize(&mut qbar);
    // The doubling runs in faer: its blocked LU and products are several times nalgebra's
    // on the 100–200-state augmented models of the MPC's Kalman filter.
    let mut gk = b * &rinv * b.transpose();
    symmetrize(&mut gk);
    let mut ak = to_faer(&abar);
    let mut gk = to_faer(&gk);
    let mut hk = to_faer(&qbar);
    let id = faer::Mat::<f64>::identity(n, n);
    let fail = |why: &str| {
        LinalgError::NoSolution(format!(
            "DARE: {why} (check stabilisability of (A, B) and detectability of (A, Q))"
        ))
    };
    let mut converged = false;
    for _ in 0..200 {
        let w = &id + &gk * &hk;
        let lu = w.partial_piv_lu();
        let y1 = lu.solve(&ak);
        let y2 = lu.solve(&gk);
        // A singular I + GH leaves non-finite solutions (faer's LU does not refuse it).
        if !(y1.is_all_finite() && y2.is_all_finite()) {
            return Err(fail("I + GH is singular"));
        }
        let a_next = &ak * &y1;
        let mut g_next = &gk + &ak * &y2 * ak.transpose();
        let mut h_next = &hk + ak.transpose() * &hk * &y1;
        symmetrize_n(&mut g_next, n);
        symmetrize_n(&mut h_next, n);
        let change = (&h_next - &hk).norm_l2();
        let scale = h_next.norm_l2();
        if !scale.is_finite() {
            return Err(fail("doubling diverged"));
        }
        ak = a_next;
        gk = g_next;
        hk = h_next;
        if change <= 1e-14 * scale.max(1e-300) {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(fail("doubling did not converge"));
    }
    let hk = DMatrix::from_fn(n, n, |i, j| hk[(i, j)]);
    let p = hk;
    let bt_p = b.transpose() * &p;
    let s = r + &bt_p * b;
    let k = s
        .clone()
        .lu()
        .solve(&(&bt_p * a + cross.transpose()))
        .ok_or_else(|| fail("R + BᵀPB is singular"))?;
    // Residual of the original (cross-term) equation.
    let res = a.transpose() * &p * a - &p - (a.transpose() * &p * b + cross) * &k + q;
    let residual = res.norm() / (1.0 + q.norm() + p.norm() * (1.0 + a.norm() * a.norm()));
    if residual.is_nan() || residual > RESIDUAL_TOL {
        return Err(LinalgError::NoSolution(format!(
            "DARE residual {residual:.3e} exceeds {RESIDUAL_TOL:.0e}"
        )));
    }
    let acl = a - b * &k;
    let unconverged =
        || LinalgError::NoSolution("DARE: closed-loop eigenvalues did not converge".into());
    if !schur_stable(&acl).ok_or_else(unconverged)? {
        let rho = spectral_radius(&acl).ok_or_else(unconverged)?;
        return Err(LinalgError::NoSolution(format!(
            "DARE: closed loop not stable (spectral radius {rho:.6})"
        )));
    }
    Ok(RiccatiSolution { k, p, residual })
}

/// Exact sampled-data LQR (Van Loan 1978): discretise the model and the continuous cost
/// ∫ xᵀQx + uᵀRu over one ZOH period `dt`, then solve the DARE with cross term.
/// Returns the solution and (A_d, B_d).
pub fn sampled_lqr(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    dt: f64,
) -> Result<(RiccatiSolution, DMatrix<f64>, DMatrix<f64>), LinalgError> {
    check_dims(a, b, q, r)?;
    if !(dt.is_finite() && dt > 0.0) {
        return Err(LinalgError::Shape(format!(
            "sampled LQR: period must be > 0 (got {dt})"
        )));
    }
    let n = a.nrows();
    let m = b.ncols();
    let nm = n + m;
    let mut f = DMatrix::<f64>::zeros(nm, nm);
    f.view_mut((0, 0), (n, n)).copy_from(a);
    f.view_mut((0, n), (n, m)).copy_from(b);
    let mut qc = DMatrix::<f64>::zeros(nm, nm);
    qc.view_mut((0, 0), (n, n)).copy_from(q);
    qc.view_mut((n, n), (m, m)).copy_from(r);
    // Van Loan: exp([−Fᵀ Qc; 0 F] dt) = [·  E12; 0  E22], W = E22ᵀ E12.
    let mut big = DMatrix::<f64>::zeros(2 * nm, 2 * nm);
    big.view_mut((0, 0), (nm, nm)).copy_from(&(-f.transpose()));
    big.view_mut((0, nm), (nm, nm)).copy_from(&qc);
    big.view_mut((nm, nm), (nm, nm)).copy_from(&f);
    let e = expm(&(big * dt)).ok_or_else(|| {
        LinalgError::Shape(format!(
            "sampled LQR: model × period has entries beyond {EXPM_MAX_ENTRY:e} or non-finite ones"
        ))
    })?;
    let e12 = e.view((0, nm), (nm, nm)).into_owned();
    let e22 = e.view((nm, nm), (nm, nm)).into_owned();
    let mut w = e22.transpose() * e12;
    symmetrize(&mut w);
    let ad = e22.view((0, 0), (n, n)).into_owned();
    let bd = e22.view((0, n), (n, m)).into_owned();
    let qd = w.view((0, 0), (n, n)).into_owned();
    let nd = w.view((0, n), (n, m)).into_owned();
    let rd = w.view((n, n), (m, m)).into_owned();
    let sol = dare_with_cross(&ad, &bd, &qd, &rd, &nd)?;
    Ok((sol, ad, bd))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalar_care_matches_closed_form() {
        let (a, b, q, r) = (0.7, 1.3, 2.0, 0.5);
        let sol = care(
            &DMatrix::from_element(1, 1, a),
            &DMatrix::from_element(1, 1, b),
            &DMatrix::from_element(1, 1, q),
            &DMatrix::from_element(1, 1, r),
        )
        .unwrap();
        // 2ap − p²b²/r + q = 0, positive root.
        let p = r * (a + (a * a + b * b * q / r).sqrt()) / (b * b);
        assert!((sol.p[(0, 0)] - p).abs() < 1e-10 * p);
        assert!((sol.k[(0, 0)] - b * p / r).abs() < 1e-10);
    }

    #[test]
    fn scalar_dare_matches_closed_form() {
        let (a, b, q, r): (f64, f64, f64, f64) = (1.2, 0.5, 1.0, 2.0);
        let sol = dare(
            &DMatrix::from_element(1, 1, a),
            &DMatrix::from_element(1, 1, b),
            &DMatrix::from_element(1, 1, q),
            &DMatrix::from_element(1, 1, r),
        )
        .unwrap();
        // p = a²p r/(r + b²p) + q ⇔ b²p² + (r − a²r − q b²)p − q r = 0.
        let (qa, qb, qc) = (b * b, r - a * a * r - q * b * b, -q * r);
        let p = (-qb + (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa);
        assert!(
            (sol.p[(0, 0)] - p).abs() < 1e-10 * p,
            "{} vs {p}",
            sol.p[(0, 0)]
        );
        assert!((sol.k[(0, 0)] - a * b * p / (r + b * b * p)).abs() < 1e-10);
    }

    #[test]
    fn unstabilisable_system_is_an_error_not_a_panic() {
        // Unstable mode not reachable from the input.
        let a = DMatrix::from_row_slice(2, 2, &[1.5, 0.0, 0.0, 0.5]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        let q = DMatrix::identity(2, 2);
        let r = DMatrix::identity(1, 1);
        assert!(matches!(
            dare(&a, &b, &q, &r),
            Err(LinalgError::NoSolution(_))
        ));
        let ac = DMatrix::from_row_slice(2, 2, &[0.5, 0.0, 0.0, -1.0]);
        assert!(matches!(
            care(&ac, &b, &q, &r),
            Err(LinalgError::NoSolution(_))
        ));
        let bad_r = DMatrix::from_element(1, 1, -1.0);
        assert!(matches!(
            dare(&a, &b, &q, &bad_r),
            Err(LinalgError::Shape(_))
        ));
    }
}
