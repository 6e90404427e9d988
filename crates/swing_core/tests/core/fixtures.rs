//! Plants shared by the test modules.

use swing_core::plant::PendulumModel;

/// The Honeybee (0.952 kg) carrying `m_p` [kg] on `l` [m], with a little joint friction so
/// the swing is stable but lightly damped, as the thesis's rig was.
pub fn pendulum(m_p: f64, l: f64) -> PendulumModel {
    PendulumModel {
        m_q: 0.952,
        m_p,
        l,
        c: 0.002,
    }
}
