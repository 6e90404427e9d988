//! The re-synthesis of the adaptive MPC, off the tick path: the job handed over (the online
//! factor, or a payload to fly the twin with), the candidate model and its MPC, the
//! closed-loop check before a swap, and the channels of the worker thread.

use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;

use super::settings::{AdaptiveSettings, SynthesisMode};
use crate::control::{ControlError, MpcController, MpcSettings};
use crate::design::check::{worst_step_check, StepCheck, Uncertainty};
use crate::design::reidentify::Twin;
use crate::design::DesignError;
use crate::sysid::online::model_from_factor;
use crate::sysid::{LinearModel, Offset};

/// The factor handed to the synthesis (a recycled buffer).
pub(super) struct Job {
    pub(super) factor: Vec<f64>,
    pub(super) weight: f64,
    /// Fly the twin with this payload (mass [kg], length [m]) instead of using the factor.
    pub(super) twin: Option<[f64; 2]>,
}

/// A candidate that passed the check (boxed so that the swap moves pointers only).
pub(super) struct Candidate {
    pub(super) mpc: Box<MpcController>,
    pub(super) model: Box<LinearModel>,
}

/// What a synthesis returns; `job` comes back for reuse.
pub(super) struct Outcome {
    pub(super) job: Box<Job>,
    pub(super) result: Result<Candidate, DesignError>,
    pub(super) check: Option<StepCheck>,
}

/// Messages to the worker.
pub(super) enum ToWorker {
    Build(Box<Job>),
    /// Replaced objects, dropped on the worker.
    Retire(#[allow(dead_code)] Retired),
}

/// What a swap or a rejection leaves behind.
pub(super) enum Retired {
    Controller(
        #[allow(dead_code)] Box<MpcController>,
        #[allow(dead_code)] Box<LinearModel>,
    ),
    Reason(#[allow(dead_code)] DesignError),
}

/// What the synthesis needs besides the factor: fixed for the controller's life.
pub(super) struct Synthesizer {
    pub(super) template: LinearModel,
    pub(super) mpc: MpcSettings,
    pub(super) settings: AdaptiveSettings,
    pub(super) twin: Option<Twin>,
}

impl Synthesizer {
    pub(super) fn run(&self, job: Box<Job>) -> Outcome {
        let mut check = None;
        let result = self.build(&job, &mut check);
        Outcome { job, result, check }
    }

    fn build(
        &self,
        job: &Job,
        check_out: &mut Option<StepCheck>,
    ) -> Result<Candidate, DesignError> {
        let t = &self.template;
        let full = t.m() + usize::from(t.offset == Offset::Affine) + t.n() * t.delays;
        // Rank 0 marks a full-rank model.
        let rank = if t.rank == 0 { full } else { t.rank.min(full) };
        let model = match (job.twin, &self.twin) {
            (Some([mass, length]), Some(twin)) => twin.identify(t, mass, length, &self.mpc)?,
            (Some(_), None) => return Err(DesignError::NoTwin),
            (None, _) => model_from_factor(&job.factor, job.weight, rank, t)?,
        };
        let rho = model.spectral_radius()?;
        // NaN is refused too.
        if rho.is_nan() || rho > self.settings.max_spectral_radius {
            return Err(DesignError::Unstable {
                radius: rho,
                bound: self.settings.max_spectral_radius,
            });
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
                mpc: Box::new(MpcController::new(&model, self.mpc.clone())?),
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
            plants.push(bare.with_velocity_drag(self.settings.check_drag)?);
        }
        let checked = MpcController::new(&bare, self.mpc.clone())?;
        let set = Uncertainty {
            plants: &plants,
            input_lags: &self.settings.input_lags,
            input_delays: &self.settings.input_delays,
            bound_amplitudes: &self.settings.bound_amplitudes,
        };
        let worst = worst_step_check(&checked, &bare, &set, self.settings.check_step)?;
        *check_out = Some(worst);
        // The same requirements and refusals as the offline selection's linear plants.
        let refusals = self.settings.bounds.refusals(&worst);
        if !refusals.is_empty() {
            return Err(DesignError::Refused(refusals));
        }
        let mpc = if model.c.iter().all(|v| *v == 0.0) {
            checked
        } else {
            MpcController::new(&model, self.mpc.clone())?
        };
        Ok(Candidate {
            mpc: Box::new(mpc),
            model: Box::new(model),
        })
    }
}

pub(super) enum Synthesis {
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

impl Synthesis {
    /// The synthesis of `mode`: nothing to start for `deferred`; for `thread`, the worker
    /// thread that runs `synth`'s jobs until the sending side is dropped.
    pub(super) fn start(
        mode: SynthesisMode,
        synth: &Arc<Synthesizer>,
    ) -> Result<Self, ControlError> {
        Ok(match mode {
            SynthesisMode::Deferred => Synthesis::Deferred {
                pending: None,
                done: None,
            },
            SynthesisMode::Thread => {
                // Capacity 2: one build and one drop may be in flight at once.
                let (tx, jobs) = sync_channel::<ToWorker>(2);
                let (out, rx) = sync_channel::<Outcome>(1);
                let synth = Arc::clone(synth);
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
        })
    }
}
