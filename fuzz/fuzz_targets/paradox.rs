//! libFuzzer entry of the `paradox` target (`cargo fuzz run paradox`, nightly); the target
//! itself is `ctopc_fuzz::targets::paradox`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::paradox(data));
