//! The IMU swing estimate told apart from drag by the pendulum's own dynamics.
//!
//! The IMU reads the cable's pull and the airframe's drag on the same two channels
//! ([`super::swing`]): a gust, or a wind the drag model does not know, reads as swing (on a
//! 0.1 kg payload under a 0.95 kg vehicle, 1.5 m/s of gust reads as about 25°). No filter on
//! frequency alone tells them apart, since a gust's drag changes as fast as the swing does.
//! The pendulum does: a payload on a cable of length l under a vehicle accelerating by a
//! (world frame, per horizontal axis) swings as
//!
//!   θ̈ = −(g/l) θ − c θ̇ − a/l,
//!
//! so a swing can only grow as the vehicle's motion drives it, while drag may move
//! independently. Per axis the observer carries x = (θ, θ̇, δ), δ the drag read as swing (a
//! random walk), measures z = θ + δ (the low-passed estimate) and is driven by a, the
//! low-passed derivative of the vehicle's velocity. The model is discretised by the
//! semi-implicit Euler step (ω ← ω + dt(−(g/l)θ − cω − a/l), θ ← θ + dt ω: area-preserving,
//! so the undamped pendulum neither grows nor decays), and the gain is the steady-state
//! Kalman gain of that model under the noise levels below. Steady flight reads no swing
//! whatever the drag, and the rate is the observer's θ̇, not a differenced estimate.
//!
//! The length and damping come from the training flight (`sysid::swing_scale`'s fit of
//! the same pendulum to the estimate).

use crate::plant::GRAVITY;

/// Measurement noise of the low-passed estimate [rad] (its noise at the default IMU,
/// vibration and 10 Hz low-pass is about 0.3°; the rest covers the estimate's first-order
/// scale and tilt errors).
const MEASUREMENT_STD: f64 = 0.02;
/// Unmodelled angular acceleration of the swing (a second link, the payload's own drag, the
/// length's error) [rad/s² per √Hz].
const SWING_FORCING_STD: f64 = 0.5;
/// How fast the drag read as swing may wander [rad/s per √Hz]: a 1.5 m/s gust's drag on a
/// light payload moves it by about 0.4 rad within 2 s.
const DRAG_WANDER_STD: f64 = 0.05;

/// The pendulum-aware swing observer, both axes (module docs). No allocation.
#[derive(Clone, Copy, Debug)]
pub struct PendulumObserver {
    a: [[f64; 3]; 3],
    b: [f64; 3],
    k: [f64; 3],
    x: [[f64; 3]; 2],
    started: bool,
}

impl PendulumObserver {
    /// An observer for a pendulum of `length` [m] and damping ratio `damping`, fed every
    /// `dt` s; None unless the length and the step are positive and finite.
    pub fn new(length: f64, damping: f64, dt: f64) -> Option<Self> {
        if !(length.is_finite() && length > 0.0 && dt.is_finite() && dt > 0.0) {
            return None;
        }
        let w2 = GRAVITY / length;
        let c = 2.0 * damping.max(0.0) * w2.sqrt();
        let keep = 1.0 - c * dt;
        let a = [
            [1.0 - w2 * dt * dt, dt * keep, 0.0],
            [-w2 * dt, keep, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let b = [-dt * dt / length, -dt / length, 0.0];
        let k = steady_gain(&a, dt);
        Some(Self {
            a,
            b,
            k,
            x: [[0.0; 3]; 2],
            started: false,
        })
    }

    /// The steady-state gain on (θ, θ̇, δ) per unit of innovation.
    pub fn gain(&self) -> [f64; 3] {
        self.k
    }

    /// Start over from the next sample: the payload hanging still, everything measured read
    /// as drag.
    pub fn restart(&mut self) {
        self.started = false;
    }

    /// Feed one low-passed estimate `z` (N, E) [rad] and the vehicle's acceleration `accel`
    /// (N, E) [m/s²]; returns the swing (N, E) [rad].
    #[inline]
    pub fn update(&mut self, z: [f64; 2], accel: [f64; 2]) -> [f64; 2] {
        if !self.started {
            self.x = [[0.0, 0.0, z[0]], [0.0, 0.0, z[1]]];
            self.started = true;
            return self.angle();
        }
        for (i, x) in self.x.iter_mut().enumerate() {
            let mut p = [0.0; 3];
            for (r, pr) in p.iter_mut().enumerate() {
                *pr = self.a[r][0] * x[0]
                    + self.a[r][1] * x[1]
                    + self.a[r][2] * x[2]
                    + self.b[r] * accel[i];
            }
            let innovation = z[i] - (p[0] + p[2]);
            for r in 0..3 {
                x[r] = p[r] + self.k[r] * innovation;
            }
        }
        self.angle()
    }

    /// The latest swing (N, E) [rad].
    pub fn angle(&self) -> [f64; 2] {
        [self.x[0][0], self.x[1][0]]
    }

    /// The latest swing rate (N, E) [rad/s].
    pub fn rate(&self) -> [f64; 2] {
        [self.x[0][1], self.x[1][1]]
    }

    /// The latest drag read as swing (N, E) [rad].
    pub fn drag(&self) -> [f64; 2] {
        [self.x[0][2], self.x[1][2]]
    }
}

/// The steady-state Kalman gain of x ← A x + w, z = θ + δ + v (module constants), by
/// iterating the Riccati recursion to its fixed point.
fn steady_gain(a: &[[f64; 3]; 3], dt: f64) -> [f64; 3] {
    let q = [
        0.0,
        SWING_FORCING_STD * SWING_FORCING_STD * dt,
        DRAG_WANDER_STD * DRAG_WANDER_STD * dt,
    ];
    let r = MEASUREMENT_STD * MEASUREMENT_STD;
    let mut p = [[0.0; 3]; 3];
    for (i, row) in p.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let mut k = [0.0; 3];
    for _ in 0..20_000 {
        // Predict: P ← A P Aᵀ + Q.
        let mut ap = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                ap[i][j] = (0..3).map(|m| a[i][m] * p[m][j]).sum();
            }
        }
        let mut pp = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                pp[i][j] = (0..3).map(|m| ap[i][m] * a[j][m]).sum::<f64>();
            }
            pp[i][i] += q[i];
        }
        // Update with H = (1, 0, 1): S = P₀₀ + 2P₀₂ + P₂₂ + R, K = P Hᵀ / S.
        let ph = [
            pp[0][0] + pp[0][2],
            pp[1][0] + pp[1][2],
            pp[2][0] + pp[2][2],
        ];
        let s = ph[0] + ph[2] + r;
        let next = [ph[0] / s, ph[1] / s, ph[2] / s];
        for i in 0..3 {
            for j in 0..3 {
                p[i][j] = pp[i][j] - next[i] * ph[j];
            }
        }
        let change = (0..3).map(|i| (next[i] - k[i]).abs()).fold(0.0, f64::max);
        k = next;
        if change < 1e-12 {
            break;
        }
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The truth: a point pendulum under a vehicle whose acceleration is given, integrated
    /// finely (RK4 at a tenth of the observer's step).
    fn pendulum(length: f64, accel: impl Fn(f64) -> f64, dt: f64, n: usize) -> Vec<f64> {
        let f = |t: f64, s: [f64; 2]| [s[1], -(GRAVITY / length) * s[0] - accel(t) / length];
        let h = dt / 10.0;
        let mut s = [0.0, 0.0];
        let mut out = Vec::with_capacity(n);
        for k in 0..n {
            out.push(s[0]);
            for j in 0..10 {
                let t = k as f64 * dt + j as f64 * h;
                let k1 = f(t, s);
                let k2 = f(
                    t + h / 2.0,
                    [s[0] + h / 2.0 * k1[0], s[1] + h / 2.0 * k1[1]],
                );
                let k3 = f(
                    t + h / 2.0,
                    [s[0] + h / 2.0 * k2[0], s[1] + h / 2.0 * k2[1]],
                );
                let k4 = f(t + h, [s[0] + h * k3[0], s[1] + h * k3[1]]);
                for i in 0..2 {
                    s[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                }
            }
        }
        out
    }

    #[test]
    fn drag_is_not_read_as_swing_and_the_swing_is() {
        // A 1 m pendulum driven by a 1 s acceleration pulse, and the drag of a gust rising
        // to 0.3 rad over 2 s from 6 s that moves nothing: the raw measurement carries both.
        let (dt, n, l) = (0.01, 1500, 1.0);
        let accel = |t: f64| if (1.0..2.0).contains(&t) { 1.0 } else { 0.0 };
        let drag = |t: f64| 0.3 * ((t - 6.0) / 2.0).clamp(0.0, 1.0);
        let theta = pendulum(l, accel, dt, n);
        let mut obs = PendulumObserver::new(l, 0.0, dt).unwrap();
        let (mut err2, mut raw2, mut swing2) = (0.0, 0.0, 0.0);
        for (k, th) in theta.iter().enumerate() {
            let t = k as f64 * dt;
            let est = obs.update([th + drag(t), 0.0], [accel(t), 0.0]);
            if t >= 6.0 {
                err2 += (est[0] - th).powi(2);
                raw2 += drag(t).powi(2);
                swing2 += th * th;
            }
        }
        let (err, raw, swing) = (err2.sqrt(), raw2.sqrt(), swing2.sqrt());
        // The drag alone would read as 0.3 rad of swing, more than the swing itself; the
        // observer cuts what of it reaches the swing at least fourfold (about fivefold).
        assert!(raw > swing, "raw {raw} swing {swing}");
        assert!(err < 0.25 * raw, "swing error {err} of raw {raw}");
        assert!((obs.drag()[0] - 0.3).abs() < 0.01, "drag {:?}", obs.drag());
        assert!(obs.angle()[1].abs() < 1e-12);
    }

    #[test]
    fn a_driven_swing_is_followed_with_its_rate() {
        let (dt, n, l) = (0.01, 2000, 0.7);
        let accel = |t: f64| if (1.0..1.5).contains(&t) { 2.0 } else { 0.0 };
        let theta = pendulum(l, accel, dt, n);
        let mut obs = PendulumObserver::new(l, 0.0, dt).unwrap();
        let (mut err, mut rate_err, mut peak): (f64, f64, f64) = (0.0, 0.0, 0.0);
        for (k, th) in theta.iter().enumerate() {
            let t = k as f64 * dt;
            obs.update([*th, 0.0], [accel(t), 0.0]);
            if t > 3.0 && k + 1 < theta.len() {
                err = err.max((obs.angle()[0] - th).abs());
                let rate = (theta[k + 1] - theta[k - 1]) / (2.0 * dt);
                rate_err = rate_err.max((obs.rate()[0] - rate).abs());
                peak = peak.max(th.abs());
            }
        }
        assert!(peak > 0.05, "the pulse must swing the payload ({peak})");
        assert!(err < 0.02 * peak, "swing error {err} of {peak}");
        let peak_rate = peak * (GRAVITY / l).sqrt();
        assert!(
            rate_err < 0.02 * peak_rate,
            "rate error {rate_err} of {peak_rate}"
        );
    }

    #[test]
    fn the_gain_converges_and_the_model_keeps_energy() {
        let obs = PendulumObserver::new(1.0, 0.0, 0.01).unwrap();
        let k = obs.gain();
        assert!(k.iter().all(|g| g.is_finite() && *g > 0.0), "{k:?}");
        let a = obs.a;
        let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
        assert!((det - 1.0).abs() < 1e-12, "det {det}");
        assert!(PendulumObserver::new(0.0, 0.0, 0.01).is_none());
        assert!(PendulumObserver::new(f64::NAN, 0.0, 0.01).is_none());
    }
}
