//! `cargo xtask setup`: everything the build and the tests need on a fresh Debian 12
//! machine, for both bitnesses (the 64-bit server and clients, the 32-bit proxy/stub,
//! opcdiag and test client). Idempotent: each step checks first and skips what is there.

use crate::arch::Arch;
use crate::{util, wine};
use std::process::Command;

/// Debian packages: Wine 8 (the 64-bit loader and, from the i386 architecture, the 32-bit
/// one: a win64 prefix runs 32-bit programs only with wine32 installed), the mingw C
/// toolchains of both bitnesses (linkers for the Rust windows-gnu targets, the shims and
/// the proxy/stub DLLs), widl (both `x86_64-` and `i686-w64-mingw32-widl` come with
/// mingw-w64-tools), the system IDL files widl imports (only libwine-dev ships them), and
/// wixl + msitools for the MSI, and pxlib-dev for the Paradox tests.
/// wine32 must be installed before a prefix is made (see [`wine::ensure_prefix`] for
/// prefixes made earlier).
pub const PACKAGES: &[&str] = &[
    "wine64",
    "wine32:i386",
    "gcc-mingw-w64-x86-64",
    "gcc-mingw-w64-i686",
    "mingw-w64-tools",
    "libwine-dev",
    // The MSI (`cargo xtask dist`, xtask/src/msi.rs): wixl builds it from WiX source,
    // msiinfo (msitools) reads its tables back for the tests.
    "wixl",
    "msitools",
    // Paradox tables written by another implementation than the reader's
    // (crates/asix-model/tests/paradox.rs compiles tests/paradox/mkpx.c against it).
    "pxlib-dev",
    // The OPC UA interop test's client (Python asyncua, xtask/src/ua.rs) lives in a venv.
    "python3-venv",
];
/// The server's target (64-bit): what `cargo xtask build` builds everything for.
pub const TARGET: &str = "x86_64-pc-windows-gnu";

pub fn run(_args: &[String]) -> Result<(), String> {
    apt_packages()?;
    rust_targets()?;
    for arch in Arch::ALL {
        build_shim(arch)?;
    }
    wine::ensure_prefix(&wine::prefix())?;
    crate::ua::venv()?;
    println!("setup: done (prefix {})", wine::prefix().display());
    Ok(())
}

fn installed(pkg: &str) -> bool {
    util::output(Command::new("dpkg-query").args(["-W", "-f=${Status}", pkg]))
        .map(|s| s.contains("install ok installed"))
        .unwrap_or(false)
}

fn has_i386() -> bool {
    util::output(Command::new("dpkg").arg("--print-foreign-architectures"))
        .map(|s| s.lines().any(|l| l.trim() == "i386"))
        .unwrap_or(false)
}

fn apt_packages() -> Result<(), String> {
    let missing: Vec<&str> = PACKAGES.iter().copied().filter(|p| !installed(p)).collect();
    if missing.is_empty() {
        println!("setup: apt packages present ({})", PACKAGES.join(", "));
        return Ok(());
    }
    let i386 = has_i386();
    if !util::is_root() {
        return Err(format!(
            "missing Debian packages: {m}\nrun as root, or install them first:\n  {arch}sudo apt-get update && sudo apt-get install -y --no-install-recommends {m}",
            m = missing.join(" "),
            arch = if i386 { "" } else { "sudo dpkg --add-architecture i386 && " }
        ));
    }
    if !i386 {
        println!("setup: adding the i386 architecture (wine32)");
        util::run(Command::new("dpkg").args(["--add-architecture", "i386"]))?;
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

fn rust_targets() -> Result<(), String> {
    let list = util::output(Command::new("rustup").args(["target", "list", "--installed"]))?;
    for arch in Arch::ALL {
        let target = arch.target();
        if list.lines().any(|l| l.trim() == target) {
            println!("setup: rust target {target} present");
        } else {
            util::run(Command::new("rustup").args(["target", "add", target]))?;
        }
    }
    Ok(())
}

/// Builds the bcryptprimitives shim for `arch` (see xtask/shim/bcryptprimitives.c) at
/// [`wine::shim`]; idempotent (msi-test calls it before making its prefix).
pub fn build_shim(arch: Arch) -> Result<(), String> {
    let root = util::root();
    let src = root.join("xtask/shim/bcryptprimitives.c");
    let def = root.join("xtask/shim/bcryptprimitives.def");
    let out = wine::shim(arch);
    if util::up_to_date(&out, &[src.clone(), def.clone()]) {
        return Ok(());
    }
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let mut gcc = Command::new(arch.gcc());
    gcc.args(["-O2", "-shared", "-o"])
        .arg(&out)
        .arg(&src)
        .arg(&def);
    if arch == Arch::X86 {
        // The .def names the undecorated ProcessPrng (as std imports it); ld maps it to
        // the stdcall symbol _ProcessPrng@8.
        gcc.arg("-Wl,--enable-stdcall-fixup");
    }
    util::run(gcc.arg("-lbcrypt"))?;
    println!("setup: built {}", out.display());
    Ok(())
}
