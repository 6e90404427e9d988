//! The twin path's policy on the tick side: when the payload measured in flight (cable
//! length from the pendulum's equation, total mass from the thrust) asks for a
//! re-identification on the vehicle's twin, and when a mass change asks for probing.

use crate::sysid::payload::PayloadTracker;

/// Smallest payload mass the twin re-identifies for [kg]: below it the swing carries no
/// dynamics to identify (the payload is gone).
pub const MIN_PAYLOAD_MASS: f64 = 0.02;

/// Standard errors by which a measured length must depart from the model's to act on it.
pub const LENGTH_SIGNIFICANCE: f64 = 3.0;

/// Spread of the total-mass estimate over the settle window below which it counts as
/// settled [kg].
pub const MASS_SETTLED_KG: f64 = 0.01;

/// The twin path's state on the tick side.
#[derive(Clone, Copy, Debug)]
pub(super) struct TwinState {
    pub(super) settings_length_change: f64,
    pub(super) confidence: f64,
    pub(super) mass_change: f64,
    pub(super) probe_ticks: u64,
    pub(super) vehicle_mass: f64,
    /// Payload (mass [kg], length [m]) the active model was identified for.
    pub(super) reference: [f64; 2],
    /// Measured total mass when the active model was adopted (NaN until measured).
    pub(super) mass_at_reference: f64,
    /// Payload of the candidate in the synthesis.
    pub(super) pending: [f64; 2],
    /// Probe until this tick (0 = not probing).
    pub(super) probe_until: u64,
    /// No new twin request before this tick (after a rejection).
    pub(super) retry_at: u64,
}

/// What the twin path decides on one tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum TwinDecision {
    /// Nothing to do.
    Wait,
    /// The total mass changed by more than `mass_change` [kg]: probe until the length is
    /// confirmed (the tracker has restarted).
    MassChanged(f64),
    /// Re-identify on the twin with this payload (mass [kg], length [m]).
    Request([f64; 2]),
}

impl TwinState {
    /// The twin path's bookkeeping of one tick (`tick`; `busy`: a synthesis is running;
    /// `suspended`: adaptation has stopped for the flight).
    pub(super) fn decide(
        &mut self,
        tracker: &mut PayloadTracker,
        tick: u64,
        busy: bool,
        suspended: bool,
    ) -> TwinDecision {
        let mass = tracker.total_mass();
        if let Some(m) = mass {
            if self.mass_at_reference.is_nan() {
                self.mass_at_reference = m;
            } else if (m - self.mass_at_reference).abs() > self.mass_change
                && self.probe_until == 0
                && !busy
            {
                self.probe_until = tick + self.probe_ticks;
                // The old swing says nothing about the new payload.
                tracker.restart();
                self.mass_at_reference = m;
                return TwinDecision::MassChanged(m);
            }
        }
        let Some((length, rel)) = tracker.length() else {
            return TwinDecision::Wait;
        };
        if rel > self.confidence {
            return TwinDecision::Wait;
        }
        self.probe_until = 0; // the length is confirmed
        if busy || suspended || tick < self.retry_at {
            return TwinDecision::Wait;
        }
        // Act on a length that departs from the model's by more than the tolerance and by
        // more than LENGTH_SIGNIFICANCE standard errors: in a transient the residual of the
        // pendulum equation (sensor lag, large angles) widens the error bar long after the
        // estimate itself has converged.
        let departure = (length - self.reference[1]).abs();
        if departure <= self.settings_length_change * self.reference[1]
            || departure <= LENGTH_SIGNIFICANCE * rel * length
        {
            return TwinDecision::Wait;
        }
        // A new length is a new payload (or the same one winched): the mass change since
        // the model's payload is the payload's. A mass change at an unchanged length is
        // taken as the vehicle's, which PX4's hover thrust absorbs.
        let payload_mass = match mass {
            // Wait until a pick-up's thrust step has settled in the estimate.
            Some(_) if !tracker.mass_settled(MASS_SETTLED_KG) => return TwinDecision::Wait,
            Some(m) => m - self.vehicle_mass,
            None => self.reference[0],
        };
        if payload_mass >= MIN_PAYLOAD_MASS {
            TwinDecision::Request([payload_mass, length])
        } else {
            TwinDecision::Wait
        }
    }
}
