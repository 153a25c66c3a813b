//! The asix network client: a tokio shell around [`ClientCore`].
//!
//! [`AsixClient`] is a handle whose methods never block and never wait for the network:
//! they queue a command and return (reads and writes return the [`RequestId`] their result
//! will carry). Everything the client has to say arrives through an [`EventSink`].

pub mod core;

use std::collections::HashMap;
use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use asix_model::ItemKey;
use ctopc_core::{OpcError, Timestamp, Value};
use tokio::io::{AsyncWriteExt, BufWriter};
use tokio::net::{TcpStream, UdpSocket};
use tokio::runtime::Handle;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tracing::{debug, warn};

pub use self::core::{Action, ClientCore, ClientEvent, LinkId, Now, RequestId};
use crate::config::ClientConfig;
use crate::discovery::{Candidate, Search};
use crate::proto::codec::{frames, next_frame, ReadError};
use crate::proto::discovery::{decode_datagram, encode_datagram, Datagram, FindServer, Resource};
use crate::proto::frame::{Frame, ReadSource};
use crate::proto::{DecodeError, MAX_DATAGRAM};
use crate::secure::{client_handshake, ClientSecurity, LinkRead, LinkWrite, Secured};
use crate::Vqt;

/// Receives the client's events. Called from the client's task, never while it holds a
/// lock; it must not block for long (hand the event on).
pub trait EventSink: Send + 'static {
    fn deliver(&mut self, event: ClientEvent);
}

impl<F: FnMut(ClientEvent) + Send + 'static> EventSink for F {
    fn deliver(&mut self, event: ClientEvent) {
        self(event)
    }
}

/// An [`EventSink`] that forwards into a tokio unbounded channel (usable from sync code
/// with `try_recv` / `blocking_recv`).
pub fn channel_sink() -> (impl EventSink, mpsc::UnboundedReceiver<ClientEvent>) {
    let (tx, rx) = mpsc::unbounded_channel();
    (move |ev| drop(tx.send(ev)), rx)
}

/// The current time for the core.
pub fn now() -> Now {
    Now {
        mono: Instant::now(),
        wall: wall_now(),
    }
}

/// The current UTC time as a FILETIME timestamp.
pub fn wall_now() -> Timestamp {
    let d = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default();
    Timestamp(Timestamp::UNIX_EPOCH_TICKS + (d.as_nanos() / 100) as i64)
}

enum Command {
    Subscribe(Vec<ItemKey>, u32),
    Unsubscribe(Vec<ItemKey>),
    Read(RequestId, Vec<ItemKey>, ReadSource),
    Write(RequestId, Vec<(ItemKey, Value)>),
    WriteVqt(RequestId, Vec<(ItemKey, Vqt)>),
    Shutdown,
}

/// Handle of a running client. Dropping it shuts the client down.
pub struct AsixClient {
    tx: mpsc::UnboundedSender<Command>,
    ids: AtomicU64,
    task: Option<JoinHandle<()>>,
}

impl AsixClient {
    /// Starts the client on a tokio runtime. Binds the discovery socket now (the only step
    /// that can fail); servers are searched for when items are first used.
    pub fn start(cfg: ClientConfig, sink: impl EventSink, rt: &Handle) -> io::Result<AsixClient> {
        let std_sock = std::net::UdpSocket::bind(cfg.discovery_bind)?;
        std_sock.set_broadcast(true)?;
        std_sock.set_nonblocking(true)?;
        let _guard = rt.enter();
        let udp = UdpSocket::from_std(std_sock)?;
        let (tx, rx) = mpsc::unbounded_channel();
        let task = rt.spawn(run(ClientCore::new(cfg), udp, rx, sink));
        Ok(AsixClient {
            tx,
            ids: AtomicU64::new(0),
            task: Some(task),
        })
    }

    fn next_id(&self) -> RequestId {
        self.ids.fetch_add(1, Ordering::Relaxed) + 1
    }

    /// Subscribes items (or changes their sampling period).
    pub fn subscribe(&self, keys: Vec<ItemKey>, sampling_ms: u32) {
        let _ = self.tx.send(Command::Subscribe(keys, sampling_ms));
    }

    pub fn unsubscribe(&self, keys: Vec<ItemKey>) {
        let _ = self.tx.send(Command::Unsubscribe(keys));
    }

    /// Starts a read; the result comes as [`ClientEvent::ReadDone`] with the returned id.
    pub fn read(&self, keys: Vec<ItemKey>, source: ReadSource) -> RequestId {
        let id = self.next_id();
        let _ = self.tx.send(Command::Read(id, keys, source));
        id
    }

    /// Starts a write; the result comes as [`ClientEvent::WriteDone`].
    pub fn write(&self, items: Vec<(ItemKey, Value)>) -> RequestId {
        let id = self.next_id();
        let _ = self.tx.send(Command::Write(id, items));
        id
    }

    /// Starts an extended (value, quality, timestamp) write.
    pub fn write_vqt(&self, items: Vec<(ItemKey, Vqt)>) -> RequestId {
        let id = self.next_id();
        let _ = self.tx.send(Command::WriteVqt(id, items));
        id
    }

    /// Closes every link and waits for the client task to end.
    pub async fn shutdown(mut self) {
        let _ = self.tx.send(Command::Shutdown);
        if let Some(t) = self.task.take() {
            let _ = t.await;
        }
    }
}

impl Drop for AsixClient {
    fn drop(&mut self) {
        let _ = self.tx.send(Command::Shutdown);
    }
}

/// Frames and link reports queued between the socket tasks and the client task.
const INTERNAL_QUEUE: usize = 1024;

enum Internal {
    Connected { link: LinkId, io: LinkIo },
    Frame { link: LinkId, frame: Frame },
    Failed { link: LinkId, error: OpcError },
}

struct LinkIo {
    tx: mpsc::UnboundedSender<Vec<u8>>,
    reader: JoinHandle<()>,
}

impl LinkIo {
    fn close(self) {
        // Dropping `tx` lets the writer flush what is queued and shut the socket down.
        self.reader.abort();
    }
}

struct Shell<S> {
    core: ClientCore,
    udp: UdpSocket,
    sink: S,
    links: HashMap<LinkId, LinkIo>,
    internal: mpsc::Sender<Internal>,
}

impl<S: EventSink> Shell<S> {
    async fn perform_all(&mut self) {
        while let Some(a) = self.core.poll_action() {
            match a {
                Action::Event(ev) => self.sink.deliver(ev),
                Action::Send { link, bytes } => {
                    if let Some(io) = self.links.get(&link) {
                        let _ = io.tx.send(bytes);
                    }
                }
                Action::Close { link } => {
                    if let Some(io) = self.links.remove(&link) {
                        io.close();
                    }
                }
                Action::Connect {
                    link,
                    addr,
                    fingerprint,
                } => {
                    let timeout = self.core.config().options.net_timeout;
                    let security = self.core.config().security.clone();
                    let internal = self.internal.clone();
                    tokio::spawn(async move {
                        // Connection, preamble and TLS handshake, bounded together.
                        let made = tokio::time::timeout(timeout, async {
                            let stream = TcpStream::connect(addr).await.map_err(|e| {
                                debug!(%addr, error = %e, "connect failed");
                                None
                            })?;
                            client_handshake(stream, &security, fingerprint)
                                .await
                                .map_err(Some)
                        })
                        .await;
                        let ev = match made {
                            Ok(Ok(secured)) => {
                                if matches!(security, ClientSecurity::Plaintext) {
                                    warn!(%addr, "plaintext asix link: no authentication, no encryption (AsixNetPlaintext; closed test network only)");
                                }
                                Internal::Connected {
                                    link,
                                    io: open_link(link, secured, internal.clone()),
                                }
                            }
                            Ok(Err(None)) => Internal::Failed {
                                link,
                                error: OpcError::NetLinkToServer,
                            },
                            Ok(Err(Some(r))) => {
                                warn!(%addr, error = %r.error, reason = %r.reason, "asix link refused");
                                Internal::Failed {
                                    link,
                                    error: r.error,
                                }
                            }
                            Err(_) => {
                                warn!(%addr, "asix link not established within NetTimeout (connection, preamble or TLS handshake)");
                                Internal::Failed {
                                    link,
                                    error: OpcError::NetLinkToServerTimeout,
                                }
                            }
                        };
                        let _ = internal.send(ev).await;
                    });
                }
                Action::SendFindServer(fs) => {
                    let targets = self.core.config().discovery_targets.clone();
                    send_find_server(&self.udp, &fs, &targets).await;
                }
            }
        }
    }

    fn internal(&mut self, ev: Internal) {
        match ev {
            Internal::Connected { link, io } => {
                self.links.insert(link, io);
                if !self.core.handle_connected(now(), link) {
                    if let Some(io) = self.links.remove(&link) {
                        io.close();
                    }
                }
            }
            Internal::Frame { link, frame } => self.core.handle_frame(now(), link, frame),
            Internal::Failed { link, error } => {
                if let Some(io) = self.links.remove(&link) {
                    io.close();
                }
                self.core.handle_link_failed(now(), link, error);
            }
        }
    }

    fn command(&mut self, c: Command) -> bool {
        let n = now();
        match c {
            Command::Subscribe(keys, ms) => self.core.subscribe(n, keys, ms),
            Command::Unsubscribe(keys) => self.core.unsubscribe(n, keys),
            Command::Read(id, keys, src) => self.core.read(n, id, keys, src),
            Command::Write(id, items) => self.core.write(n, id, items),
            Command::WriteVqt(id, items) => self.core.write_vqt(n, id, items),
            Command::Shutdown => {
                self.core.shutdown();
                return false;
            }
        }
        true
    }
}

async fn send_find_server(udp: &UdpSocket, fs: &FindServer, targets: &[SocketAddr]) {
    match encode_datagram(&Datagram::FindServer(fs.clone())) {
        Ok(bytes) => {
            for t in targets {
                if let Err(e) = udp.send_to(&bytes, t).await {
                    debug!(target = %t, error = %e, "FindServer not sent");
                }
            }
        }
        Err(e) => warn!(error = %e, "FindServer not encodable"),
    }
}

async fn run<S: EventSink>(
    core: ClientCore,
    udp: UdpSocket,
    mut cmds: mpsc::UnboundedReceiver<Command>,
    sink: S,
) {
    // Bounded: a consumer slower than the network pushes back on the sockets.
    let (itx, mut irx) = mpsc::channel(INTERNAL_QUEUE);
    let mut sh = Shell {
        core,
        udp,
        sink,
        links: HashMap::new(),
        internal: itx,
    };
    let mut buf = vec![0u8; MAX_DATAGRAM + 1];
    loop {
        sh.perform_all().await;
        let deadline = sh.core.poll_timeout();
        let sleep = async move {
            match deadline {
                Some(d) => tokio::time::sleep_until(d.into()).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            c = cmds.recv() => {
                let go_on = match c {
                    Some(c) => sh.command(c),
                    None => { sh.core.shutdown(); false }
                };
                if !go_on {
                    break;
                }
            }
            Some(ev) = irx.recv() => {
                sh.internal(ev);
                // Take what else is ready in one go (bounded) before acting.
                for _ in 0..256 {
                    match irx.try_recv() {
                        Ok(ev) => sh.internal(ev),
                        Err(_) => break,
                    }
                }
            }
            r = sh.udp.recv_from(&mut buf) => {
                if let Ok((n, from)) = r {
                    match decode_datagram(&buf[..n]) {
                        Ok(Datagram::Announce(a)) => sh.core.handle_announce(now(), a, from),
                        Ok(_) => {}
                        Err(e) => debug!(%from, error = %e, "bad datagram"),
                    }
                }
            }
            () = sleep => sh.core.handle_timeout(now()),
        }
    }
    sh.perform_all().await;
    for (_, io) in sh.links.drain() {
        io.close();
    }
}

fn open_link(link: LinkId, secured: Secured, internal: mpsc::Sender<Internal>) -> LinkIo {
    let (tx, rx) = mpsc::unbounded_channel();
    tokio::spawn(write_loop(link, secured.wr, rx, internal.clone()));
    let reader = tokio::spawn(read_loop(link, secured.rd, internal));
    LinkIo { tx, reader }
}

async fn read_loop(link: LinkId, rd: LinkRead, internal: mpsc::Sender<Internal>) {
    let mut rd = frames(rd);
    let error = loop {
        match next_frame(&mut rd).await {
            Some(Ok(frame)) => {
                if internal
                    .send(Internal::Frame { link, frame })
                    .await
                    .is_err()
                {
                    return;
                }
            }
            None | Some(Err(ReadError::Io(_))) => break OpcError::NetCloseLink,
            Some(Err(ReadError::Decode(e @ DecodeError::BadLength(_)))) => {
                warn!(link, error = %e, "bad frame");
                break OpcError::NetCloseLink;
            }
            Some(Err(ReadError::Decode(e))) => {
                warn!(link, error = %e, "undecodable frame");
                break OpcError::NetCloseLink;
            }
        }
    };
    let _ = internal.send(Internal::Failed { link, error }).await;
}

async fn write_loop(
    link: LinkId,
    wr: LinkWrite,
    mut rx: mpsc::UnboundedReceiver<Vec<u8>>,
    internal: mpsc::Sender<Internal>,
) {
    let mut w = BufWriter::with_capacity(64 * 1024, wr);
    while let Some(bytes) = rx.recv().await {
        let mut ok = w.write_all(&bytes).await.is_ok();
        while ok {
            match rx.try_recv() {
                Ok(b) => ok = w.write_all(&b).await.is_ok(),
                Err(_) => break,
            }
        }
        if !ok || w.flush().await.is_err() {
            let _ = internal
                .send(Internal::Failed {
                    link,
                    error: OpcError::NetSendData,
                })
                .await;
            return;
        }
    }
    let _ = w.shutdown().await;
}

/// One-off discovery (e.g. for an archive or alarm server): sends FindServer to the
/// configured targets and returns the candidates in the order to try them, per the
/// configuration's choice and StopAfterFirstServerFound; `ASKOM_E_NetFindServer_NotFound`
/// when none answered within FindServerTimeout.
pub async fn discover(cfg: &ClientConfig, resource: Resource) -> Result<Vec<Candidate>, OpcError> {
    let udp = UdpSocket::bind(cfg.discovery_bind)
        .await
        .map_err(|_| OpcError::NetInit)?;
    let _ = udp.set_broadcast(true);
    let start = Instant::now();
    let choice = cfg.choice_for(&resource);
    let o = &cfg.options;
    let mut search = Search::new(
        resource.clone(),
        choice,
        o.stop_after_first_server_found,
        start,
        o.find_server_timeout,
    );
    let request = (start.elapsed().as_nanos() as u32) | 1;
    let fs = FindServer {
        request,
        resource,
        client_name: cfg.client_name.clone(),
        client_host: cfg.client_host.clone(),
    };
    let mut buf = vec![0u8; MAX_DATAGRAM + 1];
    let mut next_send = start;
    // Bounded: ends at the search deadline at the latest.
    while Instant::now() < search.deadline() && !search.is_done() {
        if Instant::now() >= next_send {
            send_find_server(&udp, &fs, &cfg.discovery_targets).await;
            next_send += cfg.discovery_resend;
        }
        let until = search.deadline().min(next_send);
        if let Ok(Ok((n, from))) =
            tokio::time::timeout_at(until.into(), udp.recv_from(&mut buf)).await
        {
            if let Ok(Datagram::Announce(a)) = decode_datagram(&buf[..n]) {
                if a.request == request && cfg.security.accepts_announcement(a.fingerprint.as_ref())
                {
                    search.offer(a, from);
                }
            }
        }
    }
    let found = search.finish();
    if found.is_empty() {
        Err(OpcError::NetFindServerNotFound)
    } else {
        Ok(found)
    }
}
