//! The identified model: a discrete linear state-space over delay coordinates.
//!
//! For every method (DESIGN §7) the model acts on the stacked state
//! z_k = [x_k; x_{k-1}; …; x_{k-q+1}] (newest first) as
//! z_{k+1} = A z_k + B (u_k − input_mean) + c.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// How the constant offset of the input channel is handled (thesis 4.6.6).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Offset {
    /// No offset handling.
    None,
    /// Subtract the training input mean (the thesis's choice).
    Mean,
    /// Learn a constant column `c` (default; predicts better on held-out data).
    #[default]
    Affine,
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
}
