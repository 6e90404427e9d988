//! Error categories shared by the domain error enums.
//!
//! Each domain (`sim`, `sysid`, `control`) has its own `thiserror` enum; every variant
//! belongs to one [`Category`], which the binding maps onto a class of `swingrt.errors`.

/// The kind of failure, independent of the domain that reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Category {
    /// Invalid settings (→ `ConfigError`).
    Config,
    /// Unusable data: shape, NaN, too short, missing column (→ `DataError`).
    Data,
    /// Malformed or mismatched model (→ `ModelError`).
    Model,
    /// Identification failed on valid input (→ `IdentificationError`).
    Identification,
    /// Controller synthesis or stepping failed (→ `ControlError`).
    Control,
    /// QP solver failure (→ `SolverError`).
    Solver,
    /// Simulation diverged (→ `SimulationError`).
    Simulation,
}

/// Implemented by every domain error so the binding can pick the Python class.
pub trait Categorized {
    /// The category of this error.
    fn category(&self) -> Category;

    /// The dotted settings field a configuration error is about, when it names one.
    fn field(&self) -> Option<&str> {
        None
    }
}

impl Categorized for crate::config::ConfigError {
    fn category(&self) -> Category {
        Category::Config
    }

    fn field(&self) -> Option<&str> {
        Some(&self.field)
    }
}
