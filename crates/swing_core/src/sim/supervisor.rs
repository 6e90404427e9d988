//! Supervision of the swing controller that replaces PX4's velocity PID: attach, engage at
//! a set time with a bumpless start, enforce the per-tick compute budget, and hand the axes
//! back to PX4 for the rest of the run (bumplessly) when a tick fails, is late or returns a
//! non-finite command.

use std::time::Instant;

use nalgebra::Vector3;

use super::runner::TickStats;
use super::ticker::Ticker;
use crate::config::{non_negative, positive, ConfigError};
use crate::control::px4::{AxisSetpoint, Px4Cascade, Px4Params, Setpoint};
use crate::control::{AxisState, ControlOutput, SwingController, TickKind};
use crate::mission::{Guidance, PreviewBuffer};

/// An attached controller and its schedule.
struct Attached {
    ctrl: Box<dyn SwingController>,
    ticker: Ticker,
    budget: f64,
    engage_at: f64,
    started: bool,
    /// What the controller's command replaces.
    output: ControlOutput,
    /// Last accepted command per axis: acceleration [m/s²] or velocity [m/s] (`output`).
    acc: [f64; 2],
    /// Velocity reference of the last tick per axis [m/s].
    vel_ref: [f64; 2],
    /// Time of the reset tick [s] (the controller counts ticks from it).
    t_start: f64,
    /// The guidance's preview for a controller that tracks a position (sized at attach).
    preview: PreviewBuffer,
}

/// What a controller tick reads from the simulation.
pub(crate) struct TickInputs<'a> {
    /// Time [s].
    pub t: f64,
    /// Measured swing angles N, E [rad].
    pub swing: [f64; 2],
    /// Swing rates N, E [rad/s].
    pub swing_rate: [f64; 2],
    /// Measured position (NED) [m].
    pub pos: &'a Vector3<f64>,
    /// Measured velocity (NED) [m/s].
    pub vel: &'a Vector3<f64>,
    /// PX4 parameters (position gains and limits, velocity P gains for the hand-back).
    pub px4: &'a Px4Params,
    /// Rotor thrust projected on the vertical (up) [N].
    pub thrust_vertical: f64,
    /// The mission's guidance, once a mission is flown.
    pub guidance: Option<&'a dyn Guidance>,
}

/// The swing controller's supervisor (see module docs); without a controller it does nothing.
#[derive(Default)]
pub(crate) struct ControllerSupervisor {
    attached: Option<Attached>,
    active: bool,
    fallback: bool,
    fallback_reason: Option<String>,
    stats: TickStats,
}

impl ControllerSupervisor {
    /// Attach `ctrl` at physics step `step` of size `h` [s]; its ticks fall on the multiples
    /// of its period in physics steps, counted from step 0.
    pub(crate) fn attach(
        &mut self,
        ctrl: Box<dyn SwingController>,
        engage_at: f64,
        budget: f64,
        h: f64,
        step: u64,
    ) -> Result<(), ConfigError> {
        let period = ctrl.period();
        let steps = period / h;
        if !(steps >= 1.0 - 1e-9 && (steps - steps.round()).abs() < 1e-6) {
            return Err(ConfigError::new(
                "controller.period",
                format!("{period} s is not a multiple of the physics step {h} s"),
            ));
        }
        if !(1..=2).contains(&ctrl.axes()) {
            return Err(ConfigError::new(
                "controller.axes",
                "must be 1 (N) or 2 (N+E)",
            ));
        }
        non_negative("controller.engage_at", engage_at)?;
        positive("controller.budget", budget)?;
        let output = ctrl.output();
        let ref_steps = ctrl.reference_steps();
        let axes = ctrl.axes();
        self.attached = Some(Attached {
            output,
            preview: PreviewBuffer::new(ref_steps, axes),
            ctrl,
            ticker: Ticker::at_step(steps.round() as u64, step),
            budget,
            engage_at,
            started: false,
            acc: [0.0; 2],
            vel_ref: [0.0; 2],
            t_start: 0.0,
        });
        Ok(())
    }

    /// Advance the controller's ticker by one physics step; true when a tick is due and the
    /// controller has not been handed back.
    #[inline]
    pub(crate) fn due(&mut self) -> bool {
        let due = match self.attached.as_mut() {
            Some(a) => a.ticker.due(),
            None => false,
        };
        due && !self.fallback
    }

    /// Whether the controller's command currently replaces PX4's velocity PID.
    pub(crate) fn active(&self) -> bool {
        self.active
    }

    /// Whether the controller has been handed back to PX4.
    pub(crate) fn fell_back(&self) -> bool {
        self.fallback
    }

    /// Why the controller was handed back, if it was.
    pub(crate) fn fallback_reason(&self) -> Option<&str> {
        self.fallback_reason.as_deref()
    }

    /// Tick timings so far.
    pub(crate) fn stats(&self) -> &TickStats {
        &self.stats
    }

    /// Predicted outputs of the controller's last tick, if it predicts.
    pub(crate) fn prediction(&mut self) -> Option<Vec<f64>> {
        self.attached.as_mut().and_then(|a| a.ctrl.prediction())
    }

    /// The attached controller's events as (time [s], what, value); ticks are counted from
    /// the reset tick, which is also the first step.
    pub(crate) fn events(&self) -> Vec<(f64, &'static str, f64)> {
        match &self.attached {
            Some(a) if a.started => {
                let period = a.ctrl.period();
                a.ctrl
                    .events()
                    .iter()
                    .map(|e| (a.t_start + (e.tick as f64 - 1.0) * period, e.what, e.value))
                    .collect()
            }
            _ => Vec::new(),
        }
    }

    /// Replace the controlled axes' setpoints by the controller's command while active: an
    /// acceleration, or a velocity setpoint PX4's velocity PID tracks.
    pub(crate) fn override_setpoint(&self, sp: &mut Setpoint) {
        if let (true, Some(a)) = (self.active, &self.attached) {
            for i in 0..a.ctrl.axes() {
                sp.axes[i] = match a.output {
                    ControlOutput::Acceleration => AxisSetpoint::Acceleration(a.acc[i]),
                    ControlOutput::Velocity => AxisSetpoint::Velocity(a.acc[i]),
                };
            }
        }
    }

    /// Replace the controlled axes' velocity setpoints by the controller's reference while
    /// active (for the trace); a velocity-output controller's own setpoint is PX4's already.
    pub(crate) fn override_velocity(&self, vel_sp: &mut Vector3<f64>) {
        if let (true, Some(a)) = (self.active, &self.attached) {
            if a.output == ControlOutput::Acceleration {
                for i in 0..a.ctrl.axes() {
                    vel_sp[i] = a.vel_ref[i];
                }
            }
        }
    }

    /// One controller tick (call when [`Self::due`]): engage (bumplessly) once the engage
    /// time is reached, step, time it, and fall back to PX4 on error, overrun or a
    /// non-finite command. `sp` and `fc` are PX4's setpoint and cascade.
    pub(crate) fn tick(&mut self, inp: &TickInputs<'_>, sp: &mut Setpoint, fc: &mut Px4Cascade) {
        let t = inp.t;
        let Some(a) = self.attached.as_mut() else {
            return;
        };
        if t + 1e-9 < a.engage_at {
            return;
        }
        let axes = a.ctrl.axes();
        let mut states = [AxisState::default(); 2];
        let mut vel_ref = [0.0; 2];
        for i in 0..axes {
            states[i] = AxisState {
                v: inp.vel[i],
                swing: inp.swing[i],
                swing_rate: inp.swing_rate[i],
            };
            vel_ref[i] = match sp.axes[i] {
                AxisSetpoint::Velocity(v) => v,
                AxisSetpoint::Position(x) => ((x - inp.pos[i]) * inp.px4.pos_p[i])
                    .clamp(-inp.px4.vel_max_xy, inp.px4.vel_max_xy),
                AxisSetpoint::Trajectory { p, v, .. } => (v + (p - inp.pos[i]) * inp.px4.pos_p[i])
                    .clamp(-inp.px4.vel_max_xy, inp.px4.vel_max_xy),
                AxisSetpoint::Acceleration(_) => 0.0,
            };
        }
        if a.preview.steps() > 0 {
            // A controller that tracks a trajectory engages with the mission.
            let Some(g) = inp.guidance else {
                return;
            };
            let period = a.ctrl.period();
            let view = a.preview.fill(g, t, period);
            a.ctrl
                .observe_reference(&[inp.pos[0], inp.pos[1]][..axes], &view);
        }
        if !a.started {
            let acc = [fc.acc_sp.x, fc.acc_sp.y];
            a.ctrl.reset(&states[..axes], &acc[..axes]);
            a.acc = match a.output {
                ControlOutput::Acceleration => acc,
                ControlOutput::Velocity => vel_ref,
            };
            a.started = true;
            a.t_start = t;
        }
        a.ctrl.observe_vertical(inp.thrust_vertical, inp.vel[2]);
        let mut out = [0.0; 2];
        let t0 = Instant::now();
        let res = a
            .ctrl
            .step(&states[..axes], &vel_ref[..axes], &mut out[..axes]);
        let elapsed = t0.elapsed().as_secs_f64();
        self.stats.tick_us.push(elapsed * 1e6);
        a.ctrl.between_ticks();
        let reason = match &res {
            Err(e) => Some(format!("controller error: {e}")),
            Ok(_) if elapsed > a.budget => Some(format!(
                "tick took {:.3} ms, over its {:.3} ms budget",
                elapsed * 1e3,
                a.budget * 1e3
            )),
            Ok(_) if out[..axes].iter().any(|x| !x.is_finite()) => {
                Some("controller output is not finite".to_string())
            }
            Ok(_) => None,
        };
        if let Ok(info) = res {
            if info.kind == TickKind::Constrained {
                self.stats.constrained += 1;
            }
        }
        a.vel_ref = vel_ref;
        match reason {
            None => {
                a.acc = out;
                self.active = true;
            }
            Some(r) => {
                // Bumpless hand-back: PX4's velocity integrator takes the last acceleration
                // command (a velocity-output controller never replaced PX4's PID).
                for i in 0..axes {
                    if a.output == ControlOutput::Acceleration {
                        let err = vel_ref[i] - inp.vel[i];
                        let v = a.acc[i] - err * inp.px4.vel_p[i];
                        fc.set_velocity_integrator(i, v);
                    }
                    sp.axes[i] = AxisSetpoint::Velocity(vel_ref[i]);
                }
                self.active = false;
                self.fallback = true;
                self.fallback_reason = Some(format!("t = {t:.2} s: {r}"));
            }
        }
    }
}
