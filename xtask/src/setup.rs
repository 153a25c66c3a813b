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
    // The peer server of `cargo xtask bench --ua` (node-opcua, xtask/bench/ua-peer),
    // installed with npm from its package-lock.json.
    "nodejs",
    "npm",
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
    // Only `bench --ua` needs the peer: without the network, setup goes on without it.
    if let Err(e) = crate::ua_bench::install_peer() {
        println!("setup: the node-opcua peer of bench --ua is not installed: {e}");
    }
    println!("setup: done (prefix {})", wine::prefix().display());
    Ok(())
}

fn installed(pkg: &str) -> bool {
    util::output(Command::new("dpkg-query").args(["-W", "-f=${Status}", pkg]))
        .map(|s| s.contains("install ok installed"))
        .unwrap_or(false)
}

/// npm on the PATH: the nodejs of NodeSource's repository brings its own (and conflicts
/// with Debian's npm package).
fn npm_present() -> bool {
    util::output(Command::new("npm").arg("--version")).is_ok()
}

fn has_i386() -> bool {
    util::output(Command::new("dpkg").arg("--print-foreign-architectures"))
        .map(|s| s.lines().any(|l| l.trim() == "i386"))
        .unwrap_or(false)
}

fn apt_packages() -> Result<(), String> {
    let missing: Vec<&str> = PACKAGES
        .iter()
        .copied()
        .filter(|p| !(installed(p) || (*p == "npm" && npm_present())))
        .collect();
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
    // A Debian mirror answers "File has unexpected size … Mirror sync in progress?" for a
    // few seconds while it syncs: try the update again, and when it still fails, install
    // from the indexes it did fetch (the install then says which package is missing).
    let mut tries = 0;
    while let Err(e) = util::run(Command::new("apt-get").args(["update", "-q"])) {
        tries += 1;
        if tries == APT_UPDATE_TRIES {
            println!("setup: apt-get update failed {tries} times ({e}); installing from the indexes fetched");
            break;
        }
        println!("setup: apt-get update failed ({e}); trying again in {APT_RETRY_SECS} s");
        std::thread::sleep(std::time::Duration::from_secs(APT_RETRY_SECS));
    }
    // A dry run first: when the indexes lack the i386 build of a library at the version
    // installed for amd64 (an image newer than its mirror, or an index the update could not
    // fetch), a Multi-Arch: same pair cannot be installed; both halves then go to the
    // version the i386 index offers.
    let install = |extra: &[String], dry: bool| {
        let mut cmd = Command::new("apt-get");
        cmd.args(["install", "-y", "-q", "--no-install-recommends"])
            .args(&missing)
            .args(extra)
            .env("DEBIAN_FRONTEND", "noninteractive");
        if dry {
            cmd.arg("-s");
        }
        if !extra.is_empty() {
            cmd.arg("--allow-downgrades");
        }
        cmd
    };
    let mut extra = Vec::new();
    let dry = install(&[], true)
        .output()
        .map_err(|e| format!("cannot start apt-get: {e}"))?;
    if !dry.status.success() {
        // apt prints the resolver's report on stdout and the verdict on stderr.
        let report = String::from_utf8_lossy(&dry.stdout) + String::from_utf8_lossy(&dry.stderr);
        for name in not_installable(&report) {
            let policy =
                util::output(Command::new("apt-cache").args(["policy", &format!("{name}:i386")]))?;
            if let Some(version) = candidate(&policy) {
                println!("setup: {name} is not installable at its amd64 version; both architectures get {version}");
                extra.push(format!("{name}:amd64={version}"));
                extra.push(format!("{name}:i386={version}"));
            }
        }
    }
    util::run(&mut install(&extra, false))
}

/// The packages apt's resolver names as "… Depends: NAME (…) but it is not installable".
fn not_installable(report: &str) -> Vec<String> {
    let mut names: Vec<String> = report
        .lines()
        .filter(|l| l.contains("but it is not installable"))
        .filter_map(|l| l.split("Depends: ").nth(1))
        .filter_map(|rest| rest.split_whitespace().next())
        .map(|n| n.split(':').next().unwrap_or(n).to_string())
        .collect();
    names.sort();
    names.dedup();
    names
}

/// The "Candidate:" version of an `apt-cache policy` answer, unless it is "(none)".
fn candidate(policy: &str) -> Option<String> {
    policy
        .lines()
        .find_map(|l| l.trim().strip_prefix("Candidate:"))
        .map(str::trim)
        .filter(|v| !v.is_empty() && *v != "(none)")
        .map(str::to_string)
}

/// How often `apt_packages` runs `apt-get update` before it goes on without a clean one.
const APT_UPDATE_TRIES: u32 = 4;
/// The wait between two `apt-get update` runs (a mirror sync takes seconds to minutes).
const APT_RETRY_SECS: u64 = 20;

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_resolvers_report_names_each_uninstallable_package_once() {
        let report = " grep : PreDepends: libpcre2-8-0 (>= 10.32) but it is not installable
 libglib2.0-0 : Depends: libpcre2-8-0 (>= 10.22) but it is not installable
 libpcre2-dev : Depends: libpcre2-8-0 (= 10.42-1) but it is not installable
                Depends: libpcre2-posix3 (= 10.42-1) but it is not going to be installed
 wine32:i386 : Depends: libwine:i386 (= 8.0~repack-4) but it is not installable
E: Error, pkgProblemResolver::Resolve generated breaks";
        assert_eq!(not_installable(report), ["libpcre2-8-0", "libwine"]);
    }

    #[test]
    fn the_candidate_is_read_from_apt_cache_policy() {
        let policy =
            "libpcre2-8-0:i386:\n  Installed: (none)\n  Candidate: 10.42-1\n  Version table:\n";
        assert_eq!(candidate(policy).as_deref(), Some("10.42-1"));
        assert_eq!(candidate("x:\n  Candidate: (none)\n"), None);
    }
}
