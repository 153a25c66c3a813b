//! Two native `asix-sim --rest` stations for the end-to-end phase: the Asix.Evo REST
//! data source's test (`tests/tests/rest_source.rs`) reads the demo plant through them
//! from the server under Wine. Started before the end-to-end tests, their base URLs
//! handed over in [`ENV`] (the cargo runner, Wine and the test binaries inherit xtask's
//! environment), stopped when the guard is dropped.

use crate::util;
use std::io::{BufRead, BufReader, Write};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// The environment variable with the stations' base URLs, comma-separated.
pub const ENV: &str = "SERVERCTOPC_TEST_REST";

/// The running stations; dropping it ends them.
pub struct Stations {
    children: Vec<Child>,
}

/// The base URL on asix-sim's ready line (`asix-sim NAME udp=... tcp=... rest=URL`).
pub fn url_of(ready: &str) -> Option<&str> {
    ready
        .split_whitespace()
        .find_map(|w| w.strip_prefix("rest="))
}

/// Where the stations' asix-sim comes from.
pub enum Sim {
    /// Built now (`cargo build --release -p asix-net --bin asix-sim`).
    Build,
    /// The release asix-sim the native tests of the same run built; built now if absent.
    Built,
}

impl Stations {
    /// Starts two stations on loopback serving the demo database; sets [`ENV`] for this
    /// process and its children.
    pub fn start(sim: Sim) -> Result<Stations, String> {
        let built = util::root().join("target/release/asix-sim");
        let exe = match sim {
            Sim::Built if built.is_file() => built,
            _ => crate::build::asix_sim()?,
        };
        let db = util::root().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez");
        let mut s = Stations {
            children: Vec::new(),
        };
        let mut urls = Vec::new();
        for name in ["EVO-A", "EVO-B"] {
            let mut child = Command::new(&exe)
                .args(["--name", name, "--demo-db"])
                .arg(&db)
                .args(["--rest", "127.0.0.1:0"])
                .stdin(Stdio::piped())
                .stdout(Stdio::piped())
                .spawn()
                .map_err(|e| format!("cannot start {}: {e}", exe.display()))?;
            let out = child.stdout.take();
            s.children.push(child);
            let (tx, rx) = mpsc::channel();
            if let Some(out) = out {
                std::thread::spawn(move || {
                    // The ready line, then the rest is drained so that the pipe never fills.
                    for line in BufReader::new(out).lines() {
                        let Ok(line) = line else { break };
                        let _ = tx.send(line);
                    }
                });
            }
            let line = rx
                .recv_timeout(Duration::from_secs(30))
                .map_err(|_| format!("asix-sim {name} did not start (no ready line in 30 s)"))?;
            let url =
                url_of(&line).ok_or_else(|| format!("asix-sim {name}: no rest= in {line:?}"))?;
            urls.push(url.to_owned());
        }
        let v = urls.join(",");
        println!("test: Asix.Evo REST stations for the end-to-end tests: {v} ({ENV})");
        std::env::set_var(ENV, &v);
        Ok(s)
    }
}

impl Drop for Stations {
    fn drop(&mut self) {
        for c in &mut self.children {
            if let Some(stdin) = c.stdin.as_mut() {
                let _ = stdin.write_all(b"quit\n");
                let _ = stdin.flush();
            }
        }
        std::thread::sleep(Duration::from_millis(200));
        for c in &mut self.children {
            let _ = c.kill();
            let _ = c.wait();
        }
        std::env::remove_var(ENV);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_url_comes_from_the_ready_line() {
        assert_eq!(
            url_of("asix-sim EVO-A udp=127.0.0.1:1 tcp=127.0.0.1:2 rest=http://127.0.0.1:3"),
            Some("http://127.0.0.1:3")
        );
        assert_eq!(url_of("asix-sim X udp=a tcp=b"), None);
    }
}
