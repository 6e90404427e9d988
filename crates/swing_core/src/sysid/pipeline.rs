//! The identification pipeline on resampled columns (thesis 4.6.1–4.6.3): hold out the
//! test span at the start of the flight, fit given (q, p) or search them, score the model's
//! rollout NMAE on the held-out span; or build the white-box baseline (thesis 4.3).
//!
//! Callers resample and pick the columns (that is I/O); every rule from there on is here.

use serde_json::{json, Value};

use super::error::{data, SysidError};
use super::hankel::Trajectory;
use super::links::{self, LinkSettings};
use super::model::LinearModel;
use super::search::{grid_search, refine, Candidate, SearchResult};
use super::settings::{IdentifyMethod, IdentifySettings, SearchMode};
use super::spectrum::{self, SpectralSettings};
use super::{dmdc, havokc, metrics, whitebox};
use crate::plant::{PendulumModel, GRAVITY};

/// A model and, when it came from a search, every scored candidate.
#[derive(Clone, Debug)]
pub struct Identified {
    /// The identified model, with `states`/`inputs` named and its held-out NMAE in the
    /// diagnostics.
    pub model: LinearModel,
    /// The search, when one ran.
    pub search: Option<SearchResult>,
}

/// Split a flight into (training, test): the first `test_span` seconds are held out.
pub fn split<'a>(
    traj: &Trajectory<'a>,
    settings: &IdentifySettings,
) -> Result<(Trajectory<'a>, Trajectory<'a>), SysidError> {
    let k = settings.test_samples();
    if k >= traj.len {
        return Err(data(format!(
            "the data ({:.1} s) is not longer than the test span ({} s)",
            traj.len as f64 * settings.dt,
            settings.test_span
        )));
    }
    Ok((traj.slice(k, traj.len), traj.slice(0, k)))
}

/// Fit the data-driven method of `settings` with `delays` and `rank` on `train`.
pub fn fit(
    train: &Trajectory<'_>,
    settings: &IdentifySettings,
    delays: usize,
    rank: Option<usize>,
) -> Result<LinearModel, SysidError> {
    match settings.method {
        IdentifyMethod::Dmdc => dmdc::fit(
            train,
            &dmdc::DmdcSettings {
                delays,
                rank,
                offset: settings.offset,
                dt: settings.dt,
            },
        ),
        IdentifyMethod::Havokc => havokc::fit(
            train,
            &havokc::HavokcSettings {
                delays,
                rank,
                offset: settings.offset,
                dt: settings.dt,
            },
        ),
        IdentifyMethod::Whitebox => Err(super::error::config(
            "the white-box baseline has no delays or rank to fit",
        )),
    }
}

/// Score `model` on the held-out span from the starts a search uses (`score_delays`), storing
/// the NMAE in its diagnostics; a span too short for the rollout leaves the model unscored.
pub fn score(
    model: &mut LinearModel,
    test: &Trajectory<'_>,
    settings: &IdentifySettings,
) -> Result<(), SysidError> {
    if test.len == 0 {
        return Ok(());
    }
    let horizon = settings.rollout_samples();
    let q = metrics::score_delays(test.len, model.delays, horizon, settings.score_delays);
    let scored = metrics::start_points(test.len, q, horizon, settings.starts)
        .and_then(|starts| metrics::Scorer::new(test.clone(), starts, horizon))
        .and_then(|mut scorer| scorer.score_model(model));
    match scored {
        Ok(nm) => {
            model.diagnostics.test_nmae = Some(nm.mean);
            Ok(())
        }
        Err(SysidError::Data(_)) => Ok(()),
        Err(e) => Err(e),
    }
}

/// An input whose spread in the training data is below this fraction of the best-excited
/// input's carries no information about its axis: 60 dB below, far under the PX4 cascade's
/// own noise on an axis it merely holds (a few per cent of a stepped axis), far above the
/// rounding of an axis that never moved.
const MIN_RELATIVE_EXCITATION: f64 = 1e-3;

/// Refuse training data in which an input never varied: a model fitted to it has an
/// arbitrary response to that input (the delay coordinates of an axis at rest span nothing),
/// and a controller flying it on that axis drifts away. Names the input and its spread.
pub fn check_excitation(train: &Trajectory<'_>, inputs: &[String]) -> Result<(), SysidError> {
    // Spreads of the inputs scaled by the largest magnitude (so that no sum overflows); a
    // spread below 1e-9 of it is rounding, no variation at all.
    let size = (0..train.len)
        .flat_map(|k| train.input(k).iter())
        .fold(1.0_f64, |a, x| a.max(x.abs()));
    let spread: Vec<f64> = (0..train.m)
        .map(|j| {
            let col: Vec<f64> = (0..train.len).map(|k| train.input(k)[j] / size).collect();
            let len = col.len().max(1) as f64;
            let mean = col.iter().sum::<f64>() / len;
            (col.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / len).sqrt()
        })
        .collect();
    let best = spread.iter().copied().fold(0.0, f64::max);
    let rounding = 1e-9;
    let name = |j: usize| {
        inputs
            .get(j)
            .cloned()
            .unwrap_or_else(|| format!("input {j}"))
    };
    for (j, &s) in spread.iter().enumerate() {
        if s <= MIN_RELATIVE_EXCITATION * best || s <= rounding {
            let what = if best <= rounding {
                "no input varies in the training data".to_string()
            } else {
                let top = spread.iter().position(|&x| x == best).unwrap_or(0);
                format!(
                    "input '{}' never varies in the training data (its spread is {:.0e} of \
                     that of '{}')",
                    name(j),
                    s / best,
                    name(top)
                )
            };
            return Err(data(format!(
                "{what}: the flight did not excite that axis; identify only the axes it \
                 stepped, or fly a training flight that steps every axis"
            )));
        }
    }
    Ok(())
}

/// Name a fitted model's states and inputs.
pub fn named(
    mut model: LinearModel,
    states: &[String],
    inputs: &[String],
) -> Result<LinearModel, SysidError> {
    if states.len() != model.n() || inputs.len() != model.m() {
        return Err(data(format!(
            "{} state names and {} input names for {} states and {} inputs",
            states.len(),
            inputs.len(),
            model.n(),
            model.m()
        )));
    }
    model.states = states.to_vec();
    model.inputs = inputs.to_vec();
    Ok(model)
}

/// A search candidate as a diagnostics row (`per_state` keyed by state name).
pub fn candidate_row(c: &Candidate, states: &[String]) -> Value {
    let per: serde_json::Map<String, Value> = states
        .iter()
        .zip(&c.per_state)
        .map(|(s, v)| (s.clone(), json!(v)))
        .collect();
    json!({
        "delays": c.delays,
        "rank": c.rank,
        "nmae": finite_or_null(c.nmae),
        "per_state": per,
        "stable": c.stable,
        "spectral_radius": c.spectral_radius,
        "integrator_eigenvalue": c.verdict.as_ref().and_then(|v| v.integrator),
        "stability_screen": c.verdict.as_ref().map(|v| v.to_json()),
    })
}

fn finite_or_null(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// Run the search of `settings`: `refine` (coarse grid, then unit steps around several
/// winners when `fine` is set), or `exhaustive`.
pub fn search(
    train: &Trajectory<'_>,
    test: &Trajectory<'_>,
    settings: &IdentifySettings,
) -> Result<SearchResult, SysidError> {
    let scoring = settings
        .search_settings()
        .ok_or_else(|| super::error::config("search applies to dmdc and havokc, not whitebox"))?;
    let grid = settings.coarse_grid();
    match (settings.search_mode, settings.fine) {
        (SearchMode::Exhaustive, _) => {
            grid_search(train, test, &settings.exhaustive_grid(), &scoring)
        }
        (SearchMode::Refine, Some([qr, pr])) => refine(
            train,
            test,
            &grid,
            settings.dense_ranks,
            settings.winners,
            qr,
            pr,
            &scoring,
        ),
        (SearchMode::Refine, None) => grid_search(train, test, &grid, &scoring),
    }
}

/// The white-box baseline on the training data: the payload mass is given (`payload_mass`,
/// from the settings or an RLS estimate), the cable length from the settings or, on the
/// axis that swings most, the single pendulum that answers the vehicle's motion as the
/// swing does (`links::fit`; the FFT peak of eq. 4.8 when that fit fails).
pub fn whitebox_model(
    train: &Trajectory<'_>,
    states: &[String],
    inputs: &[String],
    settings: &IdentifySettings,
    payload_mass: f64,
) -> Result<LinearModel, SysidError> {
    let axes = inputs.len();
    if states.len() != 2 * axes {
        return Err(data(format!(
            "the white-box needs a velocity and a swing per input, got states {states:?}"
        )));
    }
    // The axis that swings most: its swing tells the links and the spectrum.
    let swing_axis = {
        let std = |j: usize| {
            let col: Vec<f64> = (0..train.len).map(|k| train.state(k)[j]).collect();
            let mean = col.iter().sum::<f64>() / col.len().max(1) as f64;
            (col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / col.len().max(1) as f64).sqrt()
        };
        (axes..2 * axes)
            .max_by(|a, b| std(*a).total_cmp(&std(*b)))
            .expect("at least one axis")
    };
    let swing: Vec<f64> = (0..train.len).map(|k| train.state(k)[swing_axis]).collect();
    let mut links = None;
    let mut fft_length = None;
    let (length, freq) = match settings.cable_length {
        Some(l) => (l, None),
        None => {
            let [lo, hi] = settings.swing_band;
            let f = whitebox::fft_peak_frequency(&swing, settings.dt, lo, hi)?;
            let l_fft = whitebox::cable_length(f, settings.vehicle_mass, payload_mass, GRAVITY);
            fft_length = Some(l_fft);
            let v: Vec<f64> = (0..train.len)
                .map(|k| train.state(k)[swing_axis - axes])
                .collect();
            // The swing's answer to the vehicle's motion fixes the length whatever the
            // flight's spectrum; the FFT peak (eq. 4.8) stands in when that fit fails.
            let rule = if settings.imu_swing {
                LinkSettings::for_imu_swing()
            } else {
                LinkSettings::default()
            };
            let fitted = links::fit(&v, &swing, settings.dt, &rule);
            links = fitted.and_then(|fit| fit.double);
            (fitted.map_or(l_fft, |fit| fit.length), Some(f))
        }
    };
    // The IMU's swing asks more of the links fit than the doubles a shaper must know of
    // give; their second mode shows in the spectrum (`spectrum`), whatever gave the length.
    let second_peak = (settings.imu_swing && links.is_none())
        .then(|| {
            let first_mode = (GRAVITY / length).sqrt();
            spectrum::second_peak(
                &swing,
                settings.dt,
                first_mode,
                &SpectralSettings::default(),
            )
        })
        .flatten();
    let params = PendulumModel {
        m_q: settings.vehicle_mass,
        m_p: payload_mass,
        l: length,
        c: settings.friction,
    };
    let mut model = whitebox::model(&params, axes, settings.dt, freq)?;
    if let Some(wb) = model.diagnostics.whitebox.as_mut() {
        wb.links = links;
        wb.second_peak = second_peak;
        wb.fft_length = fft_length;
        let j = (axes..2 * axes).next().expect("at least one axis");
        let swing: Vec<f64> = (0..train.len).map(|k| train.state(k)[j]).collect();
        wb.swing_noise = whitebox::noise_std(&swing);
        wb.attitude_lag = super::lag::attitude_lag(train, axes, settings.dt).map(|fit| fit.tau);
    }
    let mut model = named(model, states, inputs)?;
    whitebox::apply_offset(&mut model, train, settings.offset)?;
    Ok(model)
}

/// Identify a model from resampled (and, if asked, smoothed) columns: `traj` holds the
/// states named `states` and the inputs named `inputs`. The white-box needs
/// `payload_mass` when the settings give none.
pub fn identify(
    traj: &Trajectory<'_>,
    states: &[String],
    inputs: &[String],
    settings: &IdentifySettings,
    payload_mass: Option<f64>,
) -> Result<Identified, SysidError> {
    settings.validate()?;
    let (train, test) = split(traj, settings)?;
    // The data-driven fits learn each input's effect from the data; the white-box takes it
    // from physics.
    if settings.method != IdentifyMethod::Whitebox {
        check_excitation(&train, inputs)?;
    }
    let (mut model, search_result) = match settings.method {
        IdentifyMethod::Whitebox => {
            let mass = settings.payload_mass.or(payload_mass).ok_or_else(|| {
                data("the white-box needs the payload mass (payload_mass) or a thrust column")
            })?;
            (
                whitebox_model(&train, states, inputs, settings, mass)?,
                None,
            )
        }
        _ if settings.search => {
            let res = search(&train, &test, settings)?;
            let mut model = named(res.model.clone(), states, inputs)?;
            model.diagnostics.extra.insert(
                "selected".into(),
                candidate_row(&res.table[res.best], states),
            );
            (model, Some(res))
        }
        _ => {
            let model = fit(&train, settings, settings.fit_delays(), settings.rank)?;
            (named(model, states, inputs)?, None)
        }
    };
    if search_result.is_none() {
        score(&mut model, &test, settings)?;
    }
    // Finite data can still give a non-finite model (values near f64::MAX overflow the
    // input mean or the offset): refuse it here rather than hand on a model no one can use.
    model.validate().map_err(|e| {
        SysidError::Identification(format!(
            "the data gave no usable model ({e}); are the values in SI units?"
        ))
    })?;
    Ok(Identified {
        model,
        search: search_result,
    })
}

/// Columns of a flight sampled on a uniform grid, for the payload-mass estimate.
#[derive(Clone, Copy, Debug)]
pub struct ThrustLog<'a> {
    /// Total rotor thrust along body z [N].
    pub thrust: &'a [f64],
    /// Down velocity [m/s].
    pub vd: &'a [f64],
    /// Roll [rad], when logged (the thrust is projected on the vertical).
    pub roll: Option<&'a [f64]>,
    /// Pitch [rad], when logged.
    pub pitch: Option<&'a [f64]>,
    /// Sample time of the grid [s].
    pub dt: f64,
}

/// Payload mass [kg] by RLS on hover thrust (section 4.3.2): the thrust projected on the
/// vertical against g − a_down (a_down the central-difference derivative of `vd`), minus the
/// known `vehicle_mass`; the first `skip` samples are left out.
pub fn payload_mass_from_thrust(
    log: &ThrustLog<'_>,
    skip: usize,
    vehicle_mass: f64,
    forgetting: f64,
) -> Result<f64, SysidError> {
    let n = log.thrust.len();
    let same = |c: Option<&[f64]>| c.is_none_or(|c| c.len() == n);
    if log.vd.len() != n || !same(log.roll) || !same(log.pitch) {
        return Err(data("thrust, vd, roll and pitch must have the same length"));
    }
    if n < 2 || skip + 2 > n {
        return Err(data("too few samples for the payload-mass estimate"));
    }
    if !(log.dt.is_finite() && log.dt > 0.0) {
        return Err(super::error::config(format!(
            "dt must be positive, not {}",
            log.dt
        )));
    }
    let angle = |c: Option<&[f64]>, k: usize| c.map_or(1.0, |c| c[k].cos());
    let vertical: Vec<f64> = (skip..n)
        .map(|k| log.thrust[k] * angle(log.roll, k) * angle(log.pitch, k))
        .collect();
    let acc: Vec<f64> = (skip..n)
        .map(|k| {
            let v = log.vd;
            if k == 0 {
                (v[1] - v[0]) / log.dt
            } else if k == n - 1 {
                (v[n - 1] - v[n - 2]) / log.dt
            } else {
                (v[k + 1] - v[k - 1]) / (2.0 * log.dt)
            }
        })
        .collect();
    let est = whitebox::rls_mass(&vertical, &acc, GRAVITY, forgetting, vehicle_mass)?;
    let mass = est.last().copied().unwrap_or(f64::NAN) - vehicle_mass;
    if mass.is_nan() || mass <= 0.0 {
        return Err(SysidError::Identification(format!(
            "estimated payload mass {mass:.3} kg is not positive"
        )));
    }
    Ok(mass)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hover with a vertical oscillation and a tilt: the thrust that holds a total mass M is
    /// M (g − a_down) / (cos roll · cos pitch); the estimate must return M − m_Q.
    #[test]
    fn payload_mass_inverts_the_vertical_force_balance() {
        let (dt, n, m_total, m_q) = (0.01, 6000, 1.2, 0.952);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let vd: Vec<f64> = t.iter().map(|t| 0.3 * (1.1 * t).sin()).collect();
        let roll: Vec<f64> = t.iter().map(|t| 0.1 * (0.7 * t).cos()).collect();
        let pitch: Vec<f64> = t.iter().map(|t| 0.05 * (0.3 * t).sin()).collect();
        let thrust: Vec<f64> = (0..n)
            .map(|k| {
                // The exact derivative: the estimate's central difference is O(dt²) off.
                let a_down = 0.33 * (1.1 * t[k]).cos();
                m_total * (GRAVITY - a_down) / (roll[k].cos() * pitch[k].cos())
            })
            .collect();
        let log = ThrustLog {
            thrust: &thrust,
            vd: &vd,
            roll: Some(&roll),
            pitch: Some(&pitch),
            dt,
        };
        let m = payload_mass_from_thrust(&log, 100, m_q, 1.0).unwrap();
        assert!((m - (m_total - m_q)).abs() < 1e-4, "{m}");
        // A thrust too small for the vehicle alone is refused, not returned negative.
        let weak: Vec<f64> = thrust.iter().map(|f| 0.5 * f).collect();
        let log = ThrustLog {
            thrust: &weak,
            ..log
        };
        assert!(payload_mass_from_thrust(&log, 0, m_q, 1.0).is_err());
    }

    #[test]
    fn an_axis_the_flight_never_moved_is_refused_by_name() {
        // Two inputs: North stepped, East at rest up to rounding (as a North-only flight
        // identified on both axes gives).
        let len = 400;
        let u: Vec<f64> = (0..len)
            .flat_map(|k| {
                [
                    if (k / 50) % 2 == 0 { 1.0 } else { -1.0 },
                    1e-17 * (k % 3) as f64,
                ]
            })
            .collect();
        let x = vec![0.0; 2 * len];
        let traj = Trajectory::new(&x, 2, &u, 2).unwrap();
        let names = ["acc_n".to_string(), "acc_e".to_string()];
        let err = check_excitation(&traj, &names).unwrap_err().to_string();
        assert!(err.contains("'acc_e'") && err.contains("'acc_n'"), "{err}");
        // The same East input at the level of a held axis' noise (2 % of the stepped one)
        // is accepted, and so is every input at rest but the whole flight refused.
        let u: Vec<f64> = (0..len)
            .flat_map(|k| {
                [
                    if (k / 50) % 2 == 0 { 1.0 } else { -1.0 },
                    0.02 * ((k % 7) as f64 - 3.0) / 3.0,
                ]
            })
            .collect();
        assert!(check_excitation(&Trajectory::new(&x, 2, &u, 2).unwrap(), &names).is_ok());
        let still = vec![0.3; 2 * len];
        let err = check_excitation(&Trajectory::new(&x, 2, &still, 2).unwrap(), &names)
            .unwrap_err()
            .to_string();
        assert!(err.contains("no input varies"), "{err}");
    }

    #[test]
    fn split_holds_out_the_start_and_refuses_short_data() {
        let x = vec![0.0; 2 * 100];
        let u = vec![0.0; 100];
        let traj = Trajectory::new(&x, 2, &u, 1).unwrap();
        let s = IdentifySettings {
            test_span: 0.9,
            ..IdentifySettings::default()
        };
        let (train, test) = split(&traj, &s).unwrap();
        assert_eq!((train.len, test.len), (70, 30));
        let s = IdentifySettings {
            test_span: 3.0,
            ..IdentifySettings::default()
        };
        assert!(matches!(split(&traj, &s), Err(SysidError::Data(_))));
    }
}
