//! Helpers for loopback tests: simulators on 127.0.0.1 with ephemeral ports, clients with
//! short timeouts, and bounded waits for events.
#![allow(dead_code)]

use std::net::{Ipv4Addr, SocketAddr};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use asix_model::ItemKey;
use asix_net::client::ClientEvent;
use asix_net::secure::{ClientSecurity, ServerSecurity, ServerTls};
use asix_net::sim::{self, SimConfig, SimHandle};
use asix_net::tls;
use asix_net::{channel_sink, AsixClient, ClientConfig};
use ctopc_core::Quality;
use tokio::sync::mpsc::UnboundedReceiver;

pub const CH: &str = "Demo_Wytwornia_Kwasu";
pub const CLIENT_HOST: &str = "CLI";
pub const CLIENT_NAME: &str = "CLI.";

/// Every test body runs under this limit.
pub const TEST_LIMIT: Duration = Duration::from_secs(30);

/// The test PKI, made once per test binary: the servers' identity (every simulator of a
/// test uses it unless the test says otherwise) and the clients'.
pub struct Pki {
    pub server: tls::Generated,
    pub client: tls::Generated,
}

pub fn pki() -> &'static Pki {
    static PKI: OnceLock<Pki> = OnceLock::new();
    PKI.get_or_init(|| Pki {
        server: tls::generate("ASIX-TEST-SERVER", None).expect("server certificate"),
        client: tls::generate("ASIX-TEST-CLIENT", None).expect("client certificate"),
    })
}

/// TLS with the test server identity, accepting any client certificate.
pub fn server_security() -> ServerSecurity {
    ServerSecurity::tls(
        ServerTls::new(&pki().server.identity, tls::Trust::AnyCertificate).expect("server TLS"),
    )
}

/// TLS with the test client identity, pinning the test server's fingerprint.
pub fn client_security() -> ClientSecurity {
    ClientSecurity::tls(
        &pki().client.identity,
        tls::Trust::Fingerprints(vec![pki().server.identity.fingerprint()]),
    )
    .expect("client TLS")
}

/// The test client's authenticated identity, as servers know it.
pub fn client_identity() -> String {
    tls::identity_of(&pki().client.identity.fingerprint())
}

/// A client with a certificate of its own (not the test client's), pinning the test server.
pub fn stranger_cfg(targets: &[SocketAddr]) -> ClientConfig {
    static STRANGER: OnceLock<tls::Generated> = OnceLock::new();
    let me = STRANGER.get_or_init(|| tls::generate("STRANGER", None).expect("certificate"));
    let mut c = client_cfg(targets);
    c.client_name = "STRANGER.".into();
    c.security = ClientSecurity::tls(
        &me.identity,
        tls::Trust::Fingerprints(vec![pki().server.identity.fingerprint()]),
    )
    .expect("client TLS");
    c
}

pub async fn sim_with(name: &str, f: impl FnOnce(&mut SimConfig)) -> SimHandle {
    let mut cfg = SimConfig::new(name);
    cfg.tick_ms = 20;
    cfg.security = server_security();
    f(&mut cfg);
    sim::start(cfg).await.expect("simulator starts")
}

pub async fn sim(name: &str) -> SimHandle {
    sim_with(name, |_| {}).await
}

/// A client configuration for loopback: short timeouts, discovery sent to `targets`.
pub fn client_cfg(targets: &[SocketAddr]) -> ClientConfig {
    let mut c = ClientConfig::new(CLIENT_NAME, CLIENT_HOST);
    c.discovery_targets = targets.to_vec();
    c.discovery_bind = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    c.options.find_server_timeout = Duration::from_millis(400);
    c.options.net_timeout = Duration::from_millis(400);
    c.discovery_resend = Duration::from_millis(100);
    c.keepalive = Duration::from_millis(100);
    c.reconnect_interval = Duration::from_millis(200);
    c.retry_failed_items = Duration::from_millis(300);
    c.security = client_security();
    c
}

pub fn client(cfg: ClientConfig) -> (AsixClient, Events) {
    let (sink, rx) = channel_sink();
    let c =
        AsixClient::start(cfg, sink, &tokio::runtime::Handle::current()).expect("client starts");
    (
        c,
        Events {
            rx,
            seen: Vec::new(),
        },
    )
}

pub fn key(var: &str) -> ItemKey {
    ItemKey::new(CH, var)
}

/// The event stream with bounded waits.
pub struct Events {
    pub rx: UnboundedReceiver<ClientEvent>,
    /// Every event received so far.
    pub seen: Vec<ClientEvent>,
}

impl Events {
    /// Waits (at most `limit`) for the first event satisfying `f`; panics otherwise.
    pub async fn wait<T>(
        &mut self,
        limit: Duration,
        what: &str,
        mut f: impl FnMut(&ClientEvent) -> Option<T>,
    ) -> T {
        let deadline = Instant::now() + limit;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match tokio::time::timeout(left, self.rx.recv()).await {
                Ok(Some(ev)) => {
                    let r = f(&ev);
                    self.seen.push(ev);
                    if let Some(r) = r {
                        return r;
                    }
                }
                Ok(None) => panic!("client ended while waiting for {what}"),
                Err(_) => panic!(
                    "timed out after {limit:?} waiting for {what}; saw {:#?}",
                    tail(&self.seen)
                ),
            }
        }
    }

    /// The server a channel came up on.
    pub async fn channel_up(&mut self, limit: Duration) -> String {
        self.wait(limit, "ChannelUp", |e| match e {
            ClientEvent::ChannelUp { server, .. } => Some(server.clone()),
            _ => None,
        })
        .await
    }

    /// The next VQT of `k` whose quality satisfies `q`.
    pub async fn vqt_of(
        &mut self,
        k: &ItemKey,
        limit: Duration,
        what: &str,
        q: impl Fn(Quality) -> bool,
    ) -> asix_net::Vqt {
        self.wait(limit, what, |e| match e {
            ClientEvent::Updates(u) => u
                .iter()
                .rev()
                .find(|(kk, v)| kk == k && q(v.quality))
                .map(|(_, v)| v.clone()),
            _ => None,
        })
        .await
    }

    /// Drains what has arrived without waiting.
    pub fn drain(&mut self) {
        while let Ok(ev) = self.rx.try_recv() {
            self.seen.push(ev);
        }
    }
}

fn tail(v: &[ClientEvent]) -> Vec<String> {
    v.iter()
        .rev()
        .take(8)
        .map(|e| {
            let s = format!("{e:?}");
            s.chars().take(300).collect()
        })
        .collect()
}

/// A link to a simulator at the byte level, as the test client: preamble, TLS.
pub async fn raw_link(addr: SocketAddr) -> tokio_rustls::client::TlsStream<tokio::net::TcpStream> {
    use asix_net::proto::link::{encode_preamble, LinkMode, LinkStatus};
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(addr)
        .await
        .expect("connects");
    s.write_all(&encode_preamble(LinkMode::Tls, LinkStatus::Accepted))
        .await
        .expect("preamble sent");
    let mut answer = [0u8; 8];
    s.read_exact(&mut answer).await.expect("preamble answered");
    assert_eq!(answer, encode_preamble(LinkMode::Tls, LinkStatus::Accepted));
    let ClientSecurity::Tls { config, .. } = client_security() else {
        unreachable!()
    };
    tokio_rustls::TlsConnector::from(config)
        .connect(tls::sni(), s)
        .await
        .expect("TLS handshake")
}
