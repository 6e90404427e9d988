//! Fuzz targets of `swing_core`: every parser and numeric entry point that takes
//! user input. Each target takes raw bytes and must return normally for every input: a
//! typed error or a valid result is fine, a panic, an abort, an unbounded allocation or a
//! hang is a finding. The same functions are driven by libFuzzer (`fuzz_targets/`, nightly)
//! and by the stable seeded runner (`src/bin/run.rs`, what CI runs).

#![warn(missing_docs)]

pub mod targets;

/// A fuzz target: raw bytes in, returns normally unless it found a bug (then it panics).
pub type Target = fn(&[u8]);

/// Every target by name, in the order the runner drives them.
pub const TARGETS: &[(&str, Target)] = &[
    ("scenario_toml", targets::scenario_toml),
    ("scenario_json", targets::scenario_json),
    ("scenario_overrides", targets::scenario_overrides),
    ("model_json", targets::model_json),
    ("model_structured", targets::model_structured),
    ("settings", targets::settings),
    ("identify", targets::identify),
    ("mpc", targets::mpc),
    ("simulator", targets::simulator),
    ("hil", targets::hil),
];

/// Inputs longer than this are cut: the properties are about malformed content, not size
/// (and a parser's cost is linear in its text).
pub const MAX_INPUT: usize = 16 * 1024;
