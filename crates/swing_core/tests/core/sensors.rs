//! Integration tests of the sensors: the IMU swing estimator's ticks, as the offboard node
//! and the simulator run them at 100 Hz.

use nalgebra::Rotation3;
use swing_core::sensors::{ImuSwingEstimator, ImuSwingSettings};

use crate::counting::count;

#[test]
fn the_imu_swing_estimator_does_not_allocate_per_tick() {
    // The low-passed estimate alone, then with the pendulum observer, with the drag removed
    // and through the tare (0.5 s) and after it.
    for length in [0.0, 1.0] {
        let settings = ImuSwingSettings {
            length,
            damping: 0.02,
            tare: 0.5,
            drag_linear: [0.1, 0.1],
            drag_quadratic: [0.06, 0.06],
            ..ImuSwingSettings::default()
        };
        let mut est = ImuSwingEstimator::new(settings).unwrap();
        let mut last = [f64::NAN; 2];
        // 5 s of a swinging flight: tilting, accelerating to 2 m/s, pulled by the cable.
        let allocations = count(|| {
            for k in 0..500 {
                let t = k as f64 * 0.01;
                let s = (3.0 * t).sin();
                let rot = Rotation3::from_euler_angles(0.05 * s, -0.1 * s, 0.3).into_inner();
                last = est.update([0.4 * s, -0.2 * s, -9.8], &rot, [t.min(2.0), 0.1 * s, 0.0]);
            }
        });
        assert_eq!(allocations, 0, "observer length {length}");
        assert!(est.tared(), "observer length {length}");
        assert!(last.iter().all(|x| x.is_finite()), "{last:?}");
        assert_ne!(last, [0.0, 0.0], "the estimate moved");
    }
}
