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
//! Check before a swap ([`crate::design::check`], bounds of [`crate::design::selection`]): the candidate's
//! spectral radius is at most `max_spectral_radius`, and its MPC, in closed loop on the
//! candidate model itself and on the candidate with extra vehicle drag (both without the
//! constant term, which is the recent data's operating point), each behind every input
//! lag, holds hover, tracks a velocity step and stays within `bounds`. A candidate that fails is dropped and the old controller kept; the synthesis retries after
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

//!
//! The adaptive MPC lives in the design layer because what it does off the tick path is
//! design: it re-identifies (online DMDc, or the vehicle's twin for a payload measured in
//! flight) and accepts a model only after the same kind of closed-loop check the offline
//! selection uses. The simulator runs it as any [`crate::control::SwingController`].
//!
//! Files by job: [`settings`] (what can be set), [`worker`] (the re-synthesis and its
//! check, off the tick path), [`twin_path`] (when a measured payload asks for the twin),
//! [`controller`] (the tick).

pub mod controller;
pub mod settings;
mod twin_path;
mod worker;

pub use controller::{AdaptiveMpc, MAX_EVENTS, MAX_REVERTS};
pub use settings::{AdaptiveSettings, SynthesisMode, TwinPrior, TwinSettings};
pub use twin_path::{LENGTH_SIGNIFICANCE, MASS_SETTLED_KG, MIN_PAYLOAD_MASS};
