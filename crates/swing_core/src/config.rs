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

/// Collapse a (possibly multi-line) parser message onto one line.
pub fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// A serde error with its path → a [`ConfigError`] naming the dotted field.
pub fn path_error<E: std::fmt::Display>(e: serde_path_to_error::Error<E>) -> ConfigError {
    let path = e.path().to_string();
    let path = if path == "." { String::new() } else { path };
    let msg = one_line(&e.inner().to_string());
    // toml/serde_json put the offending key in the message; drop their location suffixes.
    let msg = msg
        .split(" at line ")
        .next()
        .unwrap_or(&msg)
        .trim_start_matches("TOML parse error ")
        .to_string();
    ConfigError::new(path, msg)
}

/// Deserialize settings from JSON text; unknown keys and bad values name the field.
pub fn from_json_str<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, ConfigError> {
    let mut de = serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(&mut de).map_err(path_error)
}

/// Deserialize settings from a TOML value; unknown keys and bad values name the field.
pub fn from_toml_value<T: serde::de::DeserializeOwned>(v: toml::Value) -> Result<T, ConfigError> {
    serde_path_to_error::deserialize(v).map_err(path_error)
}

/// Parse TOML text into a table; a syntax error is a [`ConfigError`] on one line.
pub fn parse_toml(text: &str) -> Result<toml::Table, ConfigError> {
    text.parse::<toml::Table>().map_err(|e| {
        let msg = one_line(&e.to_string());
        ConfigError::new("", msg.trim_start_matches("TOML parse error ").to_string())
    })
}

/// Merge `over` into `base` key by key: tables merge recursively, anything else replaces.
pub fn merge_tables(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_tables(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
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
