//! `cargo xtask build`: the Windows artifacts.

use crate::{proxy, setup::TARGET, util};
use std::path::PathBuf;

pub struct Artifacts {
    pub dir: PathBuf,
    pub server: PathBuf,
    pub proxy: PathBuf,
}

pub fn run(_args: &[String]) -> Result<Artifacts, String> {
    let root = util::root();
    let dir = root.join("target").join(TARGET).join("release");
    util::run(util::cargo().args([
        "build",
        "--release",
        "--target",
        TARGET,
        "-p",
        "serverctopc",
        "-p",
        "opc-client",
        "--bins",
    ]))?;
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let proxy = proxy::build_proxy(&root, &dir)?;
    Ok(Artifacts {
        server: dir.join("ServerCTOPC.exe"),
        proxy,
        dir,
    })
}
