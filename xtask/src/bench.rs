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
//! Then it runs bench-com.exe again with `--distinct`, against a server of a synthetic
//! database of 100,000 variables (`target/scale/db-100000`, written on first use): reads
//! of 10,000 and 80,000 distinct variables from cache and from device, their ratio, and
//! the transport floor (the same call with invalid handles). `--only-distinct` runs only
//! that part.
//!
//! `cargo xtask bench --scale [OPTIONS]` is the scale benchmark instead (`scale.rs`);
//! `cargo xtask bench --ua [OPTIONS]` the OPC UA benchmark beside node-opcua, natively
//! (`ua_bench.rs`).

use crate::{build, setup, util, wine};
use std::path::PathBuf;
use std::time::Duration;

const LIMIT: Duration = Duration::from_secs(20 * 60);

fn prefix() -> PathBuf {
    util::root().join("target/wine/bench-prefix")
}

/// Variables of the database the distinct reads use (at least the 80,000 they read).
const DISTINCT_DB_SIZE: usize = 100_000;

/// The synthetic database's variable set, as the Windows path bench-com.exe gets.
fn distinct_db() -> Result<String, String> {
    let db = crate::scale::synthetic_db(DISTINCT_DB_SIZE)?;
    Ok(wine::windows_path(&db.join("synthetic.zez")))
}

pub fn run(args: &[String]) -> Result<(), String> {
    if let Some(rest) = args.strip_prefix(&["--scale".to_owned()]) {
        return crate::scale::run(rest);
    }
    if let Some(rest) = args.strip_prefix(&["--ua".to_owned()]) {
        return crate::ua_bench::run_bench(rest);
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
        let only_distinct = args.iter().any(|a| a == "--only-distinct");
        let args: Vec<String> = args
            .iter()
            .filter(|a| *a != "--only-distinct")
            .cloned()
            .collect();
        let distinct_loop = args.iter().any(|a| a.ends_with("-distinct"));
        let mut first: Vec<String> = args.to_vec();
        if only_distinct {
            first.extend(["--distinct".to_owned(), distinct_db()?]);
            let status = util::run_with_timeout(wine::wine_in(&pfx, &exe).args(&first), LIMIT)?;
            return if status.success() {
                Ok(())
            } else {
                Err(format!("bench-com.exe --distinct failed: {status}"))
            };
        }
        if distinct_loop {
            first.extend(["--distinct".to_owned(), distinct_db()?]);
        }
        let status = util::run_with_timeout(wine::wine_in(&pfx, &exe).args(&first), LIMIT)?;
        if !status.success() {
            return Err(format!("bench-com.exe failed: {status}"));
        }
        if distinct_loop || args.iter().any(|a| a == "--loop") {
            return Ok(());
        }
        // The reads of distinct variables: a server of the synthetic database (the
        // first run's server has left with its last client).
        wine::wineserver_in(&pfx, "-w", Duration::from_secs(30));
        let mut second: Vec<String> = args.to_vec();
        second.extend(["--distinct".to_owned(), distinct_db()?]);
        let status = util::run_with_timeout(wine::wine_in(&pfx, &exe).args(&second), LIMIT)?;
        if status.success() {
            Ok(())
        } else {
            Err(format!("bench-com.exe --distinct failed: {status}"))
        }
    })();
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
    result
}
