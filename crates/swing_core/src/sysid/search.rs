//! Hyper-parameter search over delays q and rank p (thesis 4.6.3, 4.6.8).
//!
//! Every candidate (q, p) is trained on the training trajectory and scored by the held-out
//! rollout NMAE of `metrics` on the test trajectory (the thesis takes the test span from the
//! start of the flight and trains on the rest). DMDc shares one QR of the data for all q
//! and one SVD per q for all p (see `dmdc`), adding modes incrementally as p grows; HAVOKc
//! takes one SVD of Π per q. Candidates whose rollout diverges score ∞.
//!
//! Screening (`stability`): a candidate with a mode that grows by more than `growth_limit`
//! over the prediction horizon is refused — except the velocity integrator's eigenvalue,
//! judged on its own within 1 ± `integrator_tolerance`. Eigenvalues are costly next to a rollout, so
//! per q the candidates are checked in ascending NMAE order until the first stable one: that
//! gives the best stable p of every q (the error-vs-q curve, the Pareto elbow of figure 4.6)
//! and hence the best stable candidate overall.
//!
//! Scoring: every rollout starts at or after sample `score_delays` − 1 of the test span (or
//! the grid's largest q − 1, if larger), so that a candidate scores the same in every grid
//! up to q = `score_delays` and two searches' NMAEs compare.
//!
//! Coarse → fine: [`coarse_to_fine`] runs a coarse grid, then a unit-step grid of q and p
//! around the coarse winner; [`refine`] (the default search) runs a coarse grid in which
//! every low rank is tried, then unit steps around several distinct coarse winners.

use nalgebra::{DMatrix, DVector};

use super::dmdc::{delay_form, split_g, DmdcBasis};
use super::error::{config, SysidError};
use super::hankel::Trajectory;
use super::havokc::HavokcSvd;
use super::metrics::{start_points, DelayRows, Scorer};
use super::model::{LinearModel, Offset};
use super::stability::{Screen, Verdict};

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
    /// The reference grid of the search budget (docs/architecture.md, "Budgets"): q = 2…60 step 2,
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
    /// Prediction horizon the model is used over [samples] (`stability`).
    pub prediction_horizon: usize,
    /// Largest growth of a mode over `prediction_horizon` (`stability`).
    pub growth_limit: f64,
    /// Distance from 1 allowed to the velocity integrator's eigenvalue (`stability`).
    pub integrator_tolerance: f64,
    /// Indices of the velocity states in a block; `None` = the first half of the states.
    pub velocity_states: Option<Vec<usize>>,
    /// Rollouts start at or after sample `score_delays` − 1 of the test data (module docs).
    pub score_delays: usize,
}

impl Default for SearchSettings {
    fn default() -> Self {
        Self {
            method: Method::Dmdc,
            offset: Offset::Affine,
            dt: super::settings::DEFAULT_DT,
            horizon: 667,
            starts: 10,
            prediction_horizon: super::settings::default_prediction_samples(),
            growth_limit: super::settings::DEFAULT_GROWTH_LIMIT,
            integrator_tolerance: super::settings::DEFAULT_INTEGRATOR_TOLERANCE,
            velocity_states: None,
            score_delays: super::settings::DEFAULT_SCORE_DELAYS,
        }
    }
}

impl SearchSettings {
    /// The stability screen for data of `train`.
    pub fn screen(&self, train: &Trajectory<'_>) -> Screen {
        let n = train.n;
        let scale = (0..n)
            .map(|j| {
                let len = train.len.max(1) as f64;
                let mean = (0..train.len).map(|k| train.state(k)[j]).sum::<f64>() / len;
                ((0..train.len)
                    .map(|k| (train.state(k)[j] - mean).powi(2))
                    .sum::<f64>()
                    / len)
                    .sqrt()
            })
            .collect();
        Screen {
            growth_limit: self.growth_limit,
            horizon: self.prediction_horizon,
            integrator_tolerance: self.integrator_tolerance,
            states: n,
            velocity: self
                .velocity_states
                .clone()
                .unwrap_or_else(|| (0..n / 2).collect()),
            scale,
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
    /// The stability screen's verdict, when checked.
    pub verdict: Option<Verdict>,
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
    let plan: Vec<(usize, RankChoice)> = grid
        .delays
        .iter()
        .map(|q| (*q, RankChoice::Grid(grid.clone())))
        .collect();
    search_plan(train, test, &plan, settings)
}

/// The ranks to try for one q of a plan.
#[derive(Clone, Debug)]
enum RankChoice {
    /// The ranks of a grid (which depend on the numerical full rank of q's data).
    Grid(Grid),
    /// Every rank in these inclusive windows (capped at the full rank).
    Windows(Vec<(usize, usize)>),
    /// Every rank up to the first value, and the grid's ranks above it.
    Dense(usize, Grid),
}

impl RankChoice {
    fn ranks(&self, q: usize, n: usize, m: usize, constants: usize, full: usize) -> Vec<usize> {
        match self {
            RankChoice::Grid(g) => g.ranks(q, n, m, constants, full),
            RankChoice::Windows(w) => {
                let top = (n * q + m + constants).min(full);
                let mut r: Vec<usize> = w
                    .iter()
                    .flat_map(|(lo, hi)| (*lo).max(1)..=(*hi).min(top))
                    .collect();
                r.sort_unstable();
                r.dedup();
                r
            }
            RankChoice::Dense(d, g) => {
                let top = (n * q + m + constants).min(full);
                let mut r: Vec<usize> = (1..=(*d).min(top)).collect();
                r.extend(
                    g.ranks(q, n, m, constants, full)
                        .into_iter()
                        .filter(|p| p > d),
                );
                r
            }
        }
    }
}

/// Score every (q, ranks of q) of `plan`, screen, and return the best stable candidate.
fn search_plan(
    train: &Trajectory<'_>,
    test: &Trajectory<'_>,
    plan: &[(usize, RankChoice)],
    settings: &SearchSettings,
) -> Result<SearchResult, SysidError> {
    if plan.is_empty() {
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
    let q_max = plan.iter().map(|(q, _)| *q).max().expect("non-empty");
    if plan.iter().any(|(q, _)| *q == 0) {
        return Err(config("delays must be at least 1"));
    }
    let q_score =
        super::metrics::score_delays(test.len, q_max, settings.horizon, settings.score_delays);
    let starts = start_points(test.len, q_score, settings.horizon, settings.starts)?;
    let screen = settings.screen(train);
    let mut scorer = Scorer::new(test.clone(), starts, settings.horizon)?;
    // A rollout further than 100 ranges off has diverged; stop it early.
    scorer.abort_ranges = 100.0;
    let basis = match settings.method {
        // The basis of the scoring's q, so that a candidate's fit, like its score, is the
        // same in every grid up to `score_delays`.
        Method::Dmdc => Some(DmdcBasis::new(
            train,
            q_score.min(train.len.saturating_sub(2)).max(q_max),
            settings.offset,
        )?),
        Method::Havokc => None,
    };
    // Each q is fitted, scored and screened on its own (side by side), then merged in the
    // plan's order, so the table and the pick are the one-by-one loop's.
    let per_q = crate::parallel::map(plan.iter().collect(), |(q, choice)| {
        let mut scorer = scorer.clone();
        fit_one_q(
            *q,
            choice,
            train,
            basis.as_ref(),
            &mut scorer,
            &screen,
            settings,
        )
    });
    let mut table: Vec<Candidate> = Vec::new();
    // The winner so far: its index in `table`, its top rows, singular values, input mean.
    let mut best: Option<(usize, Top, Vec<f64>, Vec<f64>)> = None;
    for outcome in per_q {
        let QOutcome {
            candidates,
            winner,
            sigma,
            input_mean,
        } = outcome?;
        let first = table.len();
        table.extend(candidates);
        if let Some((i, top)) = winner {
            let i = first + i;
            if best
                .as_ref()
                .is_none_or(|(b, ..)| table[i].nmae < table[*b].nmae)
            {
                best = Some((i, top, sigma, input_mean));
            }
        }
    }
    let Some((bi, t, sigma_of_best, input_mean)) = best else {
        return Err(SysidError::Identification(format!(
            "no stable candidate among {} (every model diverged or has a mode growing more \
             than {}× over the {}-sample prediction horizon besides the velocity integrator; \
             raise growth_limit or integrator_tolerance to admit more)",
            table.len(),
            settings.growth_limit,
            settings.prediction_horizon
        )));
    };
    let c = &table[bi];
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
    if let Some(v) = &c.verdict {
        model
            .diagnostics
            .extra
            .insert("stability_screen".into(), v.to_json());
    }
    model.diagnostics.fit_nmae = Some(super::metrics::one_step_nmae(&model, train)?);
    Ok(SearchResult {
        table,
        best: bi,
        model,
    })
}

/// One q of a plan: its candidates in rank order, and the first stable one in ascending
/// NMAE (its index among them and its top rows), the q's singular values and input mean.
struct QOutcome {
    candidates: Vec<Candidate>,
    winner: Option<(usize, Top)>,
    sigma: Vec<f64>,
    input_mean: Vec<f64>,
}

/// Fit and score every rank of delay count `q`, then screen them in ascending NMAE until
/// the first stable one.
fn fit_one_q(
    q: usize,
    choice: &RankChoice,
    train: &Trajectory<'_>,
    basis: Option<&DmdcBasis>,
    scorer: &mut Scorer<'_>,
    screen: &Screen,
    settings: &SearchSettings,
) -> Result<QOutcome, SysidError> {
    let (n, m) = (train.n, train.m);
    let source = match basis {
        Some(b) => Source::Dmdc(b.svd(q)?),
        None => Source::Havokc(HavokcSvd::new(train, q, settings.offset)?),
    };
    let (full, sigma, input_mean) = match (&source, basis) {
        (Source::Dmdc(s), Some(b)) => (s.rows(), s.sigma.clone(), b.input_mean().to_vec()),
        (Source::Havokc(s), _) => (s.rows(), s.sigma.clone(), s.input_mean().to_vec()),
        (Source::Dmdc(_), None) => unreachable!("a DMDc source comes from a basis"),
    };
    let ranks = choice.ranks(q, n, m, settings.offset.constant_columns(), full);
    let mut candidates = Vec::with_capacity(ranks.len());
    let mut tops = Vec::with_capacity(ranks.len());
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
        candidates.push(Candidate {
            delays: q,
            rank: p,
            nmae: score.mean,
            per_state: score.per_state,
            stable: None,
            spectral_radius: None,
            verdict: None,
        });
        tops.push(Some(top));
    }
    // Screen this q's candidates in ascending NMAE order until the first stable one.
    let mut order: Vec<usize> = (0..candidates.len())
        .filter(|i| candidates[*i].nmae.is_finite())
        .collect();
    order.sort_by(|a, b| candidates[*a].nmae.total_cmp(&candidates[*b].nmae));
    let mut winner = None;
    for i in order {
        let t = tops[i].as_ref().expect("each top is taken once");
        let model = delay_form(
            settings.method.name(),
            settings.dt,
            q,
            candidates[i].rank,
            settings.offset,
            input_mean.clone(),
            &t.a,
            &t.b,
            &t.c,
        );
        let verdict = screen.judge(&model.a)?;
        let ok = verdict.stable;
        candidates[i].spectral_radius = Some(verdict.spectral_radius);
        candidates[i].stable = Some(ok);
        candidates[i].verdict = Some(verdict);
        if ok {
            winner = tops[i].take().map(|top| (i, top));
            break;
        }
    }
    Ok(QOutcome {
        candidates,
        winner,
        sigma,
        input_mean,
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
    Ok(merge_stages(first, second))
}

/// The default search, in two stages.
///
/// 1. **Coarse**: the q of `coarse.delays`, each with every rank up to `dense_ranks` (narrow
///    low-rank optima are common on real data: the held-out NMAE over p is jagged, an
///    optimum is often one p wide) and the grid's rank steps above.
/// 2. **Refinement**: unit steps within ±`q_radius`, ±`p_radius` around the best stable
///    candidate of each of the `winners` delay counts whose best stable NMAE is lowest
///    (several, because near-equal optima at distant q are common), and around the best
///    rank of each of those q above `dense_ranks` (a narrow optimum between two grid ranks).
///
/// The better of the two stages' screened winners is returned.
#[allow(clippy::too_many_arguments)]
pub fn refine(
    train: &Trajectory<'_>,
    test: &Trajectory<'_>,
    coarse: &Grid,
    dense_ranks: usize,
    winners: usize,
    q_radius: usize,
    p_radius: usize,
    settings: &SearchSettings,
) -> Result<SearchResult, SysidError> {
    if coarse.delays.is_empty() {
        return Err(config("the search grid has no delay values"));
    }
    let plan: Vec<(usize, RankChoice)> = coarse
        .delays
        .iter()
        .map(|q| (*q, RankChoice::Dense(dense_ranks, coarse.clone())))
        .collect();
    let first = search_plan(train, test, &plan, settings)?;
    // The best stable candidate of each q, best first.
    let mut per_q: Vec<&Candidate> = Vec::new();
    for c in first.table.iter().filter(|c| c.stable == Some(true)) {
        match per_q.iter_mut().find(|b| b.delays == c.delays) {
            Some(b) if c.nmae < b.nmae => *b = c,
            Some(_) => {}
            None => per_q.push(c),
        }
    }
    per_q.sort_by(|a, b| a.nmae.total_cmp(&b.nmae));
    let q_top = coarse.delays.iter().copied().max().unwrap_or(1) + q_radius;
    let q_top = q_top.min(settings.score_delays.max(1)).max(1);
    // Around each winner's best rank, and around its best rank of the stepped part of the
    // grid (above `dense_ranks`): a narrow optimum of the high ranks hides between grid steps
    // even when a low dense rank is the q's best so far.
    let stepped_best = |q: usize| -> Option<usize> {
        first
            .table
            .iter()
            .filter(|c| c.delays == q && c.rank > dense_ranks && c.nmae.is_finite())
            .min_by(|a, b| a.nmae.total_cmp(&b.nmae))
            .map(|c| c.rank)
    };
    let mut windows: Vec<(usize, Vec<(usize, usize)>)> = Vec::new();
    for c in per_q.iter().take(winners.max(1)) {
        let mut centres = vec![c.rank];
        centres.extend(stepped_best(c.delays).filter(|p| *p != c.rank));
        for p in centres {
            let w = (p.saturating_sub(p_radius).max(1), p + p_radius);
            for q in c.delays.saturating_sub(q_radius).max(1)..=(c.delays + q_radius).min(q_top) {
                match windows.iter_mut().find(|(wq, _)| *wq == q) {
                    Some((_, ws)) => ws.push(w),
                    None => windows.push((q, vec![w])),
                }
            }
        }
    }
    windows.sort_by_key(|(q, _)| *q);
    let plan: Vec<(usize, RankChoice)> = windows
        .into_iter()
        .map(|(q, w)| (q, RankChoice::Windows(w)))
        .collect();
    let second = search_plan(train, test, &plan, settings)?;
    Ok(merge_stages(first, second))
}

/// Both stages' candidates in one table; the better stage's winner is selected (the second
/// on a tie).
fn merge_stages(first: SearchResult, second: SearchResult) -> SearchResult {
    let mut table = first.table;
    let offset = table.len();
    table.extend(second.table);
    let (best, model) = if second.model.diagnostics.test_nmae <= first.model.diagnostics.test_nmae {
        (offset + second.best, second.model)
    } else {
        (first.best, first.model)
    };
    SearchResult { table, best, model }
}
