//! Identification settings: the one home of their defaults and checks.
//!
//! `swingrt identify`, the `[identify]` section of an experiment and `swingrt.identify(...)`
//! all read this struct (serde, unknown keys refused), so a default such as the sample time
//! or the delay count is written once, and a typo names its field before anything flies.

use serde::{Deserialize, Serialize};

use super::model::Offset;
use super::search::{Grid, Method, SearchSettings};
use super::stability;
use crate::config::{finite, non_negative, positive, ConfigError};

/// Sample time of identification and of the MPC built on its models [s] (thesis 4.6.4).
pub const DEFAULT_DT: f64 = 0.03;
/// Delay count q of a fit without search.
pub const DEFAULT_DELAYS: usize = 20;
/// Largest q of the exhaustive search, and the first rollout start (+1) of every search's
/// scoring, so that the NMAEs of the default and the exhaustive search compare.
pub const DEFAULT_SCORE_DELAYS: usize = 80;
/// Distance from 1 allowed to the velocity integrator's eigenvalue (see `stability`).
pub const DEFAULT_INTEGRATOR_TOLERANCE: f64 = 5e-3;
/// Prediction horizon a model is used over [s]: the MPC's default horizon, which spans one
/// swing period of the longest cable (≈ 3 s); the stability screen's time scale.
pub const DEFAULT_PREDICTION_HORIZON: f64 = 3.0;
/// Largest growth of any mode over the prediction horizon (`stability`): no mode's
/// open-loop prediction more than doubles within the horizon.
pub const DEFAULT_GROWTH_LIMIT: f64 = 2.0;

/// `DEFAULT_PREDICTION_HORIZON` in samples of `DEFAULT_DT` (the MPC's default horizon).
pub fn default_prediction_samples() -> usize {
    (DEFAULT_PREDICTION_HORIZON / DEFAULT_DT).round() as usize
}

/// How a search walks the (q, p) plane.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SearchMode {
    /// Coarse grid (every rank up to `dense_ranks`, `rank_step` above), then unit steps
    /// within `fine` around the best p of each of the `winners` best q (`search::refine`).
    #[default]
    Refine,
    /// Every q of `search_delays` (default 2…`score_delays`) and every p: the reference.
    Exhaustive,
}

/// Which identification method to run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum IdentifyMethod {
    /// DMDc with delay coordinates (eq. 4.9–4.15).
    #[default]
    Dmdc,
    /// HAVOKc (eq. 4.16–4.23).
    Havokc,
    /// The white-box baseline (thesis 4.3): FFT cable length, RLS payload mass, eq. 5.7.
    Whitebox,
}

impl IdentifyMethod {
    /// The data-driven method a search runs, or `None` for the white-box.
    pub fn data_driven(self) -> Option<Method> {
        match self {
            IdentifyMethod::Dmdc => Some(Method::Dmdc),
            IdentifyMethod::Havokc => Some(Method::Havokc),
            IdentifyMethod::Whitebox => None,
        }
    }

    /// The model-file name.
    pub fn name(self) -> &'static str {
        match self {
            IdentifyMethod::Dmdc => "dmdc",
            IdentifyMethod::Havokc => "havokc",
            IdentifyMethod::Whitebox => "whitebox",
        }
    }
}

/// How a search picks the model it returns.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SelectBy {
    /// Lowest held-out NMAE among candidates whose MPC passes the closed-loop step check
    /// (`design::selection`).
    #[default]
    Control,
    /// Lowest held-out NMAE among stable candidates.
    Nmae,
}

/// Settings of one identification (fit, search, white-box), with their defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IdentifySettings {
    /// Method: `dmdc`, `havokc` or `whitebox`.
    pub method: IdentifyMethod,
    /// Offset handling of the input channel (thesis 4.6.6).
    pub offset: Offset,
    /// Delay count q of a fit (default [`DEFAULT_DELAYS`]); not with `search`.
    pub delays: Option<usize>,
    /// SVD truncation rank p of a fit (default: full rank); not with `search`.
    pub rank: Option<usize>,
    /// Search (q, p) on the held-out span instead of fitting given ones.
    pub search: bool,
    /// How a search chooses among its candidates.
    pub select: SelectBy,
    /// How a search walks the (q, p) plane: `refine` (default) or `exhaustive`.
    pub search_mode: SearchMode,
    /// Refine: every rank up to this one is tried on the coarse grid.
    pub dense_ranks: usize,
    /// Refine: number of best delay counts refined in unit steps of `fine`.
    pub winners: usize,
    /// First rollout start + 1 of the scoring, and the exhaustive search's largest q.
    pub score_delays: usize,
    /// Sample time the data are resampled to [s].
    pub dt: f64,
    /// Held-out span at the start of the flight, used for scoring and selection [s].
    pub test_span: f64,
    /// Rollout length of the k-step NMAE [s] (20 s in the thesis).
    #[serde(alias = "horizon")]
    pub rollout: f64,
    /// Number of rollout start points (10 in the thesis).
    pub starts: usize,
    /// Smooth states (quadratic regression) and inputs (Gaussian average) first (4.6.6).
    pub smooth: bool,
    /// Smoothing window [samples].
    pub smooth_window: usize,
    /// Delay counts of the search's coarse grid (default q = 2, 6, …, 78); of the
    /// exhaustive search (default 2…`score_delays`).
    pub search_delays: Option<Vec<usize>>,
    /// Smallest rank of the coarse grid.
    pub rank_start: usize,
    /// Rank step of the coarse grid.
    pub rank_step: usize,
    /// Unit-step refinement radius (q, p) around the coarse winners; `None` = grid only.
    /// The default p radius 7 reaches a narrow optimum two rank steps (of 5) from the best
    /// stepped rank, which the benchmark's drag flight has.
    pub fine: Option<[usize; 2]>,
    /// Prediction horizon the model will be used over [s] (the stability screen's time
    /// scale: set it to the MPC's horizon).
    pub prediction_horizon: f64,
    /// Largest factor by which any mode of a candidate may grow over `prediction_horizon`
    /// (≥ 1; 1 = the unit circle); the velocity integrator is judged apart.
    pub growth_limit: f64,
    /// |λ − 1| allowed to the velocity integrator's eigenvalue (see `sysid::stability`).
    pub integrator_tolerance: f64,
    /// White-box: payload mass [kg]; `None` = RLS on hover thrust (needs a thrust column).
    pub payload_mass: Option<f64>,
    /// White-box: cable length [m]; `None` = from the FFT peak of the swing (eq. 4.8).
    pub cable_length: Option<f64>,
    /// White-box: vehicle mass m_Q [kg] (table 6.1).
    pub vehicle_mass: f64,
    /// White-box: joint friction c of eq. 5.7 [N·m·s/rad].
    pub friction: f64,
    /// White-box: band searched for the swing's FFT peak [Hz].
    pub swing_band: [f64; 2],
    /// White-box: the swing is the IMU's estimate, not a sensor's: a second link is then
    /// adopted only on [`LinkSettings::for_imu_swing`]'s stricter evidence.
    ///
    /// [`LinkSettings::for_imu_swing`]: super::links::LinkSettings::for_imu_swing
    pub imu_swing: bool,
}

impl Default for IdentifySettings {
    fn default() -> Self {
        Self {
            method: IdentifyMethod::Dmdc,
            offset: Offset::Affine,
            delays: None,
            rank: None,
            search: false,
            select: SelectBy::Control,
            search_mode: SearchMode::Refine,
            dense_ranks: 20,
            winners: 4,
            score_delays: DEFAULT_SCORE_DELAYS,
            dt: DEFAULT_DT,
            test_span: 40.0,
            rollout: 20.0,
            starts: 10,
            smooth: false,
            smooth_window: 20,
            search_delays: None,
            rank_start: 5,
            rank_step: 5,
            fine: Some([2, 7]),
            prediction_horizon: DEFAULT_PREDICTION_HORIZON,
            growth_limit: DEFAULT_GROWTH_LIMIT,
            integrator_tolerance: DEFAULT_INTEGRATOR_TOLERANCE,
            payload_mass: None,
            cable_length: None,
            vehicle_mass: crate::plant::params::VehicleParams::default().mass,
            friction: 0.0,
            swing_band: [0.1, 3.0],
            imu_swing: false,
        }
    }
}

impl IdentifySettings {
    /// Check every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("dt", self.dt)?;
        non_negative("test_span", self.test_span)?;
        positive("rollout", self.rollout)?;
        if self.starts == 0 {
            return Err(ConfigError::new("starts", "must be at least 1"));
        }
        if self.delays == Some(0) {
            return Err(ConfigError::new("delays", "must be a positive integer"));
        }
        if self.rank == Some(0) {
            return Err(ConfigError::new("rank", "must be a positive integer"));
        }
        if self.search {
            if self.method == IdentifyMethod::Whitebox {
                return Err(ConfigError::new(
                    "search",
                    "applies to dmdc and havokc, not whitebox",
                ));
            }
            if self.delays.is_some() || self.rank.is_some() {
                return Err(ConfigError::new(
                    "search",
                    "give either search or delays/rank, not both",
                ));
            }
            if self.test_span == 0.0 {
                return Err(ConfigError::new(
                    "test_span",
                    "a search needs a test span > 0 s",
                ));
            }
        }
        if self.smooth && self.smooth_window < 3 {
            return Err(ConfigError::new(
                "smooth_window",
                "must be at least 3 samples",
            ));
        }
        if let Some(q) = &self.search_delays {
            if q.is_empty() {
                return Err(ConfigError::new("search_delays", "must not be empty"));
            }
            if q.contains(&0) {
                return Err(ConfigError::new(
                    "search_delays",
                    "delays must be at least 1",
                ));
            }
        }
        if self.rank_start == 0 {
            return Err(ConfigError::new("rank_start", "must be at least 1"));
        }
        if self.rank_step == 0 {
            return Err(ConfigError::new("rank_step", "must be at least 1"));
        }
        positive("prediction_horizon", self.prediction_horizon)?;
        if self.prediction_horizon < self.dt {
            return Err(ConfigError::new(
                "prediction_horizon",
                format!(
                    "must span at least one sample of dt = {} s (got {} s)",
                    self.dt, self.prediction_horizon
                ),
            ));
        }
        finite("growth_limit", self.growth_limit)?;
        if self.growth_limit < 1.0 {
            return Err(ConfigError::new(
                "growth_limit",
                format!(
                    "must be at least 1 (1 = the unit circle; got {})",
                    self.growth_limit
                ),
            ));
        }
        non_negative("integrator_tolerance", self.integrator_tolerance)?;
        if self.winners == 0 {
            return Err(ConfigError::new("winners", "must be at least 1"));
        }
        if self.score_delays == 0 {
            return Err(ConfigError::new("score_delays", "must be at least 1"));
        }
        if let Some(m) = self.payload_mass {
            positive("payload_mass", m)?;
        }
        if let Some(l) = self.cable_length {
            positive("cable_length", l)?;
        }
        positive("vehicle_mass", self.vehicle_mass)?;
        non_negative("friction", self.friction)?;
        finite("swing_band", self.swing_band[0])?;
        finite("swing_band", self.swing_band[1])?;
        if !(self.swing_band[0] > 0.0 && self.swing_band[0] < self.swing_band[1]) {
            return Err(ConfigError::new(
                "swing_band",
                format!(
                    "must be [low, high] with 0 < low < high Hz (got {:?})",
                    self.swing_band
                ),
            ));
        }
        Ok(())
    }

    /// Parse from JSON text (unknown keys and bad values name the field) and validate.
    pub fn from_json(text: &str) -> Result<Self, ConfigError> {
        let s: Self = crate::config::from_json_str(text)?;
        s.validate()?;
        Ok(s)
    }

    /// Delay count q of a fit.
    pub fn fit_delays(&self) -> usize {
        self.delays.unwrap_or(DEFAULT_DELAYS)
    }

    /// Rollout length in samples at `dt`.
    pub fn rollout_samples(&self) -> usize {
        ((self.rollout / self.dt).round() as usize).max(1)
    }

    /// Samples held out at the start of the data.
    pub fn test_samples(&self) -> usize {
        (self.test_span / self.dt).round() as usize
    }

    /// The search's scoring settings; `None` for the white-box.
    pub fn search_settings(&self) -> Option<SearchSettings> {
        Some(SearchSettings {
            method: self.method.data_driven()?,
            offset: self.offset,
            dt: self.dt,
            horizon: self.rollout_samples(),
            starts: self.starts,
            prediction_horizon: ((self.prediction_horizon / self.dt).round() as usize).max(1),
            growth_limit: self.growth_limit,
            integrator_tolerance: self.integrator_tolerance,
            velocity_states: None,
            score_delays: self.score_delays,
        })
    }

    /// The exhaustive grid: every q of `search_delays` (default 2…`score_delays`), every p.
    pub fn exhaustive_grid(&self) -> Grid {
        Grid {
            delays: self
                .search_delays
                .clone()
                .unwrap_or_else(|| (2..=self.score_delays.max(2)).collect()),
            rank_start: 1,
            rank_step: 1,
            rank_window: None,
        }
    }

    /// The stability screen's criterion in words, for diagnostics.
    pub fn stability_criterion(&self) -> &'static str {
        stability::CRITERION
    }

    /// The search's coarse grid.
    pub fn coarse_grid(&self) -> Grid {
        Grid {
            delays: self
                .search_delays
                .clone()
                .unwrap_or_else(|| (2..=78).step_by(4).collect()),
            rank_start: self.rank_start,
            rank_step: self.rank_step,
            rank_window: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_bad_fields_are_named() {
        IdentifySettings::default().validate().unwrap();
        let e = IdentifySettings::from_json(r#"{"serch": true}"#).unwrap_err();
        assert!(e.to_string().contains("serch"), "{e}");
        let e = IdentifySettings::from_json(r#"{"dt": -0.1}"#).unwrap_err();
        assert_eq!(e.field, "dt");
        let e = IdentifySettings::from_json(r#"{"search": true, "delays": 4}"#).unwrap_err();
        assert_eq!(e.field, "search");
        let e =
            IdentifySettings::from_json(r#"{"method": "whitebox", "search": true}"#).unwrap_err();
        assert_eq!(e.field, "search");
        let e = IdentifySettings::from_json(r#"{"swing_band": [2.0, 1.0]}"#).unwrap_err();
        assert_eq!(e.field, "swing_band");
        let e = IdentifySettings::from_json(r#"{"growth_limit": 0.5}"#).unwrap_err();
        assert_eq!(e.field, "growth_limit");
        let e = IdentifySettings::from_json(r#"{"prediction_horizon": 0.01}"#).unwrap_err();
        assert_eq!(e.field, "prediction_horizon");
        // The fixed tolerance the growth rule replaced is refused by name.
        let e = IdentifySettings::from_json(r#"{"stability_tolerance": 1e-3}"#).unwrap_err();
        assert!(e.to_string().contains("stability_tolerance"), "{e}");
        let screen = IdentifySettings::default().search_settings().unwrap();
        assert_eq!(screen.prediction_horizon, default_prediction_samples());
        // The seconds-named alias of the rollout length is read too.
        let s = IdentifySettings::from_json(r#"{"horizon": 3.0}"#).unwrap();
        assert_eq!(s.rollout_samples(), 100);
    }

    #[test]
    fn the_coarse_grid_and_scoring_follow_the_settings() {
        let s = IdentifySettings::default();
        assert_eq!(
            s.coarse_grid().delays,
            (2..=78).step_by(4).collect::<Vec<_>>()
        );
        assert_eq!(s.fit_delays(), DEFAULT_DELAYS);
        let sc = s.search_settings().unwrap();
        assert_eq!((sc.horizon, sc.starts), (667, 10));
        let wb = IdentifySettings {
            method: IdentifyMethod::Whitebox,
            ..IdentifySettings::default()
        };
        assert!(wb.search_settings().is_none());
    }

    #[test]
    fn the_exhaustive_grid_and_the_new_search_fields() {
        let s = IdentifySettings::from_json(r#"{"search_mode": "exhaustive"}"#).unwrap();
        let g = s.exhaustive_grid();
        assert_eq!(g.delays, (2..=80).collect::<Vec<_>>());
        assert_eq!((g.rank_start, g.rank_step), (1, 1));
        assert!(s.stability_criterion().contains("velocity integrator"));
        for (json, field) in [
            (r#"{"winners": 0}"#, "winners"),
            (r#"{"score_delays": 0}"#, "score_delays"),
            (r#"{"integrator_tolerance": -1.0}"#, "integrator_tolerance"),
        ] {
            assert_eq!(IdentifySettings::from_json(json).unwrap_err().field, field);
        }
        let e = IdentifySettings::from_json(r#"{"search_mode": "grid"}"#).unwrap_err();
        assert!(e.to_string().contains("search_mode"), "{e}");
    }
}
