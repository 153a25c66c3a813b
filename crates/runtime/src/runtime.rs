//! The runtime: the engine (shared by every client of one server), the data source, one
//! driver thread that runs the scheduler and moves data between them, and one callback
//! worker per client session so that a slow or dead client never stalls another. A
//! runtime belongs to one server object graph (no process-wide runtime): the driver
//! thread holds only a weak reference and is stopped and joined by
//! [`Runtime::stop_driver`]; a worker ends when its session closes.
//!
//! The step itself and the pacing bookkeeping are pure and tested natively
//! (`ctopc_core::driver`); this module owns the threads, the condvars and the worker
//! queues. How a callback reaches a client is the front end's ([`GroupSink`]).
//!
//! The driver loop is step, deliver, wait: one [`Driver::step`] under the `driver` lock
//! (with the `_Diagnostics` read when due), then the operations told the step is done
//! (the sync waiters, the callback watch, the write audit), then the events queued to the
//! clients' workers, then a wait for a wake-up or the next due time.
//!
//! Locks (the order, where two are held together: `driver` → `sinks` → `clients`'
//! `watches`):
//! - `driver` (engine + source): short, non-blocking sections only; no client is called
//!   while it is held, and no callback worker ever waits for it (workers report back
//!   through `reports`).
//! - `sinks`: the groups' sinks and the sessions' workers and shutdown sinks, one table.
//!   Held to queue a step's events (with `watches` nested, for the admission of each) and
//!   in the driver's check of stale losses (nested in `driver`).
//! - `reports`, `signal` (the wake-up), `stepped`'s mutex (`driver`), and the leaves of
//!   [`Clients`] (`names`, `watches`): never held while taking another.
//!
//! Subscription callbacks are paced by their delivery (at most
//! `EngineConfig::max_pending_data_changes` per group under way), so a slow or hung client
//! costs the server that many pending updates per group, not a backlog.

use crate::clients::Clients;
use crate::clock;
use crate::frontend::{GroupSink, SessionSink, ThreadHook};
use ctopc_core::diagnostics::{self, Board, ChannelStatus, Sampler, ServerCounters};
use ctopc_core::driver::{self, Deliver, Driver, Report};
use ctopc_core::metrics::{CallbackKind, Metrics};
use ctopc_core::model::{Engine, Event, GroupHandle, SessionHandle};
use ctopc_core::source::{Backend, Wake};
use ctopc_core::Timestamp;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, Weak};
use std::time::Duration;

/// How long a synchronous call waits for the data source at most, beyond the engine's own
/// source timeout (which completes such requests with ASKOM_E_NetAnswerTimeout).
pub const SYNC_WAIT_MARGIN: Duration = Duration::from_secs(2);

/// How long [`Runtime::shutdown`] waits for each client's shutdown request to return.
const SHUTDOWN_REQUEST_WAIT: Duration = Duration::from_secs(5);

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

#[derive(Default)]
struct Signal {
    woken: Mutex<bool>,
    cv: Condvar,
}

impl Signal {
    fn wake(&self) {
        *lock(&self.woken) = true;
        self.cv.notify_all();
    }
    fn wait(&self, limit: Duration) {
        let mut w = lock(&self.woken);
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

/// A client's callback worker: a thread running queued deliveries in order.
struct Worker {
    tx: mpsc::Sender<Job>,
}

impl Worker {
    fn spawn(session: SessionHandle, hook: ThreadHook) -> Option<Worker> {
        let (tx, rx) = mpsc::channel::<Job>();
        std::thread::Builder::new()
            .name(format!("callbacks-{}", session.0))
            .spawn(move || {
                let _state = hook();
                while let Ok(job) = rx.recv() {
                    job();
                }
            })
            .ok()?;
        Some(Worker { tx })
    }
}

/// The front end's sinks and the sessions' workers, one table under one lock.
#[derive(Default)]
struct Sinks {
    groups: HashMap<GroupHandle, Arc<dyn GroupSink>>,
    workers: HashMap<SessionHandle, Worker>,
    sessions: HashMap<SessionHandle, Arc<dyn SessionSink>>,
}

/// The server's runtime (see the module doc). Its driver thread stops with
/// [`Runtime::stop_driver`] (the owner calls it when the last object of the server has
/// gone) or when the runtime drops.
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
    sinks: Mutex<Sinks>,
    /// What the workers report (a scheduled OnDataChange ended, a sink was lost), for the
    /// driver to tell the engine at its next step: a worker never waits for the engine's
    /// lock, it goes on with its next call.
    reports: Mutex<Vec<Report>>,
    /// The driver thread, joined by [`Runtime::stop_driver`].
    driver_thread: Mutex<Option<std::thread::JoinHandle<()>>>,
    /// Run first on every thread the runtime starts.
    thread_hook: ThreadHook,
    pub start_time: Timestamp,
    /// The client names, the write audit and the callback watches.
    pub clients: Clients,
    /// The counters and histograms (`ctopc_core::metrics`, served by
    /// [`crate::metrics_http`]).
    pub metrics: Metrics,
    /// Where the driver thread publishes the `_Diagnostics` snapshot, at most once per
    /// second (read by the namespace, the backend and browsing:
    /// `ctopc_core::diagnostics`).
    pub diagnostics: Arc<Board>,
}

/// What a step section reads for the diagnostics snapshot: the engine's statistics, per
/// session its groups and items, the backend's channels.
type DiagRead = (
    ctopc_core::model::EngineStats,
    Vec<(SessionHandle, usize, usize)>,
    Vec<ChannelStatus>,
);

impl Runtime {
    /// Starts the runtime and its driver thread. `make_source` gets the waker to call
    /// when data arrives from another thread. `diagnostics`: the board the namespace and
    /// the backend of `engine` read (an unused one when they do not); `sampler` takes its
    /// snapshots. `thread_hook` runs first on every thread the runtime starts.
    pub fn start(
        engine: Engine,
        diagnostics: (Arc<Board>, Sampler),
        thread_hook: ThreadHook,
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
            sinks: Mutex::default(),
            reports: Mutex::new(Vec::new()),
            driver_thread: Mutex::new(None),
            thread_hook,
            start_time: clock::now(),
            clients: Clients::default(),
            metrics: Metrics::default(),
            diagnostics: board,
        });
        let weak = Arc::downgrade(&rt);
        let spawned = std::thread::Builder::new()
            .name("driver".into())
            .spawn(move || drive(weak, sampler, thread_hook));
        let handle = spawned.map_err(|e| format!("cannot start the driver thread: {e}"))?;
        *lock(&rt.driver_thread) = Some(handle);
        Ok(rt)
    }

    /// Stops the driver thread and waits for it to end (not when called on the driver
    /// thread itself). Idempotent; the engine and the data source are dropped with the
    /// runtime.
    pub fn stop_driver(&self) {
        self.stop.store(true, Ordering::SeqCst);
        self.signal.wake();
        let handle = lock(&self.driver_thread).take();
        if let Some(h) = handle {
            if h.thread().id() != std::thread::current().id() {
                let _ = h.join();
            }
        }
    }

    /// The engine and source, locked (keep the section short; never call a client inside).
    pub fn lock(&self) -> MutexGuard<'_, Driver> {
        lock(&self.driver)
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

    /// Logs a WARN for the items of a write (`handles` of `group`, with their `results`)
    /// that the namespace refuses by design (OPC_E_BADRIGHTS with a
    /// [`ctopc_core::namespace::Namespace::write_refusal`] reason): one line per call,
    /// with how many, the first item and why. Nothing when no item was refused so.
    pub fn warn_refused_writes(
        &self,
        group: GroupHandle,
        handles: &[u32],
        results: &[Result<(), ctopc_core::OpcError>],
    ) {
        let refused: Vec<u32> = handles
            .iter()
            .zip(results)
            .filter(|(_, r)| matches!(r, Err(ctopc_core::OpcError::BadRights)))
            .map(|(h, _)| *h)
            .collect();
        if refused.is_empty() {
            return;
        }
        let reasons = self.lock().engine.write_refusals(group, &refused);
        if let Some((item, why)) = reasons.first() {
            tracing::warn!(
                "write refused (OPC_E_BADRIGHTS) for {} item(s) of group {}, {item} first: {why}",
                reasons.len(),
                group.0
            );
        }
    }

    /// Wakes the driver thread for a step now.
    pub fn wake(&self) {
        self.signal.wake();
    }

    /// Registers a new client session and its callback worker.
    pub fn open_session(&self) -> SessionHandle {
        let s = self.with_engine(|e, _| e.open_session());
        if let Some(w) = Worker::spawn(s, self.thread_hook) {
            lock(&self.sinks).workers.insert(s, w);
        }
        s
    }

    /// Who `session`'s caller is: the engine decides writes by it
    /// (`Engine::set_session_caller`), the audit and `_Diagnostics` show it. A front end
    /// says it when the session opens and before each write.
    pub fn set_caller(&self, session: SessionHandle, caller: ctopc_core::write_rights::Caller) {
        let text = caller.to_string();
        self.lock().engine.set_session_caller(session, caller);
        self.clients.set_identity(session, &text);
    }

    /// Ends a session: its groups go, its worker finishes what is queued and exits.
    pub fn close_session(&self, s: SessionHandle) {
        let _ = self.with_engine(|e, now| e.close_session(now, s));
        let old = {
            let mut sinks = lock(&self.sinks);
            (sinks.workers.remove(&s), sinks.sessions.remove(&s))
        };
        // Released after the lock.
        drop(old);
        self.clients.forget(s);
    }

    /// Registers a group's connection to its client (replacing the one it had).
    pub fn set_group_sink(&self, group: GroupHandle, sink: Arc<dyn GroupSink>) {
        let old = lock(&self.sinks).groups.insert(group, sink);
        // Released after the lock.
        drop(old);
    }

    /// The group has gone: its connection is forgotten.
    pub fn remove_group_sink(&self, group: GroupHandle) {
        let old = lock(&self.sinks).groups.remove(&group);
        drop(old);
    }

    /// Registers a session's shutdown listener (replacing the one it had).
    pub fn set_session_sink(&self, session: SessionHandle, sink: Arc<dyn SessionSink>) {
        let old = lock(&self.sinks).sessions.insert(session, sink);
        drop(old);
    }

    /// Sends the shutdown request with `reason` to every connected client and waits
    /// (bounded) for the calls to return. Then stops the driver.
    pub fn shutdown(&self, reason: &str) {
        let sinks: Vec<Arc<dyn SessionSink>> =
            lock(&self.sinks).sessions.values().cloned().collect();
        let mut done = Vec::new();
        for sink in sinks {
            let (tx, rx) = mpsc::channel::<()>();
            let reason = reason.to_owned();
            let hook = self.thread_hook;
            let spawned = std::thread::Builder::new()
                .name("shutdown-request".into())
                .spawn(move || {
                    let _state = hook();
                    sink.shutdown_request(&reason);
                    let _ = tx.send(());
                });
            if spawned.is_ok() {
                done.push(rx);
            }
        }
        for rx in done {
            let _ = rx.recv_timeout(SHUTDOWN_REQUEST_WAIT);
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
            let sinks = lock(&self.sinks);
            let mut queues = Queues {
                sinks: &sinks,
                rt: &self.me,
                clients: &self.clients,
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
        let verdicts = self.clients.poll_calls(clock::now());
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

    /// A client reached `CallbackFailures`: its groups' listeners are dropped and the engine
    /// told (`Report::Disconnected`), on a thread of its own, because releasing a hung
    /// client may itself hang.
    fn drop_client_sinks(&self, session: SessionHandle) {
        let groups = self.clients.groups_of(session);
        let dropping: Vec<(GroupHandle, Arc<dyn GroupSink>)> = {
            let sinks = lock(&self.sinks);
            groups
                .iter()
                .filter_map(|g| sinks.groups.get(g).map(|s| (*g, Arc::clone(s))))
                .collect()
        };
        let (timeout, failures) = self.clients.callback_limits();
        tracing::warn!(
            "{}: {failures} consecutive callbacks failed or took longer than {timeout} ms \
             (CallbackTimeout, CallbackFailures); dropping its callback connections \
             (groups {:?})",
            self.clients.client_label(session),
            dropping.iter().map(|(g, _)| g.0).collect::<Vec<_>>()
        );
        let rt = self.me.clone();
        let hook = self.thread_hook;
        let spawned = std::thread::Builder::new()
            .name(format!("drop-sinks-{}", session.0))
            .spawn(move || {
                let _state = hook();
                let mut lost = Vec::new();
                for (g, sink) in dropping {
                    if sink.drop_listener() {
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
        let clients = self.clients.client_counters(&sessions);
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
        lock(&self.reports).extend(reports);
        self.signal.wake();
    }

    /// The driver's step section: the workers' reports (less the stale losses), one
    /// [`Driver::step`], and the `_Diagnostics` read when `sampler` says it is due.
    fn step(&self, sampler: &Sampler) -> (driver::Step, Option<(Timestamp, DiagRead)>) {
        let mut reports = std::mem::take(&mut *lock(&self.reports));
        let mut d = self.lock();
        // A lost sink whose group has a listener again was re-advised meanwhile: that
        // Advise told the engine (or will, after this section), so the loss is stale.
        // Checked under the engine lock, which the Advise takes after filling the slot.
        if reports.iter().any(|r| matches!(r, Report::Disconnected(_))) {
            let sinks = lock(&self.sinks);
            reports.retain(|r| match r {
                Report::Disconnected(g) => !sinks.groups.get(g).is_some_and(|s| s.is_connected()),
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
    }

    /// What the operations hear of a step: the synchronous callers whose answer came, the
    /// callback watch, the `_Diagnostics` board when due, the write audit of its
    /// OnWriteCompletes.
    fn step_done(
        &self,
        step: &driver::Step,
        sampler: &mut Sampler,
        diag: Option<(Timestamp, DiagRead)>,
    ) {
        if let Some((now, read)) = diag {
            self.publish_diagnostics(sampler, now, read);
        }
        if !step.sync_completed.is_empty() {
            // The waiters take their own results (`Engine::take_sync_result`).
            self.stepped.notify_all();
        }
        self.watch_callbacks();
        self.audit_write_completions(&step.events);
    }

    /// The write audit's lines of the OnWriteCompletes of a step (the group names taken in
    /// a short engine section of their own; nothing when auditing is off).
    fn audit_write_completions(&self, events: &[Event]) {
        if !self.clients.auditing() {
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
            let d = self.lock();
            writes
                .iter()
                .map(|w| d.engine.audit_group_name(w.group))
                .collect()
        };
        let now = clock::now();
        for (w, name) in writes.iter().zip(&names) {
            self.clients.audit_complete(now, name.as_deref(), w);
        }
    }
}

impl Drop for Runtime {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        self.signal.wake();
    }
}

/// The clients' callback queues, as the driver's [`Deliver`]: each event becomes a job on
/// its session's worker, which hands it to the group's sink and reports.
struct Queues<'a> {
    sinks: &'a Sinks,
    rt: &'a Weak<Runtime>,
    clients: &'a Clients,
    metrics: &'a Metrics,
    /// Sessions whose sinks are to be dropped (after the tables are unlocked).
    drops: Vec<SessionHandle>,
}

impl Deliver for Queues<'_> {
    fn deliver(&mut self, event: Event, paced: bool) -> bool {
        let group = event.group();
        let session = event.session();
        let (Some(sink), Some(worker)) = (
            self.sinks.groups.get(&group).cloned(),
            self.sinks.workers.get(&session),
        ) else {
            return false;
        };
        // Nothing is queued behind a call that is over its CallbackTimeout.
        match self.clients.admit(session, group) {
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
                Some(rt) => rt.clients.call_started(session, clock::now(), group, paced),
                None => return,
            }
            let (kind, values) = metric_kind(&event);
            let started = std::time::Instant::now();
            let delivery = sink.deliver(group, event);
            let Some(rt) = rt.upgrade() else { return };
            if delivery.called {
                let us = u64::try_from(started.elapsed().as_micros()).unwrap_or(u64::MAX);
                rt.metrics.callback(kind, values, us);
            }
            if delivery.lost {
                rt.metrics.sink_dropped(true);
            }
            let verdict = rt
                .clients
                .call_finished(session, clock::now(), group, paced);
            if delivery.lost {
                rt.report([Report::Disconnected(group)]);
            }
            rt.apply_verdict(session, verdict);
        });
        worker.tx.send(job).is_ok()
    }
}

/// The driver thread: step, deliver, wait.
fn drive(rt: Weak<Runtime>, mut sampler: Sampler, hook: ThreadHook) {
    let _state = hook();
    loop {
        let Some(rt) = rt.upgrade() else { return };
        if rt.stop.load(Ordering::SeqCst) {
            return;
        }
        let (step, diag) = rt.step(&sampler);
        rt.step_done(&step, &mut sampler, diag);
        if !step.events.is_empty() {
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

/// The metrics' kind of a callback and the values it carries.
fn metric_kind(event: &Event) -> (CallbackKind, u64) {
    match event {
        Event::DataChange(d) => (CallbackKind::DataChange, d.items.len() as u64),
        Event::ReadComplete(d) => (CallbackKind::ReadComplete, d.items.len() as u64),
        Event::WriteComplete(_) => (CallbackKind::WriteComplete, 0),
        Event::CancelComplete(_) => (CallbackKind::CancelComplete, 0),
    }
}
