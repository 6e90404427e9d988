//! PX4's multicopter cascade (thesis 5.2, appendix A = PX4 defaults).
//!
//! Position P → velocity PID → acceleration setpoint → thrust vector and attitude setpoint
//! (PX4 `PositionControl::_velocityControl`, `_accelerationControl`, `ControlMath::limitTilt`
//! and `bodyzToAttitude`) → quaternion attitude P with yaw de-prioritised (PX4
//! `AttitudeControl::update`, eq. 5.1–5.2) → rate PID with D on the filtered measurement,
//! integrator limit and large-error integrator attenuation (PX4 `RateControl`) → X-quad mixer
//! (PX4's quad-X table, eq. 3.19) → PWM → thrust (eq. 6.1).
//!
//! Per axis the outer setpoint can be a position, a velocity or an acceleration; the
//! acceleration input is what identification and the MPC use. Horizontal acceleration
//! is turned into tilt with the vertical channel decoupled (PX4 `MPC_ACC_DECOUPLE`):
//! body z = normalize(−a_N, −a_E, g), tilt-limited, collective thrust scaled by the hover
//! thrust.

use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3, Vector4};
use serde::{Deserialize, Serialize};

use crate::config::{in_range, non_negative, positive, ConfigError};
use crate::control::hover_thrust::HoverThrustEstimator;
use crate::plant::dynamics::rotation;
use crate::plant::params::{VehicleParams, GRAVITY};

/// Gains, limits and loop rates of the PX4 cascade (defaults: appendix A / PX4 defaults).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Px4Params {
    /// Rate P gains roll, pitch, yaw (MC_*RATE_P) [normalised torque/(rad/s)].
    pub rate_p: [f64; 3],
    /// Rate I gains (MC_*RATE_I) [normalised torque/rad].
    pub rate_i: [f64; 3],
    /// Rate D gains (MC_*RATE_D) [normalised torque/(rad/s²)].
    pub rate_d: [f64; 3],
    /// Rate integrator limits (MC_*R_INT_LIM) [normalised torque].
    pub rate_int_limit: [f64; 3],
    /// Maximum body rates roll, pitch, yaw (MC_*RATE_MAX) [rad/s].
    pub rate_max: [f64; 3],
    /// Cut-off of the low-pass filter on the D-term angular acceleration (IMU_DGYRO_CUTOFF) [Hz].
    pub dgyro_cutoff: f64,
    /// Attitude P gains roll, pitch, yaw (MC_*_P) [1/s].
    pub att_p: [f64; 3],
    /// Velocity P gains N, E, D (MPC_XY_VEL_P_ACC, MPC_Z_VEL_P_ACC) [1/s].
    pub vel_p: [f64; 3],
    /// Velocity I gains N, E, D [1/s²].
    pub vel_i: [f64; 3],
    /// Velocity D gains N, E, D [-].
    pub vel_d: [f64; 3],
    /// Cut-off of the velocity-derivative low-pass filter (MPC_VELD_LP) [Hz].
    pub veld_cutoff: f64,
    /// Position P gains N, E, D (MPC_XY_P, MPC_Z_P) [1/s].
    pub pos_p: [f64; 3],
    /// Maximum horizontal velocity setpoint (MPC_XY_VEL_MAX) [m/s].
    pub vel_max_xy: f64,
    /// Maximum climb rate (MPC_Z_VEL_MAX_UP) [m/s].
    pub vel_max_up: f64,
    /// Maximum descent rate (MPC_Z_VEL_MAX_DN) [m/s].
    pub vel_max_down: f64,
    /// Maximum tilt (MPC_TILTMAX_AIR) [rad].
    pub tilt_max: f64,
    /// Minimum collective thrust (MPC_THR_MIN) [normalised].
    pub thrust_min: f64,
    /// Maximum collective thrust (MPC_THR_MAX) [normalised].
    pub thrust_max: f64,
    /// Horizontal thrust margin kept when vertical thrust saturates (MPC_THR_XY_MARG) [normalised].
    pub thrust_xy_margin: f64,
    /// Hover thrust (MPC_THR_HOVER) [normalised]; `None` = as PX4's hover-thrust estimator
    /// would converge to for the simulated vehicle and payload. In files, absent or 0 means
    /// `None` (and `None` is written as 0).
    #[serde(deserialize_with = "zero_is_none", serialize_with = "none_is_zero")]
    pub hover_thrust: Option<f64>,
    /// Estimate the hover thrust in flight and adopt it (MPC_USE_HTE; PX4's default on):
    /// [`crate::control::hover_thrust::HoverThrustEstimator`].
    pub hover_thrust_estimator: bool,
    /// Rate-loop frequency [Hz] (must divide the physics rate).
    pub rate_loop_hz: f64,
    /// Attitude-loop frequency [Hz].
    pub att_loop_hz: f64,
    /// Position/velocity-loop frequency [Hz].
    pub pos_loop_hz: f64,
}

impl Default for Px4Params {
    fn default() -> Self {
        let deg = std::f64::consts::PI / 180.0;
        Self {
            rate_p: [0.15, 0.15, 0.2],
            rate_i: [0.2, 0.2, 0.1],
            rate_d: [0.003, 0.003, 0.0],
            rate_int_limit: [0.3, 0.3, 0.3],
            rate_max: [220.0 * deg, 220.0 * deg, 200.0 * deg],
            dgyro_cutoff: 30.0,
            att_p: [6.5, 6.5, 2.8],
            vel_p: [1.8, 1.8, 4.0],
            vel_i: [0.4, 0.4, 2.0],
            vel_d: [0.2, 0.2, 0.0],
            veld_cutoff: 5.0,
            pos_p: [0.95, 0.95, 1.0],
            vel_max_xy: 12.0,
            vel_max_up: 3.0,
            vel_max_down: 1.0,
            tilt_max: 45.0 * deg,
            thrust_min: 0.12,
            thrust_max: 1.0,
            thrust_xy_margin: 0.3,
            hover_thrust: None,
            hover_thrust_estimator: true,
            rate_loop_hz: 500.0,
            att_loop_hz: 250.0,
            pos_loop_hz: 50.0,
        }
    }
}

/// Read an optional number where 0 (the file format's "estimate") also means `None`.
fn zero_is_none<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.filter(|x| *x != 0.0))
}

/// Write `None` as 0, the file format's "estimate".
fn none_is_zero<S: serde::Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_f64(v.unwrap_or(0.0))
}

impl Px4Params {
    /// Check gains and limits; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (name, arr) in [
            ("rate_p", &self.rate_p),
            ("rate_i", &self.rate_i),
            ("rate_d", &self.rate_d),
            ("rate_int_limit", &self.rate_int_limit),
            ("att_p", &self.att_p),
            ("vel_p", &self.vel_p),
            ("vel_i", &self.vel_i),
            ("vel_d", &self.vel_d),
            ("pos_p", &self.pos_p),
        ] {
            for (i, v) in arr.iter().enumerate() {
                non_negative(&format!("{name}[{i}]"), *v)?;
            }
        }
        for (i, v) in self.rate_max.iter().enumerate() {
            positive(&format!("rate_max[{i}]"), *v)?;
        }
        positive("vel_p[0]", self.vel_p[0])?;
        positive("dgyro_cutoff", self.dgyro_cutoff)?;
        positive("veld_cutoff", self.veld_cutoff)?;
        positive("vel_max_xy", self.vel_max_xy)?;
        positive("vel_max_up", self.vel_max_up)?;
        positive("vel_max_down", self.vel_max_down)?;
        in_range("tilt_max", self.tilt_max, 0.01, 1.5)?;
        in_range("thrust_min", self.thrust_min, 0.0, 0.9)?;
        in_range("thrust_max", self.thrust_max, self.thrust_min + 0.05, 1.0)?;
        in_range("thrust_xy_margin", self.thrust_xy_margin, 0.0, 1.0)?;
        if let Some(h) = self.hover_thrust {
            in_range("hover_thrust", h, 0.0, 0.95)?;
        }
        positive("rate_loop_hz", self.rate_loop_hz)?;
        positive("att_loop_hz", self.att_loop_hz)?;
        positive("pos_loop_hz", self.pos_loop_hz)?;
        Ok(())
    }
}

/// Setpoint of one translational axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AxisSetpoint {
    /// Hold a position [m].
    Position(f64),
    /// Track a velocity [m/s].
    Velocity(f64),
    /// Command an acceleration directly [m/s²] (velocity PID bypassed on this axis).
    Acceleration(f64),
    /// Follow a trajectory: position [m] with velocity [m/s] and acceleration [m/s²]
    /// feed-forward (PX4's auto modes: v_sp = v + P (p − p̂), a_sp = a + PID(v_sp − v̂)).
    Trajectory {
        /// Position [m].
        p: f64,
        /// Velocity feed-forward [m/s].
        v: f64,
        /// Acceleration feed-forward [m/s²].
        a: f64,
    },
}

impl AxisSetpoint {
    /// Short name of the mode (`pos`, `vel`, `acc`).
    pub fn mode(&self) -> &'static str {
        match self {
            AxisSetpoint::Position(_) => "pos",
            AxisSetpoint::Velocity(_) => "vel",
            AxisSetpoint::Acceleration(_) => "acc",
            AxisSetpoint::Trajectory { .. } => "traj",
        }
    }
}

/// Translational setpoint for North, East and Down plus the yaw setpoint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoint {
    /// North, East, Down axis setpoints.
    pub axes: [AxisSetpoint; 3],
    /// Yaw setpoint [rad].
    pub yaw: f64,
}

impl Setpoint {
    /// Hold the given NED position with yaw 0.
    pub fn hold(pos: Vector3<f64>) -> Self {
        Self {
            axes: [
                AxisSetpoint::Position(pos.x),
                AxisSetpoint::Position(pos.y),
                AxisSetpoint::Position(pos.z),
            ],
            yaw: 0.0,
        }
    }
}

/// State of the cascade between ticks (integrators, filters, latest setpoints).
#[derive(Clone, Debug)]
pub struct Px4Cascade {
    p: Px4Params,
    hover_thrust: f64,
    hte: Option<HoverThrustEstimator>,
    thrust_at_hover: f64,
    vel_int: Vector3<f64>,
    vel_prev: Option<Vector3<f64>>,
    vel_dot: Vector3<f64>,
    /// Velocity setpoint of the last position/velocity tick (NaN on acceleration axes) [m/s].
    pub vel_sp: Vector3<f64>,
    /// Acceleration setpoint of the last tick, NED [m/s²].
    pub acc_sp: Vector3<f64>,
    /// Thrust vector setpoint, NED [normalised].
    pub thr_sp: Vector3<f64>,
    /// Attitude setpoint (body → NED).
    pub q_sp: UnitQuaternion<f64>,
    /// Body-rate setpoint [rad/s].
    pub rate_sp: Vector3<f64>,
    rate_int: Vector3<f64>,
    rate_prev: Option<Vector3<f64>>,
    ang_acc: Vector3<f64>,
    /// Normalised torque setpoint [-1, 1].
    pub torque_sp: Vector3<f64>,
    /// Normalised motor commands [0, 1].
    pub motor_cmd: Vector4<f64>,
}

/// PX4's quad-X mixer table: (roll, pitch, yaw) scale of motors 1–4.
const QUAD_X: [[f64; 3]; 4] = [
    [
        -std::f64::consts::FRAC_1_SQRT_2,
        std::f64::consts::FRAC_1_SQRT_2,
        1.0,
    ],
    [
        std::f64::consts::FRAC_1_SQRT_2,
        -std::f64::consts::FRAC_1_SQRT_2,
        1.0,
    ],
    [
        std::f64::consts::FRAC_1_SQRT_2,
        std::f64::consts::FRAC_1_SQRT_2,
        -1.0,
    ],
    [
        -std::f64::consts::FRAC_1_SQRT_2,
        -std::f64::consts::FRAC_1_SQRT_2,
        -1.0,
    ],
];

impl Px4Cascade {
    /// A cascade at rest; `hover_thrust` is the normalised collective thrust that holds the
    /// weight PX4 believes it carries.
    pub fn new(p: Px4Params, hover_thrust: f64) -> Self {
        let hte = p
            .hover_thrust_estimator
            .then(|| HoverThrustEstimator::new(hover_thrust));
        Self {
            p,
            hover_thrust,
            hte,
            thrust_at_hover: hover_thrust,
            vel_int: Vector3::zeros(),
            vel_prev: None,
            vel_dot: Vector3::zeros(),
            vel_sp: Vector3::zeros(),
            acc_sp: Vector3::zeros(),
            thr_sp: Vector3::new(0.0, 0.0, -hover_thrust),
            q_sp: UnitQuaternion::identity(),
            rate_sp: Vector3::zeros(),
            rate_int: Vector3::zeros(),
            rate_prev: None,
            ang_acc: Vector3::zeros(),
            torque_sp: Vector3::zeros(),
            motor_cmd: Vector4::repeat(hover_thrust),
        }
    }

    /// Normalised hover thrust for `mass` [kg] carried by `vehicle`'s four motors.
    pub fn hover_thrust_for(vehicle: &VehicleParams, mass: f64) -> f64 {
        vehicle.command_for_thrust(mass * GRAVITY / 4.0)
    }

    /// Total mass [kg] `vehicle`'s four motors hold at the normalised `hover` thrust: the
    /// inverse of [`Self::hover_thrust_for`] (PX4's `MPC_THR_HOVER` read as a mass).
    pub fn mass_hovering_at(vehicle: &VehicleParams, hover: f64) -> f64 {
        4.0 * vehicle.thrust_at(hover) / GRAVITY
    }

    /// Gains and limits in use.
    pub fn params(&self) -> &Px4Params {
        &self.p
    }

    /// The hover thrust the cascade believes in [normalised].
    pub fn hover_thrust(&self) -> f64 {
        self.hover_thrust
    }

    /// Preset the vertical velocity integrator so that the collective thrust equals
    /// `thrust` [normalised] at zero error (start in trimmed hover, no transient).
    pub fn trim_collective(&mut self, thrust: f64) {
        self.vel_int.z =
            ((self.hover_thrust - thrust) * GRAVITY / self.hover_thrust).clamp(-GRAVITY, GRAVITY);
        self.thrust_at_hover = thrust;
        self.motor_cmd = Vector4::repeat(thrust);
        self.thr_sp = Vector3::new(0.0, 0.0, -thrust);
    }

    /// Replace the hover thrust by `hover` [normalised] without a jump in thrust: the vertical
    /// integrator takes up the difference (PX4 `PositionControl::updateHoverThrust`).
    /// `acc_bias_z` is the vertical acceleration offset the last thrust was made with (see
    /// [`Self::position_velocity`]): the thrust follows the setpoint plus it.
    pub fn adopt_hover_thrust(&mut self, hover: f64, acc_bias_z: f64) {
        if hover > f64::EPSILON && hover != self.hover_thrust {
            let a = self.acc_sp.z + acc_bias_z;
            self.vel_int.z += (a - GRAVITY) * self.hover_thrust / hover + GRAVITY - a;
            self.hover_thrust = hover;
        }
    }

    /// Clear the horizontal velocity integrator of `axis` (0 = N, 1 = E), for bumpless
    /// hand-back after an external controller commanded that axis.
    pub fn set_velocity_integrator(&mut self, axis: usize, value: f64) {
        self.vel_int[axis] = value;
    }

    /// Horizontal velocity integrator [m/s²].
    pub fn velocity_integrator(&self) -> Vector3<f64> {
        self.vel_int
    }

    /// Position and velocity loop (PX4 `PositionControl::update`), every 1/pos_loop_hz.
    ///
    /// `acc_bias` is added to the acceleration that is turned into tilt and thrust but not
    /// to the reported setpoint: it models the thesis's IMU offset (section 4.6.6).
    pub fn position_velocity(
        &mut self,
        sp: &Setpoint,
        pos: &Vector3<f64>,
        vel: &Vector3<f64>,
        dt: f64,
        acc_bias: &Vector3<f64>,
    ) {
        // Velocity derivative for the D term: finite difference, first-order low-pass.
        if let Some(prev) = self.vel_prev {
            let raw = (vel - prev) / dt;
            let alpha = lowpass_alpha(self.p.veld_cutoff, dt);
            self.vel_dot += (raw - self.vel_dot) * alpha;
            // The hover-thrust estimator reads the acceleration the last thrust setpoint
            // produced, before this tick's control (PX4's order).
            let speed_xy = (vel.x * vel.x + vel.y * vel.y).sqrt();
            let adopted = self
                .hte
                .as_mut()
                .and_then(|hte| hte.update(dt, -raw.z, -self.thr_sp.z, speed_xy, vel.z));
            if let Some(hover) = adopted {
                self.adopt_hover_thrust(hover, acc_bias.z);
            }
        }
        self.vel_prev = Some(*vel);
        let p = &self.p;

        // Position P → velocity setpoint; feed-through of velocity setpoints; acceleration
        // feed-forward (alone on acceleration axes, added to the PID's on trajectories).
        let mut vel_sp = Vector3::repeat(f64::NAN);
        let mut acc_ff = Vector3::zeros();
        for i in 0..3 {
            match sp.axes[i] {
                AxisSetpoint::Position(x) => vel_sp[i] = (x - pos[i]) * p.pos_p[i],
                AxisSetpoint::Velocity(v) => vel_sp[i] = v,
                AxisSetpoint::Acceleration(a) => acc_ff[i] = a,
                AxisSetpoint::Trajectory { p: x, v, a } => {
                    vel_sp[i] = v + (x - pos[i]) * p.pos_p[i];
                    acc_ff[i] = a;
                }
            }
        }
        // Velocity limits (PX4 constrains the position-loop output).
        let h = (vel_sp.x.is_finite() as u8, vel_sp.y.is_finite() as u8);
        if h == (1, 1) {
            let n = (vel_sp.x * vel_sp.x + vel_sp.y * vel_sp.y).sqrt();
            if n > p.vel_max_xy {
                vel_sp.x *= p.vel_max_xy / n;
                vel_sp.y *= p.vel_max_xy / n;
            }
        } else {
            for i in 0..2 {
                if vel_sp[i].is_finite() {
                    vel_sp[i] = vel_sp[i].clamp(-p.vel_max_xy, p.vel_max_xy);
                }
            }
        }
        if vel_sp.z.is_finite() {
            vel_sp.z = vel_sp.z.clamp(-p.vel_max_up, p.vel_max_down);
        }
        self.vel_sp = vel_sp;

        // Velocity PID (PX4 _velocityControl): acc = P e + I − D v̇, per available axis.
        self.vel_int.z = self.vel_int.z.clamp(-GRAVITY, GRAVITY);
        let mut vel_err = Vector3::zeros();
        let mut acc_sp = Vector3::zeros();
        for i in 0..3 {
            if vel_sp[i].is_finite() {
                vel_err[i] = vel_sp[i] - vel[i];
                acc_sp[i] = vel_err[i] * p.vel_p[i] + self.vel_int[i]
                    - self.vel_dot[i] * p.vel_d[i]
                    + acc_ff[i];
            } else {
                acc_sp[i] = acc_ff[i];
            }
        }
        self.acc_sp = acc_sp;

        // Acceleration → thrust vector (PX4 _accelerationControl, decoupled vertical).
        let a = acc_sp + acc_bias;
        let mut body_z = Vector3::new(-a.x, -a.y, GRAVITY).normalize();
        limit_tilt(&mut body_z, p.tilt_max);
        let ht = self.hover_thrust;
        let thrust_ned_z = a.z * (ht / GRAVITY) - ht;
        let cos_ned_body = body_z.z;
        let collective = (thrust_ned_z / cos_ned_body).min(-p.thrust_min);
        let mut thr = body_z * collective;

        // Vertical anti-windup.
        if (thr.z >= -p.thrust_min && vel_err.z >= 0.0)
            || (thr.z <= -p.thrust_max && vel_err.z <= 0.0)
        {
            vel_err.z = 0.0;
        }
        // Prioritise vertical thrust, keep a horizontal margin.
        let thr_xy = (thr.x * thr.x + thr.y * thr.y).sqrt();
        let tmax2 = p.thrust_max * p.thrust_max;
        let alloc_xy = thr_xy.min(p.thrust_xy_margin);
        thr.z = thr.z.max(-(tmax2 - alloc_xy * alloc_xy).sqrt());
        let xy_max2 = tmax2 - thr.z * thr.z;
        let xy_max = if xy_max2 > 0.0 { xy_max2.sqrt() } else { 0.0 };
        if thr_xy > xy_max {
            thr.x *= xy_max / thr_xy;
            thr.y *= xy_max / thr_xy;
        }
        // Tracking anti-windup in the horizontal plane (PX4: Rundqwist 1990), only while the
        // thrust vector produces less horizontal acceleration than was asked for.
        let arw = 2.0 / p.vel_p[0];
        let produced = (thr.x * (GRAVITY / ht), thr.y * (GRAVITY / ht));
        let saturated = a.x * a.x + a.y * a.y > produced.0 * produced.0 + produced.1 * produced.1;
        if saturated {
            for (i, made) in [produced.0, produced.1].into_iter().enumerate() {
                if vel_sp[i].is_finite() {
                    vel_err[i] -= arw * (a[i] - made);
                }
            }
        }
        for i in 0..3 {
            if vel_sp[i].is_finite() {
                self.vel_int[i] += vel_err[i] * p.vel_i[i] * dt;
            }
        }
        self.thr_sp = thr;
        self.q_sp = body_z_to_attitude(&(-thr), sp.yaw);
    }

    /// Attitude loop (PX4 `AttitudeControl::update`, eq. 5.1–5.2), every 1/att_loop_hz.
    pub fn attitude(&mut self, q: &Quaternion<f64>) {
        let p = &self.p;
        let q = UnitQuaternion::from_quaternion(*q);
        let mut qd = self.q_sp;
        // Reduced attitude: tilt first, yaw weighted by its gain ratio.
        let e_z = rotation(q.quaternion()).column(2).into_owned();
        let e_z_d = rotation(qd.quaternion()).column(2).into_owned();
        let mut qd_red = shortest_rotation(&e_z, &e_z_d);
        if qd_red.i.abs() > 1.0 - 1e-5 || qd_red.j.abs() > 1.0 - 1e-5 {
            qd_red = *qd.quaternion();
        } else {
            qd_red *= q.quaternion();
        }
        let yaw_w = (p.att_p[2] / p.att_p[0]).clamp(0.0, 1.0);
        let mut q_mix = canonical(&(qd_red.conjugate() * qd.quaternion()));
        q_mix.w = q_mix.w.clamp(-1.0, 1.0);
        q_mix.k = q_mix.k.clamp(-1.0, 1.0);
        let yaw_part = Quaternion::new(
            (yaw_w * q_mix.w.acos()).cos(),
            0.0,
            0.0,
            (yaw_w * q_mix.k.asin()).sin(),
        );
        qd = UnitQuaternion::from_quaternion(qd_red * yaw_part);
        let qe = canonical(&(q.quaternion().conjugate() * qd.quaternion()));
        let eq = Vector3::new(qe.i, qe.j, qe.k) * 2.0;
        let mut rate_sp = eq.component_mul(&Vector3::from(p.att_p));
        for i in 0..3 {
            rate_sp[i] = rate_sp[i].clamp(-p.rate_max[i], p.rate_max[i]);
        }
        self.rate_sp = rate_sp;
    }

    /// Rate loop (PX4 `RateControl::update`) and mixer, every 1/rate_loop_hz; returns the
    /// normalised motor commands.
    pub fn rates(&mut self, rate: &Vector3<f64>, dt: f64) -> Vector4<f64> {
        let p = &self.p;
        if let Some(prev) = self.rate_prev {
            let raw = (rate - prev) / dt;
            let alpha = lowpass_alpha(p.dgyro_cutoff, dt);
            self.ang_acc += (raw - self.ang_acc) * alpha;
        }
        self.rate_prev = Some(*rate);
        let err = self.rate_sp - rate;
        let mut torque = Vector3::zeros();
        for i in 0..3 {
            torque[i] = p.rate_p[i] * err[i] + self.rate_int[i] - p.rate_d[i] * self.ang_acc[i];
            // PX4 attenuates integration for large errors (I-term factor, 400 deg/s).
            let f = err[i] / 400f64.to_radians();
            let i_factor = (1.0 - f * f).max(0.0);
            let next = self.rate_int[i] + i_factor * p.rate_i[i] * err[i] * dt;
            self.rate_int[i] = next.clamp(-p.rate_int_limit[i], p.rate_int_limit[i]);
            torque[i] = torque[i].clamp(-1.0, 1.0);
        }
        self.torque_sp = torque;
        // PX4 applies the thrust vector's length along body −z (thrust_body[2] = −|thr_sp|).
        self.motor_cmd = mix_quad_x(self.thr_sp.norm(), &torque);
        self.motor_cmd
    }

    /// Motor thrust setpoints [N] of the current commands through the PWM curve (eq. 6.1).
    pub fn motor_thrust_setpoints(&self, vehicle: &VehicleParams) -> Vector4<f64> {
        self.motor_cmd.map(|c| vehicle.thrust_at(c))
    }

    /// Collective thrust of the trimmed start [normalised].
    pub fn trimmed_thrust(&self) -> f64 {
        self.thrust_at_hover
    }
}

/// Quad-X mixing with PX4-like desaturation: keep torques, give up collective thrust
/// first, then scale the torque part down if it alone does not fit in [0, 1].
pub fn mix_quad_x(thrust: f64, torque: &Vector3<f64>) -> Vector4<f64> {
    let mut part = [0.0; 4];
    for (m, row) in QUAD_X.iter().enumerate() {
        part[m] = row[0] * torque.x + row[1] * torque.y + row[2] * torque.z;
    }
    let (lo, hi) = part
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let span = hi - lo;
    let (scale, t) = if span > 1.0 {
        (1.0 / span, -lo / span)
    } else {
        (1.0, thrust.clamp(-lo, 1.0 - hi))
    };
    Vector4::from_fn(|m, _| (t + scale * part[m]).clamp(0.0, 1.0))
}

/// Smoothing factor of a first-order low-pass with cut-off `hz` sampled every `dt`.
fn lowpass_alpha(hz: f64, dt: f64) -> f64 {
    let rc = 1.0 / (2.0 * std::f64::consts::PI * hz);
    dt / (rc + dt)
}

/// PX4 `ControlMath::limitTilt` with world up = (0, 0, 1) in the body-z sense.
fn limit_tilt(body_z: &mut Vector3<f64>, max_angle: f64) {
    let world = Vector3::new(0.0, 0.0, 1.0);
    let dot = body_z.dot(&world).clamp(-1.0, 1.0);
    let angle = dot.acos().min(max_angle);
    let mut rejection = *body_z - world * dot;
    if rejection.norm_squared() < 1e-12 {
        rejection = Vector3::new(1.0, 0.0, 0.0);
    }
    *body_z = world * angle.cos() + rejection.normalize() * angle.sin();
}

/// PX4 `ControlMath::bodyzToAttitude`: attitude with body z along `body_z` and heading `yaw`.
pub fn body_z_to_attitude(body_z: &Vector3<f64>, yaw: f64) -> UnitQuaternion<f64> {
    let mut z = *body_z;
    if z.norm_squared() < 1e-12 {
        z = Vector3::new(0.0, 0.0, 1.0);
    }
    let z = z.normalize();
    let y_c = Vector3::new(-yaw.sin(), yaw.cos(), 0.0);
    let mut x = y_c.cross(&z);
    if z.z < 0.0 {
        x = -x;
    }
    if z.z.abs() < 1e-6 {
        x = Vector3::new(0.0, 0.0, 1.0);
    }
    let x = x.normalize();
    let y = z.cross(&x);
    let m = Matrix3::from_columns(&[x, y, z]);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

/// Shortest rotation taking unit vector `a` onto `b` (PX4 `Quaternion(src, dst)`).
fn shortest_rotation(a: &Vector3<f64>, b: &Vector3<f64>) -> Quaternion<f64> {
    let cr = a.cross(b);
    let dt = a.dot(b);
    let mut q = if cr.norm() < 1e-5 && dt < 0.0 {
        // 180° turn about any axis orthogonal to `a`.
        let c = if a.x.abs() < a.y.abs() && a.x.abs() < a.z.abs() {
            Vector3::new(1.0, 0.0, 0.0)
        } else if a.y.abs() < a.z.abs() {
            Vector3::new(0.0, 1.0, 0.0)
        } else {
            Vector3::new(0.0, 0.0, 1.0)
        };
        let axis = a.cross(&c);
        Quaternion::new(0.0, axis.x, axis.y, axis.z)
    } else {
        let mut q = Quaternion::new(dt, cr.x, cr.y, cr.z);
        q.w += q.norm();
        q
    };
    let n = q.norm();
    q /= n;
    q
}

/// Quaternion with non-negative scalar part (same rotation).
fn canonical(q: &Quaternion<f64>) -> Quaternion<f64> {
    if q.w < 0.0 {
        -*q
    } else {
        *q
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_attitude_for_zero_acceleration_and_tilt_for_north() {
        let q = body_z_to_attitude(&Vector3::new(0.0, 0.0, 1.0), 0.0);
        assert!((q.angle()).abs() < 1e-12);
        // Accelerating North: nose down (negative pitch), body z leans South.
        let q = body_z_to_attitude(&Vector3::new(-1.0, 0.0, GRAVITY).normalize(), 0.0);
        let (roll, pitch, yaw) = q.euler_angles();
        assert!(roll.abs() < 1e-12 && yaw.abs() < 1e-12);
        assert!((pitch + (1.0 / GRAVITY).atan()).abs() < 1e-12);
    }

    #[test]
    fn tilt_is_limited() {
        let mut z = Vector3::new(-10.0, 0.0, 1.0).normalize();
        limit_tilt(&mut z, 0.5);
        assert!((z.z.acos() - 0.5).abs() < 1e-12);
        assert!(z.x < 0.0 && z.y.abs() < 1e-15);
    }

    #[test]
    fn mixer_keeps_torque_and_sums_thrust() {
        let m = mix_quad_x(0.5, &Vector3::zeros());
        assert_eq!(m, Vector4::repeat(0.5));
        // Roll right: left motors (2, 3) up, right motors (1, 4) down.
        let m = mix_quad_x(0.5, &Vector3::new(0.1, 0.0, 0.0));
        assert!(m[1] > 0.5 && m[2] > 0.5 && m[0] < 0.5 && m[3] < 0.5);
        // Saturation gives up thrust, not torque.
        let m = mix_quad_x(0.99, &Vector3::new(0.0, 0.2, 0.0));
        assert!((m[0] - m[1] - 2.0 * 0.2 * std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12);
        assert!(m.max() <= 1.0);
    }

    /// The collective after one position tick holding still at the origin, with the
    /// vertical acceleration offset `bias_z`.
    fn hold_collective(c: &mut Px4Cascade, bias_z: f64) -> f64 {
        let at = Vector3::zeros();
        c.position_velocity(
            &Setpoint::hold(at),
            &at,
            &at,
            0.02,
            &Vector3::new(0.0, 0.0, bias_z),
        );
        c.thr_sp.z
    }

    #[test]
    fn adopting_a_hover_thrust_keeps_the_thrust_with_a_vertical_offset() {
        let p = Px4Params {
            hover_thrust_estimator: false,
            ..Px4Params::default()
        };
        let bias = -0.8;
        for (told, jumps) in [(bias, false), (0.0, true)] {
            let mut c = Px4Cascade::new(p.clone(), 0.5);
            c.set_velocity_integrator(2, 0.6);
            let before = hold_collective(&mut c, bias);
            c.adopt_hover_thrust(0.42, told);
            let after = hold_collective(&mut c, bias);
            // Told the offset, PX4's rule keeps the thrust; without it the thrust moves by
            // b (1 − Th'/Th) Th/g.
            let expected = if jumps {
                bias * (1.0 - 0.42 / 0.5) * 0.5 / GRAVITY
            } else {
                0.0
            };
            assert!(
                ((before - after).abs() - expected.abs()).abs() < 1e-12,
                "{before} {after}"
            );
            assert_eq!(c.hover_thrust(), 0.42);
        }
    }

    #[test]
    fn shortest_rotation_maps_a_to_b() {
        let a = Vector3::new(0.0, 0.0, 1.0);
        let b = Vector3::new(0.3, -0.2, 0.9).normalize();
        let q = shortest_rotation(&a, &b);
        let r = rotation(&q) * a;
        assert!((r - b).norm() < 1e-12);
    }
}
