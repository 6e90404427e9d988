//! Random delivery plans for campaigns: a takeoff and a chain of straight legs of random
//! length and heading, seeded.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::plan::{ItemKind, Mission, MissionItem};
use crate::config::{in_range, ConfigError};

/// A random plan's distribution (every draw from `seed` alone).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RandomPlan {
    /// Waypoints after the takeoff.
    pub waypoints: usize,
    /// Shortest leg [m].
    pub leg_min: f64,
    /// Longest leg [m].
    pub leg_max: f64,
    /// Leg speed [m/s].
    pub speed: f64,
    /// Hold at every waypoint [s].
    pub hold: f64,
    /// Acceptance radius of every waypoint [m].
    pub acceptance_radius: f64,
    /// Flight altitude above home [m].
    pub altitude: f64,
    /// Largest turn between two legs, either way [deg].
    pub turn_max: f64,
    /// Seed of the draw.
    pub seed: u64,
}

impl Default for RandomPlan {
    fn default() -> Self {
        Self {
            waypoints: 4,
            leg_min: 20.0,
            leg_max: 60.0,
            speed: 5.0,
            hold: 5.0,
            acceptance_radius: 1.0,
            altitude: 10.0,
            turn_max: 150.0,
            seed: 0,
        }
    }
}

impl RandomPlan {
    /// Check the distribution; errors name the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        in_range("waypoints", self.waypoints as f64, 1.0, 100.0)?;
        in_range("leg_min", self.leg_min, 0.0, 10_000.0)?;
        in_range("leg_max", self.leg_max, self.leg_min, 10_000.0)?;
        in_range("altitude", self.altitude, 1.0, 1000.0)?;
        in_range("turn_max", self.turn_max, 0.0, 180.0)?;
        Ok(())
    }

    /// Draw the plan (validated).
    pub fn generate(&self) -> Result<Mission, ConfigError> {
        self.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x504c_414e);
        let d = -self.altitude;
        let mut items = vec![MissionItem {
            kind: ItemKind::Takeoff,
            position: [0.0, 0.0, d],
            hold: 0.0,
            acceptance_radius: self.acceptance_radius,
            speed: self.speed,
            source: 0,
        }];
        let mut heading: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let (mut n, mut e) = (0.0, 0.0);
        for k in 0..self.waypoints {
            if k > 0 && self.turn_max > 0.0 {
                heading += rng
                    .random_range(-self.turn_max..=self.turn_max)
                    .to_radians();
            }
            let len = if self.leg_max > self.leg_min {
                rng.random_range(self.leg_min..self.leg_max)
            } else {
                self.leg_min
            };
            n += len * heading.cos();
            e += len * heading.sin();
            items.push(MissionItem {
                kind: ItemKind::Waypoint,
                position: [n, e, d],
                hold: self.hold,
                acceptance_radius: self.acceptance_radius,
                speed: self.speed,
                source: k + 1,
            });
        }
        let m = Mission {
            name: format!("random-{}", self.seed),
            home: None,
            items,
        };
        m.validate()?;
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legs_follow_the_distribution_and_the_seed() {
        let r = RandomPlan {
            seed: 7,
            ..RandomPlan::default()
        };
        let a = r.generate().unwrap();
        assert_eq!(a, r.generate().unwrap());
        assert_eq!(a.items.len(), 5);
        for w in a.items.windows(2) {
            let (p, q) = (w[0].position, w[1].position);
            let len = (q[0] - p[0]).hypot(q[1] - p[1]);
            assert!((20.0..=60.0).contains(&len), "{len}");
        }
        let b = RandomPlan { seed: 8, ..r }.generate().unwrap();
        assert_ne!(a.items, b.items);
        assert!(RandomPlan {
            leg_max: 1.0,
            ..RandomPlan::default()
        }
        .generate()
        .is_err());
    }
}
