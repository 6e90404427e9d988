//! Augmented prediction model and condensed MPC problem (thesis eq. 5.21–5.34).
//!
//! **Augmented model.** From the identified model z⁺ = A z + B (u − ū) + c (`sysid::model`) the
//! MPC builds ξ = [z; s⁻; d] with
//! * s⁻ the swing angles of each axis one and two ticks back that the delay stack does not
//!   already hold (both when q = 1, the older one when q = 2, none for q ≥ 3), so that the
//!   swing rate is an output by the two-tick difference ṡ_k = (s_k − s_{k−2})/(2 T_s). The
//!   seed's one-tick backward difference (eq. 5.26–5.27) has its largest gain, 2/T_s, at the
//!   Nyquist frequency, where a rank-truncated delay model has spurious lightly damped modes
//!   (eigenvalues near −0.8) and measurement noise has its power: a swing-rate weight on it
//!   makes the MPC fight period-2 content it cannot control, and the command chatters. The
//!   two-tick difference has the same gain at the swing frequency (≈ 0.5 Hz, T_s = 30 ms:
//!   within 1 %) and none at Nyquist;
//! * d the constant disturbances (d⁺ = d) of eq. 5.32–5.33, in one of three layouts
//!   ([`DisturbanceModel`]): `velocity` — the thesis's B_ud: one per axis on the velocity row
//!   of the newest frame, entering as T_s·d (d in m/s²); `input` — one per axis entering
//!   exactly like the input, through B (d in m/s²: thrust/IMU offset, wind force on the
//!   vehicle); `state` — one per physical state of the newest frame, entering as T_s·d.
//!   Offset-free tracking needs the disturbances to explain every steady model mismatch
//!   (Pannocchia & Rawlings 2003: as many disturbances as measured outputs). The lower
//!   delay frames are exact shifts, so `state` meets that for any constant disturbance;
//!   `velocity` and `input` only for disturbances of their own shape;
//! * g the gusts, when asked for (`gust_time`): one per axis on the velocity row of the newest
//!   frame, entering as T_s·g (g in m/s²) and decaying as g⁺ = e^{−T_s/τ} g, a first-order
//!   Gauss–Markov force of correlation time τ. A constant disturbance is the right model of
//!   steady wind and a bias, and the wrong one of a gust: the MPC predicts the gust's force
//!   held over the whole horizon, answers it in full, and the estimate carries it past the
//!   gust's end, where the vehicle brakes against a force that is gone. The gust state lets
//!   the estimator put a sudden force where it is predicted to fade; the steady target
//!   (below) counts only the constant disturbances, since a gust has no steady state.
//!
//! So ξ⁺ = 𝒜 ξ + ℬ u + c̃ with c̃ = [c − Bū; 0; 0; 0] (ξ = [z; s⁻; d; g]). Outputs per axis y = [v, ṡ, s] = 𝒞 ξ.
//!
//! **Cost** (eq. 5.28–5.31, the MPC Toolbox form the thesis uses), decision U = [u₀ … u_{Nc−1}],
//! u_j = u_{Nc−1} for j ≥ Nc (eq. 5.22):
//! ```text
//! J = Σ_{i=1}^{Np} ‖W_y (r_{k+i} − y_{k+i})‖² + Σ_{i=0}^{Np−1} ‖W_u (u_{k+i} − u_ss)‖²
//!   + Σ_{i=0}^{Nc−1} ‖W_Δu (u_{k+i} − u_{k+i−1})‖²,
//! ```
//! with references v_ref (held over the horizon), ṡ_ref = 0, s_ref = s_ss and input target
//! u_ss, where (z_ss, u_ss) is the steady state of the augmented model with v = v_ref at the
//! current disturbance estimate (target calculation; it keeps an input weight from
//! fighting offset-free tracking). Only computed when W_u or the swing weight is non-zero.
//!
//! **Condensing.** Y = Φ ξ₀ + Γ U + y_off with Φ_i = 𝒞𝒜ⁱ, Γ_{i,j} = Σ 𝒞𝒜^{i−1−l}ℬ over the
//! steps l that use decision j, y_off_i = Σ_{l<i} 𝒞𝒜ˡ c̃. Then J = ½UᵀHU + fᵀU + const with
//! H = ΓᵀQΓ + MᵀRM + DᵀSD (M the hold expansion, D the differencing), and f linear in
//! (ξ₀, v_ref, u_prev): f = F_ξ ξ₀ + F_r r + F_u u_prev + f₀. The unconstrained minimiser is
//! the precomputed linear law U* = −H⁻¹f = K_ξ ξ₀ + K_r r + K_u u_prev + k₀.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::control::ControlError;

/// Where the estimated constant disturbances enter the prediction model (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DisturbanceModel {
    /// One per axis on the velocity row (the thesis's B_ud, eq. 5.33) [m/s²].
    Velocity,
    /// One per axis through the input matrix B [m/s²].
    Input,
    /// One per physical state of the newest frame [state units per second].
    #[default]
    State,
}

/// The disturbance-augmented model of the MPC (see module docs).
#[derive(Clone, Debug)]
pub struct Augmented {
    /// 𝒜, nx × nx.
    pub a: DMatrix<f64>,
    /// ℬ, nx × m.
    pub b: DMatrix<f64>,
    /// c̃, nx.
    pub c: DVector<f64>,
    /// 𝒞, 3m × nx: per axis rows [v, swing rate, swing].
    pub cy: DMatrix<f64>,
    /// Number of measured entries (z and s⁻): ξ[0..nm].
    pub nm: usize,
    /// How the s⁻ entries advance: each (destination, source) pair copies entry `source` of
    /// the previous ξ into entry `destination`; applied last pair first and before z shifts,
    /// every copy reads a value of the previous tick.
    pub lag_copies: Vec<(usize, usize)>,
    /// Number of disturbance states, the constant ones and then the gusts: ξ[nm..nm + nd].
    pub nd: usize,
    /// Number of gust states among them, the last (0 or one per axis).
    pub gusts: usize,
    /// Number of inputs / axes.
    pub m: usize,
}

impl Augmented {
    /// Build from the identified model. `iv`, `is` are the indices of each axis' velocity
    /// and swing in the newest frame of the `n` physical states; `gust_time`, when given,
    /// adds a gust state per axis of that correlation time [s] (module docs).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        c: &DVector<f64>,
        input_mean: &[f64],
        n: usize,
        delays: usize,
        iv: &[usize],
        is: &[usize],
        dt: f64,
        disturbance: DisturbanceModel,
        gust_time: Option<f64>,
    ) -> Self {
        let nz = a.nrows();
        let m = b.ncols();
        // s_{k−1} of axis i: in the second frame of z, or extra entry nz + i (q = 1);
        // s_{k−2}: in the third frame, or the next extra entry.
        let mut lag_copies = Vec::new();
        let mut prev = vec![0; m];
        let mut prev2 = vec![0; m];
        let mut next = nz;
        for i in 0..m {
            if delays >= 2 {
                prev[i] = is[i] + n;
            } else {
                prev[i] = next;
                lag_copies.push((next, is[i]));
                next += 1;
            }
        }
        for i in 0..m {
            if delays >= 3 {
                prev2[i] = is[i] + 2 * n;
            } else {
                prev2[i] = next;
                lag_copies.push((next, prev[i]));
                next += 1;
            }
        }
        let nm = next;
        let constant = match disturbance {
            DisturbanceModel::Velocity | DisturbanceModel::Input => m,
            DisturbanceModel::State => n,
        };
        let gusts = if gust_time.is_some() { m } else { 0 };
        let nd = constant + gusts;
        let nx = nm + nd;
        let mut aa = DMatrix::<f64>::zeros(nx, nx);
        aa.view_mut((0, 0), (nz, nz)).copy_from(a);
        for &(dst, src) in &lag_copies {
            aa[(dst, src)] = 1.0;
        }
        if let Some(tau) = gust_time {
            for (i, &v) in iv.iter().enumerate() {
                let k = nm + constant + i;
                aa[(v, k)] = dt;
                aa[(k, k)] = (-dt / tau).exp();
            }
        }
        for j in 0..constant {
            match disturbance {
                DisturbanceModel::Velocity => aa[(iv[j], nm + j)] = dt,
                DisturbanceModel::Input => {
                    aa.view_mut((0, nm + j), (nz, 1)).copy_from(&b.column(j));
                }
                DisturbanceModel::State => aa[(j, nm + j)] = dt,
            }
            aa[(nm + j, nm + j)] = 1.0;
        }
        let mut bb = DMatrix::<f64>::zeros(nx, m);
        bb.view_mut((0, 0), (nz, m)).copy_from(b);
        let mut cc = DVector::<f64>::zeros(nx);
        let mu = DVector::from_column_slice(input_mean);
        cc.rows_mut(0, nz).copy_from(&(c - b * mu));
        let mut cy = DMatrix::<f64>::zeros(3 * m, nx);
        for i in 0..m {
            cy[(3 * i, iv[i])] = 1.0;
            cy[(3 * i + 1, is[i])] = 0.5 / dt;
            cy[(3 * i + 1, prev2[i])] -= 0.5 / dt;
            cy[(3 * i + 2, is[i])] = 1.0;
        }
        Self {
            a: aa,
            b: bb,
            c: cc,
            cy,
            nm,
            lag_copies,
            nd,
            gusts,
            m,
        }
    }

    /// State dimension nx = nm + nd.
    pub fn nx(&self) -> usize {
        self.a.nrows()
    }
}

/// Output and input weights of the cost (already the square roots: J uses w²).
#[derive(Clone, Copy, Debug)]
pub struct Weights {
    /// Velocity tracking weight [1/(m/s)].
    pub v: f64,
    /// Swing-rate weight [1/(rad/s)].
    pub swing_rate: f64,
    /// Swing-angle weight [1/rad].
    pub swing: f64,
    /// Input weight [1/(m/s²)].
    pub u: f64,
    /// Input-increment weight [1/(m/s²)].
    pub du: f64,
}

/// The condensed problem and its precomputed unconstrained law.
#[derive(Clone, Debug)]
pub struct Condensed {
    /// Prediction horizon Np.
    pub np: usize,
    /// Control horizon Nc.
    pub nc: usize,
    /// Inputs m.
    pub m: usize,
    /// Φ, (3m·Np) × nx.
    pub phi: DMatrix<f64>,
    /// Γ, (3m·Np) × (m·Nc).
    pub gamma: DMatrix<f64>,
    /// y_off, 3m·Np.
    pub y_off: DVector<f64>,
    /// Hessian H, (m·Nc)².
    pub h: DMatrix<f64>,
    /// K_ξ, (m·Nc) × nx.
    pub k_xi: DMatrix<f64>,
    /// K_r, (m·Nc) × m.
    pub k_r: DMatrix<f64>,
    /// K_u, (m·Nc) × m.
    pub k_u: DMatrix<f64>,
    /// k₀, m·Nc.
    pub k0: DVector<f64>,
}

/// Steady-state target maps: u_ss = S_ur r + S_ud d + s_u0, s_ss likewise (d: nd entries).
#[derive(Clone, Debug)]
struct Targets {
    u_r: DMatrix<f64>,
    u_d: DMatrix<f64>,
    u_0: DVector<f64>,
    s_r: DMatrix<f64>,
    s_d: DMatrix<f64>,
    s_0: DVector<f64>,
}

fn targets(aug: &Augmented, iv: &[usize], is: &[usize]) -> Result<Targets, ControlError> {
    let m = aug.m;
    let nm = aug.nm;
    // Unknowns [z_ss (nm); u_ss (m)]; equations (I − A_mm) z − B u = c̃_m + A_md d, v_i = r_i.
    let dim = nm + m;
    let mut lhs = DMatrix::<f64>::zeros(dim, dim);
    lhs.view_mut((0, 0), (nm, nm))
        .copy_from(&(DMatrix::<f64>::identity(nm, nm) - aug.a.view((0, 0), (nm, nm))));
    lhs.view_mut((0, nm), (nm, m))
        .copy_from(&(-aug.b.view((0, 0), (nm, m))));
    for i in 0..m {
        lhs[(nm + i, iv[i])] = 1.0;
    }
    let lu = lhs.lu();
    // Right-hand sides: columns for r (m), d (nd) and the constant.
    let nd = aug.nd;
    let mut rhs = DMatrix::<f64>::zeros(dim, m + nd + 1);
    for i in 0..m {
        rhs[(nm + i, i)] = 1.0;
    }
    rhs.view_mut((0, m), (nm, nd))
        .copy_from(&aug.a.view((0, nm), (nm, nd)));
    rhs.view_mut((0, m + nd), (nm, 1))
        .copy_from(&aug.c.rows(0, nm));
    let sol = lu.solve(&rhs).ok_or_else(|| {
        ControlError::Model(
            "no steady state with v = v_ref (the model has a zero at z = 1); \
             set w_acc = 0 and w_swing = 0"
                .into(),
        )
    })?;
    if sol.iter().any(|x| !x.is_finite()) || sol.amax() > 1e8 {
        return Err(ControlError::Model(
            "steady-state target is ill-conditioned (model nearly has a zero at z = 1); \
             set w_acc = 0 and w_swing = 0"
                .into(),
        ));
    }
    let mut t = Targets {
        u_r: sol.view((nm, 0), (m, m)).into_owned(),
        u_d: sol.view((nm, m), (m, nd)).into_owned(),
        u_0: sol.view((nm, m + nd), (m, 1)).column(0).into_owned(),
        s_r: DMatrix::zeros(m, m),
        s_d: DMatrix::zeros(m, nd),
        s_0: DVector::zeros(m),
    };
    // A gust fades: the steady state holds only the constant disturbances.
    let constant = nd - aug.gusts;
    t.u_d.columns_mut(constant, aug.gusts).fill(0.0);
    for i in 0..m {
        for j in 0..m {
            t.s_r[(i, j)] = sol[(is[i], j)];
        }
        for j in 0..constant {
            t.s_d[(i, j)] = sol[(is[i], m + j)];
        }
        t.s_0[i] = sol[(is[i], m + nd)];
    }
    Ok(t)
}

/// Condense the problem and precompute the unconstrained law.
pub fn condense(
    aug: &Augmented,
    iv: &[usize],
    is: &[usize],
    w: Weights,
    np: usize,
    nc: usize,
) -> Result<Condensed, ControlError> {
    let m = aug.m;
    let nx = aug.nx();
    let ny = 3 * m;
    let nu = m * nc;
    // Φ, S_k = 𝒞𝒜ᵏℬ, y_off.
    let mut phi = DMatrix::<f64>::zeros(ny * np, nx);
    let mut s_blocks: Vec<DMatrix<f64>> = Vec::with_capacity(np);
    let mut y_off = DVector::<f64>::zeros(ny * np);
    let mut ca = aug.cy.clone(); // 𝒞𝒜ᵏ, k = 0
    let mut acc_off = DVector::<f64>::zeros(ny);
    for i in 0..np {
        s_blocks.push(&ca * &aug.b);
        acc_off += &ca * &aug.c;
        y_off.rows_mut(i * ny, ny).copy_from(&acc_off);
        ca = &ca * &aug.a;
        phi.view_mut((i * ny, 0), (ny, nx)).copy_from(&ca);
    }
    if phi.iter().any(|x| !x.is_finite()) || phi.amax() > 1e12 {
        return Err(ControlError::Model(format!(
            "prediction over {np} steps overflows: the model is strongly unstable"
        )));
    }
    // Γ: output step i+1 (row block i), decision j < Nc−1 uses input l = j;
    // decision Nc−1 covers inputs l = Nc−1 … i.
    let mut gamma = DMatrix::<f64>::zeros(ny * np, nu);
    for i in 0..np {
        for j in 0..nc {
            if j > i {
                break;
            }
            let blk = if j + 1 < nc {
                s_blocks[i - j].clone()
            } else {
                let mut acc = DMatrix::<f64>::zeros(ny, m);
                for sk in s_blocks.iter().take(i - j + 1) {
                    acc += sk;
                }
                acc
            };
            gamma.view_mut((i * ny, j * m), (ny, m)).copy_from(&blk);
        }
    }
    // Weights (squared, eq. 5.29–5.31).
    let mut qdiag = DVector::<f64>::zeros(ny * np);
    for i in 0..np {
        for a in 0..m {
            qdiag[i * ny + 3 * a] = w.v * w.v;
            qdiag[i * ny + 3 * a + 1] = w.swing_rate * w.swing_rate;
            qdiag[i * ny + 3 * a + 2] = w.swing * w.swing;
        }
    }
    // Hold expansion counts: decision j < Nc−1 appears once, the last Np − Nc + 1 times.
    let ru = w.u * w.u;
    let sdu = w.du * w.du;
    let mut gq = gamma.transpose(); // Γᵀ Q
    for (col, qv) in qdiag.iter().enumerate() {
        gq.column_mut(col).scale_mut(*qv);
    }
    let mut h = &gq * &gamma;
    for j in 0..nc {
        let count = if j + 1 < nc {
            1.0
        } else {
            (np - nc + 1) as f64
        };
        for a in 0..m {
            let d = j * m + a;
            h[(d, d)] += ru * count;
            // DᵀSD: increments j and j+1 involve u_j.
            h[(d, d)] += sdu * if j + 1 < nc { 2.0 } else { 1.0 };
            if j + 1 < nc {
                h[(d, d + m)] -= sdu;
                h[(d + m, d)] -= sdu;
            }
        }
    }
    let hchol = h.clone().cholesky().ok_or_else(|| {
        ControlError::Synthesis(
            "MPC Hessian is not positive definite: make w_acc_rate or w_acc > 0".into(),
        )
    })?;
    // f = F_ξ ξ₀ + F_r r + F_u u_prev + f₀.
    let mut f_xi = &gq * &phi;
    let mut f_r = DMatrix::<f64>::zeros(nu, m);
    let mut f_0 = &gq * &y_off;
    // −ΓᵀQ R_v r: velocity rows carry r.
    for i in 0..np {
        for a in 0..m {
            let row = i * ny + 3 * a;
            for d in 0..nu {
                f_r[(d, a)] -= gq[(d, row)];
            }
        }
    }
    let mut f_u = DMatrix::<f64>::zeros(nu, m);
    for a in 0..m {
        f_u[(a, a)] = -sdu;
    }
    if w.u != 0.0 || w.swing != 0.0 {
        let t = targets(aug, iv, is)?;
        let nm = aug.nm;
        // Swing reference s_ss on swing rows: −ΓᵀQ R_s (S_r r + S_d d + s_0).
        // Input target: −MᵀR M_u (U_r r + U_d d + u_0).
        let mut g_s = DMatrix::<f64>::zeros(nu, m); // ΓᵀQ R_s
        for i in 0..np {
            for a in 0..m {
                let row = i * ny + 3 * a + 2;
                for d in 0..nu {
                    g_s[(d, a)] += gq[(d, row)];
                }
            }
        }
        let mut g_u = DMatrix::<f64>::zeros(nu, m); // MᵀR M_u
        for j in 0..nc {
            let count = if j + 1 < nc {
                1.0
            } else {
                (np - nc + 1) as f64
            };
            for a in 0..m {
                g_u[(j * m + a, a)] = ru * count;
            }
        }
        f_r -= &g_s * &t.s_r + &g_u * &t.u_r;
        let fd = &g_s * &t.s_d + &g_u * &t.u_d;
        let mut cols = f_xi.columns_mut(nm, aug.nd);
        cols -= &fd;
        f_0 -= &g_s * &t.s_0 + &g_u * &t.u_0;
    }
    let k_xi = -hchol.solve(&f_xi);
    let k_r = -hchol.solve(&f_r);
    let k_u = -hchol.solve(&f_u);
    let k0 = -hchol.solve(&f_0);
    Ok(Condensed {
        np,
        nc,
        m,
        phi,
        gamma,
        y_off,
        h,
        k_xi,
        k_r,
        k_u,
        k0,
    })
}
