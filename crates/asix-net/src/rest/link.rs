//! The REST link's tokio shell: [`RestLink`], a handle whose methods never block (they
//! queue a command), over a task that runs [`RestCore`] and makes its GETs with one pooled
//! keep-alive HTTP client (reqwest over hyper, rustls for HTTPS).
//!
//! Every request is bounded: the whole exchange (connect, headers, body) by the request
//! time limit, the body by [`super::MAX_BODY`] bytes read chunk by chunk (a `Content-Length`
//! over it is refused before reading), redirects are not followed, no proxy is used. A
//! request that breaks a bound is a failed request ([`FetchError`]) for the core: BAD
//! quality and failover, never a panic or a blocked driver. The credential (basic or a
//! header) is sent marked sensitive and is in no log line or error text.
//!
//! The HTTP client is the crate feature `rest`; without it ([`CLIENT_BUILT`] false)
//! [`RestLink::start`] refuses with [`StartError::NotBuilt`] and [`probe`] asks nobody.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use asix_model::{ItemKey, Secret};
use ctopc_core::VarType;
#[cfg(feature = "rest")]
use reqwest::header::{HeaderMap, HeaderName, HeaderValue};
use tokio::runtime::Handle;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
#[cfg(feature = "rest")]
use tokio::task::JoinSet;
#[cfg(feature = "rest")]
use tracing::debug;

use super::core::{FetchError, RestCoreConfig};
#[cfg(feature = "rest")]
use super::core::{Get, GetId, RestCore};
#[cfg(feature = "rest")]
use super::decode::{decode_values, VarState};
#[cfg(feature = "rest")]
use crate::client::now;
use crate::client::{EventSink, RequestId};

/// Whether this build has the REST link's HTTP client (the crate feature `rest`).
pub const CLIENT_BUILT: bool = cfg!(feature = "rest");

/// How a REST link authenticates.
#[derive(Clone, Default)]
pub enum Auth {
    #[default]
    None,
    /// HTTP basic authentication.
    Basic {
        user: String,
        password: Option<Secret>,
    },
    /// One header with every request (`Name: value`).
    Header(Secret),
}

impl std::fmt::Debug for Auth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Auth::None => f.write_str("None"),
            Auth::Basic { user, .. } => write!(f, "Basic {{ user: {user:?}, password: .. }}"),
            Auth::Header(_) => f.write_str("Header(..)"),
        }
    }
}

/// Everything a REST link needs.
#[derive(Debug, Clone)]
pub struct RestSettings {
    pub core: RestCoreConfig,
    pub auth: Auth,
    /// The time limit of one request (poll or device read), body included.
    pub request_timeout: Duration,
    /// The largest body read (default [`super::MAX_BODY`]).
    pub max_body: usize,
}

#[cfg_attr(not(feature = "rest"), allow(dead_code))]
enum Command {
    Subscribe(Vec<(ItemKey, VarType)>, u32),
    Unsubscribe(Vec<ItemKey>),
    Read(RequestId, Vec<(ItemKey, VarType)>),
}

/// Handle of a running REST link. Dropping it ends the link and its requests.
pub struct RestLink {
    tx: mpsc::UnboundedSender<Command>,
    ids: AtomicU64,
    task: Option<JoinHandle<()>>,
}

/// Why a link could not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error("the AsixEvoHeader option is not a valid header")]
    BadHeader,
    #[error("no station configured")]
    NoStation,
    #[error("HTTP client: {0}")]
    Client(String),
    #[error("this program is built without the Asix.Evo REST client")]
    NotBuilt,
}

#[cfg(feature = "rest")]
fn client(s: &RestSettings) -> Result<reqwest::Client, StartError> {
    let mut headers = HeaderMap::new();
    if let Auth::Header(h) = &s.auth {
        let (name, value) = h.expose().split_once(':').ok_or(StartError::BadHeader)?;
        let name =
            HeaderName::from_bytes(name.trim().as_bytes()).map_err(|_| StartError::BadHeader)?;
        let mut value = HeaderValue::from_str(value.trim()).map_err(|_| StartError::BadHeader)?;
        value.set_sensitive(true);
        headers.insert(name, value);
    }
    reqwest::Client::builder()
        .default_headers(headers)
        .redirect(reqwest::redirect::Policy::none())
        .no_proxy()
        .tcp_nodelay(true)
        .connect_timeout(s.request_timeout)
        .pool_max_idle_per_host(s.core.max_in_flight + 2)
        .pool_idle_timeout(Duration::from_secs(60))
        .use_rustls_tls()
        .build()
        .map_err(|e| StartError::Client(error_text(&e)))
}

impl RestLink {
    /// Starts the link on a tokio runtime; nothing is asked until variables are subscribed
    /// or read.
    pub fn start(
        s: RestSettings,
        sink: impl EventSink,
        rt: &Handle,
    ) -> Result<RestLink, StartError> {
        if s.core.stations.is_empty() {
            return Err(StartError::NoStation);
        }
        #[cfg(not(feature = "rest"))]
        {
            let _ = (sink, rt);
            Err(StartError::NotBuilt)
        }
        #[cfg(feature = "rest")]
        {
            let http = client(&s)?;
            let (tx, rx) = mpsc::unbounded_channel();
            let core = RestCore::new(s.core.clone());
            let task = rt.spawn(run(core, http, s, rx, sink));
            Ok(RestLink {
                tx,
                ids: AtomicU64::new(0),
                task: Some(task),
            })
        }
    }

    /// Subscribes variables (or changes their rate), each with its canonical type.
    pub fn subscribe(&self, keys: Vec<(ItemKey, VarType)>, rate_ms: u32) {
        let _ = self.tx.send(Command::Subscribe(keys, rate_ms));
    }

    pub fn unsubscribe(&self, keys: Vec<ItemKey>) {
        let _ = self.tx.send(Command::Unsubscribe(keys));
    }

    /// Reads from the station; the result comes as `ClientEvent::ReadDone` with this id.
    pub fn read(&self, keys: Vec<(ItemKey, VarType)>) -> RequestId {
        let id = self.ids.fetch_add(1, Ordering::Relaxed) + 1;
        let _ = self.tx.send(Command::Read(id, keys));
        id
    }
}

impl Drop for RestLink {
    fn drop(&mut self) {
        if let Some(t) = self.task.take() {
            t.abort();
        }
    }
}

#[cfg(feature = "rest")]
async fn run(
    mut core: RestCore,
    http: reqwest::Client,
    s: RestSettings,
    mut rx: mpsc::UnboundedReceiver<Command>,
    mut sink: impl EventSink,
) {
    // Dropped with the task: every request under way ends with it.
    let mut requests: JoinSet<(GetId, Result<Vec<VarState>, FetchError>)> = JoinSet::new();
    loop {
        while let Some(g) = core.poll_get() {
            let http = http.clone();
            let url = format!("{}{}", s.core.stations[g.station], g.path);
            let (auth, timeout, max) = (s.auth.clone(), s.request_timeout, s.max_body);
            requests.spawn(async move {
                let r = fetch(&http, &url, &auth, &g, timeout, max).await;
                (g.id, r)
            });
        }
        while let Some(ev) = core.poll_event() {
            sink.deliver(ev);
        }
        let deadline = core.poll_timeout();
        tokio::select! {
            cmd = rx.recv() => match cmd {
                None => break,
                Some(Command::Subscribe(keys, rate)) => core.subscribe(now(), keys, rate),
                Some(Command::Unsubscribe(keys)) => core.unsubscribe(keys),
                Some(Command::Read(id, keys)) => core.read(now(), id, keys),
            },
            Some(done) = requests.join_next(), if !requests.is_empty() => {
                if let Ok((id, r)) = done {
                    core.handle_answer(now(), id, r);
                }
            }
            () = sleep_until(deadline) => core.handle_timeout(now()),
        }
    }
    requests.abort_all();
}

#[cfg(feature = "rest")]
async fn sleep_until(t: Option<std::time::Instant>) {
    match t {
        Some(t) => tokio::time::sleep_until(t.into()).await,
        None => std::future::pending().await,
    }
}

#[cfg(feature = "rest")]
/// One GET with its bounds; the decoded states (a probe of the attribute list: none).
async fn fetch(
    http: &reqwest::Client,
    url: &str,
    auth: &Auth,
    g: &Get,
    timeout: Duration,
    max: usize,
) -> Result<Vec<VarState>, FetchError> {
    let exchange = async {
        let mut rb = http.get(url);
        if let Auth::Basic { user, password } = auth {
            rb = rb.basic_auth(user, password.as_ref().map(Secret::expose));
        }
        let mut resp = rb.send().await.map_err(transport)?;
        let status = resp.status();
        if status.is_redirection() {
            return Err(FetchError::Redirect(status.as_u16()));
        }
        if !status.is_success() {
            return Err(FetchError::Status(status.as_u16()));
        }
        if resp.content_length().is_some_and(|n| n > max as u64) {
            return Err(FetchError::TooLarge(max));
        }
        let mut body =
            Vec::with_capacity(resp.content_length().unwrap_or(0).min(64 << 10) as usize);
        while let Some(chunk) = resp.chunk().await.map_err(transport)? {
            if body.len() + chunk.len() > max {
                return Err(FetchError::TooLarge(max));
            }
            body.extend_from_slice(&chunk);
        }
        Ok(body)
    };
    let body = match tokio::time::timeout(timeout, exchange).await {
        Ok(r) => r?,
        Err(_) => return Err(FetchError::Timeout),
    };
    if g.names.is_empty() {
        return serde_json::from_slice::<serde::de::IgnoredAny>(&body)
            .map(|_| Vec::new())
            .map_err(|e| FetchError::Malformed(format!("malformed answer: {e}")));
    }
    decode_values(&body).map_err(|e| {
        debug!(url, error = %e, "Asix.Evo REST answer");
        FetchError::Malformed(e.to_string())
    })
}

#[cfg(feature = "rest")]
fn transport(e: reqwest::Error) -> FetchError {
    if e.is_timeout() {
        return FetchError::Timeout;
    }
    // The station is named by the log line; the URL (with its names) is left out.
    FetchError::Transport(error_text(&e.without_url()))
}

#[cfg(feature = "rest")]
/// An error and its causes on one line, cut to a log line's size.
fn error_text(e: &reqwest::Error) -> String {
    let mut s = String::new();
    let mut cur: Option<&dyn std::error::Error> = Some(e);
    while let Some(x) = cur {
        let t = x.to_string();
        if !s.contains(&t) {
            if !s.is_empty() {
                s.push_str(": ");
            }
            s.push_str(&t);
        }
        cur = x.source();
    }
    if s.len() > 300 {
        let mut end = 300;
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        s.truncate(end);
    }
    s
}

/// Asks every station of a REST link for its attribute list (`GET
/// /asix/v1/server/variable/attribute`, bounded as a poll is): whether each answers, in
/// the configured order (`opcdiag doctor`).
pub async fn probe(s: &RestSettings) -> Vec<(String, Result<(), FetchError>)> {
    #[cfg(not(feature = "rest"))]
    {
        let e = FetchError::Transport(StartError::NotBuilt.to_string());
        s.core
            .stations
            .iter()
            .map(|u| (u.clone(), Err(e.clone())))
            .collect()
    }
    #[cfg(feature = "rest")]
    probe_each(s).await
}

#[cfg(feature = "rest")]
async fn probe_each(s: &RestSettings) -> Vec<(String, Result<(), FetchError>)> {
    let http = match client(s) {
        Ok(h) => h,
        Err(e) => {
            let e = FetchError::Transport(e.to_string());
            return s
                .core
                .stations
                .iter()
                .map(|u| (u.clone(), Err(e.clone())))
                .collect();
        }
    };
    let g = Get {
        id: 0,
        station: 0,
        path: "/asix/v1/server/variable/attribute".into(),
        names: Vec::new(),
    };
    let mut out = Vec::new();
    for u in &s.core.stations {
        let url = format!("{u}{}", g.path);
        let r = fetch(&http, &url, &s.auth, &g, s.request_timeout, s.max_body).await;
        out.push((u.clone(), r.map(|_| ())));
    }
    out
}
