//! The plant as a hardware-in-the-loop simulator for a real PX4 flight controller.
//!
//! PX4 (SITL or a Pixhawk in HITL mode) flies the vehicle: it reads synthetic sensors and
//! answers with normalised motor commands. This module owns the physics side of that
//! exchange: vehicle + payload dynamics under the motor commands (eq. 6.1 maps them to
//! thrust), a ground to stand on, and the sensor readings PX4 expects — specific force and
//! body rates in FRD, the Earth's magnetic field in FRD, barometric pressure of the ISA
//! atmosphere, a GPS fix — plus the thesis's swing sensor. The MAVLink framing and the
//! lockstep protocol live in Python (`swingrt.hil`); nothing here knows about sockets.
//!
//! The ground: the vehicle stands on a flat ground at Down = 0 until its thrust lifts it;
//! while standing, its attitude is level (at its yaw) and it does not move. The payload lies
//! on the ground under it until the vehicle climbs higher than the cables are long; then it
//! is picked up from rest with the vertical momentum shared (an inelastic jerk of the taut
//! cable). When the payload touches the ground again it is set down.

use nalgebra::{UnitQuaternion, Vector3, Vector4};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::runner::{check_state, PlantSample, SimError};
use super::scenario::Scenario;
use super::trace::{Trace, DOUBLE_COLUMNS, TRACE_COLUMNS};
use crate::config::{in_range, non_negative, positive, ConfigError};
use crate::plant::dynamics::swing_angles;
use crate::plant::{
    Effects, Model, PayloadKind, PayloadParams, PlantState, StepInput, Wind, GRAVITY,
};
use crate::sensors::cable::body_angles;
use crate::sensors::{Imu, ImuSample, SwingSource};

/// Mean Earth radius used for the local flat-Earth GPS projection [m].
const EARTH_RADIUS: f64 = 6_371_000.0;
/// ISA sea-level pressure [hPa].
const SEA_LEVEL_HPA: f64 = 1013.25;
/// ISA sea-level temperature [°C].
const SEA_LEVEL_C: f64 = 15.0;
/// ISA temperature lapse rate [K/m].
const LAPSE: f64 = 0.0065;

/// `fields_updated` bits of HIL_SENSOR: accelerometer (0–2), gyro (3–5).
pub const FIELDS_IMU: u32 = 0b11_1111;
/// `fields_updated` bits of HIL_SENSOR: magnetometer (6–8).
pub const FIELDS_MAG: u32 = 0b1_1100_0000;
/// `fields_updated` bits of HIL_SENSOR: absolute pressure (9), pressure altitude (11) and
/// temperature (12).
pub const FIELDS_BARO: u32 = 0b1_1010_0000_0000;

/// Where the simulated vehicle is on Earth and how noisy its sensors are.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HilSettings {
    /// Physics steps per lockstep step: PX4's sensor rate is 1 / (`substeps` × physics_dt).
    pub substeps: u32,
    /// Home latitude [deg] (default: PX4's simulation home, Zürich).
    pub home_lat: f64,
    /// Home longitude [deg].
    pub home_lon: f64,
    /// Home altitude above mean sea level [m].
    pub home_alt: f64,
    /// Earth's magnetic field at home in NED [gauss] (WMM at the default home).
    pub mag_field: [f64; 3],
    /// Accelerometer white noise per sample [m/s²].
    pub accel_std: f64,
    /// Gyro white noise per sample [rad/s].
    pub gyro_std: f64,
    /// Magnetometer white noise per sample [gauss].
    pub mag_std: f64,
    /// Barometer white noise per sample [hPa].
    pub baro_std: f64,
    /// GPS fix rate [Hz] (PX4 wants 5–10).
    pub gps_rate: f64,
    /// Magnetometer and barometer rate [Hz] (a divisor of the sensor rate is used).
    pub mag_baro_rate: f64,
    /// Horizontal and vertical accuracy the GPS reports (eph, epv) [m].
    pub gps_accuracy: [f64; 2],
    /// Satellites the GPS reports.
    pub gps_satellites: u8,
}

impl Default for HilSettings {
    fn default() -> Self {
        Self {
            substeps: 4,
            home_lat: 47.397_742,
            home_lon: 8.545_594,
            home_alt: 488.0,
            mag_field: [0.2153, 0.0117, 0.4291],
            accel_std: 0.02,
            gyro_std: 0.002,
            mag_std: 0.001,
            baro_std: 0.002,
            gps_rate: 10.0,
            mag_baro_rate: 50.0,
            gps_accuracy: [0.5, 0.8],
            gps_satellites: 12,
        }
    }
}

impl HilSettings {
    /// Check the settings; the error names the offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(1..=100).contains(&self.substeps) {
            return Err(ConfigError::new(
                "substeps",
                format!("must be 1..=100 (got {})", self.substeps),
            ));
        }
        in_range("home_lat", self.home_lat, -89.0, 89.0)?;
        in_range("home_lon", self.home_lon, -180.0, 180.0)?;
        in_range("home_alt", self.home_alt, -400.0, 9000.0)?;
        crate::config::all_finite("mag_field", &self.mag_field)?;
        let strength = Vector3::from(self.mag_field).norm();
        if !(0.2..=0.7).contains(&strength) {
            return Err(ConfigError::new(
                "mag_field",
                format!("Earth's field is 0.2–0.7 gauss strong (got {strength:.3})"),
            ));
        }
        non_negative("accel_std", self.accel_std)?;
        non_negative("gyro_std", self.gyro_std)?;
        non_negative("mag_std", self.mag_std)?;
        non_negative("baro_std", self.baro_std)?;
        in_range("gps_rate", self.gps_rate, 1.0, 50.0)?;
        positive("mag_baro_rate", self.mag_baro_rate)?;
        for (i, a) in self.gps_accuracy.iter().enumerate() {
            in_range(&format!("gps_accuracy[{i}]"), *a, 0.01, 100.0)?;
        }
        if self.gps_satellites < 6 {
            return Err(ConfigError::new(
                "gps_satellites",
                format!("PX4 wants at least 6 (got {})", self.gps_satellites),
            ));
        }
        Ok(())
    }
}

/// One GPS fix in HIL_GPS units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpsFix {
    /// Latitude [deg × 1e7].
    pub lat: i32,
    /// Longitude [deg × 1e7].
    pub lon: i32,
    /// Altitude above mean sea level [mm].
    pub alt: i32,
    /// Horizontal accuracy [cm].
    pub eph: u16,
    /// Vertical accuracy [cm].
    pub epv: u16,
    /// Ground speed [cm/s].
    pub vel: u16,
    /// Velocity North, East, Down [cm/s].
    pub vel_ned: [i16; 3],
    /// Course over ground [cdeg], 0–35999.
    pub cog: u16,
    /// Satellites visible.
    pub satellites: u8,
}

/// The sensor readings of one lockstep step, in HIL_SENSOR units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorFrame {
    /// PX4's clock: simulated time since the start [µs], strictly increasing.
    pub time_usec: u64,
    /// Specific force in body FRD [m/s²] (about (0, 0, −g) at rest).
    pub accel: [f64; 3],
    /// Body rates FRD [rad/s].
    pub gyro: [f64; 3],
    /// Magnetic field in body FRD [gauss].
    pub mag: [f64; 3],
    /// Static pressure [hPa].
    pub abs_pressure: f64,
    /// Barometric altitude [m].
    pub pressure_alt: f64,
    /// Air temperature [°C].
    pub temperature: f64,
    /// HIL_SENSOR `fields_updated` bits of this frame.
    pub fields_updated: u32,
    /// A GPS fix when one is due this step.
    pub gps: Option<GpsFix>,
    /// The swing sensor: measured projected angles (N, E) [rad]; NaN when the scenario's
    /// swing source is the IMU (no sensor on the cable).
    pub swing: [f64; 2],
    /// The body cable sensor's ADC readings (x, y) [counts]; NaN unless the swing source is
    /// `body`.
    pub adc: [f64; 2],
    /// Ground truth: attitude quaternion (w, x, y, z), body FRD → NED.
    pub attitude: [f64; 4],
    /// Ground truth: position NED [m].
    pub position: [f64; 3],
    /// Ground truth: velocity NED [m/s].
    pub velocity: [f64; 3],
    /// Ground truth: acceleration NED [m/s²].
    pub acceleration: [f64; 3],
}

/// Vehicle + payload physics served to a PX4 flight controller, one lockstep step at a time.
pub struct HilPlant {
    sc: Scenario,
    settings: HilSettings,
    airborne_model: Model,
    ground_model: Model,
    payload_lifted: bool,
    state: PlantState,
    wind: Wind,
    wind_now: Vector3<f64>,
    rng: ChaCha8Rng,
    h: f64,
    step: u64,
    acc_ned: Vector3<f64>,
    motors: [f64; 4],
    swing_noise: [f64; 2],
    imu: Imu,
    /// Sums of the IMU's errors over the substeps of the current lockstep step, and count.
    imu_errors: ([f64; 6], u32),
    last_imu: ImuSample,
    noise_every: u64,
    gps_every: u64,
    mag_baro_every: u64,
    log_every: u64,
    trace: Trace,
    row: Vec<f64>,
}

/// Extra trace columns of a HIL flight: PX4's motor commands in its rotor order.
pub const MOTOR_COLUMNS: [&str; 4] = ["motor_1", "motor_2", "motor_3", "motor_4"];

impl HilPlant {
    /// The vehicle standing on the ground below the scenario's start point, payload beside
    /// it on the ground, motors off.
    pub fn new(sc: Scenario, settings: HilSettings) -> Result<Self, SimError> {
        sc.validate()?;
        settings.validate().map_err(|e| e.within("hil"))?;
        let h = sc.physics_dt;
        let div = |hz: f64| ((1.0 / (hz * h)).round() as u64).max(1);
        let airborne_model = Model::new(sc.vehicle.clone(), sc.payload.clone());
        let ground_model = Model::new(
            sc.vehicle.clone(),
            PayloadParams {
                kind: PayloadKind::None,
                events: Vec::new(),
                ..sc.payload.clone()
            },
        );
        let state = PlantState::at_rest(Vector3::new(sc.start[0], sc.start[1], 0.0), 0.0, 0.0, 0.0);
        let mut names: Vec<&str> = TRACE_COLUMNS.to_vec();
        if sc.payload.kind == PayloadKind::Double {
            names.extend(DOUBLE_COLUMNS);
        }
        names.extend(MOTOR_COLUMNS);
        let rows = ((sc.duration * sc.log_rate).ceil() as usize + 1).min(360_001);
        let lockstep = settings.substeps as u64;
        // Slower streams run on whole lockstep steps so each frame carries all it updates.
        let per_step = |hz: f64| (div(hz) / lockstep).max(1) * lockstep;
        let total = sc.vehicle.mass + sc.payload.total_mass();
        let imu = Imu::new(sc.sensors.imu.clone(), h, total * GRAVITY / 4.0, sc.seed);
        Ok(Self {
            airborne_model,
            ground_model,
            payload_lifted: false,
            state,
            wind: Wind::new(sc.wind.clone(), sc.seed),
            wind_now: Vector3::zeros(),
            rng: ChaCha8Rng::seed_from_u64(sc.seed ^ 0x4849_4c00),
            h,
            step: 0,
            acc_ned: Vector3::zeros(),
            motors: [0.0; 4],
            swing_noise: [0.0; 2],
            imu,
            imu_errors: ([0.0; 6], 0),
            last_imu: ImuSample {
                accel: [0.0, 0.0, -GRAVITY],
                gyro: [0.0; 3],
            },
            noise_every: div(sc.noise.swing_rate),
            gps_every: per_step(settings.gps_rate),
            mag_baro_every: per_step(settings.mag_baro_rate),
            log_every: div(sc.log_rate),
            trace: Trace::new(&names, rows),
            row: vec![0.0; names.len()],
            settings,
            sc,
        })
    }

    /// Simulated time [s].
    pub fn time(&self) -> f64 {
        self.step as f64 * self.h
    }

    /// Length of one lockstep step [s].
    pub fn step_dt(&self) -> f64 {
        self.settings.substeps as f64 * self.h
    }

    /// The scenario being flown.
    pub fn scenario(&self) -> &Scenario {
        &self.sc
    }

    /// The full plant state.
    pub fn state(&self) -> &PlantState {
        &self.state
    }

    /// Whether the payload hangs from the vehicle (false while it lies on the ground).
    pub fn payload_lifted(&self) -> bool {
        self.payload_lifted
    }

    /// Count the scenario's payload events that are still ahead from `origin` [s] of the
    /// plant's clock on (each one's time plus `origin`): a session that takes off first
    /// times its payload changes from the moment it holds in the air, which its boot and
    /// climb make unknown in advance.
    pub fn count_payload_events_from(&mut self, origin: f64) -> Result<(), SimError> {
        if !(origin.is_finite() && origin >= 0.0) {
            return Err(SimError::Config(crate::config::ConfigError::new(
                "origin",
                "must be a finite time >= 0 [s]",
            )));
        }
        let now = self.time();
        for e in self.airborne_model.payload.events.iter_mut() {
            if e.t >= now {
                e.t += origin;
            }
        }
        Ok(())
    }

    /// Whether the vehicle stands on the ground.
    pub fn on_ground(&self) -> bool {
        self.state.pos.z >= -1e-9
    }

    /// The logged trace so far.
    pub fn trace(&self) -> &Trace {
        &self.trace
    }

    /// Hand the logged trace over (the plant keeps logging into a fresh one).
    pub fn take_trace(&mut self) -> Trace {
        let names: Vec<String> = self.trace.names().to_vec();
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        std::mem::replace(&mut self.trace, Trace::new(&refs, 0))
    }

    fn model(&self) -> &Model {
        if self.payload_lifted {
            &self.airborne_model
        } else {
            &self.ground_model
        }
    }

    /// Advance one lockstep step under PX4's motor commands (normalised, PX4's rotor order;
    /// values outside [0, 1] are clipped, a non-finite command is an error).
    pub fn step(&mut self, motors: [f64; 4]) -> Result<(), SimError> {
        if let Some(i) = motors.iter().position(|m| !m.is_finite()) {
            return Err(SimError::Diverged {
                t: self.time(),
                what: format!("motor {} command is not finite", i + 1),
            });
        }
        self.motors = motors.map(|m| m.clamp(0.0, 1.0));
        let v = &self.sc.vehicle;
        let thrust_sp = Vector4::from(self.motors.map(|m| v.thrust_at(m)));
        let v0 = self.state.vel;
        for _ in 0..self.settings.substeps {
            self.physics_step(thrust_sp)?;
        }
        self.acc_ned = (self.state.vel - v0) / self.step_dt();
        Ok(())
    }

    fn physics_step(&mut self, thrust_sp: Vector4<f64>) -> Result<(), SimError> {
        if self.step % self.noise_every == 0 && self.sc.noise.swing_std > 0.0 {
            for i in 0..2 {
                let z: f64 = StandardNormal.sample(&mut self.rng);
                self.swing_noise[i] = self.sc.noise.swing_std * z;
            }
        }
        if self.step % self.log_every == 0 {
            self.log_row();
        }
        self.wind.advance(self.h);
        self.wind_now = self.wind.at(self.time());
        let u = StepInput {
            thrust_sp,
            wind: self.wind_now,
            external_force: Vector3::zeros(),
        };
        if !self.airborne_model.payload.events.is_empty() {
            self.payload_events();
        }
        let e = self.imu.error_sample(self.state.thrust.into());
        let (sum, n) = &mut self.imu_errors;
        for k in 0..3 {
            sum[k] += e.accel[k];
            sum[k + 3] += e.gyro[k];
        }
        *n += 1;
        let mut next = self
            .model()
            .rk4(&self.state, &u, self.h, Effects::default());
        next.project(self.model().links());
        self.state = next;
        self.ground_contact();
        self.payload_contact();
        self.step += 1;
        check_state(&self.state, self.time())
    }

    /// The ground holds the vehicle up: no sinking, no sliding, level at its yaw.
    fn ground_contact(&mut self) {
        let s = &mut self.state;
        if s.pos.z < 0.0 || (s.pos.z == 0.0 && s.vel.z < 0.0) {
            return;
        }
        s.pos.z = 0.0;
        s.vel = Vector3::zeros();
        s.rate = Vector3::zeros();
        let yaw = UnitQuaternion::from_quaternion(s.att).euler_angles().2;
        s.att = *UnitQuaternion::from_euler_angles(0.0, 0.0, yaw).quaternion();
    }

    /// The scenario's payload events (attach, detach, mass, winch, vehicle mass) on the
    /// plant's clock. An attach lifts the payload from below the vehicle if it is high
    /// enough, else the payload waits on the ground for the pick-up; on the ground the vehicle
    /// carries what the events say it carries.
    fn payload_events(&mut self) {
        let (before, t) = (self.airborne_model.links(), self.time());
        let mut state = self.state;
        if !crate::plant::apply_payload_events(&mut self.airborne_model, &mut state, t, self.h) {
            return;
        }
        let p = &self.airborne_model.payload;
        let reach = p.length + if p.links() == 2 { p.length2 } else { 0.0 };
        if p.links() == 0 {
            self.payload_lifted = false;
        } else if before == 0 {
            // An attach picks up only what hangs free: on or near the ground it waits.
            self.payload_lifted = -self.state.pos.z > reach;
        }
        if self.payload_lifted || p.links() == 0 {
            self.state = state;
        }
        self.ground_model = Model::new(
            self.airborne_model.vehicle.clone(),
            PayloadParams {
                kind: PayloadKind::None,
                events: Vec::new(),
                ..self.airborne_model.payload.clone()
            },
        );
    }

    /// Pick the payload up once the cables are taut; set it down when it touches the ground.
    fn payload_contact(&mut self) {
        let p = &self.airborne_model.payload;
        if p.links() == 0 {
            return;
        }
        let height = -self.state.pos.z;
        if !self.payload_lifted {
            let reach = p.length + if p.links() == 2 { p.length2 } else { 0.0 };
            if height > reach {
                let s = &mut self.state;
                let m = self.airborne_model.vehicle.mass;
                // Inelastic: the taut cable gives the payload the vehicle's velocity and
                // the pair keeps its vertical momentum.
                s.vel *= m / (m + p.total_mass());
                s.n = [Vector3::new(0.0, 0.0, 1.0); 2];
                s.ndot = [Vector3::zeros(); 2];
                self.payload_lifted = true;
            }
        } else {
            let lowest = self.state.payload_position(p, p.links() - 1);
            if lowest.z >= 0.0 {
                self.payload_lifted = false;
            }
        }
    }

    /// True swing of the first link (N, E, rate N, rate E); zeros while it lies on the ground.
    pub fn true_swing(&self) -> [f64; 4] {
        if !self.payload_lifted {
            return [0.0; 4];
        }
        swing_angles(&self.state.n[0], &self.state.ndot[0])
    }

    /// The swing sensor's reading (N, E) [rad]: the world-frame sensor (truth plus the
    /// scenario's sensor noise) or the body sensor composed with the attitude; NaN with the
    /// swing source `imu`.
    pub fn measured_swing(&self) -> [f64; 2] {
        match self.sc.sensors.swing {
            SwingSource::Imu => [f64::NAN; 2],
            _ if self.airborne_model.links() == 0 => [0.0; 2],
            SwingSource::Sensor => {
                let t = self.true_swing();
                [t[0] + self.swing_noise[0], t[1] + self.swing_noise[1]]
            }
            SwingSource::Body => {
                let rot = self.state.rotation();
                self.sc.sensors.body.world_swing(&rot, self.adc_counts())
            }
        }
    }

    /// The body cable sensor's ADC readings (x, y) [counts]; NaN unless the swing source is
    /// `body`. A payload lying on the ground reads as hanging straight down.
    pub fn adc_counts(&self) -> [f64; 2] {
        if self.sc.sensors.swing != SwingSource::Body {
            return [f64::NAN; 2];
        }
        let n = if self.payload_lifted {
            self.state.n[0]
        } else {
            Vector3::new(0.0, 0.0, 1.0)
        };
        let beta = body_angles(&self.state.rotation(), &n);
        let b = &self.sc.sensors.body;
        [
            b.counts(0, beta[0] + self.swing_noise[0]),
            b.counts(1, beta[1] + self.swing_noise[1]),
        ]
    }

    fn gauss3(&mut self, std: f64) -> Vector3<f64> {
        if std == 0.0 {
            return Vector3::zeros();
        }
        Vector3::from_fn(|_, _| {
            let z: f64 = StandardNormal.sample(&mut self.rng);
            std * z
        })
    }

    fn gauss(&mut self, std: f64) -> f64 {
        if std == 0.0 {
            return 0.0;
        }
        let z: f64 = StandardNormal.sample(&mut self.rng);
        std * z
    }

    /// The sensor readings at the current time (call once per lockstep step, before
    /// [`Self::step`]).
    pub fn sensors(&mut self) -> SensorFrame {
        let s = self.state;
        let r = s.rotation();
        let g = Vector3::new(0.0, 0.0, GRAVITY);
        let st = self.settings.clone();
        // The IMU's errors averaged over the step, as PX4's delta-velocity integration of a
        // fast-sampled sensor averages them.
        let (sum, n) = std::mem::replace(&mut self.imu_errors, ([0.0; 6], 0));
        let n = f64::from(n.max(1));
        let err_a = Vector3::new(sum[0], sum[1], sum[2]) / n;
        let err_g = Vector3::new(sum[3], sum[4], sum[5]) / n;
        let accel = r.transpose() * (self.acc_ned - g) + err_a + self.gauss3(st.accel_std);
        let gyro = s.rate + err_g + self.gauss3(st.gyro_std);
        self.last_imu = ImuSample {
            accel: accel.into(),
            gyro: gyro.into(),
        };
        let mag = r.transpose() * Vector3::from(st.mag_field) + self.gauss3(st.mag_std);
        let alt = st.home_alt - s.pos.z;
        let pressure = SEA_LEVEL_HPA * (1.0 - 2.255_77e-5 * alt).powf(5.255_88);
        let abs_pressure = pressure + self.gauss(st.baro_std);
        let mut fields = FIELDS_IMU;
        if self.step % self.mag_baro_every == 0 {
            fields |= FIELDS_MAG | FIELDS_BARO;
        }
        let gps = (self.step % self.gps_every == 0).then(|| self.gps_fix());
        SensorFrame {
            // PX4 wants a clock that starts above zero.
            time_usec: (self.step as f64 * self.h * 1e6).round() as u64 + 1,
            accel: accel.into(),
            gyro: gyro.into(),
            mag: mag.into(),
            abs_pressure,
            pressure_alt: alt,
            temperature: SEA_LEVEL_C - LAPSE * alt,
            fields_updated: fields,
            gps,
            swing: self.measured_swing(),
            adc: self.adc_counts(),
            attitude: [s.att.w, s.att.i, s.att.j, s.att.k],
            position: s.pos.into(),
            velocity: s.vel.into(),
            acceleration: self.acc_ned.into(),
        }
    }

    fn gps_fix(&self) -> GpsFix {
        let st = &self.settings;
        let s = &self.state;
        let lat0 = st.home_lat.to_radians();
        let lat = st.home_lat + (s.pos.x / EARTH_RADIUS).to_degrees();
        let lon = st.home_lon + (s.pos.y / (EARTH_RADIUS * lat0.cos())).to_degrees();
        let cm = |v: f64| (v * 100.0).round().clamp(-32767.0, 32767.0) as i16;
        let ground = (s.vel.x.hypot(s.vel.y) * 100.0).round().min(65534.0) as u16;
        let cog = if ground > 0 {
            (s.vel.y.atan2(s.vel.x).to_degrees().rem_euclid(360.0) * 100.0).round() as u16 % 36000
        } else {
            0
        };
        GpsFix {
            lat: (lat * 1e7).round() as i32,
            lon: (lon * 1e7).round() as i32,
            alt: ((st.home_alt - s.pos.z) * 1000.0).round() as i32,
            eph: (st.gps_accuracy[0] * 100.0).round() as u16,
            epv: (st.gps_accuracy[1] * 100.0).round() as u16,
            vel: ground,
            vel_ned: [cm(s.vel.x), cm(s.vel.y), cm(s.vel.z)],
            cog,
            satellites: st.gps_satellites,
        }
    }

    fn log_row(&mut self) {
        let s = &self.state;
        let truth = self.true_swing();
        let meas = self.measured_swing();
        let payload = if self.payload_lifted {
            s.payload_position(&self.airborne_model.payload, 0)
        } else {
            s.pos
        };
        // PX4's setpoints are PX4's (its ULog has them): NaN here.
        let row = PlantSample {
            t: self.time(),
            state: s,
            measured: meas,
            truth,
            payload,
            wind: self.wind_now,
            imu: self.last_imu,
            adc: self.adc_counts(),
            estimate: [f64::NAN; 2],
        }
        .row();
        let vals = row.values();
        let mut k = vals.len();
        self.row[..k].copy_from_slice(&vals);
        if self.sc.payload.kind == PayloadKind::Double {
            let [s2n, s2e, _, _] = if self.payload_lifted {
                swing_angles(&s.n[1], &s.ndot[1])
            } else {
                [0.0; 4]
            };
            self.row[k] = s2n;
            self.row[k + 1] = s2e;
            k += 2;
        }
        self.row[k..k + 4].copy_from_slice(&self.motors);
        self.trace.push(&self.row);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plant(payload: &str) -> HilPlant {
        let mut sc = Scenario::builtin("hover").unwrap();
        sc.payload.kind = match payload {
            "none" => PayloadKind::None,
            _ => PayloadKind::Single,
        };
        sc.sensors.imu = crate::sensors::ImuParams::ideal();
        let settings = HilSettings {
            accel_std: 0.0,
            gyro_std: 0.0,
            mag_std: 0.0,
            baro_std: 0.0,
            ..HilSettings::default()
        };
        HilPlant::new(sc, settings).unwrap()
    }

    #[test]
    fn standing_vehicle_feels_one_g_up_and_reads_home() {
        let mut p = plant("single");
        for _ in 0..50 {
            p.sensors();
            p.step([0.0; 4]).unwrap();
        }
        let f = p.sensors();
        assert!((f.accel[2] + GRAVITY).abs() < 1e-9, "{:?}", f.accel);
        assert!(f.accel[0].abs() < 1e-9 && f.accel[1].abs() < 1e-9);
        assert_eq!(f.position[2], 0.0);
        let st = HilSettings::default();
        assert!((f.pressure_alt - st.home_alt).abs() < 1e-9);
        // ISA at 488 m: 955.98 hPa and 11.83 °C.
        assert!((f.abs_pressure - 955.98).abs() < 0.01, "{}", f.abs_pressure);
        assert!((f.temperature - 11.828).abs() < 1e-3);
        // Level at yaw 0: the body field is the NED field.
        for i in 0..3 {
            assert!((f.mag[i] - st.mag_field[i]).abs() < 1e-12);
        }
        assert!(!p.payload_lifted());
    }

    #[test]
    fn clock_is_strictly_increasing_and_streams_have_their_rates() {
        let mut p = plant("single");
        let mut last = 0;
        let (mut gps, mut mag) = (0, 0);
        for _ in 0..250 {
            let f = p.sensors();
            assert!(f.time_usec > last);
            last = f.time_usec;
            gps += f.gps.is_some() as u32;
            mag += (f.fields_updated & FIELDS_MAG != 0) as u32;
            assert_eq!(f.fields_updated & FIELDS_IMU, FIELDS_IMU);
            p.step([0.0; 4]).unwrap();
        }
        assert_eq!(last, 996_001);
        assert_eq!(gps, 10);
        assert_eq!(mag, 50);
    }

    #[test]
    fn hover_command_balances_weight_and_free_fall_reads_zero() {
        let mut p = plant("none");
        let w = p.scenario().vehicle.mass * GRAVITY / 4.0;
        let cmd = p.scenario().vehicle.command_for_thrust(w);
        // Lift off slightly, then hold the hover command: the specific force is −g in z.
        p.state.pos.z = -5.0;
        p.state.thrust = Vector4::repeat(w);
        for _ in 0..100 {
            p.step([cmd; 4]).unwrap();
        }
        let f = p.sensors();
        assert!((f.accel[2] + GRAVITY).abs() < 1e-3, "{:?}", f.accel);
        assert!(f.velocity[2].abs() < 1e-3);
        // Motors off in the air: falling, the accelerometer reads only what is not gravity,
        // the decaying motor thrust and the drag of the fall (level, so body z is Down).
        for _ in 0..25 {
            p.step([0.0; 4]).unwrap();
        }
        let f = p.sensors();
        let v = &p.scenario().vehicle;
        let vz = p.state.vel.z;
        let drag = 0.5 * v.air_density * v.drag[2] * vz * vz;
        let expected = -(p.state.thrust.sum() + drag) / v.mass;
        assert!(
            (f.accel[2] - expected).abs() < 0.05,
            "{:?} vs {expected}",
            f.accel
        );
        assert!(f.acceleration[2] > 9.0);
    }

    #[test]
    fn payload_is_picked_up_above_cable_length_with_momentum_shared() {
        let mut p = plant("single");
        let sc = p.scenario().clone();
        let m = sc.vehicle.mass;
        let mp = sc.payload.mass;
        p.state.pos.z = -(sc.payload.length - 0.001);
        p.state.vel.z = -1.0;
        p.payload_contact();
        assert!(!p.payload_lifted());
        p.state.pos.z = -(sc.payload.length + 0.001);
        p.payload_contact();
        assert!(p.payload_lifted());
        assert!((p.state.vel.z + m / (m + mp)).abs() < 1e-12);
        assert_eq!(p.true_swing(), [0.0; 4]);
    }

    #[test]
    fn gps_projection_inverts_on_a_north_east_offset() {
        let mut p = plant("none");
        p.state.pos = Vector3::new(100.0, -50.0, -20.0);
        p.state.vel = Vector3::new(0.0, -2.0, 0.5);
        let f = p.gps_fix();
        let st = HilSettings::default();
        let dn = (f.lat as f64 * 1e-7 - st.home_lat).to_radians() * EARTH_RADIUS;
        let de = (f.lon as f64 * 1e-7 - st.home_lon).to_radians()
            * EARTH_RADIUS
            * st.home_lat.to_radians().cos();
        assert!(
            (dn - 100.0).abs() < 0.02 && (de + 50.0).abs() < 0.02,
            "{dn} {de}"
        );
        assert_eq!(f.alt, 508_000);
        assert_eq!(f.vel_ned, [0, -200, 50]);
        assert_eq!(f.vel, 200);
        assert_eq!(f.cog, 27000);
    }

    #[test]
    fn payload_events_attach_in_the_air_and_detach() {
        use crate::plant::events::{PayloadAction, PayloadEvent};
        let mut sc = Scenario::builtin("hover").unwrap();
        sc.payload.kind = PayloadKind::None;
        let ev = |t: f64, action| PayloadEvent {
            t,
            action,
            mass: None,
            length: None,
            rate: None,
        };
        sc.payload.events = vec![
            PayloadEvent {
                mass: Some(0.3),
                length: Some(1.5),
                ..ev(0.1, PayloadAction::Attach)
            },
            ev(0.2, PayloadAction::Detach),
        ];
        let mut p = HilPlant::new(sc, HilSettings::default()).unwrap();
        let m = p.scenario().vehicle.mass;
        let cmd = p.scenario().vehicle.command_for_thrust(m * GRAVITY / 4.0);
        p.state.pos.z = -10.0;
        p.state.vel.z = -0.5;
        p.state.thrust = Vector4::repeat(m * GRAVITY / 4.0);
        p.step([cmd; 4]).unwrap(); // 4 ms, before the attach
        assert!(!p.payload_lifted());
        while p.time() < 0.104 {
            p.step([cmd; 4]).unwrap();
        }
        assert!(
            p.payload_lifted(),
            "attached in the air, 10 m up on a 1.5 m cable"
        );
        assert!((p.airborne_model.payload.mass - 0.3).abs() < 1e-12);
        let f = p.sensors();
        assert_eq!(f.swing, [0.0, 0.0]); // picked up hanging straight down
        while p.time() < 0.204 {
            p.step([cmd; 4]).unwrap();
        }
        assert!(!p.payload_lifted());
        assert_eq!(p.model().links(), 0);
    }

    #[test]
    fn payload_events_counted_from_an_origin_wait_for_it() {
        use crate::plant::events::{PayloadAction, PayloadEvent};
        let mut sc = Scenario::builtin("hover").unwrap();
        sc.payload.length = 1.0;
        sc.payload.events = vec![PayloadEvent {
            t: 0.02,
            action: PayloadAction::Winch,
            mass: None,
            length: Some(0.5),
            rate: Some(1.0),
        }];
        let mut p = HilPlant::new(sc, HilSettings::default()).unwrap();
        let m = p.scenario().vehicle.mass + p.scenario().payload.mass;
        let cmd = p.scenario().vehicle.command_for_thrust(m * GRAVITY / 4.0);
        p.state.pos.z = -10.0;
        p.state.thrust = Vector4::repeat(m * GRAVITY / 4.0);
        p.payload_lifted = true;
        p.step([cmd; 4]).unwrap();
        let origin = p.time();
        p.count_payload_events_from(origin).unwrap();
        while p.time() < origin + 0.02 - 1e-9 {
            p.step([cmd; 4]).unwrap();
        }
        assert_eq!(
            p.airborne_model.payload.length, 1.0,
            "not yet: 0.02 s after the origin"
        );
        while p.time() < origin + 0.12 - 1e-9 {
            p.step([cmd; 4]).unwrap();
        }
        // 0.1 s of winching at 1 m/s.
        let l = p.airborne_model.payload.length;
        assert!((l - 0.9).abs() < 0.005, "{l}");
        assert!(p.count_payload_events_from(f64::NAN).is_err());
    }

    #[test]
    fn non_finite_motor_command_is_an_error_not_a_panic() {
        let mut p = plant("single");
        let e = p.step([0.5, f64::NAN, 0.5, 0.5]).unwrap_err();
        assert!(e.to_string().contains("motor 2"), "{e}");
    }

    #[test]
    fn settings_errors_name_the_field() {
        let bad = HilSettings {
            mag_field: [0.0, 0.0, 0.01],
            ..HilSettings::default()
        };
        let sc = Scenario::builtin("hover").unwrap();
        let e = HilPlant::new(sc, bad).err().unwrap();
        assert!(e.to_string().contains("hil.mag_field"), "{e}");
    }
}
