//! libFuzzer entry of the `ua_request` target (`cargo fuzz run ua_request`, nightly); the target
//! itself is `ctopc_fuzz::targets::ua_request`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::ua_request(data));
