//! The project's own Wine prefix under target/wine/prefix.

use crate::util;
use std::path::PathBuf;
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
        .env("WINEDEBUG", std::env::var("WINEDEBUG").unwrap_or_else(|_| "-all".into()));
}

/// Ends every process of the prefix (wineserver -k); harmless when none runs.
pub fn kill_all() {
    let mut c = Command::new(WINESERVER);
    env(&mut c);
    c.arg("-k");
    let _ = util::run_with_timeout(c.stdout(std::process::Stdio::null()).stderr(std::process::Stdio::null()), Duration::from_secs(20));
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
