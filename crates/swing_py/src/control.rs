//! Bindings of `swing_core::control`: the MPC and LQR controllers, the Riccati solvers and
//! the MPC tick timing used by `swingrt bench`.
//!
//! Models cross as `LinearModel` objects; settings dicts are read by the core's serde
//! structs, so unknown keys and bad values raise `swingrt.errors.ConfigError` naming the
//! field.

use nalgebra::DMatrix;
use numpy::{
    PyArray1, PyArrayMethods, PyReadonlyArray2, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use swing_bench::tick_timing;
use swing_core::control::lqr::{LqrController, LqrSettings};
use swing_core::control::mpc::{MpcController, MpcSettings};
use swing_core::control::{AxisState, ControlError, SwingController, TickInfo, TickKind};
use swing_core::design::check::{self, StepCheckSettings};
use swing_core::design::{AdaptiveMpc, AdaptiveSettings};
use swing_core::linalg::{riccati, LinalgError};
use swing_core::plant::PendulumModel;
use swing_core::testing::pendulum_delay_model;

use crate::convert;
use crate::errors::to_py;
use crate::sim::{twin_prior, PyScenario};
use crate::sysid::PyLinearModel;

/// Read a state array of shape (axes, 3) — or (3,) for one axis — of [v, swing, swing_rate].
pub(crate) fn read_state(
    arr: &PyReadonlyArrayDyn<'_, f64>,
    axes: usize,
) -> PyResult<Vec<AxisState>> {
    let shape = arr.shape().to_vec();
    let ok = (shape == [axes, 3]) || (axes == 1 && shape == [3]);
    if !ok {
        return Err(to_py(ControlError::Input(format!(
            "state must have shape ({axes}, 3) [v, swing, swing_rate], got {shape:?}"
        ))));
    }
    let view = arr.as_array();
    let flat: Vec<f64> = view.iter().copied().collect();
    Ok((0..axes)
        .map(|a| AxisState {
            v: flat[3 * a],
            swing: flat[3 * a + 1],
            swing_rate: flat[3 * a + 2],
        })
        .collect())
}

/// A float or a sequence of floats of length `axes`.
pub(crate) fn read_vec(obj: &Bound<'_, PyAny>, axes: usize, what: &str) -> PyResult<Vec<f64>> {
    let v: Vec<f64> = match obj.extract::<f64>() {
        Ok(x) => vec![x],
        Err(_) => obj.extract::<Vec<f64>>()?,
    };
    if v.len() != axes {
        return Err(to_py(ControlError::Input(format!(
            "{what} needs {axes} value(s), got {}",
            v.len()
        ))));
    }
    Ok(v)
}

pub(crate) fn tick_dict<'py>(py: Python<'py>, info: TickInfo) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let kind = match info.kind {
        TickKind::Unconstrained => "unconstrained",
        TickKind::Constrained => "constrained",
    };
    d.set_item("kind", kind)?;
    d.set_item("iterations", info.iterations)?;
    Ok(d)
}

pub(crate) fn step_any(
    ctrl: &mut dyn SwingController,
    state: &PyReadonlyArrayDyn<'_, f64>,
    vel_ref: &Bound<'_, PyAny>,
) -> PyResult<(Vec<f64>, TickInfo)> {
    let axes = ctrl.axes();
    let st = read_state(state, axes)?;
    let r = read_vec(vel_ref, axes, "vel_ref")?;
    let mut out = vec![0.0; axes];
    let info = ctrl.step(&st, &r, &mut out).map_err(to_py)?;
    Ok((out, info))
}

pub(crate) fn reset_any(
    ctrl: &mut dyn SwingController,
    state: &PyReadonlyArrayDyn<'_, f64>,
    acc: Option<&Bound<'_, PyAny>>,
) -> PyResult<()> {
    let axes = ctrl.axes();
    let st = read_state(state, axes)?;
    let a = match acc {
        Some(obj) => read_vec(obj, axes, "acc")?,
        None => vec![0.0; axes],
    };
    ctrl.reset(&st, &a);
    Ok(())
}

/// The data-driven MPC on an identified model (JSON text) with optional settings dict.
#[pyclass(name = "Mpc", module = "swingrt._core", unsendable)]
pub struct PyMpc {
    inner: MpcController,
    last: TickInfo,
}

#[pymethods]
impl PyMpc {
    /// Design the MPC on `model` with `settings` (a dict of `MpcSettings` fields).
    #[new]
    #[pyo3(signature = (model, settings=None))]
    fn new(
        py: Python<'_>,
        model: &PyLinearModel,
        settings: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let model = model.inner.clone();
        let s: MpcSettings = convert::settings(settings, "settings")?;
        let inner = py.detach(|| MpcController::new(&model, s)).map_err(to_py)?;
        Ok(Self {
            inner,
            last: TickInfo::default(),
        })
    }

    /// One tick: state (axes × [v, swing, swing_rate]) and velocity reference in,
    /// acceleration setpoint per axis [m/s²] out.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        state: PyReadonlyArrayDyn<'py, f64>,
        vel_ref: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (out, info) = step_any(&mut self.inner, &state, vel_ref)?;
        self.last = info;
        Ok(PyArray1::from_vec(py, out))
    }

    /// Restart from a measured state and acceleration setpoint (bumpless transfer).
    #[pyo3(signature = (state, acc=None))]
    fn reset(
        &mut self,
        state: PyReadonlyArrayDyn<'_, f64>,
        acc: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        reset_any(&mut self.inner, &state, acc)
    }

    /// Predicted outputs of the last tick: array (Np, axes, 3) of [v, swing_rate, swing].
    fn predicted<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let axes = self.inner.axes();
        let np = self.inner.settings().horizon;
        let v = self.inner.predicted_trajectory().to_vec();
        Ok(PyArray1::from_vec(py, v).reshape([np, axes, 3])?.into_any())
    }

    /// The optimal input sequence of the last tick, array (Nc, axes) [m/s²].
    fn predicted_inputs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let axes = self.inner.axes();
        let nc = self.inner.settings().control_horizon;
        let v = self.inner.predicted_inputs().to_vec();
        Ok(PyArray1::from_vec(py, v).reshape([nc, axes])?.into_any())
    }

    /// Estimated disturbances after the last tick (layout of the `disturbance` setting).
    fn disturbance<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.disturbance().to_vec())
    }

    /// What the last tick did: {"kind": "unconstrained"|"constrained", "iterations": n}.
    fn last_tick<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
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

    /// The settings in use, as a dict.
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        convert::to_py_object(py, self.inner.settings())
    }
}

/// The adaptive MPC (`design::adaptive`) on an identified model: the online DMDc follows
/// the payload and a checked re-synthesis is swapped in between ticks. For flight the
/// synthesis runs on a worker thread unless `adaptive` says `synthesis = "deferred"`.
#[pyclass(name = "AdaptiveMpc", module = "swingrt._core", unsendable)]
pub struct PyAdaptiveMpc {
    inner: AdaptiveMpc,
}

#[pymethods]
impl PyAdaptiveMpc {
    /// Design the first MPC on `model` with MPC `settings` and `adaptive` settings; `twin`
    /// (the vehicle's training-flight scenario) with `twin_payload` = (payload mass [kg],
    /// cable length [m], vehicle mass [kg]) the model was identified for enables the twin
    /// path (`adaptive.twin.enabled`): re-identification on the twin for the cable length
    /// measured in flight.
    #[new]
    #[pyo3(signature = (model, settings=None, adaptive=None, twin=None, twin_payload=None))]
    fn new(
        py: Python<'_>,
        model: &PyLinearModel,
        settings: Option<&Bound<'_, PyAny>>,
        adaptive: Option<&Bound<'_, PyAny>>,
        twin: Option<&PyScenario>,
        twin_payload: Option<(f64, f64, f64)>,
    ) -> PyResult<Self> {
        let model = model.inner.clone();
        let s: MpcSettings = convert::settings(settings, "settings")?;
        let a: AdaptiveSettings = convert::settings(adaptive, "adaptive")?;
        let prior = twin_prior(&a, twin, twin_payload)?;
        let inner = py
            .detach(|| AdaptiveMpc::with_twin(&model, s, a, prior))
            .map_err(to_py)?;
        Ok(Self { inner })
    }

    /// One tick: state (axes × [v, swing, swing_rate]) and velocity reference in,
    /// acceleration setpoint per axis [m/s²] out; runs deferred synthesis work after it.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        state: PyReadonlyArrayDyn<'py, f64>,
        vel_ref: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (out, _) = step_any(&mut self.inner, &state, vel_ref)?;
        self.inner.between_ticks();
        Ok(PyArray1::from_vec(py, out))
    }

    /// Restart from a measured state and acceleration setpoint (bumpless transfer).
    #[pyo3(signature = (state, acc=None))]
    fn reset(
        &mut self,
        state: PyReadonlyArrayDyn<'_, f64>,
        acc: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        reset_any(&mut self.inner, &state, acc)
    }

    /// Events so far as (tick, what, value): `detected`, `requested`, `adopted`, `rejected`.
    fn events(&self) -> Vec<(u64, String, f64)> {
        self.inner
            .events()
            .into_iter()
            .map(|e| (e.tick, e.what.to_string(), e.value))
            .collect()
    }

    /// Models adopted since the start.
    #[getter]
    fn swaps(&self) -> usize {
        self.inner.swaps()
    }

    /// Why the last re-synthesis was rejected ("" when none was).
    #[getter]
    fn last_rejection(&self) -> String {
        self.inner.last_rejection().to_string()
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

/// The baseline LQR (thesis 5.3) for the given payload parameters.
#[pyclass(name = "Lqr", module = "swingrt._core", unsendable)]
pub struct PyLqr {
    inner: LqrController,
}

#[pymethods]
impl PyLqr {
    /// Design the LQR for the white-box `params` (a dict of `m_q`, `m_p`, `l`, `c`) on
    /// `axes` axes with `settings` (a dict of `LqrSettings` fields).
    #[new]
    #[pyo3(signature = (params, axes=1, settings=None))]
    fn new(
        params: &Bound<'_, PyAny>,
        axes: usize,
        settings: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let s: LqrSettings = convert::settings(settings, "settings")?;
        let p: PendulumModel = convert::from_py(params, "params")?;
        Ok(Self {
            inner: LqrController::new(p, axes, s).map_err(to_py)?,
        })
    }

    /// One tick: state (axes × [v, swing, swing_rate]) and velocity reference in,
    /// acceleration setpoint per axis [m/s²] out.
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        state: PyReadonlyArrayDyn<'py, f64>,
        vel_ref: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (out, _) = step_any(&mut self.inner, &state, vel_ref)?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// Restart from a measured state and acceleration setpoint (bumpless transfer).
    #[pyo3(signature = (state, acc=None))]
    fn reset(
        &mut self,
        state: PyReadonlyArrayDyn<'_, f64>,
        acc: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        reset_any(&mut self.inner, &state, acc)
    }

    /// Gain K on [∫(v_sp − v), v, θ, θ̇] (u = K(x_sp − x) with the sign convention u = −Kx).
    fn gain<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.inner.gain().to_vec())
    }

    /// Tick period [s].
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

fn to_dmatrix(name: &str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<DMatrix<f64>> {
    let shape = a.shape();
    let view = a.as_array();
    let m = DMatrix::from_fn(shape[0], shape[1], |i, j| view[[i, j]]);
    if m.iter().any(|x| !x.is_finite()) {
        return Err(to_py(ControlError::Input(format!(
            "{name} has a non-finite entry"
        ))));
    }
    Ok(m)
}

fn to_numpy<'py>(py: Python<'py>, m: &DMatrix<f64>) -> PyResult<Bound<'py, PyAny>> {
    let (r, c) = m.shape();
    let mut v = Vec::with_capacity(r * c);
    for i in 0..r {
        for j in 0..c {
            v.push(m[(i, j)]);
        }
    }
    Ok(PyArray1::from_vec(py, v).reshape([r, c])?.into_any())
}

type Riccati = fn(
    &DMatrix<f64>,
    &DMatrix<f64>,
    &DMatrix<f64>,
    &DMatrix<f64>,
) -> Result<riccati::RiccatiSolution, LinalgError>;

fn riccati<'py>(
    py: Python<'py>,
    solve: Riccati,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    r: PyReadonlyArray2<'py, f64>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let (a, b, q, r) = (
        to_dmatrix("A", &a)?,
        to_dmatrix("B", &b)?,
        to_dmatrix("Q", &q)?,
        to_dmatrix("R", &r)?,
    );
    let sol = py.detach(|| solve(&a, &b, &q, &r)).map_err(to_py)?;
    Ok((to_numpy(py, &sol.k)?, to_numpy(py, &sol.p)?))
}

/// Continuous algebraic Riccati equation: returns (K, P) with u = −Kx.
#[pyfunction]
fn care<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    r: PyReadonlyArray2<'py, f64>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    riccati(py, riccati::care, a, b, q, r)
}

/// Discrete algebraic Riccati equation: returns (K, P) with u = −Kx.
#[pyfunction]
fn dare<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    r: PyReadonlyArray2<'py, f64>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    riccati(py, riccati::dare, a, b, q, r)
}

/// Time `n_ticks` MPC ticks in Rust (closed loop on the model itself; constrained: only
/// ticks that solved the QP): {"median", "p99", "max", "mean" [µs], "ticks"}.
#[pyfunction]
#[pyo3(signature = (model, settings=None, n_ticks=2000, constrained=false))]
fn mpc_tick_timing<'py>(
    py: Python<'py>,
    model: &PyLinearModel,
    settings: Option<&Bound<'py, PyAny>>,
    n_ticks: usize,
    constrained: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let model = model.inner.clone();
    let s: MpcSettings = convert::settings(settings, "settings")?;
    let t = py
        .detach(|| tick_timing(&model, &s, n_ticks, constrained))
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("median", t.median_us)?;
    d.set_item("p99", t.p99_us)?;
    d.set_item("max", t.max_us)?;
    d.set_item("mean", t.mean_us)?;
    d.set_item("ticks", t.ticks)?;
    Ok(d)
}

/// Timing of the adaptive MPC (`swing_bench::adaptive_timing`): the tick with the
/// online update over `n_ticks` ticks [µs] and the re-synthesis `repeats` times [ms].
#[pyfunction]
#[pyo3(signature = (model, settings=None, adaptive=None, n_ticks=2000, repeats=5))]
fn adaptive_timing<'py>(
    py: Python<'py>,
    model: &PyLinearModel,
    settings: Option<&Bound<'py, PyAny>>,
    adaptive: Option<&Bound<'py, PyAny>>,
    n_ticks: usize,
    repeats: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let model = model.inner.clone();
    let s: MpcSettings = convert::settings(settings, "settings")?;
    let a: swing_core::design::AdaptiveSettings = convert::settings(adaptive, "adaptive")?;
    let (tick, build) = py
        .detach(|| swing_bench::adaptive_timing(&model, &s, &a, n_ticks, repeats))
        .map_err(to_py)?;
    let d = PyDict::new(py);
    for (key, t) in [("tick_us", tick), ("resynthesis_ms", build)] {
        let e = PyDict::new(py);
        e.set_item("median", t.median_us)?;
        e.set_item("p99", t.p99_us)?;
        e.set_item("max", t.max_us)?;
        e.set_item("mean", t.mean_us)?;
        e.set_item("count", t.ticks)?;
        d.set_item(key, e)?;
    }
    Ok(d)
}

/// The white-box pendulum fitted in `delays` delay coordinates (seeded): a realistic
/// stand-in for an identified model in benchmarks and tests.
#[pyfunction]
#[pyo3(signature = (m_q=0.952, m_p=0.2, l=1.0, c=0.002, dt=0.03, delays=50, axes=1, seed=7))]
#[allow(clippy::too_many_arguments)]
fn pendulum_model(
    py: Python<'_>,
    m_q: f64,
    m_p: f64,
    l: f64,
    c: f64,
    dt: f64,
    delays: usize,
    axes: usize,
    seed: u64,
) -> PyResult<PyLinearModel> {
    let p = PendulumModel { m_q, m_p, l, c };
    let m = pendulum_delay_model(&p, dt, delays, axes, seed).map_err(to_py)?;
    PyLinearModel::wrap(py, m)
}

/// How far white measurement noise moves the `span`-second mean velocity of the MPC on
/// `model` (unconstrained, `settings`) flying the linear `plant` behind a first-order lag of
/// `input_lag` s: the stationary standard deviation of that mean [m/s], the largest over the
/// axes, `inf` for an unstable loop (`swing_core::design::check::velocity_wander`).
#[pyfunction]
#[pyo3(signature = (model, plant, settings=None, input_lag=0.0, swing_noise=0.0, velocity_noise=0.0, span=2.0))]
#[allow(clippy::too_many_arguments)]
fn velocity_wander(
    py: Python<'_>,
    model: &PyLinearModel,
    plant: &PyLinearModel,
    settings: Option<&Bound<'_, PyAny>>,
    input_lag: f64,
    swing_noise: f64,
    velocity_noise: f64,
    span: f64,
) -> PyResult<f64> {
    let model = model.inner.clone();
    let plant = plant.inner.clone();
    let settings: MpcSettings = convert::settings(settings, "settings")?;
    let noise = check::MeasurementNoise {
        velocity: velocity_noise,
        swing: swing_noise,
        swing_rate: 0.0,
    };
    py.detach(|| {
        let mpc = MpcController::new(&model, settings)?;
        check::velocity_wander(&mpc, &model, &plant, input_lag, noise, span)
    })
    .map_err(to_py)
}

/// Closed-loop step checks of the MPC on `model_json` flying each linear plant of
/// `plant_jsons` behind each of `input_lags` after a dead time of `input_delay` [s] (see `swing_core::design::check`; the MPC is
/// designed once): a list, plant-major, of dicts of `overshoot`, `final_error`,
/// `hold_drift` as fractions of the step.
#[pyfunction]
#[pyo3(signature = (model, plants, settings=None, step=2.0, t_step=2.0, duration=20.0, input_lags=vec![0.0], input_delay=0.0))]
#[allow(clippy::too_many_arguments)]
fn mpc_step_check<'py>(
    py: Python<'py>,
    model: &PyLinearModel,
    plants: Vec<PyRef<'py, PyLinearModel>>,
    settings: Option<&Bound<'py, PyAny>>,
    step: f64,
    t_step: f64,
    duration: f64,
    input_lags: Vec<f64>,
    input_delay: f64,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let model = model.inner.clone();
    let plants: Vec<_> = plants.iter().map(|p| p.inner.clone()).collect();
    let settings: MpcSettings = convert::settings(settings, "settings")?;
    let results = py
        .detach(|| {
            let mut mpc = MpcController::new(&model, settings)?;
            let mut out = Vec::with_capacity(plants.len() * input_lags.len());
            for plant in &plants {
                for &input_lag in &input_lags {
                    let check = StepCheckSettings {
                        step,
                        t_step,
                        duration,
                        input_lag,
                        input_delay,
                    };
                    out.push(check::step_check_with(&mut mpc, &model, plant, &check)?);
                }
            }
            Ok::<_, ControlError>(out)
        })
        .map_err(to_py)?;
    results
        .into_iter()
        .map(|r| {
            let d = PyDict::new(py);
            d.set_item("overshoot", r.overshoot)?;
            d.set_item("final_error", r.final_error)?;
            d.set_item("hold_drift", r.hold_drift)?;
            Ok(d)
        })
        .collect()
}

/// Largest excursion of the velocities `v` beyond the new setpoint `v_after` of a step from
/// `v_before`, as a fraction of the step (the one overshoot definition; −∞ for no samples).
#[pyfunction]
fn step_overshoot(v: &Bound<'_, PyAny>, v_before: f64, v_after: f64) -> PyResult<f64> {
    let v = convert::array1(v, "v")?;
    Ok(check::overshoot(v.as_slice()?, v_before, v_after))
}

/// The swing IAE after a step and its momentum floor [deg·s], as `(iae, floor)`: the one
/// definition of the flight metrics and the twin (`swing_core::design::check::swing_iae`);
/// `t` [s] from the step on, `swing` [rad] the swing (its magnitude for two axes), `along`
/// [rad] the swing along the step.
#[pyfunction]
fn swing_iae(
    t: &Bound<'_, PyAny>,
    swing: &Bound<'_, PyAny>,
    along: &Bound<'_, PyAny>,
) -> PyResult<(f64, f64)> {
    let t = convert::array1(t, "t")?;
    let swing = convert::array1(swing, "swing")?;
    let along = convert::array1(along, "along")?;
    let r = check::swing_iae(t.as_slice()?, swing.as_slice()?, along.as_slice()?);
    Ok((r.iae, r.floor))
}

/// Register this domain's functions and classes on the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyMpc>()?;
    m.add_class::<PyLqr>()?;
    m.add_function(wrap_pyfunction!(care, m)?)?;
    m.add_function(wrap_pyfunction!(dare, m)?)?;
    m.add_function(wrap_pyfunction!(mpc_tick_timing, m)?)?;
    m.add_function(wrap_pyfunction!(adaptive_timing, m)?)?;
    m.add_class::<PyAdaptiveMpc>()?;
    m.add_function(wrap_pyfunction!(pendulum_model, m)?)?;
    m.add_function(wrap_pyfunction!(mpc_step_check, m)?)?;
    m.add_function(wrap_pyfunction!(velocity_wander, m)?)?;
    m.add_function(wrap_pyfunction!(step_overshoot, m)?)?;
    m.add_function(wrap_pyfunction!(swing_iae, m)?)?;
    m.add("FINAL_SPAN", check::FINAL_SPAN)?;
    Ok(())
}
