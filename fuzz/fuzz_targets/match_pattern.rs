//! libFuzzer entry of the `match_pattern` target (`cargo fuzz run match_pattern`, nightly); the target
//! itself is `ctopc_fuzz::targets::match_pattern`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::match_pattern(data));
