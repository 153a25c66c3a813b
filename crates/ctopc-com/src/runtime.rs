//! The server's runtime: the engine (shared by every client of one context), the data
//! source, one driver thread that runs the scheduler and moves data between them, and one
//! callback worker per client so that a slow or dead client never stalls another. A
//! runtime belongs to one `Context` (no process-wide runtime): the driver thread holds
//! only a weak reference and is stopped and joined when the context drops
//! ([`Runtime::stop_driver`]); a worker ends when its session closes.
//!
//! The step itself and the pacing bookkeeping are pure and tested natively
//! (`ctopc_core::driver`); this module owns the threads, condvars, worker queues and the
//! VARIANT marshalling of the callbacks.
//!
//! Locks: `driver` (engine + source) is held only for short, non-blocking sections; no
//! client is ever called while it is held, and no callback worker ever waits for it
//! (workers report back through `reports`). Callbacks are queued to the client's worker,
//! which re-checks the sink before calling it. Subscription callbacks are paced by their
//! delivery (at most two per group under way; see `EngineConfig::max_pending_data_changes`),
//! so a slow or hung client costs the server two pending updates per group, not a backlog.
//! Lock order: `driver` before `sinks` (the driver checks a lost sink under the engine
//! lock); `sinks` and `workers` are never held while waiting for `driver`.

use crate::group::dataobject::{self, Da10Sinks, Routed};
use crate::interfaces::{IOPCDataCallback, IOPCShutdown};
use crate::{clock, connpoint::SinkSlot, error, variant};
use ctopc_core::diagnostics::{self, Board, ChannelStatus, Sampler, ServerCounters};
use ctopc_core::driver::{self, Deliver, Driver, Report};
use ctopc_core::model::{Engine, Event, GroupHandle, SessionHandle};
use ctopc_core::source::{Backend, Wake};
use ctopc_core::{OpcError, Timestamp};
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, Weak};
use std::time::Duration;
use windows::core::{HRESULT, PCWSTR};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Variant::VARIANT;

/// An interface pointer used from MTA threads other than the one that received it.
pub struct Mta<T>(pub T);
// SAFETY: the server process lives in the multithreaded apartment; every thread that
// uses these pointers (RPC threads, the driver, the callback workers) joined the MTA, and
// MTA proxies and our own free-threaded objects may be called from any MTA thread.
unsafe impl<T> Send for Mta<T> {}
// SAFETY: as above.
unsafe impl<T> Sync for Mta<T> {}

#[derive(Default)]
struct Signal {
    woken: Mutex<bool>,
    cv: Condvar,
}

impl Signal {
    fn wake(&self) {
        *self.woken.lock().unwrap_or_else(|p| p.into_inner()) = true;
        self.cv.notify_all();
    }
    fn wait(&self, limit: Duration) {
        let mut w = self.woken.lock().unwrap_or_else(|p| p.into_inner());
        if !*w {
            w = self
                .cv
                .wait_timeout(w, limit)
                .map(|(g, _)| g)
                .unwrap_or_else(|p| p.into_inner().0);
        }
        *w = false;
    }
}

struct SourceWaker(Weak<Signal>);

impl Wake for SourceWaker {
    fn wake(&self) {
        if let Some(s) = self.0.upgrade() {
            s.wake();
        }
    }
}

type Job = Box<dyn FnOnce() + Send>;

/// A client's callback worker: a thread in the MTA running queued deliveries in order.
struct Worker {
    tx: mpsc::Sender<Job>,
}

impl Worker {
    fn spawn(session: SessionHandle) -> Option<Worker> {
        let (tx, rx) = mpsc::channel::<Job>();
        let name = format!("callbacks-{}", session.0);
        std::thread::Builder::new()
            .name(name)
            .spawn(move || {
                let _com = crate::apartment::Apartment::mta();
                while let Ok(job) = rx.recv() {
                    job();
                }
            })
            .ok()?;
        Some(Worker { tx })
    }
}

/// The server's runtime (one per [`Context`](crate::context::Context); its driver thread
/// stops when the context drops, [`Runtime::stop_driver`]).
pub struct Runtime {
    /// Itself, for the jobs queued to the workers (which must not keep it alive).
    me: Weak<Runtime>,
    driver: Mutex<Driver>,
    /// Set by `shutdown`: the driver thread exits at its next wake-up.
    stop: AtomicBool,
    /// Notified after a driver step in which a synchronous operation completed, for the
    /// synchronous calls waiting on the source (each then takes its own result).
    stepped: Condvar,
    signal: Arc<Signal>,
    sinks: Mutex<HashMap<GroupHandle, GroupSinks>>,
    shutdown_sinks: Mutex<HashMap<SessionHandle, Arc<SinkSlot<IOPCShutdown>>>>,
    workers: Mutex<HashMap<SessionHandle, Worker>>,
    /// What the workers report (a scheduled OnDataChange ended, a sink was lost), for the
    /// driver to tell the engine at its next step: a worker never waits for the engine's
    /// lock, it goes on with its next call.
    reports: Mutex<Vec<Report>>,
    /// The driver thread, joined by [`Runtime::stop_driver`].
    driver_thread: Mutex<Option<std::thread::JoinHandle<()>>>,
    pub start_time: Timestamp,
    /// The write audit and the client names (`crate::ops`).
    pub ops: crate::ops::Ops,
    /// The counters and histograms (`ctopc_core::metrics`, served by `crate::metrics_http`).
    pub metrics: ctopc_core::metrics::Metrics,
    /// Where the driver thread publishes the `_Diagnostics` snapshot, at most once per
    /// second ([`Runtime::publish_diagnostics`]; read by the namespace, the backend and
    /// browsing: `ctopc_core::diagnostics`).
    pub diagnostics: Arc<Board>,
}

/// What a step section reads for the diagnostics snapshot: the engine's statistics, per
/// session its groups and items, the backend's channels.
type DiagRead = (
    ctopc_core::model::EngineStats,
    Vec<(SessionHandle, usize, usize)>,
    Vec<ChannelStatus>,
);

/// How long a synchronous call waits for the data source at most, beyond the engine's own
/// source timeout (which completes such requests with ASKOM_E_NetAnswerTimeout).
pub const SYNC_WAIT_MARGIN: Duration = Duration::from_secs(2);

impl Runtime {
    /// Starts the runtime and its driver thread. `make_source` gets the waker to call
    /// when data arrives from another thread.
    /// `diagnostics`: the board the namespace and the backend of `engine` read (an unused
    /// one when they do not); `sampler` takes its snapshots.
    pub fn start(
        engine: Engine,
        diagnostics: (Arc<Board>, Sampler),
        make_source: impl FnOnce(Arc<dyn Wake>) -> Result<Box<dyn Backend>, String>,
    ) -> Result<Arc<Runtime>, String> {
        let (board, sampler) = diagnostics;
        let signal = Arc::new(Signal::default());
        let waker: Arc<dyn Wake> = Arc::new(SourceWaker(Arc::downgrade(&signal)));
        let source = make_source(waker)?;
        let rt = Arc::new_cyclic(|me| Runtime {
            me: me.clone(),
            driver: Mutex::new(Driver::new(engine, source)),
            stop: AtomicBool::new(false),
            stepped: Condvar::new(),
            signal,
            sinks: Mutex::new(HashMap::new()),
            shutdown_sinks: Mutex::new(HashMap::new()),
            workers: Mutex::new(HashMap::new()),
            reports: Mutex::new(Vec::new()),
            driver_thread: Mutex::new(None),
            start_time: clock::now(),
            ops: crate::ops::Ops::default(),
            metrics: ctopc_core::metrics::Metrics::default(),
            diagnostics: board,
        });
        let weak = Arc::downgrade(&rt);
        let spawned = std::thread::Builder::new()
            .name("driver".into())
            .spawn(move || drive(weak, sampler));
        let handle = spawned.map_err(|e| format!("cannot start the driver thread: {e}"))?;
        *rt.driver_thread.lock().unwrap_or_else(|p| p.into_inner()) = Some(handle);
        Ok(rt)
    }

    /// Stops the driver thread and waits for it to end (not when called on the driver
    /// thread itself). Idempotent; the engine and the data source are dropped with the
    /// runtime.
    pub fn stop_driver(&self) {
        self.stop.store(true, Ordering::SeqCst);
        self.signal.wake();
        let handle = self
            .driver_thread
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take();
        if let Some(h) = handle {
            if h.thread().id() != std::thread::current().id() {
                let _ = h.join();
            }
        }
    }

    /// The engine and source, locked (keep the section short; never call a client inside).
    pub fn lock(&self) -> MutexGuard<'_, Driver> {
        self.driver.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Runs `f` on the engine with the current time, then wakes the driver so that what
    /// `f` queued (source requests, events) is handled at once.
    pub fn with_engine<R>(&self, f: impl FnOnce(&mut Engine, Timestamp) -> R) -> R {
        let r = {
            let mut g = self.lock();
            f(&mut g.engine, clock::now())
        };
        self.signal.wake();
        r
    }

    /// Waits until `poll` returns Some (checked now and after every driver step that
    /// completed a synchronous operation), at most `limit`.
    pub fn wait_for<R>(
        &self,
        limit: Duration,
        mut poll: impl FnMut(&mut Engine) -> Option<R>,
    ) -> Option<R> {
        let deadline = std::time::Instant::now() + limit;
        let mut g = self.lock();
        loop {
            if let Some(r) = poll(&mut g.engine) {
                return Some(r);
            }
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            if left.is_zero() {
                return None;
            }
            g = self
                .stepped
                .wait_timeout(g, left)
                .map(|(g, _)| g)
                .unwrap_or_else(|p| p.into_inner().0);
        }
    }

    pub fn wake(&self) {
        self.signal.wake();
    }

    /// Registers a new client session and its callback worker.
    pub fn open_session(&self) -> SessionHandle {
        let s = self.with_engine(|e, _| e.open_session());
        if let Some(w) = Worker::spawn(s) {
            self.workers
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .insert(s, w);
        }
        s
    }

    /// Ends a session: its groups go, its worker finishes what is queued and exits.
    pub fn close_session(&self, s: SessionHandle) {
        let _ = self.with_engine(|e, now| e.close_session(now, s));
        self.workers
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&s);
        self.shutdown_sinks
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&s);
        self.ops.forget(s);
    }

    /// Registers a group object's callback sinks: its IOPCDataCallback slot and its
    /// DA 1.0a advise connections.
    pub fn set_group_sink(
        &self,
        group: GroupHandle,
        slot: Arc<SinkSlot<IOPCDataCallback>>,
        da10: Arc<Da10Sinks>,
    ) {
        let old = self
            .sinks
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(group, (slot, da10));
        // Released after the lock.
        drop(old);
    }

    pub fn remove_group_sink(&self, group: GroupHandle) {
        let old = self
            .sinks
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&group);
        drop(old);
    }

    pub fn set_shutdown_sink(&self, session: SessionHandle, slot: Arc<SinkSlot<IOPCShutdown>>) {
        self.shutdown_sinks
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(session, slot);
    }

    /// Sends IOPCShutdown::ShutdownRequest(reason) to every connected client and waits
    /// (bounded) for the calls to return. Then stops the driver.
    pub fn shutdown(&self, reason: &str) {
        let slots: Vec<Arc<SinkSlot<IOPCShutdown>>> = self
            .shutdown_sinks
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .values()
            .cloned()
            .collect();
        let mut done = Vec::new();
        for slot in slots {
            let Some(sink) = slot.get() else { continue };
            let sink = Mta(sink);
            let reason: Vec<u16> = reason.encode_utf16().chain(std::iter::once(0)).collect();
            let (tx, rx) = mpsc::channel::<()>();
            let spawned = std::thread::Builder::new()
                .name("shutdown-request".into())
                .spawn(move || {
                    let _com = crate::apartment::Apartment::mta();
                    let sink = sink;
                    // SAFETY: `reason` is a NUL-terminated UTF-16 string alive for the call.
                    let r = unsafe { sink.0.ShutdownRequest(PCWSTR(reason.as_ptr())) };
                    if let Err(e) = r {
                        tracing::warn!("ShutdownRequest failed: {e}");
                    }
                    let _ = tx.send(());
                });
            if spawned.is_ok() {
                done.push(rx);
            }
        }
        for rx in done {
            let _ = rx.recv_timeout(Duration::from_secs(5));
        }
        self.stop.store(true, Ordering::SeqCst);
        self.signal.wake();
    }

    /// Queues events to their clients' workers. The update scheduler's OnDataChange calls
    /// are paced (`EngineConfig::max_pending_data_changes`): the engine hears when each one's
    /// delivery ended, or at once when it cannot be queued, so that a slow client gets
    /// coalesced updates instead of an unbounded queue.
    fn deliver(&self, events: Vec<Event>) {
        let (not_queued, drops) = {
            let sinks = self.sinks.lock().unwrap_or_else(|p| p.into_inner());
            let workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
            let mut queues = Queues {
                sinks: &sinks,
                workers: &workers,
                rt: &self.me,
                ops: &self.ops,
                metrics: &self.metrics,
                drops: Vec::new(),
            };
            let not_queued = driver::dispatch(events, &mut queues);
            (not_queued, queues.drops)
        };
        self.report(not_queued);
        for s in drops {
            self.drop_client_sinks(s);
        }
    }

    /// Checks the clients' calls under way against `CallbackTimeout` (every driver step):
    /// a paced call over its timeout is reported ended, a client at its failure limit loses
    /// its sinks.
    fn watch_callbacks(&self) {
        let verdicts = self.ops.poll_calls(clock::now());
        for (session, v) in verdicts {
            self.apply_verdict(session, v);
        }
    }

    fn apply_verdict(&self, session: SessionHandle, v: ctopc_core::ops::Verdict) {
        if v.failed {
            self.metrics.callback_failed();
        }
        if let Some(g) = v.ended {
            self.report([Report::Ended(g)]);
        }
        if v.drop_sinks {
            self.drop_client_sinks(session);
        }
    }

    /// A client reached `CallbackFailures`: its groups' IOPCDataCallback sinks are dropped
    /// and the engine told (`Report::Disconnected`), on a thread of its own, because
    /// releasing a hung client's proxy may itself hang.
    fn drop_client_sinks(&self, session: SessionHandle) {
        let groups = self.ops.groups_of(session);
        let slots: Vec<(GroupHandle, Arc<SinkSlot<IOPCDataCallback>>)> = {
            let sinks = self.sinks.lock().unwrap_or_else(|p| p.into_inner());
            groups
                .iter()
                .filter_map(|g| sinks.get(g).map(|(s, _)| (*g, Arc::clone(s))))
                .collect()
        };
        let (timeout, failures) = self.ops.callback_limits();
        tracing::warn!(
            "{}: {failures} consecutive callbacks failed or took longer than {timeout} ms \
             (CallbackTimeout, CallbackFailures); dropping its callback connections \
             (groups {:?})",
            self.ops.client_label(session),
            slots.iter().map(|(g, _)| g.0).collect::<Vec<_>>()
        );
        let rt = self.me.clone();
        let spawned = std::thread::Builder::new()
            .name(format!("drop-sinks-{}", session.0))
            .spawn(move || {
                let _com = crate::apartment::Apartment::mta();
                let mut lost = Vec::new();
                for (g, slot) in slots {
                    if slot.cookie().is_some_and(|c| slot.drop_if(c)) {
                        lost.push(Report::Disconnected(g));
                    }
                }
                if let Some(rt) = rt.upgrade() {
                    for _ in &lost {
                        rt.metrics.sink_dropped(false);
                    }
                    rt.report(lost);
                }
            });
        if let Err(e) = spawned {
            tracing::error!("cannot start a thread to drop a client's sinks: {e}");
        }
    }

    /// Takes the `_Diagnostics` snapshot from what the driver's step section read
    /// (`engine`) and the counters kept outside the lock (metrics, callback watches,
    /// client names), publishes it and wakes the driver, whose backend then sends the
    /// subscribed diagnostic items their samples.
    fn publish_diagnostics(&self, sampler: &mut Sampler, now: Timestamp, engine: DiagRead) {
        let (stats, sessions, channels) = engine;
        let m = self
            .metrics
            .snapshot(ctopc_core::metrics::Gauges::default());
        let server = ServerCounters {
            uptime_s: now.millis_since(self.start_time) / 1000,
            clients: stats.sessions as u64,
            groups: stats.groups as u64,
            items: stats.group_items as u64,
            callbacks_total: m.callbacks.iter().sum(),
            values_total: m.values_sent,
            failed_callbacks: m.callback_failures,
            dropped_sinks: m.dropped_disconnected + m.dropped_failures,
            pending_transactions: stats.pending_transactions as u64,
        };
        let clients = self.ops.client_counters(&sessions);
        let input = diagnostics::Input {
            server,
            clients,
            channels,
        };
        self.diagnostics.publish(sampler.sample(now, input));
        self.signal.wake();
    }

    /// Hands the workers' reports (a scheduled OnDataChange done with: delivered, failed or
    /// never queued; a sink lost) to the driver, which tells the engine at its next step.
    fn report(&self, reports: impl IntoIterator<Item = Report>) {
        let mut reports = reports.into_iter().peekable();
        if reports.peek().is_none() {
            return;
        }
        self.reports
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .extend(reports);
        self.signal.wake();
    }
}

/// The clients' callback queues, as the driver's [`Deliver`]: each event becomes a job on
/// its session's worker, which calls the group's sink (if still connected) and reports.
struct Queues<'a> {
    sinks: &'a HashMap<GroupHandle, GroupSinks>,
    workers: &'a HashMap<SessionHandle, Worker>,
    rt: &'a Weak<Runtime>,
    ops: &'a crate::ops::Ops,
    metrics: &'a ctopc_core::metrics::Metrics,
    /// Sessions whose sinks are to be dropped (after the tables are unlocked).
    drops: Vec<SessionHandle>,
}

impl Deliver for Queues<'_> {
    fn deliver(&mut self, event: Event, paced: bool) -> bool {
        let group = event.group();
        let session = event.session();
        let (Some((slot, da10)), Some(worker)) =
            (self.sinks.get(&group).cloned(), self.workers.get(&session))
        else {
            return false;
        };
        // Nothing is queued behind a call that is over its CallbackTimeout.
        match self.ops.admit(session, group) {
            ctopc_core::ops::Admit::Queue => {}
            ctopc_core::ops::Admit::Refuse => {
                self.metrics.callback_failed();
                return false;
            }
            ctopc_core::ops::Admit::Drop => {
                self.metrics.callback_failed();
                self.drops.push(session);
                return false;
            }
        }
        let rt = self.rt.clone();
        let job: Job = Box::new(move || {
            // The runtime is not kept alive across the call (a client may never return).
            match rt.upgrade() {
                Some(rt) => rt.ops.call_started(session, clock::now(), group, paced),
                None => return,
            }
            let (kind, values) = metric_kind(&event);
            let started = std::time::Instant::now();
            let (lost, called) = match dataobject::deliver(&da10, client_group(&event), &event) {
                // An IOPCAsyncIO completion went to the DA 1.0a sink (IAdviseSink returns
                // nothing: it cannot be lost).
                Routed::Mine => (false, true),
                Routed::Shared | Routed::NotMine => deliver_one(group, &slot, event),
            };
            let Some(rt) = rt.upgrade() else { return };
            if called {
                let us = u64::try_from(started.elapsed().as_micros()).unwrap_or(u64::MAX);
                rt.metrics.callback(kind, values, us);
            }
            if lost {
                rt.metrics.sink_dropped(true);
            }
            let verdict = rt.ops.call_finished(session, clock::now(), group, paced);
            if lost {
                rt.report([Report::Disconnected(group)]);
            }
            rt.apply_verdict(session, verdict);
        });
        worker.tx.send(job).is_ok()
    }
}

/// The driver thread: a step whenever woken or due, then the events to the workers.
fn drive(rt: Weak<Runtime>, mut sampler: Sampler) {
    let _com = crate::apartment::Apartment::mta();
    loop {
        let Some(rt) = rt.upgrade() else { return };
        if rt.stop.load(Ordering::SeqCst) {
            return;
        }
        let mut reports =
            std::mem::take(&mut *rt.reports.lock().unwrap_or_else(|p| p.into_inner()));
        let step = {
            let mut d = rt.lock();
            // A lost sink whose group has a sink again was re-advised meanwhile: that
            // Advise told the engine (or will, after this section), so the loss is stale.
            // Checked under the engine lock, which the Advise takes after filling the slot.
            if reports.iter().any(|r| matches!(r, Report::Disconnected(_))) {
                let sinks = rt.sinks.lock().unwrap_or_else(|p| p.into_inner());
                reports.retain(|r| match r {
                    Report::Disconnected(g) => !sinks
                        .get(g)
                        .is_some_and(|(s, da10)| s.is_connected() || da10.any()),
                    Report::Ended(_) => true,
                });
            }
            let now = clock::now();
            let step = d.step(now, reports);
            // At most once per second, in the section the step holds anyway.
            let diag = sampler.due(now).then(|| {
                (
                    now,
                    (d.engine.stats(), d.engine.session_stats(), d.channels()),
                )
            });
            (step, diag)
        };
        let (step, diag) = step;
        if let Some((now, read)) = diag {
            rt.publish_diagnostics(&mut sampler, now, read);
        }
        if !step.sync_completed.is_empty() {
            // The waiters take their own results (`Engine::take_sync_result`).
            rt.stepped.notify_all();
        }
        rt.watch_callbacks();
        if !step.events.is_empty() {
            audit_write_completions(&rt, &step.events);
            rt.deliver(step.events);
        }
        let wait = match step.next {
            Some(t) => Duration::from_millis(t.millis_since(clock::now()).clamp(1, 1000)),
            None => Duration::from_millis(1000),
        };
        let signal = Arc::clone(&rt.signal);
        drop(rt);
        signal.wait(wait);
    }
}

/// The write audit's lines of the OnWriteCompletes of a step (the group names taken in a
/// short engine section of their own; nothing when auditing is off).
fn audit_write_completions(rt: &Runtime, events: &[Event]) {
    if !rt.ops.auditing() {
        return;
    }
    let writes: Vec<&ctopc_core::model::WriteComplete> = events
        .iter()
        .filter_map(|e| match e {
            Event::WriteComplete(w) => Some(w),
            _ => None,
        })
        .collect();
    if writes.is_empty() {
        return;
    }
    let names: Vec<Option<String>> = {
        let d = rt.lock();
        writes
            .iter()
            .map(|w| d.engine.audit_group_name(w.group))
            .collect()
    };
    let now = clock::now();
    for (w, name) in writes.iter().zip(&names) {
        rt.ops.audit_complete(now, name.as_deref(), w);
    }
}

/// True for the errors that mean the client is gone.
pub fn is_disconnected(hr: HRESULT) -> bool {
    const CODES: [u32; 6] = [
        0x80010108, // RPC_E_DISCONNECTED
        0x800706BA, // RPC_S_SERVER_UNAVAILABLE
        0x800706BF, // RPC_S_CALL_FAILED_DNE
        0x80010012, // RPC_E_SERVER_DIED_DNE
        0x80010007, // RPC_E_SERVER_DIED
        0x800401FD, // CO_E_OBJNOTCONNECTED
    ];
    CODES.contains(&(hr.0 as u32))
}

/// A group's callback sinks: IOPCDataCallback's slot and the DA 1.0a connections.
type GroupSinks = (Arc<SinkSlot<IOPCDataCallback>>, Arc<Da10Sinks>);

/// The group's client handle an event carries.
fn client_group(event: &Event) -> u32 {
    match event {
        Event::DataChange(e) => e.client_group,
        Event::ReadComplete(e) => e.client_group,
        Event::WriteComplete(e) => e.client_group,
        Event::CancelComplete(e) => e.client_group,
    }
}

fn hr_of(e: Option<OpcError>) -> HRESULT {
    e.map_or(HRESULT(0), error::hresult)
}

/// The metrics' kind of a callback and the values it carries.
fn metric_kind(event: &Event) -> (ctopc_core::metrics::CallbackKind, u64) {
    use ctopc_core::metrics::CallbackKind as K;
    match event {
        Event::DataChange(d) => (K::DataChange, d.items.len() as u64),
        Event::ReadComplete(d) => (K::ReadComplete, d.items.len() as u64),
        Event::WriteComplete(_) => (K::WriteComplete, 0),
        Event::CancelComplete(_) => (K::CancelComplete, 0),
    }
}

/// Delivers one event to a group's sink on the client's worker thread: (the client is
/// gone and its sink was dropped, so the engine must hear of it; a call was made).
fn deliver_one(
    group: GroupHandle,
    slot: &SinkSlot<IOPCDataCallback>,
    event: Event,
) -> (bool, bool) {
    let (Some(sink), Some(cookie)) = (slot.get(), slot.cookie()) else {
        return (false, false);
    };
    let result = match &event {
        // A large subscription update goes in calls of at most MAX_ITEMS_PER_CALLBACK
        // items (`DataChange::calls`), one after the other, with the same buffers; a
        // failed call ends it (the client is gone, or refuses).
        Event::DataChange(d) => {
            let mut buffers = CallBuffers::default();
            d.calls()
                .into_iter()
                .try_for_each(|(quality, error, items)| {
                    buffers.call(
                        &sink,
                        true,
                        d.transaction_id,
                        d.client_group,
                        quality,
                        error,
                        items,
                    )
                })
        }
        Event::ReadComplete(d) => CallBuffers::default().call(
            &sink,
            false,
            d.transaction_id,
            d.client_group,
            d.master_quality,
            d.master_error,
            &d.items,
        ),
        Event::WriteComplete(d) => {
            let handles: Vec<u32> = d.items.iter().map(|i| i.client_handle).collect();
            let errors: Vec<HRESULT> = d.items.iter().map(|i| hr_of(i.error)).collect();
            // SAFETY: the arrays hold `handles.len()` elements and live for the call.
            unsafe {
                sink.OnWriteComplete(
                    d.transaction_id,
                    d.client_group,
                    hr_of(d.master_error),
                    handles.len() as u32,
                    handles.as_ptr(),
                    errors.as_ptr(),
                )
            }
        }
        // SAFETY: plain values.
        Event::CancelComplete(d) => unsafe {
            sink.OnCancelComplete(d.transaction_id, d.client_group)
        },
    };
    if let Err(e) = result {
        if is_disconnected(e.code()) {
            tracing::warn!(
                "group {}: the client's IOPCDataCallback is gone ({e}); dropping it",
                group.0
            );
            return (slot.drop_if(cookie), true);
        }
        tracing::debug!("group {}: callback returned {e}", group.0);
    }
    (false, true)
}

/// The arrays of one OnDataChange / OnReadComplete call, kept from call to call of a split
/// update so that each call of it reuses them instead of allocating its own.
#[derive(Default)]
struct CallBuffers {
    handles: Vec<u32>,
    qualities: Vec<u16>,
    times: Vec<FILETIME>,
    errors: Vec<HRESULT>,
    values: Vec<VARIANT>,
}

impl CallBuffers {
    #[allow(clippy::too_many_arguments)]
    fn call(
        &mut self,
        sink: &IOPCDataCallback,
        data_change: bool,
        transaction: u32,
        client_group: u32,
        master_quality: Option<OpcError>,
        master_error: Option<OpcError>,
        items: &[ctopc_core::model::ItemValue],
    ) -> windows::core::Result<()> {
        self.handles.clear();
        self.handles.extend(items.iter().map(|i| i.client_handle));
        self.qualities.clear();
        self.qualities.extend(items.iter().map(|i| i.quality.0));
        self.times.clear();
        self.times
            .extend(items.iter().map(|i| clock::filetime(i.timestamp)));
        self.errors.clear();
        self.errors.extend(items.iter().map(|i| hr_of(i.error)));
        self.values.clear();
        self.values.extend(
            items
                .iter()
                .map(|i| variant::to_variant(&i.value).unwrap_or_default()),
        );
        let n = items.len() as u32;
        let (handles, values, qualities, times, errors) = (
            self.handles.as_ptr(),
            self.values.as_ptr(),
            self.qualities.as_ptr(),
            self.times.as_ptr(),
            self.errors.as_ptr(),
        );
        // SAFETY: every array holds `n` elements and lives for the call; the VARIANTs are
        // cleared below.
        let r = unsafe {
            if data_change {
                sink.OnDataChange(
                    transaction,
                    client_group,
                    hr_of(master_quality),
                    hr_of(master_error),
                    n,
                    handles,
                    values,
                    qualities,
                    times,
                    errors,
                )
            } else {
                sink.OnReadComplete(
                    transaction,
                    client_group,
                    hr_of(master_quality),
                    hr_of(master_error),
                    n,
                    handles,
                    values,
                    qualities,
                    times,
                    errors,
                )
            }
        };
        for v in self.values.iter_mut() {
            variant::clear(v);
        }
        r
    }
}
