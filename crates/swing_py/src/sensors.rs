//! Bindings of `swing_core::sensors`: the swing estimated from the vehicle's own IMU, one
//! sample at a time (the offboard node) or over a whole log (a PX4 ULog), and the swing of a
//! cable sensor on the airframe read from its ADC counts; the estimate's scale fitted to a
//! flight.

use nalgebra::{Matrix3, Quaternion};
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use swing_core::plant::dynamics::rotation;
use swing_core::sensors::{BodySensorParams, ImuSwingEstimator, ImuSwingSettings};
use swing_core::sysid::swing_scale::{self, DragRemoval, ScaleAxis, ScaleSettings};
use swing_core::ConfigError;

use crate::convert::{self, data_err};
use crate::errors::to_py;

/// The rotation body → NED of a quaternion (w, x, y, z), or a `DataError` naming `what()`
/// when it is not finite or far from unit length (the name is built only then).
fn attitude(q: [f64; 4], what: impl Fn() -> String) -> PyResult<Matrix3<f64>> {
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    if !(n.is_finite() && (n - 1.0).abs() < 0.1) {
        return Err(data_err(format!(
            "{}: the attitude quaternion {q:?} is not a unit quaternion",
            what()
        )));
    }
    Ok(rotation(&Quaternion::new(
        q[0] / n,
        q[1] / n,
        q[2] / n,
        q[3] / n,
    )))
}

/// Every array `(name, array, width)` must be `rows`×`width`; the error names the first that
/// is not.
fn same_rows(rows: usize, arrays: &[(&str, &PyReadonlyArray2<f64>, usize)]) -> PyResult<()> {
    for (name, a, width) in arrays {
        if a.shape() != [rows, *width] {
            return Err(data_err(format!(
                "{name} must be {rows}×{width} (got {:?})",
                a.shape()
            )));
        }
    }
    Ok(())
}

fn finite3(x: [f64; 3], name: &str, what: &str) -> PyResult<()> {
    if x.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(data_err(format!("{what}: {name} {x:?} is not finite")))
    }
}

/// The swing estimated from the IMU (`swing_core::sensors::ImuSwingEstimator`): fed one
/// sample every 1/`rate` s, it returns the filtered world-frame swing (N, E) [rad]; the
/// first `tare` seconds measure the accelerometer's offset with the payload hanging still.
#[pyclass(name = "ImuSwingEstimator", module = "swingrt._core", unsendable)]
pub struct PyImuSwingEstimator {
    inner: ImuSwingEstimator,
}

#[pymethods]
impl PyImuSwingEstimator {
    /// An estimator with `settings` (a dict of `ImuSwingSettings`' fields; None: defaults).
    #[new]
    #[pyo3(signature = (settings=None))]
    fn new(settings: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let s: ImuSwingSettings = convert::settings(settings, "estimator")?;
        let inner = ImuSwingEstimator::new(s).map_err(|e| to_py(e.within("estimator")))?;
        Ok(Self { inner })
    }

    /// Feed one sample: body FRD specific force [m/s²], attitude quaternion (w, x, y, z,
    /// body → NED) and NED velocity [m/s]; returns the filtered estimate (N, E) [rad].
    fn update(&mut self, accel: [f64; 3], q: [f64; 4], vel: [f64; 3]) -> PyResult<(f64, f64)> {
        finite3(accel, "accel", "IMU sample")?;
        finite3(vel, "velocity", "IMU sample")?;
        let rot = attitude(q, || "IMU sample".into())?;
        let [n, e] = self.inner.update(accel, &rot, vel);
        Ok((n, e))
    }

    /// The latest estimate (N, E) [rad].
    #[getter]
    fn estimate(&self) -> (f64, f64) {
        let [n, e] = self.inner.estimate();
        (n, e)
    }

    /// The latest estimate's rate (N, E) [rad/s].
    #[getter]
    fn rate_estimate(&self) -> (f64, f64) {
        let [n, e] = self.inner.rate_estimate();
        (n, e)
    }

    /// Whether the tare is over (a controller on the estimate engages only then).
    #[getter]
    fn tared(&self) -> bool {
        self.inner.tared()
    }

    /// The accelerometer offset in use, body x then y [m/s²].
    #[getter]
    fn offset(&self) -> (f64, f64) {
        let [x, y] = self.inner.offset();
        (x, y)
    }

    /// The settings, as a dict.
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        convert::to_py_object(py, self.inner.settings())
    }

    /// Start over (a new flight): filters, tare and offset.
    fn reset(&mut self) {
        self.inner.reset();
    }
}

/// The swing estimated from a whole log's IMU: `accel` (N×3, body FRD specific force
/// [m/s²]), `q` (N×4 attitude quaternions w, x, y, z, body → NED) and `vel` (N×3, NED
/// [m/s]), sampled every 1/`rate` s of `settings`, fed in order to a fresh estimator;
/// returns the filtered estimate (N×2: N, E) [rad], the tare's samples included.
#[pyfunction]
#[pyo3(signature = (accel, q, vel, settings=None))]
fn estimate_swing<'py>(
    py: Python<'py>,
    accel: &Bound<'py, PyAny>,
    q: &Bound<'py, PyAny>,
    vel: &Bound<'py, PyAny>,
    settings: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let s: ImuSwingSettings = convert::settings(settings, "estimator")?;
    let mut est = ImuSwingEstimator::new(s).map_err(|e| to_py(e.within("estimator")))?;
    let accel = convert::array2(accel, "accel")?;
    let q = convert::array2(q, "q")?;
    let vel = convert::array2(vel, "vel")?;
    let rows = accel.shape()[0];
    same_rows(
        rows,
        &[("accel", &accel, 3), ("q", &q, 4), ("vel", &vel, 3)],
    )?;
    let (a, qs, v) = (accel.as_slice()?, q.as_slice()?, vel.as_slice()?);
    let mut out = numpy::ndarray::Array2::<f64>::zeros((rows, 2));
    for k in 0..rows {
        let ak = [a[3 * k], a[3 * k + 1], a[3 * k + 2]];
        let vk = [v[3 * k], v[3 * k + 1], v[3 * k + 2]];
        let qk = [qs[4 * k], qs[4 * k + 1], qs[4 * k + 2], qs[4 * k + 3]];
        let what = || format!("sample {k}");
        if !(ak.iter().chain(&vk).all(|x| x.is_finite())) {
            finite3(ak, "accel", &what())?;
            finite3(vk, "velocity", &what())?;
        }
        let rot = attitude(qk, what)?;
        let [n, e] = est.update(ak, &rot, vk);
        out[[k, 0]] = n;
        out[[k, 1]] = e;
    }
    Ok(out.into_pyarray(py))
}

/// The world-frame swing (N×2: N, E) [rad] of a cable sensor on the airframe: its ADC
/// `counts` (N×2, the body x and y potentiometers) through the calibration of `sensor` (a
/// dict of `BodySensorParams`' fields, a scenario's `[sensors.body]`; None: defaults),
/// composed with the attitude `q` (N×4, w, x, y, z, body → NED), as the simulator does.
#[pyfunction]
#[pyo3(signature = (counts, q, sensor=None))]
fn body_swing<'py>(
    py: Python<'py>,
    counts: &Bound<'py, PyAny>,
    q: &Bound<'py, PyAny>,
    sensor: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let p: BodySensorParams = convert::settings(sensor, "body")?;
    p.validate().map_err(|e| to_py(e.within("body")))?;
    let counts = convert::array2(counts, "counts")?;
    let q = convert::array2(q, "q")?;
    let rows = counts.shape()[0];
    same_rows(rows, &[("counts", &counts, 2), ("q", &q, 4)])?;
    let (c, qs) = (counts.as_slice()?, q.as_slice()?);
    let mut out = numpy::ndarray::Array2::<f64>::zeros((rows, 2));
    for k in 0..rows {
        let what = || format!("sample {k}");
        let ck = [c[2 * k], c[2 * k + 1]];
        if !ck.iter().all(|x| x.is_finite()) {
            return Err(data_err(format!(
                "{}: ADC counts {ck:?} are not finite",
                what()
            )));
        }
        let rot = attitude(
            [qs[4 * k], qs[4 * k + 1], qs[4 * k + 2], qs[4 * k + 3]],
            what,
        )?;
        let [n, e] = p.world_swing(&rot, ck);
        out[[k, 0]] = n;
        out[[k, 1]] = e;
    }
    Ok(out.into_pyarray(py))
}

/// The IMU swing estimate's scale and drag fitted to how it answers the vehicle's motion
/// (`swing_core::sysid::swing_scale`): `vel` (N×2, N and E [m/s]), `estimate` (N×2, the
/// estimator's swing [rad]) and `euler` (N×3, roll, pitch, yaw [rad], yaw unwrapped),
/// sampled every `dt` s, made by an estimator with `settings`. Returns a dict: `fit` (the
/// fitted ratio, length, drag terms, explained share and residual) or None with `reason`
/// saying why the fit is not to be used, `estimator` (the calibrated settings, or
/// `settings` unchanged) and `estimate` (N×2: the swing the calibrated estimator would have
/// made, to first order, through its pendulum observer, or `estimate` unchanged), and
/// `own_scale` (`estimator` and `estimate` as `settings` make them at their own scale,
/// without the drag the fit removes, or unchanged). Both lose the fitted drag terms `drag`
/// names (`keep`, `quadratic`: the airframe's curvature, the default; `all`); the
/// calibrated estimator's observer tells the rest of the drag from the swing.
#[pyfunction]
#[pyo3(signature = (vel, estimate, euler, dt, settings=None, drag="quadratic"))]
fn swing_scale_fit<'py>(
    py: Python<'py>,
    vel: &Bound<'py, PyAny>,
    estimate: &Bound<'py, PyAny>,
    euler: &Bound<'py, PyAny>,
    dt: f64,
    settings: Option<&Bound<'py, PyAny>>,
    drag: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let s: ImuSwingSettings = convert::settings(settings, "estimator")?;
    let drag = DragRemoval::from_name(drag).ok_or_else(|| {
        to_py(ConfigError::new(
            "drag",
            format!("must be keep, quadratic or all (got {drag:?})"),
        ))
    })?;
    s.validate().map_err(|e| to_py(e.within("estimator")))?;
    if !(dt.is_finite() && dt > 0.0) {
        return Err(data_err(format!(
            "dt must be a positive number of seconds (got {dt})"
        )));
    }
    let vel = convert::array2(vel, "vel")?;
    let est = convert::array2(estimate, "estimate")?;
    let eul = convert::array2(euler, "euler")?;
    let rows = vel.shape()[0];
    same_rows(
        rows,
        &[("vel", &vel, 2), ("estimate", &est, 2), ("euler", &eul, 3)],
    )?;
    let column =
        |a: &PyReadonlyArray2<f64>, j: usize| -> Vec<f64> { a.as_array().column(j).to_vec() };
    let (vn, ve) = (column(&vel, 0), column(&vel, 1));
    let (en, ee) = (column(&est, 0), column(&est, 1));
    let [tn, te] = swing_scale::tilt(
        &column(&eul, 0),
        &column(&eul, 1),
        &column(&eul, 2),
        dt,
        s.cutoff,
    );
    let axes = [
        ScaleAxis {
            velocity: &vn,
            estimate: &en,
            tilt: &tn,
        },
        ScaleAxis {
            velocity: &ve,
            estimate: &ee,
            tilt: &te,
        },
    ];
    let out = PyDict::new(py);
    let mut corrected = numpy::ndarray::Array2::<f64>::zeros((rows, 2));
    let fit_settings = ScaleSettings {
        drag,
        ..ScaleSettings::default()
    };
    let own = PyDict::new(py);
    let mut own_estimate = numpy::ndarray::Array2::<f64>::zeros((rows, 2));
    match swing_scale::fit(&axes, dt, &fit_settings) {
        Ok(fit) => {
            let [cn, ce] = [fit.apply(&axes[0]), fit.apply(&axes[1])];
            let first: Vec<[f64; 2]> = cn.iter().zip(&ce).map(|(n, e)| [*n, *e]).collect();
            let v: Vec<[f64; 2]> = vn.iter().zip(&ve).map(|(n, e)| [*n, *e]).collect();
            let calibrated = fit.calibrated(&s);
            for (i, x) in calibrated.observe(&first, &v).into_iter().enumerate() {
                corrected[[i, 0]] = x[0];
                corrected[[i, 1]] = x[1];
            }
            for (j, axis) in axes.iter().enumerate() {
                for (i, x) in fit.apply_without_drag(axis).into_iter().enumerate() {
                    own_estimate[[i, j]] = x;
                }
            }
            out.set_item("fit", convert::to_py_object(py, &fit)?)?;
            out.set_item("reason", py.None())?;
            out.set_item("estimator", convert::to_py_object(py, &calibrated)?)?;
            own.set_item(
                "estimator",
                convert::to_py_object(py, &fit.without_drag(&s))?,
            )?;
        }
        Err(reason) => {
            corrected.assign(&est.as_array());
            own_estimate.assign(&est.as_array());
            own.set_item("estimator", convert::to_py_object(py, &s)?)?;
            out.set_item("fit", py.None())?;
            out.set_item("reason", reason.to_string())?;
            out.set_item("estimator", convert::to_py_object(py, &s)?)?;
        }
    }
    out.set_item("estimate", corrected.into_pyarray(py))?;
    own.set_item("estimate", own_estimate.into_pyarray(py))?;
    out.set_item("own_scale", own)?;
    Ok(out)
}

/// Register this domain's functions and classes on the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyImuSwingEstimator>()?;
    m.add_function(wrap_pyfunction!(swing_scale_fit, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_swing, m)?)?;
    m.add_function(wrap_pyfunction!(body_swing, m)?)?;
    Ok(())
}
