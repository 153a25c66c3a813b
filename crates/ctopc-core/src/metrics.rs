//! The server's counters and histograms, in one place the front ends and the runtime bump
//! (atomics, no lock), and a [`Snapshot`] of them with the engine's [`Gauges`] at one
//! moment. Showing them (the text format, the endpoint) is the runtime's business.
//!
//! Metrics (prefix `ctopc_`):
//! - gauges from the engine: `clients`, `groups`, `items` (group items), `source_items`,
//!   `subscribed_items`, `pending_transactions` (async and sync operations waiting for the
//!   data source), `queued_events`; `uptime_seconds`;
//! - counters: `callbacks_total{kind}` (OnDataChange, OnReadComplete, OnWriteComplete,
//!   OnCancelComplete calls made), `values_sent_total` (items carried by OnDataChange and
//!   OnReadComplete), `callback_failures_total` (calls over `CallbackTimeout` and callbacks
//!   refused behind them), `sinks_dropped_total{reason}` (`disconnected`: the client was
//!   gone; `failures`: `CallbackFailures` reached), `writes_total` (written items);
//! - histograms (seconds): `callback_duration_seconds` (how long client callbacks took)
//!   and `call_duration_seconds{method}` (the server's COM methods, [`Method`]).

use std::sync::atomic::{AtomicU64, Ordering};

/// Upper bounds of the histogram buckets, in microseconds (the last bucket is +Inf).
pub const BUCKETS_US: [u64; 12] = [
    100, 500, 1_000, 5_000, 10_000, 50_000, 100_000, 500_000, 1_000_000, 5_000_000, 10_000_000,
    60_000_000,
];

/// A latency histogram: cumulative buckets are computed when rendered.
#[derive(Debug, Default)]
pub struct Histogram {
    /// Per bucket of [`BUCKETS_US`] (not cumulative), then the +Inf bucket.
    counts: [AtomicU64; BUCKETS_US.len() + 1],
    sum_us: AtomicU64,
}

/// A histogram's values at one moment.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct HistogramSnapshot {
    /// Not cumulative, one more than [`BUCKETS_US`] (+Inf).
    pub counts: Vec<u64>,
    pub sum_us: u64,
}

impl Histogram {
    /// Records one observation of `us` microseconds.
    pub fn observe_us(&self, us: u64) {
        let i = BUCKETS_US
            .iter()
            .position(|&b| us <= b)
            .unwrap_or(BUCKETS_US.len());
        self.counts[i].fetch_add(1, Ordering::Relaxed);
        self.sum_us.fetch_add(us, Ordering::Relaxed);
    }

    pub fn snapshot(&self) -> HistogramSnapshot {
        HistogramSnapshot {
            counts: self
                .counts
                .iter()
                .map(|c| c.load(Ordering::Relaxed))
                .collect(),
            sum_us: self.sum_us.load(Ordering::Relaxed),
        }
    }
}

macro_rules! methods {
    ($( $name:ident = $text:literal, )*) => {
        /// The COM methods whose durations are measured.
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub enum Method { $( $name, )* }
        impl Method {
            pub const ALL: &'static [Method] = &[ $( Method::$name, )* ];
            /// `Interface::Method`.
            pub const fn name(self) -> &'static str {
                match self { $( Method::$name => $text, )* }
            }
        }
    };
}

methods! {
    GetStatus = "IOPCServer::GetStatus",
    AddGroup = "IOPCServer::AddGroup",
    RemoveGroup = "IOPCServer::RemoveGroup",
    AddItems = "IOPCItemMgt::AddItems",
    RemoveItems = "IOPCItemMgt::RemoveItems",
    SyncRead = "IOPCSyncIO::Read",
    SyncWrite = "IOPCSyncIO::Write",
    ReadMaxAge = "IOPCSyncIO2::ReadMaxAge",
    WriteVqt = "IOPCSyncIO2::WriteVQT",
    AsyncRead = "IOPCAsyncIO2::Read",
    AsyncWrite = "IOPCAsyncIO2::Write",
    Refresh2 = "IOPCAsyncIO2::Refresh2",
    AsyncReadMaxAge = "IOPCAsyncIO3::ReadMaxAge",
    AsyncWriteVqt = "IOPCAsyncIO3::WriteVQT",
    ItemIoRead = "IOPCItemIO::Read",
    ItemIoWriteVqt = "IOPCItemIO::WriteVQT",
    Browse = "IOPCBrowse::Browse",
    BrowseOpcItemIds = "IOPCBrowseServerAddressSpace::BrowseOPCItemIDs",
}

/// The kinds of callbacks counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CallbackKind {
    DataChange,
    ReadComplete,
    WriteComplete,
    CancelComplete,
}

impl CallbackKind {
    pub const ALL: [CallbackKind; 4] = [
        CallbackKind::DataChange,
        CallbackKind::ReadComplete,
        CallbackKind::WriteComplete,
        CallbackKind::CancelComplete,
    ];
    pub const fn name(self) -> &'static str {
        match self {
            CallbackKind::DataChange => "OnDataChange",
            CallbackKind::ReadComplete => "OnReadComplete",
            CallbackKind::WriteComplete => "OnWriteComplete",
            CallbackKind::CancelComplete => "OnCancelComplete",
        }
    }
}

/// Every counter and histogram of one server (shared by its threads, bumped lock-free).
#[derive(Debug)]
pub struct Metrics {
    callbacks: [AtomicU64; 4],
    values_sent: AtomicU64,
    callback_failures: AtomicU64,
    dropped_disconnected: AtomicU64,
    dropped_failures: AtomicU64,
    writes: AtomicU64,
    callback_duration: Histogram,
    calls: Vec<Histogram>,
}

impl Default for Metrics {
    fn default() -> Self {
        Metrics {
            callbacks: Default::default(),
            values_sent: AtomicU64::new(0),
            callback_failures: AtomicU64::new(0),
            dropped_disconnected: AtomicU64::new(0),
            dropped_failures: AtomicU64::new(0),
            writes: AtomicU64::new(0),
            callback_duration: Histogram::default(),
            calls: Method::ALL.iter().map(|_| Histogram::default()).collect(),
        }
    }
}

/// What the engine says at the moment of a scrape (its `EngineStats`, plus the uptime).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Gauges {
    pub clients: u64,
    pub groups: u64,
    pub items: u64,
    pub source_items: u64,
    pub subscribed_items: u64,
    pub pending_transactions: u64,
    pub queued_events: u64,
    pub uptime_seconds: u64,
}

impl Gauges {
    /// From the engine's statistics.
    pub fn from_stats(s: &crate::model::EngineStats, uptime_seconds: u64) -> Gauges {
        Gauges {
            clients: s.sessions as u64,
            groups: s.groups as u64,
            items: s.group_items as u64,
            source_items: s.source_items as u64,
            subscribed_items: s.subscribed_items as u64,
            pending_transactions: s.pending_transactions as u64,
            queued_events: s.queued_events as u64,
            uptime_seconds,
        }
    }
}

/// Everything one scrape shows.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Snapshot {
    pub gauges: Gauges,
    /// In [`CallbackKind::ALL`] order.
    pub callbacks: [u64; 4],
    pub values_sent: u64,
    pub callback_failures: u64,
    pub dropped_disconnected: u64,
    pub dropped_failures: u64,
    pub writes: u64,
    pub callback_duration: HistogramSnapshot,
    /// In [`Method::ALL`] order.
    pub calls: Vec<HistogramSnapshot>,
}

impl Metrics {
    /// A callback call made (`values`: items it carried), which took `us` microseconds.
    pub fn callback(&self, kind: CallbackKind, values: u64, us: u64) {
        self.callbacks[kind as usize].fetch_add(1, Ordering::Relaxed);
        self.values_sent.fetch_add(values, Ordering::Relaxed);
        self.callback_duration.observe_us(us);
    }
    pub fn callback_failed(&self) {
        self.callback_failures.fetch_add(1, Ordering::Relaxed);
    }
    /// A sink dropped: `disconnected` (the client was gone) or for its failures.
    pub fn sink_dropped(&self, disconnected: bool) {
        let c = if disconnected {
            &self.dropped_disconnected
        } else {
            &self.dropped_failures
        };
        c.fetch_add(1, Ordering::Relaxed);
    }
    pub fn written(&self, items: u64) {
        self.writes.fetch_add(items, Ordering::Relaxed);
    }
    /// One call of `method` that took `us` microseconds.
    pub fn call(&self, method: Method, us: u64) {
        if let Some(h) = self.calls.get(method as usize) {
            h.observe_us(us);
        }
    }

    pub fn snapshot(&self, gauges: Gauges) -> Snapshot {
        let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
        Snapshot {
            gauges,
            callbacks: [
                load(&self.callbacks[0]),
                load(&self.callbacks[1]),
                load(&self.callbacks[2]),
                load(&self.callbacks[3]),
            ],
            values_sent: load(&self.values_sent),
            callback_failures: load(&self.callback_failures),
            dropped_disconnected: load(&self.dropped_disconnected),
            dropped_failures: load(&self.dropped_failures),
            writes: load(&self.writes),
            callback_duration: self.callback_duration.snapshot(),
            calls: self.calls.iter().map(Histogram::snapshot).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histograms_put_each_observation_in_its_bucket() {
        let h = Histogram::default();
        for us in [50, 100, 101, 2_000_000, 100_000_000] {
            h.observe_us(us);
        }
        let s = h.snapshot();
        assert_eq!(s.counts.len(), BUCKETS_US.len() + 1);
        assert_eq!(s.counts[0], 2, "<= 100 us");
        assert_eq!(s.counts[1], 1, "<= 500 us");
        assert_eq!(s.counts[9], 1, "<= 5 s");
        assert_eq!(s.counts[12], 1, "+Inf");
        assert_eq!(s.sum_us, 102_000_251);
    }
}
