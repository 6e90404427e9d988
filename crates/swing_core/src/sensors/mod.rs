//! The vehicle's sensors as the flight software sees them, and the swing measured from them.
//!
//! - [`imu`]: the accelerometer and gyro (noise, bias, rotor vibration, PX4's low-pass);
//! - [`cable`]: a cable-angle sensor fixed to the airframe (potentiometers on ADC channels,
//!   a calibration polynomial per channel) and the composition of body angles with the
//!   attitude into world-frame swing angles;
//! - [`swing`]: the swing sources of a flight and the swing estimated from the IMU alone;
//! - [`pendulum`]: the IMU's swing told apart from drag by the pendulum's dynamics;
//! - [`filter`]: PX4's second-order Butterworth low-pass.

pub mod cable;
pub mod filter;
pub mod imu;
pub mod pendulum;
pub mod swing;

pub use cable::{body_angles, compose, BodySensorParams};
pub use filter::{LowPass2, LowPass2x3};
pub use imu::{Imu, ImuParams, ImuSample};
pub use pendulum::PendulumObserver;
pub use swing::{ImuSwingEstimator, ImuSwingSettings, SwingFilter, SwingSource};

use serde::{Deserialize, Serialize};

use crate::config::ConfigError;

/// A flight's sensors: which one measures the swing, the IMU, and the body-fixed cable
/// sensor (scenario section `[sensors]`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorParams {
    /// The flight's swing source: `sensor` (world-frame swing sensor), `body` (cable sensor on
    /// the airframe, composed with the attitude) or `imu` (no sensor on the cable).
    pub swing: SwingSource,
    /// The IMU (always on board; the swing estimate reads it with `swing = "imu"`).
    pub imu: ImuParams,
    /// The cable-angle sensor on the airframe (used with `swing = "body"`).
    pub body: BodySensorParams,
    /// The swing estimate from the IMU (logged as `swing_est_*` in every flight; flown on
    /// with `swing = "imu"`).
    pub estimator: ImuSwingSettings,
}

impl SensorParams {
    /// Check the settings; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.imu.validate().map_err(|e| e.within("imu"))?;
        self.body.validate().map_err(|e| e.within("body"))?;
        self.estimator
            .validate()
            .map_err(|e| e.within("estimator"))?;
        Ok(())
    }
}
