//! The group object's I/O interfaces in process (no proxy): IOPCSyncIO (Read, Write),
//! IOPCSyncIO2 (ReadMaxAge, WriteVQT), IOPCAsyncIO2 (Read, Write, Refresh2, Cancel2,
//! SetEnable, GetEnable) and IOPCAsyncIO3 (ReadMaxAge, WriteVQT, RefreshMaxAge): every
//! argument branch with its exact HRESULT, out-parameters cleared on failure, per-item
//! codes, and each method's success path with the out-parameters read and freed (the
//! completions arrive at an in-process IOPCDataCallback). Harness: `common/mod.rs`; group
//! helpers: `inproc_group_support/mod.rs`.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
mod inproc_group_support;

use common::*;
use ctopc_com::interfaces::*;
use ctopc_core::{Timestamp, Value};
use inproc_group_support::*;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Ole::CONNECT_E_NOCONNECTION;
use windows::Win32::System::Variant::VARIANT;

const VT_EMPTY: u16 = 0;
const VT_R4: u16 = 4;
/// Quality BAD, OUT OF SERVICE (an inactive item or group read from the cache).
const BAD: u16 = 0x00;
const WAIT: Duration = Duration::from_secs(10);
/// Sources outside the IDL's OPCDATASOURCE (1, 2).
const BAD_SOURCES: [OPCDATASOURCE; 3] = [
    OPCDATASOURCE(0),
    OPCDATASOURCE(3),
    OPCDATASOURCE(0x7FFF_FFFF),
];

/// The tests that write the plant's writable items take turns (they read back what they
/// wrote, and the plant is one per test process).
fn writes() -> MutexGuard<'static, ()> {
    static WRITES: Mutex<()> = Mutex::new(());
    WRITES.lock().unwrap_or_else(|p| p.into_inner())
}

/// A group (client handle 1) with LEVEL, SETPOINT, UI1_WRITABLE (client handles 1, 2, 3).
struct Plant {
    _server: IOPCServer,
    g: Group,
    h: Vec<u32>,
    /// The recording sink, when advised.
    rec: Option<Arc<Recorder>>,
}

fn plant(name: &str, advise_sink: bool) -> Plant {
    let (server, g, h) = group_with(name, &[LEVEL, SETPOINT, UI1_WRITABLE]);
    let rec = advise_sink.then(|| advise(&g).1);
    Plant {
        _server: server,
        g,
        h,
        rec,
    }
}

impl Plant {
    fn sync(&self) -> IOPCSyncIO2 {
        iface(&self.g)
    }
    fn async3(&self) -> IOPCAsyncIO3 {
        iface(&self.g)
    }
    fn async2(&self) -> IOPCAsyncIO2 {
        iface(&self.g)
    }
    fn wait_tx(&self, tid: u32) -> Callback {
        self.rec
            .as_ref()
            .expect("a sink")
            .wait_for(WAIT, |c| c.transaction() == tid)
            .unwrap_or_else(|| panic!("no callback for transaction {tid}"))
    }
}

fn clients(items: &[opc_client::ReadItem]) -> Vec<u32> {
    items.iter().map(|i| i.client_handle).collect()
}

/// IOPCSyncIO::Read: (HRESULT, items with their per-item errors).
fn read(p: &Plant, source: OPCDATASOURCE, h: &[u32]) -> (HRESULT, Vec<opc_client::ReadItem>) {
    let (mut values, mut errors) = (poison::<OPCITEMSTATE>(), poison::<HRESULT>());
    // SAFETY: valid pointers.
    let hr = unsafe {
        p.sync()
            .Read(source, h.len() as u32, h.as_ptr(), &mut values, &mut errors)
    };
    assert!(hr == S_OK || hr == S_FALSE, "Read: {hr:?}");
    // SAFETY: a successful Read handed out both arrays.
    let mut items = unsafe { take_states(values, h.len()) };
    for (i, e) in items.iter_mut().zip(take_errors(hr, errors, h.len())) {
        i.error = e;
    }
    (hr, items)
}

/// IOPCSyncIO::Write: (HRESULT, errors).
fn write(p: &Plant, items: &[(u32, Value)]) -> (HRESULT, Vec<HRESULT>) {
    let h: Vec<u32> = items.iter().map(|i| i.0).collect();
    let mut vars: Vec<VARIANT> = items.iter().map(|i| var(&i.1)).collect();
    let r = errors_of(h.len(), |e| {
        // SAFETY: valid arrays of the same length.
        unsafe { p.sync().Write(h.len() as u32, h.as_ptr(), vars.as_ptr(), e) }
    });
    clear_all(&mut vars);
    r
}

/// A valid OPCITEMVQT of `v` (VariantClear its value afterwards).
fn vqt(v: &Value, quality: Option<u16>, stamp: Option<Timestamp>) -> OPCITEMVQT {
    let ft = stamp.map(ctopc_com::clock::filetime).unwrap_or_default();
    OPCITEMVQT {
        vDataValue: var(v),
        bQualitySpecified: quality.is_some().into(),
        wQuality: quality.unwrap_or(0),
        bTimeStampSpecified: stamp.is_some().into(),
        ftTimeStamp: ft,
        ..Default::default()
    }
}

fn clear_vqts(v: &mut [OPCITEMVQT]) {
    for q in v {
        clear_all(std::slice::from_mut(&mut q.vDataValue));
    }
}

// ---- IOPCSyncIO::Read -------------------------------------------------------------------

#[test]
fn sync_read_argument_branches() {
    let p = plant("io-read-args", false);
    let sync = p.sync();
    let h = &p.h;
    let call = |src, n, ph, v, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { sync.Read(src, n, ph, v, e) }
    };
    // NULL ppItemValues.
    let mut errors: *mut HRESULT = std::ptr::null_mut();
    assert_eq!(
        call(
            OPC_DS_CACHE,
            3,
            h.as_ptr(),
            std::ptr::null_mut(),
            &mut errors
        ),
        E_INVALIDARG
    );
    // NULL ppErrors: the value array is cleared.
    let mut values = poison::<OPCITEMSTATE>();
    assert_eq!(
        call(
            OPC_DS_CACHE,
            3,
            h.as_ptr(),
            &mut values,
            std::ptr::null_mut()
        ),
        E_INVALIDARG
    );
    assert!(values.is_null());
    // Count 0, NULL handles, sources outside OPCDATASOURCE: both cleared.
    let mut cases: Vec<(OPCDATASOURCE, u32, *const u32)> = vec![
        (OPC_DS_CACHE, 0, h.as_ptr()),
        (OPC_DS_DEVICE, 3, std::ptr::null()),
    ];
    cases.extend(BAD_SOURCES.iter().map(|s| (*s, 3, h.as_ptr())));
    for (src, n, ph) in cases {
        let (mut values, mut errors) = (poison::<OPCITEMSTATE>(), poison::<HRESULT>());
        assert_eq!(
            call(src, n, ph, &mut values, &mut errors),
            E_INVALIDARG,
            "{src:?} {n}"
        );
        assert!(values.is_null() && errors.is_null(), "{src:?} {n}");
    }
}

#[test]
fn sync_read_from_cache_and_device_with_per_item_errors() {
    let p = plant("io-read", false);
    let items = cache_read_good(&p.g, &p.h);
    assert_eq!(clients(&items), vec![1, 2, 3]);
    assert_eq!(items[0].vt, VT_R4);
    let (hr, items) = read(&p, OPC_DS_DEVICE, &p.h);
    assert_eq!(hr, S_OK);
    assert_eq!(clients(&items), vec![1, 2, 3]);
    assert!(items
        .iter()
        .all(|i| i.quality & 0xC0 == GOOD && i.error == S_OK));
    for src in [OPC_DS_CACHE, OPC_DS_DEVICE] {
        let (hr, items) = read(&p, src, &[p.h[0], BAD_HANDLE, p.h[1]]);
        assert_eq!(hr, S_FALSE, "{src:?}");
        assert_eq!(
            items.iter().map(|i| i.error).collect::<Vec<_>>(),
            vec![S_OK, OPC_E_INVALIDHANDLE, S_OK]
        );
        let bad = &items[1];
        assert_eq!((bad.client_handle, bad.vt, bad.quality), (0, VT_EMPTY, 0));
    }
    // Every item invalid: S_FALSE, not a call failure.
    let (hr, items) = read(&p, OPC_DS_CACHE, &[BAD_HANDLE]);
    assert_eq!((hr, items[0].error), (S_FALSE, OPC_E_INVALIDHANDLE));
    // An inactive item read from the cache: BAD (out of service), not an error.
    let (hr, _) = errors_of(1, |e| {
        // SAFETY: valid pointers.
        unsafe {
            p.g.item_mgt
                .SetActiveState(1, p.h.as_ptr(), false.into(), e)
        }
    });
    assert_eq!(hr, S_OK);
    let (hr, items) = read(&p, OPC_DS_CACHE, &p.h[..1]);
    assert_eq!((hr, items[0].error), (S_OK, S_OK));
    assert_eq!(items[0].quality & 0xC0, BAD);
}

// ---- IOPCSyncIO::Write ------------------------------------------------------------------

#[test]
fn sync_write_argument_branches() {
    let p = plant("io-write-args", false);
    let sync = p.sync();
    let mut vars = [var(&Value::R4(1.0))];
    check_count_and_handles("Write", &p.h[1..2], |n, ph, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { sync.Write(n, ph, vars.as_ptr(), e) }
    });
    let mut errors = poison::<HRESULT>();
    // SAFETY: a deliberately NULL pItemValues.
    let hr = unsafe { sync.Write(1, p.h[1..].as_ptr(), std::ptr::null(), &mut errors) };
    assert_eq!(hr, E_INVALIDARG);
    assert!(errors.is_null());
    clear_all(&mut vars);
}

#[test]
fn sync_write_with_per_item_errors_and_read_back() {
    let _w = writes();
    let p = plant("io-write", false);
    let (lvl, sp, ui1) = (p.h[0], p.h[1], p.h[2]);
    assert_eq!(
        write(
            &p,
            &[
                (sp, Value::R4(7.5)),
                (lvl, Value::R4(1.0)),
                (sp, Value::Bstr("abc".into())),
                (BAD_HANDLE, Value::R4(1.0)),
                (ui1, Value::R8(1e9)),
            ]
        ),
        (
            S_FALSE,
            vec![
                S_OK,
                OPC_E_BADRIGHTS,
                OPC_E_BADTYPE,
                OPC_E_INVALIDHANDLE,
                OPC_E_RANGE
            ]
        )
    );
    let (_, items) = read(&p, OPC_DS_DEVICE, &[sp]);
    assert_eq!(items[0].value, Value::R4(7.5));
    assert_eq!(
        write(&p, &[(sp, Value::I4(9)), (ui1, Value::R8(2.0))]),
        (S_OK, vec![S_OK, S_OK])
    );
    let (_, items) = read(&p, OPC_DS_DEVICE, &[sp, ui1]);
    assert_eq!(items[0].value, Value::R4(9.0));
    assert_eq!(items[1].value, Value::UI1(2));
}

// ---- IOPCSyncIO2::ReadMaxAge / WriteVQT -------------------------------------------------

#[allow(clippy::type_complexity)]
fn read_max_age_raw(
    p: &Plant,
    n: u32,
    h: *const u32,
    ages: *const u32,
    outs: [bool; 4],
) -> (HRESULT, [usize; 4]) {
    let mut v = poison::<VARIANT>();
    let mut q = poison::<u16>();
    let mut t = poison::<FILETIME>();
    let mut e = poison::<HRESULT>();
    fn o<T>(on: bool, p: &mut *mut T) -> *mut *mut T {
        if on {
            p
        } else {
            std::ptr::null_mut()
        }
    }
    // SAFETY: the pointers are NULL or valid for the call.
    let hr = unsafe {
        p.sync().ReadMaxAge(
            n,
            h,
            ages,
            o(outs[0], &mut v),
            o(outs[1], &mut q),
            o(outs[2], &mut t),
            o(outs[3], &mut e),
        )
    };
    assert!(hr.is_err(), "only for failing calls");
    (hr, [v as usize, q as usize, t as usize, e as usize])
}

#[test]
fn sync_read_max_age_argument_branches() {
    let p = plant("io-rma-args", false);
    let ages = [0u32, 0, 0];
    // Each out-parameter NULL in turn: E_INVALIDARG; the ones before it are cleared.
    for null in 0..4 {
        let mut outs = [true; 4];
        outs[null] = false;
        let (hr, got) = read_max_age_raw(&p, 3, p.h.as_ptr(), ages.as_ptr(), outs);
        assert_eq!(hr, E_INVALIDARG, "out-parameter {null} NULL");
        for (i, g) in got.iter().enumerate().take(null) {
            assert_eq!(*g, 0, "out-parameter {null} NULL: {i} not cleared");
        }
    }
    // Count 0, NULL handles, NULL MaxAge array: everything cleared.
    for (n, h, a) in [
        (0u32, p.h.as_ptr(), ages.as_ptr()),
        (3, std::ptr::null(), ages.as_ptr()),
        (3, p.h.as_ptr(), std::ptr::null()),
    ] {
        let (hr, got) = read_max_age_raw(&p, n, h, a, [true; 4]);
        assert_eq!(hr, E_INVALIDARG);
        assert_eq!(got, [0; 4], "count {n}");
    }
}

#[test]
fn sync_reads_with_a_null_out_parameter_clear_all_the_others() {
    let p = plant("io-read-clear", false);
    let ages = [0u32, 0, 0];
    for null in 0..4 {
        let mut outs = [true; 4];
        outs[null] = false;
        let (_, got) = read_max_age_raw(&p, 3, p.h.as_ptr(), ages.as_ptr(), outs);
        for (i, g) in got.iter().enumerate() {
            assert!(i == null || *g == 0, "ReadMaxAge {null} NULL: {i} left");
        }
    }
    let mut errors = poison::<HRESULT>();
    // SAFETY: a deliberately NULL ppItemValues.
    let hr = unsafe {
        p.sync().Read(
            OPC_DS_CACHE,
            3,
            p.h.as_ptr(),
            std::ptr::null_mut(),
            &mut errors,
        )
    };
    assert_eq!(hr, E_INVALIDARG);
    assert!(errors.is_null(), "Read: ppErrors left");
}

#[test]
fn sync_read_max_age_values_and_per_item_errors() {
    let p = plant("io-rma", false);
    cache_read_good(&p.g, &p.h);
    for age in [0u32, u32::MAX, 5_000, 1] {
        let h = [p.h[0], BAD_HANDLE, p.h[1]];
        let ages = [age; 3];
        let (mut v, mut q, mut t, mut e) = (
            poison::<VARIANT>(),
            poison::<u16>(),
            poison::<FILETIME>(),
            poison::<HRESULT>(),
        );
        // SAFETY: valid pointers.
        let hr = unsafe {
            p.sync()
                .ReadMaxAge(3, h.as_ptr(), ages.as_ptr(), &mut v, &mut q, &mut t, &mut e)
        };
        assert_eq!(hr, S_FALSE, "MaxAge {age}");
        // SAFETY: a successful call handed out four arrays of 3.
        let (values, qualities, times) =
            unsafe { (take_variants(v, 3), take_array(q, 3), take_array(t, 3)) };
        let errors = take_errors(hr, e, 3);
        assert_eq!(errors, vec![S_OK, OPC_E_INVALIDHANDLE, S_OK]);
        assert!(matches!(values[0], Value::R4(_)), "{values:?}");
        assert_eq!(values[1], Value::Empty, "a failed item is VT_EMPTY");
        assert_eq!(qualities[0] & 0xC0, GOOD);
        assert_eq!(qualities[1], BAD, "a failed item is BAD");
        assert!(times[0].dwHighDateTime != 0);
    }
}

#[test]
fn sync_write_vqt_argument_branches() {
    let p = plant("io-wvqt-args", false);
    let sync = p.sync();
    let mut v = [vqt(&Value::R4(1.0), None, None)];
    check_count_and_handles("WriteVQT", &p.h[1..2], |n, ph, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { sync.WriteVQT(n, ph, v.as_ptr(), e) }
    });
    let mut errors = poison::<HRESULT>();
    // SAFETY: a deliberately NULL pItemVQT.
    let hr = unsafe { sync.WriteVQT(1, p.h[1..].as_ptr(), std::ptr::null(), &mut errors) };
    assert_eq!(hr, E_INVALIDARG);
    assert!(errors.is_null());
    clear_vqts(&mut v);
}

#[test]
fn sync_write_vqt_writes_value_quality_and_timestamp() {
    let _w = writes();
    let p = plant("io-wvqt", false);
    let stamp = Timestamp::from_unix_millis(1_690_000_000_000);
    let h = [p.h[1], p.h[0], BAD_HANDLE];
    let mut v = [
        vqt(&Value::R4(3.25), Some(0xD8), Some(stamp)),
        vqt(&Value::R4(1.0), None, None),
        vqt(&Value::R4(1.0), None, None),
    ];
    let (hr, errs) = errors_of(3, |e| {
        // SAFETY: valid arrays of the same length.
        unsafe { p.sync().WriteVQT(3, h.as_ptr(), v.as_ptr(), e) }
    });
    clear_vqts(&mut v);
    assert_eq!(
        (hr, errs),
        (S_FALSE, vec![S_OK, OPC_E_BADRIGHTS, OPC_E_INVALIDHANDLE])
    );
    let (_, items) = read(&p, OPC_DS_DEVICE, &p.h[1..2]);
    assert_eq!(items[0].value, Value::R4(3.25));
    assert_eq!(items[0].quality, 0xD8);
    assert_eq!(items[0].timestamp, stamp);
}

// ---- IOPCAsyncIO2 / IOPCAsyncIO3: Read, Write, ReadMaxAge, WriteVQT ----------------------

/// The branches of the four `(dwCount, phServer, [array,] dwTransactionID, pdwCancelID,
/// ppErrors)` calls: `call(count, handles, cancel, errors)` passes its other arguments
/// valid.
fn check_async_args(
    what: &str,
    h: &[u32],
    call: impl Fn(u32, *const u32, *mut u32, *mut *mut HRESULT) -> HRESULT,
) {
    let n = h.len() as u32;
    // NULL ppErrors: E_INVALIDARG.
    let mut cancel = 0u32;
    assert_eq!(
        call(n, h.as_ptr(), &mut cancel, std::ptr::null_mut()),
        E_INVALIDARG,
        "{what}: NULL ppErrors"
    );
    // NULL pdwCancelID: E_INVALIDARG, the error array cleared.
    let mut errors = poison::<HRESULT>();
    assert_eq!(
        call(n, h.as_ptr(), std::ptr::null_mut(), &mut errors),
        E_INVALIDARG,
        "{what}: NULL pdwCancelID"
    );
    assert!(errors.is_null(), "{what}: NULL pdwCancelID left ppErrors");
    // Count 0 and NULL handles: both cleared.
    for (k, ph) in [(0u32, h.as_ptr()), (n, std::ptr::null())] {
        let (mut cancel, mut errors) = (POISON_U32, poison::<HRESULT>());
        assert_eq!(
            call(k, ph, &mut cancel, &mut errors),
            E_INVALIDARG,
            "{what}: count {k}"
        );
        assert!(errors.is_null(), "{what}: count {k}: ppErrors");
        assert_eq!(cancel, 0, "{what}: count {k}: cancel ID");
    }
}

/// The second array of Write / ReadMaxAge / WriteVQT NULL: `call(array_null, cancel,
/// errors)`.
fn check_second_array_null(what: &str, call: impl Fn(*mut u32, *mut *mut HRESULT) -> HRESULT) {
    let (mut cancel, mut errors) = (POISON_U32, poison::<HRESULT>());
    assert_eq!(call(&mut cancel, &mut errors), E_INVALIDARG, "{what}");
    assert!(errors.is_null(), "{what}: ppErrors");
    assert_eq!(cancel, 0, "{what}: cancel ID");
}

#[test]
fn async_read_write_argument_branches() {
    let p = plant("io-async-args", true);
    let (a2, a3) = (p.async2(), p.async3());
    let h = &p.h[1..2];
    let mut vars = [var(&Value::R4(1.0))];
    let ages = [0u32];
    let mut vqts = [vqt(&Value::R4(1.0), None, None)];
    check_async_args("IOPCAsyncIO2::Read", h, |n, ph, c, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { a2.Read(n, ph, 1, c, e) }
    });
    check_async_args("IOPCAsyncIO2::Write", h, |n, ph, c, e| {
        // SAFETY: as above.
        unsafe { a2.Write(n, ph, vars.as_ptr(), 1, c, e) }
    });
    check_async_args("IOPCAsyncIO3::ReadMaxAge", h, |n, ph, c, e| {
        // SAFETY: as above.
        unsafe { a3.ReadMaxAge(n, ph, ages.as_ptr(), 1, c, e) }
    });
    check_async_args("IOPCAsyncIO3::WriteVQT", h, |n, ph, c, e| {
        // SAFETY: as above.
        unsafe { a3.WriteVQT(n, ph, vqts.as_ptr(), 1, c, e) }
    });
    check_second_array_null("Write: NULL pItemValues", |c, e| {
        // SAFETY: a deliberately NULL value array.
        unsafe { a2.Write(1, h.as_ptr(), std::ptr::null(), 1, c, e) }
    });
    check_second_array_null("ReadMaxAge: NULL pdwMaxAge", |c, e| {
        // SAFETY: a deliberately NULL MaxAge array.
        unsafe { a3.ReadMaxAge(1, h.as_ptr(), std::ptr::null(), 1, c, e) }
    });
    check_second_array_null("WriteVQT: NULL pItemVQT", |c, e| {
        // SAFETY: a deliberately NULL VQT array.
        unsafe { a3.WriteVQT(1, h.as_ptr(), std::ptr::null(), 1, c, e) }
    });
    clear_all(&mut vars);
    clear_vqts(&mut vqts);
    // No failed call started a transaction.
    std::thread::sleep(Duration::from_millis(300));
    let rec = p.rec.as_ref().expect("sink");
    assert!(
        !rec.all().iter().any(|c| c.transaction() == 1),
        "{:?}",
        rec.all()
    );
}

#[test]
fn async_calls_with_null_errors_clear_the_cancel_id() {
    let p = plant("io-async-clear", true);
    let mut cancel = POISON_U32;
    // SAFETY: a deliberately NULL ppErrors.
    let hr = unsafe {
        p.async2()
            .Read(1, p.h.as_ptr(), 1, &mut cancel, std::ptr::null_mut())
    };
    assert_eq!(hr, E_INVALIDARG);
    assert_eq!(cancel, 0);
}

/// An asynchronous call's (HRESULT, cancel ID, errors).
fn async_call(
    n: usize,
    call: impl FnOnce(*mut u32, *mut *mut HRESULT) -> HRESULT,
) -> (HRESULT, u32, Vec<HRESULT>) {
    let (mut cancel, mut errors) = (POISON_U32, poison::<HRESULT>());
    let hr = call(&mut cancel, &mut errors);
    (hr, cancel, take_errors(hr, errors, n))
}

#[test]
fn async_read_and_read_max_age_complete_with_on_read_complete() {
    let p = plant("io-async-read", true);
    let h = [p.h[0], BAD_HANDLE, p.h[1], p.h[2]];
    let (hr, cancel, errs) = async_call(4, |c, e| {
        // SAFETY: valid pointers.
        unsafe { p.async2().Read(4, h.as_ptr(), 101, c, e) }
    });
    assert_eq!(
        (hr, &errs[..]),
        (S_FALSE, &[S_OK, OPC_E_INVALIDHANDLE, S_OK, S_OK][..])
    );
    assert_ne!(cancel, 0);
    let Callback::ReadComplete {
        group,
        master_quality,
        master_error,
        items,
        ..
    } = p.wait_tx(101)
    else {
        panic!("{:?}", p.rec.as_ref().map(|r| r.all()))
    };
    assert_eq!(group, 1, "the group's client handle");
    assert_eq!((master_quality, master_error), (S_OK, S_OK));
    assert_eq!(clients(&items), vec![1, 2, 3], "only the valid items");
    assert!(items
        .iter()
        .all(|i| i.error == S_OK && i.quality & 0xC0 == GOOD));
    // Every item invalid: S_FALSE and no callback.
    let (hr, _, errs) = async_call(1, |c, e| {
        // SAFETY: valid pointers.
        unsafe { p.async2().Read(1, [BAD_HANDLE].as_ptr(), 102, c, e) }
    });
    assert_eq!((hr, errs), (S_FALSE, vec![OPC_E_INVALIDHANDLE]));
    // ReadMaxAge.
    let ages = [0u32, u32::MAX, 1000];
    let (hr, cancel, errs) = async_call(3, |c, e| {
        // SAFETY: valid arrays of the same length.
        unsafe {
            p.async3()
                .ReadMaxAge(3, p.h.as_ptr(), ages.as_ptr(), 103, c, e)
        }
    });
    assert_eq!((hr, errs), (S_OK, vec![S_OK; 3]));
    assert_ne!(cancel, 0);
    let Callback::ReadComplete { items, .. } = p.wait_tx(103) else {
        panic!()
    };
    assert_eq!(clients(&items), vec![1, 2, 3]);
    let rec = p.rec.as_ref().expect("sink");
    assert!(rec
        .wait_for(Duration::from_millis(500), |c| c.transaction() == 102)
        .is_none());
}

#[test]
fn async_write_and_write_vqt_complete_with_on_write_complete() {
    let _w = writes();
    let p = plant("io-async-write", true);
    let h = [p.h[1], p.h[0], p.h[1], BAD_HANDLE];
    let mut vars = [
        var(&Value::R4(6.5)),
        var(&Value::R4(1.0)),
        var(&Value::Bstr("abc".into())),
        var(&Value::R4(1.0)),
    ];
    let (hr, cancel, errs) = async_call(4, |c, e| {
        // SAFETY: valid arrays of the same length.
        unsafe { p.async2().Write(4, h.as_ptr(), vars.as_ptr(), 201, c, e) }
    });
    clear_all(&mut vars);
    assert_eq!(
        (hr, errs),
        (
            S_FALSE,
            vec![S_OK, OPC_E_BADRIGHTS, OPC_E_BADTYPE, OPC_E_INVALIDHANDLE]
        )
    );
    assert_ne!(cancel, 0);
    let Callback::WriteComplete {
        group,
        master_error,
        items,
        ..
    } = p.wait_tx(201)
    else {
        panic!()
    };
    assert_eq!((group, master_error), (1, S_OK));
    assert_eq!(items, vec![(2, S_OK)], "only the items the call accepted");
    let (_, read_back) = read(&p, OPC_DS_DEVICE, &p.h[1..2]);
    assert_eq!(read_back[0].value, Value::R4(6.5));

    let stamp = Timestamp::from_unix_millis(1_700_000_000_000);
    let mut v = [
        vqt(&Value::R4(4.75), Some(0xD8), Some(stamp)),
        vqt(&Value::R4(1.0), None, None),
    ];
    let hv = [p.h[1], p.h[0]];
    let (hr, cancel, errs) = async_call(2, |c, e| {
        // SAFETY: valid arrays of the same length.
        unsafe { p.async3().WriteVQT(2, hv.as_ptr(), v.as_ptr(), 202, c, e) }
    });
    clear_vqts(&mut v);
    assert_eq!((hr, errs), (S_FALSE, vec![S_OK, OPC_E_BADRIGHTS]));
    assert_ne!(cancel, 0);
    let Callback::WriteComplete { items, .. } = p.wait_tx(202) else {
        panic!()
    };
    assert_eq!(items, vec![(2, S_OK)]);
    let (_, read_back) = read(&p, OPC_DS_DEVICE, &p.h[1..2]);
    assert_eq!(
        (
            read_back[0].value.clone(),
            read_back[0].quality,
            read_back[0].timestamp
        ),
        (Value::R4(4.75), 0xD8, stamp)
    );
}

// ---- Refresh2 / RefreshMaxAge / Cancel2 / SetEnable / GetEnable --------------------------

#[test]
fn refresh_argument_branches() {
    let p = plant("io-refresh-args", true);
    let (a2, a3) = (p.async2(), p.async3());
    // NULL pdwCancelID.
    assert_eq!(
        // SAFETY: a deliberately NULL out-pointer.
        hr(unsafe { a2.Refresh2(OPC_DS_CACHE, 1, std::ptr::null_mut()) }),
        E_INVALIDARG
    );
    assert_eq!(
        // SAFETY: a deliberately NULL out-pointer.
        hr(unsafe { a3.RefreshMaxAge(0, 1, std::ptr::null_mut()) }),
        E_INVALIDARG
    );
    // Sources outside OPCDATASOURCE.
    for src in BAD_SOURCES {
        let mut cancel = 0u32;
        assert_eq!(
            // SAFETY: a valid out-pointer.
            hr(unsafe { a2.Refresh2(src, 1, &mut cancel) }),
            E_INVALIDARG,
            "{src:?}"
        );
        assert_eq!(
            // SAFETY: a deliberately NULL out-pointer.
            hr(unsafe { a2.Refresh2(src, 1, std::ptr::null_mut()) }),
            E_INVALIDARG,
            "{src:?}"
        );
    }
    // GetEnable(NULL).
    assert_eq!(
        // SAFETY: a deliberately NULL out-pointer.
        hr(unsafe { a2.GetEnable(std::ptr::null_mut()) }),
        E_INVALIDARG
    );
    // Unknown cancel IDs: E_FAIL.
    for id in [0u32, 0xFFFF_FFF0, BAD_HANDLE] {
        // SAFETY: a plain value.
        assert_eq!(hr(unsafe { a2.Cancel2(id) }), E_FAIL, "{id:#x}");
    }
}

#[test]
fn refresh2_with_a_bad_source_clears_the_cancel_id() {
    let p = plant("io-refresh-clear", true);
    let mut cancel = POISON_U32;
    // SAFETY: a valid out-pointer.
    let r = unsafe { p.async2().Refresh2(OPCDATASOURCE(7), 1, &mut cancel) };
    assert_eq!(hr(r), E_INVALIDARG);
    assert_eq!(cancel, 0);
}

#[test]
fn refresh_sends_every_active_item_and_fails_for_an_inactive_group() {
    let p = plant("io-refresh", true);
    let (a2, a3) = (p.async2(), p.async3());
    for (src, tid) in [(OPC_DS_CACHE, 301u32), (OPC_DS_DEVICE, 302)] {
        let mut cancel = POISON_U32;
        // SAFETY: a valid out-pointer.
        assert_eq!(hr(unsafe { a2.Refresh2(src, tid, &mut cancel) }), S_OK);
        assert!(cancel != 0 && cancel != POISON_U32);
        let Callback::DataChange { group, items, .. } = p.wait_tx(tid) else {
            panic!()
        };
        assert_eq!(group, 1);
        assert_eq!(clients(&items), vec![1, 2, 3], "{src:?}");
    }
    for (age, tid) in [(0u32, 303u32), (u32::MAX, 304)] {
        let mut cancel = POISON_U32;
        // SAFETY: a valid out-pointer.
        assert_eq!(hr(unsafe { a3.RefreshMaxAge(age, tid, &mut cancel) }), S_OK);
        assert!(cancel != 0 && cancel != POISON_U32);
        let Callback::DataChange { items, .. } = p.wait_tx(tid) else {
            panic!()
        };
        assert_eq!(clients(&items), vec![1, 2, 3], "MaxAge {age}");
    }
    // An inactive group: E_FAIL, the cancel ID cleared.
    let sm: IOPCGroupStateMgt = iface(&p.g);
    let (inactive, mut revised) = (BOOL(0), 0u32);
    // SAFETY: valid pointers.
    let r = unsafe {
        sm.SetState(
            std::ptr::null(),
            &mut revised,
            &inactive,
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(r, S_OK);
    let mut cancel = POISON_U32;
    assert_eq!(
        // SAFETY: a valid out-pointer.
        hr(unsafe { a2.Refresh2(OPC_DS_CACHE, 305, &mut cancel) }),
        E_FAIL
    );
    assert_eq!(cancel, 0);
    let mut cancel = POISON_U32;
    // SAFETY: a valid out-pointer.
    assert_eq!(hr(unsafe { a3.RefreshMaxAge(0, 306, &mut cancel) }), E_FAIL);
    assert_eq!(cancel, 0);
}

#[test]
fn enable_and_cancel_of_a_completed_transaction() {
    let p = plant("io-enable", true);
    let a2 = p.async2();
    let get = || {
        let mut b = BOOL(7);
        // SAFETY: a valid out-pointer.
        assert_eq!(hr(unsafe { a2.GetEnable(&mut b) }), S_OK);
        b.as_bool()
    };
    assert!(get(), "enabled by default");
    // SAFETY: a plain value.
    assert_eq!(hr(unsafe { a2.SetEnable(false.into()) }), S_OK);
    assert!(!get());
    // SAFETY: a plain value.
    assert_eq!(hr(unsafe { a2.SetEnable(true.into()) }), S_OK);
    assert!(get());
    // A transaction that has completed cannot be cancelled.
    let (hr_, cancel, _) = async_call(1, |c, e| {
        // SAFETY: valid pointers.
        unsafe { a2.Read(1, p.h.as_ptr(), 401, c, e) }
    });
    assert_eq!(hr_, S_OK);
    let done = p.wait_tx(401);
    if matches!(done, Callback::ReadComplete { .. }) {
        // SAFETY: a plain value.
        assert_eq!(hr(unsafe { a2.Cancel2(cancel) }), E_FAIL);
    }
}

#[test]
fn async_calls_without_a_sink_are_connect_e_noconnection_with_outputs_cleared() {
    let p = plant("io-noconn", false);
    let (a2, a3) = (p.async2(), p.async3());
    let h = &p.h[1..2];
    let mut vars = [var(&Value::R4(1.0))];
    let ages = [0u32];
    let mut vqts = [vqt(&Value::R4(1.0), None, None)];
    type Call<'a> = Box<dyn Fn(*mut u32, *mut *mut HRESULT) -> HRESULT + 'a>;
    let calls: Vec<(&str, Call)> = vec![
        (
            "Read",
            // SAFETY: valid pointers.
            Box::new(|c, e| unsafe { a2.Read(1, h.as_ptr(), 1, c, e) }),
        ),
        (
            "Write",
            // SAFETY: valid pointers.
            Box::new(|c, e| unsafe { a2.Write(1, h.as_ptr(), vars.as_ptr(), 2, c, e) }),
        ),
        (
            "ReadMaxAge",
            // SAFETY: valid pointers.
            Box::new(|c, e| unsafe { a3.ReadMaxAge(1, h.as_ptr(), ages.as_ptr(), 3, c, e) }),
        ),
        (
            "WriteVQT",
            // SAFETY: valid pointers.
            Box::new(|c, e| unsafe { a3.WriteVQT(1, h.as_ptr(), vqts.as_ptr(), 4, c, e) }),
        ),
    ];
    for (what, call) in &calls {
        let (mut cancel, mut errors) = (POISON_U32, poison::<HRESULT>());
        assert_eq!(
            call(&mut cancel, &mut errors),
            CONNECT_E_NOCONNECTION,
            "{what}"
        );
        assert!(errors.is_null(), "{what}: ppErrors");
        assert_eq!(cancel, 0, "{what}: cancel ID");
    }
    drop(calls);
    clear_all(&mut vars);
    clear_vqts(&mut vqts);
    let mut cancel = POISON_U32;
    // SAFETY: a valid out-pointer.
    let r = unsafe { a2.Refresh2(OPC_DS_CACHE, 5, &mut cancel) };
    assert_eq!((hr(r), cancel), (CONNECT_E_NOCONNECTION, 0));
    let mut cancel = POISON_U32;
    // SAFETY: a valid out-pointer.
    let r = unsafe { a3.RefreshMaxAge(0, 6, &mut cancel) };
    assert_eq!((hr(r), cancel), (CONNECT_E_NOCONNECTION, 0));
    let mut b = BOOL(7);
    // SAFETY: a valid out-pointer.
    assert_eq!(hr(unsafe { a2.GetEnable(&mut b) }), CONNECT_E_NOCONNECTION);
    assert_eq!(
        // SAFETY: a plain value.
        hr(unsafe { a2.SetEnable(false.into()) }),
        CONNECT_E_NOCONNECTION
    );
}

/// A VARIANT no Value can come from (VT_NULL: OPC_E_BADTYPE when decoded).
fn null_variant() -> VARIANT {
    let mut v = VARIANT::default();
    // SAFETY: setting the VARTYPE of an empty VARIANT (VT_NULL owns nothing).
    unsafe { (*v.Anonymous.Anonymous).vt = windows::Win32::System::Variant::VT_NULL };
    v
}

#[test]
fn writes_of_variants_that_hold_no_value_fail_per_item_after_the_basic_checks() {
    let p = plant("io-write-null-variant", true);
    // SETPOINT: OPC_E_BADTYPE; LEVEL (read-only): OPC_E_BADRIGHTS wins; an unknown handle:
    // OPC_E_INVALIDHANDLE wins. Nothing is written.
    let h = [p.h[1], p.h[0], BAD_HANDLE];
    let expected = vec![OPC_E_BADTYPE, OPC_E_BADRIGHTS, OPC_E_INVALIDHANDLE];
    let vars = [null_variant(), null_variant(), null_variant()];
    let r = errors_of(3, |e| {
        // SAFETY: valid arrays of the same length.
        unsafe { p.sync().Write(3, h.as_ptr(), vars.as_ptr(), e) }
    });
    assert_eq!(r, (S_FALSE, expected.clone()), "Write");
    let vqts: Vec<OPCITEMVQT> = (0..3)
        .map(|_| OPCITEMVQT {
            vDataValue: null_variant(),
            ..Default::default()
        })
        .collect();
    let r = errors_of(3, |e| {
        // SAFETY: valid arrays of the same length.
        unsafe { p.sync().WriteVQT(3, h.as_ptr(), vqts.as_ptr(), e) }
    });
    assert_eq!(r, (S_FALSE, expected.clone()), "WriteVQT");
    let (hr_, cancel, errs) = async_call(3, |c, e| {
        // SAFETY: valid arrays of the same length.
        unsafe { p.async2().Write(3, h.as_ptr(), vars.as_ptr(), 901, c, e) }
    });
    assert_eq!((hr_, errs), (S_FALSE, expected.clone()), "async Write");
    assert_eq!(cancel, 0, "no item accepted: no transaction to cancel");
    let (hr_, _, errs) = async_call(3, |c, e| {
        // SAFETY: valid arrays of the same length.
        unsafe { p.async3().WriteVQT(3, h.as_ptr(), vqts.as_ptr(), 902, c, e) }
    });
    assert_eq!((hr_, errs), (S_FALSE, expected), "async WriteVQT");
    // No item was accepted: no completion.
    let rec = p.rec.as_ref().expect("sink");
    assert!(rec
        .wait_for(Duration::from_millis(500), |c| matches!(
            c.transaction(),
            901 | 902
        ))
        .is_none());
}

#[test]
fn cancel2_ends_a_transaction_with_on_cancel_complete_or_fails_once_it_completed() {
    let p = plant("io-cancel", true);
    let a2 = p.async2();
    let rec = p.rec.as_ref().expect("sink");
    let mut cancelled = 0;
    for tid in 801..821u32 {
        let (hr_, cancel, _) = async_call(3, |c, e| {
            // SAFETY: valid pointers.
            unsafe { a2.Read(3, p.h.as_ptr(), tid, c, e) }
        });
        assert_eq!(hr_, S_OK);
        // SAFETY: a plain value.
        match hr(unsafe { a2.Cancel2(cancel) }) {
            S_OK => {
                cancelled += 1;
                let c = p.wait_tx(tid);
                assert_eq!(
                    c,
                    Callback::CancelComplete {
                        transaction: tid,
                        group: 1
                    }
                );
                // SAFETY: a plain value.
                assert_eq!(hr(unsafe { a2.Cancel2(cancel) }), E_FAIL, "cancelled twice");
            }
            E_FAIL => {
                assert!(matches!(p.wait_tx(tid), Callback::ReadComplete { .. }));
            }
            other => panic!("Cancel2: {other:?}"),
        }
    }
    // Exactly one completion per transaction (a cancelled one has no OnReadComplete).
    std::thread::sleep(Duration::from_millis(300));
    for tid in 801..821u32 {
        let n = rec.all().iter().filter(|c| c.transaction() == tid).count();
        assert_eq!(n, 1, "transaction {tid}: {:?}", rec.all());
    }
    eprintln!("Cancel2: {cancelled} of 20 cancelled before completion");
}

/// WriteVQT of a VT_EMPTY value with a quality or a timestamp: OPC_E_NOTSUPPORTED
/// per item (DA 3.0: "the server does not support the requested combination (which could be
/// a single quantity such as just timestamp)"); VT_EMPTY alone is OPC_E_BADTYPE; a VARIANT
/// that decodes to no value keeps its decoding error (OPC_E_BADTYPE) even with a quality;
/// the handle and rights checks still come first. Nothing is written.
#[test]
fn write_vqt_of_an_empty_value_with_a_quality_or_timestamp_is_opc_e_notsupported() {
    let p = plant("io-write-vqt-empty", false);
    let vqt = |value: VARIANT, quality: bool, stamp: bool| OPCITEMVQT {
        vDataValue: value,
        bQualitySpecified: quality.into(),
        wQuality: 0xC0,
        bTimeStampSpecified: stamp.into(),
        ftTimeStamp: FILETIME {
            dwLowDateTime: 1,
            dwHighDateTime: 0x01D8_0000,
        },
        ..Default::default()
    };
    let h = [p.h[1], p.h[1], p.h[1], p.h[1], p.h[1], p.h[0], BAD_HANDLE];
    let vqts = [
        vqt(VARIANT::default(), true, false),
        vqt(VARIANT::default(), false, true),
        vqt(VARIANT::default(), true, true),
        vqt(VARIANT::default(), false, false),
        vqt(null_variant(), true, true),
        vqt(VARIANT::default(), true, false),
        vqt(VARIANT::default(), true, false),
    ];
    let r = errors_of(7, |e| {
        // SAFETY: valid arrays of the same length.
        unsafe { p.sync().WriteVQT(7, h.as_ptr(), vqts.as_ptr(), e) }
    });
    assert_eq!(
        r,
        (
            S_FALSE,
            vec![
                OPC_E_NOTSUPPORTED,
                OPC_E_NOTSUPPORTED,
                OPC_E_NOTSUPPORTED,
                OPC_E_BADTYPE,
                OPC_E_BADTYPE,
                OPC_E_BADRIGHTS,
                OPC_E_INVALIDHANDLE
            ]
        )
    );
}
