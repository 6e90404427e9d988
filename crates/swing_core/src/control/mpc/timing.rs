//! Tick timing of the MPC in closed loop with its own model as the plant (for
//! `swingrt bench` and the criterion bench): per-tick wall time of
//! [`SwingController::step`] (Kalman update included), median and 99th percentile.
//!
//! The plant is the identified model itself, z⁺ = A z + B (u − ū) + c, driven by a square
//! wave of velocity references (±`amplitude` every `period_s`). Unconstrained runs remove
//! every bound and time all ticks; constrained runs keep (or, if the settings have none,
//! add) a bound of 1 m/s² on the acceleration setpoint and time only the ticks on which
//! the QP was solved.

use std::time::Instant;

use nalgebra::DVector;

use super::{MpcController, MpcSettings};
use crate::control::{AxisState, ControlError, SwingController, TickKind};
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
    let mut plant = ModelPlant::new(model);
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

/// The identified model used as a plant, with the measured axis state read off its newest
/// frames (swing rate by backward difference unless the model has it as a state).
pub struct ModelPlant {
    model: LinearModel,
    z: DVector<f64>,
    next: DVector<f64>,
    du: DVector<f64>,
    idx: Vec<(usize, usize, Option<usize>)>,
}

impl ModelPlant {
    /// Start at z = 0 (the model must be one [`MpcController::new`] accepts).
    pub fn new(model: &LinearModel) -> Self {
        let n = model.states.len();
        let find = |name: &str| model.states.iter().position(|s| s == name);
        let idx = (0..model.inputs.len())
            .map(|a| {
                let sfx = ["n", "e"][a.min(1)];
                let iv = find(&format!("v{sfx}")).unwrap_or(0);
                let is = find(&format!("swing_{sfx}")).unwrap_or(n.saturating_sub(1));
                (iv, is, find(&format!("swing_rate_{sfx}")))
            })
            .collect();
        Self {
            z: DVector::zeros(model.a.nrows()),
            next: DVector::zeros(model.a.nrows()),
            du: DVector::zeros(model.b.ncols()),
            model: model.clone(),
            idx,
        }
    }

    /// Write the measured state of each axis.
    pub fn measure(&self, out: &mut [AxisState]) {
        let n = self.model.states.len();
        let q = self.model.delays;
        for (o, &(iv, is, ir)) in out.iter_mut().zip(&self.idx) {
            let rate = match ir {
                Some(i) => self.z[i],
                None if q >= 2 => (self.z[is] - self.z[is + n]) / self.model.dt,
                None => 0.0,
            };
            *o = AxisState {
                v: self.z[iv],
                swing: self.z[is],
                swing_rate: rate,
            };
        }
    }

    /// Advance one step with input `u`.
    pub fn step(&mut self, u: &[f64]) {
        for (i, d) in self.du.iter_mut().enumerate() {
            *d = u[i] - self.model.input_mean[i];
        }
        self.next.copy_from(&self.model.c);
        self.next.gemv(1.0, &self.model.a, &self.z, 1.0);
        self.next.gemv(1.0, &self.model.b, &self.du, 1.0);
        std::mem::swap(&mut self.z, &mut self.next);
    }
}
