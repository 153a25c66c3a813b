//! The OPC DA 1.0a data streams: what `IAdviseSink::OnDataChange` carries in its HGLOBAL
//! for the clipboard formats `OPCSTMFORMATDATA`, `OPCSTMFORMATDATATIME` and
//! `OPCSTMFORMATWRITECOMPLETE` (DA 2.05a, "IAdviseSink (old)" and the stream structures).
//!
//! A pure function of the values: the COM layer copies the bytes into global memory.
//! Every field is little-endian, as the x86 structures are in memory:
//!
//! - data (`OPCSTMFORMATDATA[TIME]`): `OPCGROUPHEADER` (20 bytes: `dwSize` the whole
//!   stream's size, `dwItemCount`, `hClientGroup`, `dwTransactionID`, `hrStatus`), then one
//!   `OPCITEMHEADER1` (20 bytes: `hClient`, `dwValueOffset`, `wQuality`, `wReserved`,
//!   `ftTimeStampItem`) or `OPCITEMHEADER2` (12 bytes: the same without the time) per item,
//!   then the values. `dwValueOffset` counts from the start of the stream (the group
//!   header). Each value is a VARIANT of 16 bytes (`vt`, three reserved words, 8 bytes of
//!   data: the 32-bit layout, the one DA 1.0a clients were written against; a 64-bit
//!   client finds `vt` and the data at the same offsets) followed by what its pointer
//!   would point to:
//!   - VT_BSTR: a DWORD byte count of the text (without the terminator), the UTF-16
//!     characters and a NUL character;
//!   - arrays (`VT_ARRAY | vt`, 1-D): a SAFEARRAY of the 32-bit layout (24 bytes:
//!     `cDims` = 1, `fFeatures` = 0, `cbElements`, `cLocks` = 0, `pvData` = 0, one bound:
//!     `cElements`, `lLbound` = 0) then the elements one after the other:
//!     fixed-size ones as `cbElements` bytes, BSTR elements each as a DWORD byte count,
//!     the characters and a NUL, VARIANT elements each as a value laid out as here.
//!
//!   The pointer fields (the VARIANT's data of a BSTR or array, `pvData`) are 0: they mean
//!   nothing in another process. Each value starts at a multiple of 4.
//! - write completion (`OPCSTMFORMATWRITECOMPLETE`): `OPCGROUPHEADERWRITE` (16 bytes:
//!   `dwItemCount`, `hClientGroup`, `dwTransactionID`, `hrStatus`), then one
//!   `OPCITEMHEADERWRITE` (8 bytes: `hClient`, `dwError`) per item.
//!
//! [`decode_data`] and [`decode_write`] are the inverses (total: any byte string gives a
//! value or an error), for tests and clients.

use crate::{Quality, Timestamp, Value, VarType};

/// Size of `OPCGROUPHEADER`.
pub const GROUP_HEADER: usize = 20;
/// Size of `OPCITEMHEADER1` (with the time stamp).
pub const ITEM_HEADER1: usize = 20;
/// Size of `OPCITEMHEADER2` (without).
pub const ITEM_HEADER2: usize = 12;
/// Size of `OPCGROUPHEADERWRITE`.
pub const GROUP_HEADER_WRITE: usize = 16;
/// Size of `OPCITEMHEADERWRITE`.
pub const ITEM_HEADER_WRITE: usize = 8;
/// Size of a VARIANT in the stream.
pub const VARIANT_SIZE: usize = 16;
/// Size of the SAFEARRAY descriptor of an array value (one dimension).
pub const SAFEARRAY_SIZE: usize = 24;

/// Which data format: `OPCSTMFORMATDATATIME` (item headers with time) or
/// `OPCSTMFORMATDATA`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataFormat {
    Data,
    DataTime,
}

/// One item of a data stream.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamItem {
    pub client_handle: u32,
    pub quality: Quality,
    /// Written only in the `DataTime` format.
    pub timestamp: Timestamp,
    pub value: Value,
}

/// A decoded data stream.
#[derive(Debug, Clone, PartialEq)]
pub struct DataStream {
    pub client_group: u32,
    pub transaction_id: u32,
    pub status: i32,
    pub items: Vec<StreamItem>,
}

/// A decoded write-completion stream: per item (client handle, HRESULT).
#[derive(Debug, Clone, PartialEq)]
pub struct WriteStream {
    pub client_group: u32,
    pub transaction_id: u32,
    pub status: i32,
    pub items: Vec<(u32, i32)>,
}

/// Why a stream could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DecodeError {
    /// Shorter than a field it must hold, at this offset.
    Truncated(usize),
    /// `dwSize` is not the stream's length.
    Size { declared: u32, actual: usize },
    /// A VARTYPE the stream format does not carry.
    Type(u16),
    /// Text that is not UTF-16, or a byte count that is odd.
    Text(usize),
    /// An array that is not 1-D, or whose element size does not match its type.
    Array(usize),
}

fn put_u16(b: &mut Vec<u8>, v: u16) {
    b.extend_from_slice(&v.to_le_bytes());
}
fn put_u32(b: &mut Vec<u8>, v: u32) {
    b.extend_from_slice(&v.to_le_bytes());
}
fn set_u32(b: &mut [u8], at: usize, v: u32) {
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

/// The 8 data bytes of a fixed-size value (little-endian, zero-padded) and their size as
/// an array element; `None` for BSTR, arrays and VARIANT.
fn fixed(v: &Value) -> Option<([u8; 8], usize)> {
    let mut d = [0u8; 8];
    let n = match v {
        Value::Empty => 0,
        Value::I1(x) => {
            d[..1].copy_from_slice(&x.to_le_bytes());
            1
        }
        Value::UI1(x) => {
            d[0] = *x;
            1
        }
        Value::I2(x) => {
            d[..2].copy_from_slice(&x.to_le_bytes());
            2
        }
        Value::UI2(x) => {
            d[..2].copy_from_slice(&x.to_le_bytes());
            2
        }
        Value::Bool(x) => {
            d[..2].copy_from_slice(&(if *x { -1i16 } else { 0 }).to_le_bytes());
            2
        }
        Value::I4(x) | Value::Error(x) => {
            d[..4].copy_from_slice(&x.to_le_bytes());
            4
        }
        Value::UI4(x) => {
            d[..4].copy_from_slice(&x.to_le_bytes());
            4
        }
        Value::R4(x) => {
            d[..4].copy_from_slice(&x.to_le_bytes());
            4
        }
        Value::I8(x) | Value::Cy(x) => {
            d.copy_from_slice(&x.to_le_bytes());
            8
        }
        Value::UI8(x) => {
            d.copy_from_slice(&x.to_le_bytes());
            8
        }
        Value::R8(x) | Value::Date(x) => {
            d.copy_from_slice(&x.to_le_bytes());
            8
        }
        Value::Bstr(_) | Value::Array(_) => return None,
    };
    Some((d, n))
}

/// The element size (`cbElements`) of an array of `t`, as a SAFEARRAY has it.
fn element_size(t: VarType) -> Option<usize> {
    Some(match t {
        VarType::I1 | VarType::UI1 => 1,
        VarType::I2 | VarType::UI2 | VarType::BOOL => 2,
        VarType::I4 | VarType::UI4 | VarType::R4 | VarType::ERROR => 4,
        VarType::I8 | VarType::UI8 | VarType::R8 | VarType::CY | VarType::DATE => 8,
        VarType::BSTR => 4,
        VarType::VARIANT => VARIANT_SIZE,
        _ => return None,
    })
}

fn put_text(b: &mut Vec<u8>, s: &str) {
    let units: Vec<u16> = s.encode_utf16().collect();
    put_u32(b, (units.len() * 2) as u32);
    for u in units {
        put_u16(b, u);
    }
    put_u16(b, 0);
}

/// Appends one value: its VARIANT and what follows it.
fn put_value(b: &mut Vec<u8>, v: &Value) {
    put_u16(b, v.var_type().0);
    b.extend_from_slice(&[0u8; 6]);
    match v {
        Value::Bstr(s) => {
            b.extend_from_slice(&[0u8; 8]);
            put_text(b, s);
        }
        Value::Array(a) => {
            b.extend_from_slice(&[0u8; 8]);
            put_u16(b, 1);
            put_u16(b, 0);
            put_u32(b, element_size(a.element_type).unwrap_or(0) as u32);
            put_u32(b, 0);
            put_u32(b, 0);
            put_u32(b, a.elements.len() as u32);
            put_u32(b, 0);
            for e in &a.elements {
                match a.element_type {
                    VarType::VARIANT => put_value(b, e),
                    VarType::BSTR => put_text(b, if let Value::Bstr(s) = e { s } else { "" }),
                    t => {
                        let n = element_size(t).unwrap_or(0);
                        let (d, _) = fixed(e).unwrap_or(([0; 8], 0));
                        b.extend_from_slice(&d[..n.min(8)]);
                    }
                }
            }
        }
        other => {
            let (d, _) = fixed(other).unwrap_or(([0; 8], 0));
            b.extend_from_slice(&d);
        }
    }
}

fn pad4(b: &mut Vec<u8>) {
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
}

/// Lays out a data stream (`OPCSTMFORMATDATA` or `OPCSTMFORMATDATATIME`).
pub fn encode_data(
    format: DataFormat,
    client_group: u32,
    transaction_id: u32,
    status: i32,
    items: &[StreamItem],
) -> Vec<u8> {
    let header = match format {
        DataFormat::Data => ITEM_HEADER2,
        DataFormat::DataTime => ITEM_HEADER1,
    };
    let mut b = Vec::with_capacity(GROUP_HEADER + items.len() * (header + VARIANT_SIZE));
    put_u32(&mut b, 0); // dwSize, set at the end
    put_u32(&mut b, items.len() as u32);
    put_u32(&mut b, client_group);
    put_u32(&mut b, transaction_id);
    b.extend_from_slice(&status.to_le_bytes());
    for it in items {
        put_u32(&mut b, it.client_handle);
        put_u32(&mut b, 0); // dwValueOffset, set below
        put_u16(&mut b, it.quality.0);
        put_u16(&mut b, 0);
        if format == DataFormat::DataTime {
            let (lo, hi) = it.timestamp.filetime_parts();
            put_u32(&mut b, lo);
            put_u32(&mut b, hi);
        }
    }
    for (i, it) in items.iter().enumerate() {
        pad4(&mut b);
        let at = b.len() as u32;
        set_u32(&mut b, GROUP_HEADER + i * header + 4, at);
        put_value(&mut b, &it.value);
    }
    pad4(&mut b);
    let size = b.len() as u32;
    set_u32(&mut b, 0, size);
    b
}

/// Lays out a write-completion stream (`OPCSTMFORMATWRITECOMPLETE`): per item (client
/// handle, HRESULT).
pub fn encode_write(
    client_group: u32,
    transaction_id: u32,
    status: i32,
    items: &[(u32, i32)],
) -> Vec<u8> {
    let mut b = Vec::with_capacity(GROUP_HEADER_WRITE + items.len() * ITEM_HEADER_WRITE);
    put_u32(&mut b, items.len() as u32);
    put_u32(&mut b, client_group);
    put_u32(&mut b, transaction_id);
    b.extend_from_slice(&status.to_le_bytes());
    for (h, e) in items {
        put_u32(&mut b, *h);
        b.extend_from_slice(&e.to_le_bytes());
    }
    b
}

// ---- decoding ---------------------------------------------------------------------------

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], DecodeError> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.b.len())
            .ok_or(DecodeError::Truncated(self.at))?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u16(&mut self) -> Result<u16, DecodeError> {
        let s = self.take(2)?;
        Ok(u16::from_le_bytes([s[0], s[1]]))
    }
    fn u32(&mut self) -> Result<u32, DecodeError> {
        let s = self.take(4)?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }
    fn bytes8(&mut self, n: usize) -> Result<[u8; 8], DecodeError> {
        let mut d = [0u8; 8];
        d[..n].copy_from_slice(self.take(n)?);
        Ok(d)
    }
    fn text(&mut self) -> Result<String, DecodeError> {
        let at = self.at;
        let n = self.u32()? as usize;
        if !n.is_multiple_of(2) {
            return Err(DecodeError::Text(at));
        }
        let raw = self.take(n)?;
        let units: Vec<u16> = raw
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect();
        if self.u16()? != 0 {
            return Err(DecodeError::Text(at));
        }
        String::from_utf16(&units).map_err(|_| DecodeError::Text(at))
    }
}

fn from_fixed(t: VarType, d: [u8; 8]) -> Result<Value, DecodeError> {
    let i2 = i16::from_le_bytes([d[0], d[1]]);
    let u4 = u32::from_le_bytes([d[0], d[1], d[2], d[3]]);
    let u8_ = u64::from_le_bytes(d);
    Ok(match t {
        VarType::EMPTY => Value::Empty,
        VarType::I1 => Value::I1(d[0] as i8),
        VarType::UI1 => Value::UI1(d[0]),
        VarType::I2 => Value::I2(i2),
        VarType::UI2 => Value::UI2(i2 as u16),
        VarType::BOOL => Value::Bool(i2 != 0),
        VarType::I4 => Value::I4(u4 as i32),
        VarType::ERROR => Value::Error(u4 as i32),
        VarType::UI4 => Value::UI4(u4),
        VarType::R4 => Value::R4(f32::from_bits(u4)),
        VarType::I8 => Value::I8(u8_ as i64),
        VarType::CY => Value::Cy(u8_ as i64),
        VarType::UI8 => Value::UI8(u8_),
        VarType::R8 => Value::R8(f64::from_bits(u8_)),
        VarType::DATE => Value::Date(f64::from_bits(u8_)),
        other => return Err(DecodeError::Type(other.0)),
    })
}

/// Nesting allowed for VARIANT arrays holding VARIANT arrays.
const MAX_DEPTH: u32 = 8;

fn read_value(r: &mut Reader<'_>, depth: u32) -> Result<Value, DecodeError> {
    let at = r.at;
    let vt = VarType(r.u16()?);
    r.take(6)?;
    let data = r.bytes8(8)?;
    if vt == VarType::BSTR {
        return Ok(Value::Bstr(r.text()?));
    }
    if !vt.is_array() {
        return from_fixed(vt, data);
    }
    let elem = vt.element();
    let size = element_size(elem).ok_or(DecodeError::Type(vt.0))?;
    let dims = r.u16()?;
    r.u16()?;
    let cb = r.u32()? as usize;
    r.u32()?;
    r.u32()?;
    let count = r.u32()? as usize;
    r.u32()?;
    if dims != 1 || cb != size || depth >= MAX_DEPTH {
        return Err(DecodeError::Array(at));
    }
    // Every element takes at least 4 bytes but the 1- and 2-byte ones: bounds the
    // allocation by the input.
    if count > r.b.len() {
        return Err(DecodeError::Truncated(r.at));
    }
    let mut elements = Vec::with_capacity(count);
    for _ in 0..count {
        elements.push(match elem {
            VarType::VARIANT => read_value(r, depth + 1)?,
            VarType::BSTR => Value::Bstr(r.text()?),
            t => from_fixed(t, r.bytes8(size)?)?,
        });
    }
    Ok(Value::Array(crate::value::ArrayValue {
        element_type: elem,
        elements,
    }))
}

/// Decodes a data stream of `format` (the inverse of [`encode_data`]).
pub fn decode_data(format: DataFormat, b: &[u8]) -> Result<DataStream, DecodeError> {
    let mut r = Reader { b, at: 0 };
    let size = r.u32()?;
    if size as usize != b.len() {
        return Err(DecodeError::Size {
            declared: size,
            actual: b.len(),
        });
    }
    let count = r.u32()? as usize;
    let client_group = r.u32()?;
    let transaction_id = r.u32()?;
    let status = r.u32()? as i32;
    if count > b.len() {
        return Err(DecodeError::Truncated(r.at));
    }
    let mut heads = Vec::with_capacity(count);
    for _ in 0..count {
        let h = r.u32()?;
        let off = r.u32()? as usize;
        let q = r.u16()?;
        r.u16()?;
        let t = if format == DataFormat::DataTime {
            let lo = r.u32()?;
            let hi = r.u32()?;
            Timestamp::from_filetime_parts(lo, hi)
        } else {
            Timestamp(0)
        };
        heads.push((h, off, q, t));
    }
    let mut items = Vec::with_capacity(count);
    for (h, off, q, t) in heads {
        let mut v = Reader { b, at: off };
        items.push(StreamItem {
            client_handle: h,
            quality: Quality(q),
            timestamp: t,
            value: read_value(&mut v, 0)?,
        });
    }
    Ok(DataStream {
        client_group,
        transaction_id,
        status,
        items,
    })
}

/// Decodes a write-completion stream (the inverse of [`encode_write`]).
pub fn decode_write(b: &[u8]) -> Result<WriteStream, DecodeError> {
    let mut r = Reader { b, at: 0 };
    let count = r.u32()? as usize;
    let client_group = r.u32()?;
    let transaction_id = r.u32()?;
    let status = r.u32()? as i32;
    if count > b.len() {
        return Err(DecodeError::Truncated(r.at));
    }
    let mut items = Vec::with_capacity(count);
    for _ in 0..count {
        items.push((r.u32()?, r.u32()? as i32));
    }
    if r.at != b.len() {
        return Err(DecodeError::Size {
            declared: r.at as u32,
            actual: b.len(),
        });
    }
    Ok(WriteStream {
        client_group,
        transaction_id,
        status,
        items,
    })
}
