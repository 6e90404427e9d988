//! Closed-loop simulation: scenario files, the multi-rate runner and traces.

pub mod runner;
pub mod scenario;
mod supervisor;
mod ticker;
pub mod trace;

pub use runner::{SimError, Simulator};
pub use scenario::{Axes, NoiseParams, RandomSteps, Scenario, SetpointEntry};
pub use trace::{StateExtras, Trace, TraceRow, STATE_KEYS, TRACE_COLUMNS};
