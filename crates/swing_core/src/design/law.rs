//! What a selected model flies: the MPC on it, or the law the selection took where no
//! candidate's MPC passed the check and that law flew better on the twin.
//!
//! The selection (`selection::select_for_control`) writes its decision into the model's
//! diagnostics (`control_check.law`), so the model file carries it to every flight: the
//! simulator's `mpc`, the offboard node and `run --px4` all build what flies here, from
//! the model alone.
//!
//! The one other law is the ZVD input shaper of PX4's velocity setpoint on the white-box
//! pendulum (`control::shaper`): it feeds nothing back from the swing, so neither a noisy
//! swing estimate nor the drag the IMU reads as swing reaches it, and it keeps PX4's own
//! velocity loop (and integrator). Where the identified model's MPC fails the check,
//! usually on those two, the shaper often passes it.

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::control::layout::AxisLayout;
use crate::control::px4::Px4Params;
use crate::control::shaper::{pendulum_swing_mode, InputShaper, ShaperSettings, SwingMode};
use crate::control::{ControlError, MpcController, MpcSettings, SwingController};
use crate::plant::PendulumModel;
use crate::sysid::LinearModel;

/// The law a model flies.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Law {
    /// The MPC on the model.
    #[default]
    Mpc,
    /// The input shaper of PX4's velocity setpoint for `mode`, the swing mode PX4's loop
    /// leaves in the white-box pendulum.
    Shaper {
        /// The shaped mode.
        mode: SwingMode,
        /// The shaper's kind and period.
        settings: ShaperSettings,
    },
}

impl Law {
    /// The shaper of `settings` on the white-box pendulum of `model`'s diagnostics, closed
    /// by PX4's velocity loop of `px4` at the model's sample time; `None` when the model
    /// carries no white-box estimate.
    pub fn whitebox_shaper(
        model: &LinearModel,
        px4: &Px4Params,
        settings: &ShaperSettings,
    ) -> Result<Option<Self>, ControlError> {
        let Some(w) = model.diagnostics.whitebox.as_ref() else {
            return Ok(None);
        };
        let pendulum = PendulumModel {
            m_q: w.vehicle_mass,
            m_p: w.payload_mass,
            l: w.length,
            c: w.friction,
        };
        let mode = pendulum_swing_mode(&pendulum, model.dt, px4)?;
        Ok(Some(Self::Shaper {
            mode,
            settings: settings.clone(),
        }))
    }

    /// The law `model`'s selection chose (`control_check.law`); the MPC when the model
    /// records none (a model not selected on a twin, or saved before the law was recorded).
    pub fn of(model: &LinearModel) -> Result<Self, ControlError> {
        let recorded = model
            .diagnostics
            .extra
            .get("control_check")
            .and_then(|c| c.get("law"));
        match recorded {
            None | Some(Value::Null) => Ok(Self::Mpc),
            Some(v) => {
                let law: Self = serde_json::from_value(v.clone()).map_err(|e| {
                    ControlError::Model(format!("the model's control_check.law: {e}"))
                })?;
                law.validate()?;
                Ok(law)
            }
        }
    }

    /// Check the shaper's mode and settings.
    pub fn validate(&self) -> Result<(), ControlError> {
        if let Self::Shaper { mode, settings } = self {
            mode.validate()?;
            settings.validate()?;
        }
        Ok(())
    }

    /// The law's name in reports (`mpc`, `shaper`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Mpc => "mpc",
            Self::Shaper { .. } => "shaper",
        }
    }

    /// The law as the model's diagnostics record it.
    pub fn to_json(&self) -> Value {
        // A unit variant and a struct of numbers always serialise.
        serde_json::to_value(self).unwrap_or(Value::Null)
    }

    /// A fresh controller of this law for `model` (its axes) with `mpc_settings` for the MPC.
    pub fn controller(
        &self,
        model: &LinearModel,
        mpc_settings: &MpcSettings,
    ) -> Result<Box<dyn SwingController>, ControlError> {
        let axes = AxisLayout::from_model(model)?.axes().len();
        self.controller_on(axes, model, mpc_settings)
    }

    /// [`Self::controller`] on `axes` axes (a shaper's; the MPC's are its model's).
    pub(crate) fn controller_on(
        &self,
        axes: usize,
        model: &LinearModel,
        mpc_settings: &MpcSettings,
    ) -> Result<Box<dyn SwingController>, ControlError> {
        match self {
            Self::Mpc => Ok(Box::new(MpcController::new(model, mpc_settings.clone())?)),
            Self::Shaper { mode, settings } => {
                Ok(Box::new(InputShaper::new(*mode, axes, settings)?))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::shaper::ShaperKind;
    use crate::design::fixtures::template;
    use crate::sim::Scenario;

    fn shaper() -> Law {
        Law::Shaper {
            mode: SwingMode {
                omega: 3.1,
                zeta: 0.02,
            },
            settings: ShaperSettings {
                kind: ShaperKind::Zv,
                ..Default::default()
            },
        }
    }

    fn model() -> LinearModel {
        template(&Scenario::builtin("training").unwrap())
    }

    fn recording(law: Option<Value>) -> LinearModel {
        let mut m = model();
        let mut check = serde_json::json!({"passed": false});
        if let Some(l) = law {
            check["law"] = l;
        }
        m.diagnostics.extra.insert("control_check".into(), check);
        m
    }

    #[test]
    fn a_law_reads_back_as_it_was_recorded() {
        let law = shaper();
        assert_eq!(Law::of(&recording(Some(law.to_json()))).unwrap(), law);
        assert_eq!(
            Law::of(&recording(Some(Law::Mpc.to_json()))).unwrap(),
            Law::Mpc
        );
    }

    #[test]
    fn a_model_that_records_no_law_flies_its_mpc() {
        assert_eq!(Law::of(&recording(None)).unwrap(), Law::Mpc);
        assert_eq!(Law::of(&model()).unwrap(), Law::Mpc);
    }

    #[test]
    fn a_damaged_law_is_refused_naming_it() {
        for bad in [
            serde_json::json!({"kind": "pid"}),
            serde_json::json!({"kind": "shaper", "mode": {"omega": -1.0, "zeta": 0.0},
                               "settings": {}}),
            serde_json::json!({"kind": "shaper", "mode": {"omega": 3.0, "zeta": 0.0}}),
        ] {
            let err = Law::of(&recording(Some(bad.clone())))
                .unwrap_err()
                .to_string();
            assert!(err.contains("law") || err.contains("omega"), "{bad}: {err}");
        }
    }

    #[test]
    fn each_law_builds_the_controller_it_names_on_the_model_s_axes() {
        let model = model();
        let mpc = Law::Mpc
            .controller(&model, &MpcSettings::default())
            .unwrap();
        assert_eq!(mpc.output(), crate::control::ControlOutput::Acceleration);
        let sh = shaper()
            .controller(&model, &MpcSettings::default())
            .unwrap();
        assert_eq!(sh.output(), crate::control::ControlOutput::Velocity);
        assert_eq!(sh.axes(), 1);
        assert_eq!(sh.period(), ShaperSettings::default().period);
    }
}
