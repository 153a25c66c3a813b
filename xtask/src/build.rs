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
    /// target/i686-pc-windows-gnu/release: the 32-bit proxy/stub, opcdiag and asix-gate
    /// (32-bit only: AsixConnect's Automation server is a 32-bit in-process DLL).
    pub dir32: PathBuf,
    pub proxy32: PathBuf,
    /// target/i686-pc-windows-gnu/release/xconnect_double.dll: the 32-bit test double of
    /// AsixConnect's Automation server, its type library `xconnect_double.tlb` beside it.
    pub xconnect_double: PathBuf,
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

/// The product's packages at `arch` (the server, the server browser and opcdiag at 64-bit;
/// opcdiag, asix-gate and the test double of `XConnect.ServerCT` at 32-bit), which
/// [`run_for_tests`] builds in one cargo call with the end-to-end tests.
pub fn product_packages(arch: Arch) -> &'static [&'static str] {
    match arch {
        Arch::X64 => &["serverctopc", "opc-server-list", "opc-client"],
        Arch::X86 => &["opc-client", "asix-gate", "xconnect-double"],
    }
}

/// The Windows build of `cargo xtask test` and `cargo xtask e2e`: at each bitness one
/// `cargo build` of the product (its packages' libraries and binaries) together with the
/// end-to-end tests (`tests`: the packages and targets of the tests' one
/// `cargo test --no-run`, `wine/guard.rs`, which lists the product's packages too), then
/// the proxy/stub DLLs and the double's type library.
///
/// Why together: cargo unifies the features of the dependencies of the packages it builds
/// at once, dev-dependencies included once a test is built; a product built alone and
/// tests built alone resolve different features and build the shared dependencies (tokio,
/// rustls, async-opcua, the windows crate) twice. With the same packages, and a test in
/// both, the tests' `--no-run` finds every dependency built. The product so built differs
/// from [`run`]'s only in features that the tests' dev-dependencies turn on (`std` of
/// getrandom, say); `cargo xtask dist` builds with [`run`].
pub fn run_for_tests(tests: &[(Arch, Vec<String>)]) -> Result<Artifacts, String> {
    let root = util::root();
    for (arch, selection) in tests {
        util::run(
            util::cargo()
                .args(["build", "--release", "--target", arch.target()])
                .args(selection.iter().filter(|a| *a != "--lib"))
                .args(["--lib", "--bins"]),
        )?;
    }
    proxy::build_proxy(&root, Arch::X64)?;
    proxy::build_proxy(&root, Arch::X86)?;
    type_library()?;
    Ok(built())
}

pub fn run(_args: &[String]) -> Result<Artifacts, String> {
    let root = util::root();
    // The server is 64-bit only (COM starts it for clients of either bitness); opcdiag
    // is built for both, so that a plant engineer can check what a 32-bit client sees;
    // asix-gate, for the asix station, at 32-bit only.
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
        "-p",
        "asix-gate",
        "--bins",
    ]))?;
    proxy::build_proxy(&root, Arch::X64)?;
    proxy::build_proxy(&root, Arch::X86)?;
    xconnect_double()?;
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
        xconnect_double: Arch::X86.release_dir(&root).join("xconnect_double.dll"),
    }
}

/// Builds the test double of `XConnect.ServerCT` (tests/xconnect-double, a 32-bit
/// in-process server, as the original) and compiles its type library with
/// `i686-w64-mingw32-widl -t` into `xconnect_double.tlb` beside the DLL (where the DLL
/// loads and registers it). widl imports `stdole2.tlb` from Wine's i386 libraries
/// (package libwine:i386, which wine32 brings).
pub fn xconnect_double() -> Result<PathBuf, String> {
    util::run(util::cargo().args([
        "build",
        "--release",
        "--target",
        Arch::X86.target(),
        "-p",
        "xconnect-double",
    ]))?;
    type_library()
}

/// Compiles the double's type library beside its built DLL; the DLL's path.
fn type_library() -> Result<PathBuf, String> {
    let root = util::root();
    let dir = Arch::X86.release_dir(&root);
    let tlb = dir.join("xconnect_double.tlb");
    util::run(
        std::process::Command::new(Arch::X86.widl())
            .args([Arch::X86.widl_m(), "-I/usr/include/wine/wine/windows"])
            .arg("-L/usr/lib/i386-linux-gnu/wine/i386-windows")
            .arg("-t")
            .arg("-o")
            .arg(&tlb)
            .arg(root.join("tests/xconnect-double/xconnect.idl")),
    )?;
    Ok(dir.join("xconnect_double.dll"))
}
