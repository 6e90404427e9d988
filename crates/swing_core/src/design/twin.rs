//! The vehicle's twin as a check plant: swingrt's nonlinear simulator of the vehicle under
//! PX4's cascade, carrying the payload of the flight's white-box, on which a candidate's
//! MPC flies a velocity step (and holds it) before it is flown on the linear plants.

use crate::config::{positive, ConfigError};
use crate::control::px4::Px4Params;
use crate::control::{ControlError, MpcController, MpcSettings, SwingController};
use crate::design::check::{overshoot, swing_iae, StepCheck, FINAL_SPAN};
use crate::plant::{PayloadKind, WindParams};
use crate::sensors::{ImuParams, SwingSource};
use crate::sim::{NoiseParams, Scenario, SetpointEntry, SimError, Simulator};
use crate::sysid::LinearModel;

/// Length of a twin step flight [s] and the time of its step [s] (as the linear check's).
pub const TWIN_CHECK_SECONDS: f64 = 20.0;
/// Time of the twin step flight's velocity step [s].
pub const TWIN_CHECK_STEP_AT: f64 = 2.0;
/// Band around the new setpoint, as a fraction of the step, that a settled velocity stays in.
pub const SETTLE_BAND: f64 = 0.05;
/// Length of the twin's hold flight (the same step, held) [s]: long enough for a slow
/// growth to show, and for the 2 s means of the velocity to average over many noise draws.
pub const TWIN_HOLD_SECONDS: f64 = 60.0;
/// Span at the end of the hold flight over which the late error is taken [s].
const LATE_SPAN: f64 = 20.0;
/// Start of the span over which the velocity's wander is measured [s].
pub const WANDER_FROM: f64 = 10.0;
/// Length of the blocks whose mean velocity error is the wander [s]: a flight's
/// steady-state error is the mean over its last 2 s.
pub const WANDER_SPAN: f64 = 2.0;

/// Peak of the gust of the twin's gust flight [m/s], against the step on every flown axis
/// (a headwind): the size of the gusts the robustness studies fly (up to 1.5 m/s per
/// axis), at which a slow disturbance estimate overshoots.
pub const TWIN_GUST: f64 = 1.0;
/// Start of the gust of the twin's gust flight [s]: the step has settled by then.
pub const TWIN_GUST_AT: f64 = 10.0;
/// Length of the gust of the twin's gust flight [s].
pub const TWIN_GUST_DURATION: f64 = 2.0;
/// Length of the twin's gust flight [s]: the settle bound's time after the gust, and more.
pub const TWIN_GUST_SECONDS: f64 = 24.0;
/// Span before the gust over which the swing it is measured against is taken [s].
const GUST_REFERENCE_SPAN: f64 = 2.0;

/// The twin as a plant of the control-relevant selection: a candidate's MPC flies a
/// velocity step (hover, step at [`TWIN_CHECK_STEP_AT`], hold) on swingrt's nonlinear
/// simulator of the vehicle under PX4's cascade, carrying the payload of the flight's
/// white-box (both links when the swing shows a second), in still air, with the flight's
/// swing-sensor noise; [`TwinPlant::hold`] holds the step for a minute.
///
/// The linear check flies a candidate on a linear pendulum behind a first-order lag. What
/// it cannot see and the twin can: the attitude loop's lag and the cascade's tilt and
/// acceleration limits, the nonlinear pendulum and the quadratic drag. A model whose MPC
/// passes the linear check can still fall into a ~1 Hz limit cycle against the
/// acceleration bound on the vehicle; on the twin it does too.
#[derive(Clone, Debug)]
pub struct TwinPlant {
    scenario: Scenario,
    step: f64,
    axes: usize,
    label: String,
    /// PX4's cascade alone on the step, flown when first asked for: the selection's
    /// robust twins (payload tolerance, slow vehicle) never ask.
    pid: std::sync::OnceLock<TwinFlight>,
}

/// Figures of one twin step flight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TwinFlight {
    /// Overshoot, final error (mean over the last second) and hold drift, as fractions of
    /// the step, worst over the axes (∞ when the flight diverged or fell back to PX4).
    pub check: StepCheck,
    /// Time after the step from which every axis' velocity stays within [`SETTLE_BAND`] of
    /// the new setpoint [s] (∞: it never does).
    pub settle: f64,
    /// Swing left to the controller after the step [deg·s]: `metrics.csv`'s
    /// `swing_excess_iae_deg_s` on the twin, by the one definition
    /// ([`crate::design::check::swing_iae`]): the swing IAE above the payload's momentum
    /// change, which every controller needs.
    pub swing_excess: f64,
}

/// Figures of the twin's hold flight: the step held for [`TWIN_HOLD_SECONDS`], flown with
/// the flight's sensor noise and again without.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TwinHold {
    /// RMS (from [`WANDER_FROM`] on) of the trailing [`WANDER_SPAN`] mean of the velocity's
    /// difference between the two flights, as a fraction of the step, worst over the axes:
    /// how far the sensor noise, fed through the MPC, moves the vehicle once it has settled,
    /// at the time scale of a flight's steady-state error (the mean over its last 2 s).
    /// 0 without noise; PX4 alone does not read the swing and has none.
    pub wander: f64,
    /// Largest |v − setpoint| over the last 20 s of the flight without noise, as a fraction
    /// of the step: in still air a settled MPC stays on the setpoint, and one whose loop
    /// slowly grows an oscillation (too slowly for the step flight to show) does not.
    pub late_error: f64,
}

/// Figures of the twin's gust flight ([`TwinPlant::gust`]): the step held, in still air
/// but for one headwind gust of [`TWIN_GUST`] from [`TWIN_GUST_AT`] for
/// [`TWIN_GUST_DURATION`], without sensor noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TwinGust {
    /// ∫ |swing − swing before the gust| dt from the gust's start to the flight's end,
    /// summed over the axes [deg·s]: the swing the gust leaves.
    pub swing_iae: f64,
    /// Time after the gust's end from which every axis' velocity stays within
    /// [`SETTLE_BAND`] of the setpoint [s] (∞: it never does).
    pub resettle: f64,
}

impl TwinGust {
    /// The figures of a gust flight that diverged or was handed back to PX4.
    pub fn diverged() -> Self {
        Self {
            swing_iae: f64::INFINITY,
            resettle: f64::INFINITY,
        }
    }
}

impl TwinHold {
    /// The figures of a hold flight that diverged or was handed back to PX4.
    pub fn diverged() -> Self {
        Self {
            wander: f64::INFINITY,
            late_error: f64::INFINITY,
        }
    }
}

impl TwinFlight {
    /// The figures of a flight that diverged or was handed back to PX4.
    pub fn diverged() -> Self {
        Self {
            check: StepCheck {
                overshoot: f64::INFINITY,
                final_error: f64::INFINITY,
                hold_drift: f64::INFINITY,
            },
            settle: f64::INFINITY,
            swing_excess: f64::INFINITY,
        }
    }
}

impl TwinPlant {
    /// The twin of the vehicle of `vehicle` (its airframe and PX4 gains; its payload, wind,
    /// noise and setpoints are replaced) carrying the payload of the white-box `plant`'s
    /// estimates, flying a `step` [m/s] on each of `axes` (1: N, 2: N and E).
    pub fn new(
        vehicle: &Scenario,
        plant: &LinearModel,
        step: f64,
        axes: usize,
    ) -> Result<Self, ConfigError> {
        let wb = plant.diagnostics.whitebox.as_ref().ok_or_else(|| {
            ConfigError::new(
                "twin",
                "the twin carries the white-box payload: the check plant has no white-box estimates",
            )
        })?;
        positive("step", step.abs())?;
        if !(1..=2).contains(&axes) {
            return Err(ConfigError::new("axes", "must be 1 (N) or 2 (N+E)"));
        }
        let mut sc = vehicle.clone();
        sc.name = "twin step check".into();
        sc.duration = TWIN_CHECK_SECONDS;
        sc.random_steps = None;
        sc.wind = WindParams::default();
        sc.noise = NoiseParams::default();
        sc.payload.kind = PayloadKind::Single;
        sc.payload.mass = wb.payload_mass;
        sc.payload.length = wb.length;
        sc.payload.events.clear();
        // The IMU feeds back only through the swing estimator: on any other swing source
        // its noise and vibration change nothing the twin measures, and drawing them is
        // the largest part of a physics step.
        if sc.sensors.swing != SwingSource::Imu {
            sc.sensors.imu = ImuParams::ideal();
        }
        // The flight's own swing-sensor noise: a model whose MPC feeds it into the
        // velocity wanders off the setpoint in flight, and on the twin too.
        sc.noise.swing_std = wb.swing_noise.unwrap_or(0.0);
        // A second link found in the swing: the lower mode an MPC can excite unseen.
        if let Some(d) = wb.links {
            let m = wb.payload_mass;
            sc.payload.kind = PayloadKind::Double;
            sc.payload.mass = m / (1.0 + d.mass_ratio);
            sc.payload.mass2 = m * d.mass_ratio / (1.0 + d.mass_ratio);
            sc.payload.length = d.length;
            sc.payload.length2 = d.length2;
        }
        let ve = (axes == 2).then_some(0.0);
        sc.setpoints = vec![
            SetpointEntry {
                t: 0.0,
                vn: Some(0.0),
                ve,
                ..Default::default()
            },
            SetpointEntry {
                t: TWIN_CHECK_STEP_AT,
                vn: Some(step),
                ve: ve.map(|_| step),
                ..Default::default()
            },
        ];
        sc.validate()
            .map_err(|e| ConfigError::new("twin", format!("twin scenario: {e}")))?;
        let payload = match wb.links {
            Some(d) => format!(
                "double pendulum {:.3} kg on {:.2} m, {:.3} kg {:.2} m below",
                sc.payload.mass, d.length, sc.payload.mass2, d.length2
            ),
            None => format!("payload {:.3} kg on {:.2} m", wb.payload_mass, wb.length),
        };
        let label = format!(
            "twin (swingrt's simulator of a {:.3} kg vehicle under PX4's cascade, {payload}, \
             still air)",
            sc.vehicle.mass
        );
        Self::flown(sc, step, axes, label, true)
    }

    /// The twin of scenario `sc` (validated); PX4's cascade alone is flown on its step now
    /// when `px4_now`, else when [`TwinPlant::pid_flight`] first asks.
    fn flown(
        sc: Scenario,
        step: f64,
        axes: usize,
        label: String,
        px4_now: bool,
    ) -> Result<Self, ConfigError> {
        let pid = std::sync::OnceLock::new();
        if px4_now {
            // Set on a lock just made: it cannot be set already.
            let _ = pid.set(px4_alone(&sc, step, axes)?);
        }
        Ok(Self {
            scenario: sc,
            step,
            axes,
            label,
            pid,
        })
    }

    /// This twin with every link of its payload `factor` times as long (the white-box's
    /// lengths are estimates): a plant of the selection's payload tolerance
    /// (`SelectionSettings::payload_tolerance`).
    pub fn with_payload_lengths(&self, factor: f64) -> Result<Self, ConfigError> {
        positive("factor", factor)?;
        let mut sc = self.scenario.clone();
        sc.payload.length *= factor;
        sc.payload.length2 *= factor;
        sc.validate()
            .map_err(|e| ConfigError::new("twin", format!("twin scenario: {e}")))?;
        let label = format!("{} with the payload's links {factor}× as long", self.label);
        Self::flown(sc, self.step, self.axes, label, false)
    }

    /// This twin with its single payload replaced by the double pendulum of the same mass
    /// whose two modes (the vehicle held) are its pendulum's √(g/l) and `omega2` [rad/s],
    /// with the heaviest lower link those rates allow ([`crate::sysid::links::heaviest_links`]):
    /// the plant of the selection's second link (`SelectionSettings::spillover`), a lower
    /// mode the white-box did not fit but the swing's spectrum shows a trace of. `None`
    /// when the twin already carries two links or `omega2` is not above its pendulum's mode.
    pub fn with_second_link(&self, omega2: f64) -> Result<Option<Self>, ConfigError> {
        let p = &self.scenario.payload;
        if p.kind != PayloadKind::Single {
            return Ok(None);
        }
        let omega1 = (crate::plant::GRAVITY / p.length).sqrt();
        let Some((length, mu)) = crate::sysid::links::heaviest_links(omega1, omega2) else {
            return Ok(None);
        };
        let mut sc = self.scenario.clone();
        let total = sc.payload.mass;
        sc.payload.kind = PayloadKind::Double;
        sc.payload.mass = total / (1.0 + mu);
        sc.payload.mass2 = total * mu / (1.0 + mu);
        sc.payload.length = length;
        sc.payload.length2 = length;
        sc.validate()
            .map_err(|e| ConfigError::new("twin", format!("twin scenario: {e}")))?;
        let label = format!(
            "{} with its payload as the double pendulum of modes {omega1:.2} and {omega2:.2} \
             rad/s ({:.3} kg over {:.3} kg, both links {length:.2} m)",
            self.label, sc.payload.mass, sc.payload.mass2
        );
        Self::flown(sc, self.step, self.axes, label, false).map(Some)
    }

    /// This twin with a slower attitude loop: its motors' time constant `motor_tau` [s]
    /// and its inertia `inertia`× its own (the twin's motors and mass distribution are the
    /// built-in's, which a user rarely knows better): the plant of the selection's slow
    /// vehicle (`SelectionSettings::slow_motor_lag`, `SelectionSettings::slow_inertia`).
    pub fn slowed(&self, motor_tau: f64, inertia: f64) -> Result<Self, ConfigError> {
        positive("motor_tau", motor_tau)?;
        positive("inertia", inertia)?;
        let mut sc = self.scenario.clone();
        sc.vehicle.motor_tau = motor_tau;
        for j in sc.vehicle.inertia.iter_mut() {
            *j *= inertia;
        }
        sc.validate()
            .map_err(|e| ConfigError::new("twin", format!("twin scenario: {e}")))?;
        let label = format!(
            "{} with motors of lag {motor_tau} s and {inertia}× its inertia",
            self.label
        );
        Self::flown(sc, self.step, self.axes, label, false)
    }

    /// PX4's parameters the twin flies with (the training flight's).
    pub fn px4(&self) -> &Px4Params {
        &self.scenario.controller
    }

    /// The number of axes the twin's step is flown on (1 = N, 2 = N + E).
    pub fn axes(&self) -> usize {
        self.axes
    }

    /// The time constant of the twin's motors [s].
    pub fn motor_lag(&self) -> f64 {
        self.scenario.vehicle.motor_tau
    }

    /// The same step flown by PX4's cascade alone: the swing a candidate must damp.
    pub fn pid_flight(&self) -> &TwinFlight {
        self.pid.get_or_init(|| {
            // The scenario was validated when this twin was made and the twin's own step
            // flew it; a flight that cannot be flown or measured here has no figures.
            px4_alone(&self.scenario, self.step, self.axes)
                .unwrap_or_else(|_| TwinFlight::diverged())
        })
    }

    /// What the twin is, for the model's diagnostics.
    pub fn label(&self) -> &str {
        &self.label
    }

    /// Whether the twin's swing is estimated from its IMU (the flight's swing source),
    /// rather than measured.
    pub fn estimates_swing(&self) -> bool {
        self.scenario.sensors.swing == SwingSource::Imu
    }

    /// Fly the MPC of `model` with `settings` (designed for this twin's axes) on the step; a
    /// diverged flight or one handed back to PX4 (a tick that failed) gives
    /// [`TwinFlight::diverged`].
    pub fn fly(
        &self,
        model: &LinearModel,
        settings: &MpcSettings,
    ) -> Result<TwinFlight, ControlError> {
        Ok(self
            .fly_with(Box::new(MpcController::new(model, settings.clone())?))?
            .flight)
    }

    /// Fly the controller `ctrl` (not flown before: an MPC, or a law on PX4's velocity
    /// setpoint) on the step, and keep the flight to be held on ([`Self::hold_on`]).
    pub fn fly_with(&self, ctrl: Box<dyn SwingController>) -> Result<TwinStep, ControlError> {
        let mut sc = self.scenario.clone();
        sc.duration = TWIN_HOLD_SECONDS;
        let mut sim = self.start(sc, ctrl)?;
        // One physics step past the step flight's end, so that its last row is logged: the
        // rows so far are the step flight's, draw for draw.
        let until = TWIN_CHECK_SECONDS + self.scenario.physics_dt;
        match sim.advance(until) {
            Ok(()) if sim.fallback_reason().is_none() => {}
            Ok(()) | Err(SimError::Diverged { .. }) => {
                return Ok(TwinStep {
                    flight: TwinFlight::diverged(),
                    sim: None,
                })
            }
            Err(e) => return Err(sim_error(e)),
        }
        let rows = column(&sim, "t")?.partition_point(|&x| x <= TWIN_CHECK_SECONDS + 1e-9);
        let flight = measure(&sim, rows, self.step, self.axes)?;
        Ok(TwinStep {
            flight,
            sim: Some(sim),
        })
    }

    /// Fly the MPC of `model` with `settings` on the step held for [`TWIN_HOLD_SECONDS`]
    /// ([`Self::hold_on`] after [`Self::fly_with`]).
    pub fn hold(
        &self,
        model: &LinearModel,
        settings: &MpcSettings,
    ) -> Result<TwinHold, ControlError> {
        let mpc = MpcController::new(model, settings.clone())?;
        let step = self.fly_with(Box::new(mpc.fresh_copy()?))?;
        self.hold_on(step, Box::new(mpc))
    }

    /// Hold the step flight `step` on to [`TWIN_HOLD_SECONDS`] with the sensor noise and,
    /// when there is some, fly the controller `ctrl` (of the same design, not flown before)
    /// again without it (the same draws otherwise): what the noise alone does to the
    /// velocity, and whether the flight without it stays on the setpoint.
    pub fn hold_on(
        &self,
        step: TwinStep,
        ctrl: Box<dyn SwingController>,
    ) -> Result<TwinHold, ControlError> {
        let Some(mut noisy) = step.sim else {
            return Ok(TwinHold::diverged());
        };
        let quiet = (self.scenario.noise.swing_std > 0.0).then(|| {
            let mut sc = self.scenario.clone();
            sc.duration = TWIN_HOLD_SECONDS;
            sc.noise.swing_std = 0.0;
            sc
        });
        // The two flights are independent: the one without noise flies on another core.
        let (held, clean) = crate::parallel::join(
            || match noisy.run_to_end() {
                Ok(()) => Ok(noisy.fallback_reason().is_none()),
                Err(SimError::Diverged { .. }) => Ok(false),
                Err(e) => Err(sim_error(e)),
            },
            move || -> Result<Option<Option<Vec<Vec<f64>>>>, ControlError> {
                let Some(sc) = quiet else {
                    return Ok(None);
                };
                let Some(sim) = self.finish(self.start(sc, ctrl)?)? else {
                    return Ok(Some(None));
                };
                let velocities = ["vn", "ve"]
                    .iter()
                    .take(self.axes)
                    .map(|name| column(&sim, name).map(<[f64]>::to_vec))
                    .collect::<Result<Vec<_>, _>>()?;
                Ok(Some(Some(velocities)))
            },
        );
        let clean = match (held?, clean?) {
            (false, _) | (_, Some(None)) => return Ok(TwinHold::diverged()),
            (true, Some(Some(v))) => Some(v),
            (true, None) => None,
        };
        let t = column(&noisy, "t")?;
        let late = t.partition_point(|&x| x < TWIN_HOLD_SECONDS - LATE_SPAN);
        let mut out = TwinHold {
            wander: 0.0,
            late_error: 0.0,
        };
        for (axis, v_name) in ["vn", "ve"].iter().take(self.axes).enumerate() {
            let v = column(&noisy, v_name)?;
            let v0 = match &clean {
                Some(c) => &c[axis][..],
                None => v,
            };
            if v0.len() != v.len() {
                return Err(ControlError::Model(
                    "the twin's flights with and without noise differ in length".into(),
                ));
            }
            out.wander = out.wander.max(wander(t, v, v0) / self.step.abs());
            let late_error = v0[late..]
                .iter()
                .fold(0.0_f64, |a, x| a.max((x - self.step).abs()));
            out.late_error = out.late_error.max(late_error / self.step.abs());
        }
        if !(out.wander.is_finite() && out.late_error.is_finite()) {
            return Ok(TwinHold::diverged());
        }
        Ok(out)
    }

    /// Fly the controller `ctrl` (not flown before) on the step held to
    /// [`TWIN_GUST_SECONDS`], with a headwind gust of [`TWIN_GUST`] on every flown axis from
    /// [`TWIN_GUST_AT`] and no sensor noise: how much swing the gust leaves and how soon the
    /// velocity is back on the setpoint ([`TwinGust`]).
    pub fn gust(&self, ctrl: Box<dyn SwingController>) -> Result<TwinGust, ControlError> {
        let mut sc = self.scenario.clone();
        sc.name = "twin gust check".into();
        sc.duration = TWIN_GUST_SECONDS;
        sc.noise.swing_std = 0.0;
        let against = -TWIN_GUST * self.step.signum();
        sc.wind.gusts = vec![crate::plant::wind::Gust {
            t: TWIN_GUST_AT,
            duration: TWIN_GUST_DURATION,
            amplitude: [against, if self.axes == 2 { against } else { 0.0 }, 0.0],
        }];
        let Some(sim) = self.finish(self.start(sc, ctrl)?)? else {
            return Ok(TwinGust::diverged());
        };
        let t = column(&sim, "t")?;
        let before = t.partition_point(|&x| x < TWIN_GUST_AT - GUST_REFERENCE_SPAN);
        let from = t.partition_point(|&x| x < TWIN_GUST_AT);
        let after = t.partition_point(|&x| x < TWIN_GUST_AT + TWIN_GUST_DURATION);
        let mut out = TwinGust {
            swing_iae: 0.0,
            resettle: 0.0,
        };
        let band = SETTLE_BAND * self.step.abs();
        for (v_name, s_name) in [("vn", "swing_true_n"), ("ve", "swing_true_e")]
            .iter()
            .take(self.axes)
        {
            let swing = column(&sim, s_name)?;
            let reference = mean(&swing[before..from]);
            out.swing_iae += (from + 1..t.len())
                .map(|k| (swing[k] - reference).abs().to_degrees() * (t[k] - t[k - 1]))
                .sum::<f64>();
            let v = column(&sim, v_name)?;
            let resettle = match v[after..]
                .iter()
                .rposition(|x| (x - self.step).abs() > band)
            {
                None => 0.0,
                Some(k) if after + k + 1 >= v.len() => f64::INFINITY,
                Some(k) => t[after + k + 1] - (TWIN_GUST_AT + TWIN_GUST_DURATION),
            };
            out.resettle = out.resettle.max(resettle);
        }
        if !out.swing_iae.is_finite() {
            return Ok(TwinGust::diverged());
        }
        Ok(out)
    }

    /// A simulator of `scenario` with `mpc` attached, not yet flown.
    fn start(
        &self,
        scenario: Scenario,
        ctrl: Box<dyn SwingController>,
    ) -> Result<Simulator, ControlError> {
        if ctrl.axes() != self.axes {
            return Err(ControlError::Model(format!(
                "the twin flies {} axes, the controller {}",
                self.axes,
                ctrl.axes()
            )));
        }
        let mut sim = Simulator::new(scenario).map_err(sim_error)?;
        // The check measures the control law, not the machine it runs on: no tick budget.
        sim.attach_controller(ctrl, 0.0, f64::MAX)
            .map_err(sim_error)?;
        Ok(sim)
    }

    /// `sim` flown to its end; `None` when it diverged or fell back to PX4.
    fn finish(&self, mut sim: Simulator) -> Result<Option<Simulator>, ControlError> {
        match sim.run_to_end() {
            Ok(()) => {}
            Err(SimError::Diverged { .. }) => return Ok(None),
            Err(e) => return Err(sim_error(e)),
        }
        Ok(sim.fallback_reason().is_none().then_some(sim))
    }
}

/// PX4's cascade alone flown on the twin scenario `sc` (a `step` [m/s] on `axes` axes).
fn px4_alone(sc: &Scenario, step: f64, axes: usize) -> Result<TwinFlight, ConfigError> {
    let mut sim = Simulator::new(sc.clone())
        .map_err(|e| ConfigError::new("twin", format!("twin scenario: {e}")))?;
    match sim.run_to_end() {
        Ok(()) => measure(&sim, usize::MAX, step, axes)
            .map_err(|e| ConfigError::new("twin", format!("PX4 alone on the twin: {e}"))),
        Err(_) => Ok(TwinFlight::diverged()),
    }
}

/// A twin step flight ([`TwinPlant::fly_with`]), its simulator kept to hold the step on.
pub struct TwinStep {
    /// The step flight's figures.
    pub flight: TwinFlight,
    /// The flight at the step flight's end (`None`: it diverged or fell back to PX4).
    sim: Option<Simulator>,
}

/// The column `name` of the finished flight `sim`.
fn column<'a>(sim: &'a Simulator, name: &str) -> Result<&'a [f64], ControlError> {
    sim.trace()
        .column(name)
        .ok_or_else(|| ControlError::Model(format!("twin flight has no column {name}")))
}

/// Figures of the finished twin step flight `sim` (a `step` [m/s] on `axes` axes).
/// Only the first `rows` rows count (the step flight's, of a flight held on).
fn measure(
    sim: &Simulator,
    rows: usize,
    step: f64,
    axes: usize,
) -> Result<TwinFlight, ControlError> {
    let column = |name: &str| column(sim, name).map(|c| &c[..rows.min(c.len())]);
    let t = column("t")?;
    let mut out = TwinFlight {
        check: StepCheck {
            overshoot: f64::NEG_INFINITY,
            final_error: 0.0,
            hold_drift: 0.0,
        },
        settle: 0.0,
        swing_excess: 0.0,
    };
    let after = t.partition_point(|&x| x < TWIN_CHECK_STEP_AT);
    let tail = t.partition_point(|&x| x < TWIN_CHECK_SECONDS - FINAL_SPAN);
    for v_name in ["vn", "ve"].iter().take(axes) {
        let v = column(v_name)?;
        let c = &mut out.check;
        c.overshoot = c.overshoot.max(overshoot(&v[after..], 0.0, step));
        let hold = v[..after].iter().fold(0.0_f64, |a, x| a.max(x.abs()));
        c.hold_drift = c.hold_drift.max(hold / step.abs());
        c.final_error = c
            .final_error
            .max((mean(&v[tail..]) - step).abs() / step.abs());
        let band = SETTLE_BAND * step.abs();
        let settle = match v[after..].iter().rposition(|x| (x - step).abs() > band) {
            None => 0.0,
            Some(k) if after + k + 1 >= v.len() => f64::INFINITY,
            Some(k) => t[after + k + 1] - TWIN_CHECK_STEP_AT,
        };
        out.settle = out.settle.max(settle);
    }
    // The swing as the flight metrics measure it: its magnitude, and along the step (the
    // same step on every axis flown).
    let sn = column("swing_true_n")?;
    let se = column("swing_true_e")?;
    let (swing, along): (Vec<f64>, Vec<f64>) = (after..t.len())
        .map(|k| match axes {
            1 => (sn[k], sn[k]),
            _ => (
                sn[k].hypot(se[k]),
                (sn[k] + se[k]) / std::f64::consts::SQRT_2,
            ),
        })
        .unzip();
    out.swing_excess = swing_iae(&t[after..], &swing, &along).excess();
    if !(out.check.overshoot.is_finite()
        && out.check.final_error.is_finite()
        && out.swing_excess.is_finite())
    {
        return Ok(TwinFlight::diverged());
    }
    Ok(out)
}

/// RMS over the hold (from [`WANDER_FROM`] + [`WANDER_SPAN`] on) of the trailing
/// [`WANDER_SPAN`] mean of `v − v0` [m/s].
fn wander(t: &[f64], v: &[f64], v0: &[f64]) -> f64 {
    let start = t.partition_point(|&x| x < WANDER_FROM);
    let mut window = std::collections::VecDeque::new();
    let (mut sum, mut sq, mut count) = (0.0, 0.0, 0usize);
    for k in start..v.len() {
        window.push_back(k);
        sum += v[k] - v0[k];
        while let Some(&j) = window.front() {
            if t[k] - t[j] < WANDER_SPAN {
                break;
            }
            sum -= v[j] - v0[j];
            window.pop_front();
        }
        if t[k] >= WANDER_FROM + WANDER_SPAN {
            sq += (sum / window.len() as f64).powi(2);
            count += 1;
        }
    }
    (sq / count.max(1) as f64).sqrt()
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len().max(1) as f64
}

fn sim_error(e: SimError) -> ControlError {
    match e {
        SimError::Config(c) => ControlError::Config(c),
        other => ControlError::Model(format!("twin flight: {other}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::fixtures::{builtin_twin, template};

    #[test]
    fn the_twin_measures_how_much_of_px4_s_swing_the_mpc_removes() {
        use crate::design::selection::TwinBounds;
        let (tpl, _, twin) = builtin_twin();
        let bounds = TwinBounds::default();
        // PX4 alone leaves the payload ringing after the step ...
        let pid = *twin.pid_flight();
        assert!(pid.swing_excess > 5.0, "{pid:?}");
        assert!(!bounds.damps(&pid, &pid), "{pid:?}");
        // ... an MPC on a model of the flight damps it, and the velocity settles sooner.
        let f = twin.fly(&tpl, &MpcSettings::default()).unwrap();
        assert!(bounds.damps(&f, &pid), "{f:?} vs {pid:?}");
        assert!(f.swing_excess < 0.3 * pid.swing_excess, "{f:?} vs {pid:?}");
        assert!(f.settle < pid.settle, "{f:?} vs {pid:?}");
    }

    /// The step flight is measured on the first 20 s of the flight the hold goes on with:
    /// draw for draw the flight of a 20 s scenario, so holding on changes no figure.
    #[test]
    fn a_twin_with_longer_links_carries_them_and_flies_px4_on_them() {
        let (_, _, twin) = builtin_twin();
        let longer = twin.with_payload_lengths(1.1).unwrap();
        let (p, q) = (&twin.scenario.payload, &longer.scenario.payload);
        assert_eq!(q.length, 1.1 * p.length);
        assert_eq!(q.length2, 1.1 * p.length2);
        assert_eq!((q.mass, q.kind), (p.mass, p.kind));
        // PX4's reference is flown on the longer pendulum: a slower swing, not the same
        // flight.
        assert_ne!(longer.pid_flight(), twin.pid_flight());
        assert!(
            longer.label().contains("1.1× as long"),
            "{}",
            longer.label()
        );
        for bad in [0.0, -1.0, f64::NAN] {
            assert!(twin.with_payload_lengths(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_twin_with_a_second_link_carries_the_payload_s_mass_on_links_of_the_two_modes() {
        let (_, _, twin) = builtin_twin();
        let p = twin.scenario.payload.clone();
        let omega1 = (crate::plant::GRAVITY / p.length).sqrt();
        let two = twin
            .with_second_link(11.0)
            .unwrap()
            .expect("a mode above the pendulum's");
        let q = &two.scenario.payload;
        assert_eq!(q.kind, PayloadKind::Double);
        assert!((q.mass + q.mass2 - p.mass).abs() < 1e-12, "{q:?}");
        assert_eq!(q.length, q.length2);
        // Its modes with the vehicle held, by the links' own rule, are the two rates.
        let (w1, w2, _) = crate::sysid::links::modes(q.length, q.length2, q.mass2 / q.mass);
        assert!(
            (w1 - omega1).abs() < 1e-9 && (w2 - 11.0).abs() < 1e-9,
            "{w1} {w2}"
        );
        assert!(two.pid.get().is_none());
        assert_eq!(two.scenario.vehicle, twin.scenario.vehicle);
        // No second link below the first mode, nor on a twin that has two already.
        assert!(twin.with_second_link(0.5 * omega1).unwrap().is_none());
        assert!(two.with_second_link(20.0).unwrap().is_none());
    }

    #[test]
    fn a_slowed_twin_carries_slower_motors_and_more_inertia_and_flies_px4_on_them() {
        let (_, _, twin) = builtin_twin();
        let slow = twin.slowed(0.04, 1.5).unwrap();
        let (v, w) = (&twin.scenario.vehicle, &slow.scenario.vehicle);
        assert_eq!(w.motor_tau, 0.04);
        for (a, b) in v.inertia.iter().zip(&w.inertia) {
            assert_eq!(*b, 1.5 * a);
        }
        assert_eq!(
            (w.mass, &slow.scenario.payload),
            (v.mass, &twin.scenario.payload)
        );
        // The selection never asks a slowed twin for PX4's flight: it is flown when asked,
        // on the slower vehicle (a lagging attitude loop), while the twin's own is flown
        // with the twin.
        assert!(slow.pid.get().is_none() && twin.pid.get().is_some());
        assert_ne!(slow.pid_flight(), twin.pid_flight());
        assert!(
            slow.label().contains("lag 0.04 s and 1.5×"),
            "{}",
            slow.label()
        );
        for (tau, j) in [
            (0.0, 1.5),
            (-0.01, 1.5),
            (f64::NAN, 1.5),
            (0.04, 0.0),
            (0.04, f64::NAN),
        ] {
            assert!(twin.slowed(tau, j).is_err(), "{tau} {j}");
        }
    }

    #[test]
    fn a_step_flight_held_on_is_the_step_flight_flown_alone() {
        let (tpl, mut plant, _) = builtin_twin();
        plant.diagnostics.whitebox.as_mut().unwrap().swing_noise = Some(2e-4);
        let sc = Scenario::builtin("training").unwrap();
        let twin = TwinPlant::new(&sc, &plant, 2.0, 1).unwrap();
        let settings = MpcSettings::default();
        let mpc = MpcController::new(&tpl, settings.clone()).unwrap();
        let held = twin.fly_with(Box::new(mpc.fresh_copy().unwrap())).unwrap();
        let alone = twin
            .finish(
                twin.start(twin.scenario.clone(), Box::new(mpc.fresh_copy().unwrap()))
                    .unwrap(),
            )
            .unwrap()
            .unwrap();
        assert_eq!(alone.time(), TWIN_CHECK_SECONDS);
        assert_eq!(held.flight, measure(&alone, usize::MAX, 2.0, 1).unwrap());
        assert!(held.flight.settle < 6.0, "{:?}", held.flight);
        let hold = twin.hold_on(held, Box::new(mpc)).unwrap();
        assert!(hold.wander > 0.0, "{hold:?}");
        assert_eq!(hold, twin.hold(&tpl, &settings).unwrap());
    }

    #[test]
    fn the_wander_is_what_the_sensor_noise_alone_moves_the_velocity() {
        let (tpl, mut plant, _) = builtin_twin();
        let sc = Scenario::builtin("training").unwrap();
        let mpc = MpcSettings::default();
        let mut at = |std: Option<f64>| {
            plant.diagnostics.whitebox.as_mut().unwrap().swing_noise = std;
            let twin = TwinPlant::new(&sc, &plant, 2.0, 1).unwrap();
            let hold = twin.hold(&tpl, &mpc).unwrap();
            // In still air and without noise the MPC stays on the setpoint.
            assert!(hold.late_error < 0.005, "{hold:?}");
            hold.wander
        };
        // Without noise there is nothing to wander from, whatever the flight's creep.
        assert_eq!(at(None), 0.0);
        let (one, two) = (at(Some(1e-4)), at(Some(2e-4)));
        assert!(one > 0.0, "{one}");
        // The MPC off its bounds is linear: twice the noise (the same draws), twice the wander.
        assert!((two / one - 2.0).abs() < 0.05, "{one} {two}");
    }

    #[test]
    fn an_mpc_assumes_the_measurement_noise_its_model_carries() {
        let (mut tpl, mut plant, _) = builtin_twin();
        plant.diagnostics.whitebox.as_mut().unwrap().swing_noise = Some(4e-4);
        let sc = Scenario::builtin("training").unwrap();
        let twin = TwinPlant::new(&sc, &plant, 2.0, 1).unwrap();
        let mpc = MpcSettings::default();
        let base = twin.hold(&tpl, &mpc).unwrap().wander;
        let raised = MpcSettings {
            kf_measurement_noise: 0.03,
            ..mpc.clone()
        };
        let by_settings = twin.hold(&tpl, &raised).unwrap().wander;
        tpl.diagnostics.measurement_noise = Some(0.03);
        let by_model = twin.hold(&tpl, &mpc).unwrap().wander;
        // The model's figure is a floor: the same MPC as the settings asking for it ...
        assert_eq!(by_model, by_settings);
        // ... and an estimator that trusts the swing less passes less of its noise on.
        assert!(by_model < 0.7 * base, "{by_model} vs {base}");
        // A bad figure is an error, not a silently different filter.
        tpl.diagnostics.measurement_noise = Some(-1.0);
        assert!(MpcController::new(&tpl, mpc).is_err());
    }

    /// The gust flight: a headwind gust pushes the velocity off the setpoint and swings the
    /// payload; an estimator whose disturbances move faster takes the gust's force up
    /// sooner, and one that carries the faster rate in its model flies as the settings
    /// asking for it would.
    #[test]
    fn a_gust_is_taken_up_sooner_by_a_faster_disturbance_estimate() {
        let (mut tpl, _, twin) = builtin_twin();
        let gust = |model: &LinearModel, q: f64| {
            let settings = MpcSettings {
                kf_disturbance_noise: q,
                ..MpcSettings::default()
            };
            twin.gust(Box::new(MpcController::new(model, settings).unwrap()))
                .unwrap()
        };
        let slow = gust(&tpl, 0.02);
        let fast = gust(&tpl, 0.05);
        assert!(slow.swing_iae > 0.5, "{slow:?}");
        assert!(slow.resettle.is_finite() && slow.resettle > 0.0, "{slow:?}");
        assert!(fast.resettle < slow.resettle, "{fast:?} vs {slow:?}");
        // The model's figure is a floor on the settings' rate.
        tpl.diagnostics.disturbance_noise = Some(0.05);
        assert_eq!(gust(&tpl, 0.02), fast);
        tpl.diagnostics.disturbance_noise = Some(f64::NAN);
        assert!(MpcController::new(&tpl, MpcSettings::default()).is_err());
    }

    #[test]
    fn the_twin_sees_the_attitude_loop_that_the_linear_check_does_not() {
        use crate::design::check::{mpc_step_check, StepCheckSettings};
        use crate::design::selection::{CheckBounds, TwinBounds};
        let (tpl, plant, twin) = builtin_twin();
        let mpc = MpcSettings::default();
        let (bounds, twin_bounds) = (CheckBounds::default(), TwinBounds::default());
        // The MPC designed on the white-box flies that linear plant as if it were exact...
        let lin =
            mpc_step_check(&plant, mpc.clone(), &plant, &StepCheckSettings::default()).unwrap();
        assert!(bounds.admit(&lin), "{lin:?}");
        // ... but on the vehicle (the attitude loop's lag, the tilt limit) it does not settle.
        let f = twin.fly(&plant, &mpc).unwrap();
        assert!(!twin_bounds.admit(&f, &bounds), "{f:?}");
        assert!(f.settle > twin_bounds.settle, "{f:?}");
        // A small delay model of 30 s of the flight, which has the cascade's lag in its
        // data, settles there.
        let g = twin.fly(&tpl, &mpc).unwrap();
        assert!(g.settle > 0.5 && g.settle < twin_bounds.settle, "{g:?}");
        assert!(
            g.check.overshoot < 0.35 && g.check.final_error < 0.01,
            "{g:?}"
        );
    }

    #[test]
    fn the_twin_needs_a_white_box_and_the_controller_s_axes() {
        let sc = Scenario::builtin("training").unwrap();
        let tpl = template(&sc);
        assert!(TwinPlant::new(&sc, &tpl, 2.0, 1).is_err());
    }
}
