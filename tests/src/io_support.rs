//! Support for the group I/O tests and the COM benchmark: a test IOPCDataCallback sink
//! that records (or only counts) what the server calls back, and small helpers that make
//! a group with items through IOPCServer::AddGroup and IOPCItemMgt::AddItems.

use ctopc_com::interfaces::*;
use opc_client::Server;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use windows::core::{implement, IUnknown, Interface, BOOL, HRESULT, PWSTR};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Com::CoTaskMemFree;
use windows::Win32::System::Variant::VARIANT;

/// One item of an OnDataChange / OnReadComplete (the client library's owned copy).
pub type CbItem = opc_client::ReadItem;

/// One call the server made on the sink.
#[derive(Debug, Clone, PartialEq)]
pub enum Callback {
    DataChange {
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        items: Vec<CbItem>,
    },
    ReadComplete {
        transaction: u32,
        group: u32,
        master_quality: HRESULT,
        master_error: HRESULT,
        items: Vec<CbItem>,
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

/// Seconds since 1970, for progress lines that are compared across processes.
pub fn unix_secs() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

/// What a sink saw. With `record` off it only counts (for the benchmark).
#[derive(Default)]
pub struct Recorder {
    record: bool,
    log: Mutex<Vec<Callback>>,
    cv: Condvar,
    /// OnDataChange calls and the items they carried (with transaction ID 0 only).
    pub data_changes: AtomicU64,
    pub data_change_items: AtomicU64,
    pub calls: AtomicU64,
    /// Print each OnDataChange's size and time to stderr (`BENCH_TRACE` set).
    trace: bool,
}

impl Recorder {
    pub fn recording() -> Arc<Recorder> {
        Arc::new(Recorder {
            record: true,
            ..Default::default()
        })
    }
    pub fn counting() -> Arc<Recorder> {
        Arc::new(Recorder {
            trace: std::env::var_os("BENCH_TRACE").is_some(),
            ..Default::default()
        })
    }

    fn push(&self, cb: impl FnOnce() -> Callback) {
        self.calls.fetch_add(1, Ordering::Relaxed);
        if self.record {
            let cb = cb();
            self.log.lock().unwrap().push(cb);
        }
        self.cv.notify_all();
    }

    /// Waits (at most `limit`) for a callback that `pred` accepts; returns the first one.
    pub fn wait_for(&self, limit: Duration, pred: impl Fn(&Callback) -> bool) -> Option<Callback> {
        let deadline = Instant::now() + limit;
        let mut log = self.log.lock().unwrap();
        loop {
            if let Some(c) = log.iter().find(|c| pred(c)) {
                return Some(c.clone());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            log = self.cv.wait_timeout(log, left).unwrap().0;
        }
    }

    /// Every callback so far.
    pub fn all(&self) -> Vec<Callback> {
        self.log.lock().unwrap().clone()
    }

    pub fn clear(&self) {
        self.log.lock().unwrap().clear();
    }
}

/// The test's IOPCDataCallback.
#[implement(IOPCDataCallback)]
pub struct TestSink(pub Arc<Recorder>);

impl TestSink {
    pub fn create(rec: &Arc<Recorder>) -> IOPCDataCallback {
        TestSink(Arc::clone(rec)).into()
    }
}

use opc_client::diag::callback_items as items;

impl IOPCDataCallback_Impl for TestSink_Impl {
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
        if transaction == 0 {
            self.0.data_changes.fetch_add(1, Ordering::Relaxed);
            self.0
                .data_change_items
                .fetch_add(u64::from(n), Ordering::Relaxed);
            if self.0.trace {
                eprintln!(
                    "OnDataChange group {group:#x}: {n} items at {:.3}",
                    unix_secs()
                );
            }
        }
        self.0.push(|| Callback::DataChange {
            transaction,
            group,
            master_quality,
            master_error,
            // SAFETY: the stub passes `n`-element arrays, read before `push` returns.
            items: unsafe { items(n, h, v, q, t, e) },
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
        self.0.push(|| Callback::ReadComplete {
            transaction,
            group,
            master_quality,
            master_error,
            // SAFETY: the stub passes `n`-element arrays, read before `push` returns.
            items: unsafe { items(n, h, v, q, t, e) },
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
        // SAFETY: the stub passes `n`-element arrays.
        let items = unsafe { opc_client::diag::write_results(n, h, e) };
        self.0.push(|| Callback::WriteComplete {
            transaction,
            group,
            master_error,
            items,
        });
        Ok(())
    }

    unsafe fn OnCancelComplete(&self, transaction: u32, group: u32) -> windows::core::Result<()> {
        self.0
            .push(|| Callback::CancelComplete { transaction, group });
        Ok(())
    }
}

/// A group made with IOPCServer::AddGroup.
pub struct TestGroup {
    pub unknown: IUnknown,
    pub server_handle: u32,
    pub revised_rate: u32,
}

impl TestGroup {
    pub fn cast<I: Interface>(&self) -> I {
        self.unknown.cast::<I>().expect("group interface")
    }
    pub fn sync(&self) -> IOPCSyncIO {
        self.cast()
    }
    pub fn sync2(&self) -> IOPCSyncIO2 {
        self.cast()
    }
    pub fn async2(&self) -> IOPCAsyncIO2 {
        self.cast()
    }
    pub fn async3(&self) -> IOPCAsyncIO3 {
        self.cast()
    }
}

/// IOPCServer::AddGroup (no deadband, English).
pub fn add_group(
    server: &Server,
    name: &str,
    active: bool,
    rate_ms: u32,
    client_handle: u32,
) -> windows::core::Result<TestGroup> {
    let name = windows::core::HSTRING::from(name);
    let mut handle = 0u32;
    let mut revised = 0u32;
    let mut unk: Option<IUnknown> = None;
    let deadband = 0.0f32;
    // SAFETY: valid string, in-pointers and out-pointers for the call.
    let hr = unsafe {
        server.server.AddGroup(
            windows::core::PCWSTR(name.as_ptr()),
            BOOL::from(active),
            rate_ms,
            client_handle,
            std::ptr::null(),
            &deadband,
            0x0409,
            &mut handle,
            &mut revised,
            &IID_IOPCItemMgt,
            &mut unk,
        )
    };
    hr.ok()?;
    let unknown =
        unk.ok_or_else(|| windows::core::Error::from(windows::Win32::Foundation::E_POINTER))?;
    Ok(TestGroup {
        unknown,
        server_handle: handle,
        revised_rate: revised,
    })
}

/// An active group (1000 ms) with active items `ids`, client handles 1, 2, … in order,
/// each added with its canonical type.
pub fn group_with_items(server: &Server, name: &str, ids: &[&str]) -> TestGroup {
    let group = add_group(server, name, true, 1000, 1).expect("AddGroup");
    let specs: Vec<ItemSpec> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| ItemSpec {
            id,
            client: i as u32 + 1,
            vt: 0,
            active: true,
        })
        .collect();
    add_ok(&group, &specs);
    group
}

/// An item to add: (item ID, client handle, requested type (VT_EMPTY for canonical), active).
pub struct ItemSpec<'a> {
    pub id: &'a str,
    pub client: u32,
    pub vt: u16,
    pub active: bool,
}

/// The per-item answer of AddItems.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Added {
    pub error: HRESULT,
    pub server: u32,
    pub canonical: u16,
    pub rights: u32,
}

/// IOPCItemMgt::AddItems: (S_OK / S_FALSE, per item).
pub fn add_items(
    group: &TestGroup,
    items: &[ItemSpec],
) -> windows::core::Result<(HRESULT, Vec<Added>)> {
    let mgt: IOPCItemMgt = group.cast();
    let ids: Vec<Vec<u16>> = items
        .iter()
        .map(|i| i.id.encode_utf16().chain(std::iter::once(0)).collect())
        .collect();
    let mut empty: Vec<u16> = vec![0];
    let defs: Vec<OPCITEMDEF> = items
        .iter()
        .zip(&ids)
        .map(|(i, id)| OPCITEMDEF {
            szAccessPath: PWSTR(empty.as_mut_ptr()),
            szItemID: PWSTR(id.as_ptr() as *mut u16),
            bActive: BOOL::from(i.active),
            hClient: i.client,
            dwBlobSize: 0,
            pBlob: std::ptr::null_mut(),
            vtRequestedDataType: windows::Win32::System::Variant::VARENUM(i.vt),
            wReserved: 0,
        })
        .collect();
    let mut results: *mut OPCITEMRESULT = std::ptr::null_mut();
    let mut errors: *mut HRESULT = std::ptr::null_mut();
    // SAFETY: `defs` holds `len` item definitions whose strings outlive the call.
    let hr = unsafe { mgt.AddItems(defs.len() as u32, defs.as_ptr(), &mut results, &mut errors) };
    if hr.is_err() {
        return Err(hr.into());
    }
    let n = items.len();
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    let errs = unsafe { opc_client::take_array(errors, n) };
    let mut out = Vec::with_capacity(n);
    if !results.is_null() {
        // SAFETY: the server allocated `n` OPCITEMRESULTs; blobs and the block freed once.
        let r = unsafe { std::slice::from_raw_parts(results, n) };
        for (i, x) in r.iter().enumerate() {
            if !x.pBlob.is_null() {
                // SAFETY: a CoTaskMem blob owned by the caller.
                unsafe { CoTaskMemFree(Some(x.pBlob as *const _)) };
            }
            out.push(Added {
                error: errs.get(i).copied().unwrap_or_default(),
                server: x.hServer,
                canonical: x.vtCanonicalDataType.0,
                rights: x.dwAccessRights,
            });
        }
        // SAFETY: as above.
        unsafe { CoTaskMemFree(Some(results as *const _)) };
    }
    Ok((hr, out))
}

/// AddItems that must succeed for every item: the server handles.
pub fn add_ok(group: &TestGroup, items: &[ItemSpec]) -> Vec<u32> {
    let (hr, added) = add_items(group, items).expect("AddItems");
    assert_eq!(hr, HRESULT(0), "AddItems: {added:x?}");
    added.iter().map(|a| a.server).collect()
}

/// IOPCGroupStateMgt::SetState(active) only.
pub fn set_active(group: &TestGroup, active: bool) -> HRESULT {
    let st: IOPCGroupStateMgt = group.cast();
    let b = BOOL::from(active);
    let mut revised = 0u32;
    // SAFETY: valid in/out pointers; the others are [unique] NULL.
    unsafe {
        st.SetState(
            std::ptr::null(),
            &mut revised,
            &b,
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
        )
    }
}

/// IOPCServer::RemoveGroup.
pub fn remove_group(server: &Server, handle: u32) -> HRESULT {
    // SAFETY: plain values.
    unsafe { server.server.RemoveGroup(handle, BOOL(0)) }
}
