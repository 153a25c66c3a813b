//! The client as a sans-IO state machine: inputs are `handle_*` calls and the user's
//! requests, outputs are [`Action`]s taken with [`ClientCore::poll_action`]; every call takes
//! the time ([`Now`]) and [`ClientCore::poll_timeout`] says when to call
//! [`ClientCore::handle_timeout`] next. No clock, no socket.
//!
//! Per channel (asix resource) the life cycle is
//! `Idle -> Searching -> Connecting -> Up -> (link lost) -> Searching ...`, with `Backoff`
//! after a round that found or reached no server. Links are per server and shared by every
//! channel bound to that server.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Instant;

use asix_model::ItemKey;
use ctopc_core::{OpcError, Quality, Timestamp, Value};
use tracing::{debug, warn};

use crate::config::ClientConfig;
use crate::discovery::{Candidate, Search};
use crate::proto::discovery::{Announce, FindServer, Resource};
use crate::proto::frame::{
    encode_frame, Frame, Hello, Message, ReadSource, ServerFlags, SubscribeItem, VarRef,
};
use crate::proto::MAX_FRAME;
use crate::secure::ClientSecurity;
use crate::tls::{fingerprint_hex, Fingerprint};
use crate::Vqt;

/// Identifies a read or write request of the user; chosen by the caller, echoed in the result.
pub type RequestId = u64;
/// Identifies one TCP link (chosen by the core).
pub type LinkId = u64;

/// The time, as both a monotonic instant (deadlines) and a UTC timestamp (VQTs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Now {
    pub mono: Instant,
    pub wall: Timestamp,
}

/// The variable as the protocol names it.
fn var_ref(key: &ItemKey) -> VarRef {
    VarRef::new(&*key.channel, &*key.variable)
}

/// What the client tells its user.
#[derive(Debug, Clone, PartialEq)]
pub enum ClientEvent {
    /// New VQTs of subscribed items: values from the server, or the client's own quality
    /// while a channel has no link (BAD Last Known Value 0x14 keeping the last value and its
    /// timestamp, or BAD Comm Failure 0x18 with no value).
    Updates(Vec<(ItemKey, Vqt)>),
    /// The server refused to subscribe an item (e.g. ASKOM_E_ItemUnknown); the item is
    /// reported with quality BAD Config Error and subscribed again later.
    ItemFailed { key: ItemKey, error: OpcError },
    /// Results of [`ClientCore::read`], one per key in request order.
    ReadDone {
        id: RequestId,
        results: Vec<(ItemKey, Result<Vqt, OpcError>)>,
    },
    /// Results of a write, one per item in request order.
    WriteDone {
        id: RequestId,
        results: Vec<(ItemKey, Result<(), OpcError>)>,
    },
    /// A channel is linked to a server (first time or after a failover).
    ChannelUp { channel: Arc<str>, server: String },
    /// A channel lost its link or found no server.
    ChannelDown { channel: Arc<str>, error: OpcError },
    /// A server reported new flags or client count.
    ServerStatus {
        server: String,
        flags: ServerFlags,
        clients: u32,
    },
}

/// What the shell must do.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Send this FindServer to every discovery target.
    SendFindServer(FindServer),
    /// Open a TCP link and secure it (preamble, TLS whose server certificate must have
    /// the announced `fingerprint`); report with `handle_connected` or `handle_link_failed`.
    Connect {
        link: LinkId,
        addr: SocketAddr,
        fingerprint: Option<Fingerprint>,
    },
    /// Write these bytes (whole frames) on the link.
    Send { link: LinkId, bytes: Vec<u8> },
    /// Close the link (after sending what is queued); no further reports are wanted.
    Close { link: LinkId },
    /// Deliver this event to the user.
    Event(ClientEvent),
}

#[derive(Debug, Clone, PartialEq)]
enum ItemState {
    /// Not subscribed on any link.
    Idle,
    /// Subscribe sent, no answer yet.
    Pending,
    Active,
    Failed(OpcError),
}

#[derive(Debug)]
struct Item {
    handle: u32,
    sampling_ms: u32,
    last: Option<Vqt>,
    state: ItemState,
    /// A down quality (LKV / comm failure) was reported since the last server value.
    down: bool,
}

enum ChanState {
    Idle,
    Searching {
        id: u32,
        search: Search,
        next_resend: Instant,
    },
    Connecting {
        link: LinkId,
        rest: Vec<Candidate>,
    },
    Up {
        link: LinkId,
    },
    Backoff {
        until: Instant,
    },
}

struct Channel {
    name: Arc<str>,
    state: ChanState,
    /// Reads and writes waiting for a link.
    queued: Vec<Part>,
    items: usize,
    down_reported: bool,
}

/// A read or write, or the part of one that goes to one channel.
struct Part {
    req: RequestId,
    positions: Vec<usize>,
    op: PartOp,
}

enum PartOp {
    Read {
        source: ReadSource,
        vars: Vec<VarRef>,
    },
    Write(Vec<(VarRef, Value)>),
    WriteVqt(Vec<(VarRef, Vqt)>),
}

impl PartOp {
    fn is_write(&self) -> bool {
        !matches!(self, PartOp::Read { .. })
    }
    fn len(&self) -> usize {
        match self {
            PartOp::Read { vars, .. } => vars.len(),
            PartOp::Write(v) => v.len(),
            PartOp::WriteVqt(v) => v.len(),
        }
    }
}

enum LinkState {
    Connecting { deadline: Instant },
    Handshake { deadline: Instant },
    Up,
}

enum Pending {
    Hello,
    Subscribe,
    Unsubscribe,
    Part {
        req: RequestId,
        positions: Vec<usize>,
        write: bool,
    },
}

struct Outstanding {
    deadline: Instant,
    what: Pending,
}

struct Link {
    server: String,
    state: LinkState,
    outstanding: HashMap<u32, Outstanding>,
    next_wire: u32,
    ping: Option<(u64, Instant)>,
    next_ping: Instant,
}

impl Link {
    fn wire_id(&mut self) -> u32 {
        self.next_wire = self.next_wire.wrapping_add(1).max(1);
        self.next_wire
    }
}

enum Results {
    Read(Vec<Option<Result<Vqt, OpcError>>>),
    Write(Vec<Option<Result<(), OpcError>>>),
}

struct UserRequest {
    keys: Vec<ItemKey>,
    results: Results,
    remaining: usize,
}

/// The positions (in the user's request) and the items of one channel's part of a write.
type ChannelPart<T> = (Vec<usize>, Vec<(VarRef, T)>);

/// Byte budget of one request frame's payload (half the maximum frame, leaving room for
/// estimates that are slightly off).
const FRAME_BUDGET: usize = MAX_FRAME / 2;

/// The client state machine.
pub struct ClientCore {
    cfg: ClientConfig,
    items: HashMap<ItemKey, Item>,
    by_handle: HashMap<u32, ItemKey>,
    next_handle: u32,
    channels: HashMap<Arc<str>, Channel>,
    searches: HashMap<u32, Arc<str>>,
    next_search: u32,
    links: HashMap<LinkId, Link>,
    next_link: LinkId,
    requests: HashMap<RequestId, UserRequest>,
    retry_at: Option<Instant>,
    next_nonce: u64,
    actions: VecDeque<Action>,
}

fn code_to_error(hr: i32, fallback: OpcError) -> OpcError {
    OpcError::from_hresult(hr).unwrap_or(fallback)
}

fn estimate_var(v: &VarRef) -> usize {
    8 + v.channel.len() + v.variable.len()
}

fn estimate_value(v: &Value) -> usize {
    match v {
        Value::Bstr(s) => 4 + s.len(),
        Value::Array(a) => 8 + a.elements.iter().map(estimate_value).sum::<usize>(),
        _ => 12,
    }
}

impl ClientCore {
    pub fn new(cfg: ClientConfig) -> Self {
        if let ClientSecurity::Unconfigured(why) = &cfg.security {
            warn!(reason = %why, "asix client links to no server");
        }
        ClientCore {
            cfg,
            items: HashMap::new(),
            by_handle: HashMap::new(),
            next_handle: 0,
            channels: HashMap::new(),
            searches: HashMap::new(),
            next_search: 0,
            links: HashMap::new(),
            next_link: 0,
            requests: HashMap::new(),
            retry_at: None,
            next_nonce: 0,
            actions: VecDeque::new(),
        }
    }

    pub fn config(&self) -> &ClientConfig {
        &self.cfg
    }

    /// The next thing to do, if any.
    pub fn poll_action(&mut self) -> Option<Action> {
        self.actions.pop_front()
    }

    /// When [`handle_timeout`](Self::handle_timeout) must next be called.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let mut t: Option<Instant> = self.retry_at;
        let mut min = |x: Instant| t = Some(t.map_or(x, |y| y.min(x)));
        for ch in self.channels.values() {
            match &ch.state {
                ChanState::Searching {
                    search,
                    next_resend,
                    ..
                } => min(search.deadline().min(*next_resend)),
                ChanState::Backoff { until } => min(*until),
                _ => {}
            }
        }
        let net = self.cfg.options.net_timeout;
        for l in self.links.values() {
            match l.state {
                LinkState::Connecting { deadline } | LinkState::Handshake { deadline } => {
                    min(deadline)
                }
                LinkState::Up => match l.ping {
                    Some((_, sent)) => min(sent + net),
                    None => min(l.next_ping),
                },
            }
            if let Some(d) = l.outstanding.values().map(|o| o.deadline).min() {
                min(d);
            }
        }
        t
    }

    // ----- user requests -------------------------------------------------------------

    /// Subscribes items (or changes their sampling period). Values arrive as
    /// [`ClientEvent::Updates`]. Subscribing an item twice does not count: one unsubscribe
    /// removes it.
    pub fn subscribe(&mut self, now: Now, keys: Vec<ItemKey>, sampling_ms: u32) {
        let mut to_send: HashMap<Arc<str>, Vec<u32>> = HashMap::new();
        let mut comm_failed = Vec::new();
        for key in keys {
            if let Some(item) = self.items.get_mut(&key) {
                if item.sampling_ms != sampling_ms {
                    item.sampling_ms = sampling_ms;
                    if matches!(item.state, ItemState::Active | ItemState::Pending) {
                        to_send
                            .entry(key.channel.clone())
                            .or_default()
                            .push(item.handle);
                    }
                }
                continue;
            }
            let handle = self.alloc_handle();
            self.by_handle.insert(handle, key.clone());
            self.items.insert(
                key.clone(),
                Item {
                    handle,
                    sampling_ms,
                    last: None,
                    state: ItemState::Idle,
                    down: false,
                },
            );
            let ch = self.channel_mut(&key.channel);
            ch.items += 1;
            match ch.state {
                ChanState::Up { .. } => {
                    to_send.entry(key.channel.clone()).or_default().push(handle)
                }
                ChanState::Idle => self.start_search(now, &key.channel),
                ChanState::Backoff { .. } => comm_failed.push(key),
                _ => {}
            }
        }
        for (ch, handles) in to_send {
            self.send_subscribe(now, &ch, handles);
        }
        if !comm_failed.is_empty() {
            let ups = comm_failed
                .into_iter()
                .filter_map(|k| self.down_vqt(now, &k).map(|v| (k, v)))
                .collect();
            self.emit_updates(ups);
        }
    }

    /// Unsubscribes items (unknown keys are ignored).
    pub fn unsubscribe(&mut self, now: Now, keys: Vec<ItemKey>) {
        let mut to_send: HashMap<Arc<str>, Vec<u32>> = HashMap::new();
        for key in keys {
            let Some(item) = self.items.remove(&key) else {
                continue;
            };
            self.by_handle.remove(&item.handle);
            if let Some(ch) = self.channels.get_mut(&key.channel) {
                ch.items = ch.items.saturating_sub(1);
                if matches!(ch.state, ChanState::Up { .. })
                    && matches!(item.state, ItemState::Active | ItemState::Pending)
                {
                    to_send
                        .entry(key.channel.clone())
                        .or_default()
                        .push(item.handle);
                }
            }
        }
        for (ch, handles) in to_send {
            let Some(link) = self.link_of(&ch) else {
                continue;
            };
            for chunk in handles.chunks(FRAME_BUDGET / 4) {
                self.send_request(
                    now,
                    link,
                    Message::Unsubscribe {
                        handles: chunk.to_vec(),
                    },
                    Pending::Unsubscribe,
                );
            }
        }
    }

    /// Reads items from the server (`source`: its cache, the device value or through the
    /// driver). Completes with [`ClientEvent::ReadDone`]; may start a server search.
    pub fn read(&mut self, now: Now, id: RequestId, keys: Vec<ItemKey>, source: ReadSource) {
        let mut parts: BTreeMap<Arc<str>, (Vec<usize>, Vec<VarRef>)> = BTreeMap::new();
        for (i, k) in keys.iter().enumerate() {
            let e = parts.entry(k.channel.clone()).or_default();
            e.0.push(i);
            e.1.push(var_ref(k));
        }
        let n = keys.len();
        self.requests.insert(
            id,
            UserRequest {
                keys,
                results: Results::Read(vec![None; n]),
                remaining: n,
            },
        );
        for (ch, (positions, vars)) in parts {
            self.dispatch(
                now,
                &ch,
                Part {
                    req: id,
                    positions,
                    op: PartOp::Read { source, vars },
                },
            );
        }
        self.complete_if_done(id);
    }

    /// Writes values (asix stamps time and good quality). Completes with
    /// [`ClientEvent::WriteDone`].
    pub fn write(&mut self, now: Now, id: RequestId, items: Vec<(ItemKey, Value)>) {
        let mut parts: BTreeMap<Arc<str>, ChannelPart<Value>> = BTreeMap::new();
        let mut keys = Vec::with_capacity(items.len());
        for (i, (k, v)) in items.into_iter().enumerate() {
            let e = parts.entry(k.channel.clone()).or_default();
            e.0.push(i);
            e.1.push((var_ref(&k), v));
            keys.push(k);
        }
        self.start_write(
            now,
            id,
            keys,
            parts
                .into_iter()
                .map(|(c, (p, v))| (c, p, PartOp::Write(v)))
                .collect(),
        );
    }

    /// Extended write: value, quality and timestamp. Completes with [`ClientEvent::WriteDone`].
    pub fn write_vqt(&mut self, now: Now, id: RequestId, items: Vec<(ItemKey, Vqt)>) {
        let mut parts: BTreeMap<Arc<str>, ChannelPart<Vqt>> = BTreeMap::new();
        let mut keys = Vec::with_capacity(items.len());
        for (i, (k, v)) in items.into_iter().enumerate() {
            let e = parts.entry(k.channel.clone()).or_default();
            e.0.push(i);
            e.1.push((var_ref(&k), v));
            keys.push(k);
        }
        self.start_write(
            now,
            id,
            keys,
            parts
                .into_iter()
                .map(|(c, (p, v))| (c, p, PartOp::WriteVqt(v)))
                .collect(),
        );
    }

    fn start_write(
        &mut self,
        now: Now,
        id: RequestId,
        keys: Vec<ItemKey>,
        parts: Vec<(Arc<str>, Vec<usize>, PartOp)>,
    ) {
        let n = keys.len();
        self.requests.insert(
            id,
            UserRequest {
                keys,
                results: Results::Write(vec![None; n]),
                remaining: n,
            },
        );
        for (ch, positions, op) in parts {
            self.dispatch(
                now,
                &ch,
                Part {
                    req: id,
                    positions,
                    op,
                },
            );
        }
        self.complete_if_done(id);
    }

    /// Closes every link (with Bye); the shell may stop after draining the actions.
    pub fn shutdown(&mut self) {
        let ids: Vec<LinkId> = self.links.keys().copied().collect();
        for id in ids {
            if let Ok(bytes) = frame_bytes(0, &Message::Bye { reason: 0 }) {
                self.actions.push_back(Action::Send { link: id, bytes });
            }
            self.actions.push_back(Action::Close { link: id });
        }
        self.links.clear();
    }

    // ----- inputs from the shell ---------------------------------------------------

    /// An announcement arrived from `from`.
    pub fn handle_announce(&mut self, now: Now, ann: Announce, from: SocketAddr) {
        let Some(ch) = self.searches.get(&ann.request).cloned() else {
            return;
        };
        let Some(channel) = self.channels.get_mut(&ch) else {
            return;
        };
        let ChanState::Searching { id, search, .. } = &mut channel.state else {
            return;
        };
        if *id != ann.request {
            return;
        }
        debug!(channel = %ch, server = %ann.server_name, flags = ann.flags.0, clients = ann.clients, "announcement");
        if !self
            .cfg
            .security
            .accepts_announcement(ann.fingerprint.as_ref())
        {
            let fp = ann.fingerprint.as_ref().map(fingerprint_hex);
            let fp = fp.as_deref().unwrap_or("none (a plaintext-only server)");
            if search.first_unpinned() {
                warn!(channel = %ch, server = %ann.server_name, %from, fingerprint = fp, "announcement ignored: the server's certificate is not pinned for this channel");
            } else {
                debug!(channel = %ch, server = %ann.server_name, %from, fingerprint = fp, "announcement ignored: not pinned");
            }
            return;
        }
        if search.offer(ann, from) {
            self.finish_search(now, &ch);
        }
    }

    /// The TCP connection of `link` is open. Returns false when the link is no longer
    /// wanted (the shell then drops it).
    pub fn handle_connected(&mut self, now: Now, link: LinkId) -> bool {
        let Some(l) = self.links.get_mut(&link) else {
            return false;
        };
        if !matches!(l.state, LinkState::Connecting { .. }) {
            return false;
        }
        l.state = LinkState::Handshake {
            deadline: now.mono + self.cfg.options.net_timeout,
        };
        let hello = Message::Hello(Hello {
            client_name: self.cfg.client_name.clone(),
            client_host: self.cfg.client_host.clone(),
            keepalive_ms: self.cfg.keepalive.as_millis().min(u32::MAX as u128) as u32,
            net_timeout_ms: self
                .cfg
                .options
                .net_timeout
                .as_millis()
                .min(u32::MAX as u128) as u32,
        });
        self.send_request(now, link, hello, Pending::Hello);
        true
    }

    /// The link failed (connection refused, closed, unreadable).
    pub fn handle_link_failed(&mut self, now: Now, link: LinkId, error: OpcError) {
        let error = match self.links.get(&link).map(|l| &l.state) {
            None => return,
            Some(LinkState::Connecting { .. }) => OpcError::NetLinkToServer,
            Some(LinkState::Handshake { .. }) if error == OpcError::NetCloseLink => {
                OpcError::NetLinkToServer
            }
            Some(_) => error,
        };
        self.link_lost(now, link, error);
    }

    /// A frame arrived on `link`.
    pub fn handle_frame(&mut self, now: Now, link: LinkId, frame: Frame) {
        let Frame { request, msg } = frame;
        match msg {
            Message::Update { items } => self.on_update(link, items),
            Message::HelloAck(ack) => {
                let Some(l) = self.links.get_mut(&link) else {
                    return;
                };
                if l.outstanding.remove(&request).is_none()
                    || !matches!(l.state, LinkState::Handshake { .. })
                {
                    return;
                }
                if ack.status < 0 {
                    let e = code_to_error(ack.status, OpcError::NetLinkToServerNegativeAnswer);
                    warn!(server = %l.server, error = %e, "link refused");
                    self.link_lost(now, link, OpcError::NetLinkToServerNegativeAnswer);
                    return;
                }
                l.state = LinkState::Up;
                l.next_ping = now.mono + self.cfg.keepalive;
                l.server = ack.server_name.clone();
                let waiting: Vec<Arc<str>> = self
                    .channels
                    .values()
                    .filter(
                        |c| matches!(c.state, ChanState::Connecting { link: x, .. } if x == link),
                    )
                    .map(|c| c.name.clone())
                    .collect();
                for ch in waiting {
                    self.channel_up(now, &ch, link);
                }
            }
            Message::Ping { nonce } => {
                if let Ok(bytes) = frame_bytes(request, &Message::Pong { nonce }) {
                    self.actions.push_back(Action::Send { link, bytes });
                }
            }
            Message::Pong { nonce } => {
                if let Some(l) = self.links.get_mut(&link) {
                    if matches!(l.ping, Some((n, _)) if n == nonce) {
                        l.ping = None;
                        l.next_ping = now.mono + self.cfg.keepalive;
                    }
                }
            }
            Message::Bye { reason } => {
                debug!(link, reason, "server said bye");
                self.link_lost(now, link, OpcError::NetCloseLink);
            }
            Message::ServerStatus { flags, clients } => {
                if let Some(l) = self.links.get(&link) {
                    let server = l.server.clone();
                    self.actions
                        .push_back(Action::Event(ClientEvent::ServerStatus {
                            server,
                            flags,
                            clients,
                        }));
                }
            }
            Message::Error { code, message } => {
                warn!(link, code = format_args!("0x{:08X}", code as u32), %message, "server error");
                let Some(o) = self
                    .links
                    .get_mut(&link)
                    .and_then(|l| l.outstanding.remove(&request))
                else {
                    return;
                };
                match o.what {
                    Pending::Part {
                        req,
                        positions,
                        write,
                    } => {
                        let fallback = if write {
                            OpcError::WriteError
                        } else {
                            OpcError::Fail
                        };
                        let e = code_to_error(code, fallback);
                        for p in positions {
                            self.fill(req, p, Err(e));
                        }
                        self.complete_if_done(req);
                    }
                    Pending::Hello => {
                        self.link_lost(now, link, OpcError::NetLinkToServerNegativeAnswer)
                    }
                    Pending::Subscribe | Pending::Unsubscribe => {}
                }
            }
            Message::SubscribeAck { results } => {
                let known = self
                    .links
                    .get_mut(&link)
                    .and_then(|l| l.outstanding.remove(&request))
                    .is_some();
                if known {
                    self.on_subscribe_ack(now, link, results);
                }
            }
            Message::UnsubscribeAck { .. } => {
                if let Some(l) = self.links.get_mut(&link) {
                    l.outstanding.remove(&request);
                }
            }
            Message::ReadResult { results } => {
                let Some(o) = self
                    .links
                    .get_mut(&link)
                    .and_then(|l| l.outstanding.remove(&request))
                else {
                    return;
                };
                let Pending::Part { req, positions, .. } = o.what else {
                    return;
                };
                for (i, p) in positions.iter().enumerate() {
                    let r = match results.get(i) {
                        Some(Ok(v)) => Ok(v.clone()),
                        Some(Err(code)) => Err(code_to_error(*code, OpcError::Fail)),
                        None => Err(OpcError::Fail),
                    };
                    self.fill_read(req, *p, r);
                }
                self.complete_if_done(req);
            }
            Message::WriteResult { results } => {
                let Some(o) = self
                    .links
                    .get_mut(&link)
                    .and_then(|l| l.outstanding.remove(&request))
                else {
                    return;
                };
                let Pending::Part { req, positions, .. } = o.what else {
                    return;
                };
                for (i, p) in positions.iter().enumerate() {
                    let r = match results.get(i) {
                        Some(&code) if code >= 0 => Ok(()),
                        Some(&code) => Err(code_to_error(code, OpcError::WriteError)),
                        None => Err(OpcError::WriteError),
                    };
                    self.fill_write(req, *p, r);
                }
                self.complete_if_done(req);
            }
            other => debug!(link, ty = ?other.msg_type(), "unexpected message ignored"),
        }
    }

    /// Deadlines: discovery, connection, answers, keep-alive, retries.
    pub fn handle_timeout(&mut self, now: Now) {
        let t = now.mono;
        // Searches and back-off.
        enum Due {
            Finish,
            Resend(FindServer),
            Search,
        }
        let resend = self.cfg.discovery_resend;
        let mut due: Vec<(Arc<str>, Due)> = Vec::new();
        for (name, c) in self.channels.iter_mut() {
            match &mut c.state {
                ChanState::Searching {
                    search,
                    next_resend,
                    id,
                } => {
                    if t >= search.deadline() {
                        due.push((name.clone(), Due::Finish));
                    } else if t >= *next_resend {
                        *next_resend = t + resend;
                        let fs = FindServer {
                            request: *id,
                            resource: search.resource().clone(),
                            client_name: self.cfg.client_name.clone(),
                            client_host: self.cfg.client_host.clone(),
                        };
                        due.push((name.clone(), Due::Resend(fs)));
                    }
                }
                ChanState::Backoff { until } if t >= *until => {
                    if c.items > 0 || !c.queued.is_empty() {
                        due.push((name.clone(), Due::Search));
                    } else {
                        c.state = ChanState::Idle;
                    }
                }
                _ => {}
            }
        }
        for (ch, d) in due {
            match d {
                Due::Finish => self.finish_search(now, &ch),
                Due::Resend(fs) => self.actions.push_back(Action::SendFindServer(fs)),
                Due::Search => self.start_search(now, &ch),
            }
        }
        // Links.
        let net = self.cfg.options.net_timeout;
        let ids: Vec<LinkId> = self.links.keys().copied().collect();
        for id in ids {
            let Some(l) = self.links.get_mut(&id) else {
                continue;
            };
            let failure = match l.state {
                LinkState::Connecting { deadline } | LinkState::Handshake { deadline }
                    if t >= deadline =>
                {
                    Some(OpcError::NetLinkToServerTimeout)
                }
                LinkState::Up if l.outstanding.values().any(|o| t >= o.deadline) => {
                    Some(OpcError::NetAnswerTimeout)
                }
                LinkState::Up if matches!(l.ping, Some((_, sent)) if t >= sent + net) => {
                    Some(OpcError::NetAnswerTimeout)
                }
                _ => None,
            };
            if let Some(e) = failure {
                warn!(server = %l.server, error = %e, "link timed out");
                self.link_lost(now, id, e);
                continue;
            }
            if matches!(l.state, LinkState::Up) && l.ping.is_none() && t >= l.next_ping {
                self.next_nonce += 1;
                let nonce = self.next_nonce;
                l.ping = Some((nonce, t));
                if let Ok(bytes) = frame_bytes(0, &Message::Ping { nonce }) {
                    self.actions.push_back(Action::Send { link: id, bytes });
                }
            }
        }
        // Items a server refused.
        if self.retry_at.is_some_and(|r| t >= r) {
            self.retry_at = None;
            let mut again: HashMap<Arc<str>, Vec<u32>> = HashMap::new();
            for (k, item) in &self.items {
                if matches!(item.state, ItemState::Failed(_))
                    && matches!(
                        self.channels.get(&k.channel).map(|c| &c.state),
                        Some(ChanState::Up { .. })
                    )
                {
                    again
                        .entry(k.channel.clone())
                        .or_default()
                        .push(item.handle);
                }
            }
            for (ch, handles) in again {
                self.send_subscribe(now, &ch, handles);
            }
        }
    }

    // ----- internals -----------------------------------------------------------------

    fn alloc_handle(&mut self) -> u32 {
        loop {
            self.next_handle = self.next_handle.wrapping_add(1);
            if self.next_handle != 0 && !self.by_handle.contains_key(&self.next_handle) {
                return self.next_handle;
            }
        }
    }

    fn channel_mut(&mut self, name: &Arc<str>) -> &mut Channel {
        self.channels
            .entry(name.clone())
            .or_insert_with(|| Channel {
                name: name.clone(),
                state: ChanState::Idle,
                queued: Vec::new(),
                items: 0,
                down_reported: false,
            })
    }

    fn link_of(&self, ch: &str) -> Option<LinkId> {
        match self.channels.get(ch)?.state {
            ChanState::Up { link } => Some(link),
            _ => None,
        }
    }

    fn find_server(&self, id: u32, resource: Resource) -> FindServer {
        FindServer {
            request: id,
            resource,
            client_name: self.cfg.client_name.clone(),
            client_host: self.cfg.client_host.clone(),
        }
    }

    fn start_search(&mut self, now: Now, ch: &Arc<str>) {
        if matches!(self.cfg.security, ClientSecurity::Unconfigured(_)) {
            // Said once at start; nothing can be linked.
            self.channel_failed(now, ch, OpcError::NetLinkToServer);
            return;
        }
        self.next_search = self.next_search.wrapping_add(1).max(1);
        let id = self.next_search;
        let resource = Resource::channel(&**ch);
        let choice = self.cfg.choice_for(&resource);
        let o = &self.cfg.options;
        let search = Search::new(
            resource.clone(),
            choice,
            o.stop_after_first_server_found,
            now.mono,
            o.find_server_timeout,
        );
        let next_resend = now.mono + self.cfg.discovery_resend;
        let fs = self.find_server(id, resource);
        let c = self.channel_mut(ch);
        if let ChanState::Searching { id: old, .. } = c.state {
            self.searches.remove(&old);
        }
        let c = self.channel_mut(ch);
        c.state = ChanState::Searching {
            id,
            search,
            next_resend,
        };
        self.searches.insert(id, ch.clone());
        debug!(channel = %ch, id, "searching for a server");
        self.actions.push_back(Action::SendFindServer(fs));
    }

    fn finish_search(&mut self, now: Now, ch: &Arc<str>) {
        let Some(c) = self.channels.get_mut(ch) else {
            return;
        };
        let state = std::mem::replace(&mut c.state, ChanState::Idle);
        let ChanState::Searching { id, search, .. } = state else {
            c.state = state;
            return;
        };
        self.searches.remove(&id);
        let candidates = search.finish();
        if candidates.is_empty() {
            self.channel_failed(now, ch, OpcError::NetFindServerNotFound);
        } else {
            self.connect_candidates(now, ch, candidates);
        }
    }

    fn connect_candidates(&mut self, now: Now, ch: &Arc<str>, mut candidates: Vec<Candidate>) {
        if candidates.is_empty() {
            self.channel_failed(now, ch, OpcError::NetLinkToServer);
            return;
        }
        let first = candidates.remove(0);
        let existing = self
            .links
            .iter()
            .find(|(_, l)| l.server.eq_ignore_ascii_case(first.name()))
            .map(|(id, l)| (*id, matches!(l.state, LinkState::Up)));
        match existing {
            Some((link, true)) => self.channel_up(now, ch, link),
            Some((link, false)) => {
                self.channel_mut(ch).state = ChanState::Connecting {
                    link,
                    rest: candidates,
                };
            }
            None => {
                self.next_link += 1;
                let link = self.next_link;
                self.links.insert(
                    link,
                    Link {
                        server: first.name().to_owned(),
                        state: LinkState::Connecting {
                            deadline: now.mono + self.cfg.options.net_timeout,
                        },
                        outstanding: HashMap::new(),
                        next_wire: 0,
                        ping: None,
                        next_ping: now.mono,
                    },
                );
                debug!(channel = %ch, server = %first.name(), addr = %first.addr, "connecting");
                self.actions.push_back(Action::Connect {
                    link,
                    addr: first.addr,
                    fingerprint: first.announce.fingerprint,
                });
                self.channel_mut(ch).state = ChanState::Connecting {
                    link,
                    rest: candidates,
                };
            }
        }
    }

    fn channel_up(&mut self, now: Now, ch: &Arc<str>, link: LinkId) {
        let server = self
            .links
            .get(&link)
            .map(|l| l.server.clone())
            .unwrap_or_default();
        let c = self.channel_mut(ch);
        c.state = ChanState::Up { link };
        c.down_reported = false;
        let queued = std::mem::take(&mut c.queued);
        debug!(channel = %ch, %server, "channel up");
        self.actions
            .push_back(Action::Event(ClientEvent::ChannelUp {
                channel: ch.clone(),
                server,
            }));
        let handles: Vec<u32> = self
            .items
            .iter()
            .filter(|(k, _)| &k.channel == ch)
            .map(|(_, i)| i.handle)
            .collect();
        self.send_subscribe(now, ch, handles);
        for part in queued {
            self.send_part(now, link, part);
        }
    }

    /// No server this round: fail waiting requests, report the items, back off.
    fn channel_failed(&mut self, now: Now, ch: &Arc<str>, error: OpcError) {
        let reconnect = self.cfg.reconnect_interval;
        let c = self.channel_mut(ch);
        let queued = std::mem::take(&mut c.queued);
        c.state = if c.items > 0 {
            ChanState::Backoff {
                until: now.mono + reconnect,
            }
        } else {
            ChanState::Idle
        };
        let report = !c.down_reported;
        c.down_reported = true;
        for part in queued {
            let e = if part.op.is_write() && error == OpcError::NetFindServerNotFound {
                OpcError::WriteErrorNetworkServerNotFound
            } else {
                error
            };
            self.fail_part(part.req, &part.positions, e);
        }
        if report {
            warn!(channel = %ch, %error, "channel has no server");
            self.actions
                .push_back(Action::Event(ClientEvent::ChannelDown {
                    channel: ch.clone(),
                    error,
                }));
        }
        self.mark_down(now, ch);
    }

    fn link_lost(&mut self, now: Now, link: LinkId, error: OpcError) {
        let Some(l) = self.links.remove(&link) else {
            return;
        };
        self.actions.push_back(Action::Close { link });
        for (_, o) in l.outstanding {
            if let Pending::Part { req, positions, .. } = o.what {
                self.fail_part(req, &positions, error);
            }
        }
        let affected: Vec<Arc<str>> = self
            .channels
            .values()
            .filter(|c| matches!(c.state, ChanState::Up { link: x } | ChanState::Connecting { link: x, .. } if x == link))
            .map(|c| c.name.clone())
            .collect();
        for ch in affected {
            let Some(c) = self.channels.get_mut(&ch) else {
                continue;
            };
            match std::mem::replace(&mut c.state, ChanState::Idle) {
                ChanState::Connecting { rest, .. } => self.connect_candidates(now, &ch, rest),
                ChanState::Up { .. } => {
                    c.down_reported = true;
                    warn!(channel = %ch, server = %l.server, %error, "link lost; looking for a server again");
                    self.actions
                        .push_back(Action::Event(ClientEvent::ChannelDown {
                            channel: ch.clone(),
                            error,
                        }));
                    self.mark_down(now, &ch);
                    if c_items(&self.channels, &ch) > 0 {
                        self.start_search(now, &ch);
                    }
                }
                other => c.state = other,
            }
        }
    }

    /// Every item of the channel goes back to Idle and, once, reports its down quality.
    fn mark_down(&mut self, now: Now, ch: &Arc<str>) {
        let keys: Vec<ItemKey> = self
            .items
            .keys()
            .filter(|k| &k.channel == ch)
            .cloned()
            .collect();
        let mut ups = Vec::new();
        for k in keys {
            if let Some(item) = self.items.get_mut(&k) {
                if matches!(item.state, ItemState::Active | ItemState::Pending) {
                    item.state = ItemState::Idle;
                }
            }
            if let Some(v) = self.down_vqt(now, &k) {
                ups.push((k, v));
            }
        }
        self.emit_updates(ups);
    }

    /// The down VQT of an item not yet reported down (and marks it reported).
    fn down_vqt(&mut self, now: Now, k: &ItemKey) -> Option<Vqt> {
        let item = self.items.get_mut(k)?;
        if item.down {
            return None;
        }
        item.down = true;
        Some(match &item.last {
            Some(last) => Vqt::new(
                last.value.clone(),
                Quality::BAD_LAST_KNOWN_VALUE,
                last.timestamp,
            ),
            None => Vqt::new(Value::Empty, Quality::BAD_COMM_FAILURE, now.wall),
        })
    }

    fn emit_updates(&mut self, ups: Vec<(ItemKey, Vqt)>) {
        if !ups.is_empty() {
            self.actions
                .push_back(Action::Event(ClientEvent::Updates(ups)));
        }
    }

    fn send_request(&mut self, now: Now, link: LinkId, msg: Message, what: Pending) {
        let deadline = now.mono + self.cfg.options.net_timeout;
        let Some(l) = self.links.get_mut(&link) else {
            return;
        };
        let wire = l.wire_id();
        match frame_bytes(wire, &msg) {
            Ok(bytes) => {
                l.outstanding.insert(wire, Outstanding { deadline, what });
                self.actions.push_back(Action::Send { link, bytes });
            }
            Err(e) => {
                warn!(error = %e, "request not encodable");
                if let Pending::Part {
                    req,
                    positions,
                    write,
                } = what
                {
                    let err = if write {
                        OpcError::WriteError
                    } else {
                        OpcError::Fail
                    };
                    self.fail_part(req, &positions, err);
                }
            }
        }
    }

    fn send_subscribe(&mut self, now: Now, ch: &Arc<str>, handles: Vec<u32>) {
        let Some(link) = self.link_of(ch) else { return };
        let mut by_rate: BTreeMap<u32, Vec<SubscribeItem>> = BTreeMap::new();
        for h in handles {
            let Some(key) = self.by_handle.get(&h) else {
                continue;
            };
            let Some(item) = self.items.get_mut(key) else {
                continue;
            };
            item.state = ItemState::Pending;
            by_rate
                .entry(item.sampling_ms)
                .or_default()
                .push(SubscribeItem {
                    handle: h,
                    var: var_ref(key),
                });
        }
        let changes_only = self.cfg.changes_only;
        for (sampling_ms, items) in by_rate {
            let mut batch = Vec::new();
            let mut size = 0;
            for it in items {
                size += 4 + estimate_var(&it.var);
                batch.push(it);
                if size >= FRAME_BUDGET {
                    let items = std::mem::take(&mut batch);
                    self.send_request(
                        now,
                        link,
                        Message::Subscribe {
                            sampling_ms,
                            changes_only,
                            items,
                        },
                        Pending::Subscribe,
                    );
                    size = 0;
                }
            }
            if !batch.is_empty() {
                self.send_request(
                    now,
                    link,
                    Message::Subscribe {
                        sampling_ms,
                        changes_only,
                        items: batch,
                    },
                    Pending::Subscribe,
                );
            }
        }
    }

    fn dispatch(&mut self, now: Now, ch: &Arc<str>, part: Part) {
        if let Some(link) = self.link_of(ch) {
            self.send_part(now, link, part);
            return;
        }
        let c = self.channel_mut(ch);
        c.queued.push(part);
        if matches!(c.state, ChanState::Idle | ChanState::Backoff { .. }) {
            self.start_search(now, ch);
        }
    }

    /// Sends a part, split into frames of bounded size.
    fn send_part(&mut self, now: Now, link: LinkId, part: Part) {
        let Part { req, positions, op } = part;
        let write = op.is_write();
        let n = op.len();
        let mut start = 0;
        while start < n {
            let mut end = start;
            let mut size = 0;
            while end < n && (end == start || size < FRAME_BUDGET) {
                size += match &op {
                    PartOp::Read { vars, .. } => estimate_var(&vars[end]),
                    PartOp::Write(v) => estimate_var(&v[end].0) + estimate_value(&v[end].1),
                    PartOp::WriteVqt(v) => {
                        estimate_var(&v[end].0) + 10 + estimate_value(&v[end].1.value)
                    }
                };
                end += 1;
            }
            let msg = match &op {
                PartOp::Read { source, vars } => Message::Read {
                    source: *source,
                    items: vars[start..end].to_vec(),
                },
                PartOp::Write(v) => Message::Write {
                    items: v[start..end].to_vec(),
                },
                PartOp::WriteVqt(v) => Message::WriteVqt {
                    items: v[start..end].to_vec(),
                },
            };
            let what = Pending::Part {
                req,
                positions: positions[start..end].to_vec(),
                write,
            };
            self.send_request(now, link, msg, what);
            start = end;
        }
    }

    fn on_update(&mut self, link: LinkId, entries: Vec<(u32, Vqt)>) {
        let mut ups = Vec::with_capacity(entries.len());
        for (h, vqt) in entries {
            let Some(key) = self.by_handle.get(&h) else {
                continue;
            };
            let Some(item) = self.items.get_mut(key) else {
                continue;
            };
            // Ignore stragglers from a link the channel no longer uses.
            match self.channels.get(&key.channel).map(|c| &c.state) {
                Some(ChanState::Up { link: l }) if *l == link => {}
                _ => continue,
            }
            item.down = false;
            if vqt.value != Value::Empty {
                item.last = Some(vqt.clone());
            }
            ups.push((key.clone(), vqt));
        }
        self.emit_updates(ups);
    }

    fn on_subscribe_ack(&mut self, now: Now, link: LinkId, results: Vec<(u32, i32)>) {
        let mut ups = Vec::new();
        for (h, code) in results {
            let Some(key) = self.by_handle.get(&h).cloned() else {
                continue;
            };
            if !matches!(self.channels.get(&key.channel).map(|c| &c.state), Some(ChanState::Up { link: l }) if *l == link)
            {
                continue;
            }
            let Some(item) = self.items.get_mut(&key) else {
                continue;
            };
            if code >= 0 {
                if item.state == ItemState::Pending {
                    item.state = ItemState::Active;
                }
                continue;
            }
            let error = code_to_error(code, OpcError::Fail);
            let first = item.state != ItemState::Failed(error);
            item.state = ItemState::Failed(error);
            if first {
                item.down = false;
                ups.push((
                    key.clone(),
                    Vqt::new(Value::Empty, Quality::BAD_CONFIG_ERROR, now.wall),
                ));
                self.actions
                    .push_back(Action::Event(ClientEvent::ItemFailed { key, error }));
            }
            if self.retry_at.is_none() {
                self.retry_at = Some(now.mono + self.cfg.retry_failed_items);
            }
        }
        self.emit_updates(ups);
    }

    fn fail_part(&mut self, req: RequestId, positions: &[usize], e: OpcError) {
        for &p in positions {
            self.fill(req, p, Err(e));
        }
        self.complete_if_done(req);
    }

    fn fill(&mut self, req: RequestId, pos: usize, r: Result<(), OpcError>) {
        match self
            .requests
            .get(&req)
            .map(|u| matches!(u.results, Results::Read(_)))
        {
            Some(true) => self.fill_read(req, pos, r.map(|()| Vqt::default())),
            Some(false) => self.fill_write(req, pos, r),
            None => {}
        }
    }

    fn fill_read(&mut self, req: RequestId, pos: usize, r: Result<Vqt, OpcError>) {
        let Some(u) = self.requests.get_mut(&req) else {
            return;
        };
        if let Results::Read(v) = &mut u.results {
            if let Some(slot @ None) = v.get_mut(pos) {
                *slot = Some(r);
                u.remaining -= 1;
            }
        }
    }

    fn fill_write(&mut self, req: RequestId, pos: usize, r: Result<(), OpcError>) {
        let Some(u) = self.requests.get_mut(&req) else {
            return;
        };
        if let Results::Write(v) = &mut u.results {
            if let Some(slot @ None) = v.get_mut(pos) {
                *slot = Some(r);
                u.remaining -= 1;
            }
        }
    }

    fn complete_if_done(&mut self, req: RequestId) {
        if self.requests.get(&req).is_none_or(|u| u.remaining > 0) {
            return;
        }
        let Some(u) = self.requests.remove(&req) else {
            return;
        };
        let ev = match u.results {
            Results::Read(v) => ClientEvent::ReadDone {
                id: req,
                results: u
                    .keys
                    .into_iter()
                    .zip(v)
                    .map(|(k, r)| (k, r.unwrap_or(Err(OpcError::Fail))))
                    .collect(),
            },
            Results::Write(v) => ClientEvent::WriteDone {
                id: req,
                results: u
                    .keys
                    .into_iter()
                    .zip(v)
                    .map(|(k, r)| (k, r.unwrap_or(Err(OpcError::WriteError))))
                    .collect(),
            },
        };
        self.actions.push_back(Action::Event(ev));
    }
}

fn c_items(channels: &HashMap<Arc<str>, Channel>, ch: &str) -> usize {
    channels.get(ch).map_or(0, |c| c.items)
}

fn frame_bytes(request: u32, msg: &Message) -> Result<Vec<u8>, crate::proto::EncodeError> {
    let mut out = Vec::new();
    encode_frame(&mut out, request, msg)?;
    Ok(out)
}

#[cfg(test)]
mod tests;
