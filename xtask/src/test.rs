//! `cargo xtask test`: the one test command (README, .ci/run).
//!
//! 1. setup (idempotent);
//! 2. the static checks, early: `cargo fmt --all --check`, then `cargo clippy` with
//!    `-D warnings` for the host and for Windows (the lint levels are the `[lints]` tables
//!    of the manifests, the settings `clippy.toml`);
//! 3. native `cargo test` of every host crate, then every fuzz target for a few seconds
//!    (the stable runner, `xtask/src/fuzz.rs`);
//! 4. the Windows build;
//! 5. registration of the proxy/stub DLL and the server in the project's Wine prefix;
//! 6. the end-to-end tests (crate `tests/`, run under Wine by the cargo runner) and the COM
//!    crate's unit tests (Windows-only).
//!
//! Steps 5 and 6 always end every Wine process of the prefix and run with timeouts.
//! `--native` stops after step 3 and skips the Windows clippy.

use crate::{build, fuzz, setup, util, wine};
use std::time::Duration;

/// The whole end-to-end run may not take longer than this.
const E2E_LIMIT: Duration = Duration::from_secs(25 * 60);

pub fn run(args: &[String]) -> Result<(), String> {
    let native_only = args.iter().any(|a| a == "--native");
    setup::run(&[])?;
    static_checks(native_only)?;

    println!("test: native tests (cargo test --workspace)");
    util::run(util::cargo().args(["test", "--workspace", "--release"]))?;
    println!(
        "test: every fuzz target for {} s (stable runner)",
        fuzz::CI_SECONDS
    );
    fuzz::run(&[
        "--stable".into(),
        "--seconds".into(),
        fuzz::CI_SECONDS.to_string(),
    ])?;
    if native_only {
        return Ok(());
    }

    let artifacts = build::run(&[])?;
    wine::kill_all();
    let result = (|| {
        register(&artifacts)?;
        println!("test: end-to-end tests under Wine");
        let mut c = util::cargo();
        // The COM crate's own unit tests only build for Windows: they run here too.
        c.args([
            "test",
            "--release",
            "--target",
            setup::TARGET,
            "-p",
            "e2e-tests",
            "-p",
            "ctopc-com",
            "--",
            "--test-threads=1",
        ]);
        c.env("CTOPC_BIN_DIR", &artifacts.dir);
        let status = util::run_with_timeout(&mut c, E2E_LIMIT)?;
        if !status.success() {
            return Err(format!("end-to-end tests failed: {status}"));
        }
        thirdparty_client()
    })();
    wine::kill_all();
    result
}

/// Formatting and clippy, before anything is built for testing: each fails the run with
/// what to do about it.
fn static_checks(native_only: bool) -> Result<(), String> {
    println!("test: formatting (cargo fmt --all --check)");
    util::run(util::cargo().args(["fmt", "--all", "--check"])).map_err(|e| {
        format!("{e}\nthe code is not formatted as rustfmt.toml says: run `cargo fmt --all`")
    })?;
    println!("test: clippy for the host (cargo clippy --workspace --all-targets --release)");
    util::run(util::cargo().args([
        "clippy",
        "--workspace",
        "--all-targets",
        "--release",
        "--",
        "-D",
        "warnings",
    ]))
    .map_err(|e| format!("{e}\nclippy (host) found the problems printed above: fix them"))?;
    if native_only {
        return Ok(());
    }
    // xtask is host-only (std::os::unix): it is not checked for Windows.
    println!(
        "test: clippy for {} (cargo clippy --workspace --exclude xtask)",
        setup::TARGET
    );
    util::run(util::cargo().args([
        "clippy",
        "--workspace",
        "--exclude",
        "xtask",
        "--all-targets",
        "--release",
        "--target",
        setup::TARGET,
        "--",
        "-D",
        "warnings",
    ]))
    .map_err(|e| {
        format!(
            "{e}\nclippy ({}) found the problems printed above: fix them",
            setup::TARGET
        )
    })
}

/// `cargo xtask e2e [ARGS...]`: the Windows build, registration in the project's prefix,
/// then `cargo test --release --target x86_64-pc-windows-gnu ARGS -- --test-threads=1`
/// under Wine (default ARGS: `-p e2e-tests -p ctopc-com`), e.g.
/// `cargo xtask e2e -p e2e-tests --test group_io` or `cargo xtask e2e -p ctopc-com`.
/// Arguments after a `--` go to the test binaries (a name filter, say). For working on
/// one part; `cargo xtask test` stays the one command that runs everything.
pub fn e2e(args: &[String]) -> Result<(), String> {
    setup::run(&[])?;
    let artifacts = build::run(&[])?;
    let (cargo_args, test_args) = match args.iter().position(|a| a == "--") {
        Some(i) => (&args[..i], &args[i + 1..]),
        None => (args, &[][..]),
    };
    wine::kill_all();
    let result = (|| {
        register(&artifacts)?;
        let mut c = util::cargo();
        c.args(["test", "--release", "--target", setup::TARGET]);
        if cargo_args.is_empty() {
            c.args(["-p", "e2e-tests", "-p", "ctopc-com"]);
        } else {
            c.args(cargo_args);
        }
        c.arg("--").arg("--test-threads=1").args(test_args);
        c.env("CTOPC_BIN_DIR", &artifacts.dir);
        let status = util::run_with_timeout(&mut c, E2E_LIMIT)?;
        if status.success() {
            Ok(())
        } else {
            Err(format!("end-to-end tests failed: {status}"))
        }
    })();
    wine::kill_all();
    result
}

/// Registers the proxy/stub DLL (its own DllRegisterServer, through regsvr32) and the
/// server (/RegServer) in the prefix.
pub fn register(a: &build::Artifacts) -> Result<(), String> {
    let limit = Duration::from_secs(120);
    let status = util::run_with_timeout(wine::wine("regsvr32").arg("/s").arg(&a.proxy), limit)?;
    if !status.success() {
        return Err(format!("regsvr32 {} failed: {status}", a.proxy.display()));
    }
    let status = util::run_with_timeout(wine::wine(&a.server).arg("/RegServer"), limit)?;
    if !status.success() {
        return Err(format!(
            "{} /RegServer failed: {status}",
            a.server.display()
        ));
    }
    println!(
        "test: registered {} and {}",
        a.proxy.display(),
        a.server.display()
    );
    Ok(())
}

/// Builds and runs tests/thirdparty-client: an OPC DA client we did not write (the opc_da
/// crate, with bindings from the OPC Foundation's IDL) reads the server's status through
/// our proxy/stub DLL.
fn thirdparty_client() -> Result<(), String> {
    println!("test: third-party OPC client (opc_da crate) under Wine");
    let root = util::root();
    let target_dir = root.join("target/thirdparty");
    util::run(
        util::cargo()
            .args([
                "build",
                "--release",
                "--target",
                setup::TARGET,
                "--manifest-path",
            ])
            .arg(root.join("tests/thirdparty-client/Cargo.toml"))
            .env("CARGO_TARGET_DIR", &target_dir),
    )?;
    let exe = target_dir
        .join(setup::TARGET)
        .join("release/thirdparty-client.exe");
    let status = util::run_with_timeout(&mut wine::wine(&exe), Duration::from_secs(120))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("third-party client failed: {status}"))
    }
}
