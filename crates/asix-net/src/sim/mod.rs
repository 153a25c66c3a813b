//! `asix-sim`: a simulated asix data server. It answers discovery, serves links, samples a
//! deterministic [`plant::Plant`], honours write rights from an asix application ini
//! ([`rights::WriteRights`]) and injects faults on command ([`SimHandle`]). The same plant
//! runs inside the server as the in-process simulation ([`inproc`]).

pub mod inproc;
pub mod plant;
#[cfg(feature = "rest")]
pub mod rest;
pub mod rights;

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::io;
use std::net::{Ipv4Addr, SocketAddr};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use ctopc_core::{OpcError, Quality, Timestamp, Value, VarType};
use tokio::io::{AsyncWriteExt, BufWriter};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::{mpsc, watch, OwnedSemaphorePermit, Semaphore};
use tokio::task::JoinHandle;
use tracing::{debug, info, warn};

use self::plant::{numeric, Behaviour, ChannelDef, Plant};
use self::rights::{Denied, WriteRights};
use crate::client::wall_now;
use crate::proto::discovery::{Announce, FindServer, Resource, ResourceKind};
use crate::proto::frame::{
    encode_frame, Frame, HelloAck, Message, ReadSource, ServerFlags, UpdateEncoder, VarRef,
};
use crate::secure::{ServerSecurity, ServerTls};
use crate::tls::{self, Fingerprint, Trust};
use crate::Vqt;

/// Simulator settings.
#[derive(Debug, Clone)]
pub struct SimConfig {
    /// The server's asix name (announced, matched by AsixServerName).
    pub server_name: String,
    /// The computer name the server runs on; clients reporting the same host are local.
    pub host_name: String,
    /// UDP address for discovery requests.
    pub discovery_addr: SocketAddr,
    /// TCP address of the link listener.
    pub tcp_addr: SocketAddr,
    pub channels: Vec<ChannelDef>,
    /// Archive names announced as resources (no archive service behind them).
    pub archives: Vec<String>,
    pub seed: u64,
    /// Length of a simulation step.
    pub tick_ms: u64,
    /// Announce as a bridge (relaying another server's data).
    pub bridge: bool,
    /// Start with the data source failed.
    pub source_failed: bool,
    /// Added to the announced client count (other clients, simulated).
    pub extra_clients: u32,
    /// Write rights and channel drivers, from the asix application ini
    /// ([`WriteRights::from_app_ini`]); the default grants remote clients nothing.
    pub write_rights: WriteRights,
    /// Extra delay of reads from the driver.
    pub driver_delay: Duration,
    /// Shorter sampling periods are raised to this.
    pub min_sampling_ms: u32,
    /// How links are secured: the server's TLS identity and the clients it accepts, or
    /// plaintext where allowed; handshake bounds.
    pub security: ServerSecurity,
    /// The writer identities (`cert:<fingerprint>`) whose writes are accepted; `None`: the
    /// asix application's rule ([`WriteRights`]) with the authenticated identity as the
    /// client's name (on a plaintext link, the name the client declared).
    pub allow_writers: Option<Vec<String>>,
}

impl SimConfig {
    /// Defaults for tests: loopback, ephemeral ports, the built-in acid plant.
    pub fn new(server_name: &str) -> Self {
        SimConfig {
            server_name: server_name.to_owned(),
            host_name: format!("{server_name}-HOST"),
            discovery_addr: SocketAddr::from((Ipv4Addr::LOCALHOST, 0)),
            tcp_addr: SocketAddr::from((Ipv4Addr::LOCALHOST, 0)),
            channels: vec![plant::acid_plant()],
            archives: Vec::new(),
            seed: 1,
            tick_ms: 100,
            bridge: false,
            source_failed: false,
            extra_clients: 0,
            write_rights: WriteRights::default(),
            driver_delay: Duration::from_millis(20),
            min_sampling_ms: 10,
            security: ephemeral_security(server_name),
            allow_writers: None,
        }
    }
}

/// A TLS identity made for this run (self-signed), accepting any client certificate: the
/// simulator's default. Clients must pin its fingerprint ([`SimHandle::fingerprint`]).
pub fn ephemeral_security(server_name: &str) -> ServerSecurity {
    let made = tls::generate(server_name, None)
        .and_then(|g| ServerTls::new(&g.identity, Trust::AnyCertificate));
    match made {
        Ok(t) => ServerSecurity::tls(t),
        Err(e) => {
            warn!(error = %e, "no TLS identity: the simulator accepts no link");
            ServerSecurity {
                tls: None,
                allow_plaintext: false,
                ..ServerSecurity::plaintext()
            }
        }
    }
}

struct Shared {
    name: String,
    host: String,
    bridge: bool,
    extra_clients: u32,
    tcp_port: u16,
    resources: Vec<Resource>,
    rights: WriteRights,
    allow_writers: Option<HashSet<String>>,
    security: ServerSecurity,
    /// Permits of the handshakes under way.
    handshakes: Arc<Semaphore>,
    driver_delay: Duration,
    min_sampling_ms: u32,
    plant: Mutex<Plant>,
    /// Plant variable -> how many link subscriptions it has (for [`SimHandle::subscriptions`]).
    subscribed: Mutex<HashMap<usize, u32>>,
    start: Instant,
    answering: AtomicBool,
    failed: AtomicBool,
    links: AtomicU32,
    drop_epoch: watch::Sender<u64>,
    status: watch::Sender<u64>,
    shutdown: watch::Sender<bool>,
}

impl Shared {
    fn answering(&self) -> bool {
        self.answering.load(Ordering::SeqCst)
    }
    fn failed(&self) -> bool {
        self.failed.load(Ordering::SeqCst)
    }
    fn clients(&self) -> u32 {
        self.links.load(Ordering::SeqCst) + self.extra_clients
    }
    fn flags(&self, client_host: &str) -> ServerFlags {
        ServerFlags(0)
            .with(
                ServerFlags::LOCAL,
                client_host.eq_ignore_ascii_case(&self.host),
            )
            .with(ServerFlags::BRIDGE, self.bridge)
            .with(ServerFlags::SOURCE_FAILED, self.failed())
    }
    fn lock(&self) -> MutexGuard<'_, Plant> {
        self.plant.lock().unwrap_or_else(|p| p.into_inner())
    }
    /// The plant, advanced to now (frozen while the data source is failed).
    fn plant_now(&self) -> MutexGuard<'_, Plant> {
        let mut p = self.lock();
        if !self.failed() {
            let tick = self.start.elapsed().as_millis() as u64 / p.tick_ms();
            p.advance_to(tick);
        }
        p
    }
    /// One link subscription more (`up`) or less of plant variable `var`.
    fn count_subscription(&self, var: usize, up: bool) {
        let mut m = self.subscribed.lock().unwrap_or_else(|p| p.into_inner());
        let n = m.entry(var).or_default();
        *n = if up { *n + 1 } else { n.saturating_sub(1) };
        if *n == 0 {
            m.remove(&var);
        }
    }
    fn offers(&self, r: &Resource) -> bool {
        r.name.is_empty() || self.resources.contains(r)
    }
    fn bump_status(&self) {
        self.status.send_modify(|v| *v += 1);
    }
}

/// A running simulator. Dropping the handle stops it.
pub struct SimHandle {
    shared: Arc<Shared>,
    discovery_addr: SocketAddr,
    tcp_addr: SocketAddr,
    tasks: Vec<JoinHandle<()>>,
}

/// Starts a simulator on the current tokio runtime.
pub async fn start(cfg: SimConfig) -> io::Result<SimHandle> {
    let udp = UdpSocket::bind(cfg.discovery_addr).await?;
    let tcp = TcpListener::bind(cfg.tcp_addr).await?;
    let discovery_addr = udp.local_addr()?;
    let tcp_addr = tcp.local_addr()?;
    let rights = cfg.write_rights;
    // Channels on driver NONE have no driver: their variables change only when written.
    let channels: Vec<ChannelDef> = cfg
        .channels
        .iter()
        .map(|c| {
            let mut c = c.clone();
            if rights
                .driver(&c.name)
                .is_some_and(|d| d.eq_ignore_ascii_case("NONE"))
            {
                for (_, b) in &mut c.vars {
                    *b = Behaviour::Constant;
                }
            }
            c
        })
        .collect();
    let mut resources: Vec<Resource> = channels
        .iter()
        .map(|c| Resource::channel(&c.name))
        .collect();
    resources.extend(cfg.archives.iter().map(|a| Resource {
        kind: ResourceKind::Archive,
        name: a.clone(),
    }));
    let plant = Plant::new(&channels, cfg.seed, cfg.tick_ms, wall_now());
    let shared = Arc::new(Shared {
        name: cfg.server_name.clone(),
        host: cfg.host_name.clone(),
        bridge: cfg.bridge,
        extra_clients: cfg.extra_clients,
        tcp_port: tcp_addr.port(),
        resources,
        rights,
        allow_writers: cfg
            .allow_writers
            .as_ref()
            .map(|v| v.iter().map(|w| w.to_ascii_lowercase()).collect()),
        handshakes: Arc::new(Semaphore::new(cfg.security.max_handshakes.max(1))),
        security: cfg.security.clone(),
        driver_delay: cfg.driver_delay,
        min_sampling_ms: cfg.min_sampling_ms.max(1),
        plant: Mutex::new(plant),
        subscribed: Mutex::new(HashMap::new()),
        start: Instant::now(),
        answering: AtomicBool::new(true),
        failed: AtomicBool::new(cfg.source_failed),
        links: AtomicU32::new(0),
        drop_epoch: watch::channel(0).0,
        status: watch::channel(0).0,
        shutdown: watch::channel(false).0,
    });
    info!(server = %cfg.server_name, udp = %discovery_addr, tcp = %tcp_addr, "asix-sim started");
    let tasks = vec![
        tokio::spawn(udp_loop(shared.clone(), udp)),
        tokio::spawn(accept_loop(shared.clone(), tcp)),
    ];
    Ok(SimHandle {
        shared,
        discovery_addr,
        tcp_addr,
        tasks,
    })
}

impl SimHandle {
    pub fn server_name(&self) -> &str {
        &self.shared.name
    }
    /// Where discovery requests go (a client's discovery target).
    pub fn discovery_addr(&self) -> SocketAddr {
        self.discovery_addr
    }
    pub fn tcp_addr(&self) -> SocketAddr {
        self.tcp_addr
    }
    /// The SHA-256 fingerprint of the server's TLS certificate (what clients pin).
    pub fn fingerprint(&self) -> Option<Fingerprint> {
        self.shared.security.fingerprint()
    }
    /// Handshakes under way now (at most the configured cap).
    pub fn handshakes(&self) -> usize {
        self.shared.security.max_handshakes.max(1) - self.shared.handshakes.available_permits()
    }
    /// Linked clients (without the configured extra ones).
    pub fn client_count(&self) -> u32 {
        self.shared.links.load(Ordering::SeqCst)
    }

    /// Fault: closes every link now (the server stays up and answers discovery).
    pub fn drop_links(&self) {
        self.shared.drop_epoch.send_modify(|v| *v += 1);
    }

    /// Fault: stop answering anything (discovery, requests, keep-alive, updates) while
    /// keeping sockets open, as a hung server would; `true` resumes.
    pub fn set_answering(&self, on: bool) {
        self.shared.answering.store(on, Ordering::SeqCst);
    }

    /// Fault: mark the data source failed (announced; values go BAD Device Failure and
    /// writes fail) or repaired.
    pub fn set_source_failed(&self, failed: bool) {
        if self.shared.failed.swap(failed, Ordering::SeqCst) != failed {
            self.shared.bump_status();
        }
    }

    /// The current VQT of a variable.
    pub fn vqt(&self, channel: &str, variable: &str) -> Option<Vqt> {
        let p = self.shared.plant_now();
        let i = p.lookup(channel, variable)?;
        Some(p.vqt(i))
    }

    /// How many subscriptions of a variable the links hold (0 for an unknown variable):
    /// lets tests see what a client subscribes and lets go.
    pub fn subscriptions(&self, channel: &str, variable: &str) -> u32 {
        let Some(i) = self.shared.lock().lookup(channel, variable) else {
            return 0;
        };
        let m = self
            .shared
            .subscribed
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        m.get(&i).copied().unwrap_or(0)
    }

    /// Forces a variable's value (good quality, now) as if the process had changed it;
    /// the variable then evolves from there. False for an unknown variable.
    pub fn force(&self, channel: &str, variable: &str, value: f64) -> bool {
        let mut p = self.shared.plant_now();
        let Some(i) = p.lookup(channel, variable) else {
            return false;
        };
        p.set(i, value, None, None);
        true
    }

    /// Text control (the binary's stdin; usable from tests): `drop-links`, `stop-answering`,
    /// `answer`, `fail-source`, `restore-source`, `status`, `help`.
    pub fn control(&self, line: &str) -> Result<String, String> {
        match line.trim() {
            "drop-links" => self.drop_links(),
            "stop-answering" => self.set_answering(false),
            "answer" | "resume" => self.set_answering(true),
            "fail-source" => self.set_source_failed(true),
            "restore-source" => self.set_source_failed(false),
            "status" => {}
            "help" | "" => return Ok(
                "commands: drop-links stop-answering answer fail-source restore-source status quit"
                    .into(),
            ),
            other => return Err(format!("unknown command {other:?}")),
        }
        Ok(format!(
            "ok server={} clients={} answering={} source_failed={}",
            self.shared.name,
            self.client_count(),
            self.shared.answering(),
            self.shared.failed()
        ))
    }

    /// Kills the server: every socket closes, as if the process died.
    pub async fn shutdown(mut self) {
        let _ = self.shared.shutdown.send(true);
        for t in self.tasks.drain(..) {
            let _ = t.await;
        }
    }
}

impl Drop for SimHandle {
    fn drop(&mut self) {
        let _ = self.shared.shutdown.send(true);
    }
}

async fn udp_loop(shared: Arc<Shared>, sock: UdpSocket) {
    let shutdown = shared.shutdown.subscribe();
    crate::server::discovery_loop(sock, shutdown, |f| {
        (shared.answering() && shared.offers(&f.resource)).then(|| announce(&shared, f))
    })
    .await;
}

fn announce(shared: &Shared, f: &FindServer) -> Announce {
    let resources = crate::server::announced_resources(&shared.resources, &f.resource);
    Announce {
        request: f.request,
        server_name: shared.name.clone(),
        server_host: shared.host.clone(),
        flags: shared.flags(&f.client_host),
        clients: shared.clients(),
        tcp_port: shared.tcp_port,
        fingerprint: shared.security.fingerprint(),
        resources,
    }
}

async fn accept_loop(shared: Arc<Shared>, listener: TcpListener) {
    let shutdown = shared.shutdown.subscribe();
    let handshakes = shared.handshakes.clone();
    crate::server::accept_loop(listener, shutdown, handshakes, |stream, peer, permit| {
        tokio::spawn(serve_link(shared.clone(), stream, peer, permit));
    })
    .await;
}

struct Sub {
    var: usize,
    sampling: u32,
    changes_only: bool,
    /// Version of the VQT last sent; 0 forces the next send.
    sent_version: u32,
}

struct Group {
    period: Duration,
    next_due: Instant,
    handles: BTreeSet<u32>,
}

struct LinkState {
    client: Option<(String, bool)>,
    /// The client's authenticated identity (`cert:<fingerprint>`); `None` on plaintext.
    identity: Option<String>,
    subs: HashMap<u32, Sub>,
    groups: BTreeMap<u32, Group>,
    last_rx: Instant,
    idle: Duration,
    counted: bool,
}

enum Step {
    Continue,
    Close,
}

async fn serve_link(
    shared: Arc<Shared>,
    stream: TcpStream,
    peer: SocketAddr,
    permit: OwnedSemaphorePermit,
) {
    let mut shut_rx = shared.shutdown.subscribe();
    let Some(secured) =
        crate::server::secure_link(stream, peer, &shared.security, &mut shut_rx).await
    else {
        return;
    };
    drop(permit);
    debug!(%peer, identity = secured.peer.as_deref().unwrap_or("none (plaintext)"), "link secured");
    let (ftx, mut frx) = mpsc::channel(64);
    let reader = tokio::spawn(crate::server::read_frames(secured.rd, ftx));
    let (dtx, mut drx) = mpsc::unbounded_channel::<Vec<u8>>();
    let mut w = BufWriter::with_capacity(64 * 1024, secured.wr);
    let mut drop_rx = shared.drop_epoch.subscribe();
    let mut status_rx = shared.status.subscribe();
    let mut st = LinkState {
        client: None,
        identity: secured.peer,
        subs: HashMap::new(),
        groups: BTreeMap::new(),
        last_rx: Instant::now(),
        idle: Duration::from_secs(10),
        counted: false,
    };
    let far = Duration::from_secs(3600);
    loop {
        let now = Instant::now();
        let next_due = st
            .groups
            .values()
            .map(|g| g.next_due)
            .min()
            .unwrap_or(now + far);
        let idle_at = st.last_rx + st.idle;
        let mut out = Vec::new();
        let step = tokio::select! {
            f = frx.recv() => match f {
                Some(Ok(frame)) if shared.answering() => {
                    st.last_rx = Instant::now();
                    handle_frame(&shared, &mut st, frame, &mut out, &dtx)
                }
                Some(Ok(_)) => Step::Continue,
                Some(Err(e)) => {
                    warn!(error = %e, "bad frame from client; closing");
                    crate::server::bad_frame(&mut out, &e);
                    Step::Close
                }
                None => Step::Close,
            },
            Some(bytes) = drx.recv() => {
                if shared.answering() {
                    out = bytes;
                }
                Step::Continue
            }
            () = tokio::time::sleep_until(next_due.into()) => {
                let now = Instant::now();
                let due: Vec<u32> = st.groups.iter().filter(|(_, g)| g.next_due <= now).map(|(k, _)| *k).collect();
                for k in due {
                    let Some(g) = st.groups.get_mut(&k) else { continue };
                    g.next_due += g.period;
                    if g.next_due < now {
                        g.next_due = now + g.period;
                    }
                    if shared.answering() {
                        let handles: Vec<u32> = g.handles.iter().copied().collect();
                        sample(&shared, &mut st.subs, &handles, &mut out);
                    }
                }
                Step::Continue
            }
            () = tokio::time::sleep_until(idle_at.into()) => {
                if shared.answering() {
                    debug!("client silent; closing link");
                    Step::Close
                } else {
                    st.last_rx = Instant::now();
                    Step::Continue
                }
            }
            _ = drop_rx.changed() => Step::Close,
            _ = status_rx.changed() => {
                if shared.answering() && st.client.is_some() {
                    let host_local = st.client.as_ref().is_some_and(|c| c.1);
                    let flags = shared.flags("").with(ServerFlags::LOCAL, host_local);
                    let _ = encode_frame(&mut out, 0, &Message::ServerStatus { flags, clients: shared.clients() });
                    for s in st.subs.values_mut() {
                        s.sent_version = 0;
                    }
                    let handles: Vec<u32> = st.subs.keys().copied().collect();
                    sample(&shared, &mut st.subs, &handles, &mut out);
                }
                Step::Continue
            }
            _ = shut_rx.changed() => break,
        };
        if !out.is_empty() && (w.write_all(&out).await.is_err() || w.flush().await.is_err()) {
            break;
        }
        if matches!(step, Step::Close) {
            break;
        }
    }
    reader.abort();
    for s in st.subs.values() {
        shared.count_subscription(s.var, false);
    }
    if st.counted {
        shared.links.fetch_sub(1, Ordering::SeqCst);
    }
    let _ = w.shutdown().await;
}

/// Appends Update frames for the handles: every sample, or for changes-only subscriptions
/// those whose VQT changed since last sent (or whose send is forced).
fn sample(shared: &Shared, subs: &mut HashMap<u32, Sub>, handles: &[u32], out: &mut Vec<u8>) {
    let failed = shared.failed();
    let mut enc = UpdateEncoder::new(64 * 1024);
    {
        let p = shared.plant_now();
        for h in handles {
            let Some(s) = subs.get_mut(h) else { continue };
            let version = p.vars()[s.var].version;
            if s.changes_only && s.sent_version == version {
                continue;
            }
            s.sent_version = version;
            let mut vqt = p.vqt(s.var);
            if failed {
                vqt.quality = Quality::BAD_DEVICE_FAILURE;
            }
            if enc.push(*h, &vqt).is_err() {
                break;
            }
        }
    }
    if let Ok(bytes) = enc.finish() {
        out.extend_from_slice(&bytes);
    }
}

use crate::server::reply;

fn handle_frame(
    shared: &Arc<Shared>,
    st: &mut LinkState,
    frame: Frame,
    out: &mut Vec<u8>,
    deferred: &mpsc::UnboundedSender<Vec<u8>>,
) -> Step {
    let Frame { request, msg } = frame;
    let Some((client_name, local)) = st.client.clone() else {
        let Message::Hello(h) = msg else {
            reply(
                out,
                request,
                &Message::Error {
                    code: OpcError::NetLinkToServerNegativeAnswer.hresult(),
                    message: "Hello expected".into(),
                },
            );
            return Step::Close;
        };
        let local = h.client_host.eq_ignore_ascii_case(&shared.host);
        st.idle = if h.keepalive_ms == 0 {
            Duration::from_secs(30)
        } else {
            Duration::from_millis(u64::from(h.keepalive_ms) * 3).max(Duration::from_secs(1))
        };
        shared.links.fetch_add(1, Ordering::SeqCst);
        st.counted = true;
        debug!(client = %h.client_name, local, "hello");
        reply(
            out,
            request,
            &Message::HelloAck(HelloAck {
                status: 0,
                server_name: shared.name.clone(),
                flags: shared.flags(&h.client_host),
                clients: shared.clients(),
                idle_timeout_ms: st.idle.as_millis() as u32,
            }),
        );
        st.client = Some((h.client_name, local));
        return Step::Continue;
    };
    match msg {
        Message::Ping { nonce } => reply(out, request, &Message::Pong { nonce }),
        Message::Pong { .. } => {}
        Message::Bye { .. } => return Step::Close,
        Message::Subscribe {
            sampling_ms,
            changes_only,
            items,
        } => {
            let sampling = sampling_ms.max(shared.min_sampling_ms);
            let mut results = Vec::with_capacity(items.len());
            let mut fresh = Vec::new();
            {
                let p = shared.lock();
                for it in items {
                    let Some(var) = p.lookup(&it.var.channel, &it.var.variable) else {
                        results.push((it.handle, OpcError::ItemUnknown.hresult()));
                        continue;
                    };
                    if let Some(old) = st.subs.insert(
                        it.handle,
                        Sub {
                            var,
                            sampling,
                            changes_only,
                            sent_version: 0,
                        },
                    ) {
                        shared.count_subscription(old.var, false);
                        if let Some(g) = st.groups.get_mut(&old.sampling) {
                            g.handles.remove(&it.handle);
                        }
                    }
                    shared.count_subscription(var, true);
                    let period = Duration::from_millis(u64::from(sampling));
                    st.groups
                        .entry(sampling)
                        .or_insert_with(|| Group {
                            period,
                            next_due: Instant::now() + period,
                            handles: BTreeSet::new(),
                        })
                        .handles
                        .insert(it.handle);
                    results.push((it.handle, 0));
                    fresh.push(it.handle);
                }
            }
            st.groups.retain(|_, g| !g.handles.is_empty());
            reply(out, request, &Message::SubscribeAck { results });
            // Initial values at once.
            sample(shared, &mut st.subs, &fresh, out);
        }
        Message::Unsubscribe { handles } => {
            let mut results = Vec::with_capacity(handles.len());
            for h in handles {
                match st.subs.remove(&h) {
                    Some(s) => {
                        shared.count_subscription(s.var, false);
                        if let Some(g) = st.groups.get_mut(&s.sampling) {
                            g.handles.remove(&h);
                        }
                        results.push((h, 0));
                    }
                    None => results.push((h, OpcError::ItemUnknown.hresult())),
                }
            }
            st.groups.retain(|_, g| !g.handles.is_empty());
            reply(out, request, &Message::UnsubscribeAck { results });
        }
        Message::Read { source, items } => {
            if source == ReadSource::Driver {
                let shared = shared.clone();
                let deferred = deferred.clone();
                tokio::spawn(async move {
                    tokio::time::sleep(shared.driver_delay).await;
                    let mut out = Vec::new();
                    reply(&mut out, request, &read(&shared, source, &items));
                    let _ = deferred.send(out);
                });
            } else {
                reply(out, request, &read(shared, source, &items));
            }
        }
        Message::Write { items } => {
            let items = items.into_iter().map(|(v, x)| (v, x, None)).collect();
            let writer = Writer {
                name: &client_name,
                identity: st.identity.as_deref(),
                local,
            };
            let results = write(shared, &writer, items);
            reply(out, request, &Message::WriteResult { results });
        }
        Message::WriteVqt { items } => {
            let items = items
                .into_iter()
                .map(|(v, x)| (v, x.value, Some((x.quality, x.timestamp))))
                .collect();
            let writer = Writer {
                name: &client_name,
                identity: st.identity.as_deref(),
                local,
            };
            let results = write(shared, &writer, items);
            reply(out, request, &Message::WriteResult { results });
        }
        other => reply(
            out,
            request,
            &Message::Error {
                code: OpcError::NotSupported.hresult(),
                message: format!("{:?} is not a request", other.msg_type()),
            },
        ),
    }
    Step::Continue
}

fn read(shared: &Shared, source: ReadSource, items: &[VarRef]) -> Message {
    let failed = shared.failed();
    // Cache: the image as it stands; Device and Driver: brought up to date first.
    let p = if source == ReadSource::Cache {
        shared.lock()
    } else {
        shared.plant_now()
    };
    let results = items
        .iter()
        .map(|v| match p.lookup(&v.channel, &v.variable) {
            Some(i) => {
                let mut vqt = p.vqt(i);
                if failed {
                    vqt.quality = Quality::BAD_DEVICE_FAILURE;
                }
                Ok(vqt)
            }
            None => Err(OpcError::ItemUnknown.hresult()),
        })
        .collect();
    Message::ReadResult { results }
}

type WriteItem = (VarRef, Value, Option<(Quality, Timestamp)>);

/// Who writes, as the link knows the client: the hook of every write right.
#[derive(Debug, Clone, Copy)]
pub struct Writer<'a> {
    /// The asix name the client declared in Hello (not authenticated).
    pub name: &'a str,
    /// The authenticated identity (`cert:<fingerprint>`), `None` on a plaintext link.
    pub identity: Option<&'a str>,
    /// The client declared this computer's name.
    pub local: bool,
}

impl Shared {
    /// The write right of `writer` on `channel` (section 8 of the protocol document):
    /// with `--allow-writer`, only the listed identities; else the asix application's
    /// rule with the authenticated identity in place of the declared name.
    fn check_writer(
        &self,
        writer: &Writer<'_>,
        channel: &str,
        extended: bool,
    ) -> Result<(), Denied> {
        let client = writer.identity.unwrap_or(writer.name);
        match &self.allow_writers {
            Some(allowed) => {
                let listed = writer
                    .identity
                    .is_some_and(|id| allowed.contains(&id.to_ascii_lowercase()));
                if !listed {
                    return Err(Denied::NoPermission);
                }
                if extended {
                    // The identity is the permission; the channel's conditions still hold.
                    self.rights.check_write_extended(channel, client, true)?;
                }
                Ok(())
            }
            None if extended => self
                .rights
                .check_write_extended(channel, client, writer.local),
            None => self.rights.check_write(channel, client, writer.local),
        }
    }
}

/// Checks and applies writes; one HRESULT per item (see the protocol document, "Writes").
fn write(shared: &Shared, writer: &Writer<'_>, items: Vec<WriteItem>) -> Vec<i32> {
    let client = writer.identity.unwrap_or(writer.name);
    let mut seen: HashMap<(&str, &str), usize> = HashMap::new();
    for (v, _, _) in &items {
        *seen
            .entry((v.channel.as_str(), v.variable.as_str()))
            .or_default() += 1;
    }
    let failed = shared.failed();
    let mut p = shared.plant_now();
    let mut results = Vec::with_capacity(items.len());
    for (v, value, ext) in &items {
        let r = (|| {
            if seen[&(v.channel.as_str(), v.variable.as_str())] > 1 {
                return Err(OpcError::TheSameItemWrittenMoreThanOnce);
            }
            let i = p
                .lookup(&v.channel, &v.variable)
                .ok_or(OpcError::ItemUnknown)?;
            shared
                .check_writer(writer, &v.channel, ext.is_some())
                .map_err(|d| match d {
                    Denied::NoPermission | Denied::NoExtendedWrite => {
                        OpcError::WriteErrorIllegalCommand
                    }
                })?;
            if !p.vars()[i].spec().writable {
                return Err(OpcError::WriteErrorDeviceRequestIllegal);
            }
            let x = numeric(value).ok_or(OpcError::BadType)?;
            if failed {
                return Err(OpcError::WriteErrorDriverTransmisionError);
            }
            let x = if p.vars()[i].spec().var_type == VarType::R4 {
                x as f32 as f64
            } else {
                x
            };
            p.set(i, x, ext.map(|e| e.0), ext.map(|e| e.1));
            Ok(())
        })();
        results.push(match r {
            Ok(()) => 0,
            Err(e) => {
                debug!(client, channel = %v.channel, variable = %v.variable, error = %e, "write refused");
                e.hresult()
            }
        });
    }
    results
}
