//! The project's own Wine prefix under target/wine/prefix, and helpers for prefixes of
//! their own (the demo's).
//!
//! The harness's tolerance of Wine's own trouble lives here too: [`guard`] (the stall
//! guard of the end-to-end runs, which runs a stalled binary once more), [`start`] (an
//! opcdiag that Wine failed to start is started again) and [`forgiven`], the count of
//! every forgiveness of a run, printed as its last line (with `xtask/wine-run.sh`'s
//! SIGKILL-after-ok and `tests/src/start.rs`'s CreateProcess retries).

use crate::arch::Arch;
use crate::util;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

pub mod forgiven;
pub mod guard;
pub mod start;

pub const WINESERVER: &str = "/usr/lib/wine/wineserver";

pub fn prefix() -> PathBuf {
    util::root().join("target/wine/prefix")
}

/// A command that runs `program` (a Windows path or a Unix path to an .exe) under Wine
/// in the project prefix, quiet, without the Mono/Gecko installers.
pub fn wine(program: impl AsRef<std::ffi::OsStr>) -> Command {
    wine_arch(Arch::X64, program)
}

/// [`wine`] with the loader of `arch`: the 32-bit loader runs 32-bit programs (and the
/// 32-bit `regsvr32` from syswow64) in the same win64 prefix.
pub fn wine_arch(arch: Arch, program: impl AsRef<std::ffi::OsStr>) -> Command {
    let mut c = Command::new(arch.loader());
    env(&mut c);
    c.arg(program);
    c
}

pub fn env(c: &mut Command) {
    c.env("WINEPREFIX", prefix())
        .env("WINEARCH", "win64")
        .env("WINEDLLOVERRIDES", "mscoree,mshtml=")
        .env(
            "WINEDEBUG",
            std::env::var("WINEDEBUG").unwrap_or_else(|_| "-all".into()),
        );
}

/// Ends every process of the prefix (wineserver -k); harmless when none runs.
pub fn kill_all() {
    let mut c = Command::new(WINESERVER);
    env(&mut c);
    c.arg("-k");
    let _ = util::run_with_timeout(
        c.stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null()),
        Duration::from_secs(20),
    );
}

/// The Windows path of a Unix path under Wine (`Z:` and backslashes).
pub fn windows_path(p: &Path) -> String {
    format!("Z:{}", p.display()).replace('/', "\\")
}

/// A command that runs `program` under Wine in the prefix `pfx` (not the project's).
pub fn wine_in(pfx: &Path, program: impl AsRef<std::ffi::OsStr>) -> Command {
    let mut c = wine(program);
    c.env("WINEPREFIX", pfx);
    c
}

/// `wineserver <arg>` for the prefix `pfx` (e.g. `-k`: end every process of it), quiet,
/// bounded by `limit`; harmless when nothing runs.
pub fn wineserver_in(pfx: &Path, arg: &str, limit: Duration) {
    let mut c = Command::new(WINESERVER);
    env(&mut c);
    c.env("WINEPREFIX", pfx).arg(arg);
    let _ = util::run_with_timeout(
        c.stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null()),
        limit,
    );
}

/// Registers the 64-bit proxy/stub DLL `proxy` (regsvr32) and the server `server`
/// (`/RegServer`) in the prefix `pfx` (a prefix of the benchmarks' own: `bench`, `bench
/// --scale`).
pub fn register_in(pfx: &Path, proxy: &Path, server: &Path) -> Result<(), String> {
    let limit = Duration::from_secs(120);
    let status = util::run_with_timeout(wine_in(pfx, "regsvr32").arg("/s").arg(proxy), limit)?;
    if !status.success() {
        return Err(format!("regsvr32 {} failed: {status}", proxy.display()));
    }
    let status = util::run_with_timeout(wine_in(pfx, server).arg("/RegServer"), limit)?;
    if !status.success() {
        return Err(format!("{} /RegServer failed: {status}", server.display()));
    }
    Ok(())
}

/// The bcryptprimitives shim `setup` builds for `arch` (xtask/shim): 64-bit in
/// target/wine, 32-bit in target/wine/x86.
pub fn shim(arch: Arch) -> PathBuf {
    let dir = util::root().join("target/wine");
    match arch.dist_subdir() {
        None => dir.join("bcryptprimitives.dll"),
        Some(sub) => dir.join(sub).join("bcryptprimitives.dll"),
    }
}

/// True when the prefix `pfx` can run 32-bit programs: its `syswow64` holds Wine's
/// 32-bit DLLs. A prefix created before wine32 was installed has an empty `syswow64`.
pub fn has_wow64(pfx: &Path) -> bool {
    pfx.join("drive_c/windows/syswow64/kernel32.dll").is_file()
}

/// Makes the Wine prefix `pfx` ready for both bitnesses: creates it when missing (about
/// 10 s), repairs a prefix made before wine32 was installed (its syswow64 is empty:
/// `wineboot -u` after removing `.update-timestamp`, about 60 s once; `wineboot -u`
/// alone does not fill it), and installs the bcryptprimitives shims `setup` built into
/// system32 (64-bit) and syswow64 (32-bit). Used for the project's prefix and for the
/// demo's and the benchmark's own.
pub fn ensure_prefix(pfx: &Path) -> Result<(), String> {
    if !pfx.join("system.reg").exists() {
        println!("creating Wine prefix {}", pfx.display());
        std::fs::create_dir_all(pfx).map_err(|e| format!("{}: {e}", pfx.display()))?;
        let status =
            util::run_with_timeout(wine_in(pfx, "wineboot").arg("-i"), Duration::from_secs(180))?;
        if !status.success() {
            return Err(format!("wineboot -i failed: {status}"));
        }
        wineserver_in(pfx, "-w", Duration::from_secs(120));
    }
    if !has_wow64(pfx) {
        println!(
            "repairing Wine prefix {} for 32-bit programs (its syswow64 is empty: made before wine32 was installed)",
            pfx.display()
        );
        // Nothing of the prefix may run during the update.
        wineserver_in(pfx, "-k", Duration::from_secs(20));
        let stamp = pfx.join(".update-timestamp");
        if stamp.exists() {
            std::fs::remove_file(&stamp).map_err(|e| format!("{}: {e}", stamp.display()))?;
        }
        let status =
            util::run_with_timeout(wine_in(pfx, "wineboot").arg("-u"), Duration::from_secs(300))?;
        if !status.success() {
            return Err(format!("wineboot -u failed: {status}"));
        }
        wineserver_in(pfx, "-w", Duration::from_secs(120));
        if !has_wow64(pfx) {
            return Err(format!(
                "{}: syswow64 is still empty after wineboot -u; is wine32 (i386) installed? (`cargo xtask setup`)",
                pfx.display()
            ));
        }
    }
    for arch in Arch::ALL {
        let shim = shim(arch);
        let dest = pfx
            .join("drive_c/windows")
            .join(arch.system_dir())
            .join("bcryptprimitives.dll");
        if !util::up_to_date(&dest, std::slice::from_ref(&shim)) {
            std::fs::copy(&shim, &dest)
                .map_err(|e| format!("copy shim to {}: {e}", dest.display()))?;
        }
    }
    Ok(())
}
