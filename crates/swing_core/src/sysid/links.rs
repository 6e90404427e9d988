//! The payload's links, from how the swing answers the vehicle's motion.
//!
//! A payload hung as a double pendulum (point mass m₁ at l₁ below the vehicle, m₂ at l₂
//! below m₁) from a vehicle accelerating horizontally by `a` answers, linearised, with the
//! upper link's angle
//!
//! ```text
//! θ₁/a = −(γ s² + 1/g) / (α s⁴ + β s² + 1),
//! α = l₁l₂ / ((1+μ) g²),  β = (l₁+l₂) / g,  γ = l₂ / ((1+μ) g²),  μ = m₂/m₁,
//! ```
//!
//! whatever holds the vehicle (PX4's loops, an MPC): the vehicle's acceleration is the
//! forcing. A single pendulum is α = γ = 0, β = l/g. The three coefficients give the three
//! unknowns: l₁ = α/γ, l₂ = βg − l₁, 1 + μ = l₂/(γg²). The swing sensor sees only the upper
//! link, so a single pendulum fitted to it takes a double pendulum for one of some length
//! in between; its lower mode, which an MPC on a delay-coordinate model can excite
//! unseen, is what this finds.
//!
//! The equation is fitted in continuous time through a state-variable filter λ⁴/(s+λ)⁴
//! (derivatives of the filtered signals, not of noisy data), with terms for the links'
//! damping and a constant for the sensor's bias. Plain least squares is biased: the swing
//! sensor's noise is in the regressors, and it pulls α and γ to zero. So the fit is
//! refined by instrumental variables (Young's refined IV, simplified): the swing of the
//! current estimate, simulated noise-free from the measured velocity, stands in for the
//! measured one in the regressors, until the estimate settles. Started from a few physical
//! guesses; the double pendulum is reported when it is physical, its simulated swing
//! matches the measured one no worse than the single pendulum's, and its second mode is one
//! the data can show and that matters: below the filter's corner (above it the filter has
//! taken the mode out of the data, and what is fitted there is the noise's) and carrying a
//! share of the upper link's static answer to the vehicle's acceleration ([`modes`]).
//!
//! The simulation error alone does not tell the two apart on long cables: over a flight of
//! minutes the single pendulum's error is mostly the slow phase drift of a lightly damped
//! swing, and a real second link with a heavy lower mass lowers it by 1–6 % only, no more
//! than a spurious fit to a single pendulum does. The second mode's place and share do:
//! spurious fits put it above the corner or give it almost nothing.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::linalg::expm;
use crate::plant::GRAVITY;

/// Settings of [`double_pendulum`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkSettings {
    /// Corner λ of the state-variable filter [rad/s]: above the swing modes of links of
    /// 0.2 m and longer (≤ 9 rad/s), below the sensor noise.
    pub filter_rate: f64,
    /// Refined-IV iterations from each start.
    pub iterations: usize,
    /// Leading span left out while the filters settle [s].
    pub settle: f64,
    /// Damping ratio of the instrument model's modes (the simulated swing must not ring
    /// forever on a start that is off).
    pub instrument_damping: f64,
    /// Smallest relative drop of the swing's simulation error that adopts the double
    /// pendulum over the single one (0: no worse).
    pub min_improvement: f64,
    /// Smallest share of the upper link's static answer that the second mode must carry
    /// ([`modes`]) for the double pendulum to be adopted: below it the second link
    /// changes nothing an MPC could excite.
    pub min_mode_share: f64,
    /// Highest rate of the second mode that is adopted, as a fraction of `filter_rate`:
    /// above the corner the filter has taken the mode out of the data.
    pub max_second_mode: f64,
    /// Largest mass ratio m₂/m₁ taken as physical.
    pub max_mass_ratio: f64,
}

impl Default for LinkSettings {
    fn default() -> Self {
        Self {
            filter_rate: 10.0,
            iterations: 10,
            settle: 5.0,
            instrument_damping: 0.05,
            min_improvement: 0.0,
            min_mode_share: 0.01,
            max_second_mode: 1.0,
            max_mass_ratio: 10.0,
        }
    }
}

impl LinkSettings {
    /// The evidence asked of a swing estimated from the IMU (`sensors::swing`): a 10 % drop
    /// of the simulation error, whatever the second mode. That swing is computed from the
    /// vehicle's own acceleration, so it carries the airframe's drag and the attitude loop's
    /// answer beside the cable's pull, and the double pendulum's extra terms fit them as a
    /// second link: on `robustness-imu` (seed 1) single payloads on 2.1 and 2.4 m (samples
    /// 213, 206) came out as two links of 1.2–1.7 m whose second mode carried 14–22 % of the
    /// static answer at a 1–6 % lower error, and no candidate then passed on the twin.
    pub fn for_imu_swing() -> Self {
        Self {
            min_improvement: 0.1,
            min_mode_share: 0.0,
            max_second_mode: f64::INFINITY,
            ..Self::default()
        }
    }
}

/// A double pendulum found in the swing.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DoublePendulum {
    /// Length of the upper link l₁ [m].
    pub length: f64,
    /// Length of the lower link l₂ [m].
    pub length2: f64,
    /// Mass ratio μ = m₂/m₁ of the lower to the upper mass.
    pub mass_ratio: f64,
    /// Error of the double pendulum's simulated swing over the single pendulum's (RMS).
    pub error_ratio: f64,
    /// Rate of the second mode ω₂ [rad/s] ([`modes`]); 0 in files written before it was
    /// recorded.
    #[serde(default)]
    pub second_mode: f64,
    /// The second mode's share of the upper link's static answer ([`modes`]).
    #[serde(default)]
    pub mode_share: f64,
}

/// Coefficients of the filtered equation: [α, δ₃, β, δ₁, γ, bias] (δ: damping terms).
pub(super) type Coefficients = [f64; 6];

/// First-order-hold discretisation of x' = A x + b u (one input) at `dt`: (Φ, Γ₁, Γ₂) with
/// x_{k+1} = Φ x_k + Γ₁ u_k + Γ₂ (u_{k+1} − u_k), exact for an input linear between samples.
/// A zero-order hold would lag the filtered signals by half a sample against the
/// feedthrough of the fourth derivative.
fn foh(a: &DMatrix<f64>, b: &DMatrix<f64>, dt: f64) -> (DMatrix<f64>, DVector<f64>, DVector<f64>) {
    let n = a.nrows();
    let mut m = DMatrix::<f64>::zeros(n + 2, n + 2);
    m.view_mut((0, 0), (n, n)).copy_from(&(a * dt));
    m.view_mut((0, n), (n, 1)).copy_from(&(b * dt));
    m[(n, n + 1)] = 1.0;
    let e = expm(&m).unwrap_or_else(|| DMatrix::from_element(n + 2, n + 2, f64::NAN));
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.column(n).rows(0, n).into_owned(),
        e.column(n + 1).rows(0, n).into_owned(),
    )
}

/// s^k·λ⁴/(s+λ)⁴ applied to `u` (sampled every `dt`, linear between samples) for k = 0…4:
/// `out[k][i]`.
fn filtered(u: &[f64], dt: f64, lambda: f64) -> [Vec<f64>; 5] {
    let c = [
        lambda.powi(4),
        4.0 * lambda.powi(3),
        6.0 * lambda.powi(2),
        4.0 * lambda,
    ];
    let mut a = DMatrix::<f64>::zeros(4, 4);
    for i in 0..3 {
        a[(i, i + 1)] = 1.0;
    }
    for (j, cj) in c.iter().enumerate() {
        a[(3, j)] = -cj;
    }
    let mut b = DMatrix::<f64>::zeros(4, 1);
    b[(3, 0)] = c[0];
    let (phi, g1, g2) = foh(&a, &b, dt);
    let mut x = DVector::<f64>::zeros(4);
    let mut out: [Vec<f64>; 5] = Default::default();
    for o in out.iter_mut() {
        o.reserve(u.len());
    }
    for (i, &uk) in u.iter().enumerate() {
        for k in 0..4 {
            out[k].push(x[k]);
        }
        out[4].push(c[0] * uk - (0..4).map(|j| c[j] * x[j]).sum::<f64>());
        let next = u.get(i + 1).copied().unwrap_or(uk);
        x = &phi * &x + &g1 * uk + &g2 * (next - uk);
    }
    out
}

/// Noise-free swing of the coefficients' model, driven by the measured velocity `v`: the
/// modes of α s⁴ + β s² + 1 with `damping`, numerator −(γ s³ + s/g) acting on v.
pub(super) fn simulate(coef: &Coefficients, v: &[f64], dt: f64, damping: f64) -> Option<Vec<f64>> {
    let [alpha, _, beta, _, gamma, _] = *coef;
    // Denominator as a monic quartic: a single pendulum (α = 0) is one mode of β s² + 1.
    let (den, num): (Vec<f64>, Vec<f64>) = if alpha.abs() < 1e-12 {
        if beta <= 0.0 {
            return None;
        }
        let w = (1.0 / beta).sqrt();
        (vec![w * w, 2.0 * damping * w], vec![0.0, -w * w / GRAVITY])
    } else {
        let disc = beta * beta - 4.0 * alpha;
        if alpha < 0.0 || beta <= 0.0 || disc <= 0.0 {
            return None;
        }
        let w1 = ((beta - disc.sqrt()) / (2.0 * alpha)).sqrt();
        let w2 = ((beta + disc.sqrt()) / (2.0 * alpha)).sqrt();
        let (p1, p2) = ([w1 * w1, 2.0 * damping * w1], [w2 * w2, 2.0 * damping * w2]);
        // (s² + p1[1] s + p1[0])(s² + p2[1] s + p2[0]) = s⁴ + d3 s³ + d2 s² + d1 s + d0
        let den = vec![
            p1[0] * p2[0],
            p1[1] * p2[0] + p1[0] * p2[1],
            p1[0] + p2[0] + p1[1] * p2[1],
            p1[1] + p2[1],
        ];
        // α s⁴ + β s² + 1 = α (s² + w1²)(s² + w2²): dividing by α scales the numerator.
        (
            den,
            vec![0.0, -1.0 / (GRAVITY * alpha), 0.0, -gamma / alpha],
        )
    };
    let n = den.len();
    let mut a = DMatrix::<f64>::zeros(n, n);
    for i in 0..n - 1 {
        a[(i, i + 1)] = 1.0;
    }
    for (j, dj) in den.iter().enumerate() {
        a[(n - 1, j)] = -dj;
    }
    let mut b = DMatrix::<f64>::zeros(n, 1);
    b[(n - 1, 0)] = 1.0;
    let (phi, g1, g2) = foh(&a, &b, dt);
    if phi.iter().any(|x| !x.is_finite()) {
        return None;
    }
    // The recursion on the stack (n ≤ 4): the swing-scale fit runs it hundreds of times over
    // a whole flight, where a heap matrix product per sample would dominate.
    let mut p = [[0.0; 4]; 4];
    let (mut h1, mut h2) = ([0.0; 4], [0.0; 4]);
    for r in 0..n {
        for c in 0..n {
            p[r][c] = phi[(r, c)];
        }
        h1[r] = g1[r];
        h2[r] = g2[r];
    }
    let mut x = [0.0; 4];
    let mut out = Vec::with_capacity(v.len());
    for (i, &vk) in v.iter().enumerate() {
        out.push(num.iter().zip(x.iter()).map(|(c, xi)| c * xi).sum::<f64>());
        let dv = v.get(i + 1).copied().unwrap_or(vk) - vk;
        let mut next = [0.0; 4];
        for r in 0..n {
            next[r] = (0..n).map(|c| p[r][c] * x[c]).sum::<f64>() + h1[r] * vk + h2[r] * dv;
        }
        x = next;
    }
    out.iter().all(|y| y.is_finite()).then_some(out)
}

/// The filtered data of one axis: regressors and target of the equation.
struct Filtered {
    theta: [Vec<f64>; 5],
    v: [Vec<f64>; 5],
    from: usize,
}

impl Filtered {
    /// Target −(F θ + F a / g), a = s v.
    fn target(&self, i: usize) -> f64 {
        -(self.theta[0][i] + self.v[1][i] / GRAVITY)
    }
}

/// Columns of the regression for the model with `double` (α, δ₃, β, δ₁, γ, bias) or without
/// (β, δ₁, bias) the lower link, from filtered swings `th` and filtered velocity `fv`.
fn row(th: &[Vec<f64>; 5], fv: &[Vec<f64>; 5], i: usize, double: bool) -> Vec<f64> {
    if double {
        vec![th[4][i], th[3][i], th[2][i], th[1][i], fv[3][i], 1.0]
    } else {
        vec![th[2][i], th[1][i], 1.0]
    }
}

/// One IV step: solve Zᵀ X c = Zᵀ y with instruments from `inst` (filtered simulated swing).
fn iv_step(f: &Filtered, inst: &[Vec<f64>; 5], double: bool) -> Option<Vec<f64>> {
    let k = if double { 6 } else { 3 };
    let mut zx = DMatrix::<f64>::zeros(k, k);
    let mut zy = DVector::<f64>::zeros(k);
    for i in f.from..f.theta[0].len() {
        let x = row(&f.theta, &f.v, i, double);
        let z = row(inst, &f.v, i, double);
        let y = f.target(i);
        for r in 0..k {
            for c in 0..k {
                zx[(r, c)] += z[r] * x[c];
            }
            zy[r] += z[r] * y;
        }
    }
    let sol = zx.lu().solve(&zy)?;
    sol.iter()
        .all(|x| x.is_finite())
        .then(|| sol.iter().copied().collect())
}

/// Full coefficients from a solution of the double (6) or single (3) regression.
fn coefficients(sol: &[f64]) -> Coefficients {
    match sol.len() {
        6 => [sol[0], sol[1], sol[2], sol[3], sol[4], sol[5]],
        _ => [0.0, 0.0, sol[0], sol[1], 0.0, sol[2]],
    }
}

/// Physical links of coefficients: (l₁, l₂, μ), or `None`.
fn links(coef: &Coefficients, max_mass_ratio: f64) -> Option<(f64, f64, f64)> {
    let [alpha, _, beta, _, gamma, _] = *coef;
    if !(alpha > 0.0 && gamma > 0.0 && beta > 0.0) {
        return None;
    }
    let l1 = alpha / gamma;
    let l2 = beta * GRAVITY - l1;
    let mu = l2 / (gamma * GRAVITY * GRAVITY) - 1.0;
    (l1 > 0.0 && l2 > 0.0 && mu > 0.0 && mu <= max_mass_ratio).then_some((l1, l2, mu))
}

/// The two modes of physical links (l₁, l₂, μ): their rates ω₁ < ω₂ [rad/s] and the second
/// mode's share of the upper link's static answer to the vehicle's acceleration, |r₂/x₂| /
/// |r₁/x₁|, where θ₁/a = r₁/(s² − x₁) + r₂/(s² − x₂) and x = −ω² (the two parts add up to the
/// static −1/g).
pub fn modes(l1: f64, l2: f64, mu: f64) -> (f64, f64, f64) {
    let [alpha, _, beta, _, gamma, _] = from_links(l1, l2, mu);
    // α x² + β x + 1 = 0 in x = s²: two negative roots for any physical links.
    let disc = (beta * beta - 4.0 * alpha).max(0.0).sqrt();
    let x1 = (-beta + disc) / (2.0 * alpha);
    let x2 = (-beta - disc) / (2.0 * alpha);
    let residue = |xi: f64, xj: f64| -(gamma * xi + 1.0 / GRAVITY) / (alpha * (xi - xj));
    let share = (residue(x2, x1) / x2).abs() / (residue(x1, x2) / x1).abs();
    ((-x1).sqrt(), (-x2).sqrt(), share)
}

/// The links with the heaviest lower mass whose two modes (the vehicle held) are `omega1` <
/// `omega2` [rad/s]: (l, μ) with both links l long and μ = m₂/m₁, or `None` unless
/// 0 < `omega1` < `omega2`. The two rates fix l₁ + l₂ = g (ω₁² + ω₂²)/(ω₁² ω₂²) and
/// l₁ l₂ = (1 + μ) g²/(ω₁² ω₂²); real lengths need (l₁ + l₂)² ≥ 4 l₁ l₂, so μ is largest at
/// equal lengths: μ = (ω₁² + ω₂²)²/(4 ω₁² ω₂²) − 1. The plant of the selection's second
/// link (`design::twin::TwinPlant::with_second_link`): of all links a swing's two rates
/// allow, the one whose lower mode an MPC excites most.
pub fn heaviest_links(omega1: f64, omega2: f64) -> Option<(f64, f64)> {
    if !(omega1.is_finite() && omega2.is_finite() && 0.0 < omega1 && omega1 < omega2) {
        return None;
    }
    let (x1, x2) = (omega1 * omega1, omega2 * omega2);
    let length = GRAVITY * (x1 + x2) / (2.0 * x1 * x2);
    let mu = (x1 + x2).powi(2) / (4.0 * x1 * x2) - 1.0;
    (length.is_finite() && mu.is_finite() && mu > 0.0).then_some((length, mu))
}

/// Coefficients of physical links (inverse of [`links`]).
fn from_links(l1: f64, l2: f64, mu: f64) -> Coefficients {
    let g2 = GRAVITY * GRAVITY;
    [
        l1 * l2 / ((1.0 + mu) * g2),
        0.0,
        (l1 + l2) / GRAVITY,
        0.0,
        l2 / ((1.0 + mu) * g2),
        0.0,
    ]
}

/// Refined IV from `start`: the settled solution, or `None` when the model leaves the
/// physical range on the way.
fn refine(
    f: &Filtered,
    v: &[f64],
    dt: f64,
    start: Coefficients,
    double: bool,
    s: &LinkSettings,
) -> Option<Coefficients> {
    let mut coef = start;
    for _ in 0..s.iterations {
        let sim = simulate(&coef, v, dt, s.instrument_damping)?;
        let inst = filtered(&sim, dt, s.filter_rate);
        let next = coefficients(&iv_step(f, &inst, double)?);
        let change = (next[0] - coef[0]).abs() / next[0].abs().max(1e-12)
            + (next[2] - coef[2]).abs() / next[2].abs().max(1e-12);
        coef = next;
        if change < 1e-4 {
            break;
        }
    }
    Some(coef)
}

/// RMS error of the coefficients' simulated swing against the measured one (each with its
/// mean removed: the sensor's bias and a steady wind's lean are not the links').
fn simulation_error(
    coef: &Coefficients,
    v: &[f64],
    theta: &[f64],
    dt: f64,
    from: usize,
    damping: f64,
) -> f64 {
    let sim = match simulate(coef, v, dt, damping) {
        Some(s) => s,
        None => return f64::INFINITY,
    };
    let n = (theta.len() - from) as f64;
    let mt = theta[from..].iter().sum::<f64>() / n;
    let ms = sim[from..].iter().sum::<f64>() / n;
    (theta[from..]
        .iter()
        .zip(&sim[from..])
        .map(|(t, s)| ((t - mt) - (s - ms)).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

/// The payload's links as the vehicle's motion forces them: the single pendulum that
/// explains the swing best and, when the swing shows one, a double pendulum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkFit {
    /// Length of the single pendulum l = βg [m]: from how the swing answers the vehicle's
    /// acceleration, so neither the vehicle's mass nor what holds it enters, and the
    /// quasi-static lean under a slow manoeuvre (which can outweigh the free oscillation in
    /// the swing's spectrum) is part of the model rather than a spurious peak.
    pub length: f64,
    /// RMS error of the single pendulum's simulated swing against the measured one [rad].
    pub error: f64,
    /// A second link, when the double pendulum explains the swing clearly better.
    pub double: Option<DoublePendulum>,
}

/// Fit the payload's links to the swing `theta` [rad] of the upper link, answering the
/// vehicle's velocity `v` [m/s] on the same axis, both sampled every `dt` [s]; `None` when
/// the data cannot say (too short, not finite, or no physical single pendulum fits).
pub fn fit(v: &[f64], theta: &[f64], dt: f64, settings: &LinkSettings) -> Option<LinkFit> {
    if !dt.is_finite() || dt <= 0.0 || v.len() != theta.len() {
        return None;
    }
    let from = (settings.settle / dt).ceil() as usize;
    if v.len() < from.saturating_add(100) {
        return None;
    }
    if v.iter().chain(theta).any(|x| !x.is_finite()) {
        return None;
    }
    let f = Filtered {
        theta: filtered(theta, dt, settings.filter_rate),
        v: filtered(v, dt, settings.filter_rate),
        from,
    };
    // The single pendulum first: least squares (its bias is small, one mode of one
    // length), refined by IV. Where the swing is a double pendulum's whose lower link is
    // the longer, one pendulum is a poor instrument and the IV can leave the physical
    // range; the least-squares pendulum then stands, as the scale of the double's starts.
    let ls = coefficients(&iv_step(&f, &f.theta, false)?);
    let single = refine(&f, v, dt, ls, false, settings).unwrap_or(ls);
    let single_error = simulation_error(&single, v, theta, dt, from, settings.instrument_damping);
    let l = single[2] * GRAVITY;
    if !(l > 0.0 && single_error.is_finite()) {
        return None;
    }
    let mut best: Option<(f64, (f64, f64, f64))> = None;
    for (r1, r2, mu) in [
        (0.8, 0.4, 0.3),
        (0.6, 0.6, 0.3),
        (0.9, 0.2, 0.2),
        (0.5, 0.8, 1.0),
        (0.8, 0.6, 1.0),
        (0.4, 0.4, 0.3),
    ] {
        let Some(coef) = refine(&f, v, dt, from_links(r1 * l, r2 * l, mu), true, settings) else {
            continue;
        };
        let Some(phys) = links(&coef, settings.max_mass_ratio) else {
            continue;
        };
        let err = simulation_error(&coef, v, theta, dt, from, settings.instrument_damping);
        if best.is_none_or(|(e, _)| err < e) {
            best = Some((err, phys));
        }
    }
    let double = best.and_then(|(err, (length, length2, mass_ratio))| {
        let error_ratio = err / single_error;
        let (_, second_mode, share) = modes(length, length2, mass_ratio);
        let seen = second_mode < settings.max_second_mode * settings.filter_rate
            && share >= settings.min_mode_share;
        (seen && error_ratio <= 1.0 - settings.min_improvement).then_some(DoublePendulum {
            length,
            length2,
            mass_ratio,
            error_ratio,
            second_mode,
            mode_share: share,
        })
    });
    Some(LinkFit {
        length: l,
        error: single_error,
        double,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_heaviest_links_of_two_rates_have_those_modes_and_no_heavier_lower_mass() {
        for (w1, w2) in [(3.283, 11.0), (2.0, 2.5), (5.0, 12.0), (1.2, 9.0)] {
            let (l, mu) = heaviest_links(w1, w2).expect("two rates");
            let (m1, m2, _) = modes(l, l, mu);
            assert!((m1 - w1).abs() < 1e-9 * w1, "{m1} for {w1}");
            assert!((m2 - w2).abs() < 1e-9 * w2, "{m2} for {w2}");
            // Unequal links of the same two rates carry a lighter lower mass: with
            // l₁ = l(1 − e), l₂ = l(1 + e) the product falls by 1 − e², and μ with it.
            for e in [0.1, 0.3] {
                let (a, b) = (l * (1.0 - e), l * (1.0 + e));
                let mu_e = (1.0 + mu) * (1.0 - e * e) - 1.0;
                if mu_e > 0.0 {
                    let (n1, n2, _) = modes(a, b, mu_e);
                    assert!((n1 - w1).abs() < 1e-9 * w1 && (n2 - w2).abs() < 1e-9 * w2);
                    assert!(mu_e < mu);
                }
            }
        }
        for (w1, w2) in [
            (3.0, 3.0),
            (4.0, 3.0),
            (0.0, 3.0),
            (f64::NAN, 3.0),
            (1.0, f64::INFINITY),
        ] {
            assert_eq!(heaviest_links(w1, w2), None, "{w1}, {w2}");
        }
    }

    #[test]
    fn mode_rates_of_equal_links_match_the_closed_form() {
        // Equal links l: ω² = (g/l)(1 + μ ± √(μ(1 + μ))).
        let l = 0.7;
        for mu in [0.05, 0.3, 1.0, 4.0] {
            let (w1, w2, share) = modes(l, l, mu);
            let root = (mu * (1.0 + mu)).sqrt();
            let want1 = (GRAVITY / l * (1.0 + mu - root)).sqrt();
            let want2 = (GRAVITY / l * (1.0 + mu + root)).sqrt();
            assert!(
                (w1 - want1).abs() < 1e-9 && (w2 - want2).abs() < 1e-9,
                "μ = {mu}"
            );
            assert!(share > 0.0 && share.is_finite(), "μ = {mu}: {share}");
        }
        // A vanishing lower mass leaves the second mode nothing of the static answer.
        let shares: Vec<f64> = [0.3, 0.03, 0.003]
            .iter()
            .map(|&mu| modes(1.0, 0.5, mu).2)
            .collect();
        assert!(
            shares[0] > shares[1] && shares[1] > shares[2] && shares[2] < 5e-3,
            "{shares:?}"
        );
    }

    #[test]
    fn filter_derivatives_of_a_sine_match_the_closed_form() {
        // Steady state of s^k λ⁴/(s+λ)⁴ on sin(ωt): gain ω^k λ⁴/(λ²+ω²)², phase k·90° − 4·atan(ω/λ).
        let (dt, w, lam) = (0.001, 2.0, 10.0);
        let u: Vec<f64> = (0..20_000).map(|i| (w * i as f64 * dt).sin()).collect();
        let out = filtered(&u, dt, lam);
        let i = 19_000;
        let t = i as f64 * dt;
        for (k, o) in out.iter().enumerate() {
            let gain = w.powi(k as i32) * lam.powi(4) / (lam * lam + w * w).powi(2);
            let phase = k as f64 * std::f64::consts::FRAC_PI_2 - 4.0 * (w / lam).atan();
            let want = gain * (w * t + phase).sin();
            assert!(
                (o[i] - want).abs() < 1e-4 * gain.max(1.0),
                "k={k}: {} vs {want}",
                o[i]
            );
        }
    }
}
