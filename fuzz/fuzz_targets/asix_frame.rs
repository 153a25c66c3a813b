//! libFuzzer entry of the `asix_frame` target (`cargo fuzz run asix_frame`, nightly); the target
//! itself is `ctopc_fuzz::targets::asix_frame`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::asix_frame(data));
