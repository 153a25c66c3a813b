//! `cargo xtask soak [--minutes M] [--clients K] [--items N] [--round-seconds R]
//! [--calls LIST | --no-in-arrays]`: the memory soak of issue 19 (not in CI).
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
//! `--calls LIST` chooses the calls of a client round (`soak-client.rs`: `add`,
//! `validate`, `read`, `write`, `itemio`, `subscribe`, `remove`; default all);
//! `--no-in-arrays` is `--calls read,subscribe,remove`: connect, GetStatus, AddGroup,
//! Read and RemoveItems by handle, a subscription, RemoveGroup, disconnect — no call
//! whose `[in]` array the stub allocates. Each client reports how many items it sent in
//! allocated `[in]` arrays; the soak prints beside the measured slope the one Wine's
//! stub predicts (it keeps the top-level block of such an array: [`KEPT_PER_ITEM`],
//! docs/wine-ndr-leak.md) and the residual, the growth Wine's leak does not explain.

use crate::{build, setup, util, wine};
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
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
}

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
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--no-in-arrays" {
            o.calls = Some(NO_IN_ARRAYS.into());
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
            _ => return Err(format!("soak: unknown option {a}")),
        }
    }
    Ok(o)
}

/// The Linux PID of the Wine process running the soak's ServerCTOPC.exe: its command line
/// names the exe by its Windows path under this worktree.
fn server_pid(exe: &Path) -> Option<u32> {
    let want = format!("Z:{}", exe.display()).replace('/', "\\");
    for e in std::fs::read_dir("/proc").ok()?.flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(cmd) = std::fs::read(e.path().join("cmdline")) else {
            continue;
        };
        let cmd = String::from_utf8_lossy(&cmd);
        if cmd.contains(&want) && cmd.contains("-Embedding") {
            return Some(pid);
        }
    }
    None
}

/// VmRSS of `pid` in MB.
fn rss_mb(pid: u32) -> Option<f64> {
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

pub fn run(args: &[String]) -> Result<(), String> {
    let o = options(args)?;
    setup::run(&[])?;
    let artifacts = build::run(&[])?;
    util::run(util::cargo().args([
        "build",
        "--release",
        "--target",
        setup::TARGET,
        "-p",
        "e2e-tests",
        "--bin",
        "soak-client",
    ]))?;
    let client = artifacts.dir.join("soak-client.exe");
    let pfx = prefix();
    wine::ensure_prefix(&pfx)?;
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
    let result = (|| {
        let limit = Duration::from_secs(120);
        let mut regsvr = wine::wine_in(&pfx, "regsvr32");
        regsvr.arg("/s").arg(&artifacts.proxy);
        let mut reg = wine::wine_in(&pfx, &artifacts.server);
        reg.arg("/RegServer");
        for c in [&mut regsvr, &mut reg] {
            let status = util::run_with_timeout(c, limit)?;
            if !status.success() {
                return Err(format!("registration in the soak prefix failed: {status}"));
            }
        }
        soak(&o, &pfx, &client, &artifacts.server)
    })();
    wine::wineserver_in(&pfx, "-k", Duration::from_secs(20));
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
        if let Some(p) = server_pid(server) {
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
        let mut kids = Vec::new();
        for _ in 0..o.clients {
            kids.push(spawn(pfx, client, &churn, Stdio::piped())?);
        }
        let deadline = Instant::now() + Duration::from_secs(u64::from(o.round_seconds) + 120);
        loop {
            let running = kids
                .iter_mut()
                .map(|k| k.try_wait())
                .filter(|w| matches!(w, Ok(None)))
                .count();
            if running == 0 {
                break;
            }
            if Instant::now() > deadline {
                kids.iter_mut().for_each(|k| {
                    let _ = k.kill();
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
        for k in kids {
            match k.wait_with_output() {
                Ok(out) if out.status.success() => {
                    let text = String::from_utf8_lossy(&out.stdout);
                    match parse_counts(&text) {
                        Some(c) => {
                            println!("soak:   client: {}", text.trim());
                            bytes += predicted_bytes(&c);
                        }
                        None => failed += 1,
                    }
                }
                _ => failed += 1,
            }
        }
        predicted.push(bytes);
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
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{parse_counts, predicted_bytes, slope};

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
    fn slope_of_a_line_and_of_flat_data() {
        let line: Vec<(f64, f64)> = (0..5)
            .map(|i| (f64::from(i), 3.0 * f64::from(i) + 1.0))
            .collect();
        assert!((slope(&line).unwrap() - 3.0).abs() < 1e-9);
        assert_eq!(slope(&[(1.0, 5.0), (2.0, 5.0)]), Some(0.0));
        assert_eq!(slope(&[(1.0, 5.0)]), None);
    }
}
