//! Writes the seed corpus (`fuzz/corpus/<target>/seed-*`) from the core's own defaults, so
//! the seeds follow the formats as they change: `cargo run --release --bin seeds`.

use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use swing_core::control::px4::Px4Params;
use swing_core::control::{LqrSettings, MpcSettings};
use swing_core::design::adaptive::AdaptiveSettings;
use swing_core::design::selection::{CheckBounds, SelectionSettings};
use swing_core::plant::{PayloadParams, PendulumModel, VehicleParams, WindParams};
use swing_core::sim::{HilSettings, NoiseParams, Scenario, SetpointEntry};
use swing_core::sysid::IdentifySettings;
use swing_fuzz::targets::small_model;

fn write(target: &str, name: &str, bytes: &[u8]) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus")
        .join(target);
    std::fs::create_dir_all(&dir).expect("corpus directory");
    std::fs::write(dir.join(format!("seed-{name}")), bytes).expect("seed file");
}

fn with_sel(sel: u8, text: &str) -> Vec<u8> {
    let mut v = vec![sel];
    v.extend_from_slice(text.as_bytes());
    v
}

fn settings_seeds<T: Serialize>(k: u8, name: &str, v: &T) {
    let json = serde_json::to_string(v).expect("json");
    write(
        "settings",
        &format!("{name}-json"),
        &with_sel(k | 0x80, &json),
    );
    if let Ok(t) = toml::to_string(v) {
        write("settings", &format!("{name}-toml"), &with_sel(k, &t));
    }
}

fn main() {
    let step = Scenario::default_step();
    let training = Scenario::default_training();
    write(
        "scenario_toml",
        "step",
        &with_sel(0, &step.to_toml().expect("step serialises")),
    );
    write(
        "scenario_toml",
        "training",
        &with_sel(0, &training.to_toml().expect("training serialises")),
    );
    write(
        "scenario_toml",
        "over-step",
        &with_sel(1, "duration = 5.0\nseed = 3\n"),
    );
    write(
        "scenario_toml",
        "over-training",
        &with_sel(
            2,
            "[random_steps]\nv_min = 0.5\nv_max = 2.0\ninterval_min = 2.0\ninterval_max = 5.0\n",
        ),
    );
    write(
        "scenario_toml",
        "over-hover",
        &with_sel(
            3,
            "[payload]\nkind = \"double\"\n\n[wind]\nmean = [1.0, 0.0, 0.0]\n",
        ),
    );
    write(
        "scenario_toml",
        "setpoints",
        &with_sel(
            1,
            "[[setpoints]]\nt = 1.0\nvn = 2.0\n\n[[setpoints]]\nt = 3.0\nve = -1.0\n",
        ),
    );
    write(
        "scenario_json",
        "step",
        serde_json::to_string(&step).expect("json").as_bytes(),
    );
    write(
        "scenario_json",
        "training",
        serde_json::to_string(&training).expect("json").as_bytes(),
    );
    let model = small_model();
    write(
        "model_json",
        "small",
        model.to_json().expect("model").as_bytes(),
    );
    settings_seeds(0, "identify", &IdentifySettings::default());
    settings_seeds(1, "mpc", &MpcSettings::default());
    settings_seeds(2, "lqr", &LqrSettings::default());
    settings_seeds(3, "selection", &SelectionSettings::default());
    settings_seeds(4, "check-bounds", &CheckBounds::default());
    settings_seeds(5, "px4", &Px4Params::default());
    settings_seeds(6, "vehicle", &VehicleParams::default());
    settings_seeds(7, "payload", &PayloadParams::default());
    settings_seeds(8, "wind", &WindParams::default());
    settings_seeds(9, "noise", &NoiseParams::default());
    settings_seeds(
        10,
        "pendulum",
        &PendulumModel {
            m_q: 1.5,
            m_p: 0.3,
            l: 1.0,
            c: 0.0,
        },
    );
    settings_seeds(11, "setpoint", &SetpointEntry::default());
    settings_seeds(13, "hil", &HilSettings::default());
    settings_seeds(14, "adaptive", &AdaptiveSettings::default());
    write(
        "settings",
        "step-check",
        &[12, 40, 40, 40, 40, 12, 0, 200, 1, 30, 2, 0, 0],
    );
    // Structured targets: fixed pseudo-random byte strings (arbitrary decodes any bytes).
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    for target in [
        "scenario_overrides",
        "model_structured",
        "identify",
        "mpc",
        "simulator",
        "hil",
    ] {
        for (i, len) in [16usize, 64, 256, 1024].into_iter().enumerate() {
            let mut buf = vec![0u8; len];
            rng.fill_bytes(&mut buf);
            write(target, &format!("random-{i}"), &buf);
        }
        write(target, "zeros", &[0u8; 256]);
    }
}
