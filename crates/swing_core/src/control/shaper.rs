//! Input shaping of PX4's velocity setpoint: the crane industry's anti-sway, no feedback.
//!
//! A shaper convolves the reference with a few impulses whose amplitudes sum to one and
//! whose times cancel the residual vibration of one lightly damped mode (Singer & Seering,
//! "Preshaping command inputs to reduce system vibration", 1990). With the mode's natural
//! frequency ω, damping ζ, damped half period τ = π/(ω√(1−ζ²)) and K = exp(−ζπ/√(1−ζ²)):
//! ```text
//!   ZV :  A = [1, K] / (1 + K),                t = [0, τ]
//!   ZVD:  A = [1, 2K, K²] / (1 + K)²,          t = [0, τ, 2τ]
//! ```
//! ZV zeroes the mode's residual vibration after a step; ZVD also zeroes its derivative
//! with respect to ω, so it tolerates an error in the frequency at the cost of τ more delay.
//!
//! The mode shaped is the swing as PX4 flies it: the velocity setpoint drives PX4's
//! velocity PID, which drives the vehicle and the payload, so the relevant pole pair is that
//! of the closed loop from the velocity setpoint to the swing ([`swing_mode`]): an
//! identified model (acceleration setpoint → velocity, swing) or the white-box pendulum of
//! the estimated length and masses, closed by PX4's velocity PID (P, I, D on the measured
//! velocity) at the model's sample time. Of the closed loop's complex pole pairs the one
//! whose swing response is largest, |residue|/(1 − |λ|) (the ℓ¹ size of the mode's share of
//! the impulse response), is the swing mode.
//!
//! A payload of two links swings in two modes; shapers in series, one per mode (their
//! impulses convolved, [`series`]), zero the residual vibration of each, at the cost of the
//! sum of their delays.
//!
//! The shaper runs at its own period; an impulse time between two ticks is split between
//! the two neighbouring samples of the held reference (linear interpolation), so the shaped
//! step cancels the mode to second order in the tick.

use nalgebra::{Complex, DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::{AxisState, ControlError, ControlOutput, SwingController, TickInfo};
use crate::config::{positive, ConfigError};
use crate::control::layout::AxisLayout;
use crate::control::px4::Px4Params;
use crate::plant::PendulumModel;
use crate::sysid::LinearModel;

/// Which shaper.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShaperKind {
    /// Zero vibration: two impulses, τ of delay.
    Zv,
    /// Zero vibration and derivative: three impulses, 2τ of delay, robust to ω errors.
    #[default]
    Zvd,
}

/// Where the shaped mode's frequency and damping come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModeSource {
    /// The identified (DMDc) model closed by PX4's velocity PID.
    #[default]
    Model,
    /// The white-box pendulum (estimated length and masses) closed by PX4's velocity PID.
    Whitebox,
}

/// Input-shaper settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShaperSettings {
    /// `zv` or `zvd`.
    pub kind: ShaperKind,
    /// `model` (the identified model) or `whitebox` (the estimated pendulum).
    pub source: ModeSource,
    /// Tick period [s] (PX4's velocity loop runs at 50 Hz).
    pub period: f64,
}

impl Default for ShaperSettings {
    fn default() -> Self {
        Self {
            kind: ShaperKind::Zvd,
            source: ModeSource::Model,
            period: 0.02,
        }
    }
}

impl ShaperSettings {
    /// Check the period.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("period", self.period)?;
        if self.period > 0.5 {
            return Err(ConfigError::new(
                "period",
                format!("must be <= 0.5 s (got {})", self.period),
            ));
        }
        Ok(())
    }
}

/// A lightly damped mode: undamped natural frequency ω [rad/s] and damping ratio ζ [-].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SwingMode {
    /// Natural frequency ω [rad/s].
    pub omega: f64,
    /// Damping ratio ζ [-], 0 ≤ ζ < 1.
    pub zeta: f64,
}

impl SwingMode {
    /// Check ω > 0 and 0 ≤ ζ < 1.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("omega", self.omega)?;
        if !(self.zeta.is_finite() && (0.0..1.0).contains(&self.zeta)) {
            return Err(ConfigError::new(
                "zeta",
                format!("must be in [0, 1) (got {})", self.zeta),
            ));
        }
        Ok(())
    }
}

/// The shaper's impulses (time [s], amplitude) for `mode` (module docs); amplitudes sum to 1.
pub fn impulses(kind: ShaperKind, mode: SwingMode) -> Vec<(f64, f64)> {
    let s = (1.0 - mode.zeta * mode.zeta).sqrt();
    let tau = std::f64::consts::PI / (mode.omega * s);
    let k = (-mode.zeta * std::f64::consts::PI / s).exp();
    match kind {
        ShaperKind::Zv => vec![(0.0, 1.0 / (1.0 + k)), (tau, k / (1.0 + k))],
        ShaperKind::Zvd => {
            let d = (1.0 + k) * (1.0 + k);
            vec![(0.0, 1.0 / d), (tau, 2.0 * k / d), (2.0 * tau, k * k / d)]
        }
    }
}

/// The impulses of shapers of `kind` in series, one per mode of `modes` (their convolution,
/// sorted by time; amplitudes sum to 1): each mode's residual vibration after a step is the
/// product of its own shaper's, zero.
pub fn series(kind: ShaperKind, modes: &[SwingMode]) -> Vec<(f64, f64)> {
    let mut out = modes.iter().fold(vec![(0.0, 1.0)], |acc, &mode| {
        let next = impulses(kind, mode);
        acc.iter()
            .flat_map(|&(t, a)| next.iter().map(move |&(u, b)| (t + u, a * b)))
            .collect()
    });
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    out
}

/// The input shaper on the velocity setpoint (see module docs); implements
/// [`SwingController`] with a velocity output.
#[derive(Clone, Debug)]
pub struct InputShaper {
    axes: usize,
    period: f64,
    mode: SwingMode,
    /// Per impulse: (whole ticks of delay, fraction of a tick, amplitude).
    taps: Vec<(usize, f64, f64)>,
    /// Per axis, ring buffer of held references, newest at `head`.
    hist: Vec<Vec<f64>>,
    head: usize,
}

impl InputShaper {
    /// A shaper of `kind` for `mode` on `axes` axes (1 = N, 2 = N + E), ticking every
    /// `period` [s].
    pub fn new(
        mode: SwingMode,
        axes: usize,
        settings: &ShaperSettings,
    ) -> Result<Self, ControlError> {
        Self::for_modes(&[mode], axes, settings)
    }

    /// Shapers of `kind` in series for each of `modes` ([`series`]), the first the swing
    /// mode [`Self::mode`] reports.
    pub fn for_modes(
        modes: &[SwingMode],
        axes: usize,
        settings: &ShaperSettings,
    ) -> Result<Self, ControlError> {
        settings.validate()?;
        let Some(&mode) = modes.first() else {
            return Err(ConfigError::new("modes", "a shaper needs at least one mode").into());
        };
        for m in modes {
            m.validate()?;
        }
        if !(1..=2).contains(&axes) {
            return Err(ConfigError::new("axes", "must be 1 (N) or 2 (N+E)").into());
        }
        let taps: Vec<(usize, f64, f64)> = series(settings.kind, modes)
            .into_iter()
            .map(|(t, a)| {
                let x = t / settings.period;
                let whole = x.floor();
                (whole as usize, x - whole, a)
            })
            .collect();
        let len = taps.iter().map(|t| t.0).max().unwrap_or(0) + 2;
        Ok(Self {
            axes,
            period: settings.period,
            mode,
            taps,
            hist: vec![vec![0.0; len]; axes],
            head: 0,
        })
    }

    /// The shaped swing mode (the first of several).
    pub fn mode(&self) -> SwingMode {
        self.mode
    }

    /// The reference `ticks` ago on `axis` (older than the buffer: the oldest held).
    fn past(&self, axis: usize, ticks: usize) -> f64 {
        let h = &self.hist[axis];
        let len = h.len();
        h[(self.head + len - ticks.min(len - 1)) % len]
    }
}

impl SwingController for InputShaper {
    fn axes(&self) -> usize {
        self.axes
    }

    fn period(&self) -> f64 {
        self.period
    }

    fn output(&self) -> ControlOutput {
        ControlOutput::Velocity
    }

    fn reset(&mut self, state: &[AxisState], _acc: &[f64]) {
        // The reference before the engage is taken as the velocity flown then.
        for (a, h) in self.hist.iter_mut().enumerate() {
            let v = state.get(a).map(|s| s.v).filter(|v| v.is_finite());
            h.fill(v.unwrap_or(0.0));
        }
    }

    fn step(
        &mut self,
        state: &[AxisState],
        vel_ref: &[f64],
        out: &mut [f64],
    ) -> Result<TickInfo, ControlError> {
        crate::control::check_tick_inputs(self.axes, state, vel_ref, out)?;
        let len = self.hist[0].len();
        self.head = (self.head + 1) % len;
        for (a, o) in out.iter_mut().enumerate() {
            self.hist[a][self.head] = vel_ref[a];
            *o = self
                .taps
                .iter()
                .map(|&(n, f, amp)| amp * ((1.0 - f) * self.past(a, n) + f * self.past(a, n + 1)))
                .sum();
        }
        Ok(TickInfo::default())
    }
}

/// The swing mode of the loop PX4 closes around a discrete model (module docs).
///
/// `a`, `b` (n × n, n × 1) are one axis' discrete model at `dt` [s] with the input the
/// acceleration setpoint, `iv` and `is` the indices of the velocity and the swing in its
/// state. PX4's velocity PID of `px4` (axis 0 gains) is closed around it at `dt`.
pub fn swing_mode(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    iv: usize,
    is: usize,
    dt: f64,
    px4: &Px4Params,
) -> Result<SwingMode, ControlError> {
    let n = a.nrows();
    if a.shape() != (n, n) || b.shape() != (n, 1) || iv >= n || is >= n {
        return Err(ControlError::Model(format!(
            "swing mode: A must be square and B one column, indices inside (A {:?}, B {:?})",
            a.shape(),
            b.shape()
        )));
    }
    // Closed loop over [z; ∫e; v_prev] with u = Kp (r − v) + ξ − Kd (v − v_prev)/dt and
    // ξ⁺ = ξ + Ki dt (r − v) (PX4's integrator in discrete time).
    let (kp, ki, kd) = (px4.vel_p[0], px4.vel_i[0], px4.vel_d[0]);
    let nc = n + 2;
    // u = k_z z + ξ + kd/dt v_prev + kp r.
    let mut kz = DVector::<f64>::zeros(n);
    kz[iv] = -kp - kd / dt;
    let mut acl = DMatrix::<f64>::zeros(nc, nc);
    let mut bcl = DVector::<f64>::zeros(nc);
    let bz = b.column(0);
    acl.view_mut((0, 0), (n, n))
        .copy_from(&(a + bz * kz.transpose()));
    for i in 0..n {
        acl[(i, n)] = bz[i];
        acl[(i, n + 1)] = bz[i] * kd / dt;
        bcl[i] = bz[i] * kp;
    }
    acl[(n, n)] = 1.0;
    acl[(n, iv)] = -ki * dt;
    bcl[n] = ki * dt;
    acl[(n + 1, iv)] = 1.0;
    if acl.iter().any(|x| !x.is_finite()) {
        return Err(ControlError::Model(
            "swing mode: model is not finite".into(),
        ));
    }
    let eig = crate::linalg::eigenvalues(&acl)
        .ok_or_else(|| ControlError::Model("swing mode: eigenvalues did not converge".into()))?;
    let ac = acl.map(|x| Complex::new(x, 0.0));
    let mut best: Option<(f64, Complex<f64>)> = None;
    for lam in eig.iter() {
        if lam.im <= 1e-9 || lam.norm() > 1.0 + 1e-9 {
            continue;
        }
        // Residue of H(z) = e_sᵀ (zI − A)⁻¹ b at λ: ε H(λ + ε) for a small ε.
        let eps = Complex::new(1e-7 * lam.norm().max(1e-3), 0.0);
        let z = lam + eps;
        let m = DMatrix::<Complex<f64>>::identity(nc, nc) * z - &ac;
        let rhs = bcl.map(|x| Complex::new(x, 0.0));
        let Some(x) = m.lu().solve(&rhs) else {
            continue;
        };
        let size = (x[is] * eps).norm() / (1.0 - lam.norm()).max(1e-9);
        if best.is_none_or(|(s, _)| size > s) {
            best = Some((size, *lam));
        }
    }
    let Some((_, lam)) = best else {
        return Err(ControlError::Model(
            "swing mode: the closed loop has no oscillatory pole pair inside the unit circle"
                .into(),
        ));
    };
    let s = lam.ln() / dt;
    let omega = s.norm();
    let zeta = (-s.re / omega).clamp(0.0, 0.99);
    Ok(SwingMode { omega, zeta })
}

/// The swing mode of an identified model's first axis under PX4's velocity PID.
pub fn model_swing_mode(model: &LinearModel, px4: &Px4Params) -> Result<SwingMode, ControlError> {
    let layout = AxisLayout::from_model(model)?;
    let ax = &layout.axes()[0];
    let b = model.b.columns(0, 1).into_owned();
    swing_mode(&model.a, &b, ax.v, ax.swing, model.dt, px4)
}

/// The swing mode of the white-box pendulum `p` under PX4's velocity PID, closed at `dt` [s].
pub fn pendulum_swing_mode(
    p: &PendulumModel,
    dt: f64,
    px4: &Px4Params,
) -> Result<SwingMode, ControlError> {
    p.validate()?;
    positive("dt", dt)?;
    let (a, b) = p.discrete(dt);
    swing_mode(&a, &b, 0, 1, dt, px4)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exact response of the undamped oscillator ẍ + ω²x = ω² u to the held samples `u`
    /// (zero-order hold of `dt`), from rest; returns (x, ẋ/ω) after the last sample.
    fn oscillator(u: &[f64], omega: f64, dt: f64) -> (f64, f64) {
        let (c, s) = ((omega * dt).cos(), (omega * dt).sin());
        let (mut x, mut w) = (0.0, 0.0); // w = ẋ/ω
        for &uk in u {
            let (dx, dw) = (x - uk, w);
            x = uk + c * dx + s * dw;
            w = -s * dx + c * dw;
        }
        (x, w)
    }

    fn shaped_step(kind: ShaperKind, mode: SwingMode, period: f64, ticks: usize) -> Vec<f64> {
        let settings = ShaperSettings {
            kind,
            period,
            ..Default::default()
        };
        let mut sh = InputShaper::new(mode, 1, &settings).unwrap();
        sh.reset(&[AxisState::default()], &[0.0]);
        let mut out = [0.0];
        (0..ticks)
            .map(|_| {
                sh.step(&[AxisState::default()], &[1.0], &mut out).unwrap();
                out[0]
            })
            .collect()
    }

    #[test]
    fn zv_leaves_no_residual_swing_on_an_undamped_pendulum() {
        // A pendulum whose suspension point follows u: θ̈ + ω²θ = ω² u / g-scaled; the
        // residual amplitude after a unit step is |Σ Aᵢ e^{jωtᵢ}| (0 for ZV and ZVD).
        let omega = std::f64::consts::PI; // half period 1 s: 50 ticks of 20 ms exactly
        let mode = SwingMode { omega, zeta: 0.0 };
        let dt = 0.02;
        let (x, w) = oscillator(&shaped_step(ShaperKind::Zv, mode, dt, 400), omega, dt);
        let residual = ((x - 1.0).powi(2) + w * w).sqrt();
        assert!(residual < 1e-12, "ZV residual {residual}");
        let (x, w) = oscillator(&vec![1.0; 400], omega, dt);
        let unshaped = ((x - 1.0).powi(2) + w * w).sqrt();
        assert!(
            (unshaped - 1.0).abs() < 1e-9,
            "unshaped residual {unshaped}"
        );
        let (x, w) = oscillator(&shaped_step(ShaperKind::Zvd, mode, dt, 400), omega, dt);
        assert!(((x - 1.0).powi(2) + w * w).sqrt() < 1e-12);
    }

    #[test]
    fn shapers_in_series_leave_no_residual_in_either_mode() {
        // Two undamped modes, half periods 1 s and 0.3 s (whole ticks of 20 ms): the series
        // shaper leaves neither swinging, each mode's own shaper leaves the other's.
        let dt = 0.02;
        let slow = SwingMode {
            omega: std::f64::consts::PI,
            zeta: 0.0,
        };
        let fast = SwingMode {
            omega: std::f64::consts::PI / 0.3,
            zeta: 0.0,
        };
        let residual = |u: &[f64], mode: SwingMode| {
            let (x, w) = oscillator(u, mode.omega, dt);
            ((x - 1.0).powi(2) + w * w).sqrt()
        };
        let step = |modes: &[SwingMode]| -> Vec<f64> {
            let mut sh = InputShaper::for_modes(modes, 1, &ShaperSettings::default()).unwrap();
            sh.reset(&[AxisState::default()], &[0.0]);
            let mut out = [0.0];
            (0..400)
                .map(|_| {
                    sh.step(&[AxisState::default()], &[1.0], &mut out).unwrap();
                    out[0]
                })
                .collect()
        };
        let both = step(&[slow, fast]);
        assert!(residual(&both, slow) < 1e-12 && residual(&both, fast) < 1e-12);
        assert!(residual(&step(&[slow]), fast) > 0.1);
        assert!(residual(&step(&[fast]), slow) > 0.1);
        let imp = series(ShaperKind::Zvd, &[slow, fast]);
        assert_eq!(imp.len(), 9);
        assert!((imp.iter().map(|x| x.1).sum::<f64>() - 1.0).abs() < 1e-12);
        assert!((imp.last().unwrap().0 - 2.6).abs() < 1e-12, "{imp:?}");
        assert!(InputShaper::for_modes(&[], 1, &ShaperSettings::default()).is_err());
    }

    #[test]
    fn off_grid_delay_cancels_to_second_order() {
        // Half period 0.8137 s is no multiple of 20 ms: the split impulse leaves a residual
        // of the order (ω dt)², far below the unshaped 1.
        let omega = std::f64::consts::PI / 0.8137;
        let mode = SwingMode { omega, zeta: 0.0 };
        let dt = 0.02;
        let (x, w) = oscillator(&shaped_step(ShaperKind::Zv, mode, dt, 400), omega, dt);
        let residual = ((x - 1.0).powi(2) + w * w).sqrt();
        assert!(residual < (omega * dt).powi(2), "ZV residual {residual}");
    }

    #[test]
    fn zvd_is_more_robust_to_a_frequency_error_than_zv() {
        // Closed form: residual of impulses (tᵢ, Aᵢ) at frequency ω' is |Σ Aᵢ e^{jω'tᵢ}|.
        let mode = SwingMode {
            omega: 3.0,
            zeta: 0.05,
        };
        // A damped mode's residual: e^{−ζωt_N}|Σ Aᵢ e^{ζωtᵢ} e^{jω_d tᵢ}| (Singer & Seering).
        let residual = |kind, w: f64| {
            let wd = w * (1.0 - mode.zeta * mode.zeta).sqrt();
            let imp = impulses(kind, mode);
            let t_end = imp.last().unwrap().0;
            let (mut re, mut im) = (0.0, 0.0);
            for (t, a) in imp {
                let d = (-mode.zeta * w * (t_end - t)).exp();
                re += a * d * (wd * t).cos();
                im += a * d * (wd * t).sin();
            }
            (re * re + im * im).sqrt()
        };
        assert!(residual(ShaperKind::Zv, 3.0) < 1e-12);
        assert!(residual(ShaperKind::Zvd, 3.0) < 1e-12);
        let (zv, zvd) = (
            residual(ShaperKind::Zv, 3.3),
            residual(ShaperKind::Zvd, 3.3),
        );
        assert!(zvd < 0.25 * zv, "ZV {zv}, ZVD {zvd} at +10 % frequency");
        let sum: f64 = impulses(ShaperKind::Zvd, mode).iter().map(|x| x.1).sum();
        assert!((sum - 1.0).abs() < 1e-12);
    }

    #[test]
    fn swing_mode_of_a_pendulum_without_feedback_is_its_own() {
        // With PX4's gains zero the closed loop is the pendulum itself: ω² = g(m_Q+m_p)/(m_Q l).
        let p = PendulumModel {
            m_q: 1.0,
            m_p: 0.2,
            l: 1.5,
            c: 0.0,
        };
        let dt = 0.03;
        let (a, b) = p.discrete(dt);
        let px4 = Px4Params {
            vel_p: [0.0; 3],
            vel_i: [0.0; 3],
            vel_d: [0.0; 3],
            ..Default::default()
        };
        let m = swing_mode(&a, &b, 0, 1, dt, &px4).unwrap();
        let want = (crate::plant::GRAVITY * 1.2 / 1.5).sqrt();
        assert!(
            (m.omega - want).abs() < 1e-9 * want,
            "{} vs {want}",
            m.omega
        );
        assert!(m.zeta < 1e-9);
        // Under PX4's velocity PID the mode moves but stays a lightly damped swing.
        let m = swing_mode(&a, &b, 0, 1, dt, &Px4Params::default()).unwrap();
        assert!(m.omega > 1.5 && m.omega < 5.0 && m.zeta < 0.5, "{m:?}");
    }
}
