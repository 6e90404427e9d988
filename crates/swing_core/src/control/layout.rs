//! Where each controlled axis' measurements sit in a linear model's state.
//!
//! A [`LinearModel`] names its states (`vn`, `ve`, `swing_n`, `swing_e`, optionally
//! `swing_rate_n`, `swing_rate_e`) and its inputs (`acc_sp_n`, `acc_sp_e`). Input j is axis j;
//! its suffix (`n`, `e`) is the part after `acc_sp_`, or the j-th of `n`, `e` when the input
//! name has no such prefix. The axis' velocity is the state `v<suffix>`, its swing
//! `swing_<suffix>` and, when the model has it, its swing rate `swing_rate_<suffix>`.

use super::ControlError;
use crate::sysid::LinearModel;

/// Which measured quantity of which axis a model state is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Measured {
    /// Velocity of axis i.
    V(usize),
    /// Swing angle of axis i.
    Swing(usize),
    /// Swing rate of axis i.
    SwingRate(usize),
}

/// Positions of one axis' quantities among the model's states (indices into the newest
/// frame of the delay stack).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AxisColumns {
    /// Axis suffix (`n` or `e`).
    pub suffix: String,
    /// Index of the velocity state.
    pub v: usize,
    /// Index of the swing state.
    pub swing: usize,
    /// Index of the swing-rate state, if the model has one.
    pub swing_rate: Option<usize>,
}

/// The axis layout of a model: one [`AxisColumns`] per input (see module docs).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AxisLayout {
    axes: Vec<AxisColumns>,
}

/// The axis suffix of input `a` called `input`.
fn axis_suffix(input: &str, a: usize) -> Result<String, ControlError> {
    match input.strip_prefix("acc_sp_") {
        Some(s) if !s.is_empty() => Ok(s.to_string()),
        _ => ["n", "e"].get(a).map(|s| s.to_string()).ok_or_else(|| {
            ControlError::Model(format!(
                "input '{input}' names no axis (expected acc_sp_<axis>)"
            ))
        }),
    }
}

impl AxisLayout {
    /// Find every axis' velocity and swing (and swing rate, if present) among the model's
    /// states; an axis without velocity or swing is a [`ControlError::Model`].
    pub fn from_model(model: &LinearModel) -> Result<Self, ControlError> {
        let find = |name: String| model.states.iter().position(|s| *s == name);
        let axes = model
            .inputs
            .iter()
            .enumerate()
            .map(|(a, input)| {
                let s = axis_suffix(input, a)?;
                match (find(format!("v{s}")), find(format!("swing_{s}"))) {
                    (Some(v), Some(swing)) => Ok(AxisColumns {
                        v,
                        swing,
                        swing_rate: find(format!("swing_rate_{s}")),
                        suffix: s,
                    }),
                    _ => Err(ControlError::Model(format!(
                        "model lacks v{s} or swing_{s} for input '{input}'"
                    ))),
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { axes })
    }

    /// The axes in input order.
    pub fn axes(&self) -> &[AxisColumns] {
        &self.axes
    }

    /// Number of axes (inputs).
    pub fn len(&self) -> usize {
        self.axes.len()
    }

    /// True for a model without inputs.
    pub fn is_empty(&self) -> bool {
        self.axes.is_empty()
    }

    /// What the state called `name` measures, if it is an axis quantity.
    pub fn classify(&self, name: &str) -> Option<Measured> {
        self.axes.iter().enumerate().find_map(|(a, ax)| {
            let s = &ax.suffix;
            if name.strip_prefix('v') == Some(s.as_str()) {
                Some(Measured::V(a))
            } else if name.strip_prefix("swing_") == Some(s.as_str()) {
                Some(Measured::Swing(a))
            } else if name.strip_prefix("swing_rate_") == Some(s.as_str()) {
                Some(Measured::SwingRate(a))
            } else {
                None
            }
        })
    }

    /// The suffixes of all axes, for messages.
    pub fn suffixes(&self) -> Vec<&str> {
        self.axes.iter().map(|a| a.suffix.as_str()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::PendulumModel;
    use crate::testing::pendulum_delay_model;

    #[test]
    fn two_axis_model_maps_each_axis_and_classifies_every_state() {
        let m = pendulum_delay_model(&PendulumModel::default(), 0.03, 2, 2, 7).unwrap();
        let layout = AxisLayout::from_model(&m).unwrap();
        assert_eq!(layout.len(), 2);
        let e = &layout.axes()[1];
        assert_eq!(
            (e.suffix.as_str(), e.v, e.swing, e.swing_rate),
            ("e", 1, 3, None)
        );
        assert_eq!(layout.classify("swing_n"), Some(Measured::Swing(0)));
        assert_eq!(layout.classify("ve"), Some(Measured::V(1)));
        assert_eq!(layout.classify("vd"), None);
    }

    #[test]
    fn a_missing_axis_state_is_an_error_not_index_zero() {
        let mut m = pendulum_delay_model(&PendulumModel::default(), 0.03, 2, 1, 7).unwrap();
        m.states = vec!["vn".into(), "theta".into()];
        let e = AxisLayout::from_model(&m).unwrap_err();
        assert!(
            matches!(e, ControlError::Model(ref s) if s.contains("swing_n")),
            "{e}"
        );
        m.states = vec!["vn".into(), "swing_n".into()];
        m.inputs = vec!["u0".into(), "u1".into(), "u2".into()];
        assert!(AxisLayout::from_model(&m).is_err());
    }
}
