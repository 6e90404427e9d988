//! Adaptive MPC: the identified model follows the payload in flight.
//!
//! Each tick (the real-time path, no allocation): the newest measured frame and the last
//! applied input update the online DMDc ([`OnlineDmdc`]: forgetting, excitation gate, change
//! detector on the adopted model's one-step residual); then the active [`MpcController`]
//! steps. When the detector has fired and, since then, `min_new_samples` excited samples
//! have entered the estimate, the current factor is copied into a recycled buffer and handed
//! to the synthesis, which runs off the tick path:
//! - `thread` (real time): a worker thread owns the template model and the settings; it
//!   builds the rank-p model from the factor (the truncated SVD of the batch fit), designs
//!   the MPC (condensing, law, Kalman gain) and checks it. The tick only `try_send`s and
//!   `try_recv`s on bounded channels and never waits.
//! - `deferred` (simulation): the same job runs in [`SwingController::between_ticks`], which
//!   runners call after the timed tick, so that a simulated flight stays a pure function of
//!   its scenario.
//!
//! Check before a swap (`control::check`, bounds of `control::selection`): the candidate's
//! spectral radius is at most `max_spectral_radius`, and its MPC, in closed loop on the
//! candidate model itself and on the candidate with extra vehicle drag (both without the
//! constant term, which is the recent data's operating point), each behind every input lag, holds hover, tracks a velocity step and stays within `bounds`. A candidate
//! that fails is dropped and the old controller kept; the synthesis retries after
//! `retry_samples` more excited samples.
//!
//! The swap happens at the start of a tick, before the step: the new controller takes over
//! the measured delay stack, the last input and the state estimate of the old one (bumpless).
//! The disturbance estimate restarts at zero when the model has the affine offset, because
//! the refit's constant term has just absorbed the steady offsets of the recent data and
//! keeping the old estimate would count them twice; without the affine column it is kept.
//! Replaced controllers and models are dropped on the worker, not on the tick.
//!
//! Revert. The check flies a candidate on its own model, so it cannot catch a model that is
//! wrong about the vehicle. The controller a swap replaced is kept; if the detector fires
//! again within `revert_window` ticks of the swap (the new model mispredicts at once), the
//! old controller, which has flown, takes over again; adaptation goes on with more data, and
//! stops for the flight after [`MAX_REVERTS`] reverts.

use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TryRecvError, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;

use serde::{Deserialize, Serialize};

use std::time::Instant;

use super::check::{step_check_with, StepCheck, StepCheckSettings};
use super::layout::{AxisLayout, Measured};
use super::mpc::timing::TickTiming;
use super::plant::LinearPlant;
use super::selection::CheckBounds;
use super::twin::{Twin, MIN_TWIN_SECONDS};
use super::{
    AxisState, ControlError, ControllerEvent, MpcController, MpcSettings, SwingController, TickInfo,
};
use crate::config::{non_negative, positive, ConfigError};
use crate::sysid::online::{model_from_factor, OnlineDmdc, OnlineSettings};
use crate::sysid::payload::{PayloadTracker, TrackerSettings};
use crate::sysid::{LinearModel, Offset};

/// Where the re-synthesis runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SynthesisMode {
    /// A worker thread (real time; the swap tick depends on wall-clock time).
    Thread,
    /// Between ticks on the caller's thread (simulation; reproducible).
    #[default]
    Deferred,
}

/// Settings of the adaptive MPC (the MPC's own settings are separate).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdaptiveSettings {
    /// Online identification: forgetting, excitation gate, detector.
    pub online: OnlineSettings,
    /// Excited samples that must enter the estimate after a detection before a rebuild
    /// [samples of the model's dt].
    pub min_new_samples: usize,
    /// Further excited samples before retrying after a rejected candidate [samples].
    pub retry_samples: usize,
    /// Velocity step of the closed-loop check [m/s].
    pub check_step: f64,
    /// Input lags of the closed-loop check [s] (0 = none).
    pub input_lags: Vec<f64>,
    /// Linear vehicle drag added to the candidate as a second check plant [1/s] (0 = only
    /// the candidate itself).
    pub check_drag: f64,
    /// Pass bounds of the check (fractions of the step).
    pub bounds: CheckBounds,
    /// Largest spectral radius of a candidate's A [dimensionless].
    pub max_spectral_radius: f64,
    /// Where the synthesis runs: `deferred` (simulation) or `thread` (real time).
    pub synthesis: SynthesisMode,
    /// Amplitude of a probing input added to the command from a detection until the next
    /// adoption [m/s²] (0 = off, the default): a pseudo-random ±amplitude sequence held for
    /// `probe_hold` ticks, which breaks the collinearity of input and state that feedback
    /// leaves in closed-loop data.
    pub probe_amplitude: f64,
    /// Ticks each probing level is held [ticks].
    pub probe_hold: usize,
    /// A detection within this many ticks of a swap reverts to the controller the swap
    /// replaced, which has flown [ticks] (0 = never); after three reverts adaptation stops
    /// for the flight.
    pub revert_window: usize,
    /// Re-identification on the vehicle's twin from the payload measured in flight
    /// ([`super::twin`]); off by default, and it needs a twin at construction.
    pub twin: TwinSettings,
}

/// Settings of the twin path of the adaptive MPC: when the measured cable length departs
/// from the model's, fly the twin with the measured payload and re-identify.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TwinSettings {
    /// Use the twin (and not the online DMDc's refits) to re-identify.
    pub enabled: bool,
    /// Length of the twin's training flight [s].
    pub duration: f64,
    /// Search the rank at the model's delays and select for control, as the model before
    /// the flight was (false: keep the model's rank).
    pub search: bool,
    /// Relative change of the measured cable length that triggers a re-identification
    /// [fraction].
    pub length_change: f64,
    /// Largest relative standard error of a length estimate acted upon [fraction] (it must
    /// also depart from the model's by [`LENGTH_SIGNIFICANCE`] standard errors).
    pub confidence: f64,
    /// Change of the measured total mass that starts probing until the length is confirmed
    /// [kg] (a pick-up in hover leaves the payload still, and a still pendulum shows no
    /// length); probing needs `probe_amplitude` > 0.
    pub mass_change: f64,
    /// Longest probing after a mass change [s].
    pub probe_seconds: f64,
    /// Forgetting factor per tick of the length estimate, (0, 1).
    pub forgetting: f64,
}

impl Default for TwinSettings {
    fn default() -> Self {
        Self {
            enabled: false,
            duration: 120.0,
            search: true,
            length_change: 0.15,
            confidence: 0.4,
            mass_change: 0.05,
            probe_seconds: 3.0,
            forgetting: 0.99,
        }
    }
}

impl TwinSettings {
    /// Check every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ConfigError> {
        crate::config::in_range("duration", self.duration, MIN_TWIN_SECONDS, 3600.0)?;
        positive("length_change", self.length_change)?;
        positive("confidence", self.confidence)?;
        positive("mass_change", self.mass_change)?;
        non_negative("probe_seconds", self.probe_seconds)?;
        crate::config::in_range("forgetting", self.forgetting, 0.5, 0.9999)?;
        Ok(())
    }
}

/// The twin and the payload the initial model was identified with.
#[derive(Clone, Debug)]
pub struct TwinPrior {
    /// The vehicle's twin.
    pub twin: Twin,
    /// Payload mass of the initial model [kg].
    pub payload_mass: f64,
    /// Cable length of the initial model [m].
    pub length: f64,
}

impl Default for AdaptiveSettings {
    fn default() -> Self {
        Self {
            online: OnlineSettings::default(),
            min_new_samples: 150,
            retry_samples: 60,
            check_step: 2.0,
            input_lags: vec![0.0, 0.1],
            check_drag: 0.12,
            bounds: CheckBounds::default(),
            max_spectral_radius: 1.005,
            synthesis: SynthesisMode::Deferred,
            probe_amplitude: 0.0,
            probe_hold: 5,
            revert_window: 200,
            twin: TwinSettings::default(),
        }
    }
}

impl AdaptiveSettings {
    /// Check every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.online.validate().map_err(|e| e.within("online"))?;
        if self.min_new_samples == 0 {
            return Err(ConfigError::new("min_new_samples", "must be at least 1"));
        }
        if self.retry_samples == 0 {
            return Err(ConfigError::new("retry_samples", "must be at least 1"));
        }
        positive("check_step", self.check_step)?;
        if self.input_lags.is_empty() {
            return Err(ConfigError::new(
                "input_lags",
                "needs at least one lag (0 = none)",
            ));
        }
        for (i, l) in self.input_lags.iter().enumerate() {
            non_negative(&format!("input_lags[{i}]"), *l)?;
        }
        non_negative("check_drag", self.check_drag)?;
        for (name, v) in [
            ("bounds.overshoot", self.bounds.overshoot),
            ("bounds.final_error", self.bounds.final_error),
            ("bounds.hold_drift", self.bounds.hold_drift),
        ] {
            positive(name, v)?;
        }
        positive("max_spectral_radius", self.max_spectral_radius)?;
        crate::config::in_range("probe_amplitude", self.probe_amplitude, 0.0, 2.0)?;
        if self.probe_hold == 0 {
            return Err(ConfigError::new("probe_hold", "must be at least 1 tick"));
        }
        self.twin.validate().map_err(|e| e.within("twin"))?;
        Ok(())
    }
}

/// The factor handed to the synthesis (a recycled buffer).
struct Job {
    factor: Vec<f64>,
    weight: f64,
    /// Fly the twin with this payload (mass [kg], length [m]) instead of using the factor.
    twin: Option<[f64; 2]>,
}

/// A candidate that passed the check (boxed so that the swap moves pointers only).
struct Candidate {
    mpc: Box<MpcController>,
    model: Box<LinearModel>,
}

/// What a synthesis returns; `job` comes back for reuse.
struct Outcome {
    job: Box<Job>,
    result: Result<Candidate, String>,
    check: Option<StepCheck>,
}

/// Messages to the worker.
enum ToWorker {
    Build(Box<Job>),
    /// Replaced objects, dropped on the worker.
    Retire(#[allow(dead_code)] Retired),
}

/// What a swap or a rejection leaves behind.
enum Retired {
    Controller(
        #[allow(dead_code)] Box<MpcController>,
        #[allow(dead_code)] Box<LinearModel>,
    ),
    Reason(#[allow(dead_code)] String),
}

/// What the synthesis needs besides the factor: fixed for the controller's life.
struct Synthesizer {
    template: LinearModel,
    mpc: MpcSettings,
    settings: AdaptiveSettings,
    twin: Option<Twin>,
}

impl Synthesizer {
    fn run(&self, job: Box<Job>) -> Outcome {
        let mut check = None;
        let result = self.build(&job, &mut check);
        Outcome { job, result, check }
    }

    fn build(&self, job: &Job, check_out: &mut Option<StepCheck>) -> Result<Candidate, String> {
        let t = &self.template;
        let full = t.m() + usize::from(t.offset == Offset::Affine) + t.n() * t.delays;
        // Rank 0 marks a full-rank model.
        let rank = if t.rank == 0 { full } else { t.rank.min(full) };
        let model = match (job.twin, &self.twin) {
            (Some([mass, length]), Some(twin)) => twin.identify(t, mass, length, &self.mpc)?,
            (Some(_), None) => return Err("no twin to fly".into()),
            (None, _) => {
                model_from_factor(&job.factor, job.weight, rank, t).map_err(|e| e.to_string())?
            }
        };
        let rho = model.spectral_radius().map_err(|e| e.to_string())?;
        // NaN is refused too.
        if rho.is_nan() || rho > self.settings.max_spectral_radius {
            return Err(format!(
                "spectral radius {rho:.4} above {}",
                self.settings.max_spectral_radius
            ));
        }
        if job.twin.is_some()
            && self
                .twin
                .as_ref()
                .is_some_and(|_| self.settings.twin.search)
        {
            // The twin's selection has flown this candidate's MPC against the white-box of
            // the measured payload, with drag and input lag: a stronger check than the
            // candidate on itself.
            return Ok(Candidate {
                mpc: Box::new(
                    MpcController::new(&model, self.mpc.clone()).map_err(|e| e.to_string())?,
                ),
                model: Box::new(model),
            });
        }
        // The refit's constant term is the operating point of the recent data (drag at
        // cruise, a thrust offset). In the check (a plant started at rest) it would be a
        // disturbance the hold phase measures instead of the dynamics, so the check flies an
        // MPC designed on the model without it, on plants without it; the MPC swapped in is
        // designed on the model as fitted.
        let mut bare = model.clone();
        bare.c.fill(0.0);
        let mut plants = vec![bare.clone()];
        if self.settings.check_drag > 0.0 {
            plants.push(
                bare.with_velocity_drag(self.settings.check_drag)
                    .map_err(|e| e.to_string())?,
            );
        }
        let mut checked = MpcController::new(&bare, self.mpc.clone()).map_err(|e| e.to_string())?;
        let mut worst = StepCheck {
            overshoot: f64::NEG_INFINITY,
            final_error: f64::NEG_INFINITY,
            hold_drift: f64::NEG_INFINITY,
        };
        for plant in &plants {
            for &input_lag in &self.settings.input_lags {
                let c = StepCheckSettings {
                    step: self.settings.check_step,
                    input_lag,
                    ..StepCheckSettings::default()
                };
                let r =
                    step_check_with(&mut checked, &bare, plant, &c).map_err(|e| e.to_string())?;
                worst.overshoot = worst.overshoot.max(r.overshoot);
                worst.final_error = worst.final_error.max(r.final_error);
                worst.hold_drift = worst.hold_drift.max(r.hold_drift);
            }
        }
        *check_out = Some(worst);
        if !self.settings.bounds.admit(&worst) {
            return Err(format!(
                "closed-loop check failed: overshoot {:.3}, final error {:.3}, hold drift {:.3}",
                worst.overshoot, worst.final_error, worst.hold_drift
            ));
        }
        let mpc = if model.c.iter().all(|v| *v == 0.0) {
            checked
        } else {
            MpcController::new(&model, self.mpc.clone()).map_err(|e| e.to_string())?
        };
        Ok(Candidate {
            mpc: Box::new(mpc),
            model: Box::new(model),
        })
    }
}

enum Synthesis {
    Thread {
        tx: Option<SyncSender<ToWorker>>,
        rx: Receiver<Outcome>,
        handle: Option<JoinHandle<()>>,
    },
    Deferred {
        pending: Option<Box<Job>>,
        done: Option<Outcome>,
    },
}

/// Reverts after which adaptation stops for the flight: a change the online model keeps
/// failing to capture is left to the controller that has flown.
pub const MAX_REVERTS: usize = 3;

/// Smallest payload mass the twin re-identifies for [kg]: below it the swing carries no
/// dynamics to identify (the payload is gone).
pub const MIN_PAYLOAD_MASS: f64 = 0.02;

/// Standard errors by which a measured length must depart from the model's to act on it.
pub const LENGTH_SIGNIFICANCE: f64 = 3.0;

/// Spread of the total-mass estimate over the settle window below which it counts as
/// settled [kg].
pub const MASS_SETTLED_KG: f64 = 0.01;

/// Most adaptation events kept (the log is preallocated; later events are counted only).
pub const MAX_EVENTS: usize = 256;

/// The adaptive MPC controller (see module docs); implements [`SwingController`].
pub struct AdaptiveMpc {
    active: Box<MpcController>,
    model: Box<LinearModel>,
    online: OnlineDmdc,
    synth: Arc<Synthesizer>,
    synthesis: Synthesis,
    spare: Option<Box<Job>>,
    sources: Vec<Measured>,
    x: Vec<f64>,
    u_last: [f64; 2],
    have_last: bool,
    busy: bool,
    retry_after: u64,
    min_new_samples: usize,
    retry_samples: u64,
    probe_amplitude: f64,
    probe_hold: u64,
    previous: Option<(Box<MpcController>, Box<LinearModel>)>,
    swapped_at: u64,
    revert_window: u64,
    suspended: bool,
    reverts: usize,
    probe_state: u64,
    probe_level: f64,
    tick: u64,
    dt: f64,
    m: usize,
    keep_disturbance: bool,
    events: Vec<ControllerEvent>,
    dropped_events: usize,
    swaps: usize,
    rejections: usize,
    last_rejection: [u8; 160],
    last_rejection_len: usize,
    tracker: PayloadTracker,
    twin: Option<TwinState>,
}

/// The twin path's state on the tick side.
#[derive(Clone, Copy, Debug)]
struct TwinState {
    settings_length_change: f64,
    confidence: f64,
    mass_change: f64,
    probe_ticks: u64,
    vehicle_mass: f64,
    /// Payload (mass [kg], length [m]) the active model was identified for.
    reference: [f64; 2],
    /// Measured total mass when the active model was adopted (NaN until measured).
    mass_at_reference: f64,
    /// Payload of the candidate in the synthesis.
    pending: [f64; 2],
    /// Probe until this tick (0 = not probing).
    probe_until: u64,
    /// No new twin request before this tick (after a rejection).
    retry_at: u64,
}

impl std::fmt::Debug for AdaptiveMpc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AdaptiveMpc")
            .field("active", &self.active)
            .field("swaps", &self.swaps)
            .field("rejections", &self.rejections)
            .finish()
    }
}

impl AdaptiveMpc {
    /// Build the controller on the identified `model`: its MPC, the online estimator of the
    /// same layout (adopting `model`) and the synthesis (a worker thread in `thread` mode).
    pub fn new(
        model: &LinearModel,
        mpc: MpcSettings,
        settings: AdaptiveSettings,
    ) -> Result<Self, ControlError> {
        Self::with_twin(model, mpc, settings, None)
    }

    /// As [`Self::new`], with the vehicle's twin for re-identification from the measured
    /// payload (used when `settings.twin.enabled`; required then).
    pub fn with_twin(
        model: &LinearModel,
        mpc: MpcSettings,
        settings: AdaptiveSettings,
        prior: Option<TwinPrior>,
    ) -> Result<Self, ControlError> {
        settings.validate()?;
        if settings.twin.enabled && prior.is_none() {
            return Err(ControlError::Config(ConfigError::new(
                "twin.enabled",
                "needs the vehicle's twin (the training flight's scenario)",
            )));
        }
        if let Some(p) = &prior {
            positive("twin.payload_mass", p.payload_mass)?;
            positive("twin.length", p.length)?;
        }
        let twin_state = prior
            .as_ref()
            .filter(|_| settings.twin.enabled)
            .map(|p| TwinState {
                settings_length_change: settings.twin.length_change,
                confidence: settings.twin.confidence,
                mass_change: settings.twin.mass_change,
                probe_ticks: (settings.twin.probe_seconds / model.dt).round() as u64,
                vehicle_mass: p.twin.vehicle_mass(),
                reference: [p.payload_mass, p.length],
                mass_at_reference: f64::NAN,
                pending: [f64::NAN; 2],
                probe_until: 0,
                retry_at: 0,
            });
        let tracker = PayloadTracker::new(
            model.m(),
            model.dt,
            TrackerSettings {
                forgetting: settings.twin.forgetting,
                ..TrackerSettings::default()
            },
        );
        let active = Box::new(MpcController::new(model, mpc.clone())?);
        let online = OnlineDmdc::for_model(model, settings.online.clone())?;
        let layout = AxisLayout::from_model(model)?;
        let sources = model
            .states
            .iter()
            .map(|name| {
                layout.classify(name).ok_or_else(|| {
                    ControlError::Model(format!("model state '{name}' is not measured"))
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let cols = online.columns();
        let job = || {
            Box::new(Job {
                factor: vec![0.0; cols * cols],
                weight: 0.0,
                twin: None,
            })
        };
        let synth = Arc::new(Synthesizer {
            template: model.clone(),
            mpc,
            settings: settings.clone(),
            twin: prior.map(|p| p.twin),
        });
        let synthesis = match settings.synthesis {
            SynthesisMode::Deferred => Synthesis::Deferred {
                pending: None,
                done: None,
            },
            SynthesisMode::Thread => {
                // Capacity 2: one build and one drop may be in flight at once.
                let (tx, jobs) = sync_channel::<ToWorker>(2);
                let (out, rx) = sync_channel::<Outcome>(1);
                let synth = Arc::clone(&synth);
                let handle = std::thread::Builder::new()
                    .name("swingrt-adaptive-synthesis".into())
                    .spawn(move || {
                        while let Ok(msg) = jobs.recv() {
                            if let ToWorker::Build(job) = msg {
                                if out.send(synth.run(job)).is_err() {
                                    break;
                                }
                            }
                        }
                    })
                    .map_err(|e| ControlError::Synthesis(format!("cannot start worker: {e}")))?;
                Synthesis::Thread {
                    tx: Some(tx),
                    rx,
                    handle: Some(handle),
                }
            }
        };
        Ok(Self {
            active,
            model: Box::new(model.clone()),
            online,
            synth,
            synthesis,
            spare: Some(job()),
            x: vec![0.0; sources.len()],
            sources,
            u_last: [0.0; 2],
            have_last: false,
            busy: false,
            retry_after: 0,
            min_new_samples: settings.min_new_samples,
            retry_samples: settings.retry_samples as u64,
            probe_amplitude: settings.probe_amplitude,
            probe_hold: settings.probe_hold as u64,
            previous: None,
            swapped_at: 0,
            revert_window: settings.revert_window as u64,
            suspended: false,
            reverts: 0,
            probe_state: 0x9e37_79b9_7f4a_7c15,
            probe_level: 0.0,
            tick: 0,
            dt: model.dt,
            m: model.m(),
            keep_disturbance: model.offset != Offset::Affine,
            events: Vec::with_capacity(MAX_EVENTS),
            dropped_events: 0,
            swaps: 0,
            rejections: 0,
            last_rejection: [0; 160],
            last_rejection_len: 0,
            tracker,
            twin: twin_state,
        })
    }

    /// The model the active controller was designed on.
    pub fn model(&self) -> &LinearModel {
        &self.model
    }

    /// The active MPC.
    pub fn controller(&self) -> &MpcController {
        &self.active
    }

    /// The online estimator.
    pub fn online(&self) -> &OnlineDmdc {
        &self.online
    }

    /// Models adopted since the start.
    pub fn swaps(&self) -> usize {
        self.swaps
    }

    /// Candidates rejected by the check.
    pub fn rejections(&self) -> usize {
        self.rejections
    }

    /// Why the last candidate was rejected (empty when none was).
    pub fn last_rejection(&self) -> &str {
        std::str::from_utf8(&self.last_rejection[..self.last_rejection_len]).unwrap_or("")
    }

    /// Run the re-synthesis on the current factor now, on this thread (benchmarks, tests):
    /// the candidate model, or why it was refused.
    pub fn synthesize_now(&self) -> Result<LinearModel, String> {
        let cols = self.online.columns();
        let job = Box::new(Job {
            factor: self.online.factor()[..cols * cols].to_vec(),
            weight: self.online.weight(),
            twin: None,
        });
        self.synth.run(job).result.map(|c| *c.model)
    }

    fn log(&mut self, what: &'static str, value: f64) {
        if self.events.len() < MAX_EVENTS {
            self.events.push(ControllerEvent {
                tick: self.tick,
                what,
                value,
            });
        } else {
            self.dropped_events += 1;
        }
    }

    /// Dispose of a replaced object off the tick path.
    fn discard(&mut self, trash: Retired) {
        match &mut self.synthesis {
            Synthesis::Thread { tx: Some(tx), .. } => {
                // A full channel means the worker is busy; dropping here is then the lesser evil.
                let _ = tx.try_send(ToWorker::Retire(trash));
            }
            _ => drop(trash),
        }
    }

    /// Apply a finished synthesis, if there is one.
    fn poll(&mut self) -> Result<(), ControlError> {
        let outcome = match &mut self.synthesis {
            Synthesis::Thread { rx, .. } => match rx.try_recv() {
                Ok(o) => Some(o),
                Err(TryRecvError::Empty) => None,
                Err(TryRecvError::Disconnected) => {
                    return Err(ControlError::Synthesis("synthesis worker stopped".into()))
                }
            },
            Synthesis::Deferred { done, .. } => done.take(),
        };
        let Some(outcome) = outcome else {
            return Ok(());
        };
        self.busy = false;
        let from_twin = outcome.job.twin.is_some();
        self.spare = Some(outcome.job);
        match outcome.result {
            Ok(Candidate { mut mpc, model }) => {
                if let (true, Some(tw)) = (from_twin, self.twin.as_mut()) {
                    tw.reference = tw.pending;
                    tw.mass_at_reference = self.tracker.total_mass().unwrap_or(f64::NAN);
                    tw.probe_until = 0;
                }
                mpc.take_over(&self.active, self.keep_disturbance)?;
                self.online.adopt(&model)?;
                let old_mpc = std::mem::replace(&mut self.active, mpc);
                let old_model = std::mem::replace(&mut self.model, model);
                // The replaced controller stays at hand for a revert; one held before it
                // (flown, then replaced) goes.
                if let Some((m, l)) = self.previous.take() {
                    self.discard(Retired::Controller(m, l));
                }
                self.previous = Some((old_mpc, old_model));
                self.swapped_at = self.tick;
                self.swaps += 1;
                let overshoot = outcome.check.map_or(f64::NAN, |c| c.overshoot);
                self.log("adopted", overshoot);
            }
            Err(reason) => {
                self.rejections += 1;
                let bytes = reason.as_bytes();
                let mut len = bytes.len().min(self.last_rejection.len());
                while !reason.is_char_boundary(len) {
                    len -= 1;
                }
                self.last_rejection[..len].copy_from_slice(&bytes[..len]);
                self.last_rejection_len = len;
                self.retry_after = self.online.accepted() + self.retry_samples;
                if let (true, Some(tw)) = (from_twin, self.twin.as_mut()) {
                    tw.retry_at = self.tick + self.retry_samples;
                }
                // The value says which test refused it: the check's worst miss ratio, or
                // NaN when the model itself was refused (unstable, no design).
                let miss = outcome
                    .check
                    .map_or(f64::NAN, |c| self.synth.settings.bounds.miss(&c));
                self.log("rejected", miss);
                self.discard(Retired::Reason(reason));
            }
        }
        Ok(())
    }

    /// Hand the current factor to the synthesis when a rebuild is due.
    /// Go back to the controller replaced by the last swap (see [`AdaptiveSettings`]'s
    /// `revert_window`); after [`MAX_REVERTS`] reverts adaptation stops for the flight.
    fn revert(&mut self) -> Result<(), ControlError> {
        let Some((mut mpc, model)) = self.previous.take() else {
            return Ok(());
        };
        mpc.take_over(&self.active, true)?;
        self.online.adopt(&model)?;
        let failed_mpc = std::mem::replace(&mut self.active, mpc);
        let failed_model = std::mem::replace(&mut self.model, model);
        self.discard(Retired::Controller(failed_mpc, failed_model));
        self.reverts += 1;
        self.suspended = self.reverts >= MAX_REVERTS;
        self.log("reverted", (self.tick - self.swapped_at) as f64);
        Ok(())
    }

    /// Twin path: probe after a mass change until the length is confirmed; request a
    /// re-identification when the measured length departs from the model's.
    fn maybe_request_twin(&mut self) {
        let Some(mut tw) = self.twin else {
            return;
        };
        let request = self.twin_decision(&mut tw);
        self.twin = Some(tw);
        let Some(payload) = request else {
            return;
        };
        let Some(mut job) = self.spare.take() else {
            return;
        };
        job.twin = Some(payload);
        if self.send(job) {
            if let Some(tw) = self.twin.as_mut() {
                tw.pending = payload;
            }
            self.busy = true;
            self.log("requested", payload[1]);
        }
    }

    /// The twin path's bookkeeping of one tick; the payload (mass, length) to fly the twin
    /// with, when a re-identification is due.
    fn twin_decision(&mut self, tw: &mut TwinState) -> Option<[f64; 2]> {
        let mass = self.tracker.total_mass();
        if let Some(m) = mass {
            if tw.mass_at_reference.is_nan() {
                tw.mass_at_reference = m;
            } else if (m - tw.mass_at_reference).abs() > tw.mass_change
                && tw.probe_until == 0
                && !self.busy
            {
                tw.probe_until = self.tick + tw.probe_ticks;
                // The old swing says nothing about the new payload.
                self.tracker.restart();
                tw.mass_at_reference = m;
                self.log("mass_changed", m);
                return None;
            }
        }
        let (length, rel) = self.tracker.length()?;
        if rel > tw.confidence {
            return None;
        }
        tw.probe_until = 0; // the length is confirmed
        if self.busy || self.suspended || self.tick < tw.retry_at {
            return None;
        }
        // Act on a length that departs from the model's by more than the tolerance and by
        // more than LENGTH_SIGNIFICANCE standard errors: in a transient the residual of the
        // pendulum equation (sensor lag, large angles) widens the error bar long after the
        // estimate itself has converged.
        let departure = (length - tw.reference[1]).abs();
        if departure <= tw.settings_length_change * tw.reference[1]
            || departure <= LENGTH_SIGNIFICANCE * rel * length
        {
            return None;
        }
        // A new length is a new payload (or the same one winched): the mass change since
        // the model's payload is the payload's. A mass change at an unchanged length is
        // taken as the vehicle's, which PX4's hover thrust absorbs.
        let payload_mass = match mass {
            // Wait until a pick-up's thrust step has settled in the estimate.
            Some(_) if !self.tracker.mass_settled(MASS_SETTLED_KG) => return None,
            Some(m) => m - tw.vehicle_mass,
            None => tw.reference[0],
        };
        (payload_mass >= MIN_PAYLOAD_MASS).then_some([payload_mass, length])
    }

    /// Hand a job to the synthesis; false (job kept) when it cannot take it now.
    fn send(&mut self, job: Box<Job>) -> bool {
        match &mut self.synthesis {
            Synthesis::Thread { tx: Some(tx), .. } => match tx.try_send(ToWorker::Build(job)) {
                Ok(()) => true,
                Err(TrySendError::Full(msg) | TrySendError::Disconnected(msg)) => {
                    if let ToWorker::Build(job) = msg {
                        self.spare = Some(job);
                    }
                    false
                }
            },
            Synthesis::Thread { tx: None, .. } => {
                self.spare = Some(job);
                false
            }
            Synthesis::Deferred { pending, .. } => {
                *pending = Some(job);
                true
            }
        }
    }

    fn maybe_request(&mut self) {
        let o = &self.online;
        let due = !self.busy
            && !self.suspended
            && o.fired()
            && o.excited()
            && o.accepted_since_fire() >= self.min_new_samples
            && o.accepted() >= self.retry_after;
        if !due {
            return;
        }
        let Some(mut job) = self.spare.take() else {
            return;
        };
        job.factor.copy_from_slice(self.online.factor());
        job.weight = self.online.weight();
        job.twin = None;
        if self.send(job) {
            self.busy = true;
            self.log("requested", self.online.weight());
        }
    }
}

impl Drop for AdaptiveMpc {
    fn drop(&mut self) {
        if let Synthesis::Thread { tx, handle, .. } = &mut self.synthesis {
            drop(tx.take());
            if let Some(h) = handle.take() {
                let _ = h.join();
            }
        }
    }
}

impl SwingController for AdaptiveMpc {
    fn axes(&self) -> usize {
        self.m
    }

    fn period(&self) -> f64 {
        self.dt
    }

    fn reset(&mut self, state: &[AxisState], acc: &[f64]) {
        self.active.reset(state, acc);
        self.online.restart_history();
        for a in 0..self.m {
            let u = acc.get(a).copied().unwrap_or(0.0);
            self.u_last[a] = if u.is_finite() { u } else { 0.0 };
        }
        self.have_last = true;
        // The reset frame starts the online history too.
        if fill_frame(&self.sources, state, &mut self.x) {
            let _ = self.online.update(&self.x, &self.u_last[..self.m]);
        }
    }

    fn step(
        &mut self,
        state: &[AxisState],
        vel_ref: &[f64],
        acc_out: &mut [f64],
    ) -> Result<TickInfo, ControlError> {
        super::check_tick_inputs(self.m, state, vel_ref, acc_out)?;
        self.tick += 1;
        if self.have_last && fill_frame(&self.sources, state, &mut self.x) {
            let st = self.online.update(&self.x, &self.u_last[..self.m])?;
            if st.fired && self.twin.is_none() {
                self.log("detected", st.statistic);
                let recent = self.tick - self.swapped_at <= self.revert_window;
                if self.previous.is_some() && recent {
                    self.revert()?;
                }
            }
        }
        self.tracker.update(state);
        self.poll()?;
        let info = self.active.step(state, vel_ref, acc_out)?;
        let probing = match &self.twin {
            Some(tw) => tw.probe_until > self.tick,
            None => self.online.fired(),
        };
        if self.probe_amplitude > 0.0 && probing {
            if self.tick % self.probe_hold == 0 {
                // xorshift64: a fixed-seed pseudo-random sign per hold.
                let mut x = self.probe_state;
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                self.probe_state = x;
                self.probe_level = if x & 1 == 0 { 1.0 } else { -1.0 } * self.probe_amplitude;
            }
            for u in acc_out.iter_mut() {
                *u += self.probe_level;
            }
        }
        self.u_last[..self.m].copy_from_slice(acc_out);
        self.have_last = true;
        if self.twin.is_some() {
            self.maybe_request_twin();
        } else {
            self.maybe_request();
        }
        Ok(info)
    }

    fn prediction(&mut self) -> Option<Vec<f64>> {
        self.active.prediction()
    }

    fn observe_vertical(&mut self, thrust_vertical: f64, vd: f64) {
        self.tracker.update_vertical(thrust_vertical, vd);
    }

    fn between_ticks(&mut self) {
        if let Synthesis::Deferred { pending, done } = &mut self.synthesis {
            if let Some(job) = pending.take() {
                *done = Some(self.synth.run(job));
            }
        }
    }

    fn events(&self) -> Vec<ControllerEvent> {
        self.events.clone()
    }
}

/// The model's state vector from the axis measurements; false when one is not finite.
fn fill_frame(sources: &[Measured], state: &[AxisState], x: &mut [f64]) -> bool {
    for (v, src) in x.iter_mut().zip(sources) {
        let s = match *src {
            Measured::V(a) | Measured::Swing(a) | Measured::SwingRate(a) => state.get(a),
        };
        let Some(s) = s else { return false };
        *v = match *src {
            Measured::V(_) => s.v,
            Measured::Swing(_) => s.swing,
            Measured::SwingRate(_) => s.swing_rate,
        };
    }
    x.iter().all(|v| v.is_finite())
}

/// Timing of the adaptive MPC for `swingrt bench` and the criterion bench: the tick with
/// the online update ([`TickTiming`] in µs) over `n_ticks` ticks in closed loop with
/// `model` itself as the plant under a ±2 m/s square wave of references (every sample
/// excited and accepted), then the re-synthesis on the collected factor, `repeats` times
/// ([`TickTiming`] in ms).
pub fn adaptive_timing(
    model: &LinearModel,
    mpc: &MpcSettings,
    settings: &AdaptiveSettings,
    n_ticks: usize,
    repeats: usize,
) -> Result<(TickTiming, TickTiming), ControlError> {
    if n_ticks == 0 || repeats == 0 {
        return Err(ControlError::Input(
            "n_ticks and repeats must be ≥ 1".into(),
        ));
    }
    let s = AdaptiveSettings {
        synthesis: SynthesisMode::Deferred,
        ..settings.clone()
    };
    let mut ctrl = AdaptiveMpc::new(model, mpc.clone(), s)?;
    let mut plant = LinearPlant::new(model)?;
    let m = ctrl.axes();
    let mut state = vec![AxisState::default(); m];
    let mut refs = vec![0.0; m];
    let mut u = vec![0.0; m];
    plant.measure(&mut state);
    ctrl.reset(&state, &u);
    let half_period = (4.0 / model.dt).round().max(1.0) as usize;
    let mut ticks = Vec::with_capacity(n_ticks);
    for k in 0..n_ticks {
        let sign = if (k / half_period) % 2 == 0 {
            1.0
        } else {
            -1.0
        };
        refs.iter_mut().for_each(|r| *r = 2.0 * sign);
        plant.measure(&mut state);
        let t0 = Instant::now();
        ctrl.step(&state, &refs, &mut u)?;
        ticks.push(t0.elapsed().as_secs_f64() * 1e6);
        plant.step(&u);
    }
    let mut builds = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let t0 = Instant::now();
        let out = ctrl.synthesize_now();
        builds.push(t0.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(&out);
    }
    Ok((summarise(ticks), summarise(builds)))
}

fn summarise(mut times: Vec<f64>) -> TickTiming {
    times.sort_by(|a, b| a.total_cmp(b));
    let pick = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
    TickTiming {
        median_us: pick(0.5),
        p99_us: pick(0.99),
        max_us: *times.last().unwrap_or(&0.0),
        mean_us: times.iter().sum::<f64>() / times.len() as f64,
        ticks: times.len(),
    }
}
