//! The client's IOPCDataCallback: [`RecordingSink`], a COM object over an
//! `Arc<`[`Recording`]`>` that keeps every callback the server makes, in the order they
//! come, and counts them. The end-to-end tests, the in-process COM tests, the benchmarks,
//! the scale and soak clients and opcdiag record callbacks with this one sink; its [`Options`] say
//! what it keeps (everything, or counts only), whether it forwards each callback into a
//! channel, and whether it traces; [`Recording::hold_calls`] makes it a slow client.

use super::diag::{callback_items, write_results};
use super::ReadItem;
use ctopc_com::interfaces::*;
use std::sync::mpsc::Sender;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use windows::core::{implement, HRESULT};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Variant::VARIANT;

/// One call the server made on the sink, owned.
#[derive(Debug, Clone, PartialEq)]
pub enum Callback {
    DataChange {
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        items: Vec<ReadItem>,
    },
    ReadComplete {
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        items: Vec<ReadItem>,
    },
    WriteComplete {
        transaction: u32,
        group: u32,
        master_error: HRESULT,
        /// (client handle, error)
        items: Vec<(u32, HRESULT)>,
    },
    CancelComplete {
        transaction: u32,
        group: u32,
    },
}

impl Callback {
    pub fn transaction(&self) -> u32 {
        match self {
            Callback::DataChange { transaction, .. }
            | Callback::ReadComplete { transaction, .. }
            | Callback::WriteComplete { transaction, .. }
            | Callback::CancelComplete { transaction, .. } => *transaction,
        }
    }
}

/// What the sink counted, kept or not.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Every call on the sink.
    pub calls: u64,
    /// OnDataChange calls of the subscription (transaction ID 0), and the items they
    /// carried.
    pub data_changes: u64,
    pub data_change_items: u64,
    /// How many of the client handles `0..Options::cover` the subscription's
    /// OnDataChange calls have carried at least once.
    pub covered: usize,
}

/// How a [`Recording`] records.
#[derive(Debug, Default)]
pub struct Options {
    /// Count only: keep no callback (the benchmark and scale clients, where keeping every
    /// item would grow the client without end and distort memory figures).
    pub count_only: bool,
    /// Send every callback into this channel too (opcdiag's streaming). A closed receiver
    /// is not an error.
    pub forward: Option<Sender<Callback>>,
    /// Track which client handles `0..cover` the subscription has carried
    /// ([`Counts::covered`]).
    pub cover: usize,
    /// Print each subscription OnDataChange's group, size and time (seconds since 1970)
    /// to stderr.
    pub trace: bool,
}

struct State {
    /// Every callback with the time it came (unless `count_only`).
    log: Vec<(Instant, Callback)>,
    counts: Counts,
    covered: Vec<bool>,
}

/// What a [`RecordingSink`] saw. The sink's calls come on the server's callback threads;
/// the waits below let a test wait for them without sleeping.
pub struct Recording {
    count_only: bool,
    trace: bool,
    forward: Option<Sender<Callback>>,
    state: Mutex<State>,
    changed: Condvar,
    /// While `Some(limit)`, each call returns only after `limit` or on
    /// [`Recording::release`].
    hold: Mutex<Option<Duration>>,
    released: Condvar,
}

impl Recording {
    /// A recording that keeps every callback.
    pub fn new() -> Arc<Recording> {
        Recording::with(Options::default())
    }

    /// A recording that only counts.
    pub fn counting() -> Arc<Recording> {
        Recording::with(Options {
            count_only: true,
            ..Options::default()
        })
    }

    pub fn with(options: Options) -> Arc<Recording> {
        Arc::new(Recording {
            count_only: options.count_only,
            trace: options.trace,
            forward: options.forward,
            state: Mutex::new(State {
                log: Vec::new(),
                counts: Counts::default(),
                covered: vec![false; options.cover],
            }),
            changed: Condvar::new(),
            hold: Mutex::new(None),
            released: Condvar::new(),
        })
    }

    /// A new sink over this recording, to advise on a group.
    pub fn sink(self: &Arc<Self>) -> IOPCDataCallback {
        RecordingSink::create(self)
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Whether the callback itself is needed (kept or forwarded), or only counted.
    fn wants_callbacks(&self) -> bool {
        !self.count_only || self.forward.is_some()
    }

    /// Records one call: `callback` builds it when it is kept or forwarded; `handles` are
    /// the client handles of a subscription OnDataChange (for `cover`).
    fn push(&self, subscription: Option<&[u32]>, callback: impl FnOnce() -> Callback) {
        let at = Instant::now();
        let callback = self.wants_callbacks().then(callback);
        let mut s = self.lock();
        s.counts.calls += 1;
        if let Some(handles) = subscription {
            s.counts.data_changes += 1;
            s.counts.data_change_items += handles.len() as u64;
            if !s.covered.is_empty() {
                let mut newly = 0;
                for &h in handles {
                    if let Some(seen) = s.covered.get_mut(h as usize) {
                        if !*seen {
                            *seen = true;
                            newly += 1;
                        }
                    }
                }
                s.counts.covered += newly;
            }
        }
        if let Some(callback) = callback {
            if let Some(tx) = &self.forward {
                let _ = tx.send(callback.clone());
            }
            if !self.count_only {
                s.log.push((at, callback));
            }
        }
        drop(s);
        self.changed.notify_all();
        self.held();
    }

    /// Returns after the hold limit, or at once when the sink is not held or released.
    fn held(&self) {
        let hold = self.hold.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(limit) = *hold {
            let _ = self
                .released
                .wait_timeout_while(hold, limit, |h| h.is_some());
        }
    }

    /// Makes the sink a slow client: each call returns only after `limit`, or at once when
    /// [`Recording::release`] is called. The call is recorded before it is held.
    pub fn hold_calls(&self, limit: Duration) {
        *self.hold.lock().unwrap_or_else(|p| p.into_inner()) = Some(limit);
    }

    /// Ends [`Recording::hold_calls`]: a held call returns now.
    pub fn release(&self) {
        *self.hold.lock().unwrap_or_else(|p| p.into_inner()) = None;
        self.released.notify_all();
    }

    /// Waits (at most `limit`) until `done`, given the kept callbacks (with the time each
    /// came) and the counts, answers `Some`: that answer, or `None` after `limit`.
    pub fn wait_until<T>(
        &self,
        limit: Duration,
        mut done: impl FnMut(&[(Instant, Callback)], &Counts) -> Option<T>,
    ) -> Option<T> {
        let deadline = Instant::now() + limit;
        let mut s = self.lock();
        loop {
            if let Some(t) = done(&s.log, &s.counts) {
                return Some(t);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            s = self
                .changed
                .wait_timeout(s, left)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }

    /// Waits (at most `limit`) for a callback that `pred` accepts; returns the first one.
    pub fn wait_for(&self, limit: Duration, pred: impl Fn(&Callback) -> bool) -> Option<Callback> {
        self.wait_until(limit, |log, _| {
            log.iter().map(|(_, c)| c).find(|c| pred(c)).cloned()
        })
    }

    /// Waits (at most `limit`) until `n` callbacks that `pred` accepts have come: whether
    /// they did.
    pub fn wait_count(&self, limit: Duration, n: usize, pred: impl Fn(&Callback) -> bool) -> bool {
        self.wait_until(limit, |log, _| {
            (log.iter().filter(|(_, c)| pred(c)).count() >= n).then_some(())
        })
        .is_some()
    }

    /// Waits (at most `limit`) until `pred` accepts the counts: those counts, or `None`.
    pub fn wait_counts(&self, limit: Duration, pred: impl Fn(&Counts) -> bool) -> Option<Counts> {
        self.wait_until(limit, |_, counts| pred(counts).then_some(*counts))
    }

    /// Every kept callback so far, in order.
    pub fn all(&self) -> Vec<Callback> {
        self.lock().log.iter().map(|(_, c)| c.clone()).collect()
    }

    /// Every kept callback so far with the time it came, in order.
    pub fn timed(&self) -> Vec<(Instant, Callback)> {
        self.lock().log.clone()
    }

    /// How many callbacks are kept.
    pub fn len(&self) -> usize {
        self.lock().log.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn counts(&self) -> Counts {
        self.lock().counts
    }

    /// Forgets the kept callbacks (the counts stay).
    pub fn clear(&self) {
        self.lock().log.clear();
    }
}

/// Seconds since 1970, for trace lines compared across processes.
fn unix_secs() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

/// The IOPCDataCallback COM object (free-threaded: the server's callback threads call it
/// directly in process; out of process the stub calls it on an RPC thread).
#[implement(IOPCDataCallback)]
pub struct RecordingSink(pub Arc<Recording>);

impl RecordingSink {
    pub fn create(recording: &Arc<Recording>) -> IOPCDataCallback {
        RecordingSink(Arc::clone(recording)).into()
    }
}

/// The `n` client handles of a callback: empty when the pointer is NULL.
///
/// # Safety
/// A non-null `h` points at `n` elements for the lifetime of the slice.
unsafe fn handles<'a>(n: u32, h: *const u32) -> &'a [u32] {
    if n == 0 || h.is_null() {
        return &[];
    }
    // SAFETY: the caller guarantees `n` elements (checked non-null above).
    unsafe { std::slice::from_raw_parts(h, n as usize) }
}

impl IOPCDataCallback_Impl for RecordingSink_Impl {
    unsafe fn OnDataChange(
        &self,
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        n: u32,
        h: *const u32,
        v: *const VARIANT,
        q: *const u16,
        t: *const FILETIME,
        e: *const HRESULT,
    ) -> windows::core::Result<()> {
        let subscription = if transaction == 0 {
            if self.0.trace {
                eprintln!(
                    "OnDataChange group {group:#x}: {n} items at {:.3}",
                    unix_secs()
                );
            }
            // SAFETY: the stub passes `n`-element arrays for the duration of the call.
            Some(unsafe { handles(n, h) })
        } else {
            None
        };
        self.0.push(subscription, || Callback::DataChange {
            transaction,
            group,
            master_quality,
            master_error,
            // SAFETY: the stub passes `n`-element arrays, read before `push` returns.
            items: unsafe { callback_items(n, h, v, q, t, e) },
        });
        Ok(())
    }

    unsafe fn OnReadComplete(
        &self,
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        n: u32,
        h: *const u32,
        v: *const VARIANT,
        q: *const u16,
        t: *const FILETIME,
        e: *const HRESULT,
    ) -> windows::core::Result<()> {
        self.0.push(None, || Callback::ReadComplete {
            transaction,
            group,
            master_quality,
            master_error,
            // SAFETY: the stub passes `n`-element arrays, read before `push` returns.
            items: unsafe { callback_items(n, h, v, q, t, e) },
        });
        Ok(())
    }

    unsafe fn OnWriteComplete(
        &self,
        transaction: u32,
        group: u32,
        master_error: HRESULT,
        n: u32,
        h: *const u32,
        e: *const HRESULT,
    ) -> windows::core::Result<()> {
        self.0.push(None, || Callback::WriteComplete {
            transaction,
            group,
            master_error,
            // SAFETY: the stub passes `n`-element arrays, read before `push` returns.
            items: unsafe { write_results(n, h, e) },
        });
        Ok(())
    }

    unsafe fn OnCancelComplete(&self, transaction: u32, group: u32) -> windows::core::Result<()> {
        self.0
            .push(None, || Callback::CancelComplete { transaction, group });
        Ok(())
    }
}
