//! What is measured of the vehicle and its payload on one horizontal axis: the quantity
//! every controller, the payload tracker and the simulator's supervisor exchange.

/// Measured state of one controlled horizontal axis (North or East).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AxisState {
    /// Velocity along the axis [m/s].
    pub v: f64,
    /// Payload swing angle in the axis–Down plane [rad].
    pub swing: f64,
    /// Swing angle rate [rad/s].
    pub swing_rate: f64,
}
