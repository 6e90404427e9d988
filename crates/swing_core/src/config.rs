//! Validation helpers shared by every settings struct.
//!
//! Settings are plain serde structs with `deny_unknown_fields`; after parsing, `validate()`
//! checks physical sense and reports the first bad field by its dotted path.

use thiserror::Error;

/// A setting that is missing, unknown, out of range or not finite; `field` is its dotted path.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{field}: {problem}")]
pub struct ConfigError {
    /// Dotted path of the offending field, e.g. `payload.mass`.
    pub field: String,
    /// What is wrong with it, in words a user understands.
    pub problem: String,
}

impl ConfigError {
    /// Build an error for `field` with the given `problem`.
    pub fn new(field: impl Into<String>, problem: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            problem: problem.into(),
        }
    }

    /// Prefix the field path with a parent section, e.g. `mass` → `payload.mass`.
    pub fn within(mut self, parent: &str) -> Self {
        self.field = if self.field.is_empty() {
            parent.to_string()
        } else {
            format!("{parent}.{}", self.field)
        };
        self
    }
}

/// Require a finite value.
pub fn finite(field: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(ConfigError::new(
            field,
            format!("must be a finite number (got {v})"),
        ))
    }
}

/// Require a finite value strictly greater than zero.
pub fn positive(field: &str, v: f64) -> Result<(), ConfigError> {
    finite(field, v)?;
    if v > 0.0 {
        Ok(())
    } else {
        Err(ConfigError::new(field, format!("must be > 0 (got {v})")))
    }
}

/// Require a finite value greater than or equal to zero.
pub fn non_negative(field: &str, v: f64) -> Result<(), ConfigError> {
    finite(field, v)?;
    if v >= 0.0 {
        Ok(())
    } else {
        Err(ConfigError::new(field, format!("must be >= 0 (got {v})")))
    }
}

/// Require a finite value inside `[lo, hi]`.
pub fn in_range(field: &str, v: f64, lo: f64, hi: f64) -> Result<(), ConfigError> {
    finite(field, v)?;
    if (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(ConfigError::new(
            field,
            format!("must be between {lo} and {hi} (got {v})"),
        ))
    }
}

/// Require every element of a vector to be finite.
pub fn all_finite(field: &str, v: &[f64]) -> Result<(), ConfigError> {
    for (i, x) in v.iter().enumerate() {
        finite(&format!("{field}[{i}]"), *x)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_nest_and_messages_name_the_field() {
        let e = positive("mass", -0.1).unwrap_err().within("payload");
        assert_eq!(e.field, "payload.mass");
        assert!(e.to_string().starts_with("payload.mass: must be > 0"));
        assert!(finite("x", f64::NAN).is_err());
        assert!(in_range("x", 2.0, 0.0, 1.0).is_err());
        assert!(non_negative("x", 0.0).is_ok());
    }
}
