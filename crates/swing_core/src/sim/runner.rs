//! The multi-rate closed-loop runner: plant at the physics step (RK4, 1 ms default), PX4's
//! rate, attitude and position/velocity loops at their own rates, an optional swing-damping
//! controller in place of PX4's velocity PID, sensor noise, wind and a 100 Hz trace.
//!
//! All loop periods are integer multiples of the physics step, so a run is a pure function
//! of the scenario (and its seed).

use nalgebra::{UnitQuaternion, Vector3, Vector4};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use thiserror::Error;

use super::scenario::{Scenario, SetpointEntry};
use super::supervisor::{ControllerSupervisor, TickInputs};
use super::ticker::Ticker;
use super::trace::{StateExtras, Trace, TraceRow, DOUBLE_COLUMNS, STATE_KEYS, TRACE_COLUMNS};
use crate::config::ConfigError;
use crate::control::px4::{AxisSetpoint, Px4Cascade, Setpoint};
use crate::control::SwingController;
use crate::error::{Categorized, Category};
use crate::mission::{Guidance, MissionEvent};
use crate::plant::dynamics::swing_angles;
use crate::plant::{Effects, Model, PayloadKind, PlantState, StepInput, Wind, GRAVITY};
use crate::sensors::cable::body_angles;
use crate::sensors::{
    Imu, ImuSample, ImuSwingEstimator, ImuSwingSettings, SwingFilter, SwingSource,
};

/// Errors of a simulation run.
#[derive(Debug, Error)]
pub enum SimError {
    /// The scenario or a runner setting is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The state became non-finite or left any sensible range.
    #[error("simulation diverged at t = {t:.3} s: {what}")]
    Diverged {
        /// Time of detection [s].
        t: f64,
        /// What went wrong.
        what: String,
    },
}

impl Categorized for SimError {
    fn category(&self) -> Category {
        match self {
            SimError::Config(_) => Category::Config,
            SimError::Diverged { .. } => Category::Simulation,
        }
    }

    fn field(&self) -> Option<&str> {
        match self {
            SimError::Config(e) => Some(&e.field),
            SimError::Diverged { .. } => None,
        }
    }
}

/// A vehicle state a trace row can show: finite, and within any sensible flight envelope.
pub(crate) fn check_state(s: &PlantState, t: f64) -> Result<(), SimError> {
    let ok = s.pos.iter().all(|x| x.is_finite() && x.abs() < 1e6)
        && s.vel.iter().all(|x| x.is_finite() && x.abs() < 1e3)
        && s.rate.iter().all(|x| x.is_finite() && x.abs() < 1e4)
        && s.att.coords.iter().all(|x| x.is_finite());
    if ok {
        Ok(())
    } else {
        Err(SimError::Diverged {
            t,
            what: "vehicle state is not finite or out of range".into(),
        })
    }
}

/// What the plant contributes to a trace row (every column but the controller's).
pub(crate) struct PlantSample<'a> {
    /// Time [s].
    pub t: f64,
    /// The plant state.
    pub state: &'a PlantState,
    /// Measured swing (N, E) [rad].
    pub measured: [f64; 2],
    /// True swing and rates (N, E, rate N, rate E).
    pub truth: [f64; 4],
    /// Position of the (first) payload mass, NED [m].
    pub payload: Vector3<f64>,
    /// Wind, NED [m/s].
    pub wind: Vector3<f64>,
    /// The IMU's reading (body FRD).
    pub imu: ImuSample,
    /// The body cable sensor's ADC readings (x, y) [counts]; NaN without one.
    pub adc: [f64; 2],
    /// The swing estimated from the IMU (N, E) [rad]; NaN without an estimate.
    pub estimate: [f64; 2],
}

impl PlantSample<'_> {
    /// The row with the controller's columns NaN (setpoints) and 0 (flags).
    pub fn row(&self) -> TraceRow {
        let s = self.state;
        let (roll, pitch, yaw) = UnitQuaternion::from_quaternion(s.att).euler_angles();
        TraceRow {
            t: self.t,
            pn: s.pos.x,
            pe: s.pos.y,
            pd: s.pos.z,
            vn: s.vel.x,
            ve: s.vel.y,
            vd: s.vel.z,
            roll,
            pitch,
            yaw,
            swing_n: self.measured[0],
            swing_e: self.measured[1],
            swing_rate_n: self.truth[2],
            swing_rate_e: self.truth[3],
            acc_sp_n: f64::NAN,
            acc_sp_e: f64::NAN,
            acc_sp_d: f64::NAN,
            vel_sp_n: f64::NAN,
            vel_sp_e: f64::NAN,
            vel_sp_d: f64::NAN,
            thrust: s.thrust.sum(),
            wind_n: self.wind.x,
            wind_e: self.wind.y,
            wind_d: self.wind.z,
            swing_true_n: self.truth[0],
            swing_true_e: self.truth[1],
            payload_pn: self.payload.x,
            payload_pe: self.payload.y,
            payload_pd: self.payload.z,
            ctrl_active: 0.0,
            fallback: 0.0,
            imu_ax: self.imu.accel[0],
            imu_ay: self.imu.accel[1],
            imu_az: self.imu.accel[2],
            imu_gx: self.imu.gyro[0],
            imu_gy: self.imu.gyro[1],
            imu_gz: self.imu.gyro[2],
            adc_x: self.adc[0],
            adc_y: self.adc[1],
            swing_est_n: self.estimate[0],
            swing_est_e: self.estimate[1],
        }
    }
}

/// Timing statistics of the swing controller's ticks (wall clock; not part of the trace).
#[derive(Clone, Debug, Default)]
pub struct TickStats {
    /// Compute time of every tick [µs].
    pub tick_us: Vec<f64>,
    /// Ticks that needed the constrained QP.
    pub constrained: usize,
}

/// A steppable closed-loop simulation of vehicle, payload, PX4 cascade and wind.
pub struct Simulator {
    sc: Scenario,
    model: Model,
    fx: Effects,
    state: PlantState,
    fc: Px4Cascade,
    wind: Wind,
    wind_now: Vector3<f64>,
    rng: ChaCha8Rng,
    h: f64,
    step: u64,
    end_step: u64,
    tick_rate: Ticker,
    tick_att: Ticker,
    tick_pos: Ticker,
    tick_log: Ticker,
    tick_noise: Ticker,
    schedule: Vec<SetpointEntry>,
    next_entry: usize,
    sp: Setpoint,
    motor_sp: Vector4<f64>,
    swing_noise: [f64; 2],
    meas_pos: Vector3<f64>,
    meas_vel: Vector3<f64>,
    acc_bias: Vector3<f64>,
    imu: Imu,
    swing_est: Option<ImuSwingEstimator>,
    /// The body sensor's swing differentiated for the controller's swing rate.
    body_rate: SwingFilter,
    tick_est: Ticker,
    supervisor: ControllerSupervisor,
    /// The mission's guidance, when one is flown, and its start time [s].
    guidance: Option<(Box<dyn Guidance>, f64)>,
    guidance_started: bool,
    trace: Trace,
    row: Vec<f64>,
}

/// Trace rows reserved when a simulator is built (the rest grow on demand).
const PREALLOCATED_ROWS: usize = 360_001;

impl Simulator {
    /// Build a simulator at trimmed hover from a scenario (validated here).
    pub fn new(sc: Scenario) -> Result<Self, SimError> {
        sc.validate()?;
        let h = sc.physics_dt;
        let div = |hz: f64| ((1.0 / (hz * h)).round() as u64).max(1);
        let model = Model::new(sc.vehicle.clone(), sc.payload.clone());
        let total = model.total_mass();
        let hover_total = Px4Cascade::hover_thrust_for(&sc.vehicle, total);
        if hover_total > sc.controller.thrust_max * 0.9 {
            return Err(ConfigError::new(
                "payload.mass",
                format!(
                    "vehicle and payload ({total:.3} kg) need {:.0} % thrust to hover; too heavy",
                    hover_total * 100.0
                ),
            )
            .into());
        }
        let believed = sc.controller.hover_thrust.unwrap_or(hover_total);
        let mut fc = Px4Cascade::new(sc.controller.clone(), believed);
        fc.trim_collective(hover_total);
        let start = Vector3::from(sc.start);
        let p = &sc.payload;
        let mut state = PlantState::at_rest(
            start,
            total * crate::plant::GRAVITY / 4.0,
            p.initial_swing_n,
            p.initial_swing_e,
        );
        state.project(model.links());
        let mut names: Vec<&str> = TRACE_COLUMNS.to_vec();
        if sc.payload.kind == PayloadKind::Double {
            names.extend(DOUBLE_COLUMNS);
        }
        // Reserve at most an hour at 100 Hz up front; a longer trace grows as it is logged.
        let rows = ((sc.duration * sc.log_rate).ceil() as usize + 1).min(PREALLOCATED_ROWS);
        let schedule = sc.schedule();
        let wind = Wind::new(sc.wind.clone(), sc.seed);
        let acc_bias = Vector3::new(sc.noise.acc_sp_bias[0], sc.noise.acc_sp_bias[1], 0.0);
        let mut imu = Imu::new(sc.sensors.imu.clone(), h, total * GRAVITY / 4.0, sc.seed);
        imu.settle(ImuSample {
            accel: [0.0, 0.0, -GRAVITY],
            gyro: [0.0; 3],
        });
        let mut sim = Self {
            model,
            fx: Effects::default(),
            state,
            motor_sp: Vector4::repeat(total * crate::plant::GRAVITY / 4.0),
            wind_now: wind.at(0.0),
            wind,
            rng: ChaCha8Rng::seed_from_u64(sc.seed ^ 0x4e4f_4953),
            h,
            step: 0,
            end_step: (sc.duration / h).round() as u64,
            tick_rate: Ticker::new(div(sc.controller.rate_loop_hz)),
            tick_att: Ticker::new(div(sc.controller.att_loop_hz)),
            tick_pos: Ticker::new(div(sc.controller.pos_loop_hz)),
            tick_log: Ticker::new(div(sc.log_rate)),
            tick_noise: Ticker::new(div(sc.noise.swing_rate)),
            schedule,
            next_entry: 0,
            sp: Setpoint::hold(start),
            swing_noise: [0.0; 2],
            meas_pos: start,
            meas_vel: Vector3::zeros(),
            acc_bias,
            imu,
            swing_est: None,
            body_rate: SwingFilter::new(1.0 / h, 0.0),
            tick_est: Ticker::new(1),
            supervisor: ControllerSupervisor::default(),
            guidance: None,
            guidance_started: false,
            trace: Trace::new(&names, rows),
            row: vec![0.0; names.len()],
            fc,
            sc,
        };
        // The IMU's swing estimate is always logged next to the true swing; with the swing
        // source `imu` the controller flies on it.
        // Its rate is rounded to one the physics step divides (the scenario's physics_dt is free).
        let mut est = sim.sc.sensors.estimator.clone();
        est.rate = 1.0 / (h * (1.0 / (est.rate * h)).round().max(1.0));
        sim.set_swing_estimator(est)?;
        sim.apply_schedule();
        Ok(sim)
    }

    /// Replace PX4's velocity PID on the controller's axes from time `engage_at` [s] on (with
    /// the swing source `imu`, not before the estimator's tare is over: until then the
    /// estimate reads the accelerometer's bias as swing).
    ///
    /// A tick whose compute time exceeds `budget` [s] or that fails hands the axes back to
    /// PX4's velocity PID for the rest of the run (logged as `fallback` = 1).
    pub fn attach_controller(
        &mut self,
        ctrl: Box<dyn SwingController>,
        engage_at: f64,
        budget: f64,
    ) -> Result<(), SimError> {
        self.supervisor
            .attach(ctrl, engage_at, budget, self.h, self.step)?;
        Ok(())
    }

    /// Fly a mission: from time `start_at` [s] on, the guidance's trajectory setpoint
    /// replaces the scenario's setpoints on all three axes at every position-loop tick
    /// (PX4's cascade flies it, or the attached swing controller tracks it).
    pub fn fly_mission(
        &mut self,
        guidance: Box<dyn Guidance>,
        start_at: f64,
    ) -> Result<(), SimError> {
        crate::config::non_negative("mission.start_at", start_at)?;
        self.guidance = Some((guidance, start_at));
        self.guidance_started = false;
        Ok(())
    }

    /// Whether the mission flown is complete (false without one).
    pub fn mission_done(&self) -> bool {
        self.guidance.as_ref().is_some_and(|(g, _)| g.done())
    }

    /// The mission's events so far (empty without one).
    pub fn mission_events(&self) -> &[MissionEvent] {
        self.guidance.as_ref().map_or(&[], |(g, _)| g.events())
    }

    /// Predicted outputs of the attached controller's last tick, if it predicts.
    pub fn controller_prediction(&mut self) -> Option<Vec<f64>> {
        self.supervisor.prediction()
    }

    /// Events of the attached controller so far as (time [s], what, value), e.g. an
    /// adaptive MPC's detections and model swaps.
    pub fn controller_events(&self) -> Vec<(f64, &'static str, f64)> {
        self.supervisor.events()
    }

    /// Estimate the swing from the IMU with `settings` from now on (fed every
    /// 1/`settings.rate` s, the tare starting now); with the scenario's swing source `imu` the
    /// controller flies on this estimate and its rate, and the trace logs it as `swing_est_*`.
    /// With the swing source `body` the sensor's reading is differentiated for the swing rate
    /// at the same rate and cutoff.
    pub fn set_swing_estimator(&mut self, settings: ImuSwingSettings) -> Result<(), SimError> {
        let steps = 1.0 / (settings.rate * self.h);
        if !(steps >= 1.0 - 1e-9 && (steps - steps.round()).abs() < 1e-6) {
            return Err(ConfigError::new(
                "swing_estimator.rate",
                format!(
                    "must divide the physics rate {} Hz evenly (got {} Hz)",
                    1.0 / self.h,
                    settings.rate
                ),
            )
            .into());
        }
        let body_rate = SwingFilter::new(settings.rate, settings.cutoff);
        let est = ImuSwingEstimator::new(settings).map_err(|e| e.within("swing_estimator"))?;
        self.tick_est = Ticker::at_step(steps.round() as u64, self.step);
        self.body_rate = body_rate;
        self.swing_est = Some(est);
        Ok(())
    }

    /// The IMU's latest filtered reading.
    pub fn imu_sample(&self) -> ImuSample {
        self.imu.filtered()
    }

    /// The latest swing estimate from the IMU (N, E) [rad], if an estimator is set.
    pub fn swing_estimate(&self) -> Option<[f64; 2]> {
        self.swing_est.as_ref().map(ImuSwingEstimator::estimate)
    }

    /// Switch idealised effects (drag, friction, rotors) for experiments.
    pub fn set_effects(&mut self, fx: Effects) {
        self.fx = fx;
    }

    /// Override the setpoint of one axis (0 = N, 1 = E, 2 = D) from now on.
    pub fn set_setpoint(&mut self, axis: usize, sp: AxisSetpoint) {
        if axis < 3 {
            self.sp.axes[axis] = sp;
        }
    }

    /// Current time [s].
    pub fn time(&self) -> f64 {
        self.step as f64 * self.h
    }

    /// Scenario duration [s].
    pub fn duration(&self) -> f64 {
        self.sc.duration
    }

    /// The scenario this simulator runs.
    pub fn scenario(&self) -> &Scenario {
        &self.sc
    }

    /// The true plant state.
    pub fn state(&self) -> &PlantState {
        &self.state
    }

    /// The plant model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The PX4 cascade (setpoints and integrators).
    pub fn cascade(&self) -> &Px4Cascade {
        &self.fc
    }

    /// The trace logged so far.
    pub fn trace(&self) -> &Trace {
        &self.trace
    }

    /// Take the trace out, leaving an empty one with the same columns.
    pub fn take_trace(&mut self) -> Trace {
        let names: Vec<String> = self.trace.names().to_vec();
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        std::mem::replace(&mut self.trace, Trace::new(&refs, 0))
    }

    /// Controller tick timings so far.
    pub fn tick_stats(&self) -> &TickStats {
        self.supervisor.stats()
    }

    /// Why the controller was handed back to PX4, if it was.
    pub fn fallback_reason(&self) -> Option<&str> {
        self.supervisor.fallback_reason()
    }

    /// The latest swing reading (N, E) [rad] of the flight's swing sensor: the world-frame
    /// sensor (truth plus noise) or the body sensor composed with the attitude; NaN when the
    /// swing source is the IMU (no sensor on the cable, see [`Self::swing_estimate`]).
    pub fn measured_swing(&self) -> [f64; 2] {
        match self.sc.sensors.swing {
            SwingSource::Imu => [f64::NAN; 2],
            _ if self.model.links() == 0 => [0.0, 0.0],
            SwingSource::Sensor => {
                let [sn, se, _, _] = swing_angles(&self.state.n[0], &self.state.ndot[0]);
                [sn + self.swing_noise[0], se + self.swing_noise[1]]
            }
            SwingSource::Body => {
                let rot = self.state.rotation();
                self.sc.sensors.body.world_swing(&rot, self.adc_counts())
            }
        }
    }

    /// The body cable sensor's ADC readings (x, y) [counts] of the cable's body angles plus
    /// the swing-sensor noise; NaN unless the swing source is `body`.
    pub fn adc_counts(&self) -> [f64; 2] {
        if self.sc.sensors.swing != SwingSource::Body {
            return [f64::NAN; 2];
        }
        let n = if self.model.links() == 0 {
            Vector3::new(0.0, 0.0, 1.0)
        } else {
            self.state.n[0]
        };
        let beta = body_angles(&self.state.rotation(), &n);
        let b = &self.sc.sensors.body;
        [
            b.counts(0, beta[0] + self.swing_noise[0]),
            b.counts(1, beta[1] + self.swing_noise[1]),
        ]
    }

    /// What the controller reads as the swing: the sensor's reading, or with the swing
    /// source `imu` the IMU estimate (NaN when no estimator is set).
    fn controller_swing(&self) -> [f64; 2] {
        match self.sc.sensors.swing {
            SwingSource::Imu => self.swing_estimate().unwrap_or([f64::NAN; 2]),
            _ => self.measured_swing(),
        }
    }

    /// What the controller reads as the swing rate, from the same measurement as
    /// [`Self::controller_swing`]: the swing sensor's rate (`sensor`), the body sensor's
    /// reading differentiated through [`SwingFilter`] (`body`), the IMU estimate's filtered
    /// derivative (`imu`; NaN when no estimator is set).
    fn controller_swing_rate(&self) -> [f64; 2] {
        match self.sc.sensors.swing {
            SwingSource::Sensor => {
                let t = self.true_swing();
                [t[2], t[3]]
            }
            SwingSource::Body => self.body_rate.rate(),
            SwingSource::Imu => self
                .swing_est
                .as_ref()
                .map_or([f64::NAN; 2], ImuSwingEstimator::rate_estimate),
        }
    }

    /// True swing angles and rates of the first link: (N, E, rate N, rate E).
    pub fn true_swing(&self) -> [f64; 4] {
        if self.model.links() == 0 {
            return [0.0; 4];
        }
        swing_angles(&self.state.n[0], &self.state.ndot[0])
    }

    /// Advance by `seconds` (rounded to whole physics steps), logging as it goes.
    pub fn advance(&mut self, seconds: f64) -> Result<(), SimError> {
        let n = (seconds / self.h).round().max(0.0) as u64;
        for _ in 0..n {
            self.physics_step()?;
        }
        Ok(())
    }

    /// Run until the scenario's duration and log the final sample.
    pub fn run_to_end(&mut self) -> Result<(), SimError> {
        while self.step < self.end_step {
            self.physics_step()?;
        }
        if self.step % self.tick_log.div() == 0 {
            self.log_row();
        }
        Ok(())
    }

    /// Run the whole scenario and return its trace.
    pub fn run(sc: Scenario) -> Result<Trace, SimError> {
        let mut sim = Simulator::new(sc)?;
        sim.run_to_end()?;
        Ok(sim.take_trace())
    }

    /// Steps remaining until the scenario's end.
    pub fn steps_left(&self) -> u64 {
        self.end_step.saturating_sub(self.step)
    }

    fn apply_schedule(&mut self) {
        let t = self.time() + 1e-9;
        while self.next_entry < self.schedule.len() && self.schedule[self.next_entry].t <= t {
            let e = self.schedule[self.next_entry].clone();
            for i in 0..3 {
                if let Some(sp) = e.axis(i) {
                    self.sp.axes[i] = sp;
                }
            }
            if let Some(y) = e.yaw {
                self.sp.yaw = y;
            }
            self.next_entry += 1;
        }
    }

    fn physics_step(&mut self) -> Result<(), SimError> {
        if self.next_entry < self.schedule.len() {
            self.apply_schedule();
        }
        let noise_due = self.tick_noise.due();
        if self.sc.noise.swing_std > 0.0 && noise_due {
            for i in 0..2 {
                let z: f64 = StandardNormal.sample(&mut self.rng);
                self.swing_noise[i] = self.sc.noise.swing_std * z;
            }
        }
        let pos_due = self.tick_pos.due();
        if pos_due {
            self.measure_translation();
            self.guidance_tick();
        }
        if self.supervisor.due() {
            self.controller_tick();
        }
        if pos_due {
            let mut sp = self.sp;
            self.supervisor.override_setpoint(&mut sp);
            let dt = self.tick_pos.div() as f64 * self.h;
            self.fc
                .position_velocity(&sp, &self.meas_pos, &self.meas_vel, dt, &self.acc_bias);
        }
        if self.tick_att.due() {
            self.fc.attitude(&self.state.att);
        }
        if self.tick_rate.due() {
            let dt = self.tick_rate.div() as f64 * self.h;
            self.fc.rates(&self.state.rate, dt);
            self.motor_sp = self.fc.motor_thrust_setpoints(&self.sc.vehicle);
        }
        if self.tick_log.due() {
            self.log_row();
            self.check_finite()?;
        }
        let t = self.time();
        if !self.model.payload.events.is_empty() {
            crate::plant::apply_payload_events(&mut self.model, &mut self.state, t, self.h);
        }
        self.wind.advance(self.h);
        self.wind_now = self.wind.at(t);
        let u = StepInput {
            thrust_sp: self.motor_sp,
            wind: self.wind_now,
            external_force: Vector3::zeros(),
        };
        let k1 = self.model.derivative(&self.state, &u, self.fx);
        self.sample_imu(&k1.vel);
        self.state = self.model.rk4_from(&self.state, &k1, &u, self.h, self.fx);
        self.step += 1;
        Ok(())
    }

    /// One position-loop tick of the mission's guidance: its setpoint on every axis.
    fn guidance_tick(&mut self) {
        let t = self.time();
        let dt = self.tick_pos.div() as f64 * self.h;
        let Some((g, start_at)) = self.guidance.as_mut() else {
            return;
        };
        if t + 1e-9 < *start_at {
            return;
        }
        let pos: [f64; 3] = self.meas_pos.into();
        let vel: [f64; 3] = self.meas_vel.into();
        if !self.guidance_started {
            g.start(t, &pos, &vel);
            self.guidance_started = true;
        }
        let sp = g.update(t, dt, &pos, &vel);
        for i in 0..3 {
            self.sp.axes[i] = AxisSetpoint::Trajectory {
                p: sp.p[i],
                v: sp.v[i],
                a: sp.a[i],
            };
        }
    }

    /// One IMU sample of the current state, whose acceleration is `acc` (NED); feeds the
    /// swing estimator when it is due.
    fn sample_imu(&mut self, acc: &Vector3<f64>) {
        let rot = self.state.rotation();
        let f = rot.transpose() * (acc - Vector3::new(0.0, 0.0, GRAVITY));
        let s = self
            .imu
            .sample(f.into(), self.state.rate.into(), self.state.thrust.into());
        if !self.tick_est.due() {
            return;
        }
        if let Some(est) = self.swing_est.as_mut() {
            est.update(s.accel, &rot, self.meas_vel.into());
        }
        if self.sc.sensors.swing == SwingSource::Body {
            let m = self.measured_swing();
            self.body_rate.update(m);
        }
    }

    fn measure_translation(&mut self) {
        self.meas_pos = self.state.pos;
        self.meas_vel = self.state.vel;
        let n = &self.sc.noise;
        if n.position_std > 0.0 || n.velocity_std > 0.0 {
            for i in 0..3 {
                let zp: f64 = StandardNormal.sample(&mut self.rng);
                let zv: f64 = StandardNormal.sample(&mut self.rng);
                self.meas_pos[i] += n.position_std * zp;
                self.meas_vel[i] += n.velocity_std * zv;
            }
        }
    }

    fn controller_tick(&mut self) {
        let taring = self.sc.sensors.swing == SwingSource::Imu
            && self.swing_est.as_ref().is_some_and(|e| !e.tared());
        if taring {
            return;
        }
        let inputs = TickInputs {
            t: self.time(),
            swing: self.controller_swing(),
            swing_rate: self.controller_swing_rate(),
            pos: &self.meas_pos,
            vel: &self.meas_vel,
            px4: &self.sc.controller,
            thrust_vertical: self.thrust_vertical(),
            guidance: match (&self.guidance, self.guidance_started) {
                (Some((g, _)), true) => Some(g.as_ref()),
                _ => None,
            },
        };
        self.supervisor.tick(&inputs, &mut self.sp, &mut self.fc);
    }

    /// Rotor thrust projected on the vertical (up) [N]: the thrust acts along −body z, whose
    /// vertical part is the (3, 3) entry of the attitude's rotation, 1 − 2(x² + y²).
    fn thrust_vertical(&self) -> f64 {
        let q = &self.state.att;
        let n2 = q.norm_squared();
        let r33 = 1.0 - 2.0 * (q.i * q.i + q.j * q.j) / n2;
        self.state.thrust.sum() * r33
    }

    fn check_finite(&self) -> Result<(), SimError> {
        check_state(&self.state, self.time())
    }

    /// The current sample of every trace column (what the next logged row would hold).
    pub fn sample(&self) -> TraceRow {
        let s = &self.state;
        let truth = self.true_swing();
        let meas = self.measured_swing();
        let payload = if self.model.links() > 0 {
            s.payload_position(&self.model.payload, 0)
        } else {
            s.pos
        };
        let mut vel_sp = self.fc.vel_sp;
        self.supervisor.override_velocity(&mut vel_sp);
        let plant = PlantSample {
            t: self.step as f64 * self.h,
            state: s,
            measured: meas,
            truth,
            payload,
            wind: self.wind_now,
            imu: self.imu.filtered(),
            adc: self.adc_counts(),
            estimate: self.swing_estimate().unwrap_or([f64::NAN; 2]),
        };
        TraceRow {
            acc_sp_n: self.fc.acc_sp.x,
            acc_sp_e: self.fc.acc_sp.y,
            acc_sp_d: self.fc.acc_sp.z,
            vel_sp_n: vel_sp.x,
            vel_sp_e: vel_sp.y,
            vel_sp_d: vel_sp.z,
            ctrl_active: self.supervisor.active() as u8 as f64,
            fallback: self.supervisor.fell_back() as u8 as f64,
            ..plant.row()
        }
    }

    /// The current state as ([`STATE_KEYS`] name, value) pairs: trace columns of
    /// [`Self::sample`] plus the attitude quaternion and body rates ([`StateExtras`]).
    pub fn state_snapshot(&self) -> Vec<(&'static str, f64)> {
        let row = self.sample();
        let s = &self.state;
        let extras = StateExtras {
            q0: s.att.w,
            q1: s.att.i,
            q2: s.att.j,
            q3: s.att.k,
            p: s.rate.x,
            q: s.rate.y,
            r: s.rate.z,
        };
        STATE_KEYS
            .iter()
            .map(|k| {
                let v = row.get(k).or_else(|| extras.get(k));
                (
                    *k,
                    v.expect("every state key is a trace column or a state extra"),
                )
            })
            .collect()
    }

    fn log_row(&mut self) {
        let vals = self.sample().values();
        self.row[..vals.len()].copy_from_slice(&vals);
        if self.model.links() == 2 {
            let s = &self.state;
            let [s2n, s2e, _, _] = swing_angles(&s.n[1], &s.ndot[1]);
            self.row[vals.len()] = s2n;
            self.row[vals.len() + 1] = s2e;
        }
        self.trace.push(&self.row);
    }
}
