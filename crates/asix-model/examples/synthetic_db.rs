//! Writes a synthetic variable database (`asix_model::synthetic`) and a ServerCTOPC.ini
//! that serves it, simulated: for measuring a server with many variables by hand, e.g.
//! browse under Wine (`docs/benchmarks.md` says which runs used it).
//!
//! `cargo run --release -p asix-model --example synthetic_db -- N DIR` writes
//! `DIR/synthetic.zez`, `DIR/atrybuty.csv` and `DIR/ServerCTOPC.ini`; the ini names the
//! database by its Wine path (`Z:` and the absolute path), so that it can be handed to
//! the server in `SERVERCTOPC_INI` under Wine.

use asix_model::synthetic::synthetic_database;
use std::path::PathBuf;

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [n, dir] = args.as_slice() else {
        return Err("usage: synthetic_db N DIR".into());
    };
    let n: usize = n
        .replace([',', '_'], "")
        .parse()
        .map_err(|e| format!("N: {e}"))?;
    let dir = std::path::absolute(PathBuf::from(dir)).map_err(|e| format!("{dir}: {e}"))?;
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let g = synthetic_database(n);
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).map_err(|e| format!("{}: {e}", p.display()))
    };
    write("atrybuty.csv", &g.csv)?;
    write("synthetic.zez", &g.zez)?;
    let zez = format!("Z:{}", dir.join("synthetic.zez").display()).replace('/', "\\");
    write(
        "ServerCTOPC.ini",
        &format!(
            "; Written by asix-model's synthetic_db example: {n} synthetic variables, simulated.\r\n\
             [Server]\r\nSimulateCurrentData = tak\r\nLogLevel = warn\r\n\
             [Channel:*]\r\nItemsDatabase = {zez}\r\n"
        ),
    )?;
    println!("{n} variables in {}", dir.display());
    Ok(())
}
