//! swing_core — the numerical core of swingrt.
//!
//! A multirotor carrying an unknown suspended payload: its simulation under PX4's cascaded
//! controller ([`plant`], [`sim`], [`control::px4`]), data-driven identification of a linear
//! model ([`sysid`]) and swing-damping control on that model ([`control`]). Pure Rust, `f64`,
//! no Python; the PyO3 binding lives in the `swing_py` crate. Equation numbers refer to the
//! thesis (see docs/architecture.md).

// Index loops mirror the equations (x_i, T_i, n_i) and read better than iterator chains here.
#![warn(missing_docs)]
#![allow(clippy::needless_range_loop)]

pub mod config;
pub mod control;
pub mod design;
pub mod error;
pub mod linalg;
pub mod mission;
pub mod parallel;
pub mod plant;
pub mod sensors;
pub mod sim;
pub mod sysid;
pub mod testing;

pub use config::ConfigError;
pub use error::{Categorized, Category};
