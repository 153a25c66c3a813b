//! `cargo xtask demo`: ServerCTOPC serving the demo plant Wytwornia_Kwasu over the asix
//! network, watched with `opcdiag demo`.
//!
//! 1. setup (idempotent), the Windows build (ServerCTOPC.exe, opc_ps.dll, opcdiag.exe)
//!    and the native asix simulator `asix-sim`;
//! 2. a demo install folder target/demo/ServerCTOPC/ as a plant engineer would have it:
//!    the server, the proxy/stub DLL, opcdiag, the demo database and an ASIXConnect.ini
//!    that takes current data from the asix network (SimulateCurrentData = nie), finding
//!    asix-sim on loopback;
//! 3. in a Wine prefix of the demo's own (target/wine/demo-prefix, made on first use):
//!    `regsvr32 opc_ps.dll` and `ServerCTOPC.exe /RegServer` of the staged server;
//! 4. asix-sim in the background serving the demo database; `opcdiag demo` in the
//!    foreground: status, plant tree, live values;
//!    With `--rest` the plant comes from asix-sim's Asix.Evo REST server instead
//!    (`AsixEvoRest` in the basic channel; `docs/asix-evo-rest.md`);
//! 5. on Ctrl+C (or when opcdiag exits, or after `--for SECONDS`): opcdiag is asked to
//!    stop (it removes its group), asix-sim quits (killed if it does not), and
//!    `wineserver -k` ends every Wine process of the demo prefix (the server too).
//!
//! `--ua`: the demo natively, without Wine: `ServerCTOPC serve` (the Linux build) with
//! the demo plant simulated in process, OPC UA on opc.tcp://127.0.0.1:48174 (Basic256Sha256
//! SignAndEncrypt), a user `demo` (role writer, password `demo`) made with `user add
//! --password-stdin`, opcdiag's client certificate trusted with `pki trust`, watched live
//! with `opcdiag --url ... subscribe` (`ua_client.rs` serves it, in target/demo-ua/).
//!
//! Why a prefix of its own: the demo registers the *staged* server (with its network
//! ASIXConnect.ini) as ServerCTOPC.App and ends with `wineserver -k`; in the test prefix
//! that would swap the server under a running `cargo xtask test` and kill it. (`cargo
//! xtask test` registers the build's own exe before its end-to-end tests anyway, so even
//! there a leftover demo registration would not matter; only a concurrent run would.)

use crate::{build, setup, util, wine};
use std::io::{BufRead, BufReader, Write};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

/// The asix network ports of the demo (UDP discovery, TCP data), on loopback only; not
/// the asix defaults (48100/48101), so that a real asix server on this machine does not
/// answer, nor the demo disturb it.
const DISCOVERY_PORT: u16 = 48170;
const DATA_PORT: u16 = 48171;
/// The port of asix-sim's Asix.Evo REST server with `--rest`, on loopback.
const REST_PORT: u16 = 48172;

const USAGE: &str = "\
usage: cargo xtask demo [--for SECONDS] [--rest | --ua]

Builds everything, stages target/demo/ServerCTOPC/ (server, opc_ps.dll, opcdiag, the demo
database, an ASIXConnect.ini reading the plant over the asix network), registers it in the
Wine prefix target/wine/demo-prefix, starts the asix simulator (asix-sim) on loopback and
runs `opcdiag demo`: the server status, the plant tree and live values. Ctrl+C stops
everything; --for SECONDS stops after SECONDS (for a non-interactive run). --rest reads
the plant through asix-sim's Asix.Evo REST server instead of the asix network (the items
are then read-only). --ua runs natively, without Wine: ServerCTOPC serve with the simulated
plant over OPC UA (opc.tcp://127.0.0.1:48174, user demo, password demo, in target/demo-ua/),
watched with `opcdiag --url ... subscribe`.
";

/// The OPC UA demo's endpoint port (loopback), and its user (role writer).
const UA_PORT: u16 = 48174;
const UA_USER: (&str, &str) = ("demo", "demo");

/// What the command line asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Options {
    for_secs: Option<u64>,
    rest: bool,
    ua: bool,
}

pub fn prefix() -> PathBuf {
    util::root().join("target/wine/demo-prefix")
}

/// Options: `--for SECONDS`, `--rest`.
fn parse(args: &[String]) -> Result<Options, String> {
    let mut for_secs = None;
    let mut rest = false;
    let mut ua = false;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--for" => {
                let v = it.next().ok_or("--for needs a number of seconds")?;
                for_secs = Some(
                    v.parse::<u64>()
                        .ok()
                        .filter(|s| *s > 0)
                        .ok_or_else(|| format!("--for: expected whole seconds > 0, got {v:?}"))?,
                );
            }
            "--rest" => rest = true,
            "--ua" => ua = true,
            "-h" | "--help" => {
                print!("{USAGE}");
                std::process::exit(0);
            }
            other => return Err(format!("demo: unknown argument {other:?}\n{USAGE}")),
        }
    }
    if rest && ua {
        return Err(format!("demo: --rest and --ua exclude each other\n{USAGE}"));
    }
    Ok(Options { for_secs, rest, ua })
}

/// The ASIXConnect.ini of the demo install folder (`rest`: the basic channel reads from
/// asix-sim's Asix.Evo REST server).
/// The demo's certificates, in the staged folder: `certs/opc` (the server's, as an asix
/// client) and `certs/asix-sim` (the simulator's), each `asix-cert.pem` + `asix-key.pem`.
const CERTS: &str = "certs";

/// Makes a key pair and certificate with `asix-sim --gen-cert`; returns the fingerprint.
fn gen_cert(sim_exe: &Path, name: &str, dir: &Path) -> Result<String, String> {
    let out = Command::new(sim_exe)
        .args(["--name", name, "--gen-cert"])
        .arg(dir)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", sim_exe.display()))?;
    let text = String::from_utf8_lossy(&out.stdout);
    match text.lines().find_map(|l| l.strip_prefix("fingerprint ")) {
        Some(fp) if out.status.success() => Ok(fp.trim().to_owned()),
        _ => Err(format!(
            "asix-sim --gen-cert {} failed: {}",
            dir.display(),
            String::from_utf8_lossy(&out.stderr)
        )),
    }
}

pub fn ini_text(rest: bool, server_fingerprint: &str) -> String {
    let rest_lines = if rest {
        format!(
            "; The plant through asix-sim's Asix.Evo REST server (read-only items).\nAsixEvoRest = http://127.0.0.1:{REST_PORT}\n"
        )
    } else {
        String::new()
    };
    format!(
        "\
; ASIXConnect.ini written by `cargo xtask demo`: the demo plant Wytwornia_Kwasu, read over
; the asix network from the asix simulator (asix-sim) on this computer.
; Every option: asixconnect.ini.example. Relative paths are relative to this folder.
[Server]
SimulateCurrentData = nie
LogLevel = info
; Discovery goes to loopback only, on the simulator's ports.
BroadcastAddress = 127.0.0.1
DiscoveryPort = {DISCOVERY_PORT}
DataPort = {DATA_PORT}
ReconnectInterval = 1000

[Channel:*]
ItemsDatabase = demo/wytwornia_kwasu/wytwornia_kwasu.zez
CheckLimits = tak
CheckControlVariables = tak
; The asix link: TLS 1.3, this server's certificate, the simulator's pinned (both made by
; `asix-sim --gen-cert` when the demo was staged).
AsixNetCertFile = {CERTS}/opc/asix-cert.pem
AsixNetKeyFile = {CERTS}/opc/asix-key.pem
AsixNetServerFingerprint = {server_fingerprint}
{rest_lines}"
    )
}

fn copy(from: &Path, to: &Path) -> Result<(), String> {
    if let Some(dir) = to.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    std::fs::copy(from, to)
        .map(|_| ())
        .map_err(|e| format!("copy {} to {}: {e}", from.display(), to.display()))
}

/// Stages the demo install folder; returns it.
pub fn stage(a: &build::Artifacts, sim_exe: &Path) -> Result<PathBuf, String> {
    let root = util::root();
    let dir = root.join("target/demo/ServerCTOPC");
    copy(&a.server, &dir.join("ServerCTOPC.exe"))?;
    copy(&a.proxy, &dir.join("opc_ps.dll"))?;
    copy(&a.dir.join("opcdiag.exe"), &dir.join("opcdiag.exe"))?;
    for f in ["atrybuty.csv", "wytwornia_kwasu.zez"] {
        copy(
            &root.join("demo/wytwornia_kwasu").join(f),
            &dir.join("demo/wytwornia_kwasu").join(f),
        )?;
    }
    let certs = dir.join(CERTS);
    let _ = std::fs::remove_dir_all(&certs);
    let sim_fp = gen_cert(sim_exe, "ASIX-SIM", &certs.join("asix-sim"))?;
    gen_cert(sim_exe, "OPC-DEMO", &certs.join("opc"))?;
    std::fs::write(certs.join("asix-sim.fingerprint"), &sim_fp)
        .map_err(|e| format!("{}: {e}", certs.display()))?;
    let ini = dir.join("ASIXConnect.ini");
    std::fs::write(&ini, ini_text(false, &sim_fp))
        .map_err(|e| format!("{}: {e}", ini.display()))?;
    println!(
        "demo: staged {} (asix-sim's certificate {sim_fp})",
        dir.display()
    );
    Ok(dir)
}

/// Registers the proxy/stub DLL and the staged server in the demo prefix.
fn register(pfx: &Path, dir: &Path) -> Result<(), String> {
    let limit = Duration::from_secs(120);
    let dll = dir.join("opc_ps.dll");
    let status = util::run_with_timeout(wine::wine_in(pfx, "regsvr32").arg("/s").arg(&dll), limit)?;
    if !status.success() {
        return Err(format!("regsvr32 {} failed: {status}", dll.display()));
    }
    let exe = dir.join("ServerCTOPC.exe");
    let status = util::run_with_timeout(
        wine::wine_in(pfx, &exe)
            .arg("/RegServer")
            .stdout(Stdio::null()),
        limit,
    )?;
    if !status.success() {
        return Err(format!("{} /RegServer failed: {status}", exe.display()));
    }
    println!(
        "demo: registered opc_ps.dll and {} in {}",
        exe.display(),
        pfx.display()
    );
    Ok(())
}

/// asix-sim running in the background; stopped (quit, else killed) on drop.
pub struct Sim(Child);

impl Sim {
    /// The simulator on the demo's asix ports, serving the database of the staged folder
    /// `dir` with the certificate staged for it.
    pub fn start(exe: &Path, dir: &Path) -> Result<Sim, String> {
        Self::spawn(exe, dir, false)
    }

    /// The same, also serving the Asix.Evo REST API on the demo's REST port.
    fn start_rest(exe: &Path, dir: &Path) -> Result<Sim, String> {
        Self::spawn(exe, dir, true)
    }

    fn spawn(exe: &Path, dir: &Path, rest: bool) -> Result<Sim, String> {
        let db = dir.join("demo/wytwornia_kwasu/wytwornia_kwasu.zez");
        let certs = dir.join(CERTS).join("asix-sim");
        let mut cmd = Command::new(exe);
        cmd.arg("--cert")
            .arg(certs.join("asix-cert.pem"))
            .arg("--key")
            .arg(certs.join("asix-key.pem"));
        cmd.arg("--demo-db").arg(db).args([
            "--udp",
            &format!("127.0.0.1:{DISCOVERY_PORT}"),
            "--tcp",
            &format!("127.0.0.1:{DATA_PORT}"),
        ]);
        if rest {
            cmd.args(["--rest", &format!("127.0.0.1:{REST_PORT}")]);
        }
        let mut child = cmd
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            // Its own process group: Ctrl+C in the terminal reaches xtask and opcdiag, not
            // the simulator, which must keep serving until opcdiag has left.
            .process_group(0)
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", exe.display()))?;
        let (tx, rx) = mpsc::channel();
        if let Some(out) = child.stdout.take() {
            std::thread::spawn(move || {
                for line in BufReader::new(out).lines() {
                    let Ok(line) = line else { break };
                    let _ = tx.send(line);
                }
            });
        }
        let sim = Sim(child);
        // asix-sim prints one line once it listens: "asix-sim NAME udp=... tcp=...".
        match rx.recv_timeout(Duration::from_secs(30)) {
            Ok(line) => {
                println!("demo: {line}");
                Ok(sim)
            }
            Err(_) => {
                Err("asix-sim did not start (no ready line in 30 s; is the port in use?)".into())
            }
        }
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        if let Some(stdin) = self.0.stdin.as_mut() {
            let _ = stdin.write_all(b"quit\n");
            let _ = stdin.flush();
        }
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            match self.0.try_wait() {
                Ok(Some(_)) => return,
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(50))
                }
                _ => break,
            }
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Asks a process to stop as Ctrl+C would (SIGINT; Wine turns it into CTRL_C_EVENT).
fn interrupt(child: &Child) {
    let _ = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .stderr(Stdio::null())
        .status();
}

/// Runs `opcdiag demo` in the foreground until it exits; on Ctrl+C (the flag) or after
/// `limit` it is interrupted, and killed if it has not left 10 s later.
fn run_opcdiag(
    pfx: &Path,
    dir: &Path,
    for_secs: Option<u64>,
    stop: &AtomicBool,
) -> Result<(), String> {
    let exe = dir.join("opcdiag.exe");
    let mut cmd = wine::wine_in(pfx, &exe);
    cmd.arg("demo");
    if let Some(s) = for_secs {
        cmd.args(["--for", &s.to_string()]);
    }
    let mut child = cmd
        .spawn()
        .map_err(|e| format!("cannot start opcdiag.exe: {e}"))?;
    let started = Instant::now();
    // With --for: its time plus Wine's and the server's start (and some slack).
    let limit = for_secs.map(|s| Duration::from_secs(s + 90));
    let mut interrupted_at: Option<Instant> = None;
    loop {
        match child.try_wait() {
            // After Ctrl+C its exit code is no verdict (it may have been stopped early).
            Ok(Some(status))
                if status.success() || interrupted_at.is_some() || stop.load(Ordering::SeqCst) =>
            {
                return Ok(())
            }
            Ok(Some(status)) => return Err(format!("opcdiag demo failed: {status}")),
            Ok(None) => {}
            Err(e) => return Err(format!("waiting for opcdiag: {e}")),
        }
        let overtime = limit.is_some_and(|l| started.elapsed() > l);
        match interrupted_at {
            None if stop.load(Ordering::SeqCst) || overtime => {
                println!("\ndemo: stopping");
                interrupt(&child);
                interrupted_at = Some(Instant::now());
                if overtime {
                    let _ = child.wait();
                    return Err(format!(
                        "opcdiag demo did not end within {} s",
                        limit.map_or(0, |l| l.as_secs())
                    ));
                }
            }
            Some(t) if t.elapsed() > Duration::from_secs(10) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err("opcdiag did not stop within 10 s of Ctrl+C and was killed".into());
            }
            _ => {}
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

pub fn run(args: &[String]) -> Result<(), String> {
    let Options { for_secs, rest, ua } = parse(args)?;
    // Ctrl+C must not end xtask before it has cleaned up: it only raises this flag (the
    // terminal's SIGINT reaches opcdiag too, which stops by itself; with --ua the server
    // as well).
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .map_err(|e| format!("cannot catch Ctrl+C: {e}"))?;
    if ua {
        return run_ua(for_secs, &stop);
    }

    setup::run(&[])?;
    let artifacts = build::run(&[])?;
    let sim_exe = build::asix_sim()?;

    let pfx = prefix();
    wine::ensure_prefix(&pfx)?;
    // A clean start: nothing of an earlier demo may hold the staged files or the ports.
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
    let dir = stage(&artifacts, &sim_exe)?;
    if rest {
        let ini = dir.join("ASIXConnect.ini");
        let fp = std::fs::read_to_string(dir.join(CERTS).join("asix-sim.fingerprint"))
            .map_err(|e| format!("{}: {e}", dir.display()))?;
        std::fs::write(&ini, ini_text(true, &fp)).map_err(|e| format!("{}: {e}", ini.display()))?;
    }
    if stop.load(Ordering::SeqCst) {
        return Err("interrupted".into());
    }

    let mut sim = None;
    let result = (|| {
        register(&pfx, &dir)?;
        sim = Some(if rest {
            Sim::start_rest(&sim_exe, &dir)?
        } else {
            Sim::start(&sim_exe, &dir)?
        });
        println!(
            "demo: starting `opcdiag demo` under Wine{}\n",
            if for_secs.is_none() {
                " (Ctrl+C to stop)"
            } else {
                ""
            }
        );
        run_opcdiag(&pfx, &dir, for_secs, &stop)
    })();
    // The server leaves by itself 3 s after its last client (and logs it); Wine's own
    // services follow. Whatever is still there after 10 s is ended. The simulator goes
    // last, so that the server never sees its asix links drop.
    wine::wineserver_in(&pfx, "-w", Duration::from_secs(10));
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
    drop(sim);
    println!(
        "demo: stopped (Wine processes of {} ended, asix-sim ended)",
        pfx.display()
    );
    result
}

/// `demo --ua`: the plant served natively over OPC UA, watched with `opcdiag --url`.
fn run_ua(for_secs: Option<u64>, stop: &AtomicBool) -> Result<(), String> {
    use crate::ua_client;
    let bins = ua_client::build()?;
    let work = util::root().join("target").join("demo-ua");
    let served = ua_client::Served::start(&bins, &work, UA_PORT)?;
    let (user, password) = UA_USER;
    let ini = work.join("ASIXConnect.ini");
    let added = ua_client::run(
        Command::new(&bins.server)
            .args(["user", "add", user, "--role", "writer", "--password-stdin"])
            .env("SERVERCTOPC_INI", &ini),
        &format!("{password}\n"),
        Duration::from_secs(60),
    )?;
    if !added.status.success() {
        return Err(format!(
            "ServerCTOPC user add {user} failed: {}",
            added.stderr
        ));
    }
    println!(
        "demo: ServerCTOPC serves the plant at {} (log {}); user {user}, password {password}",
        served.url,
        served.log.display()
    );
    if stop.load(Ordering::SeqCst) {
        return Err("interrupted".into());
    }
    let mut cmd = Command::new(&bins.opcdiag);
    cmd.args(["--url", &served.url])
        .arg("--pki")
        .arg(&served.client_pki)
        // The server was made a moment ago by this command, on loopback: its certificate
        // is accepted on first use (and shown).
        .args([
            "--trust-server",
            "accept",
            "--user",
            user,
            "--password-stdin",
        ])
        .arg("subscribe")
        .args(DEMO_ITEMS)
        .args(["--rate", "1000"]);
    if let Some(s) = for_secs {
        cmd.args(["--for", &s.to_string()]);
    }
    println!(
        "demo: `opcdiag --url {} subscribe` natively{}\n",
        served.url,
        if for_secs.is_none() {
            " (Ctrl+C to stop)"
        } else {
            ""
        }
    );
    let mut child = cmd
        .stdin(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start {}: {e}", bins.opcdiag.display()))?;
    if let Some(mut stdin) = child.stdin.take() {
        let _ = writeln!(stdin, "{password}");
    }
    let result = watch(&mut child, for_secs, stop, "opcdiag --url ... subscribe");
    let status = served.stop();
    println!("demo: stopped (ServerCTOPC serve ended: {status:?})");
    result
}

/// The demo's items (tank levels, temperatures, flows, a pump), as `opcdiag demo` follows.
const DEMO_ITEMS: &[&str] = &[
    "KW_A000", "KW_A001", "KW_A020", "KW_D002", "KW_A014", "KW_A100", "KW_A115", "KW_A400",
];

/// Waits for `child` to end: on Ctrl+C (or `for_secs` + 90 s) it is interrupted, killed
/// when it does not end within 10 s of that.
fn watch(
    child: &mut Child,
    for_secs: Option<u64>,
    stop: &AtomicBool,
    what: &str,
) -> Result<(), String> {
    let started = Instant::now();
    let limit = for_secs.map(|s| Duration::from_secs(s + 90));
    let mut interrupted_at: Option<Instant> = None;
    loop {
        match child.try_wait() {
            Ok(Some(status))
                if status.success() || interrupted_at.is_some() || stop.load(Ordering::SeqCst) =>
            {
                return Ok(())
            }
            Ok(Some(status)) => return Err(format!("{what} failed: {status}")),
            Ok(None) => {}
            Err(e) => return Err(format!("waiting for {what}: {e}")),
        }
        let overtime = limit.is_some_and(|l| started.elapsed() > l);
        match interrupted_at {
            None if stop.load(Ordering::SeqCst) || overtime => {
                println!("\ndemo: stopping");
                interrupt(child);
                interrupted_at = Some(Instant::now());
            }
            Some(t) if t.elapsed() > Duration::from_secs(10) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!(
                    "{what} did not stop within 10 s of Ctrl+C and was killed"
                ));
            }
            _ => {}
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FP: &str = "9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08";

    #[test]
    fn the_ini_reads_the_demo_database_over_the_loopback_asix_network() {
        let ini = ini_text(false, FP);
        assert!(!ini.contains("AsixEvoRest"));
        for line in [
            "SimulateCurrentData = nie",
            "BroadcastAddress = 127.0.0.1",
            "DiscoveryPort = 48170",
            "DataPort = 48171",
            "[Channel:*]",
            "ItemsDatabase = demo/wytwornia_kwasu/wytwornia_kwasu.zez",
            "AsixNetCertFile = certs/opc/asix-cert.pem",
            "AsixNetKeyFile = certs/opc/asix-key.pem",
            &format!("AsixNetServerFingerprint = {FP}"),
        ] {
            assert!(ini.lines().any(|l| l == line), "missing {line:?} in\n{ini}");
        }
    }

    #[test]
    fn the_server_loads_the_staged_configuration_without_a_complaint() {
        let dir = std::env::temp_dir().join(format!("xtask-demo-ini-{}", std::process::id()));
        let db = dir.join("demo/wytwornia_kwasu");
        std::fs::create_dir_all(&db).unwrap();
        for f in ["atrybuty.csv", "wytwornia_kwasu.zez"] {
            std::fs::copy(
                util::root().join("demo/wytwornia_kwasu").join(f),
                db.join(f),
            )
            .unwrap();
        }
        std::fs::write(dir.join("ASIXConnect.ini"), ini_text(true, FP)).unwrap();
        let (rest, _) = asix_model::load_config_file(&dir.join("ASIXConnect.ini")).unwrap();
        assert_eq!(
            rest.basic().asix_evo_rest,
            [format!("http://127.0.0.1:{REST_PORT}")]
        );
        std::fs::write(dir.join("ASIXConnect.ini"), ini_text(false, FP)).unwrap();
        let loaded = asix_model::load_config_file(&dir.join("ASIXConnect.ini"));
        let (cfg, warnings) = loaded.unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert!(!cfg.server.simulate_current_data);
        assert_eq!(cfg.basic().asix_net_server_fingerprints, [FP]);
        assert_eq!(cfg.server.broadcast_address.as_deref(), Some("127.0.0.1"));
        assert_eq!(
            (cfg.server.discovery_port, cfg.server.data_port),
            (Some(DISCOVERY_PORT), Some(DATA_PORT))
        );
        let (ns, _) = asix_model::AsixNamespace::load(cfg);
        assert_eq!(ns.no_config_reason(), None, "the demo database loads");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn for_takes_whole_seconds() {
        assert_eq!(parse(&[]), Ok(Options::default()));
        assert_eq!(
            parse(&["--for".into(), "15".into(), "--rest".into()]),
            Ok(Options {
                for_secs: Some(15),
                rest: true,
                ua: false
            })
        );
        assert_eq!(
            parse(&["--ua".into()]),
            Ok(Options {
                for_secs: None,
                rest: false,
                ua: true
            })
        );
        assert!(parse(&["--ua".into(), "--rest".into()]).is_err());
        assert!(parse(&["--for".into(), "0".into()]).is_err());
        assert!(parse(&["--for".into()]).is_err());
        assert!(parse(&["--bogus".into()]).is_err());
    }
}
