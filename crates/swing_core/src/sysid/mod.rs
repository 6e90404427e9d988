//! System identification from flight data: DMDc, HAVOKc, white-box baseline, NMAE, search.

pub mod model;

pub use model::{LinearModel, Offset};
