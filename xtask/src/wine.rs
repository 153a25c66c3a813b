//! The project's own Wine prefix under target/wine/prefix, and helpers for prefixes of
//! their own (the demo's).

use crate::util;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

pub const WINE64: &str = "/usr/lib/wine/wine64";
pub const WINESERVER: &str = "/usr/lib/wine/wineserver";

pub fn prefix() -> PathBuf {
    util::root().join("target/wine/prefix")
}

/// A command that runs `program` (a Windows path or a Unix path to an .exe) under Wine
/// in the project prefix, quiet, without the Mono/Gecko installers.
pub fn wine(program: impl AsRef<std::ffi::OsStr>) -> Command {
    let mut c = Command::new(WINE64);
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

/// Waits until the prefix's wineserver has exited (wineserver -w), bounded.
pub fn wait_idle(limit: Duration) -> Result<(), String> {
    let mut c = Command::new(WINESERVER);
    env(&mut c);
    c.arg("-w");
    util::run_with_timeout(&mut c, limit).map(|_| ())
}

/// Windows-side system32 of the prefix.
pub fn system32() -> PathBuf {
    prefix().join("drive_c/windows/system32")
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

/// Creates a Wine prefix of its own at `pfx` (as `setup` makes the project's, about 10 s
/// on first use) and installs the bcryptprimitives shim `setup` built into it.
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
    let shim = util::root().join("target/wine/bcryptprimitives.dll");
    let dest = pfx.join("drive_c/windows/system32/bcryptprimitives.dll");
    if !util::up_to_date(&dest, std::slice::from_ref(&shim)) {
        std::fs::copy(&shim, &dest).map_err(|e| format!("copy shim to {}: {e}", dest.display()))?;
    }
    Ok(())
}
