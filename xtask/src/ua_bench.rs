//! `cargo xtask bench --ua`: the OPC UA front end beside a peer server, natively (no Wine).
//!
//! The peer is node-opcua (`xtask/bench/ua-peer/peer.js`, the version pinned in its
//! package.json and package-lock.json, installed by `cargo xtask setup` with `npm ci`)
//! serving the synthetic variable set `asix_model::synthetic` as ServerCTOPC serves it: the
//! same namespace URI, tree, NodeIds and types, values changing every 250 ms (the in-process
//! simulation's tick). ServerCTOPC serves the synthetic database (`scale::synthetic_db`)
//! simulated in process, named by its aliases (`T0000000`...), `MinUpdateRate = 100`,
//! SecurityPolicy None allowed.
//!
//! For each security mode (None, Basic256Sha256 SignAndEncrypt) each server is started fresh
//! and measured by the same load client, `ua-bench` (crates/opc-client/src/bin/ua-bench,
//! async-opcua's client), with one user on both servers: the walk of the whole browse tree,
//! Read of 10,000 values, one session with 100,000 monitored items at 100 ms, 10 sessions
//! of 10,000 items. The figures are printed side by side with the ratios ours/peer and
//! SignAndEncrypt/None. Prints figures; never fails on speed. Every wait has a deadline.

use crate::ua_client::{free_port, run, Run};
use crate::util;
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// The user of both servers.
const USER: &str = "bench";
const PASSWORD: &str = "bench-hasło-1";
/// How long a server may take to listen (node-opcua builds its address space first).
const START_LIMIT: Duration = Duration::from_secs(600);
/// How long one load-client run may take.
const RUN_LIMIT: Duration = Duration::from_secs(30 * 60);

/// The peer's folder (package.json, package-lock.json, peer.js; node_modules once
/// installed).
pub fn peer_dir() -> PathBuf {
    util::root().join("xtask").join("bench").join("ua-peer")
}

/// Installs the peer's pinned packages (`npm ci`) when npm is there and they are not;
/// `Ok(false)`: no npm.
pub fn install_peer() -> Result<bool, String> {
    let dir = peer_dir();
    if util::output(Command::new("npm").arg("--version")).is_err() {
        return Ok(false);
    }
    // npm's record of what it installed (written at install time: the packages' own files
    // carry npm's fixed 1985 timestamps).
    let installed = dir.join("node_modules/.package-lock.json");
    let lock = dir.join("package-lock.json");
    if installed.is_file() && util::up_to_date(&installed, &[lock]) {
        println!("setup: node-opcua present in {}", dir.display());
        return Ok(true);
    }
    println!(
        "setup: npm ci in {} (node-opcua for bench --ua)",
        dir.display()
    );
    util::run(
        Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund"])
            .current_dir(&dir),
    )?;
    Ok(true)
}

struct Options {
    quick: bool,
    /// Use the release binaries as they are (`cargo test --workspace --release` built them).
    built: bool,
    size: usize,
    peer_size: usize,
    client: Vec<String>,
    modes: Vec<&'static str>,
    servers: Vec<&'static str>,
}

fn options(args: &[String]) -> Result<Options, String> {
    let quick = args.iter().any(|a| a == "--quick");
    let mut o = Options {
        quick,
        built: false,
        size: if quick { 2_000 } else { 1_000_000 },
        // The same variables as ours (node-opcua keeps every node in memory: about 4.7 GB
        // subscribed at 1,000,000; `--peer-size` for a smaller machine).
        peer_size: if quick { 2_000 } else { 1_000_000 },
        client: if quick {
            [
                "--read",
                "500",
                "--runs",
                "3",
                "--items",
                "1000",
                "--sessions",
                "2",
                "--session-items",
                "500",
                "--windows",
                "2",
                "--window-ms",
                "500",
                "--settle-s",
                "60",
            ]
            .iter()
            .map(|s| s.to_string())
            .collect()
        } else {
            Vec::new()
        },
        modes: vec!["none", "encrypt"],
        servers: vec!["ours", "peer"],
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = || {
            it.next()
                .cloned()
                .ok_or_else(|| format!("{a} needs a value"))
        };
        let number = |v: String| -> Result<usize, String> {
            v.replace([',', '_'], "")
                .parse()
                .map_err(|e| format!("{a} {v}: {e}"))
        };
        match a.as_str() {
            "--quick" => {}
            "--built" => o.built = true,
            "--size" => o.size = number(value()?)?,
            "--peer-size" => o.peer_size = number(value()?)?,
            "--security" => {
                let v = value()?;
                o.modes = match v.as_str() {
                    "none" => vec!["none"],
                    "encrypt" => vec!["encrypt"],
                    "both" => vec!["none", "encrypt"],
                    _ => return Err(format!("--security {v}: none, encrypt or both")),
                }
            }
            "--only" => {
                let v = value()?;
                o.servers = match v.as_str() {
                    "ours" => vec!["ours"],
                    "peer" => vec!["peer"],
                    _ => return Err(format!("--only {v}: ours or peer")),
                }
            }
            "--read" | "--runs" | "--items" | "--sampling" | "--sessions" | "--session-items"
            | "--windows" | "--window-ms" | "--settle-s" => {
                let v = value()?;
                number(v.clone())?;
                o.client.push(a.clone());
                o.client.push(v);
            }
            "--no-browse" => o.client.push(a.clone()),
            other => return Err(format!("bench --ua: unknown option {other}")),
        }
    }
    Ok(o)
}

/// A server started for one measurement, its output in a log; killed when dropped.
struct Started {
    child: Child,
    pid: u32,
    url: String,
    log: PathBuf,
}

impl Started {
    /// Starts `cmd` and waits for its "listening on" line.
    fn start(mut cmd: Command, log: &Path, port: u16) -> Result<Started, String> {
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start {cmd:?}: {e}"))?;
        let pid = child.id();
        let file = std::fs::File::create(log).map_err(|e| format!("{}: {e}", log.display()))?;
        let (tx, listening) = mpsc::channel();
        for stream in [
            child
                .stdout
                .take()
                .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
            child
                .stderr
                .take()
                .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
        ]
        .into_iter()
        .flatten()
        {
            let tx = tx.clone();
            let mut file = file
                .try_clone()
                .map_err(|e| format!("{}: {e}", log.display()))?;
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines() {
                    let Ok(line) = line else { break };
                    let _ = writeln!(file, "{line}");
                    if line.contains("listening on") {
                        let _ = tx.send(());
                    }
                }
            });
        }
        drop(tx);
        let started = Started {
            child,
            pid,
            url: format!("opc.tcp://127.0.0.1:{port}"),
            log: log.to_owned(),
        };
        match listening.recv_timeout(START_LIMIT) {
            Ok(()) => Ok(started),
            Err(_) => Err(format!(
                "the server did not listen within {} s; its log: {}",
                START_LIMIT.as_secs(),
                log.display()
            )),
        }
    }
}

impl Drop for Started {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.pid.to_string()])
            .status();
        let deadline = std::time::Instant::now() + Duration::from_secs(20);
        while std::time::Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The configuration of ServerCTOPC in the benchmark.
fn ini_text(db: &Path, port: u16) -> String {
    format!(
        "\
; Written by cargo xtask bench --ua: the synthetic database simulated in process, served
; over OPC UA on loopback with SecurityPolicy None allowed.
[Server]
SimulateCurrentData = tak
MinUpdateRate = 100
[Channel:*]
ItemsDatabase = {}
AliasAttributeName = Alias
[UA]
Endpoint = opc.tcp://127.0.0.1:{port}
AllowNone = tak
",
        db.display()
    )
}

struct Programs {
    server: PathBuf,
    client: PathBuf,
}

fn build(built: bool) -> Result<Programs, String> {
    let dir = util::root().join("target").join("release");
    let p = Programs {
        server: dir.join("ServerCTOPC"),
        client: dir.join("ua-bench"),
    };
    if built && p.server.is_file() && p.client.is_file() {
        return Ok(p);
    }
    util::run(util::cargo().args(["build", "--release", "-p", "serverctopc"]))?;
    util::run(util::cargo().args([
        "build",
        "--release",
        "-p",
        "opc-client",
        "--bin",
        "ua-bench",
    ]))?;
    Ok(p)
}

/// ServerCTOPC serving the synthetic database of `size` variables, the bench user added and
/// the load client's certificate trusted.
fn start_ours(
    p: &Programs,
    work: &Path,
    size: usize,
    client_pki: &Path,
) -> Result<Started, String> {
    let db = crate::scale::synthetic_db(size)?.join("synthetic.zez");
    let dir = work.join("ours");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let port = free_port()?;
    let ini = dir.join("ASIXConnect.ini");
    std::fs::write(&ini, ini_text(&db, port)).map_err(|e| format!("{}: {e}", ini.display()))?;
    let server = |args: &[&str], input: &str| -> Result<(), String> {
        let r = run(
            Command::new(&p.server)
                .args(args)
                .env("SERVERCTOPC_INI", &ini),
            input,
            Duration::from_secs(120),
        )?;
        if r.status.success() {
            Ok(())
        } else {
            Err(format!("ServerCTOPC {args:?}: {}{}", r.stdout, r.stderr))
        }
    };
    server(
        &["user", "add", USER, "--role", "reader", "--password-stdin"],
        &format!("{PASSWORD}\n"),
    )?;
    let cert = client_cert(p, client_pki)?;
    server(&["pki", "trust", &cert], "")?;
    let mut cmd = Command::new(&p.server);
    cmd.arg("serve")
        .env("SERVERCTOPC_INI", &ini)
        .env("NO_COLOR", "1");
    Started::start(cmd, &dir.join("serve.log"), port)
}

fn start_peer(work: &Path, size: usize) -> Result<Started, String> {
    let dir = peer_dir();
    let port = free_port()?;
    let pki = work.join("peer-pki");
    let mut cmd = Command::new("node");
    // The heap limit above node's default: the peer's address space at 1,000,000 variables.
    cmd.arg("--max-old-space-size=16384")
        .arg(dir.join("peer.js"))
        .args(["--port", &port.to_string(), "--size", &size.to_string()])
        .arg("--pki")
        .arg(&pki)
        .env("UA_PEER_USER", USER)
        .env("UA_PEER_PASSWORD", PASSWORD);
    Started::start(cmd, &work.join("peer.log"), port)
}

/// The load client's certificate (made at first use).
fn client_cert(p: &Programs, pki: &Path) -> Result<String, String> {
    let r = run(
        Command::new(&p.client)
            .arg("--pki")
            .arg(pki)
            .arg("--make-cert"),
        "",
        Duration::from_secs(120),
    )?;
    if !r.status.success() {
        return Err(format!("ua-bench --make-cert: {}", r.stderr));
    }
    Ok(r.stdout.trim().to_owned())
}

/// The `figure NAME VALUE # account` lines of a load-client run.
fn figures(out: &str) -> BTreeMap<String, (f64, String)> {
    out.lines()
        .filter_map(|l| {
            let rest = l.strip_prefix("figure ")?;
            let (head, account) = rest.split_once(" # ").unwrap_or((rest, ""));
            let (name, value) = head.split_once(' ')?;
            Some((
                name.to_owned(),
                (value.trim().parse().ok()?, account.to_owned()),
            ))
        })
        .collect()
}

type Figures = BTreeMap<String, (f64, String)>;

fn measure(
    p: &Programs,
    o: &Options,
    work: &Path,
    server: &str,
    mode: &str,
) -> Result<Figures, String> {
    let client_pki = work.join("client-pki");
    let started = if server == "ours" {
        start_ours(p, work, o.size, &client_pki)?
    } else {
        start_peer(work, o.peer_size)?
    };
    println!(
        "bench --ua: {server} (pid {}, {} variables), security {mode}",
        started.pid,
        if server == "ours" {
            o.size
        } else {
            o.peer_size
        }
    );
    let mut cmd = Command::new(&p.client);
    cmd.args(["--url", &started.url, "--security", mode, "--user", USER])
        .args(["--pid", &started.pid.to_string()])
        .arg("--pki")
        .arg(&client_pki)
        .args(&o.client);
    let r: Run = run(&mut cmd, &format!("{PASSWORD}\n"), RUN_LIMIT)?;
    print!("{}", r.stdout);
    eprint!("{}", r.stderr);
    if !r.status.success() {
        return Err(format!(
            "ua-bench against {server} ({mode}) failed ({}); the server's log: {}",
            r.status,
            started.log.display()
        ));
    }
    Ok(figures(&r.stdout))
}

/// Which way is better for a figure: `true` when higher is.
fn higher_is_better(name: &str) -> bool {
    name.ends_with("_per_s") || name == "browse_variables"
}

fn fmt(v: Option<f64>) -> String {
    match v {
        Some(v) if v.abs() >= 100.0 => format!("{v:.0}"),
        Some(v) if v.abs() >= 1.0 => format!("{v:.2}"),
        Some(v) => format!("{v:.4}"),
        None => "-".into(),
    }
}

fn ratio(a: Option<f64>, b: Option<f64>) -> String {
    match (a, b) {
        (Some(a), Some(b)) if b != 0.0 => format!("{:.2}", a / b),
        _ => "-".into(),
    }
}

fn table(all: &BTreeMap<(String, String), Figures>, o: &Options) {
    let mut names: Vec<&String> = all.values().flat_map(|f| f.keys()).collect();
    names.sort();
    names.dedup();
    println!();
    println!(
        "bench --ua: ServerCTOPC ({} variables) beside node-opcua ({} variables); ratio = ours/peer",
        o.size, o.peer_size
    );
    for mode in &o.modes {
        println!("\n  security {mode}");
        println!(
            "  {:<28} {:>14} {:>14} {:>10}  better",
            "figure", "ours", "peer", "ratio"
        );
        for name in &names {
            let get = |s: &str| {
                all.get(&(s.to_owned(), mode.to_string()))
                    .and_then(|f| f.get(*name))
                    .map(|v| v.0)
            };
            let (ours, peer) = (get("ours"), get("peer"));
            println!(
                "  {:<28} {:>14} {:>14} {:>10}  {}",
                name,
                fmt(ours),
                fmt(peer),
                ratio(ours, peer),
                if higher_is_better(name) {
                    "higher"
                } else {
                    "lower"
                }
            );
        }
    }
    if o.modes.len() == 2 {
        println!("\n  SignAndEncrypt / None");
        println!("  {:<28} {:>14} {:>14}", "figure", "ours", "peer");
        for name in &names {
            let get = |s: &str, m: &str| {
                all.get(&(s.to_owned(), m.to_owned()))
                    .and_then(|f| f.get(*name))
                    .map(|v| v.0)
            };
            println!(
                "  {:<28} {:>14} {:>14}",
                name,
                ratio(get("ours", "encrypt"), get("ours", "none")),
                ratio(get("peer", "encrypt"), get("peer", "none")),
            );
        }
    }
    // The accounts of the figures, once.
    println!();
    for name in &names {
        if let Some((_, account)) = all.values().find_map(|f| f.get(*name)) {
            println!("  {name}: {account}");
        }
    }
}

pub fn run_bench(args: &[String]) -> Result<(), String> {
    let mut o = options(args)?;
    let p = build(o.built)?;
    let peer_installed = peer_dir()
        .join("node_modules/node-opcua/package.json")
        .is_file();
    if o.servers.contains(&"peer") && !peer_installed && !install_peer()? {
        if !o.quick {
            return Err(format!(
                "node-opcua is not installed in {} and there is no npm: install Debian's \
                 nodejs and npm (cargo xtask setup), or run with --only ours",
                peer_dir().display()
            ));
        }
        println!("bench --ua: no npm, no node-opcua: the quick run measures ServerCTOPC alone");
        o.servers.retain(|s| *s != "peer");
    }
    let work = util::root().join("target").join("ua-bench");
    std::fs::create_dir_all(&work).map_err(|e| format!("{}: {e}", work.display()))?;
    if let Ok(load) = std::fs::read_to_string("/proc/loadavg") {
        println!("bench --ua: load average before: {}", load.trim());
    }
    let mut all = BTreeMap::new();
    for mode in &o.modes {
        for server in &o.servers {
            let f = measure(&p, &o, &work, server, mode)?;
            all.insert((server.to_string(), mode.to_string()), f);
        }
    }
    table(&all, &o);
    if let Ok(load) = std::fs::read_to_string("/proc/loadavg") {
        println!("\nbench --ua: load average after: {}", load.trim());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_are_read_from_the_clients_lines() {
        let f = figures("noise\nfigure read_ms 8.250000 # Read of 10000 values\nfigure x 1\n");
        assert_eq!(f["read_ms"], (8.25, "Read of 10000 values".to_owned()));
        assert_eq!(f["x"].0, 1.0);
        assert_eq!(f.len(), 2);
    }

    #[test]
    fn quick_sizes_are_small_and_options_override_them() {
        let o = options(&["--quick".into(), "--size".into(), "3,000".into()]).unwrap();
        assert_eq!((o.size, o.peer_size), (3000, 2000));
        assert!(o.client.windows(2).any(|w| w == ["--items", "1000"]));
        assert!(options(&["--bogus".into()]).is_err());
        let o = options(&[
            "--security".into(),
            "encrypt".into(),
            "--only".into(),
            "ours".into(),
        ])
        .unwrap();
        assert_eq!((o.modes, o.servers), (vec!["encrypt"], vec!["ours"]));
    }

    #[test]
    fn the_served_configuration_allows_none_and_100_ms() {
        let ini = ini_text(Path::new("/d/s.zez"), 4999);
        for line in [
            "MinUpdateRate = 100",
            "AllowNone = tak",
            "ItemsDatabase = /d/s.zez",
            "AliasAttributeName = Alias",
            "Endpoint = opc.tcp://127.0.0.1:4999",
        ] {
            assert!(ini.lines().any(|l| l == line), "{line}: {ini}");
        }
    }
}
