//! System identification from flight data: DMDc, HAVOKc, white-box baseline, NMAE, search.

pub mod dmdc;
pub mod error;
pub mod hankel;
pub mod havokc;
pub mod metrics;
pub mod model;
pub mod search;
pub mod smooth;
pub mod whitebox;

pub use error::SysidError;
pub use hankel::Trajectory;
pub use metrics::Nmae;
pub use model::{Diagnostics, LinearModel, Offset, WhiteboxEstimates};
