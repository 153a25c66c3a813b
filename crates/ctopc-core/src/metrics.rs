//! The server's counters and histograms, in one place the COM layer bumps (atomics, no
//! lock), and their rendering in the Prometheus text exposition format (version 0.0.4),
//! a pure function of a [`Snapshot`] (tested natively). The COM layer serves it on
//! `[Server] MetricsAddress` (loopback only, [`check_address`]) at `GET /metrics`.
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

use std::fmt::Write as _;
use std::net::SocketAddr;
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

fn header(out: &mut String, name: &str, kind: &str, help: &str) {
    let _ = writeln!(out, "# HELP ctopc_{name} {help}");
    let _ = writeln!(out, "# TYPE ctopc_{name} {kind}");
}

fn seconds(us: u64) -> String {
    format!("{}.{:06}", us / 1_000_000, us % 1_000_000)
}

fn histogram(out: &mut String, name: &str, labels: &str, h: &HistogramSnapshot) {
    let sep = if labels.is_empty() { "" } else { "," };
    let mut cumulative = 0;
    for (i, c) in h.counts.iter().enumerate() {
        cumulative += c;
        let le = BUCKETS_US
            .get(i)
            .map_or_else(|| "+Inf".to_string(), |&b| seconds(b));
        let _ = writeln!(
            out,
            "ctopc_{name}_bucket{{{labels}{sep}le=\"{le}\"}} {cumulative}"
        );
    }
    let braces = if labels.is_empty() {
        String::new()
    } else {
        format!("{{{labels}}}")
    };
    let _ = writeln!(out, "ctopc_{name}_sum{braces} {}", seconds(h.sum_us));
    let _ = writeln!(out, "ctopc_{name}_count{braces} {cumulative}");
}

/// The Prometheus text format (0.0.4) of a snapshot.
pub fn render(s: &Snapshot) -> String {
    let mut out = String::with_capacity(8192);
    let g = &s.gauges;
    for (name, help, v) in [
        (
            "clients",
            "Connected OPC clients (server objects).",
            g.clients,
        ),
        ("groups", "OPC groups.", g.groups),
        ("items", "Items in groups.", g.items),
        (
            "source_items",
            "Data source items in the cache.",
            g.source_items,
        ),
        (
            "subscribed_items",
            "Data source items with an active subscriber.",
            g.subscribed_items,
        ),
        (
            "pending_transactions",
            "Reads, writes and refreshes waiting for the data source.",
            g.pending_transactions,
        ),
        (
            "queued_events",
            "Callbacks produced and not yet handed to a client's worker.",
            g.queued_events,
        ),
        (
            "uptime_seconds",
            "Seconds since the server started.",
            g.uptime_seconds,
        ),
    ] {
        header(&mut out, name, "gauge", help);
        let _ = writeln!(out, "ctopc_{name} {v}");
    }
    header(
        &mut out,
        "callbacks_total",
        "counter",
        "Callbacks made to clients, by kind.",
    );
    for (k, v) in CallbackKind::ALL.iter().zip(s.callbacks) {
        let _ = writeln!(out, "ctopc_callbacks_total{{kind=\"{}\"}} {v}", k.name());
    }
    for (name, help, v) in [
        (
            "values_sent_total",
            "Item values sent in OnDataChange and OnReadComplete.",
            s.values_sent,
        ),
        (
            "callback_failures_total",
            "Callbacks over CallbackTimeout or refused behind such a call.",
            s.callback_failures,
        ),
        ("writes_total", "Items written by clients.", s.writes),
    ] {
        header(&mut out, name, "counter", help);
        let _ = writeln!(out, "ctopc_{name} {v}");
    }
    header(
        &mut out,
        "sinks_dropped_total",
        "counter",
        "Client callback sinks dropped, by reason.",
    );
    let _ = writeln!(
        out,
        "ctopc_sinks_dropped_total{{reason=\"disconnected\"}} {}",
        s.dropped_disconnected
    );
    let _ = writeln!(
        out,
        "ctopc_sinks_dropped_total{{reason=\"failures\"}} {}",
        s.dropped_failures
    );
    header(
        &mut out,
        "callback_duration_seconds",
        "histogram",
        "How long client callbacks took.",
    );
    histogram(
        &mut out,
        "callback_duration_seconds",
        "",
        &s.callback_duration,
    );
    header(
        &mut out,
        "call_duration_seconds",
        "histogram",
        "How long the server's COM methods took, by method.",
    );
    for (m, h) in Method::ALL.iter().zip(&s.calls) {
        histogram(
            &mut out,
            "call_duration_seconds",
            &format!("method=\"{}\"", m.name()),
            h,
        );
    }
    out
}

/// `MetricsAddress`: an `ip:port` on a loopback address (127.0.0.0/8 or ::1); anything
/// else is refused with the reason (the metrics carry client names' activity and are
/// served without authentication).
pub fn check_address(text: &str) -> Result<SocketAddr, String> {
    let addr: SocketAddr = text
        .trim()
        .parse()
        .map_err(|_| format!("MetricsAddress {text:?} is not an ip:port address"))?;
    if !addr.ip().is_loopback() {
        return Err(format!(
            "MetricsAddress {addr} is not a loopback address (only 127.0.0.1 or [::1] are \
             served: the endpoint has no authentication)"
        ));
    }
    Ok(addr)
}

/// The HTTP answer to a request's first line (`GET /metrics HTTP/1.1`): status line and
/// whether to send the metrics. Anything but a GET of `/metrics` (query allowed) is 404;
/// a line that is not HTTP is 400.
pub fn route(request_line: &str) -> (&'static str, bool) {
    let mut parts = request_line.split_ascii_whitespace();
    let (Some(method), Some(target), Some(version)) = (parts.next(), parts.next(), parts.next())
    else {
        return ("400 Bad Request", false);
    };
    if !version.starts_with("HTTP/") {
        return ("400 Bad Request", false);
    }
    let path = target.split('?').next().unwrap_or("");
    match (method, path) {
        ("GET", "/metrics") => ("200 OK", true),
        _ => ("404 Not Found", false),
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

    #[test]
    fn the_text_format_has_every_metric_with_help_and_type() {
        let m = Metrics::default();
        m.callback(CallbackKind::DataChange, 10, 1500);
        m.callback(CallbackKind::DataChange, 5, 200);
        m.callback(CallbackKind::WriteComplete, 0, 300);
        m.callback_failed();
        m.sink_dropped(false);
        m.sink_dropped(true);
        m.written(3);
        m.call(Method::SyncWrite, 2_500);
        let text = render(&m.snapshot(Gauges {
            clients: 2,
            groups: 3,
            items: 40,
            pending_transactions: 1,
            uptime_seconds: 61,
            ..Gauges::default()
        }));
        for line in [
            "# TYPE ctopc_clients gauge",
            "ctopc_clients 2",
            "ctopc_groups 3",
            "ctopc_items 40",
            "ctopc_pending_transactions 1",
            "ctopc_uptime_seconds 61",
            "# TYPE ctopc_callbacks_total counter",
            "ctopc_callbacks_total{kind=\"OnDataChange\"} 2",
            "ctopc_callbacks_total{kind=\"OnWriteComplete\"} 1",
            "ctopc_callbacks_total{kind=\"OnReadComplete\"} 0",
            "ctopc_values_sent_total 15",
            "ctopc_callback_failures_total 1",
            "ctopc_writes_total 3",
            "ctopc_sinks_dropped_total{reason=\"disconnected\"} 1",
            "ctopc_sinks_dropped_total{reason=\"failures\"} 1",
            "# TYPE ctopc_callback_duration_seconds histogram",
            "ctopc_callback_duration_seconds_bucket{le=\"0.000500\"} 2",
            "ctopc_callback_duration_seconds_bucket{le=\"0.005000\"} 3",
            "ctopc_callback_duration_seconds_bucket{le=\"+Inf\"} 3",
            "ctopc_callback_duration_seconds_sum 0.002000",
            "ctopc_callback_duration_seconds_count 3",
            "ctopc_call_duration_seconds_bucket{method=\"IOPCSyncIO::Write\",le=\"0.005000\"} 1",
            "ctopc_call_duration_seconds_count{method=\"IOPCSyncIO::Write\"} 1",
            "ctopc_call_duration_seconds_count{method=\"IOPCSyncIO::Read\"} 0",
        ] {
            assert!(
                text.lines().any(|l| l == line),
                "missing {line:?} in\n{text}"
            );
        }
        // Every sample line belongs to a declared metric.
        for l in text.lines().filter(|l| !l.starts_with('#')) {
            let name = l.split(['{', ' ']).next().unwrap();
            let base = name
                .trim_end_matches("_bucket")
                .trim_end_matches("_sum")
                .trim_end_matches("_count");
            assert!(
                text.contains(&format!("# TYPE {base} ")),
                "{name} has no TYPE line"
            );
        }
    }

    #[test]
    fn only_loopback_addresses_are_served() {
        assert_eq!(
            check_address("127.0.0.1:9464").unwrap(),
            "127.0.0.1:9464".parse().unwrap()
        );
        assert!(check_address("[::1]:9464").is_ok());
        assert!(check_address(" 127.0.0.2:1 ").is_ok());
        let e = check_address("0.0.0.0:9464").unwrap_err();
        assert!(e.contains("not a loopback address"), "{e}");
        assert!(check_address("192.168.1.5:9464").is_err());
        assert!(check_address("localhost:9464")
            .unwrap_err()
            .contains("ip:port"));
        assert!(check_address("127.0.0.1").is_err());
    }

    #[test]
    fn only_get_metrics_is_answered() {
        assert_eq!(route("GET /metrics HTTP/1.1"), ("200 OK", true));
        assert_eq!(route("GET /metrics?x=1 HTTP/1.0"), ("200 OK", true));
        assert_eq!(route("GET / HTTP/1.1"), ("404 Not Found", false));
        assert_eq!(route("POST /metrics HTTP/1.1"), ("404 Not Found", false));
        assert_eq!(route("GET /metrics"), ("400 Bad Request", false));
        assert_eq!(route("\u{16}\u{3}\u{1} junk"), ("400 Bad Request", false));
    }
}
