//! libFuzzer entry of the `item_id` target (`cargo fuzz run item_id`, nightly); the target
//! itself is `ctopc_fuzz::targets::item_id`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::item_id(data));
