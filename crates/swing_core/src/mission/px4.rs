//! PX4's mission behaviour for a multicopter, the baseline swingrt's missions are judged
//! against: its navigator (which item is the target, when it is reached, the hold) and its
//! auto-mode trajectory (PX4's `FlightTaskAuto` with `PositionSmoothing`), written here from
//! their rules, not their code.
//!
//! Each position-loop tick:
//! 1. **Navigator.** An item is reached when the vehicle is within its acceptance radius
//!    horizontally and `NAV_MC_ALT_RAD` vertically; its hold time counts from then; then
//!    the next item becomes the target and the reached one the previous waypoint. A
//!    rotary-wing vehicle brakes at an item with a hold (the next item is withheld from the
//!    trajectory: "brake for hold"), at a landing and at the last item; otherwise the next
//!    item shapes the corner.
//! 2. **Velocity target.** Towards the target (or, while turning onto the leg, towards
//!    the point of the leg at 5 m, at least the acceptance radius, from the trajectory: L1
//!    guidance), at the largest horizontal speed from which the jerk-limited braking still
//!    meets the speed allowed at the target:
//!    [`super::smoothing::max_speed_from_distance`], with the corner speed
//!    [`super::smoothing::max_speed_in_corner`] at `MPC_XY_TRAJ_P` × `MPC_ACC_HOR` when
//!    the vehicle does not stop there, capped by the leg's cruise speed; the speed is not
//!    raised while turning. Vertically alike with the climb/descent limits.
//! 3. **Trajectory.** Three jerk-limited axes ([`super::smoothing::VelocitySmoothing`],
//!    `MPC_JERK_AUTO`, `MPC_ACC_HOR`) advance by the tick — slowed in proportion to how far
//!    the vehicle lags behind them, to a stop at `MPC_XY_ERR_MAX` — and their state is the
//!    setpoint (position, velocity and acceleration feed-forward for PX4's position
//!    control); then they are re-planned towards the new velocity target, synchronised.
//!
//! Not modelled: yaw (PX4 turns the heading towards the target; swingrt's vehicles hold
//! theirs), the track-recovery states for a vehicle far off its leg, and emergency braking.

use serde::{Deserialize, Serialize};

use super::guidance::{
    dist_xy, reached, stops_at, EventKind, Guidance, GuidanceSettings, MissionEvent,
    TrajectorySetpoint,
};
use super::plan::Mission;
use super::smoothing::{max_speed_from_distance, max_speed_in_corner, VelocitySmoothing};
use crate::config::{in_range, positive, ConfigError};

/// PX4's parameters of its auto-mode trajectory (defaults: PX4's multicopter defaults).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Px4MissionParams {
    /// Largest horizontal acceleration (`MPC_ACC_HOR`) [m/s²].
    pub acc_hor: f64,
    /// Largest jerk (`MPC_JERK_AUTO`) [m/s³].
    pub jerk: f64,
    /// Fraction of `acc_hor` used as lateral acceleration in corners (`MPC_XY_TRAJ_P`) [-].
    pub xy_traj_p: f64,
    /// Lag of the vehicle behind the trajectory at which the trajectory stops
    /// (`MPC_XY_ERR_MAX`) [m].
    pub xy_err_max: f64,
    /// Largest horizontal speed (`MPC_XY_VEL_MAX`) [m/s].
    pub vel_max_xy: f64,
    /// Largest upward acceleration (`MPC_ACC_UP_MAX`) [m/s²].
    pub acc_up: f64,
    /// Largest downward acceleration (`MPC_ACC_DOWN_MAX`) [m/s²].
    pub acc_down: f64,
}

impl Default for Px4MissionParams {
    fn default() -> Self {
        Self {
            acc_hor: 3.0,
            jerk: 4.0,
            xy_traj_p: 0.5,
            xy_err_max: 2.0,
            vel_max_xy: 12.0,
            acc_up: 4.0,
            acc_down: 3.0,
        }
    }
}

impl Px4MissionParams {
    /// Check the limits; errors name the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        in_range("acc_hor", self.acc_hor, 0.05, 20.0)?;
        in_range("jerk", self.jerk, 0.05, 100.0)?;
        in_range("xy_traj_p", self.xy_traj_p, 0.01, 1.0)?;
        in_range("xy_err_max", self.xy_err_max, 0.0, 100.0)?;
        positive("vel_max_xy", self.vel_max_xy)?;
        positive("acc_up", self.acc_up)?;
        positive("acc_down", self.acc_down)?;
        Ok(())
    }
}

/// PX4's mission behaviour (module docs).
pub struct Px4Guidance {
    mission: Mission,
    settings: GuidanceSettings,
    axes: [VelocitySmoothing; 3],
    /// Index of the target item.
    k: usize,
    /// The previous waypoint (the vehicle's start for the first item).
    prev: [f64; 3],
    /// When the target was reached, if it was.
    reached_at: Option<f64>,
    /// Horizontal speed target of the last tick not spent turning [m/s].
    speed_before_turn: f64,
    started: bool,
    done: bool,
    events: Vec<MissionEvent>,
    last: TrajectorySetpoint,
}

impl Px4Guidance {
    /// The baseline for `mission` (settings already checked).
    pub fn new(mission: Mission, settings: GuidanceSettings) -> Self {
        let p = &settings.px4;
        let start = mission.start();
        let axis = |x: f64| VelocitySmoothing::new(x, 0.0, 0.0, p.jerk, p.acc_hor, p.vel_max_xy);
        let n = mission.items.len();
        Self {
            axes: [axis(start[0]), axis(start[1]), axis(start[2])],
            last: TrajectorySetpoint::at_rest(start),
            prev: start,
            mission,
            settings,
            k: 0,
            reached_at: None,
            speed_before_turn: 0.0,
            started: false,
            done: false,
            events: Vec::with_capacity(3 * n + 2),
        }
    }

    fn traj_pos(&self) -> [f64; 3] {
        [self.axes[0].x, self.axes[1].x, self.axes[2].x]
    }

    /// The item after the target that shapes the corner, unless the vehicle brakes there.
    fn next(&self) -> Option<[f64; 3]> {
        if self.done || stops_at(&self.mission, self.k) {
            None
        } else {
            Some(self.mission.items[self.k + 1].position)
        }
    }

    /// Whether the trajectory is still turning onto the line to `target`.
    fn turning(&self, target: &[f64; 3]) -> bool {
        let (vx, vy) = (self.axes[0].v, self.axes[1].v);
        let p = self.traj_pos();
        let (dx, dy) = (target[0] - p[0], target[1] - p[1]);
        let (vn, dn) = (vx.hypot(vy), dx.hypot(dy));
        if vn <= 0.2 || dn <= self.mission.items[self.k].acceptance_radius {
            return false;
        }
        (vx * dx + vy * dy) / (vn * dn) < 0.98
    }

    /// The point of the leg prev → target at the L1 distance from the trajectory.
    fn l1_point(&self, target: &[f64; 3]) -> [f64; 3] {
        let p = self.traj_pos();
        let d = [
            target[0] - self.prev[0],
            target[1] - self.prev[1],
            target[2] - self.prev[2],
        ];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if len < 1e-9 {
            return *target;
        }
        let u = [d[0] / len, d[1] / len, d[2] / len];
        let along: f64 = (0..3).map(|i| (p[i] - self.prev[i]) * u[i]).sum();
        let closest = [
            self.prev[0] + along * u[0],
            self.prev[1] + along * u[1],
            self.prev[2] + along * u[2],
        ];
        let cross = (0..3)
            .map(|i| (closest[i] - p[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        let l1 = self.mission.items[self.k].acceptance_radius.max(5.0);
        let ahead = if l1 > cross {
            (l1 * l1 - cross * cross).sqrt()
        } else {
            0.0
        };
        [
            closest[0] + ahead * u[0],
            closest[1] + ahead * u[1],
            closest[2] + ahead * u[2],
        ]
    }

    /// Largest horizontal speed at the trajectory's position towards the target and on
    /// to the next item (backwards over the two legs).
    fn xy_speed(&self, target: &[f64; 3], next: Option<[f64; 3]>) -> f64 {
        let p = &self.settings.px4;
        let item = &self.mission.items[self.k];
        let cruise = item.speed.min(p.vel_max_xy);
        let radius = item.acceptance_radius;
        let start_speed = |start: &[f64; 3], tgt: &[f64; 3], nxt: &[f64; 3], exit: f64| {
            let d_next = dist_xy(tgt, nxt);
            let mut at_target = 0.0;
            if d_next > 1e-3 && d_next >= radius {
                let u1 = unit_xy(tgt, start);
                let u2 = unit_xy(tgt, nxt);
                let alpha = (u1[0] * u2[0] + u1[1] * u2[1])
                    .clamp(-1.0, 1.0)
                    .acos()
                    .clamp(0.0, std::f64::consts::PI - 1e-6);
                let corner = max_speed_in_corner(alpha, p.xy_traj_p * p.acc_hor, radius);
                at_target = corner.min(exit).min(cruise);
            }
            max_speed_from_distance(p.jerk, p.acc_hor, dist_xy(start, tgt), at_target).min(cruise)
        };
        let pos = self.traj_pos();
        match next {
            None => start_speed(&pos, target, target, 0.0),
            Some(n) => {
                let exit = start_speed(target, &n, &n, 0.0);
                start_speed(&pos, target, &n, exit)
            }
        }
    }
}

/// Horizontal unit vector from `a` to `b` (zero when they coincide).
fn unit_xy(a: &[f64; 3], b: &[f64; 3]) -> [f64; 2] {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let n = dx.hypot(dy);
    if n < 1e-9 {
        [0.0, 0.0]
    } else {
        [dx / n, dy / n]
    }
}

impl Guidance for Px4Guidance {
    fn start(&mut self, t: f64, pos: &[f64; 3], vel: &[f64; 3]) {
        let p = &self.settings.px4;
        for i in 0..3 {
            self.axes[i] =
                VelocitySmoothing::new(pos[i], vel[i], 0.0, p.jerk, p.acc_hor, p.vel_max_xy);
        }
        self.prev = *pos;
        self.k = 0;
        self.reached_at = None;
        self.speed_before_turn = 0.0;
        self.started = true;
        self.done = false;
        self.events.clear();
        self.events.push(MissionEvent {
            t,
            item: 0,
            kind: EventKind::Started,
        });
        self.last = TrajectorySetpoint::at_rest(*pos);
    }

    fn update(&mut self, t: f64, dt: f64, pos: &[f64; 3], _vel: &[f64; 3]) -> TrajectorySetpoint {
        if !self.started {
            return self.last;
        }
        // 1. Navigator.
        if !self.done {
            let alt = self.settings.alt_acceptance_radius;
            if self.reached_at.is_none() && reached(&self.mission, self.k, pos, alt) {
                self.reached_at = Some(t);
                self.events.push(MissionEvent {
                    t,
                    item: self.k,
                    kind: EventKind::Reached,
                });
            }
            if let Some(tr) = self.reached_at {
                if t >= tr + self.mission.items[self.k].hold {
                    let last = self.k + 1 == self.mission.items.len();
                    self.events.push(MissionEvent {
                        t,
                        item: self.k,
                        kind: if last {
                            EventKind::Completed
                        } else {
                            EventKind::Left
                        },
                    });
                    if last {
                        self.done = true;
                    } else {
                        self.prev = self.mission.items[self.k].position;
                        self.k += 1;
                        self.reached_at = None;
                    }
                }
            }
        }
        let target = self.mission.items[self.k].position;
        let next = self.next();
        // 3a. Advance the trajectory, slowed while the vehicle lags behind it.
        let px = &self.settings.px4;
        let tp = self.traj_pos();
        let (ex, ey) = (tp[0] - pos[0], tp[1] - pos[1]);
        let lag_xy = ex.hypot(ey);
        let ahead_xy = ex * self.axes[0].v + ey * self.axes[1].v >= 0.0;
        let stretch_xy = if px.xy_err_max > 0.0 && ahead_xy {
            1.0 - (lag_xy / px.xy_err_max).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let stretch = [stretch_xy, stretch_xy, 1.0];
        let mut sp = TrajectorySetpoint::default();
        for i in 0..3 {
            self.axes[i].advance(dt, stretch[i]);
            sp.p[i] = self.axes[i].x;
            sp.v[i] = self.axes[i].v;
            sp.a[i] = self.axes[i].a;
            sp.j[i] = self.axes[i].j;
        }
        // 2. Velocity target.
        let turning = next.is_some() && self.turning(&target);
        let towards = if turning {
            self.l1_point(&target)
        } else {
            target
        };
        let mut speed = self.xy_speed(&target, next);
        if turning {
            speed = speed.min(self.speed_before_turn);
        } else {
            self.speed_before_turn = speed;
        }
        let p = self.traj_pos();
        let u = unit_xy(&p, &towards);
        let dz = target[2] - p[2];
        let (rate, acc_z) = if dz < 0.0 {
            (self.settings.climb_rate, px.acc_up)
        } else {
            (self.settings.descent_rate, px.acc_down)
        };
        let vz = dz.signum() * rate.min(max_speed_from_distance(px.jerk, acc_z, dz.abs(), 0.0));
        // 3b. Re-plan the axes towards it.
        self.axes[0].set_limits(px.jerk, px.acc_hor, px.vel_max_xy);
        self.axes[1].set_limits(px.jerk, px.acc_hor, px.vel_max_xy);
        self.axes[2].set_limits(px.jerk, acc_z, rate);
        VelocitySmoothing::plan_synchronised(&mut self.axes, &[u[0] * speed, u[1] * speed, vz]);
        self.last = sp;
        sp
    }

    fn preview(&self, _t: f64, dt: f64, out: &mut [TrajectorySetpoint]) {
        // PX4 plans no further than the next tick: its motion continued at constant
        // acceleration is all it says about the future.
        let s = &self.last;
        for (k, o) in out.iter_mut().enumerate() {
            let tau = k as f64 * dt;
            for i in 0..3 {
                o.p[i] = s.p[i] + s.v[i] * tau + 0.5 * s.a[i] * tau * tau;
                o.v[i] = s.v[i] + s.a[i] * tau;
                o.a[i] = s.a[i];
                o.j[i] = 0.0;
            }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mission::plan::{ItemKind, MissionItem};

    fn mission(hold: f64) -> Mission {
        let wp = |n: f64, e: f64, source: usize| MissionItem {
            kind: ItemKind::Waypoint,
            position: [n, e, -10.0],
            hold,
            acceptance_radius: 2.0,
            speed: 5.0,
            source,
        };
        Mission {
            name: "L".into(),
            home: None,
            items: vec![wp(40.0, 0.0, 0), wp(40.0, 40.0, 1)],
        }
    }

    /// Fly the guidance with a perfect tracker; returns the setpoints at 50 Hz.
    fn fly(m: Mission) -> (Vec<TrajectorySetpoint>, Px4Guidance) {
        let st = GuidanceSettings {
            mode: super::super::guidance::GuidanceMode::Px4,
            ..GuidanceSettings::default()
        };
        let mut g = Px4Guidance::new(m, st);
        let dt = 0.02;
        let mut pos = [0.0, 0.0, -10.0];
        g.start(0.0, &pos, &[0.0; 3]);
        let mut out = Vec::new();
        let mut t = 0.0;
        while !g.done() && t < 120.0 {
            t += dt;
            let sp = g.update(t, dt, &pos, &[0.0; 3]);
            pos = sp.p;
            out.push(sp);
        }
        (out, g)
    }

    #[test]
    fn braking_for_a_hold_stops_at_each_item_within_the_limits() {
        let (sps, g) = fly(mission(5.0));
        assert!(g.done());
        let vmax = sps.iter().map(|s| s.v[0].hypot(s.v[1])).fold(0.0, f64::max);
        let amax = sps.iter().map(|s| s.a[0].hypot(s.a[1])).fold(0.0, f64::max);
        assert!((vmax - 5.0).abs() < 0.05, "cruise {vmax}");
        assert!(amax <= 3.0 * 2f64.sqrt() + 1e-9, "acceleration {amax}");
        // The first item is reached at its acceptance radius and held 5 s; the trajectory is
        // then at rest close to the waypoint (the turn happens from a stop).
        let reached = g
            .events()
            .iter()
            .find(|e| e.kind == EventKind::Reached)
            .unwrap()
            .t;
        let left = g
            .events()
            .iter()
            .find(|e| e.kind == EventKind::Left)
            .unwrap()
            .t;
        assert!((left - reached - 5.0).abs() < 0.021);
        let at_left = sps[(left / 0.02).round() as usize - 1];
        assert!(
            dist_xy(&at_left.p, &[40.0, 0.0, -10.0]) < 0.3,
            "{:?}",
            at_left.p
        );
        assert!(at_left.v[0].hypot(at_left.v[1]) < 0.3);
    }

    #[test]
    fn without_a_hold_the_corner_is_cut_at_speed() {
        let (sps, g) = fly(mission(0.0));
        assert!(g.done());
        // Through the 90° corner the trajectory does not stop (the corner speed is
        // √(0.5·3·2·tan 45°) = 1.7 m/s; the turn of the velocity target costs some of it).
        let near = sps
            .iter()
            .filter(|s| dist_xy(&s.p, &[40.0, 0.0, -10.0]) < 3.0)
            .map(|s| s.v[0].hypot(s.v[1]))
            .fold(f64::INFINITY, f64::min);
        assert!(near > 0.5, "slowest speed near the corner {near}");
    }
}
