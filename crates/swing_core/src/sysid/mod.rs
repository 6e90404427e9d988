//! System identification from flight data: DMDc, HAVOKc, white-box baseline, NMAE, search.

// Index loops over several parallel arrays read closer to the equations than zipped iterators.
#![allow(clippy::needless_range_loop)]

pub mod dmdc;
pub mod error;
mod gram;
pub mod hankel;
pub mod havokc;
pub mod lag;
pub mod links;
pub mod metrics;
pub mod model;
pub mod online;
pub mod payload;
pub mod pipeline;
pub mod resample;
pub mod search;
pub mod settings;
pub mod smooth;
pub mod spectrum;
pub mod stability;
pub mod swing_scale;
pub mod whitebox;

pub use error::SysidError;
pub use hankel::Trajectory;
pub use metrics::Nmae;
pub use model::{Diagnostics, LinearModel, Offset, WhiteboxEstimates};
pub use online::{OnlineDmdc, OnlineSettings, OnlineStep};
pub use settings::{IdentifyMethod, IdentifySettings, SearchMode, SelectBy};
