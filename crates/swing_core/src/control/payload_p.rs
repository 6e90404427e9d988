//! Payload feedback on the velocity setpoint: the law of ArduPilot's slung-payload script
//! (`libraries/AP_Scripting/applets/copter-slung-payload.lua`, ArduPilot Copter 4.6).
//!
//! The script adds a velocity offset to the position controller's setpoint each update:
//! ```text
//!   v_off = −K_v a_p + K_wp (−p_off − o_rest),     p_off = ∫ v_off dt
//! ```
//! with a_p the payload's horizontal acceleration, p_off the position the offsets have
//! moved the vehicle by (pulled back to the waypoint), o_rest the payload's resting offset
//! from the vehicle (its horizontal offset low-passed with time constant T_rest, used only
//! while the low-passed payload velocity is below 1 m/s: wind and sensor bias, not swing),
//! K_v = SLUP_VEL_P = 0.5 s, K_wp = SLUP_WP_POS_P = 0.05 /s, T_rest = SLUP_RESTOFS_TC = 10 s
//! (its first-order filter has α = dt/(dt + T_rest/2π)). The script measures the payload
//! with a GPS on the payload; here the swing sensor and the cable length give the same
//! quantities for a taut cable: offset l sin θ, payload velocity v + l θ̇ cos θ and
//! acceleration −g tan θ (the cable's pull when its tension carries the payload's weight).

use super::{AxisState, ControlError, ControlOutput, SwingController, TickInfo};
use crate::config::{non_negative, positive, ConfigError};
use crate::plant::GRAVITY;
use serde::{Deserialize, Serialize};

/// Settings of the payload feedback (defaults: the script's parameter defaults).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PayloadPSettings {
    /// Velocity gain on the payload's acceleration (SLUP_VEL_P) [s].
    pub vel_p: f64,
    /// Gain pulling the vehicle back by the offsets' accumulated position and the resting
    /// offset (SLUP_WP_POS_P) [1/s].
    pub wp_pos_p: f64,
    /// Time constant of the resting-offset filter (SLUP_RESTOFS_TC) [s].
    pub rest_offset_tc: f64,
    /// Payload speed below which the resting offset is used (the script's
    /// PAYLOAD_OFFSET_COMP_VEL_MAX) [m/s].
    pub rest_speed_max: f64,
    /// Tick period [s] (the script runs at 100 Hz; PX4's velocity loop at 50 Hz).
    pub period: f64,
}

impl Default for PayloadPSettings {
    fn default() -> Self {
        Self {
            vel_p: 0.5,
            wp_pos_p: 0.05,
            rest_offset_tc: 10.0,
            rest_speed_max: 1.0,
            period: 0.02,
        }
    }
}

impl PayloadPSettings {
    /// Check gains and times.
    pub fn validate(&self) -> Result<(), ConfigError> {
        non_negative("vel_p", self.vel_p)?;
        non_negative("wp_pos_p", self.wp_pos_p)?;
        positive("rest_offset_tc", self.rest_offset_tc)?;
        positive("rest_speed_max", self.rest_speed_max)?;
        positive("period", self.period)?;
        Ok(())
    }
}

/// The payload feedback controller (module docs); a velocity-output [`SwingController`].
#[derive(Clone, Debug)]
pub struct PayloadP {
    s: PayloadPSettings,
    axes: usize,
    length: f64,
    alpha: f64,
    /// Per axis: accumulated position offset [m], resting offset [m], resting payload
    /// velocity [m/s].
    pos_off: [f64; 2],
    rest_off: [f64; 2],
    rest_vel: [f64; 2],
}

impl PayloadP {
    /// The controller for a cable of `length` [m] on `axes` axes.
    pub fn new(length: f64, axes: usize, settings: PayloadPSettings) -> Result<Self, ControlError> {
        settings.validate()?;
        positive("length", length)?;
        if !(1..=2).contains(&axes) {
            return Err(ConfigError::new("axes", "must be 1 (N) or 2 (N+E)").into());
        }
        let rc = settings.rest_offset_tc / (2.0 * std::f64::consts::PI);
        Ok(Self {
            alpha: settings.period / (settings.period + rc),
            s: settings,
            axes,
            length,
            pos_off: [0.0; 2],
            rest_off: [0.0; 2],
            rest_vel: [0.0; 2],
        })
    }
}

impl SwingController for PayloadP {
    fn axes(&self) -> usize {
        self.axes
    }

    fn period(&self) -> f64 {
        self.s.period
    }

    fn output(&self) -> ControlOutput {
        ControlOutput::Velocity
    }

    fn reset(&mut self, state: &[AxisState], _acc: &[f64]) {
        for a in 0..self.axes {
            let s = state.get(a).copied().unwrap_or_default();
            self.pos_off[a] = 0.0;
            self.rest_off[a] = if s.swing.is_finite() {
                self.length * s.swing.sin()
            } else {
                0.0
            };
            self.rest_vel[a] = if s.v.is_finite() { s.v } else { 0.0 };
        }
    }

    fn step(
        &mut self,
        state: &[AxisState],
        vel_ref: &[f64],
        out: &mut [f64],
    ) -> Result<TickInfo, ControlError> {
        crate::control::check_tick_inputs(self.axes, state, vel_ref, out)?;
        let l = self.length;
        let dt = self.s.period;
        let speed2: f64 = (0..self.axes)
            .map(|a| {
                let s = state[a];
                let vp = s.v + l * s.swing_rate * s.swing.cos();
                self.rest_vel[a] += (vp - self.rest_vel[a]) * self.alpha;
                self.rest_off[a] += (l * s.swing.sin() - self.rest_off[a]) * self.alpha;
                self.rest_vel[a] * self.rest_vel[a]
            })
            .sum();
        let rest_valid = speed2.sqrt() <= self.s.rest_speed_max;
        for a in 0..self.axes {
            let acc_p = -GRAVITY * state[a].swing.tan();
            let rest = if rest_valid { self.rest_off[a] } else { 0.0 };
            let v_off = -self.s.vel_p * acc_p + self.s.wp_pos_p * (-self.pos_off[a] - rest);
            self.pos_off[a] += v_off * dt;
            out[a] = vel_ref[a] + v_off;
        }
        Ok(TickInfo::default())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moves_towards_the_payload_and_back_to_the_reference() {
        let mut c = PayloadP::new(1.0, 1, PayloadPSettings::default()).unwrap();
        let swing = 0.1;
        let st = [AxisState {
            v: 0.0,
            swing,
            swing_rate: 0.0,
        }];
        c.reset(&[AxisState::default()], &[0.0]);
        let mut out = [0.0];
        c.step(&st, &[0.0], &mut out).unwrap();
        // Payload North of the vehicle: its acceleration points South, the vehicle goes North.
        let want = 0.5 * GRAVITY * swing.tan();
        assert!((out[0] - want).abs() < 0.01 * want, "{} vs {want}", out[0]);
        // Hanging still, the accumulated offset is pulled back: the setpoint returns.
        let still = [AxisState::default()];
        for _ in 0..3000 {
            c.step(&still, &[1.5], &mut out).unwrap();
        }
        assert!((out[0] - 1.5).abs() < 1e-3, "{}", out[0]);
        assert!(PayloadP::new(-1.0, 1, PayloadPSettings::default()).is_err());
    }
}
