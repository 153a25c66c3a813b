//! `cargo xtask ua-interop`: the OPC UA front end against an independent client, Python
//! `asyncua` (pinned [`ASYNCUA`], in the venv `target/ua-venv` that [`venv`] makes; setup
//! makes it too). Runs the native release `ServerCTOPC` (`--built`: the one `cargo test
//! --workspace --release` has just built for the server's command-line tests, as `cargo
//! xtask test` does; else built here) and runs `tests/ua/interop.py`: the in-process simulation of the demo
//! plant served over Basic256Sha256 SignAndEncrypt; browse, read, write, subscribe with
//! users and roles; anonymous, None and an untrusted client certificate refused;
//! RegisterNodes, Republish, TransferSubscriptions, monitored item queues; every `[UA]`
//! limit answered with its code (what it checks: the script's docstring). Then our own client, `opcdiag --url`, through the
//! same server (`ua_client.rs`: browse in pages, read, write as writer and reader,
//! subscribe, a wrong password, anonymous and None refused, the server's certificate
//! refused until pinned). Part of `cargo xtask test`'s native phase.

use crate::util;
use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

/// The asyncua release the test is written against (installs on Debian 12's Python 3.11).
pub const ASYNCUA: &str = "asyncua==1.1.5";
/// The whole interop run may not take longer than this.
const LIMIT: Duration = Duration::from_secs(10 * 60);

fn venv_dir() -> PathBuf {
    util::root().join("target").join("ua-venv")
}

/// The venv's Python, with asyncua installed (made or completed when missing).
pub fn venv() -> Result<PathBuf, String> {
    let dir = venv_dir();
    let python = dir.join("bin").join("python");
    let version = ASYNCUA.trim_start_matches("asyncua==");
    let check = format!(
        "import asyncua, importlib.metadata as m; assert m.version('asyncua') == '{version}'"
    );
    if python.exists() && util::output(Command::new(&python).args(["-c", &check])).is_ok() {
        println!("setup: {ASYNCUA} present in {}", dir.display());
        return Ok(python);
    }
    if !python.exists() {
        println!("setup: making the venv {}", dir.display());
        util::run(Command::new("python3").args(["-m", "venv"]).arg(&dir))?;
    }
    println!("setup: pip install {ASYNCUA}");
    util::run(Command::new(&python).args([
        "-m",
        "pip",
        "install",
        "-q",
        "--disable-pip-version-check",
        ASYNCUA,
    ]))?;
    Ok(python)
}

/// `ua-interop [--built] [--opcdiag-only]`: both scenarios, or only opcdiag's (no Python
/// needed); `--built`: the release binaries the native tests built.
pub fn run(args: &[String]) -> Result<(), String> {
    let built = args.iter().any(|a| a == "--built");
    if args.iter().any(|a| a == "--opcdiag-only") {
        return crate::ua_client::scenario(built);
    }
    let python = venv()?;
    let root = util::root();
    let server = root.join("target").join("release").join("ServerCTOPC");
    if built && server.exists() {
        println!(
            "ua-interop: {} (built by the native tests)",
            server.display()
        );
    } else {
        println!("ua-interop: building ServerCTOPC (native, release)");
        util::run(util::cargo().args(["build", "--release", "-p", "serverctopc"]))?;
    }
    let work = root.join("target").join("ua-interop");
    let db = root
        .join("demo")
        .join("wytwornia_kwasu")
        .join("wytwornia_kwasu.zez");
    println!("ua-interop: tests/ua/interop.py (asyncua {ASYNCUA})");
    let status = util::run_with_timeout(
        Command::new(python)
            .arg(root.join("tests").join("ua").join("interop.py"))
            .arg("--server")
            .arg(&server)
            .arg("--db")
            .arg(&db)
            .arg("--work")
            .arg(&work)
            .env_remove("SERVERCTOPC_INI"),
        LIMIT,
    )?;
    let interop = if status.success() {
        Ok(())
    } else {
        Err(format!(
            "the OPC UA interop test failed ({status}); the server's log: {}",
            work.join("serve.log").display()
        ))
    };
    println!("ua-interop: opcdiag --url against ServerCTOPC serve (xtask/src/ua_client.rs)");
    let ours = crate::ua_client::scenario(built);
    interop.and(ours)
}
