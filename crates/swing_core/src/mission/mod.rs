//! Missions: waypoint plans ([`plan`]: QGroundControl `.plan` and TOML files, local NED
//! about a home by [`geo`]), the guidance that flies them ([`guidance`]: swingrt's
//! rest-to-rest legs from [`profile`] with an exact preview, or PX4's own mission behaviour
//! in [`px4`] on [`smoothing`]) and random plans for campaigns ([`random`]).
//!
//! The guidance gives the trajectory setpoint (position, velocity, acceleration) at every
//! position-loop tick; PX4's cascade flies it (the PX4 baseline) or a swing controller
//! tracks it, the position MPC with the preview of the coming ticks
//! ([`crate::control::tracking`]).

pub mod geo;
pub mod guidance;
pub mod plan;
pub mod profile;
pub mod px4;
pub mod random;
pub mod smoothing;

pub use geo::{GeoPoint, LocalProjection};
pub use guidance::{
    EventKind, Guidance, GuidanceMode, GuidanceSettings, MissionEvent, PreviewBuffer,
    SmoothGuidance, TrajectorySetpoint,
};
pub use plan::{ItemKind, Mission, MissionItem};
pub use profile::SCurve;
pub use px4::{Px4Guidance, Px4MissionParams};
pub use random::RandomPlan;
