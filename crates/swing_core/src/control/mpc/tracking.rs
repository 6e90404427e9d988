//! Position-tracking MPC with preview: the swing-damping MPC of [`super`] with the vehicle's
//! horizontal position added to the identified model and a reference trajectory known over
//! the horizon (a mission's path), for flying waypoints.
//!
//! **Model.** The identified delay model (velocity and swing per axis) in the augmented form
//! ξ₀ = [z; s⁻; d] of [`super::condense::Augmented`] gets the position of each axis in
//! front, ξ = [p; ξ₀], integrated by the trapezoidal rule from the model's own velocity:
//! ```text
//! p⁺ = p + T_s (v + v⁺)/2,   v⁺ = e_vᵀ(𝒜₀ ξ₀ + ℬ₀ u + c̃₀)
//! ```
//! (exact for a velocity linear over the tick). The Kalman filter
//! ([`super::estimator::SteadyStateKalman`]) measures the position and the newest frame; the
//! state disturbances of ξ₀ make the position offset-free (a steady force shows as a
//! velocity disturbance, which the position, an integrator, then does not drift with).
//!
//! **Outputs and references.** Per axis the tracked outputs are y = [q, v, ṡ, s] with
//! q = p + λ s the tracked point: the vehicle (λ = 0) or the payload (λ = the cable length
//! ℓ: the payload hangs ℓ sin s ≈ ℓ s from the vehicle, and at a hold it is the payload
//! that is put over the waypoint). The reference trajectory r(t) (position, velocity,
//! acceleration a_r and jerk j_r) gives the references of every step of the horizon:
//! q_ref = p_r; s_ref = −atan(a_r/g), the swing of a payload hanging still under the
//! acceleration a_r (any cable and payload: every link aligns with the apparent gravity);
//! ṡ_ref = its rate −j_r g/(g² + a_r²); v_ref = v_r − λ ṡ_ref (the vehicle's velocity that
//! moves the tracked point at v_r); the input reference a_r. Without preview every step of
//! the horizon takes the reference of now.
//!
//! **Cost.** As the velocity MPC's (eq. 5.28–5.31) with a position weight, every reference
//! time-varying, and the input increments measured against the reference's own:
//! J = Σᵢ ‖W (r_i − y_i)‖² + Σᵢ w_u²‖u_i − a_r,i‖² + Σ_{j<Nc} w_Δu²‖Δu_j − Δa_r,j‖²
//! (following the reference's acceleration ramps costs nothing; the increment weight smooths
//! only the corrections). Stacking the weighted rows (outputs from Γ, inputs from the hold
//! expansion M) as T with weights W, H = TᵀWT + DᵀSD (D the differencing, S = w_Δu² I) and
//! the unconstrained law is U* = K_ξ ξ̂ + K_u u_prev + k₀ + K_R R + K_δ δ with
//! K_R = H⁻¹TᵀW, R the stacked references of the rows whose weight is not zero,
//! K_δ = H⁻¹DᵀS and δ the reference's acceleration increments over the control horizon
//! (the first one from the reference of the previous tick). The acceleration bound of the leg flown (the
//! reference's, else `acc_max`) and the jerk bound make it the bounded QP of [`super::qp`].

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::condense::Augmented;
use super::estimator::SteadyStateKalman;
use super::qp::Bounds;
use super::{
    check_model, frame_sources, measurement_variances, process_noise, push_frame, qp_backend,
    settings_for, solve_bounded, start_spread, with_start, Backend, MpcSettings,
};
use crate::config::{positive, ConfigError};
use crate::control::layout::Measured;
use crate::control::{AxisState, ControlError, ReferencePreview, SwingController, TickInfo};
use crate::plant::params::GRAVITY;
use crate::sysid::LinearModel;

/// What the position reference is for: the vehicle or the payload hanging below it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrackTarget {
    /// The vehicle's position follows the reference.
    #[default]
    Vehicle,
    /// The payload's position (vehicle + cable length × sin swing) follows it.
    Payload,
}

/// The MPC settings the tracking MPC starts from: the velocity MPC's, with a lighter
/// input-increment weight (1 instead of 6). A step in the velocity reference wants a
/// smooth command; a reference that is already smooth does not, and at a hold the swing
/// must die out within a couple of seconds, which the heavier weight does not allow
/// (settling 5 s instead of 1.3 s on the delivery plan of `examples/missions`).
pub fn tracking_mpc_defaults() -> MpcSettings {
    MpcSettings {
        w_acc_rate: 1.0,
        ..MpcSettings::default()
    }
}

/// Read the `mpc` table of [`TrackingSettings`] as overrides of
/// [`tracking_mpc_defaults`], so that a partial table keeps the tracking defaults.
fn over_tracking_defaults<'de, D: serde::Deserializer<'de>>(d: D) -> Result<MpcSettings, D::Error> {
    use serde::de::Error;
    let given = serde_json::Value::deserialize(d)?;
    let serde_json::Value::Object(given) = given else {
        return Err(D::Error::custom("must be a table of MPC settings"));
    };
    let mut base = serde_json::to_value(tracking_mpc_defaults()).map_err(D::Error::custom)?;
    if let serde_json::Value::Object(map) = &mut base {
        map.extend(given);
    }
    MpcSettings::deserialize(base).map_err(D::Error::custom)
}

/// Settings of the tracking MPC (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackingSettings {
    /// The MPC's horizons, weights, bounds and estimator; fields not given take
    /// [`tracking_mpc_defaults`].
    #[serde(deserialize_with = "over_tracking_defaults")]
    pub mpc: MpcSettings,
    /// Position tracking weight [1/m]. The default (3) keeps the overshoot at a stop well
    /// inside a 0.3 m acceptance radius, which a hold must not leave: on the delivery plan
    /// 0.05–0.08 m in the simulator and 0.05–0.22 m on PX4 SITL, where 1.5 left 0.21–0.26 m
    /// and 0.29–0.33 m, for about 1° more swing on each leg.
    pub w_position: f64,
    /// Use the reference's future over the horizon (false: the reference of now is held
    /// over the whole horizon).
    pub preview: bool,
    /// What follows the reference: `vehicle` or `payload`.
    pub target: TrackTarget,
    /// Cable length for the `payload` target (the identified one) [m].
    pub cable_length: Option<f64>,
    /// Kalman measurement noise std of the position [m].
    pub kf_position_noise: f64,
    /// Kalman process noise std of the position per tick [m].
    pub kf_position_process_noise: f64,
}

impl Default for TrackingSettings {
    fn default() -> Self {
        Self {
            mpc: tracking_mpc_defaults(),
            w_position: 3.0,
            preview: true,
            target: TrackTarget::Vehicle,
            cable_length: None,
            kf_position_noise: 0.02,
            kf_position_process_noise: 0.002,
        }
    }
}

impl TrackingSettings {
    /// Check weights and noise levels; a payload target needs a cable length.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.mpc.validate().map_err(|e| e.within("mpc"))?;
        positive("w_position", self.w_position)?;
        positive("kf_position_noise", self.kf_position_noise)?;
        positive("kf_position_process_noise", self.kf_position_process_noise)?;
        if let Some(l) = self.cable_length {
            crate::config::in_range("cable_length", l, 0.01, 100.0)?;
        }
        if self.target == TrackTarget::Payload && self.cable_length.is_none() {
            return Err(ConfigError::new(
                "cable_length",
                "the payload target needs the cable length (the identified one)",
            ));
        }
        Ok(())
    }

    /// λ of the tracked point q = p + λ s [m].
    fn lever(&self) -> f64 {
        match self.target {
            TrackTarget::Vehicle => 0.0,
            TrackTarget::Payload => self.cable_length.unwrap_or(0.0),
        }
    }
}

/// Number of output channels per axis: [q, v, ṡ, s].
const OUTPUTS: usize = 4;

/// The position-tracking MPC (module docs); a [`SwingController`] that needs
/// [`SwingController::observe_reference`] before each tick.
pub struct TrackingMpc {
    settings: MpcSettings,
    tracking: TrackingSettings,
    dt: f64,
    n: usize,
    nz: usize,
    m: usize,
    np: usize,
    nc: usize,
    sources: Vec<Measured>,
    lag_copies: Vec<(usize, usize)>,
    /// Entries of ξ₀'s measured stack (z and s⁻).
    nm0: usize,
    /// Output weights (squared) per channel [q, v, ṡ, s] and of the input.
    w_out: [f64; OUTPUTS],
    w_in: f64,
    /// Prediction matrices of the outputs (for plots): Φ, Γ, offsets.
    phi: DMatrix<f64>,
    gamma: DMatrix<f64>,
    y_off: DVector<f64>,
    h: DMatrix<f64>,
    k_xi: DMatrix<f64>,
    k_u: DMatrix<f64>,
    k0: DVector<f64>,
    k_r: DMatrix<f64>,
    k_delta: DMatrix<f64>,
    kf: SteadyStateKalman,
    bounds: Bounds,
    backend: Backend,
    // Work buffers (allocated once).
    y: DVector<f64>,
    u_prev: DVector<f64>,
    u_unc: DVector<f64>,
    u_sol: DVector<f64>,
    f: DVector<f64>,
    xi: DVector<f64>,
    r: DVector<f64>,
    delta: DVector<f64>,
    /// The reference acceleration of the previous tick, per axis [m/s²].
    acc_ref_prev: [f64; 2],
    pred: DVector<f64>,
    position: [f64; 2],
    /// The reference: (Np + 1) steps × axes × [p, v, a, j]; step 0 is now.
    reference: Vec<f64>,
    acc_limit: f64,
    have_reference: bool,
    initialized: bool,
}

impl std::fmt::Debug for TrackingMpc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrackingMpc")
            .field("settings", &self.settings)
            .field("tracking", &self.tracking)
            .field("dt", &self.dt)
            .field("states", &self.n)
            .field("delays", &(self.nz / self.n))
            .field("axes", &self.m)
            .finish()
    }
}

/// The reference of one output channel from a reference sample (p, v, a, j) of one axis.
fn channel_reference(c: usize, p: f64, v: f64, a: f64, j: f64, lever: f64) -> f64 {
    let g = GRAVITY;
    let swing_rate = -j * g / (g * g + a * a);
    match c {
        0 => p,
        1 => v - lever * swing_rate,
        2 => swing_rate,
        _ => -(a / g).atan(),
    }
}

impl TrackingMpc {
    /// Build the controller: augment the model with the position, design the Kalman filter,
    /// condense the problem with its preview law and set up the bounded QP. All allocation
    /// happens here.
    pub fn new(model: &LinearModel, tracking: TrackingSettings) -> Result<Self, ControlError> {
        tracking.validate()?;
        let settings = settings_for(model, tracking.mpc.clone())?;
        let (n, q, m) = check_model(model)?;
        let nz = n * q;
        let dt = model.dt;
        let (sources, iv, is) = frame_sources(model)?;
        let aug = Augmented::new(
            &model.a,
            &model.b,
            &model.c,
            &model.input_mean,
            n,
            q,
            &iv,
            &is,
            dt,
            settings.disturbance,
            settings.gust_time(),
        );
        let nx0 = aug.nx();
        let nx = m + nx0;
        // ξ = [p; ξ₀]: p⁺ = p + T/2 (v + v⁺).
        let mut a = DMatrix::<f64>::zeros(nx, nx);
        let mut b = DMatrix::<f64>::zeros(nx, m);
        let mut c = DVector::<f64>::zeros(nx);
        a.view_mut((m, m), (nx0, nx0)).copy_from(&aug.a);
        b.view_mut((m, 0), (nx0, m)).copy_from(&aug.b);
        c.rows_mut(m, nx0).copy_from(&aug.c);
        for i in 0..m {
            a[(i, i)] = 1.0;
            for col in 0..nx0 {
                a[(i, m + col)] = 0.5 * dt * aug.a[(iv[i], col)];
            }
            a[(i, m + iv[i])] += 0.5 * dt;
            for k in 0..m {
                b[(i, k)] = 0.5 * dt * aug.b[(iv[i], k)];
            }
            c[i] = 0.5 * dt * aug.c[iv[i]];
        }
        // Outputs per axis [q, v, ṡ, s] from the velocity MPC's [v, ṡ, s] rows.
        let lever = tracking.lever();
        let mut cy = DMatrix::<f64>::zeros(OUTPUTS * m, nx);
        for i in 0..m {
            cy[(OUTPUTS * i, i)] = 1.0;
            for col in 0..nx0 {
                cy[(OUTPUTS * i, m + col)] = lever * aug.cy[(3 * i + 2, col)];
                for k in 0..3 {
                    cy[(OUTPUTS * i + 1 + k, m + col)] = aug.cy[(3 * i + k, col)];
                }
            }
        }
        let np = settings.horizon;
        let nc = settings.control_horizon;
        let w_out = [
            tracking.w_position.powi(2),
            settings.w_velocity.powi(2),
            settings.w_swing_rate.powi(2),
            settings.w_swing.powi(2),
        ];
        let w_in = settings.w_acc.powi(2);
        let sdu = settings.w_acc_rate.powi(2);
        let ny = OUTPUTS * m;
        let nu = m * nc;
        // Φ, Γ and the offsets of every step.
        let mut phi = DMatrix::<f64>::zeros(ny * np, nx);
        let mut gamma = DMatrix::<f64>::zeros(ny * np, nu);
        let mut y_off = DVector::<f64>::zeros(ny * np);
        let mut ca = cy.clone();
        let mut s_blocks: Vec<DMatrix<f64>> = Vec::with_capacity(np);
        let mut acc_off = DVector::<f64>::zeros(ny);
        for i in 0..np {
            s_blocks.push(&ca * &b);
            acc_off += &ca * &c;
            y_off.rows_mut(i * ny, ny).copy_from(&acc_off);
            ca = &ca * &a;
            phi.view_mut((i * ny, 0), (ny, nx)).copy_from(&ca);
        }
        if phi.iter().any(|x| !x.is_finite()) || phi.amax() > 1e12 {
            return Err(ControlError::Model(format!(
                "prediction over {np} steps overflows: the model is strongly unstable"
            )));
        }
        for i in 0..np {
            for j in 0..nc.min(i + 1) {
                let mut blk = s_blocks[i - j].clone();
                if j + 1 == nc {
                    for sk in s_blocks.iter().take(i - j) {
                        blk += sk;
                    }
                }
                gamma.view_mut((i * ny, j * m), (ny, m)).copy_from(&blk);
            }
        }
        // The weighted rows T: outputs of steps 1..Np, then inputs of steps 0..Np−1.
        let out_rows: Vec<usize> = (0..np * ny)
            .filter(|r| w_out[r % ny % OUTPUTS] > 0.0)
            .collect();
        let in_rows: usize = if w_in > 0.0 { np * m } else { 0 };
        let nt = out_rows.len() + in_rows;
        let mut t = DMatrix::<f64>::zeros(nt, nu);
        let mut wt = DVector::<f64>::zeros(nt);
        for (k, &r) in out_rows.iter().enumerate() {
            t.row_mut(k).copy_from(&gamma.row(r));
            wt[k] = w_out[r % ny % OUTPUTS];
        }
        for i in 0..in_rows / m.max(1) {
            let j = i.min(nc - 1);
            for a_ in 0..m {
                let k = out_rows.len() + i * m + a_;
                t[(k, j * m + a_)] = 1.0;
                wt[k] = w_in;
            }
        }
        // G = TᵀW; H = G T + DᵀSD.
        let mut g = t.transpose();
        for (col, w) in wt.iter().enumerate() {
            g.column_mut(col).scale_mut(*w);
        }
        let mut h = &g * &t;
        for j in 0..nc {
            for a_ in 0..m {
                let d = j * m + a_;
                h[(d, d)] += sdu * if j + 1 < nc { 2.0 } else { 1.0 };
                if j + 1 < nc {
                    h[(d, d + m)] -= sdu;
                    h[(d + m, d)] -= sdu;
                }
            }
        }
        let chol = h.clone().cholesky().ok_or_else(|| {
            ControlError::Synthesis(
                "tracking MPC Hessian is not positive definite: make w_acc_rate or w_acc > 0"
                    .into(),
            )
        })?;
        // f = G (Φ_T ξ + off_T − R) − S u_prev (rows of T that are outputs carry Φ, off).
        let mut phi_t = DMatrix::<f64>::zeros(nt, nx);
        let mut off_t = DVector::<f64>::zeros(nt);
        for (k, &r) in out_rows.iter().enumerate() {
            phi_t.row_mut(k).copy_from(&phi.row(r));
            off_t[k] = y_off[r];
        }
        let f_xi = &g * &phi_t;
        let f_0 = &g * &off_t;
        let mut f_u = DMatrix::<f64>::zeros(nu, m);
        for a_ in 0..m {
            f_u[(a_, a_)] = -sdu;
        }
        let k_xi = -chol.solve(&f_xi);
        let k_u = -chol.solve(&f_u);
        let k0 = -chol.solve(&f_0);
        let k_r = chol.solve(&g);
        // DᵀS: increment j involves u_j (+1) and u_{j−1} (−1).
        let mut dts = DMatrix::<f64>::zeros(nu, nu);
        for j in 0..nc {
            for a_ in 0..m {
                let d = j * m + a_;
                dts[(d, d)] = sdu;
                if j + 1 < nc {
                    dts[(d, d + m)] = -sdu;
                }
            }
        }
        let k_delta = chol.solve(&dts);
        // Kalman filter: measured [p; newest frame].
        let nm0 = aug.nm;
        let mut w = vec![tracking.kf_position_process_noise.powi(2); m];
        w.extend(process_noise(&settings, dt, n, &aug, &sources));
        let wm = DMatrix::from_diagonal(&DVector::from_vec(w));
        let mut v = vec![tracking.kf_position_noise.powi(2); m];
        v.extend(measurement_variances(&settings, &sources));
        let vm = DMatrix::from_diagonal(&DVector::from_vec(v));
        let mut spread = vec![0.0; m];
        spread.extend(start_spread(&settings, n, &aug, &sources));
        let kf = with_start(
            SteadyStateKalman::new(a, b, c, m + n, &wm, &vm)?,
            &spread,
            dt,
        )?;
        let bounds = Bounds {
            u_max: settings.acc_max,
            du_max: settings.jerk_max.map(|j| j * dt),
        };
        let backend = qp_backend(&h, bounds, settings.solver, m, nc)?;
        let acc_limit = settings.acc_max.unwrap_or(f64::INFINITY);
        Ok(Self {
            dt,
            n,
            nz,
            m,
            np,
            nc,
            sources,
            lag_copies: aug.lag_copies.clone(),
            nm0,
            w_out,
            w_in,
            phi,
            gamma,
            y_off,
            h,
            k_xi,
            k_u,
            k0,
            k_r,
            k_delta,
            kf,
            bounds,
            backend,
            y: DVector::zeros(m + nm0),
            u_prev: DVector::zeros(m),
            u_unc: DVector::zeros(nu),
            u_sol: DVector::zeros(nu),
            f: DVector::zeros(nu),
            xi: DVector::zeros(nx),
            r: DVector::zeros(nt),
            delta: DVector::zeros(nu),
            acc_ref_prev: [0.0; 2],
            pred: DVector::zeros(3 * m * np),
            position: [0.0; 2],
            reference: vec![0.0; (np + 1) * m * 4],
            acc_limit,
            have_reference: false,
            initialized: false,
            settings,
            tracking,
        })
    }

    /// The settings in use (the MPC's with the model's measurement noise applied).
    pub fn settings(&self) -> (&MpcSettings, &TrackingSettings) {
        (&self.settings, &self.tracking)
    }

    /// The steady-state Kalman filter.
    pub fn estimator(&self) -> &SteadyStateKalman {
        &self.kf
    }

    /// The estimate ξ̂ = [p; z; s⁻; d] after the last correction.
    pub fn state_estimate(&self) -> &[f64] {
        self.kf.estimate().as_slice()
    }

    /// The decision U (m·Nc, stage-major) of the last tick.
    pub fn predicted_inputs(&self) -> &[f64] {
        self.u_sol.as_slice()
    }

    /// Predicted outputs of the last tick, Np steps × axes × [q, v, ṡ, s] flattened
    /// row-major (q the tracked point), at the model's dt.
    pub fn predicted_outputs(&self) -> DVector<f64> {
        let mut out = self.y_off.clone();
        out.gemv(1.0, &self.phi, &self.xi, 1.0);
        out.gemv(1.0, &self.gamma, &self.u_sol, 1.0);
        out
    }

    /// Fill the stacked reference R of the weighted rows from the stored reference.
    fn fill_references(&mut self) {
        let (m, np) = (self.m, self.np);
        let lever = self.tracking.lever();
        let preview = self.tracking.preview;
        let mut k = 0;
        for i in 1..=np {
            let step = if preview { i } else { 0 };
            for a in 0..m {
                let o = (step * m + a) * 4;
                let (p, v, acc, j) = (
                    self.reference[o],
                    self.reference[o + 1],
                    self.reference[o + 2],
                    self.reference[o + 3],
                );
                for (ch, w) in self.w_out.iter().enumerate() {
                    if *w > 0.0 {
                        self.r[k] = channel_reference(ch, p, v, acc, j, lever);
                        k += 1;
                    }
                }
            }
        }
        // Reference acceleration increments over the control horizon.
        for j in 0..self.nc {
            for a in 0..m {
                let now = |k: usize| {
                    let step = if preview { k } else { 0 };
                    self.reference[(step * m + a) * 4 + 2]
                };
                let prev = if j == 0 {
                    self.acc_ref_prev[a]
                } else {
                    now(j - 1)
                };
                self.delta[j * m + a] = now(j) - prev;
            }
        }
        if self.w_in > 0.0 {
            for i in 0..np {
                let step = if preview { i } else { 0 };
                for a in 0..m {
                    self.r[k] = self.reference[(step * m + a) * 4 + 2];
                    k += 1;
                }
            }
        }
    }
}

impl SwingController for TrackingMpc {
    fn axes(&self) -> usize {
        self.m
    }

    fn period(&self) -> f64 {
        self.dt
    }

    fn reference_steps(&self) -> usize {
        self.np + 1
    }

    fn observe_reference(&mut self, position: &[f64], preview: &ReferencePreview<'_>) {
        let k = self.m.min(position.len());
        self.position[..k].copy_from_slice(&position[..k]);
        let steps = preview.steps.min(self.np + 1);
        let m = self.m;
        for i in 0..self.np + 1 {
            // A shorter preview holds its last sample.
            let src = i.min(steps.saturating_sub(1));
            for a in 0..m {
                for c in 0..4 {
                    self.reference[(i * m + a) * 4 + c] = preview.get(src, a, c);
                }
            }
        }
        self.acc_limit = preview.acc_limit.unwrap_or(f64::INFINITY);
        self.have_reference = steps > 0;
    }

    fn prediction(&mut self) -> Option<Vec<f64>> {
        // The trait's layout: Np × axes × [v, ṡ, s].
        let out = self.predicted_outputs();
        let m = self.m;
        for i in 0..self.np {
            for a in 0..m {
                for k in 0..3 {
                    self.pred[(i * m + a) * 3 + k] = out[(i * m + a) * OUTPUTS + 1 + k];
                }
            }
        }
        Some(self.pred.as_slice().to_vec())
    }

    fn reset(&mut self, state: &[AxisState], acc: &[f64]) {
        let m = self.m;
        let mut frame = [AxisState::default(); 2];
        for (a, f) in frame.iter_mut().enumerate().take(m) {
            let s = state.get(a).copied().unwrap_or_default();
            if s.v.is_finite() && s.swing.is_finite() && s.swing_rate.is_finite() {
                *f = s;
            }
        }
        for _ in 0..self.nz / self.n + 2 {
            push_frame(
                &mut self.y.as_mut_slice()[m..],
                self.n,
                self.nz,
                &self.lag_copies,
                &self.sources,
                &frame[..m],
            );
        }
        for a in 0..m {
            self.y[a] = self.position[a];
            self.acc_ref_prev[a] = self.reference[a * 4 + 2];
            let u = acc.get(a).copied().unwrap_or(0.0);
            self.u_prev[a] = if u.is_finite() { u } else { 0.0 };
        }
        self.xi.fill(0.0);
        self.xi.rows_mut(0, m + self.nm0).copy_from(&self.y);
        self.kf.restart(self.xi.as_slice());
        for j in 0..self.nc {
            for a in 0..m {
                self.u_sol[j * m + a] = self.u_prev[a];
            }
        }
        self.initialized = true;
    }

    fn step(
        &mut self,
        state: &[AxisState],
        vel_ref: &[f64],
        acc_out: &mut [f64],
    ) -> Result<TickInfo, ControlError> {
        crate::control::check_tick_inputs(self.m, state, vel_ref, acc_out)?;
        if !self.have_reference {
            return Err(ControlError::Input(
                "the position MPC needs a reference trajectory (fly it on a mission)".into(),
            ));
        }
        let m = self.m;
        if !self.position[..m].iter().all(|x| x.is_finite())
            || !self.reference.iter().all(|x| x.is_finite())
        {
            return Err(ControlError::Input(
                "position or reference trajectory is not finite".into(),
            ));
        }
        if !self.initialized {
            let zeros = [0.0; 2];
            self.reset(state, &zeros[..m]);
        } else {
            push_frame(
                &mut self.y.as_mut_slice()[m..],
                self.n,
                self.nz,
                &self.lag_copies,
                &self.sources,
                state,
            );
            for a in 0..m {
                self.y[a] = self.position[a];
            }
        }
        self.kf.correct(&self.y);
        if self.settings.measured_state {
            self.kf.hold_measured(&self.y);
        }
        self.xi.copy_from(self.kf.estimate());
        self.fill_references();
        self.u_unc.copy_from(&self.k0);
        self.u_unc.gemv(1.0, &self.k_xi, &self.xi, 1.0);
        self.u_unc.gemv(1.0, &self.k_u, &self.u_prev, 1.0);
        self.u_unc.gemv(1.0, &self.k_r, &self.r, 1.0);
        self.u_unc.gemv(1.0, &self.k_delta, &self.delta, 1.0);
        for a in 0..m {
            self.acc_ref_prev[a] = self.reference[a * 4 + 2];
        }
        // The leg's acceleration bound, where it is tighter than the controller's own.
        if let Some(own) = self.settings.acc_max {
            let lim = own.min(self.acc_limit);
            if self.bounds.u_max != Some(lim) {
                self.bounds.u_max = Some(lim);
                self.backend.set_bounds(self.bounds);
            }
        }
        let info = solve_bounded(
            &mut self.backend,
            &self.bounds,
            &self.h,
            &self.u_unc,
            &self.u_prev,
            &mut self.f,
            &mut self.u_sol,
        )?;
        for (a, out) in acc_out.iter_mut().enumerate() {
            let u = self.u_sol[a];
            if !u.is_finite() {
                return Err(ControlError::Solver("non-finite input from the QP".into()));
            }
            *out = u;
            self.u_prev[a] = u;
        }
        self.kf.predict(&self.u_prev);
        Ok(info)
    }
}
