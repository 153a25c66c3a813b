//! A server of a test's own: a configuration folder with the embedded demo database,
//! its log, and the wait for its exit (used by the tests that start a server with their
//! own `[Server]` options through `SERVERCTOPC_INI`).

use crate::other_servers;
use std::path::{Path, PathBuf};
use std::time::Duration;

const DEMO_TABLE: &[u8] = include_bytes!("../../demo/wytwornia_kwasu/atrybuty.csv");
const DEMO_SET: &[u8] = include_bytes!("../../demo/wytwornia_kwasu/wytwornia_kwasu.zez");

/// Writes a configuration (the demo's simulated channel, `server_options` in `[Server]`,
/// `channel_options` in `[Channel:*]`, each a block of `\r\n`-ended lines or empty) with a
/// copy of the demo database into a fresh folder named after `name`: relative paths in
/// it resolve against that folder; the ini is `file` in it. Returns the folder and the
/// ini's path.
pub fn write_demo_config(
    name: &str,
    file: &str,
    server_options: &str,
    channel_options: &str,
) -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("ServerCTOPC-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("demo")).expect("temp config folder");
    std::fs::write(dir.join("demo").join("atrybuty.csv"), DEMO_TABLE).expect("demo table");
    std::fs::write(dir.join("demo").join("wytwornia_kwasu.zez"), DEMO_SET).expect("demo set");
    let ini = format!(
        "; {name}: written by e2e_tests::server_config\r\n\
         [Server]\r\n\
         SimulateCurrentData = tak\r\n\
         LogDirectory = Log\r\n\
         {server_options}\r\n\
         [Channel:*]\r\n\
         ItemsDatabase = demo\\wytwornia_kwasu.zez\r\n\
         {channel_options}"
    );
    let path = dir.join(file);
    std::fs::write(&path, ini).expect("test ini");
    (dir, path)
}

/// Everything the server logged into `dir`'s `Log` folder.
pub fn read_log(dir: &Path) -> String {
    let mut log = String::new();
    if let Ok(entries) = std::fs::read_dir(dir.join("Log")) {
        for e in entries.flatten() {
            log.push_str(&std::fs::read_to_string(e.path()).unwrap_or_default());
        }
    }
    log
}

/// Waits until no ServerCTOPC.exe runs; false after `limit`.
pub fn wait_until_no_server(limit: Duration) -> bool {
    test_support::wait::wait_until(limit, || other_servers(0).is_empty())
}
