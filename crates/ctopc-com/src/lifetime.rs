//! Process lifetime of the out-of-process server: counts live server objects and
//! IClassFactory::LockServer locks, and wakes the main thread when the last is gone.

use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

#[derive(Default)]
struct Counts {
    objects: usize,
    locks: usize,
    ever_used: bool,
    stop_requested: bool,
}

static COUNTS: Mutex<Counts> = Mutex::new(Counts {
    objects: 0,
    locks: 0,
    ever_used: false,
    stop_requested: false,
});
static CHANGED: Condvar = Condvar::new();

fn with<R>(f: impl FnOnce(&mut Counts) -> R) -> R {
    let mut g = COUNTS.lock().unwrap_or_else(|p| p.into_inner());
    let r = f(&mut g);
    CHANGED.notify_all();
    r
}

/// A live COM object that keeps the process up (held by every server object).
pub struct ObjectGuard(());

impl ObjectGuard {
    pub fn new() -> Self {
        with(|c| {
            c.objects += 1;
            c.ever_used = true;
        });
        ObjectGuard(())
    }
}

impl Default for ObjectGuard {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for ObjectGuard {
    fn drop(&mut self) {
        with(|c| c.objects = c.objects.saturating_sub(1));
    }
}

pub fn lock_server(lock: bool) {
    with(|c| {
        if lock {
            c.locks += 1;
            c.ever_used = true;
        } else {
            c.locks = c.locks.saturating_sub(1);
        }
    });
}

static STOP_REASON: Mutex<Option<&'static str>> = Mutex::new(None);

/// Asks the main loop to stop; `reason` is what clients get in IOPCShutdown.
pub fn request_stop_with(reason: &'static str) {
    *STOP_REASON.lock().unwrap_or_else(|p| p.into_inner()) = Some(reason);
    with(|c| c.stop_requested = true);
}

/// The reason of a requested stop.
pub fn stop_reason() -> &'static str {
    STOP_REASON
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .unwrap_or("ServerCTOPC is stopping")
}

/// Blocks until a stop is requested (the NT service serves until the SCM stops it).
pub fn wait_for_stop() {
    let mut g = COUNTS.lock().unwrap_or_else(|p| p.into_inner());
    while !g.stop_requested {
        g = CHANGED.wait(g).unwrap_or_else(|p| p.into_inner());
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

/// Blocks until the server is unused: every object and lock released after at least one
/// client came (and still so `linger` later: a client that connects right after the last
/// one left must not reach a process that is revoking its class object), or no client
/// within `grace` of start, or a stop was requested.
pub fn wait_until_unused(grace: Duration, linger: Duration) -> ExitReason {
    let start = Instant::now();
    let mut idle_since: Option<Instant> = None;
    let mut g = COUNTS.lock().unwrap_or_else(|p| p.into_inner());
    loop {
        if g.stop_requested {
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
            g = CHANGED
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
        g = CHANGED
            .wait_timeout(g, wait)
            .map(|(g, _)| g)
            .unwrap_or_else(|p| p.into_inner().0);
    }
}
