//! The metrics endpoint (`[Server] MetricsAddress`, off by default): a small HTTP server
//! on a thread of its own that answers `GET /metrics` with the Prometheus text of
//! [`crate::prometheus::render`] and everything else with 404 (400 for what is not HTTP).
//!
//! It never blocks the server: one connection at a time on its own thread, a request of
//! at most [`MAX_REQUEST`] bytes read with a [`IO_TIMEOUT`] read (and write) timeout, the
//! engine's statistics taken in one short section under the driver lock. Only loopback
//! addresses are served ([`check_address`]; anything else is refused
//! with an error in the log). The thread holds the runtime weakly and ends with it.

use crate::Runtime;
use ctopc_core::metrics::Gauges;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::{Arc, Weak};
use std::time::Duration;

/// The largest request read (its head; a body is never read).
pub const MAX_REQUEST: usize = 8 * 1024;
/// Read and write timeout of a connection.
pub const IO_TIMEOUT: Duration = Duration::from_secs(2);
/// How often the accept loop looks whether the runtime is still there.
const POLL: Duration = Duration::from_millis(100);

/// Starts the endpoint on `address` (logged; an address that is refused or cannot be
/// bound is an error in the log, and the server runs without metrics).
pub fn start(rt: &Arc<Runtime>, address: &str) {
    let addr: SocketAddr = match check_address(address) {
        Ok(a) => a,
        Err(e) => {
            tracing::error!("{e}; the metrics endpoint is off");
            return;
        }
    };
    let listener = match TcpListener::bind(addr).and_then(|l| {
        l.set_nonblocking(true)?;
        Ok(l)
    }) {
        Ok(l) => l,
        Err(e) => {
            tracing::error!("cannot serve metrics on {addr} (MetricsAddress): {e}");
            return;
        }
    };
    let weak = Arc::downgrade(rt);
    let spawned = std::thread::Builder::new()
        .name("metrics".into())
        .spawn(move || serve(listener, weak));
    match spawned {
        Ok(_) => tracing::info!("metrics: http://{addr}/metrics (MetricsAddress)"),
        Err(e) => tracing::error!("cannot start the metrics thread: {e}"),
    }
}

fn serve(listener: TcpListener, rt: Weak<Runtime>) {
    loop {
        match listener.accept() {
            Ok((stream, _)) => {
                let Some(rt) = rt.upgrade() else { return };
                if let Err(e) = answer(stream, &rt) {
                    tracing::debug!("metrics: a request failed: {e}");
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                if rt.strong_count() == 0 {
                    return;
                }
                std::thread::sleep(POLL);
            }
            Err(e) => {
                tracing::debug!("metrics: accept failed: {e}");
                std::thread::sleep(POLL);
            }
        }
    }
}

/// Reads the request head (bounded, with a timeout) and answers it.
fn answer(mut stream: TcpStream, rt: &Runtime) -> std::io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_read_timeout(Some(IO_TIMEOUT))?;
    stream.set_write_timeout(Some(IO_TIMEOUT))?;
    let mut head = Vec::with_capacity(512);
    let mut buf = [0u8; 1024];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") && !head.windows(2).any(|w| w == b"\n\n") {
        if head.len() >= MAX_REQUEST {
            return respond(&mut stream, "431 Request Header Fields Too Large", "");
        }
        let n = stream.read(&mut buf)?;
        if n == 0 {
            break;
        }
        head.extend_from_slice(&buf[..n.min(MAX_REQUEST - head.len())]);
    }
    let text = String::from_utf8_lossy(&head);
    let first = text.lines().next().unwrap_or("");
    let (status, metrics) = route(first);
    if metrics {
        let body = render(rt);
        respond(&mut stream, status, &body)
    } else {
        respond(&mut stream, status, "")
    }
}

/// The metrics now: the engine's gauges (one short section under the driver lock) and the
/// counters.
pub fn render(rt: &Runtime) -> String {
    let stats = rt.lock().engine.stats();
    let uptime = crate::clock::now().millis_since(rt.start_time) / 1000;
    crate::prometheus::render(&rt.metrics.snapshot(Gauges::from_stats(&stats, uptime)))
}

fn respond(stream: &mut TcpStream, status: &str, body: &str) -> std::io::Result<()> {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: text/plain; version=0.0.4; charset=utf-8\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(body.as_bytes())?;
    stream.flush()
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
