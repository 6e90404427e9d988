//! Hyper-parameter search over delays q and rank p (thesis 4.6.3, 4.6.8).
//!
//! Every candidate (q, p) is trained on the training trajectory and scored by the held-out
//! rollout NMAE of `metrics` on the test trajectory (the thesis takes the test span from the
//! start of the flight and trains on the rest). DMDc shares one QR of the data for all q
//! and one SVD per q for all p (see `dmdc`), adding modes incrementally as p grows; HAVOKc
//! takes one SVD of Π per q. Candidates whose rollout diverges score ∞.
//!
//! Screening: a candidate whose `A` has spectral radius above 1 + `stability_tolerance` is
//! unstable and never selected. Eigenvalues are costly next to a rollout, so per q the
//! candidates are checked in ascending NMAE order until the first stable one: that gives
//! the best stable p of every q (the error-vs-q curve, the Pareto elbow of figure 4.6) and
//! hence the best stable candidate overall. The tolerance admits the velocity integrator
//! (an eigenvalue at exactly 1 in the true plant, estimated at 1 ± a little).
//!
//! Coarse → fine: [`coarse_to_fine`] runs a coarse grid, then a unit-step grid of q and p
//! around the coarse winner.

use nalgebra::{DMatrix, DVector};

use super::dmdc::{delay_form, split_g, DmdcBasis};
use super::error::{config, SysidError};
use super::hankel::Trajectory;
use super::havokc::HavokcSvd;
use super::metrics::{start_points, DelayRows, Scorer};
use super::model::{spectral_radius, LinearModel, Offset};

/// Which data-driven method a search fits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// DMDc (eq. 4.9–4.15).
    Dmdc,
    /// HAVOKc (eq. 4.16–4.23).
    Havokc,
}

impl Method {
    /// The model-file name.
    pub fn name(&self) -> &'static str {
        match self {
            Method::Dmdc => "dmdc",
            Method::Havokc => "havokc",
        }
    }
}

/// A grid of candidates.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    /// Delay counts q to try.
    pub delays: Vec<usize>,
    /// Smallest rank p.
    pub rank_start: usize,
    /// Rank step.
    pub rank_step: usize,
    /// Only ranks within `rank_window` = (lo, hi) when given (fine stage).
    pub rank_window: Option<(usize, usize)>,
}

impl Grid {
    /// The reference grid of the search budget (DESIGN §8): q = 2…60 step 2,
    /// p = 5…(n·q + m) step 5.
    pub fn reference() -> Self {
        Self {
            delays: (2..=60).step_by(2).collect(),
            rank_start: 5,
            rank_step: 5,
            rank_window: None,
        }
    }

    /// Ranks tried for q with n states, m inputs, `constants` constant regression columns
    /// (see [`Offset::constant_columns`]) and numerical full rank `full`; ranks above the
    /// full rank n·q + m + constants are never tried.
    pub fn ranks(&self, q: usize, n: usize, m: usize, constants: usize, full: usize) -> Vec<usize> {
        let top = (n * q + m + constants).min(full);
        let (lo, hi) = self.rank_window.unwrap_or((1, usize::MAX));
        (self.rank_start.max(1)..=top)
            .step_by(self.rank_step.max(1))
            .filter(|p| *p >= lo && *p <= hi)
            .collect()
    }
}

/// Settings of a search.
#[derive(Clone, Debug, PartialEq)]
pub struct SearchSettings {
    /// Method.
    pub method: Method,
    /// Offset handling.
    pub offset: Offset,
    /// Sample time [s].
    pub dt: f64,
    /// Rollout horizon [samples] (20 s / dt in the thesis).
    pub horizon: usize,
    /// Number of rollout start points (10 in the thesis).
    pub starts: usize,
    /// Spectral radius allowed above 1 (see module docs).
    pub stability_tolerance: f64,
}

impl Default for SearchSettings {
    fn default() -> Self {
        Self {
            method: Method::Dmdc,
            offset: Offset::Affine,
            dt: super::settings::DEFAULT_DT,
            horizon: 667,
            starts: 10,
            stability_tolerance: 1e-3,
        }
    }
}

/// One scored candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// Delays q.
    pub delays: usize,
    /// Rank p.
    pub rank: usize,
    /// Held-out rollout NMAE per state.
    pub per_state: Vec<f64>,
    /// Mean NMAE (∞ when the rollout diverged).
    pub nmae: f64,
    /// Stability verdict; `None` when not checked (worse than the best stable p of its q).
    pub stable: Option<bool>,
    /// Spectral radius, when checked.
    pub spectral_radius: Option<f64>,
}

/// Outcome of a search.
#[derive(Clone, Debug)]
pub struct SearchResult {
    /// Every candidate tried, in grid order.
    pub table: Vec<Candidate>,
    /// Index in `table` of the selected candidate.
    pub best: usize,
    /// The selected model, trained on the training trajectory.
    pub model: LinearModel,
}

struct Top {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    c: DVector<f64>,
}

/// Per-q source of candidate models.
enum Source {
    Dmdc(super::dmdc::DmdcSvd),
    Havokc(HavokcSvd),
}

/// Run one grid: train on `train`, score on `test`.
pub fn grid_search(
    train: &Trajectory<'_>,
    test: &Trajectory<'_>,
    grid: &Grid,
    settings: &SearchSettings,
) -> Result<SearchResult, SysidError> {
    if grid.delays.is_empty() {
        return Err(config("the search grid has no delay values"));
    }
    if !(settings.dt.is_finite() && settings.dt > 0.0) {
        return Err(config(format!("dt must be positive, not {}", settings.dt)));
    }
    if train.n != test.n || train.m != test.m {
        return Err(super::error::data(
            "training and test data have different columns",
        ));
    }
    let q_max = *grid.delays.iter().max().expect("non-empty");
    if grid.delays.contains(&0) {
        return Err(config("delays must be at least 1"));
    }
    let (n, m) = (train.n, train.m);
    let starts = start_points(test.len, q_max, settings.horizon, settings.starts)?;
    let mut scorer = Scorer::new(test.clone(), starts, settings.horizon)?;
    // A rollout further than 100 ranges off has diverged; stop it early.
    scorer.abort_ranges = 100.0;
    let basis = match settings.method {
        Method::Dmdc => Some(DmdcBasis::new(train, q_max, settings.offset)?),
        Method::Havokc => None,
    };
    let mut table: Vec<Candidate> = Vec::new();
    let mut tops: Vec<Top> = Vec::new();
    let mut best: Option<usize> = None;
    let mut input_mean = vec![0.0; m];
    let mut sigma_of_best = Vec::new();
    for &q in &grid.delays {
        let source = match &basis {
            Some(b) => Source::Dmdc(b.svd(q)?),
            None => Source::Havokc(HavokcSvd::new(train, q, settings.offset)?),
        };
        let (full, sigma) = match &source {
            Source::Dmdc(s) => (s.rows(), s.sigma.clone()),
            Source::Havokc(s) => (s.rows(), s.sigma.clone()),
        };
        input_mean = match (&basis, &source) {
            (Some(b), _) => b.input_mean().to_vec(),
            (None, Source::Havokc(s)) => s.input_mean().to_vec(),
            _ => unreachable!(),
        };
        let ranks = grid.ranks(q, n, m, settings.offset.constant_columns(), full);
        let first = table.len();
        let mut g = faer::Mat::<f64>::zeros(n, full);
        let mut prev = 0;
        for &p in &ranks {
            let top = match &source {
                Source::Dmdc(s) => {
                    s.accumulate(&mut g, prev, p);
                    prev = p;
                    let (a, b, c) = split_g(&g, &s.features);
                    Top { a, b, c }
                }
                Source::Havokc(s) => {
                    let (a, b, c, _) = s.top(p)?;
                    Top { a, b, c }
                }
            };
            let rows = DelayRows::from_top(&top.a, &top.b, &top.c, &input_mean);
            let score = scorer.score(&rows)?;
            table.push(Candidate {
                delays: q,
                rank: p,
                nmae: score.mean,
                per_state: score.per_state,
                stable: None,
                spectral_radius: None,
            });
            tops.push(top);
        }
        // Screen this q's candidates in ascending NMAE order until the first stable one.
        let mut order: Vec<usize> = (first..table.len())
            .filter(|i| table[*i].nmae.is_finite())
            .collect();
        order.sort_by(|a, b| table[*a].nmae.total_cmp(&table[*b].nmae));
        for i in order {
            let t = &tops[i];
            let model = delay_form(
                settings.method.name(),
                settings.dt,
                q,
                table[i].rank,
                settings.offset,
                input_mean.clone(),
                &t.a,
                &t.b,
                &t.c,
            );
            let rho = spectral_radius(&model.a)?;
            let ok = rho <= 1.0 + settings.stability_tolerance;
            table[i].spectral_radius = Some(rho);
            table[i].stable = Some(ok);
            if ok {
                if best.is_none_or(|b| table[i].nmae < table[b].nmae) {
                    best = Some(i);
                    sigma_of_best = sigma.clone();
                }
                break;
            }
        }
        // Keep only what the winner needs.
        for (i, t) in tops.iter_mut().enumerate().skip(first) {
            if Some(i) != best {
                *t = Top {
                    a: DMatrix::zeros(0, 0),
                    b: DMatrix::zeros(0, 0),
                    c: DVector::zeros(0),
                };
            }
        }
    }
    let Some(bi) = best else {
        return Err(SysidError::Identification(format!(
            "no stable candidate among {} (every model diverged or has spectral radius above {})",
            table.len(),
            1.0 + settings.stability_tolerance
        )));
    };
    let c = &table[bi];
    let t = &tops[bi];
    let mut model = delay_form(
        settings.method.name(),
        settings.dt,
        c.delays,
        c.rank,
        settings.offset,
        input_mean,
        &t.a,
        &t.b,
        &t.c,
    );
    model.fingerprint = train.fingerprint();
    model.diagnostics.singular_values = sigma_of_best;
    model.diagnostics.test_nmae = Some(c.nmae);
    model.diagnostics.spectral_radius = c.spectral_radius;
    model.diagnostics.fit_nmae = Some(super::metrics::one_step_nmae(&model, train)?);
    Ok(SearchResult {
        table,
        best: bi,
        model,
    })
}

/// Coarse grid (`coarse`), then unit steps within ±`q_radius`, ±`p_radius` of its winner.
pub fn coarse_to_fine(
    train: &Trajectory<'_>,
    test: &Trajectory<'_>,
    coarse: &Grid,
    q_radius: usize,
    p_radius: usize,
    settings: &SearchSettings,
) -> Result<SearchResult, SysidError> {
    let first = grid_search(train, test, coarse, settings)?;
    let (q0, p0) = (first.table[first.best].delays, first.table[first.best].rank);
    let q_hi = coarse
        .delays
        .iter()
        .max()
        .copied()
        .unwrap_or(q0)
        .max(q0 + q_radius);
    let fine = Grid {
        delays: (q0.saturating_sub(q_radius).max(1)..=q_hi.min(q0 + q_radius)).collect(),
        rank_start: 1,
        rank_step: 1,
        rank_window: Some((p0.saturating_sub(p_radius).max(1), p0 + p_radius)),
    };
    let second = grid_search(train, test, &fine, settings)?;
    // Report both stages; the fine one can only improve on the coarse winner's neighbourhood.
    let mut table = first.table;
    let offset = table.len();
    table.extend(second.table);
    let (best, model) = if second.model.diagnostics.test_nmae <= first.model.diagnostics.test_nmae {
        (offset + second.best, second.model)
    } else {
        (first.best, first.model)
    };
    Ok(SearchResult { table, best, model })
}
