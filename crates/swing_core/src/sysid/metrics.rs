//! Prediction error metrics (thesis 4.6.2, eq. 4.24–4.25).
//!
//! k-step-ahead rollout: from a start sample s (with the q−1 samples before it as history),
//! the model is run for H steps on the *true* inputs u_s … u_{s+H−1} only, never corrected
//! by measurements. Per state i, MAE_i = mean_k |x̂_{s+k,i} − x_{s+k,i}| (4.24) over
//! k = 1…H and NMAE_i = MAE_i / (max x_i − min x_i) (4.25), the range taken over the whole
//! test trajectory. Scores are averaged over the start points (10 by default, evenly spaced
//! in the test span) and the model score is the mean over states (the thesis's NMAE-bar).
//!
//! Rollouts exploit the delay structure: only the top n rows of `A` are dense, so one step
//! costs n dot products of length n·q over a contiguous history buffer (oldest first), not
//! an (n·q)² matrix–vector product.

use super::error::{data, SysidError};
use super::hankel::Trajectory;
use super::model::LinearModel;
use nalgebra::{DMatrix, DVector};

/// Rollout NMAE per state and the mean over states.
#[derive(Clone, Debug, PartialEq)]
pub struct Nmae {
    /// NMAE of each state (same order as the model's states).
    pub per_state: Vec<f64>,
    /// Mean over states.
    pub mean: f64,
}

/// The delay count whose history the scoring's first start leaves room for: `score_delays`
/// (so that every model up to that q is scored from the same starts), at least `q`, and at
/// most what the data leave before a `horizon`-step rollout.
pub fn score_delays(len: usize, q: usize, horizon: usize, score_delays: usize) -> usize {
    q.max(score_delays.min(len.saturating_sub(horizon)))
}

/// `count` start samples evenly spaced in [q−1, len−1−horizon] (both ends included).
pub fn start_points(
    len: usize,
    q: usize,
    horizon: usize,
    count: usize,
) -> Result<Vec<usize>, SysidError> {
    if count == 0 {
        return Err(super::error::config("at least one start point is needed"));
    }
    if horizon == 0 {
        return Err(super::error::config(
            "the horizon must be at least one step",
        ));
    }
    let lo = q.max(1) - 1;
    // Checked: a rollout of 1e300 s is `usize::MAX` samples, and the sum would wrap.
    let need = lo.checked_add(horizon).and_then(|v| v.checked_add(1));
    if need.is_none_or(|need| len < need) {
        return Err(data(format!(
            "test data of {len} samples is too short for {q} delays and a {horizon}-step horizon \
             (need at least {})",
            lo.saturating_add(horizon).saturating_add(1)
        )));
    }
    let hi = len - 1 - horizon;
    if count == 1 {
        return Ok(vec![lo]);
    }
    Ok((0..count)
        .map(|i| lo + ((hi - lo) as f64 * i as f64 / (count - 1) as f64).round() as usize)
        .collect())
}

/// Width of the rollouts' vector blocks (four f64 lanes: one AVX2 register).
const LANES: usize = 4;

/// Dot product with four accumulators (lets the compiler vectorise).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let ca = a.chunks_exact(4);
    let cb = b.chunks_exact(4);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        acc[0] += x[0] * y[0];
        acc[1] += x[1] * y[1];
        acc[2] += x[2] * y[2];
        acc[3] += x[3] * y[3];
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// The dense top rows of a delay-form model, laid out for fast rollouts.
#[derive(Clone, Debug)]
pub struct DelayRows {
    n: usize,
    m: usize,
    q: usize,
    /// Row i: coefficients of x_{k−q+1} … x_k (oldest first), n·q values per row.
    a_rev: Vec<f64>,
    /// B_top, row-major n × m.
    b: Vec<f64>,
    /// c − B·input_mean.
    c: Vec<f64>,
}

impl DelayRows {
    /// From top rows: `a_top` (n × n·q, newest-first blocks), `b_top` (n × m), `c_top`.
    pub fn from_top(
        a_top: &DMatrix<f64>,
        b_top: &DMatrix<f64>,
        c_top: &DVector<f64>,
        input_mean: &[f64],
    ) -> Self {
        let (n, m) = (a_top.nrows(), b_top.ncols());
        let q = a_top.ncols() / n;
        let mut a_rev = vec![0.0; n * n * q];
        for i in 0..n {
            for blk in 0..q {
                for s in 0..n {
                    a_rev[i * n * q + blk * n + s] = a_top[(i, (q - 1 - blk) * n + s)];
                }
            }
        }
        let b: Vec<f64> = (0..n * m).map(|k| b_top[(k / m, k % m)]).collect();
        let c = (0..n)
            .map(|i| c_top[i] - (0..m).map(|j| b_top[(i, j)] * input_mean[j]).sum::<f64>())
            .collect();
        Self {
            n,
            m,
            q,
            a_rev,
            b,
            c,
        }
    }

    /// From a model whose lower rows are the delay shift; `None` otherwise.
    pub fn from_model(model: &LinearModel) -> Option<Self> {
        if !model.has_shift_structure() {
            return None;
        }
        let (n, nz) = (model.n(), model.order());
        let a_top = model.a.view((0, 0), (n, nz)).into_owned();
        let b_top = model.b.view((0, 0), (n, model.m())).into_owned();
        let c_top = model.c.rows(0, n).into_owned();
        Some(Self::from_top(&a_top, &b_top, &c_top, &model.input_mean))
    }

    /// Delays q.
    pub fn delays(&self) -> usize {
        self.q
    }

    /// Next state from the last q states `hist` (oldest first) and raw input `u`.
    #[inline]
    fn step(&self, hist: &[f64], u: &[f64], out: &mut [f64]) {
        let nq = self.n * self.q;
        for (i, o) in out.iter_mut().enumerate() {
            let mut v = self.c[i] + dot(&self.a_rev[i * nq..(i + 1) * nq], hist);
            for j in 0..self.m {
                v += self.b[i * self.m + j] * u[j];
            }
            *o = v;
        }
    }
}

/// Reusable rollout scorer over one test trajectory (no allocation per candidate; one per
/// thread: clone it).
#[derive(Clone)]
pub struct Scorer<'a> {
    traj: Trajectory<'a>,
    starts: Vec<usize>,
    horizon: usize,
    inv_range: Vec<f64>,
    buf: Vec<f64>,
    /// Stop a rollout once an error exceeds this many ranges (diverged: score = ∞).
    pub abort_ranges: f64,
}

impl<'a> Scorer<'a> {
    /// Score on `traj` from `starts` (each ≥ q−1 of any model scored) over `horizon` steps.
    pub fn new(
        traj: Trajectory<'a>,
        starts: Vec<usize>,
        horizon: usize,
    ) -> Result<Self, SysidError> {
        if let Some(s) = starts.iter().find(|s| **s + horizon >= traj.len) {
            return Err(data(format!(
                "start {s} + horizon {horizon} runs past the {} test samples",
                traj.len
            )));
        }
        let n = traj.n;
        let mut lo = vec![f64::INFINITY; n];
        let mut hi = vec![f64::NEG_INFINITY; n];
        for k in 0..traj.len {
            for (i, v) in traj.state(k).iter().enumerate() {
                lo[i] = lo[i].min(*v);
                hi[i] = hi[i].max(*v);
            }
        }
        let mut inv_range = Vec::with_capacity(n);
        for i in 0..n {
            let r = hi[i] - lo[i];
            if r.is_nan() || r <= 0.0 {
                return Err(data(format!(
                    "state {i} is constant over the test data: its range is zero, NMAE is undefined"
                )));
            }
            inv_range.push(1.0 / r);
        }
        Ok(Self {
            traj,
            starts,
            horizon,
            inv_range,
            buf: Vec::new(),
            abort_ranges: f64::INFINITY,
        })
    }

    /// The start samples.
    pub fn starts(&self) -> &[usize] {
        &self.starts
    }

    /// Rollout NMAE of a delay-form model given by its top rows.
    pub fn score(&mut self, rows: &DelayRows) -> Result<Nmae, SysidError> {
        let n = self.traj.n;
        let q = rows.q;
        if rows.n != n || rows.m != self.traj.m {
            return Err(super::error::model(format!(
                "model has {} states and {} inputs, the data {} and {}",
                rows.n, rows.m, n, self.traj.m
            )));
        }
        if let Some(s) = self.starts.iter().find(|s| **s + 1 < q) {
            return Err(data(format!(
                "start {s} has fewer than {q} samples of history"
            )));
        }
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 (checked just above).
                return Ok(unsafe { self.rollouts_avx2(rows) });
            }
        }
        Ok(self.rollouts(rows))
    }

    /// [`Self::rollouts`] compiled for AVX2 (four lanes for the per-start updates; no
    /// fused multiply-add, so the figures are bit-identical to the portable build).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn rollouts_avx2(&mut self, rows: &DelayRows) -> Nmae {
        self.rollouts(rows)
    }

    /// The rollouts of a checked model (see [`Self::score`]).
    #[inline(always)]
    fn rollouts(&mut self, rows: &DelayRows) -> Nmae {
        let (n, q, h) = (self.traj.n, rows.q, self.horizon);
        // All start points advance together: the history buffer is interleaved as
        // buf[(t·n + s)·W + j] (time t, state s, start j; W = starts rounded up to a whole
        // number of 4-lane blocks, the spare lanes held at zero), so each model coefficient
        // is loaded once per step and applied to W contiguous values in full vector blocks
        // (no horizontal sums, no scalar remainder).
        let ns = self.starts.len();
        let w = ns.div_ceil(LANES) * LANES;
        let nq = n * q;
        self.buf.clear();
        self.buf.resize((q + h) * n * w, 0.0);
        let x = self.traj.x;
        for (j, &st) in self.starts.iter().enumerate() {
            for b in 0..q {
                for sidx in 0..n {
                    self.buf[(b * n + sidx) * w + j] = x[(st + 1 - q + b) * n + sidx];
                }
            }
        }
        let mut per_state = vec![0.0; n];
        let mut err = vec![0.0; n * ns];
        let mut acc = vec![0.0; w];
        let limit = self.abort_ranges;
        let m = rows.m;
        let mut diverged = false;
        'steps: for k in 0..h {
            let (hist, rest) = self.buf.split_at_mut((k + q) * n * w);
            let hist = &hist[k * n * w..];
            for i in 0..n {
                let coef = &rows.a_rev[i * nq..(i + 1) * nq];
                // One 4-lane block of starts at a time, its sums held in a register over
                // all n·q coefficients.
                for (blk, out) in acc.chunks_exact_mut(LANES).enumerate() {
                    let mut r = [rows.c[i]; LANES];
                    for (a, row) in coef.iter().zip(hist.chunks_exact(w)) {
                        let v: &[f64; LANES] = row[blk * LANES..(blk + 1) * LANES]
                            .try_into()
                            .expect("a block of LANES values");
                        for l in 0..LANES {
                            r[l] += a * v[l];
                        }
                    }
                    out.copy_from_slice(&r);
                }
                for (j, &st) in self.starts.iter().enumerate() {
                    let u = &self.traj.u[(st + k) * m..(st + k + 1) * m];
                    let mut v = acc[j];
                    for l in 0..m {
                        v += rows.b[i * m + l] * u[l];
                    }
                    let e = (v - x[(st + k + 1) * n + i]).abs();
                    if e.is_nan() || e * self.inv_range[i] > limit {
                        diverged = true;
                        break 'steps;
                    }
                    err[i * ns + j] += e;
                    rest[i * w + j] = v;
                }
            }
        }
        if diverged {
            per_state.iter_mut().for_each(|v| *v = f64::INFINITY);
        } else {
            for i in 0..n {
                let total: f64 = err[i * ns..(i + 1) * ns].iter().sum();
                per_state[i] = total * self.inv_range[i] / h as f64;
            }
        }
        let count = self.starts.len() as f64;
        per_state.iter_mut().for_each(|v| *v /= count);
        let mean = per_state.iter().sum::<f64>() / n as f64;
        Nmae { per_state, mean }
    }

    /// Rollout NMAE of any model (dense rollout when `A` lacks the delay-shift structure).
    pub fn score_model(&mut self, model: &LinearModel) -> Result<Nmae, SysidError> {
        model.validate()?;
        if model.n() != self.traj.n || model.m() != self.traj.m {
            return Err(super::error::model(format!(
                "model has {} states and {} inputs, the data {} and {}",
                model.n(),
                model.m(),
                self.traj.n,
                self.traj.m
            )));
        }
        if let Some(rows) = DelayRows::from_model(model) {
            return self.score(&rows);
        }
        let (n, q, h) = (model.n(), model.delays, self.horizon);
        let mut per_state = vec![0.0; n];
        for &s in &self.starts {
            if s + 1 < q {
                return Err(data(format!(
                    "start {s} has fewer than {q} samples of history"
                )));
            }
            let hist = &self.traj.x[(s + 1 - q) * n..(s + 1) * n];
            let pred = model.predict(hist, &self.traj.u[s * model.m()..(s + h) * model.m()])?;
            for k in 0..h {
                let truth = self.traj.state(s + k + 1);
                for i in 0..n {
                    per_state[i] +=
                        (pred[k * n + i] - truth[i]).abs() * self.inv_range[i] / h as f64;
                }
            }
        }
        let count = self.starts.len() as f64;
        per_state.iter_mut().for_each(|v| *v /= count);
        let mean = per_state.iter().sum::<f64>() / n as f64;
        Ok(Nmae { per_state, mean })
    }
}

/// Held-out rollout NMAE of `model` on `traj`: `starts` evenly spaced points, `horizon` steps.
pub fn rollout_nmae(
    model: &LinearModel,
    traj: &Trajectory<'_>,
    horizon: usize,
    starts: usize,
) -> Result<Nmae, SysidError> {
    let points = start_points(traj.len, model.delays, horizon, starts)?;
    Scorer::new(traj.clone(), points, horizon)?.score_model(model)
}

/// One-step-ahead NMAE over a whole trajectory (mean over states): a fit diagnostic.
pub fn one_step_nmae(model: &LinearModel, traj: &Trajectory<'_>) -> Result<f64, SysidError> {
    let (n, q) = (model.n(), model.delays);
    let Some(rows) = DelayRows::from_model(model) else {
        return Err(super::error::model(
            "one-step NMAE needs the delay-shift structure",
        ));
    };
    if traj.len < q + 1 {
        return Err(data("too few samples for a one-step score"));
    }
    let mut lo = vec![f64::INFINITY; n];
    let mut hi = vec![f64::NEG_INFINITY; n];
    let mut err = vec![0.0; n];
    let mut pred = vec![0.0; n];
    for k in (q - 1)..traj.len - 1 {
        rows.step(
            &traj.x[(k + 1 - q) * n..(k + 1) * n],
            traj.input(k),
            &mut pred,
        );
        for (i, t) in traj.state(k + 1).iter().enumerate() {
            err[i] += (pred[i] - t).abs();
        }
    }
    for k in 0..traj.len {
        for (i, v) in traj.state(k).iter().enumerate() {
            lo[i] = lo[i].min(*v);
            hi[i] = hi[i].max(*v);
        }
    }
    let count = (traj.len - q) as f64;
    let mut sum = 0.0;
    for i in 0..n {
        let r = hi[i] - lo[i];
        sum += if r > 0.0 { err[i] / count / r } else { 0.0 };
    }
    Ok(sum / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dot_matches_naive_sum() {
        let a: Vec<f64> = (0..11).map(|k| k as f64 * 0.5).collect();
        let b: Vec<f64> = (0..11).map(|k| 1.0 - k as f64).collect();
        let naive: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert!((dot(&a, &b) - naive).abs() < 1e-12);
    }

    #[test]
    fn constant_state_is_a_data_error() {
        let x = [1.0, 0.0, 1.0, 1.0, 1.0, 2.0];
        let u = [0.0, 0.0, 0.0];
        let traj = Trajectory::new(&x, 2, &u, 1).unwrap();
        let err = Scorer::new(traj, vec![0], 1).err().unwrap();
        assert!(err.to_string().contains("state 0 is constant"));
    }
}
