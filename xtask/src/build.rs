//! `cargo xtask build`: the Windows artifacts of both bitnesses.

use crate::arch::Arch;
use crate::{proxy, setup, util};
use std::path::PathBuf;

pub struct Artifacts {
    /// target/x86_64-pc-windows-gnu/release: the server, the 64-bit proxy/stub, opcdiag.
    pub dir: PathBuf,
    pub server: PathBuf,
    /// OpcServerList.exe, our OPC.ServerList.1 (64-bit, as the server).
    pub server_list: PathBuf,
    pub proxy: PathBuf,
    /// target/i686-pc-windows-gnu/release: the 32-bit proxy/stub and opcdiag.
    pub dir32: PathBuf,
    pub proxy32: PathBuf,
}

/// Builds the native asix simulator (`asix-sim`, release) for the demo, the soak's `--net`
/// and the end-to-end tests' Asix.Evo REST stations; its path.
pub fn asix_sim() -> Result<std::path::PathBuf, String> {
    util::run(util::cargo().args(["build", "--release", "-p", "asix-net", "--bin", "asix-sim"]))?;
    Ok(util::root().join("target/release/asix-sim"))
}

/// Builds the binary `name` of the crate `tests/` (e2e-tests) for the server's target: the
/// marshal probe, the COM benchmark, the soak client.
pub fn e2e_bin(name: &str) -> Result<(), String> {
    util::run(util::cargo().args([
        "build",
        "--release",
        "--target",
        setup::TARGET,
        "-p",
        "e2e-tests",
        "--bin",
        name,
    ]))
}

pub fn run(_args: &[String]) -> Result<Artifacts, String> {
    let root = util::root();
    // The server is 64-bit only (COM starts it for clients of either bitness); opcdiag
    // is built for both, so that a plant engineer can check what a 32-bit client sees.
    util::run(util::cargo().args([
        "build",
        "--release",
        "--target",
        Arch::X64.target(),
        "-p",
        "serverctopc",
        "-p",
        "opc-server-list",
        "-p",
        "opc-client",
        "--bins",
    ]))?;
    util::run(util::cargo().args([
        "build",
        "--release",
        "--target",
        Arch::X86.target(),
        "-p",
        "opc-client",
        "--bins",
    ]))?;
    proxy::build_proxy(&root, Arch::X64)?;
    proxy::build_proxy(&root, Arch::X86)?;
    Ok(built())
}

/// Where [`run`] puts the artifacts (without building anything: for a step that runs
/// while another holds cargo's build lock, e.g. the background msi-test of `test`).
pub fn built() -> Artifacts {
    let root = util::root();
    let dir = Arch::X64.release_dir(&root);
    Artifacts {
        server: dir.join("ServerCTOPC.exe"),
        server_list: dir.join("OpcServerList.exe"),
        proxy: proxy::dll_path(&root, Arch::X64),
        dir,
        dir32: Arch::X86.release_dir(&root),
        proxy32: proxy::dll_path(&root, Arch::X86),
    }
}
