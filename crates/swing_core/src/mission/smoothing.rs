//! Jerk-limited velocity smoothing of one axis, as PX4's auto modes do it (the behaviour of
//! PX4's `VelocitySmoothing`, written here from its equations).
//!
//! The axis carries (x, v, a) and is re-planned every tick towards a velocity target
//! v_sp: the acceleration moves at jerk ±J for T₁, stays for T₂ and returns to zero at ∓J
//! over T₃, so that the velocity lands on v_sp with zero acceleration. With a₀ the current
//! acceleration and Δv = v_sp − v, the peak a₁ = a₀ + J T₁ and T₃ = a₁/J; with T₂ = 0 the
//! velocity change is Δv = (2a₁² − a₀²)/(2J), so a₁ = ±√((a₀² + 2JΔv)/2), clipped to
//! ±a_max (then T₂ = (Δv − Δv₁₃)/a₁). The direction (the sign of J) is that of v_sp minus
//! the velocity the axis reaches when its acceleration is brought to zero now,
//! v + a|a|/(2J). Several axes are synchronised by stretching the faster ones to the
//! longest total time T: then Δv = a₁T − (2a₁² − 2a₀a₁ + a₀²)/(2J), a quadratic in a₁
//! whose smaller-acceleration root is taken.

/// One smoothed axis (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VelocitySmoothing {
    /// Position [m].
    pub x: f64,
    /// Velocity [m/s].
    pub v: f64,
    /// Acceleration [m/s²].
    pub a: f64,
    /// Jerk of the current segment [m/s³].
    pub j: f64,
    max_jerk: f64,
    max_accel: f64,
    max_vel: f64,
    // The plan of the last re-plan: segment durations, direction and start state.
    t1: f64,
    t2: f64,
    t3: f64,
    dir: f64,
    local_time: f64,
    start: (f64, f64, f64),
    vel_sp: f64,
}

/// State of a polynomial segment after `t` seconds at constant jerk `j`.
fn segment(j: f64, a: f64, v: f64, x: f64, t: f64) -> (f64, f64, f64) {
    (
        a + j * t,
        v + a * t + 0.5 * j * t * t,
        x + v * t + 0.5 * a * t * t + j * t * t * t / 6.0,
    )
}

impl VelocitySmoothing {
    /// An axis at rest-or-moving state (x, v, a) with the given limits (all > 0).
    pub fn new(x: f64, v: f64, a: f64, max_jerk: f64, max_accel: f64, max_vel: f64) -> Self {
        Self {
            x,
            v,
            a,
            j: 0.0,
            max_jerk,
            max_accel,
            max_vel,
            t1: 0.0,
            t2: 0.0,
            t3: 0.0,
            dir: 0.0,
            local_time: 0.0,
            start: (x, v, a),
            vel_sp: v,
        }
    }

    /// Change the limits (jerk, acceleration, velocity); they apply from the next re-plan.
    pub fn set_limits(&mut self, max_jerk: f64, max_accel: f64, max_vel: f64) {
        self.max_jerk = max_jerk;
        self.max_accel = max_accel;
        self.max_vel = max_vel;
    }

    /// Largest acceleration [m/s²].
    pub fn max_accel(&self) -> f64 {
        self.max_accel
    }

    /// Largest jerk [m/s³].
    pub fn max_jerk(&self) -> f64 {
        self.max_jerk
    }

    /// Largest speed [m/s].
    pub fn max_vel(&self) -> f64 {
        self.max_vel
    }

    /// Total duration of the current plan [s].
    pub fn total_time(&self) -> f64 {
        self.t1 + self.t2 + self.t3
    }

    /// Overwrite the position (e.g. after an estimator reset).
    pub fn set_position(&mut self, x: f64) {
        self.x = x;
        self.start.0 = x;
    }

    /// Re-plan from the current state towards `vel_sp` (clipped to the speed limit), in the
    /// least time.
    pub fn plan(&mut self, vel_sp: f64) {
        self.vel_sp = vel_sp.clamp(-self.max_vel, self.max_vel);
        self.local_time = 0.0;
        self.start = (self.x, self.v, self.a);
        let jt = self.max_jerk;
        let v_zero_acc = self.v + self.a * self.a.abs() / (2.0 * jt);
        let mut dir = (self.vel_sp - v_zero_acc).signum();
        if self.vel_sp == v_zero_acc {
            dir = if self.a == 0.0 { 0.0 } else { self.a.signum() };
        }
        self.dir = dir;
        if dir == 0.0 {
            (self.t1, self.t2, self.t3) = (0.0, 0.0, 0.0);
            return;
        }
        let j = dir * jt;
        let (a0, dv) = (self.a, self.vel_sp - self.v);
        let disc = (a0 * a0 + 2.0 * j * dv) / 2.0;
        let mut a1 = if disc > 0.0 { dir * disc.sqrt() } else { 0.0 };
        a1 = a1.clamp(-self.max_accel, self.max_accel);
        self.set_from_peak(a0, a1, dv, j, None);
    }

    /// Stretch the current plan to last `total` seconds (for synchronising axes).
    pub fn plan_for_duration(&mut self, total: f64) {
        if self.dir == 0.0 || total <= self.total_time() {
            return;
        }
        let j = self.dir * self.max_jerk;
        let (a0, dv) = (self.start.2, self.vel_sp - self.start.1);
        // 2a₁² − 2(a₀ + JT)a₁ + (a₀² + 2JΔv) = 0.
        let b = a0 + j * total;
        let disc = b * b - 2.0 * (a0 * a0 + 2.0 * j * dv);
        if disc < 0.0 {
            return;
        }
        let roots = [(b - disc.sqrt()) / 2.0, (b + disc.sqrt()) / 2.0];
        let valid = |a1: f64| {
            let t1 = (a1 - a0) / j;
            let t3 = a1 / j;
            t1 >= -1e-9 && t3 >= -1e-9 && t1 + t3 <= total + 1e-9
        };
        let pick = roots
            .iter()
            .copied()
            .filter(|r| valid(*r))
            .min_by(|x, y| x.abs().total_cmp(&y.abs()));
        if let Some(a1) = pick {
            let a1 = a1.clamp(-self.max_accel, self.max_accel);
            self.set_from_peak(a0, a1, dv, j, Some(total));
        }
    }

    fn set_from_peak(&mut self, a0: f64, a1: f64, dv: f64, j: f64, total: Option<f64>) {
        // A peak that cannot be reached by ramping (a₀ already beyond it) keeps a₀ and
        // only ramps down.
        let t1 = ((a1 - a0) / j).max(0.0);
        let a1 = a0 + j * t1;
        let t3 = (a1 / j).max(0.0);
        let t2 = match total {
            Some(t) => (t - t1 - t3).max(0.0),
            None => {
                // Velocity gained over the two ramps; the rest at a₁.
                let dv13 = a0 * t1 + 0.5 * j * t1 * t1 + 0.5 * a1 * t3;
                if a1.abs() > 1e-12 {
                    ((dv - dv13) / a1).max(0.0)
                } else {
                    0.0
                }
            }
        };
        (self.t1, self.t2, self.t3) = (t1, t2, t3);
    }

    /// Advance the plan by `dt` × `stretch` seconds (stretch < 1 slows it down).
    pub fn advance(&mut self, dt: f64, stretch: f64) {
        self.local_time += dt * stretch;
        let tau = self.local_time;
        let (x0, v0, a0) = self.start;
        let jd = self.dir * self.max_jerk;
        let (t1, t2, t3) = (self.t1, self.t2, self.t3);
        let (mut a, mut v, mut x) = segment(jd, a0, v0, x0, tau.min(t1));
        if tau > t1 {
            (a, v, x) = segment(0.0, a, v, x, (tau - t1).min(t2));
        }
        if tau > t1 + t2 {
            (a, v, x) = segment(-jd, a, v, x, (tau - t1 - t2).min(t3));
        }
        if tau > t1 + t2 + t3 {
            (_, v, x) = segment(0.0, 0.0, v, x, tau - t1 - t2 - t3);
            a = 0.0;
        }
        self.j = if tau < t1 {
            jd
        } else if tau < t1 + t2 {
            0.0
        } else if tau < t1 + t2 + t3 {
            -jd
        } else {
            0.0
        };
        (self.x, self.v, self.a) = (x, v, a);
    }

    /// Re-plan several axes towards their targets and synchronise them to the longest.
    pub fn plan_synchronised(axes: &mut [VelocitySmoothing], targets: &[f64]) {
        for (ax, v) in axes.iter_mut().zip(targets) {
            ax.plan(*v);
        }
        let longest = axes.iter().map(|a| a.total_time()).fold(0.0, f64::max);
        if longest > 1e-9 {
            for ax in axes.iter_mut() {
                ax.plan_for_duration(longest);
            }
        }
    }
}

/// Largest speed from which a vehicle can still come down to `final_speed` within
/// `distance`, braking at `accel` after a delay of 2·accel/jerk for the jerk ramps:
/// v² + (4a²/J) v − (2 a d + v_f²) = 0 (PX4's rule for the speed towards a waypoint).
pub fn max_speed_from_distance(jerk: f64, accel: f64, distance: f64, final_speed: f64) -> f64 {
    let b = 4.0 * accel * accel / jerk;
    let c = -2.0 * accel * distance.max(0.0) - final_speed * final_speed;
    0.5 * (-b + (b * b - 4.0 * c).sqrt())
}

/// Largest speed through a corner of opening angle `alpha` [rad] (between the incoming
/// leg, reversed, and the outgoing one) on the circle tangent to both legs at distance
/// `d` from the corner, at lateral acceleration `accel`: √(a d tan(α/2)).
pub fn max_speed_in_corner(alpha: f64, accel: f64, d: f64) -> f64 {
    (accel * d * (alpha / 2.0).tan()).max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reaches_the_target_velocity_within_the_limits_in_the_planned_time() {
        let mut ax = VelocitySmoothing::new(0.0, 0.0, 0.0, 4.0, 3.0, 12.0);
        ax.plan(5.0);
        // a₁ = √(2·4·5/2) = 4.47 > 3 → clipped: T₁ = T₃ = 0.75 s, T₂ = (5 − 2.25)/3.
        assert!((ax.t1 - 0.75).abs() < 1e-12 && (ax.t3 - 0.75).abs() < 1e-12);
        assert!((ax.t2 - 2.75 / 3.0).abs() < 1e-12);
        let total = ax.total_time();
        let dt = 0.001;
        let mut t = 0.0;
        let (mut x, mut v_prev) = (0.0, 0.0);
        while t < total + 0.5 {
            ax.advance(dt, 1.0);
            assert!(ax.a.abs() <= 3.0 + 1e-9);
            assert!(((ax.v - v_prev) / dt).abs() <= 3.0 + 1e-6);
            x += 0.5 * (ax.v + v_prev) * dt;
            v_prev = ax.v;
            t += dt;
        }
        assert!((ax.v - 5.0).abs() < 1e-9 && ax.a.abs() < 1e-12);
        assert!((ax.x - x).abs() < 1e-3, "{} vs {x}", ax.x);
    }

    #[test]
    fn synchronised_axes_finish_together_on_a_straight_line() {
        let mut axes = [
            VelocitySmoothing::new(0.0, 0.0, 0.0, 4.0, 3.0, 12.0),
            VelocitySmoothing::new(0.0, 0.0, 0.0, 4.0, 3.0, 12.0),
        ];
        VelocitySmoothing::plan_synchronised(&mut axes, &[4.0, 3.0]);
        let total = axes[0].total_time();
        assert!((total - axes[1].total_time()).abs() < 1e-9);
        // The slower axis is stretched, not finished early: both land on their targets at
        // the common time and not before.
        let dt = 0.001;
        let steps = (total / dt).round() as usize;
        for k in 1..=steps + 100 {
            for ax in axes.iter_mut() {
                ax.advance(dt, 1.0);
            }
            let t = k as f64 * dt;
            if t < total - 0.05 {
                assert!(axes[0].v < 4.0 - 1e-3 && axes[1].v < 3.0 - 1e-3, "t = {t}");
            }
        }
        assert!((axes[0].v - 4.0).abs() < 1e-9 && (axes[1].v - 3.0).abs() < 1e-9);
        assert!(axes[1].a.abs() < 1e-12);
    }

    #[test]
    fn braking_speed_rule_stops_at_the_target() {
        // v at distance 0 is the final speed; the formula solves its own quadratic.
        assert_eq!(max_speed_from_distance(4.0, 3.0, 0.0, 0.0), 0.0);
        let v = max_speed_from_distance(4.0, 3.0, 10.0, 1.0);
        assert!((v * v + 9.0 * v - 61.0).abs() < 1e-9);
        // A 90° corner at 1.5 m/s² within 2 m: √(1.5·2·tan 45°).
        assert!(
            (max_speed_in_corner(std::f64::consts::FRAC_PI_2, 1.5, 2.0) - 3f64.sqrt()).abs()
                < 1e-12
        );
    }
}
