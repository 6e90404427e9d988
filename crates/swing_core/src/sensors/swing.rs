//! Swing sources, and the swing angle estimated from the vehicle's own IMU.
//!
//! A flight measures the payload's swing one way ([`SwingSource`]): a world-frame swing
//! sensor (`sensor`), a cable-angle sensor fixed to the airframe composed with the attitude
//! (`body`, [`super::cable`]), or nothing on the cable at all (`imu`).
//!
//! **The swing in the IMU.** The rotors push along body z only, so the accelerometer's body
//! x/y specific force is the external force on the vehicle other than thrust, over its mass:
//! the cable's pull T n (T the tension, n the cable's unit vector, vehicle → payload) plus
//! the airframe's drag D. In body axes, f_xy = (T n_b,xy + D_xy) / m_Q. With the payload
//! hanging, the pull along body z is T n_bz ≈ m_p (g − a_z) ≈ m_p g, so
//!
//!   n_bx / n_bz = (f_x − D_x/m_Q) / k,   k = T n_bz / m_Q ≈ g m_p / m_Q,
//!
//! the tangent of the cable's angle relative to the body, measured with a scale k that only
//! the payload-to-vehicle mass ratio sets. The estimate rotates that body direction by the
//! attitude into the world frame exactly as the body sensor does ([`super::cable::compose`]):
//! r_b = ((f_x − o_x + d_x)/k̂, (f_y − o_y + d_y)/k̂, 1), θ̂ = (atan2(r_N, r_D),
//! atan2(r_E, r_D)), then a second-order Butterworth low-pass at `cutoff` removes what is left
//! of rotor vibration and noise ([`SwingFilter`], which also gives the swing rate controllers
//! read: the backward difference of the filtered angle, so the rate carries the same lag as
//! the angle and never the simulator's truth). o is the accelerometer's offset at hover
//! (bias; `tare` measures it at the start of each flight, with the payload hanging still;
//! a controller flying on the estimate engages only once the tare is over), d the modelled
//! drag specific force removed, d_i = c_lin,i v_b,i + c_quad,i v_b,i |v_b,i| with v_b the
//! body-frame velocity (still air assumed: wind shows up as swing), the same drag model
//! PX4's EKF2 uses to estimate wind from these two channels (`EKF2_BCOEF_*`, `EKF2_MCOEF`).
//!
//! To first order the estimate is θ̂ ≈ (k/k̂)(θ − tilt) + tilt: a wrong scale both scales the
//! swing and leaks (1 − k/k̂) of the vehicle's tilt into it, which is why the scale is
//! calibrated from the flight's own dynamics (`sysid::swing_scale`). The
//! dynamic tension (centripetal m_p l θ̇², the vehicle's vertical acceleration) changes k by a
//! few per cent at most in the swings that matter here.

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use super::cable::compose_tangents;
use super::filter::LowPass2;
use super::pendulum::PendulumObserver;
use crate::config::{in_range, non_negative, positive, ConfigError};
use crate::plant::GRAVITY;

/// Where a flight's swing measurement comes from (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SwingSource {
    /// A swing sensor reading the world-frame angles.
    #[default]
    Sensor,
    /// A cable-angle sensor on the airframe, composed with the attitude.
    Body,
    /// No sensor on the cable: the swing estimated from the IMU.
    Imu,
}

impl SwingSource {
    /// The source's name in files and messages.
    pub fn name(self) -> &'static str {
        match self {
            SwingSource::Sensor => "sensor",
            SwingSource::Body => "body",
            SwingSource::Imu => "imu",
        }
    }
}

/// How the IMU's specific force becomes a world-frame swing angle (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuSwingSettings {
    /// Pull scale k̂: body-horizontal specific force per unit tangent of the cable's
    /// body-relative angle, ≈ g·m_p/m_Q [m/s²].
    pub scale: f64,
    /// Cutoff of the estimate's low-pass, and of the one the body sensor's swing is
    /// differentiated through for its rate (0: no low-pass) [Hz].
    pub cutoff: f64,
    /// Rate the estimator is fed at [Hz] (sets the low-pass coefficients).
    pub rate: f64,
    /// Accelerometer offset at hover, body x then y [m/s²], used until a tare replaces it.
    pub offset: [f64; 2],
    /// Seconds at the start of a flight over which the offset is measured (the payload
    /// hanging still; a swing controller on the estimate engages after it) [s]; 0 keeps
    /// `offset`.
    pub tare: f64,
    /// Linear drag per vehicle mass removed, body x then y [1/s].
    pub drag_linear: [f64; 2],
    /// Quadratic drag per vehicle mass removed, body x then y [1/m].
    pub drag_quadratic: [f64; 2],
    /// Cable length of the pendulum observer that tells the swing from drag
    /// ([`super::pendulum`]) [m]; 0 reads the low-passed estimate as the swing.
    pub length: f64,
    /// The observer's pendulum damping ratio.
    pub damping: f64,
}

impl Default for ImuSwingSettings {
    fn default() -> Self {
        Self {
            // A payload of a fifth of the vehicle's mass, until a calibration says better.
            scale: 0.2 * GRAVITY,
            // Measured on the default step (benches/imu_estimator.py, medians over IMU
            // seeds): 5 Hz lags (MPC on the estimate 3.9 deg·s swing excess vs 2.7 at
            // 10–20 Hz); above 15 Hz the filtered derivative is noisy enough to hurt a
            // controller that reads the rate (LQR 1.2 at 10 Hz, 2.2 at 20, 15 at 40).
            cutoff: 10.0,
            rate: 100.0,
            offset: [0.0; 2],
            tare: 1.0,
            drag_linear: [0.0; 2],
            drag_quadratic: [0.0; 2],
            length: 0.0,
            damping: 0.0,
        }
    }
}

impl ImuSwingSettings {
    /// Check the settings; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        in_range("scale", self.scale, 1e-3, 100.0)?;
        positive("rate", self.rate)?;
        non_negative("cutoff", self.cutoff)?;
        if self.cutoff > 0.0 && self.cutoff >= 0.5 * self.rate {
            return Err(ConfigError::new(
                "cutoff",
                format!(
                    "must be below half the rate {} Hz (got {} Hz)",
                    self.rate, self.cutoff
                ),
            ));
        }
        in_range("tare", self.tare, 0.0, 60.0)?;
        in_range("length", self.length, 0.0, 100.0)?;
        in_range("damping", self.damping, 0.0, 2.0)?;
        for i in 0..2 {
            in_range(&format!("offset[{i}]"), self.offset[i], -50.0, 50.0)?;
            in_range(
                &format!("drag_linear[{i}]"),
                self.drag_linear[i],
                -10.0,
                10.0,
            )?;
            in_range(
                &format!("drag_quadratic[{i}]"),
                self.drag_quadratic[i],
                -10.0,
                10.0,
            )?;
        }
        Ok(())
    }

    /// A low-passed estimate (made at this estimator's rate, from the flight's start) as this
    /// estimator's pendulum observer reads it, driven by the vehicle's NED `velocity` (N, E)
    /// [m/s] at the same samples: what [`ImuSwingEstimator::estimate`] returns, for a
    /// flight's estimate remade offline. Unchanged without an observer (`length` 0).
    pub fn observe(&self, estimate: &[[f64; 2]], velocity: &[[f64; 2]]) -> Vec<[f64; 2]> {
        let Some(mut obs) = PendulumObserver::new(self.length, self.damping, 1.0 / self.rate)
        else {
            return estimate.to_vec();
        };
        let mut motion = SwingFilter::new(self.rate, self.cutoff);
        // The online observer starts on the tare's last sample.
        let start = ((self.tare * self.rate).round() as usize).saturating_sub(1);
        estimate
            .iter()
            .zip(velocity)
            .enumerate()
            .map(|(k, (z, v))| {
                motion.update(*v);
                if k >= start {
                    obs.update(*z, motion.rate())
                } else {
                    *z
                }
            })
            .collect()
    }
}

/// The swing estimated from the IMU, one sample at a time (module docs). No allocation after
/// construction.
#[derive(Clone, Debug)]
pub struct ImuSwingEstimator {
    s: ImuSwingSettings,
    filter: SwingFilter,
    /// The velocity's low-pass, whose rate drives the observer.
    motion: SwingFilter,
    observer: Option<PendulumObserver>,
    offset: [f64; 2],
    samples: u64,
    tare_samples: u64,
    tare_sum: [f64; 2],
}

impl ImuSwingEstimator {
    /// A fresh estimator (validates the settings).
    pub fn new(settings: ImuSwingSettings) -> Result<Self, ConfigError> {
        settings.validate()?;
        let filter = SwingFilter::new(settings.rate, settings.cutoff);
        let tare_samples = (settings.tare * settings.rate).round() as u64;
        Ok(Self {
            offset: settings.offset,
            motion: filter,
            observer: PendulumObserver::new(settings.length, settings.damping, 1.0 / settings.rate),
            s: settings,
            filter,
            samples: 0,
            tare_samples,
            tare_sum: [0.0; 2],
        })
    }

    /// The settings.
    pub fn settings(&self) -> &ImuSwingSettings {
        &self.s
    }

    /// Whether the tare is over (at once with a tare of 0 s): until then the offset is the
    /// settings' and the estimate reads the accelerometer's bias as swing.
    pub fn tared(&self) -> bool {
        self.samples >= self.tare_samples
    }

    /// The offset in use (the tared one once the tare is over) [m/s²].
    pub fn offset(&self) -> [f64; 2] {
        self.offset
    }

    /// Start over (a new flight): filters, tare and offset.
    pub fn reset(&mut self) {
        let filter = SwingFilter::new(self.s.rate, self.s.cutoff);
        *self = Self {
            s: self.s.clone(),
            filter,
            motion: filter,
            observer: PendulumObserver::new(self.s.length, self.s.damping, 1.0 / self.s.rate),
            offset: self.s.offset,
            samples: 0,
            tare_samples: self.tare_samples,
            tare_sum: [0.0; 2],
        };
    }

    /// The body-horizontal pull per vehicle mass of one sample: specific force minus offset,
    /// plus the modelled drag removed [m/s²].
    #[inline]
    fn pull(&self, accel: &[f64; 3], rot: &Matrix3<f64>, vel: &[f64; 3]) -> [f64; 2] {
        let vb = rot.transpose() * nalgebra::Vector3::from(*vel);
        let mut p = [0.0; 2];
        for i in 0..2 {
            let v = vb[i];
            p[i] = accel[i] + self.s.drag_linear[i] * v + self.s.drag_quadratic[i] * v * v.abs();
        }
        p
    }

    /// The unfiltered world-frame angle of one sample [rad] (see the module docs).
    #[inline]
    pub fn angle(&self, accel: &[f64; 3], rot: &Matrix3<f64>, vel: &[f64; 3]) -> [f64; 2] {
        let p = self.pull(accel, rot, vel);
        let k = self.s.scale;
        compose_tangents(
            rot,
            [(p[0] - self.offset[0]) / k, (p[1] - self.offset[1]) / k],
        )
    }

    /// Feed one IMU sample: body specific force [m/s²], attitude (body → NED) and NED
    /// velocity [m/s]; returns the filtered estimate (swing_n, swing_e) [rad].
    #[inline]
    pub fn update(&mut self, accel: [f64; 3], rot: &Matrix3<f64>, vel: [f64; 3]) -> [f64; 2] {
        if self.samples < self.tare_samples {
            let p = self.pull(&accel, rot, &vel);
            self.tare_sum[0] += p[0];
            self.tare_sum[1] += p[1];
            self.samples += 1;
            if self.samples == self.tare_samples {
                let n = self.tare_samples as f64;
                self.offset = [self.tare_sum[0] / n, self.tare_sum[1] / n];
                // The filter restarts on the tare's own mean, the angle of a pull equal to
                // the offset (the payload hanging still, as the tare assumes), not on one
                // sample: a sample carries the accelerometer's whole noise (degrees at the
                // estimator's rate), which the observer, starting on it, would read as drag
                // and answer with a swing for seconds as the filter left it.
                self.filter.settle(compose_tangents(rot, [0.0, 0.0]));
            }
        }
        let a = self.angle(&accel, rot, &vel);
        let z = self.filter.update(a);
        // The vehicle's acceleration through the same low-pass as the estimate, so the
        // observer's input and measurement carry the same lag.
        self.motion.update([vel[0], vel[1]]);
        match self.observer.as_mut() {
            Some(obs) if self.samples >= self.tare_samples => obs.update(z, self.motion.rate()),
            _ => z,
        }
    }

    /// The latest estimate (swing_n, swing_e) [rad] (zeros before the first sample): the
    /// observer's swing once the tare is over when it has a length, else the low-passed
    /// estimate.
    pub fn estimate(&self) -> [f64; 2] {
        match &self.observer {
            Some(obs) if self.tared() => obs.angle(),
            _ => self.filter.angle(),
        }
    }

    /// The latest estimate's rate (N, E) [rad/s]: the observer's swing rate, or without one
    /// the backward difference of the filtered estimate (zeros before the second sample and
    /// right after the tare).
    pub fn rate_estimate(&self) -> [f64; 2] {
        match &self.observer {
            Some(obs) if self.tared() => obs.rate(),
            _ => self.filter.rate(),
        }
    }
}

/// A measured swing's low-pass and its rate, both channels (N, E), one sample at a time: the
/// second-order Butterworth low-pass ([`LowPass2`]), then the backward difference of its
/// output, d̂_k = (y_k − y_{k−1})·f_s. For a swing at frequency f ≪ f_c the rate lags the
/// true rate by the filter's group delay at DC, √2/(2 f_s tan(π f_c/f_s)) (≈ √2/(2π f_c)),
/// plus half a sample, 1/(2 f_s). No allocation.
#[derive(Clone, Copy, Debug)]
pub struct SwingFilter {
    lp: [LowPass2; 2],
    sample_hz: f64,
    out: [f64; 2],
    rate: [f64; 2],
    started: bool,
}

impl SwingFilter {
    /// A filter of cutoff `cutoff_hz` (0: no low-pass, the plain backward difference) for
    /// samples arriving at `sample_hz` [Hz].
    pub fn new(sample_hz: f64, cutoff_hz: f64) -> Self {
        Self {
            lp: [LowPass2::new(sample_hz, cutoff_hz); 2],
            sample_hz,
            out: [0.0; 2],
            rate: [0.0; 2],
            started: false,
        }
    }

    /// Start over from the next sample (the filter settles on it, its rate 0).
    pub fn restart(&mut self) {
        self.started = false;
    }

    /// Start over settled on `x` (N, E) [rad], its rate 0: the next sample is filtered from
    /// there.
    pub fn settle(&mut self, x: [f64; 2]) {
        for i in 0..2 {
            self.lp[i].reset(x[i]);
        }
        self.out = x;
        self.rate = [0.0; 2];
        self.started = true;
    }

    /// Feed one sample (N, E) [rad]; returns the filtered angle [rad].
    #[inline]
    pub fn update(&mut self, x: [f64; 2]) -> [f64; 2] {
        if !self.started {
            for i in 0..2 {
                self.lp[i].reset(x[i]);
            }
            self.out = x;
            self.started = true;
        }
        for i in 0..2 {
            let y = self.lp[i].apply(x[i]);
            self.rate[i] = (y - self.out[i]) * self.sample_hz;
            self.out[i] = y;
        }
        self.out
    }

    /// The latest filtered angle (N, E) [rad] (zeros before the first sample).
    pub fn angle(&self) -> [f64; 2] {
        self.out
    }

    /// The latest rate (N, E) [rad/s] (zeros before the second sample).
    pub fn rate(&self) -> [f64; 2] {
        self.rate
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::dynamics::rotation;
    use nalgebra::{UnitQuaternion, Vector3};

    fn rot(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
        let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
        rotation(q.quaternion())
    }

    /// The specific force a static payload pull of tension `t` along world direction `n`
    /// gives a vehicle of mass `m` (thrust adds only along body z, so it is left out of x/y).
    fn pull_force(r: &Matrix3<f64>, n: Vector3<f64>, t: f64, m: f64) -> [f64; 3] {
        let f = r.transpose() * n * (t / m);
        [f.x, f.y, f.z - 9.8]
    }

    #[test]
    fn the_exact_pull_scale_returns_the_true_angle_at_any_attitude() {
        let (mp, mq) = (0.2, 0.95);
        for (roll, pitch, yaw) in [(0.0, 0.0, 0.0), (0.1, -0.3, 0.7), (-0.2, 0.25, -2.0)] {
            let r = rot(roll, pitch, yaw);
            for (sn, se) in [(0.15, 0.0), (-0.3, 0.2)] {
                let n = crate::plant::dynamics::unit_from_swing(sn, se);
                // Pull along body z is exactly k·m_Q with k the scale: tension = k m_Q / n_bz.
                let k = GRAVITY * mp / mq;
                let nbz = (r.transpose() * n).z;
                let accel = pull_force(&r, n, k * mq / nbz, mq);
                let est = ImuSwingEstimator::new(ImuSwingSettings {
                    scale: k,
                    tare: 0.0,
                    ..Default::default()
                })
                .unwrap();
                let a = est.angle(&accel, &r, &[0.0; 3]);
                assert!((a[0] - sn).abs() < 1e-12, "{a:?} vs {sn} {se}");
                assert!((a[1] - se).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn a_wrong_scale_scales_the_swing_and_leaks_the_tilt() {
        // Level vehicle: only the scale; pitched vehicle, no swing: (1 − k/k̂) of the tilt.
        let k = 2.0;
        let est = ImuSwingEstimator::new(ImuSwingSettings {
            scale: 2.0 * k,
            tare: 0.0,
            ..Default::default()
        })
        .unwrap();
        let r0 = rot(0.0, 0.0, 0.0);
        let n = crate::plant::dynamics::unit_from_swing(0.02, 0.0);
        let a = est.angle(&pull_force(&r0, n, k * 0.95 / n.z, 0.95), &r0, &[0.0; 3]);
        assert!((a[0] - 0.01).abs() < 1e-5, "{a:?}");
        let r = rot(0.0, -0.04, 0.0);
        let down = Vector3::new(0.0, 0.0, 1.0);
        let nbz = (r.transpose() * down).z;
        let a = est.angle(&pull_force(&r, down, k * 0.95 / nbz, 0.95), &r, &[0.0; 3]);
        assert!((a[0] - 0.5 * -0.04).abs() < 1e-4, "{a:?}");
    }

    #[test]
    fn the_tare_removes_the_bias_and_drag_is_removed_by_its_model() {
        let mut est = ImuSwingEstimator::new(ImuSwingSettings {
            scale: 2.0,
            tare: 0.5,
            rate: 100.0,
            drag_quadratic: [0.06, 0.06],
            ..Default::default()
        })
        .unwrap();
        let r = rot(0.0, 0.0, 0.0);
        for _ in 0..50 {
            assert!(!est.tared());
            est.update([0.3, -0.1, -9.8], &r, [0.0; 3]);
        }
        assert!(est.tared());
        let o = est.offset();
        assert!(
            (o[0] - 0.3).abs() < 1e-12 && (o[1] + 0.1).abs() < 1e-12,
            "{o:?}"
        );
        // Cruising North at 2 m/s in still air: drag −0.06·4 on x, which the model removes.
        let mut last = [1.0; 2];
        for _ in 0..300 {
            last = est.update([0.3 - 0.24, -0.1, -9.8], &r, [2.0, 0.0, 0.0]);
        }
        assert!(last[0].abs() < 1e-9 && last[1].abs() < 1e-9, "{last:?}");
    }

    #[test]
    fn a_still_payload_reads_still_right_after_the_tare_whatever_its_last_sample() {
        // Hover with the payload hanging still; the tare's last sample is off by one sample
        // of the accelerometer's white noise (PX4 SITL's density in 100 Hz block means,
        // 0.13 m/s²: 4.4° of swing at the scale below), every other sample exact. The
        // observer starts as the tare ends: started on that sample it would read it as drag
        // and answer the filter's return with a swing of degrees for seconds. Started on the
        // tare's mean, what is left is the low-pass's answer to one sample and the tare's
        // mean carrying 1/100 of it.
        let settings = ImuSwingSettings {
            scale: 1.7,
            tare: 1.0,
            rate: 100.0,
            cutoff: 4.5,
            length: 1.0,
            damping: 0.01,
            ..Default::default()
        };
        let r = rot(0.0, 0.0, 0.0);
        let spike = 0.0186 * (100.0_f64 / 2.0).sqrt();
        for sign in [1.0, -1.0] {
            let mut est = ImuSwingEstimator::new(settings.clone()).unwrap();
            let mut worst = 0.0_f64;
            for k in 0..400 {
                let off = if k == 99 { sign * spike } else { 0.0 };
                let a = est.update([0.05 + off, -0.02, -9.8], &r, [0.0; 3]);
                if k >= 99 {
                    worst = worst.max(a[0].abs()).max(a[1].abs());
                }
            }
            // (Measured: 0.18° so, 3.7° started on the sample.)
            assert!(
                worst < 0.3_f64.to_radians(),
                "worst {:.3}°",
                worst.to_degrees()
            );
        }
    }

    #[test]
    fn the_filtered_rate_of_a_slow_sine_is_its_derivative_delayed_by_the_group_delay() {
        // A swing-like sine at 0.5 Hz, sampled at 100 Hz through a 20 Hz Butterworth: the rate
        // is the sine's derivative delayed by the bilinear Butterworth's group delay at DC,
        // √2/(2 f_s tan(π f_c/f_s)), plus half a sample (closed form at f ≪ f_c), with unit
        // gain; undelayed, the error is the delay times the second derivative.
        let (fs, fc, f) = (100.0, 20.0, 0.5);
        let pi = std::f64::consts::PI;
        let w = 2.0 * pi * f;
        let tau = std::f64::consts::SQRT_2 / (2.0 * fs * (pi * fc / fs).tan()) + 0.5 / fs;
        let mut filt = SwingFilter::new(fs, fc);
        let (mut worst_delayed, mut worst_now) = (0.0_f64, 0.0_f64);
        for k in 0..1000 {
            let t = k as f64 / fs;
            filt.update([(w * t).sin(), 0.3]);
            if t > 2.0 {
                let r = filt.rate();
                worst_delayed = worst_delayed.max((r[0] - w * (w * (t - tau)).cos()).abs());
                worst_now = worst_now.max((r[0] - w * (w * t).cos()).abs());
                assert!(r[1].abs() < 1e-12);
            }
        }
        assert!(worst_delayed < 0.01 * w, "{worst_delayed}");
        assert!(worst_now > 0.9 * w * w * tau, "{worst_now}");
        // The first sample after a restart settles the filter: no rate spike.
        filt.restart();
        filt.update([5.0, -5.0]);
        assert_eq!(filt.rate(), [0.0, 0.0]);
        assert_eq!(filt.angle(), [5.0, -5.0]);
    }

    #[test]
    fn bad_settings_name_the_field() {
        let s = ImuSwingSettings {
            cutoff: 60.0,
            ..Default::default()
        };
        assert_eq!(s.validate().unwrap_err().field, "cutoff");
        let s = ImuSwingSettings {
            scale: 0.0,
            ..Default::default()
        };
        assert_eq!(s.validate().unwrap_err().field, "scale");
    }
}
