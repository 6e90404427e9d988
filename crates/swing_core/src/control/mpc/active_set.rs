//! Dense dual active-set QP solver (Goldfarb & Idnani 1983) for the bounded MPC QP.
//!
//! min ½ xᵀHx + fᵀx  s.t.  s_i(x) = h_i − g_iᵀx ≥ 0.
//! With H = LLᵀ (factored once: H is constant) and J = L⁻ᵀQ, R from the QR factorisation
//! L⁻¹N_A = Q[R; 0] of the active normals n_i = −g_i, the method starts from the
//! unconstrained minimiser x = −H⁻¹f (which the MPC law already gives) and repeatedly adds
//! the most violated constraint p: with d = Jᵀn_p, primal step z = J₂d₂, dual step
//! r = R⁻¹d₁, step t = min(full step −s_p/(zᵀn_p), partial step min_{r_j>0} u_j/r_j);
//! a full step adds p to the active set (Givens rotations on d, J and a new column of R),
//! a partial step drops the blocking constraint (Givens re-triangularisation of R). Every
//! iterate is dual feasible; the first primal-feasible one is optimal. It is exact (no
//! interior-point tolerance), needs no allocation (all buffers sized at construction) and,
//! because the unconstrained minimiser is the start, costs nothing when no bound is active.

use nalgebra::DMatrix;

use super::qp::{constraint_rows, fill_rhs, Bounds};
use crate::control::ControlError;

/// Workspace of the dual active-set method for the MPC's box/increment-bounded QP.
#[derive(Clone, Debug)]
pub struct ActiveSetQp {
    n: usize,
    /// L⁻ᵀ (n × n, column-major).
    j0: Vec<f64>,
    /// Sparse rows of G: up to two (column, value) pairs; value 0 marks an unused slot.
    rows: Vec<[(usize, f64); 2]>,
    h: Vec<f64>,
    bounds: Bounds,
    m: usize,
    nc: usize,
    // Work buffers.
    jm: Vec<f64>,
    rm: Vec<f64>,
    active: Vec<usize>,
    u: Vec<f64>,
    d: Vec<f64>,
    z: Vec<f64>,
    r: Vec<f64>,
    x: Vec<f64>,
    np_vec: Vec<f64>,
}

impl ActiveSetQp {
    /// Factor H and lay out the constraints.
    pub fn new(
        h: &DMatrix<f64>,
        bounds: Bounds,
        m: usize,
        nc: usize,
    ) -> Result<Self, ControlError> {
        let n = h.nrows();
        let chol = h.clone().cholesky().ok_or_else(|| {
            ControlError::Synthesis("active set: Hessian not positive definite".into())
        })?;
        let l = chol.l();
        let linv = l
            .solve_lower_triangular(&DMatrix::<f64>::identity(n, n))
            .ok_or_else(|| {
                ControlError::Synthesis("active set: singular Cholesky factor".into())
            })?;
        let j0 = linv.transpose();
        let g = constraint_rows(&bounds, m, nc);
        let mut rows = Vec::with_capacity(g.nrows());
        for i in 0..g.nrows() {
            let mut entry = [(0usize, 0.0f64); 2];
            let mut k = 0;
            for c in 0..n {
                if g[(i, c)] != 0.0 {
                    if k >= 2 {
                        return Err(ControlError::Synthesis(
                            "active set: constraint row with more than two entries".into(),
                        ));
                    }
                    entry[k] = (c, g[(i, c)]);
                    k += 1;
                }
            }
            rows.push(entry);
        }
        let ncon = rows.len();
        Ok(Self {
            n,
            j0: j0.as_slice().to_vec(),
            rows,
            h: vec![0.0; ncon],
            bounds,
            m,
            nc,
            jm: vec![0.0; n * n],
            rm: vec![0.0; n * n],
            active: vec![0; n],
            u: vec![0.0; n + 1],
            d: vec![0.0; n],
            z: vec![0.0; n],
            r: vec![0.0; n],
            x: vec![0.0; n],
            np_vec: vec![0.0; n],
        })
    }

    /// Change the bound values (of the kinds the solver was built with: a bound that was
    /// absent stays absent); they apply from the next solve.
    pub fn set_bounds(&mut self, bounds: Bounds) {
        if bounds.u_max.is_some() == self.bounds.u_max.is_some()
            && bounds.du_max.is_some() == self.bounds.du_max.is_some()
        {
            self.bounds = bounds;
        }
    }

    #[inline]
    fn slack(&self, i: usize, x: &[f64]) -> f64 {
        let [(c0, v0), (c1, v1)] = self.rows[i];
        self.h[i] - v0 * x[c0] - v1 * x[c1]
    }

    /// Solve with gradient `f`, unconstrained minimiser `x_unc` = −H⁻¹f and previous input;
    /// writes the minimiser to `out` and returns the number of active-set changes.
    pub fn solve(
        &mut self,
        _f: &[f64],
        x_unc: &[f64],
        u_prev: &[f64],
        out: &mut [f64],
    ) -> Result<u32, ControlError> {
        let n = self.n;
        fill_rhs(&self.bounds, self.m, self.nc, u_prev, &mut self.h);
        self.x.copy_from_slice(x_unc);
        self.jm.copy_from_slice(&self.j0);
        let mut q = 0usize;
        let mut iters = 0u32;
        let max_iter = 10 * (n + self.rows.len()) as u32;
        let scale = 1.0 + self.h.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let tol = 1e-10 * scale;
        loop {
            // 1. Most violated constraint.
            let mut p = usize::MAX;
            let mut worst = -tol;
            for i in 0..self.rows.len() {
                let s = self.slack(i, &self.x);
                if s < worst {
                    worst = s;
                    p = i;
                }
            }
            if p == usize::MAX {
                break;
            }
            // n_p = −g_p (dense copy for the products below).
            self.np_vec.fill(0.0);
            for &(c, v) in &self.rows[p] {
                self.np_vec[c] -= v;
            }
            let mut u_plus = 0.0;
            loop {
                iters += 1;
                if iters > max_iter {
                    return Err(ControlError::Solver(
                        "active set: iteration limit reached".into(),
                    ));
                }
                // 2. d = Jᵀ n_p (n_p has at most two non-zeros), z = J₂ d₂, r = R⁻¹ d₁.
                let [(c0, v0), (c1, v1)] = self.rows[p];
                for k in 0..n {
                    let col = &self.jm[k * n..(k + 1) * n];
                    self.d[k] = -(v0 * col[c0] + v1 * col[c1]);
                }
                self.z.fill(0.0);
                for k in q..n {
                    let dk = self.d[k];
                    let col = &self.jm[k * n..(k + 1) * n];
                    for (zi, ci) in self.z.iter_mut().zip(col) {
                        *zi += dk * ci;
                    }
                }
                for i in (0..q).rev() {
                    let mut acc = self.d[i];
                    for k in (i + 1)..q {
                        acc -= self.rm[k * n + i] * self.r[k];
                    }
                    self.r[i] = acc / self.rm[i * n + i];
                }
                // 3. Step lengths.
                let mut t1 = f64::INFINITY;
                let mut kdrop = usize::MAX;
                for k in 0..q {
                    if self.r[k] > 0.0 {
                        let t = self.u[k] / self.r[k];
                        if t < t1 {
                            t1 = t;
                            kdrop = k;
                        }
                    }
                }
                let zn: f64 = self.z.iter().zip(&self.np_vec).map(|(a, b)| a * b).sum();
                let znorm: f64 = self.z.iter().map(|a| a.abs()).fold(0.0, f64::max);
                let t2 = if znorm > 1e-14 && zn > 1e-14 {
                    -self.slack(p, &self.x) / zn
                } else {
                    f64::INFINITY
                };
                let t = t1.min(t2);
                if !t.is_finite() {
                    return Err(ControlError::Solver(
                        "QP infeasible: the previous acceleration is outside acc_max by more \
                         than one tick of jerk_max"
                            .into(),
                    ));
                }
                if t2.is_finite() {
                    for (xi, zi) in self.x.iter_mut().zip(&self.z) {
                        *xi += t * zi;
                    }
                }
                for k in 0..q {
                    self.u[k] -= t * self.r[k];
                }
                u_plus += t;
                if t == t2 {
                    // Full step: add p.
                    self.add_constraint(q);
                    self.active[q] = p;
                    self.u[q] = u_plus;
                    q += 1;
                    break;
                }
                // Partial (or dual) step: drop the blocking constraint and retry p.
                self.drop_constraint(kdrop, q);
                q -= 1;
            }
        }
        out.copy_from_slice(&self.x);
        Ok(iters)
    }

    /// Rotate d[q..n] into d[q] (and J alike); the new column q of R is d[0..=q].
    fn add_constraint(&mut self, q: usize) {
        let n = self.n;
        for j in ((q + 1)..n).rev() {
            let (a, b) = (self.d[j - 1], self.d[j]);
            if b == 0.0 {
                continue;
            }
            let hyp = a.hypot(b);
            let (c, s) = (a / hyp, b / hyp);
            self.d[j - 1] = hyp;
            self.d[j] = 0.0;
            let (left, right) = self.jm.split_at_mut(j * n);
            let colj1 = &mut left[(j - 1) * n..j * n];
            let colj = &mut right[..n];
            for (x1, x2) in colj1.iter_mut().zip(colj.iter_mut()) {
                let (t1, t2) = (*x1, *x2);
                *x1 = c * t1 + s * t2;
                *x2 = -s * t1 + c * t2;
            }
        }
        for i in 0..=q {
            self.rm[q * n + i] = self.d[i];
        }
    }

    /// Remove active constraint k of q and re-triangularise R (rotating J alike).
    fn drop_constraint(&mut self, k: usize, q: usize) {
        let n = self.n;
        for j in k..q - 1 {
            for i in 0..n {
                self.rm[j * n + i] = self.rm[(j + 1) * n + i];
            }
            self.active[j] = self.active[j + 1];
            self.u[j] = self.u[j + 1];
        }
        for j in k..q - 1 {
            let (a, b) = (self.rm[j * n + j], self.rm[j * n + j + 1]);
            if b == 0.0 {
                continue;
            }
            let hyp = a.hypot(b);
            let (c, s) = (a / hyp, b / hyp);
            for l in j..q - 1 {
                let (t1, t2) = (self.rm[l * n + j], self.rm[l * n + j + 1]);
                self.rm[l * n + j] = c * t1 + s * t2;
                self.rm[l * n + j + 1] = -s * t1 + c * t2;
            }
            let (left, right) = self.jm.split_at_mut((j + 1) * n);
            let colj = &mut left[j * n..];
            let colj1 = &mut right[..n];
            for (x1, x2) in colj.iter_mut().zip(colj1.iter_mut()) {
                let (t1, t2) = (*x1, *x2);
                *x1 = c * t1 + s * t2;
                *x2 = -s * t1 + c * t2;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::qp::ClarabelQp;
    use super::*;
    use nalgebra::DVector;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A seeded SPD Hessian of the MPC's shape (m·Nc) and a gradient.
    fn problem(m: usize, nc: usize, seed: u64) -> (DMatrix<f64>, DVector<f64>) {
        let n = m * nc;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut rnd = || rng.random_range(-0.5..0.5);
        let x = DMatrix::from_fn(n, n, |_, _| rnd());
        let h = &x * x.transpose() + DMatrix::identity(n, n) * 0.5;
        let f = DVector::from_fn(n, |_, _| 20.0 * rnd());
        (h, f)
    }

    /// KKT certificate: feasibility, complementary slackness and λ ≥ 0 with
    /// Hx + f + Gᵀλ = 0 solved by least squares on the active rows.
    fn kkt_error(
        h: &DMatrix<f64>,
        f: &DVector<f64>,
        g: &DMatrix<f64>,
        rhs: &[f64],
        x: &DVector<f64>,
    ) -> f64 {
        let slack: Vec<f64> = (0..g.nrows())
            .map(|i| rhs[i] - g.row(i).dot(&x.transpose()))
            .collect();
        let infeas = slack.iter().fold(0.0f64, |a, s| a.max(-s));
        let active: Vec<usize> = (0..g.nrows()).filter(|&i| slack[i].abs() < 1e-7).collect();
        let grad = h * x + f;
        if active.is_empty() {
            return infeas.max(grad.amax());
        }
        let ga = DMatrix::from_fn(active.len(), g.ncols(), |r, c| g[(active[r], c)]);
        let lam = ga
            .transpose()
            .svd(true, true)
            .solve(&(-&grad), 1e-12)
            .unwrap();
        let stationarity = (ga.transpose() * &lam + &grad).amax();
        let dual_infeas = lam.iter().fold(0.0f64, |a, l| a.max(-l));
        infeas.max(stationarity).max(dual_infeas)
    }

    #[test]
    fn active_set_meets_kkt_and_agrees_with_clarabel() {
        // The certificate solves λ by least squares on the active rows, which needs them
        // linearly independent, and Clarabel's default accuracy must resolve 1e-6: the seeds
        // give such problems (many random ones have a degenerate active set).
        for (m, nc, seed) in [(1, 20, 1), (2, 20, 3), (1, 5, 3), (2, 8, 4)] {
            let (h, f) = problem(m, nc, seed);
            let bounds = Bounds {
                u_max: Some(1.0),
                du_max: Some(0.4),
            };
            let u_prev = vec![0.3; m];
            let x_unc = -h.clone().cholesky().unwrap().solve(&f);
            let mut as_qp = ActiveSetQp::new(&h, bounds, m, nc).unwrap();
            let mut x = vec![0.0; m * nc];
            as_qp
                .solve(f.as_slice(), x_unc.as_slice(), &u_prev, &mut x)
                .unwrap();
            let g = constraint_rows(&bounds, m, nc);
            let mut rhs = vec![0.0; g.nrows()];
            fill_rhs(&bounds, m, nc, &u_prev, &mut rhs);
            let xv = DVector::from_vec(x.clone());
            assert!(
                bounds.violated(x_unc.as_slice(), &u_prev, 1e-9),
                "test needs active bounds"
            );
            let err = kkt_error(&h, &f, &g, &rhs, &xv);
            assert!(err < 1e-8, "KKT error {err}");
            let mut cl = ClarabelQp::new(&h, bounds, m, nc).unwrap();
            let mut xc = vec![0.0; m * nc];
            cl.solve(f.as_slice(), &u_prev, &mut xc).unwrap();
            let diff = x
                .iter()
                .zip(&xc)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(diff < 1e-6, "active set vs Clarabel differ by {diff}");
        }
    }

    #[test]
    fn inactive_bounds_return_the_unconstrained_minimiser_exactly() {
        let (h, f) = problem(1, 10, 9);
        let x_unc = -h.clone().cholesky().unwrap().solve(&f);
        let big = x_unc.amax() * 10.0 + 1.0;
        let bounds = Bounds {
            u_max: Some(big),
            du_max: Some(2.0 * big),
        };
        let mut qp = ActiveSetQp::new(&h, bounds, 1, 10).unwrap();
        let mut x = vec![0.0; 10];
        let iters = qp
            .solve(f.as_slice(), x_unc.as_slice(), &[0.0], &mut x)
            .unwrap();
        assert_eq!(iters, 0);
        assert_eq!(x.as_slice(), x_unc.as_slice());
        // Clarabel reaches the same point to interior-point accuracy.
        let mut cl = ClarabelQp::new(&h, bounds, 1, 10).unwrap();
        let mut xc = vec![0.0; 10];
        cl.solve(f.as_slice(), &[0.0], &mut xc).unwrap();
        let diff = x
            .iter()
            .zip(&xc)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(diff < 1e-6, "{diff}");
    }

    #[test]
    fn infeasible_bounds_are_a_solver_error() {
        // u_prev = 3 with |u| ≤ 1 and |Δu| ≤ 0.5: no feasible first move.
        let (h, f) = problem(1, 4, 5);
        let bounds = Bounds {
            u_max: Some(1.0),
            du_max: Some(0.5),
        };
        let x_unc = -h.clone().cholesky().unwrap().solve(&f);
        let mut qp = ActiveSetQp::new(&h, bounds, 1, 4).unwrap();
        let mut x = vec![0.0; 4];
        let r = qp.solve(f.as_slice(), x_unc.as_slice(), &[3.0], &mut x);
        assert!(matches!(r, Err(ControlError::Solver(_))));
        let mut cl = ClarabelQp::new(&h, bounds, 1, 4).unwrap();
        assert!(matches!(
            cl.solve(f.as_slice(), &[3.0], &mut x),
            Err(ControlError::Solver(_))
        ));
    }
}
