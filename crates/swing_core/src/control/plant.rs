//! A linear model flown as the plant: z⁺ = A z + B (u − ū) + c, started at z = 0, with each
//! axis' measured state read off the newest frame of z ([`AxisLayout`]).
//!
//! The swing rate is the model's own swing-rate state when it has one, otherwise the
//! backward difference of the swing over the last step. Used by the closed-loop step check,
//! the MPC tick timing and the tests; allocation happens in [`LinearPlant::new`] only.

use nalgebra::DVector;

use super::layout::AxisLayout;
use super::{AxisState, ControlError};
use crate::sysid::LinearModel;

/// A linear model stepped as a plant (see module docs).
#[derive(Clone, Debug)]
pub struct LinearPlant {
    model: LinearModel,
    layout: AxisLayout,
    z: DVector<f64>,
    next: DVector<f64>,
    du: DVector<f64>,
    /// Swing of each axis before the last step [rad].
    prev_swing: Vec<f64>,
}

impl LinearPlant {
    /// Check the model's shapes and axis layout and start at z = 0.
    pub fn new(model: &LinearModel) -> Result<Self, ControlError> {
        let n = model.states.len();
        let nz = n * model.delays;
        let m = model.inputs.len();
        if n == 0
            || model.delays == 0
            || model.a.shape() != (nz, nz)
            || model.b.shape() != (nz, m)
            || model.c.len() != nz
            || model.input_mean.len() != m
        {
            return Err(ControlError::Model(format!(
                "plant model: {n} states × {} delays and {m} inputs do not match A {:?}, \
                 B {:?}, c ({}) and input_mean ({})",
                model.delays,
                model.a.shape(),
                model.b.shape(),
                model.c.len(),
                model.input_mean.len()
            )));
        }
        if !(model.dt.is_finite() && model.dt > 0.0) {
            return Err(ControlError::Model(format!(
                "plant model: dt must be > 0 (got {})",
                model.dt
            )));
        }
        let layout = AxisLayout::from_model(model)?;
        Ok(Self {
            z: DVector::zeros(nz),
            next: DVector::zeros(nz),
            du: DVector::zeros(m),
            prev_swing: vec![0.0; m],
            layout,
            model: model.clone(),
        })
    }

    /// Number of axes (model inputs).
    pub fn axes(&self) -> usize {
        self.layout.len()
    }

    /// The axis layout of the model.
    pub fn layout(&self) -> &AxisLayout {
        &self.layout
    }

    /// The delay-stacked state z.
    pub fn z(&self) -> &DVector<f64> {
        &self.z
    }

    /// Write the measured state of each axis into `out` (one entry per axis).
    pub fn measure(&self, out: &mut [AxisState]) {
        let dt = self.model.dt;
        for ((o, ax), prev) in out.iter_mut().zip(self.layout.axes()).zip(&self.prev_swing) {
            let swing = self.z[ax.swing];
            *o = AxisState {
                v: self.z[ax.v],
                swing,
                swing_rate: match ax.swing_rate {
                    Some(i) => self.z[i],
                    None => (swing - prev) / dt,
                },
            };
        }
    }

    /// The measured state of each axis (allocates; see [`Self::measure`]).
    pub fn state(&self) -> Vec<AxisState> {
        let mut out = vec![AxisState::default(); self.axes()];
        self.measure(&mut out);
        out
    }

    /// Advance one step with input `u` (one entry per axis).
    pub fn step(&mut self, u: &[f64]) {
        for (p, ax) in self.prev_swing.iter_mut().zip(self.layout.axes()) {
            *p = self.z[ax.swing];
        }
        for (i, d) in self.du.iter_mut().enumerate() {
            *d = u[i] - self.model.input_mean[i];
        }
        self.next.copy_from(&self.model.c);
        self.next.gemv(1.0, &self.model.a, &self.z, 1.0);
        self.next.gemv(1.0, &self.model.b, &self.du, 1.0);
        std::mem::swap(&mut self.z, &mut self.next);
    }
}
