//! Swing-damping and flight control: PX4's cascade, the LQR baseline and the MPC.
//!
//! A [`SwingController`] replaces PX4's velocity PID on one or two horizontal axes: it reads
//! the measured velocity and swing of each controlled axis and writes the acceleration
//! setpoint PX4's attitude generation then tracks (thesis figure 5.1, chapter 5).

pub mod px4;

use thiserror::Error;

use crate::error::{Categorized, Category};

pub mod deepc;
pub mod hover_thrust;
pub mod layout;
pub mod lqr;
pub mod mpc;
pub mod payload_p;
pub mod plant;
pub mod shaper;

pub use crate::plant::AxisState;
pub use deepc::{DeepcController, DeepcSettings};
pub use layout::{AxisColumns, AxisLayout, Measured};
pub use lqr::{LqrController, LqrSettings};
pub use mpc::tracking::{TrackTarget, TrackingMpc, TrackingSettings};
pub use mpc::{MpcController, MpcSettings, QpSolverKind};
pub use payload_p::{PayloadP, PayloadPSettings};
pub use plant::LinearPlant;
pub use shaper::{InputShaper, ShaperKind, ShaperSettings, SwingMode};

/// A reference trajectory over the coming ticks for controllers that track a position with
/// preview: per step k (k = 0 is now, then every controller tick) and horizontal axis
/// (North, East) the reference position [m], velocity [m/s], acceleration [m/s²] and jerk
/// [m/s³], and the acceleration bound of the leg flown now.
#[derive(Clone, Copy, Debug)]
pub struct ReferencePreview<'a> {
    /// Number of steps (k = 0 … steps − 1).
    pub steps: usize,
    /// Number of axes in `data`.
    pub axes: usize,
    /// `data[(k · axes + axis) · 4 + c]`, c = 0 position, 1 velocity, 2 acceleration, 3 jerk.
    pub data: &'a [f64],
    /// Acceleration bound of the leg flown now [m/s²] (none: the controller's own).
    pub acc_limit: Option<f64>,
}

impl ReferencePreview<'_> {
    /// Channel `c` (0 position, 1 velocity, 2 acceleration, 3 jerk) of `axis` at step `k`.
    pub fn get(&self, k: usize, axis: usize, c: usize) -> f64 {
        self.data[(k * self.axes + axis) * 4 + c]
    }
}

/// Something a controller did that a flight log should show (e.g. a model re-adopted).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerEvent {
    /// Controller tick at which it happened (1 = the first tick after the reset).
    pub tick: u64,
    /// What happened (`detected`, `requested`, `adopted`, `rejected`, `reverted`).
    pub what: &'static str,
    /// An accompanying figure (the detector statistic, the effective sample count …; NaN
    /// when none).
    pub value: f64,
}

/// How a controller tick produced its output.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TickKind {
    /// A precomputed linear law (no constraint active).
    #[default]
    Unconstrained,
    /// A constrained QP was solved.
    Constrained,
}

/// What a controller's output replaces in PX4's cascade.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ControlOutput {
    /// An acceleration setpoint [m/s²] in place of PX4's velocity PID (MPC, LQR, DeePC).
    #[default]
    Acceleration,
    /// A velocity setpoint [m/s] that PX4's own velocity PID then tracks (input shaper,
    /// payload feedback on the velocity setpoint).
    Velocity,
}

/// What one controller tick did, for logging.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TickInfo {
    /// Whether the QP was needed.
    pub kind: TickKind,
    /// Solver iterations (0 for the linear law).
    pub iterations: u32,
}

/// Errors of controller synthesis and stepping.
#[derive(Debug, Error)]
pub enum ControlError {
    /// Invalid controller settings.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// The model does not fit the controller (dimensions, missing states, unstable …).
    #[error("model: {0}")]
    Model(String),
    /// An identification step of a control routine failed (e.g. a refit in selection).
    #[error(transparent)]
    Sysid(#[from] crate::sysid::SysidError),
    /// A linear-algebra step (Riccati equation, eigenvalues) failed.
    #[error(transparent)]
    Linalg(#[from] crate::linalg::LinalgError),
    /// A Riccati equation or other synthesis step has no (stabilising) solution.
    #[error("synthesis failed: {0}")]
    Synthesis(String),
    /// The QP solver failed on a tick.
    #[error("QP solver: {0}")]
    Solver(String),
    /// Measurements or references of the wrong length or not finite.
    #[error("input: {0}")]
    Input(String),
}

impl Categorized for ControlError {
    fn category(&self) -> Category {
        match self {
            ControlError::Config(_) => Category::Config,
            ControlError::Model(_) => Category::Model,
            ControlError::Sysid(e) => e.category(),
            ControlError::Linalg(e) => e.category(),
            ControlError::Synthesis(_) => Category::Control,
            ControlError::Solver(_) => Category::Solver,
            ControlError::Input(_) => Category::Data,
        }
    }

    fn field(&self) -> Option<&str> {
        match self {
            ControlError::Config(e) => Some(&e.field),
            ControlError::Sysid(e) => e.field(),
            _ => None,
        }
    }
}

/// Check one tick's slices: one state, reference and output per axis, all finite.
pub fn check_tick_inputs(
    axes: usize,
    state: &[AxisState],
    vel_ref: &[f64],
    out: &[f64],
) -> Result<(), ControlError> {
    if state.len() != axes || vel_ref.len() != axes || out.len() != axes {
        return Err(ControlError::Input(format!(
            "expected {axes} axis state(s), reference(s) and output(s), got {}, {} and {}",
            state.len(),
            vel_ref.len(),
            out.len()
        )));
    }
    for (i, s) in state.iter().enumerate() {
        if !(s.v.is_finite() && s.swing.is_finite() && s.swing_rate.is_finite()) {
            return Err(ControlError::Input(format!(
                "axis {i} state is not finite: {s:?}"
            )));
        }
    }
    if let Some(i) = vel_ref.iter().position(|x| !x.is_finite()) {
        return Err(ControlError::Input(format!("vel_ref[{i}] is not finite")));
    }
    Ok(())
}

/// A swing-damping controller in place of PX4's velocity PID on the controlled axes.
///
/// Slices have one entry per controlled axis, in the order North, East.
pub trait SwingController: Send {
    /// Number of controlled horizontal axes (1 = North, 2 = North + East).
    fn axes(&self) -> usize;
    /// Tick period [s]; the runner calls [`SwingController::step`] at this rate.
    fn period(&self) -> f64;
    /// What the output of [`SwingController::step`] is (default: an acceleration setpoint).
    fn output(&self) -> ControlOutput {
        ControlOutput::Acceleration
    }
    /// Start from the given measured state and acceleration setpoint (bumpless transfer).
    fn reset(&mut self, state: &[AxisState], acc: &[f64]);
    /// One tick: measured state and velocity reference in, acceleration setpoint [m/s²] out
    /// (or a velocity setpoint [m/s] when [`SwingController::output`] says so).
    fn step(
        &mut self,
        state: &[AxisState],
        vel_ref: &[f64],
        acc_out: &mut [f64],
    ) -> Result<TickInfo, ControlError>;
    /// Predicted outputs of the last tick for plots (MPC: Np × axes × [v, swing rate,
    /// swing]); `None` for controllers that do not predict. Not for the real-time path.
    fn prediction(&mut self) -> Option<Vec<f64>> {
        None
    }
    /// Work that may run between ticks, off the timed tick path (e.g. a deferred model
    /// re-synthesis in simulation). Runners call it after each tick; the default does nothing.
    fn between_ticks(&mut self) {}
    /// The vertical channel of the last measurement: rotor thrust projected on the vertical
    /// [N] and the down velocity [m/s] (payload mass estimates); called before
    /// [`SwingController::step`] where the runner knows them. The default ignores them.
    fn observe_vertical(&mut self, _thrust_vertical: f64, _vd: f64) {}
    /// Steps of reference a controller that tracks a position with preview wants before each
    /// tick (see [`SwingController::observe_reference`]); 0 (the default) for controllers
    /// that track the velocity reference of [`SwingController::step`].
    fn reference_steps(&self) -> usize {
        0
    }
    /// The measured horizontal position [m] (one per axis) and the reference over the
    /// coming ticks, given before each [`SwingController::step`] while a trajectory is flown
    /// to controllers with [`SwingController::reference_steps`] > 0. The default ignores them.
    fn observe_reference(&mut self, _position: &[f64], _preview: &ReferencePreview<'_>) {}
    /// Events so far (see [`ControllerEvent`]); empty for controllers without any. Not for
    /// the real-time path.
    fn events(&self) -> Vec<ControllerEvent> {
        Vec::new()
    }
}
