//! libFuzzer entry of the `ua_node_id` target (`cargo fuzz run ua_node_id`, nightly); the target
//! itself is `ctopc_fuzz::targets::ua_node_id`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::ua_node_id(data));
