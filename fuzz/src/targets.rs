//! The target functions. Each takes raw bytes (text targets read them as UTF-8, structured
//! targets decode them with `arbitrary`), calls the core, and checks the property: a typed
//! error, or a result that is itself valid (a parsed scenario re-validates and builds a
//! simulator; an identified model validates and serialises; a controller's output is finite).

use arbitrary::{Result as AResult, Unstructured};
use nalgebra::{DMatrix, DVector};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::de::DeserializeOwned;

use swing_core::config::{from_json_str, from_toml_value, parse_toml};
use swing_core::control::mpc::condense::DisturbanceModel;
use swing_core::control::px4::Px4Params;
use swing_core::control::{
    AxisState, LqrController, LqrSettings, MpcController, MpcSettings, QpSolverKind,
    SwingController,
};
use swing_core::design::adaptive::AdaptiveSettings;
use swing_core::design::selection::{CheckBounds, SelectionSettings};
use swing_core::design::{mpc_step_check, StepCheckSettings};
use swing_core::plant::{PayloadParams, PendulumModel, VehicleParams, WindParams};
use swing_core::sim::{HilPlant, HilSettings, NoiseParams, Scenario, SetpointEntry, Simulator};
use swing_core::sysid::pipeline::{identify as run_identify, payload_mass_from_thrust, ThrustLog};
use swing_core::sysid::{
    Diagnostics, IdentifyMethod, IdentifySettings, LinearModel, Offset, Trajectory,
};

use crate::MAX_INPUT;

fn text(data: &[u8]) -> String {
    String::from_utf8_lossy(&data[..data.len().min(MAX_INPUT)]).into_owned()
}

/// A float that is usually ordinary and often one of the values parsers and solvers trip on.
fn float(u: &mut Unstructured<'_>) -> AResult<f64> {
    Ok(match u.int_in_range(0u8..=31)? {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => f64::NEG_INFINITY,
        3 => 0.0,
        4 => -0.0,
        5 => 1e30,
        6 => -1e30,
        7 => f64::MIN_POSITIVE,
        8 => f64::MAX,
        9 => f64::from_bits(u.arbitrary()?),
        10 => 1e-300,
        _ => f64::from(u.arbitrary::<i16>()?) / 1000.0,
    })
}

/// A float that is usually a plausible positive setting (weights, noise, times).
fn positive(u: &mut Unstructured<'_>, typical: f64) -> AResult<f64> {
    if u.ratio(7u8, 8u8)? {
        Ok(typical * (0.05 + f64::from(u.int_in_range(0u16..=2000)?) / 100.0))
    } else {
        float(u)
    }
}

fn opt<T>(
    u: &mut Unstructured<'_>,
    f: impl FnOnce(&mut Unstructured<'_>) -> AResult<T>,
) -> AResult<Option<T>> {
    Ok(if u.arbitrary()? { Some(f(u)?) } else { None })
}

/// A valid scenario must round-trip through its TOML and build a simulator (which checks
/// physical sense beyond the field checks) without panicking or allocating without bound.
fn check_scenario(sc: Scenario) {
    sc.validate().expect("a parsed scenario validates again");
    let text = sc.to_toml().expect("a valid scenario serialises as TOML");
    let again = Scenario::from_toml(&text);
    assert!(
        again.is_ok(),
        "a valid scenario's TOML does not parse back: {:?}",
        again.err()
    );
    let _ = Simulator::new(sc);
}

/// Scenario TOML text, alone and over each built-in scenario (first byte picks the base).
pub fn scenario_toml(data: &[u8]) {
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    let text = text(rest);
    let res = match sel % 5 {
        0 => Scenario::from_toml(&text),
        1 => Scenario::from_toml_over(&text, "step"),
        2 => Scenario::from_toml_over(&text, "training"),
        3 => Scenario::from_toml_over(&text, "hover"),
        _ => Scenario::from_toml_over(&text, "no-such-base"),
    };
    if let Ok(sc) = res {
        check_scenario(sc);
    }
}

/// Scenario JSON text (the form model files and pickles carry).
pub fn scenario_json(data: &[u8]) {
    if let Ok(sc) = Scenario::from_json(&text(data)) {
        check_scenario(sc);
    }
}

/// Every leaf of a TOML table by dotted path (arrays are leaves).
fn leaves(prefix: &mut Vec<String>, v: &toml::Value, out: &mut Vec<(Vec<String>, toml::Value)>) {
    match v {
        toml::Value::Table(t) => {
            for (k, v) in t {
                prefix.push(k.clone());
                leaves(prefix, v, out);
                prefix.pop();
            }
        }
        other => out.push((prefix.clone(), other.clone())),
    }
}

fn insert(table: &mut toml::Table, path: &[String], v: toml::Value) {
    let (last, parents) = path.split_last().expect("non-empty path");
    let mut t = table;
    for p in parents {
        let entry = t
            .entry(p.clone())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if !entry.is_table() {
            *entry = toml::Value::Table(toml::Table::new());
        }
        t = entry.as_table_mut().expect("a table");
    }
    t.insert(last.clone(), v);
}

const WORDS: &[&str] = &[
    "single", "double", "none", "both", "north", "east", "", "x", "NaN", "1e999", "state",
];

/// A replacement for a leaf: usually of the leaf's type, sometimes of another.
fn mutate_value(u: &mut Unstructured<'_>, old: &toml::Value) -> AResult<toml::Value> {
    use toml::Value as V;
    let confuse = u.ratio(1u8, 8u8)?;
    Ok(match (old, confuse) {
        (V::Float(_), false) => V::Float(float(u)?),
        (V::Integer(_), false) => V::Integer(match u.int_in_range(0u8..=5)? {
            0 => 0,
            1 => -1,
            2 => i64::MAX,
            3 => i64::MIN,
            _ => i64::from(u.arbitrary::<i16>()?),
        }),
        (V::Boolean(b), false) => V::Boolean(!b),
        (V::String(_), false) => V::String((*u.choose(WORDS)?).to_string()),
        (V::Array(a), false) => {
            let len = if u.ratio(3u8, 4u8)? {
                a.len()
            } else {
                u.int_in_range(0..=5)?
            };
            let mut out = Vec::with_capacity(len);
            for i in 0..len {
                let like = a.get(i).cloned().unwrap_or(V::Float(0.0));
                out.push(mutate_value(u, &like)?);
            }
            V::Array(out)
        }
        _ => match u.int_in_range(0u8..=4)? {
            0 => V::String((*u.choose(WORDS)?).to_string()),
            1 => V::Float(float(u)?),
            2 => V::Boolean(u.arbitrary()?),
            3 => V::Array(vec![]),
            _ => V::Table(toml::Table::new()),
        },
    })
}

/// Overrides that name real scenario fields with mutated values, plus setpoint entries.
fn scenario_overrides_from(u: &mut Unstructured<'_>, base: &Scenario) -> AResult<toml::Table> {
    let mut all = Vec::new();
    if let Ok(v) = toml::Value::try_from(base) {
        leaves(&mut Vec::new(), &v, &mut all);
    }
    // Optional sections a default scenario leaves out.
    for (path, v) in [
        ("random_steps.start", toml::Value::Float(0.0)),
        ("random_steps.v_min", toml::Value::Float(0.5)),
        ("random_steps.v_max", toml::Value::Float(2.0)),
        ("random_steps.interval_min", toml::Value::Float(2.0)),
        ("random_steps.interval_max", toml::Value::Float(5.0)),
        ("random_steps.axes", toml::Value::String("both".into())),
        ("controller.hover_thrust", toml::Value::Float(0.5)),
    ] {
        all.push((path.split('.').map(String::from).collect(), v));
    }
    let mut over = toml::Table::new();
    let count = u.int_in_range(0..=6)?;
    for _ in 0..count {
        if all.is_empty() {
            break;
        }
        let (path, old) = u.choose(&all)?.clone();
        let v = mutate_value(u, &old)?;
        insert(&mut over, &path, v);
    }
    if u.ratio(1u8, 3u8)? {
        let n = u.int_in_range(0..=4)?;
        let mut entries = Vec::new();
        for _ in 0..n {
            let mut t = toml::Table::new();
            t.insert("t".into(), toml::Value::Float(positive(u, 1.0)?));
            if u.arbitrary()? {
                t.insert("vn".into(), toml::Value::Float(float(u)?));
            }
            if u.arbitrary()? {
                t.insert("ve".into(), toml::Value::Float(float(u)?));
            }
            entries.push(toml::Value::Table(t));
        }
        over.insert("setpoints".into(), toml::Value::Array(entries));
    }
    if u.ratio(1u8, 16u8)? {
        over.insert("no_such_key".into(), toml::Value::Integer(1));
    }
    Ok(over)
}

fn base_scenario(u: &mut Unstructured<'_>) -> AResult<Scenario> {
    Ok(match u.int_in_range(0u8..=2)? {
        0 => Scenario::default_step(),
        1 => Scenario::default_training(),
        _ => Scenario::builtin("hover").expect("built-in"),
    })
}

/// `Scenario::with_overrides` with structured overrides of real fields (type confusion,
/// non-finite and extreme values, unknown keys).
pub fn scenario_overrides(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let Ok(base) = base_scenario(&mut u) else {
        return;
    };
    let Ok(over) = scenario_overrides_from(&mut u, &base) else {
        return;
    };
    if let Ok(sc) = base.with_overrides(over) {
        check_scenario(sc);
    }
}

/// A valid model must validate, serialise, parse back equal and predict.
fn check_model(m: &LinearModel) {
    m.validate().expect("a parsed model validates again");
    let text = m.to_json().expect("a valid model serialises");
    let back = LinearModel::from_json(&text).expect("a serialised model parses back");
    assert_eq!(back.a, m.a, "A changed in a JSON round trip");
    let _ = m.spectral_radius();
    let hist = vec![0.0; m.n() * m.delays];
    let inputs = vec![0.1; m.m() * 3];
    let _ = m.predict(&hist, &inputs);
}

/// Model JSON text (`swingrt-model/1`).
pub fn model_json(data: &[u8]) {
    if let Ok(m) = LinearModel::from_json(&text(data)) {
        check_model(&m);
    }
}

fn json_float(v: f64) -> String {
    if v.is_nan() {
        "NaN".into()
    } else if v.is_infinite() {
        if v > 0.0 { "1e999" } else { "-1e999" }.into()
    } else {
        format!("{v:?}")
    }
}

fn json_row(u: &mut Unstructured<'_>, len: usize, out: &mut String) -> AResult<()> {
    out.push('[');
    for j in 0..len {
        if j > 0 {
            out.push(',');
        }
        out.push_str(&json_float(float(u)?));
    }
    out.push(']');
    Ok(())
}

/// Declared dimensions that may be huge (n·q overflows usize, or would need terabytes).
fn declared_delays(u: &mut Unstructured<'_>) -> AResult<u64> {
    Ok(match u.int_in_range(0u8..=9)? {
        0 => 0,
        1 => 1 << 20,
        2 => 1 << 32,
        3 => u64::MAX / 2,
        4 => u64::MAX,
        _ => u64::from(u.int_in_range(1u8..=4)?),
    })
}

fn model_text(u: &mut Unstructured<'_>) -> AResult<String> {
    let n = u.int_in_range(0usize..=4)?;
    let m = u.int_in_range(0usize..=2)?;
    let q = declared_delays(u)?;
    let nz = (n as u64).saturating_mul(q);
    let small = |d: u64| if d <= 12 { d as usize } else { 12 };
    let ragged = u.ratio(1u8, 6u8)?;
    let rows_a = if u.ratio(7u8, 8u8)? {
        small(nz)
    } else {
        u.int_in_range(0..=12)?
    };
    let mut s = String::from("{");
    let fields: [&str; 12] = [
        "format",
        "method",
        "dt",
        "delays",
        "rank",
        "states",
        "inputs",
        "offset",
        "input_mean",
        "A",
        "B",
        "c",
    ];
    let mut first = true;
    for f in fields {
        if u.ratio(1u8, 40u8)? {
            continue; // a missing field
        }
        if !first {
            s.push(',');
        }
        first = false;
        s.push_str(&format!("\"{f}\":"));
        if u.ratio(1u8, 40u8)? {
            s.push_str(u.choose(&["null", "\"x\"", "[]", "{}", "-1", "1.5", "true"])?);
            continue;
        }
        match f {
            "format" => s.push_str(if u.ratio(15u8, 16u8)? {
                "\"swingrt-model/1\""
            } else {
                "\"swingrt-model/2\""
            }),
            "method" => s.push_str(&format!(
                "\"{}\"",
                u.choose(&["dmdc", "havokc", "whitebox", "ols"])?
            )),
            "dt" => s.push_str(&json_float(if u.ratio(3u8, 4u8)? {
                0.03
            } else {
                float(u)?
            })),
            "delays" => s.push_str(&q.to_string()),
            "rank" => s.push_str(&u.int_in_range(0u32..=20)?.to_string()),
            "states" | "inputs" => {
                let k = if f == "states" { n } else { m };
                let names: Vec<String> = (0..k).map(|i| format!("\"s{i}\"")).collect();
                s.push_str(&format!("[{}]", names.join(",")));
            }
            "offset" => s.push_str(&format!(
                "\"{}\"",
                u.choose(&["affine", "mean", "none", "zero"])?
            )),
            "input_mean" => json_row(u, m, &mut s)?,
            "c" => json_row(u, small(nz), &mut s)?,
            "A" | "B" => {
                let rows = if f == "A" { rows_a } else { small(nz) };
                let cols = if f == "A" { small(nz) } else { m };
                s.push('[');
                for i in 0..rows {
                    if i > 0 {
                        s.push(',');
                    }
                    let len = if ragged {
                        u.int_in_range(0..=12)?
                    } else {
                        cols
                    };
                    json_row(u, len, &mut s)?;
                }
                s.push(']');
            }
            _ => unreachable!(),
        }
    }
    if u.ratio(1u8, 16u8)? {
        s.push_str(",\"surprise\":1");
    }
    s.push('}');
    Ok(s)
}

/// Model JSON built from structure: declared dimensions against the arrays given (huge
/// delay counts, ragged and non-square A), NaN/Inf entries, missing and mistyped fields.
pub fn model_structured(data: &[u8]) {
    let mut u = Unstructured::new(data);
    if let Ok(text) = model_text(&mut u) {
        if let Ok(m) = LinearModel::from_json(&text) {
            check_model(&m);
        }
    }
}

fn parse_as<T: DeserializeOwned>(text: &str, json: bool) -> Option<T> {
    if json {
        from_json_str(text).ok()
    } else {
        parse_toml(text)
            .ok()
            .and_then(|t| from_toml_value(toml::Value::Table(t)).ok())
    }
}

fn pendulum() -> PendulumModel {
    PendulumModel {
        m_q: 1.5,
        m_p: 0.3,
        l: 1.0,
        c: 0.0,
    }
}

/// Every settings struct from JSON or TOML text (first byte picks the struct and the
/// format), validated, and used where using it is cheap.
pub fn settings(data: &[u8]) {
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    let json = sel & 0x80 != 0;
    let text = text(rest);
    match (sel & 0x7f) % 15 {
        0 => {
            if let Some(s) = parse_as::<IdentifySettings>(&text, json) {
                if s.validate().is_ok() {
                    let _ = (s.test_samples(), s.rollout_samples(), s.fit_delays());
                    let _ = (s.search_settings(), s.coarse_grid());
                }
            }
        }
        1 => {
            if let Some(s) = parse_as::<MpcSettings>(&text, json) {
                let _ = s.validate();
            }
        }
        2 => {
            if let Some(s) = parse_as::<LqrSettings>(&text, json) {
                if s.validate().is_ok() {
                    let _ = LqrController::new(pendulum(), 2, s);
                }
            }
        }
        3 => {
            if let Some(s) = parse_as::<SelectionSettings>(&text, json) {
                let _ = s.validate();
            }
        }
        4 => {
            let _ = parse_as::<CheckBounds>(&text, json);
        }
        5 => {
            if let Some(s) = parse_as::<Px4Params>(&text, json) {
                let _ = s.validate();
            }
        }
        6 => {
            if let Some(s) = parse_as::<VehicleParams>(&text, json) {
                let _ = s.validate();
            }
        }
        7 => {
            if let Some(s) = parse_as::<PayloadParams>(&text, json) {
                let _ = s.validate();
            }
        }
        8 => {
            if let Some(s) = parse_as::<WindParams>(&text, json) {
                let _ = s.validate();
            }
        }
        9 => {
            if let Some(s) = parse_as::<NoiseParams>(&text, json) {
                let _ = s.validate();
            }
        }
        10 => {
            if let Some(p) = parse_as::<PendulumModel>(&text, json) {
                if p.validate().is_ok() {
                    let _ = LqrController::new(p, 1, LqrSettings::default());
                }
            }
        }
        11 => {
            // Checked inside a scenario (its validate is private); here the parse alone.
            let _ = parse_as::<SetpointEntry>(&text, json);
        }
        13 => {
            if let Some(s) = parse_as::<HilSettings>(&text, json) {
                if s.validate().is_ok() {
                    let _ = HilPlant::new(Scenario::builtin("hover").expect("built-in"), s);
                }
            }
        }
        14 => {
            if let Some(s) = parse_as::<AdaptiveSettings>(&text, json) {
                let _ = s.validate();
            }
        }
        _ => {
            // StepCheckSettings has no serde form: its five numbers from the bytes.
            let mut u = Unstructured::new(rest);
            let Ok(check) = (|| -> AResult<StepCheckSettings> {
                Ok(StepCheckSettings {
                    step: float(&mut u)?,
                    t_step: float(&mut u)?,
                    duration: float(&mut u)?,
                    input_lag: float(&mut u)?,
                    input_delay: float(&mut u)?,
                })
            })() else {
                return;
            };
            if check.validate().is_ok() {
                let model = small_model();
                let settings = MpcSettings {
                    horizon: 10,
                    control_horizon: 3,
                    ..MpcSettings::default()
                };
                let _ = mpc_step_check(&model, settings, &model, &check);
            }
        }
    }
}

/// A small, stable single-axis model (v, swing, swing rate; one delay).
pub fn small_model() -> LinearModel {
    let a = nalgebra_like(&[0.98, 0.0, 0.0, 0.0, 0.99, 0.03, 0.0, -0.3, 0.99], 3, 3);
    let b = nalgebra_like(&[0.03, -0.003, -0.1], 3, 1);
    LinearModel {
        method: "dmdc".into(),
        dt: 0.03,
        delays: 1,
        rank: 3,
        states: vec!["vn".into(), "swing_n".into(), "swing_rate_n".into()],
        inputs: vec!["acc_n".into()],
        offset: Offset::Affine,
        input_mean: vec![0.0],
        a,
        b,
        c: DVector::from_vec(vec![0.0; 3]),
        fingerprint: String::new(),
        diagnostics: Diagnostics::default(),
    }
}

fn nalgebra_like(v: &[f64], r: usize, c: usize) -> DMatrix<f64> {
    DMatrix::from_row_slice(r, c, v)
}

fn names(n: usize, prefix: &str) -> Vec<String> {
    let pool = [
        "vn",
        "swing_n",
        "swing_rate_n",
        "ve",
        "swing_e",
        "swing_rate_e",
    ];
    (0..n)
        .map(|i| {
            pool.get(i)
                .map_or_else(|| format!("{prefix}{i}"), |s| s.to_string())
        })
        .collect()
}

/// The identification pipeline (fit, search, white-box; split and scoring) on small
/// synthetic, corrupted or raw data with arbitrary settings.
pub fn identify(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let _ = identify_inner(&mut u);
}

fn identify_inner(u: &mut Unstructured<'_>) -> AResult<()> {
    let n = u.int_in_range(1usize..=4)?;
    let m = u.int_in_range(1usize..=2)?;
    let len = u.int_in_range(0usize..=400)?;
    let mode = u.int_in_range(0u8..=3)?;
    let mut rng = ChaCha8Rng::seed_from_u64(u.arbitrary()?);
    let mut x = vec![0.0; n * len];
    let mut inp = vec![0.0; m * len];
    match mode {
        0 | 1 => {
            // A stable coupled linear system under random steps.
            let mut state = vec![0.0; n];
            let mut cur = vec![0.0; m];
            for k in 0..len {
                if k % 40 == 0 {
                    for c in cur.iter_mut() {
                        *c = rng.random_range(-1.0..1.0);
                    }
                }
                let mut next = vec![0.0; n];
                for i in 0..n {
                    let prev = if i > 0 { state[i - 1] } else { 0.0 };
                    next[i] = 0.95 * state[i]
                        + 0.04 * prev
                        + 0.05 * cur[i % m]
                        + 1e-3 * rng.random_range(-1.0..1.0);
                }
                state = next;
                x[k * n..(k + 1) * n].copy_from_slice(&state);
                inp[k * m..(k + 1) * m].copy_from_slice(&cur);
            }
            if mode == 1 {
                for _ in 0..u.int_in_range(1..=3)? {
                    let v = float(u)?;
                    if !x.is_empty() {
                        let i = u.choose_index(x.len())?;
                        x[i] = v;
                    }
                }
            }
        }
        2 => {
            for v in x.iter_mut().chain(inp.iter_mut()) {
                *v = float(u).unwrap_or(0.0);
            }
        }
        _ => {} // constant zero data: rank-deficient everywhere
    }
    let dt = if u.ratio(3u8, 4u8)? { 0.03 } else { float(u)? };
    let frac = |u: &mut Unstructured<'_>| -> AResult<f64> {
        Ok(f64::from(u.int_in_range(0u8..=255)?) / 200.0 * len as f64 * 0.03)
    };
    let method = *u.choose(&[
        IdentifyMethod::Dmdc,
        IdentifyMethod::Havokc,
        IdentifyMethod::Whitebox,
    ])?;
    let search = method != IdentifyMethod::Whitebox && u.ratio(1u8, 3u8)?;
    let settings = IdentifySettings {
        method,
        offset: *u.choose(&[Offset::Affine, Offset::Mean, Offset::None])?,
        delays: if search {
            None
        } else {
            opt(u, |u| Ok(*u.choose(&[0usize, 1, 2, 3, 5, 8, 20, 1000])?))?
        },
        rank: if search {
            None
        } else {
            opt(u, |u| u.int_in_range(0usize..=30))?
        },
        search,
        dt,
        test_span: if u.ratio(7u8, 8u8)? {
            frac(u)?
        } else {
            float(u)?
        },
        rollout: if u.ratio(7u8, 8u8)? {
            frac(u)?
        } else {
            float(u)?
        },
        starts: u.int_in_range(0usize..=12)?,
        search_delays: Some(
            (0..u.int_in_range(0..=3)?)
                .map(|_| u.int_in_range(0usize..=12))
                .collect::<AResult<_>>()?,
        ),
        rank_start: u.int_in_range(0usize..=10)?,
        rank_step: u.int_in_range(0usize..=5)?,
        fine: opt(u, |u| {
            Ok([u.int_in_range(0usize..=1)?, u.int_in_range(0usize..=2)?])
        })?,
        prediction_horizon: if u.ratio(7u8, 8u8)? { 3.0 } else { float(u)? },
        growth_limit: if u.ratio(7u8, 8u8)? { 2.0 } else { float(u)? },
        payload_mass: opt(u, |u| positive(u, 0.3))?,
        cable_length: opt(u, |u| positive(u, 1.0))?,
        vehicle_mass: positive(u, 1.5)?,
        friction: if u.arbitrary()? { 0.0 } else { float(u)? },
        swing_band: [positive(u, 0.1)?, positive(u, 3.0)?],
        ..IdentifySettings::default()
    };
    let (states, inputs) = if method == IdentifyMethod::Whitebox && u.arbitrary()? {
        // The white-box wants a velocity and a swing per input.
        (names(2 * m, "s"), names(m, "u"))
    } else {
        (names(n, "s"), names(m, "u"))
    };
    let mass = opt(u, |u| positive(u, 0.3))?;
    let xs = if states.len() == n {
        x.clone()
    } else {
        vec![0.1; states.len() * len]
    };
    let Ok(traj) = Trajectory::new(&xs, states.len(), &inp, m) else {
        return Ok(());
    };
    if let Ok(out) = run_identify(&traj, &states, &inputs, &settings, mass) {
        out.model.validate().expect("an identified model is valid");
        out.model.to_json().expect("an identified model serialises");
    }
    // The payload-mass estimate on the same buffers.
    let thrust: Vec<f64> = x.iter().step_by(n).copied().collect();
    let vd: Vec<f64> = inp.iter().step_by(m).copied().take(thrust.len()).collect();
    let log = ThrustLog {
        thrust: &thrust,
        vd: &vd,
        roll: None,
        pitch: None,
        dt,
    };
    let skip = u.int_in_range(0usize..=50)?;
    let _ = payload_mass_from_thrust(&log, skip, settings.vehicle_mass, positive(u, 0.99)?);
    Ok(())
}

/// MPC construction from an arbitrary small model and settings, then a few ticks with
/// arbitrary measurements (non-finite, wrong lengths); an accepted tick's output is finite.
pub fn mpc(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let _ = mpc_inner(&mut u);
}

fn axis_state(u: &mut Unstructured<'_>) -> AResult<AxisState> {
    Ok(AxisState {
        v: float(u)?,
        swing: float(u)?,
        swing_rate: float(u)?,
    })
}

fn mpc_inner(u: &mut Unstructured<'_>) -> AResult<()> {
    let axes = u.int_in_range(1usize..=2)?;
    let per_axis = u.int_in_range(1usize..=3)?;
    let mut states = Vec::new();
    for a in 0..axes {
        let s = ["n", "e"][a];
        let all = [
            format!("v{s}"),
            format!("swing_{s}"),
            format!("swing_rate_{s}"),
        ];
        states.extend(all.into_iter().take(per_axis));
    }
    if u.ratio(1u8, 16u8)? {
        states.push("altitude".into());
    }
    let n = states.len();
    let q = u.int_in_range(1usize..=3)?;
    let nz = n * q;
    let stable = u.ratio(3u8, 4u8)?;
    let mut a = vec![0.0; nz * nz];
    for i in 0..nz {
        for j in 0..nz {
            a[i * nz + j] = if i < n {
                let base = if i == j { 0.97 } else { 0.0 };
                if stable {
                    base + f64::from(u.int_in_range(-20i8..=20)?) / 1000.0
                } else {
                    float(u)?
                }
            } else if j + n == i {
                1.0
            } else {
                0.0
            };
        }
    }
    let mut b = vec![0.0; nz * axes];
    for i in 0..n {
        for j in 0..axes {
            b[i * axes + j] = if stable {
                f64::from(u.int_in_range(-50i8..=50)?) / 1000.0
            } else {
                float(u)?
            };
        }
    }
    let c: Vec<f64> = (0..nz)
        .map(|i| if i < n && !stable { float(u) } else { Ok(0.0) })
        .collect::<AResult<_>>()?;
    let input_mean: Vec<f64> = (0..axes)
        .map(|_| if stable { Ok(0.0) } else { float(u) })
        .collect::<AResult<_>>()?;
    let model = LinearModel {
        method: "dmdc".into(),
        dt: if u.ratio(7u8, 8u8)? { 0.03 } else { float(u)? },
        delays: q,
        rank: nz,
        states,
        inputs: (0..axes)
            .map(|a| format!("acc_{}", ["n", "e"][a]))
            .collect(),
        offset: Offset::Affine,
        input_mean,
        a: DMatrix::from_row_slice(nz, nz, &a),
        b: DMatrix::from_row_slice(nz, axes, &b),
        c: DVector::from_vec(c),
        fingerprint: String::new(),
        diagnostics: Diagnostics::default(),
    };
    let horizon = u.int_in_range(1usize..=40)?;
    let settings = MpcSettings {
        horizon,
        control_horizon: u.int_in_range(0usize..=horizon + 1)?,
        w_velocity: positive(u, 1.0)?,
        w_swing_rate: positive(u, 6.0)?,
        w_swing: if u.arbitrary()? {
            0.0
        } else {
            positive(u, 1.0)?
        },
        w_acc: if u.arbitrary()? {
            0.0
        } else {
            positive(u, 0.1)?
        },
        w_acc_rate: positive(u, 2.0)?,
        acc_max: opt(u, |u| positive(u, 4.0))?,
        jerk_max: opt(u, |u| positive(u, 20.0))?,
        kf_process_noise: positive(u, 0.01)?,
        disturbance: *u.choose(&[
            DisturbanceModel::State,
            DisturbanceModel::Velocity,
            DisturbanceModel::Input,
        ])?,
        kf_disturbance_noise: positive(u, 0.02)?,
        kf_swing_disturbance_scale: positive(u, 0.1)?,
        gust_noise: if u.arbitrary()? {
            0.0
        } else {
            positive(u, 0.3)?
        },
        gust_time: positive(u, 2.0)?,
        kf_measurement_noise: positive(u, 0.01)?,
        kf_swing_measurement_noise: opt(u, |u| positive(u, 0.01))?,
        kf_start_spread: if u.arbitrary()? {
            0.0
        } else {
            positive(u, 3.0)?
        },
        solver: *u.choose(&[QpSolverKind::ActiveSet, QpSolverKind::Clarabel])?,
        measured_state: u.arbitrary()?,
    };
    let Ok(mut mpc) = MpcController::new(&model, settings) else {
        return Ok(());
    };
    if u.arbitrary()? {
        let st: Vec<AxisState> = (0..axes).map(|_| axis_state(u)).collect::<AResult<_>>()?;
        let acc: Vec<f64> = (0..axes).map(|_| float(u)).collect::<AResult<_>>()?;
        mpc.reset(&st, &acc);
    }
    for _ in 0..u.int_in_range(1..=6)? {
        let k = if u.ratio(7u8, 8u8)? {
            axes
        } else {
            u.int_in_range(0..=3)?
        };
        let st: Vec<AxisState> = (0..k)
            .map(|_| {
                if u.ratio(3u8, 4u8)? {
                    Ok(AxisState {
                        v: f64::from(u.arbitrary::<i8>()?) / 20.0,
                        swing: f64::from(u.arbitrary::<i8>()?) / 500.0,
                        swing_rate: f64::from(u.arbitrary::<i8>()?) / 100.0,
                    })
                } else {
                    axis_state(u)
                }
            })
            .collect::<AResult<_>>()?;
        let r: Vec<f64> = (0..k)
            .map(|_| {
                if u.ratio(3u8, 4u8)? {
                    Ok(2.0)
                } else {
                    float(u)
                }
            })
            .collect::<AResult<_>>()?;
        let mut out = vec![0.0; k];
        if let Ok(_info) = mpc.step(&st, &r, &mut out) {
            assert!(
                out.iter().all(|v| v.is_finite()),
                "an accepted MPC tick commanded a non-finite acceleration: {out:?}"
            );
        }
    }
    let _ = mpc.predicted_trajectory();
    Ok(())
}

/// A valid scenario (structured overrides of a built-in one) built and flown a few physics
/// steps, optionally with the LQR attached.
pub fn simulator(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let _ = simulator_inner(&mut u);
}

fn simulator_inner(u: &mut Unstructured<'_>) -> AResult<()> {
    let base = base_scenario(u)?;
    let over = scenario_overrides_from(u, &base)?;
    let Ok(sc) = base.with_overrides(over) else {
        return Ok(());
    };
    let h = sc.physics_dt;
    let Ok(mut sim) = Simulator::new(sc) else {
        return Ok(());
    };
    if u.arbitrary()? {
        let axes = u.int_in_range(1usize..=2)?;
        if let Ok(lqr) = LqrController::new(pendulum(), axes, LqrSettings::default()) {
            let ctrl: Box<dyn SwingController> = Box::new(lqr);
            let _ = sim.attach_controller(ctrl, float(u)?.abs().min(1.0), positive(u, 0.01)?);
        }
    }
    let steps = u.int_in_range(1u32..=200)?;
    let _ = sim.advance(f64::from(steps) * h);
    let trace = sim.trace();
    let _ = trace;
    Ok(())
}

/// The hardware-in-the-loop plant under arbitrary motor commands (NaN, ±∞, huge, negative)
/// from any scenario: every step is a typed error or a physical state, every sensor frame
/// is finite while the plant is.
pub fn hil(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let _ = hil_inner(&mut u);
}

fn hil_inner(u: &mut Unstructured<'_>) -> AResult<()> {
    let base = base_scenario(u)?;
    let over = scenario_overrides_from(u, &base)?;
    let Ok(sc) = base.with_overrides(over) else {
        return Ok(());
    };
    let Ok(mut plant) = HilPlant::new(sc, HilSettings::default()) else {
        return Ok(());
    };
    let steps = u.int_in_range(1u32..=100)?;
    for _ in 0..steps {
        let frame = plant.sensors();
        assert!(
            frame.accel.iter().chain(&frame.gyro).all(|x| x.is_finite()),
            "non-finite sensor frame from a finite plant: {frame:?}"
        );
        let motors = [float(u)?, float(u)?, float(u)?, float(u)?];
        if plant.step(motors).is_err() {
            break;
        }
    }
    Ok(())
}
