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
use crate::control::shaper::{
    pendulum_swing_mode, InputShaper, ModeSource, ShaperSettings, SwingMode,
};
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
    /// leaves in the white-box pendulum, in series with one for `second` where the swing
    /// shows a second mode.
    Shaper {
        /// The shaped mode.
        mode: SwingMode,
        /// A double pendulum's second mode, shaped too.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        second: Option<SwingMode>,
        /// The shaper's kind and period.
        settings: ShaperSettings,
    },
}

impl Law {
    /// The shaper of `settings` on the white-box pendulum of `model`'s diagnostics, closed
    /// by PX4's velocity loop of `px4` at the model's sample time; `None` when the model
    /// carries no white-box estimate. Where the swing shows a second mode
    /// (`WhiteboxEstimates::second_mode`: the fitted links' with the vehicle held, or the
    /// second peak of the swing's spectrum), it is shaped too, undamped: it lies well above
    /// the vehicle's velocity loop, which moves the first mode, not it.
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
        let second = w
            .second_mode()
            .filter(|&omega| omega > mode.omega)
            .map(|omega| SwingMode { omega, zeta: 0.0 });
        // The record says where the mode came from, whatever source `settings` named.
        Ok(Some(Self::Shaper {
            mode,
            second,
            settings: ShaperSettings {
                source: ModeSource::Whitebox,
                ..settings.clone()
            },
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
        if let Self::Shaper {
            mode,
            second,
            settings,
        } = self
        {
            mode.validate()?;
            if let Some(m) = second {
                m.validate()?;
            }
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
            Self::Shaper {
                mode,
                second,
                settings,
            } => {
                let modes: Vec<SwingMode> = std::iter::once(*mode).chain(*second).collect();
                Ok(Box::new(InputShaper::for_modes(&modes, axes, settings)?))
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
            second: None,
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
    fn the_whitebox_shaper_shapes_the_second_mode_where_the_white_box_found_two_links() {
        use crate::sysid::links::{modes, DoublePendulum};
        use crate::sysid::WhiteboxEstimates;
        let mut m = model();
        assert_eq!(
            Law::whitebox_shaper(&m, &Px4Params::default(), &ShaperSettings::default()).unwrap(),
            None
        );
        let (l1, l2, mu) = (0.8, 0.4, 0.5);
        let (_, second_mode, mode_share) = modes(l1, l2, mu);
        let single = WhiteboxEstimates {
            vehicle_mass: 0.952,
            payload_mass: 0.3,
            length: 1.0,
            friction: 0.0,
            ..Default::default()
        };
        let px4 = Px4Params::default();
        let settings = ShaperSettings::default();
        m.diagnostics.whitebox = Some(single.clone());
        let Some(Law::Shaper {
            mode,
            second: None,
            settings: recorded,
        }) = Law::whitebox_shaper(&m, &px4, &settings).unwrap()
        else {
            panic!("a single pendulum's shaper shapes one mode");
        };
        // The first mode is the pendulum's under PX4's loop; the record says where it came from.
        let pendulum = PendulumModel {
            m_q: 0.952,
            m_p: 0.3,
            l: 1.0,
            c: 0.0,
        };
        assert_eq!(mode, pendulum_swing_mode(&pendulum, m.dt, &px4).unwrap());
        assert_eq!(recorded.source, ModeSource::Whitebox);
        m.diagnostics.whitebox = Some(WhiteboxEstimates {
            links: Some(DoublePendulum {
                length: l1,
                length2: l2,
                mass_ratio: mu,
                error_ratio: 0.5,
                second_mode,
                mode_share,
            }),
            ..single
        });
        let law = Law::whitebox_shaper(&m, &px4, &settings).unwrap().unwrap();
        let Law::Shaper {
            second: Some(second),
            ..
        } = law
        else {
            panic!("a double pendulum's shaper shapes its second mode: {law:?}");
        };
        assert_eq!(second.omega, second_mode);
        assert_eq!(Law::of(&recording(Some(law.to_json()))).unwrap(), law);
        // Nine impulses of the two ZVDs in series: the controller is the series shaper.
        let mut c = law.controller(&m, &MpcSettings::default()).unwrap();
        let state = [crate::control::AxisState::default()];
        c.reset(&state, &[0.0]);
        let mut out = [0.0];
        c.step(&state, &[1.0], &mut out).unwrap();
        let first = crate::control::shaper::series(settings.kind, &[mode, second])[0].1;
        assert!((out[0] - first).abs() < 1e-12, "{} vs {first}", out[0]);
    }

    #[test]
    fn a_second_peak_of_the_swings_spectrum_is_shaped_only_when_shown_and_no_links_were_fitted() {
        use crate::sysid::links::DoublePendulum;
        use crate::sysid::spectrum::SecondPeak;
        use crate::sysid::WhiteboxEstimates;
        let mut m = model();
        let px4 = Px4Params::default();
        let settings = ShaperSettings::default();
        let peak = SecondPeak {
            omega: 7.4,
            first: 3.3,
            power_ratio: 0.5,
            shown: true,
        };
        let single = WhiteboxEstimates {
            vehicle_mass: 0.952,
            payload_mass: 0.3,
            length: 0.9,
            friction: 0.0,
            ..Default::default()
        };
        let second_of = |w: WhiteboxEstimates, m: &mut LinearModel| {
            m.diagnostics.whitebox = Some(w);
            match Law::whitebox_shaper(m, &px4, &settings).unwrap() {
                Some(Law::Shaper { second, .. }) => second.map(|s| s.omega),
                other => panic!("not a shaper: {other:?}"),
            }
        };
        let shown = WhiteboxEstimates {
            second_peak: Some(peak),
            ..single.clone()
        };
        assert_eq!(second_of(shown.clone(), &mut m), Some(7.4));
        let faint = WhiteboxEstimates {
            second_peak: Some(SecondPeak {
                shown: false,
                ..peak
            }),
            ..single.clone()
        };
        assert_eq!(second_of(faint, &mut m), None);
        // A peak below the shaped mode is not a double pendulum's second mode.
        let below = WhiteboxEstimates {
            second_peak: Some(SecondPeak { omega: 1.5, ..peak }),
            ..single.clone()
        };
        assert_eq!(second_of(below, &mut m), None);
        // Fitted links say more than a peak: their mode is the one shaped.
        let both = WhiteboxEstimates {
            links: Some(DoublePendulum {
                length: 0.5,
                length2: 0.4,
                mass_ratio: 0.5,
                error_ratio: 0.8,
                second_mode: 9.0,
                mode_share: 0.2,
            }),
            ..shown
        };
        assert_eq!(second_of(both, &mut m), Some(9.0));
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
