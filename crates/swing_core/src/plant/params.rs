//! Physical parameters of the vehicle, the payload and the air (thesis table 6.1, section 3.5).

use serde::{Deserialize, Serialize};

use crate::config::{non_negative, positive, ConfigError};

/// Standard gravity [m/s²].
pub const GRAVITY: f64 = 9.80665;

/// A built-in vehicle: the parameters a scenario's `[vehicle]` table starts from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Airframe {
    /// The thesis's Honeybee (table 6.1).
    #[default]
    Honeybee,
    /// PX4's reference quadrotor, the x500 of its Gazebo SITL (model `x500`, airframe 4001).
    X500,
}

impl Airframe {
    /// Every built-in airframe, in the order the CLI lists them.
    pub const ALL: [Airframe; 2] = [Airframe::Honeybee, Airframe::X500];

    /// The name a scenario file uses.
    pub fn name(self) -> &'static str {
        match self {
            Airframe::Honeybee => "honeybee",
            Airframe::X500 => "x500",
        }
    }

    /// The airframe of that name; the error lists the known ones.
    pub fn from_name(name: &str) -> Result<Self, ConfigError> {
        Self::ALL
            .into_iter()
            .find(|a| a.name() == name)
            .ok_or_else(|| {
                let known: Vec<&str> = Self::ALL.iter().map(|a| a.name()).collect();
                ConfigError::new(
                    "airframe",
                    format!("unknown airframe {name:?} (built in: {})", known.join(", ")),
                )
            })
    }

    /// The airframe's parameters.
    pub fn params(self) -> VehicleParams {
        match self {
            Airframe::Honeybee => VehicleParams::default(),
            Airframe::X500 => VehicleParams::x500(),
        }
    }
}

/// Rigid-body, actuator and drag parameters of the multirotor (defaults: Honeybee, table 6.1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VehicleParams {
    /// The built-in vehicle these parameters start from (naming another one in a scenario
    /// file replaces the whole table before the file's own values apply).
    pub airframe: Airframe,
    /// Vehicle mass m_Q including companion computer and swing sensor [kg].
    pub mass: f64,
    /// Distance from the CoM to each motor d [m].
    pub arm: f64,
    /// Rotor position |x|, |y| in body axes [m] of a rectangular X (PX4's `CA_ROTOR*_PX`,
    /// `_PY`): the pitch and roll moment arms. Unset: a square X, both d/√2. When set, `arm`
    /// must be their distance √(x² + y²).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotor_xy: Option<[f64; 2]>,
    /// Virtual yaw moment arm R_N [m].
    pub yaw_arm: f64,
    /// Principal moments of inertia (I_xx, I_yy, I_zz) [kg·m²].
    pub inertia: [f64; 3],
    /// Lumped drag coefficients × reference areas C_Q in body x, y, z [m²].
    pub drag: [f64; 3],
    /// Motor–propeller first-order time constant τ [s].
    pub motor_tau: f64,
    /// PWM → thrust polynomial (eq. 6.1), coefficients of x³, x², x, 1 with x in µs; thrust [N].
    pub thrust_poly: [f64; 4],
    /// PWM at zero command [µs] (PX4 PWM_MAIN_MIN).
    pub pwm_min: f64,
    /// PWM at full command [µs] (PX4 PWM_MAIN_MAX).
    pub pwm_max: f64,
    /// Air density ρ [kg/m³].
    pub air_density: f64,
}

impl Default for VehicleParams {
    fn default() -> Self {
        Self {
            airframe: Airframe::Honeybee,
            mass: 0.952,
            arm: 0.11,
            rotor_xy: None,
            yaw_arm: 7.997e-3,
            inertia: [2.00e-3, 1.32e-3, 3.35e-3],
            drag: [0.096, 0.096, 0.256],
            motor_tau: 0.015,
            thrust_poly: [-3.508e-9, 1.627e-5, -0.0172, 4.528],
            pwm_min: 1000.0,
            pwm_max: 2000.0,
            air_density: 1.225,
        }
    }
}

/// Distance the rotors of a rectangular X may be off `arm` [m] (rounding in a file).
const ARM_TOLERANCE: f64 = 1e-3;

impl VehicleParams {
    /// PX4's x500 as its Gazebo model describes it: 2.0 kg, inertia (0.0217, 0.0217,
    /// 0.04) kg·m², rotors at |x| 0.13 and |y| 0.20–0.22 m (their mean 0.21 here),
    /// thrust k·ω² with k = 8.54858e-6 N·s² and ω = 150–1000 rad/s over the command
    /// (written as eq. 6.1's polynomial in PWM), moment ratio 0.016 m, motor lag the mean of
    /// its 12.5 ms up and 25 ms down. The Gazebo model has no body drag, only rotor drag
    /// linear in speed (8.06428e-5 N·s per rad/s per rotor); the quadratic drag here matches
    /// it at 2 m/s in hover.
    pub fn x500() -> Self {
        let (k, w_min, w_max) = (8.54858e-6, 150.0, 1000.0);
        // ω = w_min + (w_max − w_min)(pwm − 1000)/1000 = a·pwm + b
        let a = (w_max - w_min) / 1000.0;
        let b = w_min - 1000.0 * a;
        let (x, y): (f64, f64) = (0.13, 0.21);
        let rotor_drag = 4.0 * 8.06428e-5 * (0.25 * 2.0 * GRAVITY / k).sqrt();
        let drag = rotor_drag * 2.0 / (0.5 * 1.225 * 2.0 * 2.0);
        Self {
            airframe: Airframe::X500,
            mass: 2.0,
            arm: x.hypot(y),
            rotor_xy: Some([x, y]),
            yaw_arm: 0.016,
            inertia: [0.02166666666666667, 0.02166666666666667, 0.04],
            drag: [drag, drag, 2.0 * drag],
            motor_tau: 0.5 * (0.0125 + 0.025),
            thrust_poly: [0.0, k * a * a, 2.0 * k * a * b, k * b * b],
            pwm_min: 1000.0,
            pwm_max: 2000.0,
            air_density: 1.225,
        }
    }

    /// Pitch and roll moment arms [m]: the rotors' |x| and |y|.
    pub fn moment_arms(&self) -> [f64; 2] {
        self.rotor_xy
            .unwrap_or([self.arm * std::f64::consts::FRAC_1_SQRT_2; 2])
    }

    /// Check physical sense; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("mass", self.mass)?;
        positive("arm", self.arm)?;
        if let Some([x, y]) = self.rotor_xy {
            positive("rotor_xy[0]", x)?;
            positive("rotor_xy[1]", y)?;
            if (x.hypot(y) - self.arm).abs() > ARM_TOLERANCE {
                return Err(ConfigError::new(
                    "arm",
                    format!(
                        "must be the rotors' distance √(x² + y²) = {:.4} m of rotor_xy (got {})",
                        x.hypot(y),
                        self.arm
                    ),
                ));
            }
        }
        positive("yaw_arm", self.yaw_arm)?;
        for (i, v) in self.inertia.iter().enumerate() {
            positive(&format!("inertia[{i}]"), *v)?;
        }
        for (i, v) in self.drag.iter().enumerate() {
            non_negative(&format!("drag[{i}]"), *v)?;
        }
        positive("motor_tau", self.motor_tau)?;
        for (i, v) in self.thrust_poly.iter().enumerate() {
            crate::config::finite(&format!("thrust_poly[{i}]"), *v)?;
        }
        positive("pwm_min", self.pwm_min)?;
        positive("pwm_max", self.pwm_max)?;
        if self.pwm_max <= self.pwm_min {
            return Err(ConfigError::new("pwm_max", "must be greater than pwm_min"));
        }
        positive("air_density", self.air_density)?;
        // The thrust curve must rise over the PWM range, else no controller can work.
        let (lo, hi) = (self.thrust_at(0.0), self.thrust_at(1.0));
        if !(hi > lo && hi > 0.0) {
            return Err(ConfigError::new(
                "thrust_poly",
                format!("thrust must increase over the PWM range (got {lo:.3} N → {hi:.3} N)"),
            ));
        }
        let steps = 64;
        for k in 0..steps {
            let (a, b) = (k as f64 / steps as f64, (k + 1) as f64 / steps as f64);
            if self.thrust_at(b) < self.thrust_at(a) {
                return Err(ConfigError::new(
                    "thrust_poly",
                    "thrust must be monotonic over the PWM range",
                ));
            }
        }
        if 4.0 * hi < self.mass * GRAVITY * 1.2 {
            return Err(ConfigError::new(
                "thrust_poly",
                format!(
                    "four motors give at most {:.2} N, too little to lift {:.3} kg with margin",
                    4.0 * hi,
                    self.mass
                ),
            ));
        }
        Ok(())
    }

    /// Steady-state thrust of one motor [N] for a normalised command `cmd` ∈ [0, 1] (eq. 6.1).
    #[inline]
    pub fn thrust_at(&self, cmd: f64) -> f64 {
        let x = self.pwm_min + (self.pwm_max - self.pwm_min) * cmd;
        let [a3, a2, a1, a0] = self.thrust_poly;
        (((a3 * x + a2) * x + a1) * x + a0).max(0.0)
    }

    /// Normalised command giving `thrust` [N] on one motor (inverse of eq. 6.1 by bisection).
    pub fn command_for_thrust(&self, thrust: f64) -> f64 {
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if self.thrust_at(mid) < thrust {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }
}

/// The kind of suspended payload.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PayloadKind {
    /// No payload.
    None,
    /// Point mass on a rigid massless cable (section 3.5).
    #[default]
    Single,
    /// Elongated payload: double pendulum, the second link hidden (section 4.6.9).
    Double,
}

/// Suspended payload parameters (section 3.5; defaults: 0.2 kg on 1 m).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PayloadParams {
    /// Payload kind: `none`, `single` or `double`.
    pub kind: PayloadKind,
    /// Payload mass m_p (first mass for `double`) [kg].
    pub mass: f64,
    /// Cable length l (first link for `double`) [m].
    pub length: f64,
    /// Second mass m_2 of a `double` payload [kg].
    pub mass2: f64,
    /// Second link length l_2 of a `double` payload [m].
    pub length2: f64,
    /// Lumped drag coefficient × area of each payload mass C_p [m²].
    pub drag: f64,
    /// Linear joint friction c at each joint [N·m·s/rad].
    pub friction: f64,
    /// Initial cable angle in the North–Down plane [rad].
    pub initial_swing_n: f64,
    /// Initial cable angle in the East–Down plane [rad].
    pub initial_swing_e: f64,
    /// Events in flight (`[[payload.events]]`: attach, detach, mass, winch, vehicle_mass),
    /// in time order; see [`super::events`] for fields, units and physics.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub events: Vec<super::events::PayloadEvent>,
}

impl Default for PayloadParams {
    fn default() -> Self {
        Self {
            kind: PayloadKind::Single,
            mass: 0.2,
            length: 1.0,
            mass2: 0.1,
            length2: 0.3,
            drag: 0.005,
            friction: 0.001,
            initial_swing_n: 0.0,
            initial_swing_e: 0.0,
            events: Vec::new(),
        }
    }
}

impl PayloadParams {
    /// Check physical sense; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.kind == PayloadKind::None {
            return Ok(());
        }
        positive("mass", self.mass)?;
        positive("length", self.length)?;
        if self.kind == PayloadKind::Double {
            positive("mass2", self.mass2)?;
            positive("length2", self.length2)?;
        }
        non_negative("drag", self.drag)?;
        non_negative("friction", self.friction)?;
        crate::config::in_range("initial_swing_n", self.initial_swing_n, -1.4, 1.4)?;
        crate::config::in_range("initial_swing_e", self.initial_swing_e, -1.4, 1.4)?;
        Ok(())
    }

    /// Number of rigid links (0, 1 or 2).
    pub fn links(&self) -> usize {
        match self.kind {
            PayloadKind::None => 0,
            PayloadKind::Single => 1,
            PayloadKind::Double => 2,
        }
    }

    /// Total suspended mass [kg].
    pub fn total_mass(&self) -> f64 {
        match self.kind {
            PayloadKind::None => 0.0,
            PayloadKind::Single => self.mass,
            PayloadKind::Double => self.mass + self.mass2,
        }
    }
}
