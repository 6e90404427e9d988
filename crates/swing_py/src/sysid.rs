//! Bindings of `swing_core::sysid`.

use pyo3::prelude::*;

/// Register this domain's functions and classes on the module.
pub fn register(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}
