//! libFuzzer entry of the `csv_attributes` target (`cargo fuzz run csv_attributes`, nightly); the target
//! itself is `ctopc_fuzz::targets::csv_attributes`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::csv_attributes(data));
