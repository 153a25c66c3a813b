//! DA 1.0a data transfer on the group: `IDataObject` (DAdvise, DUnadvise, EnumDAdvise; the
//! rest as the DA 2.05a specification allows, E_NOTIMPL) and the delivery of the OPC streams to the
//! clients' `IAdviseSink::OnDataChange`.
//!
//! A client advises one sink per stream format, each registered with
//! `RegisterClipboardFormatW`: `OPCSTMFORMATDATA` (values without time stamps),
//! `OPCSTMFORMATDATATIME` (with) and `OPCSTMFORMATWRITECOMPLETE`, always on
//! `TYMED_HGLOBAL`; another format is DV_E_FORMATETC, another medium DV_E_TYMED, a second
//! advise of a format CONNECT_E_ADVISELIMIT, an unknown connection in DUnadvise
//! OLE_E_NOCONNECTION.
//!
//! The advise connections are the group's [`Da10Sinks`], registered with the runtime
//! beside the IOPCDataCallback slot. The engine sees one "callback connected" flag per
//! group: set while an IOPCDataCallback or any DA 1.0a sink is connected
//! ([`Da10Sinks::any`]). Routing, on the client's callback worker ([`deliver`]):
//! subscription updates (transaction 0) go to every data-format sink, and to the
//! IOPCDataCallback sink too; the completion of an IOPCAsyncIO transaction (recorded by
//! `async1.rs` under the engine lock, so before its completion can be dispatched) goes to
//! the one connection the call named, as a data stream (Read, Refresh) or a write stream
//! (Write), with the transaction ID as `dwTransactionID`; a cancelled one's
//! OnCancelComplete has no DA 1.0a counterpart and is dropped.
//!
//! The stream bytes are `ctopc_core::stream` (pure, tested natively); here they are copied
//! into an HGLOBAL the server owns and frees after the call (`pUnkForRelease` NULL: the
//! sink must not free it), which ole32's IAdviseSink proxy copies to the client.

use super::Group_Impl;
use crate::com::abi;
use crate::com::comdef::{RawAdviseSink, RawDataObject_Impl, StgMedium};
use crate::com::connpoint::SinkSlot;
use crate::com::enums::StatDataEnum;
use crate::com::error;
use crate::com::interfaces::IOPCDataCallback;
use ctopc_core::model::GroupHandle;
use ctopc_core::model::{DataChangeKind, Event, ItemValue};
use ctopc_core::stream::{self, DataFormat, StreamItem};
use ctopc_core::OpcError;
use ctopc_runtime::{Delivery, GroupSink};
use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Arc;
use std::sync::{Mutex, MutexGuard};
use windows::core::{IUnknown, Interface, BOOL, HRESULT, PCWSTR};
use windows::Win32::Foundation::{
    DV_E_FORMATETC, DV_E_TYMED, E_INVALIDARG, E_NOTIMPL, E_POINTER, OLE_E_NOCONNECTION, S_OK,
};
use windows::Win32::System::Com::{
    IAdviseSink, IEnumFORMATETC, IEnumSTATDATA, FORMATETC, TYMED_HGLOBAL,
};
use windows::Win32::System::Ole::CONNECT_E_ADVISELIMIT;

// Not in the windows features the workspace builds with (Win32_System_Memory,
// Win32_System_DataExchange): declared here, as kernel32 and user32 export them.
#[link(name = "kernel32")]
extern "system" {
    fn GlobalAlloc(flags: u32, bytes: usize) -> *mut c_void;
    fn GlobalLock(mem: *mut c_void) -> *mut c_void;
    fn GlobalUnlock(mem: *mut c_void) -> BOOL;
    fn GlobalFree(mem: *mut c_void) -> *mut c_void;
    fn GlobalSize(mem: *mut c_void) -> usize;
}
#[link(name = "user32")]
extern "system" {
    fn RegisterClipboardFormatW(name: PCWSTR) -> u32;
}

const GMEM_MOVEABLE: u32 = 0x0002;
const DVASPECT_CONTENT: u32 = 1;

/// The three stream formats' names.
pub const FORMAT_DATA: &str = "OPCSTMFORMATDATA";
pub const FORMAT_DATATIME: &str = "OPCSTMFORMATDATATIME";
pub const FORMAT_WRITECOMPLETE: &str = "OPCSTMFORMATWRITECOMPLETE";

/// The clipboard format registered for `name` (0 if the registration failed).
pub fn clipboard_format(name: &str) -> u16 {
    let wide: Vec<u16> = name.encode_utf16().chain(std::iter::once(0)).collect();
    // SAFETY: `wide` is a NUL-terminated UTF-16 string alive for the call.
    let f = unsafe { RegisterClipboardFormatW(PCWSTR(wide.as_ptr())) };
    f as u16
}

/// A copy of the bytes of an HGLOBAL (a client's side: what an IAdviseSink received).
///
/// # Safety
/// `mem` is NULL or a live global memory handle.
pub unsafe fn hglobal_bytes(mem: *mut c_void) -> Vec<u8> {
    if mem.is_null() {
        return Vec::new();
    }
    // SAFETY: the caller's contract; the block is locked while it is copied.
    unsafe {
        let n = GlobalSize(mem);
        let p = GlobalLock(mem);
        if p.is_null() {
            return Vec::new();
        }
        let bytes = std::slice::from_raw_parts(p.cast::<u8>(), n).to_vec();
        let _ = GlobalUnlock(mem);
        bytes
    }
}

/// Which stream an advise connection receives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Data(DataFormat),
    Write,
}

struct Advise {
    connection: u32,
    kind: Kind,
    /// DAdvise's ADVF flags, kept for EnumDAdvise (the streams always carry data).
    advf: u32,
    sink: RawAdviseSink,
}

#[derive(Default)]
struct State {
    advises: Vec<Advise>,
    /// IOPCAsyncIO transactions under way: cancel ID (the DA 1.0a transaction ID) → the
    /// connection that receives the completion.
    txns: HashMap<u32, u32>,
}

/// The DA 1.0a advise connections of one group object, and its IOPCAsyncIO transactions.
pub struct Da10Sinks {
    data: u16,
    data_time: u16,
    write: u16,
    /// Set at the group's first DA 1.0a advise or IOPCAsyncIO transaction: until then
    /// every event is IOPCDataCallback's, and routing it takes no lock.
    used: AtomicBool,
    state: Mutex<State>,
}

// SAFETY: as `connpoint::SinkSlot`: the server process is in the MTA and the sinks are
// MTA proxies usable from any MTA thread, guarded by the mutex.
unsafe impl Send for Da10Sinks {}
// SAFETY: as above.
unsafe impl Sync for Da10Sinks {}

static NEXT_CONNECTION: AtomicU32 = AtomicU32::new(1);

impl Default for Da10Sinks {
    fn default() -> Self {
        Da10Sinks {
            data: clipboard_format(FORMAT_DATA),
            data_time: clipboard_format(FORMAT_DATATIME),
            write: clipboard_format(FORMAT_WRITECOMPLETE),
            used: AtomicBool::new(false),
            state: Mutex::new(State::default()),
        }
    }
}

impl Da10Sinks {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The stream kind of a clipboard format, if it is one of the three.
    pub fn kind_of(&self, cf: u16) -> Option<Kind> {
        if cf == 0 {
            None
        } else if cf == self.data {
            Some(Kind::Data(DataFormat::Data))
        } else if cf == self.data_time {
            Some(Kind::Data(DataFormat::DataTime))
        } else if cf == self.write {
            Some(Kind::Write)
        } else {
            None
        }
    }

    fn format_of(&self, kind: Kind) -> u16 {
        match kind {
            Kind::Data(DataFormat::Data) => self.data,
            Kind::Data(DataFormat::DataTime) => self.data_time,
            Kind::Write => self.write,
        }
    }

    /// True while any DA 1.0a sink is connected.
    pub fn any(&self) -> bool {
        !self.lock().advises.is_empty()
    }

    /// The kind of connection `connection`, if it is one of this group's.
    pub fn connection_kind(&self, connection: u32) -> Option<Kind> {
        self.lock()
            .advises
            .iter()
            .find(|a| a.connection == connection)
            .map(|a| a.kind)
    }

    /// Records an IOPCAsyncIO transaction whose completion goes to `connection` (called
    /// under the engine lock, before the completion can be dispatched).
    pub fn start_txn(&self, transaction: u32, connection: u32) {
        if transaction != 0 {
            self.used.store(true, Ordering::Release);
            self.lock().txns.insert(transaction, connection);
        }
    }

    /// True if `transaction` is an IOPCAsyncIO transaction under way.
    pub fn has_txn(&self, transaction: u32) -> bool {
        self.lock().txns.contains_key(&transaction)
    }

    fn advise(&self, kind: Kind, advf: u32, sink: RawAdviseSink) -> Result<u32, HRESULT> {
        self.used.store(true, Ordering::Release);
        let mut s = self.lock();
        if s.advises.iter().any(|a| a.kind == kind) {
            return Err(CONNECT_E_ADVISELIMIT);
        }
        let connection = NEXT_CONNECTION.fetch_add(1, Ordering::Relaxed).max(1);
        s.advises.push(Advise {
            connection,
            kind,
            advf,
            sink,
        });
        Ok(connection)
    }

    /// A snapshot for EnumDAdvise: (format, advf, sink, connection).
    fn snapshot(&self) -> Vec<(FORMATETC, u32, IAdviseSink, u32)> {
        self.lock()
            .advises
            .iter()
            .map(|a| {
                let f = FORMATETC {
                    cfFormat: self.format_of(a.kind),
                    ptd: std::ptr::null_mut(),
                    dwAspect: DVASPECT_CONTENT,
                    lindex: -1,
                    tymed: TYMED_HGLOBAL.0 as u32,
                };
                (f, a.advf, IAdviseSink::from(a.sink.clone()), a.connection)
            })
            .collect()
    }

    /// Removes a connection; the sink is released by the caller after the lock.
    fn unadvise(&self, connection: u32) -> Option<RawAdviseSink> {
        let mut s = self.lock();
        let i = s.advises.iter().position(|a| a.connection == connection)?;
        Some(s.advises.remove(i).sink)
    }

    /// Every connection gone (the group object's end); released after the lock.
    pub fn clear(&self) -> bool {
        let old = std::mem::take(&mut self.lock().advises);
        !old.is_empty()
    }

    /// The sinks an event goes to, with their kinds: `None` when the event is not the
    /// DA 1.0a side's (it goes to IOPCDataCallback only).
    fn route(&self, event: &Event) -> Option<(u32, Vec<(Kind, RawAdviseSink)>)> {
        if !self.used.load(Ordering::Acquire) {
            return None;
        }
        let mut s = self.lock();
        let cancel = event.cancel_id();
        if cancel != 0 {
            let connection = s.txns.remove(&cancel)?;
            let sinks = s
                .advises
                .iter()
                .filter(|a| a.connection == connection)
                .map(|a| (a.kind, a.sink.clone()))
                .collect();
            return Some((cancel, sinks));
        }
        match event {
            Event::DataChange(d) if d.kind == DataChangeKind::Subscription => Some((
                0,
                s.advises
                    .iter()
                    .filter(|a| matches!(a.kind, Kind::Data(_)))
                    .map(|a| (a.kind, a.sink.clone()))
                    .collect(),
            )),
            _ => None,
        }
    }
}

/// What a DA 1.0a routing decided for an event.
pub enum Routed {
    /// Not a DA 1.0a event: IOPCDataCallback only.
    NotMine,
    /// A subscription update: delivered to the DA 1.0a sinks, IOPCDataCallback too.
    Shared,
    /// An IOPCAsyncIO completion: delivered (or dropped) here only.
    Mine,
}

fn hr_of(e: Option<OpcError>) -> i32 {
    e.map_or(0, |e| error::hresult(e).0)
}

fn stream_items(items: &[ItemValue]) -> Vec<StreamItem> {
    items
        .iter()
        .map(|i| StreamItem {
            client_handle: i.client_handle,
            quality: i.quality,
            timestamp: i.timestamp,
            value: i.value.clone(),
        })
        .collect()
}

/// Calls one sink with `bytes` in an HGLOBAL of format `cf` (freed after the call).
fn send(sink: &RawAdviseSink, cf: u16, bytes: &[u8]) {
    // SAFETY: a plain allocation of at least one byte; checked for NULL.
    let mem = unsafe { GlobalAlloc(GMEM_MOVEABLE, bytes.len().max(1)) };
    if mem.is_null() {
        tracing::warn!("DA 1.0a stream of {} bytes: no global memory", bytes.len());
        return;
    }
    // SAFETY: `mem` is a live moveable block of `bytes.len()` bytes or more; locked for
    // the copy and unlocked after it.
    unsafe {
        let p = GlobalLock(mem);
        if p.is_null() {
            GlobalFree(mem);
            return;
        }
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), p.cast::<u8>(), bytes.len());
        let _ = GlobalUnlock(mem);
    }
    let format = FORMATETC {
        cfFormat: cf,
        ptd: std::ptr::null_mut(),
        dwAspect: DVASPECT_CONTENT,
        lindex: -1,
        tymed: TYMED_HGLOBAL.0 as u32,
    };
    let medium = StgMedium {
        tymed: TYMED_HGLOBAL.0 as u32,
        handle: mem,
        unk_for_release: std::ptr::null_mut(),
    };
    // SAFETY: both structures live for the call; the medium stays ours (no
    // pUnkForRelease) and is freed below, after the call returned.
    unsafe {
        sink.OnDataChange(&format, &medium);
        GlobalFree(mem);
    }
}

/// Delivers `event` to the DA 1.0a sinks it is for (on the client's worker thread).
pub fn deliver(sinks: &Da10Sinks, client_group: u32, event: &Event) -> Routed {
    let Some((transaction, targets)) = sinks.route(event) else {
        return Routed::NotMine;
    };
    let shared = transaction == 0;
    for (kind, sink) in targets {
        let cf = sinks.format_of(kind);
        let bytes = match (kind, event) {
            (Kind::Data(f), Event::DataChange(d)) => Some(stream::encode_data(
                f,
                client_group,
                transaction,
                hr_of(d.master_error.or(d.master_quality)),
                &stream_items(&d.items),
            )),
            (Kind::Data(f), Event::ReadComplete(d)) => Some(stream::encode_data(
                f,
                client_group,
                transaction,
                hr_of(d.master_error.or(d.master_quality)),
                &stream_items(&d.items),
            )),
            (Kind::Write, Event::WriteComplete(w)) => {
                let items: Vec<(u32, i32)> = w
                    .items
                    .iter()
                    .map(|i| (i.client_handle, hr_of(i.error)))
                    .collect();
                Some(stream::encode_write(
                    client_group,
                    transaction,
                    hr_of(w.master_error),
                    &items,
                ))
            }
            _ => None,
        };
        if let Some(bytes) = bytes {
            send(&sink, cf, &bytes);
        }
    }
    if shared {
        Routed::Shared
    } else {
        Routed::Mine
    }
}

// ---------------------------------------------------------------------------------------
// IDataObject
// ---------------------------------------------------------------------------------------

impl Group_Impl {
    /// Tells the engine whether any callback sink (IOPCDataCallback or DA 1.0a) is
    /// connected.
    pub(crate) fn update_connected(&self) -> Result<(), OpcError> {
        let connected = self.sink.is_connected() || self.da10.any();
        self.engine(|e, now, g| e.set_callback_connected(now, g, connected))
    }
}

impl RawDataObject_Impl for Group_Impl {
    unsafe fn GetData(&self, _format: *const FORMATETC, pmedium: *mut StgMedium) -> HRESULT {
        if !pmedium.is_null() {
            // SAFETY: the method's non-NULL [out] medium.
            unsafe {
                pmedium.write(StgMedium {
                    tymed: 0,
                    handle: std::ptr::null_mut(),
                    unk_for_release: std::ptr::null_mut(),
                })
            };
        }
        E_NOTIMPL
    }

    unsafe fn GetDataHere(&self, _format: *const FORMATETC, _pmedium: *mut StgMedium) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn QueryGetData(&self, _format: *const FORMATETC) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn GetCanonicalFormatEtc(
        &self,
        _format_in: *const FORMATETC,
        format_out: *mut FORMATETC,
    ) -> HRESULT {
        if !format_out.is_null() {
            // SAFETY: the method's non-NULL [out] structure.
            unsafe { format_out.write(FORMATETC::default()) };
        }
        E_NOTIMPL
    }

    unsafe fn SetData(
        &self,
        _format: *const FORMATETC,
        _medium: *const StgMedium,
        _release: BOOL,
    ) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn EnumFormatEtc(
        &self,
        _direction: u32,
        ppenum: *mut Option<IEnumFORMATETC>,
    ) -> HRESULT {
        // SAFETY: the method's [out] interface pointer.
        unsafe { abi::clear_outs((ppenum,)) };
        E_NOTIMPL
    }

    unsafe fn DAdvise(
        &self,
        pformatetc: *const FORMATETC,
        advf: u32,
        padvsink: *mut c_void,
        pdwconnection: *mut u32,
    ) -> HRESULT {
        // SAFETY: the method's [out] parameter.
        unsafe { abi::clear_outs((pdwconnection,)) };
        if pformatetc.is_null() || padvsink.is_null() || pdwconnection.is_null() {
            return E_INVALIDARG;
        }
        // SAFETY: checked non-NULL; an [in] FORMATETC.
        let format = unsafe { &*pformatetc };
        let Some(kind) = self.da10.kind_of(format.cfFormat) else {
            return DV_E_FORMATETC;
        };
        if format.tymed & (TYMED_HGLOBAL.0 as u32) == 0 {
            return DV_E_TYMED;
        }
        // SAFETY: `padvsink` is the caller's [in] IAdviseSink pointer, valid for the
        // call; borrowed, then AddRef'd by the cast.
        let Some(unk) = (unsafe { IUnknown::from_raw_borrowed(&padvsink) }) else {
            return E_INVALIDARG;
        };
        let Ok(sink) = unk.cast::<RawAdviseSink>() else {
            return E_INVALIDARG;
        };
        let connection = match self.da10.advise(kind, advf, sink) {
            Ok(c) => c,
            Err(hr) => return hr,
        };
        if let Err(e) = self.update_connected() {
            drop(self.da10.unadvise(connection));
            return error::hresult(e);
        }
        // SAFETY: checked non-NULL above.
        unsafe { pdwconnection.write(connection) };
        S_OK
    }

    unsafe fn DUnadvise(&self, dwconnection: u32) -> HRESULT {
        let Some(sink) = self.da10.unadvise(dwconnection) else {
            return OLE_E_NOCONNECTION;
        };
        drop(sink);
        let _ = self.update_connected();
        S_OK
    }

    /// A snapshot of the advise connections (E_POINTER for a NULL `ppenum`, as
    /// IEnum-returning COM methods answer).
    unsafe fn EnumDAdvise(&self, ppenum: *mut Option<IEnumSTATDATA>) -> HRESULT {
        // SAFETY: the method's [out] interface pointer.
        unsafe { abi::clear_outs((ppenum,)) };
        if ppenum.is_null() {
            return E_POINTER;
        }
        let e = StatDataEnum::create(self.da10.snapshot());
        // SAFETY: checked non-NULL; the [out] interface pointer takes the reference.
        unsafe { ppenum.write(Some(e)) };
        S_OK
    }
}

/// A group's callback sinks: IOPCDataCallback's slot and the DA 1.0a connections.
pub struct GroupSinks {
    pub slot: Arc<SinkSlot<IOPCDataCallback>>,
    pub da10: Arc<Da10Sinks>,
}

impl GroupSink for GroupSinks {
    fn deliver(&self, group: GroupHandle, event: Event) -> Delivery {
        match deliver(
            &self.da10,
            crate::da::callbacks::client_group(&event),
            &event,
        ) {
            // An IOPCAsyncIO completion went to the DA 1.0a sink (IAdviseSink returns
            // nothing: it cannot be lost).
            Routed::Mine => Delivery {
                called: true,
                lost: false,
            },
            Routed::Shared | Routed::NotMine => {
                crate::da::callbacks::deliver_one(group, &self.slot, event)
            }
        }
    }

    fn is_connected(&self) -> bool {
        self.slot.is_connected() || self.da10.any()
    }

    fn drop_listener(&self) -> bool {
        self.slot.cookie().is_some_and(|c| self.slot.drop_if(c))
    }
}
