//! Bindings of the field's other swing controllers (`control::shaper`, `control::payload_p`,
//! `control::deepc`) as one `Controller` class, and the adapter that lets the simulator's
//! runner call a Python controller object under the same supervisor.

use nalgebra::DMatrix;
use numpy::{PyArray1, PyArray2, PyReadonlyArray2, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use swing_core::control::deepc::{DeepcController, DeepcSettings, IoData};
use swing_core::control::payload_p::{PayloadP, PayloadPSettings};
use swing_core::control::px4::Px4Params;
use swing_core::control::shaper::{
    model_swing_mode, pendulum_swing_mode, InputShaper, ShaperSettings, SwingMode,
};
use swing_core::control::{AxisState, ControlError, ControlOutput, SwingController, TickInfo};
use swing_core::design::Law;
use swing_core::plant::PendulumModel;
use swing_core::ConfigError;

use crate::convert;
use crate::errors::to_py;
use crate::sysid::PyLinearModel;

fn output_name(o: ControlOutput) -> &'static str {
    match o {
        ControlOutput::Acceleration => "acceleration",
        ControlOutput::Velocity => "velocity",
    }
}

/// One of the core's other swing controllers (`shaper`, `payload_p`, `deepc`): `step` /
/// `reset` like `Mpc`, for `swingrt fly`; `Simulator.attach` takes it over.
#[pyclass(name = "Controller", module = "swingrt._core", unsendable)]
pub struct PyController {
    inner: Option<Box<dyn SwingController>>,
    kind: &'static str,
    info: serde_json::Value,
}

impl PyController {
    fn new(ctrl: Box<dyn SwingController>, kind: &'static str, info: serde_json::Value) -> Self {
        Self {
            inner: Some(ctrl),
            kind,
            info,
        }
    }

    fn get(&mut self) -> PyResult<&mut Box<dyn SwingController>> {
        self.inner.as_mut().ok_or_else(|| {
            to_py(ControlError::Input(
                "this controller was attached to a simulator and is no longer here".into(),
            ))
        })
    }

    /// Take the controller out (for a simulator to own).
    pub fn take(&mut self) -> PyResult<Box<dyn SwingController>> {
        self.get()?;
        Ok(self.inner.take().expect("checked above"))
    }
}

fn io_data(u: &PyReadonlyArray2<'_, f64>, y: &PyReadonlyArray2<'_, f64>) -> PyResult<IoData> {
    let to = |a: &PyReadonlyArray2<'_, f64>| {
        let v = a.as_array();
        DMatrix::from_fn(v.nrows(), v.ncols(), |i, j| v[(i, j)])
    };
    Ok(IoData { u: to(u), y: to(y) })
}

#[pymethods]
impl PyController {
    /// ZV / ZVD input shaper on the velocity setpoint for the mode (`omega` [rad/s],
    /// `zeta` [-]) on `axes` axes.
    #[staticmethod]
    #[pyo3(signature = (omega, zeta, axes=1, settings=None))]
    fn shaper(
        omega: f64,
        zeta: f64,
        axes: usize,
        settings: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let s: ShaperSettings = convert::settings(settings, "shaper")?;
        let mode = SwingMode { omega, zeta };
        let ctrl = InputShaper::new(mode, axes, &s).map_err(to_py)?;
        let info = serde_json::json!({"omega": omega, "zeta": zeta, "settings": s});
        Ok(Self::new(Box::new(ctrl), "shaper", info))
    }

    /// The law other than the MPC that `model`'s selection took (`design::law`: the input
    /// shaper where no candidate's MPC passed), on the model's axes; `None` when the model
    /// flies its MPC.
    #[staticmethod]
    fn flown(model: &PyLinearModel) -> PyResult<Option<Self>> {
        let law = Law::of(&model.inner).map_err(to_py)?;
        if law == Law::Mpc {
            return Ok(None);
        }
        let ctrl = law
            .controller(&model.inner, &Default::default())
            .map_err(to_py)?;
        let info = law.to_json();
        Ok(Some(Self::new(ctrl, law.name(), info)))
    }

    /// ArduPilot's slung-payload feedback on the velocity setpoint for a cable of `length` [m].
    #[staticmethod]
    #[pyo3(signature = (length, axes=1, settings=None))]
    fn payload_p(length: f64, axes: usize, settings: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let s: PayloadPSettings = convert::settings(settings, "payload_p")?;
        let ctrl = PayloadP::new(length, axes, s.clone()).map_err(to_py)?;
        let info = serde_json::json!({"length": length, "settings": s});
        Ok(Self::new(Box::new(ctrl), "payload_p", info))
    }

    /// DeePC from the training inputs `u` (T, m) and outputs `y` (T, 2m: per axis v, swing)
    /// at `dt` [s], its regularisation chosen on the held-out `u_test`, `y_test` (GIL
    /// released).
    #[staticmethod]
    #[pyo3(signature = (u, y, u_test, y_test, dt, settings=None))]
    fn deepc(
        py: Python<'_>,
        u: PyReadonlyArray2<'_, f64>,
        y: PyReadonlyArray2<'_, f64>,
        u_test: PyReadonlyArray2<'_, f64>,
        y_test: PyReadonlyArray2<'_, f64>,
        dt: f64,
        settings: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let s: DeepcSettings = convert::settings(settings, "deepc")?;
        let train = io_data(&u, &y)?;
        let test = io_data(&u_test, &y_test)?;
        let ctrl = py
            .detach(|| DeepcController::fit(&train, &test, dt, s))
            .map_err(to_py)?;
        let info = serde_json::json!({"fit": ctrl.fit_info(), "settings": ctrl.settings()});
        Ok(Self::new(Box::new(ctrl), "deepc", info))
    }

    /// One tick: state (axes × [v, swing, swing_rate]) and velocity reference in; the
    /// command per axis out (acceleration [m/s²] or velocity [m/s], see `output`).
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        state: PyReadonlyArrayDyn<'py, f64>,
        vel_ref: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let ctrl = self.get()?;
        let (out, _) = crate::control::step_any(ctrl.as_mut(), &state, vel_ref)?;
        Ok(PyArray1::from_vec(py, out))
    }

    /// Restart from a measured state and acceleration setpoint (bumpless transfer).
    #[pyo3(signature = (state, acc=None))]
    fn reset(
        &mut self,
        state: PyReadonlyArrayDyn<'_, f64>,
        acc: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let ctrl = self.get()?;
        crate::control::reset_any(ctrl.as_mut(), &state, acc)
    }

    /// Which controller: `shaper`, `payload_p` or `deepc`.
    #[getter]
    fn kind(&self) -> &'static str {
        self.kind
    }

    /// What the command is: `acceleration` or `velocity` (a setpoint PX4's PID tracks).
    #[getter]
    fn output(&mut self) -> PyResult<&'static str> {
        Ok(output_name(self.get()?.output()))
    }

    /// Tick period [s].
    #[getter]
    fn period(&mut self) -> PyResult<f64> {
        Ok(self.get()?.period())
    }

    /// Number of controlled axes.
    #[getter]
    fn axes(&mut self) -> PyResult<usize> {
        Ok(self.get()?.axes())
    }

    /// How it was built (mode, settings, DeePC's choice on the held-out data) as a dict.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        convert::to_py_object(py, &self.info)
    }
}

/// The swing mode (ω [rad/s], ζ [-]) PX4's velocity PID (gains of `px4`, a dict of the
/// scenario's `controller` fields) leaves in an identified `model`, or in the white-box
/// pendulum `params` (`m_q`, `m_p`, `l`, `c`) closed at `dt` [s].
#[pyfunction]
#[pyo3(signature = (model=None, params=None, dt=0.03, px4=None))]
fn swing_mode(
    model: Option<&PyLinearModel>,
    params: Option<&Bound<'_, PyAny>>,
    dt: f64,
    px4: Option<&Bound<'_, PyAny>>,
) -> PyResult<(f64, f64)> {
    let px4: Px4Params = convert::settings(px4, "px4")?;
    let mode = match (model, params) {
        (Some(m), None) => model_swing_mode(&m.inner, &px4),
        (None, Some(p)) => {
            let p: PendulumModel = convert::from_py(p, "params")?;
            pendulum_swing_mode(&p, dt, &px4)
        }
        _ => {
            return Err(to_py(ConfigError::new(
                "model",
                "give either an identified model or white-box params",
            )))
        }
    }
    .map_err(to_py)?;
    Ok((mode.omega, mode.zeta))
}

/// A Python controller object (`reset(state, acc)`, `step(state, vel_ref)`) as a core
/// controller: the runner calls it at its period, under the supervisor's checks, taking the
/// GIL for each call. A Python exception in `step` is a controller error (the supervisor
/// hands back to PX4); one in `reset` is reported by the next `step`.
pub struct PythonController {
    obj: Py<PyAny>,
    axes: usize,
    period: f64,
    output: ControlOutput,
    pending: Option<String>,
}

impl PythonController {
    /// Wrap `obj` flying `axes` axes every `period` [s] with an `output` command.
    pub fn new(
        obj: Py<PyAny>,
        axes: usize,
        period: f64,
        output: &str,
    ) -> Result<Self, ConfigError> {
        swing_core::config::positive("period", period)?;
        let output = match output {
            "acceleration" => ControlOutput::Acceleration,
            "velocity" => ControlOutput::Velocity,
            other => {
                return Err(ConfigError::new(
                    "output",
                    format!("must be \"acceleration\" or \"velocity\" (got {other:?})"),
                ))
            }
        };
        Ok(Self {
            obj,
            axes,
            period,
            output,
            pending: None,
        })
    }

    fn state_array<'py>(py: Python<'py>, state: &[AxisState]) -> Bound<'py, PyArray2<f64>> {
        let rows: Vec<Vec<f64>> = state
            .iter()
            .map(|s| vec![s.v, s.swing, s.swing_rate])
            .collect();
        PyArray2::from_vec2(py, &rows).expect("rows of equal length")
    }
}

impl SwingController for PythonController {
    fn axes(&self) -> usize {
        self.axes
    }

    fn period(&self) -> f64 {
        self.period
    }

    fn output(&self) -> ControlOutput {
        self.output
    }

    fn reset(&mut self, state: &[AxisState], acc: &[f64]) {
        let res = Python::attach(|py| -> PyResult<()> {
            let st = Self::state_array(py, state);
            let a = PyArray1::from_slice(py, acc);
            self.obj.call_method1(py, "reset", (st, a))?;
            Ok(())
        });
        self.pending = res.err().map(|e| format!("reset: {e}"));
    }

    fn step(
        &mut self,
        state: &[AxisState],
        vel_ref: &[f64],
        out: &mut [f64],
    ) -> Result<TickInfo, ControlError> {
        if let Some(e) = self.pending.take() {
            return Err(ControlError::Solver(e));
        }
        let res = Python::attach(|py| -> PyResult<Vec<f64>> {
            let st = Self::state_array(py, state);
            let r = PyArray1::from_slice(py, vel_ref);
            let v = self.obj.call_method1(py, "step", (st, r))?;
            let arr = v.bind(py).call_method0("__iter__")?;
            let mut vals = Vec::new();
            for x in arr.try_iter()? {
                vals.push(x?.extract::<f64>()?);
            }
            Ok(vals)
        });
        let vals = res.map_err(|e| ControlError::Solver(format!("Python controller: {e}")))?;
        if vals.len() != out.len() {
            return Err(ControlError::Input(format!(
                "Python controller returned {} value(s), expected {}",
                vals.len(),
                out.len()
            )));
        }
        out.copy_from_slice(&vals);
        Ok(TickInfo::default())
    }
}

/// Register this domain's functions and classes on the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyController>()?;
    m.add_function(wrap_pyfunction!(swing_mode, m)?)?;
    Ok(())
}
