//! Bindings of `swing_core::sim::hil`: the plant served to a PX4 flight controller.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use swing_core::sim::hil::{HilPlant, HilSettings, MOTOR_COLUMNS};

use crate::errors::to_py;
use crate::sim::{trace_to_dict, PyScenario};

/// Vehicle + payload physics for hardware-in-the-loop: motor commands in, PX4's sensor
/// readings out, one lockstep step at a time. The vehicle starts standing on the ground
/// below the scenario's start point.
#[pyclass(name = "HilPlant", module = "swingrt._core")]
pub struct PyHilPlant {
    inner: HilPlant,
}

#[pymethods]
impl PyHilPlant {
    /// Build from a scenario and optional HIL settings (home, magnetic field, sensor noise,
    /// rates; see `HilSettings` in the core).
    #[new]
    #[pyo3(signature = (scenario, settings=None))]
    fn new(scenario: &PyScenario, settings: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let s: HilSettings = crate::convert::settings(settings, "hil")?;
        Ok(Self {
            inner: HilPlant::new(scenario.inner.clone(), s).map_err(to_py)?,
        })
    }

    /// Simulated time [s].
    #[getter]
    fn t(&self) -> f64 {
        self.inner.time()
    }

    /// Length of one lockstep step [s].
    #[getter]
    fn step_dt(&self) -> f64 {
        self.inner.step_dt()
    }

    /// Whether the payload hangs from the vehicle (false while it lies on the ground).
    #[getter]
    fn payload_lifted(&self) -> bool {
        self.inner.payload_lifted()
    }

    /// Whether the vehicle stands on the ground.
    #[getter]
    fn on_ground(&self) -> bool {
        self.inner.on_ground()
    }

    /// Count the payload events still ahead from `origin` [s] of the plant's clock on
    /// (a session that takes off first times them from its hold in the air).
    fn count_payload_events_from(&mut self, origin: f64) -> PyResult<()> {
        self.inner.count_payload_events_from(origin).map_err(to_py)
    }

    /// Advance one lockstep step under normalised motor commands in PX4's rotor order.
    fn step(&mut self, motors: [f64; 4]) -> PyResult<()> {
        self.inner.step(motors).map_err(to_py)
    }

    /// The sensor readings of the current step as a dict in HIL_SENSOR / HIL_GPS units
    /// (`gps` is None when no fix is due), with the swing sensor, the body cable sensor's ADC
    /// counts (`adc`, NaN unless the swing source is `body`) and the ground truth (the true
    /// swing of the first link N, E [rad] as `swing_true`).
    fn sensors<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let f = self.inner.sensors();
        let d = PyDict::new(py);
        d.set_item("time_usec", f.time_usec)?;
        d.set_item("accel", f.accel)?;
        d.set_item("gyro", f.gyro)?;
        d.set_item("mag", f.mag)?;
        d.set_item("abs_pressure", f.abs_pressure)?;
        d.set_item("pressure_alt", f.pressure_alt)?;
        d.set_item("temperature", f.temperature)?;
        d.set_item("fields_updated", f.fields_updated)?;
        d.set_item("swing", f.swing)?;
        d.set_item("adc", f.adc)?;
        let truth = self.inner.true_swing();
        d.set_item("swing_true", [truth[0], truth[1]])?;
        d.set_item("attitude", f.attitude)?;
        d.set_item("position", f.position)?;
        d.set_item("velocity", f.velocity)?;
        d.set_item("acceleration", f.acceleration)?;
        match f.gps {
            None => d.set_item("gps", py.None())?,
            Some(g) => {
                let gd = PyDict::new(py);
                gd.set_item("lat", g.lat)?;
                gd.set_item("lon", g.lon)?;
                gd.set_item("alt", g.alt)?;
                gd.set_item("eph", g.eph)?;
                gd.set_item("epv", g.epv)?;
                gd.set_item("vel", g.vel)?;
                gd.set_item("vel_ned", g.vel_ned)?;
                gd.set_item("cog", g.cog)?;
                gd.set_item("satellites", g.satellites)?;
                d.set_item("gps", gd)?;
            }
        }
        Ok(d)
    }

    /// Take the physics trace logged so far (trace columns, PX4's setpoints as NaN, plus
    /// the motor commands); the plant keeps logging into a fresh one.
    fn take_trace<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        trace_to_dict(py, self.inner.take_trace())
    }
}

/// Register this domain's classes on the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyHilPlant>()?;
    m.add("MOTOR_COLUMNS", PyTuple::new(m.py(), MOTOR_COLUMNS)?)?;
    Ok(())
}
