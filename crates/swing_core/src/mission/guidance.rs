//! Guidance: what the vehicle should do, instant by instant, to fly a [`Mission`].
//!
//! A [`Guidance`] turns the mission and the measured vehicle position into a trajectory
//! setpoint (position, velocity, acceleration and jerk, NED) at every position-loop tick,
//! reports the mission's events (an item reached, left; the mission complete) and, for
//! controllers that plan ahead, previews the reference over the coming ticks.
//!
//! Two behaviours:
//! * [`SmoothGuidance`] (swingrt's): every leg is a straight rest-to-rest double-S profile
//!   ([`super::profile::SCurve`]) at the leg's speed with swingrt's acceleration and jerk
//!   limits. The hold at an item starts when the *vehicle* is within the item's
//!   acceptance radius (horizontally, and within the altitude acceptance vertically) — as
//!   PX4 counts it — and the next leg starts when the hold is over (never before the
//!   reference itself has arrived). The whole future is a closed form, so the preview is
//!   exact up to the one unknown, the vehicle's arrival: until it is seen, the preview
//!   assumes the vehicle arrives with the reference (or now, if later). The preview ends
//!   at the first hold ahead: beyond it the reference stays on that item, so that a
//!   controller planning ahead keeps the vehicle and payload still for the whole hold
//!   (a delivery's drop) instead of leaning into the next leg before the hold is over.
//! * [`super::px4::Px4Guidance`]: PX4's own mission behaviour (its navigator and
//!   jerk-limited trajectory), the baseline.

use serde::{Deserialize, Serialize};

use super::plan::{ItemKind, Mission};
use super::profile::SCurve;
use super::px4::Px4MissionParams;
use crate::config::{in_range, positive, ConfigError};

/// A trajectory setpoint, NED.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TrajectorySetpoint {
    /// Position [m].
    pub p: [f64; 3],
    /// Velocity [m/s].
    pub v: [f64; 3],
    /// Acceleration [m/s²].
    pub a: [f64; 3],
    /// Jerk [m/s³].
    pub j: [f64; 3],
}

impl TrajectorySetpoint {
    /// At rest at `p`.
    pub fn at_rest(p: [f64; 3]) -> Self {
        Self {
            p,
            ..Self::default()
        }
    }
}

/// What happened in a mission.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// The mission started (item: the first item).
    Started,
    /// The vehicle reached the item (its hold starts).
    Reached,
    /// The vehicle left the item for the next one (its hold is over).
    Left,
    /// The last item's hold is over: the mission is complete.
    Completed,
}

impl EventKind {
    /// Short name (`started`, `reached`, `left`, `completed`).
    pub fn name(self) -> &'static str {
        match self {
            EventKind::Started => "started",
            EventKind::Reached => "reached",
            EventKind::Left => "left",
            EventKind::Completed => "completed",
        }
    }
}

/// One event of a mission.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MissionEvent {
    /// Time [s].
    pub t: f64,
    /// Index of the item in [`Mission::items`].
    pub item: usize,
    /// What happened.
    pub kind: EventKind,
}

/// Which guidance flies the mission.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GuidanceMode {
    /// swingrt's rest-to-rest legs with an exact preview ([`SmoothGuidance`]).
    #[default]
    Smooth,
    /// PX4's mission behaviour ([`super::px4::Px4Guidance`]).
    Px4,
}

/// Settings of the guidance (both behaviours).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GuidanceSettings {
    /// `smooth` (swingrt's legs) or `px4` (PX4's mission behaviour).
    pub mode: GuidanceMode,
    /// Smooth: largest acceleration along a leg [m/s²].
    pub acc_max: f64,
    /// Smooth: largest jerk along a leg [m/s³].
    pub jerk_max: f64,
    /// Largest climb rate in automatic flight (PX4 `MPC_Z_V_AUTO_UP`) [m/s].
    pub climb_rate: f64,
    /// Largest descent rate in automatic flight (PX4 `MPC_Z_V_AUTO_DN`) [m/s].
    pub descent_rate: f64,
    /// Vertical distance within which an item counts as reached (PX4 `NAV_MC_ALT_RAD`) [m].
    pub alt_acceptance_radius: f64,
    /// PX4's parameters of its mission behaviour (mode `px4`).
    pub px4: Px4MissionParams,
}

impl Default for GuidanceSettings {
    fn default() -> Self {
        Self {
            mode: GuidanceMode::Smooth,
            // A quasi-static swing of atan(a/g) = 9° at the peak, and a jerk ramp of 1 s,
            // longer than a third of the swing period of a cable of 0.5 m or more; the
            // payload then never sees a step of acceleration.
            acc_max: 1.6,
            jerk_max: 1.6,
            climb_rate: 3.0,
            descent_rate: 1.5,
            alt_acceptance_radius: 0.8,
            px4: Px4MissionParams::default(),
        }
    }
}

impl GuidanceSettings {
    /// Check the limits; errors name the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        in_range("acc_max", self.acc_max, 0.05, 10.0)?;
        in_range("jerk_max", self.jerk_max, 0.05, 50.0)?;
        positive("climb_rate", self.climb_rate)?;
        positive("descent_rate", self.descent_rate)?;
        in_range(
            "alt_acceptance_radius",
            self.alt_acceptance_radius,
            0.05,
            50.0,
        )?;
        self.px4.validate().map_err(|e| e.within("px4"))?;
        Ok(())
    }

    /// The guidance these settings describe, for `mission`.
    pub fn build(&self, mission: &Mission) -> Result<Box<dyn Guidance>, ConfigError> {
        self.validate()?;
        Ok(match self.mode {
            GuidanceMode::Smooth => Box::new(SmoothGuidance::new(mission.clone(), self.clone())),
            GuidanceMode::Px4 => {
                Box::new(super::px4::Px4Guidance::new(mission.clone(), self.clone()))
            }
        })
    }
}

/// A mission's guidance (module docs).
pub trait Guidance: Send {
    /// Begin the mission at time `t` [s] from the vehicle position `pos` and velocity `vel`
    /// (NED).
    fn start(&mut self, t: f64, pos: &[f64; 3], vel: &[f64; 3]);
    /// One position-loop tick at time `t` (after a step of `dt` [s]) with the measured
    /// position and velocity: the setpoint to fly now.
    fn update(&mut self, t: f64, dt: f64, pos: &[f64; 3], vel: &[f64; 3]) -> TrajectorySetpoint;
    /// The reference at t + k·dt for every k of `out` (k = 0: now) as it is known after the
    /// last [`Guidance::update`]; guidances that cannot look ahead continue the last
    /// setpoint's motion. Allocates nothing.
    fn preview(&self, t: f64, dt: f64, out: &mut [TrajectorySetpoint]);
    /// Whether the mission is complete.
    fn done(&self) -> bool;
    /// The events so far.
    fn events(&self) -> &[MissionEvent];
    /// The mission flown.
    fn mission(&self) -> &Mission;
    /// Acceleration bound of the leg flown now [m/s²], if the mission sets one.
    fn acc_limit(&self) -> Option<f64> {
        None
    }
}

/// The guidance's preview laid out for a position-tracking controller
/// ([`crate::control::ReferencePreview`]): sized once, refilled every tick without
/// allocating.
#[derive(Clone, Debug)]
pub struct PreviewBuffer {
    setpoints: Vec<TrajectorySetpoint>,
    data: Vec<f64>,
    axes: usize,
}

impl PreviewBuffer {
    /// A buffer of `steps` steps for `axes` horizontal axes (North, then East).
    pub fn new(steps: usize, axes: usize) -> Self {
        Self {
            setpoints: vec![TrajectorySetpoint::default(); steps],
            data: vec![0.0; steps * axes * 4],
            axes,
        }
    }

    /// Number of steps.
    pub fn steps(&self) -> usize {
        self.setpoints.len()
    }

    /// Fill from `guidance` at time `t` every `dt` [s] and view it as a controller reads it.
    pub fn fill(
        &mut self,
        guidance: &dyn Guidance,
        t: f64,
        dt: f64,
    ) -> crate::control::ReferencePreview<'_> {
        guidance.preview(t, dt, &mut self.setpoints);
        let axes = self.axes;
        for (k, sp) in self.setpoints.iter().enumerate() {
            for i in 0..axes {
                let o = (k * axes + i) * 4;
                self.data[o] = sp.p[i];
                self.data[o + 1] = sp.v[i];
                self.data[o + 2] = sp.a[i];
                self.data[o + 3] = sp.j[i];
            }
        }
        crate::control::ReferencePreview {
            steps: self.setpoints.len(),
            axes,
            data: &self.data,
            acc_limit: guidance.acc_limit(),
        }
    }
}

/// Horizontal distance between two NED points [m].
pub(crate) fn dist_xy(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Whether the vehicle at `pos` has reached item `k` of `mission` (PX4's rule:
/// horizontally within the item's acceptance radius, vertically within `alt_radius`).
pub(crate) fn reached(mission: &Mission, k: usize, pos: &[f64; 3], alt_radius: f64) -> bool {
    let it = &mission.items[k];
    dist_xy(pos, &it.position) <= it.acceptance_radius
        && (pos[2] - it.position[2]).abs() <= alt_radius
}

/// One straight leg of [`SmoothGuidance`].
#[derive(Clone, Copy, Debug)]
struct Leg {
    from: [f64; 3],
    dir: [f64; 3],
    profile: SCurve,
}

impl Leg {
    fn new(from: [f64; 3], to: [f64; 3], speed: f64, st: &GuidanceSettings) -> Self {
        let d = [to[0] - from[0], to[1] - from[1], to[2] - from[2]];
        let length = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let dir = if length > 1e-9 {
            [d[0] / length, d[1] / length, d[2] / length]
        } else {
            [0.0; 3]
        };
        // The leg speed is horizontal (as PX4's cruise speed); the vertical part is
        // limited by the climb or descent rate.
        let horiz = dir[0].hypot(dir[1]);
        let mut v = if horiz > 1e-9 {
            speed / horiz
        } else {
            f64::INFINITY
        };
        if dir[2].abs() > 1e-9 {
            let rate = if dir[2] < 0.0 {
                st.climb_rate
            } else {
                st.descent_rate
            };
            v = v.min(rate / dir[2].abs());
        }
        if !v.is_finite() {
            v = speed;
        }
        Self {
            from,
            dir,
            profile: SCurve::new(length, v, st.acc_max, st.jerk_max),
        }
    }

    fn at(&self, tau: f64) -> TrajectorySetpoint {
        let q = self.profile.at(tau);
        let mut sp = TrajectorySetpoint::default();
        for i in 0..3 {
            sp.p[i] = self.from[i] + q.s * self.dir[i];
            sp.v[i] = q.v * self.dir[i];
            sp.a[i] = q.a * self.dir[i];
            sp.j[i] = q.j * self.dir[i];
        }
        sp
    }
}

/// swingrt's guidance: rest-to-rest legs with an exact preview (module docs).
pub struct SmoothGuidance {
    mission: Mission,
    settings: GuidanceSettings,
    legs: Vec<Leg>,
    /// The leg flown now (towards item `k`).
    k: usize,
    /// Its departure time [s].
    dep: f64,
    /// When the vehicle reached item `k`, if it has.
    arrived: Option<f64>,
    started: bool,
    done: bool,
    start_pos: [f64; 3],
    events: Vec<MissionEvent>,
}

impl SmoothGuidance {
    /// The guidance for `mission` (settings already checked).
    pub fn new(mission: Mission, settings: GuidanceSettings) -> Self {
        let n = mission.items.len();
        let start_pos = mission.start();
        Self {
            mission,
            settings,
            legs: Vec::with_capacity(n),
            k: 0,
            dep: 0.0,
            arrived: None,
            started: false,
            done: false,
            start_pos,
            events: Vec::with_capacity(3 * n + 2),
        }
    }

    /// When the hold at item `j` ends, given its arrival (assumed, if not seen yet, to be
    /// with the reference or `now`, whichever is later).
    fn hold_end(&self, j: usize, dep: f64, arrived: Option<f64>, now: f64) -> f64 {
        let ref_end = dep + self.legs[j].profile.duration();
        let arrival = arrived.unwrap_or_else(|| ref_end.max(now));
        (arrival + self.mission.items[j].hold).max(ref_end)
    }

    /// The reference at time `tau` as known at time `now`; with `past_holds` false, at rest
    /// on the first item with a hold ahead for every `tau` after that hold (the preview).
    fn reference(&self, tau: f64, now: f64, past_holds: bool) -> TrajectorySetpoint {
        if !self.started {
            return TrajectorySetpoint::at_rest(self.start_pos);
        }
        if self.done {
            let last = self.mission.items.len() - 1;
            return TrajectorySetpoint::at_rest(self.mission.items[last].position);
        }
        let mut j = self.k;
        let mut dep = self.dep;
        let mut arrived = self.arrived;
        loop {
            let end = self.hold_end(j, dep, arrived, now);
            if tau < end || j + 1 == self.legs.len() {
                return self.legs[j].at(tau - dep);
            }
            if !past_holds && self.mission.items[j].hold > 0.0 {
                return TrajectorySetpoint::at_rest(self.mission.items[j].position);
            }
            j += 1;
            dep = end;
            arrived = None;
        }
    }
}

impl Guidance for SmoothGuidance {
    fn start(&mut self, t: f64, pos: &[f64; 3], _vel: &[f64; 3]) {
        self.legs.clear();
        let mut from = *pos;
        for it in &self.mission.items {
            self.legs
                .push(Leg::new(from, it.position, it.speed, &self.settings));
            from = it.position;
        }
        self.start_pos = *pos;
        self.k = 0;
        self.dep = t;
        self.arrived = None;
        self.started = true;
        self.done = false;
        self.events.clear();
        self.events.push(MissionEvent {
            t,
            item: 0,
            kind: EventKind::Started,
        });
    }

    fn update(&mut self, t: f64, _dt: f64, pos: &[f64; 3], _vel: &[f64; 3]) -> TrajectorySetpoint {
        if self.started && !self.done {
            // Zero-length legs (a takeoff from its own altitude) pass in the same tick.
            for _ in 0..self.legs.len() {
                let k = self.k;
                if self.arrived.is_none()
                    && t >= self.dep
                    && reached(&self.mission, k, pos, self.settings.alt_acceptance_radius)
                {
                    self.arrived = Some(t);
                    self.events.push(MissionEvent {
                        t,
                        item: k,
                        kind: EventKind::Reached,
                    });
                }
                let Some(_) = self.arrived else { break };
                let end = self.hold_end(k, self.dep, self.arrived, t);
                if t < end {
                    break;
                }
                let last = k + 1 == self.legs.len();
                self.events.push(MissionEvent {
                    t,
                    item: k,
                    kind: if last {
                        EventKind::Completed
                    } else {
                        EventKind::Left
                    },
                });
                if last {
                    self.done = true;
                    break;
                }
                self.k += 1;
                self.dep = end;
                self.arrived = None;
            }
        }
        self.reference(t, t, true)
    }

    fn preview(&self, t: f64, dt: f64, out: &mut [TrajectorySetpoint]) {
        for (k, o) in out.iter_mut().enumerate() {
            *o = self.reference(t + k as f64 * dt, t, false);
        }
    }

    fn done(&self) -> bool {
        self.done
    }

    fn events(&self) -> &[MissionEvent] {
        &self.events
    }

    fn mission(&self) -> &Mission {
        &self.mission
    }
}

/// Whether `kind` ends the leg at rest (a hold, a landing, the last item).
pub(crate) fn stops_at(mission: &Mission, k: usize) -> bool {
    let it = &mission.items[k];
    it.hold > 0.0 || it.kind == ItemKind::Land || k + 1 == mission.items.len()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mission::plan::MissionItem;

    fn square() -> Mission {
        let wp = |n: f64, e: f64, hold: f64, source: usize| MissionItem {
            kind: ItemKind::Waypoint,
            position: [n, e, -10.0],
            hold,
            acceptance_radius: 0.5,
            speed: 5.0,
            source,
        };
        Mission {
            name: "square".into(),
            home: None,
            items: vec![
                wp(30.0, 0.0, 5.0, 0),
                wp(30.0, 40.0, 5.0, 1),
                wp(0.0, 40.0, 0.0, 2),
            ],
        }
    }

    #[test]
    fn a_vehicle_on_the_reference_flies_every_leg_and_holds_from_its_arrival() {
        let m = square();
        let st = GuidanceSettings::default();
        let mut g = SmoothGuidance::new(m.clone(), st.clone());
        let start = [0.0, 0.0, -10.0];
        g.start(0.0, &start, &[0.0; 3]);
        let dt = 0.02;
        let mut t = 0.0;
        let mut pos = start;
        let mut prev = g.update(0.0, dt, &pos, &[0.0; 3]);
        while !g.done() && t < 200.0 {
            t += dt;
            let sp = g.update(t, dt, &pos, &[0.0; 3]);
            // Continuous position, bounded acceleration along the path.
            let jump = dist_xy(&sp.p, &prev.p);
            assert!(jump <= 5.0 * dt + 1e-9, "t = {t}: jump {jump}");
            assert!(sp.a[0].hypot(sp.a[1]) <= st.acc_max + 1e-9);
            pos = sp.p; // a perfect tracker
            prev = sp;
        }
        assert!(g.done());
        let ev: Vec<_> = g.events().iter().map(|e| (e.item, e.kind)).collect();
        use EventKind::*;
        assert_eq!(
            ev,
            [
                (0, Started),
                (0, Reached),
                (0, Left),
                (1, Reached),
                (1, Left),
                (2, Reached),
                (2, Completed)
            ]
        );
        // Each hold lasts its hold time from the arrival.
        let when = |item, kind| {
            g.events()
                .iter()
                .find(|e| e.item == item && e.kind == kind)
                .unwrap()
                .t
        };
        assert!((when(0, Left) - when(0, Reached) - 5.0).abs() < dt + 1e-9);
        // Leg 1 (30 m at 5 m/s, 1.6 m/s², 1.6 m/s³) takes its profile's time to the radius.
        let p = SCurve::new(30.0, 5.0, 1.6, 1.6);
        assert!(when(0, Reached) < p.duration() && when(0, Reached) > p.duration() - 2.0);
    }

    #[test]
    fn the_preview_is_the_future_reference_and_waits_for_a_late_vehicle() {
        let m = square();
        let mut g = SmoothGuidance::new(m, GuidanceSettings::default());
        g.start(0.0, &[0.0, 0.0, -10.0], &[0.0; 3]);
        let dt = 0.03;
        let mut out = [TrajectorySetpoint::default(); 100];
        g.update(1.0, dt, &[0.0, 0.0, -10.0], &[0.0; 3]);
        g.preview(1.0, dt, &mut out);
        // On the first leg, the preview is the profile itself.
        let leg = SCurve::new(30.0, 5.0, 1.6, 1.6);
        for (k, o) in out.iter().enumerate() {
            let q = leg.at(1.0 + k as f64 * dt);
            assert!((o.p[0] - q.s).abs() < 1e-12 && (o.v[0] - q.v).abs() < 1e-12);
        }
        // The vehicle lags 3 m behind at the end of the leg: the reference waits at the
        // waypoint (no departure while the vehicle has not arrived).
        let t_end = leg.duration() + 4.0;
        let sp = g.update(t_end, dt, &[27.0, 0.0, -10.0], &[0.0; 3]);
        assert_eq!(sp.p, [30.0, 0.0, -10.0]);
        g.preview(t_end, dt, &mut out);
        assert!(out.iter().all(|o| o.p == [30.0, 0.0, -10.0]));
        // It arrives: the next leg starts 5 s later. Until the hold is over the preview
        // stays on the waypoint, past the hold's end too (a hold is held still), and once
        // it is over the preview is the next leg.
        g.update(t_end + dt, dt, &[29.8, 0.0, -10.0], &[0.0; 3]);
        g.update(t_end + 3.0, dt, &[30.0, 0.0, -10.0], &[0.0; 3]);
        g.preview(t_end + 3.0, dt, &mut out);
        assert!(out
            .iter()
            .all(|o| o.p == [30.0, 0.0, -10.0] && o.v == [0.0; 3]));
        let departs = t_end + dt + 5.0;
        let sp = g.update(departs + 0.5, dt, &[30.0, 0.0, -10.0], &[0.0; 3]);
        assert!(sp.p[1] > 0.0, "the next leg started");
        g.preview(departs + 0.5, dt, &mut out);
        let next = SCurve::new(40.0, 5.0, 1.6, 1.6);
        for (k, o) in out.iter().enumerate() {
            let q = next.at(0.5 + k as f64 * dt);
            assert!((o.p[1] - q.s).abs() < 1e-9, "k {k}");
        }
    }
}
