//! `cargo xtask test`: the one test command (README, .ci/run).
//!
//! 1. setup (idempotent);
//! 2. the static checks, early: `cargo fmt --all --check`, then `cargo clippy` with
//!    `-D warnings` for the host and for Windows (the lint levels are the `[lints]` tables
//!    of the manifests, the settings `clippy.toml`);
//! 3. native `cargo test` of every host crate, then every fuzz target for a few seconds
//!    (the stable runner, `xtask/src/fuzz.rs`), then the OPC UA interop test
//!    (`cargo xtask ua-interop`, `xtask/src/ua.rs`: `ServerCTOPC serve` natively against
//!    Python asyncua); the OPC UA benchmark (`cargo xtask bench --ua [--quick]`) is not
//!    part of the run: it prints figures, and its node-opcua peer starts for minutes;
//! 4. the Windows build (both bitnesses, `build::run_for_tests`: the product and the
//!    end-to-end tests in one cargo call per bitness, built once); then, **in the background** beside
//!    steps 5 to 7 (which mostly wait on Wine and the server, not the CPU), the
//!    third-party client's builds (both bitnesses, in `target/thirdparty`, which cargo
//!    locks apart from `target/`) and step 8;
//! 5. registration of the proxy/stub DLLs (64-bit and 32-bit), the server and the test
//!    double of `XConnect.ServerCT` (32-bit) in the project's Wine prefix; two native
//!    `asix-sim --rest` stations for the Asix.Evo REST test (`rest_stations.rs`), up until
//!    the end-to-end tests end;
//! 6. the end-to-end tests (crate `tests/`, run under Wine by the cargo runner) and the COM
//!    crate's unit tests (Windows-only), then the third-party client;
//! 7. the end-to-end tests again as a **32-bit client** ([`E2E_32`]: built for
//!    `i686-pc-windows-gnu`, run by Wine's 32-bit loader in the same prefix, through the
//!    32-bit proxy/stub, against the same 64-bit server), then the third-party client
//!    built for 32-bit;
//! 8. the MSI (`cargo xtask msi-test --built`, xtask/src/msi.rs, about 3 min here; its
//!    own prefixes, so it runs beside 5 to 7; its log, `target/msi-test/run.log`, is
//!    printed when it is waited for, at the end): a broken
//!    package, then install, a 64-bit and a 32-bit client (status, write, read back,
//!    subscribe, the server browser), upgrade with `SERVICE=1`, uninstall, each in a
//!    fresh prefix of its own (copies of `target/wine/msi-template`).
//!
//! Steps 6 and 7 run one test binary at a time under the stall guard (`wine/guard.rs`): a
//! binary silent for 4 minutes gets a backtrace report, then runs once more.
//! The run's last line counts the Wine trouble it forgave (`wine/forgiven.rs`), also when
//! it failed: `forgiven: 0 SIGKILL-after-ok, 0 stall rerun, 0 CreateProcess-1359 retry,
//! 0 opcdiag retry`, under one line per forgiveness.
//! Steps 5 to 7 always end every Wine process of the prefix and run with timeouts.
//! `--native` stops after step 3 and skips the Windows clippy.

use crate::arch::Arch;
use crate::wine::{self, forgiven, guard};
use crate::{build, fuzz, rest_stations, setup, util};
use std::time::Duration;

/// The whole end-to-end run may not take longer than this.
const E2E_LIMIT: Duration = Duration::from_secs(25 * 60);

pub fn run(args: &[String]) -> Result<(), String> {
    let ledger = forgiven::Ledger::begin(&forgiven::path())?;
    ledger.end(run_all(args))
}

/// Prints how long a phase of the run took (wall time), so that a run's log says where its
/// time went.
fn took(phase: &str, since: std::time::Instant) {
    println!("test: {phase} took {} s", since.elapsed().as_secs());
}

fn run_all(args: &[String]) -> Result<(), String> {
    let start = std::time::Instant::now();
    let native_only = args.iter().any(|a| a == "--native");
    setup::run(&[])?;
    took("setup", start);
    let t = std::time::Instant::now();
    static_checks(native_only)?;
    took("the static checks", t);

    println!("test: native tests (cargo test --workspace)");
    let t = std::time::Instant::now();
    util::run(util::cargo().args(["test", "--workspace", "--release"]))?;
    println!(
        "test: every fuzz target for {} s (stable runner)",
        fuzz::CI_SECONDS
    );
    fuzz::run(&[
        "--built".into(),
        "--seconds".into(),
        fuzz::CI_SECONDS.to_string(),
    ])?;
    took("the native tests and the fuzz targets", t);
    let t = std::time::Instant::now();
    // The release ServerCTOPC the native tests built (crates/server/tests/cli.rs).
    crate::ua::run(&["--built".into()])?;
    took("the OPC UA interop test", t);
    if native_only {
        return Ok(());
    }

    let t = std::time::Instant::now();
    let artifacts = build::run_for_tests(&[
        (Arch::X64, selection(Arch::X64)?),
        (Arch::X86, selection(Arch::X86)?),
    ])?;
    took("the Windows build", t);
    // Two steps that need neither the project's prefix nor cargo's build lock run beside
    // the end-to-end tests, which mostly wait on Wine and the server: the third-party
    // client's builds (their own target dir) and the MSI test (its own prefixes).
    let mut background = Background::start()?;
    wine::kill_all();
    let result = (|| {
        register(&artifacts)?;
        // For tests/tests/rest_source.rs (both bitnesses): ended when the phase ends. The
        // native tests built asix-sim (a binary of a package with integration tests).
        let _stations = rest_stations::Stations::start(rest_stations::Sim::Built)?;
        println!("test: end-to-end tests under Wine (one binary at a time, wine/guard.rs)");
        let units = units_64()?;
        let build64 = selection(Arch::X64)?;
        let plan = guard::Plan {
            target: setup::TARGET,
            test_args: &[],
            limit: E2E_LIMIT,
            retries: 1,
            build: &build64,
        };
        let t = std::time::Instant::now();
        guard::run_units(&plan, &units)?;
        took("the end-to-end tests (64-bit client)", t);
        let [client64, client32] = background.clients()?;
        thirdparty_client(Arch::X64, &client64)?;
        println!(
            "test: end-to-end tests as a 32-bit client ({})",
            Arch::X86.target()
        );
        // marshal_strings (32-bit client) talks to the 64-bit marshal probe, which the
        // 64-bit build made (a package's binaries are built for its integration tests).
        let units = units_32();
        let build32 = selection(Arch::X86)?;
        let plan = guard::Plan {
            target: Arch::X86.target(),
            build: &build32,
            ..plan
        };
        let t = std::time::Instant::now();
        guard::run_units(&plan, &units)?;
        took("the end-to-end tests (32-bit client)", t);
        thirdparty_client(Arch::X86, &client32)
    })();
    wine::kill_all();
    // Waited for whatever happened above: it ends on its own, within its timeouts.
    let msi = background.msi_test();
    result?;
    msi?;
    took("the whole run", start);
    Ok(())
}

/// The steps `run` starts in the background after the Windows build, each logging to a
/// file (printed when it is joined) so that the foreground's output stays readable.
/// Together they are about 10 minutes of work (the msi-test and the third-party client's
/// clean builds at both bitnesses; docs/benchmarks.md), which made in turn would add to
/// the run; beside the end-to-end tests, which mostly wait on Wine, they lengthen those
/// only by their CPU share.
struct Background {
    /// The third-party client built for 64-bit, then 32-bit: the two exes.
    clients: Option<std::thread::JoinHandle<Result<[std::path::PathBuf; 2], String>>>,
    /// `cargo xtask msi-test --built` (this exe), and its log.
    msi: std::process::Child,
    msi_log: std::path::PathBuf,
}

impl Background {
    fn start() -> Result<Background, String> {
        let root = util::root();
        let clients = Some(std::thread::spawn(|| {
            Ok([thirdparty_build(Arch::X64)?, thirdparty_build(Arch::X86)?])
        }));
        let dir = root.join("target/msi-test");
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let msi_log = dir.join("run.log");
        let log =
            std::fs::File::create(&msi_log).map_err(|e| format!("{}: {e}", msi_log.display()))?;
        let err = log
            .try_clone()
            .map_err(|e| format!("{}: {e}", msi_log.display()))?;
        let exe = std::env::current_exe().map_err(|e| format!("this exe: {e}"))?;
        println!(
            "test: the MSI under Wine in the background (msi-test --built, log {})",
            msi_log.display()
        );
        let msi = std::process::Command::new(exe)
            .args(["msi-test", "--built"])
            .stdin(std::process::Stdio::null())
            .stdout(log)
            .stderr(err)
            .spawn()
            .map_err(|e| format!("cannot start the msi-test: {e}"))?;
        Ok(Background {
            clients,
            msi,
            msi_log,
        })
    }

    /// Waits for the third-party client's builds.
    fn clients(&mut self) -> Result<[std::path::PathBuf; 2], String> {
        let Some(h) = self.clients.take() else {
            return Err("the third-party client's builds were joined already".into());
        };
        h.join()
            .map_err(|_| "the third-party client's build panicked".to_string())?
    }

    /// Waits for the msi-test and prints its log.
    fn msi_test(mut self) -> Result<(), String> {
        println!("test: the MSI under Wine (cargo xtask msi-test, run in the background)");
        let status = self.msi.wait();
        let log = std::fs::read_to_string(&self.msi_log).unwrap_or_default();
        print!("{log}");
        match status {
            Ok(s) if s.success() => Ok(()),
            Ok(s) => Err(format!(
                "msi-test failed: {s} (log {})",
                self.msi_log.display()
            )),
            Err(e) => Err(format!("waiting for the msi-test: {e}")),
        }
    }
}

/// The end-to-end test files that also run from a 32-bit client: every interface and
/// method of the server, the callbacks (OnDataChange, OnReadComplete, OnWriteComplete,
/// ShutdownRequest, and OnCancelComplete of requests waiting for a slow device in
/// `group_slow_source`), every string out-parameter (marshal_strings, the 32-bit proxy
/// against the 64-bit probe's stub), registration as 32-bit processes see it, and the
/// 32-bit opcdiag (`opcdiag`, and `doctor`: its self-check, broken copies of the prefix
/// included). Left out: `service` (it tests the server as an NT service, not the
/// client's side of the wire). Measured: that one passes at 32-bit too. `xconnect` (the
/// late-bound Automation client against the test double of AsixConnect's
/// `XConnect.ServerCT`, a 32-bit in-process server), `gate_xconnect` (asix-gate's engine
/// over its Automation adapter, against the same double) and `gate_service` (the 32-bit
/// asix-gate.exe as an NT service) run only here: their files are empty in a 64-bit build.
pub const E2E_32: &[&str] = &[
    "da10",
    "diagnostics",
    "doctor",
    "foundation",
    "gate_e2e",
    "gate_service",
    "gate_xconnect",
    "generic_clients",
    "group_async",
    "group_callbacks",
    "group_io",
    "group_items",
    "group_slow_source",
    "group_state",
    "item_buffering",
    "marshal_strings",
    "opcdiag",
    "ops_audit",
    "ops_metrics",
    "ops_slow_clients",
    "registration",
    "rest_source",
    "server_browse",
    "server_groups",
    "server_itemio",
    "server_list",
    "server_props",
    "server_shutdown",
    "write_rights",
    "xconnect",
];

/// The 64-bit end-to-end units: the COM crate's unit and in-process tests and the server
/// browser's in-process tests (they only build for Windows), then the crate `tests/` (its
/// unit tests, then each test file).
fn units_64() -> Result<Vec<guard::Unit>, String> {
    let root = util::root();
    let mut units = vec![guard::Unit::lib("ctopc-com")];
    for t in guard::integration_tests(&root.join("crates/ctopc-com/tests"))? {
        units.push(guard::Unit::test("ctopc-com", &t));
    }
    for t in guard::integration_tests(&root.join("crates/serverlist/tests"))? {
        units.push(guard::Unit::test("opc-server-list", &t));
    }
    units.push(guard::Unit::lib("e2e-tests"));
    for t in guard::integration_tests(&root.join("tests/tests"))? {
        units.push(guard::Unit::test("e2e-tests", &t));
    }
    Ok(units)
}

/// The cargo arguments of the end-to-end tests' one `cargo test --no-run` at `arch`: the
/// product's packages (`build::product_packages`) and the units' packages and targets.
/// `build::run_for_tests` builds the same packages and tests, so that this finds
/// everything built (see there why).
fn selection(arch: Arch) -> Result<Vec<String>, String> {
    let units = match arch {
        Arch::X64 => units_64()?,
        Arch::X86 => units_32(),
    };
    let mut args: Vec<String> = Vec::new();
    for p in build::product_packages(arch) {
        args.extend(["-p".to_owned(), (*p).to_owned()]);
    }
    let mut rest = guard::build_args(&units).into_iter();
    while let Some(a) = rest.next() {
        if a == "-p" {
            let Some(p) = rest.next() else { break };
            if !build::product_packages(arch).contains(&p.as_str()) {
                args.extend([a, p]);
            }
        } else {
            args.push(a);
        }
    }
    Ok(args)
}

/// The 32-bit client's units: the [`E2E_32`] test files (the 32-bit runner,
/// xtask/wine-runner32.sh, runs them with Wine's 32-bit loader).
fn units_32() -> Vec<guard::Unit> {
    E2E_32
        .iter()
        .map(|t| guard::Unit::test("e2e-tests", t))
        .collect()
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
    })?;
    // What is built for 32-bit Windows: opcdiag and the e2e tests (the 32-bit client), with
    // the client library and the core beneath them, and asix-gate (a 32-bit program beside
    // AsixConnect's in-process Automation server).
    let x86 = Arch::X86.target();
    println!("test: clippy for {x86} (the 32-bit client side, asix-gate)");
    util::run(util::cargo().args([
        "clippy",
        "-p",
        "e2e-tests",
        "-p",
        "asix-gate",
        "-p",
        "opc-client",
        "-p",
        "ctopc-com",
        "-p",
        "ctopc-core",
        "--all-targets",
        "--release",
        "--target",
        x86,
        "--",
        "-D",
        "warnings",
    ]))
    .map_err(|e| format!("{e}\nclippy ({x86}) found the problems printed above: fix them"))
}

/// `cargo xtask e2e [ARGS...]`: the Windows build, registration in the project's prefix,
/// then `cargo test --release --target x86_64-pc-windows-gnu ARGS -- --test-threads=1`
/// under Wine and the stall guard (`wine/guard.rs`; a stall is reported, not run again)
/// (default ARGS: each test binary of `-p ctopc-com` and `-p e2e-tests` in turn), e.g.
/// `cargo xtask e2e -p e2e-tests --test group_io` or `cargo xtask e2e -p ctopc-com`.
/// Arguments after a `--` go to the test binaries (a name filter, say). For working on
/// one part; `cargo xtask test` stays the one command that runs everything.
/// `--x86` first runs the tests as a 32-bit client instead (default: the [`E2E_32`]
/// files), e.g. `cargo xtask e2e --x86 -p e2e-tests --test group_io`. Ends, as `test`
/// does, with the count of the Wine trouble forgiven (`wine/forgiven.rs`).
pub fn e2e(args: &[String]) -> Result<(), String> {
    let ledger = forgiven::Ledger::begin(&forgiven::path())?;
    ledger.end(e2e_only(args))
}

fn e2e_only(args: &[String]) -> Result<(), String> {
    let x86 = args.first().is_some_and(|a| a == "--x86");
    let args = if x86 { &args[1..] } else { args };
    setup::run(&[])?;
    let artifacts = build::run_for_tests(&[
        (Arch::X64, selection(Arch::X64)?),
        (Arch::X86, selection(Arch::X86)?),
    ])?;
    let (cargo_args, test_args) = match args.iter().position(|a| a == "--") {
        Some(i) => (&args[..i], &args[i + 1..]),
        None => (args, &[][..]),
    };
    wine::kill_all();
    let result = (|| {
        register(&artifacts)?;
        let _stations = rest_stations::Stations::start(rest_stations::Sim::Build)?;
        let units = if !cargo_args.is_empty() {
            vec![guard::Unit {
                label: cargo_args.join(" "),
                cargo_args: cargo_args.to_vec(),
            }]
        } else if x86 {
            units_32()
        } else {
            units_64()?
        };
        let arch = if x86 { Arch::X86 } else { Arch::X64 };
        let build = selection(arch)?;
        let plan = guard::Plan {
            target: arch.target(),
            test_args,
            limit: E2E_LIMIT,
            retries: 0,
            build: &build,
        };
        guard::run_units(&plan, &units)
    })();
    wine::kill_all();
    result
}

/// Registers the proxy/stub DLLs (their own DllRegisterServer, through regsvr32: the
/// 64-bit DLL with the 64-bit regsvr32 of system32, the 32-bit DLL with the 32-bit one of
/// syswow64, each into its own registry view) and the server (/RegServer) in the prefix.
pub fn register(a: &build::Artifacts) -> Result<(), String> {
    let limit = Duration::from_secs(120);
    for (arch, dll) in [(Arch::X64, &a.proxy), (Arch::X86, &a.proxy32)] {
        let status =
            util::run_with_timeout(wine::wine_arch(arch, "regsvr32").arg("/s").arg(dll), limit)?;
        if !status.success() {
            return Err(format!(
                "regsvr32 ({}) {} failed: {status}",
                arch.target(),
                dll.display()
            ));
        }
    }
    // The test double of AsixConnect's XConnect.ServerCT (tests/tests/xconnect.rs): a
    // 32-bit in-process server, so the 32-bit regsvr32 (its DllRegisterServer writes the
    // 32-bit view and registers its type library).
    let status = util::run_with_timeout(
        wine::wine_arch(Arch::X86, "regsvr32")
            .arg("/s")
            .arg(&a.xconnect_double),
        limit,
    )?;
    if !status.success() {
        return Err(format!(
            "regsvr32 ({}) {} failed: {status}",
            Arch::X86.target(),
            a.xconnect_double.display()
        ));
    }
    // The server browser too (OPC.ServerList.1: tests/tests/server_list.rs).
    for exe in [&a.server, &a.server_list] {
        let status = util::run_with_timeout(wine::wine(exe).arg("/RegServer"), limit)?;
        if !status.success() {
            return Err(format!("{} /RegServer failed: {status}", exe.display()));
        }
    }
    println!(
        "test: registered {}, {}, {}, {} and {}",
        a.proxy.display(),
        a.proxy32.display(),
        a.xconnect_double.display(),
        a.server.display(),
        a.server_list.display()
    );
    Ok(())
}

/// Builds tests/thirdparty-client for `arch` (its own target dir, target/thirdparty, so
/// that it builds while cargo's lock of target/ is held; its output to
/// target/thirdparty/build-<triple>.log, printed on failure); returns the exe.
fn thirdparty_build(arch: Arch) -> Result<std::path::PathBuf, String> {
    let root = util::root();
    let target_dir = root.join("target/thirdparty");
    std::fs::create_dir_all(&target_dir).map_err(|e| format!("{}: {e}", target_dir.display()))?;
    let log_path = target_dir.join(format!("build-{}.log", arch.target()));
    let log =
        std::fs::File::create(&log_path).map_err(|e| format!("{}: {e}", log_path.display()))?;
    let err = log
        .try_clone()
        .map_err(|e| format!("{}: {e}", log_path.display()))?;
    util::run(
        util::cargo()
            .args([
                "build",
                "--release",
                "--target",
                arch.target(),
                "--manifest-path",
            ])
            .arg(root.join("tests/thirdparty-client/Cargo.toml"))
            .env("CARGO_TARGET_DIR", &target_dir)
            .stdout(log)
            .stderr(err),
    )
    .map_err(|e| {
        let log = std::fs::read_to_string(&log_path).unwrap_or_default();
        format!("{log}\n{e}")
    })?;
    Ok(target_dir
        .join(arch.target())
        .join("release/thirdparty-client.exe"))
}

/// Runs the third-party client `exe` built for `arch` ([`thirdparty_build`]): an OPC DA
/// client we did not write (the opc_da crate, with bindings from the OPC Foundation's
/// IDL) reads the server's status through our proxy/stub DLL of that bitness.
fn thirdparty_client(arch: Arch, exe: &std::path::Path) -> Result<(), String> {
    println!(
        "test: third-party OPC client (opc_da crate) under Wine, {}",
        arch.target()
    );
    let status = util::run_with_timeout(&mut wine::wine_arch(arch, exe), Duration::from_secs(120))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!(
            "third-party client ({}) failed: {status}",
            arch.target()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The packages a unit names.
    fn packages(units: &[guard::Unit]) -> Vec<String> {
        let mut out: Vec<String> = units
            .iter()
            .filter_map(|u| {
                let i = u.cargo_args.iter().position(|a| a == "-p")?;
                u.cargo_args.get(i + 1).cloned()
            })
            .collect();
        out.sort();
        out.dedup();
        out
    }

    /// Every unit's package and target is in its bitness's one build, each package once,
    /// or the guard's `--no-run` of that selection would not make the unit's executable.
    #[test]
    fn the_windows_build_selects_every_unit_and_the_product() {
        for (arch, units) in [(Arch::X64, units_64().unwrap()), (Arch::X86, units_32())] {
            let sel = selection(arch).unwrap();
            let selected: Vec<&String> = sel
                .windows(2)
                .filter(|w| w[0] == "-p")
                .map(|w| &w[1])
                .collect();
            let mut wanted = packages(&units);
            wanted.extend(
                build::product_packages(arch)
                    .iter()
                    .map(|p| (*p).to_owned()),
            );
            for p in &wanted {
                assert_eq!(
                    selected.iter().filter(|q| **q == p).count(),
                    1,
                    "{p} once at {}: {sel:?}",
                    arch.target()
                );
            }
            for u in &units {
                for a in u.cargo_args.windows(2).filter(|w| w[0] == "--test") {
                    assert!(sel.windows(2).any(|w| w == a), "{a:?} at {}", arch.target());
                }
            }
        }
    }
}
