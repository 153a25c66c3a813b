//! The `_Diagnostics` branch of the address space: items any OPC client
//! can browse, read and subscribe that show what the server is doing. Pure: the model of
//! the branch (its names, types, descriptions), the values of one counters snapshot, and
//! the wrappers that put the branch beside the real address space.
//!
//! ```text
//! _Diagnostics.Server.Uptime              I4   s     seconds since the server started
//! _Diagnostics.Server.Clients ... .PendingTransactions
//! _Diagnostics.Clients.<client>.Name ... .Failures        one branch per connected client
//! _Diagnostics.Channels.<channel>.LinkState ... .Subscriptions   one branch per channel
//! ```
//!
//! Data flow: the runtime (COM layer) takes a [`Input`] of the counters at most once per
//! second (the engine's statistics under the lock it holds anyway for its step, the
//! `crate::metrics` atomics, the callback watches, the data source's
//! [`Backend::channels`](crate::source::Backend::channels)); [`Sampler::sample`] turns it
//! into a [`Snapshot`] (rates per second over the interval since the last one, the client
//! branch names, the small browse tree of the branch, rebuilt only when a branch comes or
//! goes) and publishes it on the [`Board`]. Readers then take an `Arc` of the snapshot:
//! - [`DiagNamespace`] wraps the real namespace: `_Diagnostics.*` IDs resolve to read-only
//!   items with their properties, anything else goes to the real namespace unchanged (one
//!   prefix comparison);
//! - [`backend::DiagBackend`] wraps the real backend: reads and subscriptions of
//!   `_Diagnostics.*` items are answered from the snapshot (subscriptions get a sample per
//!   snapshot), everything else passes through. It keeps its own `Arc` of the snapshot and
//!   looks at the board only when its generation changed, so the driver's step (and the
//!   OnDataChange path behind it) takes no lock it did not take before;
//! - [`browse`] puts the branch into every browse path (IOPCBrowseServerAddressSpace and
//!   IOPCBrowse) beside the real [`AddressSpace`].
//!
//! Names: a client's branch is the name it gave with `IOPCCommon::SetClientName`, with `.`
//! and control characters replaced by `_` (a branch name is one segment of the item ID);
//! a client without a name is `Client<session>`; names that two connected clients share
//! get `#<session>` appended, each of them. A channel's branch is its asix channel name
//! made safe the same way.

pub mod backend;
pub mod browse;

use std::collections::HashSet;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock};

use crate::browse::{AddressSpace, MatchCase, NodeId};
use crate::namespace::{EuInfo, ItemDef, Namespace, PropertyAttributes, OPC_READABLE};
use crate::{Lang, OpcError, OpcResult, Timestamp, Value, VarType};

/// The branch's name under the root, and the first segment of its item IDs.
pub const ROOT: &str = "_Diagnostics";
const SERVER: &str = "Server";
const CLIENTS: &str = "Clients";
const CHANNELS: &str = "Channels";

/// How often the runtime takes a snapshot, ms (the values' update rate).
pub const SNAPSHOT_PERIOD_MS: u64 = 1000;

/// True for `_Diagnostics` and every ID below it.
pub fn is_diagnostic_id(item_id: &str) -> bool {
    item_id
        .strip_prefix(ROOT)
        .is_some_and(|r| r.is_empty() || r.starts_with('.'))
}

/// One item of the branch: its name (last segment), canonical type, descriptions, units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Field {
    pub name: &'static str,
    pub canonical_type: VarType,
    pub description_pl: &'static str,
    pub description_en: &'static str,
    pub eu_units: Option<&'static str>,
    /// OPC_ENUMERATED texts of the values 0.. (empty: no EU type).
    pub enumerated: &'static [&'static str],
}

const fn field(
    name: &'static str,
    canonical_type: VarType,
    description_pl: &'static str,
    description_en: &'static str,
    eu_units: Option<&'static str>,
) -> Field {
    Field {
        name,
        canonical_type,
        description_pl,
        description_en,
        eu_units,
        enumerated: &[],
    }
}

/// The items of `_Diagnostics.Server`, in this order (the indexes of [`Snapshot::value`]).
pub const SERVER_FIELDS: [Field; 9] = [
    field(
        "Uptime",
        VarType::I4,
        "Czas pracy serwera od startu",
        "Time since the server started",
        Some("s"),
    ),
    field(
        "Clients",
        VarType::I4,
        "Liczba podłączonych klientów",
        "Connected clients",
        None,
    ),
    field(
        "Groups",
        VarType::I4,
        "Liczba grup wszystkich klientów",
        "Groups of all clients",
        None,
    ),
    field(
        "Items",
        VarType::I4,
        "Liczba elementów we wszystkich grupach",
        "Items in all groups",
        None,
    ),
    field(
        "CallbacksPerSecond",
        VarType::R8,
        "Wywołania zwrotne na sekundę (średnia z ostatniego okresu)",
        "Callbacks per second (average over the last period)",
        Some("1/s"),
    ),
    field(
        "ValuesPerSecond",
        VarType::R8,
        "Wartości wysłane klientom na sekundę (średnia z ostatniego okresu)",
        "Values sent to clients per second (average over the last period)",
        Some("1/s"),
    ),
    field(
        "FailedCallbacks",
        VarType::I4,
        "Nieudane wywołania zwrotne od startu (błąd, przekroczony CallbackTimeout, odmowa)",
        "Callbacks failed since the start (error, over CallbackTimeout, refused)",
        None,
    ),
    field(
        "DroppedSinks",
        VarType::I4,
        "Odłączone połączenia zwrotne od startu (klient zniknął lub za dużo błędów)",
        "Callback connections dropped since the start (client gone or too many failures)",
        None,
    ),
    field(
        "PendingTransactions",
        VarType::I4,
        "Oczekujące transakcje (odczyty i zapisy asynchroniczne, odświeżenia)",
        "Pending transactions (asynchronous reads and writes, refreshes)",
        None,
    ),
];

/// The items of `_Diagnostics.Clients.<client>`.
pub const CLIENT_FIELDS: [Field; 7] = [
    field(
        "Name",
        VarType::BSTR,
        "Nazwa klienta (IOPCCommon::SetClientName, pusta gdy nie podana)",
        "The client's name (IOPCCommon::SetClientName, empty when not given)",
        None,
    ),
    field(
        "Groups",
        VarType::I4,
        "Liczba grup klienta",
        "The client's groups",
        None,
    ),
    field(
        "Items",
        VarType::I4,
        "Liczba elementów w grupach klienta",
        "Items in the client's groups",
        None,
    ),
    field(
        "LastCallbackLatency",
        VarType::R8,
        "Czas trwania ostatniego wywołania zwrotnego klienta (-1: jeszcze żadnego)",
        "Duration of the client's last callback (-1: none yet)",
        Some("ms"),
    ),
    field(
        "CallbacksPending",
        VarType::I4,
        "Wywołania zwrotne czekające w kolejce klienta",
        "Callbacks waiting in the client's queue",
        None,
    ),
    field(
        "Failures",
        VarType::I4,
        "Nieudane wywołania zwrotne klienta od podłączenia",
        "The client's failed callbacks since it connected",
        None,
    ),
    field(
        "Identity",
        VarType::BSTR,
        "Kim jest klient według kontekstu bezpieczeństwa wywołania (user:DOMENA\\nazwa; unknown (powód), gdy platforma nie wie)",
        "Who the client is by the call's security context (user:DOMAIN\\name; unknown (reason) when the platform cannot tell)",
        None,
    ),
];

/// The values of `_Diagnostics.Channels.<channel>.LinkState`.
pub const LINK_STATES: &[&str] = &["no link", "linked", "simulation"];

/// The items of `_Diagnostics.Channels.<channel>`.
pub const CHANNEL_FIELDS: [Field; 5] = [
    Field {
        enumerated: LINK_STATES,
        ..field(
            "LinkState",
            VarType::I4,
            "Stan połączenia kanału z serwerem asix: 0 brak, 1 połączony, 2 symulacja",
            "The channel's link to an asix server: 0 no link, 1 linked, 2 simulation",
            None,
        )
    },
    field(
        "Server",
        VarType::BSTR,
        "Bieżący serwer asix kanału",
        "The channel's current asix server",
        None,
    ),
    field(
        "Failovers",
        VarType::I4,
        "Przełączenia na inny serwer od startu",
        "Failovers to another server since the start",
        None,
    ),
    field(
        "LastError",
        VarType::BSTR,
        "Ostatni błąd połączenia (pusty: żaden)",
        "The last link error (empty: none)",
        None,
    ),
    field(
        "Subscriptions",
        VarType::I4,
        "Subskrybowane zmienne kanału",
        "The channel's subscribed variables",
        None,
    ),
];

/// A channel's link, as the data source knows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LinkState {
    #[default]
    Down = 0,
    Up = 1,
    /// The in-process simulation: no link to have.
    Simulation = 2,
}

/// What a data source says of one channel ([`crate::source::Backend::channels`]).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ChannelStatus {
    /// The asix channel (of the item IDs a data server serves, e.g. `SIARKA`).
    pub name: String,
    pub link: LinkState,
    /// The asix server the channel is linked to (empty: none).
    pub server: String,
    pub failovers: u64,
    /// The last link error's text (empty: none).
    pub last_error: String,
    pub subscriptions: u64,
}

/// The server-wide counters of one snapshot, as the runtime reads them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ServerCounters {
    pub uptime_s: u64,
    pub clients: u64,
    pub groups: u64,
    pub items: u64,
    /// Totals since the start ([`crate::metrics`]); the snapshot turns them into rates.
    pub callbacks_total: u64,
    pub values_total: u64,
    pub failed_callbacks: u64,
    pub dropped_sinks: u64,
    pub pending_transactions: u64,
}

/// One connected client's counters.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ClientCounters {
    /// The engine's session handle (the fallback name and the tie-breaker).
    pub session: u32,
    pub name: Option<String>,
    pub groups: u64,
    pub items: u64,
    /// The last callback's duration, ms (`None`: none yet).
    pub last_latency_ms: Option<f64>,
    pub pending: u64,
    pub failures: u64,
    /// Who the client is ([`crate::write_rights::Caller`]'s text; `None`: not told).
    pub identity: Option<String>,
}

/// What the runtime hands [`Sampler::sample`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Input {
    pub server: ServerCounters,
    pub clients: Vec<ClientCounters>,
    pub channels: Vec<ChannelStatus>,
}

/// The values of the branch at one moment, and its browse tree.
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// The values' timestamp.
    pub taken: Timestamp,
    pub server: ServerCounters,
    pub callbacks_per_s: f64,
    pub values_per_s: f64,
    /// Sorted by branch name (binary search).
    pub clients: Vec<(String, ClientCounters)>,
    /// Sorted by branch name.
    pub channels: Vec<(String, ChannelStatus)>,
    /// The branch as an address space of its own: its root holds [`ROOT`] only; item IDs
    /// are the full diagnostic IDs.
    pub space: Arc<AddressSpace>,
}

impl Default for Snapshot {
    fn default() -> Self {
        Snapshot {
            taken: Timestamp::default(),
            server: ServerCounters::default(),
            callbacks_per_s: 0.0,
            values_per_s: 0.0,
            clients: Vec::new(),
            channels: Vec::new(),
            space: Arc::new(build_space(&[], &[], MatchCase::default())),
        }
    }
}

/// Which part of the branch an item is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Section {
    Server,
    Client,
    Channel,
}

impl Section {
    pub fn fields(self) -> &'static [Field] {
        match self {
            Section::Server => &SERVER_FIELDS,
            Section::Client => &CLIENT_FIELDS,
            Section::Channel => &CHANNEL_FIELDS,
        }
    }
}

/// A diagnostic item ID taken apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DiagItem<'a> {
    pub section: Section,
    /// The client's or channel's branch name (`""` for the server).
    pub owner: &'a str,
    /// Index into [`Section::fields`].
    pub field: usize,
}

impl<'a> DiagItem<'a> {
    /// Parses an item ID of the branch (`None`: not one of its items, e.g. a branch).
    pub fn parse(item_id: &'a str) -> Option<DiagItem<'a>> {
        let rest = item_id.strip_prefix(ROOT)?.strip_prefix('.')?;
        let (section, rest) = rest.split_once('.')?;
        let (section, owner, name) = match section {
            SERVER => (Section::Server, "", rest),
            CLIENTS | CHANNELS => {
                let (owner, name) = rest.rsplit_once('.')?;
                if owner.is_empty() || owner.contains('.') {
                    return None;
                }
                let s = if section == CLIENTS {
                    Section::Client
                } else {
                    Section::Channel
                };
                (s, owner, name)
            }
            _ => return None,
        };
        let field = section.fields().iter().position(|f| f.name == name)?;
        Some(DiagItem {
            section,
            owner,
            field,
        })
    }

    pub fn info(&self) -> &'static Field {
        &self.section.fields()[self.field]
    }
}

/// The description of a branch of `_Diagnostics` (the branch itself, its sections, a
/// client's or a channel's branch) in `lang`; `None` for any other ID (items included:
/// theirs are their [`Field`]'s). The OPC UA front end serves it as the folder's
/// Description.
pub fn branch_description(item_id: &str, lang: Lang) -> Option<String> {
    let pick = |pl: &str, en: &str| match lang {
        Lang::Polish => pl.to_owned(),
        Lang::English => en.to_owned(),
    };
    let rest = item_id.strip_prefix(ROOT)?;
    if rest.is_empty() {
        return Some(pick(
            "Diagnostyka serwera: serwer, podłączeni klienci, kanały",
            "Server diagnostics: the server, the connected clients, the channels",
        ));
    }
    let rest = rest.strip_prefix('.')?;
    let (section, owner) = match rest.split_once('.') {
        Some((section, owner)) if !owner.is_empty() && !owner.contains('.') => {
            (section, Some(owner))
        }
        Some(_) => return None,
        None => (rest, None),
    };
    Some(match (section, owner) {
        (SERVER, None) => pick("Liczniki serwera", "The server's counters"),
        (CLIENTS, None) => pick(
            "Podłączeni klienci, po jednej gałęzi na klienta",
            "The connected clients, one branch per client",
        ),
        (CHANNELS, None) => pick(
            "Kanały źródła danych, po jednej gałęzi na kanał",
            "The data source's channels, one branch per channel",
        ),
        (CLIENTS, Some(c)) => pick(&format!("Klient {c}"), &format!("Client {c}")),
        (CHANNELS, Some(c)) => pick(&format!("Kanał {c}"), &format!("Channel {c}")),
        _ => return None,
    })
}

/// A name made fit for one segment of an item ID: `.` and control characters become `_`.
pub fn segment(name: &str) -> String {
    name.chars()
        .map(|c| if c == '.' || c.is_control() { '_' } else { c })
        .collect()
}

/// The branch names of the clients, in input order (see the module doc).
pub fn client_branches(clients: &[ClientCounters]) -> Vec<String> {
    let base: Vec<String> = clients
        .iter()
        .map(|c| match c.name.as_deref().map(segment) {
            Some(n) if !n.is_empty() => n,
            _ => format!("Client{}", c.session),
        })
        .collect();
    let mut seen = HashSet::new();
    let shared: HashSet<&str> = base
        .iter()
        .filter(|n| !seen.insert(n.as_str()))
        .map(String::as_str)
        .collect();
    base.iter()
        .zip(clients)
        .map(|(n, c)| {
            if shared.contains(n.as_str()) {
                format!("{n}#{}", c.session)
            } else {
                n.clone()
            }
        })
        .collect()
}

fn build_space(clients: &[String], channels: &[String], case: MatchCase) -> AddressSpace {
    let mut b = AddressSpace::builder();
    b.filter_case(case);
    // The sections first, in this order, and branches even when empty.
    if let Ok(root) = b.add_branch(NodeId::ROOT, ROOT, ROOT) {
        for s in [SERVER, CLIENTS, CHANNELS] {
            let _ = b.add_branch(root, s, &format!("{ROOT}.{s}"));
        }
    }
    let mut add = |path: String| {
        // Every segment is non-empty by construction; a failure would only drop the item.
        let _ = b.add_path(&path, '.');
    };
    for f in &SERVER_FIELDS {
        add(format!("{ROOT}.{SERVER}.{}", f.name));
    }
    for c in clients {
        for f in &CLIENT_FIELDS {
            add(format!("{ROOT}.{CLIENTS}.{c}.{}", f.name));
        }
    }
    for c in channels {
        for f in &CHANNEL_FIELDS {
            add(format!("{ROOT}.{CHANNELS}.{c}.{}", f.name));
        }
    }
    b.build()
}

/// Takes [`Snapshot`]s: the rates over the interval since the previous one, the browse tree
/// rebuilt only when the set of branches changed.
#[derive(Debug)]
pub struct Sampler {
    case: MatchCase,
    last: Option<(Timestamp, u64, u64)>,
    branches: (Vec<String>, Vec<String>),
    space: Arc<AddressSpace>,
}

impl Sampler {
    /// `case`: the real address space's filter rule (the branch browses the same way).
    pub fn new(case: MatchCase) -> Sampler {
        Sampler {
            case,
            last: None,
            branches: (Vec::new(), Vec::new()),
            space: Arc::new(build_space(&[], &[], case)),
        }
    }

    /// True when the next snapshot is due at `now` (the first one at once).
    pub fn due(&self, now: Timestamp) -> bool {
        self.last
            .is_none_or(|(t, ..)| now.millis_since(t) >= SNAPSHOT_PERIOD_MS)
    }

    /// The snapshot of `input` taken at `now`.
    pub fn sample(&mut self, now: Timestamp, input: Input) -> Snapshot {
        let s = input.server;
        let (callbacks_per_s, values_per_s) = match self.last {
            Some((t, cb, v)) if now.millis_since(t) > 0 => {
                let secs = now.millis_since(t) as f64 / 1000.0;
                (
                    s.callbacks_total.saturating_sub(cb) as f64 / secs,
                    s.values_total.saturating_sub(v) as f64 / secs,
                )
            }
            _ => (0.0, 0.0),
        };
        self.last = Some((now, s.callbacks_total, s.values_total));
        let mut clients: Vec<(String, ClientCounters)> = client_branches(&input.clients)
            .into_iter()
            .zip(input.clients)
            .collect();
        clients.sort_by(|a, b| a.0.cmp(&b.0));
        let mut channels: Vec<(String, ChannelStatus)> = input
            .channels
            .into_iter()
            .map(|c| (segment(&c.name), c))
            .filter(|(n, _)| !n.is_empty())
            .collect();
        channels.sort_by(|a, b| a.0.cmp(&b.0));
        channels.dedup_by(|a, b| a.0 == b.0);
        let client_names: Vec<String> = clients.iter().map(|c| c.0.clone()).collect();
        let channel_names: Vec<String> = channels.iter().map(|c| c.0.clone()).collect();
        if client_names != self.branches.0 || channel_names != self.branches.1 {
            self.space = Arc::new(build_space(&client_names, &channel_names, self.case));
            self.branches = (client_names, channel_names);
        }
        Snapshot {
            taken: now,
            server: s,
            callbacks_per_s,
            values_per_s,
            clients,
            channels,
            space: Arc::clone(&self.space),
        }
    }
}

fn count(n: u64) -> Value {
    Value::I4(i32::try_from(n).unwrap_or(i32::MAX))
}

impl Snapshot {
    fn client(&self, branch: &str) -> Option<&ClientCounters> {
        let i = self
            .clients
            .binary_search_by(|c| c.0.as_str().cmp(branch))
            .ok()?;
        Some(&self.clients[i].1)
    }

    fn channel(&self, branch: &str) -> Option<&ChannelStatus> {
        let i = self
            .channels
            .binary_search_by(|c| c.0.as_str().cmp(branch))
            .ok()?;
        Some(&self.channels[i].1)
    }

    /// Whether the item exists in this snapshot (its client or channel is there).
    pub fn has(&self, item: &DiagItem<'_>) -> bool {
        match item.section {
            Section::Server => true,
            Section::Client => self.client(item.owner).is_some(),
            Section::Channel => self.channel(item.owner).is_some(),
        }
    }

    /// The item's value (`None`: its client has gone, or its channel is unknown).
    pub fn value(&self, item: &DiagItem<'_>) -> Option<Value> {
        Some(match item.section {
            Section::Server => {
                let s = &self.server;
                match item.field {
                    0 => count(s.uptime_s),
                    1 => count(s.clients),
                    2 => count(s.groups),
                    3 => count(s.items),
                    4 => Value::R8(self.callbacks_per_s),
                    5 => Value::R8(self.values_per_s),
                    6 => count(s.failed_callbacks),
                    7 => count(s.dropped_sinks),
                    _ => count(s.pending_transactions),
                }
            }
            Section::Client => {
                let c = self.client(item.owner)?;
                match item.field {
                    0 => Value::Bstr(c.name.clone().unwrap_or_default()),
                    1 => count(c.groups),
                    2 => count(c.items),
                    3 => Value::R8(c.last_latency_ms.unwrap_or(-1.0)),
                    4 => count(c.pending),
                    5 => count(c.failures),
                    _ => Value::Bstr(c.identity.clone().unwrap_or_default()),
                }
            }
            Section::Channel => {
                let c = self.channel(item.owner)?;
                match item.field {
                    0 => Value::I4(c.link as i32),
                    1 => Value::Bstr(c.server.clone()),
                    2 => count(c.failovers),
                    3 => Value::Bstr(c.last_error.clone()),
                    _ => count(c.subscriptions),
                }
            }
        })
    }
}

/// Where the runtime publishes snapshots and readers take them. The lock is taken once per
/// snapshot by the runtime and by readers of the whole snapshot (namespace lookups of
/// diagnostic IDs, browsing); the backend checks [`Board::generation`] first.
#[derive(Debug, Default)]
pub struct Board {
    current: RwLock<Arc<Snapshot>>,
    generation: AtomicU64,
}

impl Board {
    pub fn new() -> Board {
        Board::default()
    }

    /// Makes `s` the current snapshot.
    pub fn publish(&self, s: Snapshot) {
        *self.current.write().unwrap_or_else(|p| p.into_inner()) = Arc::new(s);
        self.generation.fetch_add(1, Ordering::Release);
    }

    /// Bumped by every [`Board::publish`].
    pub fn generation(&self) -> u64 {
        self.generation.load(Ordering::Acquire)
    }

    pub fn current(&self) -> Arc<Snapshot> {
        Arc::clone(&self.current.read().unwrap_or_else(|p| p.into_inner()))
    }

    /// The current browse tree of the branch.
    pub fn space(&self) -> Arc<AddressSpace> {
        Arc::clone(&self.current().space)
    }
}

/// The real namespace with the `_Diagnostics` items beside it (see the module doc).
pub struct DiagNamespace {
    inner: Arc<dyn Namespace>,
    board: Arc<Board>,
}

impl DiagNamespace {
    pub fn new(inner: Arc<dyn Namespace>, board: Arc<Board>) -> DiagNamespace {
        DiagNamespace { inner, board }
    }
}

/// The item definition of a diagnostic item: read-only, its ID its own source key.
pub fn item_def(item_id: &str, item: &DiagItem<'_>) -> ItemDef {
    let f = item.info();
    ItemDef {
        source_key: item_id.to_owned(),
        channel: "*".to_owned(),
        canonical_type: f.canonical_type,
        access_rights: OPC_READABLE,
        eu: eu(f),
        constant: None,
    }
}

fn eu(f: &Field) -> EuInfo {
    if f.enumerated.is_empty() {
        EuInfo::None
    } else {
        EuInfo::Enumerated(f.enumerated.iter().map(|s| (*s).to_owned()).collect())
    }
}

/// A field's description in `lang`.
pub fn description(f: &Field, lang: Lang) -> &'static str {
    match lang {
        Lang::Polish => f.description_pl,
        Lang::English => f.description_en,
    }
}

impl DiagNamespace {
    /// A diagnostic ID's item, if it is one that exists now. Access paths: only `""`.
    fn diag(&self, item_id: &str, access_path: &str) -> OpcResult<(ItemDef, PropertyAttributes)> {
        let item = DiagItem::parse(item_id).ok_or(OpcError::UnknownItemId)?;
        if !self.board.current().has(&item) {
            return Err(OpcError::UnknownItemId);
        }
        if !access_path.is_empty() {
            return Err(OpcError::UnknownPath);
        }
        let f = item.info();
        let attrs = PropertyAttributes {
            description: Some(f.description_pl.to_owned()),
            description_en: Some(f.description_en.to_owned()),
            eu_units: f.eu_units.map(str::to_owned),
            eu: eu(f),
            ..PropertyAttributes::default()
        };
        Ok((item_def(item_id, &item), attrs))
    }
}

impl Namespace for DiagNamespace {
    fn resolve(&self, item_id: &str, access_path: &str) -> OpcResult<ItemDef> {
        if is_diagnostic_id(item_id) {
            return self.diag(item_id, access_path).map(|(d, _)| d);
        }
        self.inner.resolve(item_id, access_path)
    }

    fn check_write_value(&self, value: &Value) -> OpcResult<()> {
        self.inner.check_write_value(value)
    }

    fn resolve_with_attributes(
        &self,
        item_id: &str,
        access_path: &str,
    ) -> OpcResult<(ItemDef, PropertyAttributes)> {
        if is_diagnostic_id(item_id) {
            return self.diag(item_id, access_path);
        }
        self.inner.resolve_with_attributes(item_id, access_path)
    }

    fn property_item_id(&self, item_id: &str, def: &ItemDef, property_id: u32) -> Option<String> {
        if is_diagnostic_id(item_id) {
            return None;
        }
        self.inner.property_item_id(item_id, def, property_id)
    }

    fn write_refusal(&self, item_id: &str, access_path: &str) -> Option<String> {
        if is_diagnostic_id(item_id) {
            return None;
        }
        self.inner.write_refusal(item_id, access_path)
    }
}

#[cfg(test)]
mod tests;
