//! ServerCTOPC.exe reserves 256 MiB of stack per thread (address space only, committed
//! only as used; the server is 64-bit only): Wine's and Windows' RPC threads, which
//! unmarshal every COM call's arguments, take the exe's default stack reserve, and the
//! unmarshalling of a VARIANT recurses once per nested array level (oleaut32's
//! VARIANT_UserUnmarshal / VARIANT_UserFree) before the server's own, bounded decoding
//! (`ctopc_core::limits`) sees it. With the linker's default of 2 MiB a VARIANT of 10,000
//! levels overflows an RPC thread and the call never returns. docs/limits.md gives the
//! depth each reserve carries (about 800,000 levels with this one) and what happens
//! beyond it. Threads the server starts itself (std::thread) set their own stack size and
//! do not take this reserve.
fn main() {
    let target = std::env::var("TARGET").unwrap_or_default();
    if target.ends_with("-windows-gnu") {
        println!("cargo:rustc-link-arg-bins=-Wl,--stack,268435456");
    }
}
