//! What the runtime keeps of each client session: its name (IOPCCommon::SetClientName)
//! and its identity (who the caller is, as the front end could tell:
//! `ctopc_core::write_rights::Caller`), which the write audit logs, the audit's switch, and the watch over the session's
//! callbacks (`ctopc_core::ops::CallbackWatch` decides; [`crate::Runtime`] tells it when a
//! callback is queued, started and finished). The audit line format is
//! `ctopc_core::audit`'s; this module only gathers the record's parts and logs the lines
//! under the target [`audit::TARGET`](ctopc_core::audit::TARGET).
//!
//! Its mutexes are leaves: held only to copy or update plain data, never while calling
//! anything or taking another lock.

use ctopc_core::audit::{self, Client, CompleteRecord, WriteRecord};
use ctopc_core::diagnostics::ClientCounters;
use ctopc_core::model::{GroupHandle, ItemVqt, SessionHandle, WriteComplete};
use ctopc_core::ops::{Admit, CallbackWatch, OpsConfig, Verdict};
use ctopc_core::{OpcError, Timestamp};
use std::collections::{BTreeSet, HashMap};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Mutex;

/// See the module doc.
pub struct Clients {
    audit_writes: AtomicBool,
    names: Mutex<HashMap<SessionHandle, Who>>,
    callback_timeout_ms: AtomicU32,
    callback_failures: AtomicU32,
    watches: Mutex<HashMap<SessionHandle, Watch>>,
}

/// A session's name and identity.
#[derive(Default)]
struct Who {
    name: Option<String>,
    identity: Option<String>,
}

/// A client's callback watch and the groups it has delivered to (whose sinks a drop
/// removes).
struct Watch {
    watch: CallbackWatch,
    groups: BTreeSet<GroupHandle>,
}

impl Default for Clients {
    fn default() -> Self {
        let c = OpsConfig::default();
        Clients {
            audit_writes: AtomicBool::new(c.audit_writes),
            names: Mutex::default(),
            callback_timeout_ms: AtomicU32::new(c.callback_timeout_ms),
            callback_failures: AtomicU32::new(c.callback_failures),
            watches: Mutex::default(),
        }
    }
}

/// What one audited write call was.
pub struct WriteCall<'a> {
    pub session: SessionHandle,
    /// The COM method, e.g. `IOPCSyncIO::Write`.
    pub method: &'a str,
    /// The group's name (`None`: IOPCItemIO).
    pub group: Option<&'a str>,
    /// Per item: its ID, if known, and the server handle the client gave (groups).
    pub items: &'a [(Option<&'a str>, Option<u32>)],
    pub values: &'a [ItemVqt],
    /// The asynchronous call's cancel ID.
    pub cancel_id: Option<u32>,
    /// Per item: the write-rights policy refused it (`Engine::denied_by_policy`); empty
    /// when none was.
    pub denied: &'a [bool],
}

impl Clients {
    /// Applies the configuration (at start).
    pub fn configure(&self, config: &OpsConfig) {
        self.audit_writes
            .store(config.audit_writes, Ordering::Relaxed);
        self.callback_timeout_ms
            .store(config.callback_timeout_ms, Ordering::Relaxed);
        self.callback_failures
            .store(config.callback_failures, Ordering::Relaxed);
    }

    /// `CallbackTimeout`, ms, and `CallbackFailures`.
    pub fn callback_limits(&self) -> (u32, u32) {
        (
            self.callback_timeout_ms.load(Ordering::Relaxed),
            self.callback_failures.load(Ordering::Relaxed),
        )
    }

    fn watch<R>(&self, session: SessionHandle, f: impl FnOnce(&mut Watch) -> R) -> R {
        let mut g = self.watches.lock().unwrap_or_else(|p| p.into_inner());
        let w = g.entry(session).or_insert_with(|| {
            let (timeout, failures) = self.callback_limits();
            Watch {
                watch: CallbackWatch::new(timeout, failures),
                groups: BTreeSet::new(),
            }
        });
        f(w)
    }

    /// A callback for `group` of `session` is about to be queued ([`CallbackWatch::admit`]).
    pub fn admit(&self, session: SessionHandle, group: GroupHandle) -> Admit {
        self.watch(session, |w| {
            w.groups.insert(group);
            w.watch.admit()
        })
    }

    /// The watch of a session that has one (made by [`Clients::admit`]; a session that has
    /// ended has none, so that jobs its worker still runs leave nothing behind).
    fn existing<R: Default>(&self, session: SessionHandle, f: impl FnOnce(&mut Watch) -> R) -> R {
        let mut g = self.watches.lock().unwrap_or_else(|p| p.into_inner());
        g.get_mut(&session).map(f).unwrap_or_default()
    }

    /// The session's worker starts a call ([`CallbackWatch::start`]).
    pub fn call_started(
        &self,
        session: SessionHandle,
        now: Timestamp,
        group: GroupHandle,
        paced: bool,
    ) {
        self.existing(session, |w| w.watch.start(now, group, paced));
    }

    /// The session's worker's call returned ([`CallbackWatch::finish`]). A session without
    /// a watch (ended meanwhile): a paced call is just reported ended.
    pub fn call_finished(
        &self,
        session: SessionHandle,
        now: Timestamp,
        group: GroupHandle,
        paced: bool,
    ) -> Verdict {
        let mut g = self.watches.lock().unwrap_or_else(|p| p.into_inner());
        match g.get_mut(&session) {
            Some(w) => w.watch.finish(now),
            None => Verdict {
                ended: paced.then_some(group),
                ..Verdict::default()
            },
        }
    }

    /// Checks every client's call under way ([`CallbackWatch::poll`]): the verdicts that
    /// say something.
    pub fn poll_calls(&self, now: Timestamp) -> Vec<(SessionHandle, Verdict)> {
        let mut g = self.watches.lock().unwrap_or_else(|p| p.into_inner());
        g.iter_mut()
            .map(|(s, w)| (*s, w.watch.poll(now)))
            .filter(|(_, v)| *v != Verdict::default())
            .collect()
    }

    /// The groups whose sinks a drop of `session`'s callbacks removes.
    pub fn groups_of(&self, session: SessionHandle) -> Vec<GroupHandle> {
        self.existing(session, |w| w.groups.iter().copied().collect())
    }

    /// The `_Diagnostics` counters of each session (`sessions`: the engine's
    /// `session_stats`): name, groups, items, and from its callback watch the last call's
    /// duration, the callbacks queued and the failures. Each mutex is taken once, alone.
    pub fn client_counters(
        &self,
        sessions: &[(SessionHandle, usize, usize)],
    ) -> Vec<ClientCounters> {
        let mut out: Vec<ClientCounters> = {
            let names = self.lock();
            sessions
                .iter()
                .map(|(s, groups, items)| ClientCounters {
                    session: s.0,
                    name: names.get(s).and_then(|w| w.name.clone()),
                    identity: names.get(s).and_then(|w| w.identity.clone()),
                    groups: *groups as u64,
                    items: *items as u64,
                    ..ClientCounters::default()
                })
                .collect()
        };
        let watches = self.watches.lock().unwrap_or_else(|p| p.into_inner());
        for c in &mut out {
            if let Some(w) = watches.get(&SessionHandle(c.session)) {
                c.last_latency_ms = w.watch.last_latency_ms();
                c.pending = w.watch.queued();
                c.failures = w.watch.total_failures();
            }
        }
        out
    }

    /// How the log names a client: its name, else its session.
    pub fn client_label(&self, session: SessionHandle) -> String {
        match self.client_name(session) {
            Some(n) => format!("client \"{}\" (session {})", n.escape_debug(), session.0),
            None => format!("client session {}", session.0),
        }
    }

    /// True when writes are audited (callers skip gathering the record otherwise).
    pub fn auditing(&self) -> bool {
        self.audit_writes.load(Ordering::Relaxed)
    }

    /// IOPCCommon::SetClientName.
    pub fn set_client_name(&self, session: SessionHandle, name: &str) {
        self.lock().entry(session).or_default().name = Some(name.to_owned());
    }

    /// The client name of `session`, if it gave one.
    pub fn client_name(&self, session: SessionHandle) -> Option<String> {
        self.lock().get(&session).and_then(|w| w.name.clone())
    }

    /// Who `session`'s caller is (the text of `ctopc_core::write_rights::Caller`), for the
    /// audit and `_Diagnostics` ([`crate::Runtime::set_caller`] keeps it with the engine's).
    pub fn set_identity(&self, session: SessionHandle, identity: &str) {
        let mut g = self.lock();
        let w = g.entry(session).or_default();
        if w.identity.as_deref() != Some(identity) {
            w.identity = Some(identity.to_owned());
        }
    }

    /// The identity of `session`, if the front end told it.
    pub fn identity(&self, session: SessionHandle) -> Option<String> {
        self.lock().get(&session).and_then(|w| w.identity.clone())
    }

    /// The session ended.
    pub fn forget(&self, session: SessionHandle) {
        self.lock().remove(&session);
        self.watches
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&session);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<SessionHandle, Who>> {
        self.names.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Logs one line per written item with its result (nothing when auditing is off).
    pub fn audit_write(
        &self,
        now: Timestamp,
        call: &WriteCall<'_>,
        results: &[Result<(), OpcError>],
    ) {
        if !self.auditing() {
            return;
        }
        let (name, identity) = {
            let g = self.lock();
            let w = g.get(&call.session);
            (
                w.and_then(|w| w.name.clone()),
                w.and_then(|w| w.identity.clone()),
            )
        };
        let client = match &name {
            Some(n) => Client::Named(n),
            None => Client::Session(call.session.0),
        };
        for (i, v) in call.values.iter().enumerate() {
            let (item_id, server_handle) = call.items.get(i).copied().unwrap_or((None, None));
            let line = audit::format_write(&WriteRecord {
                time: now,
                client,
                method: call.method,
                group: call.group,
                item_id,
                server_handle,
                value: &v.value,
                quality: v.quality,
                timestamp: v.timestamp,
                cancel_id: call.cancel_id,
                result: results.get(i).copied().unwrap_or(Err(OpcError::Fail)),
                identity: identity.as_deref(),
                denied: call.denied.get(i).copied().unwrap_or(false),
            });
            tracing::info!(target: audit::TARGET, "{line}");
        }
    }

    /// Logs the items of an OnWriteComplete (`group`: the group's name, if it still has one).
    pub fn audit_complete(&self, now: Timestamp, group: Option<&str>, w: &WriteComplete) {
        if !self.auditing() {
            return;
        }
        let name = self.client_name(w.session);
        let client = match &name {
            Some(n) => Client::Named(n),
            None => Client::Session(w.session.0),
        };
        for it in &w.items {
            let line = audit::format_complete(&CompleteRecord {
                time: now,
                client,
                group,
                cancel_id: w.cancel_id,
                transaction_id: w.transaction_id,
                client_handle: it.client_handle,
                result: it.error.map_or(Ok(()), Err),
            });
            tracing::info!(target: audit::TARGET, "{line}");
        }
    }
}

/// Records how long a COM method took when dropped: `let _t = ops::timed(&metrics, M);`
/// as the method's first line.
pub struct Timed<'a> {
    metrics: &'a ctopc_core::metrics::Metrics,
    method: ctopc_core::metrics::Method,
    start: std::time::Instant,
}

/// See [`Timed`].
pub fn timed(
    metrics: &ctopc_core::metrics::Metrics,
    method: ctopc_core::metrics::Method,
) -> Timed<'_> {
    Timed {
        metrics,
        method,
        start: std::time::Instant::now(),
    }
}

impl Drop for Timed<'_> {
    fn drop(&mut self) {
        let us = u64::try_from(self.start.elapsed().as_micros()).unwrap_or(u64::MAX);
        self.metrics.call(self.method, us);
    }
}
