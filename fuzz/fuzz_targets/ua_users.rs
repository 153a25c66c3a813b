//! libFuzzer entry of the `ua_users` target (`cargo fuzz run ua_users`, nightly); the target
//! itself is `ctopc_fuzz::targets::ua_users`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::ua_users(data));
