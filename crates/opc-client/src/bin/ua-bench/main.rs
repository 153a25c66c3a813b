//! `ua-bench`: the load client of `cargo xtask bench --ua` (xtask/src/ua_bench.rs), the
//! same for ServerCTOPC and for the node-opcua peer. async-opcua's client, as opcdiag's.
//!
//! Against one server, one security mode, one user: the walk of the whole browse tree; Read
//! of `--read` values (median of `--runs`); one subscription of `--items` monitored items
//! at `--sampling` ms (creation time, notifications per second delivered, the server's CPU
//! per 1,000 notifications from `/proc/<pid>/stat`, its resident bytes per item from
//! `/proc/<pid>/status`); `--sessions` sessions of `--session-items` items each. Rates are
//! medians of `--windows` windows of `--window-ms`. Each figure is printed as a line
//! `figure NAME VALUE` (read by xtask), with its account on the same line after `#`.
//!
//! Variables are named as `asix_model::synthetic` names them: the alias `T<i, 7 digits>`,
//! in the namespace `urn:askom:ServerCTOPC`, below the object `ServerCTOPC` under Objects.

#[cfg(ua)]
mod bench;

#[cfg(ua)]
fn main() -> std::process::ExitCode {
    bench::main()
}

#[cfg(not(ua))]
fn main() -> std::process::ExitCode {
    eprintln!("ua-bench: built without the OPC UA client (feature `ua`)");
    std::process::ExitCode::FAILURE
}
