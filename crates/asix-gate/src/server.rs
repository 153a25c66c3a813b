//! The asix protocol's server role over the [`Engine`]: discovery answers, the link
//! listener with its TLS handshake (asix-net's [`server`] plumbing, shared with
//! asix-sim), and one task per
//! link serving Hello, Subscribe/Unsubscribe (sampled from the channels' images), Read,
//! Write and WriteVqt (`docs/asix-net-protocol.md`).
//!
//! Writes are granted by the write-rights policy ([`WriteRights`], `ZEZWOLENIE_ZAPISU` of
//! `asix-gate.ini`) to the link's authenticated identity (`cert:<fingerprint>`); on a
//! plaintext link (only for channels that allow it) to the client's declared asix name.
//! A refused write gets `ASKOM_E_WriteError_IllegalCommand`, as asix-sim refuses it.
//!
//! Bounds: requests under way per link ([`MAX_PENDING`]; more are answered busy), the
//! frames read ahead (64), the handshakes under way (the security settings). A link that
//! goes away drops its subscriptions at once.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use asix_net::proto::discovery::{Announce, FindServer, Resource};
use asix_net::proto::frame::{
    encode_frame, Frame, HelloAck, Message, ReadSource, ServerFlags, UpdateEncoder,
};
use asix_net::secure::ServerSecurity;
use asix_net::server::{self, reply};
use asix_net::tls::Fingerprint;
use ctopc_core::audit;
use ctopc_core::write_rights::{Caller, WriteRights};
use ctopc_core::{OpcError, Quality, Timestamp, Value};
use tokio::io::{AsyncWriteExt, BufWriter};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::{mpsc, watch, OwnedSemaphorePermit, Semaphore};
use tokio::task::JoinHandle;
use tracing::{debug, info, warn};

use crate::channel::DataSource;
use crate::engine::{Channel, Engine};

/// Reads and writes under way per link.
pub const MAX_PENDING: usize = 32;

/// What the network side needs besides the engine.
pub struct ServeConfig {
    pub server_name: String,
    /// This computer's name (clients declaring it are told LOCAL).
    pub host_name: String,
    pub discovery: SocketAddr,
    pub listen: SocketAddr,
    pub security: ServerSecurity,
    pub write_rights: WriteRights,
    /// Shorter sampling periods are raised to this.
    pub min_sampling_ms: u32,
}

struct Shared {
    cfg: ServeConfig,
    engine: Arc<Engine>,
    tcp_port: u16,
    resources: Vec<Resource>,
    handshakes: Arc<Semaphore>,
    links: AtomicU32,
    shutdown: watch::Sender<bool>,
}

impl Shared {
    fn flags(&self, client_host: &str) -> ServerFlags {
        ServerFlags(0)
            .with(
                ServerFlags::LOCAL,
                !client_host.is_empty() && client_host.eq_ignore_ascii_case(&self.cfg.host_name),
            )
            .with(ServerFlags::SOURCE_FAILED, self.engine.source_failed())
    }
    fn clients(&self) -> u32 {
        self.links.load(Ordering::SeqCst)
    }
}

/// A running gate server. Dropping it stops the network side.
pub struct GateServer {
    shared: Arc<Shared>,
    discovery_addr: SocketAddr,
    tcp_addr: SocketAddr,
    tasks: Vec<JoinHandle<()>>,
}

/// Binds the sockets and serves on the current tokio runtime.
pub async fn serve(cfg: ServeConfig, engine: Arc<Engine>) -> io::Result<GateServer> {
    let udp = UdpSocket::bind(cfg.discovery)
        .await
        .map_err(|e| bind_error("discovery (UDP)", cfg.discovery, e))?;
    let tcp = TcpListener::bind(cfg.listen)
        .await
        .map_err(|e| bind_error("link listener (TCP)", cfg.listen, e))?;
    let discovery_addr = udp.local_addr()?;
    let tcp_addr = tcp.local_addr()?;
    let resources = engine
        .channels
        .iter()
        .map(|c| Resource::channel(&c.config.name))
        .collect();
    let shared = Arc::new(Shared {
        handshakes: Arc::new(Semaphore::new(cfg.security.max_handshakes.max(1))),
        cfg,
        engine,
        tcp_port: tcp_addr.port(),
        resources,
        links: AtomicU32::new(0),
        shutdown: watch::channel(false).0,
    });
    info!(server = %shared.cfg.server_name, udp = %discovery_addr, tcp = %tcp_addr, "asix-gate serving");
    let tasks = vec![
        tokio::spawn(udp_loop(shared.clone(), udp)),
        tokio::spawn(accept_loop(shared.clone(), tcp)),
    ];
    Ok(GateServer {
        shared,
        discovery_addr,
        tcp_addr,
        tasks,
    })
}

/// A bind failure that says which socket, which address and what went wrong (the
/// platform's text of an OS error may be no more than its number).
fn bind_error(what: &str, addr: SocketAddr, e: io::Error) -> io::Error {
    io::Error::new(e.kind(), format!("{what} {addr}: {} ({e})", e.kind()))
}

impl GateServer {
    pub fn discovery_addr(&self) -> SocketAddr {
        self.discovery_addr
    }
    pub fn tcp_addr(&self) -> SocketAddr {
        self.tcp_addr
    }
    pub fn fingerprint(&self) -> Option<Fingerprint> {
        self.shared.cfg.security.fingerprint()
    }
    /// Linked clients now.
    pub fn client_count(&self) -> u32 {
        self.shared.clients()
    }
    /// The announcement a FindServer for `resource` gets now.
    pub fn announcement(&self, resource: Resource) -> Announce {
        announce(
            &self.shared,
            &FindServer {
                request: 0,
                client_name: String::new(),
                client_host: String::new(),
                resource,
            },
        )
    }
    /// Stops serving: every socket closes.
    pub async fn shutdown(mut self) {
        let _ = self.shared.shutdown.send(true);
        for t in self.tasks.drain(..) {
            let _ = t.await;
        }
    }
}

impl Drop for GateServer {
    fn drop(&mut self) {
        let _ = self.shared.shutdown.send(true);
    }
}

async fn udp_loop(shared: Arc<Shared>, sock: UdpSocket) {
    let shutdown = shared.shutdown.subscribe();
    server::discovery_loop(sock, shutdown, |f| {
        (f.resource.name.is_empty() || shared.resources.contains(&f.resource))
            .then(|| announce(&shared, f))
    })
    .await;
}

fn announce(shared: &Shared, f: &FindServer) -> Announce {
    let resources = server::announced_resources(&shared.resources, &f.resource);
    Announce {
        request: f.request,
        server_name: shared.cfg.server_name.clone(),
        server_host: shared.cfg.host_name.clone(),
        flags: shared.flags(&f.client_host),
        clients: shared.clients(),
        tcp_port: shared.tcp_port,
        fingerprint: shared.cfg.security.fingerprint(),
        resources,
    }
}

async fn accept_loop(shared: Arc<Shared>, listener: TcpListener) {
    let shutdown = shared.shutdown.subscribe();
    let handshakes = shared.handshakes.clone();
    server::accept_loop(listener, shutdown, handshakes, |stream, peer, permit| {
        tokio::spawn(serve_link(shared.clone(), stream, peer, permit));
    })
    .await;
}

struct Sub {
    channel: Arc<Channel>,
    item: String,
    sampling: u32,
    changes_only: bool,
    /// Version last sent; 0 forces the next send.
    sent_version: u32,
}

struct Group {
    period: Duration,
    next_due: Instant,
    handles: BTreeSet<u32>,
}

struct Link {
    /// The asix name the client declared.
    client: Option<String>,
    /// The client declared this computer's name.
    local: bool,
    identity: Option<String>,
    certificate: Option<Fingerprint>,
    subs: HashMap<u32, Sub>,
    groups: BTreeMap<u32, Group>,
    last_rx: Instant,
    idle: Duration,
    counted: bool,
}

impl Link {
    fn plaintext(&self) -> bool {
        self.certificate.is_none()
    }
    /// The write-rights caller: the certificate on TLS links, the declared name only on
    /// plaintext ones (where nothing better exists).
    fn caller(&self) -> Caller {
        if self.certificate.is_some() {
            Caller::Link {
                client: None,
                certificate: self.certificate,
            }
        } else {
            Caller::Link {
                client: self.client.clone(),
                certificate: None,
            }
        }
    }
    fn drop_sub(&mut self, engine: &Engine, handle: u32) -> bool {
        let Some(s) = self.subs.remove(&handle) else {
            return false;
        };
        engine.unsubscribe(&s.channel, &s.item);
        if let Some(g) = self.groups.get_mut(&s.sampling) {
            g.handles.remove(&handle);
        }
        true
    }
}

async fn serve_link(
    shared: Arc<Shared>,
    stream: TcpStream,
    peer: SocketAddr,
    permit: OwnedSemaphorePermit,
) {
    let mut shut_rx = shared.shutdown.subscribe();
    let Some(secured) = server::secure_link(stream, peer, &shared.cfg.security, &mut shut_rx).await
    else {
        return;
    };
    drop(permit);
    info!(%peer, identity = secured.peer.as_deref().unwrap_or("none (plaintext)"), "client linked");
    let (ftx, mut frx) = mpsc::channel(64);
    let reader = tokio::spawn(server::read_frames(secured.rd, ftx));
    let (dtx, mut drx) = mpsc::channel::<Vec<u8>>(MAX_PENDING);
    let pending = Arc::new(Semaphore::new(MAX_PENDING));
    let mut w = BufWriter::with_capacity(64 * 1024, secured.wr);
    let mut status_rx = shared.engine.status.subscribe();
    let mut link = Link {
        client: None,
        local: false,
        identity: secured.peer,
        certificate: secured.peer_fingerprint,
        subs: HashMap::new(),
        groups: BTreeMap::new(),
        last_rx: Instant::now(),
        idle: Duration::from_secs(10),
        counted: false,
    };
    let far = Duration::from_secs(3600);
    loop {
        let now = Instant::now();
        let next_due = link
            .groups
            .values()
            .map(|g| g.next_due)
            .min()
            .unwrap_or(now + far);
        let idle_at = link.last_rx + link.idle;
        let mut out = Vec::new();
        let close = tokio::select! {
            f = frx.recv() => match f {
                Some(Ok(frame)) => {
                    link.last_rx = Instant::now();
                    handle_frame(&shared, &mut link, frame, &mut out, &dtx, &pending)
                }
                Some(Err(e)) => {
                    warn!(%peer, error = %e, "bad frame from client; closing");
                    server::bad_frame(&mut out, &e);
                    true
                }
                None => true,
            },
            Some(bytes) = drx.recv() => {
                out = bytes;
                false
            }
            () = tokio::time::sleep_until(next_due.into()) => {
                let now = Instant::now();
                let due: Vec<u32> = link.groups.iter().filter(|(_, g)| g.next_due <= now).map(|(k, _)| *k).collect();
                for k in due {
                    let Some(g) = link.groups.get_mut(&k) else { continue };
                    g.next_due += g.period;
                    if g.next_due < now {
                        g.next_due = now + g.period;
                    }
                    let handles: Vec<u32> = g.handles.iter().copied().collect();
                    sample(&mut link.subs, &handles, false, &mut out);
                }
                false
            }
            () = tokio::time::sleep_until(idle_at.into()) => {
                debug!(%peer, "client silent; closing link");
                true
            }
            _ = status_rx.changed() => {
                if link.client.is_some() {
                    let _ = encode_frame(&mut out, 0, &Message::ServerStatus { flags: shared.flags("").with(ServerFlags::LOCAL, link.local), clients: shared.clients() });
                    let handles: Vec<u32> = link.subs.keys().copied().collect();
                    sample(&mut link.subs, &handles, true, &mut out);
                }
                false
            }
            _ = shut_rx.changed() => true,
        };
        if !out.is_empty() && (w.write_all(&out).await.is_err() || w.flush().await.is_err()) {
            break;
        }
        if close {
            break;
        }
    }
    reader.abort();
    let handles: Vec<u32> = link.subs.keys().copied().collect();
    for h in handles {
        link.drop_sub(&shared.engine, h);
    }
    if link.counted {
        shared.links.fetch_sub(1, Ordering::SeqCst);
    }
    info!(%peer, "client gone");
    let _ = w.shutdown().await;
}

/// Appends Update frames for the handles: changed entries (or every one when `all` or
/// the subscription is not changes-only).
fn sample(subs: &mut HashMap<u32, Sub>, handles: &[u32], all: bool, out: &mut Vec<u8>) {
    let mut enc = UpdateEncoder::new(64 * 1024);
    for h in handles {
        let Some(s) = subs.get_mut(h) else { continue };
        let Some((vqt, version)) = s.channel.entry(&s.item) else {
            continue;
        };
        if s.changes_only && !all && s.sent_version == version {
            continue;
        }
        s.sent_version = version;
        if enc.push(*h, &vqt).is_err() {
            break;
        }
    }
    if let Ok(bytes) = enc.finish() {
        out.extend_from_slice(&bytes);
    }
}

/// Handles one frame; true closes the link.
fn handle_frame(
    shared: &Arc<Shared>,
    link: &mut Link,
    frame: Frame,
    out: &mut Vec<u8>,
    deferred: &mpsc::Sender<Vec<u8>>,
    pending: &Arc<Semaphore>,
) -> bool {
    let Frame { request, msg } = frame;
    if link.client.is_none() {
        let Message::Hello(h) = msg else {
            reply(
                out,
                request,
                &Message::Error {
                    code: OpcError::NetLinkToServerNegativeAnswer.hresult(),
                    message: "Hello expected".into(),
                },
            );
            return true;
        };
        link.idle = if h.keepalive_ms == 0 {
            Duration::from_secs(30)
        } else {
            Duration::from_millis(u64::from(h.keepalive_ms) * 3).max(Duration::from_secs(1))
        };
        shared.links.fetch_add(1, Ordering::SeqCst);
        link.counted = true;
        debug!(client = %h.client_name, identity = link.identity.as_deref().unwrap_or("-"), "hello");
        reply(
            out,
            request,
            &Message::HelloAck(HelloAck {
                status: 0,
                server_name: shared.cfg.server_name.clone(),
                flags: shared.flags(&h.client_host),
                clients: shared.clients(),
                idle_timeout_ms: link.idle.as_millis() as u32,
            }),
        );
        link.local = shared.flags(&h.client_host).local();
        link.client = Some(h.client_name);
        return false;
    }
    let engine = &shared.engine;
    // The channel of a variable, if served to this link.
    let channel_for = |link: &Link, name: &str| -> Result<Arc<Channel>, i32> {
        let ch = engine
            .channel(name)
            .ok_or(OpcError::ItemUnknown.hresult())?;
        if link.plaintext() && !ch.config.allow_plaintext {
            return Err(OpcError::NetLinkToServerNegativeAnswer.hresult());
        }
        Ok(ch.clone())
    };
    match msg {
        Message::Ping { nonce } => reply(out, request, &Message::Pong { nonce }),
        Message::Pong { .. } => {}
        Message::Bye { .. } => return true,
        Message::Subscribe {
            sampling_ms,
            changes_only,
            items,
        } => {
            let sampling = sampling_ms.max(shared.cfg.min_sampling_ms).max(1);
            let mut results = Vec::with_capacity(items.len());
            let mut fresh = Vec::new();
            for it in items {
                let ch = match channel_for(link, &it.var.channel) {
                    Ok(c) => c,
                    Err(code) => {
                        results.push((it.handle, code));
                        continue;
                    }
                };
                link.drop_sub(engine, it.handle);
                engine.subscribe(&ch, &it.var.variable);
                link.subs.insert(
                    it.handle,
                    Sub {
                        channel: ch,
                        item: it.var.variable.clone(),
                        sampling,
                        changes_only,
                        sent_version: 0,
                    },
                );
                let period = Duration::from_millis(u64::from(sampling));
                link.groups
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
            link.groups.retain(|_, g| !g.handles.is_empty());
            reply(out, request, &Message::SubscribeAck { results });
            sample(&mut link.subs, &fresh, true, out);
        }
        Message::Unsubscribe { handles } => {
            let results = handles
                .into_iter()
                .map(|h| {
                    let code = if link.drop_sub(engine, h) {
                        0
                    } else {
                        OpcError::ItemUnknown.hresult()
                    };
                    (h, code)
                })
                .collect();
            link.groups.retain(|_, g| !g.handles.is_empty());
            reply(out, request, &Message::UnsubscribeAck { results });
        }
        Message::Read { source, items } => {
            let Ok(permit) = pending.clone().try_acquire_owned() else {
                return busy(out, request);
            };
            // Per item: its channel, or the error.
            let mut plan: Vec<Result<(Arc<Channel>, String), i32>> = Vec::new();
            for v in &items {
                plan.push(channel_for(link, &v.channel).map(|c| (c, v.variable.clone())));
            }
            let engine = engine.clone();
            let deferred = deferred.clone();
            tokio::spawn(async move {
                let results = read(&engine, source, plan).await;
                let mut out = Vec::new();
                reply(&mut out, request, &Message::ReadResult { results });
                let _ = deferred.send(out).await;
                drop(permit);
            });
        }
        Message::Write { items } => {
            let items = items.into_iter().map(|(v, x)| (v, x, None)).collect();
            return write(shared, link, request, items, out, deferred, pending);
        }
        Message::WriteVqt { items } => {
            let items = items
                .into_iter()
                .map(|(v, x)| (v, x.value, Some((x.quality, x.timestamp))))
                .collect();
            return write(shared, link, request, items, out, deferred, pending);
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
    false
}

fn busy(out: &mut Vec<u8>, request: u32) -> bool {
    reply(
        out,
        request,
        &Message::Error {
            code: OpcError::NetSendData.hresult(),
            message: format!("more than {MAX_PENDING} requests under way"),
        },
    );
    false
}

/// Reads the planned items, one engine call per channel (in parallel across channels).
async fn read(
    engine: &Arc<Engine>,
    source: ReadSource,
    plan: Vec<Result<(Arc<Channel>, String), i32>>,
) -> Vec<Result<ctopc_core::Vqt, i32>> {
    let mut results: Vec<Result<ctopc_core::Vqt, i32>> = vec![Err(0); plan.len()];
    let mut by_channel: Vec<(Arc<Channel>, Vec<usize>, Vec<String>)> = Vec::new();
    for (i, p) in plan.into_iter().enumerate() {
        match p {
            Err(code) => results[i] = Err(code),
            Ok((ch, item)) => match by_channel.iter_mut().find(|(c, _, _)| Arc::ptr_eq(c, &ch)) {
                Some((_, idx, names)) => {
                    idx.push(i);
                    names.push(item);
                }
                None => by_channel.push((ch, vec![i], vec![item])),
            },
        }
    }
    let mut tasks = Vec::new();
    for (ch, idx, names) in by_channel {
        // Cache: the gate's image of subscribed items, else the asix system's cache.
        if source == ReadSource::Cache {
            let cached: Option<Vec<_>> = names.iter().map(|n| ch.entry(n)).collect();
            if let Some(c) = cached {
                for (i, (vqt, _)) in idx.into_iter().zip(c) {
                    results[i] = Ok(vqt);
                }
                continue;
            }
        }
        let ds = match source {
            ReadSource::Driver => DataSource::Driver,
            _ => ch.config.device_read,
        };
        let engine = engine.clone();
        tasks.push(tokio::spawn(async move {
            let r = engine.read(&ch, ds, names).await;
            (idx, r)
        }));
    }
    for t in tasks {
        if let Ok((idx, r)) = t.await {
            for (i, v) in idx.into_iter().zip(r) {
                results[i] = v.map_err(|e| e.hresult());
            }
        }
    }
    results
}

/// How an audited write item ended.
#[derive(Debug, Clone, Copy)]
enum AuditResult {
    /// The write-rights policy refused it (the client got the original's
    /// `ASKOM_E_WriteError_IllegalCommand`).
    Denied,
    /// Written to the channel, with its HRESULT (0: S_OK).
    Written(i32),
}

/// The write audit line of one item (`ctopc_core::audit`'s format, under its target, as
/// the server's): who wrote it by the link's authenticated identity, beside the name the
/// client declared.
fn audit_line(
    client: Option<&str>,
    caller: &Caller,
    v: &asix_net::proto::frame::VarRef,
    value: &Value,
    ext: Option<(Quality, Timestamp)>,
    result: AuditResult,
) {
    let identity = caller.to_string();
    let item = format!("{}.{}", v.channel, v.variable);
    let (result, denied) = match result {
        AuditResult::Denied => (Err(OpcError::BadRights), true),
        AuditResult::Written(0) => (Ok(()), false),
        AuditResult::Written(hr) => (
            Err(OpcError::from_hresult(hr).unwrap_or(OpcError::Fail)),
            false,
        ),
    };
    let record = audit::WriteRecord {
        time: ctopc_runtime::clock::now(),
        client: audit::Client::Named(client.unwrap_or("")),
        identity: Some(&identity),
        method: if ext.is_some() {
            "asix::WriteEx"
        } else {
            "asix::Write"
        },
        group: None,
        item_id: Some(&item),
        server_handle: None,
        value,
        quality: ext.map(|e| e.0),
        timestamp: ext.map(|e| e.1),
        cancel_id: None,
        result,
        denied,
    };
    info!(target: audit::TARGET, "{}", audit::format_write(&record));
}

type WriteItem = (
    asix_net::proto::frame::VarRef,
    Value,
    Option<(Quality, Timestamp)>,
);

/// Checks each item's write right by the link's identity, then writes the granted ones.
fn write(
    shared: &Arc<Shared>,
    link: &Link,
    request: u32,
    items: Vec<WriteItem>,
    out: &mut Vec<u8>,
    deferred: &mpsc::Sender<Vec<u8>>,
    pending: &Arc<Semaphore>,
) -> bool {
    let Ok(permit) = pending.clone().try_acquire_owned() else {
        return busy(out, request);
    };
    let caller = link.caller();
    let engine = &shared.engine;
    let mut results: Vec<i32> = vec![0; items.len()];
    let mut seen: HashMap<(String, String), usize> = HashMap::new();
    for (v, _, _) in &items {
        *seen
            .entry((
                v.channel.to_ascii_uppercase(),
                v.variable.to_ascii_uppercase(),
            ))
            .or_default() += 1;
    }
    let mut by_channel: Vec<(Arc<Channel>, Vec<usize>, Vec<crate::engine::WriteItem>)> = Vec::new();
    for (i, (v, value, ext)) in items.into_iter().enumerate() {
        if seen[&(
            v.channel.to_ascii_uppercase(),
            v.variable.to_ascii_uppercase(),
        )] > 1
        {
            results[i] = OpcError::TheSameItemWrittenMoreThanOnce.hresult();
            continue;
        }
        let ch = match engine.channel(&v.channel) {
            Some(c) if !link.plaintext() || c.config.allow_plaintext => c.clone(),
            Some(_) => {
                results[i] = OpcError::NetLinkToServerNegativeAnswer.hresult();
                continue;
            }
            None => {
                results[i] = OpcError::ItemUnknown.hresult();
                continue;
            }
        };
        let d = shared.cfg.write_rights.decide(&ch.config.name, &caller);
        if !d.allowed {
            warn!(caller = %caller, channel = %ch.config.name, variable = %v.variable, decision = %d, "write refused");
            results[i] = OpcError::WriteErrorIllegalCommand.hresult();
            audit_line(
                link.client.as_deref(),
                &caller,
                &v,
                &value,
                ext,
                AuditResult::Denied,
            );
            continue;
        }
        debug!(caller = %caller, channel = %ch.config.name, variable = %v.variable, decision = %d, "write");
        // A simple write and an extended one go to different members: one batch each.
        let extended = ext.is_some();
        match by_channel
            .iter_mut()
            .find(|(c, _, b)| Arc::ptr_eq(c, &ch) && b[0].2.is_some() == extended)
        {
            Some((_, idx, batch)) => {
                idx.push(i);
                batch.push((v.variable, value, ext));
            }
            None => by_channel.push((ch, vec![i], vec![(v.variable, value, ext)])),
        }
    }
    let engine = engine.clone();
    let deferred = deferred.clone();
    let client = link.client.clone();
    tokio::spawn(async move {
        for (ch, idx, batch) in by_channel {
            let written: Vec<_> = batch
                .iter()
                .map(|(variable, value, ext)| (variable.clone(), value.clone(), *ext))
                .collect();
            let r = engine.write(&ch, batch).await;
            for ((i, x), (variable, value, ext)) in idx.into_iter().zip(r).zip(written) {
                results[i] = x.err().unwrap_or(0);
                let v = asix_net::proto::frame::VarRef {
                    channel: ch.config.name.clone(),
                    variable,
                };
                audit_line(
                    client.as_deref(),
                    &caller,
                    &v,
                    &value,
                    ext,
                    AuditResult::Written(results[i]),
                );
            }
        }
        let mut out = Vec::new();
        reply(&mut out, request, &Message::WriteResult { results });
        let _ = deferred.send(out).await;
        drop(permit);
    });
    false
}
