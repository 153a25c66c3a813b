//! `cargo xtask bench --scale`: ServerCTOPC with a synthetic database of 100,000 and
//! 1,000,000 variables under Wine (not in CI).
//!
//! Options: `--sizes 100000,1000000`, `--runs 3`, `--items 100000`, `--soak-minutes 10`,
//! `--only <phase>` (`load`, `browse`, `items`, `soak`; may be repeated).
//!
//! The databases are `target/scale/db-N`, written by asix-model's `synthetic_db` example
//! (17 attributes a row, branches of 100) and reused when present; each gets a
//! `scale.ini` of the benchmark's own (simulated, `LogLevel = info`, its log in
//! `target/scale/log`). The baseline of the same run is the demo plant (its database
//! from `demo/`, the same options). Everything runs in a Wine prefix of its own,
//! `target/wine/scale-prefix`, where the proxy/stub and the server are registered.
//!
//! Each run of each size is a fresh server, started as COM would start it
//! (`ServerCTOPC.exe -Embedding`, the ini in `SERVERCTOPC_INI`), then:
//! - **load**: the server's `start: ...` log lines (configuration read, browse tree,
//!   `serving`, the deferred simulation ready) give the time from reading the
//!   configuration to serving; resident memory (`VmRSS` of the Wine process, read from
//!   `/proc`) once the simulation is ready and a client holds the server
//!   (`soak-client --hold`); bytes per variable = (RSS − the demo's RSS) / N;
//! - **browse**: `opcdiag browse --flat` and `opcdiag browse` (tree), stdout to a file,
//!   wall time of the whole opcdiag run (the line count is checked);
//! - **items** (needs `scale-client`, tests/src/bin/scale-client.rs): one client with
//!   `--items I` in an inactive group: the AddItems time it reports and
//!   (RSS after AddItems − RSS connected) / I; then a client that adds them to an
//!   inactive group too and then subscribes (Advise, SetState active, 1 s): RSS after
//!   its first callbacks covered every item and five more seconds − RSS after its
//!   AddItems (no subscription before its stage 3: `scale-client --active`). Each client
//!   first makes the measured stages' calls once with one item (its warm-up), so that the
//!   connections Wine's RPC opens for a client's calls, each with a thread whose stack
//!   keeps ~1 MB resident, are the client's before the measurement; the thread
//!   stacks of each phase are still shown apart ([`thread_stacks`]);
//! - **soak** (once, the largest size, after the runs): that active subscription for
//!   `--soak-minutes`, a stdin line a second (`ready tick ...`), RSS sampled every 10 s;
//!   the least-squares slope after the first fifth (warm-up).
//!
//! Prints every measurement and then, per size, medians of the runs beside the
//! baseline's. Never fails on figures; fails when a phase cannot be measured.

use crate::{build, setup, soak, util, wine};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

fn prefix() -> PathBuf {
    util::root().join("target/wine/scale-prefix")
}

fn scale_dir() -> PathBuf {
    util::root().join("target/scale")
}

#[derive(Debug, Clone, PartialEq)]
struct Options {
    sizes: Vec<usize>,
    runs: usize,
    items: usize,
    soak_minutes: f64,
    only: Vec<String>,
}

const PHASES: [&str; 4] = ["load", "browse", "items", "soak"];

fn options(args: &[String]) -> Result<Options, String> {
    let mut o = Options {
        sizes: vec![100_000, 1_000_000],
        runs: 3,
        items: 100_000,
        soak_minutes: 10.0,
        only: Vec::new(),
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = || {
            it.next()
                .map(|v| v.replace(['_', ','], ""))
                .ok_or(format!("bench --scale: {a} needs a value"))
        };
        let num = |v: String| {
            v.parse::<usize>()
                .map_err(|e| format!("bench --scale: {a} {v}: {e}"))
        };
        match a.as_str() {
            "--sizes" => {
                let v = it
                    .next()
                    .ok_or(format!("bench --scale: {a} needs a value"))?;
                o.sizes = v
                    .split(',')
                    .map(|s| {
                        s.trim()
                            .replace('_', "")
                            .parse()
                            .map_err(|e| format!("bench --scale: --sizes {s}: {e}"))
                    })
                    .collect::<Result<_, _>>()?;
            }
            "--runs" => o.runs = num(value()?)?.max(1),
            "--items" => o.items = num(value()?)?,
            "--soak-minutes" => {
                let v = value()?;
                o.soak_minutes = v
                    .parse()
                    .map_err(|e| format!("bench --scale: {a} {v}: {e}"))?;
            }
            "--only" => {
                let v = it
                    .next()
                    .ok_or(format!("bench --scale: {a} needs a value"))?;
                if !PHASES.contains(&v.as_str()) {
                    return Err(format!(
                        "bench --scale: --only {v}: one of {}",
                        PHASES.join(", ")
                    ));
                }
                o.only.push(v.clone());
            }
            _ => return Err(format!("bench --scale: unknown option {a}")),
        }
    }
    Ok(o)
}

impl Options {
    fn phase(&self, p: &str) -> bool {
        self.only.is_empty() || self.only.iter().any(|o| o == p)
    }
}

/// The median of `xs` (the mean of the middle two of an even count); `None` when empty.
/// ServerCTOPC.exe's stack reserve per thread, KB (`crates/server/build.rs`: 256 MiB).
const STACK_RESERVE_KB: u64 = 256 * 1024;

/// Thread stacks of a process: how many and their resident MB.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stacks {
    pub count: usize,
    pub rss_mb: f64,
}

/// The thread stacks in a `/proc/PID/smaps` text: the mappings of at least `reserve_kb`
/// (every thread of the server reserves the exe's 256 MiB; nothing else maps that much),
/// with their resident memory. Wine keeps about 1 MB of each resident whatever the
/// reserve (measured: 976 KB in every thread of opcdiag.exe, 2 MiB reserve, as in the
/// server's), so a phase that starts threads grows by that much per thread, none of it
/// the server's data. The threads a client's phases add are Wine's RPC I/O threads, one
/// per client connection (`/proc/PID/task/*/comm`: `wine_rpcrt4_io`; 8 of them in the
/// server while one `opcdiag subscribe` runs, besides `main`, `driver`, `callbacks-1`,
/// the log writer and Wine's RPC listener).
pub fn thread_stacks(smaps: &str, reserve_kb: u64) -> Stacks {
    let mut count = 0;
    let mut rss_kb = 0u64;
    let mut big = false;
    for line in smaps.lines() {
        let mut words = line.split_whitespace();
        let first = words.next().unwrap_or("");
        if let Some((a, b)) = first.split_once('-') {
            if let (Ok(a), Ok(b)) = (u64::from_str_radix(a, 16), u64::from_str_radix(b, 16)) {
                big = b.saturating_sub(a) / 1024 >= reserve_kb;
                count += usize::from(big);
                continue;
            }
        }
        if big && first == "Rss:" {
            rss_kb += words.next().and_then(|w| w.parse().ok()).unwrap_or(0);
        }
    }
    Stacks {
        count,
        rss_mb: rss_kb as f64 / 1024.0,
    }
}

pub fn median(xs: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    Some(if v.len() % 2 == 1 {
        v[m]
    } else {
        (v[m - 1] + v[m]) / 2.0
    })
}

/// Seconds since midnight of a log line's leading RFC 3339 timestamp
/// (`2026-12-02T13:45:00.123456Z  INFO ...`, tracing's default format).
pub fn line_seconds(line: &str) -> Option<f64> {
    let stamp = line.split_whitespace().next()?;
    let (_, time) = stamp.split_once('T')?;
    let time = time.trim_end_matches('Z');
    let mut parts = time.splitn(3, ':');
    let h: f64 = parts.next()?.parse().ok()?;
    let m: f64 = parts.next()?.parse().ok()?;
    let s: f64 = parts.next()?.parse().ok()?;
    Some(h * 3600.0 + m * 60.0 + s)
}

/// What the server's start-up lines say (`crates/server/src/main.rs`, `backend.rs`,
/// ctopc-com's `host.rs`), in ms from the start of reading the configuration.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Startup {
    pub config_ms: f64,
    pub variables: usize,
    pub tree_ms: Option<f64>,
    pub serving_ms: Option<f64>,
    pub simulation_ready_ms: Option<f64>,
}

/// The start-up phases of the log `text` (the last start in it).
pub fn parse_startup(text: &str) -> Option<Startup> {
    let mut s: Option<Startup> = None;
    // The configuration line's time, and the ms it says had passed then.
    let mut anchor = 0.0;
    let at = |line: &str, anchor: f64, config_ms: f64| {
        line_seconds(line).map(|t| {
            let d = t - anchor;
            config_ms + if d < 0.0 { d + 86_400.0 } else { d } * 1000.0
        })
    };
    for line in text.lines() {
        if let Some(rest) = after(line, "start: configuration read in ") {
            let (ms, rest) = rest.split_once(" ms (")?;
            let variables = rest.split_whitespace().next()?.parse().ok()?;
            anchor = line_seconds(line)?;
            s = Some(Startup {
                config_ms: ms.parse().ok()?,
                variables,
                ..Startup::default()
            });
        } else if let Some(st) = s.as_mut() {
            if let Some(rest) = after(line, "start: browse tree built at ") {
                st.tree_ms = rest.trim_end_matches(" ms").trim().parse().ok();
            } else if after(line, "serving ServerCTOPC").is_some() {
                st.serving_ms = at(line, anchor, st.config_ms);
            } else if after(line, "start: simulation ready in ").is_some() {
                st.simulation_ready_ms = at(line, anchor, st.config_ms);
            }
        }
    }
    s
}

/// The text after `pat` in `line`.
fn after<'a>(line: &'a str, pat: &str) -> Option<&'a str> {
    line.find(pat).map(|i| &line[i + pat.len()..])
}

/// A line of scale-client's stdout (tests/src/bin/scale-client.rs).
#[derive(Debug, Clone, PartialEq)]
pub enum Ready {
    Connected {
        ms: f64,
    },
    Added {
        items: usize,
        ms: f64,
        errors: usize,
    },
    Subscribed {
        ms: f64,
        values: u64,
    },
    Tick {
        callbacks: u64,
        values: u64,
    },
    Removed {
        ms: f64,
    },
    Error(String),
}

/// Parses one line of scale-client; `None` for a line that is not a stage line.
pub fn parse_ready(line: &str) -> Option<Ready> {
    let w: Vec<&str> = line.split_whitespace().collect();
    let num = |i: usize| w.get(i).and_then(|s| s.parse::<f64>().ok());
    let int = |i: usize| w.get(i).and_then(|s| s.parse::<u64>().ok());
    match w.as_slice() {
        ["error", ..] => Some(Ready::Error(w[1..].join(" "))),
        ["ready", "connected", ..] => Some(Ready::Connected { ms: num(2)? }),
        ["ready", "added", _, "items", _, "ms", "errors", _] => Some(Ready::Added {
            items: int(2)? as usize,
            ms: num(4)?,
            errors: int(7)? as usize,
        }),
        ["ready", "subscribed", "first-callback", _, "ms", "values", _] => {
            Some(Ready::Subscribed {
                ms: num(3)?,
                values: int(6)?,
            })
        }
        ["ready", "tick", _, _] => Some(Ready::Tick {
            callbacks: int(2)?,
            values: int(3)?,
        }),
        ["ready", "removed", ..] => Some(Ready::Removed { ms: num(2)? }),
        _ => None,
    }
}

/// The slope of (minutes, MB) samples after the first fifth of the run (warm-up), MB
/// per minute.
pub fn slope_after_warmup(samples: &[(f64, f64)]) -> Option<f64> {
    let skip = samples.len() / 5;
    soak::slope(&samples[skip..])
}

/// One configuration the benchmark serves: the demo (baseline) or a synthetic size.
struct Config {
    label: String,
    /// 0 for the demo.
    size: usize,
    ini: PathBuf,
}

/// The configuration a database folder gets: simulated, info-level log in `log`.
fn write_ini(path: &Path, database: &Path, log: &Path) -> Result<(), String> {
    let text = format!(
        "; Written by cargo xtask bench --scale.\r\n[Server]\r\nSimulateCurrentData = tak\r\n\
         LogLevel = info\r\nLogDirectory = {}\r\n[Channel:*]\r\nItemsDatabase = {}\r\n",
        wine::windows_path(log),
        wine::windows_path(database)
    );
    std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
}

/// The folder of the synthetic database of `n` variables (`synthetic.zez` and
/// `atrybuty.csv`, `asix_model::synthetic`), written on first use under `target/scale`.
pub fn synthetic_db(n: usize) -> Result<PathBuf, String> {
    let db = scale_dir().join(format!("db-{n}"));
    if !db.join("synthetic.zez").is_file() || !db.join("atrybuty.csv").is_file() {
        println!(
            "scale: writing a database of {n} variables in {}",
            db.display()
        );
        util::run(
            util::cargo()
                .args(["run", "--release", "-p", "asix-model"])
                .args([
                    "--example",
                    "synthetic_db",
                    "--",
                    &n.to_string(),
                    &db.display().to_string(),
                ]),
        )?;
    }
    Ok(db)
}

fn configs(o: &Options) -> Result<Vec<Config>, String> {
    let dir = scale_dir();
    let log = dir.join("log");
    let demo_dir = dir.join("demo");
    std::fs::create_dir_all(&demo_dir).map_err(|e| format!("{}: {e}", demo_dir.display()))?;
    let demo_db = util::root().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez");
    let demo_ini = demo_dir.join("scale.ini");
    write_ini(&demo_ini, &demo_db, &log)?;
    let mut out = vec![Config {
        label: "demo (baseline)".into(),
        size: 0,
        ini: demo_ini,
    }];
    for &n in &o.sizes {
        let db = synthetic_db(n)?;
        let ini = db.join("scale.ini");
        write_ini(&ini, &db.join("synthetic.zez"), &log)?;
        out.push(Config {
            label: format!("{n} variables"),
            size: n,
            ini,
        });
    }
    Ok(out)
}

/// The programs the benchmark runs.
struct Programs {
    server: PathBuf,
    opcdiag: PathBuf,
    holder: PathBuf,
    scale_client: Option<PathBuf>,
}

/// A started server of one configuration, in the scale prefix.
struct Server {
    child: Child,
    pid: u32,
    startup: Startup,
    /// CPU seconds (user + system) the process had used when its `serving` line was seen
    /// (polled every 100 ms): on a shared machine the wall time overstates the work.
    cpu_at_serving: Option<f64>,
}

/// User + system CPU seconds of `/proc/<pid>/stat`'s text (fields 14 and 15, counted
/// after the command name's closing parenthesis; USER_HZ is 100 on Linux).
pub fn stat_cpu_seconds(stat: &str) -> Option<f64> {
    let rest = &stat[stat.rfind(')')? + 1..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // `rest` starts at field 3 (state): utime is field 14, stime 15.
    let utime: u64 = f.get(11)?.parse().ok()?;
    let stime: u64 = f.get(12)?.parse().ok()?;
    Some((utime + stime) as f64 / 100.0)
}

fn cpu_seconds(pid: u32) -> Option<f64> {
    stat_cpu_seconds(&std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?)
}

const START_LIMIT: Duration = Duration::from_secs(180);

fn log_text() -> String {
    let dir = scale_dir().join("log");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    files.sort();
    files
        .iter()
        .filter_map(|f| std::fs::read(f).ok())
        .map(|b| String::from_utf8_lossy(&b).into_owned())
        .collect()
}

fn command(pfx: &Path, program: &Path, ini: &Path) -> Command {
    let mut c = wine::wine_in(pfx, program);
    c.env("SERVERCTOPC_INI", wine::windows_path(ini));
    c
}

fn start_server(pfx: &Path, p: &Programs, c: &Config) -> Result<Server, String> {
    wine::wineserver_in(pfx, "-k", Duration::from_secs(20));
    let log = scale_dir().join("log");
    let _ = std::fs::remove_dir_all(&log);
    std::fs::create_dir_all(&log).map_err(|e| format!("{}: {e}", log.display()))?;
    let mut child = command(pfx, &p.server, &c.ini)
        .arg("-Embedding")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("start {}: {e}", p.server.display()))?;
    let t = Instant::now();
    let (mut pid, mut cpu_at_serving) = (None, None);
    loop {
        if pid.is_none() {
            pid = soak::server_pid(&p.server, pfx);
        }
        let startup = parse_startup(&log_text());
        if cpu_at_serving.is_none() && startup.is_some_and(|s| s.serving_ms.is_some()) {
            cpu_at_serving = pid.and_then(cpu_seconds);
        }
        if let Some(s) =
            startup.filter(|s| s.serving_ms.is_some() && s.simulation_ready_ms.is_some())
        {
            let pid = pid
                .or_else(|| soak::server_pid(&p.server, pfx))
                .ok_or("scale: the server serves but its process is not found")?;
            return Ok(Server {
                child,
                pid,
                startup: s,
                cpu_at_serving,
            });
        }
        if let Ok(Some(status)) = child.try_wait() {
            return Err(format!(
                "scale: the server ended before serving ({status}); log:\n{}",
                log_text()
            ));
        }
        if t.elapsed() > START_LIMIT {
            let _ = child.kill();
            return Err(format!(
                "scale: {} did not serve within {} s; log:\n{}",
                c.label,
                START_LIMIT.as_secs(),
                log_text()
            ));
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

impl Server {
    fn rss(&self) -> Result<f64, String> {
        soak::rss_mb(self.pid).ok_or_else(|| format!("scale: no VmRSS for pid {}", self.pid))
    }

    /// The server's thread stacks now: how many, and their resident MB.
    fn stacks(&self) -> Result<Stacks, String> {
        let smaps = std::fs::read_to_string(format!("/proc/{}/smaps", self.pid))
            .map_err(|e| format!("scale: smaps of pid {}: {e}", self.pid))?;
        Ok(thread_stacks(&smaps, STACK_RESERVE_KB))
    }

    fn stop(mut self, pfx: &Path) {
        wine::wineserver_in(pfx, "-k", Duration::from_secs(20));
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Figures of one run of one configuration (NaN: not measured).
#[derive(Debug, Clone, Copy)]
struct Run {
    start_ms: f64,
    start_cpu_ms: f64,
    simulation_ms: f64,
    rss_mb: f64,
    flat_s: f64,
    tree_s: f64,
    add_ms: f64,
    per_item_b: f64,
    /// Of `per_item_b`, what new threads' stacks hold (the client's connection).
    per_item_stacks_b: f64,
    subscription_mb: f64,
    /// Of `subscription_mb`, what new threads' stacks hold (Wine keeps ~1 MB resident per
    /// thread, see [`thread_stacks`]).
    subscription_stacks_mb: f64,
}

impl Default for Run {
    fn default() -> Self {
        Run {
            start_ms: f64::NAN,
            start_cpu_ms: f64::NAN,
            simulation_ms: f64::NAN,
            rss_mb: f64::NAN,
            flat_s: f64::NAN,
            tree_s: f64::NAN,
            add_ms: f64::NAN,
            per_item_b: f64::NAN,
            per_item_stacks_b: f64::NAN,
            subscription_mb: f64::NAN,
            subscription_stacks_mb: f64::NAN,
        }
    }
}

/// Runs opcdiag with `args`, stdout to `out`; its wall time in s and the lines written.
fn timed_opcdiag(
    pfx: &Path,
    p: &Programs,
    c: &Config,
    args: &[&str],
    out: &Path,
) -> Result<(f64, usize), String> {
    let file = std::fs::File::create(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let t = Instant::now();
    let status = util::run_with_timeout(
        command(pfx, &p.opcdiag, &c.ini)
            .args(args)
            .stdout(file)
            .stderr(Stdio::null()),
        Duration::from_secs(600),
    )?;
    let secs = t.elapsed().as_secs_f64();
    if !status.success() {
        return Err(format!(
            "scale: opcdiag {} failed: {status}",
            args.join(" ")
        ));
    }
    let lines = std::fs::read(out)
        .map(|b| b.iter().filter(|&&c| c == b'\n').count())
        .unwrap_or(0);
    Ok((secs, lines))
}

/// A running scale-client: its stage lines arrive on a channel.
struct Client {
    child: Child,
    stdin: Option<ChildStdin>,
    lines: Receiver<String>,
}

const STAGE_LIMIT: Duration = Duration::from_secs(300);

impl Client {
    fn start(pfx: &Path, exe: &Path, c: &Config, args: &[String]) -> Result<Client, String> {
        let mut child = command(pfx, exe, &c.ini)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| format!("start {}: {e}", exe.display()))?;
        let stdout = child.stdout.take().ok_or("scale-client: no stdout")?;
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Ok(Client {
            stdin: child.stdin.take(),
            child,
            lines,
        })
    }

    /// The next stage line (other lines are printed and skipped).
    fn next(&mut self) -> Result<Ready, String> {
        let t = Instant::now();
        loop {
            let left = STAGE_LIMIT.saturating_sub(t.elapsed());
            match self.lines.recv_timeout(left) {
                Ok(line) => match parse_ready(&line) {
                    Some(Ready::Error(e)) => return Err(format!("scale-client: error {e}")),
                    Some(r) => return Ok(r),
                    None => println!("scale-client: {line}"),
                },
                Err(RecvTimeoutError::Timeout) => {
                    return Err(format!(
                        "scale-client: no stage line within {} s",
                        STAGE_LIMIT.as_secs()
                    ))
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return Err("scale-client ended without a stage line".into())
                }
            }
        }
    }

    fn go(&mut self) -> Result<(), String> {
        let stdin = self.stdin.as_mut().ok_or("scale-client: stdin closed")?;
        stdin
            .write_all(b"\n")
            .and_then(|()| stdin.flush())
            .map_err(|e| format!("scale-client stdin: {e}"))
    }

    /// `quit`, then waits for it to end (killed after a minute).
    fn quit(mut self) {
        if let Some(mut s) = self.stdin.take() {
            let _ = s.write_all(b"quit\n");
        }
        let t = Instant::now();
        while matches!(self.child.try_wait(), Ok(None)) && t.elapsed() < Duration::from_secs(60) {
            std::thread::sleep(Duration::from_millis(100));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn client_args(c: &Config, items: usize, active: bool) -> Vec<String> {
    let mut a = vec![
        "--items".to_owned(),
        items.to_string(),
        "--synthetic".to_owned(),
        c.size.to_string(),
    ];
    if active {
        a.extend([
            "--active".to_owned(),
            "--rate".to_owned(),
            "1000".to_owned(),
        ]);
    }
    a
}

/// The item phases of one run: per group item, AddItems, the active subscription.
fn items_phase(
    pfx: &Path,
    exe: &Path,
    c: &Config,
    s: &Server,
    items: usize,
    run: &mut Run,
) -> Result<(), String> {
    let mut cl = Client::start(pfx, exe, c, &client_args(c, items, false))?;
    let Ready::Connected { .. } = cl.next()? else {
        return Err("scale-client: expected `ready connected`".into());
    };
    let before = s.rss()?;
    let stacks_before = s.stacks()?;
    cl.go()?;
    let Ready::Added {
        items: n,
        ms,
        errors,
    } = cl.next()?
    else {
        return Err("scale-client: expected `ready added`".into());
    };
    let added = s.rss()?;
    let stacks_added = s.stacks()?;
    run.add_ms = ms;
    run.per_item_b = (added - before) * 1024.0 * 1024.0 / n.max(1) as f64;
    run.per_item_stacks_b =
        (stacks_added.rss_mb - stacks_before.rss_mb) * 1024.0 * 1024.0 / n.max(1) as f64;
    println!(
        "scale: {}: AddItems of {n} in one call {ms:.0} ms, {errors} errors; RSS {before:.1} → {added:.1} MB: {:.0} B per group item; thread stacks {:+.1} MB (threads {} → {})",
        c.label,
        run.per_item_b,
        stacks_added.rss_mb - stacks_before.rss_mb,
        stacks_before.count,
        stacks_added.count
    );
    cl.go()?;
    let _ = cl.next()?;
    cl.quit();
    let mut cl = Client::start(pfx, exe, c, &client_args(c, items, true))?;
    cl.next()?;
    cl.go()?;
    cl.next()?;
    let added = s.rss()?;
    let stacks_added = s.stacks()?;
    cl.go()?;
    let Ready::Subscribed { ms, values } = cl.next()? else {
        return Err("scale-client: expected `ready subscribed`".into());
    };
    // A few callbacks on, so that the steady state (not only the first one) is counted.
    for _ in 0..5 {
        std::thread::sleep(Duration::from_secs(1));
        cl.go()?;
        cl.next()?;
    }
    let sub = s.rss()?;
    let stacks_sub = s.stacks()?;
    run.subscription_mb = sub - added;
    run.subscription_stacks_mb = stacks_sub.rss_mb - stacks_added.rss_mb;
    println!(
        "scale: {}: active subscription of {items} items at 1 s: first callback after {ms:.0} ms ({values} values); RSS {added:.1} → {sub:.1} MB: +{:.1} MB, of it thread stacks +{:.1} MB (threads {} → {})",
        c.label, run.subscription_mb, run.subscription_stacks_mb, stacks_added.count, stacks_sub.count
    );
    cl.quit();
    Ok(())
}

/// The soak: an active subscription of `items` for `minutes`, RSS every 10 s.
fn soak_phase(
    pfx: &Path,
    exe: &Path,
    c: &Config,
    s: &Server,
    items: usize,
    minutes: f64,
) -> Result<(), String> {
    let mut cl = Client::start(pfx, exe, c, &client_args(c, items, true))?;
    cl.next()?;
    cl.go()?;
    cl.next()?;
    cl.go()?;
    cl.next()?;
    let t0 = Instant::now();
    let total = Duration::from_secs_f64(minutes * 60.0);
    let mut samples: Vec<(f64, f64)> = Vec::new();
    let mut last_sample = None::<Instant>;
    let (mut callbacks, mut values) = (0, 0);
    while t0.elapsed() < total {
        std::thread::sleep(Duration::from_secs(1));
        cl.go()?;
        if let Ready::Tick {
            callbacks: cb,
            values: v,
        } = cl.next()?
        {
            (callbacks, values) = (cb, v);
        }
        if last_sample.is_none_or(|l| l.elapsed() >= Duration::from_secs(10)) {
            last_sample = Some(Instant::now());
            let mb = s.rss()?;
            let min = t0.elapsed().as_secs_f64() / 60.0;
            println!(
                "scale: soak {min:6.2} min  {mb:8.1} MB  ({callbacks} callbacks, {values} values)"
            );
            samples.push((min, mb));
        }
    }
    cl.quit();
    match slope_after_warmup(&samples) {
        Some(sl) => println!(
            "scale: soak of {items} items at 1 s for {minutes} min: slope after warm-up {sl:+.3} MB/min ({} samples)",
            samples.len()
        ),
        None => println!("scale: soak: too few samples for a slope"),
    }
    Ok(())
}

fn one_run(
    pfx: &Path,
    p: &Programs,
    c: &Config,
    o: &Options,
    i: usize,
) -> Result<(Run, Option<Server>), String> {
    let mut run = Run::default();
    let s = start_server(pfx, p, c)?;
    run.start_ms = s.startup.serving_ms.unwrap_or(f64::NAN);
    run.start_cpu_ms = s.cpu_at_serving.map_or(f64::NAN, |c| c * 1000.0);
    run.simulation_ms = s.startup.simulation_ready_ms.unwrap_or(f64::NAN);
    let mut holder = command(pfx, &p.holder, &c.ini)
        .args(["--hold", "--seconds", "3600"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("start {}: {e}", p.holder.display()))?;
    std::thread::sleep(Duration::from_secs(3));
    run.rss_mb = s.rss()?;
    println!(
        "scale: {} run {i}: configuration {:.0} ms ({} variables), tree at {:.0} ms, serving at {:.0} ms (CPU {:.0} ms), simulation ready at {:.0} ms; RSS {:.1} MB; load average {}",
        c.label,
        s.startup.config_ms,
        s.startup.variables,
        s.startup.tree_ms.unwrap_or(f64::NAN),
        run.start_ms,
        run.start_cpu_ms,
        run.simulation_ms,
        run.rss_mb,
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .split_whitespace()
            .next()
            .unwrap_or("?")
    );
    let result = (|| {
        if c.size > 0 && o.phase("browse") {
            let out = scale_dir().join("out");
            std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
            let (secs, lines) =
                timed_opcdiag(pfx, p, c, &["browse", "--flat"], &out.join("flat.txt"))?;
            run.flat_s = secs;
            println!(
                "scale: {} run {i}: opcdiag browse --flat {secs:.2} s ({lines} lines)",
                c.label
            );
            let (secs, lines) = timed_opcdiag(pfx, p, c, &["browse"], &out.join("tree.txt"))?;
            run.tree_s = secs;
            println!(
                "scale: {} run {i}: opcdiag browse (tree) {secs:.2} s ({lines} lines)",
                c.label
            );
        }
        if c.size > 0 && o.phase("items") {
            match &p.scale_client {
                Some(exe) => items_phase(pfx, exe, c, &s, o.items.min(c.size), &mut run)?,
                None => println!(
                    "scale: items: scale-client not built (tests/src/bin/scale-client.rs missing)"
                ),
            }
        }
        Ok(())
    })();
    let _ = holder.kill();
    let _ = holder.wait();
    match result {
        Ok(()) => Ok((run, Some(s))),
        Err(e) => {
            s.stop(pfx);
            Err(e)
        }
    }
}

fn fmt(x: Option<f64>, unit: &str, digits: usize) -> String {
    match x {
        Some(v) => format!("{v:.digits$} {unit}"),
        None => "—".to_owned(),
    }
}

fn summary(o: &Options, results: &[(Config, Vec<Run>)]) {
    let med = |runs: &[Run], f: fn(&Run) -> f64| median(&runs.iter().map(f).collect::<Vec<_>>());
    let Some((_, base)) = results.iter().find(|(c, _)| c.size == 0) else {
        return;
    };
    let base_rss = med(base, |r| r.rss_mb);
    let base_start = med(base, |r| r.start_ms);
    println!(
        "\nServerCTOPC at scale (Wine; medians of {} runs; baseline: the demo plant, start {}, RSS {})",
        o.runs,
        fmt(base_start, "ms", 0),
        fmt(base_rss, "MB", 1)
    );
    println!(
        "| figure | {} | goal |",
        results
            .iter()
            .filter(|(c, _)| c.size > 0)
            .map(|(c, _)| c.label.clone())
            .collect::<Vec<_>>()
            .join(" | ")
    );
    println!("|---|{}---|", "---|".repeat(results.len() - 1));
    type Row = (
        &'static str,
        Box<dyn Fn(&Config, &[Run]) -> String>,
        &'static str,
    );
    let rows: Vec<Row> = vec![
        (
            "start (configuration read to serving)",
            Box::new(move |_, r| {
                let m = med(r, |r| r.start_ms);
                format!(
                    "{} ({:.1}× demo)",
                    fmt(m, "ms", 0),
                    m.zip(base_start).map_or(f64::NAN, |(a, b)| a / b)
                )
            }),
            "1,000,000 in ≤ 3 s",
        ),
        (
            "… CPU time of the process until serving (Wine's own start included)",
            Box::new(move |_, r| fmt(med(r, |r| r.start_cpu_ms), "ms", 0)),
            "—",
        ),
        (
            "simulation ready (deferred, after serving)",
            Box::new(move |_, r| fmt(med(r, |r| r.simulation_ms), "ms", 0)),
            "—",
        ),
        (
            "server resident memory",
            Box::new(move |_, r| fmt(med(r, |r| r.rss_mb), "MB", 1)),
            "—",
        ),
        (
            "… bytes per variable (RSS − demo) / N",
            Box::new(move |c, r| {
                fmt(
                    med(r, |r| r.rss_mb)
                        .zip(base_rss)
                        .map(|(a, b)| (a - b) * 1024.0 * 1024.0 / c.size as f64),
                    "B",
                    0,
                )
            }),
            "≤ 300 B",
        ),
        (
            "`opcdiag browse --flat`",
            Box::new(move |_, r| fmt(med(r, |r| r.flat_s), "s", 2)),
            "1,000,000 in ≤ 10 s",
        ),
        (
            "`opcdiag browse` (tree)",
            Box::new(move |_, r| fmt(med(r, |r| r.tree_s), "s", 2)),
            "1,000,000 in ≤ 30 s",
        ),
        (
            "AddItems of the items in one call",
            Box::new(move |_, r| fmt(med(r, |r| r.add_ms), "ms", 0)),
            "—",
        ),
        (
            "resident growth per group item",
            Box::new(move |_, r| fmt(med(r, |r| r.per_item_b), "B", 0)),
            "≤ 150 B",
        ),
        (
            "… of it, the stacks of threads started meanwhile (Wine: ~1 MB a thread)",
            Box::new(move |_, r| fmt(med(r, |r| r.per_item_stacks_b), "B", 0)),
            "—",
        ),
        (
            "extra memory of the active subscription",
            Box::new(move |_, r| fmt(med(r, |r| r.subscription_mb), "MB", 1)),
            "≤ 15 MB",
        ),
        (
            "… of it, the stacks of threads started meanwhile (Wine: ~1 MB a thread)",
            Box::new(move |_, r| fmt(med(r, |r| r.subscription_stacks_mb), "MB", 1)),
            "—",
        ),
    ];
    for (name, f, goal) in rows {
        let cells: Vec<String> = results
            .iter()
            .filter(|(c, _)| c.size > 0)
            .map(|(c, r)| f(c, r))
            .collect();
        println!("| {name} | {} | {goal} |", cells.join(" | "));
    }
    println!(
        "(items: {} per client, or the database size when smaller)",
        o.items
    );
}

pub fn run(args: &[String]) -> Result<(), String> {
    let o = options(args)?;
    setup::run(&[])?;
    let artifacts = build::run(&[])?;
    build::e2e_bin("soak-client")?;
    let has_client = util::root().join("tests/src/bin/scale-client.rs").is_file();
    if has_client {
        build::e2e_bin("scale-client")?;
    }
    let p = Programs {
        server: artifacts.server.clone(),
        opcdiag: artifacts.dir.join("opcdiag.exe"),
        holder: artifacts.dir.join("soak-client.exe"),
        scale_client: has_client.then(|| artifacts.dir.join("scale-client.exe")),
    };
    let configs = configs(&o)?;
    let pfx = prefix();
    wine::ensure_prefix(&pfx)?;
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
    wine::register_in(&pfx, &artifacts.proxy, &artifacts.server)?;
    println!(
        "scale: prefix {}, sizes {:?}, {} runs, {} items",
        pfx.display(),
        o.sizes,
        o.runs,
        o.items
    );
    let mut results: Vec<(Config, Vec<Run>)> = Vec::new();
    let result = (|| {
        let want_runs = o.phase("load") || o.phase("browse") || o.phase("items");
        for c in configs {
            let mut runs = Vec::new();
            let last = c.size > 0 && c.size == o.sizes.iter().copied().max().unwrap_or(0);
            for i in 1..=o.runs {
                if !want_runs {
                    break;
                }
                let (r, s) = one_run(&pfx, &p, &c, &o, i)?;
                if let Some(s) = s {
                    s.stop(&pfx);
                }
                runs.push(r);
            }
            if last && o.phase("soak") {
                if let Some(exe) = &p.scale_client {
                    let s = start_server(&pfx, &p, &c)?;
                    let r = soak_phase(&pfx, exe, &c, &s, o.items.min(c.size), o.soak_minutes);
                    s.stop(&pfx);
                    r?;
                } else {
                    println!("scale: soak: scale-client not built");
                }
            }
            results.push((c, runs));
        }
        Ok(())
    })();
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
    summary(&o, &results);
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_stacks_are_the_mappings_of_the_reserve_with_their_resident_memory() {
        let smaps = "\
00022000-10120000 rw-p 00000000 00:00 0
Size:             263160 kB
Rss:                1036 kB
Pss:                1036 kB
7fe107bc2000-7fe117cc0000 rw-p 00000000 00:00 0
Size:             263160 kB
Rss:                 976 kB
129a0000-13ac0000 rw-p 00000000 00:00 0
Size:              17536 kB
Rss:               17468 kB
140000000-140001000 r--p 00000000 08:01 123 /x/ServerCTOPC.exe
Rss:                   4 kB
";
        let s = thread_stacks(smaps, STACK_RESERVE_KB);
        assert_eq!(s.count, 2);
        assert!((s.rss_mb - 2012.0 / 1024.0).abs() < 1e-9, "{s:?}");
        assert_eq!(thread_stacks("", STACK_RESERVE_KB).count, 0);
    }

    #[test]
    fn median_of_odd_even_and_empty() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), Some(2.5));
        assert_eq!(median(&[f64::NAN, 5.0]), Some(5.0));
        assert_eq!(median(&[]), None);
    }

    #[test]
    fn the_start_up_lines_give_each_phase_from_the_configuration_read() {
        let log = "\
2026-12-02T13:59:58.000000Z  INFO main ServerCTOPC: ServerCTOPC starting version=\"0.1.0\"
2026-12-02T13:59:58.100000Z  INFO main ServerCTOPC: start: configuration read in 1800 ms (1000000 variables)
2026-12-02T13:59:58.700000Z  INFO main ServerCTOPC: start: browse tree built at 2400 ms
2026-12-02T13:59:58.900000Z  INFO main ctopc_com::host: serving ServerCTOPC.App
2026-12-02T14:00:00.000000Z  INFO data source ServerCTOPC::backend: start: simulation ready in 1000 ms
";
        let s = parse_startup(log).unwrap();
        assert_eq!(s.config_ms, 1800.0);
        assert_eq!(s.variables, 1_000_000);
        assert_eq!(s.tree_ms, Some(2400.0));
        assert!((s.serving_ms.unwrap() - 2600.0).abs() < 0.01, "{s:?}");
        assert!(
            (s.simulation_ready_ms.unwrap() - 3700.0).abs() < 0.01,
            "{s:?}"
        );
        // Not yet serving: the phases so far.
        let early: String = log.lines().take(3).map(|l| format!("{l}\n")).collect();
        assert_eq!(parse_startup(&early).unwrap().serving_ms, None);
        assert_eq!(parse_startup("nothing here\n"), None);
        assert_eq!(line_seconds("2026-12-02T01:02:03.5Z x"), Some(3723.5));
    }

    #[test]
    fn cpu_seconds_of_a_proc_stat_line() {
        // A command name with a space and a parenthesis, as Wine's can have.
        let stat =
            "4242 (Server CTOPC.ex)) S 1 4242 4242 0 -1 4194560 100 0 0 0 250 37 0 0 20 0 9 0";
        assert_eq!(stat_cpu_seconds(stat), Some(2.87));
        assert_eq!(stat_cpu_seconds("garbage"), None);
    }

    #[test]
    fn scale_client_stage_lines() {
        assert_eq!(
            parse_ready("ready connected 120"),
            Some(Ready::Connected { ms: 120.0 })
        );
        assert_eq!(
            parse_ready("ready added 100000 items 812 ms errors 0"),
            Some(Ready::Added {
                items: 100_000,
                ms: 812.0,
                errors: 0
            })
        );
        assert_eq!(
            parse_ready("ready subscribed first-callback 1500 ms values 100000"),
            Some(Ready::Subscribed {
                ms: 1500.0,
                values: 100_000
            })
        );
        assert_eq!(
            parse_ready("ready tick 12 340000"),
            Some(Ready::Tick {
                callbacks: 12,
                values: 340_000
            })
        );
        assert_eq!(
            parse_ready("ready removed 40"),
            Some(Ready::Removed { ms: 40.0 })
        );
        assert_eq!(
            parse_ready("error added timeout after 120 s"),
            Some(Ready::Error("added timeout after 120 s".into()))
        );
        assert_eq!(parse_ready("ready added many items"), None);
        assert_eq!(parse_ready("connecting..."), None);
    }

    #[test]
    fn the_slope_skips_the_warm_up() {
        // A jump in the first fifth, then flat: no growth.
        let mut s: Vec<(f64, f64)> = (0..10).map(|i| (f64::from(i), 100.0)).collect();
        s[0].1 = 50.0;
        s[1].1 = 80.0;
        assert_eq!(slope_after_warmup(&s), Some(0.0));
        let rising: Vec<(f64, f64)> = (0..10)
            .map(|i| (f64::from(i), 2.0 * f64::from(i)))
            .collect();
        assert!((slope_after_warmup(&rising).unwrap() - 2.0).abs() < 1e-9);
        assert_eq!(slope_after_warmup(&[(0.0, 1.0)]), None);
    }

    #[test]
    fn options_and_their_defaults() {
        let o = options(&[]).unwrap();
        assert_eq!(o.sizes, vec![100_000, 1_000_000]);
        assert_eq!((o.runs, o.items, o.soak_minutes), (3, 100_000, 10.0));
        assert!(o.phase("soak"));
        let a: Vec<String> = [
            "--sizes",
            "1000,20_000",
            "--runs",
            "1",
            "--only",
            "load",
            "--soak-minutes",
            "0.5",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let o = options(&a).unwrap();
        assert_eq!(o.sizes, vec![1000, 20_000]);
        assert_eq!((o.runs, o.soak_minutes), (1, 0.5));
        assert!(o.phase("load") && !o.phase("browse"));
        assert!(options(&["--only".into(), "x".into()]).is_err());
        assert!(options(&["--bogus".into()]).is_err());
    }
}
