//! The adaptive MPC controller on the tick path: the online update, the detector, the swap
//! between ticks and the revert (see the module docs of [`super`]).

use std::sync::mpsc::{TryRecvError, TrySendError};
use std::sync::Arc;

use super::settings::{AdaptiveSettings, TwinPrior};
use super::twin_path::{TwinDecision, TwinState};
use super::worker::{Candidate, Job, Retired, Synthesis, Synthesizer, ToWorker};
use crate::config::{positive, ConfigError};
use crate::control::layout::{AxisLayout, Measured};
use crate::control::{
    AxisState, ControlError, ControllerEvent, MpcController, MpcSettings, SwingController, TickInfo,
};
use crate::design::DesignError;
use crate::sysid::online::OnlineDmdc;
use crate::sysid::payload::{PayloadTracker, TrackerSettings};
use crate::sysid::{LinearModel, Offset};

/// Reverts after which adaptation stops for the flight: a change the online model keeps
/// failing to capture is left to the controller that has flown.
pub const MAX_REVERTS: usize = 3;

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
        let synthesis = Synthesis::start(settings.synthesis, &synth)?;
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
    pub fn synthesize_now(&self) -> Result<LinearModel, DesignError> {
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
                self.last_rejection_len = write_truncated(&mut self.last_rejection, &reason);
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
        let decision = tw.decide(&mut self.tracker, self.tick, self.busy, self.suspended);
        self.twin = Some(tw);
        let payload = match decision {
            TwinDecision::Wait => return,
            TwinDecision::MassChanged(m) => {
                self.log("mass_changed", m);
                return;
            }
            TwinDecision::Request(payload) => payload,
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
        crate::control::check_tick_inputs(self.m, state, vel_ref, acc_out)?;
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

/// Write `what` into `buf` as far as it fits, cut at a character boundary, with no
/// allocation (the tick thread records a rejection): the length written.
fn write_truncated(buf: &mut [u8], what: &impl std::fmt::Display) -> usize {
    use std::io::Write;
    let mut cursor = std::io::Cursor::new(&mut buf[..]);
    // A message longer than the buffer fills it; the error only says so.
    let _ = write!(cursor, "{what}");
    let len = cursor.position() as usize;
    match std::str::from_utf8(&buf[..len]) {
        Ok(_) => len,
        Err(e) => e.valid_up_to(),
    }
}

#[cfg(test)]
mod tests {
    use super::write_truncated;

    #[test]
    fn a_long_reason_is_cut_at_a_character_boundary() {
        let mut buf = [0u8; 8];
        let n = write_truncated(&mut buf, &"abc");
        assert_eq!(&buf[..n], b"abc");
        // "ééééé" is 10 bytes: 8 fit, the cut falls between characters.
        let n = write_truncated(&mut buf, &"ééééé");
        assert_eq!(std::str::from_utf8(&buf[..n]).unwrap(), "éééé");
        // 'aé…': the second character would be split at byte 8.
        let n = write_truncated(&mut buf, &"aaaaaaaé");
        assert_eq!(std::str::from_utf8(&buf[..n]).unwrap(), "aaaaaaa");
    }
}
