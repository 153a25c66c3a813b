//! `cargo xtask soak [--minutes M] [--clients K] [--items N] [--round-seconds R]
//! [--calls LIST | --no-in-arrays] [--stall-seconds S] [--simulate-stall]`: the memory soak
//! (not in CI).
//!
//! Builds the server and `soak-client.exe`, registers them in a Wine prefix of the soak's
//! own (`target/wine/soak-prefix`), starts one client that holds the server for the whole
//! run, then runs rounds until M minutes (default 5) have passed: K client processes
//! (default 4) churn for R seconds (default 60) each — connect, AddItems of N items
//! (default 1000), Read, Write, a subscription, RemoveGroup, disconnect, again — and 15 s
//! after each round the server's resident memory is read from outside, from
//! `/proc/<pid>/status` (VmRSS) of the Wine process running ServerCTOPC.exe. Samples are
//! taken every 5 s meanwhile. Prints every sample, then the least-squares slope of the
//! after-round figures from the second round on (the first is warm-up), in MB per round
//! and per minute. A flat slope means no memory kept per call.
//!
//! **`--load`**: the device-read load of clients in parallel: 20 clients, each round
//! of each adding 1,000 items cycling through every item of the demo plant
//! (`soak-client --ids all`), reading them from cache and from the device, subscribing
//! and leaving (`--calls add,read,device,subscribe,remove`), three rounds of 60 s. After
//! each round it prints the device reads made and how many failed (an answer other than
//! S_OK), with the failing items' codes; any failed device read fails the run. The other
//! options still apply after it (`--load --minutes 1`).
//!
//! **`--net`**: the server reads the demo plant over the asix network from a native
//! `asix-sim` on loopback, as `cargo xtask demo` sets it up (the demo's staged folder and
//! `ASIXConnect.ini`), instead of the in-process simulation.
//!
//! `--calls LIST` chooses the calls of a client round (`soak-client.rs`: `add`,
//! `validate`, `read`, `write`, `itemio`, `subscribe`, `remove`; default all);
//! `--no-in-arrays` is `--calls read,subscribe,remove`: connect, GetStatus, AddGroup,
//! Read and RemoveItems by handle, a subscription, RemoveGroup, disconnect — no call
//! whose `[in]` array the stub allocates. Each client reports how many items it sent in
//! allocated `[in]` arrays; the soak prints beside the measured slope the one Wine's
//! stub predicts (it keeps the top-level block of such an array: [`KEPT_PER_ITEM`],
//! docs/wine-ndr-leak.md) and the residual, the growth Wine's leak does not explain.
//!
//! **Stalls** (no call may hang): each churning client prints a line per round;
//! when a running client has printed nothing for `--stall-seconds S` (default 60), the
//! soak, before it stops anything, takes `winedbg` backtraces of every thread of the
//! server and of every soak client ([`capture_backtraces`]), writes them with the Linux
//! threads' states to `target/soak/stall-<unix time>.txt`, prints the path and fails.
//! `--simulate-stall` (to see that capture work) makes the first client of round 1 stop
//! after 10 s as a hung call would (`soak-client --stall-after 10`).

use crate::{build, setup, util, wine};
use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

fn prefix() -> PathBuf {
    util::root().join("target/wine/soak-prefix")
}

struct Options {
    minutes: f64,
    clients: u32,
    items: u32,
    round_seconds: u32,
    calls: Option<String>,
    stall_seconds: u64,
    simulate_stall: bool,
    /// `--ids all` to the clients.
    all_ids: bool,
    /// `--load`: a failed device read fails the run.
    load: bool,
    /// `--net`: the demo plant over the asix network from asix-sim.
    net: bool,
}

/// The calls of `--load`.
const LOAD_CALLS: &str = "add,read,device,subscribe,remove";

/// The calls of `--no-in-arrays`: none carries an `[in]` array the stub allocates.
const NO_IN_ARRAYS: &str = "read,subscribe,remove";

/// Bytes Wine's stub keeps per item of an allocated `[in]` array in the 64-bit server
/// (docs/wine-ndr-leak.md): (what, the soak client's count name, bytes).
pub const KEPT_PER_ITEM: [(&str, &str, f64); 4] = [
    ("AddItems item (OPCITEMDEF)", "additems", 48.0),
    ("ValidateItems item (OPCITEMDEF)", "validateitems", 48.0),
    ("Write VARIANT", "writes", 24.0),
    ("IOPCItemIO::Read item ID (pointer)", "itemio", 8.0),
];

/// The counts of a soak client's last line (`soak-client: counts rounds=R ...`).
pub fn parse_counts(out: &str) -> Option<Vec<(String, u64)>> {
    let line = out
        .lines()
        .rev()
        .find(|l| l.starts_with("soak-client: counts "))?;
    line.trim_start_matches("soak-client: counts ")
        .split_whitespace()
        .map(|kv| {
            let (k, v) = kv.split_once('=')?;
            Some((k.to_owned(), v.parse().ok()?))
        })
        .collect()
}

/// The bytes Wine's stub keeps for `counts` ([`KEPT_PER_ITEM`]).
pub fn predicted_bytes(counts: &[(String, u64)]) -> f64 {
    KEPT_PER_ITEM
        .iter()
        .map(|(_, name, bytes)| {
            counts
                .iter()
                .filter(|(k, _)| k == name)
                .map(|(_, n)| *n as f64 * bytes)
                .sum::<f64>()
        })
        .sum()
}

fn options(args: &[String]) -> Result<Options, String> {
    let mut o = Options {
        minutes: 5.0,
        clients: 4,
        items: 1000,
        round_seconds: 60,
        calls: None,
        stall_seconds: 60,
        simulate_stall: false,
        all_ids: false,
        load: false,
        net: false,
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--load" {
            o.load = true;
            o.clients = 20;
            o.items = 1000;
            o.round_seconds = 60;
            // Three rounds of 60 s with the 15 s pause after each.
            o.minutes = 3.0 * 75.0 / 60.0 - 0.1;
            o.calls = Some(LOAD_CALLS.into());
            o.all_ids = true;
            continue;
        }
        if a == "--no-in-arrays" {
            o.calls = Some(NO_IN_ARRAYS.into());
            continue;
        }
        if a == "--net" {
            o.net = true;
            continue;
        }
        if a == "--simulate-stall" {
            o.simulate_stall = true;
            continue;
        }
        let v = it.next().ok_or(format!("soak: {a} needs a value"))?;
        let bad = || format!("soak: bad value `{v}` for {a}");
        match a.as_str() {
            "--minutes" => o.minutes = v.parse().map_err(|_| bad())?,
            "--clients" => o.clients = v.parse().map_err(|_| bad())?,
            "--items" => o.items = v.parse().map_err(|_| bad())?,
            "--round-seconds" => o.round_seconds = v.parse().map_err(|_| bad())?,
            "--calls" => o.calls = Some(v.clone()),
            "--ids" => o.all_ids = v == "all",
            "--stall-seconds" => o.stall_seconds = v.parse().map_err(|_| bad())?,
            _ => return Err(format!("soak: unknown option {a}")),
        }
    }
    Ok(o)
}

/// The Linux PID of the Wine process running ServerCTOPC.exe `-Embedding` from `exe` in
/// the Wine prefix `pfx`: its command line holds the exe's Windows path under this
/// worktree (started by COM) or starts with its Unix path (started by the scale benchmark
/// through the loader), and its environment names `pfx` (a server of the same build in
/// another prefix, e.g. the test prefix's, is not this one).
pub fn server_pid(exe: &Path, pfx: &Path) -> Option<u32> {
    let windows = wine::windows_path(exe);
    let unix = exe.display().to_string();
    for e in std::fs::read_dir("/proc").ok()?.flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(cmd) = std::fs::read(e.path().join("cmdline")) else {
            continue;
        };
        let cmd = String::from_utf8_lossy(&cmd);
        let ours = cmd.contains(&windows) || cmd.starts_with(&unix);
        if ours && cmd.contains("-Embedding") && in_prefix(&e.path(), pfx) {
            return Some(pid);
        }
    }
    None
}

/// Whether the process at `proc_dir` (`/proc/PID`) runs in the Wine prefix `pfx`.
fn in_prefix(proc_dir: &Path, pfx: &Path) -> bool {
    std::fs::read(proc_dir.join("environ")).is_ok_and(|env| environ_names_prefix(&env, pfx))
}

/// Whether a `/proc/PID/environ` text sets `WINEPREFIX` to `pfx`.
pub fn environ_names_prefix(environ: &[u8], pfx: &Path) -> bool {
    let want = pfx.as_os_str().as_encoded_bytes();
    environ.split(|&b| b == 0).any(|var| {
        var.strip_prefix(b"WINEPREFIX=")
            .is_some_and(|v| v.strip_suffix(b"/").unwrap_or(v) == want)
    })
}

/// VmRSS of `pid` in MB.
pub fn rss_mb(pid: u32) -> Option<f64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = s.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// (predicted MB kept so far, measured MB) per round from the second on: the slope of
/// these is the resident growth per byte Wine's leak predicts.
pub fn explained(after_rounds: &[(f64, f64)], predicted: &[f64]) -> Vec<(f64, f64)> {
    let mut sum = 0.0;
    let mut out = Vec::new();
    for (i, ((_, mb), p)) in after_rounds.iter().zip(predicted).enumerate() {
        sum += p / (1024.0 * 1024.0);
        if i > 0 {
            out.push((sum, *mb));
        }
    }
    out
}

/// The least-squares slope of `points` (x, y).
pub fn slope(points: &[(f64, f64)]) -> Option<f64> {
    let n = points.len() as f64;
    if points.len() < 2 {
        return None;
    }
    let mx = points.iter().map(|p| p.0).sum::<f64>() / n;
    let my = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

fn spawn(pfx: &Path, exe: &Path, args: &[String], out: Stdio) -> Result<Child, String> {
    wine::wine_in(pfx, exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(out)
        .spawn()
        .map_err(|e| format!("start {}: {e}", exe.display()))
}

/// A churning client and what it printed: its lines and when it last printed one (its
/// progress: a line per round).
struct Watched {
    child: Child,
    log: Arc<Mutex<(String, Instant)>>,
    reader: Option<std::thread::JoinHandle<()>>,
}

impl Watched {
    fn since_progress(&self) -> Duration {
        self.log.lock().map_or(Duration::ZERO, |l| l.1.elapsed())
    }

    /// Waits for the client (it has ended): whether it succeeded, and its output.
    fn finish(mut self) -> (bool, String) {
        let ok = self.child.wait().is_ok_and(|s| s.success());
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
        let text = self.log.lock().map_or(String::new(), |l| l.0.clone());
        (ok, text)
    }
}

fn watch(mut child: Child) -> Watched {
    let log = Arc::new(Mutex::new((String::new(), Instant::now())));
    let reader = child.stdout.take().map(|out| {
        let log = Arc::clone(&log);
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if let Ok(mut l) = log.lock() {
                    l.0.push_str(&line);
                    l.0.push('\n');
                    l.1 = Instant::now();
                }
            }
        })
    });
    Watched { child, log, reader }
}

/// A process of winedbg's `info thread`: Windows pid, image name, thread ids.
#[derive(Debug, PartialEq)]
pub struct WineProcess {
    pub pid: u32,
    pub name: String,
    pub threads: Vec<u32>,
}

/// Parses winedbg's `info thread`: a process line `0000011c ServerCTOPC.exe` (the
/// debugger's own marked `(D)`), then its threads, each `\t00000120    0     main`.
pub fn parse_info_thread(text: &str) -> Vec<WineProcess> {
    let hex8 = |t: &str| {
        (t.len() == 8)
            .then(|| u32::from_str_radix(t, 16).ok())
            .flatten()
    };
    let mut out: Vec<WineProcess> = Vec::new();
    for line in text.lines() {
        let mut words = line.split_whitespace();
        let Some(id) = words.next().and_then(hex8) else {
            continue;
        };
        if line.starts_with('\t') {
            if let Some(p) = out.last_mut() {
                p.threads.push(id);
            }
        } else {
            let rest: Vec<&str> = words.filter(|w| *w != "(D)").collect();
            out.push(WineProcess {
                pid: id,
                name: rest.join(" "),
                threads: Vec::new(),
            });
        }
    }
    out
}

/// The processes of a stall report: the server and the soak clients.
fn is_ours(name: &str) -> bool {
    let n = name.to_ascii_lowercase();
    n.ends_with("serverctopc.exe") || n.ends_with("soak-client.exe")
}

/// A winedbg script that attaches to each of `procs` in turn and backtraces every thread.
pub fn backtrace_script(procs: &[WineProcess]) -> String {
    let mut s = String::new();
    for p in procs {
        // winedbg's first backtrace after an attach faults (c0000005) here, whatever the
        // thread: a warm-up one of the debugger's own thread in the process first.
        s += &format!("attach 0x{:x}\necho (warm-up)\nbt\n", p.pid);
        for t in &p.threads {
            s += &format!(
                "echo ==== {} (process 0x{:x}) thread 0x{t:x}\n",
                p.name, p.pid
            );
            // `bt` faults (c0000005) on the main threads here: a stack dump too,
            // whose words into our code [`symbolize`] resolves.
            s += &format!("thread 0x{t:x}\nbt\ninfo stack 1024\n");
        }
        s += "detach\n";
    }
    s += "quit\n";
    s
}

/// Runs winedbg in `pfx` on `script` (a file in `dir`), bounded: its output.
fn winedbg(pfx: &Path, dir: &Path, script: &str) -> Result<String, String> {
    let file = dir.join("winedbg-script.txt");
    let out = dir.join("winedbg-out.txt");
    std::fs::write(&file, script).map_err(|e| format!("{}: {e}", file.display()))?;
    let f = std::fs::File::create(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    let f2 = f.try_clone().map_err(|e| e.to_string())?;
    let mut c = wine::wine_in(pfx, "winedbg");
    c.arg("--file")
        .arg(&file)
        .stdin(Stdio::null())
        .stdout(f)
        .stderr(f2);
    let status = util::run_with_timeout(&mut c, Duration::from_secs(180));
    let text = std::fs::read_to_string(&out).unwrap_or_default();
    match status {
        Ok(_) => Ok(text),
        Err(e) => Ok(format!("{text}\n(winedbg: {e})\n")),
    }
}

/// The Linux view of `pid`'s threads: name, state and kernel wait channel of each.
fn linux_threads(pid: u32) -> String {
    let mut s = format!("== Linux pid {pid}: {}\n", {
        let c = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        String::from_utf8_lossy(&c).replace('\0', " ")
    });
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return s + "   (gone)\n";
    };
    for t in tasks.flatten() {
        let read = |f: &str| std::fs::read_to_string(t.path().join(f)).unwrap_or_default();
        let stat = read("stat");
        // The state is the first field after the parenthesised name.
        let state = stat
            .rsplit_once(") ")
            .map_or("?", |(_, r)| &r[..1.min(r.len())]);
        s += &format!(
            "   tid {} {:<20} state {state} wchan {}\n",
            t.file_name().to_string_lossy(),
            read("comm").trim(),
            read("wchan").trim()
        );
    }
    s
}

/// The module and return address of a winedbg frame line of a module without symbols:
/// `  5 0x0000014034af0e in serverctopc (+0x34af0e) (...)` is ("serverctopc", 0x14034af0e).
pub fn frame_address(line: &str) -> Option<(String, u64)> {
    let mut w = line.split_whitespace();
    let (_, addr, in_, module, offset) = (w.next()?, w.next()?, w.next()?, w.next()?, w.next()?);
    if in_ != "in" || !offset.starts_with("(+0x") {
        return None;
    }
    let addr = u64::from_str_radix(addr.strip_prefix("0x")?, 16).ok()?;
    Some((module.to_ascii_lowercase(), addr))
}

/// The module name winedbg gives the executable of a `==== <exe> (process ...)` header.
fn header_module(line: &str) -> Option<String> {
    let exe = line.strip_prefix("==== ")?.split_whitespace().next()?;
    let stem = exe.rsplit('\\').next()?.to_ascii_lowercase();
    Some(stem.trim_end_matches(".exe").to_owned())
}

/// The words of an `info stack` line (`0x0000000021f548:  000000007b075550 0000000000000003`).
pub fn stack_words(line: &str) -> Option<Vec<u64>> {
    let (at, words) = line.split_once(":  ")?;
    u64::from_str_radix(at.strip_prefix("0x")?, 16).ok()?;
    words
        .split_whitespace()
        .map(|w| u64::from_str_radix(w, 16).ok())
        .collect()
}

/// Our executables load at their preferred base (no relocation under Wine here).
const IMAGE_BASE: u64 = 0x1_4000_0000;

/// `winedbg` output with each frame of our executables followed by its functions and lines
/// (from the executables' DWARF, `addr2line`, one run per executable; a return address
/// minus 1, inside the call). A thread whose `bt` faults has an `info stack` dump instead:
/// it becomes the list of its words that resolve to our code (a scan, not a walk).
/// `exes`: (winedbg's module name, path).
fn symbolize(bt: &str, exes: &[(&str, &Path)]) -> String {
    let image_end = |m: &str| {
        exes.iter()
            .find(|(n, _)| *n == m)
            .and_then(|(_, p)| std::fs::metadata(p).ok())
            .map_or(IMAGE_BASE, |md| IMAGE_BASE + md.len())
    };
    // Per line: the (module, address) pairs to resolve.
    let mut module = String::new();
    let mut wanted: Vec<Vec<(String, u64)>> = Vec::new();
    for line in bt.lines() {
        if let Some(m) = header_module(line) {
            module = m;
        }
        let mut w = Vec::new();
        if let Some((m, a)) = frame_address(line) {
            w.push((m, a.saturating_sub(1)));
        } else if let Some(words) = stack_words(line) {
            let end = image_end(&module);
            w.extend(
                words
                    .into_iter()
                    .filter(|a| (IMAGE_BASE + 0x1000..end).contains(a))
                    .map(|a| (module.clone(), a - 1)),
            );
        }
        wanted.push(w);
    }
    let mut found: std::collections::BTreeMap<String, Vec<u64>> = Default::default();
    for (m, a) in wanted.iter().flatten() {
        found.entry(m.clone()).or_default().push(*a);
    }
    let mut names: HashMap<(String, u64), Vec<String>> = HashMap::new();
    for (module, addrs) in &mut found {
        let Some((_, exe)) = exes.iter().find(|(m, _)| m == module) else {
            continue;
        };
        addrs.sort_unstable();
        addrs.dedup();
        let mut c = std::process::Command::new("addr2line");
        c.args(["-a", "-f", "-C", "-i", "-e"]).arg(exe);
        c.args(addrs.iter().map(|a| format!("0x{a:x}")));
        let Ok(out) = c.stderr(Stdio::null()).output() else {
            continue;
        };
        let text = String::from_utf8_lossy(&out.stdout);
        let mut cur: Option<u64> = None;
        let mut lines = text.lines();
        while let Some(l) = lines.next() {
            if let Some(a) = l
                .strip_prefix("0x")
                .and_then(|h| u64::from_str_radix(h, 16).ok())
            {
                cur = Some(a);
                continue;
            }
            let place = lines.next().unwrap_or("");
            // A word that is data, or code without a function name, says nothing.
            if let (Some(a), false) = (cur, l == "??") {
                names
                    .entry((module.clone(), a))
                    .or_default()
                    .push(format!("{l} ({place})"));
            }
        }
    }
    let mut out = String::new();
    for (line, w) in bt.lines().zip(&wanted) {
        let dump = stack_words(line).is_some();
        if !dump {
            out += line;
            out.push('\n');
        }
        for (m, a) in w {
            let Some(ns) = names.get(&(m.clone(), *a)) else {
                continue;
            };
            if dump {
                out += &format!("  stack word 0x{:x} in {m}:\n", a + 1);
            }
            for n in ns {
                out += &format!("        {n}\n");
            }
        }
    }
    out
}

/// Writes a stall report to `target/soak/stall-<unix time>.txt`: `what`, the Linux threads
/// of `linux_pids` and winedbg backtraces of every thread of the server and of the soak
/// clients (the prefix still runs). Its path.
pub fn capture_backtraces(
    pfx: &Path,
    linux_pids: &[u32],
    exes: &[(&str, &Path)],
    what: &str,
) -> Result<PathBuf, String> {
    let dir = util::root().join("target/soak");
    capture(
        &dir,
        pfx,
        linux_pids,
        exes,
        &is_ours,
        &format!("soak stall: {what}"),
    )
}

/// Writes a stall report to `dir/stall-<unix time>.txt`: `what`, the Linux threads of
/// `linux_pids` and winedbg backtraces of every thread of the processes of `pfx` whose
/// name `ours` accepts, the frames of `exes` resolved (the prefix still runs). Its path.
/// Also the e2e runs' stall guard (`wine/guard.rs`).
pub fn capture(
    dir: &Path,
    pfx: &Path,
    linux_pids: &[u32],
    exes: &[(&str, &Path)],
    ours: &dyn Fn(&str) -> bool,
    what: &str,
) -> Result<PathBuf, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let path = dir.join(format!("stall-{secs}.txt"));
    let mut report = format!("{what}\n\n");
    for pid in linux_pids {
        report += &linux_threads(*pid);
    }
    let listing = winedbg(pfx, dir, "info thread\nquit\n")?;
    report += "\n== winedbg: info thread\n";
    report += &listing;
    let ours: Vec<WineProcess> = parse_info_thread(&listing)
        .into_iter()
        .filter(|p| ours(&p.name))
        .collect();
    report += "\n== winedbg: backtraces, our frames resolved by addr2line\n";
    report += &symbolize(&winedbg(pfx, dir, &backtrace_script(&ours))?, exes);
    std::fs::write(&path, report).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(path)
}

pub fn run(args: &[String]) -> Result<(), String> {
    let o = options(args)?;
    setup::run(&[])?;
    let artifacts = build::run(&[])?;
    build::e2e_bin("soak-client")?;
    let client = artifacts.dir.join("soak-client.exe");
    let pfx = prefix();
    wine::ensure_prefix(&pfx)?;
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
    let mut sim = None;
    let server = if o.net {
        let sim_exe = build::asix_sim()?;
        let dir = crate::demo::stage(&artifacts, &sim_exe)?;
        sim = Some(crate::demo::Sim::start(&sim_exe, &dir)?);
        dir.join("ServerCTOPC.exe")
    } else {
        artifacts.server.clone()
    };
    let result = (|| {
        let limit = Duration::from_secs(120);
        let mut regsvr = wine::wine_in(&pfx, "regsvr32");
        regsvr.arg("/s").arg(&artifacts.proxy);
        let mut reg = wine::wine_in(&pfx, &server);
        reg.arg("/RegServer");
        for c in [&mut regsvr, &mut reg] {
            let status = util::run_with_timeout(c, limit)?;
            if !status.success() {
                return Err(format!("registration in the soak prefix failed: {status}"));
            }
        }
        soak(&o, &pfx, &client, &server)
    })();
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
    drop(sim);
    result
}

fn soak(o: &Options, pfx: &Path, client: &Path, server: &Path) -> Result<(), String> {
    let total = Duration::from_secs_f64(o.minutes * 60.0);
    let hold_secs = total.as_secs() + u64::from(o.round_seconds) + 120;
    let mut holder = spawn(
        pfx,
        client,
        &["--hold".into(), "--seconds".into(), hold_secs.to_string()],
        Stdio::inherit(),
    )?;
    let started = Instant::now();
    let pid = loop {
        if let Some(p) = server_pid(server, pfx) {
            break p;
        }
        if started.elapsed() > Duration::from_secs(60) {
            let _ = holder.kill();
            return Err("soak: the server did not start within 60 s".into());
        }
        std::thread::sleep(Duration::from_millis(500));
    };
    std::thread::sleep(Duration::from_secs(5));
    println!(
        "soak: server pid {pid}; {} clients x {} s x {} items per round, {} min, calls {}",
        o.clients,
        o.round_seconds,
        o.items,
        o.minutes,
        o.calls.as_deref().unwrap_or("(all)")
    );
    let t0 = Instant::now();
    let sample = |what: &str| -> Option<f64> {
        let mb = rss_mb(pid)?;
        println!(
            "soak: {:7.1} s  {mb:8.1} MB  {what}",
            t0.elapsed().as_secs_f64()
        );
        Some(mb)
    };
    sample("before the first round");
    let mut after_rounds: Vec<(f64, f64)> = Vec::new();
    // The bytes Wine's leak predicts for each round.
    let mut predicted: Vec<f64> = Vec::new();
    let mut round = 0u32;
    let mut total_device_failed = 0u64;
    while t0.elapsed() < total {
        round += 1;
        let churn: Vec<String> = vec![
            "--seconds".into(),
            o.round_seconds.to_string(),
            "--items".into(),
            o.items.to_string(),
        ];
        let mut churn = churn;
        if let Some(c) = &o.calls {
            churn.extend(["--calls".to_owned(), c.clone()]);
        }
        if o.all_ids {
            churn.extend(["--ids".to_owned(), "all".to_owned()]);
        }
        let mut kids = Vec::new();
        for i in 0..o.clients {
            let mut args = churn.clone();
            if o.simulate_stall && round == 1 && i == 0 {
                args.extend(["--stall-after".to_owned(), "10".to_owned()]);
            }
            kids.push(watch(spawn(pfx, client, &args, Stdio::piped())?));
        }
        let deadline = Instant::now() + Duration::from_secs(u64::from(o.round_seconds) + 120);
        let stall = Duration::from_secs(o.stall_seconds);
        loop {
            let mut running = 0;
            let mut quiet: Option<(usize, Duration)> = None;
            for (i, k) in kids.iter_mut().enumerate() {
                if matches!(k.child.try_wait(), Ok(None)) {
                    running += 1;
                    let since = k.since_progress();
                    if since >= stall && quiet.is_none_or(|(_, q)| since > q) {
                        quiet = Some((i, since));
                    }
                }
            }
            if running == 0 {
                break;
            }
            if let Some((i, since)) = quiet {
                let what = format!(
                    "round {round}: client {i} (of {}) made no progress for {} s{}",
                    kids.len(),
                    since.as_secs(),
                    if o.simulate_stall {
                        " (--simulate-stall)"
                    } else {
                        ""
                    }
                );
                println!("soak: {what}: a stall; taking backtraces before stopping anything");
                let mut pids = vec![pid, holder.id()];
                pids.extend(kids.iter().map(|k| k.child.id()));
                let exes = [("serverctopc", server), ("soak-client", client)];
                let captured = capture_backtraces(pfx, &pids, &exes, &what);
                kids.iter_mut().for_each(|k| {
                    let _ = k.child.kill();
                });
                let _ = holder.kill();
                return Err(match captured {
                    Ok(path) => format!(
                        "soak: {what}: a stall; backtraces of the server and the clients in {}",
                        path.display()
                    ),
                    Err(e) => format!("soak: {what}: a stall; the backtraces failed: {e}"),
                });
            }
            if Instant::now() > deadline {
                kids.iter_mut().for_each(|k| {
                    let _ = k.child.kill();
                });
                return Err(format!(
                    "soak: round {round}: clients still run after the deadline"
                ));
            }
            sample(&format!("round {round}, {running} clients"));
            std::thread::sleep(Duration::from_secs(5));
        }
        let mut failed = 0;
        let mut bytes = 0.0;
        let (mut device_reads, mut device_failed) = (0u64, 0u64);
        for k in kids {
            let (ok, text) = k.finish();
            for l in text.lines().filter(|l| l.contains(" device failure ")) {
                println!("soak:   client: {l}");
            }
            match parse_counts(&text).filter(|_| ok) {
                Some(c) => {
                    if let Some(line) = text.lines().rev().find(|l| l.contains(" counts ")) {
                        println!("soak:   client: {line}");
                    }
                    bytes += predicted_bytes(&c);
                    let count =
                        |name: &str| c.iter().find(|(k, _)| k == name).map_or(0, |(_, n)| *n);
                    device_reads += count("devicereads");
                    device_failed += count("devicefailed");
                }
                None => failed += 1,
            }
        }
        predicted.push(bytes);
        if device_reads > 0 {
            println!("soak: round {round}: {device_reads} device reads, {device_failed} failed");
            total_device_failed += device_failed;
        }
        std::thread::sleep(Duration::from_secs(15));
        let mb = sample(&format!(
            "15 s after round {round} ({failed} clients failed)"
        ))
        .ok_or("soak: the server is gone")?;
        after_rounds.push((f64::from(round), mb));
    }
    let _ = holder.kill();
    let steady: Vec<(f64, f64)> = after_rounds.iter().skip(1).copied().collect();
    println!("soak: after each round: {after_rounds:?}");
    let per_minute = |mb_per_round: f64| mb_per_round * 60.0 / f64::from(o.round_seconds + 15);
    match slope(&steady) {
        Some(s) => {
            println!(
                "soak: measured slope after warm-up: {s:+.2} MB per round ({:+.2} MB/min; {} rounds)",
                per_minute(s),
                steady.len()
            );
            // Rounds 2.. are the ones of the slope: the mean of their prediction.
            let p = predicted.iter().skip(1).sum::<f64>()
                / predicted.len().saturating_sub(1).max(1) as f64
                / (1024.0 * 1024.0);
            println!(
                "soak: slope Wine's [in]-array leak predicts: {p:+.2} MB per round ({:+.2} MB/min)",
                per_minute(p)
            );
            println!(
                "soak: residual (measured - predicted): {:+.2} MB per round ({:+.2} MB/min)",
                s - p,
                per_minute(s - p)
            );
            // Rounds differ in work: resident memory against the predicted bytes so far.
            if let Some(r) = slope(&explained(&after_rounds, &predicted)) {
                println!("soak: resident growth per predicted byte after warm-up: {r:.2} (1 = all Wine's leak)");
            }
        }
        None => println!("soak: too few rounds for a slope (run longer: --minutes)"),
    }
    if o.load && total_device_failed > 0 {
        return Err(format!(
            "soak --load: {total_device_failed} device reads failed (expected none)"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{environ_names_prefix, parse_counts, predicted_bytes, slope};
    use std::path::Path;

    #[test]
    fn the_server_of_a_prefix_is_told_by_its_environment() {
        let env = b"HOME=/root\0WINEPREFIX=/w/target/wine/scale-prefix\0WINEDEBUG=-all\0";
        assert!(environ_names_prefix(
            env,
            Path::new("/w/target/wine/scale-prefix")
        ));
        assert!(!environ_names_prefix(
            env,
            Path::new("/w/target/wine/prefix")
        ));
        assert!(environ_names_prefix(
            b"WINEPREFIX=/w/p/\0",
            Path::new("/w/p")
        ));
        assert!(!environ_names_prefix(
            b"XWINEPREFIX=/w/p\0",
            Path::new("/w/p")
        ));
        assert!(!environ_names_prefix(b"", Path::new("/w/p")));
    }

    #[test]
    fn counts_and_the_bytes_they_predict() {
        let out = "noise\nsoak-client: counts rounds=3 failures=0 additems=3000 \
                   validateitems=3000 writes=750 itemio=3000\n";
        let c = parse_counts(out).unwrap();
        assert_eq!(c[0], ("rounds".to_owned(), 3));
        let want = 3000.0 * 48.0 + 3000.0 * 48.0 + 750.0 * 24.0 + 3000.0 * 8.0;
        assert_eq!(predicted_bytes(&c), want);
        assert_eq!(parse_counts("soak-client: held"), None);
        let mb = 1024.0 * 1024.0;
        let rounds = [(1.0, 50.0), (2.0, 52.0), (3.0, 56.0)];
        let e = super::explained(&rounds, &[1.0 * mb, 2.0 * mb, 4.0 * mb]);
        assert_eq!(e, [(3.0, 52.0), (7.0, 56.0)]);
        assert!((slope(&e).unwrap() - 1.0).abs() < 1e-9);
        assert_eq!(parse_counts("soak-client: counts rounds=x"), None);
    }

    #[test]
    fn winedbg_threads_and_the_backtrace_script() {
        let listing = "0x000001700555f5 ntdll+0x555f5: ret\n\
            process  tid      prio    name (all IDs are in hex)\n\
            00000020 (D) Z:\\t\\soak-client.exe\n\
            \t00000024    0     main\n\
            \t0000016c    0 <== \n\
            0000011c ServerCTOPC.exe\n\
            \t00000120    0     main\n\
            \t00000150    0     wine_rpcrt4_server\n\
            00000198 start.exe\n";
        let p = super::parse_info_thread(listing);
        assert_eq!(p.len(), 3);
        assert_eq!(p[0].pid, 0x20);
        assert_eq!(p[0].name, "Z:\\t\\soak-client.exe");
        assert_eq!(p[0].threads, [0x24, 0x16c]);
        assert_eq!(p[1].threads, [0x120, 0x150]);
        assert!(p[2].threads.is_empty());
        assert!(super::is_ours(&p[0].name) && super::is_ours(&p[1].name));
        assert!(!super::is_ours(&p[2].name));
        let script = super::backtrace_script(&p[1..2]);
        assert_eq!(
            script,
            "attach 0x11c\necho (warm-up)\nbt\necho ==== ServerCTOPC.exe (process 0x11c) thread 0x120\nthread 0x120\nbt\ninfo stack 1024\n\
             echo ==== ServerCTOPC.exe (process 0x11c) thread 0x150\nthread 0x150\nbt\ninfo stack 1024\ndetach\nquit\n"
        );
        let o = super::options(&[
            "--simulate-stall".into(),
            "--stall-seconds".into(),
            "30".into(),
        ]);
        let o = o.unwrap();
        assert!(o.simulate_stall);
        assert_eq!(o.stall_seconds, 30);
    }

    #[test]
    fn slope_of_a_line_and_of_flat_data() {
        let line: Vec<(f64, f64)> = (0..5)
            .map(|i| (f64::from(i), 3.0 * f64::from(i) + 1.0))
            .collect();
        assert!((slope(&line).unwrap() - 3.0).abs() < 1e-9);
        assert_eq!(slope(&[(1.0, 5.0), (2.0, 5.0)]), Some(0.0));
        assert_eq!(slope(&[(1.0, 5.0)]), None);
    }
}
