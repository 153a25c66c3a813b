//! The server role's plumbing that every asix data server shares (asix-sim, asix-gate):
//! answering discovery, accepting links under the handshake cap, securing a link within
//! its bound, reading a link's frames, and encoding a reply. What a server serves, and
//! how, stays with it.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use ctopc_core::OpcError;
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::{mpsc, watch, OwnedSemaphorePermit, Semaphore};
use tracing::{debug, warn};

use crate::proto::codec::{frames, next_frame, ReadError};
use crate::proto::discovery::{
    decode_datagram, encode_datagram, Announce, Datagram, FindServer, Resource,
};
use crate::proto::frame::{encode_frame, Frame, Message};
use crate::proto::{DecodeError, MAX_DATAGRAM};
use crate::secure::{refuse_busy, server_handshake, LinkRead, Secured, ServerSecurity};

/// Answers FindServer datagrams with what `answer` announces (`None`: stay silent) until
/// `shutdown` changes.
pub async fn discovery_loop(
    sock: UdpSocket,
    mut shutdown: watch::Receiver<bool>,
    answer: impl Fn(&FindServer) -> Option<Announce>,
) {
    let mut buf = vec![0u8; MAX_DATAGRAM + 1];
    loop {
        let (n, from) = tokio::select! {
            _ = shutdown.changed() => break,
            r = sock.recv_from(&mut buf) => match r {
                Ok(x) => x,
                Err(e) => {
                    // e.g. ICMP port unreachable reported on Windows; do not spin.
                    debug!(error = %e, "discovery socket error");
                    tokio::time::sleep(Duration::from_millis(10)).await;
                    continue;
                }
            },
        };
        let Ok(Datagram::FindServer(f)) = decode_datagram(&buf[..n]) else {
            continue;
        };
        let Some(a) = answer(&f) else { continue };
        match encode_datagram(&Datagram::Announce(a)) {
            Ok(bytes) => {
                let _ = sock.send_to(&bytes, from).await;
            }
            Err(e) => warn!(error = %e, "announcement not encodable"),
        }
    }
}

/// Accepts connections until `shutdown` changes; each gets a permit of `handshakes` and
/// goes to `serve`, connections beyond the cap are refused as busy without being read.
pub async fn accept_loop(
    listener: TcpListener,
    mut shutdown: watch::Receiver<bool>,
    handshakes: Arc<Semaphore>,
    serve: impl Fn(TcpStream, SocketAddr, OwnedSemaphorePermit),
) {
    loop {
        tokio::select! {
            _ = shutdown.changed() => break,
            r = listener.accept() => match r {
                Ok((stream, peer)) => match handshakes.clone().try_acquire_owned() {
                    Ok(permit) => {
                        debug!(%peer, "connection accepted");
                        serve(stream, peer, permit);
                    }
                    Err(_) => {
                        debug!(%peer, "too many handshakes under way: connection refused as busy");
                        refuse_busy(&stream);
                    }
                },
                Err(e) => {
                    debug!(error = %e, "accept failed");
                    tokio::time::sleep(Duration::from_millis(10)).await;
                }
            },
        }
    }
}

/// Secures a new link within the handshake bound (a refusal is logged); `None` when it
/// was refused, took too long or `shutdown` changed first.
pub async fn secure_link(
    stream: TcpStream,
    peer: SocketAddr,
    security: &ServerSecurity,
    shutdown: &mut watch::Receiver<bool>,
) -> Option<Secured> {
    let handshake = tokio::time::timeout(
        security.handshake_timeout,
        server_handshake(stream, peer, security),
    );
    tokio::select! {
        r = handshake => match r {
            Ok(Ok(s)) => Some(s),
            Ok(Err(reason)) => {
                warn!(%peer, %reason, "asix link refused");
                None
            }
            Err(_) => {
                warn!(%peer, timeout_ms = security.handshake_timeout.as_millis() as u64, "asix link refused: handshake not finished in time");
                None
            }
        },
        _ = shutdown.changed() => None,
    }
}

/// Reads a link's frames into `tx` (bounded: the link's loop takes them at its pace) until
/// the link ends or a frame does not decode (sent, then the end).
pub async fn read_frames(rd: LinkRead, tx: mpsc::Sender<Result<Frame, DecodeError>>) {
    let mut rd = frames(rd);
    loop {
        let r = match next_frame(&mut rd).await {
            Some(Ok(frame)) => Ok(frame),
            Some(Err(ReadError::Decode(e))) => Err(e),
            None | Some(Err(ReadError::Io(_))) => return,
        };
        let stop = r.is_err();
        if tx.send(r).await.is_err() || stop {
            return;
        }
    }
}

/// The Error frame that answers an undecodable frame before the link closes.
pub fn bad_frame(out: &mut Vec<u8>, e: &DecodeError) {
    let code = match e {
        DecodeError::Version(_) => OpcError::NetLinkToServerNegativeAnswer,
        _ => OpcError::NetSendData,
    };
    let _ = encode_frame(
        out,
        0,
        &Message::Error {
            code: code.hresult(),
            message: e.to_string(),
        },
    );
}

/// Appends the reply to `request`; one that cannot be encoded becomes an Error (E_FAIL).
pub fn reply(out: &mut Vec<u8>, request: u32, msg: &Message) {
    if let Err(e) = encode_frame(out, request, msg) {
        warn!(error = %e, "reply not encodable");
        let _ = encode_frame(
            out,
            request,
            &Message::Error {
                code: OpcError::Fail.hresult(),
                message: e.to_string(),
            },
        );
    }
}

/// The resources an announcement lists: the one asked for first (when named), then the
/// rest of what the server offers.
pub fn announced_resources(offered: &[Resource], asked: &Resource) -> Vec<Resource> {
    let mut resources = Vec::with_capacity(offered.len() + 1);
    if !asked.name.is_empty() {
        resources.push(asked.clone());
    }
    resources.extend(offered.iter().filter(|r| *r != asked).cloned());
    resources
}
