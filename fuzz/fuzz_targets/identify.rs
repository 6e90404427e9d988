//! libFuzzer entry of the `identify` target (nightly + cargo-fuzz; see fuzz/README.md).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    swing_fuzz::targets::identify(data);
});
