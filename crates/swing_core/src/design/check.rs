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
//! Before flying, the unconstrained loop (the MPC's linear law and Kalman filter, the plant
//! and the lag) is checked for an eigenvalue on or outside the unit circle: such a loop
//! counts as diverged even when its growth is too slow to show within the check.
//!
//! The same linear loop driven by white measurement noise ([`noise_loop`], [`noise_gain`])
//! gives the stationary RMS of the command and of its tick-to-tick change: how much sensor
//! noise the MPC passes on to the attitude loop; and the standard deviation of the velocity's
//! mean over a span ([`velocity_wander`]): how far the noise moves a flight's steady state.

use crate::config::{finite, non_negative, positive, ConfigError};
use std::ops::{AddAssign, SubAssign};

use nalgebra::DMatrix;

use crate::control::{
    AxisState, ControlError, LinearPlant, Measured, MpcController, MpcSettings, SwingController,
};
use crate::linalg::Stationary;
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
    /// Pure delay of the command before the lag [s], rounded to whole ticks of the plant's
    /// `dt` ([`delay_ticks`]; 0 = none).
    pub input_delay: f64,
}

impl Default for StepCheckSettings {
    fn default() -> Self {
        Self {
            step: 2.0,
            t_step: 2.0,
            duration: 20.0,
            input_lag: 0.0,
            input_delay: 0.0,
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
        non_negative("input_delay", self.input_delay)?;
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

/// Span at the end of a step flight over which final values (velocity, swing) are averaged
/// [s]: the flight metrics' "final" (`ss_error`, the swing's) and the twin's.
pub const FINAL_SPAN: f64 = 2.0;

/// The swing IAE of a step flight and its momentum floor [deg·s] (see [`swing_iae`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SwingIae {
    /// ∫ |swing − final| dt.
    pub iae: f64,
    /// |∫ (along − final) dt|: what the step's change of the payload's momentum needs and no
    /// controller can remove (the cable is all that accelerates the payload horizontally).
    pub floor: f64,
}

impl SwingIae {
    /// The part of the swing IAE a controller decides: the IAE above its floor.
    pub fn excess(&self) -> f64 {
        self.iae - self.floor
    }
}

/// The one definition of the swing IAE after a step, of the flight metrics
/// (`swing_iae_deg_s`, `swing_excess_iae_deg_s`) and the twin's: over the samples `t` [s]
/// from the step on, `swing` [rad] is the swing (its magnitude for two axes) and `along`
/// [rad] the swing along the step; "final" is each one's mean over the last
/// [`FINAL_SPAN`]; integrals are left Riemann sums. NaN for fewer than two samples or
/// lengths that differ.
pub fn swing_iae(t: &[f64], swing: &[f64], along: &[f64]) -> SwingIae {
    let n = t.len();
    if n < 2 || swing.len() != n || along.len() != n {
        return SwingIae {
            iae: f64::NAN,
            floor: f64::NAN,
        };
    }
    let tail = t.partition_point(|&x| x < t[n - 1] - FINAL_SPAN);
    let final_of = |x: &[f64]| x[tail..].iter().sum::<f64>() / (n - tail) as f64;
    let (s_final, a_final) = (final_of(swing), final_of(along));
    let (mut iae, mut signed) = (0.0, 0.0);
    for k in 0..n - 1 {
        let dt = t[k + 1] - t[k];
        iae += (swing[k] - s_final).abs() * dt;
        signed += (along[k] - a_final) * dt;
    }
    SwingIae {
        iae: iae.to_degrees(),
        floor: signed.abs().to_degrees(),
    }
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

/// Longest dead time a check takes, in ticks (3 s at 30 ms): the loop's matrix grows by one
/// state per tick and input, so an absurd delay is refused, not allocated.
pub const MAX_DELAY_TICKS: usize = 100;

/// A pure delay of `delay` seconds as whole ticks of `dt` (nearest; at most
/// [`MAX_DELAY_TICKS`]).
pub fn delay_ticks(delay: f64, dt: f64) -> Result<usize, ConfigError> {
    non_negative("input_delay", delay)?;
    let ticks = (delay / dt).round();
    if !ticks.is_finite() || ticks > MAX_DELAY_TICKS as f64 {
        return Err(ConfigError::new(
            "input_delay",
            format!("{delay} s at dt = {dt} s is too many ticks"),
        ));
    }
    Ok(ticks as usize)
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

/// The uncertainty a model's MPC must be robust to: the plants it may fly and what may stand
/// between its command and them. Every plant is flown behind each lag (no dead time) and
/// behind each dead time (no lag); and, for a limit cycle against the acceleration bound,
/// the unconstrained loop of every plant behind each lag must also be stable at the bound's
/// describing function of each amplitude ([`saturation_gain`]).
#[derive(Clone, Copy, Debug)]
pub struct Uncertainty<'a> {
    /// Linear plants (the white-box of the flight, with and without drag …).
    pub plants: &'a [LinearModel],
    /// Time constants of a first-order lag at the acceleration input [s] (0: none).
    pub input_lags: &'a [f64],
    /// Dead times at the acceleration input [s]: the delay margin.
    pub input_delays: &'a [f64],
    /// Amplitudes of the unconstrained command, as multiples of the acceleration bound
    /// (each > 1), at which no limit cycle may be predicted.
    pub bound_amplitudes: &'a [f64],
}

/// Worst figures of `mpc` (designed on `controller`, not flown; each loop flies a fresh
/// copy) flying a `step` [m/s] over the `set` ([`Uncertainty`]): the one worst-case loop of
/// the offline selection and the adaptive swap. The loops are independent and flown side by
/// side ([`crate::parallel`]). A loop predicted to limit-cycle against the bound
/// has never settled: its final error and overshoot are ∞, as a diverging loop's.
pub fn worst_step_check(
    mpc: &MpcController,
    controller: &LinearModel,
    set: &Uncertainty<'_>,
    step: f64,
) -> Result<StepCheck, ControlError> {
    let actuators: Vec<(f64, f64)> = set
        .input_lags
        .iter()
        .map(|&l| (l, 0.0))
        .chain(set.input_delays.iter().map(|&d| (0.0, d)))
        .collect();
    let mut worst = StepCheck {
        overshoot: f64::NEG_INFINITY,
        final_error: f64::NEG_INFINITY,
        hold_drift: f64::NEG_INFINITY,
    };
    check_bound_amplitudes(set.bound_amplitudes)?;
    let mut cycles = Vec::new();
    for plant in set.plants {
        for &tau in set.input_lags {
            for &amplitude in set.bound_amplitudes {
                cycles.push((plant, tau, amplitude));
            }
        }
    }
    let limit_cycle = crate::parallel::map(cycles, |(plant, tau, amplitude)| {
        let actuator = Actuator {
            lag: lag_factor(tau, plant.dt)?,
            delay: 0,
            gain: saturation_gain(amplitude),
        };
        actuated_stable(mpc, controller, plant, actuator).map(|stable| !stable)
    });
    for cycles in limit_cycle {
        if cycles? {
            worst.overshoot = f64::INFINITY;
            worst.final_error = f64::INFINITY;
            worst.hold_drift = 0.0;
            return Ok(worst);
        }
    }
    let mut loops = Vec::with_capacity(set.plants.len() * actuators.len());
    for plant in set.plants {
        for &actuator in &actuators {
            loops.push((plant, actuator, mpc.fresh_copy()?));
        }
    }
    let checks = crate::parallel::map(loops, |(plant, (input_lag, input_delay), mut mpc)| {
        let check = StepCheckSettings {
            step,
            input_lag,
            input_delay,
            ..StepCheckSettings::default()
        };
        step_check_with(&mut mpc, controller, plant, &check)
    });
    for r in checks {
        let r = r?;
        worst.overshoot = worst.overshoot.max(r.overshoot);
        worst.final_error = worst.final_error.max(r.final_error);
        worst.hold_drift = worst.hold_drift.max(r.hold_drift);
    }
    Ok(worst)
}

/// Check amplitudes of the describing-function test: each a finite multiple of the bound
/// above 1 (within the bound the loop is linear, and checked as such).
pub fn check_bound_amplitudes(amplitudes: &[f64]) -> Result<(), ConfigError> {
    for (i, a) in amplitudes.iter().enumerate() {
        if !(*a > 1.0 && a.is_finite()) {
            return Err(ConfigError::new(
                format!("bound_amplitudes[{i}]"),
                format!("{a} is not a finite multiple of the bound above 1"),
            ));
        }
    }
    Ok(())
}

/// The check's lag factor for an input lag of `tau` [s] ([`crate::linalg::lag_factor`]),
/// a negative one refused.
fn lag_factor(tau: f64, dt: f64) -> Result<f64, ConfigError> {
    non_negative("input_lag", tau)?;
    Ok(crate::linalg::lag_factor(tau, dt))
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
    let lag = lag_factor(check.input_lag, dt)?;
    let delay = delay_ticks(check.input_delay, dt)?;
    let step = check.step.abs();
    // An unconstrained loop with an eigenvalue outside the unit circle grows into a limit
    // cycle against the acceleration bound in flight, however slowly it shows in 20 s.
    let actuator = Actuator {
        lag,
        delay,
        gain: 1.0,
    };
    if !actuated_stable(mpc, controller, plant, actuator)? {
        return Ok(StepCheck {
            overshoot: f64::INFINITY,
            final_error: f64::INFINITY,
            hold_drift: 0.0,
        });
    }
    let mut applied = vec![0.0; m];
    // The commands in flight: the oldest, `delay` ticks back, reaches the lag next.
    let mut in_flight: std::collections::VecDeque<Vec<f64>> =
        std::iter::repeat_n(vec![0.0; m], delay).collect();
    let mut state = vec![AxisState::default(); m];
    let mut vel_ref = vec![0.0; m];
    let mut out = vec![0.0; m];
    mpc.reset(&state, &out);
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
        // The new command joins the queue in the oldest's place and the oldest is applied
        // (with no delay the command itself): no allocation per tick. `out` is written
        // whole by the next step.
        if let Some(mut oldest) = in_flight.pop_front() {
            std::mem::swap(&mut oldest, &mut out);
            in_flight.push_back(oldest);
        }
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

/// Standard deviations of white measurement noise on each measured quantity, per tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasurementNoise {
    /// Velocity noise [m/s].
    pub velocity: f64,
    /// Swing-angle noise [rad].
    pub swing: f64,
    /// Swing-rate noise [rad/s] (only for models with a swing-rate state).
    pub swing_rate: f64,
}

/// The unconstrained MPC (its linear law U* and Kalman filter) in closed loop with a linear
/// plant, driven by white measurement noise e on the controller's newest frame:
/// X⁺ = A X + B e, u = C_u X + D_u e, Δu = u − u_prev = C_du X + D_du e, with
/// X = [plant z; controller's previous delay stack; Kalman prior ξ̂; previous input].
#[derive(Clone, Debug)]
pub struct NoiseLoop {
    /// Closed-loop state matrix.
    pub a: DMatrix<f64>,
    /// Noise input matrix (one column per model state of the newest frame).
    pub b: DMatrix<f64>,
    /// Input map from the state.
    pub c_u: DMatrix<f64>,
    /// Input map from the noise.
    pub d_u: DMatrix<f64>,
    /// Input-increment map from the state.
    pub c_du: DMatrix<f64>,
    /// Input-increment map from the noise.
    pub d_du: DMatrix<f64>,
}

/// What measurement noise does to the commands of an MPC in closed loop ([`noise_gain`]).
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseGain {
    /// Closed-loop eigenvalues (re, im), largest modulus first.
    pub eigenvalues: Vec<(f64, f64)>,
    /// Largest closed-loop eigenvalue modulus (≥ 1: unstable, the RMS figures are ∞).
    pub spectral_radius: f64,
    /// Stationary RMS of the acceleration setpoint over the axes [m/s²] (H2 norm of the
    /// noise → u map with the given noise levels).
    pub rms_u: f64,
    /// Stationary RMS of the tick-to-tick setpoint change over the axes [m/s²].
    pub rms_du: f64,
}

/// Build the [`NoiseLoop`] of `mpc` (designed on `controller`) flying `plant`.
pub fn noise_loop(
    mpc: &MpcController,
    controller: &LinearModel,
    plant: &LinearModel,
) -> Result<NoiseLoop, ControlError> {
    lagged_noise_loop(mpc, controller, plant, 0.0)
}

/// [`noise_loop`] with the step check's first-order lag between controller and plant:
/// a⁺ = λ a + (1 − λ) u, the plant driven by a⁺ (λ = exp(−dt/τ), 0 = no lag); the lag
/// states are appended to the plant's z in X.
pub fn lagged_noise_loop(
    mpc: &MpcController,
    controller: &LinearModel,
    plant: &LinearModel,
    lag: f64,
) -> Result<NoiseLoop, ControlError> {
    actuated_noise_loop(mpc, controller, plant, Actuator::lagged(lag))
}

/// What stands between the MPC's law and the plant in a linear check loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Actuator {
    /// First-order lag factor λ = exp(−dt/τ) of the attitude loop (0: none).
    pub lag: f64,
    /// Whole ticks the command waits before the lag (0: none).
    pub delay: usize,
    /// Share of the law's command that is applied, and that the controller remembers as
    /// applied: the acceleration bound's describing function ([`saturation_gain`]; 1:
    /// within the bound).
    pub gain: f64,
}

impl Actuator {
    /// A first-order lag of factor `lag` alone.
    pub fn lagged(lag: f64) -> Self {
        Self {
            lag,
            delay: 0,
            gain: 1.0,
        }
    }
}

/// Describing function of a saturation for a sinusoid of `amplitude` times its bound: the
/// gain of the first harmonic that passes, (2/π)(asin r + r √(1 − r²)) with r = 1/amplitude
/// (1 within the bound, → 4/(π·amplitude) far beyond it). A loop that is stable at gain 1 but
/// unstable at one of these is predicted to limit-cycle against the bound at that amplitude.
pub fn saturation_gain(amplitude: f64) -> f64 {
    if amplitude.is_nan() || amplitude <= 1.0 {
        return 1.0;
    }
    let r = 1.0 / amplitude;
    std::f64::consts::FRAC_2_PI * (r.asin() + r * (1.0 - r * r).sqrt())
}

/// [`lagged_noise_loop`] behind an [`Actuator`]: the command also delayed by
/// `actuator.delay` whole ticks before the lag (the commands in flight w₁ … w_d, w₁⁺ = u,
/// wᵢ⁺ = wᵢ₋₁, follow the lag's state in X, and w_d drives the lag; u itself with no delay),
/// and scaled by `actuator.gain` as it leaves the law (u = gain · law, remembered so).
pub fn actuated_noise_loop(
    mpc: &MpcController,
    controller: &LinearModel,
    plant: &LinearModel,
    actuator: Actuator,
) -> Result<NoiseLoop, ControlError> {
    let Actuator { lag, delay, gain } = actuator;
    if !(gain > 0.0 && gain <= 1.0) {
        return Err(ConfigError::new("gain", format!("{gain} not in (0, 1]")).into());
    }
    check_plant(controller, plant)?;
    if !(0.0..1.0).contains(&lag) {
        return Err(
            ConfigError::new("input_lag", format!("lag factor {lag} not in [0, 1)")).into(),
        );
    }
    let layout = crate::control::AxisLayout::from_model(plant)?;
    let (sources, _, n) = mpc.frame_layout();
    let aug = mpc.augmented();
    let cond = mpc.condensed();
    let kf = mpc.estimator();
    let m = aug.m;
    let nm = aug.nm;
    let nx = aug.nx();
    let nz = controller.states.len() * controller.delays;
    let nzp = plant.a.nrows();
    let pn = plant.states.len();
    let mp = plant.b.ncols();
    if delay > MAX_DELAY_TICKS {
        return Err(ConfigError::new("input_delay", format!("{delay} ticks is too many")).into());
    }
    // Actuator states after z: the lag's a (with a lag), then the commands in flight w.
    // With o = S s + D u the command leaving the delay (w_d, or u with no delay), the lag
    // is a⁺ = λ a + (1 − λ) o and the plant is driven by a⁺ (by o with no lag).
    let na = if lag > 0.0 { mp } else { 0 };
    let (ia, iw) = (nzp, nzp + na);
    let np = nzp + na + delay * mp;
    let mut out_s = DMatrix::<f64>::zeros(mp, np);
    let mut out_u = DMatrix::<f64>::zeros(mp, mp);
    if delay > 0 {
        for i in 0..mp {
            out_s[(i, iw + (delay - 1) * mp + i)] = 1.0;
        }
    } else {
        out_u.fill_with_identity();
    }
    // The plant's drive: λ a + (1 − λ) o (o itself with no lag, λ = 0).
    let (mut drive_s, drive_u) = (out_s * (1.0 - lag), out_u * (1.0 - lag));
    if lag > 0.0 {
        for i in 0..mp {
            drive_s[(i, ia + i)] += lag;
        }
    }
    let mut plant_a = DMatrix::<f64>::zeros(np, np);
    let mut plant_b = DMatrix::<f64>::zeros(np, mp);
    plant_a.view_mut((0, 0), (nzp, nzp)).copy_from(&plant.a);
    plant_a.rows_mut(0, nzp).add_assign(&(&plant.b * &drive_s));
    plant_b.rows_mut(0, nzp).copy_from(&(&plant.b * &drive_u));
    if lag > 0.0 {
        plant_a.rows_mut(ia, mp).copy_from(&drive_s);
        plant_b.rows_mut(ia, mp).copy_from(&drive_u);
    }
    for i in 0..delay * mp {
        if i < mp {
            plant_b[(iw + i, i)] = 1.0;
        } else {
            plant_a[(iw + i, iw + i - mp)] = 1.0;
        }
    }
    if layout.len() != m {
        return Err(ControlError::Model(format!(
            "plant has {} axes, the controller {m}",
            layout.len()
        )));
    }
    // Frame = M_z z + e.
    let mut mz = DMatrix::<f64>::zeros(n, np);
    for (k, src) in sources.iter().enumerate() {
        match *src {
            Measured::V(a) => mz[(k, layout.axes()[a].v)] = 1.0,
            Measured::Swing(a) => mz[(k, layout.axes()[a].swing)] = 1.0,
            Measured::SwingRate(a) => {
                let ax = &layout.axes()[a];
                if let Some(i) = ax.swing_rate {
                    mz[(k, i)] = 1.0;
                } else if plant.delays >= 2 {
                    mz[(k, ax.swing)] = 1.0 / plant.dt;
                    mz[(k, ax.swing + pn)] = -1.0 / plant.dt;
                } else {
                    return Err(ControlError::Model(
                        "the plant has neither a swing rate nor a previous frame".into(),
                    ));
                }
            }
        }
    }
    // y = S_h y_prev + E frame (the controller's `push_frame`).
    let mut sh = DMatrix::<f64>::zeros(nm, nm);
    for i in n..nz {
        sh[(i, i - n)] = 1.0;
    }
    for &(dst, src) in &aug.lag_copies {
        sh[(dst, src)] = 1.0;
    }
    let mut e = DMatrix::<f64>::zeros(nm, n);
    for k in 0..n {
        e[(k, k)] = 1.0;
    }
    // post = P_y y + P_p prior.
    // The filter measures the first ny entries of the stack (innovation y[..ny] − ξ̂[..ny]).
    let l = kf.gain();
    let ny = l.ncols();
    let mut py = DMatrix::<f64>::zeros(nx, nm);
    py.columns_mut(0, ny).copy_from(l);
    let mut pp = DMatrix::<f64>::identity(nx, nx);
    pp.columns_mut(0, ny).sub_assign(l);
    if mpc.settings().measured_state {
        py.rows_mut(0, nm).fill_with_identity();
        pp.rows_mut(0, nm).fill(0.0);
    }
    let (iz, iy, ip, iu) = (0, np, np + nm, np + nm + nx);
    let dim = iu + m;
    let emz = &e * &mz;
    // post = G X + G_e e.
    let mut g = DMatrix::<f64>::zeros(nx, dim);
    g.columns_mut(iz, np).copy_from(&(&py * &emz));
    g.columns_mut(iy, nm).copy_from(&(&py * &sh));
    g.columns_mut(ip, nx).copy_from(&pp);
    let ge = &py * &e;
    let k1 = cond.k_xi.rows(0, m).into_owned() * gain;
    let ku1 = cond.k_u.rows(0, m).into_owned() * gain;
    let mut c_u = &k1 * &g;
    c_u.columns_mut(iu, m).add_assign(&ku1);
    let d_u = &k1 * &ge;
    let mut c_du = c_u.clone();
    for a in 0..m {
        c_du[(a, iu + a)] -= 1.0;
    }
    let d_du = d_u.clone();
    let mut acl = DMatrix::<f64>::zeros(dim, dim);
    let mut bcl = DMatrix::<f64>::zeros(dim, n);
    acl.view_mut((iz, iz), (np, np)).copy_from(&plant_a);
    acl.rows_mut(iz, np).add_assign(&(&plant_b * &c_u));
    bcl.rows_mut(iz, np).copy_from(&(&plant_b * &d_u));
    acl.view_mut((iy, iz), (nm, np)).copy_from(&emz);
    acl.view_mut((iy, iy), (nm, nm)).copy_from(&sh);
    bcl.rows_mut(iy, nm).copy_from(&e);
    acl.rows_mut(ip, nx)
        .copy_from(&(&aug.a * &g + &aug.b * &c_u));
    bcl.rows_mut(ip, nx)
        .copy_from(&(&aug.a * &ge + &aug.b * &d_u));
    acl.rows_mut(iu, m).copy_from(&c_u);
    bcl.rows_mut(iu, m).copy_from(&d_u);
    Ok(NoiseLoop {
        a: acl,
        b: bcl,
        c_u,
        d_u,
        c_du,
        d_du,
    })
}

/// Largest eigenvalue modulus of the unconstrained closed loop of `mpc` (designed on
/// `controller`) and `plant` behind a first-order lag of factor `lag` ([`lagged_noise_loop`]).
pub fn closed_loop_radius(
    mpc: &MpcController,
    controller: &LinearModel,
    plant: &LinearModel,
    lag: f64,
) -> Result<f64, ControlError> {
    let nl = lagged_noise_loop(mpc, controller, plant, lag)?;
    let ev = crate::linalg::eigenvalues(&nl.a).ok_or_else(unconverged)?;
    Ok(ev.iter().map(|c| c.norm()).fold(0.0, f64::max))
}

/// Whether the unconstrained closed loop of [`closed_loop_radius`] is stable (ρ < 1),
/// decided by [`crate::linalg::schur_stable`]: the check's question, mostly without the
/// eigenvalues of a loop of several hundred states.
pub fn closed_loop_stable(
    mpc: &MpcController,
    controller: &LinearModel,
    plant: &LinearModel,
    lag: f64,
) -> Result<bool, ControlError> {
    actuated_stable(mpc, controller, plant, Actuator::lagged(lag))
}

/// [`closed_loop_stable`] behind an [`Actuator`] ([`actuated_noise_loop`]).
pub fn actuated_stable(
    mpc: &MpcController,
    controller: &LinearModel,
    plant: &LinearModel,
    actuator: Actuator,
) -> Result<bool, ControlError> {
    let nl = actuated_noise_loop(mpc, controller, plant, actuator)?;
    // The plant's states come first in the loop's state; the frames the filter never reads
    // fall in the other block.
    let plant_states: Vec<usize> = (0..plant.a.nrows()).collect();
    crate::linalg::schur_stable_split(&nl.a, &plant_states).ok_or_else(unconverged)
}

/// Closed-loop eigenvalues and the stationary RMS of u and Δu of `mpc` (designed on
/// `controller`, unconstrained) flying `plant` with white measurement noise of `noise`.
pub fn noise_gain(
    mpc: &MpcController,
    controller: &LinearModel,
    plant: &LinearModel,
    noise: MeasurementNoise,
) -> Result<NoiseGain, ControlError> {
    let nl = noise_loop(mpc, controller, plant)?;
    let w = noise_levels(mpc, noise)?;
    let ev = crate::linalg::eigenvalues(&nl.a).ok_or_else(unconverged)?;
    let mut eigenvalues: Vec<(f64, f64)> = ev.iter().map(|c| (c.re, c.im)).collect();
    eigenvalues.sort_by(|x, y| x.0.hypot(x.1).total_cmp(&y.0.hypot(y.1)).reverse());
    let spectral_radius = eigenvalues.first().map_or(0.0, |x| x.0.hypot(x.1));
    if spectral_radius >= 1.0 {
        return Ok(NoiseGain {
            eigenvalues,
            spectral_radius,
            rms_u: f64::INFINITY,
            rms_du: f64::INFINITY,
        });
    }
    let mut bw = nl.b.clone();
    for (j, s) in w.iter().enumerate() {
        bw.column_mut(j).scale_mut(*s);
    }
    let p = match crate::linalg::stationary_covariance(&nl.a, &bw) {
        Some(Stationary::Stable(p)) => p,
        // Within rounding of the unit circle the doubling's certificate can disagree.
        Some(Stationary::Unstable) => {
            return Ok(NoiseGain {
                eigenvalues,
                spectral_radius,
                rms_u: f64::INFINITY,
                rms_du: f64::INFINITY,
            })
        }
        None => return Err(unconverged()),
    };
    let rms = |c: &DMatrix<f64>, d: &DMatrix<f64>| {
        let mut dw = d.clone();
        for (j, s) in w.iter().enumerate() {
            dw.column_mut(j).scale_mut(*s);
        }
        ((c * &p * c.transpose()).trace() + (&dw * dw.transpose()).trace()).sqrt()
    };
    Ok(NoiseGain {
        eigenvalues,
        spectral_radius,
        rms_u: rms(&nl.c_u, &nl.d_u),
        rms_du: rms(&nl.c_du, &nl.d_du),
    })
}

/// The error of a closed loop whose eigenvalues (or covariance) did not converge.
fn unconverged() -> ControlError {
    ControlError::Synthesis("closed-loop eigenvalues did not converge".into())
}

/// The noise level of each model state of `mpc`'s newest frame, checked non-negative.
fn noise_levels(mpc: &MpcController, noise: MeasurementNoise) -> Result<Vec<f64>, ControlError> {
    for (name, v) in [
        ("velocity", noise.velocity),
        ("swing", noise.swing),
        ("swing_rate", noise.swing_rate),
    ] {
        non_negative(name, v)?;
    }
    let (sources, _, _) = mpc.frame_layout();
    Ok(sources
        .iter()
        .map(|s| match s {
            Measured::V(_) => noise.velocity,
            Measured::Swing(_) => noise.swing,
            Measured::SwingRate(_) => noise.swing_rate,
        })
        .collect())
}

/// How far white measurement noise moves the mean velocity over `span` seconds (the figure a
/// flight's steady-state error is read from) when `mpc` (designed on `controller`,
/// unconstrained) flies `plant` behind a first-order lag of time constant `input_lag` [s]:
/// the stationary standard deviation of that mean [m/s], the largest over the axes; ∞ when
/// the loop is unstable. The linear, analytic counterpart of the twin's hold wander.
pub fn velocity_wander(
    mpc: &MpcController,
    controller: &LinearModel,
    plant: &LinearModel,
    input_lag: f64,
    noise: MeasurementNoise,
    span: f64,
) -> Result<f64, ControlError> {
    non_negative("input_lag", input_lag)?;
    positive("span", span)?;
    let w = noise_levels(mpc, noise)?;
    let dt = plant.dt;
    let window = (span / dt).round();
    if window > MAX_CHECK_TICKS as f64 {
        return Err(
            ConfigError::new("span", format!("{span} s at dt = {dt} s is too long")).into(),
        );
    }
    let nl = lagged_noise_loop(mpc, controller, plant, lag_factor(input_lag, dt)?)?;
    // A non-finite entry between the blocks below would escape both: refused as before.
    if !nl.a.iter().chain(nl.b.iter()).all(|v| v.is_finite()) {
        return Err(unconverged());
    }
    // The plant's states come first in the loop's state.
    let layout = crate::control::AxisLayout::from_model(plant)?;
    let velocities: Vec<usize> = layout.axes().iter().map(|ax| ax.v).collect();
    // Most of the controller's frame stack never reaches the velocity (the filter reads the
    // newest frame): the velocity's statistics are those of the block that does, a loop of
    // about half the states. The other block must still be stable, as the whole loop must.
    let (kept, rest) = crate::linalg::split_reaching(&nl.a, &velocities);
    let stable_rest = crate::linalg::schur_stable(&crate::linalg::principal_block(&nl.a, &rest));
    if !stable_rest.ok_or_else(unconverged)? {
        return Ok(f64::INFINITY);
    }
    let a = crate::linalg::principal_block(&nl.a, &kept);
    let mut bw = nl.b.select_rows(&kept);
    for (j, s) in w.iter().enumerate() {
        bw.column_mut(j).scale_mut(*s);
    }
    let p = match crate::linalg::stationary_covariance(&a, &bw) {
        Some(Stationary::Stable(p)) => p,
        Some(Stationary::Unstable) => return Ok(f64::INFINITY),
        None => return Err(unconverged()),
    };
    let mut worst = 0.0_f64;
    for v in velocities {
        let mut c = DMatrix::<f64>::zeros(1, a.ncols());
        c[(0, kept.partition_point(|&i| i < v))] = 1.0;
        worst = worst.max(crate::linalg::window_mean_std(&a, &p, &c, window as usize));
    }
    Ok(worst)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, dt: f64) -> Vec<f64> {
        (0..n).map(|k| k as f64 * dt).collect()
    }

    #[test]
    fn a_one_sided_lean_is_all_floor_and_an_oscillation_all_excess() {
        // Lean θ₀ for 3 s, then hang still for 3 s: ∫|θ| = |∫θ| = 3θ₀, nothing in excess.
        let dt = 0.001;
        let t = grid(6000, dt);
        let lean: Vec<f64> = t.iter().map(|&x| if x < 3.0 { 0.1 } else { 0.0 }).collect();
        let r = swing_iae(&t, &lean, &lean);
        assert!((r.iae - 0.3_f64.to_degrees()).abs() < 1e-2, "{r:?}");
        assert!(
            (r.floor - r.iae).abs() < 1e-9 && r.excess().abs() < 1e-9,
            "{r:?}"
        );
        // Three whole periods of A sin(2πt), then still: ∫|θ| = 3 · 2A/π, ∫θ = 0.
        let a = 0.05;
        let osc: Vec<f64> = t
            .iter()
            .map(|&x| {
                if x < 3.0 {
                    a * (std::f64::consts::TAU * x).sin()
                } else {
                    0.0
                }
            })
            .collect();
        let r = swing_iae(&t, &osc, &osc);
        let expected = (3.0 * 2.0 * a / std::f64::consts::PI).to_degrees();
        assert!(
            (r.iae - expected).abs() < 1e-3 * expected,
            "{r:?} vs {expected}"
        );
        assert!(r.floor < 1e-6 && (r.excess() - expected).abs() < 1e-3 * expected);
        // The final value is the mean of the last FINAL_SPAN: a steady lean there is not swing.
        let offset: Vec<f64> = osc.iter().map(|x| x + 0.02).collect();
        let shifted = swing_iae(&t, &offset, &offset);
        assert!((shifted.iae - r.iae).abs() < 1e-9 && shifted.floor < 1e-6);
        assert!(swing_iae(&t[..1], &osc[..1], &osc[..1]).iae.is_nan());
        assert!(swing_iae(&t, &osc[..10], &osc).iae.is_nan());
    }
}
