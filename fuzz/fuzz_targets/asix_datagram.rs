//! libFuzzer entry of the `asix_datagram` target (`cargo fuzz run asix_datagram`, nightly); the target
//! itself is `ctopc_fuzz::targets::asix_datagram`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| ctopc_fuzz::targets::asix_datagram(data));
