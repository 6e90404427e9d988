//! Mapping of core errors onto the classes of `swingrt.errors`.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use swing_core::{Categorized, Category};

/// Class name in `swingrt.errors` for a core error category.
fn class_name(cat: Category) -> &'static str {
    match cat {
        Category::Config => "ConfigError",
        Category::Data => "DataError",
        Category::Model => "ModelError",
        Category::Identification => "IdentificationError",
        Category::Control => "ControlError",
        Category::Solver => "SolverError",
        Category::Simulation => "SimulationError",
    }
}

/// Build a `swingrt.errors` exception of the given category carrying `msg`.
pub fn raise(cat: Category, msg: impl Into<String>) -> PyErr {
    raise_with_field(cat, msg.into(), None)
}

/// Build a `swingrt.errors` exception; a `ConfigError` also carries the dotted `field`.
fn raise_with_field(cat: Category, msg: String, field: Option<&str>) -> PyErr {
    Python::attach(|py| {
        let built = py
            .import("swingrt.errors")
            .and_then(|m| m.getattr(class_name(cat)))
            .and_then(|cls| match field {
                Some(f) if cat == Category::Config => {
                    let kw = pyo3::types::PyDict::new(py);
                    kw.set_item("field", f)?;
                    cls.call((msg.clone(),), Some(&kw))
                }
                _ => cls.call1((msg.clone(),)),
            });
        match built {
            Ok(inst) => PyErr::from_value(inst),
            // The Python package is always importable when the extension is; keep a sane
            // fallback for the extension loaded on its own.
            Err(_) => PyValueError::new_err(msg),
        }
    })
}

/// Convert any categorized core error into the matching Python exception.
pub fn to_py<E: Categorized + std::fmt::Display>(e: E) -> PyErr {
    raise_with_field(e.category(), e.to_string(), e.field())
}
