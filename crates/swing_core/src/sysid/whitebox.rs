//! White-box baseline (thesis 4.3): the linearised floating pendulum
//! ([`PendulumModel`], eq. 5.7–5.8, states s = [v, θ, θ̇], ZOH-discretised) with estimated
//! payload parameters.
//!
//! Cable length from the swing frequency (eq. 4.8): ω_n = √(g/l · (m_Q+m_p)/m_Q), so
//! l = g (m_Q+m_p) / (m_Q ω_n²), with ω_n = 2π f and f the FFT peak in **Hz** (section
//! 4.3.3 labels it rad/s, a slip). Payload mass by recursive least squares on hover thrust:
//! T_z = (m_Q + m_p)(g − a_d) (NED, a_d the vertical acceleration), one scalar parameter.
//! g is the plant's [`crate::plant::GRAVITY`]; the functions take it as an argument only so that a caller
//! can state it explicitly.
//!
//! Delay form: the measured states are x = [v, θ] only (θ̇ is hidden, as for the data-driven
//! models), so the model is written over z_k = [x_k; x_{k−1}] (q = 2), exactly. From
//! y_k = C s_k and y_{k−1} = C A_d⁻¹ (s_k − B_d u_{k−1}) — four equations in the four
//! unknowns (s_k, u_{k−1}) — s_k = L z_k with L the first three rows of
//! [C 0; C A_d⁻¹ −C A_d⁻¹ B_d]⁻¹. Then x_{k+1} = C A_d L z_k + C B_d u_k: an exact
//! representation of the discretised 3-state model (its outputs agree sample for sample
//! once two samples of history exist), with no past input in the state. For several axes
//! (states [v_1…v_a, θ_1…θ_a]) the axes are decoupled copies.

use nalgebra::{DMatrix, DVector};

use super::dmdc::delay_form;
use super::error::{config, data, SysidError};
use super::hankel::Trajectory;
use super::model::{LinearModel, Offset, WhiteboxEstimates};
use crate::plant::PendulumModel;

/// Cable length from the swing frequency `freq_hz` (eq. 4.8) under gravity `gravity`
/// [m/s²] (the plant's is [`crate::plant::GRAVITY`]).
pub fn cable_length(freq_hz: f64, vehicle_mass: f64, payload_mass: f64, gravity: f64) -> f64 {
    let w = 2.0 * std::f64::consts::PI * freq_hz;
    gravity * (vehicle_mass + payload_mass) / (vehicle_mass * w * w)
}

/// In-place iterative radix-2 FFT (length a power of two).
fn fft(re: &mut [f64], im: &mut [f64]) {
    let n = re.len();
    let mut j = 0;
    for i in 1..n {
        let mut bit = n >> 1;
        while j & bit != 0 {
            j ^= bit;
            bit >>= 1;
        }
        j |= bit;
        if i < j {
            re.swap(i, j);
            im.swap(i, j);
        }
    }
    let mut len = 2;
    while len <= n {
        let ang = -2.0 * std::f64::consts::PI / len as f64;
        for start in (0..n).step_by(len) {
            for k in 0..len / 2 {
                let (wr, wi) = ((ang * k as f64).cos(), (ang * k as f64).sin());
                let (a, b) = (start + k, start + k + len / 2);
                let (xr, xi) = (re[b] * wr - im[b] * wi, re[b] * wi + im[b] * wr);
                re[b] = re[a] - xr;
                im[b] = im[a] - xi;
                re[a] += xr;
                im[a] += xi;
            }
        }
        len <<= 1;
    }
}

/// Dominant frequency [Hz] of `signal` sampled at `dt`, searched in [f_min, f_max].
///
/// The mean is removed, a Hann window applied, the record zero-padded to ≥ 16× its length
/// (power of two) and the single-sided amplitude spectrum's peak refined by a parabola
/// through the log amplitudes of its neighbours.
pub fn fft_peak_frequency(
    signal: &[f64],
    dt: f64,
    f_min: f64,
    f_max: f64,
) -> Result<f64, SysidError> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(config(format!("dt must be positive, not {dt}")));
    }
    if !(f_min >= 0.0 && f_max > f_min) {
        return Err(config(format!(
            "frequency band [{f_min}, {f_max}] Hz is empty"
        )));
    }
    if signal.len() < 8 {
        return Err(data(format!(
            "{} samples are too few for a spectrum (need at least 8)",
            signal.len()
        )));
    }
    if let Some(k) = signal.iter().position(|v| !v.is_finite()) {
        return Err(data(format!("swing signal is not finite at sample {k}")));
    }
    let n = signal.len();
    let mean = signal.iter().sum::<f64>() / n as f64;
    let size = (16 * n).next_power_of_two();
    let mut re = vec![0.0; size];
    let mut im = vec![0.0; size];
    for (k, v) in signal.iter().enumerate() {
        let w = 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / (n - 1) as f64).cos();
        re[k] = (v - mean) * w;
    }
    fft(&mut re, &mut im);
    let df = 1.0 / (size as f64 * dt);
    let k_lo = ((f_min / df).ceil() as usize).max(1);
    let k_hi = ((f_max / df).floor() as usize).min(size / 2 - 1);
    if k_lo > k_hi {
        return Err(config("frequency band holds no spectral line"));
    }
    let amp = |k: usize| re[k].hypot(im[k]);
    let kp = (k_lo..=k_hi)
        .max_by(|a, b| amp(*a).total_cmp(&amp(*b)))
        .expect("non-empty band");
    if amp(kp) == 0.0 {
        return Err(data(
            "the swing signal is constant: no oscillation to measure",
        ));
    }
    let (l, c, r) = (amp(kp - 1).ln(), amp(kp).ln(), amp(kp + 1).ln());
    let denom = l - 2.0 * c + r;
    let shift = if denom.abs() > 0.0 {
        0.5 * (l - r) / denom
    } else {
        0.0
    };
    Ok((kp as f64 + shift.clamp(-0.5, 0.5)) * df)
}

/// Total mass by RLS on hover thrust: T_z,k = M (g − a_d,k) + e_k, forgetting factor λ.
///
/// Returns the estimate after every sample (the last one is the final estimate).
pub fn rls_mass(
    thrust_vertical: &[f64],
    acc_down: &[f64],
    gravity: f64,
    forgetting: f64,
    initial: f64,
) -> Result<Vec<f64>, SysidError> {
    if thrust_vertical.len() != acc_down.len() {
        return Err(data(format!(
            "{} thrust samples but {} acceleration samples",
            thrust_vertical.len(),
            acc_down.len()
        )));
    }
    if thrust_vertical.is_empty() {
        return Err(data("no thrust samples for the mass estimate"));
    }
    if !(forgetting > 0.0 && forgetting <= 1.0) {
        return Err(config(format!(
            "forgetting factor must be in (0, 1], not {forgetting}"
        )));
    }
    let mut theta = initial;
    let mut p = 1e3;
    let mut out = Vec::with_capacity(acc_down.len());
    for (k, (t, a)) in thrust_vertical.iter().zip(acc_down).enumerate() {
        if !(t.is_finite() && a.is_finite()) {
            return Err(data(format!(
                "thrust or acceleration not finite at sample {k}"
            )));
        }
        let phi = gravity - a;
        let gain = p * phi / (forgetting + phi * p * phi);
        theta += gain * (t - phi * theta);
        p = (p - gain * phi * p) / forgetting;
        out.push(theta);
    }
    Ok(out)
}

/// Top rows (2 × 4, 2 × 1) of the exact q = 2 delay form of one axis (see module docs).
pub fn axis_delay_rows(
    params: &PendulumModel,
    dt: f64,
) -> Result<(DMatrix<f64>, DMatrix<f64>), SysidError> {
    params.validate()?;
    if !(dt.is_finite() && dt > 0.0) {
        return Err(config(format!("dt must be positive, not {dt}")));
    }
    let (ad, bd) = params.discrete(dt);
    if !ad.iter().chain(bd.iter()).all(|v| v.is_finite()) {
        return Err(SysidError::Identification(format!(
            "the white-box model does not discretise over dt = {dt} s (masses, length and \
             friction out of range)"
        )));
    }
    let ad_inv = ad
        .clone()
        .try_inverse()
        .ok_or_else(|| SysidError::Identification("discrete white-box A is singular".into()))?;
    // Outputs [v, θ] of s = [v, θ, θ̇].
    let c = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    let mut m = DMatrix::<f64>::zeros(4, 4);
    m.view_mut((0, 0), (2, 3)).copy_from(&c);
    m.view_mut((2, 0), (2, 3)).copy_from(&(&c * &ad_inv));
    m.view_mut((2, 3), (2, 1))
        .copy_from(&(-(&c * &ad_inv * &bd)));
    let m_inv = m.try_inverse().ok_or_else(|| {
        SysidError::Identification(
            "swing rate cannot be reconstructed from two samples at this dt".into(),
        )
    })?;
    let l = m_inv.view((0, 0), (3, 4)).into_owned();
    Ok((&c * &ad * l, &c * &bd))
}

/// The white-box model for `axes` decoupled axes (states [v…, θ…], inputs one per axis),
/// in the q = 2 delay form, with the estimates recorded in the diagnostics.
pub fn model(
    params: &PendulumModel,
    axes: usize,
    dt: f64,
    frequency_hz: Option<f64>,
) -> Result<LinearModel, SysidError> {
    if axes == 0 {
        return Err(config("at least one axis is needed"));
    }
    let (top1, b1) = axis_delay_rows(params, dt)?;
    let n = 2 * axes;
    let mut a_top = DMatrix::<f64>::zeros(n, 2 * n);
    let mut b_top = DMatrix::<f64>::zeros(n, axes);
    for ax in 0..axes {
        // Axis state s ∈ {0: v, 1: θ} lives at index ax (v) or axes + ax (θ).
        let idx = |s: usize| if s == 0 { ax } else { axes + ax };
        for i in 0..2 {
            for lag in 0..2 {
                for s in 0..2 {
                    a_top[(idx(i), lag * n + idx(s))] = top1[(i, lag * 2 + s)];
                }
            }
            b_top[(idx(i), ax)] = b1[(i, 0)];
        }
    }
    let mut out = delay_form(
        "whitebox",
        dt,
        2,
        0,
        Offset::None,
        vec![0.0; axes],
        &a_top,
        &b_top,
        &DVector::zeros(n),
    );
    out.diagnostics.whitebox = Some(WhiteboxEstimates {
        vehicle_mass: params.m_q,
        payload_mass: params.m_p,
        length: params.l,
        frequency_hz,
        friction: params.c,
        links: None,
        second_peak: None,
        fft_length: None,
        swing_noise: None,
        attitude_lag: None,
        velocity_residual: None,
    });
    Ok(out)
}

/// Apply the offset handling to a white-box model using training data: `mean` subtracts the
/// training input mean; `affine` learns the one-step residual of each state as a constant
/// plus a term in its axis's velocity, by least squares over the training flight.
///
/// Why the velocity term: what the pendulum model leaves out of a flight is mostly the
/// airframe's drag, −c_d (v − w) in the wind w, and, for a swing estimated from the IMU, the
/// same drag read as swing (`crate::sensors::swing`). Both are affine in the velocity. A
/// constant alone would carry the drag at the training flight's mean speed as a disturbance
/// at every speed, hover included: the closed-loop check then starts its hover on a push
/// the flight does not have (on a long cable, read as several degrees of swing). The
/// velocity coefficients go into the model's newest-velocity column and are recorded in
/// `diagnostics.whitebox.velocity_residual`; a flight whose velocity barely varies gets the
/// constant alone.
pub fn apply_offset(
    model: &mut LinearModel,
    traj: &Trajectory<'_>,
    offset: Offset,
) -> Result<(), SysidError> {
    if traj.n != model.n() || traj.m != model.m() {
        return Err(data(
            "training data does not match the white-box model's columns",
        ));
    }
    model.offset = offset;
    match offset {
        Offset::None => {}
        Offset::Mean => model.input_mean = traj.input_mean(),
        Offset::Affine => {
            let (n, q) = (model.n(), model.delays);
            if traj.len < q + 1 {
                return Err(data("too few samples to learn the affine offset"));
            }
            // States are [v_1…v_a, θ_1…θ_a]: row i belongs to axis i mod a.
            let axes = n / 2;
            let velocity = |i: usize| i % axes.max(1);
            let rows = traj.len - q;
            let mut resid = DMatrix::<f64>::zeros(rows, n);
            for (r, k) in ((q - 1)..traj.len - 1).enumerate() {
                let hist = &traj.x[(k + 1 - q) * n..(k + 1) * n];
                let pred = model.predict(hist, traj.input(k))?;
                for i in 0..n {
                    resid[(r, i)] = traj.state(k + 1)[i] - pred[i];
                }
            }
            // Each axis's velocity at the newest frame of every residual's history.
            let speeds: Vec<Vec<f64>> = (0..axes.max(1))
                .map(|ax| ((q - 1)..traj.len - 1).map(|k| traj.state(k)[ax]).collect())
                .collect();
            let mut slopes = vec![0.0; n];
            for i in 0..n {
                let (c0, slope) = affine_fit(&speeds[velocity(i)], resid.column(i).as_slice());
                model.c[i] += c0;
                // The newest frame's velocity column of row i.
                model.a[(i, velocity(i))] += slope;
                slopes[i] = slope;
            }
            if let Some(wb) = model.diagnostics.whitebox.as_mut() {
                wb.velocity_residual = Some(slopes);
            }
        }
    }
    model.fingerprint = traj.fingerprint();
    Ok(())
}

/// Least-squares (intercept, slope) of `y` on `x`; a slope of 0 (the mean alone) where `x`
/// barely varies (a spread below 1 mm/s).
fn affine_fit(x: &[f64], y: &[f64]) -> (f64, f64) {
    let count = x.len() as f64;
    let mx = x.iter().sum::<f64>() / count;
    let my = y.iter().sum::<f64>() / count;
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    if sxx / count < 1e-6 {
        return (my, 0.0);
    }
    let slope = sxy / sxx;
    (my - slope * mx, slope)
}

/// Standard deviation of white noise on a smooth `signal`, from its third differences: white
/// noise of std σ gives third differences of std σ·√20 (weights 1, −3, 3, −1), while a swing
/// sampled well above its frequency contributes little. The median absolute difference
/// (over 0.6745) keeps the transients of a manoeuvre out; `None` for fewer than 8 samples.
pub fn noise_std(signal: &[f64]) -> Option<f64> {
    if signal.len() < 8 {
        return None;
    }
    let mut d: Vec<f64> = signal
        .windows(4)
        .map(|w| (w[3] - 3.0 * w[2] + 3.0 * w[1] - w[0]).abs())
        .collect();
    let mid = d.len() / 2;
    let (_, median, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    let sigma = *median / 0.674_489_75 / 20f64.sqrt();
    sigma.is_finite().then_some(sigma)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_std_recovers_white_noise_on_a_swing() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for sigma in [0.0005, 0.005] {
            // A 1 Hz, 5° swing at 0.03 s plus uniform noise of std σ (half-width σ√3).
            let x: Vec<f64> = (0..10_000)
                .map(|k| {
                    let t = 0.03 * k as f64;
                    0.087 * (std::f64::consts::TAU * t).sin()
                        + sigma * 3f64.sqrt() * rng.random_range(-1.0..1.0)
                })
                .collect();
            let est = noise_std(&x).unwrap();
            assert!((est / sigma - 1.0).abs() < 0.15, "{est} vs {sigma}");
        }
        assert_eq!(noise_std(&[0.0; 5]), None);
    }

    #[test]
    fn fft_matches_direct_dft() {
        let mut re: Vec<f64> = (0..8)
            .map(|k| (k as f64 * 0.3).sin() + 0.1 * k as f64)
            .collect();
        let orig = re.clone();
        let mut im = vec![0.0; 8];
        fft(&mut re, &mut im);
        for f in 0..8 {
            let (mut r, mut i) = (0.0, 0.0);
            for (k, v) in orig.iter().enumerate() {
                let ang = -2.0 * std::f64::consts::PI * (f * k) as f64 / 8.0;
                r += v * ang.cos();
                i += v * ang.sin();
            }
            assert!((re[f] - r).abs() < 1e-12 && (im[f] - i).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_parameters_name_the_field() {
        let p = PendulumModel {
            l: 0.0,
            ..Default::default()
        };
        let e = axis_delay_rows(&p, 0.03).unwrap_err();
        assert!(
            matches!(e, SysidError::Config(ref s) if s.field == "l"),
            "{e}"
        );
    }
}
