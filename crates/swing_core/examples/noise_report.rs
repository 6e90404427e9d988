//! Closed-loop noise report of an MPC: eigenvalues of the unconstrained loop with a plant
//! model and the RMS acceleration setpoint and setpoint change that white measurement noise
//! causes.
//!
//! `cargo run --release -p swing_core --example noise_report -- MODEL.json PLANT.json
//! [SETTINGS_JSON]` — the MPC is designed on MODEL (a model file), flown on PLANT (e.g. the
//! white-box model of the same flight); SETTINGS_JSON overrides MPC settings.

use swing_core::control::{MpcController, MpcSettings};
use swing_core::design::check::{noise_gain, MeasurementNoise};
use swing_core::sysid::LinearModel;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        return Err("usage: noise_report MODEL.json PLANT.json [SETTINGS_JSON]".into());
    }
    let model = LinearModel::from_json(&std::fs::read_to_string(&args[0])?)?;
    let plant = LinearModel::from_json(&std::fs::read_to_string(&args[1])?)?;
    let settings: MpcSettings = match args.get(2) {
        Some(s) => swing_core::config::from_json_str(s)?,
        None => MpcSettings::default(),
    };
    let mpc = MpcController::new(&model, settings)?;
    let noise = MeasurementNoise {
        velocity: 0.02,
        swing: 0.01,
        swing_rate: 0.0,
    };
    let g = noise_gain(&mpc, &model, &plant, noise)?;
    println!(
        "spectral radius {:.4}  rms u {:.4} m/s²  rms Δu {:.4} m/s² (noise v 0.02 m/s, swing 0.01 rad)",
        g.spectral_radius, g.rms_u, g.rms_du
    );
    for (label, nv, ns) in [
        ("velocity noise only", 0.02, 0.0),
        ("swing noise only", 0.0, 0.01),
    ] {
        let one = MeasurementNoise {
            velocity: nv,
            swing: ns,
            swing_rate: 0.0,
        };
        let g1 = noise_gain(&mpc, &model, &plant, one)?;
        println!("  {label}: rms u {:.4}  rms Δu {:.4}", g1.rms_u, g1.rms_du);
    }
    let own = noise_gain(&mpc, &model, &model, noise)?;
    println!(
        "on its own model: spectral radius {:.4}  rms u {:.4}  rms Δu {:.4}",
        own.spectral_radius, own.rms_u, own.rms_du
    );
    let show = |label: &str, ev: &[(f64, f64)]| {
        println!("{label}: eigenvalues with re < 0 or modulus > 0.9 (modulus, angle/π):");
        for (re, im) in ev
            .iter()
            .filter(|e| e.0 < 0.0 || e.0.hypot(e.1) > 0.9)
            .take(12)
        {
            if *im >= 0.0 {
                println!(
                    "  {:+.4} {:+.4}i  |λ| {:.4}  arg/π {:.3}",
                    re,
                    im,
                    re.hypot(*im),
                    im.atan2(*re) / std::f64::consts::PI
                );
            }
        }
    };
    show("on its own model", &own.eigenvalues);
    show("on the plant", &g.eigenvalues);
    Ok(())
}
