//! In-flight payload estimates from the signals the swing controller already has: the cable
//! length from the pendulum's own equation of motion, the total mass from the thrust.
//!
//! Length. For a pendulum hanging from a vehicle that accelerates horizontally by `a`, the
//! linearised swing obeys `l·θ̈ + g·θ = −a` whatever the payload's mass and whatever holds
//! the vehicle (PX4's loops, an MPC): the vehicle's measured acceleration is the forcing.
//! Integrated over a window of `W` ticks it needs no second derivative:
//! `l·(θ̇(k) − θ̇(k−W)) = −(g·∫θ dt + v(k) − v(k−W))`, one unknown, solved by least
//! squares with exponential forgetting. A swing of a tenth of a degree already pins it when
//! the sensor is clean; the standard error, from the residual, says how far to trust it
//! when it is not. A pendulum at rest (hover, steady cruise) carries no information on its
//! length, and the estimate then keeps what it last learned while its error bar grows.
//!
//! Mass. The rotor thrust projected on the vertical over `g − a_down` is the total mass;
//! low-pass filtered it settles within a second of a pick-up or a drop.
//!
//! Everything is preallocated: an update does not allocate.

use crate::plant::GRAVITY;

use crate::plant::AxisState;

/// Ticks over which the total-mass estimate must hold still to count as settled.
pub const MASS_SETTLE_TICKS: usize = 10;

/// Settings of the [`PayloadTracker`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackerSettings {
    /// Integration window W of the pendulum equation [ticks].
    pub window: usize,
    /// Forgetting factor per tick of the length least squares, (0, 1) [dimensionless].
    pub forgetting: f64,
    /// Time constant of the total-mass filter [s].
    pub mass_tau: f64,
}

impl Default for TrackerSettings {
    fn default() -> Self {
        Self {
            window: 10,
            forgetting: 0.99,
            mass_tau: 0.5,
        }
    }
}

/// Streaming estimator of the cable length and the total mass (see module docs).
#[derive(Clone, Debug)]
pub struct PayloadTracker {
    settings: TrackerSettings,
    dt: f64,
    axes: usize,
    /// Ring of the last W + 1 frames per axis: (v, swing, swing rate).
    ring: Vec<[f64; 3]>,
    head: usize,
    filled: usize,
    sxx: f64,
    sxy: f64,
    syy: f64,
    /// Σ of the forgetting weights (the effective sample count).
    weight: f64,
    mass: f64,
    have_mass: bool,
    /// The mass estimate of the last `MASS_SETTLE_TICKS` ticks (a ring).
    mass_ring: [f64; MASS_SETTLE_TICKS],
    mass_head: usize,
    mass_count: usize,
    vd_last: f64,
    have_vd: bool,
}

impl PayloadTracker {
    /// A tracker for `axes` horizontal axes (1 or 2) sampled every `dt` seconds.
    pub fn new(axes: usize, dt: f64, settings: TrackerSettings) -> Self {
        let w = settings.window.max(1);
        Self {
            settings: TrackerSettings {
                window: w,
                ..settings
            },
            dt,
            axes: axes.clamp(1, 2),
            ring: vec![[0.0; 3]; (w + 1) * axes.clamp(1, 2)],
            head: 0,
            filled: 0,
            sxx: 0.0,
            sxy: 0.0,
            syy: 0.0,
            weight: 0.0,
            mass: f64::NAN,
            have_mass: false,
            mass_ring: [f64::NAN; MASS_SETTLE_TICKS],
            mass_head: 0,
            mass_count: 0,
            vd_last: 0.0,
            have_vd: false,
        }
    }

    /// Forget everything learned on the length (e.g. after a flight segment without data).
    pub fn restart(&mut self) {
        self.filled = 0;
        self.sxx = 0.0;
        self.sxy = 0.0;
        self.syy = 0.0;
        self.weight = 0.0;
    }

    /// One tick of horizontal measurements; non-finite frames are skipped (and break the
    /// window, so that no integral spans a gap).
    pub fn update(&mut self, state: &[AxisState]) {
        let w = self.settings.window;
        let axes = self.axes.min(state.len());
        let finite = state[..axes]
            .iter()
            .all(|s| s.v.is_finite() && s.swing.is_finite() && s.swing_rate.is_finite());
        if !finite {
            self.filled = 0;
            return;
        }
        self.head = (self.head + 1) % (w + 1);
        for (a, s) in state[..axes].iter().enumerate() {
            self.ring[a * (w + 1) + self.head] = [s.v, s.swing, s.swing_rate];
        }
        self.filled = (self.filled + 1).min(w + 1);
        if self.filled <= w {
            return;
        }
        let lambda = self.settings.forgetting;
        self.sxx *= lambda;
        self.sxy *= lambda;
        self.syy *= lambda;
        self.weight = lambda * self.weight + 1.0;
        let oldest = (self.head + 1) % (w + 1);
        for a in 0..axes {
            let ring = &self.ring[a * (w + 1)..(a + 1) * (w + 1)];
            let (new, old) = (ring[self.head], ring[oldest]);
            // Trapezoid rule over the W + 1 frames of the window.
            let mut integral = 0.5 * (new[1] + old[1]);
            for f in ring
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != self.head && *i != oldest)
            {
                integral += f.1[1];
            }
            integral *= self.dt;
            let x = new[2] - old[2];
            let y = -(GRAVITY * integral + new[0] - old[0]);
            self.sxx += x * x;
            self.sxy += x * y;
            self.syy += y * y;
        }
    }

    /// One tick of the vertical channel: rotor thrust projected on the vertical [N] and the
    /// measured down velocity [m/s].
    pub fn update_vertical(&mut self, thrust_vertical: f64, vd: f64) {
        if !(thrust_vertical.is_finite() && vd.is_finite()) {
            self.have_vd = false;
            return;
        }
        let a_down = if self.have_vd {
            (vd - self.vd_last) / self.dt
        } else {
            0.0
        };
        self.vd_last = vd;
        self.have_vd = true;
        let denom = GRAVITY - a_down;
        if denom <= 0.5 * GRAVITY {
            return; // a hard descent says nothing reliable about the mass
        }
        let raw = thrust_vertical / denom;
        if self.have_mass {
            let alpha = (self.dt / self.settings.mass_tau).min(1.0);
            self.mass += alpha * (raw - self.mass);
        } else {
            self.mass = raw;
            self.have_mass = true;
        }
        self.mass_head = (self.mass_head + 1) % MASS_SETTLE_TICKS;
        self.mass_ring[self.mass_head] = self.mass;
        self.mass_count = (self.mass_count + 1).min(MASS_SETTLE_TICKS);
    }

    /// Whether the total-mass estimate has stayed within `tolerance` [kg] over the last
    /// [`MASS_SETTLE_TICKS`] ticks (a pick-up or a drop has finished moving it).
    pub fn mass_settled(&self, tolerance: f64) -> bool {
        if self.mass_count < MASS_SETTLE_TICKS {
            return false;
        }
        let (lo, hi) = self
            .mass_ring
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), m| {
                (lo.min(*m), hi.max(*m))
            });
        hi - lo <= tolerance
    }

    /// Cable length estimate [m] and its relative standard error, when the data so far
    /// define one (some swing, a positive length).
    pub fn length(&self) -> Option<(f64, f64)> {
        if self.sxx <= 0.0 || self.weight < 2.0 {
            return None;
        }
        let l = self.sxy / self.sxx;
        if !(l.is_finite() && l > 0.0) {
            return None;
        }
        let resid = (self.syy - self.sxy * self.sxy / self.sxx).max(0.0);
        // Overlapping windows share W samples of noise: the residuals are correlated over
        // W, so the independent count is the weight over W.
        let dof = (self.weight * self.axes as f64 / self.settings.window as f64 - 1.0).max(1.0);
        let se = (resid / dof / self.sxx).sqrt() * (self.settings.window as f64).sqrt();
        Some((l, se / l))
    }

    /// Total mass estimate (vehicle + payload) [kg], once the vertical channel has data.
    pub fn total_mass(&self) -> Option<f64> {
        self.have_mass.then_some(self.mass)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pendulum of length l under a known horizontal acceleration profile, integrated
    /// finely: the tracker recovers l from 0.03 s samples.
    fn pendulum(l: f64, amp: f64, seconds: f64) -> Vec<AxisState> {
        let h: f64 = 1e-4;
        let dt: f64 = 0.03;
        let (mut th, mut thd, mut v) = (0.0f64, 0.0f64, 0.0f64);
        let mut out = Vec::new();
        let per = (dt / h).round() as usize;
        let steps = (seconds / h) as usize;
        for k in 0..steps {
            let t = k as f64 * h;
            let a = amp * (1.3 * t).sin() + 0.5 * amp * (0.7 * t).cos();
            if k % per == 0 {
                out.push(AxisState {
                    v,
                    swing: th,
                    swing_rate: thd,
                });
            }
            // Full nonlinear pendulum on an accelerating support.
            let thdd = -(GRAVITY * th.sin() + a * th.cos()) / l;
            thd += h * thdd;
            th += h * thd;
            v += h * a;
        }
        out
    }

    #[test]
    fn length_of_a_pendulum_on_a_moving_support() {
        for &l in &[0.3, 1.0, 2.5] {
            let mut tr = PayloadTracker::new(1, 0.03, TrackerSettings::default());
            for s in pendulum(l, 0.3, 20.0) {
                tr.update(&[s]);
            }
            let (est, rel) = tr.length().expect("an estimate");
            assert!((est / l - 1.0).abs() < 0.02, "l {l}: estimated {est}");
            assert!(rel < 0.02, "l {l}: relative error bar {rel}");
        }
    }

    #[test]
    fn no_swing_gives_no_length() {
        let mut tr = PayloadTracker::new(1, 0.03, TrackerSettings::default());
        for k in 0..500 {
            tr.update(&[AxisState {
                v: 0.01 * k as f64,
                swing: 0.0,
                swing_rate: 0.0,
            }]);
        }
        assert!(tr.length().is_none());
    }

    #[test]
    fn mass_from_hover_thrust_and_a_climb() {
        let mut tr = PayloadTracker::new(1, 0.03, TrackerSettings::default());
        let m = 1.25;
        // Climbing with a_down = −0.5 m/s²: thrust m (g + 0.5).
        for k in 0..200 {
            tr.update_vertical(m * (GRAVITY + 0.5), -0.5 * 0.03 * k as f64);
        }
        let est = tr.total_mass().unwrap();
        assert!((est - m).abs() < 1e-5, "{est}");
    }
}
