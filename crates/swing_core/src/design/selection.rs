//! Control-relevant model selection: from a search's candidates, the model to fly an MPC on.
//!
//! Rollout NMAE alone is a poor guide (see `check`): models within a few percent of the best
//! can carry spurious slow modes that the MPC's feedback excites. Up to `candidates`
//! distinct (q, p) are refitted and, best first, the MPC designed on each flies the
//! white-box model of the same flight in closed loop — as identified, and with each of
//! `vehicle_drag` added — behind each of `input_lags`: hover, a step, hold. The stable rows
//! of the search come first, in NMAE order; with a twin, the rows it did not screen (worse
//! than a stable p of their q) follow, each screened when its turn comes. The first
//! candidate whose every run stays within `bounds` is selected; with none passing, the one
//! that misses its bounds least (largest ratio to a bound), and its diagnostics say so.
//!
//! With a [`TwinPlant`] the candidate's MPC first flies the same step on the vehicle's
//! twin (the nonlinear simulator under PX4's cascade with the white-box payload and the
//! flight's sensor noise) and must settle there within `twin_bounds`; only then is it
//! flown on the linear plants. The linear check covers drag and input lags the twin does
//! not vary; the twin covers the attitude loop, the limits and the nonlinearity the linear
//! plants lack. A candidate that settles on both then holds the step on the twin for a
//! minute, with the noise and without: what the noise alone does to the velocity, and a
//! slowly growing oscillation, are bounded too (`TwinHold`). A candidate that settles
//! everywhere must also damp the swing: its twin
//! swing excess within a fraction of PX4's own on the same step. When none does, the
//! settled candidate that swings least is taken rather than the first that settled.

use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::config::{finite, non_negative, positive, ConfigError};
use crate::control::{ControlError, MpcController, MpcSettings};
use crate::design::check::{worst_step_check, StepCheck};
use crate::design::twin::{TwinFlight, TwinHold, TwinPlant};
use crate::sysid::pipeline::{self, candidate_row};
use crate::sysid::search::SearchResult;
use crate::sysid::{IdentifySettings, LinearModel, Trajectory};

/// Bounds of the closed-loop check, as fractions of the step.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CheckBounds {
    /// Largest overshoot beyond the new setpoint.
    pub overshoot: f64,
    /// Largest |v − setpoint| at the end of the check.
    pub final_error: f64,
    /// Largest |v| while holding hover before the step.
    pub hold_drift: f64,
}

impl Default for CheckBounds {
    fn default() -> Self {
        Self {
            overshoot: 0.35,
            final_error: 0.03,
            hold_drift: 0.1,
        }
    }
}

impl CheckBounds {
    /// Whether a check's every figure is within its bound.
    pub fn admit(&self, c: &StepCheck) -> bool {
        c.passes(self.overshoot, self.final_error, self.hold_drift)
    }

    /// How far a check misses its bounds: the largest ratio of a figure to its bound.
    pub fn miss(&self, c: &StepCheck) -> f64 {
        (c.overshoot / self.overshoot)
            .max(c.final_error / self.final_error)
            .max(c.hold_drift / self.hold_drift)
    }
}

/// Bounds of the twin step flight.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TwinBounds {
    /// Latest time after the step by which the velocity stays within 5 % of the step [s].
    pub settle: f64,
    /// Largest |v − setpoint| over the last second, as a fraction of the step: the twin has
    /// no noise and no wind, so an offset-free MPC ends on the setpoint.
    pub final_error: f64,
    /// Largest wander of the velocity over the hold flight (`TwinHold::wander`: the RMS of
    /// the 2 s mean of what the flight's swing-sensor noise, fed through the MPC, moved
    /// it), as a fraction of the step: an MPC that turns the noise into velocity wanders
    /// off the setpoint in flight.
    pub wander: f64,
    /// Largest |v − setpoint| late in the hold flight without noise (`TwinHold::late_error`),
    /// as a fraction of the step: a loop that slowly grows an oscillation settles on the
    /// step flight and leaves the setpoint later.
    pub late_error: f64,
    /// Largest swing excess (`TwinFlight::swing_excess`) as a fraction of PX4's alone on
    /// the same step: an MPC that moves the vehicle without damping the payload swings as
    /// PX4 does.
    pub swing_vs_pid: f64,
    /// ... unless the excess is below this [deg·s]: a short cable's swing is small and
    /// short-lived under any controller.
    pub swing_excess_min: f64,
}

impl Default for TwinBounds {
    fn default() -> Self {
        // A good MPC settles a 2 m/s step in 3-4 s on the twin; candidates that take longer
        // than 6 s creep, and in flight they creep past the end of the manoeuvre.
        // PX4 alone leaves 5-20 deg·s of swing excess on a 2 m/s step with a 0.3-3 m cable;
        // the MPCs that damp it leave a tenth of that, the ones that do not, half or more.
        Self {
            settle: 6.0,
            final_error: 0.005,
            wander: 0.005,
            late_error: 0.01,
            swing_vs_pid: 0.3,
            swing_excess_min: 1.0,
        }
    }
}

impl TwinBounds {
    /// Whether a twin step flight is within these bounds and the linear `bounds`' overshoot.
    pub fn admit(&self, f: &TwinFlight, bounds: &CheckBounds) -> bool {
        f.settle <= self.settle
            && f.check.final_error <= self.final_error
            && f.check.overshoot <= bounds.overshoot
            && f.check.hold_drift <= bounds.hold_drift
    }

    /// Whether a twin hold flight is within these bounds.
    pub fn holds(&self, h: &TwinHold) -> bool {
        h.wander <= self.wander && h.late_error <= self.late_error
    }

    /// The largest swing excess admitted, given PX4's own flight `pid` of the same step.
    pub fn swing_bound(&self, pid: &TwinFlight) -> f64 {
        (self.swing_vs_pid * pid.swing_excess).max(self.swing_excess_min)
    }

    /// Whether a twin flight damps the swing: its excess is within [`Self::swing_bound`].
    pub fn damps(&self, f: &TwinFlight, pid: &TwinFlight) -> bool {
        f.swing_excess <= self.swing_bound(pid)
    }

    /// How far a twin flight misses: the largest ratio of a figure to its bound.
    /// The hold flight `h` counts when it was flown.
    pub fn miss(&self, f: &TwinFlight, h: Option<&TwinHold>, bounds: &CheckBounds) -> f64 {
        let hold = h.map_or(0.0, |h| {
            (h.wander / self.wander).max(h.late_error / self.late_error)
        });
        (f.settle / self.settle)
            .max(f.check.final_error / self.final_error)
            .max(hold)
            .max(f.check.overshoot / bounds.overshoot)
            .max(f.check.hold_drift / bounds.hold_drift)
    }
}

/// Settings of [`select_for_control`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SelectionSettings {
    /// How many of the lowest-NMAE stable candidates are flown at most.
    pub candidates: usize,
    /// Time constants of a first-order lag between controller and plant [s] (0 = none).
    pub input_lags: Vec<f64>,
    /// Linear vehicle drags added to the white-box plant as extra plants [1/s].
    ///
    /// Quadratic drag linearised at airspeed w is ρ C_Q w / m per second: for the Honeybee
    /// (C_Q 0.096 m², 1.0–1.45 kg with payload) 0.12 /s near 1–1.5 m/s, 0.4 /s near 3.5–5 m/s,
    /// a 2 m/s step into a 3 m/s headwind. A model identified in light air whose MPC only
    /// holds the first creeps or cycles in strong wind, so the default checks both.
    pub vehicle_drag: Vec<f64>,
    /// Velocity step of the check [m/s].
    pub step: f64,
    /// Pass bounds (fractions of the step).
    pub bounds: CheckBounds,
    /// Pass bounds of the twin step flight (when a twin is given).
    pub twin_bounds: TwinBounds,
    /// Factor by which a candidate's MPC raises its Kalman filter's measurement noise
    /// (`kf_measurement_noise`) when the twin's hold shows the flight's sensor noise moving
    /// the velocity more than `noise_retry_wander`; the candidate is then checked again
    /// with it (1 = never), and flown so when that settles where the first did not, or
    /// settles, damps as well and wanders less. The chosen model carries the raised noise
    /// (`Diagnostics::measurement_noise`), and every MPC built on it assumes at least that.
    pub noise_retry: f64,
    /// Wander (`TwinHold::wander`, a fraction of the step) above which the retry is flown.
    pub noise_retry_wander: f64,
    /// What the plant of the check is and where its parameters came from, written into the
    /// diagnostics as `control_check.plant` (e.g. `whitebox(payload mass 0.2 kg from thrust)`).
    pub plant_label: String,
}

impl Default for SelectionSettings {
    fn default() -> Self {
        Self {
            candidates: 80,
            input_lags: vec![0.0, 0.1],
            vehicle_drag: vec![0.12, 0.4],
            step: 2.0,
            bounds: CheckBounds::default(),
            twin_bounds: TwinBounds::default(),
            // Three times the default (0.03 rad) halves what 0.005-0.01 rad of swing noise
            // does to the velocity, for a little less damping; as a default for every model
            // it costs more flights than it saves.
            noise_retry: 3.0,
            // A flight's steady-state error is a 2 s mean: with the wander at 0.3 % of the
            // step, an error of 1 % (0.02 m/s on 2 m/s) takes a 3.3-sigma draw of the noise.
            noise_retry_wander: 0.003,
            plant_label: "whitebox".into(),
        }
    }
}

impl SelectionSettings {
    /// Check every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.candidates == 0 {
            return Err(ConfigError::new("candidates", "must be at least 1"));
        }
        if self.input_lags.is_empty() {
            return Err(ConfigError::new(
                "input_lags",
                "needs at least one lag (0 = none)",
            ));
        }
        for (i, l) in self.input_lags.iter().enumerate() {
            non_negative(&format!("input_lags[{i}]"), *l)?;
        }
        for (i, k) in self.vehicle_drag.iter().enumerate() {
            non_negative(&format!("vehicle_drag[{i}]"), *k)?;
        }
        finite("step", self.step)?;
        if self.step == 0.0 {
            return Err(ConfigError::new("step", "must be non-zero"));
        }
        for (name, v) in [
            ("overshoot", self.bounds.overshoot),
            ("final_error", self.bounds.final_error),
            ("hold_drift", self.bounds.hold_drift),
        ] {
            finite(&format!("bounds.{name}"), v)?;
        }
        positive("twin_bounds.settle", self.twin_bounds.settle)?;
        positive("twin_bounds.final_error", self.twin_bounds.final_error)?;
        positive("twin_bounds.wander", self.twin_bounds.wander)?;
        positive("twin_bounds.late_error", self.twin_bounds.late_error)?;
        finite("noise_retry", self.noise_retry)?;
        if self.noise_retry < 1.0 {
            return Err(ConfigError::new(
                "noise_retry",
                "must be at least 1 (1 = never)",
            ));
        }
        positive("noise_retry_wander", self.noise_retry_wander)?;
        non_negative("twin_bounds.swing_vs_pid", self.twin_bounds.swing_vs_pid)?;
        non_negative(
            "twin_bounds.swing_excess_min",
            self.twin_bounds.swing_excess_min,
        )?;
        Ok(())
    }
}

/// One candidate flown in the check.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckedCandidate {
    /// Delays q.
    pub delays: usize,
    /// Rank p.
    pub rank: usize,
    /// Held-out NMAE from the search.
    pub nmae: f64,
    /// Whether every run was within the bounds.
    pub passed: bool,
    /// Whether every run was within the bounds but the twin's swing bound (= `passed`
    /// without a twin).
    pub settled: bool,
    /// Worst figures over every plant and lag (NaN when the twin flight failed first and
    /// the linear plants were not flown).
    pub worst: StepCheck,
    /// The twin step flight, when a twin was given.
    pub twin: Option<TwinFlight>,
    /// The twin hold flight, when the candidate settled on the step flight and the linear
    /// plants.
    pub hold: Option<TwinHold>,
    /// The raised Kalman measurement noise these figures were flown with, when the first
    /// flight's wander asked for it (`SelectionSettings::noise_retry`).
    pub measurement_noise: Option<f64>,
}

impl CheckedCandidate {
    /// How far the candidate misses its bounds: the twin's miss first (a candidate that
    /// fails on the twin ranks behind every one that settles there), then the linear one.
    fn miss(&self, settings: &SelectionSettings) -> (f64, f64) {
        let twin = self.twin.map_or(0.0, |f| {
            settings
                .twin_bounds
                .miss(&f, self.hold.as_ref(), &settings.bounds)
                .max(1.0)
        });
        let linear = if self.worst.final_error.is_nan() {
            f64::INFINITY
        } else {
            settings.bounds.miss(&self.worst)
        };
        (twin, linear)
    }
}

/// One candidate's figures in [`select_for_control`].
struct Evaluation {
    flight: Option<TwinFlight>,
    worst: StepCheck,
    hold: Option<TwinHold>,
    settled: bool,
    damps: bool,
}

/// Outcome of [`select_for_control`].
#[derive(Clone, Debug)]
pub struct Selection {
    /// The model to fly, with `selected` and `control_check` in its diagnostics.
    pub model: LinearModel,
    /// Whether it passed the check (false: the least violating candidate).
    pub passed: bool,
    /// Every candidate flown, in the order flown.
    pub checked: Vec<CheckedCandidate>,
}

/// Pick from `search` (run on `train`/`test` with `identify`) the model to fly an MPC with
/// `mpc_settings` on, checking each candidate against the white-box `plant` of the flight
/// and, when given, first on the vehicle's `twin`.
#[allow(clippy::too_many_arguments)]
pub fn select_for_control(
    train: &Trajectory<'_>,
    test: &Trajectory<'_>,
    states: &[String],
    inputs: &[String],
    identify: &IdentifySettings,
    search: &SearchResult,
    plant: &LinearModel,
    mpc_settings: &MpcSettings,
    settings: &SelectionSettings,
    twin: Option<&TwinPlant>,
) -> Result<Selection, ControlError> {
    settings.validate()?;
    mpc_settings.validate()?;
    let mut plants = vec![plant.clone()];
    for &k in &settings.vehicle_drag {
        plants.push(plant.with_velocity_drag(k)?);
    }
    let best = &search.table[search.best];
    let refit = |q: usize, p: usize| -> Result<LinearModel, ControlError> {
        if (q, p) == (best.delays, best.rank) {
            let mut m = pipeline::named(search.model.clone(), states, inputs)?;
            m.diagnostics.test_nmae = search.model.diagnostics.test_nmae;
            return Ok(m);
        }
        let mut m = pipeline::named(pipeline::fit(train, identify, q, Some(p))?, states, inputs)?;
        pipeline::score(&mut m, test, identify)?;
        Ok(m)
    };
    // Stable rows first, best first: the screen's verdict is in the table. With a twin,
    // rows the search did not screen (worse than a stable p of their q) follow, screened
    // when their turn comes: a model whose rollout ranks behind can still be the one whose
    // MPC damps, and the twin's flight, not the linear check alone, is what vets it.
    let mut rows: Vec<_> = search
        .table
        .iter()
        .filter(|c| {
            c.nmae.is_finite()
                && match c.stable {
                    Some(stable) => stable,
                    None => twin.is_some(),
                }
        })
        .collect();
    rows.sort_by(|a, b| {
        (a.stable != Some(true))
            .cmp(&(b.stable != Some(true)))
            .then(a.nmae.total_cmp(&b.nmae))
    });
    // The search's stages can score the same (q, p) twice.
    let mut seen = std::collections::HashSet::new();
    rows.retain(|c| seen.insert((c.delays, c.rank)));
    let screen = identify.search_settings().map(|s| s.screen(train));
    let mut screened_out = 0usize;
    let mut verdicts = std::collections::HashMap::new();
    let mut checked: Vec<CheckedCandidate> = Vec::new();
    // One candidate's figures: the twin's step flight, then the linear plants, then the
    // twin's hold (the step flight held on), each only when the one before settled. The
    // MPC is designed once; every flight flies a fresh copy of it.
    let evaluate =
        |model: &LinearModel, twin: Option<&TwinPlant>| -> Result<Evaluation, ControlError> {
            let mpc = MpcController::new(model, mpc_settings.clone())?;
            let step = match twin {
                Some(tw) => Some(tw.fly_with(mpc.fresh_copy()?)?),
                None => None,
            };
            let flight = step.as_ref().map(|s| s.flight);
            let on_twin = flight.is_none_or(|f| settings.twin_bounds.admit(&f, &settings.bounds));
            let worst = if on_twin {
                worst_step_check(&mpc, model, &plants, &settings.input_lags, settings.step)?
            } else {
                StepCheck {
                    overshoot: f64::NAN,
                    final_error: f64::NAN,
                    hold_drift: f64::NAN,
                }
            };
            let mut settled = on_twin && settings.bounds.admit(&worst);
            let hold = match (twin, step) {
                (Some(tw), Some(step)) if settled => Some(tw.hold_on(step, mpc)?),
                _ => None,
            };
            if let Some(h) = &hold {
                settled = settings.twin_bounds.holds(h);
            }
            let damps = match (twin, &flight) {
                (Some(tw), Some(f)) => settings.twin_bounds.damps(f, tw.pid_flight()),
                _ => true,
            };
            Ok(Evaluation {
                flight,
                worst,
                hold,
                settled,
                damps,
            })
        };
    let mut chosen = None;
    for row in rows {
        if checked.len() >= settings.candidates {
            break;
        }
        let model = refit(row.delays, row.rank)?;
        if row.stable.is_none() {
            if let Some(screen) = &screen {
                let verdict = screen.judge(&model.a)?;
                if !verdict.stable {
                    screened_out += 1;
                    continue;
                }
                verdicts.insert((row.delays, row.rank), verdict);
            }
        }
        let mut model = model;
        let mut run = evaluate(&model, twin)?;
        let wander = |e: &Evaluation| e.hold.map_or(f64::INFINITY, |h| h.wander);
        // Only a candidate that settled up to its hold has a wander to retry.
        let noisy = run
            .hold
            .is_some_and(|h| h.wander > settings.noise_retry_wander);
        if noisy && settings.noise_retry > 1.0 {
            let mut retry = model.clone();
            retry.diagnostics.measurement_noise =
                Some(mpc_settings.kf_measurement_noise * settings.noise_retry);
            let again = evaluate(&retry, twin)?;
            let better = again.settled
                && (!run.settled || ((again.damps || !run.damps) && wander(&again) < wander(&run)));
            if better {
                (model, run) = (retry, again);
            }
        }
        let Evaluation {
            flight,
            worst,
            hold,
            settled,
            damps,
        } = run;
        checked.push(CheckedCandidate {
            delays: row.delays,
            rank: row.rank,
            nmae: row.nmae,
            passed: settled && damps,
            settled,
            worst,
            twin: flight,
            hold,
            measurement_noise: model.diagnostics.measurement_noise,
        });
        if settled && damps {
            chosen = Some(model);
            break;
        }
    }
    let passed = chosen.is_some();
    // A checked candidate's model, with the estimator noise it was flown with.
    let refit_as = |c: &CheckedCandidate| -> Result<LinearModel, ControlError> {
        let mut m = refit(c.delays, c.rank)?;
        m.diagnostics.measurement_noise = c.measurement_noise;
        Ok(m)
    };
    // Without a pass: the settled candidate that swings least, else the least miss.
    let least_swing = checked.iter().filter(|c| c.settled).min_by(|a, b| {
        let swing = |c: &CheckedCandidate| c.twin.map_or(f64::INFINITY, |f| f.swing_excess);
        swing(a).total_cmp(&swing(b))
    });
    let (mut model, pick) = match chosen {
        Some(m) => (m, "the first candidate within every bound"),
        None => match least_swing {
            Some(c) => (
                refit_as(c)?,
                "none damped the swing within the bound: the settled candidate that swings least",
            ),
            None => {
                let least = checked
                    .iter()
                    .min_by(|a, b| {
                        let (ta, la) = a.miss(settings);
                        let (tb, lb) = b.miss(settings);
                        ta.total_cmp(&tb).then(la.total_cmp(&lb))
                    })
                    .ok_or_else(|| {
                        ControlError::Model("the search has no stable candidate to check".into())
                    })?;
                (
                    refit_as(least)?,
                    "none settled: the candidate that misses its bounds least",
                )
            }
        },
    };
    let selected = search
        .table
        .iter()
        .find(|c| (c.delays, c.rank) == (model.delays, model.rank))
        .unwrap_or(best);
    let extra = &mut model.diagnostics.extra;
    extra.insert("selected".into(), candidate_row(selected, states));
    if let Some(v) = selected
        .verdict
        .as_ref()
        .or(verdicts.get(&(model.delays, model.rank)))
    {
        extra.insert("stability_screen".into(), v.to_json());
    }
    extra.insert(
        "control_check".into(),
        json!({
            "plant": settings.plant_label,
            "input_lags": settings.input_lags,
            "vehicle_drag": settings.vehicle_drag,
            "step": settings.step,
            "bounds": settings.bounds,
            "twin": twin.map(|t| json!({
                "plant": t.label(),
                "bounds": settings.twin_bounds,
                "pid": flight_json(t.pid_flight()),
                "swing_bound": settings.twin_bounds.swing_bound(t.pid_flight()),
            })),
            "passed": passed,
            "pick": pick,
            "screened_out": screened_out,
            "checked": checked.iter().map(|c| json!({
                "delays": c.delays,
                "rank": c.rank,
                "nmae": c.nmae,
                "passed": c.passed,
                "settled": c.settled,
                "overshoot": c.worst.overshoot,
                "final_error": c.worst.final_error,
                "hold_drift": c.worst.hold_drift,
                "twin": c.twin.as_ref().map(flight_json),
                "measurement_noise": c.measurement_noise,
                "hold": c.hold.map(|h| json!({"wander": h.wander, "late_error": h.late_error})),
            })).collect::<Vec<_>>(),
        }),
    );
    Ok(Selection {
        model,
        passed,
        checked,
    })
}

/// A twin flight's figures for the diagnostics.
fn flight_json(f: &TwinFlight) -> serde_json::Value {
    json!({
        "settle": f.settle,
        "overshoot": f.check.overshoot,
        "final_error": f.check.final_error,
        "hold_drift": f.check.hold_drift,
        "swing_excess": f.swing_excess,
    })
}
