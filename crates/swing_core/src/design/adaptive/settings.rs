//! Settings of the adaptive MPC: the online identification, when a re-synthesis is due,
//! its closed-loop check and the twin path.

use serde::{Deserialize, Serialize};

use crate::config::{non_negative, positive, ConfigError};
use crate::design::reidentify::{Twin, MIN_TWIN_SECONDS};
use crate::design::selection::CheckBounds;
use crate::sysid::online::OnlineSettings;

/// Where the re-synthesis runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SynthesisMode {
    /// A worker thread (real time; the swap tick depends on wall-clock time).
    Thread,
    /// Between ticks on the caller's thread (simulation; reproducible).
    #[default]
    Deferred,
}

/// Settings of the adaptive MPC (the MPC's own settings are separate).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdaptiveSettings {
    /// Online identification: forgetting, excitation gate, detector.
    pub online: OnlineSettings,
    /// Excited samples that must enter the estimate after a detection before a rebuild
    /// [samples of the model's dt].
    pub min_new_samples: usize,
    /// Further excited samples before retrying after a rejected candidate [samples].
    pub retry_samples: usize,
    /// Velocity step of the closed-loop check [m/s].
    pub check_step: f64,
    /// Input lags of the closed-loop check [s] (0 = none).
    pub input_lags: Vec<f64>,
    /// Pure delays of the command the check's loop must also stand, with no lag [s]: the
    /// offline selection's delay margin (`SelectionSettings::input_delays`; off by default,
    /// as there).
    pub input_delays: Vec<f64>,
    /// Amplitudes of the command, as multiples of the MPC's acceleration bound, at which the
    /// check's loops must not be predicted to limit-cycle against it (the offline
    /// selection's describing-function test, `SelectionSettings::bound_amplitudes`; off by
    /// default, as there).
    pub bound_amplitudes: Vec<f64>,
    /// Linear vehicle drag added to the candidate as a second check plant [1/s] (0 = only
    /// the candidate itself).
    pub check_drag: f64,
    /// Pass bounds of the check (fractions of the step).
    pub bounds: CheckBounds,
    /// Largest spectral radius of a candidate's A [dimensionless].
    pub max_spectral_radius: f64,
    /// Where the synthesis runs: `deferred` (simulation) or `thread` (real time).
    pub synthesis: SynthesisMode,
    /// Amplitude of a probing input added to the command from a detection until the next
    /// adoption [m/s²] (0 = off, the default): a pseudo-random ±amplitude sequence held for
    /// `probe_hold` ticks, which breaks the collinearity of input and state that feedback
    /// leaves in closed-loop data.
    pub probe_amplitude: f64,
    /// Ticks each probing level is held [ticks].
    pub probe_hold: usize,
    /// A detection within this many ticks of a swap reverts to the controller the swap
    /// replaced, which has flown [ticks] (0 = never); after three reverts adaptation stops
    /// for the flight.
    pub revert_window: usize,
    /// Re-identification on the vehicle's twin from the payload measured in flight
    /// ([`crate::design::reidentify`]); off by default, and it needs a twin at construction.
    pub twin: TwinSettings,
}

/// Settings of the twin path of the adaptive MPC: when the measured cable length departs
/// from the model's, fly the twin with the measured payload and re-identify.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TwinSettings {
    /// Use the twin (and not the online DMDc's refits) to re-identify.
    pub enabled: bool,
    /// Length of the twin's training flight [s].
    pub duration: f64,
    /// Search the rank at the model's delays and select for control, as the model before
    /// the flight was (false: keep the model's rank).
    pub search: bool,
    /// Relative change of the measured cable length that triggers a re-identification
    /// [fraction].
    pub length_change: f64,
    /// Largest relative standard error of a length estimate acted upon [fraction] (it must
    /// also depart from the model's by [`LENGTH_SIGNIFICANCE`] standard errors).
    pub confidence: f64,
    /// Change of the measured total mass that starts probing until the length is confirmed
    /// [kg] (a pick-up in hover leaves the payload still, and a still pendulum shows no
    /// length); probing needs `probe_amplitude` > 0.
    pub mass_change: f64,
    /// Longest probing after a mass change [s].
    pub probe_seconds: f64,
    /// Forgetting factor per tick of the length estimate, (0, 1).
    pub forgetting: f64,
}

impl Default for TwinSettings {
    fn default() -> Self {
        Self {
            enabled: false,
            duration: 120.0,
            search: true,
            length_change: 0.15,
            confidence: 0.4,
            mass_change: 0.05,
            probe_seconds: 3.0,
            forgetting: 0.99,
        }
    }
}

impl TwinSettings {
    /// Check every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ConfigError> {
        crate::config::in_range("duration", self.duration, MIN_TWIN_SECONDS, 3600.0)?;
        positive("length_change", self.length_change)?;
        positive("confidence", self.confidence)?;
        positive("mass_change", self.mass_change)?;
        non_negative("probe_seconds", self.probe_seconds)?;
        crate::config::in_range("forgetting", self.forgetting, 0.5, 0.9999)?;
        Ok(())
    }
}

/// The twin and the payload the initial model was identified with.
#[derive(Clone, Debug)]
pub struct TwinPrior {
    /// The vehicle's twin.
    pub twin: Twin,
    /// Payload mass of the initial model [kg].
    pub payload_mass: f64,
    /// Cable length of the initial model [m].
    pub length: f64,
}

impl Default for AdaptiveSettings {
    fn default() -> Self {
        Self {
            online: OnlineSettings::default(),
            min_new_samples: 150,
            retry_samples: 60,
            check_step: 2.0,
            input_lags: vec![0.0, 0.1],
            input_delays: Vec::new(),
            bound_amplitudes: Vec::new(),
            check_drag: 0.12,
            bounds: CheckBounds::default(),
            max_spectral_radius: 1.005,
            synthesis: SynthesisMode::Deferred,
            probe_amplitude: 0.0,
            probe_hold: 5,
            revert_window: 200,
            twin: TwinSettings::default(),
        }
    }
}

impl AdaptiveSettings {
    /// Check every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.online.validate().map_err(|e| e.within("online"))?;
        if self.min_new_samples == 0 {
            return Err(ConfigError::new("min_new_samples", "must be at least 1"));
        }
        if self.retry_samples == 0 {
            return Err(ConfigError::new("retry_samples", "must be at least 1"));
        }
        positive("check_step", self.check_step)?;
        if self.input_lags.is_empty() {
            return Err(ConfigError::new(
                "input_lags",
                "needs at least one lag (0 = none)",
            ));
        }
        for (i, l) in self.input_lags.iter().enumerate() {
            non_negative(&format!("input_lags[{i}]"), *l)?;
        }
        for (i, d) in self.input_delays.iter().enumerate() {
            non_negative(&format!("input_delays[{i}]"), *d)?;
        }
        crate::design::check::check_bound_amplitudes(&self.bound_amplitudes)?;
        non_negative("check_drag", self.check_drag)?;
        for (name, v) in [
            ("bounds.overshoot", self.bounds.overshoot),
            ("bounds.final_error", self.bounds.final_error),
            ("bounds.hold_drift", self.bounds.hold_drift),
        ] {
            positive(name, v)?;
        }
        positive("max_spectral_radius", self.max_spectral_radius)?;
        crate::config::in_range("probe_amplitude", self.probe_amplitude, 0.0, 2.0)?;
        if self.probe_hold == 0 {
            return Err(ConfigError::new("probe_hold", "must be at least 1 tick"));
        }
        self.twin.validate().map_err(|e| e.within("twin"))?;
        Ok(())
    }
}
