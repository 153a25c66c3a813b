//! libFuzzer entry of the `format` target (`cargo fuzz run format`, nightly); the target
//! itself is `ctopc_fuzz::targets::format`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::format(data));
