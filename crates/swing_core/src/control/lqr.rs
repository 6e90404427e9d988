//! Riccati solvers and the baseline LQR swing-damping controller (thesis 5.3).
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
//! loop (Re λ(A − BK) < 0, resp. |λ(A − BK)| < 1), otherwise [`ControlError::Synthesis`].
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

use super::{AxisState, ControlError, SwingController, TickInfo, TickKind};
use crate::config::{non_negative, positive, ConfigError};
use crate::sysid::{LinearModel, Offset};

/// Standard gravity [m/s²].
pub const GRAVITY: f64 = 9.80665;

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

fn symmetrize(m: &mut DMatrix<f64>) {
    let n = m.nrows();
    for i in 0..n {
        for j in (i + 1)..n {
            let v = 0.5 * (m[(i, j)] + m[(j, i)]);
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
}

fn check_dims(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<(), ControlError> {
    let n = a.nrows();
    let m = b.ncols();
    let bad = |w: &str| Err(ControlError::Model(format!("Riccati: {w}")));
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
) -> Result<RiccatiSolution, ControlError> {
    check_dims(a, b, q, r)?;
    let n = a.nrows();
    let rinv = r
        .clone()
        .try_inverse()
        .ok_or_else(|| ControlError::Synthesis("R is singular".into()))?;
    let g = b * &rinv * b.transpose();
    let mut z = DMatrix::<f64>::zeros(2 * n, 2 * n);
    z.view_mut((0, 0), (n, n)).copy_from(a);
    z.view_mut((0, n), (n, n)).copy_from(&(-&g));
    z.view_mut((n, 0), (n, n)).copy_from(&(-q));
    z.view_mut((n, n), (n, n)).copy_from(&(-a.transpose()));
    let fail = || {
        ControlError::Synthesis(
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
        .map_err(|e| ControlError::Synthesis(format!("CARE: least squares failed: {e}")))?;
    symmetrize(&mut p);
    let k = &rinv * b.transpose() * &p;
    let res = a.transpose() * &p + &p * a - &p * &g * &p + q;
    let residual =
        res.norm() / (1.0 + q.norm() + 2.0 * (a.norm() * p.norm()) + (&p * &g * &p).norm());
    if residual.is_nan() || residual > RESIDUAL_TOL {
        return Err(ControlError::Synthesis(format!(
            "CARE residual {residual:.3e} exceeds {RESIDUAL_TOL:.0e}"
        )));
    }
    let acl = a - b * &k;
    let max_re = acl
        .complex_eigenvalues()
        .iter()
        .map(|l| l.re)
        .fold(f64::NEG_INFINITY, f64::max);
    if max_re >= 0.0 {
        return Err(ControlError::Synthesis(format!(
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
) -> Result<RiccatiSolution, ControlError> {
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
) -> Result<RiccatiSolution, ControlError> {
    check_dims(a, b, q, r)?;
    let n = a.nrows();
    if cross.nrows() != n || cross.ncols() != b.ncols() {
        return Err(ControlError::Model(format!(
            "Riccati: N must be {n}×{} (got {}×{})",
            b.ncols(),
            cross.nrows(),
            cross.ncols()
        )));
    }
    let rinv = r
        .clone()
        .try_inverse()
        .ok_or_else(|| ControlError::Synthesis("R is singular".into()))?;
    let abar = a - b * &rinv * cross.transpose();
    let mut qbar = q - cross * &rinv * cross.transpose();
    symmetrize(&mut qbar);
    let id = DMatrix::<f64>::identity(n, n);
    let mut ak = abar.clone();
    let mut gk = b * &rinv * b.transpose();
    symmetrize(&mut gk);
    let mut hk = qbar.clone();
    let fail = |why: &str| {
        ControlError::Synthesis(format!(
            "DARE: {why} (check stabilisability of (A, B) and detectability of (A, Q))"
        ))
    };
    let mut converged = false;
    for _ in 0..200 {
        let w = &id + &gk * &hk;
        let lu = w.lu();
        let y1 = lu.solve(&ak).ok_or_else(|| fail("I + GH is singular"))?;
        let y2 = lu.solve(&gk).ok_or_else(|| fail("I + GH is singular"))?;
        let a_next = &ak * &y1;
        let mut g_next = &gk + &ak * y2 * ak.transpose();
        let mut h_next = &hk + ak.transpose() * &hk * &y1;
        symmetrize(&mut g_next);
        symmetrize(&mut h_next);
        let change = (&h_next - &hk).norm();
        let scale = h_next.norm();
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
        return Err(ControlError::Synthesis(format!(
            "DARE residual {residual:.3e} exceeds {RESIDUAL_TOL:.0e}"
        )));
    }
    let acl = a - b * &k;
    let rho = acl
        .complex_eigenvalues()
        .iter()
        .map(|l| l.norm())
        .fold(0.0, f64::max);
    if rho >= 1.0 {
        return Err(ControlError::Synthesis(format!(
            "DARE: closed loop not stable (spectral radius {rho:.6})"
        )));
    }
    Ok(RiccatiSolution { k, p, residual })
}

/// Zero-order-hold discretisation of ẋ = Ax + Bu over `dt`: (A_d, B_d) = blocks of
/// exp([A B; 0 0] dt).
pub fn c2d_zoh(a: &DMatrix<f64>, b: &DMatrix<f64>, dt: f64) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = a.nrows();
    let m = b.ncols();
    let mut f = DMatrix::<f64>::zeros(n + m, n + m);
    f.view_mut((0, 0), (n, n)).copy_from(a);
    f.view_mut((0, n), (n, m)).copy_from(b);
    let e = (f * dt).exp();
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, m)).into_owned(),
    )
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
) -> Result<(RiccatiSolution, DMatrix<f64>, DMatrix<f64>), ControlError> {
    check_dims(a, b, q, r)?;
    if !(dt.is_finite() && dt > 0.0) {
        return Err(ControlError::Model(format!(
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
    let e = (big * dt).exp();
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
            Err(ControlError::Synthesis(_))
        ));
        let ac = DMatrix::from_row_slice(2, 2, &[0.5, 0.0, 0.0, -1.0]);
        assert!(matches!(
            care(&ac, &b, &q, &r),
            Err(ControlError::Synthesis(_))
        ));
        let bad_r = DMatrix::from_element(1, 1, -1.0);
        assert!(matches!(
            dare(&a, &b, &q, &bad_r),
            Err(ControlError::Model(_))
        ));
    }
}
