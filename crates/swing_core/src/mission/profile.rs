//! A rest-to-rest motion profile along one straight leg, jerk- and acceleration-limited
//! (the "double-S" or seven-segment profile; Biagiotti & Melchiorri, *Trajectory Planning
//! for Automatic Machines and Robots*, Springer 2008, section 3.4).
//!
//! Over a distance L with limits v_max, a_max, j_max: the acceleration rises at +j to the
//! peak a_p, stays, falls at −j to zero (reaching the cruise speed v), the speed stays v,
//! and the deceleration mirrors the acceleration. The acceleration phase lasts
//! T_a = v/a_p + a_p/j and covers v·T_a/2, so with a cruise the total time is
//! T = L/v + T_a. When L is too short for v_max the cruise speed is the root of
//! v²/a_p + v a_p/j = L (a constant-acceleration part remains), and when even that leaves
//! v < a_p²/j the peak drops to a_p = √(v j) with v = (L² j / 4)^{1/3} (pure jerk ramps).
//! Every quantity is a closed form of time, so a preview of the leg costs a few flops per
//! sample.

/// Position, velocity, acceleration and jerk along the leg at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProfilePoint {
    /// Distance from the start [m].
    pub s: f64,
    /// Speed [m/s].
    pub v: f64,
    /// Acceleration [m/s²].
    pub a: f64,
    /// Jerk [m/s³].
    pub j: f64,
}

/// A rest-to-rest double-S profile over one leg (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SCurve {
    length: f64,
    jerk: f64,
    /// Peak acceleration [m/s²].
    peak_acc: f64,
    /// Cruise speed [m/s].
    cruise: f64,
    /// Duration of the jerk ramps [s].
    t_j: f64,
    /// Duration of the acceleration phase [s].
    t_a: f64,
    /// Total duration [s].
    total: f64,
}

impl SCurve {
    /// The profile over `length` [m] with the limits (all > 0; a zero length gives a
    /// profile of zero duration).
    pub fn new(length: f64, v_max: f64, a_max: f64, j_max: f64) -> Self {
        let length = length.max(0.0);
        if length < 1e-9 {
            return Self {
                length: 0.0,
                jerk: j_max,
                peak_acc: 0.0,
                cruise: 0.0,
                t_j: 0.0,
                t_a: 0.0,
                total: 0.0,
            };
        }
        // Peak acceleration reachable before the speed limit cuts the ramp short.
        let mut a_p = a_max.min((v_max * j_max).sqrt());
        let mut v = v_max;
        // Distance of acceleration + deceleration at speed v: v·T_a.
        let dist = |v: f64, a_p: f64| v * (v / a_p + a_p / j_max);
        if dist(v, a_p) > length {
            // No cruise at v_max: v²/a_p + v a_p/j − L = 0.
            let b = a_p / j_max;
            v = 0.5 * a_p * (-b + (b * b + 4.0 * length / a_p).sqrt());
            if v < a_p * a_p / j_max {
                // Not even the peak acceleration: pure jerk ramps.
                v = (length * length * j_max / 4.0).cbrt();
                a_p = (v * j_max).sqrt();
            }
        }
        let t_j = a_p / j_max;
        let t_a = v / a_p + t_j;
        let total = length / v + t_a;
        Self {
            length,
            jerk: j_max,
            peak_acc: a_p,
            cruise: v,
            t_j,
            t_a,
            total,
        }
    }

    /// Total duration [s].
    pub fn duration(&self) -> f64 {
        self.total
    }

    /// Leg length [m].
    pub fn length(&self) -> f64 {
        self.length
    }

    /// Cruise (largest) speed [m/s].
    pub fn cruise_speed(&self) -> f64 {
        self.cruise
    }

    /// Peak acceleration [m/s²].
    pub fn peak_acceleration(&self) -> f64 {
        self.peak_acc
    }

    /// The acceleration phase at time τ ∈ [0, T_a] (speed from 0 to v).
    fn accelerating(&self, tau: f64) -> ProfilePoint {
        let (j, a_p, t_j, t_a) = (self.jerk, self.peak_acc, self.t_j, self.t_a);
        if tau <= t_j {
            return ProfilePoint {
                s: j * tau.powi(3) / 6.0,
                v: 0.5 * j * tau * tau,
                a: j * tau,
                j,
            };
        }
        // End of the first ramp.
        let s1 = j * t_j.powi(3) / 6.0;
        let v1 = 0.5 * j * t_j * t_j;
        let t_c = t_a - 2.0 * t_j;
        if tau <= t_j + t_c {
            let u = tau - t_j;
            return ProfilePoint {
                s: s1 + v1 * u + 0.5 * a_p * u * u,
                v: v1 + a_p * u,
                a: a_p,
                j: 0.0,
            };
        }
        // Last ramp, mirrored about the end of the phase: speed v − j(T_a − τ)²/2.
        let r = t_a - tau;
        let v_end = self.cruise;
        let s_end = 0.5 * v_end * t_a;
        ProfilePoint {
            s: s_end - v_end * r + j * r.powi(3) / 6.0,
            v: v_end - 0.5 * j * r * r,
            a: j * r,
            j: -j,
        }
    }

    /// The profile at time `t` [s] from the start; before the start it is at rest at 0 and
    /// after the end at rest at the leg's length.
    pub fn at(&self, t: f64) -> ProfilePoint {
        if t <= 0.0 || self.total <= 0.0 {
            return ProfilePoint::default();
        }
        if t >= self.total {
            return ProfilePoint {
                s: self.length,
                ..ProfilePoint::default()
            };
        }
        if t <= self.t_a {
            return self.accelerating(t);
        }
        let t_dec = self.total - self.t_a;
        if t <= t_dec {
            let s_a = 0.5 * self.cruise * self.t_a;
            return ProfilePoint {
                s: s_a + self.cruise * (t - self.t_a),
                v: self.cruise,
                a: 0.0,
                j: 0.0,
            };
        }
        // Deceleration: the acceleration phase run backwards from the end.
        let m = self.accelerating(self.total - t);
        ProfilePoint {
            s: self.length - m.s,
            v: m.v,
            a: -m.a,
            j: m.j,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Limits everywhere, continuity, and each quantity the derivative of the one before
    /// (central differences), so the closed forms are one consistent motion.
    fn check_consistent(p: &SCurve, v_max: f64, a_max: f64, j_max: f64) {
        let h = 1e-5;
        let n = 20_000;
        for k in 0..=n {
            let t = p.duration() * k as f64 / n as f64 + 1e-7;
            let (q, lo, hi) = (p.at(t), p.at(t - h), p.at(t + h));
            assert!(q.v <= v_max + 1e-9 && q.a.abs() <= a_max + 1e-9 && q.j.abs() <= j_max + 1e-9);
            assert!(
                ((hi.s - lo.s) / (2.0 * h) - q.v).abs() < 1e-6,
                "ds/dt at {t}"
            );
            // (a has kinks where the jerk switches: the central difference is off by ≤ j h.)
            assert!(
                ((hi.v - lo.v) / (2.0 * h) - q.a).abs() <= j_max * h,
                "dv/dt at {t}"
            );
            // The jerk is piecewise constant: away from its switches it is da/dt.
            if lo.j == hi.j {
                assert!(
                    ((hi.a - lo.a) / (2.0 * h) - q.j).abs() < 1e-6,
                    "da/dt at {t}"
                );
            }
            assert!(
                (hi.a - lo.a).abs() <= 2.0 * h * j_max + 1e-12,
                "a jumps at {t}"
            );
        }
        let end = p.at(p.duration() + 1.0);
        assert_eq!((end.s, end.v, end.a), (p.length(), 0.0, 0.0));
        let before = p.at(p.duration() - 1e-9);
        assert!((before.s - p.length()).abs() < 1e-6 && before.v.abs() < 1e-6);
    }

    #[test]
    fn long_leg_cruises_at_the_limit_with_the_textbook_duration() {
        // 40 m at 5 m/s, 2 m/s², 2 m/s³: a_p = 2, T_j = 1, T_a = 5/2 + 1 = 3.5 s,
        // T = 40/5 + 3.5 = 11.5 s.
        let p = SCurve::new(40.0, 5.0, 2.0, 2.0);
        assert!((p.duration() - 11.5).abs() < 1e-12);
        assert_eq!((p.cruise_speed(), p.peak_acceleration()), (5.0, 2.0));
        check_consistent(&p, 5.0, 2.0, 2.0);
        let mid = p.at(p.duration() / 2.0);
        assert!((mid.s - 20.0).abs() < 1e-9 && mid.v == 5.0);
    }

    #[test]
    fn short_legs_lower_the_speed_and_then_the_acceleration() {
        // Cruise speed from v²/a + v a/j = L: 6 m at a_p = 2, j = 2 → v² /2 + v − 6 = 0 → v = 2.6458.
        let p = SCurve::new(6.0, 5.0, 2.0, 2.0);
        assert!((p.cruise_speed() - (-1.0 + 13f64.sqrt())).abs() < 1e-12);
        check_consistent(&p, 5.0, 2.0, 2.0);
        // 1 m: v = (L² j / 4)^(1/3) = 0.7937, a_p = √(v j) = 1.26 < 2.
        let p = SCurve::new(1.0, 5.0, 2.0, 2.0);
        assert!((p.cruise_speed() - 0.5f64.cbrt()).abs() < 1e-12);
        assert!(p.peak_acceleration() < 2.0);
        check_consistent(&p, 5.0, 2.0, 2.0);
        assert_eq!(SCurve::new(0.0, 5.0, 2.0, 2.0).duration(), 0.0);
    }

    #[test]
    fn a_low_speed_limit_caps_the_acceleration_ramp() {
        // v_max j < a_max²: the ramp never reaches a_max.
        let p = SCurve::new(20.0, 0.5, 3.0, 4.0);
        assert!((p.peak_acceleration() - 2f64.sqrt()).abs() < 1e-12);
        check_consistent(&p, 0.5, 3.0, 4.0);
    }
}
