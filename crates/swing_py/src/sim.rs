//! Bindings of `swing_core::sim`: scenarios, the steppable simulator and whole runs.

use numpy::{IntoPyArray, PyArray1};
use std::sync::{Mutex, MutexGuard};

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use swing_core::control::lqr::{LqrController, LqrSettings};
use swing_core::control::mpc::MpcSettings;
use swing_core::control::px4::AxisSetpoint;
use swing_core::design::adaptive::TwinPrior;
use swing_core::design::reidentify::Twin;
use swing_core::design::{AdaptiveMpc, AdaptiveSettings, Law};
use swing_core::plant::PendulumModel;
use swing_core::sim::{Scenario, Simulator, Trace, FLIGHT_COLUMNS, STATE_KEYS, TRACE_COLUMNS};
use swing_core::ConfigError;

use crate::errors::to_py;
use crate::sysid::PyLinearModel;

/// The adaptive MPC's twin path prior from the training flight's scenario `twin` and
/// `twin_payload` = (payload mass [kg], cable length [m], vehicle mass [kg]) the model was
/// identified for: both or neither.
pub(crate) fn twin_prior(
    adaptive: &AdaptiveSettings,
    twin: Option<&PyScenario>,
    twin_payload: Option<(f64, f64, f64)>,
) -> PyResult<Option<TwinPrior>> {
    match (twin, twin_payload) {
        (Some(sc), Some((payload_mass, length, vehicle_mass))) => {
            let twin = Twin::new(
                &sc.inner,
                adaptive.twin.duration,
                vehicle_mass,
                adaptive.twin.search,
            )
            .map_err(|e| to_py(e.within("twin")))?;
            Ok(Some(TwinPrior {
                twin,
                payload_mass,
                length,
            }))
        }
        (None, None) => Ok(None),
        _ => Err(to_py(ConfigError::new(
            "twin_payload",
            "twin and twin_payload go together",
        ))),
    }
}

/// A core trace as a dict of numpy columns.
pub fn trace_to_dict<'py>(py: Python<'py>, trace: Trace) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (name, col) in trace.into_columns() {
        d.set_item(name, col.into_pyarray(py))?;
    }
    Ok(d)
}

/// A complete, validated simulation scenario (vehicle, payload, wind, noise, PX4 gains,
/// schedule). Built from a built-in base plus TOML text or a dict, merged in the core.
#[pyclass(name = "Scenario", module = "swingrt._core", frozen)]
#[derive(Clone)]
pub struct PyScenario {
    /// The core scenario.
    pub inner: Scenario,
}

fn overrides(obj: &Bound<'_, PyAny>) -> PyResult<toml::Table> {
    crate::convert::toml_table(obj, "")
}

#[pymethods]
impl PyScenario {
    /// A built-in scenario: `step` (simulate), `training` (collect) or `hover`.
    #[staticmethod]
    #[pyo3(signature = (name="step"))]
    fn builtin(name: &str) -> PyResult<Self> {
        Ok(Self {
            inner: Scenario::builtin(name).map_err(to_py)?,
        })
    }

    /// TOML text merged over the built-in scenario `base` (tables merge key by key).
    #[staticmethod]
    #[pyo3(signature = (text, base="step"))]
    fn from_toml(text: &str, base: &str) -> PyResult<Self> {
        Ok(Self {
            inner: Scenario::from_toml_over(text, base).map_err(to_py)?,
        })
    }

    /// A dict merged over the built-in scenario `base`.
    #[staticmethod]
    #[pyo3(signature = (overrides, base="step"))]
    fn from_dict(overrides: &Bound<'_, PyAny>, base: &str) -> PyResult<Self> {
        let over = self::overrides(overrides)?;
        let base = Scenario::builtin(base).map_err(to_py)?;
        Ok(Self {
            inner: base.with_overrides(over).map_err(to_py)?,
        })
    }

    /// Parse complete scenario JSON (what `to_json` writes).
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Self> {
        Ok(Self {
            inner: Scenario::from_json(text).map_err(to_py)?,
        })
    }

    /// This scenario with a dict of overrides merged in (tables merge key by key).
    fn with_overrides(&self, overrides: &Bound<'_, PyAny>) -> PyResult<Self> {
        let over = self::overrides(overrides)?;
        Ok(Self {
            inner: self.inner.with_overrides(over).map_err(to_py)?,
        })
    }

    /// Every field as a dict.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::convert::to_py_object(py, &self.inner)
    }

    /// Every field as JSON text.
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.inner).map_err(|e| crate::convert::data_err(e.to_string()))
    }

    /// Every field as TOML text.
    fn to_toml(&self) -> PyResult<String> {
        self.inner.to_toml().map_err(to_py)
    }

    /// Name used in reports.
    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }

    /// Simulated duration [s].
    #[getter]
    fn duration(&self) -> f64 {
        self.inner.duration
    }

    /// Seed of every random generator of the run.
    #[getter]
    fn seed(&self) -> u64 {
        self.inner.seed
    }

    /// Physics step [s].
    #[getter]
    fn physics_dt(&self) -> f64 {
        self.inner.physics_dt
    }

    /// Normalised hover thrust PX4's estimator settles on for this vehicle and payload.
    fn hover_thrust(&self) -> f64 {
        self.inner.hover_thrust()
    }

    /// Roll and pitch angular acceleration [rad/s²] per unit of normalised torque at hover
    /// (the rate loop's plant gain).
    fn rate_authority(&self) -> [f64; 2] {
        self.inner.rate_authority()
    }

    /// Total mass [kg] this vehicle's motors hold at the normalised `hover` thrust (the
    /// inverse of `hover_thrust`).
    fn mass_hovering_at(&self, hover: f64) -> f64 {
        swing_core::control::px4::Px4Cascade::mass_hovering_at(&self.inner.vehicle, hover)
    }

    /// The setpoint schedule (explicit entries and seeded random steps) as dicts.
    fn schedule<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        crate::convert::to_py_object(py, &self.inner.schedule())
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        match other.cast::<PyScenario>() {
            Ok(o) => self.inner == o.get().inner,
            Err(_) => false,
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "Scenario({:?}, duration={} s, seed={}, payload={:?})",
            self.inner.name, self.inner.duration, self.inner.seed, self.inner.payload.kind
        )
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (String,))> {
        let text = serde_json::to_string(&slf.get().inner)
            .map_err(|e| crate::convert::data_err(e.to_string()))?;
        Ok((slf.get_type().getattr("from_json")?, (text,)))
    }
}

/// Simulated seconds per wall second of the full loop of `scenario` (with its payload),
/// measured over `seconds` of simulated flight on the calling thread.
#[pyfunction]
fn sim_real_time_factor(py: Python<'_>, scenario: &PyScenario, seconds: f64) -> PyResult<f64> {
    let sc = scenario.inner.clone();
    py.detach(|| swing_core::sim::real_time_factor(sc, seconds))
        .map_err(to_py)
}

/// The steppable closed-loop simulator (vehicle, payload, PX4 cascade, wind).
#[pyclass(name = "Simulator", module = "swingrt._core")]
pub struct PySimulator {
    // A Mutex makes the simulator shareable between threads (a Dask worker may drop it on
    // another thread than it ran on); `&mut self` methods reach it without locking.
    inner: Mutex<Simulator>,
}

impl PySimulator {
    fn sim(&self) -> MutexGuard<'_, Simulator> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn sim_mut(&mut self) -> &mut Simulator {
        self.inner.get_mut().unwrap_or_else(|e| e.into_inner())
    }
}

#[pymethods]
impl PySimulator {
    /// Build from a scenario.
    #[new]
    fn new(scenario: &PyScenario) -> PyResult<Self> {
        Ok(Self {
            inner: Mutex::new(Simulator::new(scenario.inner.clone()).map_err(to_py)?),
        })
    }

    /// Current simulated time [s].
    #[getter]
    fn t(&self) -> f64 {
        self.sim().time()
    }

    /// Scenario duration [s].
    #[getter]
    fn duration(&self) -> f64 {
        self.sim().duration()
    }

    /// Physics steps left until the scenario's end.
    #[getter]
    fn steps_left(&self) -> u64 {
        self.sim().steps_left()
    }

    /// Why the attached controller was handed back to PX4, if it was.
    #[getter]
    fn fallback_reason(&self) -> Option<String> {
        self.sim().fallback_reason().map(str::to_string)
    }

    /// Advance by `dt` seconds (GIL released).
    fn advance(&mut self, py: Python<'_>, dt: f64) -> PyResult<()> {
        if !dt.is_finite() || dt < 0.0 {
            return Err(to_py(ConfigError::new(
                "dt",
                format!("must be a finite number >= 0 (got {dt})"),
            )));
        }
        let inner = self.sim_mut();
        py.detach(|| inner.advance(dt)).map_err(to_py)
    }

    /// Run to the scenario's end (GIL released), logging the final sample.
    fn run_to_end(&mut self, py: Python<'_>) -> PyResult<()> {
        let inner = self.sim_mut();
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
        self.sim_mut().set_setpoint(axis, sp);
        Ok(())
    }

    /// The current state as a dict keyed by `STATE_KEYS` (true plant state, measured
    /// swing, cascade setpoints).
    fn state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in self.sim().state_snapshot() {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// The trace logged so far, copied into a dict of numpy arrays.
    fn trace<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        trace_to_dict(py, self.sim().trace().clone())
    }

    /// Take the trace out (the simulator keeps logging into a fresh one).
    fn take_trace<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        trace_to_dict(py, self.sim_mut().take_trace())
    }

    /// Wall-clock compute time of every controller tick so far [µs].
    fn tick_times<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.sim().tick_stats().tick_us.clone().into_pyarray(py)
    }

    /// Fly what an identified model flies (`design::law`: the MPC on it in place of PX4's
    /// velocity PID, or the input shaper its selection took on PX4's velocity setpoint) on
    /// the model's axes from `engage_at` [s]; `budget` [s] per tick before fallback.
    #[pyo3(signature = (model, settings, engage_at, budget))]
    fn attach_mpc(
        &mut self,
        model: &PyLinearModel,
        settings: Option<&Bound<'_, PyAny>>,
        engage_at: f64,
        budget: f64,
    ) -> PyResult<()> {
        let settings: MpcSettings = crate::convert::settings(settings, "mpc")?;
        let ctrl = Law::of(&model.inner)
            .and_then(|law| law.controller(&model.inner, &settings))
            .map_err(to_py)?;
        self.sim_mut()
            .attach_controller(ctrl, engage_at, budget)
            .map_err(to_py)
    }

    /// Fly the adaptive MPC (`design::adaptive`) designed on `model` with MPC `settings`
    /// and `adaptive` settings from `engage_at` [s]: the model follows the payload online.
    /// `twin` (the training flight's scenario) with `twin_payload` = (payload mass [kg],
    /// cable length [m], vehicle mass [kg]) the model was identified for enables the twin
    /// path (`adaptive.twin.enabled`).
    #[pyo3(signature = (model, settings, adaptive, engage_at, budget, twin=None, twin_payload=None))]
    #[allow(clippy::too_many_arguments)]
    fn attach_adaptive_mpc(
        &mut self,
        model: &PyLinearModel,
        settings: Option<&Bound<'_, PyAny>>,
        adaptive: Option<&Bound<'_, PyAny>>,
        engage_at: f64,
        budget: f64,
        twin: Option<&PyScenario>,
        twin_payload: Option<(f64, f64, f64)>,
    ) -> PyResult<()> {
        let settings: MpcSettings = crate::convert::settings(settings, "mpc")?;
        let adaptive: AdaptiveSettings = crate::convert::settings(adaptive, "adaptive")?;
        let prior = twin_prior(&adaptive, twin, twin_payload)?;
        let ctrl =
            AdaptiveMpc::with_twin(&model.inner, settings, adaptive, prior).map_err(to_py)?;
        self.sim_mut()
            .attach_controller(Box::new(ctrl), engage_at, budget)
            .map_err(to_py)
    }

    /// Fly a core `Controller` (`shaper`, `payload_p`, `deepc`) from `engage_at` [s] with
    /// `budget` [s] per tick before fallback; the simulator takes it over.
    #[pyo3(signature = (controller, engage_at, budget))]
    fn attach(
        &mut self,
        controller: &mut crate::methods::PyController,
        engage_at: f64,
        budget: f64,
    ) -> PyResult<()> {
        let ctrl = controller.take()?;
        self.sim_mut()
            .attach_controller(ctrl, engage_at, budget)
            .map_err(to_py)
    }

    /// Fly a Python controller object (`reset(state, acc)`, `step(state, vel_ref)` with
    /// state an (axes, 3) array of [v, swing, swing_rate]) on `axes` axes every `period` [s]
    /// under the same supervisor: `output` is `acceleration` (in place of PX4's velocity
    /// PID) or `velocity` (a setpoint PX4's PID tracks); a Python exception, a late tick
    /// (over `budget` [s]) or a non-finite command hands the axes back to PX4.
    #[pyo3(signature = (controller, axes, period, output, engage_at, budget))]
    fn attach_python(
        &mut self,
        controller: Py<PyAny>,
        axes: usize,
        period: f64,
        output: &str,
        engage_at: f64,
        budget: f64,
    ) -> PyResult<()> {
        let ctrl = crate::methods::PythonController::new(controller, axes, period, output)
            .map_err(to_py)?;
        self.sim_mut()
            .attach_controller(Box::new(ctrl), engage_at, budget)
            .map_err(to_py)
    }

    /// Events of the attached controller so far as (time [s], what, value) tuples, e.g. the
    /// adaptive MPC's `detected`, `requested`, `adopted` and `rejected`.
    fn controller_events(&self) -> Vec<(f64, String, f64)> {
        self.sim()
            .controller_events()
            .into_iter()
            .map(|(t, w, v)| (t, w.to_string(), v))
            .collect()
    }

    /// Fly the baseline LQR (eq. 5.12–5.20) with the white-box `params` (a dict of `m_q`,
    /// `m_p`, `l`, `c`) on `axes` axes (1 = N, 2 = N+E) from `engage_at` [s].
    #[pyo3(signature = (params, axes, settings, engage_at, budget))]
    fn attach_lqr(
        &mut self,
        params: &Bound<'_, PyAny>,
        axes: usize,
        settings: Option<&Bound<'_, PyAny>>,
        engage_at: f64,
        budget: f64,
    ) -> PyResult<()> {
        let settings: LqrSettings = crate::convert::settings(settings, "lqr")?;
        let params: PendulumModel = crate::convert::from_py(params, "lqr_params")?;
        let lqr = LqrController::new(params, axes, settings).map_err(to_py)?;
        self.sim_mut()
            .attach_controller(Box::new(lqr), engage_at, budget)
            .map_err(to_py)
    }

    /// Fly `mission` from `start_at` [s] with the guidance of `guidance` settings (a dict of
    /// `GuidanceSettings` fields; mode `smooth` — swingrt's legs — or `px4` — PX4's mission
    /// behaviour): its trajectory setpoint replaces the scenario's setpoints on every axis.
    #[pyo3(signature = (mission, guidance=None, start_at=0.0))]
    fn fly_mission(
        &mut self,
        mission: &crate::mission::PyMission,
        guidance: Option<&Bound<'_, PyAny>>,
        start_at: f64,
    ) -> PyResult<()> {
        let s: swing_core::mission::GuidanceSettings =
            crate::convert::settings(guidance, "guidance")?;
        let g = s
            .build(&mission.inner)
            .map_err(|e| to_py(crate::convert::within(e, "guidance")))?;
        self.sim_mut().fly_mission(g, start_at).map_err(to_py)
    }

    /// Whether the mission flown is complete.
    #[getter]
    fn mission_done(&self) -> bool {
        self.sim().mission_done()
    }

    /// The mission's events so far as (time [s], item index, kind) with kind `started`,
    /// `reached`, `left` or `completed`.
    fn mission_events(&self) -> Vec<(f64, usize, String)> {
        self.sim()
            .mission_events()
            .iter()
            .map(|e| (e.t, e.item, e.kind.name().to_string()))
            .collect()
    }

    /// Fly the position-tracking MPC with preview (`control::mpc::tracking`) on an
    /// identified model with `tracking` settings from `engage_at` [s]; it tracks the mission
    /// flown (`fly_mission`) and engages when the mission starts.
    #[pyo3(signature = (model, tracking, engage_at, budget))]
    fn attach_tracking_mpc(
        &mut self,
        model: &PyLinearModel,
        tracking: Option<&Bound<'_, PyAny>>,
        engage_at: f64,
        budget: f64,
    ) -> PyResult<()> {
        let tracking: swing_core::control::TrackingSettings =
            crate::convert::settings(tracking, "tracking")?;
        let mpc = swing_core::control::TrackingMpc::new(&model.inner, tracking).map_err(to_py)?;
        self.sim_mut()
            .attach_controller(Box::new(mpc), engage_at, budget)
            .map_err(to_py)
    }

    /// Predicted outputs of the attached controller's last tick (MPC), else None.
    fn controller_prediction<'py>(&mut self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.sim_mut()
            .controller_prediction()
            .map(|v| v.into_pyarray(py))
    }

    /// Number of controller ticks that needed the constrained QP.
    #[getter]
    fn constrained_ticks(&self) -> usize {
        self.sim().tick_stats().constrained
    }
}

/// Register this domain's functions and classes on the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScenario>()?;
    m.add_function(wrap_pyfunction!(sim_real_time_factor, m)?)?;
    m.add_class::<PySimulator>()?;
    m.add("TRACE_COLUMNS", PyTuple::new(m.py(), TRACE_COLUMNS)?)?;
    m.add("STATE_KEYS", PyTuple::new(m.py(), STATE_KEYS)?)?;
    m.add("FLIGHT_COLUMNS", PyTuple::new(m.py(), FLIGHT_COLUMNS)?)?;
    Ok(())
}
