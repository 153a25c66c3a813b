//! Checking a link's identity without using the link (`opcdiag doctor`): every server that
//! answers the discovery of a resource, pinned or not, is connected to and its handshake
//! made with the client's security as configured; what the server presented is reported
//! (its certificate's fingerprint, whether the pins accept it, the end of its validity),
//! or that the link is plaintext, or why no link was made. Nothing is sent after the
//! handshake: the link closes at once.
//!
//! Bounded: the discovery by FindServerTimeout, each server's connection and handshake by
//! NetTimeout.

use std::net::SocketAddr;
use std::time::Duration;

use ctopc_core::OpcError;
use tokio::net::TcpStream;

use crate::config::ClientConfig;
use crate::proto::discovery::Resource;
use crate::secure::{client_handshake, ClientSecurity};
use crate::tls::{self, Fingerprint};

/// What a server's link showed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkIdentity {
    /// A TLS handshake: the server's certificate as presented, whether the client's pins
    /// accept it (`refused`: why the handshake failed, when it did), the certificate's
    /// `notAfter` in seconds since 1970.
    Tls {
        fingerprint: Fingerprint,
        pinned: bool,
        not_after: Option<i64>,
        refused: Option<String>,
    },
    /// The client's setting is plaintext (`AsixNetPlaintext`) and the server took it.
    Plaintext,
}

/// One server of a resource and what its link showed (`Err`: unreachable or refused
/// before any certificate, with the reason).
#[derive(Debug, Clone)]
pub struct ServerProbe {
    pub server: String,
    pub addr: SocketAddr,
    /// The fingerprint the server announced.
    pub announced: Option<Fingerprint>,
    pub result: Result<LinkIdentity, String>,
}

/// Connects to `addr` and makes the handshake with `security`, within `limit`.
pub async fn probe_server(
    addr: SocketAddr,
    security: &ClientSecurity,
    announced: Option<Fingerprint>,
    limit: Duration,
) -> Result<LinkIdentity, String> {
    let stream = match tokio::time::timeout(limit, TcpStream::connect(addr)).await {
        Ok(Ok(s)) => s,
        Ok(Err(e)) => return Err(format!("unreachable: {e}")),
        Err(_) => {
            return Err(format!(
                "unreachable: no connection within {} ms",
                limit.as_millis()
            ))
        }
    };
    let (security, seen) = match security {
        ClientSecurity::Tls { config, trust } => {
            let (config, seen) = tls::recording_client_config(config, trust.clone());
            (
                ClientSecurity::Tls {
                    config,
                    trust: trust.clone(),
                },
                Some(seen),
            )
        }
        other => (other.clone(), None),
    };
    let result =
        match tokio::time::timeout(limit, client_handshake(stream, &security, announced)).await {
            Ok(Ok(_secured)) => Ok(()),
            Ok(Err(refused)) => Err(refused.reason),
            Err(_) => Err(format!(
                "the handshake did not finish within {} ms",
                limit.as_millis()
            )),
        };
    let presented = seen.and_then(|s| s.lock().unwrap_or_else(|p| p.into_inner()).take());
    match (presented, result) {
        (Some(cert), r) => Ok(LinkIdentity::Tls {
            fingerprint: tls::fingerprint(&cert),
            pinned: r.is_ok(),
            not_after: tls::not_after(&cert),
            refused: r.err(),
        }),
        (None, Ok(())) if matches!(security, ClientSecurity::Plaintext) => {
            Ok(LinkIdentity::Plaintext)
        }
        (None, Ok(())) => Err("linked without a certificate".into()),
        (None, Err(e)) => Err(e),
    }
}

/// Discovers every server answering for `resource` (as `cfg` searches, whatever
/// fingerprint it announces) and probes each one's link; the discovery's error when no
/// server answered.
pub async fn probe_resource(
    cfg: &ClientConfig,
    resource: Resource,
) -> Result<Vec<ServerProbe>, OpcError> {
    // Plaintext accepts every announcement: the pins are the probe's to judge.
    let mut any = cfg.clone();
    any.security = ClientSecurity::Plaintext;
    let found = crate::client::discover(&any, resource).await?;
    let limit = cfg.options.net_timeout;
    let probes = found.into_iter().map(|c| async move {
        let announced = c.announce.fingerprint;
        ServerProbe {
            server: c.name().to_owned(),
            addr: c.addr,
            announced,
            result: probe_server(c.addr, &cfg.security, announced, limit).await,
        }
    });
    let mut out = Vec::new();
    for p in probes {
        out.push(p.await);
    }
    Ok(out)
}
