//! Design and qualification: from identified models to the one to fly, above the simulator.
//!
//! This layer chooses and accepts models. It may use everything below it (the simulator to
//! fly the vehicle's twin, the identification pipeline to refit candidates, the controllers
//! to design an MPC on each); nothing below uses it. See docs/architecture.md, "Layers".
//!
//! - [`check`]: the closed-loop step check of an MPC on a linear plant and the analysis of
//!   its unconstrained loop (spectral radius, noise gains).
//! - [`selection`]: the control-relevant choice among a search's candidates.
//! - [`twin`]: the vehicle's twin as a check plant (a step flown on the simulator).
//! - [`reidentify`]: a model re-identified on the twin for a payload measured in flight.
//! - [`law`]: what a selected model flies (its MPC, or the input shaper the selection took).
//! - [`error`]: why a model was not designed or not adopted ([`DesignError`]).
//! - [`adaptive`]: the adaptive MPC (online identification, checked re-synthesis, swap).

pub mod adaptive;
pub mod check;
pub mod error;
pub mod law;
pub mod reidentify;
pub mod selection;
pub mod twin;

#[cfg(test)]
pub(crate) mod fixtures;

pub use adaptive::{AdaptiveMpc, AdaptiveSettings, SynthesisMode};
pub use check::{mpc_step_check, step_check_with, StepCheck, StepCheckSettings};
pub use error::DesignError;
pub use law::Law;
