//! TCP link frames.
//!
//! ```text
//! offset size  field
//! 0      u32   len      bytes after this field (header rest + payload): 8 ..= MAX_FRAME-4
//! 4      u8    version  PROTOCOL_VERSION
//! 5      u8    type     MsgType
//! 6      u16   flags    reserved, 0 (receivers ignore it)
//! 8      u32   request  correlation id: non-zero in requests, echoed in replies, 0 otherwise
//! 12     ...   payload
//! ```

use ctopc_core::Value;

use super::{
    get_value, get_vqt, put_count, put_i32, put_str, put_u16, put_u32, put_u64, put_value, put_vqt,
    DecodeError, EncodeError, Reader, FRAME_HEADER_LEN, MAX_FRAME, PROTOCOL_VERSION,
};
use crate::Vqt;

const E_FAIL: i32 = 0x8000_4005u32 as i32;

/// Magic at the start of a Hello payload: "ASXN".
pub const HELLO_MAGIC: u32 = u32::from_le_bytes(*b"ASXN");

/// Message type codes (frame header byte 5).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum MsgType {
    Hello = 0x01,
    HelloAck = 0x02,
    Bye = 0x03,
    Ping = 0x08,
    Pong = 0x09,
    Error = 0x0A,
    ServerStatus = 0x0B,
    Subscribe = 0x10,
    SubscribeAck = 0x11,
    Unsubscribe = 0x12,
    UnsubscribeAck = 0x13,
    Update = 0x20,
    Read = 0x30,
    ReadResult = 0x31,
    Write = 0x40,
    WriteVqt = 0x41,
    WriteResult = 0x42,
}

impl MsgType {
    pub fn from_u8(b: u8) -> Option<MsgType> {
        use MsgType::*;
        Some(match b {
            0x01 => Hello,
            0x02 => HelloAck,
            0x03 => Bye,
            0x08 => Ping,
            0x09 => Pong,
            0x0A => Error,
            0x0B => ServerStatus,
            0x10 => Subscribe,
            0x11 => SubscribeAck,
            0x12 => Unsubscribe,
            0x13 => UnsubscribeAck,
            0x20 => Update,
            0x30 => Read,
            0x31 => ReadResult,
            0x40 => Write,
            0x41 => WriteVqt,
            0x42 => WriteResult,
            _ => return None,
        })
    }
}

/// Server flags (announcements, HelloAck, ServerStatus).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct ServerFlags(pub u8);

impl ServerFlags {
    /// The server runs on the requesting client's computer.
    pub const LOCAL: u8 = 0x01;
    /// The server relays another server's data (a bridge) rather than serving its own.
    pub const BRIDGE: u8 = 0x02;
    /// The server's data source (driver / PLC link) has failed.
    pub const SOURCE_FAILED: u8 = 0x04;
    /// Announcements only: the resource list was cut to fit the datagram.
    pub const TRUNCATED: u8 = 0x08;

    pub const fn local(self) -> bool {
        self.0 & Self::LOCAL != 0
    }
    pub const fn bridge(self) -> bool {
        self.0 & Self::BRIDGE != 0
    }
    pub const fn source_failed(self) -> bool {
        self.0 & Self::SOURCE_FAILED != 0
    }
    pub const fn with(self, bit: u8, on: bool) -> Self {
        if on {
            ServerFlags(self.0 | bit)
        } else {
            ServerFlags(self.0 & !bit)
        }
    }
}

/// Where a read takes its values from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[repr(u8)]
pub enum ReadSource {
    /// The asix server's process image as it stands (no refresh).
    #[default]
    Cache = 0,
    /// The current value as the asix system keeps it (refreshed at the variable's rate).
    Device = 1,
    /// Read through the driver from the controller now (slowest, freshest).
    Driver = 2,
}

impl ReadSource {
    pub fn from_u8(b: u8) -> Option<ReadSource> {
        match b {
            0 => Some(ReadSource::Cache),
            1 => Some(ReadSource::Device),
            2 => Some(ReadSource::Driver),
            _ => None,
        }
    }
}

/// A process variable named on the wire: asix channel plus variable name (case-sensitive).
/// An empty channel asks the server to find the variable by name in any of its channels.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct VarRef {
    pub channel: String,
    pub variable: String,
}

impl VarRef {
    pub fn new(channel: impl Into<String>, variable: impl Into<String>) -> Self {
        VarRef {
            channel: channel.into(),
            variable: variable.into(),
        }
    }
}

/// Client -> server, first frame of a link.
#[derive(Debug, Clone, PartialEq)]
pub struct Hello {
    /// The client's asix name (`[ASLINK] Nazwa`, or computer name + ".").
    pub client_name: String,
    /// The client's computer name (lets the server tell local clients).
    pub client_host: String,
    /// The client sends a Ping at least this often.
    pub keepalive_ms: u32,
    /// The client's NetTimeout (informational).
    pub net_timeout_ms: u32,
}

/// Server -> client answer to Hello.
#[derive(Debug, Clone, PartialEq)]
pub struct HelloAck {
    /// 0 = accepted; otherwise an ASKOM HRESULT (e.g. NetLinkToServerNegativeAnswer) and the
    /// server closes the link.
    pub status: i32,
    pub server_name: String,
    pub flags: ServerFlags,
    pub clients: u32,
    /// The server drops a link it hears nothing from for this long.
    pub idle_timeout_ms: u32,
}

/// One entry of a Subscribe.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SubscribeItem {
    /// Client-chosen handle, unique on the link; Updates carry it.
    pub handle: u32,
    pub var: VarRef,
}

/// A message of the TCP link.
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    Hello(Hello),
    HelloAck(HelloAck),
    /// Orderly close, with a reason code (0 or an ASKOM HRESULT).
    Bye {
        reason: i32,
    },
    Ping {
        nonce: u64,
    },
    Pong {
        nonce: u64,
    },
    /// A request could not be processed at all (malformed, unsupported).
    Error {
        code: i32,
        message: String,
    },
    /// Unsolicited: the server's flags or client count changed.
    ServerStatus {
        flags: ServerFlags,
        clients: u32,
    },
    /// Subscribe (or change the sampling period of) items. The server sends each item's
    /// VQT every `sampling_ms` (every sample, changed or not), or with `changes_only` only
    /// when it changed; and the current VQT at once after the SubscribeAck.
    Subscribe {
        sampling_ms: u32,
        changes_only: bool,
        items: Vec<SubscribeItem>,
    },
    /// Per-handle results of a Subscribe (HRESULT, 0 = ok).
    SubscribeAck {
        results: Vec<(u32, i32)>,
    },
    Unsubscribe {
        handles: Vec<u32>,
    },
    UnsubscribeAck {
        results: Vec<(u32, i32)>,
    },
    /// Unsolicited batch of (handle, VQT).
    Update {
        items: Vec<(u32, Vqt)>,
    },
    Read {
        source: ReadSource,
        items: Vec<VarRef>,
    },
    /// One result per requested item, in order: the VQT or a failure HRESULT.
    ReadResult {
        results: Vec<Result<Vqt, i32>>,
    },
    Write {
        items: Vec<(VarRef, Value)>,
    },
    WriteVqt {
        items: Vec<(VarRef, Vqt)>,
    },
    /// One HRESULT per written item, in order (0 = ok).
    WriteResult {
        results: Vec<i32>,
    },
}

impl Message {
    pub fn msg_type(&self) -> MsgType {
        match self {
            Message::Hello(_) => MsgType::Hello,
            Message::HelloAck(_) => MsgType::HelloAck,
            Message::Bye { .. } => MsgType::Bye,
            Message::Ping { .. } => MsgType::Ping,
            Message::Pong { .. } => MsgType::Pong,
            Message::Error { .. } => MsgType::Error,
            Message::ServerStatus { .. } => MsgType::ServerStatus,
            Message::Subscribe { .. } => MsgType::Subscribe,
            Message::SubscribeAck { .. } => MsgType::SubscribeAck,
            Message::Unsubscribe { .. } => MsgType::Unsubscribe,
            Message::UnsubscribeAck { .. } => MsgType::UnsubscribeAck,
            Message::Update { .. } => MsgType::Update,
            Message::Read { .. } => MsgType::Read,
            Message::ReadResult { .. } => MsgType::ReadResult,
            Message::Write { .. } => MsgType::Write,
            Message::WriteVqt { .. } => MsgType::WriteVqt,
            Message::WriteResult { .. } => MsgType::WriteResult,
        }
    }
}

/// A decoded frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub request: u32,
    pub msg: Message,
}

/// Starts a frame in `out`; returns the offset to pass to [`end_frame`].
pub fn begin_frame(out: &mut Vec<u8>, ty: MsgType, request: u32) -> usize {
    let start = out.len();
    put_u32(out, 0); // patched by end_frame
    out.push(PROTOCOL_VERSION);
    out.push(ty as u8);
    put_u16(out, 0);
    put_u32(out, request);
    start
}

/// Completes a frame begun at `start` by patching its length; fails (and removes the
/// partial frame) when it exceeds [`MAX_FRAME`].
pub fn end_frame(out: &mut Vec<u8>, start: usize) -> Result<(), EncodeError> {
    let total = out.len() - start;
    if total > MAX_FRAME {
        out.truncate(start);
        return Err(EncodeError::TooLarge(total));
    }
    let len = (total - 4) as u32;
    out[start..start + 4].copy_from_slice(&len.to_le_bytes());
    Ok(())
}

/// Appends the encoding of one frame to `out` (left unchanged on error).
pub fn encode_frame(out: &mut Vec<u8>, request: u32, msg: &Message) -> Result<(), EncodeError> {
    let start = begin_frame(out, msg.msg_type(), request);
    if let Err(e) = encode_payload(out, msg) {
        out.truncate(start);
        return Err(e);
    }
    end_frame(out, start)
}

/// Encodes one frame into a new buffer.
pub fn frame_bytes(request: u32, msg: &Message) -> Result<Vec<u8>, EncodeError> {
    let mut out = Vec::new();
    encode_frame(&mut out, request, msg)?;
    Ok(out)
}

fn encode_payload(out: &mut Vec<u8>, msg: &Message) -> Result<(), EncodeError> {
    match msg {
        Message::Hello(h) => {
            put_u32(out, HELLO_MAGIC);
            put_str(out, &h.client_name)?;
            put_str(out, &h.client_host)?;
            put_u32(out, h.keepalive_ms);
            put_u32(out, h.net_timeout_ms);
        }
        Message::HelloAck(a) => {
            put_i32(out, a.status);
            put_str(out, &a.server_name)?;
            out.push(a.flags.0);
            put_u32(out, a.clients);
            put_u32(out, a.idle_timeout_ms);
        }
        Message::Bye { reason } => put_i32(out, *reason),
        Message::Ping { nonce } | Message::Pong { nonce } => put_u64(out, *nonce),
        Message::Error { code, message } => {
            put_i32(out, *code);
            put_str(out, message)?;
        }
        Message::ServerStatus { flags, clients } => {
            out.push(flags.0);
            put_u32(out, *clients);
        }
        Message::Subscribe {
            sampling_ms,
            changes_only,
            items,
        } => {
            put_u32(out, *sampling_ms);
            out.push(u8::from(*changes_only));
            put_count(out, items.len())?;
            for it in items {
                put_u32(out, it.handle);
                put_var(out, &it.var)?;
            }
        }
        Message::SubscribeAck { results } | Message::UnsubscribeAck { results } => {
            put_count(out, results.len())?;
            for (h, r) in results {
                put_u32(out, *h);
                put_i32(out, *r);
            }
        }
        Message::Unsubscribe { handles } => {
            put_count(out, handles.len())?;
            for h in handles {
                put_u32(out, *h);
            }
        }
        Message::Update { items } => {
            put_count(out, items.len())?;
            for (h, v) in items {
                put_u32(out, *h);
                put_vqt(out, v)?;
            }
        }
        Message::Read { source, items } => {
            out.push(*source as u8);
            put_count(out, items.len())?;
            for v in items {
                put_var(out, v)?;
            }
        }
        Message::ReadResult { results } => {
            put_count(out, results.len())?;
            for r in results {
                match r {
                    Ok(v) => {
                        put_i32(out, 0);
                        put_vqt(out, v)?;
                    }
                    // A failure must be negative; a non-negative one is sent as E_FAIL.
                    Err(code) => put_i32(out, if *code < 0 { *code } else { E_FAIL }),
                }
            }
        }
        Message::Write { items } => {
            put_count(out, items.len())?;
            for (var, value) in items {
                put_var(out, var)?;
                put_value(out, value)?;
            }
        }
        Message::WriteVqt { items } => {
            put_count(out, items.len())?;
            for (var, v) in items {
                put_var(out, var)?;
                put_vqt(out, v)?;
            }
        }
        Message::WriteResult { results } => {
            put_count(out, results.len())?;
            for r in results {
                put_i32(out, *r);
            }
        }
    }
    Ok(())
}

fn put_var(out: &mut Vec<u8>, v: &VarRef) -> Result<(), EncodeError> {
    put_str(out, &v.channel)?;
    put_str(out, &v.variable)
}

fn get_var(r: &mut Reader<'_>) -> Result<VarRef, DecodeError> {
    Ok(VarRef {
        channel: r.string()?,
        variable: r.string()?,
    })
}

/// The frame length announced by the first four bytes of a frame, validated: the number of
/// bytes that follow the length field. Use it to size the next read.
pub fn body_len(len_field: [u8; 4]) -> Result<usize, DecodeError> {
    let len = u32::from_le_bytes(len_field) as u64;
    if len < (FRAME_HEADER_LEN - 4) as u64 || len > (MAX_FRAME - 4) as u64 {
        return Err(DecodeError::BadLength(len));
    }
    Ok(len as usize)
}

/// Decodes the bytes that follow the length field (exactly [`body_len`] of them).
pub fn decode_body(body: &[u8]) -> Result<Frame, DecodeError> {
    let mut r = Reader::new(body);
    let version = r.u8()?;
    if version != PROTOCOL_VERSION {
        return Err(DecodeError::Version(version));
    }
    let ty = r.u8()?;
    let _flags = r.u16()?;
    let request = r.u32()?;
    let ty = MsgType::from_u8(ty).ok_or(DecodeError::UnknownType(ty))?;
    let msg = decode_payload(&mut r, ty)?;
    r.finish()?;
    Ok(Frame { request, msg })
}

/// Decodes one frame from the start of `buf`. `Ok(None)`: more bytes are needed.
/// On success returns the frame and the number of bytes it took.
pub fn decode_frame(buf: &[u8]) -> Result<Option<(Frame, usize)>, DecodeError> {
    if buf.len() < 4 {
        return Ok(None);
    }
    let len = body_len([buf[0], buf[1], buf[2], buf[3]])?;
    let Some(body) = buf.get(4..4 + len) else {
        return Ok(None);
    };
    Ok(Some((decode_body(body)?, 4 + len)))
}

fn results(r: &mut Reader<'_>) -> Result<Vec<(u32, i32)>, DecodeError> {
    let n = r.count(8)?;
    let mut v = Vec::with_capacity(n);
    for _ in 0..n {
        v.push((r.u32()?, r.i32()?));
    }
    Ok(v)
}

fn decode_payload(r: &mut Reader<'_>, ty: MsgType) -> Result<Message, DecodeError> {
    Ok(match ty {
        MsgType::Hello => {
            if r.u32()? != HELLO_MAGIC {
                return Err(DecodeError::Magic);
            }
            Message::Hello(Hello {
                client_name: r.string()?,
                client_host: r.string()?,
                keepalive_ms: r.u32()?,
                net_timeout_ms: r.u32()?,
            })
        }
        MsgType::HelloAck => Message::HelloAck(HelloAck {
            status: r.i32()?,
            server_name: r.string()?,
            flags: ServerFlags(r.u8()?),
            clients: r.u32()?,
            idle_timeout_ms: r.u32()?,
        }),
        MsgType::Bye => Message::Bye { reason: r.i32()? },
        MsgType::Ping => Message::Ping { nonce: r.u64()? },
        MsgType::Pong => Message::Pong { nonce: r.u64()? },
        MsgType::Error => Message::Error {
            code: r.i32()?,
            message: r.string()?,
        },
        MsgType::ServerStatus => Message::ServerStatus {
            flags: ServerFlags(r.u8()?),
            clients: r.u32()?,
        },
        MsgType::Subscribe => {
            let sampling_ms = r.u32()?;
            let changes_only = match r.u8()? {
                0 => false,
                1 => true,
                _ => return Err(DecodeError::Invalid("subscribe mode")),
            };
            let n = r.count(8)?;
            let mut items = Vec::with_capacity(n);
            for _ in 0..n {
                items.push(SubscribeItem {
                    handle: r.u32()?,
                    var: get_var(r)?,
                });
            }
            Message::Subscribe {
                sampling_ms,
                changes_only,
                items,
            }
        }
        MsgType::SubscribeAck => Message::SubscribeAck {
            results: results(r)?,
        },
        MsgType::UnsubscribeAck => Message::UnsubscribeAck {
            results: results(r)?,
        },
        MsgType::Unsubscribe => {
            let n = r.count(4)?;
            let mut handles = Vec::with_capacity(n);
            for _ in 0..n {
                handles.push(r.u32()?);
            }
            Message::Unsubscribe { handles }
        }
        MsgType::Update => {
            let n = r.count(16)?;
            let mut items = Vec::with_capacity(n);
            for _ in 0..n {
                items.push((r.u32()?, get_vqt(r)?));
            }
            Message::Update { items }
        }
        MsgType::Read => {
            let source = ReadSource::from_u8(r.u8()?).ok_or(DecodeError::Invalid("read source"))?;
            let n = r.count(4)?;
            let mut items = Vec::with_capacity(n);
            for _ in 0..n {
                items.push(get_var(r)?);
            }
            Message::Read { source, items }
        }
        MsgType::ReadResult => {
            let n = r.count(4)?;
            let mut results = Vec::with_capacity(n);
            for _ in 0..n {
                let code = r.i32()?;
                results.push(if code >= 0 {
                    Ok(get_vqt(r)?)
                } else {
                    Err(code)
                });
            }
            Message::ReadResult { results }
        }
        MsgType::Write => {
            let n = r.count(6)?;
            let mut items = Vec::with_capacity(n);
            for _ in 0..n {
                items.push((get_var(r)?, get_value(r)?));
            }
            Message::Write { items }
        }
        MsgType::WriteVqt => {
            let n = r.count(16)?;
            let mut items = Vec::with_capacity(n);
            for _ in 0..n {
                items.push((get_var(r)?, get_vqt(r)?));
            }
            Message::WriteVqt { items }
        }
        MsgType::WriteResult => {
            let n = r.count(4)?;
            let mut results = Vec::with_capacity(n);
            for _ in 0..n {
                results.push(r.i32()?);
            }
            Message::WriteResult { results }
        }
    })
}

/// Builds Update frames incrementally without an intermediate `Message` (the server's hot
/// path). Entries go into the current frame until it reaches `soft_limit` bytes, then a new
/// frame starts in the same buffer.
pub struct UpdateEncoder {
    buf: Vec<u8>,
    start: usize,
    count: u32,
    soft_limit: usize,
}

impl UpdateEncoder {
    pub fn new(soft_limit: usize) -> Self {
        let soft_limit = soft_limit.clamp(1024, MAX_FRAME / 2);
        UpdateEncoder {
            buf: Vec::new(),
            start: usize::MAX,
            count: 0,
            soft_limit,
        }
    }

    fn open(&mut self) {
        self.start = begin_frame(&mut self.buf, MsgType::Update, 0);
        put_u32(&mut self.buf, 0);
        self.count = 0;
    }

    fn close(&mut self) -> Result<(), EncodeError> {
        if self.start == usize::MAX {
            return Ok(());
        }
        let c = self.start + FRAME_HEADER_LEN;
        self.buf[c..c + 4].copy_from_slice(&self.count.to_le_bytes());
        let r = end_frame(&mut self.buf, self.start);
        self.start = usize::MAX;
        r
    }

    /// Adds one entry. A value that cannot be encoded is sent as EMPTY with its quality.
    pub fn push(&mut self, handle: u32, vqt: &Vqt) -> Result<(), EncodeError> {
        if self.start == usize::MAX {
            self.open();
        }
        let mark = self.buf.len();
        put_u32(&mut self.buf, handle);
        if put_vqt(&mut self.buf, vqt).is_err() {
            self.buf.truncate(mark);
            put_u32(&mut self.buf, handle);
            let empty = Vqt {
                value: Value::Empty,
                quality: vqt.quality,
                timestamp: vqt.timestamp,
            };
            put_vqt(&mut self.buf, &empty)?;
        }
        self.count += 1;
        if self.buf.len() - self.start >= self.soft_limit {
            self.close()?;
        }
        Ok(())
    }

    /// True when nothing has been pushed since the last `finish`.
    pub fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    /// The encoded frames; the encoder is reset.
    pub fn finish(&mut self) -> Result<Vec<u8>, EncodeError> {
        self.close()?;
        Ok(std::mem::take(&mut self.buf))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ctopc_core::{Quality, Timestamp};

    #[test]
    fn update_encoder_splits_frames_and_decodes() {
        let mut enc = UpdateEncoder::new(1024);
        for h in 0..500u32 {
            enc.push(
                h,
                &Vqt::new(Value::R4(h as f32), Quality::GOOD, Timestamp(h as i64)),
            )
            .unwrap();
        }
        let bytes = enc.finish().unwrap();
        let mut pos = 0;
        let mut seen = 0u32;
        let mut frames = 0;
        while pos < bytes.len() {
            let (f, n) = decode_frame(&bytes[pos..]).unwrap().unwrap();
            pos += n;
            frames += 1;
            let Message::Update { items } = f.msg else {
                panic!("not an update")
            };
            for (h, v) in items {
                assert_eq!(h, seen);
                assert_eq!(v.value, Value::R4(seen as f32));
                assert_eq!(v.quality, Quality::GOOD);
                seen += 1;
            }
        }
        assert_eq!(seen, 500);
        assert!(frames > 1);
    }

    #[test]
    fn bad_lengths_are_rejected_before_reading_the_body() {
        assert!(decode_frame(&[0, 0, 0, 0]).is_err());
        assert!(decode_frame(&[7, 0, 0, 0]).is_err());
        assert!(decode_frame(&(MAX_FRAME as u32).to_le_bytes()).is_err());
        assert_eq!(decode_frame(&[8, 0, 0]), Ok(None));
        assert_eq!(decode_frame(&[8, 0, 0, 0, 1]), Ok(None));
    }

    #[test]
    fn too_large_frames_are_refused_and_leave_the_buffer_unchanged() {
        let items: Vec<u32> = (0..(MAX_FRAME as u32 / 4)).collect();
        let mut out = vec![1, 2, 3];
        let e = encode_frame(&mut out, 1, &Message::Unsubscribe { handles: items }).unwrap_err();
        assert!(matches!(e, EncodeError::TooLarge(_)));
        assert_eq!(out, vec![1, 2, 3]);
    }
}
