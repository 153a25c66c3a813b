//! asix-sim's REST mode: the simulated plant through the requests of the Asix.Evo REST
//! server that are known (`docs/asix-evo-rest.md`), on a real HTTP/1.1 server (hyper,
//! keep-alive), with switches that make it misbehave, for the REST link's tests:
//!
//! - `GET /asix/v1/variable/value?name=A&name=B`: one state per name, in order (camelCase
//!   fields; an unknown name has `readSucceeded: false`);
//! - `GET /asix/v1/server/variable/attribute`: the attribute names (`Name`, `Type`);
//! - `GET /asix/v1/variable/attribute?name=A&attribute=Name&attribute=Type`: one array of
//!   attribute values per name, `null` for an unknown name;
//! - `POST /sim/mode?...` (loopback peers only): the switches ([`RestMode`]); `GET
//!   /sim/stats`: requests and names served so far.
//!
//! The switches: `fail` (503 to every API request), `slow_ms` (wait before answering),
//! `single` (answer only the first name of a batch, as a server without batches would),
//! `malformed` (cut JSON), `huge` (an endless body), `slow_body_ms` (the body a byte at a
//! time, this far apart), `redirect` (302); `reset` clears them all.

use std::convert::Infallible;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use bytes::Bytes;
use ctopc_core::{Value, Vqt};
use http_body_util::combinators::BoxBody;
use http_body_util::{BodyExt, Full, StreamBody};
use hyper::body::{Frame, Incoming};
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::TokioIo;
use tokio::net::TcpListener;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tracing::debug;

use super::{Shared, SimHandle};
use crate::rest::decode::format_iso8601;

/// The misbehaviour switches, changeable while serving.
#[derive(Debug, Default)]
pub struct RestMode {
    pub fail: AtomicBool,
    pub slow_ms: AtomicU64,
    pub single: AtomicBool,
    pub malformed: AtomicBool,
    pub huge: AtomicBool,
    pub slow_body_ms: AtomicU64,
    pub redirect: AtomicBool,
    /// API requests served.
    pub requests: AtomicU64,
    /// Names asked in value requests.
    pub names: AtomicU64,
}

impl RestMode {
    /// Applies `key=value` pairs of a query (`fail=1&slow_ms=200`, `reset=1`).
    pub fn apply(&self, query: &str) -> Result<(), String> {
        for (k, v) in query_pairs(query) {
            let on = || v != "0" && !v.eq_ignore_ascii_case("false");
            let ms = || v.parse::<u64>().map_err(|_| format!("bad number {v:?}"));
            match k.as_str() {
                "fail" => self.fail.store(on(), Ordering::SeqCst),
                "single" => self.single.store(on(), Ordering::SeqCst),
                "malformed" => self.malformed.store(on(), Ordering::SeqCst),
                "huge" => self.huge.store(on(), Ordering::SeqCst),
                "redirect" => self.redirect.store(on(), Ordering::SeqCst),
                "slow_ms" => self.slow_ms.store(ms()?, Ordering::SeqCst),
                "slow_body_ms" => self.slow_body_ms.store(ms()?, Ordering::SeqCst),
                "reset" => {
                    for b in [
                        &self.fail,
                        &self.single,
                        &self.malformed,
                        &self.huge,
                        &self.redirect,
                    ] {
                        b.store(false, Ordering::SeqCst);
                    }
                    self.slow_ms.store(0, Ordering::SeqCst);
                    self.slow_body_ms.store(0, Ordering::SeqCst);
                }
                other => return Err(format!("unknown switch {other:?}")),
            }
        }
        Ok(())
    }

    fn describe(&self) -> String {
        format!(
            "ok fail={} slow_ms={} single={} malformed={} huge={} slow_body_ms={} redirect={} requests={} names={}",
            self.fail.load(Ordering::SeqCst) as u8,
            self.slow_ms.load(Ordering::SeqCst),
            self.single.load(Ordering::SeqCst) as u8,
            self.malformed.load(Ordering::SeqCst) as u8,
            self.huge.load(Ordering::SeqCst) as u8,
            self.slow_body_ms.load(Ordering::SeqCst),
            self.redirect.load(Ordering::SeqCst) as u8,
            self.requests.load(Ordering::SeqCst),
            self.names.load(Ordering::SeqCst),
        )
    }
}

/// A running REST server. Dropping it stops accepting (connections end with their task).
pub struct RestServer {
    addr: SocketAddr,
    mode: Arc<RestMode>,
    task: JoinHandle<()>,
}

impl RestServer {
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
    /// `http://<addr>`, the base URL a channel's `AsixEvoRest` names.
    pub fn url(&self) -> String {
        format!("http://{}", self.addr)
    }
    pub fn mode(&self) -> &Arc<RestMode> {
        &self.mode
    }
}

impl Drop for RestServer {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl SimHandle {
    /// Serves the plant through the Asix.Evo REST API on `addr` (on the current tokio
    /// runtime).
    pub async fn serve_rest(&self, addr: SocketAddr) -> io::Result<RestServer> {
        let listener = TcpListener::bind(addr).await?;
        let addr = listener.local_addr()?;
        let mode = Arc::new(RestMode::default());
        let task = tokio::spawn(accept(listener, self.shared.clone(), mode.clone()));
        Ok(RestServer { addr, mode, task })
    }
}

async fn accept(listener: TcpListener, shared: Arc<Shared>, mode: Arc<RestMode>) {
    let mut conns = tokio::task::JoinSet::new();
    loop {
        let (stream, peer) = match listener.accept().await {
            Ok(x) => x,
            Err(e) => {
                debug!(error = %e, "REST accept");
                tokio::time::sleep(Duration::from_millis(10)).await;
                continue;
            }
        };
        let _ = stream.set_nodelay(true);
        let (shared, mode) = (shared.clone(), mode.clone());
        while conns.try_join_next().is_some() {}
        conns.spawn(async move {
            let svc = hyper::service::service_fn(move |req| {
                let (shared, mode) = (shared.clone(), mode.clone());
                async move { Ok::<_, Infallible>(handle(&shared, &mode, peer, req).await) }
            });
            let _ = hyper::server::conn::http1::Builder::new()
                .serve_connection(TokioIo::new(stream), svc)
                .await;
        });
    }
}

type Body = BoxBody<Bytes, Infallible>;

fn full(status: StatusCode, ctype: &str, body: impl Into<Bytes>) -> Response<Body> {
    let mut r = Response::new(Full::new(body.into()).boxed());
    *r.status_mut() = status;
    if let Ok(v) = ctype.parse() {
        r.headers_mut().insert(hyper::header::CONTENT_TYPE, v);
    }
    r
}

fn json(v: &serde_json::Value) -> Response<Body> {
    full(
        StatusCode::OK,
        "application/json; charset=utf-8",
        serde_json::to_vec(v).unwrap_or_default(),
    )
}

/// A body fed by a task (the slow and the endless bodies).
struct ChanBody(mpsc::Receiver<Bytes>);

impl futures_core::Stream for ChanBody {
    type Item = Result<Frame<Bytes>, Infallible>;
    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Self::Item>> {
        self.0.poll_recv(cx).map(|o| o.map(|b| Ok(Frame::data(b))))
    }
}

fn streamed(chunks: impl Iterator<Item = Bytes> + Send + 'static, gap: Duration) -> Response<Body> {
    let (tx, rx) = mpsc::channel(1);
    tokio::spawn(async move {
        for c in chunks {
            if tx.send(c).await.is_err() {
                break;
            }
            if !gap.is_zero() {
                tokio::time::sleep(gap).await;
            }
        }
    });
    let mut r = Response::new(StreamBody::new(ChanBody(rx)).boxed());
    if let Ok(v) = "application/json".parse() {
        r.headers_mut().insert(hyper::header::CONTENT_TYPE, v);
    }
    r
}

async fn handle(
    shared: &Shared,
    mode: &RestMode,
    peer: SocketAddr,
    req: Request<Incoming>,
) -> Response<Body> {
    let path = req.uri().path().to_owned();
    let query = req.uri().query().unwrap_or("").to_owned();
    match (req.method(), path.as_str()) {
        (&Method::POST, "/sim/mode") => {
            if !peer.ip().is_loopback() {
                return full(StatusCode::FORBIDDEN, "text/plain", "loopback only\n");
            }
            match mode.apply(&query) {
                Ok(()) => full(StatusCode::OK, "text/plain", mode.describe() + "\n"),
                Err(e) => full(StatusCode::BAD_REQUEST, "text/plain", e + "\n"),
            }
        }
        (&Method::GET, "/sim/stats") => full(StatusCode::OK, "text/plain", mode.describe() + "\n"),
        (&Method::GET, p) if p.starts_with("/asix/v1/") => {
            mode.requests.fetch_add(1, Ordering::Relaxed);
            let slow = mode.slow_ms.load(Ordering::SeqCst);
            if slow > 0 {
                tokio::time::sleep(Duration::from_millis(slow)).await;
            }
            if mode.fail.load(Ordering::SeqCst) {
                return full(StatusCode::SERVICE_UNAVAILABLE, "text/plain", "failing\n");
            }
            if mode.redirect.load(Ordering::SeqCst) {
                let mut r = full(StatusCode::FOUND, "text/plain", "");
                if let Ok(v) = "/elsewhere".parse() {
                    r.headers_mut().insert(hyper::header::LOCATION, v);
                }
                return r;
            }
            if mode.huge.load(Ordering::SeqCst) {
                let chunk = Bytes::from(vec![b' '; 64 << 10]);
                return streamed(
                    std::iter::once(Bytes::from_static(b"[")).chain(std::iter::repeat(chunk)),
                    Duration::ZERO,
                );
            }
            if mode.malformed.load(Ordering::SeqCst) {
                return full(StatusCode::OK, "application/json", "[{\"id\":\"A0");
            }
            let body = api(shared, mode, p, &query);
            let gap = mode.slow_body_ms.load(Ordering::SeqCst);
            match body {
                Some(v) if gap > 0 => {
                    let bytes = serde_json::to_vec(&v).unwrap_or_default();
                    let chunks: Vec<Bytes> = bytes.chunks(1).map(Bytes::copy_from_slice).collect();
                    streamed(chunks.into_iter(), Duration::from_millis(gap))
                }
                Some(v) => json(&v),
                None => full(StatusCode::NOT_FOUND, "text/plain", "no such request\n"),
            }
        }
        _ => full(StatusCode::NOT_FOUND, "text/plain", "no such request\n"),
    }
}

/// The answer of an API request, `None` for an unknown one.
fn api(shared: &Shared, mode: &RestMode, path: &str, query: &str) -> Option<serde_json::Value> {
    use serde_json::Value as J;
    let pairs = query_pairs(query);
    let names: Vec<&str> = pairs
        .iter()
        .filter(|(k, _)| k.eq_ignore_ascii_case("name"))
        .map(|(_, v)| v.as_str())
        .collect();
    match path {
        "/asix/v1/variable/value" => {
            mode.names.fetch_add(names.len() as u64, Ordering::Relaxed);
            let names = if mode.single.load(Ordering::SeqCst) {
                &names[..names.len().min(1)]
            } else {
                &names[..]
            };
            let p = shared.plant_now();
            let states = names
                .iter()
                .map(|n| match p.lookup("", n) {
                    Some(i) => state(n, &p.vqt(i)),
                    None => serde_json::json!({
                        "id": n,
                        "readSucceeded": false,
                        "readStatusString": "Unknown variable",
                        "timeStamp": format_iso8601(crate::client::wall_now()),
                        "quality": 0,
                        "value": null,
                    }),
                })
                .collect();
            Some(J::Array(states))
        }
        "/asix/v1/server/variable/attribute" => Some(serde_json::json!(["Name", "Type"])),
        "/asix/v1/variable/attribute" => {
            let attrs: Vec<&str> = pairs
                .iter()
                .filter(|(k, _)| k.eq_ignore_ascii_case("attribute"))
                .map(|(_, v)| v.as_str())
                .collect();
            let p = shared.lock();
            let rows = names
                .iter()
                .map(|n| match p.lookup("", n) {
                    None => J::Null,
                    Some(i) => J::Array(
                        attrs
                            .iter()
                            .map(|a| {
                                J::String(match a.to_ascii_lowercase().as_str() {
                                    "name" => (*n).to_owned(),
                                    "type" => format!("{:?}", p.vars()[i].spec().var_type),
                                    _ => String::new(),
                                })
                            })
                            .collect(),
                    ),
                })
                .collect();
            Some(J::Array(rows))
        }
        _ => None,
    }
}

/// One variable state as the REST server writes it (camelCase).
fn state(name: &str, v: &Vqt) -> serde_json::Value {
    let value = match &v.value {
        Value::Bool(b) => serde_json::Value::Bool(*b),
        Value::Bstr(s) => serde_json::Value::String(s.clone()),
        Value::I1(x) => (*x).into(),
        Value::UI1(x) => (*x).into(),
        Value::I2(x) => (*x).into(),
        Value::UI2(x) => (*x).into(),
        Value::I4(x) => (*x).into(),
        Value::UI4(x) => (*x).into(),
        Value::I8(x) => (*x).into(),
        Value::UI8(x) => (*x).into(),
        Value::R4(x) => {
            serde_json::Number::from_f64(f64::from(*x)).map_or(serde_json::Value::Null, Into::into)
        }
        Value::R8(x) => {
            serde_json::Number::from_f64(*x).map_or(serde_json::Value::Null, Into::into)
        }
        _ => serde_json::Value::Null,
    };
    serde_json::json!({
        "id": name,
        "readSucceeded": true,
        "readStatusString": "",
        "timeStamp": format_iso8601(v.timestamp),
        "quality": v.quality.0,
        "value": value,
    })
}

/// The `key=value` pairs of a query, percent-decoded (`+` is a space).
pub fn query_pairs(query: &str) -> Vec<(String, String)> {
    query
        .split('&')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let (k, v) = p.split_once('=').unwrap_or((p, ""));
            (percent_decode(k), percent_decode(v))
        })
        .collect()
}

fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'%' if i + 2 < b.len() => {
                let hex = std::str::from_utf8(&b[i + 1..i + 3]).ok();
                match hex.and_then(|h| u8::from_str_radix(h, 16).ok()) {
                    Some(v) => {
                        out.push(v);
                        i += 3;
                        continue;
                    }
                    None => out.push(b'%'),
                }
            }
            b'+' => out.push(b' '),
            c => out.push(c),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}
