//! Securing a new link (protocol version 2, `docs/asix-net-protocol.md` section 3): the
//! preamble exchange ([`crate::proto::link`]) and the TLS 1.3 handshake, on the client side
//! ([`client_handshake`]) and on the server side ([`server_handshake`]). What comes out is
//! a pair of byte streams for the frame loops and the peer's authenticated identity.
//!
//! Neither side waits without bound: the client's whole handshake is bounded by its
//! NetTimeout (by the caller), the server's by [`ServerSecurity::handshake_timeout`], and a
//! server runs at most [`ServerSecurity::max_handshakes`] at once (the caller holds the
//! permits and answers [`LinkStatus::Busy`] beyond them, [`refuse_busy`]).

use std::fmt;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use ctopc_core::OpcError;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpStream;
use tracing::warn;

use crate::proto::frame::{encode_frame, Message};
use crate::proto::link::{
    decode_preamble, encode_preamble, LinkMode, LinkStatus, PreambleError, PREAMBLE_LEN,
};
use crate::tls::{self, fingerprint_hex, Fingerprint, Identity, TlsError, Trust};

/// The read half of a secured link.
pub type LinkRead = Box<dyn AsyncRead + Send + Unpin>;
/// The write half of a secured link.
pub type LinkWrite = Box<dyn AsyncWrite + Send + Unpin>;

/// A link after its handshake.
pub struct Secured {
    pub rd: LinkRead,
    pub wr: LinkWrite,
    /// The peer's authenticated identity (`cert:<fingerprint>`); `None` on a plaintext link.
    pub peer: Option<String>,
    /// The peer certificate's fingerprint (TLS links).
    pub peer_fingerprint: Option<Fingerprint>,
}

/// How a client's links are secured (one setting per AsixConnect channel).
#[derive(Clone)]
pub enum ClientSecurity {
    /// TLS 1.3 with the client's certificate, accepting the servers `trust` pins.
    Tls {
        config: Arc<rustls::ClientConfig>,
        trust: Trust,
    },
    /// Plaintext links (`AsixNetPlaintext = 1`): for a closed test network only; every
    /// link is logged with a warning.
    Plaintext,
    /// No usable setting (no certificate, no pinned server, a file that cannot be read):
    /// no link is made, and this says why.
    Unconfigured(String),
}

impl fmt::Debug for ClientSecurity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ClientSecurity::Tls { trust, .. } => write!(f, "Tls({trust:?})"),
            ClientSecurity::Plaintext => f.write_str("Plaintext"),
            ClientSecurity::Unconfigured(why) => write!(f, "Unconfigured({why})"),
        }
    }
}

impl Default for ClientSecurity {
    fn default() -> Self {
        ClientSecurity::Unconfigured(
            "no TLS identity (AsixNetCertFile, AsixNetKeyFile) and no pinned server (AsixNetServerFingerprint or AsixNetCaFile), and plaintext is not allowed (AsixNetPlaintext)".into(),
        )
    }
}

impl ClientSecurity {
    /// TLS with `identity`, accepting the servers `trust` pins.
    pub fn tls(identity: &Identity, trust: Trust) -> Result<ClientSecurity, TlsError> {
        Ok(ClientSecurity::Tls {
            config: tls::client_config(identity, trust.clone())?,
            trust,
        })
    }

    /// May a server announcing this fingerprint be linked to? A TLS client never tries a
    /// server that announces no fingerprint or an unpinned one; a plaintext client tries any.
    pub fn accepts_announcement(&self, fp: Option<&Fingerprint>) -> bool {
        match self {
            ClientSecurity::Tls { trust, .. } => fp.is_some_and(|f| trust.may_accept(f)),
            ClientSecurity::Plaintext => true,
            ClientSecurity::Unconfigured(_) => false,
        }
    }
}

/// Why a link could not be made: the client's error code and a reason for the log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkRefused {
    pub error: OpcError,
    pub reason: String,
}

fn refused(error: OpcError, reason: impl Into<String>) -> LinkRefused {
    LinkRefused {
        error,
        reason: reason.into(),
    }
}

/// The client's side of a new link: preamble, then TLS whose server certificate must be
/// pinned and, when the announcement named one, have the announced fingerprint.
pub async fn client_handshake(
    mut stream: TcpStream,
    security: &ClientSecurity,
    announced: Option<Fingerprint>,
) -> Result<Secured, LinkRefused> {
    let _ = stream.set_nodelay(true);
    let mode = match security {
        ClientSecurity::Tls { .. } => LinkMode::Tls,
        ClientSecurity::Plaintext => LinkMode::Plaintext,
        ClientSecurity::Unconfigured(why) => {
            return Err(refused(OpcError::NetLinkToServer, why.clone()))
        }
    };
    let io = |e: std::io::Error| {
        refused(
            OpcError::NetLinkToServer,
            format!("during the link preamble: {e}"),
        )
    };
    stream
        .write_all(&encode_preamble(mode, LinkStatus::Accepted))
        .await
        .map_err(io)?;
    let mut answer = [0u8; PREAMBLE_LEN];
    stream.read_exact(&mut answer).await.map_err(io)?;
    let p = decode_preamble(&answer).map_err(|e| match e {
        PreambleError::Version1 => refused(
            OpcError::NetLinkToServerNegativeAnswer,
            "the server speaks asix protocol version 1 (plaintext, no TLS); this client speaks version 2",
        ),
        other => refused(OpcError::NetLinkToServerNegativeAnswer, other.to_string()),
    })?;
    match LinkStatus::from_code(p.status) {
        Some(LinkStatus::Accepted) if p.mode() == Some(mode) => {}
        Some(s) if s != LinkStatus::Accepted => {
            return Err(refused(OpcError::NetLinkToServerNegativeAnswer, s.reason()))
        }
        _ => {
            return Err(refused(
                OpcError::NetLinkToServerNegativeAnswer,
                format!("unexpected preamble answer {answer:02X?}"),
            ))
        }
    }
    match security {
        ClientSecurity::Tls { config, .. } => {
            let connector = tokio_rustls::TlsConnector::from(config.clone());
            let tls = connector.connect(tls::sni(), stream).await.map_err(|e| {
                refused(
                    OpcError::NetLinkToServer,
                    format!("TLS handshake failed: {e}"),
                )
            })?;
            let fp = tls::peer_fingerprint(tls.get_ref().1);
            if let (Some(want), Some(got)) = (announced, fp) {
                if want != got {
                    return Err(refused(
                        OpcError::NetLinkToServerNegativeAnswer,
                        format!(
                            "the server's certificate {} is not the announced {}",
                            fingerprint_hex(&got),
                            fingerprint_hex(&want)
                        ),
                    ));
                }
            }
            let peer = fp.map(|f| tls::identity_of(&f));
            let (rd, wr) = tokio::io::split(tls);
            Ok(Secured {
                rd: Box::new(rd),
                wr: Box::new(wr),
                peer,
                peer_fingerprint: fp,
            })
        }
        _ => {
            let (rd, wr) = stream.into_split();
            Ok(Secured {
                rd: Box::new(rd),
                wr: Box::new(wr),
                peer: None,
                peer_fingerprint: None,
            })
        }
    }
}

/// A server's TLS identity and the clients it accepts.
#[derive(Clone)]
pub struct ServerTls {
    config: Arc<rustls::ServerConfig>,
    fingerprint: Fingerprint,
}

impl ServerTls {
    pub fn new(identity: &Identity, clients: Trust) -> Result<ServerTls, TlsError> {
        Ok(ServerTls {
            config: tls::server_config(identity, clients)?,
            fingerprint: identity.fingerprint(),
        })
    }
    /// The fingerprint of the server's certificate (announced in discovery).
    pub fn fingerprint(&self) -> Fingerprint {
        self.fingerprint
    }
}

/// How a server secures the links it accepts.
#[derive(Clone)]
pub struct ServerSecurity {
    /// TLS identity and client pins; `None`: no TLS (plaintext links only, if allowed).
    pub tls: Option<ServerTls>,
    /// Accept plaintext links (closed test networks only; each is logged with a warning).
    pub allow_plaintext: bool,
    /// The longest a new connection may take from accept to an established link.
    pub handshake_timeout: Duration,
    /// The most handshakes under way at once; more connections are refused as busy.
    pub max_handshakes: usize,
}

impl fmt::Debug for ServerSecurity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ServerSecurity")
            .field(
                "fingerprint",
                &self.fingerprint().map(|f| fingerprint_hex(&f)),
            )
            .field("allow_plaintext", &self.allow_plaintext)
            .field("handshake_timeout", &self.handshake_timeout)
            .field("max_handshakes", &self.max_handshakes)
            .finish()
    }
}

/// Default bound of a server's handshake.
pub const DEFAULT_HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);
/// Default number of concurrent handshakes a server runs.
pub const DEFAULT_MAX_HANDSHAKES: usize = 64;

impl ServerSecurity {
    pub fn tls(tls: ServerTls) -> ServerSecurity {
        ServerSecurity {
            tls: Some(tls),
            allow_plaintext: false,
            handshake_timeout: DEFAULT_HANDSHAKE_TIMEOUT,
            max_handshakes: DEFAULT_MAX_HANDSHAKES,
        }
    }
    /// Plaintext only (closed test networks).
    pub fn plaintext() -> ServerSecurity {
        ServerSecurity {
            tls: None,
            allow_plaintext: true,
            handshake_timeout: DEFAULT_HANDSHAKE_TIMEOUT,
            max_handshakes: DEFAULT_MAX_HANDSHAKES,
        }
    }
    pub fn fingerprint(&self) -> Option<Fingerprint> {
        self.tls.as_ref().map(ServerTls::fingerprint)
    }
}

/// A version-1 `Error` frame (the version-1 encoding of Error is the version-2 one with
/// byte 4 = 1), so that a version-1 client reads why it is refused.
pub fn version1_error_frame(code: OpcError, message: &str) -> Vec<u8> {
    let mut out = Vec::new();
    if encode_frame(
        &mut out,
        0,
        &Message::Error {
            code: code.hresult(),
            message: message.to_owned(),
        },
    )
    .is_ok()
    {
        out[4] = 1;
    }
    out
}

/// The message a version-1 client gets.
pub const VERSION1_REFUSAL: &str = "this asix server speaks protocol version 2 (TLS): upgrade the client (ServerCTOPC) or, on a closed test network, allow plaintext on both sides";

/// Refuses a connection without reading it: too many handshakes under way. Never waits.
pub fn refuse_busy(stream: &TcpStream) {
    let _ = stream.try_write(&encode_preamble(LinkMode::Tls, LinkStatus::Busy));
}

async fn answer(stream: &mut TcpStream, mode: LinkMode, status: LinkStatus) -> Result<(), String> {
    stream
        .write_all(&encode_preamble(mode, status))
        .await
        .map_err(|e| format!("preamble answer not sent: {e}"))
}

/// The server's side of a new link (without its time bound, which the caller sets with
/// [`ServerSecurity::handshake_timeout`]). The error says why the link was refused.
pub async fn server_handshake(
    mut stream: TcpStream,
    peer: SocketAddr,
    security: &ServerSecurity,
) -> Result<Secured, String> {
    let _ = stream.set_nodelay(true);
    let mut first = [0u8; PREAMBLE_LEN];
    stream
        .read_exact(&mut first)
        .await
        .map_err(|e| format!("closed before its preamble: {e}"))?;
    let p = match decode_preamble(&first) {
        Ok(p) => p,
        Err(PreambleError::Version1) => {
            let frame =
                version1_error_frame(OpcError::NetLinkToServerNegativeAnswer, VERSION1_REFUSAL);
            let _ = stream.write_all(&frame).await;
            let _ = stream.shutdown().await;
            return Err(
                "a protocol version 1 client (plaintext Hello): refused with an Error frame".into(),
            );
        }
        Err(e) => return Err(e.to_string()),
    };
    match (p.mode(), &security.tls) {
        (Some(LinkMode::Tls), Some(t)) => {
            answer(&mut stream, LinkMode::Tls, LinkStatus::Accepted).await?;
            let acceptor = tokio_rustls::TlsAcceptor::from(t.config.clone());
            let tls = acceptor
                .accept(stream)
                .await
                .map_err(|e| format!("TLS handshake failed: {e}"))?;
            let fp = tls::peer_fingerprint(tls.get_ref().1);
            let (rd, wr) = tokio::io::split(tls);
            Ok(Secured {
                rd: Box::new(rd),
                wr: Box::new(wr),
                peer: fp.map(|f| tls::identity_of(&f)),
                peer_fingerprint: fp,
            })
        }
        (Some(LinkMode::Tls), None) => {
            answer(&mut stream, LinkMode::Tls, LinkStatus::TlsUnavailable).await?;
            Err(LinkStatus::TlsUnavailable.reason().into())
        }
        (Some(LinkMode::Plaintext), _) if security.allow_plaintext => {
            answer(&mut stream, LinkMode::Plaintext, LinkStatus::Accepted).await?;
            warn!(%peer, "plaintext asix link accepted: no authentication, no encryption (closed test network only)");
            let (rd, wr) = stream.into_split();
            Ok(Secured {
                rd: Box::new(rd),
                wr: Box::new(wr),
                peer: None,
                peer_fingerprint: None,
            })
        }
        (Some(LinkMode::Plaintext), _) => {
            answer(
                &mut stream,
                LinkMode::Plaintext,
                LinkStatus::PlaintextRefused,
            )
            .await?;
            Err("a plaintext link asked for: plaintext is not allowed".into())
        }
        (None, _) => {
            answer(&mut stream, LinkMode::Tls, LinkStatus::BadMode).await?;
            Err(format!("unknown link mode {}", p.mode))
        }
    }
}
