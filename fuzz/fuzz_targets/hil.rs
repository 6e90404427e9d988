//! libFuzzer entry of the `hil` target (nightly + cargo-fuzz; see fuzz/README.md).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    swing_fuzz::targets::hil(data);
});
