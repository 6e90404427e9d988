//! Why the design layer produced no model to fly: the twin's re-identification failed, the
//! candidate is unstable, or its closed-loop check refused it. Typed, so a caller can tell a
//! refusal (expected: the adaptive MPC waits for more data and retries) from a failure.

use thiserror::Error;

use crate::config::ConfigError;
use crate::control::ControlError;
use crate::design::selection::Refusal;
use crate::sim::SimError;
use crate::sysid::SysidError;

/// Why no model came out of a design step (the adaptive MPC's synthesis, the twin's
/// re-identification).
#[derive(Debug, Error)]
pub enum DesignError {
    /// Settings or a payload that are not valid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The identification of a candidate failed.
    #[error(transparent)]
    Sysid(#[from] SysidError),
    /// An MPC could not be designed or checked on the candidate.
    #[error(transparent)]
    Control(#[from] ControlError),
    /// The twin's flight failed.
    #[error("twin flight: {0}")]
    Sim(#[from] SimError),
    /// A model the step cannot work with (a method or a column it needs is missing).
    #[error("model: {0}")]
    Model(String),
    /// A re-identification on the twin was asked for with no twin.
    #[error("no twin to fly")]
    NoTwin,
    /// The candidate's spectral radius is above the bound (NaN included).
    #[error("spectral radius {radius:.4} above {bound}")]
    Unstable {
        /// The candidate's largest eigenvalue modulus.
        radius: f64,
        /// The largest accepted.
        bound: f64,
    },
    /// The candidate's MPC failed its closed-loop check, for each of these reasons.
    #[error("closed-loop check failed: {}", Reasons(.0))]
    Refused(Vec<Refusal>),
    /// No candidate of the twin's selection passed its closed-loop check.
    #[error("no rank at q = {delays} passed the closed-loop check on the twin's white-box")]
    NonePassed {
        /// The delay count every candidate had.
        delays: usize,
    },
}

/// Refusals written one after another, separated by "; " (no allocation).
struct Reasons<'a>(&'a [Refusal]);

impl std::fmt::Display for Reasons<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, r) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str("; ")?;
            }
            write!(f, "{r}")?;
        }
        Ok(())
    }
}
