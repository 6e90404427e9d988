//! Swing-damping and flight control: PX4 cascade, LQR and MPC.

