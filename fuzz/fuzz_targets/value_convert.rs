//! libFuzzer entry of the `value_convert` target (`cargo fuzz run value_convert`, nightly); the target
//! itself is `ctopc_fuzz::targets::value_convert`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::value_convert(data));
