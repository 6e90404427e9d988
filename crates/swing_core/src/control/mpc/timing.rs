//! Tick timing of the MPC in closed loop with its own model as the plant (for
//! `swingrt bench` and the criterion bench): per-tick wall time of
//! [`SwingController::step`] (Kalman update included), median and 99th percentile.
//!
//! The plant is the identified model itself ([`LinearPlant`]), driven by a square
//! wave of velocity references (±`amplitude` every `period_s`). Unconstrained runs remove
//! every bound and time all ticks; constrained runs keep (or, if the settings have none,
//! add) a bound of 1 m/s² on the acceleration setpoint and time only the ticks on which
//! the QP was solved.

use std::time::Instant;

use super::{MpcController, MpcSettings};
use crate::control::{AxisState, ControlError, LinearPlant, SwingController, TickKind};
use crate::sysid::LinearModel;

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

/// Run `n_ticks` timed ticks (see module docs) and summarise them.
pub fn tick_timing(
    model: &LinearModel,
    settings: &MpcSettings,
    n_ticks: usize,
    constrained: bool,
) -> Result<TickTiming, ControlError> {
    if n_ticks == 0 {
        return Err(ControlError::Input("n_ticks must be ≥ 1".into()));
    }
    let mut s = settings.clone();
    if constrained {
        if s.acc_max.is_none() && s.jerk_max.is_none() {
            s.acc_max = Some(1.0);
        }
    } else {
        s.acc_max = None;
        s.jerk_max = None;
    }
    let mut ctrl = MpcController::new(model, s)?;
    let mut times = Vec::with_capacity(n_ticks);
    let mut plant = LinearPlant::new(model)?;
    let m = ctrl.axes();
    let mut state = vec![AxisState::default(); m];
    let mut refs = vec![0.0; m];
    let mut u = vec![0.0; m];
    plant.measure(&mut state);
    ctrl.reset(&state, &u);
    let amplitude = if constrained { 4.0 } else { 2.0 };
    let half_period = (4.0 / model.dt).round().max(1.0) as usize;
    let mut k = 0usize;
    // Give up if bounds are never active (e.g. a huge acc_max).
    let max_total = 50 * n_ticks + 10_000;
    while times.len() < n_ticks {
        if k > max_total {
            return Err(ControlError::Input(
                "constrained timing: the bounds were (almost) never active".into(),
            ));
        }
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
        let dt = t0.elapsed().as_secs_f64() * 1e6;
        if !constrained || info.kind == TickKind::Constrained {
            times.push(dt);
        }
        plant.step(&u);
        k += 1;
    }
    times.sort_by(|a, b| a.total_cmp(b));
    let pick = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
    Ok(TickTiming {
        median_us: pick(0.5),
        p99_us: pick(0.99),
        max_us: *times.last().unwrap_or(&0.0),
        mean_us: times.iter().sum::<f64>() / times.len() as f64,
        ticks: times.len(),
    })
}
