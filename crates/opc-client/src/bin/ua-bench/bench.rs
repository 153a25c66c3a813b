//! The measurements (see main.rs).

use clap::{Parser, ValueEnum};
use opcua::client::{
    Client, ClientBuilder, DataChangeCallback, IdentityToken, MonitoredItem, Session,
};
use opcua::crypto::SecurityPolicy;
use opcua::types::{
    AttributeId, BrowseDescription, BrowseDirection, BrowseResultMask, DataValue, ExtensionObject,
    MessageSecurityMode, MonitoredItemCreateRequest, MonitoringMode, MonitoringParameters,
    NodeClass, NodeClassMask, NodeId, ObjectId, QualifiedName, ReadValueId, ReferenceTypeId,
    StatusCode, TimestampsToReturn,
};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::task::JoinSet;

const NAMESPACE_URI: &str = "urn:askom:ServerCTOPC";
/// Every request's timeout (creating a thousand items on a slow peer takes seconds).
const REQUEST_TIMEOUT: Duration = Duration::from_secs(120);
const CONNECT_TIMEOUT: Duration = Duration::from_secs(60);
/// Monitored items per CreateMonitoredItems call and calls in flight at once. Requests stay
/// within one 64 kB chunk: node-opcua closed the connection on this client's requests of
/// more chunks (a Read of 3,000 values).
const ITEMS_PER_CALL: usize = 500;
const CALLS_IN_FLIGHT: usize = 8;
/// Values per Read request; the Reads of one measured Read are all in flight at once.
const READ_PER_CALL: usize = 1000;
/// Nodes per Browse request of the tree walk, references per node per answer.
const BROWSE_NODES_PER_CALL: usize = 50;
const BROWSE_REFS_PER_NODE: u32 = 1000;
/// The longest array a response may hold (a Publish of every item of a subscription).
const MAX_ARRAY: usize = 1_000_000;
/// The largest tree walked (nodes): a bound on memory against any server.
const MAX_BROWSED: usize = 5_000_000;

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Security {
    None,
    Encrypt,
}

#[derive(Parser, Debug)]
#[command(name = "ua-bench", about = "The load client of cargo xtask bench --ua")]
struct Args {
    /// The server's endpoint URL.
    #[arg(long)]
    url: Option<String>,
    /// None, or Basic256Sha256 SignAndEncrypt.
    #[arg(long, value_enum, default_value = "none")]
    security: Security,
    /// The client's PKI folder (its certificate is made there at first use).
    #[arg(long)]
    pki: PathBuf,
    /// Only make the client certificate and print its path.
    #[arg(long)]
    make_cert: bool,
    /// The user; the password is the first line of standard input.
    #[arg(long)]
    user: Option<String>,
    /// The server's process (for CPU and resident memory from /proc).
    #[arg(long)]
    pid: Option<u32>,
    /// Skip the walk of the browse tree.
    #[arg(long)]
    no_browse: bool,
    /// Values per Read (0: no Read).
    #[arg(long, default_value_t = 10_000)]
    read: usize,
    /// Reads measured (the median is printed).
    #[arg(long, default_value_t = 20)]
    runs: usize,
    /// Monitored items of the one-client subscription (0: none).
    #[arg(long, default_value_t = 100_000)]
    items: usize,
    /// Sampling and publishing interval (ms).
    #[arg(long, default_value_t = 100)]
    sampling: u32,
    /// Sessions of the many-session subscription (0: none), and items each.
    #[arg(long, default_value_t = 10)]
    sessions: usize,
    #[arg(long, default_value_t = 10_000)]
    session_items: usize,
    /// Windows of the rates (the median is printed) and their length (ms).
    #[arg(long, default_value_t = 5)]
    windows: usize,
    #[arg(long, default_value_t = 2000)]
    window_ms: u64,
    /// How long the first values of every item may take to arrive (s).
    #[arg(long, default_value_t = 300)]
    settle_s: u64,
}

fn figure(name: &str, value: f64, account: &str) {
    println!("figure {name} {value:.6} # {account}");
}

pub fn main() -> ExitCode {
    let args = Args::parse();
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("ua-bench: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let result = runtime.block_on(run(args));
    runtime.shutdown_timeout(Duration::from_secs(2));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("ua-bench: {e}");
            ExitCode::FAILURE
        }
    }
}

fn client(args: &Args) -> Result<Client, String> {
    ClientBuilder::new()
        .application_name("ua-bench")
        .application_uri("urn:askom:ua-bench")
        .product_uri("urn:askom:ua-bench")
        .pki_dir(&args.pki)
        .create_sample_keypair(true)
        .trust_server_certs(true)
        .verify_server_certs(false)
        .session_retry_limit(0)
        .request_timeout(REQUEST_TIMEOUT)
        // A Publish answer of 100,000 notifications is a few MB: no limit (0) on the
        // message size and the chunk count.
        .max_message_size(0)
        .max_chunk_count(0)
        // The subscriptions ask for every notification in one Publish (no maximum): its
        // array holds up to one notification per item, above async-opcua's default of
        // 1,000 elements (a larger one failed to decode and closed the connection).
        .max_array_length(MAX_ARRAY)
        .session_name("ua-bench")
        .client()
        .map_err(|e| format!("the OPC UA client: {}", e.join("; ")))
}

async fn run(args: Args) -> Result<(), String> {
    let client = client(&args)?;
    if args.make_cert {
        println!("{}", args.pki.join("own").join("cert.der").display());
        return Ok(());
    }
    let password = if args.user.is_some() {
        let mut line = String::new();
        std::io::stdin()
            .read_line(&mut line)
            .map_err(|e| format!("cannot read the password: {e}"))?;
        line.trim_end_matches(['\n', '\r']).to_owned()
    } else {
        String::new()
    };
    let b = Bench {
        args: &args,
        client,
        password,
    };
    let main = b.connect().await?;
    let ns = main
        .session
        .get_namespace_index(NAMESPACE_URI)
        .await
        .map_err(|e| format!("no namespace {NAMESPACE_URI}: {e}"))?;
    if !args.no_browse {
        b.browse(&main.session, ns).await?;
    }
    if args.read > 0 {
        b.read(&main.session, ns).await?;
    }
    if args.items > 0 {
        b.subscribe_one(&main.session, ns).await?;
    }
    if args.sessions > 0 && args.session_items > 0 {
        b.subscribe_many(main, ns).await?;
    } else {
        main.close().await;
    }
    Ok(())
}

struct Bench<'a> {
    args: &'a Args,
    client: Client,
    password: String,
}

struct Connection {
    session: Arc<Session>,
    event_loop: tokio::task::JoinHandle<StatusCode>,
}

impl Connection {
    async fn close(self) {
        let _ = tokio::time::timeout(Duration::from_secs(30), self.session.disconnect()).await;
        self.event_loop.abort();
    }
}

/// The server's CPU time (s) and resident bytes, from /proc (None elsewhere).
fn cpu_seconds(pid: Option<u32>) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{}/stat", pid?)).ok()?;
    // The fields after the command name (which may hold spaces) in parentheses.
    let rest = stat.get(stat.rfind(')')? + 2..)?;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    // USER_HZ: 100 on every Linux this runs on (sysconf(_SC_CLK_TCK) needs libc).
    Some((utime + stime) / 100.0)
}

fn resident_bytes(pid: Option<u32>) -> Option<f64> {
    let status = std::fs::read_to_string(format!("/proc/{}/status", pid?)).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0)
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

fn node(ns: u16, i: usize) -> NodeId {
    NodeId::new(ns, format!("T{i:07}"))
}

impl Bench<'_> {
    async fn connect(&self) -> Result<Connection, String> {
        let url = self.args.url.clone().unwrap_or_default();
        let (policy, mode) = match self.args.security {
            Security::None => (SecurityPolicy::None, MessageSecurityMode::None),
            Security::Encrypt => (
                SecurityPolicy::Basic256Sha256,
                MessageSecurityMode::SignAndEncrypt,
            ),
        };
        let endpoints = tokio::time::timeout(
            CONNECT_TIMEOUT,
            self.client.get_server_endpoints_from_url(url.as_str()),
        )
        .await
        .map_err(|_| format!("{url} did not answer GetEndpoints"))?
        .map_err(|e| format!("cannot reach {url}: {e}"))?;
        let endpoint = Client::find_matching_endpoint(&endpoints, &url, policy, mode)
            .ok_or_else(|| format!("{url} offers no endpoint {policy} {mode:?}"))?;
        let identity = match &self.args.user {
            Some(u) => IdentityToken::new_user_name(u.clone(), self.password.clone()),
            None => IdentityToken::Anonymous,
        };
        let (session, event_loop) = self
            .client
            .session_builder()
            .with_endpoints(endpoints)
            .connect_to_matching_endpoint(endpoint)
            .and_then(|b| {
                b.user_identity_token(identity)
                    .build(self.client.certificate_store().clone())
            })
            .map_err(|e| format!("cannot open a session: {e}"))?;
        let mut event_loop = event_loop.spawn();
        let connected = tokio::select! {
            connected = session.wait_for_connection() => Ok(connected),
            code = &mut event_loop => Err(code.unwrap_or(StatusCode::BadUnexpectedError)),
            () = tokio::time::sleep(CONNECT_TIMEOUT) => Err(StatusCode::BadTimeout),
        };
        match connected {
            Ok(true) => Ok(Connection {
                session,
                event_loop,
            }),
            Ok(false) => Err("the session was closed while opening".into()),
            Err(code) => {
                event_loop.abort();
                Err(format!("the session was refused: {code}"))
            }
        }
    }

    /// Walks the tree below the object `ServerCTOPC`: every folder's objects and variables.
    async fn browse(&self, session: &Session, ns: u16) -> Result<(), String> {
        let started = Instant::now();
        let objects: NodeId = ObjectId::ObjectsFolder.into();
        let top = children(session, std::slice::from_ref(&objects))
            .await?
            .into_iter()
            .find(|(_, name, _)| *name == QualifiedName::new(ns, "ServerCTOPC"))
            .ok_or("no object ServerCTOPC under Objects")?;
        let mut level = vec![top.0];
        let (mut folders, mut variables, mut requests) = (0usize, 0usize, 0usize);
        while !level.is_empty() {
            folders += level.len();
            let mut next = Vec::new();
            for chunk in level.chunks(BROWSE_NODES_PER_CALL) {
                requests += 1;
                for (id, _, class) in children(session, chunk).await? {
                    match class {
                        NodeClass::Object => next.push(id),
                        NodeClass::Variable => variables += 1,
                        _ => {}
                    }
                }
                if folders + next.len() + variables > MAX_BROWSED {
                    return Err(format!("the tree has more than {MAX_BROWSED} nodes"));
                }
            }
            level = next;
        }
        let s = started.elapsed().as_secs_f64();
        figure(
            "browse_s",
            s,
            &format!("{variables} variables in {folders} folders, {requests} Browse requests"),
        );
        figure("browse_variables", variables as f64, "variables walked");
        Ok(())
    }

    async fn read(&self, session: &Arc<Session>, ns: u16) -> Result<(), String> {
        let ids: Vec<ReadValueId> = (0..self.args.read)
            .map(|i| ReadValueId {
                node_id: node(ns, i),
                attribute_id: AttributeId::Value as u32,
                ..Default::default()
            })
            .collect();
        let mut times = Vec::new();
        // One unmeasured Read first (the servers' first sample of every variable).
        for run in 0..=self.args.runs {
            let started = Instant::now();
            let mut calls = JoinSet::new();
            for chunk in ids.chunks(READ_PER_CALL) {
                let s = Arc::clone(session);
                let chunk = chunk.to_vec();
                calls.spawn(async move { s.read(&chunk, TimestampsToReturn::Both, 0.0).await });
            }
            let mut values = Vec::with_capacity(ids.len());
            while let Some(done) = calls.join_next().await {
                values.extend(
                    done.map_err(|e| format!("Read task: {e}"))?
                        .map_err(|e| format!("Read of {} values: {e}", ids.len()))?,
                );
            }
            let ms = started.elapsed().as_secs_f64() * 1000.0;
            let good = values
                .iter()
                .filter(|v| v.status.is_none_or(|s| s.is_good()))
                .count();
            if run == 0 && good < values.len() {
                eprintln!(
                    "ua-bench: the first Read: {good} of {} values Good",
                    values.len()
                );
            }
            if run > 0 {
                times.push(ms);
            }
        }
        figure(
            "read_ms",
            median(times),
            &format!(
                "Read of {} values, MaxAge 0, {READ_PER_CALL} a request all in flight, median of {}",
                self.args.read, self.args.runs
            ),
        );
        Ok(())
    }

    /// A subscription of `items` items starting at variable `first`: its id, how long the
    /// items took to create, the delivered count.
    async fn subscription(
        &self,
        session: &Arc<Session>,
        ns: u16,
        first: usize,
        items: usize,
        count: Arc<AtomicU64>,
    ) -> Result<(u32, f64), String> {
        let counter = Arc::clone(&count);
        let callback = DataChangeCallback::new(move |_dv: DataValue, _item: &MonitoredItem| {
            counter.fetch_add(1, Ordering::Relaxed);
        });
        let interval = Duration::from_millis(u64::from(self.args.sampling));
        let sub = session
            .create_subscription(interval, 6000, 50, 0, 0, true, callback)
            .await
            .map_err(|e| format!("CreateSubscription: {e}"))?;
        let started = Instant::now();
        let mut calls = JoinSet::new();
        let mut failed = 0usize;
        let mut pending = (first..first + items).collect::<Vec<_>>();
        pending.reverse();
        while !pending.is_empty() || !calls.is_empty() {
            while calls.len() < CALLS_IN_FLIGHT && !pending.is_empty() {
                let take = pending.len().min(ITEMS_PER_CALL);
                let batch: Vec<MonitoredItemCreateRequest> = pending
                    .split_off(pending.len() - take)
                    .into_iter()
                    .rev()
                    .map(|i| {
                        MonitoredItemCreateRequest::new(
                            ReadValueId::from(node(ns, i)),
                            MonitoringMode::Reporting,
                            MonitoringParameters {
                                client_handle: 0,
                                sampling_interval: f64::from(self.args.sampling),
                                filter: ExtensionObject::null(),
                                queue_size: 1,
                                discard_oldest: true,
                            },
                        )
                    })
                    .collect();
                let s = Arc::clone(session);
                calls.spawn(async move {
                    s.create_monitored_items(sub, TimestampsToReturn::Both, batch)
                        .await
                });
            }
            if let Some(done) = calls.join_next().await {
                let created = done
                    .map_err(|e| format!("CreateMonitoredItems task: {e}"))?
                    .map_err(|e| format!("CreateMonitoredItems: {e}"))?;
                failed += created
                    .iter()
                    .filter(|c| c.result.status_code.is_bad())
                    .count();
            }
        }
        let created_s = started.elapsed().as_secs_f64();
        if failed > 0 {
            return Err(format!("{failed} of {items} monitored items were refused"));
        }
        Ok((sub, created_s))
    }

    /// Waits until `count` reaches `at_least` (every item's first value).
    async fn settle(&self, count: &AtomicU64, at_least: u64) -> Result<f64, String> {
        let started = Instant::now();
        let limit = Duration::from_secs(self.args.settle_s);
        while count.load(Ordering::Relaxed) < at_least {
            if started.elapsed() > limit {
                return Err(format!(
                    "only {} of {at_least} first values within {} s",
                    count.load(Ordering::Relaxed),
                    limit.as_secs()
                ));
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        Ok(started.elapsed().as_secs_f64())
    }

    /// The delivered rate and the server's CPU per 1,000 notifications: medians of windows.
    async fn windows(&self, count: &AtomicU64, prefix: &str, what: &str) {
        let mut rates = Vec::new();
        let mut cpus = Vec::new();
        let mut loads = Vec::new();
        for _ in 0..self.args.windows {
            let c0 = count.load(Ordering::Relaxed);
            let cpu0 = cpu_seconds(self.args.pid);
            let t0 = Instant::now();
            tokio::time::sleep(Duration::from_millis(self.args.window_ms)).await;
            let secs = t0.elapsed().as_secs_f64();
            let n = (count.load(Ordering::Relaxed) - c0) as f64;
            rates.push(n / secs);
            if let (Some(a), Some(b)) = (cpu0, cpu_seconds(self.args.pid)) {
                loads.push((b - a) / secs * 100.0);
                if n > 0.0 {
                    cpus.push((b - a) * 1000.0 / (n / 1000.0));
                }
            }
        }
        let windows = format!(
            "median of {} windows of {} ms",
            self.args.windows, self.args.window_ms
        );
        figure(
            &format!("{prefix}_notifications_per_s"),
            median(rates),
            &format!("{what}: notifications/s delivered, {windows}"),
        );
        if !cpus.is_empty() {
            figure(
                &format!("{prefix}_cpu_ms_per_1000"),
                median(cpus),
                &format!("{what}: server CPU ms per 1,000 notifications, {windows}"),
            );
            figure(
                &format!("{prefix}_cpu_percent"),
                median(loads),
                &format!("{what}: server CPU % of one core, {windows}"),
            );
        }
    }

    async fn subscribe_one(&self, session: &Arc<Session>, ns: u16) -> Result<(), String> {
        let items = self.args.items;
        let rss0 = resident_bytes(self.args.pid);
        let count = Arc::new(AtomicU64::new(0));
        let (sub, created_s) = self
            .subscription(session, ns, 0, items, Arc::clone(&count))
            .await?;
        figure(
            "create_items_s",
            created_s,
            &format!(
                "CreateMonitoredItems of {items} items, {ITEMS_PER_CALL} a call, {CALLS_IN_FLIGHT} calls in flight"
            ),
        );
        let settle_s = self.settle(&count, items as u64).await?;
        figure(
            "first_values_s",
            settle_s,
            "until every item's first value arrived",
        );
        let what = format!("1 session, {items} items at {} ms", self.args.sampling);
        self.windows(&count, "one", &what).await;
        if let (Some(a), Some(b)) = (rss0, resident_bytes(self.args.pid)) {
            figure(
                "rss_bytes_per_item",
                (b - a) / items as f64,
                &format!("server VmRSS after minus before the subscription, over {items} items"),
            );
            figure(
                "rss_mb_subscribed",
                b / 1e6,
                "server VmRSS while subscribed (MB)",
            );
        }
        let _ = session.delete_subscription(sub).await;
        Ok(())
    }

    async fn subscribe_many(&self, main: Connection, ns: u16) -> Result<(), String> {
        let n = self.args.sessions;
        let per = self.args.session_items;
        let mut conns = vec![main];
        for _ in 1..n {
            conns.push(self.connect().await?);
        }
        let count = Arc::new(AtomicU64::new(0));
        let started = Instant::now();
        let mut subs = Vec::new();
        for (k, c) in conns.iter().enumerate() {
            let (sub, _) = self
                .subscription(&c.session, ns, k * per, per, Arc::clone(&count))
                .await?;
            subs.push(sub);
        }
        figure(
            "many_create_items_s",
            started.elapsed().as_secs_f64(),
            &format!("{n} sessions x {per} items created, one session after the other"),
        );
        self.settle(&count, (n * per) as u64).await?;
        let what = format!("{n} sessions x {per} items at {} ms", self.args.sampling);
        self.windows(&count, "many", &what).await;
        for c in conns {
            c.close().await;
        }
        Ok(())
    }
}

/// The forward hierarchical references of `nodes` to objects and variables, through
/// BrowseNext until every continuation point is used.
async fn children(
    session: &Session,
    nodes: &[NodeId],
) -> Result<Vec<(NodeId, QualifiedName, NodeClass)>, String> {
    let descs: Vec<BrowseDescription> = nodes
        .iter()
        .map(|n| BrowseDescription {
            node_id: n.clone(),
            browse_direction: BrowseDirection::Forward,
            reference_type_id: ReferenceTypeId::HierarchicalReferences.into(),
            include_subtypes: true,
            node_class_mask: (NodeClassMask::OBJECT | NodeClassMask::VARIABLE).bits(),
            result_mask: BrowseResultMask::BrowseName as u32 | BrowseResultMask::NodeClass as u32,
        })
        .collect();
    let mut results = session
        .browse(&descs, BROWSE_REFS_PER_NODE, None)
        .await
        .map_err(|e| format!("Browse: {e}"))?;
    let mut out = Vec::new();
    loop {
        let mut cps = Vec::new();
        for r in &mut results {
            if r.status_code.is_bad() {
                return Err(format!("Browse: {}", r.status_code));
            }
            for rd in r.references.take().unwrap_or_default() {
                out.push((rd.node_id.node_id, rd.browse_name, rd.node_class));
            }
            if !r.continuation_point.is_null() && !r.continuation_point.is_empty() {
                cps.push(r.continuation_point.clone());
            }
        }
        if cps.is_empty() {
            return Ok(out);
        }
        results = session
            .browse_next(false, &cps)
            .await
            .map_err(|e| format!("BrowseNext: {e}"))?;
    }
}
