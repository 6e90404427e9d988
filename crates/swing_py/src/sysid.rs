//! Bindings of `swing_core::sysid`: the `LinearModel` and `Search` classes and the
//! identification entry points. Conversion and error mapping only.
//!
//! Data cross as C-contiguous float64 arrays of shape (samples, columns), borrowed without
//! copies; models as `LinearModel` objects (JSON only for files and pickling); settings as
//! dicts read by the core's serde structs. Long calls release the GIL.

use std::sync::Arc;

use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use swing_core::control::mpc::MpcSettings;
use swing_core::design::selection::{self, SelectionSettings};
use swing_core::design::twin::TwinPlant;
use swing_core::plant::GRAVITY;
use swing_core::sysid::metrics::rollout_nmae;
use swing_core::sysid::pipeline::{self, candidate_row, ThrustLog};
use swing_core::sysid::search::SearchResult;
use swing_core::sysid::{lag, smooth, whitebox, IdentifySettings, LinearModel, Trajectory};
use swing_core::Category;

use crate::convert::{array1, array2, cols, data_err, from_py, to_py_object};
use crate::errors::{raise, to_py};
use crate::sim::PyScenario;

/// A discrete linear model over delay coordinates (`swingrt-model/1`):
/// z_{k+1} = A z_k + B (u_k − input_mean) + c, z_k = [x_k; …; x_{k−q+1}] (newest first).
#[pyclass(name = "LinearModel", module = "swingrt._core", frozen)]
pub struct PyLinearModel {
    /// The core model (shared, immutable).
    pub inner: Arc<LinearModel>,
    a: Py<PyArray2<f64>>,
    b: Py<PyArray2<f64>>,
    c: Py<PyArray1<f64>>,
}

fn readonly2<'py>(py: Python<'py>, m: &nalgebra::DMatrix<f64>) -> PyResult<Py<PyArray2<f64>>> {
    let rows: Vec<Vec<f64>> = (0..m.nrows())
        .map(|i| m.row(i).iter().copied().collect())
        .collect();
    let arr = if m.nrows() == 0 {
        PyArray2::<f64>::zeros(py, [0, m.ncols()], false)
    } else {
        PyArray2::from_vec2(py, &rows).map_err(|e| data_err(e.to_string()))?
    };
    arr.readwrite().make_nonwriteable();
    Ok(arr.unbind())
}

impl PyLinearModel {
    /// Wrap a core model (validated by the caller).
    pub fn wrap(py: Python<'_>, model: LinearModel) -> PyResult<Self> {
        let a = readonly2(py, &model.a)?;
        let b = readonly2(py, &model.b)?;
        let c = PyArray1::from_slice(py, model.c.as_slice());
        c.readwrite().make_nonwriteable();
        Ok(Self {
            inner: Arc::new(model),
            a,
            b,
            c: c.unbind(),
        })
    }

    fn parse(py: Python<'_>, text: &str) -> PyResult<Self> {
        let model = LinearModel::from_json(text).map_err(to_py)?;
        Self::wrap(py, model)
    }
}

#[pymethods]
impl PyLinearModel {
    /// Parse and validate `swingrt-model/1` JSON text (`ModelError` naming the problem).
    #[staticmethod]
    fn from_json(py: Python<'_>, text: &str) -> PyResult<Self> {
        Self::parse(py, text)
    }

    /// Read a model file (`ModelError` naming the file and the problem).
    #[staticmethod]
    fn load(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Self> {
        let shown = path.display().to_string();
        if !path.is_file() {
            return Err(raise(
                Category::Model,
                format!("{shown}: no such model file"),
            ));
        }
        let text = std::fs::read_to_string(&path)
            .map_err(|e| raise(Category::Model, format!("{shown}: cannot read: {e}")))?;
        let model = LinearModel::from_json(&text)
            .map_err(|e| raise(Category::Model, format!("{shown}: {e}")))?;
        Self::wrap(py, model)
    }

    /// The `swingrt-model/1` JSON text.
    fn to_json(&self) -> PyResult<String> {
        self.inner.to_json().map_err(to_py)
    }

    /// Write the JSON atomically (a temporary file beside `path`, then a rename).
    fn save(&self, path: std::path::PathBuf) -> PyResult<()> {
        let text = self.inner.to_json().map_err(to_py)? + "\n";
        crate::convert::write_atomic(&path, &text).map_err(|e| {
            raise(
                Category::Data,
                format!("{}: cannot write: {e}", path.display()),
            )
        })
    }

    /// State matrix A, (n·q) × (n·q) (read-only).
    #[getter(A)]
    fn a<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        self.a.bind(py).clone()
    }

    /// Input matrix B, (n·q) × m (read-only).
    #[getter(B)]
    fn b<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        self.b.bind(py).clone()
    }

    /// Constant term c, n·q (read-only).
    #[getter]
    fn c<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.c.bind(py).clone()
    }

    /// Identification method: `dmdc`, `havokc` or `whitebox`.
    #[getter]
    fn method(&self) -> &str {
        &self.inner.method
    }

    /// Sample time [s].
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.dt
    }

    /// Number of stacked frames q.
    #[getter]
    fn delays(&self) -> usize {
        self.inner.delays
    }

    /// SVD truncation rank p (0 when not applicable).
    #[getter]
    fn rank(&self) -> usize {
        self.inner.rank
    }

    /// Names of the physical states.
    #[getter]
    fn states(&self) -> Vec<String> {
        self.inner.states.clone()
    }

    /// Names of the inputs.
    #[getter]
    fn inputs(&self) -> Vec<String> {
        self.inner.inputs.clone()
    }

    /// Offset handling: `none`, `mean` or `affine`.
    #[getter]
    fn offset(&self) -> &'static str {
        self.inner.offset.name()
    }

    /// Input mean subtracted before B.
    #[getter]
    fn input_mean<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.input_mean)
    }

    /// Fingerprint of the training data (empty when unknown).
    #[getter]
    fn fingerprint(&self) -> &str {
        &self.inner.fingerprint
    }

    /// Dimension n·q of the stacked state.
    #[getter]
    fn order(&self) -> usize {
        self.inner.order()
    }

    /// Largest eigenvalue modulus of A.
    #[getter]
    fn spectral_radius(&self) -> PyResult<f64> {
        match self.inner.diagnostics.spectral_radius {
            Some(r) => Ok(r),
            None => self.inner.spectral_radius().map_err(to_py),
        }
    }

    /// Fit diagnostics as a dict (singular values, NMAE, search choice, control check …).
    #[getter]
    fn diagnostics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py_object(py, &self.inner.diagnostics)
    }

    /// A copy with `items` added to (or replacing entries of) the diagnostics.
    fn with_diagnostics(&self, py: Python<'_>, items: &Bound<'_, PyDict>) -> PyResult<Self> {
        let extra: serde_json::Map<String, serde_json::Value> = from_py(items, "diagnostics")?;
        let mut d =
            serde_json::to_value(&self.inner.diagnostics).map_err(|e| data_err(e.to_string()))?;
        if let serde_json::Value::Object(map) = &mut d {
            map.extend(extra);
        }
        let mut model = (*self.inner).clone();
        model.diagnostics = serde_json::from_value(d)
            .map_err(|e| raise(Category::Config, format!("diagnostics: {e}")))?;
        Self::wrap(py, model)
    }

    /// A copy with a linear vehicle drag of `k` [1/s] on each horizontal velocity.
    fn with_velocity_drag(&self, py: Python<'_>, k: f64) -> PyResult<Self> {
        let model = self.inner.with_velocity_drag(k).map_err(to_py)?;
        Self::wrap(py, model)
    }

    /// Roll the model on from `history` (the last q state rows, oldest first, (q, n)) under
    /// future `inputs` (H, m); returns the predicted (H, n) states x_{k+1..k+H}.
    fn predict<'py>(
        &self,
        py: Python<'py>,
        history: &Bound<'py, PyAny>,
        inputs: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let model = &self.inner;
        let (h, u) = (array2(history, "history")?, array2(inputs, "inputs")?);
        if h.shape()[0] != model.delays || cols(&h) != model.n() {
            return Err(data_err(format!(
                "history must have shape ({}, {}), not {:?}",
                model.delays,
                model.n(),
                h.shape()
            )));
        }
        if cols(&u) != model.m() {
            return Err(data_err(format!("inputs must have {} columns", model.m())));
        }
        let out = model.predict(h.as_slice()?, u.as_slice()?).map_err(to_py)?;
        let rows = out.len() / model.n().max(1);
        PyArray1::from_vec(py, out).reshape([rows, model.n()])
    }

    fn __repr__(&self) -> String {
        let m = &self.inner;
        let score = m
            .diagnostics
            .test_nmae
            .map(|v| format!(", test NMAE {v:.4}"))
            .unwrap_or_default();
        format!(
            "LinearModel({}, q={}, p={}, states={:?}, inputs={:?}, dt={}{score})",
            m.method, m.delays, m.rank, m.states, m.inputs, m.dt
        )
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        match other.cast::<PyLinearModel>() {
            Ok(o) => *self.inner == *o.get().inner,
            Err(_) => false,
        }
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (String,))> {
        let text = slf.get().inner.to_json().map_err(to_py)?;
        let ctor = slf.get_type().getattr("from_json")?;
        Ok((ctor, (text,)))
    }
}

/// The outcome of a (q, p) search: every scored candidate and the selected model.
#[pyclass(name = "Search", module = "swingrt._core", frozen)]
pub struct PySearch {
    inner: Arc<SearchResult>,
    states: Vec<String>,
}

#[pymethods]
impl PySearch {
    /// Every candidate as a dict: delays, rank, nmae, per_state, stable, spectral_radius.
    fn table<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let rows = PyList::empty(py);
        for c in &self.inner.table {
            let mut row = candidate_row(c, &self.states);
            if !c.nmae.is_finite() {
                row["nmae"] = serde_json::Value::Null;
            }
            let obj = to_py_object(py, &row)?;
            if !c.nmae.is_finite() {
                obj.set_item("nmae", c.nmae)?;
            }
            rows.append(obj)?;
        }
        Ok(rows)
    }

    /// Index of the selected candidate in the table.
    #[getter]
    fn best(&self) -> usize {
        self.inner.best
    }
}

/// Borrowed (x, u) of a flight with their names.
struct Columns<'py> {
    x: numpy::PyReadonlyArray2<'py, f64>,
    u: numpy::PyReadonlyArray2<'py, f64>,
}

impl<'py> Columns<'py> {
    fn new(
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        states: &[String],
        inputs: &[String],
    ) -> PyResult<Self> {
        let (x, u) = (array2(x, "x")?, array2(u, "u")?);
        if cols(&x) != states.len() || cols(&u) != inputs.len() {
            return Err(data_err(format!(
                "x has {} columns for {} state names, u {} for {} input names",
                cols(&x),
                states.len(),
                cols(&u),
                inputs.len()
            )));
        }
        Ok(Self { x, u })
    }

    fn trajectory(&self) -> PyResult<Trajectory<'_>> {
        Trajectory::new(
            self.x.as_slice()?,
            cols(&self.x),
            self.u.as_slice()?,
            cols(&self.u),
        )
        .map_err(to_py)
    }
}

/// Check a settings section against its core struct and return it with every default
/// filled in: `identify`, `mpc`, `lqr`, `selection`, `adaptive`, `shaper`, `payload_p`,
/// `deepc`, `tracking`, `guidance` or `random_plan` (`ConfigError` naming `section.field`).
#[pyfunction]
#[pyo3(signature = (section, settings=None))]
fn check_settings<'py>(
    py: Python<'py>,
    section: &str,
    settings: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    use swing_core::control::{LqrSettings, MpcSettings};
    let within = |e: swing_core::ConfigError| to_py(crate::convert::within(e, section));
    match section {
        "identify" => {
            let s: IdentifySettings = crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        "mpc" => {
            let s: MpcSettings = crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        "lqr" => {
            let s: LqrSettings = crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        "selection" => {
            let s: SelectionSettings = crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        "adaptive" => {
            let s: swing_core::design::AdaptiveSettings =
                crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        "shaper" => {
            let s: swing_core::control::ShaperSettings =
                crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        "payload_p" => {
            let s: swing_core::control::PayloadPSettings =
                crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        "deepc" => {
            let s: swing_core::control::DeepcSettings =
                crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        "tracking" => {
            let s: swing_core::control::TrackingSettings =
                crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        "guidance" => {
            let s: swing_core::mission::GuidanceSettings =
                crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        "random_plan" => {
            let s: swing_core::mission::RandomPlan = crate::convert::settings(settings, section)?;
            s.validate().map_err(within)?;
            to_py_object(py, &s)
        }
        other => Err(raise(
            Category::Config,
            format!(
                "unknown settings section {other:?} (identify, mpc, lqr, selection, adaptive, \
                 shaper, payload_p, deepc, tracking, guidance, random_plan)"
            ),
        )),
    }
}

/// Identify a model from resampled columns `x` (N, n) named `states` and `u` (N, m) named
/// `inputs`: fit, search or white-box per `settings`. Returns (model, search or None).
#[pyfunction]
#[pyo3(signature = (x, u, states, inputs, settings=None, *, payload_mass=None))]
fn identify<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    states: Vec<String>,
    inputs: Vec<String>,
    settings: Option<&Bound<'py, PyAny>>,
    payload_mass: Option<f64>,
) -> PyResult<(PyLinearModel, Option<PySearch>)> {
    let s: IdentifySettings = crate::convert::settings(settings, "")?;
    let data = Columns::new(x, u, &states, &inputs)?;
    let traj = data.trajectory()?;
    let out = py
        .detach(|| pipeline::identify(&traj, &states, &inputs, &s, payload_mass))
        .map_err(to_py)?;
    let search = out.search.map(|r| PySearch {
        inner: Arc::new(r),
        states: states.clone(),
    });
    Ok((PyLinearModel::wrap(py, out.model)?, search))
}

/// Control-relevant selection (see `swing_core::design::selection`): from `search` (run on
/// `x`, `u` with `settings`), the model whose MPC (`mpc` settings) flies the white-box
/// `plant` within bounds, first flying the vehicle's twin when `twin` (a scenario of the
/// vehicle) is given. Returns (model, passed).
#[pyfunction]
#[pyo3(signature = (x, u, states, inputs, settings, search, plant, mpc=None, selection=None, twin=None))]
#[allow(clippy::too_many_arguments)]
fn select_for_control<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    states: Vec<String>,
    inputs: Vec<String>,
    settings: Option<&Bound<'py, PyAny>>,
    search: &PySearch,
    plant: &PyLinearModel,
    mpc: Option<&Bound<'py, PyAny>>,
    selection: Option<&Bound<'py, PyAny>>,
    twin: Option<&PyScenario>,
) -> PyResult<(PyLinearModel, bool)> {
    let s: IdentifySettings = crate::convert::settings(settings, "")?;
    s.validate().map_err(to_py)?;
    let mpc: MpcSettings = crate::convert::settings(mpc, "mpc")?;
    let sel: SelectionSettings = crate::convert::settings(selection, "")?;
    let data = Columns::new(x, u, &states, &inputs)?;
    let traj = data.trajectory()?;
    let (train, test) = pipeline::split(&traj, &s).map_err(to_py)?;
    let result = search.inner.clone();
    let plant = plant.inner.clone();
    let twin = twin
        .map(|sc| TwinPlant::new(&sc.inner, &plant, sel.step, inputs.len()))
        .transpose()
        .map_err(to_py)?;
    let picked = py
        .detach(|| {
            selection::select_for_control(
                &train,
                &test,
                &states,
                &inputs,
                &s,
                &result,
                &plant,
                &mpc,
                &sel,
                twin.as_ref(),
            )
        })
        .map_err(to_py)?;
    Ok((PyLinearModel::wrap(py, picked.model)?, picked.passed))
}

/// Held-out rollout NMAE of `model` on (x, u) over `rollout_samples` steps from `starts`
/// start points: returns (per-state list, mean).
#[pyfunction]
#[pyo3(signature = (model, x, u, *, rollout_samples, starts=10))]
fn evaluate(
    py: Python<'_>,
    model: &PyLinearModel,
    x: &Bound<'_, PyAny>,
    u: &Bound<'_, PyAny>,
    rollout_samples: usize,
    starts: usize,
) -> PyResult<(Vec<f64>, f64)> {
    let model = model.inner.clone();
    let data = Columns::new(x, u, &model.states, &model.inputs)?;
    let traj = data.trajectory()?;
    let nm = py
        .detach(|| rollout_nmae(&model, &traj, rollout_samples, starts))
        .map_err(to_py)?;
    Ok((nm.per_state, nm.mean))
}

/// Payload mass [kg] by RLS on hover thrust (thesis 4.3.2) from columns on a uniform grid
/// of `dt`; `skip` samples at the start are left out.
#[pyfunction]
#[pyo3(signature = (thrust, vd, roll=None, pitch=None, *, dt, skip=0, vehicle_mass, forgetting=1.0))]
#[allow(clippy::too_many_arguments)]
fn whitebox_payload_mass(
    thrust: &Bound<'_, PyAny>,
    vd: &Bound<'_, PyAny>,
    roll: Option<&Bound<'_, PyAny>>,
    pitch: Option<&Bound<'_, PyAny>>,
    dt: f64,
    skip: usize,
    vehicle_mass: f64,
    forgetting: f64,
) -> PyResult<f64> {
    let thrust = array1(thrust, "thrust")?;
    let vd = array1(vd, "vd")?;
    let roll = roll.map(|r| array1(r, "roll")).transpose()?;
    let pitch = pitch.map(|p| array1(p, "pitch")).transpose()?;
    let log = ThrustLog {
        thrust: thrust.as_slice()?,
        vd: vd.as_slice()?,
        roll: roll.as_ref().map(|r| r.as_slice()).transpose()?,
        pitch: pitch.as_ref().map(|p| p.as_slice()).transpose()?,
        dt,
    };
    pipeline::payload_mass_from_thrust(&log, skip, vehicle_mass, forgetting).map_err(to_py)
}

/// Dominant frequency [Hz] of `signal` in [f_min, f_max] (FFT peak, thesis 4.3.3).
#[pyfunction]
fn sysid_fft_peak(signal: &Bound<'_, PyAny>, dt: f64, f_min: f64, f_max: f64) -> PyResult<f64> {
    let s = array1(signal, "signal")?;
    whitebox::fft_peak_frequency(s.as_slice()?, dt, f_min, f_max).map_err(to_py)
}

/// Cable length [m] from the swing frequency [Hz] (eq. 4.8).
#[pyfunction]
#[pyo3(signature = (freq_hz, vehicle_mass, payload_mass, gravity=GRAVITY))]
fn sysid_cable_length(freq_hz: f64, vehicle_mass: f64, payload_mass: f64, gravity: f64) -> f64 {
    whitebox::cable_length(freq_hz, vehicle_mass, payload_mass, gravity)
}

/// The two modes of a double pendulum with the vehicle held (upper link `l1` [m], lower
/// `l2` [m], mass ratio `mu` = m₂/m₁): (ω₁, ω₂) [rad/s] and the second mode's share of the
/// upper link's static answer (`swing_core::sysid::links::modes`).
#[pyfunction]
fn sysid_link_modes(l1: f64, l2: f64, mu: f64) -> PyResult<(f64, f64, f64)> {
    for (field, v) in [("l1", l1), ("l2", l2), ("mu", mu)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(to_py(swing_core::ConfigError::new(
                field,
                format!("must be finite and > 0, not {v}"),
            )));
        }
    }
    Ok(swing_core::sysid::links::modes(l1, l2, mu))
}

/// The links with the heaviest lower mass whose modes with the vehicle held are `omega1` <
/// `omega2` [rad/s]: (l, μ), both links l [m] long and μ = m₂/m₁, or `None`
/// (`swing_core::sysid::links::heaviest_links`).
#[pyfunction]
fn sysid_heaviest_links(omega1: f64, omega2: f64) -> Option<(f64, f64)> {
    swing_core::sysid::links::heaviest_links(omega1, omega2)
}

/// RLS total-mass estimates after each sample from vertical thrust and down acceleration.
#[pyfunction]
#[pyo3(signature = (thrust_vertical, acc_down, *, gravity=GRAVITY, forgetting=1.0, initial=1.0))]
fn sysid_rls_mass<'py>(
    py: Python<'py>,
    thrust_vertical: &Bound<'py, PyAny>,
    acc_down: &Bound<'py, PyAny>,
    gravity: f64,
    forgetting: f64,
    initial: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (t, a) = (
        array1(thrust_vertical, "thrust")?,
        array1(acc_down, "acc_down")?,
    );
    let out = whitebox::rls_mass(t.as_slice()?, a.as_slice()?, gravity, forgetting, initial)
        .map_err(to_py)?;
    Ok(PyArray1::from_vec(py, out))
}

/// The attitude loop's lag [s] from one axis of a flight sampled every `dt` s: velocity,
/// swing and acceleration command (`swing_core::sysid::lag`); None when the flight does
/// not tell it.
#[pyfunction]
fn sysid_attitude_lag(
    velocity: &Bound<'_, PyAny>,
    swing: &Bound<'_, PyAny>,
    command: &Bound<'_, PyAny>,
    dt: f64,
) -> PyResult<Option<f64>> {
    let (v, th, u) = (
        array1(velocity, "velocity")?,
        array1(swing, "swing")?,
        array1(command, "command")?,
    );
    let (v, th, u) = (v.as_slice()?, th.as_slice()?, u.as_slice()?);
    if th.len() != v.len() {
        return Err(data_err(format!(
            "swing has {} samples, velocity {}",
            th.len(),
            v.len()
        )));
    }
    let x: Vec<f64> = v.iter().zip(th).flat_map(|(a, b)| [*a, *b]).collect();
    let train = Trajectory::new(&x, 2, u, 1).map_err(to_py)?;
    Ok(lag::attitude_lag(&train, 1, dt).map(|fit| fit.tau))
}

/// Which of several selections made on readings of one flight to fly, each given as its
/// `pick_kind` (None: no pick) and its swing excess on the twin over PX4's there
/// (`swing_core::design::selection::choose_reading`); None when there are none.
#[pyfunction]
fn selection_choose_reading(picks: Vec<(Option<String>, Option<f64>)>) -> PyResult<Option<usize>> {
    let picks = picks
        .into_iter()
        .map(|(kind, swing)| match kind {
            None => Ok((None, swing)),
            Some(k) => selection::Pick::from_name(&k)
                .map(|p| (Some(p), swing))
                .ok_or_else(|| {
                    let known: Vec<_> = selection::Pick::ALL.iter().map(|p| p.name()).collect();
                    to_py(swing_core::ConfigError::new(
                        "pick_kind",
                        format!("unknown pick {k:?} ({})", known.join(", ")),
                    ))
                }),
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok(selection::choose_reading(&picks))
}

/// Quadratic-regression smoothing (thesis 4.6.6, states).
#[pyfunction]
fn sysid_smooth_quadratic<'py>(
    py: Python<'py>,
    signal: &Bound<'py, PyAny>,
    window: usize,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let s = array1(signal, "signal")?;
    let out = smooth::quadratic(s.as_slice()?, window).map_err(to_py)?;
    Ok(PyArray1::from_vec(py, out))
}

/// Gaussian-weighted moving average (thesis 4.6.6, inputs).
#[pyfunction]
fn sysid_smooth_gaussian<'py>(
    py: Python<'py>,
    signal: &Bound<'py, PyAny>,
    window: usize,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let s = array1(signal, "signal")?;
    let out = smooth::gaussian(s.as_slice()?, window).map_err(to_py)?;
    Ok(PyArray1::from_vec(py, out))
}

/// Register this domain's functions and classes on the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyLinearModel>()?;
    m.add_class::<PySearch>()?;
    m.add_function(wrap_pyfunction!(check_settings, m)?)?;
    m.add_function(wrap_pyfunction!(identify, m)?)?;
    m.add_function(wrap_pyfunction!(select_for_control, m)?)?;
    m.add_function(wrap_pyfunction!(selection_choose_reading, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(whitebox_payload_mass, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_fft_peak, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_cable_length, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_link_modes, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_heaviest_links, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_rls_mass, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_attitude_lag, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_smooth_quadratic, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_smooth_gaussian, m)?)?;
    Ok(())
}
