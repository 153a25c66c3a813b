//! libFuzzer entry of the `zez_varset` target (`cargo fuzz run zez_varset`, nightly); the target
//! itself is `ctopc_fuzz::targets::zez_varset`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::zez_varset(data));
