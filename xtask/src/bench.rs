//! `cargo xtask bench`: the COM benchmark (tests/src/bin/bench-com.rs) under Wine.
//!
//! Builds the Windows artifacts and bench-com.exe, registers the proxy/stub DLL and the
//! server in a Wine prefix of the benchmark's own (target/wine/bench-prefix, made like
//! the test prefix on first use), so that a benchmark run neither disturbs nor is
//! disturbed by end-to-end tests in the test prefix; runs bench-com.exe with a timeout
//! (extra arguments are passed on, e.g. `--quick`) and ends every Wine process of the
//! benchmark prefix (wineserver -k) at the end. Prints figures; never fails on speed.
//! bench-com.exe points the server at a configuration of its own (the demo plant with
//! `MinUpdateRate = 250`, written as `bench-ServerCTOPC.ini` beside it, handed over in
//! `SERVERCTOPC_INI`), so the registered server's own ini is not involved.
//!
//! `cargo xtask bench --scale [OPTIONS]` is the scale benchmark instead (`scale.rs`).

use crate::{build, setup, util, wine};
use std::path::PathBuf;
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(20 * 60);

fn prefix() -> PathBuf {
    util::root().join("target/wine/bench-prefix")
}

pub fn run(args: &[String]) -> Result<(), String> {
    if let Some(rest) = args.strip_prefix(&["--scale".to_owned()]) {
        return crate::scale::run(rest);
    }
    setup::run(&[])?;
    let artifacts = build::run(&[])?;
    build::e2e_bin("bench-com")?;
    let exe = artifacts.dir.join("bench-com.exe");
    let pfx = prefix();
    wine::ensure_prefix(&pfx)?;
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
    let result = (|| {
        wine::register_in(&pfx, &artifacts.proxy, &artifacts.server)?;
        println!(
            "bench: running {} under Wine (prefix {})",
            exe.display(),
            pfx.display()
        );
        let status = util::run_with_timeout(wine::wine_in(&pfx, &exe).args(args), LIMIT)?;
        if status.success() {
            Ok(())
        } else {
            Err(format!("bench-com.exe failed: {status}"))
        }
    })();
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
    result
}
