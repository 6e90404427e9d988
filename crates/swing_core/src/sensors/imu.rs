//! The vehicle's IMU: body-frame specific force and angular rate as the flight controller
//! reads them, with the errors users know from PX4's simulators and real airframes.
//!
//! Per raw sample (the physics rate in the simulator), for each axis of the accelerometer
//! (and likewise of the gyro):
//!
//!   raw = truth + b_on + b(t) + σ_d·N(0, 1) + Σ_motors v_i(t),
//!
//! - white noise of density N [unit/√Hz]: per-sample σ_d = N/√Δt (the Gazebo IMU plugin of
//!   PX4 SITL, `accelerometerNoiseDensity`, `gyroscopeNoiseDensity`);
//! - a turn-on bias b_on ~ N(0, σ_on²) drawn once per flight (`…TurnOnBiasSigma`);
//! - a bias drift b(t), first-order Gauss–Markov of random-walk density σ_b and correlation
//!   time τ: b ← e^{−Δt/τ} b + σ_b √(τ/2 (1 − e^{−2Δt/τ})) N(0, 1) (`…RandomWalk`,
//!   `…BiasCorrelationTime`);
//! - rotor vibration: each motor's imbalance shakes the airframe at its rotation frequency
//!   f_i = f_hover √(T_i / T_hover) (thrust ∝ ω²) with an amplitude ∝ T_i / T_hover (the
//!   imbalance force ∝ ω²), a seeded phase per motor and axis, scaled so that the four motors
//!   together give `vibration_accel` / `vibration_gyro` RMS per axis at hover.
//!
//! Then PX4's filter: the second-order Butterworth low-pass of `vehicle_acceleration`
//! (`IMU_ACCEL_CUTOFF`, default 30 Hz) and `vehicle_angular_velocity` (`IMU_GYRO_CUTOFF`,
//! default 40 Hz) at the raw rate ([`super::filter::LowPass2`]). The IMU sits at the centre of
//! mass (no lever arm). Every draw comes from the IMU's own seeded generator, so switching the
//! IMU's errors on or off changes no other random stream of a flight.

use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::filter::LowPass2x3;
use crate::config::{in_range, ConfigError};

/// IMU error model and PX4's IMU filter (defaults: the Gazebo IMU of PX4 SITL, PX4's default
/// cutoffs, a well-mounted flight controller's vibration).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImuParams {
    /// Accelerometer white-noise density [m/s²/√Hz].
    pub accel_noise_density: f64,
    /// Accelerometer bias random-walk density [m/s³/√Hz].
    pub accel_random_walk: f64,
    /// Accelerometer bias correlation time [s].
    pub accel_bias_correlation_time: f64,
    /// Standard deviation of the accelerometer's turn-on bias, per axis [m/s²].
    pub accel_turn_on_bias: f64,
    /// Gyro white-noise density [rad/s/√Hz].
    pub gyro_noise_density: f64,
    /// Gyro bias random-walk density [rad/s²/√Hz].
    pub gyro_random_walk: f64,
    /// Gyro bias correlation time [s].
    pub gyro_bias_correlation_time: f64,
    /// Standard deviation of the gyro's turn-on bias, per axis [rad/s].
    pub gyro_turn_on_bias: f64,
    /// Rotor vibration on the raw accelerometer at hover, RMS per body axis x, y, z [m/s²].
    pub vibration_accel: [f64; 3],
    /// Rotor vibration on the raw gyro at hover, RMS per body axis x, y, z [rad/s].
    pub vibration_gyro: [f64; 3],
    /// Rotor rotation frequency at hover thrust [Hz] (it scales with √thrust).
    pub rotor_hz: f64,
    /// Cutoff of PX4's accelerometer low-pass, `IMU_ACCEL_CUTOFF` [Hz] (0 = off).
    pub accel_cutoff: f64,
    /// Cutoff of PX4's gyro low-pass, `IMU_GYRO_CUTOFF` [Hz] (0 = off).
    pub gyro_cutoff: f64,
}

impl Default for ImuParams {
    fn default() -> Self {
        Self {
            accel_noise_density: 0.00186,
            accel_random_walk: 0.006,
            accel_bias_correlation_time: 300.0,
            accel_turn_on_bias: 0.196,
            gyro_noise_density: 0.000_186_65,
            gyro_random_walk: 3.8785e-5,
            gyro_bias_correlation_time: 1000.0,
            gyro_turn_on_bias: 0.0087,
            vibration_accel: [2.0, 2.0, 4.0],
            vibration_gyro: [0.05, 0.05, 0.02],
            rotor_hz: 230.0,
            accel_cutoff: 30.0,
            gyro_cutoff: 40.0,
        }
    }
}

impl ImuParams {
    /// An ideal IMU: no noise, bias or vibration (PX4's filter kept).
    pub fn ideal() -> Self {
        Self {
            accel_noise_density: 0.0,
            accel_random_walk: 0.0,
            accel_turn_on_bias: 0.0,
            gyro_noise_density: 0.0,
            gyro_random_walk: 0.0,
            gyro_turn_on_bias: 0.0,
            vibration_accel: [0.0; 3],
            vibration_gyro: [0.0; 3],
            ..Self::default()
        }
    }

    /// Check the settings; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        // Upper bounds far beyond any real IMU (a consumer MEMS part is ~1e-3 of each) keep
        // every error sample finite at any physics step.
        in_range("accel_noise_density", self.accel_noise_density, 0.0, 10.0)?;
        in_range("accel_random_walk", self.accel_random_walk, 0.0, 10.0)?;
        in_range(
            "accel_bias_correlation_time",
            self.accel_bias_correlation_time,
            1e-3,
            1e7,
        )?;
        in_range("accel_turn_on_bias", self.accel_turn_on_bias, 0.0, 100.0)?;
        in_range("gyro_noise_density", self.gyro_noise_density, 0.0, 10.0)?;
        in_range("gyro_random_walk", self.gyro_random_walk, 0.0, 10.0)?;
        in_range(
            "gyro_bias_correlation_time",
            self.gyro_bias_correlation_time,
            1e-3,
            1e7,
        )?;
        in_range("gyro_turn_on_bias", self.gyro_turn_on_bias, 0.0, 10.0)?;
        for (i, v) in self.vibration_accel.iter().enumerate() {
            in_range(&format!("vibration_accel[{i}]"), *v, 0.0, 300.0)?;
        }
        for (i, v) in self.vibration_gyro.iter().enumerate() {
            in_range(&format!("vibration_gyro[{i}]"), *v, 0.0, 30.0)?;
        }
        in_range("rotor_hz", self.rotor_hz, 1e-3, 1e5)?;
        in_range("accel_cutoff", self.accel_cutoff, 0.0, 1000.0)?;
        in_range("gyro_cutoff", self.gyro_cutoff, 0.0, 1000.0)?;
        Ok(())
    }
}

/// One IMU reading in body FRD.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ImuSample {
    /// Specific force (acceleration minus gravity) [m/s²]; about (0, 0, −g) at hover.
    pub accel: [f64; 3],
    /// Angular rate [rad/s].
    pub gyro: [f64; 3],
}

/// Bias state of one sensor: turn-on part plus a Gauss–Markov drift.
#[derive(Clone, Copy, Debug)]
struct Bias {
    on: Vector3<f64>,
    drift: Vector3<f64>,
    decay: f64,
    step_std: f64,
    white_std: f64,
}

impl Bias {
    fn new(rng: &mut ChaCha8Rng, turn_on: f64, walk: f64, tau: f64, density: f64, dt: f64) -> Self {
        let on = Vector3::from_fn(|_, _| {
            let z: f64 = StandardNormal.sample(rng);
            turn_on * z
        });
        let decay = (-dt / tau).exp();
        Self {
            on,
            drift: Vector3::zeros(),
            decay,
            step_std: walk * (0.5 * tau * (1.0 - decay * decay)).sqrt(),
            white_std: density / dt.sqrt(),
        }
    }

    /// Advance the drift by one sample; the bias plus this sample's white noise.
    fn error(&mut self, rng: &mut ChaCha8Rng) -> Vector3<f64> {
        let mut e = self.on;
        if self.step_std > 0.0 {
            for i in 0..3 {
                let z: f64 = StandardNormal.sample(rng);
                self.drift[i] = self.decay * self.drift[i] + self.step_std * z;
            }
        }
        e += self.drift;
        if self.white_std > 0.0 {
            for i in 0..3 {
                let z: f64 = StandardNormal.sample(rng);
                e[i] += self.white_std * z;
            }
        }
        e
    }
}

/// The simulated IMU (module docs): call [`Imu::sample`] once per raw sample.
#[derive(Clone, Debug)]
pub struct Imu {
    p: ImuParams,
    rng: ChaCha8Rng,
    dt: f64,
    accel_bias: Bias,
    gyro_bias: Bias,
    /// Rotation phase of each motor [rad].
    phase: [f64; 4],
    /// Phase offset of each motor's vibration on each axis, accelerometer then gyro [rad].
    offset: [[f64; 6]; 4],
    hover_thrust_each: f64,
    lp_accel: LowPass2x3,
    lp_gyro: LowPass2x3,
    raw: ImuSample,
    filtered: ImuSample,
}

impl Imu {
    /// An IMU sampled every `dt` [s] on a vehicle whose motors each give `hover_thrust_each`
    /// [N] at hover; its errors are drawn from `seed`. `params` must be valid.
    pub fn new(params: ImuParams, dt: f64, hover_thrust_each: f64, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x494d_5500);
        let p = params;
        let accel_bias = Bias::new(
            &mut rng,
            p.accel_turn_on_bias,
            p.accel_random_walk,
            p.accel_bias_correlation_time,
            p.accel_noise_density,
            dt,
        );
        let gyro_bias = Bias::new(
            &mut rng,
            p.gyro_turn_on_bias,
            p.gyro_random_walk,
            p.gyro_bias_correlation_time,
            p.gyro_noise_density,
            dt,
        );
        let tau = std::f64::consts::TAU;
        let phase = [0; 4].map(|_| rng.random_range(0.0..tau));
        let offset = [0; 4].map(|_| [0; 6].map(|_| rng.random_range(0.0..tau)));
        let fs = 1.0 / dt;
        Self {
            lp_accel: LowPass2x3::new(fs, p.accel_cutoff),
            lp_gyro: LowPass2x3::new(fs, p.gyro_cutoff),
            p,
            rng,
            dt,
            accel_bias,
            gyro_bias,
            phase,
            offset,
            hover_thrust_each: hover_thrust_each.max(1e-6),
            raw: ImuSample::default(),
            filtered: ImuSample::default(),
        }
    }

    /// Settle PX4's filters on a reading (the vehicle at rest before the first sample).
    pub fn settle(&mut self, truth: ImuSample) {
        self.lp_accel.reset(truth.accel);
        self.lp_gyro.reset(truth.gyro);
        self.raw = truth;
        self.filtered = truth;
    }

    /// The errors of one raw sample (bias, noise and vibration; body FRD) of a vehicle whose
    /// four motors give `thrust` [N]: advances the bias drift and the rotor phases.
    pub fn error_sample(&mut self, thrust: [f64; 4]) -> ImuSample {
        let mut a = self.accel_bias.error(&mut self.rng);
        let mut w = self.gyro_bias.error(&mut self.rng);
        let va = self.p.vibration_accel;
        let vg = self.p.vibration_gyro;
        if va.iter().chain(&vg).any(|v| *v > 0.0) {
            // Four motors of random phase add to √2 × each one's amplitude (RMS).
            let per_motor = std::f64::consts::FRAC_1_SQRT_2;
            for (i, t) in thrust.iter().enumerate() {
                // Bounded at 100× hover (no real rotor): a wild command keeps the sample finite.
                let r = t / self.hover_thrust_each;
                let ratio = if r.is_nan() { 0.0 } else { r.clamp(0.0, 100.0) };
                let f = self.p.rotor_hz * ratio.sqrt();
                self.phase[i] =
                    (self.phase[i] + std::f64::consts::TAU * f * self.dt) % std::f64::consts::TAU;
                let amp = ratio * per_motor;
                for k in 0..3 {
                    a[k] += va[k] * amp * (self.phase[i] + self.offset[i][k]).sin();
                    w[k] += vg[k] * amp * (self.phase[i] + self.offset[i][k + 3]).sin();
                }
            }
        }
        ImuSample {
            accel: a.into(),
            gyro: w.into(),
        }
    }

    /// One raw sample from the true specific force and rate (body FRD) and the four motor
    /// thrusts [N]; returns PX4's filtered reading.
    pub fn sample(&mut self, accel: [f64; 3], gyro: [f64; 3], thrust: [f64; 4]) -> ImuSample {
        let e = self.error_sample(thrust);
        self.raw = ImuSample {
            accel: [0, 1, 2].map(|k| accel[k] + e.accel[k]),
            gyro: [0, 1, 2].map(|k| gyro[k] + e.gyro[k]),
        };
        self.filtered = ImuSample {
            accel: self.lp_accel.apply(self.raw.accel),
            gyro: self.lp_gyro.apply(self.raw.gyro),
        };
        self.filtered
    }

    /// The last raw sample (before PX4's filter).
    pub fn raw(&self) -> ImuSample {
        self.raw
    }

    /// The last filtered sample (what `vehicle_acceleration` / `vehicle_angular_velocity`
    /// publish).
    pub fn filtered(&self) -> ImuSample {
        self.filtered
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rms(x: &[f64]) -> f64 {
        let m = x.iter().sum::<f64>() / x.len() as f64;
        (x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64).sqrt()
    }

    #[test]
    fn an_ideal_imu_reads_the_truth() {
        let mut imu = Imu::new(ImuParams::ideal(), 1e-3, 2.8, 1);
        let truth = ImuSample {
            accel: [0.3, -0.2, -9.8],
            gyro: [0.01, 0.02, 0.03],
        };
        imu.settle(truth);
        let s = imu.sample(truth.accel, truth.gyro, [2.8; 4]);
        for k in 0..3 {
            assert!((s.accel[k] - truth.accel[k]).abs() < 1e-12);
            assert!((s.gyro[k] - truth.gyro[k]).abs() < 1e-12);
        }
    }

    #[test]
    fn white_noise_follows_its_density() {
        let p = ImuParams {
            accel_noise_density: 0.004,
            accel_cutoff: 0.0,
            ..ImuParams::ideal()
        };
        let dt = 1e-3;
        let mut imu = Imu::new(p, dt, 2.8, 7);
        let x: Vec<f64> = (0..200_000)
            .map(|_| imu.sample([0.0; 3], [0.0; 3], [2.8; 4]).accel[0])
            .collect();
        let want = 0.004 / dt.sqrt();
        assert!((rms(&x) / want - 1.0).abs() < 0.01, "{} vs {want}", rms(&x));
    }

    #[test]
    fn vibration_has_its_rms_at_hover_and_px4_filter_removes_most_of_it() {
        let p = ImuParams {
            vibration_accel: [2.0, 0.0, 0.0],
            accel_cutoff: 0.0,
            ..ImuParams::ideal()
        };
        let mut raw = Imu::new(p.clone(), 1e-3, 2.8, 3);
        let x: Vec<f64> = (0..100_000)
            .map(|_| raw.sample([0.0; 3], [0.0; 3], [2.8; 4]).accel[0])
            .collect();
        // Four incommensurate phases: the RMS is 2 up to the beat of equal frequencies.
        assert!((rms(&x) - 2.0).abs() < 0.5, "{}", rms(&x));
        let mut filt = Imu::new(
            ImuParams {
                accel_cutoff: 30.0,
                ..p
            },
            1e-3,
            2.8,
            3,
        );
        let y: Vec<f64> = (0..100_000)
            .map(|_| filt.sample([0.0; 3], [0.0; 3], [2.8; 4]).accel[0])
            .collect();
        // |H(230 Hz)| of the 30 Hz Butterworth at 1 kHz ≈ 0.016.
        let ratio = rms(&y[1000..]) / rms(&x[1000..]);
        assert!((0.010..0.022).contains(&ratio), "{ratio}");
    }

    #[test]
    fn the_same_seed_gives_the_same_errors_and_another_does_not() {
        let p = ImuParams::default();
        let run = |seed| {
            let mut imu = Imu::new(p.clone(), 1e-3, 2.8, seed);
            (0..50)
                .map(|_| imu.sample([0.0, 0.0, -9.8], [0.0; 3], [2.8; 4]).accel[1])
                .collect::<Vec<_>>()
        };
        assert_eq!(run(5), run(5));
        assert_ne!(run(5), run(6));
    }

    #[test]
    fn bad_settings_name_the_field() {
        let p = ImuParams {
            rotor_hz: 0.0,
            ..ImuParams::default()
        };
        assert_eq!(p.validate().unwrap_err().field, "rotor_hz");
        let p = ImuParams {
            vibration_accel: [1.0, f64::NAN, 0.0],
            ..ImuParams::default()
        };
        assert_eq!(p.validate().unwrap_err().field, "vibration_accel[1]");
    }
}
