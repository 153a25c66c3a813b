//! libFuzzer entry of the `ua_variant` target (`cargo fuzz run ua_variant`, nightly); the target
//! itself is `ctopc_fuzz::targets::ua_variant`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::ua_variant(data));
