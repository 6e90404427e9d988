//! The second-order Butterworth low-pass PX4 applies to its IMU data (`IMU_ACCEL_CUTOFF`,
//! `IMU_GYRO_CUTOFF`; PX4's `LowPassFilter2p`), run sample by sample.
//!
//! Continuous prototype H(s) = ω_c² / (s² + √2 ω_c s + ω_c²), discretised by the bilinear
//! transform with the cutoff pre-warped, Ω = tan(π f_c / f_s):
//!
//!   b₀ = Ω²/c, b₁ = 2b₀, b₂ = b₀, a₁ = 2(Ω² − 1)/c, a₂ = (1 − √2 Ω + Ω²)/c,
//!   c = 1 + √2 Ω + Ω²,
//!
//! in direct form II (w_k = x_k − a₁ w_{k−1} − a₂ w_{k−2}, y_k = b₀ w_k + b₁ w_{k−1} + b₂
//! w_{k−2}). Unit gain at DC, −3 dB and −90° at f_c, −40 dB/decade above. A cutoff of 0 or at
//! or above the Nyquist frequency passes the signal through unchanged (PX4 does the same).

/// One channel of the second-order Butterworth low-pass (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LowPass2 {
    b0: f64,
    a1: f64,
    a2: f64,
    w1: f64,
    w2: f64,
    pass: bool,
}

impl LowPass2 {
    /// A filter of cutoff `cutoff_hz` for samples arriving at `sample_hz`, at rest at 0.
    pub fn new(sample_hz: f64, cutoff_hz: f64) -> Self {
        let pass = !(cutoff_hz > 0.0 && sample_hz > 0.0 && cutoff_hz < 0.5 * sample_hz);
        if pass {
            return Self {
                b0: 1.0,
                a1: 0.0,
                a2: 0.0,
                w1: 0.0,
                w2: 0.0,
                pass,
            };
        }
        let ohm = (std::f64::consts::PI * cutoff_hz / sample_hz).tan();
        let s2 = std::f64::consts::SQRT_2 * ohm;
        let c = 1.0 + s2 + ohm * ohm;
        Self {
            b0: ohm * ohm / c,
            a1: 2.0 * (ohm * ohm - 1.0) / c,
            a2: (1.0 - s2 + ohm * ohm) / c,
            w1: 0.0,
            w2: 0.0,
            pass,
        }
    }

    /// Filter one sample.
    #[inline]
    pub fn apply(&mut self, x: f64) -> f64 {
        if self.pass {
            return x;
        }
        let w0 = x - self.a1 * self.w1 - self.a2 * self.w2;
        let y = self.b0 * (w0 + 2.0 * self.w1 + self.w2);
        self.w2 = self.w1;
        self.w1 = w0;
        y
    }

    /// Settle the filter on a constant input `x` (its output is `x` from the next sample on).
    pub fn reset(&mut self, x: f64) {
        if !self.pass {
            let w = x / (1.0 + self.a1 + self.a2);
            self.w1 = w;
            self.w2 = w;
        }
    }
}

/// Three channels of [`LowPass2`] with one cutoff (an IMU's x, y, z).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LowPass2x3 {
    ch: [LowPass2; 3],
}

impl LowPass2x3 {
    /// Three channels at rest at 0.
    pub fn new(sample_hz: f64, cutoff_hz: f64) -> Self {
        Self {
            ch: [LowPass2::new(sample_hz, cutoff_hz); 3],
        }
    }

    /// Filter one three-axis sample.
    #[inline]
    pub fn apply(&mut self, x: [f64; 3]) -> [f64; 3] {
        [
            self.ch[0].apply(x[0]),
            self.ch[1].apply(x[1]),
            self.ch[2].apply(x[2]),
        ]
    }

    /// Settle every channel on the constant sample `x`.
    pub fn reset(&mut self, x: [f64; 3]) {
        for (c, v) in self.ch.iter_mut().zip(x) {
            c.reset(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Steady-state amplitude and phase [rad] of the filter's answer to a sine.
    fn response(fs: f64, fc: f64, f: f64) -> (f64, f64) {
        let mut lp = LowPass2::new(fs, fc);
        let n = (fs * 40.0 / f.min(fc)).ceil() as usize + 4000;
        let w = 2.0 * std::f64::consts::PI * f / fs;
        let (mut c, mut s) = (0.0, 0.0);
        let tail = n / 2;
        // Project the settled second half on cos/sin over whole periods (approximately).
        for k in 0..n {
            let y = lp.apply((w * k as f64).sin());
            if k >= tail {
                c += y * (w * k as f64).cos();
                s += y * (w * k as f64).sin();
            }
        }
        let m = (n - tail) as f64 / 2.0;
        ((c * c + s * s).sqrt() / m, c.atan2(s))
    }

    #[test]
    fn unit_dc_gain_and_reset_settles_at_once() {
        let mut lp = LowPass2::new(1000.0, 30.0);
        lp.reset(2.5);
        for _ in 0..10 {
            assert!((lp.apply(2.5) - 2.5).abs() < 1e-12);
        }
    }

    #[test]
    fn half_power_and_quarter_turn_at_the_cutoff() {
        // Bilinear with pre-warping maps the analogue cutoff exactly: |H| = 1/√2, ∠H = −90°.
        let (a, ph) = response(1000.0, 30.0, 30.0);
        assert!((a - std::f64::consts::FRAC_1_SQRT_2).abs() < 5e-3, "{a}");
        assert!((ph + std::f64::consts::FRAC_PI_2).abs() < 2e-2, "{ph}");
    }

    #[test]
    fn forty_decibels_per_decade_above_the_cutoff() {
        // Analogue |H(j10ω_c)| = 1/√(1 + 10⁴) ≈ 0.0100; the bilinear map is slightly lower.
        let (a, _) = response(8000.0, 30.0, 300.0);
        assert!((a - 0.0100).abs() < 5e-4, "{a}");
    }

    #[test]
    fn a_cutoff_at_or_above_nyquist_passes_through() {
        let mut lp = LowPass2::new(50.0, 30.0);
        assert_eq!(lp.apply(1.25), 1.25);
        let mut off = LowPass2::new(1000.0, 0.0);
        assert_eq!(off.apply(-3.0), -3.0);
    }
}
