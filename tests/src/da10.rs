//! A DA 1.0a client of our own for the end-to-end tests: an `IAdviseSink` that copies the
//! HGLOBAL of each `OnDataChange` and a decoder that reads the OPC stream field by field,
//! written from the DA 2.05a structure definitions (OPCGROUPHEADER, OPCITEMHEADER1/2,
//! OPCGROUPHEADERWRITE, OPCITEMHEADERWRITE, the VARIANTs with their BSTR payloads) rather
//! than with the server's encoder (`ctopc_core::stream`), so that a layout mistake there
//! shows here; plus IDataObject::DAdvise and the IOPCAsyncIO calls as raw HRESULTs.

use crate::interfaces::*;
use ctopc_com::comdef::{RawAdviseSink, RawAdviseSink_Impl, RawDataObject, StgMedium};
use ctopc_com::group::dataobject::{
    clipboard_format, hglobal_bytes, FORMAT_DATA, FORMAT_DATATIME, FORMAT_WRITECOMPLETE,
};
use std::ffi::c_void;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use windows::core::{implement, IUnknown, Interface, HRESULT};
use windows::Win32::System::Com::FORMATETC;
use windows::Win32::System::Variant::VARIANT;

pub const TYMED_HGLOBAL: u32 = 1;
pub const TYMED_ISTREAM: u32 = 4;

/// The three formats as this process registered them (the same atoms as the server's).
pub fn cf_data() -> u16 {
    clipboard_format(FORMAT_DATA)
}
pub fn cf_data_time() -> u16 {
    clipboard_format(FORMAT_DATATIME)
}
pub fn cf_write() -> u16 {
    clipboard_format(FORMAT_WRITECOMPLETE)
}

/// One OnDataChange as received.
#[derive(Clone, Debug)]
pub struct Received {
    pub cf: u16,
    pub aspect: u32,
    pub lindex: i32,
    pub format_tymed: u32,
    pub tymed: u32,
    pub bytes: Vec<u8>,
}

/// What a sink received, in order.
#[derive(Default)]
pub struct Streams {
    log: Mutex<Vec<Received>>,
    cv: Condvar,
}

impl Streams {
    /// Waits (at most `limit`) for the first stream `pred` accepts.
    pub fn wait_for(&self, limit: Duration, pred: impl Fn(&Received) -> bool) -> Option<Received> {
        let deadline = Instant::now() + limit;
        let mut log = self.log.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            if let Some(r) = log.iter().find(|r| pred(r)) {
                return Some(r.clone());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            log = self
                .cv
                .wait_timeout(log, left)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }
    pub fn all(&self) -> Vec<Received> {
        self.log.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }
}

#[implement(RawAdviseSink)]
struct AdviseSink(Arc<Streams>);

impl RawAdviseSink_Impl for AdviseSink_Impl {
    unsafe fn OnDataChange(&self, f: *const FORMATETC, m: *const StgMedium) {
        if f.is_null() || m.is_null() {
            return;
        }
        // SAFETY: checked non-NULL; the stub passes a FORMATETC and a STGMEDIUM valid for
        // the call, the medium's HGLOBAL owned by the caller.
        let r = unsafe {
            Received {
                cf: (*f).cfFormat,
                aspect: (*f).dwAspect,
                lindex: (*f).lindex,
                format_tymed: (*f).tymed,
                tymed: (*m).tymed,
                bytes: hglobal_bytes((*m).handle),
            }
        };
        self.0.log.lock().unwrap_or_else(|p| p.into_inner()).push(r);
        self.0.cv.notify_all();
    }
    unsafe fn OnViewChange(&self, _: u32, _: i32) {}
    unsafe fn OnRename(&self, _: *mut c_void) {}
    unsafe fn OnSave(&self) {}
    unsafe fn OnClose(&self) {}
}

/// A new recording sink.
pub fn advise_sink() -> (RawAdviseSink, Arc<Streams>) {
    let s = Arc::new(Streams::default());
    (AdviseSink(Arc::clone(&s)).into(), s)
}

pub fn formatetc(cf: u16, tymed: u32) -> FORMATETC {
    FORMATETC {
        cfFormat: cf,
        ptd: std::ptr::null_mut(),
        dwAspect: 1,
        lindex: -1,
        tymed,
    }
}

/// The group's IDataObject (through ole32's proxy).
pub fn data_object(group: &IUnknown) -> RawDataObject {
    group.cast().expect("IDataObject on the group")
}

/// IDataObject::DAdvise: (HRESULT, connection).
pub fn dadvise(d: &RawDataObject, cf: u16, tymed: u32, sink: &RawAdviseSink) -> (HRESULT, u32) {
    let mut c = 0xDEAD_BEE0u32;
    // SAFETY: valid pointers for the call.
    let hr = unsafe { d.DAdvise(&formatetc(cf, tymed), 0, sink.as_raw(), &mut c) };
    (hr, c)
}

/// Takes a CoTaskMem HRESULT array of `n` (NULL: empty).
fn take_errors(p: *mut HRESULT, n: usize) -> Vec<HRESULT> {
    if p.is_null() {
        return Vec::new();
    }
    // SAFETY: the call handed out `n` HRESULTs in CoTaskMem, freed here.
    unsafe {
        let v = std::slice::from_raw_parts(p, n).to_vec();
        windows::Win32::System::Com::CoTaskMemFree(Some(p as *const c_void));
        v
    }
}

/// IOPCAsyncIO::Read: (HRESULT, transaction ID, errors).
pub fn read(
    a: &IOPCAsyncIO,
    connection: u32,
    source: OPCDATASOURCE,
    h: &[u32],
) -> (HRESULT, u32, Vec<HRESULT>) {
    let (mut t, mut e) = (0xDEAD_BEE0u32, std::ptr::null_mut());
    // SAFETY: valid pointers for the call.
    let hr = unsafe {
        a.Read(
            connection,
            source,
            h.len() as u32,
            h.as_ptr(),
            &mut t,
            &mut e,
        )
    };
    (hr, t, take_errors(e, h.len()))
}

/// IOPCAsyncIO::Write: (HRESULT, transaction ID, errors).
pub fn write(
    a: &IOPCAsyncIO,
    connection: u32,
    h: &[u32],
    values: &[VARIANT],
) -> (HRESULT, u32, Vec<HRESULT>) {
    let (mut t, mut e) = (0xDEAD_BEE0u32, std::ptr::null_mut());
    // SAFETY: arrays of the same length, valid for the call.
    let hr = unsafe {
        a.Write(
            connection,
            h.len() as u32,
            h.as_ptr(),
            values.as_ptr(),
            &mut t,
            &mut e,
        )
    };
    (hr, t, take_errors(e, h.len()))
}

/// IOPCAsyncIO::Refresh: (HRESULT, transaction ID).
pub fn refresh(a: &IOPCAsyncIO, connection: u32, source: OPCDATASOURCE) -> (HRESULT, u32) {
    let mut t = 0xDEAD_BEE0u32;
    // SAFETY: a valid out-pointer.
    let r = unsafe { a.Refresh(connection, source, &mut t) };
    (r.map_or_else(|e| e.code(), |()| HRESULT(0)), t)
}

// ---- the decoder ----------------------------------------------------------------------

fn u16_at(b: &[u8], at: usize) -> Result<u16, String> {
    b.get(at..at + 2)
        .map(|s| u16::from_le_bytes([s[0], s[1]]))
        .ok_or_else(|| format!("no WORD at {at} of {}", b.len()))
}
fn u32_at(b: &[u8], at: usize) -> Result<u32, String> {
    b.get(at..at + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .ok_or_else(|| format!("no DWORD at {at} of {}", b.len()))
}
fn u64_at(b: &[u8], at: usize) -> Result<u64, String> {
    Ok(u64::from(u32_at(b, at)?) | (u64::from(u32_at(b, at + 4)?) << 32))
}

/// OPCGROUPHEADER.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GroupHeader {
    pub size: u32,
    pub item_count: u32,
    pub client_group: u32,
    pub transaction_id: u32,
    pub status: HRESULT,
}

/// One item: OPCITEMHEADER1/2 and its VARIANT.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamValue {
    pub client: u32,
    pub value_offset: u32,
    pub quality: u16,
    pub reserved: u16,
    /// FILETIME (OPCITEMHEADER1 only).
    pub time: Option<u64>,
    pub vt: u16,
    /// The VARIANT's 8 data bytes.
    pub data: [u8; 8],
    /// VT_BSTR: the text after the VARIANT (its DWORD byte count, the characters, NUL).
    pub text: Option<String>,
}

impl StreamValue {
    pub fn f32(&self) -> f32 {
        f32::from_le_bytes([self.data[0], self.data[1], self.data[2], self.data[3]])
    }
    pub fn f64(&self) -> f64 {
        f64::from_le_bytes(self.data)
    }
    pub fn i64(&self) -> i64 {
        i64::from_le_bytes(self.data)
    }
}

/// A data stream, decoded field by field; `with_time` for OPCSTMFORMATDATATIME.
pub fn decode_data(b: &[u8], with_time: bool) -> Result<(GroupHeader, Vec<StreamValue>), String> {
    let h = GroupHeader {
        size: u32_at(b, 0)?,
        item_count: u32_at(b, 4)?,
        client_group: u32_at(b, 8)?,
        transaction_id: u32_at(b, 12)?,
        status: HRESULT(u32_at(b, 16)? as i32),
    };
    if h.size as usize != b.len() {
        return Err(format!("dwSize {} of a {}-byte HGLOBAL", h.size, b.len()));
    }
    let item_size = if with_time { 20 } else { 12 };
    let mut items = Vec::new();
    for i in 0..h.item_count as usize {
        let at = 20 + i * item_size;
        let value_offset = u32_at(b, at + 4)?;
        let v = value_offset as usize;
        if v < 20 + h.item_count as usize * item_size {
            return Err(format!("item {i}: value offset {v} inside the headers"));
        }
        let vt = u16_at(b, v)?;
        let mut data = [0u8; 8];
        data.copy_from_slice(b.get(v + 8..v + 16).ok_or("truncated VARIANT")?);
        let text = if vt == 8 {
            let n = u32_at(b, v + 16)? as usize;
            let chars: Result<Vec<u16>, String> =
                (0..n / 2).map(|k| u16_at(b, v + 20 + 2 * k)).collect();
            if u16_at(b, v + 20 + n)? != 0 {
                return Err(format!("item {i}: BSTR without its NUL"));
            }
            Some(String::from_utf16(&chars?).map_err(|e| e.to_string())?)
        } else {
            None
        };
        items.push(StreamValue {
            client: u32_at(b, at)?,
            value_offset,
            quality: u16_at(b, at + 8)?,
            reserved: u16_at(b, at + 10)?,
            time: if with_time {
                Some(u64_at(b, at + 12)?)
            } else {
                None
            },
            vt,
            data,
            text,
        });
    }
    Ok((h, items))
}

/// OPCGROUPHEADERWRITE and the OPCITEMHEADERWRITEs: (item count, client group,
/// transaction, status, [(client handle, error)]).
pub type WriteDecoded = (u32, u32, u32, HRESULT, Vec<(u32, HRESULT)>);

pub fn decode_write(b: &[u8]) -> Result<WriteDecoded, String> {
    let n = u32_at(b, 0)?;
    if b.len() != 16 + 8 * n as usize {
        return Err(format!("{} items in {} bytes", n, b.len()));
    }
    let items = (0..n as usize)
        .map(|i| {
            Ok((
                u32_at(b, 16 + 8 * i)?,
                HRESULT(u32_at(b, 20 + 8 * i)? as i32),
            ))
        })
        .collect::<Result<Vec<_>, String>>()?;
    Ok((
        n,
        u32_at(b, 4)?,
        u32_at(b, 8)?,
        HRESULT(u32_at(b, 12)? as i32),
        items,
    ))
}
