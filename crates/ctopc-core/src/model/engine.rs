//! The process-wide engine: configuration, the shared cache, sessions and groups, and the
//! output queues.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

use super::cache::SourceTable;
use super::datasource::SourceRequest;
use super::events::Event;
use super::group::Group;
use super::item::{GroupItem, ItemFlags, ItemOpts, NameTable};
use super::scheduler::Scheduler;
use super::transactions::Txns;
use super::util::IntMap;
use crate::convert::Locale;
use crate::namespace::Namespace;
use crate::write_rights::{Caller, Decision, WriteRights};
use crate::{OpcError, Timestamp};

/// Default minimum update rate (AsixConnect 4 §6.6: 1 s).
pub const DEFAULT_MIN_UPDATE_RATE_MS: u32 = 1000;
/// Default bound on outstanding asynchronous transactions per group (see the module docs
/// of [`crate::model`]; one more answers CONNECT_E_ADVISELIMIT).
pub const DEFAULT_MAX_TRANSACTIONS_PER_GROUP: u32 = 256;
/// Default time the engine waits for the data source to answer a device read or write
/// before failing the items with ASKOM_E_NetAnswerTimeout. Longer than asix's own
/// NetTimeout (3 s) plus server discovery (FindServerTimeout, 3 s), so the backend's own,
/// more specific error normally arrives first.
pub const DEFAULT_SOURCE_TIMEOUT_MS: u32 = 10_000;

/// Default bound of the wait for the first sample of newly active items before their
/// first OnDataChange ([`EngineConfig::first_sample_wait_ms`]): asix's default
/// `NetTimeout` (3 s), the time the network client itself gives a data server to answer.
pub const DEFAULT_FIRST_SAMPLE_WAIT_MS: u32 = 3000;

/// The server's [`EngineConfig::max_pending_data_changes`]: one callback travelling, the
/// next one ready.
pub const SERVER_PENDING_DATA_CHANGES: u32 = 2;

/// Engine configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct EngineConfig {
    /// Shortest update rate, keep-alive time and sampling rate, in ms (at least 1).
    pub min_update_rate_ms: u32,
    /// Outstanding asynchronous transactions allowed per group.
    pub max_transactions_per_group: u32,
    /// How long to wait for the data source to answer a read or write, in ms.
    pub source_timeout_ms: u32,
    /// The number format for conversions to and from strings when a group's LCID is a
    /// default/neutral LCID (the COM layer passes the system's).
    pub default_locale: Locale,
    /// Pace subscription callbacks by their delivery: a group has at most this many
    /// OnDataChange (or keep-alive) calls from the update scheduler under way at once; the
    /// caller reports each delivery's end with
    /// [`Engine::data_change_delivered`](crate::model::Engine::data_change_delivered).
    /// Updates that fall due meanwhile are coalesced: a slow client gets the latest values
    /// as soon as it returns, never a growing backlog. 1 strictly alternates producing and
    /// delivering; 2 lets the next callback be prepared while the previous one travels
    /// (the server's setting, [`SERVER_PENDING_DATA_CHANGES`]). 0: no pacing, an event at
    /// every update regardless.
    pub max_pending_data_changes: u32,
    /// How long an active item that has no sample from the data source yet is held back
    /// from OnDataChange, in ms, so that its first callback carries a real value instead
    /// of `BAD Waiting for Initial Data` (see [`crate::model`], "first callback"). 0: no
    /// wait (items are reported at once, with the placeholder).
    pub first_sample_wait_ms: u32,
}

impl EngineConfig {
    /// Scheduled callbacks wait for their delivery ([`Self::max_pending_data_changes`]).
    pub fn paces(&self) -> bool {
        self.max_pending_data_changes > 0
    }
}

impl Default for EngineConfig {
    fn default() -> Self {
        EngineConfig {
            min_update_rate_ms: DEFAULT_MIN_UPDATE_RATE_MS,
            max_transactions_per_group: DEFAULT_MAX_TRANSACTIONS_PER_GROUP,
            source_timeout_ms: DEFAULT_SOURCE_TIMEOUT_MS,
            default_locale: Locale::EnUs,
            max_pending_data_changes: 0,
            first_sample_wait_ms: DEFAULT_FIRST_SAMPLE_WAIT_MS,
        }
    }
}

/// One client's server object (IOPCServer).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SessionHandle(pub u32);

/// A group's server handle (hServerGroup); unique in the process and never reused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct GroupHandle(pub u32);

/// Counters for diagnostics and the benchmark.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EngineStats {
    pub sessions: usize,
    pub groups: usize,
    pub group_items: usize,
    /// Source items in the cache.
    pub source_items: usize,
    /// Source items with at least one active subscriber.
    pub subscribed_items: usize,
    pub pending_transactions: usize,
    pub queued_events: usize,
}

pub(crate) struct Session {
    pub names: HashMap<String, GroupHandle>,
    /// Every group of the session, including ones removed while still referenced.
    pub groups: Vec<GroupHandle>,
    pub last_update: Timestamp,
    pub name_counter: u32,
    /// The LCID of IOPCCommon::SetLocaleID: the conversion locale of the session's
    /// group-less writes (IOPCItemIO::WriteVQT). LOCALE_SYSTEM_DEFAULT until set.
    pub lcid: u32,
    /// Who is calling, as the front end last said ([`Engine::set_session_caller`]); what
    /// the write-rights policy decides on.
    pub caller: Caller,
}

/// The OPC DA server model. See [`crate::model`].
///
/// `Send` (not internally synchronized): the COM layer keeps it behind a `Mutex` and never
/// calls a client while holding it.
pub struct Engine {
    pub(crate) cfg: EngineConfig,
    pub(crate) ns: Arc<dyn Namespace>,
    pub(crate) sources: SourceTable,
    pub(crate) names: NameTable,
    pub(crate) sessions: IntMap<u32, Session>,
    pub(crate) next_session: u32,
    pub(crate) groups: Vec<Option<Group>>,
    pub(crate) free_groups: Vec<u32>,
    pub(crate) group_slots: IntMap<u32, u32>,
    pub(crate) next_group_handle: u32,
    pub(crate) next_item_handle: u32,
    /// Bumped whenever a cached value or quality changes.
    pub(crate) change_seq: u64,
    pub(crate) sched: Scheduler,
    pub(crate) txns: Txns,
    pub(crate) events: VecDeque<Event>,
    pub(crate) requests: VecDeque<SourceRequest>,
    /// Slots of groups holding items back until their first sample (may hold stale or
    /// duplicate slots; checked when used).
    pub(crate) first_sample_waiters: Vec<u32>,
    /// Cache entry -> (group handle, item handle) of the items with buffering on that
    /// refer to it (may hold stale pairs; checked when used, `model/buffer.rs`).
    pub(crate) buffer_refs: IntMap<u32, Vec<(u32, u32)>>,
    /// Who may write ([`crate::write_rights`]); open until set.
    pub(crate) write_rights: Arc<WriteRights>,
}

impl Engine {
    pub fn new(config: EngineConfig, namespace: Arc<dyn Namespace>) -> Self {
        let mut cfg = config;
        cfg.min_update_rate_ms = cfg.min_update_rate_ms.max(1);
        Engine {
            cfg,
            ns: namespace,
            sources: SourceTable::default(),
            names: NameTable::default(),
            sessions: IntMap::default(),
            next_session: 1,
            groups: Vec::new(),
            free_groups: Vec::new(),
            group_slots: IntMap::default(),
            next_group_handle: 1,
            next_item_handle: 1,
            change_seq: 0,
            sched: Scheduler::default(),
            txns: Txns::default(),
            events: VecDeque::new(),
            requests: VecDeque::new(),
            first_sample_waiters: Vec::new(),
            buffer_refs: IntMap::default(),
            write_rights: Arc::new(WriteRights::open()),
        }
    }

    /// Sets the write-rights policy every write is decided by (open until set).
    pub fn set_write_rights(&mut self, rights: Arc<WriteRights>) {
        self.write_rights = rights;
    }

    /// The write-rights policy.
    pub fn write_rights(&self) -> &WriteRights {
        &self.write_rights
    }

    /// Who is calling on `session`: the front end says it when the session opens and again
    /// before each write (the caller of one server object may change between calls).
    /// Unknown sessions are ignored.
    pub fn set_session_caller(&mut self, session: SessionHandle, caller: Caller) {
        if let Some(s) = self.sessions.get_mut(&session.0) {
            s.caller = caller;
        }
    }

    /// The caller of `session` ([`Self::set_session_caller`]), if the session exists.
    pub fn session_caller(&self, session: SessionHandle) -> Option<&Caller> {
        self.sessions.get(&session.0).map(|s| &s.caller)
    }

    /// The policy's decision for a write of `session` to an item of `channel`.
    pub fn write_decision(&self, session: SessionHandle, channel: &str) -> Decision {
        match self.session_caller(session) {
            Some(c) => self.write_rights.decide(channel, c),
            None => self
                .write_rights
                .decide(channel, &Caller::unknown("no such session")),
        }
    }

    /// May `session` write the cache entry `source`? (Open policies skip the lookup.)
    pub(crate) fn may_write(&self, session: SessionHandle, source: u32) -> bool {
        self.write_rights.is_open()
            || self
                .write_decision(session, self.sources.channel(source))
                .allowed
    }

    pub fn config(&self) -> &EngineConfig {
        &self.cfg
    }

    /// Replaces the namespace (e.g. after the variable database was reloaded). Items
    /// already in groups keep their definitions.
    pub fn set_namespace(&mut self, namespace: Arc<dyn Namespace>) {
        self.ns = namespace;
    }

    pub fn stats(&self) -> EngineStats {
        EngineStats {
            sessions: self.sessions.len(),
            groups: self.groups.iter().flatten().filter(|g| !g.deleted).count(),
            group_items: self.groups.iter().flatten().map(|g| g.items.len()).sum(),
            source_items: self.sources.live(),
            subscribed_items: self.sources.subscribed(),
            pending_transactions: self.txns.map.len(),
            queued_events: self.events.len(),
        }
    }

    /// Per session: its groups (not removed) and the items in them, by session handle
    /// (for the `_Diagnostics` branch, [`crate::diagnostics`]).
    pub fn session_stats(&self) -> Vec<(SessionHandle, usize, usize)> {
        let mut out: Vec<(SessionHandle, usize, usize)> = self
            .sessions
            .keys()
            .map(|&s| (SessionHandle(s), 0, 0))
            .collect();
        out.sort_unstable_by_key(|e| e.0);
        for g in self.groups.iter().flatten().filter(|g| !g.deleted) {
            if let Ok(i) = out.binary_search_by_key(&g.session, |e| e.0) {
                out[i].1 += 1;
                out[i].2 += g.items.len();
            }
        }
        out
    }

    // ---- sessions ------------------------------------------------------------------

    /// A new server object (one per COM client).
    pub fn open_session(&mut self) -> SessionHandle {
        let h = self.next_session;
        self.next_session = self.next_session.wrapping_add(1).max(1);
        self.sessions.insert(
            h,
            Session {
                names: HashMap::new(),
                groups: Vec::new(),
                last_update: Timestamp(0),
                name_counter: 0,
                lcid: crate::lang::LOCALE_SYSTEM_DEFAULT,
                caller: Caller::default(),
            },
        );
        SessionHandle(h)
    }

    /// IOPCCommon::SetLocaleID: the session's LCID, the locale in which its IOPCItemIO
    /// writes convert text (as a group's LCID does for the group's writes). Accepted: the
    /// LCIDs the server speaks (Polish, any English, the neutral/default and invariant
    /// locales: [`crate::lang::Lang::from_lcid`]); others, and an unknown session, are
    /// E_INVALIDARG and change nothing.
    pub fn set_session_lcid(&mut self, session: SessionHandle, lcid: u32) -> Result<(), OpcError> {
        if crate::lang::Lang::from_lcid(lcid, crate::lang::Lang::English).is_none() {
            return Err(OpcError::InvalidArg);
        }
        let s = self
            .sessions
            .get_mut(&session.0)
            .ok_or(OpcError::InvalidArg)?;
        s.lcid = lcid;
        Ok(())
    }

    /// The session's LCID ([`Self::set_session_lcid`]; LOCALE_SYSTEM_DEFAULT until set).
    pub fn session_lcid(&self, session: SessionHandle) -> Result<u32, OpcError> {
        self.sessions
            .get(&session.0)
            .map(|s| s.lcid)
            .ok_or(OpcError::InvalidArg)
    }

    /// Releases a server object: every group is removed (as with bForce).
    pub fn close_session(
        &mut self,
        now: Timestamp,
        session: SessionHandle,
    ) -> Result<(), OpcError> {
        let s = self.sessions.get(&session.0).ok_or(OpcError::InvalidArg)?;
        for g in s.groups.clone() {
            if let Some(&slot) = self.group_slots.get(&g.0) {
                self.destroy_group(now, slot as usize, true);
            }
        }
        self.sessions.remove(&session.0);
        Ok(())
    }

    /// The last time an OnDataChange with data was queued for this session's groups
    /// (IOPCServer::GetStatus ftLastUpdateTime); `Timestamp(0)` before the first.
    pub fn last_update_time(&self, session: SessionHandle) -> Result<Timestamp, OpcError> {
        self.sessions
            .get(&session.0)
            .map(|s| s.last_update)
            .ok_or(OpcError::InvalidArg)
    }

    // ---- lookups -------------------------------------------------------------------

    /// The slot of a live (not removed) group; E_FAIL otherwise (the COM object outlived
    /// its group).
    pub(crate) fn live_slot(&self, g: GroupHandle) -> Result<usize, OpcError> {
        let slot = *self.group_slots.get(&g.0).ok_or(OpcError::Fail)? as usize;
        match &self.groups[slot] {
            Some(grp) if !grp.deleted => Ok(slot),
            _ => Err(OpcError::Fail),
        }
    }

    pub(crate) fn group(&self, slot: usize) -> &Group {
        self.groups[slot].as_ref().expect("live group slot")
    }

    pub(crate) fn group_mut(&mut self, slot: usize) -> &mut Group {
        self.groups[slot].as_mut().expect("live group slot")
    }

    /// A new item server handle: from a process-wide counter (never 0, never reused until
    /// the counter wraps), greater than every handle in `items` so they stay sorted; after
    /// a wrap the group falls back to linear search.
    pub(crate) fn alloc_item_handle(
        counter: &mut u32,
        items: &[GroupItem],
        sorted: &mut bool,
    ) -> u32 {
        loop {
            let h = *counter;
            *counter = counter.wrapping_add(1).max(1);
            if !matches!(items.last(), Some(it) if h <= it.handle) {
                return h;
            }
            *sorted = false;
            if !items.iter().any(|it| it.handle == h) {
                return h;
            }
        }
    }

    pub(crate) fn locale(&self, lcid: u32) -> Locale {
        Locale::from_lcid(lcid, self.cfg.default_locale)
    }

    /// A requested rate raised to the minimum.
    pub(crate) fn revise_rate(&self, requested: u32) -> super::Revised {
        let value = requested.max(self.cfg.min_update_rate_ms);
        super::Revised {
            value,
            revised: value != requested,
        }
    }

    // ---- subscriptions ---------------------------------------------------------------

    /// Brings one item's subscription in line with its state: subscribed while the item is
    /// active in an active, live group and not constant; at its item sampling rate
    /// (`sampling`, [`ItemOpts::sampling`]) if set, else the group's.
    pub(crate) fn sync_sub(
        sources: &mut SourceTable,
        group_on: bool,
        group_rate: u32,
        sampling: u32,
        it: &mut GroupItem,
    ) {
        let want = group_on && it.active() && !sources.entries[it.source as usize].is_constant();
        let has = it.flags.contains(ItemFlags::SUBSCRIBED);
        let rate = if sampling != 0 { sampling } else { group_rate };
        if want && !has {
            sources.add_rate(it.source, rate);
            it.flags.insert(ItemFlags::SUBSCRIBED);
        } else if !want && has {
            sources.remove_rate(it.source, rate);
            it.flags.remove(ItemFlags::SUBSCRIBED);
        }
    }

    /// Re-evaluates the subscriptions of every item of a group.
    pub(crate) fn sync_group_subs(&mut self, slot: usize) {
        let Engine {
            groups, sources, ..
        } = self;
        let g = groups[slot].as_mut().expect("group");
        let on = g.active && !g.deleted;
        let rate = g.update_rate;
        for it in &mut g.items {
            let sampling = ItemOpts::sampling(&g.opts, it);
            Self::sync_sub(sources, on, rate, sampling, it);
        }
    }

    /// Changes the rate a subscribed item is counted with.
    pub(crate) fn move_rate(sources: &mut SourceTable, it: &GroupItem, old: u32, new: u32) {
        if it.flags.contains(ItemFlags::SUBSCRIBED) && old != new {
            sources.remove_rate(it.source, old);
            sources.add_rate(it.source, new);
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn engine_is_send() {
        fn send<T: Send>() {}
        send::<super::Engine>();
    }
}
