//! Helpers of the in-process group-object tests (`inproc_group_*.rs`), over the harness in
//! `common/mod.rs`: item definitions of the demo plant, a group with items, readers of the
//! CoTaskMem arrays the group hands out, and a recording IOPCDataCallback sink.
#![allow(dead_code, unused_imports)]

use crate::common::*;
use ctopc_com::interfaces::*;
use opc_client::ReadItem;
use std::ffi::c_void;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use windows::core::implement;
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Com::IConnectionPointContainer;
use windows::Win32::System::Variant::{VariantClear, VARENUM, VARIANT};

/// Level of tank Z101 (R4, read-only, EU 0..8).
pub const LEVEL: &str = "KW_A000";
/// Sulphur feed rate setpoint (R4 0..20 t/h, writable).
pub const SETPOINT: &str = "KW_A110";
/// A writable UI1 (0..2).
pub const UI1_WRITABLE: &str = "KW_D201";
/// The formatted text of LEVEL (BSTR, read-only, no deadband).
pub const TEXT: &str = "KW_A000.FormatedCV";
/// A server handle no item of these tests has.
pub const BAD_HANDLE: u32 = 0x7FFF_FF01;

/// The 32-bit value [`POISON`] for plain `[out]` DWORDs.
pub const POISON_U32: u32 = 0xDEAD_BEE0;

/// Item definitions and the strings they point to (valid while this lives).
pub struct Defs {
    _strings: Vec<HSTRING>,
    pub defs: Vec<OPCITEMDEF>,
}

/// One item of [`defs_of`]: ID, access path, client handle, requested type, active.
#[derive(Clone, Copy)]
pub struct Def<'a> {
    pub id: &'a str,
    pub path: &'a str,
    pub client: u32,
    pub vt: u16,
    pub active: bool,
}

/// An active item with client handle `client`, no access path, the canonical type.
pub fn def(id: &str, client: u32) -> Def<'_> {
    Def {
        id,
        path: "",
        client,
        vt: 0,
        active: true,
    }
}

pub fn defs_of(items: &[Def]) -> Defs {
    let mut strings = Vec::new();
    let mut defs = Vec::new();
    for d in items {
        let id = wide(d.id);
        let path = wide(d.path);
        defs.push(OPCITEMDEF {
            szAccessPath: PWSTR(path.as_ptr() as *mut u16),
            szItemID: PWSTR(id.as_ptr() as *mut u16),
            bActive: BOOL::from(d.active),
            hClient: d.client,
            vtRequestedDataType: VARENUM(d.vt),
            ..Default::default()
        });
        strings.push(id);
        strings.push(path);
    }
    Defs {
        _strings: strings,
        defs,
    }
}

/// Active items `ids` with client handles 1, 2, 3, ...
pub fn defs(ids: &[&str]) -> Defs {
    let items: Vec<Def> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| def(id, i as u32 + 1))
        .collect();
    defs_of(&items)
}

/// AddItems: (HRESULT, per item (result, error)); the arrays are freed.
pub fn add_items(g: &Group, d: &Defs) -> (HRESULT, Vec<(OPCITEMRESULT, HRESULT)>) {
    let (mut results, mut errors) = (poison::<OPCITEMRESULT>(), poison::<HRESULT>());
    // SAFETY: valid arrays of `d.defs.len()` definitions and valid out-pointers.
    let hr = unsafe {
        g.item_mgt.AddItems(
            d.defs.len() as u32,
            d.defs.as_ptr(),
            &mut results,
            &mut errors,
        )
    };
    take_results(hr, results, errors, d.defs.len())
}

/// The OPCITEMRESULT and error arrays of AddItems/ValidateItems, freed (NULL for a failed
/// call, checked).
pub fn take_results(
    hr: HRESULT,
    results: *mut OPCITEMRESULT,
    errors: *mut HRESULT,
    n: usize,
) -> (HRESULT, Vec<(OPCITEMRESULT, HRESULT)>) {
    if hr.is_err() {
        assert!(
            results.is_null() && errors.is_null(),
            "{hr:?}: outputs left"
        );
        return (hr, Vec::new());
    }
    // SAFETY: a successful call handed out two arrays of `n` elements; this server's
    // results own no blob.
    let r = unsafe { take_array(results, n) };
    // SAFETY: as above.
    let e = unsafe { take_array(errors, n) };
    assert!(r.iter().all(|r| r.pBlob.is_null() && r.dwBlobSize == 0));
    (hr, r.into_iter().zip(e).collect())
}

/// AddItems of `ids` (client handles 1, 2, ...) that must all succeed: the server handles.
pub fn add_ok(g: &Group, ids: &[&str]) -> Vec<u32> {
    let d = defs(ids);
    let (hr, out) = add_items(g, &d);
    assert_eq!(hr, S_OK, "AddItems({ids:?})");
    out.into_iter()
        .map(|(r, e)| {
            assert_eq!(e, S_OK);
            assert_ne!(r.hServer, 0);
            r.hServer
        })
        .collect()
}

/// A new server, a group on it and the items `ids` (client handles 1, 2, ...).
pub fn group_with(name: &str, ids: &[&str]) -> (IOPCServer, Group, Vec<u32>) {
    let (s, g) = server_with_group(name);
    let h = add_ok(&g, ids);
    (s, g, h)
}

/// The group object as interface `T`.
pub fn iface<T: Interface>(g: &Group) -> T {
    g.unknown
        .cast::<T>()
        .expect("the group object implements the interface")
}

/// Takes an error array of `n` HRESULTs (NULL for a failed call, checked).
pub fn take_errors(hr: HRESULT, errors: *mut HRESULT, n: usize) -> Vec<HRESULT> {
    if hr.is_err() {
        assert!(errors.is_null(), "{hr:?}: error array left");
        return Vec::new();
    }
    assert!(!errors.is_null(), "{hr:?}: no error array");
    // SAFETY: a successful call handed out `n` HRESULTs.
    unsafe { take_array(errors, n) }
}

/// Copies the VARIANTs of a CoTaskMem array as values and frees them (VariantClear each,
/// then the block). Empty for NULL.
///
/// # Safety
/// `p` is NULL or a CoTaskMem array of `n` initialised VARIANTs owned by the caller.
pub unsafe fn take_variants(p: *mut VARIANT, n: usize) -> Vec<ctopc_core::Value> {
    if p.is_null() {
        return Vec::new();
    }
    // SAFETY: contract of this function.
    let vars = unsafe { std::slice::from_raw_parts_mut(p, n) };
    let values = vars
        .iter_mut()
        .map(|v| {
            let value = ctopc_com::variant::from_variant(v).unwrap_or(ctopc_core::Value::Empty);
            // SAFETY: an initialised VARIANT owned by the caller.
            assert!(unsafe { VariantClear(v) }.is_ok());
            value
        })
        .collect();
    // SAFETY: the block is the caller's; its VARIANTs are cleared.
    unsafe { task_free(p) };
    values
}

/// Copies an OPCITEMSTATE array of IOPCSyncIO::Read and frees it (VariantClear each).
///
/// # Safety
/// `p` is NULL or a CoTaskMem array of `n` OPCITEMSTATEs owned by the caller.
pub unsafe fn take_states(p: *mut OPCITEMSTATE, n: usize) -> Vec<ReadItem> {
    if p.is_null() {
        return Vec::new();
    }
    // SAFETY: contract of this function.
    let states = unsafe { std::slice::from_raw_parts_mut(p, n) };
    let out = states
        .iter_mut()
        .map(|s| {
            let value =
                ctopc_com::variant::from_variant(&s.vDataValue).unwrap_or(ctopc_core::Value::Empty);
            // SAFETY: reading the VARTYPE of an initialised VARIANT.
            let vt = unsafe { s.vDataValue.Anonymous.Anonymous.vt.0 };
            let item = ReadItem {
                client_handle: s.hClient,
                vt,
                value,
                quality: s.wQuality,
                timestamp: ctopc_core::Timestamp::from_filetime_parts(
                    s.ftTimeStamp.dwLowDateTime,
                    s.ftTimeStamp.dwHighDateTime,
                ),
                error: S_OK,
            };
            // SAFETY: an initialised VARIANT owned by the caller.
            assert!(unsafe { VariantClear(&mut s.vDataValue) }.is_ok());
            item
        })
        .collect();
    // SAFETY: the block is the caller's; its VARIANTs are cleared.
    unsafe { task_free(p) };
    out
}

/// A VARIANT holding `v` (VariantClear it, or hand it to [`clear_all`]).
pub fn var(v: &ctopc_core::Value) -> VARIANT {
    ctopc_com::variant::to_variant(v).expect("to_variant")
}

/// VariantClear of every VARIANT the test made.
pub fn clear_all(vars: &mut [VARIANT]) {
    for v in vars {
        // SAFETY: a VARIANT the test initialised.
        let _ = unsafe { VariantClear(v) };
    }
}

/// Quality GOOD (the quality bits).
pub const GOOD: u16 = 0xC0;

/// Reads `handles` from the cache until every item is GOOD (the first samples arrive
/// shortly after AddItems); the items read.
pub fn cache_read_good(g: &Group, handles: &[u32]) -> Vec<ReadItem> {
    let sync: IOPCSyncIO = iface(g);
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let (mut values, mut errors) = (poison::<OPCITEMSTATE>(), poison::<HRESULT>());
        // SAFETY: valid handles and out-pointers.
        let hr = unsafe {
            sync.Read(
                OPC_DS_CACHE,
                handles.len() as u32,
                handles.as_ptr(),
                &mut values,
                &mut errors,
            )
        };
        assert!(hr == S_OK || hr == S_FALSE, "Read(CACHE): {hr:?}");
        // SAFETY: a successful Read handed out both arrays.
        let items = unsafe { take_states(values, handles.len()) };
        let errs = take_errors(hr, errors, handles.len());
        if hr == S_OK
            && errs.iter().all(|e| *e == S_OK)
            && items.iter().all(|i| i.quality & 0xC0 == GOOD)
        {
            return items;
        }
        assert!(Instant::now() < deadline, "no GOOD values: {items:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

// ---------------------------------------------------------------------------------------
// A recording IOPCDataCallback
// ---------------------------------------------------------------------------------------

/// One call the server made on the sink.
#[derive(Debug, Clone, PartialEq)]
pub enum Callback {
    DataChange {
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        items: Vec<ReadItem>,
    },
    ReadComplete {
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        items: Vec<ReadItem>,
    },
    WriteComplete {
        transaction: u32,
        group: u32,
        master_error: HRESULT,
        items: Vec<(u32, HRESULT)>,
    },
    CancelComplete {
        transaction: u32,
        group: u32,
    },
}

impl Callback {
    pub fn transaction(&self) -> u32 {
        match self {
            Callback::DataChange { transaction, .. }
            | Callback::ReadComplete { transaction, .. }
            | Callback::WriteComplete { transaction, .. }
            | Callback::CancelComplete { transaction, .. } => *transaction,
        }
    }
}

/// What a sink saw.
#[derive(Default)]
pub struct Recorder {
    log: Mutex<Vec<Callback>>,
    cv: Condvar,
}

impl Recorder {
    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<Callback>> {
        self.log.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn push(&self, cb: Callback) {
        self.lock().push(cb);
        self.cv.notify_all();
    }

    /// Waits (at most `limit`) for a callback that `pred` accepts; the first one.
    pub fn wait_for(&self, limit: Duration, pred: impl Fn(&Callback) -> bool) -> Option<Callback> {
        let deadline = Instant::now() + limit;
        let mut log = self.lock();
        loop {
            if let Some(c) = log.iter().find(|c| pred(c)) {
                return Some(c.clone());
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

    /// Every callback so far.
    pub fn all(&self) -> Vec<Callback> {
        self.lock().clone()
    }
}

/// The tests' IOPCDataCallback (a free-threaded in-process object: the server's callback
/// workers call it directly).
#[implement(IOPCDataCallback)]
pub struct Sink(pub Arc<Recorder>);

impl Sink {
    pub fn create() -> (IOPCDataCallback, Arc<Recorder>) {
        let rec = Arc::new(Recorder::default());
        (Sink(Arc::clone(&rec)).into(), rec)
    }
}

impl IOPCDataCallback_Impl for Sink_Impl {
    unsafe fn OnDataChange(
        &self,
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        n: u32,
        h: *const u32,
        v: *const VARIANT,
        q: *const u16,
        t: *const FILETIME,
        e: *const HRESULT,
    ) -> windows::core::Result<()> {
        // SAFETY: the server passes `n`-element arrays.
        let items = unsafe { opc_client::diag::callback_items(n, h, v, q, t, e) };
        self.0.push(Callback::DataChange {
            transaction,
            group,
            master_quality,
            master_error,
            items,
        });
        Ok(())
    }

    unsafe fn OnReadComplete(
        &self,
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        n: u32,
        h: *const u32,
        v: *const VARIANT,
        q: *const u16,
        t: *const FILETIME,
        e: *const HRESULT,
    ) -> windows::core::Result<()> {
        // SAFETY: the server passes `n`-element arrays.
        let items = unsafe { opc_client::diag::callback_items(n, h, v, q, t, e) };
        self.0.push(Callback::ReadComplete {
            transaction,
            group,
            master_quality,
            master_error,
            items,
        });
        Ok(())
    }

    unsafe fn OnWriteComplete(
        &self,
        transaction: u32,
        group: u32,
        master_error: HRESULT,
        n: u32,
        h: *const u32,
        e: *const HRESULT,
    ) -> windows::core::Result<()> {
        // SAFETY: the server passes `n`-element arrays.
        let items = unsafe { opc_client::diag::write_results(n, h, e) };
        self.0.push(Callback::WriteComplete {
            transaction,
            group,
            master_error,
            items,
        });
        Ok(())
    }

    unsafe fn OnCancelComplete(&self, transaction: u32, group: u32) -> windows::core::Result<()> {
        self.0.push(Callback::CancelComplete { transaction, group });
        Ok(())
    }
}

/// The group's IOPCDataCallback connection point.
pub fn data_point(g: &Group) -> windows::Win32::System::Com::IConnectionPoint {
    let cpc: IConnectionPointContainer = iface(g);
    // SAFETY: a valid IID.
    unsafe { cpc.FindConnectionPoint(&IOPCDataCallback::IID) }.expect("FindConnectionPoint")
}

/// Advises a new recording sink on the group: (cookie, recorder).
pub fn advise(g: &Group) -> (u32, Arc<Recorder>) {
    let (sink, rec) = Sink::create();
    // SAFETY: a valid sink.
    let cookie = unsafe { data_point(g).Advise(&IUnknown::from(&sink)) }.expect("Advise");
    (cookie, rec)
}

// ---------------------------------------------------------------------------------------
// Argument branches shared by the per-item methods
// ---------------------------------------------------------------------------------------

/// The branches every `(dwCount, phServer, ..., ppErrors)` method shares, with `call`
/// passing its other arguments valid: NULL ppErrors, a count of 0 and a NULL phServer are
/// E_INVALIDARG, and the error array is left NULL (it is cleared before the count and
/// phServer are checked).
pub fn check_count_and_handles(
    what: &str,
    handles: &[u32],
    call: impl Fn(u32, *const u32, *mut *mut HRESULT) -> HRESULT,
) {
    let n = handles.len() as u32;
    assert_eq!(
        call(n, handles.as_ptr(), std::ptr::null_mut()),
        E_INVALIDARG,
        "{what}: NULL ppErrors"
    );
    let mut errors = poison::<HRESULT>();
    assert_eq!(
        call(0, handles.as_ptr(), &mut errors),
        E_INVALIDARG,
        "{what}: count 0"
    );
    assert!(errors.is_null(), "{what}: count 0 left ppErrors");
    let mut errors = poison::<HRESULT>();
    assert_eq!(
        call(n, std::ptr::null(), &mut errors),
        E_INVALIDARG,
        "{what}: NULL phServer"
    );
    assert!(errors.is_null(), "{what}: NULL phServer left ppErrors");
}

/// A per-item call's (HRESULT, errors): `call` gets a valid error out-pointer.
pub fn errors_of(
    n: usize,
    call: impl FnOnce(*mut *mut HRESULT) -> HRESULT,
) -> (HRESULT, Vec<HRESULT>) {
    let mut errors = poison::<HRESULT>();
    let hr = call(&mut errors);
    (hr, take_errors(hr, errors, n))
}
