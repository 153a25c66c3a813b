//! Lifetime of a served context: a [`Lifetime`] counts the live COM objects that keep the
//! server up ([`ObjectGuard`]) and the IClassFactory::LockServer locks, holds the stop
//! request and its reason, and wakes whoever waits for the server to become unused
//! (`host::serve_as`). It is an object, one per context (`Context::lifetime`), handed to
//! the objects that count: no process-wide counters.
//!
//! The stop request comes from outside through a [`StopSignal`], a parameter of
//! `host::serve_as`: the console handler (`host::stop_on_console_ctrl`) and the NT service's
//! stop (`service::run`) only *trigger* it; `serve_as` forwards it to the context's
//! lifetime ([`Lifetime::stop_on`]).

use std::sync::{Arc, Condvar, Mutex, Weak};
use std::time::{Duration, Instant};

#[derive(Default)]
struct Counts {
    objects: usize,
    locks: usize,
    ever_used: bool,
    /// Objects made and LockServer locks taken so far (never decreases): tells whether a
    /// client came in a window even if it left again ([`Lifetime::stays_unused`]).
    arrivals: u64,
    /// The reason of a requested stop (what clients get in IOPCShutdown), once requested.
    stop: Option<&'static str>,
}

/// The reason given when a stop was requested without one.
pub const DEFAULT_STOP_REASON: &str = "ServerCTOPC is stopping";

/// The counts and the stop request of one context (see the module documentation).
#[derive(Default)]
pub struct Lifetime {
    counts: Mutex<Counts>,
    changed: Condvar,
}

impl Lifetime {
    pub fn new() -> Arc<Lifetime> {
        Arc::new(Lifetime::default())
    }

    fn with<R>(&self, f: impl FnOnce(&mut Counts) -> R) -> R {
        let mut g = self.counts.lock().unwrap_or_else(|p| p.into_inner());
        let r = f(&mut g);
        self.changed.notify_all();
        r
    }

    /// IClassFactory::LockServer.
    pub fn lock_server(&self, lock: bool) {
        self.with(|c| {
            if lock {
                c.locks += 1;
                c.ever_used = true;
                c.arrivals += 1;
            } else {
                c.locks = c.locks.saturating_sub(1);
            }
        });
    }

    /// Asks the serving loop to stop; `reason` is what clients get in IOPCShutdown (a
    /// later request's reason replaces an earlier one's).
    pub fn request_stop(&self, reason: &'static str) {
        self.with(|c| c.stop = Some(reason));
    }

    /// Forwards `signal` to this lifetime: a trigger (earlier or later) requests the stop.
    /// The signal holds only a weak reference.
    pub fn stop_on(self: &Arc<Self>, signal: &StopSignal) {
        let me: Weak<Lifetime> = Arc::downgrade(self);
        signal.subscribe(Box::new(move |reason| {
            if let Some(l) = me.upgrade() {
                l.request_stop(reason);
            }
        }));
    }

    /// The reason of a requested stop ([`DEFAULT_STOP_REASON`] if none was requested).
    pub fn stop_reason(&self) -> &'static str {
        self.with(|c| c.stop.unwrap_or(DEFAULT_STOP_REASON))
    }

    /// Blocks until a stop is requested (the NT service serves until the SCM stops it).
    pub fn wait_for_stop(&self) {
        let mut g = self.counts.lock().unwrap_or_else(|p| p.into_inner());
        while g.stop.is_none() {
            g = self.changed.wait(g).unwrap_or_else(|p| p.into_inner());
        }
    }

    /// Blocks until the server is unused: every object and lock released after at least
    /// one client came (and still so `linger` later: a client that connects right after
    /// the last one left must not reach a process that is revoking its class object), or
    /// no client within `grace` of start, or a stop was requested.
    pub fn wait_until_unused(&self, grace: Duration, linger: Duration) -> ExitReason {
        let start = Instant::now();
        let mut idle_since: Option<Instant> = None;
        let mut g = self.counts.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            if g.stop.is_some() {
                return ExitReason::StopRequested;
            }
            if g.ever_used && g.objects == 0 && g.locks == 0 {
                let since = *idle_since.get_or_insert_with(Instant::now);
                if since.elapsed() >= linger {
                    return ExitReason::LastClientGone;
                }
                let left = linger
                    .saturating_sub(since.elapsed())
                    .max(Duration::from_millis(10));
                g = self
                    .changed
                    .wait_timeout(g, left)
                    .map(|(g, _)| g)
                    .unwrap_or_else(|p| p.into_inner().0);
                continue;
            }
            idle_since = None;
            if !g.ever_used && start.elapsed() >= grace {
                return ExitReason::NeverUsed;
            }
            let wait = if g.ever_used {
                Duration::from_secs(1)
            } else {
                grace
                    .saturating_sub(start.elapsed())
                    .max(Duration::from_millis(10))
            };
            g = self
                .changed
                .wait_timeout(g, wait)
                .map(|(g, _)| g)
                .unwrap_or_else(|p| p.into_inner().0);
        }
    }

    /// After the class object was revoked: waits `settle` and tells whether the server
    /// stayed unused all along (no object made, no lock taken in the window, none held at
    /// its end) or a stop was requested. `false` means a client reached the server while
    /// it was deciding to exit (it had the class object from the system just before the
    /// revoke: `wait_until_unused` returned, then its CreateInstance came), so the server
    /// must register its class object again and serve on instead of exiting under that
    /// client. Returns as soon as a client comes.
    pub fn stays_unused(&self, settle: Duration) -> bool {
        let start = Instant::now();
        let mut g = self.counts.lock().unwrap_or_else(|p| p.into_inner());
        let arrivals = g.arrivals;
        loop {
            if g.stop.is_some() {
                return true;
            }
            if g.arrivals != arrivals || g.objects > 0 || g.locks > 0 {
                return false;
            }
            let left = settle.saturating_sub(start.elapsed());
            if left.is_zero() {
                return true;
            }
            g = self
                .changed
                .wait_timeout(g, left)
                .map(|(g, _)| g)
                .unwrap_or_else(|p| p.into_inner().0);
        }
    }
}

/// A live COM object that keeps its context's server up (held by every server object,
/// group object and item-attributes enumerator). Cloning counts one more object.
pub struct ObjectGuard(Arc<Lifetime>);

impl ObjectGuard {
    pub fn new(lifetime: &Arc<Lifetime>) -> Self {
        lifetime.with(|c| {
            c.objects += 1;
            c.ever_used = true;
            c.arrivals += 1;
        });
        ObjectGuard(Arc::clone(lifetime))
    }
}

impl Clone for ObjectGuard {
    fn clone(&self) -> Self {
        ObjectGuard::new(&self.0)
    }
}

impl Drop for ObjectGuard {
    fn drop(&mut self) {
        self.0.with(|c| c.objects = c.objects.saturating_sub(1));
    }
}

/// Why `wait_until_unused` returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitReason {
    /// The last client released its last object.
    LastClientGone,
    /// Nobody connected within the start-up grace period.
    NeverUsed,
    StopRequested,
}

type Listener = Box<dyn Fn(&'static str) + Send + Sync>;

#[derive(Default)]
struct SignalState {
    /// The last trigger's reason.
    reason: Option<&'static str>,
    listeners: Vec<Listener>,
}

/// The shutdown signal of a served context (cheap to clone; every clone is the same
/// signal): whoever may stop the server (the console handler, the NT service's control
/// handler, a test) [`trigger`](Self::trigger)s it, `host::serve_as` listens to it.
#[derive(Clone, Default)]
pub struct StopSignal(Arc<Mutex<SignalState>>);

impl StopSignal {
    pub fn new() -> StopSignal {
        StopSignal::default()
    }

    /// Requests the stop, with the reason clients get in IOPCShutdown (a later trigger's
    /// reason replaces an earlier one's).
    pub fn trigger(&self, reason: &'static str) {
        let mut s = self.0.lock().unwrap_or_else(|p| p.into_inner());
        s.reason = Some(reason);
        for l in &s.listeners {
            l(reason);
        }
    }

    /// The reason, once triggered.
    pub fn triggered(&self) -> Option<&'static str> {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).reason
    }

    /// Calls `f` on a trigger (at once if already triggered): for a serving function that
    /// is not a COM context (asix-gate's service). `f` runs under the signal's lock: it
    /// must not trigger or subscribe to this signal.
    pub fn on_trigger(&self, f: impl Fn(&'static str) + Send + Sync + 'static) {
        self.subscribe(Box::new(f));
    }

    /// Calls `f` on a trigger (at once if already triggered). `f` runs under the signal's
    /// lock: it must not trigger or subscribe to this signal.
    fn subscribe(&self, f: Listener) {
        let mut s = self.0.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(r) = s.reason {
            f(r);
        }
        s.listeners.push(f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SHORT: Duration = Duration::from_millis(50);

    #[test]
    fn never_used_after_the_grace_period() {
        let l = Lifetime::new();
        assert_eq!(l.wait_until_unused(SHORT, SHORT), ExitReason::NeverUsed);
    }

    #[test]
    fn last_client_gone_once_every_object_and_lock_is_released() {
        let l = Lifetime::new();
        let g = ObjectGuard::new(&l);
        let g2 = g.clone();
        l.lock_server(true);
        drop(g);
        drop(g2);
        let waiter = {
            let l = Arc::clone(&l);
            std::thread::spawn(move || l.wait_until_unused(Duration::from_secs(30), SHORT))
        };
        std::thread::sleep(SHORT * 2);
        assert!(
            !waiter.is_finished(),
            "a LockServer lock keeps the server up"
        );
        l.lock_server(false);
        assert_eq!(waiter.join().unwrap(), ExitReason::LastClientGone);
    }

    #[test]
    fn stays_unused_when_no_client_comes_within_the_settle_time() {
        let l = Lifetime::new();
        drop(ObjectGuard::new(&l));
        let start = Instant::now();
        assert!(l.stays_unused(SHORT));
        assert!(start.elapsed() >= SHORT, "it waits the whole settle time");
    }

    #[test]
    fn a_client_that_comes_during_the_settle_time_keeps_the_server() {
        // One arriving (and holding an object) while the server settles.
        let l = Lifetime::new();
        let waiter = {
            let l = Arc::clone(&l);
            std::thread::spawn(move || {
                let start = Instant::now();
                (l.stays_unused(Duration::from_secs(30)), start.elapsed())
            })
        };
        std::thread::sleep(SHORT);
        let _guard = ObjectGuard::new(&l);
        let (unused, took) = waiter.join().unwrap();
        assert!(!unused);
        assert!(
            took < Duration::from_secs(10),
            "it returns as soon as one comes"
        );

        // One that came and went again within the window also counts: it was there.
        let l = Lifetime::new();
        let waiter = {
            let l = Arc::clone(&l);
            std::thread::spawn(move || l.stays_unused(SHORT * 4))
        };
        std::thread::sleep(SHORT);
        drop(ObjectGuard::new(&l));
        assert!(!waiter.join().unwrap());

        // A LockServer lock taken during the window, or held when it starts.
        let l = Lifetime::new();
        let waiter = {
            let l = Arc::clone(&l);
            std::thread::spawn(move || l.stays_unused(SHORT * 4))
        };
        std::thread::sleep(SHORT);
        l.lock_server(true);
        assert!(!waiter.join().unwrap());
        assert!(!l.stays_unused(SHORT), "a lock held at the start");
        l.lock_server(false);
        assert!(l.stays_unused(SHORT));
    }

    #[test]
    fn a_stop_request_ends_the_settle_time_as_unused() {
        let l = Lifetime::new();
        let _guard = ObjectGuard::new(&l);
        l.request_stop("test");
        assert!(l.stays_unused(Duration::from_secs(30)));
    }

    #[test]
    fn a_stop_signal_triggered_before_or_after_stops_each_lifetime_it_is_forwarded_to() {
        let early = StopSignal::new();
        early.trigger("first");
        early.trigger("second");
        let a = Lifetime::new();
        a.stop_on(&early);
        assert_eq!(
            a.wait_until_unused(Duration::from_secs(30), SHORT),
            ExitReason::StopRequested
        );
        assert_eq!(a.stop_reason(), "second");

        let late = StopSignal::new();
        let b = Lifetime::new();
        let _guard = ObjectGuard::new(&b);
        b.stop_on(&late);
        assert_eq!(b.stop_reason(), DEFAULT_STOP_REASON);
        let waiter = {
            let b = Arc::clone(&b);
            std::thread::spawn(move || b.wait_for_stop())
        };
        late.clone().trigger("the console");
        waiter.join().unwrap();
        assert_eq!(b.stop_reason(), "the console");
        assert_eq!(late.triggered(), Some("the console"));
        // Another context's lifetime is not touched.
        assert_eq!(Lifetime::new().stop_reason(), DEFAULT_STOP_REASON);
    }
}
