//! `cargo xtask setup`: everything the build and the tests need on a fresh Debian 12
//! machine. Idempotent: each step checks first and skips what is there.

use crate::{util, wine};
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// Debian packages: Wine 8 (64-bit), the mingw C toolchain (linker for the Rust
/// windows-gnu target, the shim and the proxy/stub DLL), widl, and the system IDL files
/// widl imports (only libwine-dev ships them).
pub const PACKAGES: &[&str] = &[
    "wine64",
    "gcc-mingw-w64-x86-64",
    "mingw-w64-tools",
    "libwine-dev",
];
pub const TARGET: &str = "x86_64-pc-windows-gnu";

pub fn run(_args: &[String]) -> Result<(), String> {
    apt_packages()?;
    rust_target()?;
    let shim = build_shim()?;
    prefix(&shim)?;
    println!("setup: done (prefix {})", wine::prefix().display());
    Ok(())
}

fn installed(pkg: &str) -> bool {
    util::output(Command::new("dpkg-query").args(["-W", "-f=${Status}", pkg]))
        .map(|s| s.contains("install ok installed"))
        .unwrap_or(false)
}

fn apt_packages() -> Result<(), String> {
    let missing: Vec<&str> = PACKAGES.iter().copied().filter(|p| !installed(p)).collect();
    if missing.is_empty() {
        println!("setup: apt packages present ({})", PACKAGES.join(", "));
        return Ok(());
    }
    if !util::is_root() {
        return Err(format!(
            "missing Debian packages: {m}\nrun as root, or install them first:\n  sudo apt-get update && sudo apt-get install -y --no-install-recommends {m}",
            m = missing.join(" ")
        ));
    }
    println!("setup: installing {}", missing.join(" "));
    util::run(Command::new("apt-get").args(["update", "-q"]))?;
    util::run(
        Command::new("apt-get")
            .args(["install", "-y", "-q", "--no-install-recommends"])
            .args(&missing)
            .env("DEBIAN_FRONTEND", "noninteractive"),
    )
}

fn rust_target() -> Result<(), String> {
    let list = util::output(Command::new("rustup").args(["target", "list", "--installed"]))?;
    if list.lines().any(|l| l.trim() == TARGET) {
        println!("setup: rust target {TARGET} present");
        return Ok(());
    }
    util::run(Command::new("rustup").args(["target", "add", TARGET]))
}

/// Builds target/wine/bcryptprimitives.dll (see xtask/shim/bcryptprimitives.c).
fn build_shim() -> Result<std::path::PathBuf, String> {
    let root = util::root();
    let src = root.join("xtask/shim/bcryptprimitives.c");
    let def = root.join("xtask/shim/bcryptprimitives.def");
    let out = root.join("target/wine/bcryptprimitives.dll");
    if util::up_to_date(&out, &[src.clone(), def.clone()]) {
        return Ok(out);
    }
    std::fs::create_dir_all(root.join("target/wine")).map_err(|e| e.to_string())?;
    util::run(
        Command::new("x86_64-w64-mingw32-gcc")
            .args(["-O2", "-shared", "-o"])
            .arg(&out)
            .arg(&src)
            .arg(&def)
            .arg("-lbcrypt"),
    )?;
    println!("setup: built {}", out.display());
    Ok(out)
}

fn prefix(shim: &Path) -> Result<(), String> {
    let pfx = wine::prefix();
    if !pfx.join("system.reg").exists() {
        println!("setup: creating Wine prefix {}", pfx.display());
        std::fs::create_dir_all(&pfx).map_err(|e| e.to_string())?;
        let status =
            util::run_with_timeout(wine::wine("wineboot").arg("-i"), Duration::from_secs(180))?;
        if !status.success() {
            return Err(format!("wineboot -i failed: {status}"));
        }
        wine::wait_idle(Duration::from_secs(120))?;
    } else {
        println!("setup: Wine prefix present");
    }
    let dest = wine::system32().join("bcryptprimitives.dll");
    if !util::up_to_date(&dest, &[shim.to_path_buf()]) {
        std::fs::copy(shim, &dest).map_err(|e| format!("copy shim to {}: {e}", dest.display()))?;
        println!("setup: installed bcryptprimitives shim");
    }
    Ok(())
}
