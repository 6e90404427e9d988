//! Errors of system identification, each mapped onto a [`Category`].

use thiserror::Error;

use crate::config::ConfigError;
use crate::error::{Categorized, Category};

/// Everything that can go wrong while identifying, evaluating or loading a model.
#[derive(Debug, Error)]
pub enum SysidError {
    /// Unusable data: wrong shape, non-finite values, too short for the chosen delays.
    #[error("data: {0}")]
    Data(String),
    /// Invalid settings (delays, rank, horizon, offset …); names the field.
    #[error("{0}")]
    Config(#[from] ConfigError),
    /// Identification failed on valid input (e.g. no stable candidate in a search).
    #[error("identification: {0}")]
    Identification(String),
    /// A model (JSON or in memory) is malformed or does not fit the data.
    #[error("model: {0}")]
    Model(String),
}

impl Categorized for SysidError {
    fn category(&self) -> Category {
        match self {
            SysidError::Data(_) => Category::Data,
            SysidError::Config(_) => Category::Config,
            SysidError::Identification(_) => Category::Identification,
            SysidError::Model(_) => Category::Model,
        }
    }

    fn field(&self) -> Option<&str> {
        match self {
            SysidError::Config(e) => Some(&e.field),
            _ => None,
        }
    }
}

/// Shorthand for a data error.
pub(crate) fn data(msg: impl Into<String>) -> SysidError {
    SysidError::Data(msg.into())
}

/// Shorthand for a settings error.
pub(crate) fn config(msg: impl Into<String>) -> SysidError {
    SysidError::Config(ConfigError::new("settings", msg))
}

/// Shorthand for a model error.
pub(crate) fn model(msg: impl Into<String>) -> SysidError {
    SysidError::Model(msg.into())
}
