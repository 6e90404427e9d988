//! Bindings of `swing_core::mission` and the position-tracking MPC: missions from files or
//! a random draw, the guidance that flies them, the local projection, and the tracking MPC
//! for a flight outside the simulator (`swingrt fly --mission`).

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use swing_core::control::{ControlError, SwingController, TickInfo, TrackingMpc, TrackingSettings};
use swing_core::mission::{
    Guidance, GuidanceSettings, LocalProjection, Mission, PreviewBuffer, RandomPlan,
};
use swing_core::ConfigError;

use crate::control::{read_state, read_vec, tick_dict};
use crate::convert::{self, to_py_object};
use crate::errors::to_py;
use crate::sysid::PyLinearModel;

/// A mission: position items in local NED about a home (`swing_core::mission::plan`).
#[pyclass(name = "Mission", module = "swingrt._core", frozen)]
#[derive(Clone)]
pub struct PyMission {
    pub inner: Mission,
}

#[pymethods]
impl PyMission {
    /// Read a mission from file text: `kind` is the file's extension, `plan` (a
    /// QGroundControl plan) or `toml` (NED waypoints). Unsupported items raise
    /// `ConfigError` naming them (`mission.items[4]: command 20 (RTL) is not supported`).
    #[staticmethod]
    fn from_text(text: &str, kind: &str) -> PyResult<Self> {
        Ok(Self {
            inner: Mission::from_text(text, kind).map_err(to_py)?,
        })
    }

    /// A mission from its JSON form (`to_json`), checked.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Self> {
        let inner: Mission = swing_core::config::from_json_str(text).map_err(to_py)?;
        inner.validate().map_err(to_py)?;
        Ok(Self { inner })
    }

    /// A random delivery plan drawn from `settings` (a dict of `RandomPlan` fields:
    /// waypoints, leg_min, leg_max, speed, hold, acceptance_radius, altitude, turn_max, seed).
    #[staticmethod]
    #[pyo3(signature = (settings=None))]
    fn random(settings: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let r: RandomPlan = convert::settings(settings, "random")?;
        let inner = r
            .generate()
            .map_err(|e| to_py(convert::within(e, "random")))?;
        Ok(Self { inner })
    }

    /// The mission as JSON text.
    fn to_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.inner)
            .map_err(|e| to_py(ConfigError::new("mission", e.to_string())))
    }

    /// The mission as TOML text (the format `from_text(..., "toml")` reads).
    fn to_toml(&self) -> String {
        self.inner.to_toml()
    }

    /// The mission as a dict (`name`, `home`, `items`: kind, position, hold,
    /// acceptance_radius, speed, source).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py_object(py, &self.inner)
    }

    /// Name for reports.
    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }

    /// The items as a list of dicts.
    #[getter]
    fn items<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py_object(py, &self.inner.items)
    }

    /// Geodetic origin (lat [deg], lon [deg], alt AMSL [m]), or None.
    #[getter]
    fn home(&self) -> Option<(f64, f64, f64)> {
        self.inner.home.map(|h| (h.lat, h.lon, h.alt))
    }

    /// Where the vehicle starts, NED [m] (above the first item).
    #[getter]
    fn start(&self) -> [f64; 3] {
        self.inner.start()
    }

    /// The mission with every position shifted by `offset` (NED) [m].
    fn shifted(&self, offset: [f64; 3]) -> Self {
        Self {
            inner: self.inner.shifted(offset),
        }
    }

    fn __len__(&self) -> usize {
        self.inner.items.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "Mission({:?}, {} items)",
            self.inner.name,
            self.inner.items.len()
        )
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other
            .cast::<PyMission>()
            .map(|o| o.get().inner == self.inner)
            .unwrap_or(false)
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (String,))> {
        let cls = slf.get_type().getattr("from_json")?;
        Ok((cls, (slf.get().to_json()?,)))
    }
}

/// North and East [m] of (`lat`, `lon`) [deg] about the origin (`lat0`, `lon0`) — PX4's
/// local projection.
#[pyfunction]
fn geo_project(lat0: f64, lon0: f64, lat: f64, lon: f64) -> (f64, f64) {
    LocalProjection::new(lat0, lon0).project(lat, lon)
}

/// Latitude and longitude [deg] of the point `north`, `east` [m] from the origin
/// (`lat0`, `lon0`).
#[pyfunction]
fn geo_reproject(lat0: f64, lon0: f64, north: f64, east: f64) -> (f64, f64) {
    LocalProjection::new(lat0, lon0).reproject(north, east)
}

fn point3(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<[f64; 3]> {
    let v = read_vec(obj, 3, what)?;
    if v.iter().any(|x| !x.is_finite()) {
        return Err(to_py(ControlError::Input(format!("{what} is not finite"))));
    }
    Ok([v[0], v[1], v[2]])
}

/// The guidance of a mission outside the simulator (`swingrt fly --mission`): setpoints,
/// events and the preview for the tracking MPC.
#[pyclass(name = "Guidance", module = "swingrt._core", unsendable)]
pub struct PyGuidance {
    inner: Box<dyn Guidance>,
}

#[pymethods]
impl PyGuidance {
    /// The guidance of `mission` with `settings` (a dict of `GuidanceSettings` fields:
    /// mode `smooth` or `px4`, limits, PX4's parameters).
    #[new]
    #[pyo3(signature = (mission, settings=None))]
    fn new(mission: &PyMission, settings: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let s: GuidanceSettings = convert::settings(settings, "guidance")?;
        let inner = s
            .build(&mission.inner)
            .map_err(|e| to_py(convert::within(e, "guidance")))?;
        Ok(Self { inner })
    }

    /// Begin the mission at time `t` [s] from position `pos` and velocity `vel` (NED).
    fn start(&mut self, t: f64, pos: &Bound<'_, PyAny>, vel: &Bound<'_, PyAny>) -> PyResult<()> {
        let (p, v) = (point3(pos, "pos")?, point3(vel, "vel")?);
        self.inner.start(t, &p, &v);
        Ok(())
    }

    /// One tick at time `t` after `dt` [s] with the measured position and velocity: the
    /// setpoint now, an array (4, 3) of rows position, velocity, acceleration, jerk (NED).
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        t: f64,
        dt: f64,
        pos: &Bound<'py, PyAny>,
        vel: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        if !(t.is_finite() && dt.is_finite() && dt >= 0.0) {
            return Err(to_py(ControlError::Input(format!(
                "t and dt must be finite, dt >= 0 (got {t}, {dt})"
            ))));
        }
        let (p, v) = (point3(pos, "pos")?, point3(vel, "vel")?);
        let sp = self.inner.update(t, dt, &p, &v);
        let flat: Vec<f64> = [sp.p, sp.v, sp.a, sp.j].concat();
        Ok(PyArray1::from_vec(py, flat).reshape([4, 3])?.into_any())
    }

    /// Whether the mission is complete.
    #[getter]
    fn done(&self) -> bool {
        self.inner.done()
    }

    /// The events so far as (time [s], item index, kind) with kind `started`, `reached`,
    /// `left` or `completed`.
    fn events(&self) -> Vec<(f64, usize, String)> {
        self.inner
            .events()
            .iter()
            .map(|e| (e.t, e.item, e.kind.name().to_string()))
            .collect()
    }

    /// The mission flown.
    #[getter]
    fn mission(&self) -> PyMission {
        PyMission {
            inner: self.inner.mission().clone(),
        }
    }
}

/// The position-tracking MPC with preview (`control::mpc::tracking`) for a flight outside
/// the simulator: each tick reads the state, the horizontal position and the guidance.
#[pyclass(name = "TrackingMpc", module = "swingrt._core", unsendable)]
pub struct PyTrackingMpc {
    inner: TrackingMpc,
    preview: PreviewBuffer,
    last: TickInfo,
}

impl PyTrackingMpc {
    fn observe(
        &mut self,
        position: &Bound<'_, PyAny>,
        guidance: &PyGuidance,
        t: f64,
    ) -> PyResult<()> {
        let axes = self.inner.axes();
        let pos = read_vec(position, axes, "position")?;
        if !t.is_finite() {
            return Err(to_py(ControlError::Input(format!("t is not finite ({t})"))));
        }
        let period = self.inner.period();
        let view = self.preview.fill(guidance.inner.as_ref(), t, period);
        self.inner.observe_reference(&pos, &view);
        Ok(())
    }
}

#[pymethods]
impl PyTrackingMpc {
    /// Design on `model` with `tracking` settings (a dict of `TrackingSettings` fields,
    /// its `mpc` table the MPC's horizons, weights and estimator).
    #[new]
    #[pyo3(signature = (model, tracking=None))]
    fn new(
        py: Python<'_>,
        model: &PyLinearModel,
        tracking: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let model = model.inner.clone();
        let tr: TrackingSettings = convert::settings(tracking, "tracking")?;
        let inner = py.detach(|| TrackingMpc::new(&model, tr)).map_err(to_py)?;
        let preview = PreviewBuffer::new(inner.reference_steps(), inner.axes());
        Ok(Self {
            inner,
            preview,
            last: TickInfo::default(),
        })
    }

    /// Restart from the measured state (axes × [v, swing, swing_rate]), horizontal
    /// position and acceleration setpoint, with the reference of `guidance` at time `t`.
    #[pyo3(signature = (state, position, guidance, t, acc=None))]
    fn reset(
        &mut self,
        state: PyReadonlyArrayDyn<'_, f64>,
        position: &Bound<'_, PyAny>,
        guidance: &PyGuidance,
        t: f64,
        acc: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        self.observe(position, guidance, t)?;
        let axes = self.inner.axes();
        let st = read_state(&state, axes)?;
        let a = match acc {
            Some(obj) => read_vec(obj, axes, "acc")?,
            None => vec![0.0; axes],
        };
        self.inner.reset(&st, &a);
        Ok(())
    }

    /// One tick: state, horizontal position [m] and the guidance's reference at time `t` in,
    /// acceleration setpoint per axis [m/s²] out.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        state: PyReadonlyArrayDyn<'py, f64>,
        position: &Bound<'py, PyAny>,
        guidance: &PyGuidance,
        t: f64,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        self.observe(position, guidance, t)?;
        let axes = self.inner.axes();
        let st = read_state(&state, axes)?;
        let mut out = vec![0.0; axes];
        let zeros = vec![0.0; axes];
        self.last = self.inner.step(&st, &zeros, &mut out).map_err(to_py)?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// What the last tick did: {"kind": "unconstrained"|"constrained", "iterations": n}.
    fn last_tick<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        tick_dict(py, self.last)
    }

    /// Tick period [s] (the model's dt).
    #[getter]
    fn period(&self) -> f64 {
        self.inner.period()
    }

    /// Number of controlled axes.
    #[getter]
    fn axes(&self) -> usize {
        self.inner.axes()
    }
}

/// Register this domain's functions and classes on the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyMission>()?;
    m.add_class::<PyGuidance>()?;
    m.add_class::<PyTrackingMpc>()?;
    m.add_function(wrap_pyfunction!(geo_project, m)?)?;
    m.add_function(wrap_pyfunction!(geo_reproject, m)?)?;
    Ok(())
}
