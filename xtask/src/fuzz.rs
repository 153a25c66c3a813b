//! `cargo xtask fuzz [--seconds N] [--stable | --built] [TARGET...]`: every fuzz target of
//! `fuzz/` (crate `ctopc-fuzz`) for N seconds each (default 10).
//!
//! With cargo-fuzz and a nightly toolchain (`cargo +nightly fuzz --version` works), each
//! target runs under libFuzzer, coverage-guided, with its corpus in `fuzz/corpus/<target>`
//! (kept between runs, not committed) and crashes in `fuzz/artifacts/<target>/`. Without
//! them (a machine has only its one stable toolchain) — or with `--stable` — the stable
//! runner `fuzz-random` mutates the targets' seeds with a seeded PRNG and catches
//! panics; a failing input lands in `target/fuzz-failures/`. cargo-fuzz is not installed
//! here: `cargo install cargo-fuzz` once, where crates.io and a nightly are reachable.
//! `cargo xtask test` runs the stable runner for [`CI_SECONDS`] per target, `--built`:
//! the runner its native tests built, not through `cargo run`.

use crate::util;
use std::process::Command;
use std::time::Duration;

/// Seconds per target in `cargo xtask test` (fifteen targets: about a minute with the build).
pub const CI_SECONDS: u32 = 3;

/// The targets, as `fuzz/src/lib.rs` lists them (checked by `fuzz`'s own test).
const TARGETS: &[&str] = &[
    "asix_frame",
    "asix_datagram",
    "ini",
    "csv_attributes",
    "paradox",
    "zez_varset",
    "item_id",
    "match_pattern",
    "format",
    "value_convert",
    "asix_rest_answer",
    "ua_request",
    "ua_variant",
    "ua_users",
    "ua_node_id",
];

pub fn run(args: &[String]) -> Result<(), String> {
    let mut seconds: u32 = 10;
    let mut stable = false;
    let mut built = false;
    let mut names: Vec<String> = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--seconds" => {
                seconds = it
                    .next()
                    .and_then(|s| s.parse().ok())
                    .ok_or("--seconds needs a whole number")?;
            }
            "--stable" => stable = true,
            "--built" => {
                stable = true;
                built = true;
            }
            t if TARGETS.contains(&t) => names.push(t.to_owned()),
            other => {
                return Err(format!(
                    "fuzz: unknown argument `{other}` (targets: {})",
                    TARGETS.join(", ")
                ))
            }
        }
    }
    if !stable && libfuzzer_available() {
        libfuzzer(seconds, &names)
    } else {
        if !stable {
            println!(
                "fuzz: no cargo-fuzz with a nightly toolchain here; the stable runner instead"
            );
        }
        stable_runner(seconds, &names, built)
    }
}

/// `cargo +nightly fuzz --version` succeeds.
fn libfuzzer_available() -> bool {
    Command::new("cargo")
        .args(["+nightly", "fuzz", "--version"])
        .current_dir(util::root())
        .output()
        .is_ok_and(|o| o.status.success())
}

fn libfuzzer(seconds: u32, names: &[String]) -> Result<(), String> {
    let root = util::root();
    for t in TARGETS
        .iter()
        .filter(|t| names.is_empty() || names.iter().any(|n| n == *t))
    {
        println!("fuzz: {t} under libFuzzer for {seconds} s");
        let corpus = root.join("fuzz/corpus").join(t);
        std::fs::create_dir_all(&corpus).map_err(|e| format!("{}: {e}", corpus.display()))?;
        let mut c = Command::new("cargo");
        c.current_dir(&root).args([
            "+nightly",
            "fuzz",
            "run",
            "--fuzz-dir",
            "fuzz",
            "--features",
            "libfuzzer",
            "--sanitizer",
            "none",
            "--release",
            t,
        ]);
        c.arg(&corpus);
        // The demo plant's files seed the text decoders (read, never written, by libFuzzer).
        if matches!(*t, "ini" | "csv_attributes" | "zez_varset") {
            c.arg(root.join("demo/wytwornia_kwasu"));
        }
        // The committed pxlib table seeds the Paradox reader.
        if *t == "paradox" {
            c.arg(root.join("crates/asix-model/tests/paradox"));
        }
        c.arg("--")
            .arg(format!("-max_total_time={seconds}"))
            .arg("-rss_limit_mb=2048")
            .arg("-timeout=5");
        let limit = Duration::from_secs(u64::from(seconds) + 900);
        let status = util::run_with_timeout(&mut c, limit)?;
        if !status.success() {
            return Err(format!(
                "fuzz target {t} failed ({status}): the input is in fuzz/artifacts/{t}/; \
                 fix it and keep the input in fuzz/regressions/{t}/"
            ));
        }
    }
    Ok(())
}

/// The stable runner; `built`: the `target/release/fuzz-random` that `cargo test
/// --workspace --release` built (the package has integration tests, so its binaries are
/// built with them) run as it is, for `cargo run -p ctopc-fuzz` alone would resolve the
/// package's features apart from the workspace's and build its dependencies again
/// (async-opcua, tokio, rustls: minutes).
fn stable_runner(seconds: u32, names: &[String], built: bool) -> Result<(), String> {
    let mut c = if built {
        let exe = util::root().join("target/release/fuzz-random");
        if !exe.is_file() {
            return Err(format!(
                "fuzz --built: {} is not built (cargo test --workspace --release builds it)",
                exe.display()
            ));
        }
        let mut c = Command::new(exe);
        c.current_dir(util::root());
        c
    } else {
        let mut c = util::cargo();
        c.args([
            "run",
            "--release",
            "--quiet",
            "-p",
            "ctopc-fuzz",
            "--bin",
            "fuzz-random",
            "--",
        ]);
        c
    };
    c.arg("--seconds").arg(seconds.to_string()).args(names);
    util::run(&mut c).map_err(|e| {
        format!(
            "{e}\nfuzz: a target failed; the input is in target/fuzz-failures/: fix it and \
             keep the input in fuzz/regressions/<target>/"
        )
    })
}
