//! Timing harnesses of swingrt's real-time paths, for `swingrt bench` (through the binding)
//! and the criterion benches of this crate; kept out of the library, which never times
//! itself.
//!
//! [`tick_timing`]: tick timing of the MPC in closed loop with its own model as the plant:
//! per-tick wall time of [`SwingController::step`] (Kalman update included), median and
//! 99th percentile.
//!
//! The plant is the identified model itself ([`LinearPlant`]), driven by a square wave of
//! velocity references. Unconstrained runs remove every bound and time all ticks;
//! constrained runs bound the acceleration setpoint at half the largest command of the
//! unconstrained run and time only the ticks on which the QP was solved.
//!
//! [`adaptive_timing`]: the adaptive MPC's tick with its online update, and its
//! re-synthesis.

use std::time::Instant;

use swing_core::control::{
    AxisState, ControlError, LinearPlant, MpcController, MpcSettings, SwingController, TickKind,
};
use swing_core::design::adaptive::{AdaptiveMpc, AdaptiveSettings, SynthesisMode};
use swing_core::sysid::LinearModel;

/// Timing summary of MPC ticks [µs].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TickTiming {
    /// Median tick time [µs].
    pub median_us: f64,
    /// 99th percentile tick time [µs].
    pub p99_us: f64,
    /// Longest tick [µs].
    pub max_us: f64,
    /// Mean tick time [µs].
    pub mean_us: f64,
    /// Number of ticks timed.
    pub ticks: usize,
}

/// Amplitude of the velocity-reference square wave of an unconstrained run [m/s].
const AMPLITUDE: f64 = 2.0;
/// Amplitude of the square wave of a constrained run [m/s]: larger steps, larger commands.
const AMPLITUDE_CONSTRAINED: f64 = 4.0;
/// Half period of the square wave [s].
const HALF_PERIOD: f64 = 4.0;
/// Fraction of the unconstrained run's largest command that bounds a constrained run: every
/// transient of the square wave then needs the QP, however smooth the MPC's settings are.
const BOUND_FRACTION: f64 = 0.5;

/// Fly `ctrl` in closed loop with `model` as the plant under the square wave of `amplitude`
/// (axis 0 at +amplitude, axis 1 at −0.7 × it, sign flipped every [`HALF_PERIOD`]), calling
/// `tick` with each tick's wall time [µs] and kind until it returns false or `max_ticks`.
fn fly(
    ctrl: &mut MpcController,
    model: &LinearModel,
    amplitude: f64,
    max_ticks: usize,
    mut tick: impl FnMut(f64, TickKind, &[f64]) -> bool,
) -> Result<(), ControlError> {
    let mut plant = LinearPlant::new(model)?;
    let m = ctrl.axes();
    let mut state = vec![AxisState::default(); m];
    let mut refs = vec![0.0; m];
    let mut u = vec![0.0; m];
    plant.measure(&mut state);
    ctrl.reset(&state, &u);
    let half_period = (HALF_PERIOD / model.dt).round().max(1.0) as usize;
    for k in 0..max_ticks {
        let sign = if (k / half_period) % 2 == 0 {
            1.0
        } else {
            -1.0
        };
        for (a, r) in refs.iter_mut().enumerate() {
            *r = sign * amplitude * if a == 0 { 1.0 } else { -0.7 };
        }
        plant.measure(&mut state);
        let t0 = Instant::now();
        let info = ctrl.step(&state, &refs, &mut u)?;
        let us = t0.elapsed().as_secs_f64() * 1e6;
        if !tick(us, info.kind, &u) {
            return Ok(());
        }
        plant.step(&u);
    }
    Ok(())
}

/// Run `n_ticks` timed ticks (see module docs) and summarise them.
///
/// Unconstrained: every bound removed, every tick timed. Constrained: the acceleration bound
/// is [`BOUND_FRACTION`] of the largest command the unconstrained MPC gives on the same
/// square wave (or the settings' bound when it is tighter), the jerk bound is the settings',
/// and only the ticks that solved the QP are timed.
pub fn tick_timing(
    model: &LinearModel,
    settings: &MpcSettings,
    n_ticks: usize,
    constrained: bool,
) -> Result<TickTiming, ControlError> {
    if n_ticks == 0 {
        return Err(ControlError::Input("n_ticks must be ≥ 1".into()));
    }
    let mut free = settings.clone();
    free.acc_max = None;
    free.jerk_max = None;
    let mut times = Vec::with_capacity(n_ticks);
    if !constrained {
        let mut ctrl = MpcController::new(model, free)?;
        fly(&mut ctrl, model, AMPLITUDE, n_ticks, |us, _, _| {
            times.push(us);
            true
        })?;
        return Ok(summarise(times));
    }
    let half_period = (HALF_PERIOD / model.dt).round().max(1.0) as usize;
    let mut peak = 0.0_f64;
    let mut ctrl = MpcController::new(model, free)?;
    fly(
        &mut ctrl,
        model,
        AMPLITUDE_CONSTRAINED,
        4 * half_period,
        |_, _, u| {
            peak = u.iter().fold(peak, |p, x| p.max(x.abs()));
            true
        },
    )?;
    if !(peak.is_finite() && peak > 0.0) {
        return Err(ControlError::Input(format!(
            "constrained timing: the unconstrained MPC commands nothing to bound (peak {peak})"
        )));
    }
    let mut s = settings.clone();
    let bound = BOUND_FRACTION * peak;
    s.acc_max = Some(s.acc_max.map_or(bound, |a| a.min(bound)));
    let mut ctrl = MpcController::new(model, s)?;
    // Every half period has a transient against the bound; a few hundred ticks per timed
    // one is far more than any run needs.
    let max_ticks = 500 * n_ticks + 10_000;
    fly(
        &mut ctrl,
        model,
        AMPLITUDE_CONSTRAINED,
        max_ticks,
        |us, kind, _| {
            if kind == TickKind::Constrained {
                times.push(us);
            }
            times.len() < n_ticks
        },
    )?;
    if times.len() < n_ticks {
        return Err(ControlError::Input(format!(
            "constrained timing: the bound was active on {} of {max_ticks} ticks",
            times.len()
        )));
    }
    Ok(summarise(times))
}

/// Timing of the adaptive MPC for `swingrt bench` and the criterion bench: the tick with
/// the online update ([`TickTiming`] in µs) over `n_ticks` ticks in closed loop with
/// `model` itself as the plant under a ±2 m/s square wave of references (every sample
/// excited and accepted), then the re-synthesis on the collected factor, `repeats` times
/// ([`TickTiming`] in ms).
pub fn adaptive_timing(
    model: &LinearModel,
    mpc: &MpcSettings,
    settings: &AdaptiveSettings,
    n_ticks: usize,
    repeats: usize,
) -> Result<(TickTiming, TickTiming), ControlError> {
    if n_ticks == 0 || repeats == 0 {
        return Err(ControlError::Input(
            "n_ticks and repeats must be ≥ 1".into(),
        ));
    }
    let s = AdaptiveSettings {
        synthesis: SynthesisMode::Deferred,
        ..settings.clone()
    };
    let mut ctrl = AdaptiveMpc::new(model, mpc.clone(), s)?;
    let mut plant = LinearPlant::new(model)?;
    let m = ctrl.axes();
    let mut state = vec![AxisState::default(); m];
    let mut refs = vec![0.0; m];
    let mut u = vec![0.0; m];
    plant.measure(&mut state);
    ctrl.reset(&state, &u);
    let half_period = (4.0 / model.dt).round().max(1.0) as usize;
    let mut ticks = Vec::with_capacity(n_ticks);
    for k in 0..n_ticks {
        let sign = if (k / half_period) % 2 == 0 {
            1.0
        } else {
            -1.0
        };
        refs.iter_mut().for_each(|r| *r = 2.0 * sign);
        plant.measure(&mut state);
        let t0 = Instant::now();
        ctrl.step(&state, &refs, &mut u)?;
        ticks.push(t0.elapsed().as_secs_f64() * 1e6);
        plant.step(&u);
    }
    let mut builds = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t0 = Instant::now();
        let out = ctrl.synthesize_now();
        builds.push(t0.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(&out);
    }
    Ok((summarise(ticks), summarise(builds)))
}

/// Median, 99th percentile, largest and mean of `times`.
fn summarise(mut times: Vec<f64>) -> TickTiming {
    times.sort_by(|a, b| a.total_cmp(b));
    let pick = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
    TickTiming {
        median_us: pick(0.5),
        p99_us: pick(0.99),
        max_us: *times.last().unwrap_or(&0.0),
        mean_us: times.iter().sum::<f64>() / times.len() as f64,
        ticks: times.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use swing_core::plant::PendulumModel;
    use swing_core::testing::pendulum_delay_model;

    /// The constrained timing of `swingrt bench` times QP ticks with the MPC's default
    /// settings, whose input-increment weight keeps the commands well inside the default
    /// acceleration bound: the bound it times against is the run's own.
    #[test]
    fn constrained_timing_finds_active_bounds_with_default_settings() {
        let model = pendulum_delay_model(&PendulumModel::default(), 0.03, 20, 1, 3).unwrap();
        for constrained in [false, true] {
            let t = tick_timing(&model, &MpcSettings::default(), 40, constrained).unwrap();
            assert_eq!(t.ticks, 40);
            assert!(t.median_us > 0.0 && t.median_us <= t.p99_us && t.p99_us <= t.max_us);
        }
    }
}
