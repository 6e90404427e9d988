//! Scenario files: vehicle, payload, wind, sensor noise, setpoint schedule and duration.
//!
//! One struct validates TOML and JSON alike (`deny_unknown_fields`); errors name the field by
//! its dotted path, e.g. `payload.mass: must be > 0 (got -0.1)` or
//! `payload.masss: unknown field`.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::config::{finite, in_range, non_negative, positive, ConfigError};
use crate::control::px4::{AxisSetpoint, Px4Params};
use crate::plant::{Airframe, PayloadParams, VehicleParams, WindParams};
use crate::sensors::SensorParams;

/// Sensor noise and bias (seeded by the scenario seed).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseParams {
    /// Standard deviation of the swing-angle measurement noise [rad] (0 = off).
    pub swing_std: f64,
    /// Sample rate of the band-limited swing noise (a new value every 1/rate) [Hz].
    pub swing_rate: f64,
    /// Standard deviation of the velocity estimate noise [m/s].
    pub velocity_std: f64,
    /// Standard deviation of the position estimate noise [m].
    pub position_std: f64,
    /// Constant offset between commanded and realised horizontal acceleration (N, E) [m/s²]
    /// — the thesis's IMU offset (section 4.6.6).
    pub acc_sp_bias: [f64; 2],
}

impl Default for NoiseParams {
    fn default() -> Self {
        Self {
            swing_std: 0.0,
            swing_rate: 100.0,
            velocity_std: 0.0,
            position_std: 0.0,
            acc_sp_bias: [0.0, 0.0],
        }
    }
}

impl NoiseParams {
    /// Check the settings; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        non_negative("swing_std", self.swing_std)?;
        positive("swing_rate", self.swing_rate)?;
        non_negative("velocity_std", self.velocity_std)?;
        non_negative("position_std", self.position_std)?;
        crate::config::all_finite("acc_sp_bias", &self.acc_sp_bias)?;
        Ok(())
    }
}

/// One entry of the setpoint schedule: from time `t` on, each named axis takes the new
/// setpoint; axes not named keep theirs. Per axis give at most one of position (`p*`),
/// velocity (`v*`) or acceleration (`a*`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetpointEntry {
    /// Time the entry takes effect [s].
    pub t: f64,
    /// North position [m].
    pub pn: Option<f64>,
    /// East position [m].
    pub pe: Option<f64>,
    /// Down position [m].
    pub pd: Option<f64>,
    /// North velocity [m/s].
    pub vn: Option<f64>,
    /// East velocity [m/s].
    pub ve: Option<f64>,
    /// Down velocity [m/s].
    pub vd: Option<f64>,
    /// North acceleration [m/s²].
    pub an: Option<f64>,
    /// East acceleration [m/s²].
    pub ae: Option<f64>,
    /// Down acceleration [m/s²].
    pub ad: Option<f64>,
    /// Yaw [rad].
    pub yaw: Option<f64>,
}

impl SetpointEntry {
    /// Per axis (N, E, D): the setpoint this entry sets, if any.
    pub fn axis(&self, i: usize) -> Option<AxisSetpoint> {
        let (p, v, a) = match i {
            0 => (self.pn, self.vn, self.an),
            1 => (self.pe, self.ve, self.ae),
            _ => (self.pd, self.vd, self.ad),
        };
        p.map(AxisSetpoint::Position)
            .or(v.map(AxisSetpoint::Velocity))
            .or(a.map(AxisSetpoint::Acceleration))
    }

    fn validate(&self) -> Result<(), ConfigError> {
        non_negative("t", self.t)?;
        let names = [["pn", "vn", "an"], ["pe", "ve", "ae"], ["pd", "vd", "ad"]];
        let vals = [
            [self.pn, self.vn, self.an],
            [self.pe, self.ve, self.ae],
            [self.pd, self.vd, self.ad],
        ];
        for (axis, row) in vals.iter().enumerate() {
            let given: Vec<usize> = (0..3).filter(|k| row[*k].is_some()).collect();
            if given.len() > 1 {
                return Err(ConfigError::new(
                    names[axis][given[1]],
                    format!(
                        "conflicts with `{}` in the same entry",
                        names[axis][given[0]]
                    ),
                ));
            }
            for k in given {
                finite(names[axis][k], row[k].unwrap_or(0.0))?;
            }
        }
        if let Some(y) = self.yaw {
            finite("yaw", y)?;
        }
        Ok(())
    }
}

/// The horizontal axes that [`RandomSteps`] steps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Axes {
    /// North only.
    #[default]
    #[serde(rename = "n")]
    N,
    /// East only.
    #[serde(rename = "e")]
    E,
    /// North and East.
    #[serde(rename = "ne")]
    Ne,
}

impl Axes {
    /// Whether North is stepped.
    pub fn north(self) -> bool {
        matches!(self, Axes::N | Axes::Ne)
    }

    /// Whether East is stepped.
    pub fn east(self) -> bool {
        matches!(self, Axes::E | Axes::Ne)
    }
}

/// The thesis's random velocity steps (section 4.6.1, table 4.1): step values and hold
/// times drawn uniformly, seeded.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RandomSteps {
    /// Axes stepped: `n`, `e` or `ne`.
    pub axes: Axes,
    /// Time of the first step [s].
    pub start: f64,
    /// Smallest velocity step value [m/s].
    pub v_min: f64,
    /// Largest velocity step value [m/s].
    pub v_max: f64,
    /// Shortest hold time [s].
    pub interval_min: f64,
    /// Longest hold time [s].
    pub interval_max: f64,
    /// Draw the sign at random too (values in ±[v_min, v_max]); the table's range is one-sided.
    pub symmetric: bool,
    /// Seed of the schedule (default: the scenario seed).
    pub seed: Option<u64>,
}

impl Default for RandomSteps {
    fn default() -> Self {
        Self {
            axes: Axes::N,
            start: 2.0,
            v_min: 0.0,
            v_max: 3.0,
            interval_min: 10.0,
            interval_max: 25.0,
            symmetric: false,
            seed: None,
        }
    }
}

impl RandomSteps {
    fn validate(&self) -> Result<(), ConfigError> {
        non_negative("start", self.start)?;
        non_negative("v_min", self.v_min)?;
        in_range("v_max", self.v_max, self.v_min, 12.0)?;
        positive("interval_min", self.interval_min)?;
        in_range("interval_max", self.interval_max, self.interval_min, 1e6)?;
        Ok(())
    }

    /// The schedule up to `duration`, drawn from `seed` unless the settings carry their own.
    pub fn schedule(&self, duration: f64, seed: u64) -> Vec<SetpointEntry> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed.unwrap_or(seed) ^ 0x5354_4550);
        let mut out = Vec::new();
        let mut t = self.start;
        while t < duration {
            let draw = |rng: &mut ChaCha8Rng| {
                let v = if self.v_max > self.v_min {
                    rng.random_range(self.v_min..self.v_max)
                } else {
                    self.v_min
                };
                if self.symmetric && rng.random_bool(0.5) {
                    -v
                } else {
                    v
                }
            };
            let mut e = SetpointEntry {
                t,
                ..Default::default()
            };
            if self.axes.north() {
                e.vn = Some(draw(&mut rng));
            }
            if self.axes.east() {
                e.ve = Some(draw(&mut rng));
            }
            out.push(e);
            t += if self.interval_max > self.interval_min {
                rng.random_range(self.interval_min..self.interval_max)
            } else {
                self.interval_min
            };
        }
        out
    }
}

/// Where `over` names another airframe (`[vehicle] airframe = "x500"`) than `base`'s, put
/// that airframe's whole vehicle table in `base`, so the file's other vehicle values apply to
/// it and nothing of the old vehicle is left.
fn select_airframe(base: &mut toml::Table, over: &toml::Table) -> Result<(), ConfigError> {
    let named = over
        .get("vehicle")
        .and_then(|v| v.as_table())
        .and_then(|v| v.get("airframe"));
    let Some(named) = named else {
        return Ok(());
    };
    let airframe = named
        .as_str()
        .ok_or_else(|| ConfigError::new("airframe", "must be a name").within("vehicle"))
        .and_then(|n| Airframe::from_name(n).map_err(|e| e.within("vehicle")))?;
    let current = base
        .get("vehicle")
        .and_then(|v| v.get("airframe"))
        .and_then(|v| v.as_str());
    if current != Some(airframe.name()) {
        let table = toml::Value::try_from(airframe.params())
            .map_err(|e| ConfigError::new("vehicle", e.to_string()))?;
        base.insert("vehicle".into(), table);
    }
    Ok(())
}

/// Longest scenario [s] (a day): beyond it a typo (`duration = 4294967296`) would ask for a
/// trace of terabytes and a run of centuries, so it is refused by name instead.
pub const MAX_DURATION: f64 = 86_400.0;

/// Most random steps a schedule may draw; `random_steps.interval_min` is refused when the
/// duration would need more (a near-zero hold time would otherwise never end the loop).
pub const MAX_RANDOM_STEPS: f64 = 1e6;

/// A complete simulation scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scenario {
    /// Free-form name used in reports.
    pub name: String,
    /// Simulated duration [s].
    pub duration: f64,
    /// Seed of every random generator of the run.
    pub seed: u64,
    /// Physics (RK4) step [s].
    pub physics_dt: f64,
    /// Trace logging rate [Hz].
    pub log_rate: f64,
    /// Initial vehicle position, NED [m] (held until the schedule says otherwise).
    pub start: [f64; 3],
    /// Vehicle parameters.
    pub vehicle: VehicleParams,
    /// Payload parameters.
    pub payload: PayloadParams,
    /// Wind.
    pub wind: WindParams,
    /// Sensor noise and bias.
    pub noise: NoiseParams,
    /// The swing source, the IMU and the body-fixed cable sensor.
    pub sensors: SensorParams,
    /// PX4 cascade gains and limits.
    pub controller: Px4Params,
    /// Setpoint schedule (sorted by time when loaded).
    pub setpoints: Vec<SetpointEntry>,
    /// Random velocity steps appended to the schedule (table 4.1).
    pub random_steps: Option<RandomSteps>,
}

impl Default for Scenario {
    fn default() -> Self {
        Self {
            name: "default".into(),
            duration: 20.0,
            seed: 0,
            physics_dt: 0.001,
            log_rate: 100.0,
            start: [0.0, 0.0, -10.0],
            vehicle: VehicleParams::default(),
            payload: PayloadParams::default(),
            wind: WindParams::default(),
            noise: NoiseParams::default(),
            sensors: SensorParams::default(),
            controller: Px4Params::default(),
            setpoints: Vec::new(),
            random_steps: None,
        }
    }
}

impl Scenario {
    /// The default `simulate` scenario: 0.2 kg on 1 m, 2 m/s North step at t = 2 s.
    pub fn default_step() -> Self {
        Self {
            name: "step".into(),
            setpoints: vec![
                SetpointEntry {
                    t: 0.0,
                    vn: Some(0.0),
                    ..Default::default()
                },
                SetpointEntry {
                    t: 2.0,
                    vn: Some(2.0),
                    ..Default::default()
                },
            ],
            ..Default::default()
        }
    }

    /// The default `collect` scenario: random North velocity steps of table 4.1 for 300 s.
    pub fn default_training() -> Self {
        Self {
            name: "training".into(),
            duration: 300.0,
            setpoints: vec![SetpointEntry {
                t: 0.0,
                vn: Some(0.0),
                ..Default::default()
            }],
            random_steps: Some(RandomSteps::default()),
            ..Default::default()
        }
    }

    /// A built-in scenario by name: `step` (simulate), `training` (collect) or `hover` (the
    /// step scenario without a schedule, an hour long: hold the start position).
    pub fn builtin(name: &str) -> Result<Self, ConfigError> {
        match name {
            "step" => Ok(Self::default_step()),
            "training" => Ok(Self::default_training()),
            "hover" => Ok(Self {
                name: "hover".into(),
                setpoints: Vec::new(),
                duration: 3600.0,
                ..Self::default_step()
            }),
            other => Err(ConfigError::new(
                "scenario",
                format!("unknown built-in scenario {other:?} (use step, training or hover)"),
            )),
        }
    }

    /// This scenario with `over` merged in key by key (tables merge, anything else replaces),
    /// parsed and validated; errors name the dotted field.
    pub fn with_overrides(&self, over: toml::Table) -> Result<Self, ConfigError> {
        let mut base = match toml::Value::try_from(self) {
            Ok(toml::Value::Table(t)) => t,
            _ => {
                return Err(ConfigError::new(
                    "scenario",
                    "cannot be represented as TOML",
                ))
            }
        };
        select_airframe(&mut base, &over)?;
        crate::config::merge_tables(&mut base, over);
        let sc: Scenario = crate::config::from_toml_value(toml::Value::Table(base))?;
        sc.validate()?;
        Ok(sc)
    }

    /// Parse TOML text over the built-in scenario `base` (see [`Scenario::builtin`]).
    pub fn from_toml_over(text: &str, base: &str) -> Result<Self, ConfigError> {
        Self::builtin(base)?.with_overrides(crate::config::parse_toml(text)?)
    }

    /// Parse TOML text; unknown keys and bad values give a [`ConfigError`] naming the field.
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        let table = crate::config::parse_toml(text)?;
        let sc: Scenario = crate::config::from_toml_value(toml::Value::Table(table))?;
        sc.validate()?;
        Ok(sc)
    }

    /// Parse JSON text (model files and pickles carry scenarios this way); same rules as TOML.
    pub fn from_json(text: &str) -> Result<Self, ConfigError> {
        let sc: Scenario = crate::config::from_json_str(text)?;
        sc.validate()?;
        Ok(sc)
    }

    /// Normalised hover thrust PX4's estimator settles on for this vehicle and payload.
    pub fn hover_thrust(&self) -> f64 {
        crate::control::px4::Px4Cascade::hover_thrust_for(
            &self.vehicle,
            self.vehicle.mass + self.payload.total_mass(),
        )
    }

    /// Roll and pitch angular acceleration [rad/s²] per unit of the cascade's normalised
    /// torque at hover: the rate loop's plant gain, what its gains must suit (the motors'
    /// slope at hover through the quad-X mixing, the moment arms, the inertia).
    pub fn rate_authority(&self) -> [f64; 2] {
        use crate::control::px4::mix_quad_x;
        let v = &self.vehicle;
        let hover = self.hover_thrust();
        let at = |torque: nalgebra::Vector3<f64>| {
            let cmd = mix_quad_x(hover, &torque);
            let thrust = nalgebra::Vector4::from_fn(|m, _| v.thrust_at(cmd[m]));
            crate::plant::dynamics::mix(&thrust)
        };
        let h = 1e-3;
        let (zero, roll, pitch) = (
            at(nalgebra::Vector3::zeros()),
            at(nalgebra::Vector3::new(h, 0.0, 0.0)),
            at(nalgebra::Vector3::new(0.0, h, 0.0)),
        );
        // δ_A, δ_E carry the square X's 1/√2 (see `plant::dynamics::mix`).
        let [pitch_arm, roll_arm] = v.moment_arms();
        let k = std::f64::consts::SQRT_2 / h;
        [
            roll_arm * k * (roll[1] - zero[1]) / v.inertia[0],
            pitch_arm * k * (pitch[2] - zero[2]) / v.inertia[1],
        ]
    }

    /// Check physical sense of every section; the error names the field by dotted path.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("duration", self.duration)?;
        if self.duration > MAX_DURATION {
            return Err(ConfigError::new(
                "duration",
                format!("must be at most {MAX_DURATION} s (got {})", self.duration),
            ));
        }
        in_range("physics_dt", self.physics_dt, 1e-5, 0.01)?;
        // TOML integers are i64: a larger seed would write a scenario TOML (reports,
        // reproducibility) that cannot be read back.
        let seeds = [
            ("seed", Some(self.seed)),
            (
                "random_steps.seed",
                self.random_steps.as_ref().and_then(|r| r.seed),
            ),
        ];
        for (field, seed) in seeds {
            if seed.is_some_and(|s| s > i64::MAX as u64) {
                return Err(ConfigError::new(
                    field,
                    format!("must be at most {} (a TOML integer)", i64::MAX),
                ));
            }
        }
        positive("log_rate", self.log_rate)?;
        if self.log_rate * self.physics_dt > 1.0 + 1e-9 {
            return Err(ConfigError::new(
                "log_rate",
                "must not exceed the physics rate 1/physics_dt",
            ));
        }
        crate::config::all_finite("start", &self.start)?;
        self.vehicle.validate().map_err(|e| e.within("vehicle"))?;
        self.payload.validate().map_err(|e| e.within("payload"))?;
        let heaviest = crate::plant::check_events(&self.payload, self.vehicle.mass)
            .map_err(|e| e.within("payload"))?;
        let needed = crate::control::px4::Px4Cascade::hover_thrust_for(&self.vehicle, heaviest);
        if needed > self.controller.thrust_max * 0.9 {
            return Err(ConfigError::new(
                "payload.events",
                format!(
                    "the events reach {heaviest:.3} kg, which needs {:.0} % thrust to hover; \
                     too heavy",
                    needed * 100.0
                ),
            ));
        }
        self.wind.validate().map_err(|e| e.within("wind"))?;
        self.noise.validate().map_err(|e| e.within("noise"))?;
        self.sensors.validate().map_err(|e| e.within("sensors"))?;
        self.controller
            .validate()
            .map_err(|e| e.within("controller"))?;
        for (name, hz) in [
            ("rate_loop_hz", self.controller.rate_loop_hz),
            ("att_loop_hz", self.controller.att_loop_hz),
            ("pos_loop_hz", self.controller.pos_loop_hz),
        ] {
            let steps = 1.0 / (hz * self.physics_dt);
            if steps < 1.0 - 1e-9 || (steps - steps.round()).abs() > 1e-6 {
                return Err(ConfigError::new(
                    format!("controller.{name}"),
                    format!(
                        "must divide the physics rate {} Hz evenly (got {hz} Hz)",
                        1.0 / self.physics_dt
                    ),
                ));
            }
        }
        for (i, s) in self.setpoints.iter().enumerate() {
            s.validate()
                .map_err(|e| e.within(&format!("setpoints[{i}]")))?;
        }
        if let Some(r) = &self.random_steps {
            r.validate().map_err(|e| e.within("random_steps"))?;
            let draws = (self.duration - r.start).max(0.0) / r.interval_min;
            if draws > MAX_RANDOM_STEPS {
                return Err(ConfigError::new(
                    "random_steps.interval_min",
                    format!(
                        "{} s draws about {draws:.0} steps over {} s, more than {MAX_RANDOM_STEPS}",
                        r.interval_min, self.duration
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The full schedule: explicit entries and random steps, sorted by time (stable).
    pub fn schedule(&self) -> Vec<SetpointEntry> {
        let mut all = self.setpoints.clone();
        if let Some(r) = &self.random_steps {
            all.extend(r.schedule(self.duration, self.seed));
        }
        all.sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
        all
    }

    /// The same scenario serialised as TOML (for reports and reproducibility).
    pub fn to_toml(&self) -> Result<String, ConfigError> {
        toml::to_string(self).map_err(|e| ConfigError::new("scenario", e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_key_and_bad_values_name_the_field() {
        let e = Scenario::from_toml("[payload]\nmasss = 0.2\n").unwrap_err();
        assert!(e.field.starts_with("payload"), "{e}");
        assert!(e.to_string().contains("masss"), "{e}");
        let e = Scenario::from_toml("[payload]\nmass = -0.2\n").unwrap_err();
        assert_eq!(e.field, "payload.mass");
        let e = Scenario::from_toml("[payload]\nlength = 0.0\n").unwrap_err();
        assert_eq!(e.field, "payload.length");
        let e = Scenario::from_toml("duration = nan\n").unwrap_err();
        assert_eq!(e.field, "duration");
        let e = Scenario::from_json(r#"{"vehicle": {"inertia": [1, 2]}}"#).unwrap_err();
        assert!(e.field.starts_with("vehicle.inertia"), "{e}");
        let e = Scenario::from_toml("[[setpoints]]\nt = 1\nvn = 1\npn = 2\n").unwrap_err();
        assert_eq!(e.field, "setpoints[0].vn");
    }

    #[test]
    fn random_steps_follow_table_4_1_and_the_seed() {
        let sc = Scenario::default_training();
        let a = sc.schedule();
        let b = sc.schedule();
        assert_eq!(a, b);
        let steps: Vec<_> = a.iter().filter(|e| e.t > 0.0).collect();
        assert!(steps.len() >= 10);
        for w in steps.windows(2) {
            let dt = w[1].t - w[0].t;
            assert!((10.0..=25.0).contains(&dt), "{dt}");
        }
        for e in &steps {
            let v = e.vn.unwrap();
            assert!((0.0..=3.0).contains(&v));
        }
        let mut other = sc.clone();
        other.seed = 1;
        assert_ne!(other.schedule(), a);
    }

    #[test]
    fn round_trip_through_toml() {
        let sc = Scenario::default_step();
        let back = Scenario::from_toml(&sc.to_toml().unwrap()).unwrap();
        assert_eq!(back, sc);
    }
}
