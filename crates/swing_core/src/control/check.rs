//! Closed-loop step check of an MPC against a plant model: control-relevant model screening.
//!
//! Held-out rollout error (thesis 4.6.2) scores a model on inputs like those of its training
//! flight. An MPC drives the vehicle with other inputs, and a delay model of high rank can
//! have spurious slow modes that no training rollout excites but that the MPC's feedback on
//! the measured history does: the vehicle then creeps towards the setpoint for tens of
//! seconds or drifts off hover. Models within a few percent of the best rollout error differ
//! wildly here. This check flies the MPC designed on a candidate model, in closed loop, on a
//! *different*, physically structured plant (the white-box model of the same data: a true
//! velocity integrator and one pendulum), optionally behind a first-order input lag: hold,
//! velocity step, hold. A model whose MPC cannot hold and track that plant is not one to fly.

use crate::config::{finite, non_negative, positive, ConfigError};
use crate::control::{
    AxisState, ControlError, LinearPlant, MpcController, MpcSettings, SwingController,
};
use crate::sysid::LinearModel;

/// Most controller ticks one check may fly (a 20 s check at 30 ms is 667): a huge
/// `duration` or a tiny model `dt` is refused instead of looping for hours.
pub const MAX_CHECK_TICKS: usize = 1_000_000;

/// Scenario of a closed-loop step check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepCheckSettings {
    /// Velocity step on every axis [m/s].
    pub step: f64,
    /// Time of the step [s]; before it the reference is 0 (hover).
    pub t_step: f64,
    /// Length of the check [s].
    pub duration: f64,
    /// Time constant of a first-order lag between the controller and the plant [s] (0 = none).
    pub input_lag: f64,
}

impl Default for StepCheckSettings {
    fn default() -> Self {
        Self {
            step: 2.0,
            t_step: 2.0,
            duration: 20.0,
            input_lag: 0.0,
        }
    }
}

impl StepCheckSettings {
    /// Check the values: a non-zero finite step, the step inside the run.
    pub fn validate(&self) -> Result<(), ConfigError> {
        finite("step", self.step)?;
        if self.step == 0.0 {
            return Err(ConfigError::new("step", "must be non-zero"));
        }
        non_negative("t_step", self.t_step)?;
        positive("duration", self.duration)?;
        non_negative("input_lag", self.input_lag)?;
        if self.t_step >= self.duration {
            return Err(ConfigError::new(
                "t_step",
                format!("must be before the end ({} s)", self.duration),
            ));
        }
        Ok(())
    }
}

/// Excursion of a velocity `v` beyond the new setpoint `v_after` of a step from `v_before`,
/// as a fraction of the step (≤ 0 while short of the setpoint; 0 for no step). The one
/// definition of overshoot: the step check's and the flight metrics' (`overshoot_pct` =
/// 100 × the largest excursion after the step, at least 0).
pub fn excursion(v: f64, v_before: f64, v_after: f64) -> f64 {
    let step = v_after - v_before;
    if step == 0.0 {
        0.0
    } else {
        (v - v_after) * step.signum() / step.abs()
    }
}

/// Largest [`excursion`] over the velocities `v` after a step (−∞ for no samples).
pub fn overshoot(v: &[f64], v_before: f64, v_after: f64) -> f64 {
    v.iter()
        .map(|x| excursion(*x, v_before, v_after))
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Outcome of a closed-loop step check; errors are worst over the axes, relative to the step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepCheck {
    /// Largest [`excursion`] beyond the new setpoint, as a fraction of the step (≤ 0: none).
    pub overshoot: f64,
    /// |v − setpoint| at the end, as a fraction of the step (∞ when the loop diverged).
    pub final_error: f64,
    /// Largest |v| while holding hover before the step, as a fraction of the step.
    pub hold_drift: f64,
}

impl StepCheck {
    /// Whether every figure is within its bound (fractions of the step).
    pub fn passes(&self, max_overshoot: f64, max_final_error: f64, max_hold_drift: f64) -> bool {
        self.overshoot <= max_overshoot
            && self.final_error <= max_final_error
            && self.hold_drift <= max_hold_drift
    }
}

/// Check that `plant` can stand in for the controller's model: same inputs and sample time.
fn check_plant(controller: &LinearModel, plant: &LinearModel) -> Result<(), ControlError> {
    if controller.inputs != plant.inputs {
        return Err(ControlError::Model(format!(
            "plant inputs {:?} differ from the controller model's {:?}",
            plant.inputs, controller.inputs
        )));
    }
    if (controller.dt - plant.dt).abs() > 1e-9 * controller.dt.max(1.0) {
        return Err(ControlError::Model(format!(
            "plant dt {} s differs from the controller model's {} s",
            plant.dt, controller.dt
        )));
    }
    Ok(())
}

/// Fly the MPC designed on `controller` (with `settings`) on the linear `plant`, started at
/// rest (zero history; the plant's constant term acts as a disturbance): hover, a step of
/// `check.step` on every axis at `check.t_step`, hold to `check.duration`.
pub fn mpc_step_check(
    controller: &LinearModel,
    settings: MpcSettings,
    plant: &LinearModel,
    check: &StepCheckSettings,
) -> Result<StepCheck, ControlError> {
    let mut mpc = MpcController::new(controller, settings)?;
    step_check_with(&mut mpc, controller, plant, check)
}

/// [`mpc_step_check`] with a controller already built on `controller` (reset at the start):
/// one design, the costly part, serves several plants and lags.
pub fn step_check_with(
    mpc: &mut MpcController,
    controller: &LinearModel,
    plant: &LinearModel,
    check: &StepCheckSettings,
) -> Result<StepCheck, ControlError> {
    check.validate()?;
    check_plant(controller, plant)?;
    let mut lin = LinearPlant::new(plant)?;
    let m = lin.axes();
    let dt = plant.dt;
    let ticks_f = (check.duration / dt).round();
    if ticks_f.is_nan() || ticks_f > MAX_CHECK_TICKS as f64 {
        return Err(ConfigError::new(
            "duration",
            format!(
                "{} s at dt = {dt} s is more than {MAX_CHECK_TICKS} ticks",
                check.duration
            ),
        )
        .into());
    }
    let ticks = ticks_f as usize;
    let step_tick = (check.t_step / dt).round() as usize;
    let lag = if check.input_lag > 0.0 {
        (-dt / check.input_lag).exp()
    } else {
        0.0
    };
    let mut applied = vec![0.0; m];
    let mut state = vec![AxisState::default(); m];
    let mut vel_ref = vec![0.0; m];
    let mut out = vec![0.0; m];
    mpc.reset(&state, &out);
    let step = check.step.abs();
    let mut result = StepCheck {
        overshoot: f64::NEG_INFINITY,
        final_error: 0.0,
        hold_drift: 0.0,
    };
    for k in 0..ticks {
        lin.measure(&mut state);
        for a in 0..m {
            let v = state[a].v;
            if !v.is_finite() || v.abs() > 1e3 * step {
                result.final_error = f64::INFINITY;
                result.overshoot = f64::INFINITY;
                return Ok(result);
            }
            if k < step_tick {
                result.hold_drift = result.hold_drift.max(v.abs() / step);
            } else {
                result.overshoot = result.overshoot.max(excursion(v, 0.0, check.step));
            }
            vel_ref[a] = if k >= step_tick { check.step } else { 0.0 };
        }
        mpc.step(&state, &vel_ref, &mut out)?;
        for a in 0..m {
            applied[a] = lag * applied[a] + (1.0 - lag) * out[a];
        }
        lin.step(&applied);
    }
    lin.measure(&mut state);
    for s in &state {
        let e = (s.v - check.step).abs() / step;
        result.final_error = result
            .final_error
            .max(if e.is_finite() { e } else { f64::INFINITY });
    }
    Ok(result)
}
