//! Payload events in flight: pick a payload up, drop it, change its mass, winch its cable,
//! change the vehicle's mass.
//!
//! A scenario lists them under `[[payload.events]]`:
//!
//! ```toml
//! [[payload.events]]
//! t = 5.0            # time the event starts [s]
//! action = "attach"  # attach | detach | mass | winch | vehicle_mass
//! mass = 0.3         # attach, mass: payload mass [kg]; vehicle_mass: vehicle mass [kg]
//! length = 1.5       # attach: cable length [m]; winch: target length [m]
//! rate = 0.3         # winch: cable speed [m/s]
//! ```
//!
//! Physics at each event (one function, [`apply_payload_events`], callable from any stepping
//! loop: the simulator's runner and the hardware-in-the-loop server alike):
//! - `attach`: the payload is picked up from rest directly below the vehicle (cable
//!   vertical). The cable can only pull along itself, so the pick-up is an inelastic impulse
//!   along the cable: momentum along the cable is shared by vehicle and payload, the
//!   components across it are unchanged (the payload stays at rest across the cable, which
//!   gives the link an initial rate ṅ = −v_⊥/l). In hover the velocities are zero and nothing
//!   jumps; the new weight is what the vehicle feels.
//! - `detach`: the cable goes slack; the vehicle keeps its state.
//! - `mass`: the payload's mass changes without an impulse (the mass that leaves or joins
//!   moves with the payload), so velocities are unchanged.
//! - `winch`: from `t` on the cable length moves towards `length` at `rate` until reached or
//!   until the next event. Quasi-static: each physics step sets the length and keeps the link
//!   direction n and its rate ṅ; the radial payload velocity l̇·n and the Coriolis term it
//!   brings into the swing (−2 l̇/l · ṅ) are neglected, which at the cable speeds of a winch
//!   (≤ 1 m/s) against swing speeds of l·ω changes the swing energy by a few percent per
//!   metre of cable.
//! - `vehicle_mass`: the vehicle's mass changes without an impulse (a dropped battery or
//!   sensor); PX4 is not told, its velocity integrators absorb the new hover thrust.
//!
//! Events need a single point-mass payload (or none, for `attach`); the double pendulum of
//! section 4.6.9 has no events.

use serde::{Deserialize, Serialize};

use super::dynamics::{Model, PlantState};
use super::params::{PayloadKind, PayloadParams};
use crate::config::{non_negative, positive, ConfigError};

/// What a payload event does (see module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PayloadAction {
    /// Pick a payload of `mass` on a cable of `length` up from rest below the vehicle.
    Attach,
    /// Drop the payload.
    Detach,
    /// Set the payload mass to `mass`.
    Mass,
    /// Move the cable length towards `length` at `rate`.
    Winch,
    /// Set the vehicle mass to `mass`.
    VehicleMass,
}

/// One payload event of a scenario (see module docs for units and physics).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PayloadEvent {
    /// Time the event starts [s].
    pub t: f64,
    /// What happens.
    pub action: PayloadAction,
    /// Payload mass (`attach`, `mass`) or vehicle mass (`vehicle_mass`) [kg].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mass: Option<f64>,
    /// Cable length (`attach`) or the winch's target length (`winch`) [m].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length: Option<f64>,
    /// Winch cable speed [m/s] (`winch`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate: Option<f64>,
}

impl PayloadEvent {
    fn need(&self, field: &str, v: Option<f64>) -> Result<f64, ConfigError> {
        let v = v.ok_or_else(|| {
            ConfigError::new(
                field,
                format!("is required for action {:?}", self.action_name()),
            )
        })?;
        positive(field, v)?;
        Ok(v)
    }

    fn forbid(&self, field: &str, v: Option<f64>) -> Result<(), ConfigError> {
        match v {
            Some(_) => Err(ConfigError::new(
                field,
                format!("is not used by action {:?}", self.action_name()),
            )),
            None => Ok(()),
        }
    }

    fn action_name(&self) -> &'static str {
        match self.action {
            PayloadAction::Attach => "attach",
            PayloadAction::Detach => "detach",
            PayloadAction::Mass => "mass",
            PayloadAction::Winch => "winch",
            PayloadAction::VehicleMass => "vehicle_mass",
        }
    }

    /// Check the fields this action needs (and that it has no others).
    pub fn validate(&self) -> Result<(), ConfigError> {
        non_negative("t", self.t)?;
        match self.action {
            PayloadAction::Attach => {
                self.need("mass", self.mass)?;
                self.need("length", self.length)?;
                self.forbid("rate", self.rate)?;
            }
            PayloadAction::Detach => {
                self.forbid("mass", self.mass)?;
                self.forbid("length", self.length)?;
                self.forbid("rate", self.rate)?;
            }
            PayloadAction::Mass | PayloadAction::VehicleMass => {
                self.need("mass", self.mass)?;
                self.forbid("length", self.length)?;
                self.forbid("rate", self.rate)?;
            }
            PayloadAction::Winch => {
                self.forbid("mass", self.mass)?;
                self.need("length", self.length)?;
                self.need("rate", self.rate)?;
            }
        }
        Ok(())
    }
}

/// Check a payload's events in time order: each one's fields, and that it applies to the
/// payload present at its time (attach only without a payload, the others only with a
/// single one). Errors name `events[i].<field>`. Returns the largest total mass
/// (vehicle + payload) [kg] the events reach, for the hover-thrust check.
pub fn check_events(payload: &PayloadParams, vehicle_mass: f64) -> Result<f64, ConfigError> {
    let mut kind = payload.kind;
    let mut mass = payload.total_mass();
    let mut vehicle = vehicle_mass;
    let mut heaviest = vehicle + mass;
    let mut last_t = 0.0;
    for (i, e) in payload.events.iter().enumerate() {
        let at = |err: ConfigError| err.within(&format!("events[{i}]"));
        e.validate().map_err(at)?;
        if e.t < last_t {
            return Err(at(ConfigError::new(
                "t",
                format!("events must be in time order ({} s after {last_t} s)", e.t),
            )));
        }
        last_t = e.t;
        let has = match kind {
            PayloadKind::None => false,
            PayloadKind::Single => true,
            PayloadKind::Double => {
                return Err(at(ConfigError::new(
                    "action",
                    "payload events need a single or no payload, not a double pendulum",
                )))
            }
        };
        match e.action {
            PayloadAction::Attach if has => {
                return Err(at(ConfigError::new(
                    "action",
                    "attach needs no payload at that time (detach the present one first)",
                )))
            }
            PayloadAction::Detach | PayloadAction::Mass | PayloadAction::Winch if !has => {
                return Err(at(ConfigError::new(
                    "action",
                    format!("{} needs a payload at that time", e.action_name()),
                )))
            }
            _ => {}
        }
        match e.action {
            PayloadAction::Attach => {
                kind = PayloadKind::Single;
                mass = e.mass.unwrap_or(0.0);
            }
            PayloadAction::Detach => {
                kind = PayloadKind::None;
                mass = 0.0;
            }
            PayloadAction::Mass => mass = e.mass.unwrap_or(mass),
            PayloadAction::Winch => {}
            PayloadAction::VehicleMass => vehicle = e.mass.unwrap_or(vehicle),
        }
        heaviest = heaviest.max(vehicle + mass);
    }
    Ok(heaviest)
}

/// Apply the payload events of `model.payload` that fall in the physics step [t, t + dt)
/// to the model and the state, and move an active winch by one step (see module docs).
/// Returns whether anything changed. Call once per physics step before integrating it.
pub fn apply_payload_events(model: &mut Model, state: &mut PlantState, t: f64, dt: f64) -> bool {
    let eps = 1e-9 * dt.max(1e-12);
    let mut changed = false;
    let count = model.payload.events.len();
    let mut latest = None;
    for i in 0..count {
        let e = &model.payload.events[i];
        if e.t > t + dt - eps {
            break;
        }
        latest = Some(i);
        if e.t >= t - eps {
            let e = e.clone();
            fire(model, state, &e);
            changed = true;
        }
    }
    // A winch runs from its time until the next event or until the length is reached.
    if let Some(i) = latest {
        let e = &model.payload.events[i];
        if e.action == PayloadAction::Winch && model.links() == 1 {
            let (target, rate) = (e.length.unwrap_or(0.0), e.rate.unwrap_or(0.0));
            let l = model.payload.length;
            if (target - l).abs() > 0.0 {
                let start = e.t.max(t);
                let span = (t + dt - start).max(0.0);
                let dl = (rate * span).min((target - l).abs());
                model.set_length(l + dl * (target - l).signum());
                changed = true;
            }
        }
    }
    changed
}

fn fire(model: &mut Model, state: &mut PlantState, e: &PayloadEvent) {
    match e.action {
        PayloadAction::Attach => {
            let (m, l) = (e.mass.unwrap_or(0.0), e.length.unwrap_or(0.0));
            let mq = model.vehicle.mass;
            let down = nalgebra::Vector3::new(0.0, 0.0, 1.0);
            // Inelastic pick-up along the vertical cable: the shared vertical velocity keeps
            // the vertical momentum; across the cable nothing is transmitted.
            let vz = state.vel.z * mq / (mq + m);
            let v_perp = nalgebra::Vector3::new(state.vel.x, state.vel.y, 0.0);
            state.vel.z = vz;
            state.n[0] = down;
            state.ndot[0] = -v_perp / l;
            let mut p = model.payload.clone();
            p.kind = PayloadKind::Single;
            p.mass = m;
            p.length = l;
            p.initial_swing_n = 0.0;
            p.initial_swing_e = 0.0;
            model.set_payload(p);
        }
        PayloadAction::Detach => {
            let mut p = model.payload.clone();
            p.kind = PayloadKind::None;
            model.set_payload(p);
        }
        PayloadAction::Mass => {
            let mut p = model.payload.clone();
            p.mass = e.mass.unwrap_or(p.mass);
            model.set_payload(p);
        }
        PayloadAction::Winch => {}
        PayloadAction::VehicleMass => {
            let mass = e.mass.unwrap_or(model.vehicle.mass);
            model.set_vehicle_mass(mass);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::{Effects, StepInput, VehicleParams, GRAVITY};
    use nalgebra::Vector3;

    fn ev(t: f64, action: PayloadAction) -> PayloadEvent {
        PayloadEvent {
            t,
            action,
            mass: None,
            length: None,
            rate: None,
        }
    }

    #[test]
    fn pick_up_conserves_momentum_along_the_cable() {
        let payload = PayloadParams {
            kind: PayloadKind::None,
            events: vec![PayloadEvent {
                mass: Some(0.3),
                length: Some(1.5),
                ..ev(1.0, PayloadAction::Attach)
            }],
            ..PayloadParams::default()
        };
        let mut model = Model::new(VehicleParams::default(), payload);
        let mut s = PlantState::at_rest(Vector3::zeros(), 2.0, 0.0, 0.0);
        s.vel = Vector3::new(2.0, -1.0, 0.5);
        assert!(!apply_payload_events(&mut model, &mut s, 0.5, 0.001));
        assert_eq!(model.links(), 0);
        assert!(apply_payload_events(&mut model, &mut s, 1.0, 0.001));
        assert_eq!(model.links(), 1);
        let (mq, mp) = (0.952, 0.3);
        // Vertical momentum m_Q·0.5 is shared; horizontal vehicle velocity unchanged.
        let vp = s.payload_velocity(&model.payload, 0);
        assert!((s.vel.z * (mq + mp) - 0.5 * mq).abs() < 1e-12);
        assert!(
            (vp - Vector3::new(0.0, 0.0, s.vel.z)).norm() < 1e-12,
            "{vp:?}"
        );
        assert_eq!((s.vel.x, s.vel.y), (2.0, -1.0));
        // Applied once only.
        assert!(!apply_payload_events(&mut model, &mut s, 1.001, 0.001));
    }

    #[test]
    fn winch_moves_the_length_at_its_rate_and_stops_at_the_target() {
        let payload = PayloadParams {
            length: 2.0,
            events: vec![PayloadEvent {
                length: Some(0.5),
                rate: Some(0.3),
                ..ev(1.0, PayloadAction::Winch)
            }],
            ..PayloadParams::default()
        };
        let mut model = Model::new(VehicleParams::default(), payload);
        let mut s = PlantState::at_rest(Vector3::zeros(), 2.0, 0.0, 0.0);
        let h = 0.001;
        let mut t = 0.0;
        let mut at_3s = 0.0;
        for k in 0..8000 {
            t = k as f64 * h;
            apply_payload_events(&mut model, &mut s, t, h);
            if k == 2999 {
                at_3s = model.payload.length;
            }
        }
        assert!((at_3s - (2.0 - 0.3 * 2.0)).abs() < 1e-9, "{at_3s}");
        assert!((model.payload.length - 0.5).abs() < 1e-12, "t {t}");
    }

    #[test]
    fn detach_and_mass_change_keep_velocities_and_change_the_weight() {
        let payload = PayloadParams {
            events: vec![
                PayloadEvent {
                    mass: Some(0.1),
                    ..ev(0.0, PayloadAction::Mass)
                },
                PayloadEvent {
                    mass: Some(0.7),
                    ..ev(0.0, PayloadAction::VehicleMass)
                },
                ev(1.0, PayloadAction::Detach),
            ],
            ..PayloadParams::default()
        };
        let mut model = Model::new(VehicleParams::default(), payload);
        let mut s = PlantState::at_rest(Vector3::zeros(), 2.0, 0.0, 0.0);
        s.vel = Vector3::new(1.0, 0.0, 0.0);
        apply_payload_events(&mut model, &mut s, 0.0, 0.001);
        assert!((model.total_mass() - 0.8).abs() < 1e-12);
        assert_eq!(s.vel, Vector3::new(1.0, 0.0, 0.0));
        apply_payload_events(&mut model, &mut s, 1.0, 0.001);
        assert_eq!(model.links(), 0);
        // Free fall of the bare vehicle with rotors off: a = g exactly.
        let fx = Effects {
            drag: false,
            friction: false,
            rotors: false,
        };
        let d = model.derivative(&s, &StepInput::default(), fx);
        assert!((d.vel.z - GRAVITY).abs() < 1e-12);
    }

    #[test]
    fn events_are_checked_in_order_and_name_the_field() {
        let mut p = PayloadParams {
            kind: PayloadKind::None,
            events: vec![ev(1.0, PayloadAction::Detach)],
            ..PayloadParams::default()
        };
        let e = check_events(&p, 1.0).unwrap_err();
        assert_eq!(e.field, "events[0].action");
        p.events = vec![ev(1.0, PayloadAction::Attach)];
        assert_eq!(check_events(&p, 1.0).unwrap_err().field, "events[0].mass");
        p.events = vec![PayloadEvent {
            mass: Some(0.3),
            length: Some(-1.0),
            ..ev(1.0, PayloadAction::Attach)
        }];
        assert_eq!(check_events(&p, 1.0).unwrap_err().field, "events[0].length");
        p.events = vec![
            PayloadEvent {
                mass: Some(0.3),
                length: Some(1.0),
                ..ev(1.0, PayloadAction::Attach)
            },
            PayloadEvent {
                rate: Some(0.3),
                ..ev(0.5, PayloadAction::Detach)
            },
        ];
        assert_eq!(check_events(&p, 1.0).unwrap_err().field, "events[1].rate");
        p.events[1].rate = None;
        assert_eq!(check_events(&p, 1.0).unwrap_err().field, "events[1].t");
        p.events[1].t = 2.0;
        assert!((check_events(&p, 1.0).unwrap() - 1.3).abs() < 1e-12);
    }
}
