//! A flight trace: named columns of equal length, logged at a fixed rate (DESIGN §2).

/// Column names every trace has, in order (DESIGN §2 plus simulator extras).
pub const BASE_COLUMNS: [&str; 31] = [
    "t",
    "pn",
    "pe",
    "pd",
    "vn",
    "ve",
    "vd",
    "roll",
    "pitch",
    "yaw",
    "swing_n",
    "swing_e",
    "swing_rate_n",
    "swing_rate_e",
    "acc_sp_n",
    "acc_sp_e",
    "acc_sp_d",
    "vel_sp_n",
    "vel_sp_e",
    "vel_sp_d",
    "thrust",
    "wind_n",
    "wind_e",
    "wind_d",
    "swing_true_n",
    "swing_true_e",
    "payload_pn",
    "payload_pe",
    "payload_pd",
    "ctrl_active",
    "fallback",
];

/// Extra columns of a double-pendulum payload (the hidden second link).
pub const DOUBLE_COLUMNS: [&str; 2] = ["swing2_n", "swing2_e"];

/// Columnar trace; every column has one value per logged sample.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trace {
    names: Vec<String>,
    columns: Vec<Vec<f64>>,
}

impl Trace {
    /// An empty trace with the given column names; `capacity` rows are preallocated.
    pub fn new(names: &[&str], capacity: usize) -> Self {
        Self {
            names: names.iter().map(|s| s.to_string()).collect(),
            columns: names.iter().map(|_| Vec::with_capacity(capacity)).collect(),
        }
    }

    /// Append one row; `row` must have one value per column.
    pub fn push(&mut self, row: &[f64]) {
        debug_assert_eq!(row.len(), self.columns.len());
        for (c, v) in self.columns.iter_mut().zip(row) {
            c.push(*v);
        }
    }

    /// Column names in order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }

    /// True when no row has been logged.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The column called `name`, if present.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }

    /// Take the columns out as (name, values) pairs.
    pub fn into_columns(self) -> Vec<(String, Vec<f64>)> {
        self.names.into_iter().zip(self.columns).collect()
    }
}
