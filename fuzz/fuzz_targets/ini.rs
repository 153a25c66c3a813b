//! libFuzzer entry of the `ini` target (`cargo fuzz run ini`, nightly); the target
//! itself is `ctopc_fuzz::targets::ini`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::ini(data));
