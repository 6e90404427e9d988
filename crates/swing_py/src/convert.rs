//! Conversions shared by every binding: settings dicts, serde values and numpy arrays.

use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use serde::de::DeserializeOwned;
use serde::Serialize;
use swing_core::{Category, ConfigError};

use crate::errors::{raise, to_py};

/// A settings dict (or None, for the defaults) → a core settings struct, by serde.
///
/// Unknown keys and values of the wrong type raise `ConfigError` naming `section.field`.
pub fn settings<T: DeserializeOwned + Default>(
    obj: Option<&Bound<'_, PyAny>>,
    section: &str,
) -> PyResult<T> {
    match obj {
        None => Ok(T::default()),
        Some(o) if o.is_none() => Ok(T::default()),
        Some(o) => from_py(o, section),
    }
}

/// Any Python value → a serde type; errors name `section.field`.
pub fn from_py<T: DeserializeOwned>(obj: &Bound<'_, PyAny>, section: &str) -> PyResult<T> {
    let mut de = pythonize::Depythonizer::from_object(obj);
    serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let err = swing_core::config::path_error(e);
        to_py(within(err, section))
    })
}

/// Prefix a config error's field with `section` (no prefix for an empty section).
pub fn within(err: ConfigError, section: &str) -> ConfigError {
    if section.is_empty() {
        err
    } else {
        err.within(section)
    }
}

/// A serde value → Python objects (dicts, lists, floats …).
pub fn to_py_object<'py, T: Serialize>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyAny>> {
    pythonize::pythonize(py, v).map_err(|e| raise(Category::Data, e.to_string()))
}

/// Raise a `DataError`.
pub fn data_err(msg: impl Into<String>) -> PyErr {
    raise(Category::Data, msg)
}

/// Borrow a 2-D float64 C-contiguous array, or raise `DataError` naming it.
pub fn array2<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<PyReadonlyArray2<'py, f64>> {
    let arr: PyReadonlyArray2<'py, f64> = obj
        .extract()
        .map_err(|_| data_err(format!("{name} must be a 2-D numpy array of float64")))?;
    // as_slice also accepts Fortran order, which would scramble the time-major layout.
    if !arr.is_c_contiguous() {
        return Err(data_err(format!("{name} must be C-contiguous")));
    }
    Ok(arr)
}

/// Borrow a 1-D float64 contiguous array, or raise `DataError` naming it.
pub fn array1<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<PyReadonlyArray1<'py, f64>> {
    let arr: PyReadonlyArray1<'py, f64> = obj
        .extract()
        .map_err(|_| data_err(format!("{name} must be a 1-D numpy array of float64")))?;
    if arr.as_slice().is_err() {
        return Err(data_err(format!("{name} must be contiguous")));
    }
    Ok(arr)
}

/// Columns of a 2-D array.
pub fn cols(a: &PyReadonlyArray2<'_, f64>) -> usize {
    a.shape()[1]
}

/// Write `text` to `path` atomically: a temporary file beside it, then a rename.
pub fn write_atomic(path: &std::path::Path, text: &str) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    // Unique per process and call, and never an existing file: two threads (or a Dask
    // worker's tasks) saving the same target each write their own temporary.
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = dir.join(format!(".{name}.{}.{n}.tmp", std::process::id()));
    let result = (|| {
        use std::io::Write;
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        f.write_all(text.as_bytes())?;
        f.sync_all()?; // the data is on disk before the rename makes it the file
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// A Python dict of overrides → a TOML table: `None` values are left out (absent = the
/// base's value), floats keep NaN/∞ so the core's checks name them.
pub fn toml_table(obj: &Bound<'_, PyAny>, section: &str) -> PyResult<toml::Table> {
    match toml_value(obj, section)? {
        Some(toml::Value::Table(t)) => Ok(t),
        _ => Err(to_py(ConfigError::new(
            if section.is_empty() {
                "scenario"
            } else {
                section
            },
            "must be a table (dict) of settings",
        ))),
    }
}

fn toml_value(obj: &Bound<'_, PyAny>, path: &str) -> PyResult<Option<toml::Value>> {
    use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
    let bad = |what: &str| {
        to_py(ConfigError::new(
            if path.is_empty() { "scenario" } else { path },
            format!("unsupported value {what}"),
        ))
    };
    if obj.is_none() {
        return Ok(None);
    }
    let value = if let Ok(d) = obj.cast::<PyDict>() {
        let mut t = toml::Table::new();
        for (k, v) in d.iter() {
            let key: String = k.extract().map_err(|_| bad("(a non-string key)"))?;
            let sub = if path.is_empty() {
                key.clone()
            } else {
                format!("{path}.{key}")
            };
            if let Some(v) = toml_value(&v, &sub)? {
                t.insert(key, v);
            }
        }
        toml::Value::Table(t)
    } else if obj.is_instance_of::<PyBool>() {
        toml::Value::Boolean(obj.extract()?)
    } else if obj.is_instance_of::<PyInt>() {
        toml::Value::Integer(
            obj.extract()
                .map_err(|_| bad("(an integer out of range)"))?,
        )
    } else if obj.is_instance_of::<PyFloat>() {
        toml::Value::Float(obj.extract()?)
    } else if obj.is_instance_of::<PyString>() {
        toml::Value::String(obj.extract()?)
    } else if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() {
        let mut items = Vec::new();
        for (i, v) in obj.try_iter()?.enumerate() {
            let sub = format!("{path}[{i}]");
            match toml_value(&v?, &sub)? {
                Some(v) => items.push(v),
                None => return Err(bad("None in a list")),
            }
        }
        toml::Value::Array(items)
    } else if let Ok(x) = obj.extract::<f64>() {
        // numpy scalars and other numbers.
        toml::Value::Float(x)
    } else {
        let name = obj
            .get_type()
            .name()
            .map(|n| n.to_string())
            .unwrap_or_default();
        return Err(bad(&format!("of type {name}")));
    };
    Ok(Some(value))
}
