//! Data-driven swing-damping MPC on an identified delay-coordinate model (thesis 5.4).
//!
//! Equations: prediction model with the delay-embedded state, backward-difference swing rate
//! and velocity input disturbance (eq. 5.23–5.27, 5.32–5.34) in [`condense`]; cost with
//! output, input and input-increment weights over prediction horizon Np and control horizon
//! Nc with the input held after Nc (eq. 5.21–5.22, 5.28–5.31) condensed to a dense QP in
//! [`condense`]; the steady-state Kalman filter of the disturbance in [`estimator`]; the
//! bounded QP and its solvers in [`qp`] and [`active_set`].
//!
//! One tick: shift the measured history into the delay stack, Kalman correction, the
//! precomputed unconstrained law U* = K_ξ ξ̂ + K_r v_ref + K_u u_prev + k₀; if U* violates a
//! bound, solve the QP (Clarabel or the dense active set) with gradient f = −H U*; apply the
//! first move, Kalman prediction. All work buffers are allocated at construction.

pub mod active_set;
pub mod condense;
pub mod estimator;
pub mod qp;
pub mod tracking;

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use self::active_set::ActiveSetQp;
pub use self::condense::DisturbanceModel;
use self::condense::{condense, Augmented, Condensed, Weights};
use self::estimator::SteadyStateKalman;
use self::qp::{Bounds, ClarabelQp};
use super::layout::{AxisLayout, Measured};
use super::{AxisState, ControlError, SwingController, TickInfo, TickKind};
use crate::config::{non_negative, positive, ConfigError};
use crate::sysid::LinearModel;

/// Which QP solver handles ticks with an active bound.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QpSolverKind {
    /// Clarabel interior point, built once and updated in place.
    Clarabel,
    /// Dense Goldfarb–Idnani dual active set on the constant Cholesky factor of H.
    #[default]
    ActiveSet,
}

/// MPC tuning and limits. Weights multiply the error before squaring (eq. 5.29–5.31).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MpcSettings {
    /// Prediction horizon Np [ticks of the model's dt]; should span ≥ one swing period of
    /// the longest cable (≈ 3 s).
    pub horizon: usize,
    /// Control horizon Nc [ticks], 1 ≤ Nc ≤ Np; the input is held after Nc (eq. 5.22).
    pub control_horizon: usize,
    /// Velocity tracking weight [1/(m/s)].
    pub w_velocity: f64,
    /// Swing-rate weight [1/(rad/s)] (backward difference, eq. 5.27).
    pub w_swing_rate: f64,
    /// Swing-angle weight [1/rad] (reference: the steady-state swing; 0 = off, as the thesis).
    pub w_swing: f64,
    /// Input weight [1/(m/s²)] around the steady-state input (0 = off).
    pub w_acc: f64,
    /// Input-increment weight [1/(m/s²)] per tick.
    pub w_acc_rate: f64,
    /// Bound on |acceleration setpoint| [m/s²] (none = unbounded).
    pub acc_max: Option<f64>,
    /// Bound on |acceleration setpoint change| [m/s³] (none = unbounded); per tick the
    /// increment bound is jerk_max · dt.
    pub jerk_max: Option<f64>,
    /// Kalman process noise std of the model state per tick [state units: m/s, rad].
    pub kf_process_noise: f64,
    /// Where the estimated disturbances enter: `state` (default, offset-free for any
    /// constant disturbance), `velocity` (the thesis's eq. 5.33) or `input`.
    pub disturbance: DisturbanceModel,
    /// Kalman process noise std of each disturbance per tick [m/s² for velocity/input;
    /// state units per second for state]; a model that carries a larger one
    /// (`Diagnostics::disturbance_noise`, from the selection's disturbance design) raises it.
    pub kf_disturbance_noise: f64,
    /// With `disturbance = "state"`: process noise std of the swing disturbances, as a
    /// fraction of `kf_disturbance_noise` (1 = same; < 1 adapts to a steady payload force
    /// such as wind more slowly than to a force on the vehicle).
    pub kf_swing_disturbance_scale: f64,
    /// Stationary std of the gust force the filter estimates on each axis' velocity
    /// [m/s²] (0: no gust state; `condense` module docs); a model that carries a larger
    /// one (`Diagnostics::gust_noise`, from the selection's disturbance design) raises it.
    pub gust_noise: f64,
    /// Correlation time of the gust force [s]: how fast the MPC predicts a gust to fade.
    pub gust_time: f64,
    /// Kalman measurement noise std [state units: m/s, rad]; a model that carries a
    /// larger one (`Diagnostics::measurement_noise`, from the selection) raises it.
    pub kf_measurement_noise: f64,
    /// Kalman measurement noise std of the swing channels [rad, rad/s] (none: the same as
    /// `kf_measurement_noise`); a model that carries a larger one
    /// (`Diagnostics::swing_measurement_noise`, from the selection's noise design) raises it.
    pub kf_swing_measurement_noise: Option<f64>,
    /// Spread of the filter's first guess of every swing in the delay stack when the
    /// controller takes over, as a multiple of the swing's measurement noise std (the guess,
    /// a steady history, holds a swing the payload already has at one phase only): the
    /// filter starts from that prior and its gain settles to the steady one
    /// ([`SteadyStateKalman::with_start`]); 0 = steady from the first tick. Relative to the
    /// measurement noise so that a model trusted over its measurement (a larger swing
    /// measurement noise, the selection's trust design) still learns a swing it did not
    /// cause as fast as it would measure it: raising V by f² alone would shrink the prior
    /// by f² as well, since the gain depends only on the ratios of P₀, W and V.
    pub kf_start_spread: f64,
    /// QP solver for ticks with an active bound: `clarabel` or `active_set`.
    pub solver: QpSolverKind,
    /// Use the measured delay stack as the state and estimate only the disturbances
    /// (see [`SteadyStateKalman::hold_measured`]); `false` filters the stack too.
    pub measured_state: bool,
}

impl Default for MpcSettings {
    fn default() -> Self {
        Self {
            // One home with the identification's stability screen, which judges a model's
            // growth over the horizon it will be used for.
            horizon: crate::sysid::settings::default_prediction_samples(),
            control_horizon: 20,
            w_velocity: 1.0,
            // Tuned on the thesis's experiment matrix (payload grid, wind, double pendulum,
            // mass change; `swingrt experiment`): the swing-rate weight damps heavy payloads
            // on short cables; an input-rate weight as large keeps the command as smooth as
            // the LQR's (total variation within 1.6× in every experiment, against up to 5×
            // and a diverging light long-cable case at 2) for at most 0.6 deg·s more swing
            // above the momentum floor, still below the LQR's.
            w_swing_rate: 6.0,
            w_swing: 0.0,
            w_acc: 0.0,
            w_acc_rate: 6.0,
            acc_max: Some(4.0),
            jerk_max: None,
            kf_process_noise: 0.01,
            disturbance: DisturbanceModel::State,
            kf_disturbance_noise: 0.02,
            // A swing disturbance that adapts as fast as the velocity one lets the estimator
            // explain a model's slow-mode mismatch as a payload force, and the loop creeps or
            // runs away; a tenth of the velocity disturbance's rate avoids that and still
            // lets a wind step settle.
            kf_swing_disturbance_scale: 0.1,
            gust_noise: 0.0,
            // The gusts of the robustness studies last 2 s, and a gust much longer than the
            // swing's period is wind the constant disturbance takes up.
            gust_time: 2.0,
            kf_measurement_noise: 0.01,
            kf_swing_measurement_noise: None,
            // Off: at 3 (a guess worth a ninth of a measurement), which lets the trust
            // design's picks damp a swing already there at the takeover as the picks as
            // designed do, some vehicles the twin is not swing more after the step, and on
            // PX4 SITL's model every raised trust drifts in the selection's linear hold
            // (docs/selection.md).
            kf_start_spread: 0.0,
            solver: QpSolverKind::ActiveSet,
            measured_state: false,
        }
    }
}

impl MpcSettings {
    /// The Kalman measurement noise std of the swing channels in effect.
    pub fn swing_measurement_noise(&self) -> f64 {
        self.kf_swing_measurement_noise
            .unwrap_or(self.kf_measurement_noise)
    }

    /// The gust states' correlation time [s] when the filter estimates gusts
    /// (`gust_noise` > 0).
    pub fn gust_time(&self) -> Option<f64> {
        (self.gust_noise > 0.0).then_some(self.gust_time)
    }

    /// Check horizons, weights and limits.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.horizon == 0 || self.horizon > 2000 {
            return Err(ConfigError::new(
                "horizon",
                format!("must be between 1 and 2000 ticks (got {})", self.horizon),
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
        non_negative("w_acc", self.w_acc)?;
        non_negative("w_acc_rate", self.w_acc_rate)?;
        if self.w_acc == 0.0 && self.w_acc_rate == 0.0 {
            return Err(ConfigError::new(
                "w_acc_rate",
                "w_acc or w_acc_rate must be > 0 (the QP needs a positive definite Hessian)",
            ));
        }
        if let Some(a) = self.acc_max {
            positive("acc_max", a)?;
        }
        if let Some(j) = self.jerk_max {
            positive("jerk_max", j)?;
        }
        positive("kf_process_noise", self.kf_process_noise)?;
        positive("kf_disturbance_noise", self.kf_disturbance_noise)?;
        positive(
            "kf_swing_disturbance_scale",
            self.kf_swing_disturbance_scale,
        )?;
        non_negative("gust_noise", self.gust_noise)?;
        positive("gust_time", self.gust_time)?;
        positive("kf_measurement_noise", self.kf_measurement_noise)?;
        if let Some(r) = self.kf_swing_measurement_noise {
            positive("kf_swing_measurement_noise", r)?;
        }
        non_negative("kf_start_spread", self.kf_start_spread)?;
        Ok(())
    }
}

pub(crate) enum Backend {
    None,
    Clarabel(Box<ClarabelQp>),
    ActiveSet(Box<ActiveSetQp>),
}

impl Backend {
    /// New bound values of the same kinds (an acceleration bound that changes per leg).
    pub(crate) fn set_bounds(&mut self, bounds: Bounds) {
        match self {
            Backend::None => {}
            Backend::Clarabel(qp) => qp.set_bounds(bounds),
            Backend::ActiveSet(qp) => qp.set_bounds(bounds),
        }
    }
}

/// The MPC controller (see module docs); implements [`SwingController`] at the model's dt.
pub struct MpcController {
    settings: MpcSettings,
    dt: f64,
    n: usize,
    nz: usize,
    m: usize,
    sources: Vec<Measured>,
    /// Per axis: index of the swing in the newest frame.
    is: Vec<usize>,
    aug: Augmented,
    cond: Condensed,
    kf: SteadyStateKalman,
    bounds: Bounds,
    backend: Backend,
    // Work buffers (allocated once).
    y: DVector<f64>,
    u_prev: DVector<f64>,
    r: DVector<f64>,
    u_unc: DVector<f64>,
    u_sol: DVector<f64>,
    f: DVector<f64>,
    xi_last: DVector<f64>,
    pred: DVector<f64>,
    initialized: bool,
}

impl std::fmt::Debug for MpcController {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MpcController")
            .field("settings", &self.settings)
            .field("dt", &self.dt)
            .field("states", &self.n)
            .field("delays", &(self.nz / self.n))
            .field("axes", &self.m)
            .finish()
    }
}

/// Check a model's dimensions and entries; returns (states n, delays q, inputs m).
pub(crate) fn check_model(model: &LinearModel) -> Result<(usize, usize, usize), ControlError> {
    let bad = |s: String| Err(ControlError::Model(s));
    let n = model.states.len();
    let q = model.delays;
    let m = model.inputs.len();
    if n == 0 || q == 0 {
        return bad(format!(
            "model needs ≥ 1 state and delays ≥ 1 (got {n} states, q = {q})"
        ));
    }
    if !(1..=2).contains(&m) {
        return bad(format!("model must have 1 or 2 inputs (axes), got {m}"));
    }
    let Some(nz) = n.checked_mul(q) else {
        return bad(format!("{n} states × {q} delays overflows"));
    };
    if model.a.shape() != (nz, nz) {
        return bad(format!(
            "A must be {nz}×{nz} (states × delays), got {:?}",
            model.a.shape()
        ));
    }
    if model.b.shape() != (nz, m) {
        return bad(format!("B must be {nz}×{m}, got {:?}", model.b.shape()));
    }
    if model.c.len() != nz {
        return bad(format!("c must have {nz} entries, got {}", model.c.len()));
    }
    if model.input_mean.len() != m {
        return bad(format!(
            "input_mean must have {m} entries, got {}",
            model.input_mean.len()
        ));
    }
    if !(model.dt.is_finite() && model.dt > 0.0) {
        return bad(format!("dt must be > 0 (got {})", model.dt));
    }
    let finite = model.a.iter().all(|x| x.is_finite())
        && model.b.iter().all(|x| x.is_finite())
        && model.c.iter().all(|x| x.is_finite())
        && model.input_mean.iter().all(|x| x.is_finite());
    if !finite {
        return bad("model has non-finite entries".into());
    }
    Ok((n, q, m))
}

/// `settings` checked, with the Kalman measurement noise and the disturbances' process noise
/// raised to what the model carries (a model selected on noisy data says how much noise its
/// estimator must assume, one designed against a gust how fast its disturbances move), and
/// the input-rate weight too (one designed against an unseen second link how smooth its
/// command must be).
pub(crate) fn settings_for(
    model: &LinearModel,
    settings: MpcSettings,
) -> Result<MpcSettings, ControlError> {
    settings.validate()?;
    let mut settings = settings;
    if let Some(r) = model.diagnostics.measurement_noise {
        positive("measurement_noise", r)?;
        settings.kf_measurement_noise = settings.kf_measurement_noise.max(r);
    }
    if let Some(r) = model.diagnostics.swing_measurement_noise {
        positive("swing_measurement_noise", r)?;
        let own = settings.swing_measurement_noise();
        settings.kf_swing_measurement_noise = Some(own.max(r));
    }
    if let Some(q) = model.diagnostics.disturbance_noise {
        positive("disturbance_noise", q)?;
        settings.kf_disturbance_noise = settings.kf_disturbance_noise.max(q);
    }
    if let Some(g) = model.diagnostics.gust_noise {
        positive("gust_noise", g)?;
        settings.gust_noise = settings.gust_noise.max(g);
    }
    if let Some(w) = model.diagnostics.acc_rate_weight {
        positive("acc_rate_weight", w)?;
        settings.w_acc_rate = settings.w_acc_rate.max(w);
    }
    Ok(settings)
}

/// The Kalman measurement noise variance of each model state of the newest frame: the
/// velocity's `kf_measurement_noise`, the swing's and its rate's
/// [`MpcSettings::swing_measurement_noise`].
pub(crate) fn measurement_variances(settings: &MpcSettings, sources: &[Measured]) -> Vec<f64> {
    sources
        .iter()
        .map(|s| match s {
            Measured::V(_) => settings.kf_measurement_noise.powi(2),
            Measured::Swing(_) | Measured::SwingRate(_) => {
                settings.swing_measurement_noise().powi(2)
            }
        })
        .collect()
}

/// Diagonal of the Kalman filter's start spread Σ₀ over ξ = [z; s⁻; d; g]
/// ([`SteadyStateKalman::with_start`]): (`kf_start_spread` × the swing measurement noise)²
/// on every swing and swing rate of the delay stack and on the lagged swings; nothing on the
/// velocities (measured as well before the takeover as after) and on the disturbances.
pub(crate) fn start_spread(
    settings: &MpcSettings,
    n: usize,
    aug: &Augmented,
    sources: &[Measured],
) -> Vec<f64> {
    let var = (settings.kf_start_spread * settings.swing_measurement_noise()).powi(2);
    let nz = aug.nm - aug.lag_copies.len();
    (0..aug.nx())
        .map(|i| {
            if i < nz {
                match sources[i % n] {
                    Measured::V(_) => 0.0,
                    Measured::Swing(_) | Measured::SwingRate(_) => var,
                }
            } else if i < aug.nm {
                var
            } else {
                0.0
            }
        })
        .collect()
}

/// The start's length cap [s] and tolerance (relative to the steady gain's largest entry).
/// Cut at the stack's length (when every frame of the guess has shifted out) instead, the
/// start ends far from the steady gain when the filter trusts its model 30-100× more, and
/// the jump left the default step's trust picks swinging (seed 1: 3.7 deg·s against 0.5).
const START_MAX_S: f64 = 10.0;
const START_TOL: f64 = 1e-3;

/// `kf` with the start of the `spread` ([`start_spread`]) for a model of tick `dt`.
pub(crate) fn with_start(
    kf: SteadyStateKalman,
    spread: &[f64],
    dt: f64,
) -> Result<SteadyStateKalman, ControlError> {
    kf.with_start(spread, (START_MAX_S / dt).ceil() as usize, START_TOL)
}

/// The Kalman filter of the MPC: the steady gain for the settings' process and measurement
/// noise, with the start of `settings.kf_start_spread`.
fn mpc_filter(
    aug: &Augmented,
    settings: &MpcSettings,
    dt: f64,
    n: usize,
    sources: &[Measured],
) -> Result<SteadyStateKalman, ControlError> {
    let w = DMatrix::from_diagonal(&DVector::from_vec(process_noise(
        settings, dt, n, aug, sources,
    )));
    let v = DMatrix::from_diagonal(&DVector::from_vec(measurement_variances(settings, sources)));
    let kf = SteadyStateKalman::new(aug.a.clone(), aug.b.clone(), aug.c.clone(), n, &w, &v)?;
    with_start(kf, &start_spread(settings, n, aug, sources), dt)
}

/// What each model state of the newest frame measures, then each axis' velocity index and
/// swing index in that frame.
type FrameSources = (Vec<Measured>, Vec<usize>, Vec<usize>);

/// What each model state of the newest frame measures, and each axis' velocity and swing
/// index in that frame.
pub(crate) fn frame_sources(model: &LinearModel) -> Result<FrameSources, ControlError> {
    let layout = AxisLayout::from_model(model)?;
    let sources = model
        .states
        .iter()
        .map(|name| {
            layout.classify(name).ok_or_else(|| {
                ControlError::Model(format!(
                    "model state '{name}' is not one the controller measures on axes {:?} \
                     (expected v<axis>, swing_<axis> or swing_rate_<axis>)",
                    layout.suffixes()
                ))
            })
        })
        .collect::<Result<Vec<Measured>, _>>()?;
    let iv = layout.axes().iter().map(|a| a.v).collect();
    let is = layout.axes().iter().map(|a| a.swing).collect();
    Ok((sources, iv, is))
}

/// Build the QP backend for the bounds (none when there is no bound).
pub(crate) fn qp_backend(
    h: &DMatrix<f64>,
    bounds: Bounds,
    solver: QpSolverKind,
    m: usize,
    nc: usize,
) -> Result<Backend, ControlError> {
    Ok(if !bounds.any() {
        Backend::None
    } else {
        match solver {
            QpSolverKind::Clarabel => {
                Backend::Clarabel(Box::new(ClarabelQp::new(h, bounds, m, nc)?))
            }
            QpSolverKind::ActiveSet => {
                Backend::ActiveSet(Box::new(ActiveSetQp::new(h, bounds, m, nc)?))
            }
        }
    })
}

/// Diagonal of the Kalman process noise of ξ = [z; s⁻; d; g] (module docs of
/// [`estimator`]) for a model of tick `dt`: only the newest frame is a new measurement each
/// tick; the older frames of the stack are the same measurements shifted down, so they
/// carry neither process noise (the shift is exact) nor fresh measurement noise. Filtering
/// them as independent measurements would let the noise of every frame through the gain
/// K_ξ, which weighs differences of frames (rates) heavily. The `gusts` gust states, last,
/// get the per-tick noise that keeps their stationary std at `gust_noise`.
pub(crate) fn process_noise(
    settings: &MpcSettings,
    dt: f64,
    n: usize,
    aug: &Augmented,
    sources: &[Measured],
) -> Vec<f64> {
    let (nm, nd) = (aug.nm, aug.nd);
    let constant = nd - aug.gusts;
    let decay = (-2.0 * dt / settings.gust_time).exp();
    let gust = settings.gust_noise.powi(2) * (1.0 - decay);
    (0..nm + nd)
        .map(|i| {
            if i < n {
                settings.kf_process_noise.powi(2)
            } else if i < nm {
                0.0
            } else if i >= nm + constant {
                gust
            } else {
                let swing = settings.disturbance == DisturbanceModel::State
                    && !matches!(sources[i - nm], Measured::V(_));
                let scale = if swing {
                    settings.kf_swing_disturbance_scale
                } else {
                    1.0
                };
                (settings.kf_disturbance_noise * scale).powi(2)
            }
        })
        .collect()
}

/// Write the newest measured frame into the delay stack `ys` of n states × nz entries
/// (shifting older frames down; `lag_copies` keep the older swings the stack does not hold).
pub(crate) fn push_frame(
    ys: &mut [f64],
    n: usize,
    nz: usize,
    lag_copies: &[(usize, usize)],
    sources: &[Measured],
    state: &[AxisState],
) {
    // Older swings the stack does not hold (q < 3), for the swing-rate difference; the
    // copies run from the last (oldest) backwards so each reads the previous tick's value.
    for &(dst, src) in lag_copies.iter().rev() {
        ys[dst] = ys[src];
    }
    ys.copy_within(0..nz - n, n);
    for (k, src) in sources.iter().enumerate() {
        ys[k] = match *src {
            Measured::V(a) => state[a].v,
            Measured::Swing(a) => state[a].swing,
            Measured::SwingRate(a) => state[a].swing_rate,
        };
    }
}

/// The decision of one tick: the unconstrained minimiser `u_unc` when it meets the bounds,
/// else the bounded QP's (f = −H U*, as U* minimises ½UᵀHU + fᵀU); written to `u_sol`.
pub(crate) fn solve_bounded(
    backend: &mut Backend,
    bounds: &Bounds,
    h: &DMatrix<f64>,
    u_unc: &DVector<f64>,
    u_prev: &DVector<f64>,
    f: &mut DVector<f64>,
    u_sol: &mut DVector<f64>,
) -> Result<TickInfo, ControlError> {
    let mut info = TickInfo::default();
    let needs_qp = bounds.any() && bounds.violated(u_unc.as_slice(), u_prev.as_slice(), 1e-9);
    if !needs_qp {
        u_sol.copy_from(u_unc);
        return Ok(info);
    }
    f.gemv(-1.0, h, u_unc, 0.0);
    let iters = match backend {
        Backend::None => 0,
        Backend::Clarabel(qp) => qp.solve(f.as_slice(), u_prev.as_slice(), u_sol.as_mut_slice())?,
        Backend::ActiveSet(qp) => qp.solve(
            f.as_slice(),
            u_unc.as_slice(),
            u_prev.as_slice(),
            u_sol.as_mut_slice(),
        )?,
    };
    info.kind = TickKind::Constrained;
    info.iterations = iters;
    Ok(info)
}

impl MpcController {
    /// Build the controller: augment the model, design the Kalman filter, condense the QP
    /// and set up the solver. All allocation happens here.
    pub fn new(model: &LinearModel, settings: MpcSettings) -> Result<Self, ControlError> {
        let settings = settings_for(model, settings)?;
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
        let nm = aug.nm;
        let nx = aug.nx();
        let weights = Weights {
            v: settings.w_velocity,
            swing_rate: settings.w_swing_rate,
            swing: settings.w_swing,
            u: settings.w_acc,
            du: settings.w_acc_rate,
        };
        let cond = condense(
            &aug,
            &iv,
            &is,
            weights,
            settings.horizon,
            settings.control_horizon,
        )?;
        let kf = mpc_filter(&aug, &settings, dt, n, &sources)?;
        let bounds = Bounds {
            u_max: settings.acc_max,
            du_max: settings.jerk_max.map(|j| j * dt),
        };
        let nc = settings.control_horizon;
        let backend = qp_backend(&cond.h, bounds, settings.solver, m, nc)?;
        let nu = m * nc;
        let ny = 3 * m * settings.horizon;
        Ok(Self {
            settings,
            dt,
            n,
            nz,
            m,
            sources,
            is,
            aug,
            cond,
            kf,
            bounds,
            backend,
            y: DVector::zeros(nm),
            u_prev: DVector::zeros(m),
            r: DVector::zeros(m),
            u_unc: DVector::zeros(nu),
            u_sol: DVector::zeros(nu),
            f: DVector::zeros(nu),
            xi_last: DVector::zeros(nx),
            pred: DVector::zeros(ny),
            initialized: false,
        })
    }

    /// This design with the Kalman filter's swing-channel measurement noise set to `r`
    /// (as [`Self::new`] on a model carrying it would build it, not yet flown): only the
    /// filter is designed again; the condensed QP, which does not depend on it, is kept.
    pub fn with_swing_measurement_noise(&self, r: f64) -> Result<Self, ControlError> {
        positive("kf_swing_measurement_noise", r)?;
        let mut out = self.fresh_copy()?;
        out.settings.kf_swing_measurement_noise = Some(r);
        out.kf = mpc_filter(&out.aug, &out.settings, out.dt, out.n, &out.sources)?;
        Ok(out)
    }

    /// A controller of the same design that has not flown yet, as [`Self::new`] returns it
    /// (with the bounds now in force): the Kalman gain and the condensed QP, the costly
    /// part of a design, are copied; the QP solver is set up afresh, so nothing of this
    /// controller's flight (its solver's warm start, its last input) carries over.
    pub fn fresh_copy(&self) -> Result<Self, ControlError> {
        let backend = qp_backend(
            &self.cond.h,
            self.bounds,
            self.settings.solver,
            self.m,
            self.cond.nc,
        )?;
        Ok(Self {
            settings: self.settings.clone(),
            dt: self.dt,
            n: self.n,
            nz: self.nz,
            m: self.m,
            sources: self.sources.clone(),
            is: self.is.clone(),
            aug: self.aug.clone(),
            cond: self.cond.clone(),
            kf: self.kf.clone(),
            bounds: self.bounds,
            backend,
            y: DVector::zeros(self.y.len()),
            u_prev: DVector::zeros(self.m),
            r: DVector::zeros(self.m),
            u_unc: DVector::zeros(self.u_unc.len()),
            u_sol: DVector::zeros(self.u_sol.len()),
            f: DVector::zeros(self.f.len()),
            xi_last: DVector::zeros(self.xi_last.len()),
            pred: DVector::zeros(self.pred.len()),
            initialized: false,
        })
    }

    /// The settings in use.
    pub fn settings(&self) -> &MpcSettings {
        &self.settings
    }

    /// The condensed problem (prediction matrices, Hessian, unconstrained gains).
    pub fn condensed(&self) -> &Condensed {
        &self.cond
    }

    /// The disturbance-augmented prediction model.
    pub fn augmented(&self) -> &Augmented {
        &self.aug
    }

    /// The steady-state Kalman filter.
    pub fn estimator(&self) -> &SteadyStateKalman {
        &self.kf
    }

    /// Estimated disturbances (after the last correction), in the layout of
    /// [`MpcSettings::disturbance`], then the gusts (one per axis) when estimated.
    pub fn disturbance(&self) -> &[f64] {
        let nm = self.aug.nm;
        &self.kf.estimate().as_slice()[nm..nm + self.aug.nd]
    }

    /// The decision U (m·Nc, stage-major: u_0 of every axis, then u_1 …) of the last tick.
    pub fn predicted_inputs(&self) -> &[f64] {
        self.u_sol.as_slice()
    }

    /// Predicted outputs of the last tick, Np steps × axes × [v [m/s], swing rate [rad/s],
    /// swing [rad]] flattened row-major (step k+1 first), at the model's dt.
    pub fn predicted_trajectory(&mut self) -> &[f64] {
        self.pred.copy_from(&self.cond.y_off);
        self.pred.gemv(1.0, &self.cond.phi, &self.xi_last, 1.0);
        self.pred.gemv(1.0, &self.cond.gamma, &self.u_sol, 1.0);
        self.pred.as_slice()
    }

    /// Continue from `prev` (same states, delays and axes) without a bump: take over its
    /// measured delay stack, last input and state estimate; the disturbance estimate is taken
    /// over only with `keep_disturbance` (else it restarts at zero). Allocates nothing; for
    /// swapping in a controller re-synthesised on a new model between two ticks.
    pub fn take_over(
        &mut self,
        prev: &MpcController,
        keep_disturbance: bool,
    ) -> Result<(), ControlError> {
        if prev.n != self.n
            || prev.nz != self.nz
            || prev.m != self.m
            || prev.y.len() != self.y.len()
        {
            return Err(ControlError::Model(format!(
                "cannot take over from a controller with {} states × {} delays and {} axes \
                 (this one has {} × {} and {})",
                prev.n,
                prev.nz / prev.n,
                prev.m,
                self.n,
                self.nz / self.n,
                self.m
            )));
        }
        if !prev.initialized {
            self.initialized = false;
            return Ok(());
        }
        self.y.copy_from(&prev.y);
        self.u_prev.copy_from(&prev.u_prev);
        let nm = self.aug.nm;
        let prev_est = prev.kf.estimate();
        self.xi_last.fill(0.0);
        self.xi_last
            .rows_mut(0, nm)
            .copy_from(&prev_est.rows(0, nm));
        if keep_disturbance && prev.aug.nd == self.aug.nd {
            let nd = self.aug.nd;
            self.xi_last
                .rows_mut(nm, nd)
                .copy_from(&prev_est.rows(prev.aug.nm, nd));
        }
        // The previous controller's last posterior, propagated by the new model: the prior
        // the next tick corrects.
        self.kf.set_prior(self.xi_last.as_slice());
        self.kf.predict(&self.u_prev);
        for j in 0..self.cond.nc {
            for a in 0..self.m {
                self.u_sol[j * self.m + a] = self.u_prev[a];
            }
        }
        self.initialized = true;
        Ok(())
    }

    /// Which measured quantity each model state of the newest frame is, and each axis'
    /// swing index in that frame (for the closed-loop linear maps of [`crate::design::check`]).
    pub(crate) fn frame_layout(&self) -> (&[Measured], &[usize], usize) {
        (&self.sources, &self.is, self.n)
    }

    /// Write the newest measured frame into the delay stack (shifting older frames down).
    fn push_frame(&mut self, state: &[AxisState]) {
        push_frame(
            self.y.as_mut_slice(),
            self.n,
            self.nz,
            &self.aug.lag_copies,
            &self.sources,
            state,
        );
    }
}

impl SwingController for MpcController {
    fn axes(&self) -> usize {
        self.m
    }

    fn prediction(&mut self) -> Option<Vec<f64>> {
        Some(self.predicted_trajectory().to_vec())
    }

    fn period(&self) -> f64 {
        self.dt
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
        // A steady history: every frame equal to the current measurement.
        for _ in 0..self.nz / self.n + 2 {
            self.push_frame(&frame[..m]);
        }
        for a in 0..m {
            let u = acc.get(a).copied().unwrap_or(0.0);
            self.u_prev[a] = if u.is_finite() { u } else { 0.0 };
        }
        let nm = self.aug.nm;
        self.xi_last.fill(0.0);
        self.xi_last.rows_mut(0, nm).copy_from(&self.y);
        self.kf.restart(self.xi_last.as_slice());
        self.u_sol.fill(0.0);
        for j in 0..self.cond.nc {
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
        if !self.initialized {
            let zeros = [0.0; 2];
            self.reset(state, &zeros[..self.m]);
        } else {
            self.push_frame(state);
        }
        self.kf.correct(&self.y);
        if self.settings.measured_state {
            self.kf.hold_measured(&self.y);
        }
        self.xi_last.copy_from(self.kf.estimate());
        self.r.copy_from_slice(vel_ref);
        // Unconstrained law.
        let c = &self.cond;
        self.u_unc.copy_from(&c.k0);
        self.u_unc.gemv(1.0, &c.k_xi, &self.xi_last, 1.0);
        self.u_unc.gemv(1.0, &c.k_r, &self.r, 1.0);
        self.u_unc.gemv(1.0, &c.k_u, &self.u_prev, 1.0);
        let info = solve_bounded(
            &mut self.backend,
            &self.bounds,
            &c.h,
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
