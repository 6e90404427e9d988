//! Bindings of `swing_core::sysid`: conversion and error mapping only.
//!
//! Models cross the boundary as `swingrt-model/1` JSON text (validated by the core on the
//! way in); data as C-contiguous float64 arrays of shape (samples, columns), borrowed
//! without copies. Long calls release the GIL.

use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyList;
use swing_core::plant::{PendulumModel, GRAVITY};
use swing_core::sysid::dmdc::{self, DmdcSettings};
use swing_core::sysid::havokc::{self, HavokcSettings};
use swing_core::sysid::metrics::rollout_nmae;
use swing_core::sysid::search::{coarse_to_fine, grid_search, Grid, Method, SearchSettings};
use swing_core::sysid::whitebox;
use swing_core::sysid::{smooth, LinearModel, Offset, SysidError, Trajectory};
use swing_core::Category;

use crate::errors::{raise, to_py};

fn data_err(msg: impl Into<String>) -> PyErr {
    raise(Category::Data, msg)
}

/// Borrow a 2-D float64 C-contiguous array, or raise `DataError` naming it.
fn array2<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<PyReadonlyArray2<'py, f64>> {
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
fn array1<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<PyReadonlyArray1<'py, f64>> {
    let arr: PyReadonlyArray1<'py, f64> = obj
        .extract()
        .map_err(|_| data_err(format!("{name} must be a 1-D numpy array of float64")))?;
    if arr.as_slice().is_err() {
        return Err(data_err(format!("{name} must be contiguous")));
    }
    Ok(arr)
}

/// Columns of a 2-D array.
fn cols(a: &PyReadonlyArray2<'_, f64>) -> usize {
    a.shape()[1]
}

fn parse_offset(s: &str) -> PyResult<Offset> {
    Offset::parse(s).map_err(to_py)
}

fn named(mut m: LinearModel, states: Vec<String>, inputs: Vec<String>) -> PyResult<LinearModel> {
    if states.len() != m.n() || inputs.len() != m.m() {
        return Err(data_err(format!(
            "{} state names and {} input names for {} states and {} inputs",
            states.len(),
            inputs.len(),
            m.n(),
            m.m()
        )));
    }
    m.states = states;
    m.inputs = inputs;
    Ok(m)
}

fn model_from(text: &str) -> PyResult<LinearModel> {
    LinearModel::from_json(text).map_err(to_py)
}

/// Fit DMDc (eq. 4.9–4.15) to states `x` (N, n) and inputs `u` (N, m); returns model JSON.
#[pyfunction]
#[pyo3(signature = (x, u, states, inputs, *, delays, rank=None, offset="affine", dt=0.03, method="dmdc"))]
#[allow(clippy::too_many_arguments)]
fn sysid_fit(
    py: Python<'_>,
    x: &Bound<'_, PyAny>,
    u: &Bound<'_, PyAny>,
    states: Vec<String>,
    inputs: Vec<String>,
    delays: usize,
    rank: Option<usize>,
    offset: &str,
    dt: f64,
    method: &str,
) -> PyResult<String> {
    let (xa, ua) = (array2(x, "x")?, array2(u, "u")?);
    let offset = parse_offset(offset)?;
    let (n, m) = (cols(&xa), cols(&ua));
    let (xs, us) = (xa.as_slice()?, ua.as_slice()?);
    let method = method.to_string();
    let model = py
        .detach(|| {
            let traj = Trajectory::new(xs, n, us, m)?;
            match method.as_str() {
                "dmdc" => dmdc::fit(
                    &traj,
                    &DmdcSettings {
                        delays,
                        rank,
                        offset,
                        dt,
                    },
                ),
                "havokc" => havokc::fit(
                    &traj,
                    &HavokcSettings {
                        delays,
                        rank,
                        offset,
                        dt,
                    },
                ),
                other => Err(SysidError::Config(format!(
                    "method must be dmdc or havokc, not {other:?}"
                ))),
            }
        })
        .map_err(to_py)?;
    named(model, states, inputs)?.to_json().map_err(to_py)
}

/// Grid or coarse→fine search; returns (model JSON, table rows, index of the best row).
///
/// Table rows are (q, p, nmae, per_state list, stable or None, spectral radius or None).
#[pyfunction]
#[pyo3(signature = (x_train, u_train, x_test, u_test, states, inputs, *, method="dmdc",
    offset="affine", dt=0.03, horizon=667, starts=10, delays=None, rank_start=5, rank_step=5,
    rank_extra=0, fine=None, stability_tolerance=1e-3))]
#[allow(clippy::too_many_arguments)]
fn sysid_search<'py>(
    py: Python<'py>,
    x_train: &Bound<'py, PyAny>,
    u_train: &Bound<'py, PyAny>,
    x_test: &Bound<'py, PyAny>,
    u_test: &Bound<'py, PyAny>,
    states: Vec<String>,
    inputs: Vec<String>,
    method: &str,
    offset: &str,
    dt: f64,
    horizon: usize,
    starts: usize,
    delays: Option<Vec<usize>>,
    rank_start: usize,
    rank_step: usize,
    rank_extra: usize,
    fine: Option<(usize, usize)>,
    stability_tolerance: f64,
) -> PyResult<(String, Bound<'py, PyList>, usize)> {
    let (xa, ua) = (array2(x_train, "x_train")?, array2(u_train, "u_train")?);
    let (xb, ub) = (array2(x_test, "x_test")?, array2(u_test, "u_test")?);
    let method = match method {
        "dmdc" => Method::Dmdc,
        "havokc" => Method::Havokc,
        other => {
            return Err(raise(
                Category::Config,
                format!("search method must be dmdc or havokc, not {other:?}"),
            ))
        }
    };
    let settings = SearchSettings {
        method,
        offset: parse_offset(offset)?,
        dt,
        horizon,
        starts,
        stability_tolerance,
    };
    let grid = Grid {
        delays: delays.unwrap_or_else(|| Grid::reference().delays),
        rank_start,
        rank_step,
        rank_extra,
        rank_window: None,
    };
    let (n, m) = (cols(&xa), cols(&ua));
    let (n2, m2) = (cols(&xb), cols(&ub));
    let (s1, s2, s3, s4) = (
        xa.as_slice()?,
        ua.as_slice()?,
        xb.as_slice()?,
        ub.as_slice()?,
    );
    let res = py
        .detach(|| {
            let train = Trajectory::new(s1, n, s2, m)?;
            let test = Trajectory::new(s3, n2, s4, m2)?;
            match fine {
                Some((qr, pr)) => coarse_to_fine(&train, &test, &grid, qr, pr, &settings),
                None => grid_search(&train, &test, &grid, &settings),
            }
        })
        .map_err(to_py)?;
    let rows = PyList::empty(py);
    for c in &res.table {
        rows.append((
            c.delays,
            c.rank,
            c.nmae,
            c.per_state.clone(),
            c.stable,
            c.spectral_radius,
        ))?;
    }
    let json = named(res.model, states, inputs)?.to_json().map_err(to_py)?;
    Ok((json, rows, res.best))
}

/// Held-out rollout NMAE of a model on (x, u): returns (per-state list, mean).
#[pyfunction]
#[pyo3(signature = (model_json, x, u, *, horizon, starts=10))]
fn sysid_evaluate(
    py: Python<'_>,
    model_json: &str,
    x: &Bound<'_, PyAny>,
    u: &Bound<'_, PyAny>,
    horizon: usize,
    starts: usize,
) -> PyResult<(Vec<f64>, f64)> {
    let model = model_from(model_json)?;
    let (xa, ua) = (array2(x, "x")?, array2(u, "u")?);
    let (n, m) = (cols(&xa), cols(&ua));
    let (xs, us) = (xa.as_slice()?, ua.as_slice()?);
    let nm = py
        .detach(|| {
            let traj = Trajectory::new(xs, n, us, m)?;
            rollout_nmae(&model, &traj, horizon, starts)
        })
        .map_err(to_py)?;
    Ok((nm.per_state, nm.mean))
}

/// Predict H state rows from `history` (q, n) and future `inputs` (H, m); returns (H·n,).
#[pyfunction]
fn sysid_predict<'py>(
    py: Python<'py>,
    model_json: &str,
    history: &Bound<'py, PyAny>,
    inputs: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let model = model_from(model_json)?;
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
    Ok(PyArray1::from_vec(py, out))
}

/// Validate model JSON; returns it normalised, with the spectral radius in diagnostics.
#[pyfunction]
fn sysid_check_model(model_json: &str) -> PyResult<(String, f64)> {
    let mut model = model_from(model_json)?;
    let rho = model.spectral_radius().map_err(to_py)?;
    model.diagnostics.spectral_radius = Some(rho);
    Ok((model.to_json().map_err(to_py)?, rho))
}

/// White-box model (eq. 5.7, stable sign, ZOH, exact q = 2 delay form) for `axes` axes.
#[pyfunction]
#[pyo3(signature = (states, inputs, *, payload_mass, length, vehicle_mass=0.952, friction=0.0,
    gravity=GRAVITY, dt=0.03, frequency_hz=None, x=None, u=None, offset="none"))]
#[allow(clippy::too_many_arguments)]
fn sysid_whitebox(
    states: Vec<String>,
    inputs: Vec<String>,
    payload_mass: f64,
    length: f64,
    vehicle_mass: f64,
    friction: f64,
    gravity: f64,
    dt: f64,
    frequency_hz: Option<f64>,
    x: Option<&Bound<'_, PyAny>>,
    u: Option<&Bound<'_, PyAny>>,
    offset: &str,
) -> PyResult<String> {
    if gravity != GRAVITY {
        return Err(raise(
            Category::Config,
            format!(
                "gravity: the white-box model uses the plant's g = {GRAVITY} m/s² (got {gravity})"
            ),
        ));
    }
    let params = PendulumModel {
        m_q: vehicle_mass,
        m_p: payload_mass,
        l: length,
        c: friction,
    };
    let axes = inputs.len();
    let model = whitebox::model(&params, axes, dt, frequency_hz).map_err(to_py)?;
    let mut model = named(model, states, inputs)?;
    let offset = parse_offset(offset)?;
    if let (Some(x), Some(u)) = (x, u) {
        let (xa, ua) = (array2(x, "x")?, array2(u, "u")?);
        let traj =
            Trajectory::new(xa.as_slice()?, cols(&xa), ua.as_slice()?, cols(&ua)).map_err(to_py)?;
        whitebox::apply_offset(&mut model, &traj, offset).map_err(to_py)?;
    } else if offset != Offset::None {
        return Err(raise(
            Category::Config,
            "offset mean/affine needs training data x, u",
        ));
    }
    model.to_json().map_err(to_py)
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
    m.add_function(wrap_pyfunction!(sysid_fit, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_search, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_predict, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_check_model, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_whitebox, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_fft_peak, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_cable_length, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_rls_mass, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_smooth_quadratic, m)?)?;
    m.add_function(wrap_pyfunction!(sysid_smooth_gaussian, m)?)?;
    Ok(())
}
