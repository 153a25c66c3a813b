//! The asix network client as the engine's data source ([`ctopc_core::source::Backend`]):
//! [`NetSource`], the network as a raw [`VariableSource`], under the one asix adapter
//! ([`AsixBackend`], which holds the fan-out, rates, quality rules, derivations, write
//! checks and request bookkeeping; see [`crate::backend`]).
//!
//! One [`AsixClient`] per AsixConnect channel (the OPC access path, `SourceItem::channel`),
//! configured from that channel's options; a variable is an asix variable ([`ItemKey`]:
//! asix channel + variable) on the client of a channel ([`NetVar`]), and a device request
//! is spread over the clients of its items' channels.
//!
//! Never blocks: requests go to the clients' queues; the clients' events come back through a
//! channel and a [`Wake`], and [`Backend::poll`] drains them.

use std::collections::{BTreeMap, HashMap};
use std::sync::mpsc;
use std::sync::Arc;

use asix_model::namespace::AsixNamespace;
use asix_model::{ServerOptions, ServerSelection};
use ctopc_core::diagnostics::{ChannelStatus, LinkState};
use ctopc_core::model::datasource::ItemVqt;
use ctopc_core::source::{Backend, Wake};
use ctopc_core::{OpcError, Quality, Timestamp, VarType};
use tokio::runtime::{Handle, Runtime};
use tracing::{info, warn};

use crate::backend::{AsixBackend, RawId, RawOutput, VariableSource};
use crate::client::{AsixClient, ClientEvent, RequestId};
use crate::config::{security_from_options, ClientConfig, ConnectOptions, ExternalServerLists};
use crate::naming::asix_client_name;
use crate::proto::frame::ReadSource;
use crate::proto::DEFAULT_DISCOVERY_PORT;
use crate::rest::{RestLink, RestSettings};
use crate::Vqt;
use asix_model::ItemKey;

pub use crate::pipeline::{limit_variables, CHANNEL_ATTRIBUTE};

/// What the network source needs to know of the configuration: the namespace source items
/// are resolved through, and each channel's client settings.
pub trait Resolver: Send {
    /// The asix namespace (item IDs, databases, the channels' quality rules).
    fn namespace(&self) -> Arc<AsixNamespace>;
    /// The client configuration for an AsixConnect channel.
    fn client_config(&self, channel: &str) -> ClientConfig;
    /// The REST link settings of a channel that reads from Asix.Evo REST servers
    /// (`AsixEvoRest`); `None`: the channel uses the asix network.
    fn rest_settings(&self, _channel: &str) -> Option<RestSettings> {
        None
    }
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

/// The asix namespace of a configuration with the client settings of its channels (items
/// resolve through the pipeline, [`crate::pipeline::resolve`]: descriptive IDs carry their
/// channel, database variables take it from the `Channel` attribute, empty when there is
/// none: the server then finds the variable by name).
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
    fn namespace(&self) -> Arc<AsixNamespace> {
        Arc::clone(&self.ns)
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
            // A channel that says nothing of its links keeps the base's setting (in the
            // server, none: such a channel links to no server).
            let says = o.asix_net_plaintext
                || o.asix_net_cert_file.is_some()
                || o.asix_net_key_file.is_some()
                || o.asix_net_ca_file.is_some()
                || !o.asix_net_server_fingerprints.is_empty();
            if says {
                c.security = security_from_options(rc.name, o, |p| cfg.resolve_path(p));
            }
        }
        c
    }

    fn rest_settings(&self, channel: &str) -> Option<RestSettings> {
        let cfg = self.ns.config();
        let rc = cfg.resolve_channel(channel).ok()?;
        crate::rest::settings_from_options(
            rc.name,
            rc.options,
            cfg.server.source_timeout_ms,
            std::time::Duration::from_millis(u64::from(cfg.server.reconnect_interval_ms.max(100))),
        )
    }
}

/// An asix variable on the client of an AsixConnect channel: the network's handle of a
/// variable.
pub type NetVar = (Arc<str>, ItemKey);

/// The asix network data source: the one asix adapter over the network clients.
pub type AsixSource<R> = AsixBackend<NetSource<R>>;

impl<R: Resolver> AsixBackend<NetSource<R>> {
    /// `rt` runs the clients; `wake` is called (from the clients' task) when events arrive.
    pub fn new(resolver: R, rt: Handle, wake: Arc<dyn Wake>) -> Self {
        let ns = resolver.namespace();
        AsixBackend::from_source(ns, NetSource::new(resolver, rt, wake))
    }

    /// As [`AsixSource::new`] with a runtime of its own (one worker thread), for callers
    /// without tokio (the COM driver thread).
    pub fn with_own_runtime(resolver: R, wake: Arc<dyn Wake>) -> std::io::Result<Self> {
        let ns = resolver.namespace();
        Ok(AsixBackend::from_source(
            ns,
            NetSource::with_own_runtime(resolver, wake)?,
        ))
    }
}

/// How an AsixConnect channel reaches its data: the asix network, or Asix.Evo REST
/// servers.
enum Link {
    Asix(AsixClient),
    Rest(RestLink),
}

/// The warning of a refused write to a channel that reads from Asix.Evo REST servers.
const REST_READ_ONLY: &str = "write refused (OPC_E_BADRIGHTS): the items of a channel that reads from Asix.Evo REST servers are read-only, because the Asix.Evo REST API documents no write request";

/// The asix network as a raw variable source: one [`AsixClient`] per AsixConnect channel
/// (started when first used), variables as [`NetVar`]s, device requests in one part per
/// channel.
pub struct NetSource<R: Resolver> {
    resolver: R,
    rt: Handle,
    /// The runtime when the source owns one ([`NetSource::with_own_runtime`]).
    own_rt: Option<Runtime>,
    wake: Arc<dyn Wake>,
    /// The namespace (the canonical types of REST variables).
    ns: Arc<AsixNamespace>,
    clients: HashMap<Arc<str>, Link>,
    tx: mpsc::Sender<(Arc<str>, ClientEvent)>,
    rx: mpsc::Receiver<(Arc<str>, ClientEvent)>,
    /// (client channel, client request) -> raw request.
    parts: HashMap<(Arc<str>, RequestId), RawId>,
    /// Answers made without a client (it could not start).
    ready: RawOutput<NetVar>,
    /// Each asix channel's link as its client reported it, and whether it was ever
    /// linked (the next link is then a failover), for the `_Diagnostics` branch.
    links: HashMap<Arc<str>, (ChannelStatus, bool)>,
}

/// At most this many client events are taken in one `poll` (the rest wake it again).
const POLL_BATCH: usize = 4096;

impl<R: Resolver> NetSource<R> {
    /// `rt` runs the clients; `wake` is called (from the clients' task) when events arrive.
    pub fn new(resolver: R, rt: Handle, wake: Arc<dyn Wake>) -> Self {
        let (tx, rx) = mpsc::channel();
        NetSource {
            ns: resolver.namespace(),
            resolver,
            rt,
            own_rt: None,
            wake,
            clients: HashMap::new(),
            tx,
            rx,
            parts: HashMap::new(),
            ready: RawOutput::default(),
            links: HashMap::new(),
        }
    }

    /// As [`NetSource::new`] with a runtime of its own (one worker thread).
    pub fn with_own_runtime(resolver: R, wake: Arc<dyn Wake>) -> std::io::Result<Self> {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("asix-net")
            .enable_all()
            .build()?;
        let mut s = NetSource::new(resolver, rt.handle().clone(), wake);
        s.own_rt = Some(rt);
        Ok(s)
    }

    fn client(&mut self, channel: &Arc<str>) -> Option<&Link> {
        if !self.clients.contains_key(channel) {
            let tx = self.tx.clone();
            let wake = self.wake.clone();
            let ch = channel.clone();
            let sink = move |ev: ClientEvent| {
                let _ = tx.send((ch.clone(), ev));
                wake.wake();
            };
            let link = match self.resolver.rest_settings(channel) {
                Some(s) => {
                    let stations = s.core.stations.join(", ");
                    RestLink::start(s, sink, &self.rt)
                        .map(|l| {
                            info!(channel = %channel, %stations, "Asix.Evo REST link started; the channel's items are read-only (the Asix.Evo REST API documents no write request)");
                            Link::Rest(l)
                        })
                        .map_err(|e| e.to_string())
                }
                None => AsixClient::start(self.resolver.client_config(channel), sink, &self.rt)
                    .map(|c| {
                        info!(channel = %channel, "asix client started");
                        Link::Asix(c)
                    })
                    .map_err(|e| e.to_string()),
            };
            match link {
                Ok(l) => {
                    self.clients.insert(channel.clone(), l);
                }
                Err(e) => {
                    warn!(channel = %channel, error = %e, "asix client cannot start");
                    return None;
                }
            }
        }
        self.clients.get(channel)
    }

    /// The canonical type of a variable of a REST channel (EMPTY, as answered, when the
    /// channel's database does not know it).
    fn var_type(&self, channel: &str, key: &ItemKey) -> VarType {
        self.ns
            .database(channel)
            .and_then(|db| {
                db.find_real_index(&key.variable)
                    .map(|i| db.variables.view(i).data_type())
            })
            .unwrap_or(VarType::EMPTY)
    }

    /// Does the channel read from Asix.Evo REST servers?
    fn is_rest(&self, channel: &str) -> bool {
        match self.clients.get(channel) {
            Some(l) => matches!(l, Link::Rest(_)),
            None => self.resolver.rest_settings(channel).is_some(),
        }
    }

    fn event(&mut self, channel: Arc<str>, ev: ClientEvent, out: &mut RawOutput<NetVar>) {
        match ev {
            ClientEvent::Updates(ups) => {
                out.samples.extend(
                    ups.into_iter()
                        .map(|(key, vqt)| ((channel.clone(), key), vqt)),
                );
            }
            ClientEvent::ReadDone { id, results } => {
                if let Some(raw) = self.parts.remove(&(channel, id)) {
                    out.reads
                        .push((raw, results.into_iter().map(|(_, r)| r).collect()));
                }
            }
            ClientEvent::WriteDone { id, results } => {
                if let Some(raw) = self.parts.remove(&(channel, id)) {
                    out.writes
                        .push((raw, results.into_iter().map(|(_, r)| r).collect()));
                }
            }
            ClientEvent::ChannelUp { channel: c, server } => {
                info!(%channel, asix_channel = %c, %server, "linked");
                let (s, ever) = self.link(&c);
                s.failovers += u64::from(*ever);
                *ever = true;
                s.link = LinkState::Up;
                s.server = server;
            }
            ClientEvent::ChannelDown { channel: c, error } => {
                warn!(%channel, asix_channel = %c, %error, "no link");
                let (s, _) = self.link(&c);
                s.link = LinkState::Down;
                s.server.clear();
                s.last_error = error.to_string();
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

impl<R: Resolver> NetSource<R> {
    fn link(&mut self, channel: &Arc<str>) -> &mut (ChannelStatus, bool) {
        self.links.entry(channel.clone()).or_insert_with(|| {
            (
                ChannelStatus {
                    name: channel.to_string(),
                    ..ChannelStatus::default()
                },
                false,
            )
        })
    }
}

impl<R: Resolver> Drop for NetSource<R> {
    fn drop(&mut self) {
        // Clients first (they ask their tasks to close the links), then the runtime, without
        // blocking the dropping thread.
        self.clients.clear();
        if let Some(rt) = self.own_rt.take() {
            rt.shutdown_background();
        }
    }
}

impl<R: Resolver> VariableSource for NetSource<R> {
    type Var = NetVar;
    type Part = Arc<str>;

    /// Any asix variable may exist somewhere on the network: the server answers for it.
    fn lookup(&self, channel: &Arc<str>, key: &ItemKey) -> Option<NetVar> {
        Some((channel.clone(), key.clone()))
    }

    fn part(&self, var: &NetVar) -> Arc<str> {
        var.0.clone()
    }

    /// Every asix channel (the channel a server serves, of the item IDs) that a client
    /// reported on or that has subscribed variables: its link as last reported (no link
    /// until the first report), its subscribed variables.
    fn channels(&self, subscribed: &mut dyn Iterator<Item = &NetVar>) -> Vec<ChannelStatus> {
        let mut counts: BTreeMap<&str, u64> = BTreeMap::new();
        for (channel, key) in subscribed {
            // A REST link reports under its AsixConnect channel, an asix client under
            // the asix channels of its variables.
            let name = match self.clients.get(channel) {
                Some(Link::Rest(_)) => &**channel,
                _ => &*key.channel,
            };
            *counts.entry(name).or_default() += 1;
        }
        for c in self.links.keys() {
            counts.entry(c).or_default();
        }
        counts
            .into_iter()
            .map(|(c, n)| {
                let mut s =
                    self.links
                        .get(c)
                        .map(|l| l.0.clone())
                        .unwrap_or_else(|| ChannelStatus {
                            name: c.to_owned(),
                            ..ChannelStatus::default()
                        });
                s.subscriptions = n;
                s
            })
            .collect()
    }

    fn subscribe(&mut self, _now: Timestamp, vars: Vec<(NetVar, u32)>) {
        let mut by: BTreeMap<(Arc<str>, u32), Vec<ItemKey>> = BTreeMap::new();
        for ((channel, key), rate) in vars {
            by.entry((channel, rate)).or_default().push(key);
        }
        for ((channel, rate), keys) in by {
            let typed: Vec<(ItemKey, VarType)> = if self.is_rest(&channel) {
                keys.into_iter()
                    .map(|k| {
                        let t = self.var_type(&channel, &k);
                        (k, t)
                    })
                    .collect()
            } else {
                keys.into_iter().map(|k| (k, VarType::EMPTY)).collect()
            };
            match self.client(&channel) {
                Some(Link::Asix(c)) => {
                    c.subscribe(typed.into_iter().map(|(k, _)| k).collect(), rate)
                }
                Some(Link::Rest(l)) => l.subscribe(typed, rate),
                None => {}
            }
        }
    }

    fn unsubscribe(&mut self, _now: Timestamp, vars: Vec<NetVar>) {
        let mut by: BTreeMap<Arc<str>, Vec<ItemKey>> = BTreeMap::new();
        for (channel, key) in vars {
            by.entry(channel).or_default().push(key);
        }
        for (channel, keys) in by {
            match self.clients.get(&channel) {
                Some(Link::Asix(c)) => c.unsubscribe(keys),
                Some(Link::Rest(l)) => l.unsubscribe(keys),
                None => {}
            }
        }
    }

    fn read(&mut self, _now: Timestamp, id: RawId, vars: Vec<NetVar>) {
        let Some(channel) = vars.first().map(|v| v.0.clone()) else {
            self.ready.reads.push((id, Vec::new()));
            return;
        };
        let n = vars.len();
        let rest = self.is_rest(&channel);
        let keys: Vec<(ItemKey, VarType)> = vars
            .into_iter()
            .map(|(_, k)| {
                let t = if rest {
                    self.var_type(&channel, &k)
                } else {
                    VarType::EMPTY
                };
                (k, t)
            })
            .collect();
        let rid = match self.client(&channel) {
            Some(Link::Asix(c)) => c.read(
                keys.into_iter().map(|(k, _)| k).collect(),
                ReadSource::Device,
            ),
            Some(Link::Rest(l)) => l.read(keys),
            None => {
                self.ready.reads.push((id, vec![Err(OpcError::NetInit); n]));
                return;
            }
        };
        self.parts.insert((channel, rid), id);
    }

    fn write(&mut self, now: Timestamp, id: RawId, items: Vec<(NetVar, ItemVqt)>) {
        let Some(channel) = items.first().map(|(v, _)| v.0.clone()) else {
            self.ready.writes.push((id, Vec::new()));
            return;
        };
        let n = items.len();
        let simple = items
            .iter()
            .all(|(_, v)| v.quality.is_none() && v.timestamp.is_none());
        let c = match self.client(&channel) {
            Some(Link::Asix(c)) => c,
            Some(Link::Rest(_)) => {
                warn!(%channel, items = n, "{REST_READ_ONLY}");
                self.ready
                    .writes
                    .push((id, vec![Err(OpcError::BadRights); n]));
                return;
            }
            None => {
                let e = Err(OpcError::WriteErrorNetworkServerNotFound);
                self.ready.writes.push((id, vec![e; n]));
                return;
            }
        };
        let rid = if simple {
            c.write(items.into_iter().map(|((_, k), v)| (k, v.value)).collect())
        } else {
            // Extended write: what the client left out is good quality, now.
            c.write_vqt(
                items
                    .into_iter()
                    .map(|((_, k), v)| {
                        let vqt = Vqt::new(
                            v.value,
                            v.quality.unwrap_or(Quality::GOOD),
                            v.timestamp.unwrap_or(now),
                        );
                        (k, vqt)
                    })
                    .collect(),
            )
        };
        self.parts.insert((channel, rid), id);
    }

    fn poll(&mut self, _now: Timestamp, out: &mut RawOutput<NetVar>) {
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
        out.reads.append(&mut self.ready.reads);
        out.writes.append(&mut self.ready.writes);
        if more {
            self.wake.wake();
        }
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        if self.ready.is_empty() {
            None
        } else {
            Some(Timestamp(0))
        }
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
