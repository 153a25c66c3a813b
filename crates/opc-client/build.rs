//! `cfg(ua)`: opcdiag's OPC UA client (`src/bin/opcdiag/ua/`) is built where its
//! dependency is: with the feature `ua` (on by default) and not for 32-bit Windows, whose
//! opcdiag stays the small OPC DA client (Cargo.toml).

fn main() {
    println!("cargo::rustc-check-cfg=cfg(ua)");
    println!("cargo::rerun-if-changed=build.rs");
    let var = |k: &str| std::env::var(k).unwrap_or_default();
    let feature = std::env::var_os("CARGO_FEATURE_UA").is_some();
    let windows_x86 =
        var("CARGO_CFG_TARGET_OS") == "windows" && var("CARGO_CFG_TARGET_ARCH") == "x86";
    if feature && !windows_x86 {
        println!("cargo::rustc-cfg=ua");
    }
}
