//! Bindings of `swing_core::sim`: scenarios, the steppable simulator and whole runs.

use numpy::{IntoPyArray, PyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use swing_core::control::lqr::{LqrController, LqrSettings};
use swing_core::control::mpc::{MpcController, MpcSettings};
use swing_core::control::px4::AxisSetpoint;
use swing_core::plant::PendulumModel;
use swing_core::sim::{Scenario, Simulator, Trace, STATE_KEYS, TRACE_COLUMNS};
use swing_core::sysid::LinearModel;
use swing_core::ConfigError;

use crate::errors::to_py;

/// Parse a settings struct from JSON; unknown keys and bad values name the field.
pub fn parse_settings<T: serde::de::DeserializeOwned>(json: &str, section: &str) -> PyResult<T> {
    let mut de = serde_json::Deserializer::from_str(json);
    serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        to_py(ConfigError::new(
            if path == "." {
                section.to_string()
            } else {
                format!("{section}.{path}")
            },
            e.inner().to_string(),
        ))
    })
}

fn trace_to_dict<'py>(py: Python<'py>, trace: Trace) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (name, col) in trace.into_columns() {
        d.set_item(name, col.into_pyarray(py))?;
    }
    Ok(d)
}

fn parse(json: &str) -> PyResult<Scenario> {
    Scenario::from_json(json).map_err(to_py)
}

/// Validate a TOML scenario and return it, defaults filled in, as JSON.
#[pyfunction]
fn scenario_from_toml(text: &str) -> PyResult<String> {
    let sc = Scenario::from_toml(text).map_err(to_py)?;
    Ok(serde_json::to_string(&sc).expect("scenario serialises"))
}

/// Validate a JSON scenario and return it, defaults filled in, as JSON.
#[pyfunction]
fn scenario_from_json(text: &str) -> PyResult<String> {
    Ok(serde_json::to_string(&parse(text)?).expect("scenario serialises"))
}

/// A built-in scenario as JSON: `step` (simulate) or `training` (collect).
#[pyfunction]
fn default_scenario(kind: &str) -> PyResult<String> {
    let sc = match kind {
        "step" => Scenario::default_step(),
        "training" => Scenario::default_training(),
        other => {
            return Err(to_py(ConfigError::new(
                "scenario",
                format!("unknown built-in scenario {other:?} (use \"step\" or \"training\")"),
            )))
        }
    };
    Ok(serde_json::to_string(&sc).expect("scenario serialises"))
}

/// A scenario (JSON) as TOML text.
#[pyfunction]
fn scenario_to_toml(json: &str) -> PyResult<String> {
    Ok(parse(json)?.to_toml())
}

/// Run a whole scenario (JSON) and return its trace as a dict of numpy arrays.
#[pyfunction]
fn run_scenario<'py>(py: Python<'py>, json: &str) -> PyResult<Bound<'py, PyDict>> {
    let sc = parse(json)?;
    let trace = py.detach(|| Simulator::run(sc)).map_err(to_py)?;
    trace_to_dict(py, trace)
}

/// Simulated seconds per wall second of the full loop (with the scenario's payload),
/// measured over `seconds` of simulated flight on the calling thread.
#[pyfunction]
fn sim_real_time_factor(py: Python<'_>, json: &str, seconds: f64) -> PyResult<f64> {
    let mut sc = parse(json)?;
    sc.duration = seconds;
    py.detach(|| {
        let mut sim = Simulator::new(sc)?;
        let t0 = std::time::Instant::now();
        sim.run_to_end()?;
        Ok::<f64, swing_core::sim::SimError>(seconds / t0.elapsed().as_secs_f64())
    })
    .map_err(to_py)
}

/// The steppable closed-loop simulator (vehicle, payload, PX4 cascade, wind).
#[pyclass(name = "Simulator", module = "swingrt._core", unsendable)]
pub struct PySimulator {
    /// The core simulator (also used by the control bindings to attach controllers).
    pub inner: Simulator,
}

#[pymethods]
impl PySimulator {
    /// Build from a scenario given as JSON text.
    #[new]
    fn new(json: &str) -> PyResult<Self> {
        let sc = parse(json)?;
        Ok(Self {
            inner: Simulator::new(sc).map_err(to_py)?,
        })
    }

    /// Current simulated time [s].
    #[getter]
    fn t(&self) -> f64 {
        self.inner.time()
    }

    /// Scenario duration [s].
    #[getter]
    fn duration(&self) -> f64 {
        self.inner.duration()
    }

    /// Physics steps left until the scenario's end.
    #[getter]
    fn steps_left(&self) -> u64 {
        self.inner.steps_left()
    }

    /// Why the attached controller was handed back to PX4, if it was.
    #[getter]
    fn fallback_reason(&self) -> Option<String> {
        self.inner.fallback_reason().map(str::to_string)
    }

    /// Advance by `dt` seconds (GIL released).
    fn advance(&mut self, py: Python<'_>, dt: f64) -> PyResult<()> {
        if !dt.is_finite() || dt < 0.0 {
            return Err(to_py(ConfigError::new(
                "dt",
                format!("must be a finite number >= 0 (got {dt})"),
            )));
        }
        let inner = &mut self.inner;
        py.detach(|| inner.advance(dt)).map_err(to_py)
    }

    /// Run to the scenario's end (GIL released), logging the final sample.
    fn run_to_end(&mut self, py: Python<'_>) -> PyResult<()> {
        let inner = &mut self.inner;
        py.detach(|| inner.run_to_end()).map_err(to_py)
    }

    /// Set one axis (0 = N, 1 = E, 2 = D) to mode `pos`, `vel` or `acc` with `value` (SI).
    fn set_setpoint(&mut self, axis: usize, mode: &str, value: f64) -> PyResult<()> {
        if axis > 2 {
            return Err(to_py(ConfigError::new(
                "axis",
                "must be 0 (N), 1 (E) or 2 (D)",
            )));
        }
        if !value.is_finite() {
            return Err(to_py(ConfigError::new(
                "value",
                format!("must be finite (got {value})"),
            )));
        }
        let sp = match mode {
            "pos" => AxisSetpoint::Position(value),
            "vel" => AxisSetpoint::Velocity(value),
            "acc" => AxisSetpoint::Acceleration(value),
            other => {
                return Err(to_py(ConfigError::new(
                    "mode",
                    format!("must be \"pos\", \"vel\" or \"acc\" (got {other:?})"),
                )))
            }
        };
        self.inner.set_setpoint(axis, sp);
        Ok(())
    }

    /// The current state as a dict keyed by `STATE_KEYS` (true plant state, measured
    /// swing, cascade setpoints).
    fn state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in self.inner.state_snapshot() {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// The trace logged so far, copied into a dict of numpy arrays.
    fn trace<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        trace_to_dict(py, self.inner.trace().clone())
    }

    /// Take the trace out (the simulator keeps logging into a fresh one).
    fn take_trace<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        trace_to_dict(py, self.inner.take_trace())
    }

    /// Wall-clock compute time of every controller tick so far [µs].
    fn tick_times<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.tick_stats().tick_us.clone().into_pyarray(py)
    }

    /// Fly the MPC on an identified model (swingrt-model/1 JSON) in place of PX4's velocity
    /// PID on the model's axes from `engage_at` [s]; `budget` [s] per tick before fallback.
    #[pyo3(signature = (model_json, settings_json, engage_at, budget))]
    fn attach_mpc(
        &mut self,
        model_json: &str,
        settings_json: Option<&str>,
        engage_at: f64,
        budget: f64,
    ) -> PyResult<()> {
        let model = LinearModel::from_json(model_json).map_err(to_py)?;
        let settings = match settings_json {
            Some(t) => parse_settings::<MpcSettings>(t, "mpc")?,
            None => MpcSettings::default(),
        };
        let mpc = MpcController::new(&model, settings).map_err(to_py)?;
        self.inner
            .attach_controller(Box::new(mpc), engage_at, budget)
            .map_err(to_py)
    }

    /// Fly the baseline LQR (eq. 5.12–5.20) with the given white-box parameters on `axes`
    /// axes (1 = N, 2 = N+E) from `engage_at` [s].
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (m_q, m_p, l, c, axes, settings_json, engage_at, budget))]
    fn attach_lqr(
        &mut self,
        m_q: f64,
        m_p: f64,
        l: f64,
        c: f64,
        axes: usize,
        settings_json: Option<&str>,
        engage_at: f64,
        budget: f64,
    ) -> PyResult<()> {
        let settings = match settings_json {
            Some(t) => parse_settings::<LqrSettings>(t, "lqr")?,
            None => LqrSettings::default(),
        };
        let params = PendulumModel { m_q, m_p, l, c };
        let lqr = LqrController::new(params, axes, settings).map_err(to_py)?;
        self.inner
            .attach_controller(Box::new(lqr), engage_at, budget)
            .map_err(to_py)
    }

    /// Predicted outputs of the attached controller's last tick (MPC), else None.
    fn controller_prediction<'py>(&mut self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.inner
            .controller_prediction()
            .map(|v| v.into_pyarray(py))
    }

    /// Number of controller ticks that needed the constrained QP.
    #[getter]
    fn constrained_ticks(&self) -> usize {
        self.inner.tick_stats().constrained
    }
}

/// Register this domain's functions and classes on the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(scenario_from_toml, m)?)?;
    m.add_function(wrap_pyfunction!(scenario_from_json, m)?)?;
    m.add_function(wrap_pyfunction!(scenario_to_toml, m)?)?;
    m.add_function(wrap_pyfunction!(default_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(run_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(sim_real_time_factor, m)?)?;
    m.add_class::<PySimulator>()?;
    m.add("TRACE_COLUMNS", PyTuple::new(m.py(), TRACE_COLUMNS)?)?;
    m.add("STATE_KEYS", PyTuple::new(m.py(), STATE_KEYS)?)?;
    Ok(())
}
