//! DA 1.0a on the group object in process (no proxy): IDataObject (DAdvise of each OPC
//! stream format, its failure codes, DUnadvise, EnumDAdvise, the methods the specification leaves
//! E_NOTIMPL) and IOPCAsyncIO (Read from cache and device, Write, Refresh, Cancel, every
//! argument branch), with the streams decoded by `ctopc_core::stream` from what an
//! in-process IAdviseSink received.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
mod inproc_group_support;

use common::*;
use ctopc_com::comdef::{
    RawAdviseSink, RawAdviseSink_Impl, RawDataObject, RawEnumSTATDATA, StgMedium,
};
use ctopc_com::group::dataobject::{
    clipboard_format, hglobal_bytes, FORMAT_DATA, FORMAT_DATATIME, FORMAT_WRITECOMPLETE,
};
use ctopc_com::interfaces::*;
use ctopc_core::stream::{decode_data, decode_write, DataFormat, DataStream, WriteStream};
use ctopc_core::Value;
use inproc_group_support::*;
use std::ffi::c_void;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use windows::core::implement;
use windows::Win32::Foundation::{DV_E_FORMATETC, DV_E_TYMED, E_NOTIMPL, OLE_E_NOCONNECTION};
use windows::Win32::System::Com::{IEnumFORMATETC, IEnumSTATDATA, FORMATETC, STATDATA};
use windows::Win32::System::Ole::{CONNECT_E_ADVISELIMIT, CONNECT_E_NOCONNECTION};
use windows::Win32::System::Variant::VARIANT;

const WAIT: Duration = Duration::from_secs(10);
const TYMED_HGLOBAL: u32 = 1;
const TYMED_ISTREAM: u32 = 4;

/// One OnDataChange: the format and the HGLOBAL's bytes.
#[derive(Clone, Debug)]
struct Received {
    cf: u16,
    tymed: u32,
    bytes: Vec<u8>,
}

#[derive(Default)]
struct Streams {
    log: Mutex<Vec<Received>>,
    cv: Condvar,
}

impl Streams {
    fn wait_for(&self, pred: impl Fn(&Received) -> bool) -> Option<Received> {
        let deadline = Instant::now() + WAIT;
        let mut log = self.log.lock().unwrap();
        loop {
            if let Some(r) = log.iter().find(|r| pred(r)) {
                return Some(r.clone());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            log = self.cv.wait_timeout(log, left).unwrap().0;
        }
    }
    fn all(&self) -> Vec<Received> {
        self.log.lock().unwrap().clone()
    }
}

#[implement(RawAdviseSink)]
struct AdviseSink(Arc<Streams>);

impl RawAdviseSink_Impl for AdviseSink_Impl {
    unsafe fn OnDataChange(&self, f: *const FORMATETC, m: *const StgMedium) {
        // SAFETY: the server passes a valid FORMATETC and STGMEDIUM for the call.
        let (cf, tymed, bytes) = unsafe { ((*f).cfFormat, (*m).tymed, hglobal_bytes((*m).handle)) };
        self.0
            .log
            .lock()
            .unwrap()
            .push(Received { cf, tymed, bytes });
        self.0.cv.notify_all();
    }
    unsafe fn OnViewChange(&self, _: u32, _: i32) {}
    unsafe fn OnRename(&self, _: *mut c_void) {}
    unsafe fn OnSave(&self) {}
    unsafe fn OnClose(&self) {}
}

/// Our definition of the enumerator, for raw HRESULTs.
fn raw_enum(e: Option<IEnumSTATDATA>) -> RawEnumSTATDATA {
    e.expect("an enumerator").cast().unwrap()
}

fn sink() -> (RawAdviseSink, Arc<Streams>) {
    let s = Arc::new(Streams::default());
    (AdviseSink(Arc::clone(&s)).into(), s)
}

fn fmt(cf: u16, tymed: u32) -> FORMATETC {
    FORMATETC {
        cfFormat: cf,
        ptd: std::ptr::null_mut(),
        dwAspect: 1,
        lindex: -1,
        tymed,
    }
}

fn cf_data() -> u16 {
    clipboard_format(FORMAT_DATA)
}
fn cf_time() -> u16 {
    clipboard_format(FORMAT_DATATIME)
}
fn cf_write() -> u16 {
    clipboard_format(FORMAT_WRITECOMPLETE)
}

/// DAdvise: (HRESULT, connection).
fn dadvise(d: &RawDataObject, cf: u16, tymed: u32, s: &RawAdviseSink) -> (HRESULT, u32) {
    let mut c = POISON_U32;
    // SAFETY: valid pointers for the call.
    let hr = unsafe { d.DAdvise(&fmt(cf, tymed), 0, s.as_raw(), &mut c) };
    (hr, c)
}

/// A group with LEVEL, SETPOINT, TEXT and its IDataObject.
struct Plant {
    _server: IOPCServer,
    g: Group,
    h: Vec<u32>,
    d: RawDataObject,
}

fn plant(name: &str) -> Plant {
    let (server, g, h) = group_with(name, &[LEVEL, SETPOINT, TEXT]);
    let d = iface::<RawDataObject>(&g);
    Plant {
        _server: server,
        g,
        h,
        d,
    }
}

impl Plant {
    fn a1(&self) -> IOPCAsyncIO {
        iface(&self.g)
    }
    /// Read: (HRESULT, transaction, errors).
    fn read(&self, conn: u32, source: OPCDATASOURCE, h: &[u32]) -> (HRESULT, u32, Vec<HRESULT>) {
        let (mut t, mut e) = (POISON_U32, poison::<HRESULT>());
        // SAFETY: valid pointers.
        let hr = unsafe {
            self.a1()
                .Read(conn, source, h.len() as u32, h.as_ptr(), &mut t, &mut e)
        };
        (hr, t, take_errors(hr, e, h.len()))
    }
    fn write(&self, conn: u32, items: &[(u32, Value)]) -> (HRESULT, u32, Vec<HRESULT>) {
        let h: Vec<u32> = items.iter().map(|i| i.0).collect();
        let mut vars: Vec<VARIANT> = items.iter().map(|i| var(&i.1)).collect();
        let (mut t, mut e) = (POISON_U32, poison::<HRESULT>());
        // SAFETY: valid arrays of the same length.
        let hr = unsafe {
            self.a1().Write(
                conn,
                h.len() as u32,
                h.as_ptr(),
                vars.as_ptr(),
                &mut t,
                &mut e,
            )
        };
        clear_all(&mut vars);
        (hr, t, take_errors(hr, e, h.len()))
    }
}

fn data_of(s: &Streams, cf: u16, tid: u32) -> DataStream {
    let f = if cf == cf_time() {
        DataFormat::DataTime
    } else {
        DataFormat::Data
    };
    let r = s
        .wait_for(|r| r.cf == cf && decode_data(f, &r.bytes).is_ok_and(|d| d.transaction_id == tid))
        .unwrap_or_else(|| panic!("no data stream of transaction {tid}: {:?}", s.all()));
    assert_eq!(r.tymed, TYMED_HGLOBAL);
    decode_data(f, &r.bytes).unwrap()
}

fn write_of(s: &Streams, tid: u32) -> WriteStream {
    let r = s
        .wait_for(|r| {
            r.cf == cf_write() && decode_write(&r.bytes).is_ok_and(|w| w.transaction_id == tid)
        })
        .unwrap_or_else(|| panic!("no write stream of transaction {tid}"));
    decode_write(&r.bytes).unwrap()
}

#[test]
fn the_group_offers_iopcasyncio_and_idataobject() {
    let p = plant("da10-qi");
    assert!(p.g.unknown.cast::<IOPCAsyncIO>().is_ok());
    assert!(p
        .g
        .unknown
        .cast::<windows::Win32::System::Com::IDataObject>()
        .is_ok());
    assert_ne!(cf_data(), 0);
    assert_ne!(cf_data(), cf_time());
    assert_ne!(cf_time(), cf_write());
}

#[test]
fn dadvise_argument_branches_and_dunadvise() {
    let p = plant("da10-advise");
    let (s, _) = sink();
    // NULL FORMATETC, sink, connection.
    let mut c = POISON_U32;
    // SAFETY: deliberately NULL arguments.
    unsafe {
        assert_eq!(
            p.d.DAdvise(std::ptr::null(), 0, s.as_raw(), &mut c),
            E_INVALIDARG
        );
        assert_eq!(c, 0, "cleared");
        c = POISON_U32;
        assert_eq!(
            p.d.DAdvise(
                &fmt(cf_data(), TYMED_HGLOBAL),
                0,
                std::ptr::null_mut(),
                &mut c
            ),
            E_INVALIDARG
        );
        assert_eq!(c, 0);
        assert_eq!(
            p.d.DAdvise(
                &fmt(cf_data(), TYMED_HGLOBAL),
                0,
                s.as_raw(),
                std::ptr::null_mut()
            ),
            E_INVALIDARG
        );
    }
    // Another format, another medium.
    assert_eq!(
        dadvise(&p.d, 1, TYMED_HGLOBAL, &s),
        (DV_E_FORMATETC, 0),
        "CF_TEXT"
    );
    assert_eq!(dadvise(&p.d, cf_data(), TYMED_ISTREAM, &s), (DV_E_TYMED, 0));
    // Each format once.
    let mut conns = Vec::new();
    for cf in [cf_data(), cf_time(), cf_write()] {
        let (hr, c) = dadvise(&p.d, cf, TYMED_HGLOBAL | TYMED_ISTREAM, &s);
        assert_eq!(hr, S_OK);
        assert_ne!(c, 0);
        assert_eq!(
            dadvise(&p.d, cf, TYMED_HGLOBAL, &s),
            (CONNECT_E_ADVISELIMIT, 0)
        );
        conns.push(c);
    }
    // EnumDAdvise lists the three with their formats.
    let mut e: Option<IEnumSTATDATA> = None;
    // SAFETY: a valid out-pointer.
    assert_eq!(unsafe { p.d.EnumDAdvise(&mut e) }, S_OK);
    let mut got: [STATDATA; 4] = Default::default();
    let mut n = 0u32;
    let e = raw_enum(e);
    // SAFETY: room for 4 elements.
    let r = unsafe { e.Next(4, got.as_mut_ptr(), &mut n) };
    assert_eq!(r, S_FALSE);
    assert_eq!(n, 3);
    let mut listed: Vec<(u32, u16)> = got[..3]
        .iter_mut()
        .map(|d| {
            assert!(d.pAdvSink.is_some());
            assert_eq!(d.formatetc.tymed, TYMED_HGLOBAL);
            // SAFETY: the enumerator handed out a reference: released once.
            unsafe { std::mem::ManuallyDrop::drop(&mut d.pAdvSink) };
            (d.dwConnection, d.formatetc.cfFormat)
        })
        .collect();
    listed.sort_unstable();
    let mut want: Vec<(u32, u16)> = conns
        .iter()
        .copied()
        .zip([cf_data(), cf_time(), cf_write()])
        .collect();
    want.sort_unstable();
    assert_eq!(listed, want);
    conns.sort_unstable();
    conns.dedup();
    assert_eq!(conns.len(), 3, "distinct connections");
    // SAFETY: plain values.
    unsafe {
        assert_eq!(p.d.DUnadvise(0x7FFF_0000), OLE_E_NOCONNECTION);
        for c in &conns {
            assert_eq!(p.d.DUnadvise(*c), S_OK);
            assert_eq!(p.d.DUnadvise(*c), OLE_E_NOCONNECTION);
        }
    }
    // Advise again after DUnadvise.
    assert_eq!(dadvise(&p.d, cf_data(), TYMED_HGLOBAL, &s).0, S_OK);
}

#[test]
fn the_other_idataobject_methods_are_not_implemented() {
    let p = plant("da10-notimpl");
    let f = fmt(cf_data(), TYMED_HGLOBAL);
    let mut m = StgMedium {
        tymed: POISON_U32,
        handle: poison(),
        unk_for_release: poison(),
    };
    let mut out = fmt(7, 7);
    let mut e1: Option<IEnumFORMATETC> = None;
    let mut e2: Option<IEnumSTATDATA> = None;
    // SAFETY: valid pointers for the calls.
    unsafe {
        assert_eq!(p.d.GetData(&f, &mut m), E_NOTIMPL);
        assert!(
            m.handle.is_null() && m.tymed == 0,
            "GetData cleared the medium"
        );
        assert_eq!(p.d.GetDataHere(&f, &mut m), E_NOTIMPL);
        assert_eq!(p.d.QueryGetData(&f), E_NOTIMPL);
        assert_eq!(p.d.GetCanonicalFormatEtc(&f, &mut out), E_NOTIMPL);
        assert_eq!(out.cfFormat, 0, "cleared");
        assert_eq!(p.d.SetData(&f, &m, false.into()), E_NOTIMPL);
        assert_eq!(p.d.EnumFormatEtc(1, &mut e1), E_NOTIMPL);
        assert!(e1.is_none());
        // No connection: an empty enumerator.
        assert_eq!(p.d.EnumDAdvise(&mut e2), S_OK);
        let mut got = [STATDATA::default()];
        let mut n = 7u32;
        assert_eq!(raw_enum(e2).Next(1, got.as_mut_ptr(), &mut n), S_FALSE);
        assert_eq!(n, 0);
        assert_eq!(p.d.EnumDAdvise(std::ptr::null_mut()), E_POINTER);
        assert_eq!(p.d.GetData(&f, std::ptr::null_mut()), E_NOTIMPL);
    }
}

#[test]
fn iopcasyncio_needs_the_right_connection() {
    let p = plant("da10-noconn");
    let h = &p.h[..1];
    assert_eq!(p.read(1, OPC_DS_CACHE, h).0, CONNECT_E_NOCONNECTION);
    assert_eq!(
        p.write(1, &[(p.h[1], Value::R4(1.0))]).0,
        CONNECT_E_NOCONNECTION
    );
    let mut t = POISON_U32;
    // SAFETY: valid pointer.
    let r = unsafe { p.a1().Refresh(1, OPC_DS_CACHE, &mut t) };
    assert_eq!(hr(r), CONNECT_E_NOCONNECTION);
    assert_eq!(t, 0);
    let (s, _) = sink();
    let (_, data) = dadvise(&p.d, cf_data(), TYMED_HGLOBAL, &s);
    let (_, w) = dadvise(&p.d, cf_write(), TYMED_HGLOBAL, &s);
    // A data connection does not take writes, nor the write one reads.
    assert_eq!(
        p.write(data, &[(p.h[1], Value::R4(1.0))]).0,
        CONNECT_E_NOCONNECTION
    );
    let (hr_, mut t, _) = p.read(w, OPC_DS_CACHE, h);
    assert_eq!((hr_, t), (CONNECT_E_NOCONNECTION, 0));
    // SAFETY: valid pointer.
    let r = unsafe { p.a1().Refresh(w, OPC_DS_CACHE, &mut t) };
    assert_eq!(hr(r), CONNECT_E_NOCONNECTION);
    // Unknown transaction.
    // SAFETY: a plain value.
    assert_eq!(hr(unsafe { p.a1().Cancel(0x7FFF_0001) }), E_FAIL);
}

#[test]
fn iopcasyncio_argument_branches() {
    let p = plant("da10-args");
    let (s, _) = sink();
    let (_, c) = dadvise(&p.d, cf_time(), TYMED_HGLOBAL, &s);
    let (_, w) = dadvise(&p.d, cf_write(), TYMED_HGLOBAL, &s);
    let a = p.a1();
    let h = p.h.clone();
    let mut vars = [var(&Value::R4(1.0))];
    // SAFETY: the pointers are NULL or valid for each call.
    unsafe {
        for src in [OPCDATASOURCE(0), OPCDATASOURCE(3), OPCDATASOURCE(7)] {
            let (mut t, mut e) = (POISON_U32, poison::<HRESULT>());
            assert_eq!(a.Read(c, src, 1, h.as_ptr(), &mut t, &mut e), E_INVALIDARG);
            assert!(e.is_null());
            assert_eq!(t, 0);
            assert_eq!(hr(a.Refresh(c, src, &mut t)), E_INVALIDARG);
        }
        for (n, ph) in [(0u32, h.as_ptr()), (1, std::ptr::null())] {
            let (mut t, mut e) = (POISON_U32, poison::<HRESULT>());
            assert_eq!(a.Read(c, OPC_DS_CACHE, n, ph, &mut t, &mut e), E_INVALIDARG);
            assert!(e.is_null());
            assert_eq!(t, 0);
            let (mut t, mut e) = (POISON_U32, poison::<HRESULT>());
            assert_eq!(
                a.Write(w, n, ph, vars.as_ptr(), &mut t, &mut e),
                E_INVALIDARG
            );
            assert!(e.is_null());
            assert_eq!(t, 0);
        }
        let (mut t, mut e) = (POISON_U32, poison::<HRESULT>());
        assert_eq!(
            a.Write(w, 1, h.as_ptr(), std::ptr::null(), &mut t, &mut e),
            E_INVALIDARG
        );
        assert!(e.is_null());
        let mut e = poison::<HRESULT>();
        assert_eq!(
            a.Read(c, OPC_DS_CACHE, 1, h.as_ptr(), std::ptr::null_mut(), &mut e),
            E_INVALIDARG
        );
        assert!(e.is_null());
        let mut t = POISON_U32;
        assert_eq!(
            a.Read(c, OPC_DS_CACHE, 1, h.as_ptr(), &mut t, std::ptr::null_mut()),
            E_INVALIDARG
        );
        assert_eq!(t, 0);
        assert_eq!(
            hr(a.Refresh(c, OPC_DS_CACHE, std::ptr::null_mut())),
            E_INVALIDARG
        );
    }
    clear_all(&mut vars);
}

#[test]
fn read_from_cache_and_device_comes_as_a_data_stream() {
    let p = plant("da10-read");
    // The cache holds every item's first sample.
    cache_read_good(&p.g, &p.h);
    let (s, streams) = sink();
    let (_, c) = dadvise(&p.d, cf_time(), TYMED_HGLOBAL, &s);
    for source in [OPC_DS_CACHE, OPC_DS_DEVICE] {
        let h = [p.h[0], BAD_HANDLE, p.h[2]];
        let (hr_, t, errors) = p.read(c, source, &h);
        assert_eq!(hr_, S_FALSE, "{source:?}");
        assert_eq!(errors[0], S_OK);
        assert_eq!(errors[1].0 as u32, 0xC004_0001, "OPC_E_INVALIDHANDLE");
        assert_ne!(t, 0, "a transaction ID");
        let d = data_of(&streams, cf_time(), t);
        assert_eq!(d.client_group, 1);
        let handles: Vec<u32> = d.items.iter().map(|i| i.client_handle).collect();
        assert_eq!(handles, [1, 3], "the valid items, client handles");
        assert!(matches!(d.items[0].value, Value::R4(_)), "{:?}", d.items[0]);
        assert!(
            matches!(d.items[1].value, Value::Bstr(_)),
            "{:?}",
            d.items[1]
        );
        assert!(d.items[0].timestamp.0 > 0);
    }
}

#[test]
fn write_completes_with_a_write_stream() {
    let p = plant("da10-write");
    let (s, streams) = sink();
    let (_, w) = dadvise(&p.d, cf_write(), TYMED_HGLOBAL, &s);
    let (hr_, t, errors) = p.write(w, &[(p.h[1], Value::R4(3.5)), (BAD_HANDLE, Value::R4(1.0))]);
    assert_eq!(hr_, S_FALSE);
    assert_eq!(errors[1].0 as u32, 0xC004_0001);
    assert_ne!(t, 0);
    let ws = write_of(&streams, t);
    assert_eq!(ws.client_group, 1);
    assert_eq!(ws.items, vec![(2, 0)]);
    assert_eq!(ws.status, 0);
    // Nothing went to a data format.
    assert!(streams.all().iter().all(|r| r.cf == cf_write()));
}

#[test]
fn refresh_and_subscription_come_as_data_streams() {
    let p = plant("da10-refresh");
    let (s, streams) = sink();
    let (_, c) = dadvise(&p.d, cf_data(), TYMED_HGLOBAL, &s);
    // The subscription: transaction 0, every active item.
    let sub = data_of(&streams, cf_data(), 0);
    assert_eq!(sub.items.len(), 3, "{sub:?}");
    let mut t = POISON_U32;
    // SAFETY: valid pointer.
    let r = unsafe { p.a1().Refresh(c, OPC_DS_DEVICE, &mut t) };
    assert_eq!(hr(r), S_OK);
    assert_ne!(t, 0);
    let d = data_of(&streams, cf_data(), t);
    assert_eq!(d.items.len(), 3);
    assert!(
        d.items.iter().all(|i| i.timestamp.0 == 0),
        "no time in OPCSTMFORMATDATA"
    );
    // Cancel after the completion: E_FAIL.
    // SAFETY: a plain value.
    assert_eq!(hr(unsafe { p.a1().Cancel(t) }), E_FAIL);
}

#[test]
fn dunadvise_stops_the_streams() {
    let p = plant("da10-stop");
    let (s, streams) = sink();
    let (_, c) = dadvise(&p.d, cf_data(), TYMED_HGLOBAL, &s);
    data_of(&streams, cf_data(), 0);
    // SAFETY: a plain value.
    assert_eq!(unsafe { p.d.DUnadvise(c) }, S_OK);
    std::thread::sleep(Duration::from_millis(300));
    let n = streams.all().len();
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(streams.all().len(), n, "no stream after DUnadvise");
    assert_eq!(p.read(c, OPC_DS_CACHE, &p.h[..1]).0, CONNECT_E_NOCONNECTION);
}

#[test]
fn iopcasyncio2_still_needs_an_iopcdatacallback() {
    let p = plant("da10-mixed");
    let (s, _) = sink();
    assert_eq!(dadvise(&p.d, cf_data(), TYMED_HGLOBAL, &s).0, S_OK);
    assert_eq!(dadvise(&p.d, cf_write(), TYMED_HGLOBAL, &s).0, S_OK);
    let a2 = iface::<IOPCAsyncIO2>(&p.g);
    let (mut c, mut e) = (POISON_U32, poison::<HRESULT>());
    // SAFETY: valid pointers.
    unsafe {
        assert_eq!(
            a2.Read(1, p.h.as_ptr(), 5, &mut c, &mut e),
            CONNECT_E_NOCONNECTION
        );
        assert!(e.is_null());
        assert_eq!(c, 0);
        assert_eq!(
            hr(a2.Refresh2(OPC_DS_CACHE, 5, &mut c)),
            CONNECT_E_NOCONNECTION
        );
    }
}
