//! Timing harnesses of swingrt's real-time paths, for `swingrt bench` (through the binding)
//! and the criterion benches of this crate; kept out of the library, which never times
//! itself.
//!
//! [`tick_timing`]: tick timing of the MPC in closed loop with its own model as the plant:
//! per-tick wall time of [`SwingController::step`] (Kalman update included), median and
//! 99th percentile.
//!
//! The plant is the identified model itself ([`LinearPlant`]), driven by a square wave of
//! velocity references (±amplitude, switching every 4 s). Unconstrained runs remove every
//! bound and time all ticks at an amplitude of 2 m/s. Constrained runs keep the settings'
//! own bounds (or, if they have none, add a bound of 1 m/s² on the acceleration setpoint)
//! and time only the ticks on which the QP was solved. Without bounds, controller and plant
//! are linear and start at rest, so the largest setpoint (and setpoint step) they command
//! scales with the amplitude: a pilot run at unit amplitude gives the amplitude at which the
//! bounds are certainly active (twice the one that just reaches them; at least 4 m/s).
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
/// Smallest amplitude of the square wave of a constrained run [m/s].
const AMPLITUDE_CONSTRAINED_MIN: f64 = 4.0;
/// Half period of the square wave [s].
const HALF_PERIOD: f64 = 4.0;
/// Acceleration bound a constrained run adds when the settings have none [m/s²].
const DEFAULT_ACC_BOUND: f64 = 1.0;

/// Fly `ctrl` in closed loop with `model` as the plant under the square wave of `amplitude`
/// (axis 0 at +amplitude, axis 1 at −0.7 × it, sign flipped every [`HALF_PERIOD`]), calling
/// `tick` with each tick's wall time [µs] and kind until it returns false or `max_ticks`.
fn fly(
    ctrl: &mut impl SwingController,
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
/// Unconstrained: every bound removed, every tick timed. Constrained: the settings' own
/// bounds (an acceleration bound of [`DEFAULT_ACC_BOUND`] when they have none), on a square
/// wave sized from an unconstrained pilot run so that they are active after every switch;
/// only the ticks that solved the QP are timed.
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
    let mut s = settings.clone();
    if s.acc_max.is_none() && s.jerk_max.is_none() {
        s.acc_max = Some(DEFAULT_ACC_BOUND);
    }
    // Pilot: the unconstrained loop at unit amplitude over two switches; its largest
    // setpoint and setpoint step scale with the amplitude.
    let half_period = (HALF_PERIOD / model.dt).round().max(1.0) as usize;
    let (mut peak_u, mut peak_du) = (0.0_f64, 0.0_f64);
    let mut ctrl = MpcController::new(model, free)?;
    let mut before = vec![0.0; ctrl.axes()];
    fly(&mut ctrl, model, 1.0, 4 * half_period, |_, _, u| {
        for (v, w) in u.iter().zip(before.iter_mut()) {
            peak_u = peak_u.max(v.abs());
            peak_du = peak_du.max((v - *w).abs());
            *w = *v;
        }
        true
    })?;
    let mut reach = f64::INFINITY;
    if let Some(a) = s.acc_max.filter(|_| peak_u > 0.0) {
        reach = reach.min(a / peak_u);
    }
    if let Some(j) = s.jerk_max.filter(|_| peak_du > 0.0) {
        reach = reach.min(j * model.dt / peak_du);
    }
    if !reach.is_finite() {
        return Err(ControlError::Input(
            "constrained timing: the model's loop commands no acceleration".into(),
        ));
    }
    let amplitude = (2.0 * reach).max(AMPLITUDE_CONSTRAINED_MIN);
    let mut ctrl = MpcController::new(model, s)?;
    // The bounds are active after every switch, so this many ticks always suffice.
    let max_ticks = 50 * n_ticks + 10_000;
    fly(&mut ctrl, model, amplitude, max_ticks, |us, kind, _| {
        if kind == TickKind::Constrained {
            times.push(us);
        }
        times.len() < n_ticks
    })?;
    if times.len() < n_ticks {
        return Err(ControlError::Input(format!(
            "constrained timing: the bounds were active on {} of {max_ticks} ticks",
            times.len()
        )));
    }
    Ok(summarise(times))
}

/// Timing of the adaptive MPC for `swingrt bench` and the criterion bench: the tick with
/// the online update ([`TickTiming`] in µs) over `n_ticks` ticks in closed loop with
/// `model` itself as the plant under the square wave of the unconstrained [`tick_timing`]
/// (every sample excited and accepted), then the re-synthesis on the collected factor, `repeats` times
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
    let mut ticks = Vec::with_capacity(n_ticks);
    fly(&mut ctrl, model, AMPLITUDE, n_ticks, |us, _, _| {
        ticks.push(us);
        true
    })?;
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

    /// The constrained timing of `swingrt bench` times QP ticks against the settings' own
    /// bound. The default bound (4 m/s²) is far above what a ±4 m/s square wave asks of the
    /// default MPC, and a bound of 100 m/s² further still; the timing must still find QP
    /// ticks (it sizes the square wave to the bound), for one axis and two, and for a jerk
    /// bound alone.
    #[test]
    fn constrained_tick_timing_reaches_the_settings_own_bound() {
        let p = PendulumModel::default();
        let one = pendulum_delay_model(&p, 0.03, 8, 1, 7).unwrap();
        let two = pendulum_delay_model(&p, 0.03, 8, 2, 7).unwrap();
        let far = MpcSettings {
            acc_max: Some(100.0),
            ..MpcSettings::default()
        };
        for m in [&one, &two] {
            for s in [&MpcSettings::default(), &far] {
                let t = tick_timing(m, s, 50, true).unwrap();
                assert_eq!(t.ticks, 50);
                assert!(t.median_us > 0.0 && t.median_us <= t.p99_us && t.p99_us <= t.max_us);
            }
        }
        let jerk = MpcSettings {
            acc_max: None,
            jerk_max: Some(20.0),
            ..MpcSettings::default()
        };
        assert_eq!(tick_timing(&one, &jerk, 50, true).unwrap().ticks, 50);
        assert_eq!(
            tick_timing(&one, &MpcSettings::default(), 50, false)
                .unwrap()
                .ticks,
            50
        );
        assert!(tick_timing(&one, &MpcSettings::default(), 0, true).is_err());
    }
}
