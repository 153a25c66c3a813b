//! Project automation, reached as `cargo xtask <command>` (alias in .cargo/config.toml).
//! std only (plus the small `ctrlc` crate for the demo's Ctrl+C), so that it compiles in
//! seconds on a fresh machine.

mod arch;
mod bench;
mod build;
mod demo;
mod dist;
mod fuzz;
mod msi;
mod proxy;
mod rest_stations;
mod scale;
mod setup;
mod soak;
mod test;
mod ua;
mod ua_bench;
mod ua_client;
mod util;
mod wine;

use std::process::ExitCode;

const USAGE: &str = "\
usage: cargo xtask <command>

commands:
  setup   install what the build and tests need on Debian 12 (apt packages, the
          rustup target, the bcryptprimitives shim, a Wine prefix under target/wine);
          idempotent: skips what exists
  build   build the Windows artifacts: ServerCTOPC.exe, opc_ps.dll and opcdiag.exe into
          target/x86_64-pc-windows-gnu/release, the 32-bit opc_ps.dll and opcdiag.exe
          into target/i686-pc-windows-gnu/release
  test    native `cargo test` of every host crate, then the Wine end-to-end tests
          (64-bit client, then most of them again as a 32-bit client)
  e2e     the Windows build, registration, then only the Wine tests named by its
          cargo arguments, e.g. `cargo xtask e2e -p e2e-tests --test group_io`
          (default `-p e2e-tests -p ctopc-com`; after `--`, test-binary arguments);
          `e2e --x86 [ARGS...]` runs them as a 32-bit client (default: the e2e files
          `cargo xtask test` runs at 32-bit)
  demo    the server with the demo plant Wytwornia_Kwasu, read over the asix network from
          the asix simulator, watched with `opcdiag demo` (status, plant tree, live
          values) in a Wine prefix of its own; Ctrl+C stops everything; `--for SECONDS`
          stops after SECONDS; `--ua`: natively, no Wine: ServerCTOPC serve with the
          simulated plant over OPC UA, watched with `opcdiag --url ... subscribe`
  ua-interop  the OPC UA front end natively against Python asyncua (venv
          target/ua-venv): ServerCTOPC serve with the simulated demo plant over
          Basic256Sha256 SignAndEncrypt; browse, read, write, subscribe, users and roles,
          anonymous, None and an untrusted certificate refused; then the same through
          `opcdiag --url` (also part of `test`; `--opcdiag-only`: only that part)
  proxy   build only the proxy/stub DLLs from idl/ (64-bit and 32-bit)
  dist    target/dist/ServerCTOPC-<version>.zip and ServerCTOPC-<version>-x64.msi
          (installer/, xtask/src/msi.rs; needs wixl): server, proxy/stub, opcdiag (the last
          two also 32-bit, in x86/), example configuration, demo database, deployment
          guide and docs
  msi-test  the MSI under Wine, each part in a fresh prefix (a copy of
          target/wine/msi-template): a broken package fails and leaves nothing; silent
          install, a 64-bit and a 32-bit opcdiag status, write, read back, subscribe
          and servers; a major upgrade with SERVICE=1 keeps a modified ASIXConnect.ini,
          installs the service and still serves; silent uninstall leaves no keys (both
          views), service or files (also part of `test`, beside its e2e tests);
          `--built`: use the Windows build as it is (no cargo build)
  fuzz    every fuzz target of fuzz/ for `--seconds N` each (default 10): under
          libFuzzer with cargo-fuzz and a nightly, else (or with `--stable`) the stable
          random-mutation runner; targets may be named
  soak    the memory soak (not in CI): one client holds the server while rounds of
          clients churn (connect, add, read, write, subscribe, disconnect); the
          server's resident memory sampled from /proc, the slope after warm-up beside
          the slope Wine's [in]-array leak predicts (docs/wine-ndr-leak.md);
          `--minutes M`, `--clients K`, `--items N`, `--round-seconds R`, `--calls
          LIST` (add,validate,read,device,write,itemio,subscribe,remove) or
          `--no-in-arrays`, `--ids all`; `--load`: 20 clients x 1,000 demo items, cache
          and device reads, subscribe, leave, three 60 s rounds; fails on any failed
          device read
  bench   build, register and run the COM benchmark (bench-com.exe) under Wine in a
          prefix of its own; prints figures (medians, ratios to a null round trip,
          goals) and never fails on speed; `--quick` for a short run.
          `bench --scale`: the server with synthetic databases of many variables
          (xtask/src/scale.rs): start time, resident memory per variable, flat and
          tree browse, AddItems, memory per group item and of an active subscription,
          a soak; medians beside the demo's; `--sizes 100000,1000000`, `--runs 3`,
          `--items 100000`, `--soak-minutes 10`, `--only load|browse|items|soak`.
          `bench --ua`: natively, no Wine: ServerCTOPC serve (synthetic database of
          `--size` variables, default 1000000) beside a node-opcua peer (`--peer-size`,
          default 100000; xtask/bench/ua-peer), measured by one async-opcua load client
          (ua-bench): tree browse, Read of 10,000 values, 100,000 monitored items at
          100 ms, 10 sessions x 10,000 items, with None and SignAndEncrypt; ratios
          ours/peer; `--quick` (a few seconds), `--security none|encrypt|both`, `--only
          ours|peer`, `--items N`, `--read N`, `--runs N`, `--sessions N`,
          `--session-items N`, `--windows N`, `--window-ms MS`, `--no-browse`
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(cmd) = args.first() else {
        eprint!("{USAGE}");
        return ExitCode::from(2);
    };
    let rest = &args[1..];
    let result = match cmd.as_str() {
        "setup" => setup::run(rest),
        "build" => build::run(rest).map(|_| ()),
        "test" => test::run(rest),
        "e2e" => test::e2e(rest),
        "demo" => demo::run(rest),
        "dist" => dist::run(rest),
        "msi-test" => msi::test(rest),
        "bench" => bench::run(rest),
        "fuzz" => fuzz::run(rest),
        "soak" => soak::run(rest),
        "ua-interop" => ua::run(rest),
        "proxy" => proxy::build_both(&util::root()).map(|dlls| {
            for p in dlls {
                println!("built {}", p.display());
            }
        }),
        "help" | "--help" | "-h" => {
            print!("{USAGE}");
            Ok(())
        }
        other => Err(format!("unknown command `{other}`\n{USAGE}")),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: error: {e}");
            ExitCode::FAILURE
        }
    }
}
