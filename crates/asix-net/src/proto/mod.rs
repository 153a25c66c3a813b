//! The asix network protocol, version 2: discovery datagrams ([`discovery`]), the link
//! preamble that starts TLS ([`link`]) and the framed TCP link ([`frame`]). Documented for gateway writers in `docs/asix-net-protocol.md`.
//!
//! Everything is little-endian. Decoding is total: any byte sequence yields a value or a
//! [`DecodeError`], never a panic, and never an allocation larger than the input justifies.

pub mod codec;
pub mod discovery;
pub mod frame;
pub mod link;

use ctopc_core::value::ArrayValue;
use ctopc_core::{Quality, Timestamp, Value, VarType};

use crate::Vqt;

/// The protocol version this crate speaks (frame header byte 4, datagram byte 4, the
/// link preamble's byte 4).
pub const PROTOCOL_VERSION: u8 = 2;
/// Largest TCP frame, length field included (1 MiB). Larger frames are a protocol error.
pub const MAX_FRAME: usize = 1 << 20;
/// Size of the TCP frame header (length, version, type, flags, request id).
pub const FRAME_HEADER_LEN: usize = 12;
/// Largest discovery datagram (8 KiB).
pub const MAX_DATAGRAM: usize = 8192;
/// Default UDP port servers listen on for discovery requests.
pub const DEFAULT_DISCOVERY_PORT: u16 = 48100;
/// Default TCP port of the link.
pub const DEFAULT_TCP_PORT: u16 = 48101;
/// Longest string on the wire (u16 length prefix).
pub const MAX_STRING: usize = u16::MAX as usize;

/// Why bytes could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("truncated input")]
    Truncated,
    #[error("frame length {0} out of range")]
    BadLength(u64),
    #[error("unsupported protocol version {0}")]
    Version(u8),
    #[error("unknown message type 0x{0:02X}")]
    UnknownType(u8),
    #[error("bad magic")]
    Magic,
    #[error("string is not UTF-8")]
    Utf8,
    #[error("unsupported value type 0x{0:04X}")]
    ValueType(u16),
    #[error("invalid {0}")]
    Invalid(&'static str),
    #[error("{0} trailing bytes")]
    Trailing(usize),
}

/// Why a message could not be encoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    #[error("frame of {0} bytes exceeds the maximum")]
    TooLarge(usize),
    #[error("string of {0} bytes exceeds the maximum")]
    StringTooLong(usize),
    #[error("value type 0x{0:04X} cannot be sent")]
    ValueType(u16),
}

/// A bounds-checked cursor over received bytes.
pub(crate) struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    pub(crate) fn new(buf: &'a [u8]) -> Self {
        Reader { buf, pos: 0 }
    }
    pub(crate) fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }
    pub(crate) fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        if self.remaining() < n {
            return Err(DecodeError::Truncated);
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    pub(crate) fn u8(&mut self) -> Result<u8, DecodeError> {
        Ok(self.array::<1>()?[0])
    }
    pub(crate) fn u16(&mut self) -> Result<u16, DecodeError> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    pub(crate) fn u32(&mut self) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub(crate) fn i32(&mut self) -> Result<i32, DecodeError> {
        Ok(i32::from_le_bytes(self.array()?))
    }
    pub(crate) fn u64(&mut self) -> Result<u64, DecodeError> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    pub(crate) fn i64(&mut self) -> Result<i64, DecodeError> {
        Ok(i64::from_le_bytes(self.array()?))
    }
    pub(crate) fn string(&mut self) -> Result<String, DecodeError> {
        let n = self.u16()? as usize;
        let bytes = self.take(n)?;
        std::str::from_utf8(bytes)
            .map(str::to_owned)
            .map_err(|_| DecodeError::Utf8)
    }
    /// An element count, checked against the bytes left so that a hostile count cannot
    /// make us allocate more than the input could fill (`min_size` bytes per element).
    pub(crate) fn count(&mut self, min_size: usize) -> Result<usize, DecodeError> {
        let n = self.u32()? as usize;
        if n.saturating_mul(min_size.max(1)) > self.remaining() {
            return Err(DecodeError::Truncated);
        }
        Ok(n)
    }
    pub(crate) fn finish(self) -> Result<(), DecodeError> {
        match self.remaining() {
            0 => Ok(()),
            n => Err(DecodeError::Trailing(n)),
        }
    }
}

pub(crate) fn put_u16(out: &mut Vec<u8>, v: u16) {
    out.extend_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_i32(out: &mut Vec<u8>, v: i32) {
    out.extend_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_u64(out: &mut Vec<u8>, v: u64) {
    out.extend_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_i64(out: &mut Vec<u8>, v: i64) {
    out.extend_from_slice(&v.to_le_bytes());
}
pub(crate) fn put_str(out: &mut Vec<u8>, s: &str) -> Result<(), EncodeError> {
    let n = u16::try_from(s.len()).map_err(|_| EncodeError::StringTooLong(s.len()))?;
    put_u16(out, n);
    out.extend_from_slice(s.as_bytes());
    Ok(())
}
pub(crate) fn put_count(out: &mut Vec<u8>, n: usize) -> Result<(), EncodeError> {
    let n = u32::try_from(n).map_err(|_| EncodeError::TooLarge(n))?;
    put_u32(out, n);
    Ok(())
}

/// Encodes a value: `u16` VARTYPE tag, then the data (see the protocol document, "Values").
pub fn put_value(out: &mut Vec<u8>, v: &Value) -> Result<(), EncodeError> {
    put_u16(out, v.var_type().0);
    match v {
        Value::Array(a) => {
            let el = a.element_type;
            if el.is_array() || !scalar_tag_ok(el) && el != VarType::VARIANT || el == VarType::EMPTY
            {
                return Err(EncodeError::ValueType(v.var_type().0));
            }
            put_count(out, a.elements.len())?;
            for e in &a.elements {
                if el == VarType::VARIANT {
                    if matches!(e, Value::Array(_)) {
                        return Err(EncodeError::ValueType(e.var_type().0));
                    }
                    put_value(out, e)?;
                } else {
                    if e.var_type() != el {
                        return Err(EncodeError::ValueType(e.var_type().0));
                    }
                    put_scalar(out, e)?;
                }
            }
            Ok(())
        }
        scalar => put_scalar(out, scalar),
    }
}

fn scalar_tag_ok(t: VarType) -> bool {
    matches!(
        t,
        VarType::EMPTY
            | VarType::I1
            | VarType::UI1
            | VarType::I2
            | VarType::UI2
            | VarType::I4
            | VarType::UI4
            | VarType::I8
            | VarType::UI8
            | VarType::R4
            | VarType::R8
            | VarType::CY
            | VarType::DATE
            | VarType::BSTR
            | VarType::BOOL
            | VarType::ERROR
    )
}

fn put_scalar(out: &mut Vec<u8>, v: &Value) -> Result<(), EncodeError> {
    match v {
        Value::Empty => {}
        Value::I1(x) => out.push(*x as u8),
        Value::UI1(x) => out.push(*x),
        Value::I2(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::UI2(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::I4(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::UI4(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::I8(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::UI8(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::R4(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::R8(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::Cy(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::Date(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::Bstr(s) => put_str(out, s)?,
        Value::Bool(b) => out.push(u8::from(*b)),
        Value::Error(x) => out.extend_from_slice(&x.to_le_bytes()),
        Value::Array(_) => return Err(EncodeError::ValueType(v.var_type().0)),
    }
    Ok(())
}

/// Decodes a value written by [`put_value`].
pub(crate) fn get_value(r: &mut Reader<'_>) -> Result<Value, DecodeError> {
    let tag = r.u16()?;
    let t = VarType(tag);
    if t.is_array() {
        let el = t.element();
        if el == VarType::EMPTY || !(scalar_tag_ok(el) || el == VarType::VARIANT) {
            return Err(DecodeError::ValueType(tag));
        }
        // A VARIANT element is at least its 2-byte tag; other elements at least 1 byte
        // (EMPTY is excluded above).
        let n = r.count(if el == VarType::VARIANT { 2 } else { 1 })?;
        let mut elements = Vec::with_capacity(n);
        for _ in 0..n {
            let e = if el == VarType::VARIANT {
                let inner = r.u16()?;
                if VarType(inner).is_array() {
                    return Err(DecodeError::ValueType(inner));
                }
                get_scalar(r, VarType(inner))?
            } else {
                get_scalar(r, el)?
            };
            elements.push(e);
        }
        return Ok(Value::Array(ArrayValue {
            element_type: el,
            elements,
        }));
    }
    get_scalar(r, t)
}

fn get_scalar(r: &mut Reader<'_>, t: VarType) -> Result<Value, DecodeError> {
    Ok(match t {
        VarType::EMPTY => Value::Empty,
        VarType::I1 => Value::I1(r.u8()? as i8),
        VarType::UI1 => Value::UI1(r.u8()?),
        VarType::I2 => Value::I2(r.u16()? as i16),
        VarType::UI2 => Value::UI2(r.u16()?),
        VarType::I4 => Value::I4(r.i32()?),
        VarType::UI4 => Value::UI4(r.u32()?),
        VarType::I8 => Value::I8(r.i64()?),
        VarType::UI8 => Value::UI8(r.u64()?),
        VarType::R4 => Value::R4(f32::from_bits(r.u32()?)),
        VarType::R8 => Value::R8(f64::from_bits(r.u64()?)),
        VarType::CY => Value::Cy(r.i64()?),
        VarType::DATE => Value::Date(f64::from_bits(r.u64()?)),
        VarType::BSTR => Value::Bstr(r.string()?),
        VarType::BOOL => match r.u8()? {
            0 => Value::Bool(false),
            1 => Value::Bool(true),
            _ => return Err(DecodeError::Invalid("boolean")),
        },
        VarType::ERROR => Value::Error(r.i32()?),
        other => return Err(DecodeError::ValueType(other.0)),
    })
}

/// Encodes a VQT: `u16` quality, `i64` FILETIME timestamp, then the value.
pub fn put_vqt(out: &mut Vec<u8>, v: &Vqt) -> Result<(), EncodeError> {
    put_u16(out, v.quality.0);
    put_i64(out, v.timestamp.0);
    put_value(out, &v.value)
}

pub(crate) fn get_vqt(r: &mut Reader<'_>) -> Result<Vqt, DecodeError> {
    let quality = Quality(r.u16()?);
    let timestamp = Timestamp(r.i64()?);
    let value = get_value(r)?;
    Ok(Vqt {
        value,
        quality,
        timestamp,
    })
}
