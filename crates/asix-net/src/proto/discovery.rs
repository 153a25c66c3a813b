//! Discovery datagrams (UDP).
//!
//! ```text
//! offset size  field
//! 0      [u8;4] magic    "ASXD"
//! 4      u8     version  PROTOCOL_VERSION
//! 5      u8     type     1 = FindServer, 2 = Announce
//! 6      u16    reserved 0
//! 8      u32    request  FindServer: chosen by the client; Announce: echoed
//! 12     ...    payload
//! ```

use super::frame::ServerFlags;
use super::{
    put_str, put_u16, put_u32, DecodeError, EncodeError, Reader, MAX_DATAGRAM, PROTOCOL_VERSION,
};

/// Magic at the start of every discovery datagram.
pub const DISCOVERY_MAGIC: [u8; 4] = *b"ASXD";

/// What a discovery request looks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum ResourceKind {
    /// A channel of current data (`[AsixCTServers]`).
    Channel = 1,
    /// An archive (`[AsixHTServers]`).
    Archive = 2,
    /// An alarm server, by network name (`[AsixALServers]`).
    AlarmServer = 3,
}

impl ResourceKind {
    pub fn from_u8(b: u8) -> Option<Self> {
        match b {
            1 => Some(ResourceKind::Channel),
            2 => Some(ResourceKind::Archive),
            3 => Some(ResourceKind::AlarmServer),
            _ => None,
        }
    }
}

/// A named resource a server offers.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Resource {
    pub kind: ResourceKind,
    pub name: String,
}

impl Resource {
    pub fn channel(name: impl Into<String>) -> Self {
        Resource {
            kind: ResourceKind::Channel,
            name: name.into(),
        }
    }
}

/// Client -> every server: "whoever offers this resource, announce yourself".
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FindServer {
    pub request: u32,
    /// The resource sought. An empty name asks every server to announce itself.
    pub resource: Resource,
    pub client_name: String,
    /// The client's computer name; a server on that computer sets `LOCAL`.
    pub client_host: String,
}

/// Server -> client (unicast to the request's source address).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Announce {
    pub request: u32,
    pub server_name: String,
    pub server_host: String,
    pub flags: ServerFlags,
    /// Number of clients currently linked.
    pub clients: u32,
    /// TCP port of the link, on the datagram's source address.
    pub tcp_port: u16,
    /// SHA-256 fingerprint of the server's TLS certificate; `None` for a server that
    /// serves plaintext links only.
    pub fingerprint: Option<[u8; 32]>,
    /// Resources offered; the requested one first.
    pub resources: Vec<Resource>,
}

/// A discovery datagram.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Datagram {
    FindServer(FindServer),
    Announce(Announce),
}

fn header(out: &mut Vec<u8>, ty: u8, request: u32) {
    out.extend_from_slice(&DISCOVERY_MAGIC);
    out.push(PROTOCOL_VERSION);
    out.push(ty);
    put_u16(out, 0);
    put_u32(out, request);
}

/// Encodes a datagram. An announcement whose resource list would not fit in
/// [`MAX_DATAGRAM`] is cut and flagged `TRUNCATED`.
pub fn encode_datagram(d: &Datagram) -> Result<Vec<u8>, EncodeError> {
    let mut out = Vec::with_capacity(256);
    match d {
        Datagram::FindServer(f) => {
            header(&mut out, 1, f.request);
            out.push(f.resource.kind as u8);
            put_str(&mut out, &f.resource.name)?;
            put_str(&mut out, &f.client_name)?;
            put_str(&mut out, &f.client_host)?;
        }
        Datagram::Announce(a) => {
            header(&mut out, 2, a.request);
            put_str(&mut out, &a.server_name)?;
            put_str(&mut out, &a.server_host)?;
            let flags_at = out.len();
            out.push(a.flags.0);
            put_u32(&mut out, a.clients);
            put_u16(&mut out, a.tcp_port);
            match &a.fingerprint {
                Some(fp) => {
                    out.push(32);
                    out.extend_from_slice(fp);
                }
                None => out.push(0),
            }
            let count_at = out.len();
            put_u16(&mut out, 0);
            let mut n: u16 = 0;
            for r in &a.resources {
                let mark = out.len();
                out.push(r.kind as u8);
                put_str(&mut out, &r.name)?;
                if out.len() > MAX_DATAGRAM || n == u16::MAX {
                    out.truncate(mark);
                    out[flags_at] |= ServerFlags::TRUNCATED;
                    break;
                }
                n += 1;
            }
            out[count_at..count_at + 2].copy_from_slice(&n.to_le_bytes());
        }
    }
    if out.len() > MAX_DATAGRAM {
        return Err(EncodeError::TooLarge(out.len()));
    }
    Ok(out)
}

/// Decodes a datagram; never panics.
pub fn decode_datagram(buf: &[u8]) -> Result<Datagram, DecodeError> {
    if buf.len() > MAX_DATAGRAM {
        return Err(DecodeError::BadLength(buf.len() as u64));
    }
    let mut r = Reader::new(buf);
    if r.take(4)? != DISCOVERY_MAGIC {
        return Err(DecodeError::Magic);
    }
    let version = r.u8()?;
    if version != PROTOCOL_VERSION {
        return Err(DecodeError::Version(version));
    }
    let ty = r.u8()?;
    let _reserved = r.u16()?;
    let request = r.u32()?;
    let d = match ty {
        1 => {
            let kind =
                ResourceKind::from_u8(r.u8()?).ok_or(DecodeError::Invalid("resource kind"))?;
            Datagram::FindServer(FindServer {
                request,
                resource: Resource {
                    kind,
                    name: r.string()?,
                },
                client_name: r.string()?,
                client_host: r.string()?,
            })
        }
        2 => {
            let server_name = r.string()?;
            let server_host = r.string()?;
            let flags = ServerFlags(r.u8()?);
            let clients = r.u32()?;
            let tcp_port = r.u16()?;
            let fingerprint = match r.u8()? {
                0 => None,
                32 => {
                    let mut fp = [0u8; 32];
                    fp.copy_from_slice(r.take(32)?);
                    Some(fp)
                }
                _ => return Err(DecodeError::Invalid("fingerprint length")),
            };
            let n = r.u16()? as usize;
            if n.saturating_mul(3) > r.remaining() {
                return Err(DecodeError::Truncated);
            }
            let mut resources = Vec::with_capacity(n);
            for _ in 0..n {
                let kind =
                    ResourceKind::from_u8(r.u8()?).ok_or(DecodeError::Invalid("resource kind"))?;
                resources.push(Resource {
                    kind,
                    name: r.string()?,
                });
            }
            Datagram::Announce(Announce {
                request,
                server_name,
                server_host,
                flags,
                clients,
                tcp_port,
                fingerprint,
                resources,
            })
        }
        other => return Err(DecodeError::UnknownType(other)),
    };
    r.finish()?;
    Ok(d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn announcement_resource_list_is_cut_to_fit() {
        let resources = (0..2000)
            .map(|i| Resource::channel(format!("CHANNEL_{i:05}")))
            .collect();
        let a = Announce {
            request: 7,
            server_name: "S".into(),
            server_host: "H".into(),
            flags: ServerFlags(ServerFlags::LOCAL),
            clients: 3,
            tcp_port: 1,
            fingerprint: Some([7; 32]),
            resources,
        };
        let bytes = encode_datagram(&Datagram::Announce(a)).unwrap();
        assert!(bytes.len() <= MAX_DATAGRAM);
        let Datagram::Announce(back) = decode_datagram(&bytes).unwrap() else {
            panic!()
        };
        assert!(back.flags.local());
        assert_eq!(back.fingerprint, Some([7; 32]));
        assert_ne!(back.flags.0 & ServerFlags::TRUNCATED, 0);
        assert!(back.resources.len() < 2000 && !back.resources.is_empty());
        assert_eq!(back.resources[0].name, "CHANNEL_00000");
    }
}
