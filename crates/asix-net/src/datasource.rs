//! The asix network client as the engine's data source ([`ctopc_core::source::Backend`]).
//!
//! One [`AsixClient`] per AsixConnect channel (the OPC access path, `SourceItem::channel`),
//! configured from that channel's options; a source item maps to an asix variable
//! ([`ItemKey`]: asix channel + variable) plus a [`Derivation`] (value, formatted, percent,
//! bars) applied to every sample. Several source items may share one asix variable: it is
//! subscribed once, at the fastest rate asked for, and its samples fan out. The variables an
//! item's quality rules read (its control variable, limits held in variables) are
//! subscribed with it on the same client, without being items themselves, and let go with
//! the last item needing them.
//!
//! Never blocks: requests go to the clients' queues; the clients' events come back through a
//! channel and a [`Wake`], and [`Backend::poll`] drains them.

use std::collections::{btree_map, BTreeMap, HashMap};
use std::sync::mpsc;
use std::sync::Arc;

use asix_model::namespace::AsixNamespace;
use asix_model::{ServerOptions, ServerSelection};
use ctopc_core::model::datasource::{ItemVqt, SourceItem, SourceKey, SourceReqId, SourceRequest};
use ctopc_core::source::{Backend, SourceOutput, Wake};
use ctopc_core::{OpcError, Quality, Timestamp, Value};
use tokio::runtime::{Handle, Runtime};
use tracing::{info, warn};

use crate::client::{AsixClient, ClientEvent, ItemKey, RequestId};
use crate::config::{ClientConfig, ConnectOptions, ExternalServerLists};
use crate::naming::asix_client_name;
use crate::pipeline::Resolution;
use crate::proto::frame::ReadSource;
use crate::proto::DEFAULT_DISCOVERY_PORT;
use crate::Vqt;

/// What a source item is on the asix network: the pipeline's resolution with asix
/// variables ([`ItemKey`]s) as handles.
pub type Resolved = crate::pipeline::Resolved<ItemKey>;

pub use crate::pipeline::{limit_variables, CHANNEL_ATTRIBUTE};

/// Maps source items onto the asix network.
pub trait Resolver: Send {
    /// The asix variable behind a source item; `None`: not an asix item (reported
    /// ASKOM_E_ItemUnknown).
    fn resolve(&self, item: &SourceItem) -> Option<Resolved>;
    /// The client configuration for an AsixConnect channel.
    fn client_config(&self, channel: &str) -> ClientConfig;
}

/// The client configuration the `[Server]` options of `ASIXConnect.ini` give: `ClientName`
/// (else the computer name plus a dot), discovery to `BroadcastAddress` (default
/// 255.255.255.255) and the local server on `DiscoveryPort` (default 48100), and
/// `ReconnectInterval` as the retry period of refused subscriptions. (`DataPort` is the
/// gateway's listening port; the client learns it from the announcements.)
pub fn client_config_from_server_options(
    opts: &ServerOptions,
    computer_name: &str,
) -> ClientConfig {
    let name = match opts.client_name.as_deref().map(str::trim) {
        Some(n) if !n.is_empty() => n.to_owned(),
        _ => asix_client_name(None, computer_name),
    };
    let mut c = ClientConfig::new(name, computer_name);
    let port = opts.discovery_port.unwrap_or(DEFAULT_DISCOVERY_PORT);
    let broadcast = opts
        .broadcast_address
        .as_deref()
        .and_then(|a| a.trim().parse::<std::net::IpAddr>().ok())
        .unwrap_or(std::net::IpAddr::V4(std::net::Ipv4Addr::BROADCAST));
    c.discovery_targets = vec![
        std::net::SocketAddr::new(broadcast, port),
        std::net::SocketAddr::new(std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST), port),
    ];
    c.retry_failed_items =
        std::time::Duration::from_millis(u64::from(opts.reconnect_interval_ms.max(100)));
    c
}

/// Resolves through the asix namespace of the core: descriptive IDs carry their channel,
/// database variables take it from the `Channel` attribute (empty when there is none: the
/// server then finds the variable by name).
pub struct NamespaceResolver {
    ns: Arc<AsixNamespace>,
    /// Client name, host, discovery targets and timings; the discovery options come from
    /// each channel, the external server lists from the configuration (replacing the
    /// base's).
    base: ClientConfig,
}

impl NamespaceResolver {
    pub fn new(ns: Arc<AsixNamespace>, base: ClientConfig) -> Self {
        NamespaceResolver { ns, base }
    }
}

impl Resolver for NamespaceResolver {
    fn resolve(&self, item: &SourceItem) -> Option<Resolved> {
        // Any asix variable may exist somewhere on the network: the server answers for it.
        match crate::pipeline::resolve(&self.ns, item, |k| Some(k.clone())) {
            Resolution::Resolved(r) => Some(r),
            Resolution::NotLive | Resolution::NoVariable(_) => None,
        }
    }

    fn client_config(&self, channel: &str) -> ClientConfig {
        let mut c = self.base.clone();
        let cfg = self.ns.config();
        c.external = ExternalServerLists::from_config(cfg);
        if let Ok(rc) = cfg.resolve_channel(channel) {
            let o = rc.options;
            c.options = ConnectOptions {
                asix_server_name: match cfg.current_data_servers(rc.name) {
                    ServerSelection::Any => String::new(),
                    ServerSelection::Local => "LOCAL".into(),
                    ServerSelection::Named(v) => v.join(","),
                },
                stop_after_first_server_found: o.stop_after_first_server_found,
                find_server_timeout: std::time::Duration::from_millis(u64::from(
                    o.find_server_timeout_ms,
                )),
                net_timeout: std::time::Duration::from_millis(u64::from(o.net_timeout_ms)),
            };
        }
        c
    }
}

/// An asix variable on the client of an AsixConnect channel.
type Fan = (Arc<str>, ItemKey);

/// The asix variables a request touched, each with the rate it was subscribed at before
/// the request (`None`: not subscribed).
type Touched = BTreeMap<Fan, Option<u32>>;

struct Mapped {
    channel: Arc<str>,
    /// Resolved once, when subscribed; reads and writes of the item reuse it.
    r: Arc<Resolved>,
    rate: u32,
}

impl Mapped {
    fn key(&self) -> &ItemKey {
        &self.r.key
    }
}

enum Kind {
    Read,
    Write,
}

/// One device request of the engine, possibly spread over several clients.
struct Pending {
    kind: Kind,
    results: Vec<Option<Result<Vqt, OpcError>>>,
    resolved: Vec<Option<Arc<Resolved>>>,
    remaining: usize,
}

/// The asix network data source.
pub struct AsixSource<R: Resolver> {
    resolver: R,
    rt: Handle,
    /// The runtime when the source owns one ([`AsixSource::with_own_runtime`]).
    own_rt: Option<Runtime>,
    wake: Arc<dyn Wake>,
    clients: HashMap<Arc<str>, AsixClient>,
    tx: mpsc::Sender<(Arc<str>, ClientEvent)>,
    rx: mpsc::Receiver<(Arc<str>, ClientEvent)>,
    items: HashMap<SourceKey, Mapped>,
    /// The items reading each asix variable.
    fanout: HashMap<Fan, Vec<SourceKey>>,
    /// Variables subscribed for the quality rules of items (control and limit variables):
    /// the items whose rules read each (an item once per variable). They are not items
    /// themselves unless they are also in `fanout`.
    rule_vars: HashMap<Fan, Vec<SourceKey>>,
    /// The last VQT of every subscribed variable: the values the quality rules read, and
    /// the items' samples their qualities are computed again from when a control or limit
    /// variable changes.
    last: HashMap<Fan, Vqt>,
    /// (client channel, client request) -> (engine request, positions in it).
    parts: HashMap<(Arc<str>, RequestId), (SourceReqId, Vec<usize>)>,
    pending: HashMap<SourceReqId, Pending>,
    /// Reads: the AsixConnect channel of each position (for the quality rules).
    read_channels: HashMap<SourceReqId, HashMap<usize, Arc<str>>>,
    ready_reads: Vec<(SourceReqId, Vec<Result<Vqt, OpcError>>)>,
    ready_writes: Vec<(SourceReqId, Vec<Result<(), OpcError>>)>,
}

/// At most this many client events are taken in one `poll` (the rest wake it again).
const POLL_BATCH: usize = 4096;

impl<R: Resolver> AsixSource<R> {
    /// `rt` runs the clients; `wake` is called (from the clients' task) when events arrive.
    pub fn new(resolver: R, rt: Handle, wake: Arc<dyn Wake>) -> Self {
        let (tx, rx) = mpsc::channel();
        AsixSource {
            resolver,
            rt,
            own_rt: None,
            wake,
            clients: HashMap::new(),
            tx,
            rx,
            items: HashMap::new(),
            fanout: HashMap::new(),
            rule_vars: HashMap::new(),
            last: HashMap::new(),
            parts: HashMap::new(),
            pending: HashMap::new(),
            read_channels: HashMap::new(),
            ready_reads: Vec::new(),
            ready_writes: Vec::new(),
        }
    }

    /// As [`AsixSource::new`] with a runtime of its own (one worker thread), for callers
    /// without tokio (the COM driver thread).
    pub fn with_own_runtime(resolver: R, wake: Arc<dyn Wake>) -> std::io::Result<Self> {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("asix-net")
            .enable_all()
            .build()?;
        let mut s = AsixSource::new(resolver, rt.handle().clone(), wake);
        s.own_rt = Some(rt);
        Ok(s)
    }

    fn client(&mut self, channel: &Arc<str>) -> Option<&AsixClient> {
        if !self.clients.contains_key(channel) {
            let cfg = self.resolver.client_config(channel);
            let tx = self.tx.clone();
            let wake = self.wake.clone();
            let ch = channel.clone();
            let sink = move |ev: ClientEvent| {
                let _ = tx.send((ch.clone(), ev));
                wake.wake();
            };
            match AsixClient::start(cfg, sink, &self.rt) {
                Ok(c) => {
                    info!(channel = %channel, "asix client started");
                    self.clients.insert(channel.clone(), c);
                }
                Err(e) => {
                    warn!(channel = %channel, error = %e, "asix client cannot start");
                    return None;
                }
            }
        }
        self.clients.get(channel)
    }

    /// The rate an asix variable is subscribed at: the fastest any source item reading it,
    /// or whose quality rules read it, asks for; `None` when nothing wants it.
    fn rate_of(&self, fan: &Fan) -> Option<u32> {
        let items = self.fanout.get(fan).into_iter().flatten();
        let rules = self.rule_vars.get(fan).into_iter().flatten();
        items
            .chain(rules)
            .filter_map(|k| self.items.get(k))
            .map(|m| m.rate)
            .min()
    }

    /// Is the asix variable wanted by an item or by the quality rules of one?
    fn wanted(&self, fan: &Fan) -> bool {
        self.fanout.contains_key(fan) || self.rule_vars.contains_key(fan)
    }

    /// Notes the current rate of a variable a request is about to change (once: the first
    /// note of a request is the state before it).
    fn touch(&self, touched: &mut Touched, fan: Fan) {
        if let btree_map::Entry::Vacant(e) = touched.entry(fan) {
            let rate = self.rate_of(e.key());
            e.insert(rate);
        }
    }

    /// [`Self::touch`] for an item's variable and its rule variables.
    fn touch_item(&self, touched: &mut Touched, m: &Mapped) {
        self.touch(touched, (m.channel.clone(), m.key().clone()));
        for k in m.r.rule_variables() {
            self.touch(touched, (m.channel.clone(), k.clone()));
        }
    }

    /// Brings the clients in line with the variables a request touched: unsubscribes those
    /// nothing wants any more (forgetting their last values), subscribes those newly wanted
    /// or wanted at another rate. Done once per request, from the state before and after
    /// it, so that a variable let go and taken again in one request (an item subscribed
    /// again, a limit variable passed from one item to another) is never unsubscribed, and
    /// the rate asked for is the final one.
    fn apply_touched(&mut self, touched: Touched) {
        let mut gone: BTreeMap<Arc<str>, Vec<ItemKey>> = BTreeMap::new();
        let mut wanted: BTreeMap<(Arc<str>, u32), Vec<ItemKey>> = BTreeMap::new();
        for (fan, before) in touched {
            match self.rate_of(&fan) {
                None => {
                    self.last.remove(&fan);
                    if before.is_some() {
                        gone.entry(fan.0).or_default().push(fan.1);
                    }
                }
                Some(after) if before != Some(after) => {
                    wanted.entry((fan.0, after)).or_default().push(fan.1)
                }
                Some(_) => {}
            }
        }
        for (channel, keys) in gone {
            if let Some(c) = self.clients.get(&channel) {
                c.unsubscribe(keys);
            }
        }
        for ((channel, rate), keys) in wanted {
            if let Some(c) = self.client(&channel) {
                c.subscribe(keys, rate);
            }
        }
    }

    fn subscribe(&mut self, subs: Vec<(SourceItem, u32)>) {
        let mut touched = Touched::new();
        for (item, rate) in subs {
            let Some(r) = self.resolver.resolve(&item).map(Arc::new) else {
                warn!(item = %item.item_id, "not an asix item");
                continue;
            };
            let m = Mapped {
                channel: item.channel.clone(),
                r,
                rate,
            };
            if let Some(old) = self.items.get(&item.key) {
                self.touch_item(&mut touched, old);
            }
            self.touch_item(&mut touched, &m);
            let fan = (m.channel.clone(), m.key().clone());
            let rule_fans: Vec<Fan> =
                m.r.rule_variables()
                    .into_iter()
                    .map(|k| (m.channel.clone(), k.clone()))
                    .collect();
            // The new mapping first, then the old one is let go: what both need stays.
            let old = self.items.insert(item.key, m);
            let keys = self.fanout.entry(fan.clone()).or_default();
            if !keys.contains(&item.key) {
                keys.push(item.key);
            }
            for f in rule_fans {
                self.rule_vars.entry(f).or_default().push(item.key);
            }
            if let Some(old) = old {
                self.release(item.key, &old, Some(&fan));
            }
        }
        self.apply_touched(touched);
    }

    /// Takes item `k`, mapped as `m`, out of the fan-out of its variable (unless that is
    /// `keep`, the variable it reads now) and out of the users of its rule variables.
    fn release(&mut self, k: SourceKey, m: &Mapped, keep: Option<&Fan>) {
        let fan = (m.channel.clone(), m.key().clone());
        if keep != Some(&fan) {
            if let Some(list) = self.fanout.get_mut(&fan) {
                list.retain(|x| *x != k);
                if list.is_empty() {
                    self.fanout.remove(&fan);
                }
            }
        }
        for c in m.r.rule_variables() {
            let f = (m.channel.clone(), c.clone());
            let Some(list) = self.rule_vars.get_mut(&f) else {
                continue;
            };
            // One use less (the item may be listed twice while it is subscribed again).
            if let Some(i) = list.iter().position(|x| *x == k) {
                list.swap_remove(i);
            }
            if list.is_empty() {
                self.rule_vars.remove(&f);
            }
        }
    }

    fn set_rates(&mut self, rates: Vec<(SourceKey, u32)>) {
        let mut touched = Touched::new();
        for (k, rate) in rates {
            let Some(m) = self.items.get(&k) else {
                continue;
            };
            self.touch_item(&mut touched, m);
            if let Some(m) = self.items.get_mut(&k) {
                m.rate = rate;
            }
        }
        self.apply_touched(touched);
    }

    fn unsubscribe(&mut self, keys: Vec<SourceKey>) {
        let mut touched = Touched::new();
        for k in keys {
            let Some(m) = self.items.get(&k) else {
                continue;
            };
            self.touch_item(&mut touched, m);
            if let Some(m) = self.items.remove(&k) {
                self.release(k, &m, None);
            }
        }
        self.apply_touched(touched);
    }

    fn start_request(&mut self, req_id: SourceReqId, kind: Kind, n: usize) {
        self.pending.insert(
            req_id,
            Pending {
                kind,
                results: vec![None; n],
                resolved: vec![None; n],
                remaining: n,
            },
        );
    }

    fn fill(&mut self, req_id: SourceReqId, pos: usize, r: Result<Vqt, OpcError>) {
        let Some(p) = self.pending.get_mut(&req_id) else {
            return;
        };
        if let Some(slot @ None) = p.results.get_mut(pos) {
            *slot = Some(r);
            p.remaining -= 1;
        }
    }

    fn finish_if_done(&mut self, req_id: SourceReqId, channels: &HashMap<usize, Arc<str>>) {
        if self.pending.get(&req_id).is_none_or(|p| p.remaining > 0) {
            return;
        }
        let Some(p) = self.pending.remove(&req_id) else {
            return;
        };
        match p.kind {
            Kind::Read => {
                let results = p
                    .results
                    .into_iter()
                    .zip(p.resolved)
                    .enumerate()
                    .map(|(i, (r, res))| {
                        let r = r.unwrap_or(Err(OpcError::Fail))?;
                        Ok(match (res, channels.get(&i)) {
                            (Some(res), Some(ch)) => self.item_vqt(ch, &res, r),
                            _ => r,
                        })
                    })
                    .collect();
                self.ready_reads.push((req_id, results));
            }
            Kind::Write => {
                let results = p
                    .results
                    .into_iter()
                    .map(|r| r.unwrap_or(Err(OpcError::Fail)).map(|_| ()))
                    .collect();
                self.ready_writes.push((req_id, results));
            }
        }
    }

    /// The last VQT of a variable of an AsixConnect channel's client.
    fn last_of(&self, channel: &Arc<str>, k: &ItemKey) -> Option<&Vqt> {
        self.last.get(&(channel.clone(), k.clone()))
    }

    /// An item's VQT from its variable's: the pipeline's quality rules and derivation
    /// ([`Resolved::sample`]).
    ///
    /// The rules read the last values of the item's control and limit variables, known
    /// while some subscribed item needs them (a read of an item nothing subscribes finds
    /// them unknown).
    fn item_vqt(&self, channel: &Arc<str>, r: &Resolved, v: Vqt) -> Vqt {
        r.sample(v, |k| self.last_of(channel, k).cloned())
    }

    /// A subscribed item's VQT from the last sample of its variable; `None` before one.
    fn current_vqt(&self, k: SourceKey) -> Option<Vqt> {
        let m = self.items.get(&k)?;
        let raw = self.last_of(&m.channel, m.key())?;
        Some(self.item_vqt(&m.channel, &m.r, raw.clone()))
    }

    /// A new sample of a subscribed variable: fanned out to the items reading it, kept, and,
    /// when it changes a control or limit variable, the items whose rules read it are
    /// reported again if their quality changes. (Their next sample would use the new value
    /// anyway, but an item sampled seldom, or only on changes, would keep showing a limit
    /// state that no longer holds.) Such a report keeps the item's value and takes the
    /// later of the two timestamps, the time the quality became what it is.
    fn update(&mut self, fan: Fan, vqt: Vqt, out: &mut SourceOutput) {
        if !self.wanted(&fan) {
            // A late sample of a variable let go.
            return;
        }
        if let Some(list) = self.fanout.get(&fan) {
            for sk in list {
                let Some(m) = self.items.get(sk) else {
                    continue;
                };
                out.updates
                    .push((*sk, self.item_vqt(&fan.0, &m.r, vqt.clone())));
            }
        }
        // Only a new value or quality of a rule variable can change the rules' outcome.
        let same = |l: &Vqt| l.value == vqt.value && l.quality == vqt.quality;
        let users = match self.rule_vars.get(&fan) {
            Some(users) if !self.last.get(&fan).is_some_and(same) => users.clone(),
            _ => Vec::new(),
        };
        let before: Vec<(SourceKey, Quality)> = users
            .into_iter()
            .filter_map(|k| Some((k, self.current_vqt(k)?.quality)))
            .collect();
        let at = vqt.timestamp;
        self.last.insert(fan, vqt);
        for (k, q) in before {
            if let Some(mut v) = self.current_vqt(k) {
                if v.quality != q {
                    v.timestamp = v.timestamp.max(at);
                    out.updates.push((k, v));
                }
            }
        }
    }

    /// A source item's resolution: the one made when it was subscribed (the same key, so
    /// the same item of the same generation), else resolved now (an item read or written
    /// while nothing subscribes it).
    fn resolved(&self, item: &SourceItem) -> Option<Arc<Resolved>> {
        match self.items.get(&item.key) {
            Some(m) if m.channel == item.channel => Some(Arc::clone(&m.r)),
            _ => self.resolver.resolve(item).map(Arc::new),
        }
    }

    fn read(&mut self, req_id: SourceReqId, items: Vec<SourceItem>) {
        self.start_request(req_id, Kind::Read, items.len());
        let mut by_channel: BTreeMap<Arc<str>, (Vec<usize>, Vec<ItemKey>)> = BTreeMap::new();
        for (i, item) in items.iter().enumerate() {
            match self.resolved(item) {
                Some(r) => {
                    let e = by_channel.entry(item.channel.clone()).or_default();
                    e.0.push(i);
                    e.1.push(r.key.clone());
                    if let Some(p) = self.pending.get_mut(&req_id) {
                        p.resolved[i] = Some(r);
                    }
                }
                None => self.fill(req_id, i, Err(OpcError::ItemUnknown)),
            }
        }
        let channels: HashMap<usize, Arc<str>> = by_channel
            .iter()
            .flat_map(|(c, (pos, _))| pos.iter().map(move |p| (*p, c.clone())))
            .collect();
        self.read_channels.insert(req_id, channels);
        for (channel, (positions, keys)) in by_channel {
            match self.client(&channel) {
                Some(c) => {
                    let id = c.read(keys, ReadSource::Device);
                    self.parts.insert((channel, id), (req_id, positions));
                }
                None => {
                    for p in positions {
                        self.fill(req_id, p, Err(OpcError::NetInit));
                    }
                }
            }
        }
        self.finish(req_id);
    }

    fn finish(&mut self, req_id: SourceReqId) {
        if self.pending.get(&req_id).is_some_and(|p| p.remaining == 0) {
            let channels = self.read_channels.remove(&req_id).unwrap_or_default();
            self.finish_if_done(req_id, &channels);
        }
    }

    fn write(&mut self, req_id: SourceReqId, items: Vec<(SourceItem, ItemVqt)>, now: Timestamp) {
        self.start_request(req_id, Kind::Write, items.len());
        type Parts = (
            Vec<usize>,
            Vec<(ItemKey, Value)>,
            Vec<usize>,
            Vec<(ItemKey, Vqt)>,
        );
        let mut by_channel: BTreeMap<Arc<str>, Parts> = BTreeMap::new();
        for (i, (item, v)) in items.into_iter().enumerate() {
            let Some(r) = self.resolved(&item) else {
                self.fill(req_id, i, Err(OpcError::ItemUnknown));
                continue;
            };
            // Derived items (formatted, percent, bars) cannot be written; values must be
            // integers or reals; read-only variables are refused here already.
            if let Err(e) = r.check_write(&v.value) {
                self.fill(req_id, i, Err(e));
                continue;
            }
            let e = by_channel.entry(item.channel.clone()).or_default();
            if v.quality.is_none() && v.timestamp.is_none() {
                e.0.push(i);
                e.1.push((r.key.clone(), v.value));
            } else {
                // Extended write: what the client left out is good quality, now.
                e.2.push(i);
                let vqt = Vqt::new(
                    v.value,
                    v.quality.unwrap_or(Quality::GOOD),
                    v.timestamp.unwrap_or(now),
                );
                e.3.push((r.key.clone(), vqt));
            }
        }
        for (channel, (pos_simple, simple, pos_ext, ext)) in by_channel {
            let Some(c) = self.client(&channel) else {
                for p in pos_simple.into_iter().chain(pos_ext) {
                    self.fill(req_id, p, Err(OpcError::WriteErrorNetworkServerNotFound));
                }
                continue;
            };
            let mut ids = Vec::new();
            if !simple.is_empty() {
                ids.push((c.write(simple), pos_simple));
            }
            if !ext.is_empty() {
                ids.push((c.write_vqt(ext), pos_ext));
            }
            for (id, positions) in ids {
                self.parts
                    .insert((channel.clone(), id), (req_id, positions));
            }
        }
        self.finish(req_id);
    }

    fn event(&mut self, channel: Arc<str>, ev: ClientEvent, out: &mut SourceOutput) {
        match ev {
            ClientEvent::Updates(ups) => {
                for (key, vqt) in ups {
                    self.update((channel.clone(), key), vqt, out);
                }
            }
            ClientEvent::ReadDone { id, results } => {
                let Some((req, positions)) = self.parts.remove(&(channel, id)) else {
                    return;
                };
                for (p, (_, r)) in positions.into_iter().zip(results) {
                    self.fill(req, p, r);
                }
                self.finish(req);
            }
            ClientEvent::WriteDone { id, results } => {
                let Some((req, positions)) = self.parts.remove(&(channel, id)) else {
                    return;
                };
                for (p, (_, r)) in positions.into_iter().zip(results) {
                    self.fill(req, p, r.map(|()| Vqt::default()));
                }
                self.finish(req);
            }
            ClientEvent::ChannelUp { channel: c, server } => {
                info!(%channel, asix_channel = %c, %server, "linked")
            }
            ClientEvent::ChannelDown { channel: c, error } => {
                warn!(%channel, asix_channel = %c, %error, "no link")
            }
            ClientEvent::ItemFailed { key, error } => {
                warn!(%channel, item = %key, %error, "item refused")
            }
            ClientEvent::ServerStatus {
                server,
                flags,
                clients,
            } => {
                info!(%channel, %server, flags = flags.0, clients, "server status")
            }
        }
    }
}

impl<R: Resolver> Drop for AsixSource<R> {
    fn drop(&mut self) {
        // Clients first (they ask their tasks to close the links), then the runtime, without
        // blocking the dropping thread.
        self.clients.clear();
        if let Some(rt) = self.own_rt.take() {
            rt.shutdown_background();
        }
    }
}

impl<R: Resolver> Backend for AsixSource<R> {
    fn request(&mut self, now: Timestamp, req: SourceRequest) {
        match req {
            SourceRequest::Subscribe(subs) => self.subscribe(
                subs.into_iter()
                    .map(|s| (s.item, s.sampling_rate_ms))
                    .collect(),
            ),
            SourceRequest::SetSamplingRate(rates) => self.set_rates(rates),
            SourceRequest::Unsubscribe(keys) => self.unsubscribe(keys),
            SourceRequest::Read { req_id, items } => self.read(req_id, items),
            SourceRequest::Write { req_id, items } => {
                let items = items
                    .into_iter()
                    .map(|(i, v)| (i, ItemVqt::value(v)))
                    .collect();
                self.write(req_id, items, now)
            }
            SourceRequest::WriteVqt { req_id, items } => self.write(req_id, items, now),
        }
    }

    fn poll(&mut self, _now: Timestamp, out: &mut SourceOutput) {
        let mut more = false;
        for i in 0..=POLL_BATCH {
            match self.rx.try_recv() {
                Ok((ch, ev)) if i < POLL_BATCH => self.event(ch, ev, out),
                Ok((ch, ev)) => {
                    self.event(ch, ev, out);
                    more = true;
                }
                Err(_) => break,
            }
        }
        out.read_results.append(&mut self.ready_reads);
        out.write_results.append(&mut self.ready_writes);
        if more {
            self.wake.wake();
        }
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        None
    }
}

/// The asix network backend for a loaded namespace, ready for the server's driver loop:
/// client settings from the `[Server]` options ([`client_config_from_server_options`]) and
/// this computer's name, per-channel discovery options from the channels, the external
/// server lists of `ASIXConnect.ini` ([`ExternalServerLists::from_config`]), and a tokio
/// runtime of its own. Callable from any thread (no tokio context needed).
pub fn network_backend(
    ns: Arc<AsixNamespace>,
    wake: Arc<dyn Wake>,
) -> std::io::Result<Box<dyn Backend>> {
    let base =
        client_config_from_server_options(&ns.config().server, &crate::naming::computer_name());
    let source = AsixSource::with_own_runtime(NamespaceResolver::new(ns, base), wake)?;
    Ok(Box::new(source))
}
