//! Asix.Evo REST link benchmark (prints figures, asserts nothing about speed): values per
//! second through one REST link at N subscribed items, and the CPU of the server side per
//! 1,000 values.
//!
//! The REST server is an `asix-sim --rest` process (N noisy variables, 10 ms ticks), so
//! that this process holds only what ServerCTOPC holds: the network backend
//! (`network_backend`: `AsixBackend` over `NetSource` with its own one-thread runtime,
//! the channel's `RestLink`), and a driver loop that polls it every 10 ms as the runtime's
//! driver thread does. Per configuration (the items' rate), the median over one-second
//! windows of the values the backend handed out, and this process's CPU time per 1,000 of
//! them over all the windows.
//!
//! Run: `cargo bench -p asix-net --bench rest` (release). Environment: `BENCH_VARS`
//! (default 10000), `BENCH_RUNS` (one-second windows, default 5), `BENCH_BATCH`
//! (`AsixEvoMaxBatch`, default 100).

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use asix_model::namespace::AsixNamespace;
use asix_net::client::wall_now;
use ctopc_core::model::datasource::{SourceItem, SourceKey, SourceRequest, Subscription};
use ctopc_core::source::{SourceOutput, Wake};
use ctopc_core::VarType;
use test_support::measure::cpu_seconds;

fn env(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

struct Sim(Child);

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `asix-sim --rest` and returns it with its base URL.
fn start_sim(vars: usize) -> (Sim, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_asix-sim"))
        .args(["--noisy", &format!("BENCH:{vars}"), "--tick-ms", "10"])
        .args(["--rest", "127.0.0.1:0"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("asix-sim starts");
    let out = child.stdout.take().unwrap();
    let mut line = String::new();
    BufReader::new(out).read_line(&mut line).unwrap();
    let url = line
        .split_whitespace()
        .find_map(|w| w.strip_prefix("rest="))
        .expect("a rest= on the ready line")
        .to_owned();
    (Sim(child), url)
}

struct NoWake;

impl Wake for NoWake {
    fn wake(&self) {}
}

fn run(url: &str, vars: usize, rate_ms: u32, runs: usize, batch: usize) {
    let ini = format!("[Channel:EVO]\nAsixEvoRest = {url}\nAsixEvoMaxBatch = {batch}\n");
    let (config, _) = asix_model::parse_config(ini.as_bytes(), "bench.ini").unwrap();
    let (ns, _) = AsixNamespace::load(config);
    let ns = Arc::new(ns);
    let mut backend = asix_net::datasource::network_backend(ns, Arc::new(NoWake)).unwrap();
    let channel: Arc<str> = "EVO".into();
    let subs = (0..vars)
        .map(|i| Subscription {
            item: SourceItem {
                key: SourceKey::new(i as u32, 0),
                channel: channel.clone(),
                item_id: format!("asmen.BENCH.V{i:05}.R4").into(),
                canonical_type: VarType::R4,
            },
            sampling_rate_ms: rate_ms,
        })
        .collect();
    backend.request(wall_now(), SourceRequest::Subscribe(subs));
    let mut out = SourceOutput::default();
    // Until every item has a first value.
    let mut seen = vec![false; vars];
    let mut left = vars;
    let t0 = Instant::now();
    while left > 0 && t0.elapsed() < Duration::from_secs(30) {
        backend.poll(wall_now(), &mut out);
        for (k, _) in out.updates.drain(..) {
            let s = &mut seen[k.index() as usize];
            if !std::mem::replace(s, true) {
                left -= 1;
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    assert_eq!(left, 0, "every item got a value");
    let mut rates = Vec::new();
    let (cpu_start, mut total) = (cpu_seconds(), 0usize);
    for _ in 0..runs {
        let start = Instant::now();
        let mut n = 0usize;
        while start.elapsed() < Duration::from_secs(1) {
            backend.poll(wall_now(), &mut out);
            n += out.updates.len();
            out.updates.clear();
            std::thread::sleep(Duration::from_millis(10));
        }
        rates.push(n as f64 / start.elapsed().as_secs_f64());
        total += n;
    }
    // Over all windows: the process's CPU clock counts in 10 ms ticks.
    let cpu = cpu_seconds() - cpu_start;
    println!(
        "rest: {vars} items at {rate_ms} ms, batch {batch}: {:.0} values/s (median of {runs} s; runs {:?}), server CPU {:.3} ms per 1,000 values ({cpu:.2} s CPU for {total} values)",
        median(rates.clone()),
        rates.iter().map(|r| r.round() as u64).collect::<Vec<_>>(),
        cpu * 1e6 / total.max(1) as f64,
    );
}

fn main() {
    let vars = env("BENCH_VARS", 10_000);
    let runs = env("BENCH_RUNS", 5);
    let batch = env("BENCH_BATCH", 100);
    let (_sim, url) = start_sim(vars);
    // 1000 ms: the plant's usual rate (at most `vars` values a second); 50 ms, the
    // fastest poll: what one link carries when it polls without pause.
    for rate in [1000, 50] {
        run(&url, vars, rate, runs, batch);
    }
}
