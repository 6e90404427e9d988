//! Data-enabled predictive control (DeePC; Coulson, Lygeros & Dörfler, "Data-enabled
//! predictive control: in the shallows of the DeePC", ECC 2019): the Hankel matrices of the
//! training flight in place of a model.
//!
//! **Data.** Inputs u (acceleration setpoints, m per axis) and outputs y (per axis [v,
//! swing]) sampled at T_s, each channel divided by its standard deviation. A column j of the
//! Hankel matrix holds a window of length L = T_ini + N: past inputs u_{j..j+T_ini−1} and
//! outputs y_{j+1..j+T_ini} (U_p, Y_p), future inputs u_{j+T_ini..j+L−1} and outputs
//! y_{j+T_ini+1..j+L} (U_f, Y_f); the output is paired one sample later than the input
//! because the setpoint u_k acts only after y_k was measured. At tick k, u_ini = u_{k−T_ini..k−1},
//! y_ini = y_{k−T_ini+1..k} (the newest measurement included).
//!
//! **Problem** (the 2-norm regularised DeePC of Dörfler, Coulson & Markovsky, "Bridging
//! direct and indirect data-driven control formulations via regularizations and
//! relaxations", IEEE TAC 2023):
//! ```text
//!   min_g  J_track(Y_f g) + Σ_j ‖W_Δu Δu_j‖² + λ_g ‖g‖² + λ_y ‖Y_p g − y_ini‖²
//!   s.t.   U_p g = u_ini,   U_f g = u,   |u_j| ≤ u_max,   |Δu_j| ≤ Δu_max,
//! ```
//! with the identified MPC's cost ([`crate::control::mpc`]): velocity tracking, the swing
//! rate by the two-tick difference (s_{k+i} − s_{k+i−2})/(2T_s), the swing angle, the input
//! increments over the control horizon N_c and the input held after N_c, so that the two
//! controllers differ only in the predictor.
//!
//! **Solution.** Every optimal g lies in the row space of D = [U_p; Y_p; U_f; Y_f] (a part
//! orthogonal to it only adds to ‖g‖²), so g = V h with D = W Σ Vᵀ (from the eigen-
//! decomposition of the Gram D Dᵀ) and ‖g‖ = ‖h‖: the problem is exactly one over h of the
//! dimension of D's row space, not of the data length. For given inputs U the optimal h is
//! the solution of an equality-constrained least-squares problem (one KKT system,
//! factored once), linear in U and in θ = (u_ini, y_ini, v_ref); substituted back, the
//! problem is a dense QP in U alone, ½UᵀHU + fᵀU with constant H and f linear in θ. As in
//! the MPC its unconstrained minimiser is a precomputed linear law U* = K θ, and a tick
//! with an active bound solves the QP with the dense active-set method on the constant
//! factor of H ([`crate::control::mpc::active_set`]).
//!
//! **Settings from the training flight.** T_ini and λ_y are chosen by the held-out N-step
//! prediction error of the same regularised predictor (the DeePC problem without the
//! tracking cost: the least-norm consistent g for the measured past and the future inputs
//! actually flown) on the part of the flight that identification holds out too. λ_g is
//! given: a prediction with the inputs given cannot show what it is for (in closed loop a
//! small λ_g lets the optimiser plan through the data's noise directions: on a simulated
//! training flight λ_g = 0.1 predicts best and flies the vehicle away at −8 m/s, λ_g ≥ 100
//! flies the step); `swingrt.methods` chooses it by a step flight on the vehicle's twin.

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use super::mpc::active_set::ActiveSetQp;
use super::mpc::qp::Bounds;
use super::{AxisState, ControlError, SwingController, TickInfo, TickKind};
use crate::config::{non_negative, positive, ConfigError};

/// DeePC settings: the cost is the MPC's, the regularisation is chosen on held-out data
/// when not given.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DeepcSettings {
    /// Prediction horizon N [ticks].
    pub horizon: usize,
    /// Control horizon N_c [ticks], 1 ≤ N_c ≤ N; the input is held after it.
    pub control_horizon: usize,
    /// Velocity tracking weight [1/(m/s)].
    pub w_velocity: f64,
    /// Swing-rate weight [1/(rad/s)].
    pub w_swing_rate: f64,
    /// Swing-angle weight [1/rad].
    pub w_swing: f64,
    /// Input-increment weight [1/(m/s²)] per tick (> 0).
    pub w_acc_rate: f64,
    /// Bound on |acceleration setpoint| [m/s²] (none = unbounded).
    pub acc_max: Option<f64>,
    /// Bound on |acceleration setpoint change| [m/s³] (none = unbounded).
    pub jerk_max: Option<f64>,
    /// Past window T_ini [ticks] (≥ 2); none = chosen on the held-out data from `t_ini_grid`.
    pub t_ini: Option<usize>,
    /// Candidates for T_ini [ticks].
    pub t_ini_grid: Vec<usize>,
    /// Regularisation of ‖g‖² [-] (standardised data); none = the largest of
    /// `lambda_g_grid`.
    pub lambda_g: Option<f64>,
    /// Candidates for λ_g [-]: a closed-loop choice (`swingrt.methods` flies each on the
    /// vehicle's twin), not a prediction-error one: with the future inputs given, small λ_g
    /// predicts best, but in the loop the optimiser then steers by the data's noise
    /// directions.
    pub lambda_g_grid: Vec<f64>,
    /// Weight of the past-output slack ‖σ_y‖² [-] (standardised outputs); none = chosen
    /// from `lambda_y_grid`.
    pub lambda_y: Option<f64>,
    /// Candidates for λ_y [-].
    pub lambda_y_grid: Vec<f64>,
    /// Starts of the held-out prediction windows [-].
    pub holdout_windows: usize,
}

impl Default for DeepcSettings {
    fn default() -> Self {
        Self {
            horizon: 100,
            control_horizon: 20,
            w_velocity: 1.0,
            w_swing_rate: 6.0,
            w_swing: 0.0,
            w_acc_rate: 6.0,
            acc_max: Some(4.0),
            jerk_max: None,
            t_ini: None,
            t_ini_grid: vec![5, 10, 20],
            lambda_g: None,
            lambda_g_grid: vec![1.0, 10.0, 100.0, 1e3, 1e4],
            lambda_y: None,
            lambda_y_grid: vec![1e2, 1e4, 1e6],
            holdout_windows: 10,
        }
    }
}

impl DeepcSettings {
    /// Check horizons, weights, bounds and the candidate grids.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.horizon == 0 || self.horizon > 1000 {
            return Err(ConfigError::new(
                "horizon",
                format!("must be between 1 and 1000 ticks (got {})", self.horizon),
            ));
        }
        if self.control_horizon == 0 || self.control_horizon > self.horizon {
            return Err(ConfigError::new(
                "control_horizon",
                format!(
                    "must be between 1 and horizon = {} (got {})",
                    self.horizon, self.control_horizon
                ),
            ));
        }
        non_negative("w_velocity", self.w_velocity)?;
        non_negative("w_swing_rate", self.w_swing_rate)?;
        non_negative("w_swing", self.w_swing)?;
        positive("w_acc_rate", self.w_acc_rate)?;
        if let Some(a) = self.acc_max {
            positive("acc_max", a)?;
        }
        if let Some(j) = self.jerk_max {
            positive("jerk_max", j)?;
        }
        let t_ini_ok = |t: usize| (2..=200).contains(&t);
        if let Some(t) = self.t_ini {
            if !t_ini_ok(t) {
                return Err(ConfigError::new(
                    "t_ini",
                    format!("must be between 2 and 200 ticks (got {t})"),
                ));
            }
        } else if self.t_ini_grid.is_empty() || !self.t_ini_grid.iter().all(|&t| t_ini_ok(t)) {
            return Err(ConfigError::new(
                "t_ini_grid",
                "must be a non-empty list of values between 2 and 200 ticks",
            ));
        }
        for (name, one, grid) in [
            ("lambda_g", self.lambda_g, &self.lambda_g_grid),
            ("lambda_y", self.lambda_y, &self.lambda_y_grid),
        ] {
            match one {
                Some(v) => positive(name, v)?,
                None => {
                    let field = format!("{name}_grid");
                    if grid.is_empty() {
                        return Err(ConfigError::new(field, "must not be empty"));
                    }
                    for &v in grid {
                        positive(&field, v)?;
                    }
                }
            }
        }
        if self.holdout_windows == 0 {
            return Err(ConfigError::new("holdout_windows", "must be >= 1"));
        }
        Ok(())
    }
}

/// A flight as DeePC reads it: inputs (T × m) and outputs (T × 2m, per axis [v, swing]) at
/// one sample time.
#[derive(Clone, Debug)]
pub struct IoData {
    /// Inputs, one row per sample [m/s²].
    pub u: DMatrix<f64>,
    /// Outputs, one row per sample [m/s, rad].
    pub y: DMatrix<f64>,
}

impl IoData {
    fn check(&self, what: &str) -> Result<(usize, usize), ControlError> {
        let (t, m) = self.u.shape();
        if !(1..=2).contains(&m) || self.y.shape() != (t, 2 * m) {
            return Err(ControlError::Input(format!(
                "{what}: inputs must be T × m (m = 1 or 2) and outputs T × 2m, got {:?} and {:?}",
                self.u.shape(),
                self.y.shape()
            )));
        }
        if self.u.iter().chain(self.y.iter()).any(|x| !x.is_finite()) {
            return Err(ControlError::Input(format!("{what}: data are not finite")));
        }
        Ok((t, m))
    }
}

/// The Hankel data in the row-space coordinates h (module docs).
#[derive(Clone, Debug)]
struct Hankel {
    t_ini: usize,
    n: usize,
    m: usize,
    p: usize,
    /// Channel scales (standard deviations) of u and y.
    su: DVector<f64>,
    sy: DVector<f64>,
    /// D_h = W Σ: rows of [U_p; Y_p; U_f; Y_f] in the h coordinates.
    dh: DMatrix<f64>,
}

impl Hankel {
    fn new(data: &IoData, t_ini: usize, n: usize) -> Result<Self, ControlError> {
        let (t, m) = data.check("training data")?;
        let p = 2 * m;
        let l = t_ini + n;
        let rows = l * (m + p);
        if t < l + 1 + 2 * rows {
            return Err(ControlError::Input(format!(
                "DeePC needs at least {} samples for T_ini = {t_ini}, N = {n} (got {t})",
                l + 1 + 2 * rows
            )));
        }
        let std = |col: nalgebra::DVectorView<'_, f64>| {
            let mean = col.mean();
            let var = col.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / col.len() as f64;
            var.sqrt().max(1e-9)
        };
        let su = DVector::from_iterator(m, (0..m).map(|c| std(data.u.column(c))));
        let sy = DVector::from_iterator(p, (0..p).map(|c| std(data.y.column(c))));
        let cols = t - l;
        let mut d = DMatrix::<f64>::zeros(rows, cols);
        let (up, yp, uf, yf) = offsets(t_ini, n, m, p);
        for j in 0..cols {
            for i in 0..t_ini {
                for c in 0..m {
                    d[(up + i * m + c, j)] = data.u[(j + i, c)] / su[c];
                }
                for c in 0..p {
                    d[(yp + i * p + c, j)] = data.y[(j + 1 + i, c)] / sy[c];
                }
            }
            for i in 0..n {
                for c in 0..m {
                    d[(uf + i * m + c, j)] = data.u[(j + t_ini + i, c)] / su[c];
                }
                for c in 0..p {
                    d[(yf + i * p + c, j)] = data.y[(j + t_ini + 1 + i, c)] / sy[c];
                }
            }
        }
        let gram = &d * d.transpose();
        let eig = SymmetricEigen::new(gram);
        let top = eig.eigenvalues.max();
        let keep: Vec<usize> = (0..rows)
            .filter(|&i| eig.eigenvalues[i] > 1e-12 * top)
            .collect();
        let mut dh = DMatrix::<f64>::zeros(rows, keep.len());
        for (k, &i) in keep.iter().enumerate() {
            let s = eig.eigenvalues[i].sqrt();
            dh.column_mut(k)
                .copy_from(&(eig.eigenvectors.column(i) * s));
        }
        Ok(Self {
            t_ini,
            n,
            m,
            p,
            su,
            sy,
            dh,
        })
    }

    fn r(&self) -> usize {
        self.dh.ncols()
    }

    /// KKT of min λ_g‖h‖² + λ_y‖Y_p h − y‖² + ‖A h + c‖² s.t. [U_p; U_f] h = e, with the
    /// extra quadratic `extra` = 2AᵀA (zero for pure prediction); returns its LU.
    fn kkt(
        &self,
        lambda_g: f64,
        lambda_y: f64,
        extra: Option<&DMatrix<f64>>,
    ) -> Result<nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>, ControlError> {
        let (up, yp, uf, _) = offsets(self.t_ini, self.n, self.m, self.p);
        let r = self.r();
        let ne = (self.t_ini + self.n) * self.m;
        let ypm = self.dh.rows(yp, self.t_ini * self.p);
        let mut k = DMatrix::<f64>::zeros(r + ne, r + ne);
        let mut p = ypm.transpose() * ypm * (2.0 * lambda_y);
        for i in 0..r {
            p[(i, i)] += 2.0 * lambda_g;
        }
        if let Some(x) = extra {
            p += x;
        }
        k.view_mut((0, 0), (r, r)).copy_from(&p);
        let mut e = DMatrix::<f64>::zeros(ne, r);
        e.rows_mut(0, self.t_ini * self.m)
            .copy_from(&self.dh.rows(up, self.t_ini * self.m));
        e.rows_mut(self.t_ini * self.m, self.n * self.m)
            .copy_from(&self.dh.rows(uf, self.n * self.m));
        k.view_mut((r, 0), (ne, r)).copy_from(&e);
        k.view_mut((0, r), (r, ne)).copy_from(&e.transpose());
        let lu = k.lu();
        if !lu.is_invertible() {
            return Err(ControlError::Synthesis(
                "DeePC: the input data are not persistently exciting (singular KKT system)".into(),
            ));
        }
        Ok(lu)
    }

    /// Mean held-out NMAE of the regularised predictor over `windows` windows of `test`.
    fn holdout_error(
        &self,
        test: &IoData,
        lambda_g: f64,
        lambda_y: f64,
        windows: usize,
    ) -> Result<f64, ControlError> {
        let (t, _) = test.check("held-out data")?;
        let (m, p, ti, n) = (self.m, self.p, self.t_ini, self.n);
        let l = ti + n;
        if t < l + 2 {
            return Err(ControlError::Input(format!(
                "held-out data of {t} samples are shorter than one window ({} samples)",
                l + 2
            )));
        }
        let lu = self.kkt(lambda_g, lambda_y, None)?;
        let (_, yp, _, yf) = offsets(ti, n, m, p);
        let r = self.r();
        let ne = l * m;
        let last = t - l - 1;
        let starts: Vec<usize> = (0..windows)
            .map(|w| (w * last) / windows.max(2).saturating_sub(1).max(1))
            .map(|s| s.min(last))
            .collect();
        let range: Vec<f64> = (0..p)
            .map(|c| {
                let col = test.y.column(c);
                (col.max() - col.min()).max(1e-9)
            })
            .collect();
        let ypm = self.dh.rows(yp, ti * p).into_owned();
        let yfm = self.dh.rows(yf, n * p).into_owned();
        let mut err = vec![0.0; p];
        for &j in &starts {
            let mut rhs = DVector::<f64>::zeros(r + ne);
            let mut yini = DVector::<f64>::zeros(ti * p);
            for i in 0..ti {
                for c in 0..p {
                    yini[i * p + c] = test.y[(j + 1 + i, c)] / self.sy[c];
                }
            }
            rhs.rows_mut(0, r)
                .copy_from(&(ypm.transpose() * &yini * (2.0 * lambda_y)));
            for i in 0..l {
                for c in 0..m {
                    rhs[r + i * m + c] = test.u[(j + i, c)] / self.su[c];
                }
            }
            let sol = lu.solve(&rhs).ok_or_else(|| {
                ControlError::Synthesis("DeePC: held-out prediction failed".into())
            })?;
            let yhat = &yfm * sol.rows(0, r);
            for i in 0..n {
                for c in 0..p {
                    let pred = yhat[i * p + c] * self.sy[c];
                    err[c] += (pred - test.y[(j + ti + 1 + i, c)]).abs();
                }
            }
        }
        let count = (starts.len() * n) as f64;
        Ok((0..p).map(|c| err[c] / count / range[c]).sum::<f64>() / p as f64)
    }
}

/// Row offsets of U_p, Y_p, U_f, Y_f in D.
fn offsets(t_ini: usize, n: usize, m: usize, p: usize) -> (usize, usize, usize, usize) {
    let up = 0;
    let yp = t_ini * m;
    let uf = yp + t_ini * p;
    let yf = uf + n * m;
    (up, yp, uf, yf)
}

/// What the choice of T_ini, λ_g and λ_y found on the held-out data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeepcFit {
    /// Chosen past window [ticks].
    pub t_ini: usize,
    /// Chosen λ_g [-].
    pub lambda_g: f64,
    /// Chosen λ_y [-].
    pub lambda_y: f64,
    /// Held-out N-step NMAE of the chosen predictor [-].
    pub holdout_nmae: f64,
    /// Columns of the Hankel matrix [-].
    pub columns: usize,
    /// Dimension of its row space (the size of h) [-].
    pub rank: usize,
}

/// The DeePC controller (module docs); implements [`SwingController`] at the data's T_s.
pub struct DeepcController {
    s: DeepcSettings,
    dt: f64,
    m: usize,
    p: usize,
    t_ini: usize,
    fit: DeepcFit,
    /// Unconstrained law U* = K θ, θ = [u_ini; y_ini; v_ref] (physical units).
    k: DMatrix<f64>,
    h: DMatrix<f64>,
    bounds: Bounds,
    qp: Option<Box<ActiveSetQp>>,
    /// Past inputs (T_ini × m) and outputs (T_ini × p), oldest first, in θ layout.
    theta: DVector<f64>,
    u_prev: DVector<f64>,
    u_unc: DVector<f64>,
    u_sol: DVector<f64>,
    f: DVector<f64>,
}

impl std::fmt::Debug for DeepcController {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeepcController")
            .field("settings", &self.s)
            .field("dt", &self.dt)
            .field("fit", &self.fit)
            .finish()
    }
}

impl DeepcController {
    /// Build from the training data `train` and the held-out `test` at sample time `dt`
    /// [s]: choose T_ini, λ_g and λ_y on `test` (those not given), then condense.
    pub fn fit(
        train: &IoData,
        test: &IoData,
        dt: f64,
        settings: DeepcSettings,
    ) -> Result<Self, ControlError> {
        settings.validate()?;
        positive("dt", dt)?;
        let grid_t = settings
            .t_ini
            .map(|t| vec![t])
            .unwrap_or_else(|| settings.t_ini_grid.clone());
        // λ_g is not chosen on the prediction error (see the settings); the grid's largest
        // stands in when none is given.
        let grid_g = [settings.lambda_g.unwrap_or_else(|| {
            settings
                .lambda_g_grid
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max)
        })];
        let grid_y = settings
            .lambda_y
            .map(|v| vec![v])
            .unwrap_or_else(|| settings.lambda_y_grid.clone());
        let single = grid_t.len() == 1 && grid_g.len() == 1 && grid_y.len() == 1;
        let mut best: Option<(f64, Hankel, f64, f64)> = None;
        for &ti in &grid_t {
            let hk = Hankel::new(train, ti, settings.horizon)?;
            let mut best_here: Option<(f64, f64, f64)> = None;
            for &lg in &grid_g {
                for &ly in &grid_y {
                    let e = if single {
                        f64::NAN
                    } else {
                        hk.holdout_error(test, lg, ly, settings.holdout_windows)?
                    };
                    if best_here.is_none_or(|(b, _, _)| e < b) {
                        best_here = Some((e, lg, ly));
                    }
                }
            }
            let (e, lg, ly) = best_here.expect("grids are not empty");
            if best.as_ref().is_none_or(|(b, ..)| e < *b) {
                best = Some((e, hk, lg, ly));
            }
        }
        let (e, hk, lg, ly) = best.expect("grids are not empty");
        let holdout = if e.is_nan() {
            hk.holdout_error(test, lg, ly, settings.holdout_windows)?
        } else {
            e
        };
        let columns = train.u.nrows() - (hk.t_ini + hk.n);
        let fit = DeepcFit {
            t_ini: hk.t_ini,
            lambda_g: lg,
            lambda_y: ly,
            holdout_nmae: holdout,
            columns,
            rank: hk.r(),
        };
        Self::condense(&hk, dt, settings, fit)
    }

    /// The choice made on the held-out data.
    pub fn fit_info(&self) -> &DeepcFit {
        &self.fit
    }

    /// The settings in use.
    pub fn settings(&self) -> &DeepcSettings {
        &self.s
    }

    /// The decision U (m·N_c, stage-major) of the last tick.
    pub fn predicted_inputs(&self) -> &[f64] {
        self.u_sol.as_slice()
    }

    fn condense(
        hk: &Hankel,
        dt: f64,
        s: DeepcSettings,
        fit: DeepcFit,
    ) -> Result<Self, ControlError> {
        let (m, p, ti, n) = (hk.m, hk.p, hk.t_ini, hk.n);
        let nc = s.control_horizon;
        let nu = m * nc;
        let r = hk.r();
        let nth = ti * m + ti * p + m;
        let (th_u, th_y, th_r) = (0, ti * m, ti * m + ti * p);
        let (_, yp, _, yf) = offsets(ti, n, m, p);
        let (lg, ly) = (fit.lambda_g, fit.lambda_y);
        // Residual ρ = A_h h + A_U U + A_θ θ, rows: √λ_g h | √λ_y (Y_p h − y_ini/s_y) |
        // tracking (3 per step and axis) | increments (m per decision).
        let nrho = r + ti * p + 3 * m * n + nu;
        let mut ah = DMatrix::<f64>::zeros(nrho, r);
        let mut au = DMatrix::<f64>::zeros(nrho, nu);
        let mut at = DMatrix::<f64>::zeros(nrho, nth);
        for i in 0..r {
            ah[(i, i)] = lg.sqrt();
        }
        let mut row = r;
        for i in 0..ti * p {
            let c = i % p;
            ah.row_mut(row).copy_from(&(hk.dh.row(yp + i) * ly.sqrt()));
            at[(row, th_y + i)] = -ly.sqrt() / hk.sy[c];
            row += 1;
        }
        // Predicted raw output (step i, channel c) in physical units: s_y[c] · Y_f,h row.
        let yrow = |i: usize, c: usize| hk.dh.row(yf + i * p + c) * hk.sy[c];
        for i in 0..n {
            for a in 0..m {
                let (cv, cs) = (2 * a, 2 * a + 1);
                // Velocity: w_v (v − r).
                ah.row_mut(row).copy_from(&(yrow(i, cv) * s.w_velocity));
                at[(row, th_r + a)] = -s.w_velocity;
                row += 1;
                // Swing rate: w (s_{i} − s_{i−2}) / (2 T_s); steps before the horizon are
                // the measured past (y_ini's last two).
                let g = s.w_swing_rate / (2.0 * dt);
                let mut hr = yrow(i, cs) * g;
                if i >= 2 {
                    hr -= yrow(i - 2, cs) * g;
                } else {
                    // i = 0 → s_{k−1} (y_ini index T_ini − 2), i = 1 → s_k (index T_ini − 1).
                    at[(row, th_y + (ti - 2 + i) * p + cs)] = -g;
                }
                ah.row_mut(row).copy_from(&hr);
                row += 1;
                // Swing angle.
                ah.row_mut(row).copy_from(&(yrow(i, cs) * s.w_swing));
                row += 1;
            }
        }
        for j in 0..nc {
            for a in 0..m {
                au[(row, j * m + a)] = s.w_acc_rate;
                if j == 0 {
                    at[(row, th_u + (ti - 1) * m + a)] = -s.w_acc_rate;
                } else {
                    au[(row, (j - 1) * m + a)] = -s.w_acc_rate;
                }
                row += 1;
            }
        }
        debug_assert_eq!(row, nrho);
        // h(U, θ) from the KKT system of the tracking + regularisation terms.
        let ata = ah.transpose() * &ah * 2.0;
        // The λ terms are in A_h already: build the KKT with λ = 0 and the full 2AᵀA.
        let lu = hk.kkt(0.0, 0.0, Some(&ata))?;
        let ne = (ti + n) * m;
        let mut bu = DMatrix::<f64>::zeros(r + ne, nu);
        let mut bt = DMatrix::<f64>::zeros(r + ne, nth);
        bu.rows_mut(0, r).copy_from(&(ah.transpose() * &au * -2.0));
        bt.rows_mut(0, r).copy_from(&(ah.transpose() * &at * -2.0));
        for i in 0..ti {
            for c in 0..m {
                bt[(r + i * m + c, th_u + i * m + c)] = 1.0 / hk.su[c];
            }
        }
        for i in 0..n {
            let j = i.min(nc - 1);
            for c in 0..m {
                bu[(r + ti * m + i * m + c, j * m + c)] = 1.0 / hk.su[c];
            }
        }
        let solve = |b: &DMatrix<f64>| {
            lu.solve(b)
                .ok_or_else(|| ControlError::Synthesis("DeePC: KKT solve failed".into()))
        };
        let hu = solve(&bu)?.rows(0, r).into_owned();
        let ht = solve(&bt)?.rows(0, r).into_owned();
        let ru = &ah * &hu + &au;
        let rt = &ah * &ht + &at;
        let h = ru.transpose() * &ru;
        let chol = h.clone().cholesky().ok_or_else(|| {
            ControlError::Synthesis("DeePC Hessian is not positive definite".into())
        })?;
        let k = -chol.solve(&(ru.transpose() * &rt));
        if k.iter().any(|x| !x.is_finite()) {
            return Err(ControlError::Synthesis("DeePC law is not finite".into()));
        }
        let bounds = Bounds {
            u_max: s.acc_max,
            du_max: s.jerk_max.map(|j| j * dt),
        };
        let qp = if bounds.any() {
            Some(Box::new(ActiveSetQp::new(&h, bounds, m, nc)?))
        } else {
            None
        };
        Ok(Self {
            s,
            dt,
            m,
            p,
            t_ini: ti,
            fit,
            k,
            h,
            bounds,
            qp,
            theta: DVector::zeros(nth),
            u_prev: DVector::zeros(m),
            u_unc: DVector::zeros(nu),
            u_sol: DVector::zeros(nu),
            f: DVector::zeros(nu),
        })
    }

    /// Shift the past window by one tick and write the newest output.
    fn push_output(&mut self, state: &[AxisState]) {
        let (m, p, ti) = (self.m, self.p, self.t_ini);
        let y0 = ti * m;
        let th = self.theta.as_mut_slice();
        th.copy_within(y0 + p..y0 + ti * p, y0);
        for (a, s) in state.iter().enumerate().take(m) {
            th[y0 + (ti - 1) * p + 2 * a] = s.v;
            th[y0 + (ti - 1) * p + 2 * a + 1] = s.swing;
        }
    }

    /// Shift the past inputs by one tick and write the input just applied.
    fn push_input(&mut self) {
        let (m, ti) = (self.m, self.t_ini);
        let th = self.theta.as_mut_slice();
        th.copy_within(m..ti * m, 0);
        for a in 0..m {
            th[(ti - 1) * m + a] = self.u_prev[a];
        }
    }
}

impl SwingController for DeepcController {
    fn axes(&self) -> usize {
        self.m
    }

    fn period(&self) -> f64 {
        self.dt
    }

    fn reset(&mut self, state: &[AxisState], acc: &[f64]) {
        for a in 0..self.m {
            let u = acc.get(a).copied().unwrap_or(0.0);
            self.u_prev[a] = if u.is_finite() { u } else { 0.0 };
        }
        let mut frame = [AxisState::default(); 2];
        for (a, f) in frame.iter_mut().enumerate().take(self.m) {
            let s = state.get(a).copied().unwrap_or_default();
            if s.v.is_finite() && s.swing.is_finite() {
                *f = s;
            }
        }
        // A steady past: every sample equal to the current one.
        for _ in 0..self.t_ini {
            self.push_output(&frame[..self.m]);
            self.push_input();
        }
        self.u_sol.fill(0.0);
    }

    fn step(
        &mut self,
        state: &[AxisState],
        vel_ref: &[f64],
        out: &mut [f64],
    ) -> Result<TickInfo, ControlError> {
        crate::control::check_tick_inputs(self.m, state, vel_ref, out)?;
        self.push_output(state);
        let nth = self.theta.len();
        for a in 0..self.m {
            self.theta[nth - self.m + a] = vel_ref[a];
        }
        self.u_unc.gemv(1.0, &self.k, &self.theta, 0.0);
        let mut info = TickInfo::default();
        let needs_qp = self.bounds.any()
            && self
                .bounds
                .violated(self.u_unc.as_slice(), self.u_prev.as_slice(), 1e-9);
        match (&mut self.qp, needs_qp) {
            (Some(qp), true) => {
                self.f.gemv(-1.0, &self.h, &self.u_unc, 0.0);
                info.iterations = qp.solve(
                    self.f.as_slice(),
                    self.u_unc.as_slice(),
                    self.u_prev.as_slice(),
                    self.u_sol.as_mut_slice(),
                )?;
                info.kind = TickKind::Constrained;
            }
            _ => self.u_sol.copy_from(&self.u_unc),
        }
        for (a, o) in out.iter_mut().enumerate() {
            let u = self.u_sol[a];
            if !u.is_finite() {
                return Err(ControlError::Solver("non-finite input from DeePC".into()));
            }
            *o = u;
            self.u_prev[a] = u;
        }
        self.push_input();
        Ok(info)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::PendulumModel;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// Noise-free data of the discrete white-box pendulum (outputs v, θ) under a random
    /// input that is held for a few ticks (persistently exciting).
    fn pendulum_data(t: usize, seed: u64) -> (IoData, DMatrix<f64>, DMatrix<f64>) {
        let p = PendulumModel {
            m_q: 1.0,
            m_p: 0.3,
            l: 1.2,
            c: 0.01,
        };
        let (a, b) = p.discrete(0.03);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut x = DVector::<f64>::zeros(3);
        let mut u = DMatrix::<f64>::zeros(t, 1);
        let mut y = DMatrix::<f64>::zeros(t, 2);
        let mut hold = 0.0;
        for k in 0..t {
            y[(k, 0)] = x[0];
            y[(k, 1)] = x[1];
            if k % 3 == 0 {
                let z: f64 = StandardNormal.sample(&mut rng);
                hold = z - 0.3 * x[0];
            }
            u[(k, 0)] = hold;
            x = &a * &x + &b * hold;
        }
        (IoData { u, y }, a, b)
    }

    /// The model-based MPC with the same cost, condensed by hand from the true (A, B) and
    /// the true state: min over U of ‖W(Y − R)‖² + ‖W_Δu ΔU‖² (unconstrained).
    #[allow(clippy::too_many_arguments)] // a test oracle: the true model, state and cost
    fn model_mpc(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        x0: &DVector<f64>,
        s_prev: f64,
        u_prev: f64,
        r: f64,
        s: &DeepcSettings,
        dt: f64,
    ) -> DVector<f64> {
        let (n, nc) = (s.horizon, s.control_horizon);
        // Stack predicted v_i, θ_i (i = 1..N) as affine functions of U.
        let mut fv = DMatrix::<f64>::zeros(2 * n, nc);
        let mut c0 = DVector::<f64>::zeros(2 * n);
        let mut x = x0.clone();
        let mut xu = DMatrix::<f64>::zeros(3, nc);
        for i in 0..n {
            let j = i.min(nc - 1);
            x = a * &x;
            xu = a * &xu;
            for r in 0..3 {
                xu[(r, j)] += b[(r, 0)];
            }
            c0[2 * i] = x[0];
            c0[2 * i + 1] = x[1];
            fv.row_mut(2 * i).copy_from(&xu.row(0));
            fv.row_mut(2 * i + 1).copy_from(&xu.row(1));
        }
        let rows = 3 * n + nc;
        let mut ma = DMatrix::<f64>::zeros(rows, nc);
        let mut mb = DVector::<f64>::zeros(rows);
        let g = s.w_swing_rate / (2.0 * dt);
        let mut row = 0;
        for i in 0..n {
            ma.row_mut(row).copy_from(&(fv.row(2 * i) * s.w_velocity));
            mb[row] = (c0[2 * i] - r) * s.w_velocity;
            row += 1;
            let mut hr = fv.row(2 * i + 1) * g;
            let mut cst = c0[2 * i + 1] * g;
            match i {
                0 => cst -= s_prev * g,
                1 => cst -= x0[1] * g,
                _ => {
                    hr -= fv.row(2 * (i - 2) + 1) * g;
                    cst -= c0[2 * (i - 2) + 1] * g;
                }
            }
            ma.row_mut(row).copy_from(&hr);
            mb[row] = cst;
            row += 1;
            ma.row_mut(row).copy_from(&(fv.row(2 * i + 1) * s.w_swing));
            mb[row] = c0[2 * i + 1] * s.w_swing;
            row += 1;
        }
        for j in 0..nc {
            ma[(row, j)] = s.w_acc_rate;
            if j == 0 {
                mb[row] = -u_prev * s.w_acc_rate;
            } else {
                ma[(row, j - 1)] = -s.w_acc_rate;
            }
            row += 1;
        }
        let h = ma.transpose() * &ma;
        -h.cholesky().unwrap().solve(&(ma.transpose() * mb))
    }

    #[test]
    fn deepc_on_noise_free_linear_data_reproduces_the_model_based_mpc() {
        let (data, a, b) = pendulum_data(1500, 3);
        let (test, ..) = pendulum_data(400, 4);
        let s = DeepcSettings {
            horizon: 40,
            control_horizon: 10,
            w_swing: 1.0,
            acc_max: None,
            t_ini: Some(6),
            lambda_g: Some(1e-9),
            lambda_y: Some(1e9),
            ..Default::default()
        };
        let dt = 0.03;
        let mut ctrl = DeepcController::fit(&data, &test, dt, s.clone()).unwrap();
        assert!(ctrl.fit_info().holdout_nmae < 1e-5, "{:?}", ctrl.fit_info());
        // A past of the plant under known inputs; DeePC reads it from its window.
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut x = DVector::<f64>::zeros(3);
        ctrl.reset(&[AxisState::default()], &[0.0]);
        let mut out = [0.0];
        let mut s_prev = 0.0;
        let mut u_last = 0.0;
        for _ in 0..12 {
            let z: f64 = StandardNormal.sample(&mut rng);
            let st = [AxisState {
                v: x[0],
                swing: x[1],
                swing_rate: x[2],
            }];
            // Feed the window: the controller's own move is replaced by the random one.
            ctrl.step(&st, &[0.0], &mut out).unwrap();
            ctrl.u_prev[0] = z;
            let th = ctrl.theta.as_mut_slice();
            th[ctrl.t_ini - 1] = z;
            s_prev = x[1];
            u_last = z;
            x = &a * &x + &b * z;
        }
        let st = [AxisState {
            v: x[0],
            swing: x[1],
            swing_rate: x[2],
        }];
        ctrl.step(&st, &[1.0], &mut out).unwrap();
        let want = model_mpc(&a, &b, &x, s_prev, u_last, 1.0, &s, dt);
        let got = DVector::from_column_slice(ctrl.predicted_inputs());
        let err = (&got - &want).amax() / want.amax();
        assert!(
            err < 1e-4,
            "DeePC {got} vs MPC {want}: relative error {err}"
        );
    }

    #[test]
    fn bad_settings_name_the_field() {
        let s = DeepcSettings {
            t_ini: Some(1),
            ..Default::default()
        };
        assert_eq!(s.validate().unwrap_err().field, "t_ini");
        let s = DeepcSettings {
            lambda_g_grid: vec![],
            ..Default::default()
        };
        assert_eq!(s.validate().unwrap_err().field, "lambda_g_grid");
    }
}
