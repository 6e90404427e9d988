//! The constrained condensed QP of the MPC and its solvers.
//!
//! min ½ UᵀHU + fᵀU  s.t.  |u_j,a| ≤ u_max,  |u_j,a − u_{j−1},a| ≤ Δu_max  (j < Nc, u_{−1} =
//! u_prev), the bounds on the acceleration setpoint and its increment per tick. Written as
//! G U ≤ h with G constant and only h's first increment rows (which hold u_prev) and f
//! changing from tick to tick.
//!
//! * Clarabel (interior point): the solver object is built once with H, G and the cone;
//!   each tick only `update_q` (f) and `update_b` (h) overwrite its data in place (presolve
//!   and zero-dropping disabled so that in-place updates are allowed).
//! * Active set (see [`super::active_set`]): Goldfarb–Idnani's dual method on the constant
//!   Cholesky factor of H, started from the unconstrained minimiser the law already gives.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use nalgebra::DMatrix;

use crate::control::ControlError;

/// Box bounds of the QP, already in per-tick units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// |u| ≤ u_max [m/s²].
    pub u_max: Option<f64>,
    /// |Δu| ≤ du_max per tick [m/s²].
    pub du_max: Option<f64>,
}

impl Bounds {
    /// True when there is at least one bound.
    pub fn any(&self) -> bool {
        self.u_max.is_some() || self.du_max.is_some()
    }

    /// Whether U (m·Nc, stage-major) with previous input `u_prev` violates a bound by more
    /// than `tol`.
    pub fn violated(&self, u: &[f64], u_prev: &[f64], tol: f64) -> bool {
        let m = u_prev.len();
        if let Some(lim) = self.u_max {
            if u.iter().any(|x| x.abs() > lim + tol) {
                return true;
            }
        }
        if let Some(lim) = self.du_max {
            for (k, x) in u.iter().enumerate() {
                let prev = if k < m { u_prev[k] } else { u[k - m] };
                if (x - prev).abs() > lim + tol {
                    return true;
                }
            }
        }
        false
    }
}

/// Constraint matrix G (dense) and right-hand side h in the row order of the module docs:
/// u rows (2 per decision: +u ≤ u_max, −u ≤ u_max) then increment rows (2 per decision).
pub fn constraint_rows(bounds: &Bounds, m: usize, nc: usize) -> DMatrix<f64> {
    let nu = m * nc;
    let nu_rows = if bounds.u_max.is_some() { 2 * nu } else { 0 };
    let nd_rows = if bounds.du_max.is_some() { 2 * nu } else { 0 };
    let mut g = DMatrix::<f64>::zeros(nu_rows + nd_rows, nu);
    for col in 0..nu {
        if nu_rows > 0 {
            g[(2 * col, col)] = 1.0;
            g[(2 * col + 1, col)] = -1.0;
        }
        if nd_rows > 0 {
            let off = nu_rows;
            g[(off + 2 * col, col)] = 1.0;
            g[(off + 2 * col + 1, col)] = -1.0;
            if col + m < nu {
                g[(off + 2 * (col + m), col)] = -1.0;
                g[(off + 2 * (col + m) + 1, col)] = 1.0;
            }
        }
    }
    g
}

/// Fill h for the current previous input.
pub fn fill_rhs(bounds: &Bounds, m: usize, nc: usize, u_prev: &[f64], h: &mut [f64]) {
    let nu = m * nc;
    let mut off = 0;
    if let Some(lim) = bounds.u_max {
        h[..2 * nu].fill(lim);
        off = 2 * nu;
    }
    if let Some(lim) = bounds.du_max {
        h[off..off + 2 * nu].fill(lim);
        for a in 0..m {
            h[off + 2 * a] = lim + u_prev[a];
            h[off + 2 * a + 1] = lim - u_prev[a];
        }
    }
}

/// Dense matrix → Clarabel CSC, keeping explicit zeros out (`upper`: only i ≤ j).
fn to_csc(mat: &DMatrix<f64>, upper: bool) -> CscMatrix<f64> {
    let (rows, cols) = mat.shape();
    let mut colptr = Vec::with_capacity(cols + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for j in 0..cols {
        let last = if upper { j + 1 } else { rows };
        for i in 0..last {
            let v = mat[(i, j)];
            if v != 0.0 || (upper && i == j) {
                rowval.push(i);
                nzval.push(v);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(rows, cols, colptr, rowval, nzval)
}

/// Clarabel built once for the condensed QP and updated in place each tick.
pub struct ClarabelQp {
    solver: DefaultSolver<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
    bounds: Bounds,
    m: usize,
    nc: usize,
}

impl std::fmt::Debug for ClarabelQp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClarabelQp")
            .field("variables", &self.q.len())
            .field("constraints", &self.b.len())
            .finish()
    }
}

impl ClarabelQp {
    /// Build the solver for Hessian `h` and the given bounds.
    pub fn new(
        h: &DMatrix<f64>,
        bounds: Bounds,
        m: usize,
        nc: usize,
    ) -> Result<Self, ControlError> {
        let g = constraint_rows(&bounds, m, nc);
        let ncon = g.nrows();
        let p = to_csc(h, true);
        let a = to_csc(&g, false);
        let q = vec![0.0; h.nrows()];
        let mut b = vec![0.0; ncon];
        fill_rhs(&bounds, m, nc, &vec![0.0; m], &mut b);
        let cones = [SupportedConeT::NonnegativeConeT(ncon)];
        let settings = DefaultSettings::<f64> {
            verbose: false,
            presolve_enable: false,
            input_sparse_dropzeros: false,
            max_iter: 100,
            ..Default::default()
        };
        let solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings)
            .map_err(|e| ControlError::Solver(format!("Clarabel setup: {e:?}")))?;
        if !solver.is_data_update_allowed() {
            return Err(ControlError::Solver(
                "Clarabel refused in-place data updates".into(),
            ));
        }
        Ok(Self {
            solver,
            q,
            b,
            bounds,
            m,
            nc,
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

    /// Solve for gradient `f` and previous input `u_prev`; the minimiser goes to `out`.
    /// Returns the iteration count.
    pub fn solve(
        &mut self,
        f: &[f64],
        u_prev: &[f64],
        out: &mut [f64],
    ) -> Result<u32, ControlError> {
        self.q.copy_from_slice(f);
        fill_rhs(&self.bounds, self.m, self.nc, u_prev, &mut self.b);
        self.solver
            .update_q(&self.q)
            .map_err(|e| ControlError::Solver(format!("Clarabel update: {e}")))?;
        self.solver
            .update_b(&self.b)
            .map_err(|e| ControlError::Solver(format!("Clarabel update: {e}")))?;
        self.solver.solve();
        let sol = &self.solver.solution;
        match sol.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {
                out.copy_from_slice(&sol.x);
                Ok(sol.iterations)
            }
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                Err(ControlError::Solver(
                    "QP infeasible: the previous acceleration is outside acc_max by more than \
                     one tick of jerk_max"
                        .into(),
                ))
            }
            s => Err(ControlError::Solver(format!("Clarabel stopped: {s:?}"))),
        }
    }
}
