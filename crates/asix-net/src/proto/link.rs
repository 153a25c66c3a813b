//! The link preamble of protocol version 2 (`docs/asix-net-protocol.md`, section 3): the
//! 8 bytes each side sends first on a new TCP connection, before TLS (or, where both sides
//! allow it, plaintext frames).
//!
//! ```text
//! offset type    field
//! 0      [u8;4]  magic "ASXL" (41 53 58 4C)
//! 4      u8      version = 2
//! 5      u8      mode: 1 TLS, 0 plaintext (client: asked for; server: granted)
//! 6      u16     status: 0 in the client's; the server's: 0 accepted, else a refusal
//! ```
//!
//! A version-1 peer never sends this: its first bytes are a frame header (a length, then
//! version 1), which [`decode_preamble`] recognises ([`PreambleError::Version1`]) so that
//! either side can say so instead of failing obscurely.

use super::{FRAME_HEADER_LEN, MAX_FRAME};

/// The preamble's magic, `"ASXL"`.
pub const LINK_MAGIC: [u8; 4] = *b"ASXL";
/// The link version of the preamble.
pub const LINK_VERSION: u8 = super::PROTOCOL_VERSION;
/// Length of the preamble.
pub const PREAMBLE_LEN: usize = 8;

/// How the link goes on after the preamble.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkMode {
    /// Frames in the clear (only where both sides allow it: closed test networks).
    Plaintext = 0,
    /// A TLS 1.3 handshake, then frames inside TLS.
    Tls = 1,
}

/// The server's answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkStatus {
    /// The mode asked for is granted; the link goes on in it.
    Accepted = 0,
    /// Plaintext asked for, and the server does not allow it.
    PlaintextRefused = 1,
    /// TLS asked for, and the server has no certificate.
    TlsUnavailable = 2,
    /// Too many handshakes under way; try again later.
    Busy = 3,
    /// A mode the server does not know.
    BadMode = 4,
}

impl LinkStatus {
    pub fn from_code(c: u16) -> Option<LinkStatus> {
        Some(match c {
            0 => LinkStatus::Accepted,
            1 => LinkStatus::PlaintextRefused,
            2 => LinkStatus::TlsUnavailable,
            3 => LinkStatus::Busy,
            4 => LinkStatus::BadMode,
            _ => return None,
        })
    }

    /// What a refusal means, for the log.
    pub fn reason(self) -> &'static str {
        match self {
            LinkStatus::Accepted => "accepted",
            LinkStatus::PlaintextRefused => "the server does not allow plaintext links",
            LinkStatus::TlsUnavailable => "the server has no TLS certificate",
            LinkStatus::Busy => "the server has too many handshakes under way",
            LinkStatus::BadMode => "the server does not know the link mode asked for",
        }
    }
}

/// A decoded preamble.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Preamble {
    /// The mode byte (0 or 1 are defined).
    pub mode: u8,
    /// The status field.
    pub status: u16,
}

impl Preamble {
    pub fn mode(&self) -> Option<LinkMode> {
        match self.mode {
            0 => Some(LinkMode::Plaintext),
            1 => Some(LinkMode::Tls),
            _ => None,
        }
    }
}

/// Why the first 8 bytes are not a preamble.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PreambleError {
    /// They are a protocol-version-1 frame header: the peer speaks version 1 (plaintext).
    #[error("the peer speaks asix protocol version 1 (plaintext, no TLS)")]
    Version1,
    /// The magic is right and the version is not 2.
    #[error("the peer speaks link version {0}")]
    Version(u8),
    /// Not the asix protocol at all.
    #[error("the peer does not speak the asix protocol")]
    NotAsix,
}

/// The 8 bytes of a preamble.
pub fn encode_preamble(mode: LinkMode, status: LinkStatus) -> [u8; PREAMBLE_LEN] {
    let s = (status as u16).to_le_bytes();
    let [a, b, c, d] = LINK_MAGIC;
    [a, b, c, d, LINK_VERSION, mode as u8, s[0], s[1]]
}

/// Decodes the first 8 bytes a peer sent.
pub fn decode_preamble(b: &[u8; PREAMBLE_LEN]) -> Result<Preamble, PreambleError> {
    if b[..4] == LINK_MAGIC {
        if b[4] != LINK_VERSION {
            return Err(PreambleError::Version(b[4]));
        }
        return Ok(Preamble {
            mode: b[5],
            status: u16::from_le_bytes([b[6], b[7]]),
        });
    }
    let len = u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize;
    if b[4] == 1 && (FRAME_HEADER_LEN - 4..=MAX_FRAME - 4).contains(&len) {
        return Err(PreambleError::Version1);
    }
    Err(PreambleError::NotAsix)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preambles_round_trip_and_version_1_is_recognised() {
        let p = encode_preamble(LinkMode::Tls, LinkStatus::Accepted);
        assert_eq!(p, [0x41, 0x53, 0x58, 0x4C, 2, 1, 0, 0]);
        assert_eq!(decode_preamble(&p), Ok(Preamble { mode: 1, status: 0 }));
        let busy = encode_preamble(LinkMode::Tls, LinkStatus::Busy);
        let d = decode_preamble(&busy).unwrap();
        assert_eq!(LinkStatus::from_code(d.status), Some(LinkStatus::Busy));
        // A version-1 Hello's first 8 bytes (the protocol document's example).
        let hello_v1 = [0x1F, 0, 0, 0, 0x01, 0x01, 0, 0];
        assert_eq!(decode_preamble(&hello_v1), Err(PreambleError::Version1));
        let mut v3 = p;
        v3[4] = 3;
        assert_eq!(decode_preamble(&v3), Err(PreambleError::Version(3)));
        // A TLS ClientHello sent without preamble, and HTTP.
        assert_eq!(
            decode_preamble(&[0x16, 3, 1, 0, 0xC8, 1, 0, 0]),
            Err(PreambleError::NotAsix)
        );
        assert_eq!(decode_preamble(b"GET / HT"), Err(PreambleError::NotAsix));
    }
}
