//! Errors of system identification, each mapped onto a [`Category`].

use thiserror::Error;

use crate::error::{Categorized, Category};

/// Everything that can go wrong while identifying, evaluating or loading a model.
#[derive(Debug, Error)]
pub enum SysidError {
    /// Unusable data: wrong shape, non-finite values, too short for the chosen delays.
    #[error("data: {0}")]
    Data(String),
    /// Invalid settings (delays, rank, horizon, offset …).
    #[error("settings: {0}")]
    Config(String),
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
}

/// Shorthand for a data error.
pub(crate) fn data(msg: impl Into<String>) -> SysidError {
    SysidError::Data(msg.into())
}

/// Shorthand for a settings error.
pub(crate) fn config(msg: impl Into<String>) -> SysidError {
    SysidError::Config(msg.into())
}

/// Shorthand for a model error.
pub(crate) fn model(msg: impl Into<String>) -> SysidError {
    SysidError::Model(msg.into())
}
