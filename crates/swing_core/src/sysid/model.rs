//! The identified model: a discrete linear state-space over delay coordinates.
//!
//! For every method the model acts on the stacked state
//! z_k = [x_k; x_{k-1}; …; x_{k-q+1}] (newest first) as
//! z_{k+1} = A z_k + B (u_k − input_mean) + c.
//!
//! The JSON form (`"format": "swingrt-model/1"`) stores `A`, `B` as nested row lists and
//! `c`, `input_mean` as lists, with the training-data `fingerprint` and `diagnostics`.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::error::{model, SysidError};

/// The schema tag of a model file.
pub const MODEL_FORMAT: &str = "swingrt-model/1";

/// Largest stacked state n·q a model may declare. The thesis's search tops out at q = 58
/// over six states (348); a file declaring more (`"delays": 18446744073709551615`) is
/// refused before its dimensions are multiplied or anything is allocated for them.
pub const MAX_MODEL_ORDER: usize = 4096;

/// n·q when it is within [`MAX_MODEL_ORDER`], else the error naming both.
pub fn model_order(n: usize, q: usize) -> Result<usize, SysidError> {
    n.checked_mul(q)
        .filter(|nz| *nz <= MAX_MODEL_ORDER)
        .ok_or_else(|| {
            model(format!(
                "{n} states × {q} delays exceeds the largest model order {MAX_MODEL_ORDER}"
            ))
        })
}

/// How the constant offset of the input channel is handled (thesis 4.6.6).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Offset {
    /// No offset handling.
    None,
    /// Subtract the training input mean (the thesis's choice).
    Mean,
    /// Learn a constant column `c` (default; predicts better on held-out data); the
    /// white-box learns its residual's term in the velocity beside it
    /// (`whitebox::apply_offset`).
    #[default]
    Affine,
}

impl Offset {
    /// Parse `none`, `mean` or `affine`.
    pub fn parse(s: &str) -> Result<Self, SysidError> {
        match s {
            "none" => Ok(Offset::None),
            "mean" => Ok(Offset::Mean),
            "affine" => Ok(Offset::Affine),
            other => Err(super::error::config(format!(
                "offset must be none, mean or affine, not {other:?}"
            ))),
        }
    }

    /// Constant regression columns the offset adds (1 for `affine`): the full rank of a
    /// fit is n·q + m + this.
    pub fn constant_columns(&self) -> usize {
        usize::from(*self == Offset::Affine)
    }

    /// The lowercase name.
    pub fn name(&self) -> &'static str {
        match self {
            Offset::None => "none",
            Offset::Mean => "mean",
            Offset::Affine => "affine",
        }
    }
}

/// White-box parameter estimates (thesis 4.3), reported in a model's diagnostics.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WhiteboxEstimates {
    /// Vehicle mass m_Q [kg] (known).
    pub vehicle_mass: f64,
    /// Payload mass m_p [kg] (RLS on hover thrust, or given).
    pub payload_mass: f64,
    /// Cable length l [m]: given, or the single pendulum fitted to the swing's answer to
    /// the vehicle's motion (`sysid::links::fit`), or the FFT peak's when that fit fails.
    pub length: f64,
    /// Measured swing frequency [Hz] (FFT peak), if the length was estimated.
    pub frequency_hz: Option<f64>,
    /// The length the FFT peak gives (eq. 4.8, the thesis's estimate), if estimated [m].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fft_length: Option<f64>,
    /// Joint friction coefficient c of eq. 5.7 [N·m·s/rad].
    pub friction: f64,
    /// A second link found in the swing (`sysid::links`), when the length was estimated:
    /// the model stays a single pendulum of `length`; the vehicle's twin carries both links.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub links: Option<super::links::DoublePendulum>,
    /// The second peak of the swing's spectrum (`sysid::spectrum`), for a swing estimated
    /// from the IMU whose links fit found no second link.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub second_peak: Option<super::spectrum::SecondPeak>,
    /// Standard deviation of the swing sensor's white noise [rad], estimated from the
    /// training swing (`whitebox::noise_std`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub swing_noise: Option<f64>,
    /// The attitude loop as a first-order lag from the acceleration command to the
    /// vehicle's acceleration [s], fitted to the training flight (`sysid::lag`), when the
    /// flight tells it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attitude_lag: Option<f64>,
    /// With the `affine` offset: each state row's one-step residual per m/s of its axis's
    /// velocity, added to the model's newest-velocity column (`whitebox::apply_offset`): the
    /// airframe's drag and, for a swing estimated from the IMU, the drag it reads as swing
    /// [state unit per tick per m/s].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity_residual: Option<Vec<f64>>,
}

impl WhiteboxEstimates {
    /// The rate of the payload's second mode [rad/s], where the swing shows one: the
    /// fitted links' (with the vehicle held), else the second peak of the swing's spectrum
    /// where it is high enough.
    pub fn second_mode(&self) -> Option<f64> {
        let fitted = self
            .links
            .as_ref()
            .map(|d| d.second_mode)
            .filter(|w| w.is_finite() && *w > 0.0);
        fitted.or(self
            .second_peak
            .filter(|p| p.shown && p.omega.is_finite())
            .map(|p| p.omega))
    }
}

/// Diagnostics stored with a model.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Diagnostics {
    /// Singular values of the regression matrix (Ω for DMDc, Π for HAVOKc), descending.
    #[serde(default)]
    pub singular_values: Vec<f64>,
    /// One-step-ahead NMAE on the training data (mean over states).
    #[serde(default)]
    pub fit_nmae: Option<f64>,
    /// Held-out k-step rollout NMAE (mean over states), when a test span was scored.
    #[serde(default)]
    pub test_nmae: Option<f64>,
    /// Spectral radius of `A`.
    #[serde(default)]
    pub spectral_radius: Option<f64>,
    /// White-box estimates (method `whitebox`).
    #[serde(default)]
    pub whitebox: Option<WhiteboxEstimates>,
    /// Kalman measurement noise std of every channel [m/s, rad] that an MPC on this model
    /// assumes at least, given by the user or a model file; the selection designs only the
    /// swing channels' (`swing_measurement_noise`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measurement_noise: Option<f64>,
    /// Kalman measurement noise std of the swing channels an MPC on this model assumes at
    /// least [rad]: set by the control-relevant selection's noise design, against the
    /// flight's swing-sensor noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub swing_measurement_noise: Option<f64>,
    /// Kalman process noise std of the disturbances an MPC on this model assumes at least
    /// (`MpcSettings::kf_disturbance_noise`): set by the control-relevant selection's
    /// disturbance design, on the twin's gust flight.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub disturbance_noise: Option<f64>,
    /// Stationary std of the gust force an MPC on this model estimates at least
    /// (`MpcSettings::gust_noise`) [m/s²]: set by the control-relevant selection's
    /// disturbance design, on the twin's gust flight.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gust_noise: Option<f64>,
    /// Weight of the acceleration command's change (`MpcSettings::w_acc_rate`) an MPC on
    /// this model uses at least: set by the control-relevant selection's second-link design
    /// (`SelectionSettings::spillover`), where the pick's command would drive a lower mode
    /// the model does not carry.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acc_rate_weight: Option<f64>,
    /// Anything else callers attach (search table, sweep settings …).
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

/// A discrete linear model over delay coordinates (see module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearModel {
    /// Identification method: `dmdc`, `havokc` or `whitebox`.
    pub method: String,
    /// Sample time [s].
    pub dt: f64,
    /// Number of stacked frames q (1 = no delays).
    pub delays: usize,
    /// SVD truncation rank p (0 when not applicable).
    pub rank: usize,
    /// Names of the physical states x (e.g. `vn`, `swing_n`).
    pub states: Vec<String>,
    /// Names of the inputs u (e.g. `acc_sp_n`).
    pub inputs: Vec<String>,
    /// Offset handling used in training.
    pub offset: Offset,
    /// Input mean subtracted before `B` [input units]; zeros unless `offset = mean`.
    pub input_mean: Vec<f64>,
    /// State matrix, (n·q) × (n·q).
    pub a: DMatrix<f64>,
    /// Input matrix, (n·q) × m.
    pub b: DMatrix<f64>,
    /// Constant term, n·q.
    pub c: DVector<f64>,
    /// Fingerprint of the training data (empty when unknown).
    pub fingerprint: String,
    /// Fit diagnostics.
    pub diagnostics: Diagnostics,
}

/// On-disk form (`swingrt-model/1` JSON; README, "Identification").
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    format: String,
    method: String,
    dt: f64,
    delays: usize,
    rank: usize,
    states: Vec<String>,
    inputs: Vec<String>,
    offset: Offset,
    input_mean: Vec<f64>,
    #[serde(rename = "A")]
    a: Vec<Vec<f64>>,
    #[serde(rename = "B")]
    b: Vec<Vec<f64>>,
    c: Vec<f64>,
    #[serde(default)]
    fingerprint: String,
    #[serde(default)]
    diagnostics: Diagnostics,
}

fn rows_of(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| m.row(i).iter().copied().collect())
        .collect()
}

fn matrix_from(
    name: &str,
    rows: &[Vec<f64>],
    nr: usize,
    nc: usize,
) -> Result<DMatrix<f64>, SysidError> {
    if rows.len() != nr {
        return Err(model(format!(
            "{name} has {} rows, expected {nr}",
            rows.len()
        )));
    }
    for (i, r) in rows.iter().enumerate() {
        if r.len() != nc {
            return Err(model(format!(
                "{name} row {i} has {} entries, expected {nc}",
                r.len()
            )));
        }
    }
    Ok(DMatrix::from_fn(nr, nc, |i, j| rows[i][j]))
}

impl LinearModel {
    /// Number of physical states n.
    pub fn n(&self) -> usize {
        self.states.len()
    }

    /// Number of inputs m.
    pub fn m(&self) -> usize {
        self.inputs.len()
    }

    /// Dimension of the stacked state n·q.
    pub fn order(&self) -> usize {
        self.n().saturating_mul(self.delays)
    }

    /// This model with a linear vehicle drag of `k` [1/s] on each horizontal velocity
    /// (`vn`, `ve`): v⁺ −= k·dt·v in the newest frame. Identified and white-box models of a
    /// hovering vehicle have none; the real one has about 0.12 /s at cruise speeds. The
    /// fingerprint is cleared (no data were fitted to this model).
    pub fn with_velocity_drag(&self, k: f64) -> Result<Self, SysidError> {
        if !(k.is_finite() && k >= 0.0) {
            return Err(super::error::config(format!(
                "vehicle drag must be a finite number >= 0 1/s, not {k}"
            )));
        }
        let mut out = self.clone();
        for (i, name) in self.states.iter().enumerate() {
            if name == "vn" || name == "ve" {
                out.a[(i, i)] -= k * self.dt;
            }
        }
        out.fingerprint.clear();
        Ok(out)
    }

    /// Check dimensions, names, finiteness and the sample time; the error names the problem.
    pub fn validate(&self) -> Result<(), SysidError> {
        let (n, m, q) = (self.n(), self.m(), self.delays);
        if !["dmdc", "havokc", "whitebox"].contains(&self.method.as_str()) {
            return Err(model(format!(
                "method must be dmdc, havokc or whitebox, not {:?}",
                self.method
            )));
        }
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(model(format!(
                "dt must be a positive number of seconds, not {}",
                self.dt
            )));
        }
        if n == 0 {
            return Err(model("states is empty"));
        }
        if m == 0 {
            return Err(model("inputs is empty"));
        }
        if q == 0 {
            return Err(model("delays must be at least 1"));
        }
        let nz = model_order(n, q)?;
        if self.a.shape() != (nz, nz) {
            return Err(model(format!(
                "A is {}×{}, expected {nz}×{nz} (states × delays)",
                self.a.nrows(),
                self.a.ncols()
            )));
        }
        if self.b.shape() != (nz, m) {
            return Err(model(format!(
                "B is {}×{}, expected {nz}×{m}",
                self.b.nrows(),
                self.b.ncols()
            )));
        }
        if self.c.len() != nz {
            return Err(model(format!(
                "c has {} entries, expected {nz}",
                self.c.len()
            )));
        }
        if self.input_mean.len() != m {
            return Err(model(format!(
                "input_mean has {} entries, expected {m}",
                self.input_mean.len()
            )));
        }
        for (name, vals) in [
            ("A", self.a.as_slice()),
            ("B", self.b.as_slice()),
            ("c", self.c.as_slice()),
            ("input_mean", self.input_mean.as_slice()),
        ] {
            if vals.iter().any(|v| !v.is_finite()) {
                return Err(model(format!("{name} contains a non-finite value")));
            }
        }
        for (name, r) in [
            ("measurement_noise", self.diagnostics.measurement_noise),
            (
                "swing_measurement_noise",
                self.diagnostics.swing_measurement_noise,
            ),
            ("disturbance_noise", self.diagnostics.disturbance_noise),
            ("gust_noise", self.diagnostics.gust_noise),
            ("acc_rate_weight", self.diagnostics.acc_rate_weight),
        ] {
            if let Some(r) = r {
                if !(r.is_finite() && r > 0.0) {
                    return Err(model(format!(
                        "diagnostics.{name} must be a positive number, not {r}"
                    )));
                }
            }
        }
        Ok(())
    }

    /// Serialize to the `swingrt-model/1` JSON text.
    pub fn to_json(&self) -> Result<String, SysidError> {
        self.validate()?;
        let mut diagnostics = self.diagnostics.clone();
        // JSON has no inf/NaN: drop scores that are not finite.
        for v in [
            &mut diagnostics.fit_nmae,
            &mut diagnostics.test_nmae,
            &mut diagnostics.spectral_radius,
        ] {
            if v.is_some_and(|x| !x.is_finite()) {
                *v = None;
            }
        }
        let file = ModelFile {
            format: MODEL_FORMAT.to_string(),
            method: self.method.clone(),
            dt: self.dt,
            delays: self.delays,
            rank: self.rank,
            states: self.states.clone(),
            inputs: self.inputs.clone(),
            offset: self.offset,
            input_mean: self.input_mean.clone(),
            a: rows_of(&self.a),
            b: rows_of(&self.b),
            c: self.c.iter().copied().collect(),
            fingerprint: self.fingerprint.clone(),
            diagnostics,
        };
        serde_json::to_string_pretty(&file).map_err(|e| model(format!("cannot serialize: {e}")))
    }

    /// Parse and validate a `swingrt-model/1` JSON text.
    pub fn from_json(text: &str) -> Result<Self, SysidError> {
        let file: ModelFile =
            serde_json::from_str(text).map_err(|e| model(format!("invalid model JSON: {e}")))?;
        if file.format != MODEL_FORMAT {
            return Err(model(format!(
                "format is {:?}, expected {MODEL_FORMAT:?}",
                file.format
            )));
        }
        let (n, m, q) = (file.states.len(), file.inputs.len(), file.delays);
        let nz = model_order(n, q)?;
        let a = matrix_from("A", &file.a, nz, nz)?;
        let b = matrix_from("B", &file.b, nz, m)?;
        let out = LinearModel {
            method: file.method,
            dt: file.dt,
            delays: q,
            rank: file.rank,
            states: file.states,
            inputs: file.inputs,
            offset: file.offset,
            input_mean: file.input_mean,
            a,
            b,
            c: DVector::from_vec(file.c),
            fingerprint: file.fingerprint,
            diagnostics: file.diagnostics,
        };
        out.validate()?;
        Ok(out)
    }

    /// Whether rows n.. of `A` are the exact delay shift (and those rows of `B`, `c` zero).
    pub fn has_shift_structure(&self) -> bool {
        let (n, nz) = (self.n(), self.order());
        for i in n..nz {
            for j in 0..nz {
                let want = if j + n == i { 1.0 } else { 0.0 };
                if self.a[(i, j)] != want {
                    return false;
                }
            }
            if self.b.row(i).iter().any(|v| *v != 0.0) || self.c[i] != 0.0 {
                return false;
            }
        }
        true
    }

    /// Spectral radius of `A` (largest eigenvalue modulus).
    pub fn spectral_radius(&self) -> Result<f64, SysidError> {
        spectral_radius(&self.a)
    }

    /// Roll the model forward from `history` (the last q state rows, oldest first,
    /// time-major n·q values) under `inputs` (H rows of m, time-major); returns the H
    /// predicted state rows x_{k+1..k+H} (time-major).
    pub fn predict(&self, history: &[f64], inputs: &[f64]) -> Result<Vec<f64>, SysidError> {
        let (n, m, q) = (self.n(), self.m(), self.delays);
        if Some(history.len()) != n.checked_mul(q) {
            return Err(super::error::data(format!(
                "history has {} values, expected the last {q} rows of {n} states",
                history.len()
            )));
        }
        if inputs.len() % m != 0 {
            return Err(super::error::data(format!(
                "inputs have {} values, not a multiple of {m} inputs",
                inputs.len()
            )));
        }
        if history.iter().chain(inputs).any(|v| !v.is_finite()) {
            return Err(super::error::data(
                "history or inputs contain a non-finite value",
            ));
        }
        let horizon = inputs.len() / m;
        let nz = n * q;
        // z newest first from the oldest-first history rows.
        let mut z = DVector::<f64>::from_fn(nz, |i, _| {
            let (lag, s) = (i / n, i % n);
            history[(q - 1 - lag) * n + s]
        });
        let mut du = DVector::<f64>::zeros(m);
        let mut out = Vec::with_capacity(horizon * n);
        for k in 0..horizon {
            for j in 0..m {
                du[j] = inputs[k * m + j] - self.input_mean[j];
            }
            z = &self.a * &z + &self.b * &du + &self.c;
            out.extend(z.iter().take(n));
        }
        Ok(out)
    }
}

/// Spectral radius of a square matrix ([`crate::linalg::spectral_radius`]).
pub fn spectral_radius(a: &DMatrix<f64>) -> Result<f64, SysidError> {
    crate::linalg::spectral_radius(a)
        .ok_or_else(|| model("eigenvalues did not converge (or the matrix is not finite)"))
}
