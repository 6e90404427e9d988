//! The scale of the swing estimated from the IMU, from how that swing answers the vehicle's
//! motion.
//!
//! The IMU's estimate reads the cable's angle relative to the body through a scale
//! k = g·m_p/m_Q that only the unknown payload-to-vehicle mass ratio sets; the estimator
//! assumes k̂ ([`ImuSwingSettings::scale`]). To first order its output is
//! θ̂ = τ + (k/k̂)(θ − τ) + e_d, with τ the vehicle's tilt (the direction of its body z axis,
//! filtered as the estimate is) and e_d the airframe's drag read as swing (module docs of
//! [`crate::sensors::swing`]). So the true swing is θ = τ + ρ(θ̂ − τ − e_d), ρ = k̂/k, and
//! whatever hangs below the vehicle answers its velocity v as a pendulum,
//! θ = −s v/(l s² + 2ζω l s + g), whatever holds the vehicle. The fit finds the length l
//! whose simulated swing θ_l explains the estimate best:
//!
//! ```text
//! θ̂ − τ = (θ_l − τ)/ρ + c_v v + c_q v|v| + b_axis
//! ```
//!
//! is linear in (1/ρ, c_v, c_q, b) for a given l (the estimate's noise is in the regressand
//! only, so it does not bias 1/ρ); l is searched on a log grid, then l and the damping ratio
//! ζ are refined in turn (how long each manoeuvre's swing rings on weighs on 1/ρ). The swing's
//! scale is then ρ times the estimate's, so neither the payload's mass nor the vehicle's
//! enters; both axes share l and ρ. The drag terms are fitted so that the drag does not bias
//! ρ, and the estimate flown loses the quadratic one ([`DragRemoval`]). A
//! double pendulum is taken for a single one of some length in between, which leaves the
//! scale (the lean under a steady acceleration) right. Where the estimate does not follow
//! the vehicle's motion (gusty wind, a payload too light to pull), the fit says why.

use nalgebra::{DMatrix, DVector, Rotation3};
use serde::{Deserialize, Serialize};

use super::links;
use crate::plant::GRAVITY;
use crate::sensors::cable::compose_tangents;
use crate::sensors::filter::LowPass2;
use crate::sensors::ImuSwingSettings;

/// Settings of [`fit`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScaleSettings {
    /// Shortest and longest pendulum searched [m].
    pub lengths: [f64; 2],
    /// Points of the log-spaced length grid before the refinement.
    pub grid: usize,
    /// Damping ratio of the simulated pendulum the length grid is searched with.
    pub damping: f64,
    /// Range the damping ratio is refined within.
    pub dampings: [f64; 2],
    /// Leading span left out (the estimator's tare and the pendulum's start) [s].
    pub settle: f64,
    /// Smallest share of the estimate's variation (beyond drag and bias) the pendulum must
    /// explain for the fit to be used.
    pub min_explained: f64,
    /// Which of the fitted drag terms the estimate flown loses.
    pub drag: DragRemoval,
}

/// Which of the fitted drag terms ([`ScaleFit::drag_linear`], [`ScaleFit::drag_quadratic`])
/// the estimate flown loses.
///
/// The airframe's drag reads as swing, c (v − w)|v − w| in the airspeed (w the wind). A
/// linear model holds its linear part, but not its curvature: on the default step the
/// estimate reads 7.1° of drag at 2 m/s and 1.5° at 0.9 m/s, the identified model misreads
/// the step's end, and the vehicle creeps to its speed with the payload leaning 0.8–1.0°
/// 4 s after the step (0.39–0.56° with a swing sensor). The quadratic term, fitted in the
/// ground speed v, is the airframe's own coefficient whatever the wind (where v and v − w
/// keep their sign, c (v − w)² = c v² − 2cwv + cw²), so removing c v|v| leaves a drag
/// linear in v that the model holds. The linear term is the wind's (−2cw) and is kept:
/// removed in one wind it is wrong in the next, and removing both failed more of the
/// sensorless robustness study (27 of its first 208 samples, against 22 keeping both).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DragRemoval {
    /// Keep reading all the drag as swing (scaled).
    Keep,
    /// Remove the quadratic term (the default).
    #[default]
    Quadratic,
    /// Remove both terms.
    All,
}

impl DragRemoval {
    /// The name settings and reports use.
    pub fn name(self) -> &'static str {
        match self {
            DragRemoval::Keep => "keep",
            DragRemoval::Quadratic => "quadratic",
            DragRemoval::All => "all",
        }
    }

    /// The removal a name stands for, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        [DragRemoval::Keep, DragRemoval::Quadratic, DragRemoval::All]
            .into_iter()
            .find(|d| d.name() == name)
    }
}

impl Default for ScaleSettings {
    fn default() -> Self {
        Self {
            lengths: [0.1, 10.0],
            grid: 81,
            damping: 0.05,
            dampings: [1e-3, 1.0],
            settle: 5.0,
            min_explained: 0.2,
            drag: DragRemoval::Quadratic,
        }
    }
}

/// Why [`fit`] gives no scale to use: the flight cannot be fitted, or its fit does not
/// describe a payload.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ScaleRefusal {
    /// No axis was given, or the sample period is not positive.
    #[error("no axis or no sample period")]
    NoData,
    /// An axis's velocity, estimate and tilt columns differ in length.
    #[error("the axis's columns differ in length")]
    ColumnLengths,
    /// The flight is too short to fit after the settling span.
    #[error("the flight is shorter than {seconds:.1} s")]
    TooShort {
        /// The shortest flight the fit takes [s].
        seconds: f64,
    },
    /// A column holds NaN or infinity after the settling span.
    #[error("the flight's velocity, estimate or attitude is not finite")]
    NotFinite,
    /// No pendulum of the searched lengths could be simulated.
    #[error("no pendulum of the searched lengths could be simulated")]
    NoPendulum,
    /// The best pendulum lies on the length grid's bound.
    #[error(
        "the best pendulum is at the searched bound ({length:.2} m): the estimate does not \
         swing like a payload"
    )]
    AtBound {
        /// The bound's length [m].
        length: f64,
    },
    /// The refined pendulum could not be simulated.
    #[error("the best pendulum could not be simulated")]
    Unsimulated,
    /// The estimate leans against the vehicle's acceleration instead of with it.
    #[error(
        "the estimate answers the vehicle's motion with the wrong sign (1/ρ = {inverse_ratio:.3})"
    )]
    WrongSign {
        /// The fitted 1/ρ.
        inverse_ratio: f64,
    },
    /// The pendulum explains too little of the estimate beyond drag and bias.
    #[error(
        "the pendulum explains {:.0} % of the estimate (beyond drag), under {:.0} %",
        100.0 * explained,
        100.0 * minimum
    )]
    Unexplained {
        /// The share explained.
        explained: f64,
        /// The smallest share used ([`ScaleSettings::min_explained`]).
        minimum: f64,
    },
}

/// One horizontal axis of a flight on a uniform grid: the vehicle's velocity [m/s], the
/// estimator's swing [rad] and the vehicle's tilt [rad], filtered as the estimate is
/// ([`tilt`]).
#[derive(Clone, Copy, Debug)]
pub struct ScaleAxis<'a> {
    /// Velocity along the axis [m/s].
    pub velocity: &'a [f64],
    /// The IMU's swing estimate on the axis [rad].
    pub estimate: &'a [f64],
    /// The vehicle's tilt on the axis, through the estimate's low-pass [rad].
    pub tilt: &'a [f64],
}

/// What [`fit`] found.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScaleFit {
    /// ρ = k̂/k: the true swing's scale over the estimate's (θ − τ = ρ(θ̂ − τ − e_d)).
    pub ratio: f64,
    /// Length of the pendulum that explains the estimate [m].
    pub length: f64,
    /// Its damping ratio.
    pub damping: f64,
    /// Drag read as swing, linear in the velocity [rad per m/s].
    pub drag_linear: f64,
    /// Drag read as swing, quadratic in the velocity [rad per (m/s)²].
    pub drag_quadratic: f64,
    /// Share of the estimate's variation beyond drag and bias that the pendulum explains.
    pub explained: f64,
    /// Which drag terms the estimate flown loses ([`ScaleSettings::drag`]).
    pub drag_removed: DragRemoval,
    /// RMS of what is left [rad].
    pub residual: f64,
}

impl ScaleFit {
    /// The estimator's settings with this fit's scale, its pendulum for the observer that
    /// tells the swing from drag, and its drag removed ([`Self::without_drag`]): its
    /// estimate is then the swing itself.
    pub fn calibrated(&self, s: &ImuSwingSettings) -> ImuSwingSettings {
        let mut out = self.without_drag(s);
        out.scale = s.scale / self.ratio;
        out.length = self.length;
        out.damping = self.damping;
        out
    }

    /// The estimator's settings at its own scale, losing the drag this fit removes: the
    /// fitted drag in swing at scale k̂ is k̂ times it in specific force.
    pub fn without_drag(&self, s: &ImuSwingSettings) -> ImuSwingSettings {
        let mut out = s.clone();
        let (linear, quadratic) = self.removed_terms();
        for i in 0..2 {
            out.drag_linear[i] = s.drag_linear[i] - s.scale * linear;
            out.drag_quadratic[i] = s.drag_quadratic[i] - s.scale * quadratic;
        }
        out
    }

    /// The (linear, quadratic) drag terms this fit removes [rad per m/s, per (m/s)²].
    fn removed_terms(&self) -> (f64, f64) {
        match self.drag_removed {
            DragRemoval::Keep => (0.0, 0.0),
            DragRemoval::Quadratic => (0.0, self.drag_quadratic),
            DragRemoval::All => (self.drag_linear, self.drag_quadratic),
        }
    }

    /// One axis's estimate as the calibrated estimator would have made it (to first order):
    /// τ + ρ(θ̂ − τ − e_d), e_d the drag removed.
    pub fn apply(&self, axis: &ScaleAxis) -> Vec<f64> {
        self.remade(axis, self.ratio)
    }

    /// One axis's estimate as [`Self::without_drag`]'s estimator would have made it (to first
    /// order): θ̂ − e_d.
    pub fn apply_without_drag(&self, axis: &ScaleAxis) -> Vec<f64> {
        self.remade(axis, 1.0)
    }

    /// τ + ρ(θ̂ − τ − e_d) for a scale ratio ρ.
    fn remade(&self, axis: &ScaleAxis, ratio: f64) -> Vec<f64> {
        let (linear, quadratic) = self.removed_terms();
        axis.estimate
            .iter()
            .zip(axis.tilt)
            .zip(axis.velocity)
            .map(|((&e, &t), &v)| t + ratio * (e - t - linear * v - quadratic * v * v.abs()))
            .collect()
    }
}

/// The vehicle's tilt on the North and East axes (the world angles of its body z axis, as
/// [`compose_tangents`] gives a cable along it), from ZYX Euler angles sampled every `dt`,
/// through the estimate's low-pass at `cutoff` [Hz] (none at 0 or at or above Nyquist).
pub fn tilt(roll: &[f64], pitch: &[f64], yaw: &[f64], dt: f64, cutoff: f64) -> [Vec<f64>; 2] {
    let rate = 1.0 / dt;
    let filter = cutoff > 0.0 && cutoff < 0.5 * rate;
    let mut lp = [LowPass2::new(rate, cutoff), LowPass2::new(rate, cutoff)];
    let mut out = [
        Vec::with_capacity(roll.len()),
        Vec::with_capacity(roll.len()),
    ];
    for i in 0..roll.len().min(pitch.len()).min(yaw.len()) {
        let rot = Rotation3::from_euler_angles(roll[i], pitch[i], yaw[i]);
        let a = compose_tangents(rot.matrix(), [0.0, 0.0]);
        for k in 0..2 {
            let y = if !filter {
                a[k]
            } else {
                if i == 0 {
                    lp[k].reset(a[k]);
                }
                lp[k].apply(a[k])
            };
            out[k].push(y);
        }
    }
    out
}

/// Least squares of the estimate on (θ_l − τ, v, v|v|, a bias per axis) for one length:
/// (residual sum of squares, coefficients), or `None` when the pendulum cannot be simulated.
fn regress(
    axes: &[ScaleAxis],
    dt: f64,
    from: usize,
    length: f64,
    damping: f64,
) -> Option<(f64, DVector<f64>, f64)> {
    let coef: links::Coefficients = [0.0, 0.0, length / GRAVITY, 0.0, 0.0, 0.0];
    let k = 3 + axes.len();
    let mut xtx = DMatrix::<f64>::zeros(k, k);
    let mut xty = DVector::<f64>::zeros(k);
    let mut yty = 0.0;
    let mut row = DVector::<f64>::zeros(k);
    for (j, ax) in axes.iter().enumerate() {
        let sim = links::simulate(&coef, ax.velocity, dt, damping)?;
        for i in from..ax.velocity.len() {
            let v = ax.velocity[i];
            row.fill(0.0);
            row[0] = sim[i] - ax.tilt[i];
            row[1] = v;
            row[2] = v * v.abs();
            row[3 + j] = 1.0;
            let y = ax.estimate[i] - ax.tilt[i];
            xtx.ger(1.0, &row, &row, 1.0);
            xty.axpy(y, &row, 1.0);
            yty += y * y;
        }
    }
    let c = xtx.clone().cholesky()?.solve(&xty);
    // rss = yᵀy − 2cᵀXᵀy + cᵀXᵀXc
    let rss = (yty - 2.0 * c.dot(&xty) + c.dot(&(&xtx * &c))).max(0.0);
    // The same without the pendulum's column: what drag and bias alone leave.
    let sub = xtx.view((1, 1), (k - 1, k - 1)).into_owned();
    let suby = xty.rows(1, k - 1).into_owned();
    let c0 = sub.clone().cholesky()?.solve(&suby);
    let rss0 = (yty - 2.0 * c0.dot(&suby) + c0.dot(&(&sub * &c0))).max(0.0);
    Some((rss, c, rss0))
}

/// The minimum of `f` on [a, b] by golden-section search (40 steps: the bracket shrinks by
/// about 1e-8).
fn golden(mut a: f64, mut b: f64, f: impl Fn(f64) -> f64) -> f64 {
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (b - r * (b - a), a + r * (b - a));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..40 {
        if f1 <= f2 {
            b = x2;
            (x2, f2) = (x1, f1);
            x1 = b - r * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            (x1, f1) = (x2, f2);
            x2 = a + r * (b - a);
            f2 = f(x2);
        }
    }
    0.5 * (a + b)
}

/// Fit the estimate's scale and drag to the axes' motion (module docs), all sampled every
/// `dt` [s]. The error says why the fit is not to be used.
pub fn fit(axes: &[ScaleAxis], dt: f64, s: &ScaleSettings) -> Result<ScaleFit, ScaleRefusal> {
    if axes.is_empty() || !(dt.is_finite() && dt > 0.0) {
        return Err(ScaleRefusal::NoData);
    }
    let from = (s.settle / dt).ceil() as usize;
    for ax in axes {
        let n = ax.velocity.len();
        if ax.estimate.len() != n || ax.tilt.len() != n {
            return Err(ScaleRefusal::ColumnLengths);
        }
        if n < from.saturating_add(100) {
            return Err(ScaleRefusal::TooShort {
                seconds: s.settle + 100.0 * dt,
            });
        }
        let finite = |c: &[f64]| c[from..].iter().all(|x| x.is_finite());
        if !(finite(ax.velocity) && finite(ax.estimate) && finite(ax.tilt)) {
            return Err(ScaleRefusal::NotFinite);
        }
    }
    let rss = |l: f64, z: f64| regress(axes, dt, from, l, z).map_or(f64::INFINITY, |r| r.0);
    let (lo, hi) = (s.lengths[0].ln(), s.lengths[1].ln());
    let n = s.grid.max(3);
    let step = (hi - lo) / (n - 1) as f64;
    let grid: Vec<f64> = (0..n).map(|i| lo + step * i as f64).collect();
    let scores: Vec<f64> = grid.iter().map(|&g| rss(g.exp(), s.damping)).collect();
    let best = (0..n)
        .min_by(|&a, &b| scores[a].total_cmp(&scores[b]))
        .filter(|&i| scores[i].is_finite())
        .ok_or(ScaleRefusal::NoPendulum)?;
    if best == 0 || best == n - 1 {
        return Err(ScaleRefusal::AtBound {
            length: grid[best].exp(),
        });
    }
    // The damping shapes how long each manoeuvre's swing rings on, so a wrong one biases
    // the scale: refine length and damping in turn (log scales), from the grid's best.
    let (mut log_l, mut log_z) = (grid[best], s.damping.ln());
    let (z_lo, z_hi) = (s.dampings[0].ln(), s.dampings[1].ln());
    for _ in 0..3 {
        log_z = golden(z_lo, z_hi, |x| rss(log_l.exp(), x.exp()));
        log_l = golden(log_l - step, log_l + step, |x| rss(x.exp(), log_z.exp()));
    }
    let (length, damping) = (log_l.exp(), log_z.exp());
    let (rss, c, rss0) =
        regress(axes, dt, from, length, damping).ok_or(ScaleRefusal::Unsimulated)?;
    let samples: usize = axes.iter().map(|ax| ax.velocity.len() - from).sum();
    let explained = if rss0 > 0.0 { 1.0 - rss / rss0 } else { 0.0 };
    let fit = ScaleFit {
        ratio: 1.0 / c[0],
        length,
        damping,
        drag_linear: c[1],
        drag_quadratic: c[2],
        explained,
        drag_removed: s.drag,
        residual: (rss / samples as f64).sqrt(),
    };
    if !(c[0] > 0.0 && fit.ratio.is_finite()) {
        return Err(ScaleRefusal::WrongSign {
            inverse_ratio: c[0],
        });
    }
    if explained < s.min_explained {
        return Err(ScaleRefusal::Unexplained {
            explained,
            minimum: s.min_explained,
        });
    }
    Ok(fit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A velocity of random ramps held between steps, as a training flight flies.
    fn velocity(n: usize, dt: f64, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (mut v, mut target, mut out) = (0.0f64, 0.0f64, Vec::with_capacity(n));
        for i in 0..n {
            if i % 400 == 0 {
                target = rng.random_range(-3.0..3.0);
            }
            v += (target - v).clamp(-2.0 * dt, 2.0 * dt);
            out.push(v);
        }
        out
    }

    /// A synthetic flight whose estimate is τ + (θ − τ)/ρ + drag + bias + noise, θ the
    /// pendulum of `length` answering the velocity, τ a tilt that leads the acceleration.
    fn flight(
        length: f64,
        ratio: f64,
        drag: [f64; 2],
        noise: f64,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        flight_at(0.0, length, ratio, drag, noise)
    }

    /// [`flight`] about a cruise of `cruise` m/s.
    fn flight_at(
        cruise: f64,
        length: f64,
        ratio: f64,
        drag: [f64; 2],
        noise: f64,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let dt = 0.01;
        let v: Vec<f64> = velocity(30_000, dt, 7).iter().map(|x| cruise + x).collect();
        let coef: links::Coefficients = [0.0, 0.0, length / GRAVITY, 0.0, 0.0, 0.0];
        let theta = links::simulate(&coef, &v, dt, 0.02).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut tilt = Vec::with_capacity(v.len());
        let mut est = Vec::with_capacity(v.len());
        for i in 0..v.len() {
            let a = if i == 0 { 0.0 } else { (v[i] - v[i - 1]) / dt };
            let t = -1.2 * a / GRAVITY + 0.3 * theta[i];
            let d = drag[0] * v[i] + drag[1] * v[i] * v[i].abs();
            let z: f64 = rng.random_range(-1.0..1.0);
            tilt.push(t);
            est.push(t + (theta[i] - t) / ratio + d + 0.01 + noise * z);
        }
        (v, est, tilt)
    }

    #[test]
    fn the_scale_length_and_drag_of_a_synthetic_estimate_are_found() {
        for (length, ratio) in [(1.0, 0.95), (0.5, 3.8), (2.0, 0.4)] {
            let drag = [-0.002, -0.035];
            let (v, est, tilt) = flight(length, ratio, drag, 0.02);
            let axis = ScaleAxis {
                velocity: &v,
                estimate: &est,
                tilt: &tilt,
            };
            let removing = ScaleSettings {
                drag: DragRemoval::All,
                ..ScaleSettings::default()
            };
            let fit = fit(&[axis], 0.01, &removing).unwrap();
            // The simulated pendulum is damped as the fit's is not quite: a per cent.
            assert!(
                (fit.ratio / ratio - 1.0).abs() < 0.02,
                "{fit:?} vs ρ {ratio}"
            );
            assert!(
                (fit.length / length - 1.0).abs() < 0.02,
                "{fit:?} vs l {length}"
            );
            assert!((fit.drag_quadratic - drag[1]).abs() < 2e-3, "{fit:?}");
            // The calibrated estimate is the swing, up to the noise scaled by ρ.
            let coef: links::Coefficients = [0.0, 0.0, length / GRAVITY, 0.0, 0.0, 0.0];
            let theta = links::simulate(&coef, &v, 0.01, 0.02).unwrap();
            let swing = fit.apply(&axis);
            let rms = (swing[500..]
                .iter()
                .zip(&theta[500..])
                .map(|(a, b)| (a - b - ratio * 0.01).powi(2))
                .sum::<f64>()
                / (swing.len() - 500) as f64)
                .sqrt();
            assert!(rms < 0.02 * ratio, "rms {rms}");
        }
    }

    #[test]
    fn an_estimate_that_does_not_answer_the_motion_is_refused() {
        let (v, _, tilt) = flight(1.0, 1.0, [0.0, 0.0], 0.0);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let est: Vec<f64> = tilt
            .iter()
            .map(|t| t + 0.05 * rng.random_range(-1.0..1.0))
            .collect();
        let axis = ScaleAxis {
            velocity: &v,
            estimate: &est,
            tilt: &tilt,
        };
        let err = fit(&[axis], 0.01, &ScaleSettings::default()).unwrap_err();
        assert!(
            matches!(
                err,
                ScaleRefusal::Unexplained { .. }
                    | ScaleRefusal::AtBound { .. }
                    | ScaleRefusal::WrongSign { .. }
            ),
            "{err}"
        );
        let short = ScaleAxis {
            velocity: &v[..200],
            estimate: &est[..200],
            tilt: &tilt[..200],
        };
        let err = fit(&[short], 0.01, &ScaleSettings::default()).unwrap_err();
        assert!(matches!(err, ScaleRefusal::TooShort { .. }), "{err}");
        assert_eq!(err.to_string(), "the flight is shorter than 6.0 s");
    }

    #[test]
    fn the_calibrated_estimator_divides_the_scale_and_removes_the_drag() {
        let s = ImuSwingSettings {
            scale: 2.0,
            drag_linear: [0.1, 0.1],
            ..ImuSwingSettings::default()
        };
        let fit = ScaleFit {
            ratio: 4.0,
            length: 1.0,
            damping: 0.05,
            drag_linear: 0.01,
            drag_quadratic: -0.03,
            explained: 0.9,
            drag_removed: DragRemoval::All,
            residual: 0.0,
        };
        let c = fit.calibrated(&s);
        assert_eq!(c.scale, 0.5);
        // Swing read per m/s at the assumed scale 2, in specific force: 2 × 0.01 m/s² per m/s.
        assert!((c.drag_linear[0] - (0.1 - 0.02)).abs() < 1e-15);
        assert!((c.drag_quadratic[1] - 0.06).abs() < 1e-15);
        // The default keeps the wind's linear term and the estimator's own scale.
        let quadratic = ScaleFit {
            drag_removed: DragRemoval::Quadratic,
            ..fit
        };
        let own = quadratic.without_drag(&s);
        assert_eq!((own.scale, own.length), (2.0, s.length));
        assert_eq!(own.drag_linear, [0.1, 0.1]);
        assert!((own.drag_quadratic[0] - 0.06).abs() < 1e-15);
        let kept = ScaleFit {
            drag_removed: DragRemoval::Keep,
            ..fit
        };
        assert_eq!(kept.without_drag(&s), s);
    }

    #[test]
    fn the_quadratic_drag_fitted_in_a_wind_is_the_airframe_s() {
        // The same airframe's drag, c (v − w)|v − w| in the airspeed, cruising at 2–8 m/s in
        // still air and in a head and a tail wind that never turn the airspeed round: the
        // fitted quadratic term is c in each, and removing it leaves a drag linear in the
        // ground speed.
        let (length, ratio, c) = (1.0, 1.0, -0.035);
        for w in [-1.5, 0.0, 1.5] {
            let (v, clean, tilt) = flight_at(5.0, length, ratio, [0.0, 0.0], 0.02);
            let est: Vec<f64> = clean
                .iter()
                .zip(&v)
                .map(|(e, &x)| e + c * (x - w) * (x - w).abs())
                .collect();
            let axis = ScaleAxis {
                velocity: &v,
                estimate: &est,
                tilt: &tilt,
            };
            let fit = fit(&[axis], 0.01, &ScaleSettings::default()).unwrap();
            assert!((fit.drag_quadratic - c).abs() < 2e-3, "wind {w}: {fit:?}");
            assert!(
                (fit.drag_linear + 2.0 * c * w).abs() < 2e-2,
                "wind {w}: {fit:?}"
            );
            // What is left after the removal is the wind's −2cw v + cw², exactly linear.
            let left: Vec<f64> = fit
                .apply_without_drag(&axis)
                .iter()
                .zip(&clean)
                .map(|(a, b)| a - b)
                .collect();
            let want = |x: f64| (c - fit.drag_quadratic) * x * x - 2.0 * c * w * x + c * w * w;
            let worst = left
                .iter()
                .zip(&v)
                .map(|(l, &x)| (l - want(x)).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-12, "wind {w}: {worst}");
        }
    }

    #[test]
    fn the_tilt_of_a_level_vehicle_is_zero_and_a_pitch_reads_north() {
        let n = 50;
        let zero = vec![0.0; n];
        let pitch = vec![0.1; n];
        let yaw = vec![0.5; n];
        let [tn, te] = tilt(&zero, &zero, &zero, 0.01, 0.0);
        assert!(tn.iter().chain(&te).all(|x| *x == 0.0));
        // Nose up: body z leans North (a cable along it hangs North); turned by the yaw.
        let [tn, te] = tilt(&zero, &pitch, &yaw, 0.01, 0.0);
        let (want_n, want_e) = (0.1f64.tan() * 0.5f64.cos(), 0.1f64.tan() * 0.5f64.sin());
        assert!((tn[0].tan() - want_n).abs() < 1e-12 && (te[0].tan() - want_e).abs() < 1e-12);
    }
}
