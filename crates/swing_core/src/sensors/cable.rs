//! A cable-angle sensor fixed to the airframe (thesis 6.1.2): a two-axis joystick whose two
//! potentiometers are read as ADC channels of the flight controller, one calibration
//! polynomial per channel, composed with the vehicle's attitude into the world-frame swing.
//!
//! Body angles: with the cable's unit vector n_b in body FRD (vehicle → payload),
//! β_x = atan2(n_bx, n_bz) is the cable angle in the body x–z plane (positive towards the
//! nose) and β_y = atan2(n_by, n_bz) in the body y–z plane (positive towards the right).
//!
//! The simulated sensor: each potentiometer reads counts = clamp(round(c₀ + g·(β + e)),
//! 0, 2^bits − 1) with e the scenario's swing-sensor noise; the flight software maps counts
//! back to an angle with the user's bench calibration, β̂ = Σ_k p_k·counts^k (default: the
//! exact inverse of c₀, g, the thesis's best-fit straight line).
//!
//! World angles ([`compose`]): r_b = (tan β_x, tan β_y, 1), r = R(q) r_b (NED), then
//! swing_n = atan2(r_N, r_D), swing_e = atan2(r_E, r_D) — the same projected angles the
//! simulator's world-frame swing uses ([`crate::plant::dynamics::swing_angles`]).

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::config::{finite, in_range, positive, ConfigError};

/// The body-fixed cable-angle sensor: its ADC and the user's calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BodySensorParams {
    /// ADC resolution [bits].
    pub adc_bits: u32,
    /// ADC reading at zero cable angle, body x then y [counts].
    pub zero: [f64; 2],
    /// ADC counts per radian of cable angle, body x then y [counts/rad].
    pub gain: [f64; 2],
    /// `adc_report` channel ids of the x and y potentiometers.
    pub channels: [i32; 2],
    /// Calibration of the x channel: angle [rad] = Σ_k c_k·counts^k (empty: the exact
    /// inverse of `zero` and `gain`).
    pub calibration_x: Vec<f64>,
    /// Calibration of the y channel [rad per counts^k] (empty: the exact inverse).
    pub calibration_y: Vec<f64>,
}

impl Default for BodySensorParams {
    fn default() -> Self {
        Self {
            adc_bits: 12,
            zero: [2048.0, 2048.0],
            // A joystick sweeping ±45° over most of the 12-bit range.
            gain: [2400.0, 2400.0],
            channels: [10, 11],
            calibration_x: Vec::new(),
            calibration_y: Vec::new(),
        }
    }
}

impl BodySensorParams {
    /// Check the settings; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(8..=24).contains(&self.adc_bits) {
            return Err(ConfigError::new(
                "adc_bits",
                format!("must be 8..=24 (got {})", self.adc_bits),
            ));
        }
        let full = self.full_scale();
        for i in 0..2 {
            in_range(&format!("zero[{i}]"), self.zero[i], 0.0, full)?;
            positive(&format!("gain[{i}]"), self.gain[i].abs())?;
        }
        if self.channels[0] == self.channels[1] {
            return Err(ConfigError::new(
                "channels",
                "the x and y potentiometers need two different ADC channels",
            ));
        }
        for (name, c) in [
            ("calibration_x", &self.calibration_x),
            ("calibration_y", &self.calibration_y),
        ] {
            if c.len() > 8 {
                return Err(ConfigError::new(name, "at most 8 coefficients (degree 7)"));
            }
            for (k, v) in c.iter().enumerate() {
                finite(&format!("{name}[{k}]"), *v)?;
            }
        }
        Ok(())
    }

    /// Largest ADC reading [counts].
    pub fn full_scale(&self) -> f64 {
        (1u64 << self.adc_bits) as f64 - 1.0
    }

    /// The ADC reading of body angle `beta` [rad] on axis `i` (0 = x, 1 = y), quantised and
    /// clipped to the converter's range.
    pub fn counts(&self, i: usize, beta: f64) -> f64 {
        (self.zero[i] + self.gain[i] * beta)
            .round()
            .clamp(0.0, self.full_scale())
    }

    /// The calibration polynomial of axis `i` as coefficients of counts^k (the exact inverse
    /// of `zero` and `gain` when none is given).
    pub fn calibration(&self, i: usize) -> Vec<f64> {
        let given = if i == 0 {
            &self.calibration_x
        } else {
            &self.calibration_y
        };
        if given.is_empty() {
            vec![-self.zero[i] / self.gain[i], 1.0 / self.gain[i]]
        } else {
            given.clone()
        }
    }

    /// The body angle [rad] of ADC reading `counts` on axis `i` through its calibration.
    pub fn angle(&self, i: usize, counts: f64) -> f64 {
        let given = if i == 0 {
            &self.calibration_x
        } else {
            &self.calibration_y
        };
        if given.is_empty() {
            (counts - self.zero[i]) / self.gain[i]
        } else {
            polynomial(given, counts)
        }
    }

    /// The world-frame swing (swing_n, swing_e) [rad] of the readings `counts` (x, y) under
    /// attitude `rot` (body → NED): each channel through its calibration, then [`compose`].
    pub fn world_swing(&self, rot: &Matrix3<f64>, counts: [f64; 2]) -> [f64; 2] {
        compose(rot, [self.angle(0, counts[0]), self.angle(1, counts[1])])
    }
}

/// Evaluate Σ_k c_k·x^k (Horner).
#[inline]
pub fn polynomial(c: &[f64], x: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, ck| acc * x + ck)
}

/// The cable's body angles (β_x, β_y) [rad] of a world-frame cable direction `n` (NED,
/// vehicle → payload) seen from attitude `rot` (body → NED).
pub fn body_angles(rot: &Matrix3<f64>, n: &Vector3<f64>) -> [f64; 2] {
    let nb = rot.transpose() * n;
    [nb.x.atan2(nb.z), nb.y.atan2(nb.z)]
}

/// World-frame projected swing angles (swing_n, swing_e) [rad] of body angles (β_x, β_y)
/// under attitude `rot` (body → NED); see the module docs.
#[inline]
pub fn compose(rot: &Matrix3<f64>, beta: [f64; 2]) -> [f64; 2] {
    compose_tangents(rot, [beta[0].tan(), beta[1].tan()])
}

/// [`compose`] from the tangents (tan β_x, tan β_y) of the body angles.
#[inline]
pub fn compose_tangents(rot: &Matrix3<f64>, tangent: [f64; 2]) -> [f64; 2] {
    let r = rot * Vector3::new(tangent[0], tangent[1], 1.0);
    [r.x.atan2(r.z), r.y.atan2(r.z)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::dynamics::{rotation, swing_angles, unit_from_swing};
    use nalgebra::{Quaternion, UnitQuaternion};

    #[test]
    fn compose_inverts_body_angles_at_any_attitude() {
        for (roll, pitch, yaw) in [(0.0, 0.0, 0.0), (0.3, -0.2, 1.0), (-0.5, 0.4, -2.5)] {
            let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
            let rot = rotation(q.quaternion());
            for (sn, se) in [(0.0, 0.0), (0.2, -0.1), (-0.6, 0.5)] {
                let n = unit_from_swing(sn, se);
                let beta = body_angles(&rot, &n);
                let back = compose(&rot, beta);
                let want = swing_angles(&n, &Vector3::zeros());
                assert!((back[0] - want[0]).abs() < 1e-12, "{back:?} {want:?}");
                assert!((back[1] - want[1]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn a_level_vehicle_reads_the_world_angles_and_a_pitched_one_the_difference() {
        let level = rotation(&Quaternion::new(1.0, 0.0, 0.0, 0.0));
        let n = unit_from_swing(0.2, 0.0);
        let b = body_angles(&level, &n);
        assert!((b[0] - 0.2).abs() < 1e-12 && b[1].abs() < 1e-12);
        // Nose up by 0.05 rad: the cable leans 0.05 rad less towards the nose.
        let q = UnitQuaternion::from_euler_angles(0.0, 0.05, 0.0);
        let b = body_angles(&rotation(q.quaternion()), &n);
        assert!((b[0] - 0.15).abs() < 1e-12, "{b:?}");
        // Right wing down by 0.1 rad: a cable hanging straight down leans right in the body.
        let q = UnitQuaternion::from_euler_angles(0.1, 0.0, 0.0);
        let b = body_angles(&rotation(q.quaternion()), &unit_from_swing(0.0, 0.0));
        assert!((b[1] - 0.1).abs() < 1e-12, "{b:?}");
    }

    #[test]
    fn counts_round_clip_and_the_default_calibration_inverts_them() {
        let p = BodySensorParams::default();
        let c = p.counts(0, 0.1);
        assert_eq!(c, 2288.0);
        let back = polynomial(&p.calibration(0), c);
        assert!((back - 0.1).abs() < 0.5 / 2400.0);
        // One rule, with or without a given polynomial: the same angle.
        assert!((p.angle(0, c) - back).abs() < 1e-15);
        let cubic = BodySensorParams {
            calibration_y: vec![-0.9, 4e-4, 1e-9, -2e-13],
            ..Default::default()
        };
        let want = -0.9 + 4e-4 * c + 1e-9 * c * c - 2e-13 * c * c * c;
        assert!((cubic.angle(1, c) - want).abs() < 1e-12);
        let level =
            crate::plant::dynamics::rotation(&nalgebra::Quaternion::new(1.0, 0.0, 0.0, 0.0));
        let w = cubic.world_swing(&level, [c, c]);
        assert!(
            (w[0] - back).abs() < 1e-12 && (w[1] - want).abs() < 1e-12,
            "{w:?}"
        );
        assert_eq!(p.counts(1, 10.0), 4095.0);
        assert_eq!(p.counts(1, -10.0), 0.0);
    }

    #[test]
    fn bad_settings_name_the_field() {
        let p = BodySensorParams {
            channels: [3, 3],
            ..Default::default()
        };
        assert_eq!(p.validate().unwrap_err().field, "channels");
        let p = BodySensorParams {
            calibration_y: vec![0.0, f64::INFINITY],
            ..Default::default()
        };
        assert_eq!(p.validate().unwrap_err().field, "calibration_y[1]");
        let p = BodySensorParams {
            zero: [5000.0, 0.0],
            ..Default::default()
        };
        assert_eq!(p.validate().unwrap_err().field, "zero[0]");
    }
}
