//! Closed-loop simulation: scenario files, the multi-rate runner and traces.

pub mod hil;
pub mod runner;
pub mod scenario;
mod supervisor;
mod ticker;
pub mod trace;

pub use hil::{HilPlant, HilSettings, SensorFrame};
pub use runner::{SimError, Simulator};
pub use scenario::{Axes, NoiseParams, RandomSteps, Scenario, SetpointEntry};
pub use trace::{StateExtras, Trace, TraceRow, FLIGHT_COLUMNS, STATE_KEYS, TRACE_COLUMNS};

/// Simulated seconds per wall second of the full loop of `scenario` over `seconds` of
/// simulated flight on the calling thread.
pub fn real_time_factor(mut scenario: Scenario, seconds: f64) -> Result<f64, SimError> {
    scenario.duration = seconds;
    let mut sim = Simulator::new(scenario)?;
    let t0 = std::time::Instant::now();
    sim.run_to_end()?;
    Ok(seconds / t0.elapsed().as_secs_f64())
}
