//! libFuzzer entry of the `scenario_overrides` target (nightly + cargo-fuzz; see fuzz/README.md).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    swing_fuzz::targets::scenario_overrides(data);
});
