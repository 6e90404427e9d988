//! The swing's spectrum: Welch's averaged periodogram on a fine grid of rates, and the
//! second mode it shows.
//!
//! A double pendulum's swing rings at two rates. On a swing sensor the links fit
//! (`sysid::links`) finds the second link; on a swing estimated from the IMU it asks for a
//! 10 % lower simulation error first ([`LinkSettings::for_imu_swing`]), because the IMU's
//! swing carries the airframe's drag and the attitude loop, which a second link's terms
//! would fit as well. The doubles that matter to an input shaper rarely clear that bar, and
//! a shaper of one mode leaves them swinging at the other. Their second mode shows plainly
//! in the spectrum instead: a second peak well above the floor a single payload leaves
//! there (its side lobes, the drag's answer to the steps, the noise).
//!
//! Welch's estimate (Hann segments, half overlap, each segment's mean removed) is evaluated
//! by a direct transform on a grid much finer than the segments' resolution, so a peak's
//! rate is read to the grid's step, not to a bin.
//!
//! [`LinkSettings::for_imu_swing`]: super::links::LinkSettings::for_imu_swing

use std::f64::consts::PI;

use serde::{Deserialize, Serialize};

/// Settings of [`second_peak`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpectralSettings {
    /// Length of Welch's segments [s]: 256 samples at the default 0.03 s, a resolution of
    /// 2π/7.68 = 0.82 rad/s, so a flight of a minute averages about fifteen segments.
    pub segment: f64,
    /// Band searched for peaks [rad/s]: the swing modes of links from about 0.07 m to
    /// 10 m, above the flight's steps.
    pub band: [f64; 2],
    /// Step of the grid of rates [rad/s], a sixteenth of the segments' resolution.
    pub step: f64,
    /// Smallest power of the second peak relative to the highest for the swing to show a
    /// second mode (dimensionless). Set on `robustness-imu` seeds 4 and 5, on the IMU swing
    /// of all 56 samples whose law was the shaper: every double the one-mode shaper left
    /// swinging read 0.16–0.96, every double it damped 0.019 or less, every single payload
    /// 0.008 or less.
    pub min_ratio: f64,
}

impl Default for SpectralSettings {
    fn default() -> Self {
        Self {
            segment: 7.68,
            band: [1.0, 12.0],
            step: 0.05,
            min_ratio: 0.06,
        }
    }
}

/// The second-highest peak of a swing's spectrum.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SecondPeak {
    /// Its rate [rad/s].
    pub omega: f64,
    /// The highest peak's rate [rad/s].
    pub first: f64,
    /// Its power over the highest peak's.
    pub power_ratio: f64,
    /// Whether it is high enough to be a second mode ([`SpectralSettings::min_ratio`]).
    pub shown: bool,
}

/// Welch's power of `signal` (sampled at `dt`) at each rate of `omegas` [rad/s], over Hann
/// segments of `segment` samples at half overlap, each segment's mean removed; empty when
/// the signal is shorter than one segment. Scaled as the mean squared magnitude of the
/// windowed segments' transforms: a unit sinusoid at ω reads N²/16 at ω for a Hann window
/// of N samples.
pub fn welch_power(signal: &[f64], dt: f64, segment: usize, omegas: &[f64]) -> Vec<f64> {
    if segment < 2 || signal.len() < segment {
        return Vec::new();
    }
    let window: Vec<f64> = (0..segment)
        .map(|k| 0.5 - 0.5 * (2.0 * PI * k as f64 / (segment - 1) as f64).cos())
        .collect();
    let hop = (segment / 2).max(1);
    let segments: Vec<Vec<f64>> = (0..=(signal.len() - segment) / hop)
        .map(|s| {
            let seg = &signal[s * hop..s * hop + segment];
            let mean = seg.iter().sum::<f64>() / segment as f64;
            seg.iter()
                .zip(&window)
                .map(|(x, w)| (x - mean) * w)
                .collect()
        })
        .collect();
    let mut cos = vec![0.0; segment];
    let mut sin = vec![0.0; segment];
    omegas
        .iter()
        .map(|&omega| {
            for k in 0..segment {
                let (s, c) = (omega * dt * k as f64).sin_cos();
                cos[k] = c;
                sin[k] = s;
            }
            let total: f64 = segments
                .iter()
                .map(|seg| {
                    let re: f64 = seg.iter().zip(&cos).map(|(x, c)| x * c).sum();
                    let im: f64 = seg.iter().zip(&sin).map(|(x, s)| x * s).sum();
                    re * re + im * im
                })
                .sum();
            total / segments.len() as f64
        })
        .collect()
}

/// The highest local maximum of `signal`'s Welch spectrum above the swing's first mode,
/// against the first mode's own peak: the first mode's peak is the spectrum's highest point
/// within a main lobe of `first_mode` [rad/s] (the single pendulum the white-box fitted),
/// where that point is a local maximum;
/// the second is sought above it by at least a main lobe and within the settings' band. A
/// double pendulum's second mode is its faster one; below the first lie the lines of the
/// flight's own steps, which on the IMU's swing (it reads the drag) can outgrow the
/// swing's. `None` when the signal is shorter than a segment, not finite or constant, or
/// shows no such pair of peaks.
pub fn second_peak(
    signal: &[f64],
    dt: f64,
    first_mode: f64,
    settings: &SpectralSettings,
) -> Option<SecondPeak> {
    let [lo, hi] = settings.band;
    let usable = dt > 0.0 && settings.step > 0.0 && hi > lo && first_mode.is_finite();
    if !usable || signal.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let segment = (settings.segment / dt).round() as usize;
    // A Hann window's main lobe spans two resolutions either side of its peak.
    let lobe = 2.0 * 2.0 * PI / (segment as f64 * dt);
    let from = (first_mode - lobe).max(lo);
    if from >= hi {
        return None;
    }
    let n = ((hi - from) / settings.step).floor() as usize + 1;
    let omegas: Vec<f64> = (0..n).map(|i| from + i as f64 * settings.step).collect();
    let power = welch_power(signal, dt, segment, &omegas);
    if power.len() < 3 {
        return None;
    }
    let peaks: Vec<usize> = (1..power.len() - 1)
        .filter(|&i| power[i] > power[i - 1] && power[i] >= power[i + 1])
        .collect();
    let highest = |keep: &dyn Fn(f64) -> bool| {
        peaks
            .iter()
            .copied()
            .filter(|&i| keep(omegas[i]))
            .max_by(|a, b| power[*a].total_cmp(&power[*b]))
    };
    // The first mode's peak is the spectrum's highest point within a lobe of the stated
    // rate, and a peak: not the flank of a stronger line beside it.
    let first = (0..power.len())
        .filter(|&i| (omegas[i] - first_mode).abs() <= lobe)
        .max_by(|a, b| power[*a].total_cmp(&power[*b]))
        .filter(|i| peaks.contains(i))?;
    // Below rounding of the signal's own size the spectrum is of a constant.
    let scale = signal.iter().fold(0.0_f64, |m, v| m.max(v.abs())) * segment as f64;
    if power[first] <= f64::EPSILON * scale * scale {
        return None;
    }
    let second = highest(&|w| w >= omegas[first] + lobe)?;
    let power_ratio = power[second] / power[first];
    Some(SecondPeak {
        omega: omegas[second],
        first: omegas[first],
        power_ratio,
        shown: power_ratio >= settings.min_ratio,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tones(parts: &[(f64, f64)], dt: f64, n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| {
                parts
                    .iter()
                    .map(|(a, w)| a * (w * dt * k as f64).sin())
                    .sum()
            })
            .collect()
    }

    #[test]
    fn a_sinusoid_reads_its_closed_form_power_at_its_rate() {
        // A whole number of cycles per segment: the Hann-windowed transform of a unit
        // sinusoid at its own rate is N/4 in magnitude, so its power N²/16.
        let (dt, n) = (0.03, 256);
        let omega = 2.0 * PI * 10.0 / (n as f64 * dt);
        let x = tones(&[(1.0, omega)], dt, 4 * n);
        let p = welch_power(&x, dt, n, &[omega])[0];
        let expected = (n * n) as f64 / 16.0;
        assert!((p / expected - 1.0).abs() < 0.02, "{p} vs {expected}");
    }

    #[test]
    fn two_tones_give_their_rates_and_the_square_of_their_amplitude_ratio() {
        let dt = 0.03;
        let x = tones(&[(1.0, 3.3), (0.4, 7.4)], dt, 2000);
        let peak = second_peak(&x, dt, 3.0, &SpectralSettings::default()).unwrap();
        assert!((peak.first - 3.3).abs() <= 0.05, "{peak:?}");
        assert!((peak.omega - 7.4).abs() <= 0.05, "{peak:?}");
        assert!((peak.power_ratio - 0.16).abs() < 0.02, "{peak:?}");
        assert!(peak.shown);
    }

    #[test]
    fn a_single_tone_shows_no_second_mode() {
        // Only the Hann window's side lobes (−31 dB) and their neighbours remain.
        let dt = 0.03;
        let x = tones(&[(1.0, 4.1)], dt, 2000);
        let peak = second_peak(&x, dt, 4.0, &SpectralSettings::default());
        assert!(
            peak.is_none_or(|p| !p.shown && p.power_ratio < 1e-3),
            "{peak:?}"
        );
    }

    #[test]
    fn a_weak_second_tone_is_below_the_bar_and_a_constant_or_short_signal_has_no_peak() {
        let dt = 0.03;
        let s = SpectralSettings::default();
        let x = tones(&[(1.0, 3.3), (0.15, 8.2)], dt, 2000);
        let peak = second_peak(&x, dt, 3.5, &s).unwrap();
        assert!((peak.power_ratio - 0.0225).abs() < 0.005, "{peak:?}");
        assert!(!peak.shown);
        assert_eq!(second_peak(&[0.2; 2000], dt, 3.5, &s), None);
        assert_eq!(second_peak(&x[..100], dt, 3.5, &s), None);
        assert_eq!(second_peak(&x, dt, f64::NAN, &s), None);
        let mut bad = x.clone();
        bad[7] = f64::NAN;
        assert_eq!(second_peak(&bad, dt, 3.5, &s), None);
    }

    #[test]
    fn lines_below_the_first_mode_are_not_a_second_mode_however_strong() {
        // The flight's steps read by the IMU's swing: a line below the pendulum's, stronger.
        let dt = 0.03;
        let s = SpectralSettings::default();
        let x = tones(&[(2.0, 1.05), (1.0, 3.9)], dt, 2000);
        let peak = second_peak(&x, dt, 3.8, &s);
        assert!(peak.is_none_or(|p| !p.shown), "{peak:?}");
        // The first mode is the one near the white-box's, not the highest line.
        let x = tones(&[(2.0, 1.05), (1.0, 3.9), (0.5, 8.0)], dt, 2000);
        let peak = second_peak(&x, dt, 3.8, &s).unwrap();
        assert!((peak.first - 3.9).abs() <= 0.05, "{peak:?}");
        assert!((peak.omega - 8.0).abs() <= 0.05, "{peak:?}");
        assert!((peak.power_ratio - 0.25).abs() < 0.03, "{peak:?}");
        // No peak near the stated first mode: nothing to compare against.
        assert_eq!(second_peak(&x, dt, 6.0, &s), None);
    }
}
