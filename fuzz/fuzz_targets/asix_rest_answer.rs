//! libFuzzer entry of the `asix_rest_answer` target (`cargo fuzz run asix_rest_answer`,
//! nightly); the target itself is `ctopc_fuzz::targets::asix_rest_answer`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::asix_rest_answer(data));
