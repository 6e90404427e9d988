//! The physical plant: vehicle, suspended payload and air (thesis chapter 3).

pub mod axis;
pub mod dynamics;
pub mod events;
pub mod linear;
pub mod params;
pub mod wind;

pub use axis::AxisState;
pub use dynamics::{Effects, Model, PlantState, StepInput};
pub use events::{apply_payload_events, check_events, PayloadAction, PayloadEvent};
pub use linear::PendulumModel;
pub use params::{Airframe, PayloadKind, PayloadParams, VehicleParams, GRAVITY};
pub use wind::{Wind, WindParams};
