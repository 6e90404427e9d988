//! `swingrt._core`: the thin PyO3 binding of `swing_core`.
//!
//! Conversion and error mapping only; every algorithm lives in the core. Long calls release
//! the GIL. Each domain registers its functions from its own module.

use pyo3::prelude::*;

mod control;
mod convert;
mod errors;
mod hil;
mod methods;
mod mission;
mod sensors;
mod sim;
mod sysid;

/// The extension module `swingrt._core`.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("GRAVITY", swing_core::plant::GRAVITY)?;
    sim::register(m)?;
    hil::register(m)?;
    sysid::register(m)?;
    control::register(m)?;
    methods::register(m)?;
    mission::register(m)?;
    sensors::register(m)?;
    Ok(())
}
