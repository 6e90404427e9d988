//! Re-identification on the vehicle's twin: swingrt's own simulator of the vehicle under
//! PX4's cascade turns a payload measured in flight into a delay-coordinate model.
//!
//!
//! A payload change leaves too little closed-loop data for a data-driven refit before the
//! next manoeuvre (the adaptive MPC's online DMDc needs minutes of excitation to match a
//! training flight). What the flight does give within a second or two is the payload's
//! physics: the cable length from the pendulum's equation of motion and the mass from the
//! thrust (`sysid::payload`). The twin turns those into a model of the same form as the
//! one identified before the flight: it flies the training flight (the same random steps)
//! with the measured payload and fits DMDc with the original model's delays, rank and
//! offset. Whatever the twin gets wrong about the vehicle, the original model also
//! carried, because both come from a training flight of the same vehicle; on a real
//! vehicle the twin's fidelity (PX4's gains, the attitude loop's lag) bounds what this
//! gives, which is why the candidate still goes through the closed-loop check.

use crate::config::{positive, ConfigError};
use crate::control::MpcSettings;
use crate::design::selection::{select_for_control, Fallback, SelectionSettings};
use crate::design::twin::TwinPlant;
use crate::design::DesignError;
use crate::plant::PayloadKind;
use crate::sim::{Scenario, Simulator};
use crate::sysid::dmdc::{self, DmdcSettings};
use crate::sysid::hankel::Trajectory;
use crate::sysid::pipeline::named;
use crate::sysid::pipeline::{search, split, whitebox_model};
use crate::sysid::resample::resample;
use crate::sysid::settings::IdentifySettings;
use crate::sysid::LinearModel;

/// Shortest twin training flight [s]: below this a model of a 20-frame delay stack is
/// poorly determined.
pub const MIN_TWIN_SECONDS: f64 = 20.0;

/// The twin and what it re-identifies.
#[derive(Clone, Debug)]
pub struct Twin {
    scenario: Scenario,
    vehicle_mass: f64,
    search: bool,
}

/// Share of the twin's flight held out to score the search's candidates.
pub const TEST_FRACTION: f64 = 0.25;

impl Twin {
    /// A twin that flies `training` (the scenario of the training flight, random steps and
    /// all) for `seconds` with the payload it is asked about; `vehicle_mass` [kg] is the
    /// vehicle's own mass as identified (the total mass less it is the payload's).
    /// With `search`, the rank is searched at the template's delays and the candidate picked
    /// by the control-relevant selection; without, the template's rank is kept.
    pub fn new(
        training: &Scenario,
        seconds: f64,
        vehicle_mass: f64,
        search: bool,
    ) -> Result<Self, ConfigError> {
        if !(seconds.is_finite() && seconds >= MIN_TWIN_SECONDS) {
            return Err(ConfigError::new(
                "duration",
                format!("twin duration must be at least {MIN_TWIN_SECONDS} s, not {seconds}"),
            ));
        }
        positive("vehicle_mass", vehicle_mass)?;
        let mut scenario = training.clone();
        scenario.duration = seconds;
        scenario.payload.events.clear();
        scenario.validate().map_err(|e| e.within("scenario"))?;
        Ok(Self {
            scenario,
            vehicle_mass,
            search,
        })
    }

    /// The vehicle's own mass [kg].
    pub fn vehicle_mass(&self) -> f64 {
        self.vehicle_mass
    }

    /// Fly the twin with a single payload of `mass` [kg] on `length` [m] and fit a model of
    /// `template`'s form (method DMDc, its delays, offset, sample time, state and input
    /// names; its rank, or with `search` the rank selected for the MPC of `mpc`).
    pub fn identify(
        &self,
        template: &LinearModel,
        mass: f64,
        length: f64,
        mpc: &MpcSettings,
    ) -> Result<LinearModel, DesignError> {
        if template.method != "dmdc" {
            return Err(DesignError::Model(format!(
                "the twin re-identifies DMDc models, not {}",
                template.method
            )));
        }
        let mut sc = self.scenario.clone();
        sc.payload.kind = PayloadKind::Single;
        sc.payload.mass = mass;
        sc.payload.length = length;
        sc.validate().map_err(|e| e.within("payload"))?;
        let trace = Simulator::run(sc)?;
        let column = |name: &str| {
            trace
                .column(name)
                .ok_or_else(|| DesignError::Model(format!("twin flight has no column {name}")))
        };
        let t = column("t")?;
        let states = template
            .states
            .iter()
            .map(|s| column(s))
            .collect::<Result<Vec<_>, _>>()?;
        let inputs = template
            .inputs
            .iter()
            .map(|s| column(s))
            .collect::<Result<Vec<_>, _>>()?;
        let dt = template.dt;
        let (x, n) = resample(t, &states, dt);
        let (u, m) = resample(t, &inputs, dt);
        let traj = Trajectory::new(&x, states.len(), &u, inputs.len())?;
        debug_assert_eq!(n, m);
        if !self.search {
            let full = template.n() * template.delays + template.m();
            let rank = (template.rank != 0 && template.rank < full).then_some(template.rank);
            let model = dmdc::fit(
                &traj,
                &DmdcSettings {
                    delays: template.delays,
                    rank,
                    offset: template.offset,
                    dt,
                },
            )?;
            return Ok(named(model, &template.states, &template.inputs)?);
        }
        // As the oracle is identified (search, then the control-relevant selection against
        // the white-box of the flight), but at the template's q: the delay stack the
        // flying controller hands over keeps its size.
        let settings = IdentifySettings {
            dt,
            offset: template.offset,
            search: true,
            search_delays: Some(vec![template.delays]),
            fine: Some([0, 7]),
            test_span: self.scenario.duration * TEST_FRACTION,
            cable_length: Some(length),
            vehicle_mass: self.vehicle_mass,
            ..IdentifySettings::default()
        };
        let (train, test) = split(&traj, &settings)?;
        let found = search(&train, &test, &settings)?;
        let plant = whitebox_model(&train, &template.states, &template.inputs, &settings, mass)?;
        let selection_settings = SelectionSettings {
            plant_label: format!("twin whitebox (payload {mass:.3} kg on {length:.2} m)"),
            // The adaptive MPC swaps MPC models: a model whose MPC did not pass is not one
            // to adopt, whatever else would have.
            fallback: Fallback::None,
            ..SelectionSettings::default()
        };
        // The same selection as the model's own, twin flights included: at a long delay
        // stack the stability screen leaves few ranks, and only the twin's flight vets
        // the ones it did not screen.
        let vetting = TwinPlant::new(
            &self.scenario,
            &plant,
            selection_settings.step,
            template.m(),
        )?;
        let selection = select_for_control(
            &train,
            &test,
            &template.states,
            &template.inputs,
            &settings,
            &found,
            &plant,
            mpc,
            &selection_settings,
            Some(&vetting),
        )?;
        if !selection.passed {
            return Err(DesignError::NonePassed {
                delays: template.delays,
            });
        }
        Ok(selection.model)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::fixtures::template;
    use crate::plant::GRAVITY;

    /// Frequency [rad/s] of the least damped oscillatory mode of a model's A.
    fn swing_frequency(m: &LinearModel) -> f64 {
        m.a.complex_eigenvalues()
            .iter()
            .filter(|z| z.im > 1e-3)
            .max_by(|a, b| a.norm().total_cmp(&b.norm()))
            .map(|z| z.arg() / m.dt)
            .unwrap()
    }

    #[test]
    fn twin_models_swing_at_the_pendulum_frequency_of_the_length_asked() {
        let sc = Scenario::builtin("training").unwrap();
        let tpl = template(&sc);
        let twin = Twin::new(&sc, 40.0, sc.vehicle.mass, false).unwrap();
        for &l in &[0.5, 2.0] {
            let m = twin
                .identify(&tpl, 0.2, l, &MpcSettings::default())
                .unwrap();
            assert_eq!((m.delays, m.states.clone()), (6, tpl.states.clone()));
            let w = swing_frequency(&m);
            // Under velocity control the vehicle is neither pinned nor free: the swing
            // lies between sqrt(g/l) and sqrt(g/l · (1 + m_p/m_v)), within 10 %.
            let pinned = (GRAVITY / l).sqrt();
            let free = (GRAVITY / l * (1.0 + 0.2 / sc.vehicle.mass)).sqrt();
            assert!(
                w > 0.9 * pinned && w < 1.1 * free,
                "l {l}: {w} rad/s, pinned {pinned}, free {free}"
            );
        }
    }

    #[test]
    fn refuses_short_flights_and_bad_masses() {
        let sc = Scenario::builtin("training").unwrap();
        assert!(Twin::new(&sc, 5.0, 1.0, false).is_err());
        assert!(Twin::new(&sc, 60.0, -1.0, false).is_err());
        let twin = Twin::new(&sc, 30.0, 0.952, false).unwrap();
        let tpl = template(&sc);
        let mpc = MpcSettings::default();
        assert!(twin.identify(&tpl, -0.1, 1.0, &mpc).is_err());
        let mut havok = tpl.clone();
        havok.method = "havokc".into();
        assert!(twin.identify(&havok, 0.2, 1.0, &mpc).is_err());
    }

    #[test]
    fn twin_search_keeps_the_delays_and_passes_the_check() {
        let sc = Scenario::builtin("training").unwrap();
        let tpl = template(&sc);
        let twin = Twin::new(&sc, 120.0, sc.vehicle.mass, true).unwrap();
        let m = twin
            .identify(&tpl, 0.3, 1.5, &MpcSettings::default())
            .unwrap();
        assert_eq!(m.delays, tpl.delays);
        let check = &m.diagnostics.extra["control_check"];
        assert_eq!(check["passed"], serde_json::json!(true), "{check}");
    }
}
