//! The Prometheus text exposition format (version 0.0.4) of a
//! [`ctopc_core::metrics::Snapshot`]: a pure function, tested natively; served by
//! [`crate::metrics_http`].
//!
//! Written here rather than with `prometheus-client`: that crate writes OpenMetrics 1.0
//! text, whose counter families are declared without `_total` (`# TYPE ctopc_callbacks
//! counter`), whose bucket bounds and sums are shortest floats (`le="0.0005"`, not
//! `le="0.000500"`) and which ends in `# EOF`; its histograms also take a lock per
//! observation, where [`ctopc_core::metrics::Histogram`] is lock-free.

use ctopc_core::metrics::{CallbackKind, HistogramSnapshot, Method, Snapshot, BUCKETS_US};
use std::fmt::Write as _;

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

#[cfg(test)]
mod tests {
    use super::*;
    use ctopc_core::metrics::{Gauges, Metrics};

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
}
