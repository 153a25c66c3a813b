//! The metrics endpoint (`[Server] MetricsAddress`, off by default): a small HTTP/1.1
//! server on a thread of its own. `GET /metrics` is answered with the text of
//! [`crate::prometheus::render`], anything else with 404 and what is not HTTP with 400
//! ([`route`]); a head longer than [`MAX_REQUEST`] with 431.
//!
//! It never holds up the server and its memory is bounded: one connection at a time, its
//! head read into a buffer of [`MAX_REQUEST`] bytes (a body is never read) within
//! [`IO_TIMEOUT`], after which the connection is closed; the engine's statistics are taken
//! in one short section under the driver lock. Only loopback addresses are served
//! ([`check_address`]; anything else is refused with an error in the log). The thread
//! holds the runtime weakly, and ends within [`POLL`] once the runtime has gone.
//!
//! Hand-written rather than over `tiny_http` 0.12, which bounds neither the length of a
//! request head (it never answers 431) nor the time to send it (ARCHITECTURE.md).

use crate::Runtime;
use ctopc_core::metrics::Gauges;
use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::{Arc, Weak};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The largest request head read (a body is never read).
pub const MAX_REQUEST: usize = 8 * 1024;
/// How long a connection may take to send its head, and the write timeout of the answer.
pub const IO_TIMEOUT: Duration = Duration::from_secs(2);
/// How often the idle accept loop looks whether the runtime is still there.
pub const POLL: Duration = Duration::from_millis(100);

/// A started endpoint.
#[derive(Debug)]
pub struct Endpoint {
    /// Where it listens (with the port the system chose when the address gave 0).
    pub address: SocketAddr,
    /// Its thread, which ends once the runtime has gone.
    pub thread: JoinHandle<()>,
}

/// Starts the endpoint on `address` (logged; an address that is refused or cannot be
/// bound is an error in the log, and the server runs without metrics: `None`).
pub fn start(rt: &Arc<Runtime>, address: &str) -> Option<Endpoint> {
    match listen(rt, address) {
        Ok(endpoint) => {
            tracing::info!(
                "metrics: http://{}/metrics (MetricsAddress)",
                endpoint.address
            );
            Some(endpoint)
        }
        Err(e) => {
            tracing::error!("{e}");
            None
        }
    }
}

fn listen(rt: &Arc<Runtime>, address: &str) -> Result<Endpoint, String> {
    let addr = check_address(address).map_err(|e| format!("{e}; the metrics endpoint is off"))?;
    let bound = TcpListener::bind(addr).and_then(|l| {
        l.set_nonblocking(true)?;
        Ok((l.local_addr()?, l))
    });
    let (address, listener) =
        bound.map_err(|e| format!("cannot serve metrics on {addr} (MetricsAddress): {e}"))?;
    let weak = Arc::downgrade(rt);
    let thread = std::thread::Builder::new()
        .name("metrics".into())
        .spawn(move || serve(listener, weak))
        .map_err(|e| format!("cannot start the metrics thread: {e}"))?;
    Ok(Endpoint { address, thread })
}

/// The accept loop: non-blocking, so that it sees the runtime go without a connection.
fn serve(listener: TcpListener, rt: Weak<Runtime>) {
    while rt.strong_count() > 0 {
        match listener.accept() {
            Ok((stream, _)) => {
                if let Err(e) = answer(stream, &rt) {
                    tracing::debug!("metrics: a request failed: {e}");
                }
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => std::thread::sleep(POLL),
            Err(e) => {
                tracing::debug!("metrics: accept failed: {e}");
                std::thread::sleep(POLL);
            }
        }
    }
}

/// Reads the request head (bounded, within [`IO_TIMEOUT`]) and answers it. The runtime is
/// held only while the metrics are taken.
fn answer(stream: TcpStream, rt: &Weak<Runtime>) -> io::Result<()> {
    // An accepted socket may inherit the listener's non-blocking mode (Windows).
    stream.set_nonblocking(false)?;
    stream.set_write_timeout(Some(IO_TIMEOUT))?;
    let mut buf = [0; MAX_REQUEST];
    let mut within = Within {
        stream: &stream,
        deadline: Instant::now() + IO_TIMEOUT,
    };
    let (status, send_metrics) = match read_head(&mut within, &mut buf)? {
        Some(head) => route(String::from_utf8_lossy(head).lines().next().unwrap_or("")),
        None => ("431 Request Header Fields Too Large", false),
    };
    let body = if send_metrics {
        match rt.upgrade() {
            Some(rt) => render(&rt),
            None => return Ok(()),
        }
    } else {
        String::new()
    };
    respond(&stream, status, &body)
}

/// Reads a request head into `buf`: up to its blank line, or all the client sent before
/// it stopped sending. `None` when `buf` filled before the blank line (nothing more is read).
fn read_head<'b>(r: &mut impl Read, buf: &'b mut [u8]) -> io::Result<Option<&'b [u8]>> {
    let mut len = 0;
    loop {
        let head = &buf[..len];
        if head.windows(4).any(|w| w == b"\r\n\r\n") || head.windows(2).any(|w| w == b"\n\n") {
            break;
        }
        if len == buf.len() {
            return Ok(None);
        }
        let n = r.read(&mut buf[len..])?;
        if n == 0 {
            break;
        }
        len += n;
    }
    Ok(Some(&buf[..len]))
}

/// A connection whose reads share one deadline (a client sending a byte at a time gets
/// no more time than one sending its head at once).
struct Within<'a> {
    stream: &'a TcpStream,
    deadline: Instant,
}

impl Read for Within<'_> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let left = self.deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(io::ErrorKind::TimedOut.into());
        }
        self.stream.set_read_timeout(Some(left))?;
        Read::read(&mut self.stream, buf)
    }
}

/// The metrics now: the engine's gauges (one short section under the driver lock) and the
/// counters.
pub fn render(rt: &Runtime) -> String {
    let stats = rt.lock().engine.stats();
    let uptime = crate::clock::now().millis_since(rt.start_time) / 1000;
    crate::prometheus::render(&rt.metrics.snapshot(Gauges::from_stats(&stats, uptime)))
}

fn respond(mut stream: &TcpStream, status: &str, body: &str) -> io::Result<()> {
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

    /// Counts what it hands out: `data`, then `fill` without end.
    struct Client<'a> {
        data: &'a [u8],
        fill: u8,
        read: usize,
    }

    impl Read for Client<'_> {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            // At most 1000 bytes a read, as a network delivers them.
            let n = buf.len().min(1000);
            for (i, b) in buf[..n].iter_mut().enumerate() {
                *b = self.data.get(self.read + i).copied().unwrap_or(self.fill);
            }
            self.read += n;
            Ok(n)
        }
    }

    #[test]
    fn a_head_is_read_to_its_blank_line() {
        let mut buf = [0; MAX_REQUEST];
        for data in [
            &b"GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n"[..],
            b"GET /metrics HTTP/1.0\n\n",
        ] {
            let mut c = Client {
                data,
                fill: b'x',
                read: 0,
            };
            let head = read_head(&mut c, &mut buf).unwrap().unwrap();
            assert!(head.starts_with(data), "{head:?}");
        }
        let mut ended: &[u8] = b"GET / HTTP/1.1\r\n";
        assert_eq!(
            read_head(&mut ended, &mut buf).unwrap(),
            Some(&b"GET / HTTP/1.1\r\n"[..]),
            "a client that stops sending ends its head"
        );
    }

    #[test]
    fn an_endless_head_is_read_only_to_the_bound() {
        let mut buf = [0; MAX_REQUEST];
        let mut c = Client {
            data: b"GET /metrics HTTP/1.1\r\n",
            fill: b'a',
            read: 0,
        };
        assert_eq!(read_head(&mut c, &mut buf).unwrap(), None);
        assert_eq!(c.read, MAX_REQUEST, "nothing is read past the bound");
    }
}
