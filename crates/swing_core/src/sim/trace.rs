//! A flight trace: named columns of equal length, logged at a fixed rate (names, units and docs: the `schema!` list below).

/// Declare a row struct of named `f64` fields and the matching name list together, so the
/// two cannot drift apart: `schema!(Row, NAMES, [field: "doc", …])`.
macro_rules! schema {
    ($(#[$meta:meta])* $row:ident, $(#[$nmeta:meta])* $names:ident, [$($field:ident : $doc:literal),* $(,)?]) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, Default, PartialEq)]
        pub struct $row {
            $(#[doc = $doc] pub $field: f64,)*
        }

        $(#[$nmeta])*
        pub const $names: &[&str] = &[$(stringify!($field)),*];

        impl $row {
            /// The values in the order of the name list.
            pub fn values(&self) -> [f64; $names.len()] {
                [$(self.$field),*]
            }

            /// The value called `name`, if the row has it.
            pub fn get(&self, name: &str) -> Option<f64> {
                match name {
                    $(stringify!($field) => Some(self.$field),)*
                    _ => None,
                }
            }
        }
    };
}

schema!(
    /// One logged sample of every trace column (the flight columns plus simulator extras), by name.
    TraceRow,
    /// Column names every trace has, in order: the fields of [`TraceRow`].
    TRACE_COLUMNS,
    [
        t: "Time [s].",
        pn: "Position North [m].",
        pe: "Position East [m].",
        pd: "Position Down [m].",
        vn: "Velocity North [m/s].",
        ve: "Velocity East [m/s].",
        vd: "Velocity Down [m/s].",
        roll: "Roll angle [rad].",
        pitch: "Pitch angle [rad].",
        yaw: "Yaw angle [rad].",
        swing_n: "Measured swing angle in the North–Down plane [rad].",
        swing_e: "Measured swing angle in the East–Down plane [rad].",
        swing_rate_n: "Swing rate North [rad/s].",
        swing_rate_e: "Swing rate East [rad/s].",
        acc_sp_n: "Acceleration setpoint North [m/s²].",
        acc_sp_e: "Acceleration setpoint East [m/s²].",
        acc_sp_d: "Acceleration setpoint Down [m/s²].",
        vel_sp_n: "Velocity setpoint North [m/s] (the swing controller's reference while it flies).",
        vel_sp_e: "Velocity setpoint East [m/s].",
        vel_sp_d: "Velocity setpoint Down [m/s].",
        thrust: "Total rotor thrust [N].",
        wind_n: "Wind North [m/s].",
        wind_e: "Wind East [m/s].",
        wind_d: "Wind Down [m/s].",
        swing_true_n: "True (noise-free) swing angle North [rad].",
        swing_true_e: "True (noise-free) swing angle East [rad].",
        payload_pn: "Payload position North [m].",
        payload_pe: "Payload position East [m].",
        payload_pd: "Payload position Down [m].",
        ctrl_active: "1 while the swing controller flies the controlled axes, else 0.",
        fallback: "1 once the swing controller has been handed back to PX4, else 0.",
        imu_ax: "Accelerometer x: body FRD specific force as PX4's filtered `vehicle_acceleration` [m/s²].",
        imu_ay: "Accelerometer y [m/s²].",
        imu_az: "Accelerometer z [m/s²] (about −g at hover).",
        imu_gx: "Gyro x: body FRD rate as PX4's filtered `vehicle_angular_velocity` [rad/s].",
        imu_gy: "Gyro y [rad/s].",
        imu_gz: "Gyro z [rad/s].",
        adc_x: "Body cable sensor: ADC reading of the x potentiometer [counts] (NaN without one).",
        adc_y: "Body cable sensor: ADC reading of the y potentiometer [counts] (NaN without one).",
        swing_est_n: "Swing North estimated from the IMU, as the controller got it [rad] (NaN without an estimate).",
        swing_est_e: "Swing East estimated from the IMU [rad] (NaN without an estimate).",
    ]
);

schema!(
    /// State of the vehicle that [`STATE_KEYS`] adds to the trace columns.
    StateExtras,
    /// Names of the fields of [`StateExtras`].
    STATE_EXTRA_KEYS,
    [
        q0: "Attitude quaternion, scalar part.",
        q1: "Attitude quaternion, i part.",
        q2: "Attitude quaternion, j part.",
        q3: "Attitude quaternion, k part.",
        p: "Body roll rate [rad/s].",
        q: "Body pitch rate [rad/s].",
        r: "Body yaw rate [rad/s].",
    ]
);

/// Keys of a simulator state snapshot, in order: each is a [`TRACE_COLUMNS`] or a
/// [`STATE_EXTRA_KEYS`] name.
pub const STATE_KEYS: &[&str] = &[
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
    "q0",
    "q1",
    "q2",
    "q3",
    "p",
    "q",
    "r",
    "swing_n",
    "swing_e",
    "swing_rate_n",
    "swing_rate_e",
    "acc_sp_n",
    "acc_sp_e",
    "acc_sp_d",
    "swing_true_n",
    "swing_true_e",
    "thrust",
    "imu_ax",
    "imu_ay",
    "imu_az",
    "imu_gx",
    "imu_gy",
    "imu_gz",
    "adc_x",
    "adc_y",
    "swing_est_n",
    "swing_est_e",
];

/// Columns every flight log has, whatever its source (simulator, offboard node, PX4 ULog,
/// CSV): the leading part of [`TRACE_COLUMNS`] up to the velocity setpoints; the rest are
/// the simulator's own.
pub const FLIGHT_COLUMNS: &[&str] = TRACE_COLUMNS.split_at(20).0;

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flight_columns_are_the_trace_prefix_up_to_the_velocity_setpoints() {
        assert_eq!(FLIGHT_COLUMNS.first(), Some(&"t"));
        assert_eq!(FLIGHT_COLUMNS.last(), Some(&"vel_sp_d"));
        assert_eq!(&TRACE_COLUMNS[..FLIGHT_COLUMNS.len()], FLIGHT_COLUMNS);
    }

    #[test]
    fn every_state_key_is_a_trace_column_or_an_extra() {
        for key in STATE_KEYS {
            let known = TRACE_COLUMNS.contains(key) || STATE_EXTRA_KEYS.contains(key);
            assert!(known, "{key}");
        }
    }

    #[test]
    fn row_values_follow_the_names() {
        let row = TraceRow {
            pd: 3.0,
            fallback: 7.0,
            ..Default::default()
        };
        let v = row.values();
        assert_eq!(v.len(), TRACE_COLUMNS.len());
        for (name, x) in TRACE_COLUMNS.iter().zip(v) {
            assert_eq!(row.get(name), Some(x));
        }
        assert_eq!(row.get("nope"), None);
    }
}
