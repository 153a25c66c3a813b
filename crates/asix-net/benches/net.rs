//! asix network benchmark (prints figures, asserts nothing about speed).
//!
//! 1. VQT updates per second from a simulator to a client on loopback: one link, N noisy
//!    variables sampled every 10 ms (every sample sent), counted at the client's event sink.
//!    Median of several one-second windows, over a plaintext link and over a TLS 1.3 link,
//!    and their ratio (goal: TLS within 20 % of plaintext).
//! 2. Failover time after a simulator process is killed (SIGKILL; the kernel closes its
//!    sockets): from the kill to the first GOOD value from the other simulator, for
//!    StopAfterFirstServerFound = tak and nie, against FindServerTimeout. Also a hung
//!    (stop-answering) simulator, detected by keep-alive within NetTimeout.
//!
//! Run: `cargo bench -p asix-net --bench net` (release). Environment: `BENCH_VARS` (default
//! 20000), `BENCH_RUNS` (default 5), `BENCH_FAILOVER_RUNS` (default 3).

use std::io::{BufRead, BufReader, Write};
use std::net::{Ipv4Addr, SocketAddr};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use asix_model::ItemKey;
use asix_net::client::ClientEvent;
use asix_net::secure::{ClientSecurity, ServerSecurity, ServerTls};
use asix_net::sim::plant::ChannelDef;
use asix_net::sim::{self, SimConfig};
use asix_net::tls;
use asix_net::{AsixClient, ClientConfig};
use tokio::runtime::{Builder, Runtime};

fn env(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn runtime(threads: usize, name: &str) -> Runtime {
    Builder::new_multi_thread()
        .worker_threads(threads)
        .thread_name(name)
        .enable_all()
        .build()
        .unwrap()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// The benchmark's certificates: the simulators' (also in files, for the asix-sim
/// processes) and the client's.
struct Pki {
    server: tls::Generated,
    client: tls::Generated,
    cert_file: PathBuf,
    key_file: PathBuf,
}

fn pki() -> &'static Pki {
    static PKI: OnceLock<Pki> = OnceLock::new();
    PKI.get_or_init(|| {
        let server = tls::generate("BENCH-SIM", None).unwrap();
        let dir = std::env::temp_dir().join(format!("asix-net-bench-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cert_file = dir.join("asix-cert.pem");
        let key_file = dir.join("asix-key.pem");
        std::fs::write(&cert_file, &server.cert_pem).unwrap();
        std::fs::write(&key_file, &server.key_pem).unwrap();
        Pki {
            server,
            client: tls::generate("BENCH", None).unwrap(),
            cert_file,
            key_file,
        }
    })
}

fn client_cfg(targets: Vec<SocketAddr>, plaintext: bool) -> ClientConfig {
    let mut c = ClientConfig::new("BENCH.", "BENCH");
    c.discovery_targets = targets;
    c.discovery_bind = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    c.security = if plaintext {
        ClientSecurity::Plaintext
    } else {
        ClientSecurity::tls(
            &pki().client.identity,
            tls::Trust::Fingerprints(vec![pki().server.identity.fingerprint()]),
        )
        .unwrap()
    };
    c
}

/// The median VQT/s of one link, plaintext or TLS.
fn throughput(plaintext: bool) -> f64 {
    let n = env("BENCH_VARS", 20_000);
    let runs = env("BENCH_RUNS", 5);
    let sampling_ms = 10u32;
    // Separate runtimes (threads) for server and client, as separate processes would be.
    let sim_rt = runtime(1, "sim");
    let cli_rt = runtime(1, "client");
    let mut cfg = SimConfig::new("BENCH-SIM");
    cfg.channels = vec![ChannelDef::noisy("BENCH", n)];
    cfg.tick_ms = 10;
    cfg.security = if plaintext {
        ServerSecurity::plaintext()
    } else {
        ServerSecurity::tls(
            ServerTls::new(&pki().server.identity, tls::Trust::AnyCertificate).unwrap(),
        )
    };
    let sim = sim_rt.block_on(sim::start(cfg)).unwrap();
    let count = Arc::new(AtomicU64::new(0));
    let c2 = count.clone();
    let up = Arc::new(AtomicU64::new(0));
    let up2 = up.clone();
    let sink = move |ev: ClientEvent| match ev {
        ClientEvent::Updates(u) => {
            c2.fetch_add(u.len() as u64, Ordering::Relaxed);
        }
        ClientEvent::ChannelUp { .. } => {
            up2.fetch_add(1, Ordering::Relaxed);
        }
        _ => {}
    };
    let client = AsixClient::start(
        client_cfg(vec![sim.discovery_addr()], plaintext),
        sink,
        cli_rt.handle(),
    )
    .unwrap();
    let keys: Vec<ItemKey> = (0..n)
        .map(|i| ItemKey::new("BENCH", &format!("V{i:05}")))
        .collect();
    client.subscribe(keys, sampling_ms);
    let t0 = Instant::now();
    while up.load(Ordering::Relaxed) == 0 && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_secs(1)); // warm-up
    let offered = n as f64 * 1000.0 / sampling_ms as f64;
    let mut rates = Vec::new();
    for _ in 0..runs {
        let c0 = count.load(Ordering::Relaxed);
        let t = Instant::now();
        std::thread::sleep(Duration::from_secs(1));
        let got = count.load(Ordering::Relaxed) - c0;
        rates.push(got as f64 / t.elapsed().as_secs_f64());
    }
    let med = median(rates.clone());
    let link = if plaintext { "plaintext" } else { "TLS 1.3" };
    println!(
        "throughput ({link} link): {n} variables sampled every {sampling_ms} ms = {offered:.0} VQT/s offered"
    );
    println!(
        "  runs (VQT/s): {}",
        rates
            .iter()
            .map(|r| format!("{r:.0}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "  median: {med:.0} VQT/s (goal >= 500000: {})",
        if med >= 500_000.0 { "met" } else { "NOT met" }
    );
    drop(client);
    drop(sim);
    cli_rt.shutdown_timeout(Duration::from_secs(1));
    sim_rt.shutdown_timeout(Duration::from_secs(1));
    med
}

/// A simulator process.
struct SimProc {
    child: Child,
    name: String,
    udp: SocketAddr,
}

impl SimProc {
    fn spawn(name: &str) -> SimProc {
        let mut child = Command::new(env!("CARGO_BIN_EXE_asix-sim"))
            .args([
                "--name",
                name,
                "--udp",
                "127.0.0.1:0",
                "--tcp",
                "127.0.0.1:0",
                "--tick-ms",
                "50",
                "--run-for-ms",
                "120000",
            ])
            .arg("--cert")
            .arg(&pki().cert_file)
            .arg("--key")
            .arg(&pki().key_file)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("asix-sim starts");
        let mut line = String::new();
        BufReader::new(child.stdout.as_mut().unwrap())
            .read_line(&mut line)
            .unwrap();
        let udp = line
            .split_whitespace()
            .find_map(|w| w.strip_prefix("udp="))
            .unwrap()
            .parse()
            .unwrap();
        SimProc {
            child,
            name: name.to_owned(),
            udp,
        }
    }
    fn command(&mut self, cmd: &str) {
        let _ = writeln!(self.child.stdin.as_mut().unwrap(), "{cmd}");
    }
}

impl Drop for SimProc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Fault {
    Kill,
    Hang,
}

/// The server the first GOOD value came from, and when.
type Seen = (Option<String>, Option<Instant>);

/// One failover: returns (time to the first GOOD value from the other server, its name).
fn failover_once(
    rt: &Runtime,
    stop_after_first: bool,
    fault: Fault,
    find_ms: u64,
    net_ms: u64,
) -> Option<Duration> {
    let mut a = SimProc::spawn("FA");
    let mut b = SimProc::spawn("FB");
    let mut cfg = client_cfg(vec![a.udp, b.udp], false);
    cfg.options.stop_after_first_server_found = stop_after_first;
    cfg.options.find_server_timeout = Duration::from_millis(find_ms);
    cfg.options.net_timeout = Duration::from_millis(net_ms);
    cfg.keepalive = Duration::from_millis(net_ms / 3);
    let state: Arc<Mutex<Seen>> = Arc::new(Mutex::new((None, None)));
    let st = state.clone();
    let current = Arc::new(Mutex::new(String::new()));
    let cur = current.clone();
    let key = ItemKey::new("Demo_Wytwornia_Kwasu", "ZB1_POZIOM");
    let k2 = key.clone();
    let sink = move |ev: ClientEvent| match ev {
        ClientEvent::ChannelUp { server, .. } => *cur.lock().unwrap() = server,
        ClientEvent::Updates(u) if u.iter().any(|(k, v)| *k == k2 && v.quality.is_good()) => {
            let mut s = st.lock().unwrap();
            let server = cur.lock().unwrap().clone();
            if s.0.as_deref() != Some(&server) {
                s.0 = Some(server);
                s.1 = Some(Instant::now());
            }
        }
        _ => {}
    };
    let client = AsixClient::start(cfg, sink, rt.handle()).unwrap();
    client.subscribe(vec![key], 100);
    let wait = |pred: &dyn Fn(&Seen) -> bool, limit: Duration| {
        let t = Instant::now();
        while t.elapsed() < limit {
            if pred(&state.lock().unwrap()) {
                return true;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        false
    };
    if !wait(&|s| s.0.is_some(), Duration::from_millis(find_ms + 5000)) {
        return None;
    }
    let first = state.lock().unwrap().0.clone().unwrap();
    let victim = if first == a.name { &mut a } else { &mut b };
    let t0 = Instant::now();
    match fault {
        Fault::Kill => {
            let _ = victim.child.kill();
            let _ = victim.child.wait();
        }
        Fault::Hang => {
            victim.command("stop-answering");
        }
    }
    let ok = wait(
        &|s| s.0.as_deref() != Some(&first),
        Duration::from_millis(find_ms + 2 * net_ms + 5000),
    );
    let took = state
        .lock()
        .unwrap()
        .1
        .map(|t| t.saturating_duration_since(t0));
    drop(client);
    if ok {
        took
    } else {
        None
    }
}

fn failover() {
    let runs = env("BENCH_FAILOVER_RUNS", 3);
    let rt = runtime(1, "client");
    let find_ms = 3000; // the defaults of FindServerTimeout and NetTimeout
    let net_ms = 3000;
    for (label, stop, fault, net) in [
        (
            "killed, StopAfterFirstServerFound=tak",
            true,
            Fault::Kill,
            net_ms,
        ),
        (
            "killed, StopAfterFirstServerFound=nie",
            false,
            Fault::Kill,
            net_ms,
        ),
        (
            "hung (stop-answering), tak, NetTimeout=1000",
            true,
            Fault::Hang,
            1000,
        ),
    ] {
        let mut times = Vec::new();
        for _ in 0..runs {
            match failover_once(&rt, stop, fault, find_ms, net) {
                Some(t) => times.push(t.as_secs_f64() * 1000.0),
                None => println!("  ({label}: a run did not fail over)"),
            }
        }
        if times.is_empty() {
            println!("failover {label}: no successful run");
            continue;
        }
        let med = median(times.clone());
        // Killed: FindServerTimeout + 1 s. Hung: detection takes NetTimeout, then the same.
        let (goal, basis) = match fault {
            Fault::Kill => (find_ms + 1000, "FindServerTimeout + 1 s"),
            Fault::Hang => (net + find_ms + 1000, "NetTimeout + FindServerTimeout + 1 s"),
        };
        let goal = goal as f64;
        println!(
            "failover {label}: runs (ms) {}; median {med:.0} ms (FindServerTimeout {find_ms} ms; goal <= {goal:.0} ms = {basis}: {})",
            times.iter().map(|t| format!("{t:.0}")).collect::<Vec<_>>().join(", "),
            if med <= goal { "met" } else { "NOT met" }
        );
    }
    rt.shutdown_timeout(Duration::from_secs(1));
}

fn main() {
    // `cargo bench` passes `--bench`; a filter argument selects one part.
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let want = |name: &str| filter.as_deref().is_none_or(|f| name.contains(f));
    if want("throughput") {
        let plain = throughput(true);
        let tls = throughput(false);
        println!(
            "throughput TLS / plaintext: {tls:.0} / {plain:.0} VQT/s = {:.1} % (goal >= 80 %: {})",
            tls * 100.0 / plain,
            if tls >= 0.8 * plain { "met" } else { "NOT met" }
        );
    }
    if want("failover") {
        failover();
    }
    if let Some(dir) = pki().cert_file.parent() {
        let _ = std::fs::remove_dir_all(dir);
    }
}
