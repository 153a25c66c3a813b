//! Helpers shared by the group tests (group_items, group_state, group_callbacks): a group
//! made through IOPCServer::AddGroup, and a recording IOPCDataCallback sink.
#![allow(dead_code)]

use e2e_tests::interfaces::*;
use opc_client::{ItemDef, OpcGroup, Server};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use windows::core::{implement, IUnknown, Interface, BOOL, HRESULT, HSTRING, PCWSTR};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Com::{IConnectionPoint, IConnectionPointContainer};
use windows::Win32::System::Variant::VARIANT;

/// The proxy's answer to a NULL top-level [ref] pointer (the call never reaches the server).
pub const RPC_X_NULL_REF_POINTER: HRESULT = HRESULT(0x800706F4u32 as i32);

pub const VT_EMPTY: u16 = 0;
pub const VT_I2: u16 = 2;
pub const VT_I4: u16 = 3;
pub const VT_R4: u16 = 4;
pub const VT_R8: u16 = 5;
pub const VT_BSTR: u16 = 8;
pub const VT_DISPATCH: u16 = 9;
pub const VT_ARRAY: u16 = 0x2000;

/// A group made with IOPCServer::AddGroup (update rate 1000 ms, English, no deadband).
pub struct G {
    pub group: OpcGroup,
    pub server_handle: u32,
    pub revised_rate: u32,
}

impl std::ops::Deref for G {
    type Target = OpcGroup;
    fn deref(&self) -> &OpcGroup {
        &self.group
    }
}

/// IOPCServer::AddGroup, asking for IUnknown.
pub fn try_add_group(
    server: &Server,
    name: &str,
    active: bool,
    rate: u32,
    client: u32,
) -> windows::core::Result<G> {
    let name = HSTRING::from(name);
    let (mut handle, mut revised) = (0u32, 0u32);
    let mut unk: Option<IUnknown> = None;
    let deadband = 0.0f32;
    let bias = 0i32;
    // SAFETY: valid string, in-pointers and out-pointers for the call.
    let hr = unsafe {
        server.server.AddGroup(
            PCWSTR(name.as_ptr()),
            BOOL::from(active),
            rate,
            client,
            &bias,
            &deadband,
            0x0409,
            &mut handle,
            &mut revised,
            &IUnknown::IID,
            &mut unk,
        )
    };
    hr.ok()?;
    let unknown =
        unk.ok_or_else(|| windows::core::Error::from(windows::Win32::Foundation::E_POINTER))?;
    Ok(G {
        group: OpcGroup::from_unknown(unknown)?,
        server_handle: handle,
        revised_rate: revised,
    })
}

pub fn add_group(server: &Server, name: &str, active: bool, client: u32) -> G {
    try_add_group(server, name, active, 1000, client).expect("AddGroup")
}

/// AddItems that must succeed for every item: the server handles.
pub fn add_ok(g: &OpcGroup, items: &[ItemDef]) -> Vec<u32> {
    let (hr, out) = g.add_items(items).expect("AddItems");
    assert_eq!(hr, HRESULT(0), "AddItems: {out:x?}");
    out.iter().map(|o| o.server_handle).collect()
}

pub fn item(id: &str, client: u32) -> ItemDef {
    ItemDef::new(id, client)
}

pub fn item_in(id: &str, path: &str, client: u32) -> ItemDef {
    ItemDef {
        access_path: path.into(),
        ..ItemDef::new(id, client)
    }
}

pub fn item_typed(id: &str, client: u32, vt: u16) -> ItemDef {
    ItemDef {
        requested_type: vt,
        ..ItemDef::new(id, client)
    }
}

pub fn inactive(id: &str, client: u32) -> ItemDef {
    ItemDef {
        active: false,
        ..ItemDef::new(id, client)
    }
}

/// The group's IOPCDataCallback connection point.
pub fn data_point(g: &OpcGroup) -> IConnectionPoint {
    let cpc: IConnectionPointContainer = g.unknown.cast().expect("IConnectionPointContainer");
    // SAFETY: valid IID.
    unsafe { cpc.FindConnectionPoint(&IOPCDataCallback::IID) }
        .expect("FindConnectionPoint(IOPCDataCallback)")
}

// ---- the sink ------------------------------------------------------------------------------

/// One OnDataChange.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    pub transaction: u32,
    pub group: u32,
    pub master_quality: HRESULT,
    pub master_error: HRESULT,
    /// (client handle, value, quality, error)
    pub items: Vec<(u32, ctopc_core::Value, u16, HRESULT)>,
    pub at: Instant,
}

#[derive(Default)]
pub struct Log {
    changes: Mutex<Vec<Change>>,
    cv: Condvar,
    /// While set, OnDataChange records the call and then holds it (a slow client), up to
    /// `hold_limit`.
    hold: std::sync::atomic::AtomicBool,
    hold_limit: Mutex<Duration>,
}

impl Log {
    pub fn new() -> Arc<Log> {
        Arc::new(Log::default())
    }

    pub fn changes(&self) -> Vec<Change> {
        self.changes.lock().unwrap().clone()
    }

    pub fn count(&self) -> usize {
        self.changes.lock().unwrap().len()
    }

    /// Makes the sink a slow client: each OnDataChange returns only after `limit`, or at
    /// once when [`Log::release`] is called.
    pub fn hold_calls(&self, limit: Duration) {
        *self.hold_limit.lock().unwrap() = limit;
        self.hold.store(true, std::sync::atomic::Ordering::SeqCst);
    }

    /// Ends [`Log::hold_calls`]: a held call returns now.
    pub fn release(&self) {
        self.hold.store(false, std::sync::atomic::Ordering::SeqCst);
    }

    /// Waits at most `limit` for `n` OnDataChange calls that `pred` accepts.
    pub fn wait(&self, limit: Duration, n: usize, pred: impl Fn(&Change) -> bool) -> Vec<Change> {
        let deadline = Instant::now() + limit;
        let mut g = self.changes.lock().unwrap();
        loop {
            let found: Vec<Change> = g.iter().filter(|c| pred(c)).cloned().collect();
            let left = deadline.saturating_duration_since(Instant::now());
            if found.len() >= n || left.is_zero() {
                return found;
            }
            g = self.cv.wait_timeout(g, left).unwrap().0;
        }
    }
}

#[implement(IOPCDataCallback)]
pub struct Sink(pub Arc<Log>);

impl Sink {
    pub fn create(log: &Arc<Log>) -> IOPCDataCallback {
        Sink(Arc::clone(log)).into()
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
        _t: *const FILETIME,
        e: *const HRESULT,
    ) -> windows::core::Result<()> {
        let mut items = Vec::new();
        if n > 0 && !h.is_null() && !v.is_null() && !q.is_null() && !e.is_null() {
            for i in 0..n as usize {
                // SAFETY: the stub passes [in, size_is(n)] arrays.
                unsafe {
                    items.push((
                        *h.add(i),
                        ctopc_com::variant::from_variant(&*v.add(i))
                            .unwrap_or(ctopc_core::Value::Empty),
                        *q.add(i),
                        *e.add(i),
                    ));
                }
            }
        }
        let c = Change {
            transaction,
            group,
            master_quality,
            master_error,
            items,
            at: Instant::now(),
        };
        self.0.changes.lock().unwrap().push(c);
        self.0.cv.notify_all();
        let until = Instant::now() + *self.0.hold_limit.lock().unwrap();
        while self.0.hold.load(std::sync::atomic::Ordering::SeqCst) && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(20));
        }
        Ok(())
    }
    unsafe fn OnReadComplete(
        &self,
        _: u32,
        _: u32,
        _: HRESULT,
        _: HRESULT,
        _: u32,
        _: *const u32,
        _: *const VARIANT,
        _: *const u16,
        _: *const FILETIME,
        _: *const HRESULT,
    ) -> windows::core::Result<()> {
        Ok(())
    }
    unsafe fn OnWriteComplete(
        &self,
        _: u32,
        _: u32,
        _: HRESULT,
        _: u32,
        _: *const u32,
        _: *const HRESULT,
    ) -> windows::core::Result<()> {
        Ok(())
    }
    unsafe fn OnCancelComplete(&self, _: u32, _: u32) -> windows::core::Result<()> {
        Ok(())
    }
}

/// Advises `sink` on the group's IOPCDataCallback point: the cookie.
pub fn advise(g: &OpcGroup, sink: &IOPCDataCallback) -> windows::core::Result<u32> {
    let cp = data_point(g);
    // SAFETY: a valid interface pointer.
    unsafe { cp.Advise(&sink.cast::<IUnknown>()?) }
}

pub fn unadvise(g: &OpcGroup, cookie: u32) -> windows::core::Result<()> {
    let cp = data_point(g);
    // SAFETY: plain value.
    unsafe { cp.Unadvise(cookie) }
}
