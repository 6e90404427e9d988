//! Optional preprocessing of thesis 4.6.6.
//!
//! * States: a quadratic-regression smoother (as MATLAB's `smoothdata(…, 'loess', w)`):
//!   each sample is replaced by the value at that sample of a quadratic fitted by weighted
//!   least squares to the `window` samples around it, with tricube weights
//!   w_j = (1 − |d_j/d_max|³)³ (d_max just beyond the farthest sample, so every sample
//!   counts). Near the ends the window is shifted inside the record. A quadratic passes
//!   through unchanged.
//! * Inputs: a Gaussian-weighted moving average over `window` samples with
//!   σ = (window − 1)/5 samples (MATLAB's `gausswin` default), truncated and renormalised at
//!   the ends. It keeps the sharp steps of the setpoint better than a polynomial fit.

use super::error::{config, SysidError};

fn check(window: usize, len: usize) -> Result<(), SysidError> {
    if window < 3 {
        return Err(config(format!(
            "smoothing window must be ≥ 3 samples, not {window}"
        )));
    }
    if len < window {
        return Err(super::error::data(format!(
            "{len} samples are fewer than the smoothing window of {window}"
        )));
    }
    Ok(())
}

/// Quadratic-regression (loess-type) smoothing of one signal.
pub fn quadratic(signal: &[f64], window: usize) -> Result<Vec<f64>, SysidError> {
    check(window, signal.len())?;
    let n = signal.len();
    let half = window / 2;
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let lo = k.saturating_sub(half).min(n - window);
        let hi = lo + window;
        let dmax = (k - lo).max(hi - 1 - k) as f64 + 1.0;
        // Normal equations of the weighted quadratic in d = j − k.
        let mut s = [0.0f64; 5];
        let mut t = [0.0f64; 3];
        for (j, y) in signal.iter().enumerate().take(hi).skip(lo) {
            let d = j as f64 - k as f64;
            let r = (d.abs() / dmax).powi(3);
            let w = (1.0 - r).powi(3);
            let mut pw = w;
            for sv in s.iter_mut() {
                *sv += pw;
                pw *= d;
            }
            t[0] += w * y;
            t[1] += w * y * d;
            t[2] += w * y * d * d;
        }
        // Solve [[s0 s1 s2][s1 s2 s3][s2 s3 s4]] β = t for β0 (value at d = 0).
        let m = nalgebra::Matrix3::new(s[0], s[1], s[2], s[1], s[2], s[3], s[2], s[3], s[4]);
        let beta = m
            .lu()
            .solve(&nalgebra::Vector3::new(t[0], t[1], t[2]))
            .ok_or_else(|| config("smoothing window too small for a quadratic fit"))?;
        out.push(beta[0]);
    }
    Ok(out)
}

/// Gaussian-weighted moving average of one signal.
pub fn gaussian(signal: &[f64], window: usize) -> Result<Vec<f64>, SysidError> {
    check(window, signal.len())?;
    let n = signal.len();
    let half = (window / 2) as isize;
    let sigma = (window as f64 - 1.0) / 5.0;
    let kernel: Vec<f64> = (-half..=half)
        .map(|d| (-0.5 * (d as f64 / sigma).powi(2)).exp())
        .collect();
    let mut out = Vec::with_capacity(n);
    for k in 0..n as isize {
        let (mut acc, mut wsum) = (0.0, 0.0);
        for (i, w) in kernel.iter().enumerate() {
            let j = k + i as isize - half;
            if j >= 0 && (j as usize) < n {
                acc += w * signal[j as usize];
                wsum += w;
            }
        }
        out.push(acc / wsum);
    }
    Ok(out)
}
