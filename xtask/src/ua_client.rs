//! opcdiag's OPC UA client against the native `ServerCTOPC serve`: the test scenario of
//! `cargo xtask ua-interop` (after the asyncua one) and the server of `cargo xtask demo
//! --ua`.
//!
//! [`Served`] runs `ServerCTOPC serve` natively with the demo plant simulated in process
//! (a configuration of its own in a work folder, users made with `user add
//! --password-stdin`, opcdiag's client certificate trusted with `pki trust`). Every wait
//! waits on output (the server's "listening" line, a process's end) with a deadline; nothing
//! sleeps.

use crate::util;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// The users made in every served configuration: (name, role, password).
pub const USERS: &[(&str, &str, &str)] = &[
    ("writer1", "writer", "pisarz-hasło-1"),
    ("reader1", "reader", "czytelnik-hasło-2"),
];
/// How long the server may take to listen, and an opcdiag run to end.
const START_LIMIT: Duration = Duration::from_secs(120);
const RUN_LIMIT: Duration = Duration::from_secs(60);

/// The server and opcdiag, native.
pub struct Binaries {
    pub server: PathBuf,
    pub opcdiag: PathBuf,
}

/// Builds `ServerCTOPC` and `opcdiag` natively in the dev profile, in two cargo runs: the
/// server's as `ua-interop` builds it (the same features, so nothing is built twice).
pub fn build() -> Result<Binaries, String> {
    util::run(util::cargo().args(["build", "-p", "serverctopc"]))?;
    util::run(util::cargo().args(["build", "-p", "opc-client", "--bin", "opcdiag"]))?;
    let dir = util::root().join("target").join("debug");
    Ok(Binaries {
        server: dir.join("ServerCTOPC"),
        opcdiag: dir.join("opcdiag"),
    })
}

/// The configuration of a served demo plant: simulated in process, UA on `port` (loopback).
pub fn ini_text(db: &Path, port: u16) -> String {
    format!(
        "\
; Written by cargo xtask (OPC UA, native): the demo plant Wytwornia_Kwasu simulated in
; process, served over OPC UA on loopback. pki/ and ua-users.txt are beside this file.
[Server]
SimulateCurrentData = tak
[Channel:*]
ItemsDatabase = {}
[UA]
Endpoint = opc.tcp://127.0.0.1:{port}
",
        db.display()
    )
}

/// What a finished process said.
pub struct Run {
    pub status: ExitStatus,
    pub stdout: String,
    pub stderr: String,
}

impl Run {
    pub fn code(&self) -> i32 {
        self.status.code().unwrap_or(-1)
    }
}

/// Runs `cmd` with `input` on its standard input; ends it after `limit`.
pub fn run(cmd: &mut Command, input: &str, limit: Duration) -> Result<Run, String> {
    let mut child = cmd
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start {cmd:?}: {e}"))?;
    if let Some(mut stdin) = child.stdin.take() {
        let _ = stdin.write_all(input.as_bytes());
    }
    let pid = child.id();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    match rx.recv_timeout(limit) {
        Ok(Ok(out)) => Ok(Run {
            status: out.status,
            stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
            stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        }),
        Ok(Err(e)) => Err(format!("{cmd:?}: {e}")),
        Err(_) => {
            signal(pid, "KILL");
            Err(format!("{cmd:?} did not end within {} s", limit.as_secs()))
        }
    }
}

fn signal(pid: u32, sig: &str) {
    let _ = Command::new("kill")
        .args([&format!("-{sig}"), &pid.to_string()])
        .stderr(Stdio::null())
        .status();
}

/// A free loopback port (the system's choice).
pub fn free_port() -> Result<u16, String> {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| format!("no free port: {e}"))
}

/// `ServerCTOPC serve` with the demo plant, its users, and opcdiag's certificate trusted.
pub struct Served {
    pub url: String,
    /// opcdiag's PKI folder (`--pki`).
    pub client_pki: PathBuf,
    pub log: PathBuf,
    pid: u32,
    ended: mpsc::Receiver<ExitStatus>,
}

impl Served {
    /// Writes the configuration in `work` (emptied first), adds [`USERS`], makes and
    /// trusts opcdiag's certificate, starts `serve` and waits for it to listen.
    pub fn start(bins: &Binaries, work: &Path, port: u16) -> Result<Served, String> {
        let root = util::root();
        let db = root.join("demo/wytwornia_kwasu/wytwornia_kwasu.zez");
        let _ = std::fs::remove_dir_all(work);
        std::fs::create_dir_all(work).map_err(|e| format!("{}: {e}", work.display()))?;
        let ini = work.join("ASIXConnect.ini");
        std::fs::write(&ini, ini_text(&db, port)).map_err(|e| format!("{}: {e}", ini.display()))?;
        let server = |args: &[&str], input: &str| -> Result<(), String> {
            let r = run(
                Command::new(&bins.server)
                    .args(args)
                    .env("SERVERCTOPC_INI", &ini),
                input,
                RUN_LIMIT,
            )?;
            if r.status.success() {
                Ok(())
            } else {
                Err(format!(
                    "ServerCTOPC {args:?} failed: {}{}",
                    r.stdout, r.stderr
                ))
            }
        };
        for (name, role, password) in USERS {
            server(
                &["user", "add", name, "--role", role, "--password-stdin"],
                &format!("{password}\n"),
            )?;
        }
        let client_pki = work.join("opcdiag-pki");
        let cert = run(
            Command::new(&bins.opcdiag)
                .arg("cert")
                .arg("--pki")
                .arg(&client_pki),
            "",
            RUN_LIMIT,
        )?;
        let cert_file = cert
            .stdout
            .lines()
            .find_map(|l| l.strip_prefix("Certificate"))
            .map(|f| f.trim().to_owned())
            .ok_or_else(|| format!("opcdiag cert printed no certificate: {}", cert.stderr))?;
        server(&["pki", "trust", &cert_file], "")?;

        let log = work.join("serve.log");
        let mut child = Command::new(&bins.server)
            .arg("serve")
            .env("SERVERCTOPC_INI", &ini)
            .env("NO_COLOR", "1")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", bins.server.display()))?;
        let pid = child.id();
        // Both streams into the log; the "listening" line is reported as it passes.
        let (listening_tx, listening) = mpsc::channel();
        let file = std::fs::File::create(&log).map_err(|e| format!("{}: {e}", log.display()))?;
        let streams: Vec<Box<dyn std::io::Read + Send>> = [
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
        .collect();
        for stream in streams {
            let tx = listening_tx.clone();
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
        drop(listening_tx);
        let (ended_tx, ended) = mpsc::channel();
        std::thread::spawn(move || {
            if let Ok(status) = child.wait() {
                let _ = ended_tx.send(status);
            }
        });
        let served = Served {
            url: format!("opc.tcp://127.0.0.1:{port}"),
            client_pki,
            log: log.clone(),
            pid,
            ended,
        };
        match listening.recv_timeout(START_LIMIT) {
            Ok(()) => Ok(served),
            Err(_) => Err(format!(
                "ServerCTOPC serve did not listen on port {port} within {} s; its log: {}",
                START_LIMIT.as_secs(),
                log.display()
            )),
        }
    }

    /// Stops the server (SIGTERM, then SIGKILL after 20 s); its exit status.
    pub fn stop(&self) -> Option<ExitStatus> {
        signal(self.pid, "TERM");
        match self.ended.recv_timeout(Duration::from_secs(20)) {
            Ok(status) => Some(status),
            Err(_) => {
                signal(self.pid, "KILL");
                self.ended.recv_timeout(Duration::from_secs(5)).ok()
            }
        }
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        if self.ended.try_recv().is_err() {
            let _ = self.stop();
        }
    }
}

/// The password of one of [`USERS`].
pub fn password(user: &str) -> &'static str {
    USERS
        .iter()
        .find(|(name, _, _)| *name == user)
        .map_or("", |(_, _, p)| p)
}

/// The thumbprint opcdiag names in its message about an untrusted server certificate.
pub fn thumbprint_in(message: &str) -> Option<&str> {
    let at = message.find("--trust-server ")? + "--trust-server ".len();
    let t = message.get(at..at + 40)?;
    t.chars().all(|c| c.is_ascii_hexdigit()).then_some(t)
}

/// The scenario: opcdiag against the served demo plant over Basic256Sha256
/// SignAndEncrypt. Prints `ok`/`FAIL` per check; `Err` when one failed.
/// The release binaries of the scenario: those `cargo test --workspace --release` built
/// (`built`: the server's and opcdiag's command-line tests need them), else built here.
fn release_binaries(built: bool) -> Result<Binaries, String> {
    let dir = util::root().join("target").join("release");
    let bins = Binaries {
        server: dir.join("ServerCTOPC"),
        opcdiag: dir.join("opcdiag"),
    };
    if built && bins.server.exists() && bins.opcdiag.exists() {
        return Ok(bins);
    }
    util::run(util::cargo().args(["build", "--release", "-p", "serverctopc"]))?;
    util::run(util::cargo().args(["build", "--release", "-p", "opc-client", "--bin", "opcdiag"]))?;
    Ok(bins)
}

pub fn scenario(built: bool) -> Result<(), String> {
    let bins = release_binaries(built)?;
    let work = util::root().join("target").join("ua-client");
    let served = Served::start(&bins, &work, free_port()?)?;
    let mut checks = Checks::default();
    let result = checks_against(&bins, &served, &mut checks);
    let status = served.stop();
    checks.check(
        "serve stops on SIGTERM with exit code 0",
        status.is_some_and(|s| s.success()),
        &format!("{status:?}"),
    );
    result?;
    println!(
        "ua-client: {} passed, {} failed",
        checks.passed, checks.failed
    );
    if checks.failed > 0 {
        return Err(format!(
            "the opcdiag OPC UA test failed; the server's log: {}",
            served.log.display()
        ));
    }
    Ok(())
}

#[derive(Default)]
struct Checks {
    passed: usize,
    failed: usize,
}

impl Checks {
    fn check(&mut self, name: &str, ok: bool, detail: &str) {
        if ok {
            self.passed += 1;
            println!("ok   {name}");
        } else {
            self.failed += 1;
            println!("FAIL {name}: {detail}");
        }
    }

    /// Checks the exit code of `r` and that its stdout (`out`) or stderr (`err`) holds
    /// each of `wanted`.
    fn run(&mut self, name: &str, r: &Run, code: i32, wanted: &[&str]) {
        let all = format!("{}{}", r.stdout, r.stderr);
        let missing: Vec<&&str> = wanted.iter().filter(|w| !all.contains(**w)).collect();
        self.check(
            name,
            r.code() == code && missing.is_empty(),
            &format!(
                "exit code {} (wanted {code}), missing {missing:?}; stdout:\n{}stderr:\n{}",
                r.code(),
                r.stdout,
                r.stderr
            ),
        );
    }
}

fn checks_against(bins: &Binaries, s: &Served, c: &mut Checks) -> Result<(), String> {
    let opcdiag = |user: Option<&str>, password: &str, args: &[&str]| -> Result<Run, String> {
        let mut cmd = Command::new(&bins.opcdiag);
        cmd.args(["--url", &s.url]).arg("--pki").arg(&s.client_pki);
        if let Some(u) = user {
            cmd.args(["--user", u, "--password-stdin"]);
        }
        cmd.args(args);
        run(&mut cmd, &format!("{password}\n"), RUN_LIMIT)
    };
    let as_user = |user: &str, args: &[&str]| opcdiag(Some(user), password(user), args);

    // 1. The server's certificate: unknown, so refused (and saved in rejected/).
    let r = as_user("writer1", &["read", "KW_A000"])?;
    c.run(
        "an untrusted server certificate is refused (exit 3)",
        &r,
        3,
        &["the server's certificate is not trusted", "--trust-server"],
    );
    let rejected = std::fs::read_dir(s.client_pki.join("rejected")).map_or(0, |d| d.count());
    c.check(
        "the refused server certificate is saved in rejected/",
        rejected == 1,
        &format!("{rejected} files"),
    );
    let Some(thumbprint) = thumbprint_in(&r.stderr).map(str::to_owned) else {
        c.check("the refusal names the thumbprint", false, &r.stderr);
        return Ok(());
    };
    let wrong = "0".repeat(40);
    let r = as_user("writer1", &["--trust-server", &wrong, "read", "KW_A000"])?;
    c.run(
        "a certificate other than the pinned one is refused",
        &r,
        3,
        &["not the one pinned"],
    );

    // 2. Pinned: read, then the next runs trust it without the option.
    let r = as_user(
        "writer1",
        &[
            "--trust-server",
            &thumbprint,
            "read",
            "KW_A000",
            "ns=2;s=KW_A001",
        ],
    )?;
    c.run(
        "pinned: read by item ID and by NodeId, Float, Good, timestamps",
        &r,
        0,
        &[
            "KW_A000  ",
            "  Float  Good  ",
            "(server 20",
            "ns=2;s=KW_A001  ",
        ],
    );
    let r = as_user("reader1", &["read", "NO_SUCH_ITEM"])?;
    c.run(
        "an unknown item is BadNodeIdUnknown (exit 1)",
        &r,
        1,
        &["NO_SUCH_ITEM  error BadNodeIdUnknown (0x80340000)"],
    );

    // 3. Browse: in pages of 2 references (BrowseNext), two levels, and flat.
    let r = as_user("reader1", &["browse", "--page", "2", "--depth", "2"])?;
    c.run(
        "browse in pages of 2 with BrowseNext: the plant's groups, two levels",
        &r,
        0,
        &[
            "Magazyn siarki/\n  Zbiornik siarki ciekłej Z101/\n",
            "Diagnostyka/\n",
        ],
    );
    let r = as_user("reader1", &["browse", "--flat", "--page", "7"])?;
    c.run(
        "browse --flat lists the variables by item ID",
        &r,
        0,
        &["KW_A000\nKW_A001\nKW_A002\n"],
    );

    // 4. Write as the writer (read back), refused for the reader and a read-only variable.
    let r = as_user("writer1", &["write", "KW_A110", "12.5"])?;
    c.run(
        "write as the writer",
        &r,
        0,
        &["KW_A110: written 12.5 (Float): OK"],
    );
    let r = as_user("reader1", &["read", "KW_A110", "--device"])?;
    c.run(
        "the written value reads back",
        &r,
        0,
        &["KW_A110  12.5  Float  Good"],
    );
    let r = as_user("reader1", &["write", "KW_A110", "3"])?;
    c.run(
        "the reader's write is refused: BadUserAccessDenied and why (exit 1)",
        &r,
        1,
        &["write 3 (Float) failed: BadUserAccessDenied", "role"],
    );
    let r = as_user("writer1", &["write", "KW_A000", "1"])?;
    c.run(
        "a read-only variable: BadNotWritable (exit 1)",
        &r,
        1,
        &["BadNotWritable", "read-only"],
    );
    let r = as_user("writer1", &["write", "KW_A110", "x"])?;
    c.run(
        "a value that is no Float: exit 2",
        &r,
        2,
        &["not a valid value"],
    );

    // 5. Subscribe until 3 changes have arrived.
    let r = as_user(
        "reader1",
        &[
            "subscribe",
            "KW_A001",
            "--rate",
            "200",
            "--count",
            "3",
            "--seconds",
            "30",
        ],
    )?;
    c.run(
        "subscribe --count 3: three changes, then the end",
        &r,
        0,
        &["Subscribed to 1 item(s)", "KW_A001  ", "3 change(s) in"],
    );

    // 6. What is refused: a wrong password, anonymous, SecurityPolicy None.
    let r = opcdiag(Some("writer1"), "not the password", &["read", "KW_A000"])?;
    c.run(
        "a wrong password is refused (exit 3)",
        &r,
        3,
        &["refused user writer1: wrong user name or password"],
    );
    let r = opcdiag(None, "", &["read", "KW_A000"])?;
    c.run(
        "anonymous is refused (exit 3)",
        &r,
        3,
        &["anonymous", "--user"],
    );
    let r = as_user("writer1", &["--security", "none", "read", "KW_A000"])?;
    c.run(
        "SecurityPolicy None is refused (exit 3)",
        &r,
        3,
        &["offers no endpoint with None"],
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_served_configuration_simulates_the_plant_on_loopback() {
        let ini = ini_text(Path::new("/d/w.zez"), 4841);
        for line in [
            "SimulateCurrentData = tak",
            "ItemsDatabase = /d/w.zez",
            "Endpoint = opc.tcp://127.0.0.1:4841",
        ] {
            assert!(ini.lines().any(|l| l == line), "{line}: {ini}");
        }
    }

    #[test]
    fn the_thumbprint_is_read_from_opcdiags_refusal() {
        let t = "0e2c62d1ef56df9e8e84ab3e0ff5085a69df9426";
        let msg = format!("... then run again with --trust-server {t} (or move ...)");
        assert_eq!(thumbprint_in(&msg), Some(t));
        assert_eq!(thumbprint_in("run again with --trust-server accept"), None);
        assert_eq!(password("reader1"), "czytelnik-hasło-2");
    }
}
