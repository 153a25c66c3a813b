//! Connection points to the letter: the sink is QueryInterfaced for the expected
//! interface, one connection per point (CONNECT_E_ADVISELIMIT beyond), non-zero cookies,
//! unknown cookies rejected. The container holds only the sink slots, never the
//! IConnectionPoint objects, so there is no reference cycle: each FindConnectionPoint
//! makes a small connection point that holds the container.
//!
//! The objects implement our own definitions of the interfaces (`crate::com::comdef`): NULL
//! out-parameters are E_POINTER (the contracts name it), out-parameters are cleared first
//! and filled on success only.

use crate::com::abi;
use crate::com::comdef::{RawConnectionPoint, RawConnectionPoint_Impl};
use crate::com::enums::ConnectionPointEnum;
use std::ffi::c_void;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use windows::core::{implement, IUnknown, Interface, GUID, HRESULT};
use windows::Win32::Foundation::{E_POINTER, S_OK};
use windows::Win32::System::Com::{
    IConnectionPoint, IConnectionPointContainer, IEnumConnectionPoints, IEnumConnections,
};
use windows::Win32::System::Ole::{
    CONNECT_E_ADVISELIMIT, CONNECT_E_CANNOTCONNECT, CONNECT_E_NOCONNECTION,
};

static NEXT_COOKIE: AtomicU32 = AtomicU32::new(1);

/// The one connection a point allows, typed as the outgoing interface `I`.
pub struct SinkSlot<I: Interface> {
    sink: Mutex<Option<(u32, I)>>,
}

// SAFETY: the server process is in the MTA; the interface pointers a slot holds are MTA
// proxies (or free-threaded objects) that may be used from any MTA thread, and the slot
// guards them with a mutex.
unsafe impl<I: Interface> Send for SinkSlot<I> {}
// SAFETY: as above.
unsafe impl<I: Interface> Sync for SinkSlot<I> {}

impl<I: Interface> Default for SinkSlot<I> {
    fn default() -> Self {
        SinkSlot {
            sink: Mutex::new(None),
        }
    }
}

impl<I: Interface + Clone> SinkSlot<I> {
    fn lock(&self) -> std::sync::MutexGuard<'_, Option<(u32, I)>> {
        self.sink.lock().unwrap_or_else(|p| p.into_inner())
    }
    /// The connected sink, if any (a new reference: call it without holding any lock).
    pub fn get(&self) -> Option<I> {
        self.lock().as_ref().map(|(_, s)| s.clone())
    }
    pub fn is_connected(&self) -> bool {
        self.lock().is_some()
    }
    /// The current connection: its cookie and a new reference to its sink (call it
    /// without holding any lock).
    pub fn connection(&self) -> Option<(u32, I)> {
        self.lock().as_ref().map(|(c, s)| (*c, s.clone()))
    }
    /// The cookie of the current connection.
    pub fn cookie(&self) -> Option<u32> {
        self.lock().as_ref().map(|(c, _)| *c)
    }
    /// Drops the sink if it is still the one with `cookie` (after a failed callback).
    pub fn drop_if(&self, cookie: u32) -> bool {
        let taken = {
            let mut g = self.lock();
            if g.as_ref().is_some_and(|(c, _)| *c == cookie) {
                g.take()
            } else {
                None
            }
        };
        // Released after the lock: releasing a proxy is a call to the client.
        taken.is_some()
    }
    fn advise(&self, unk: &IUnknown) -> windows::core::Result<u32> {
        let sink: I = unk
            .cast()
            .map_err(|_| windows::core::Error::from(CONNECT_E_CANNOTCONNECT))?;
        let mut g = self.lock();
        if g.is_some() {
            return Err(CONNECT_E_ADVISELIMIT.into());
        }
        let cookie = NEXT_COOKIE.fetch_add(1, Ordering::Relaxed).max(1);
        *g = Some((cookie, sink));
        Ok(cookie)
    }
    fn unadvise(&self, cookie: u32) -> windows::core::Result<()> {
        if self.drop_if(cookie) {
            Ok(())
        } else {
            Err(CONNECT_E_NOCONNECTION.into())
        }
    }
    fn connections(&self) -> Vec<(u32, IUnknown)> {
        // The QueryInterface is a call on the client's proxy: made after the lock, which
        // the callback workers and the driver thread take (no lock held across a call out).
        let current = self.lock().clone();
        current
            .and_then(|(c, s)| s.cast::<IUnknown>().ok().map(|u| (c, u)))
            .into_iter()
            .collect()
    }
}

/// Advise/Unadvise of one slot, type-erased for the connection point object.
pub trait Slot: Send + Sync {
    fn advise(&self, unk: &IUnknown) -> windows::core::Result<u32>;
    fn unadvise(&self, cookie: u32) -> windows::core::Result<()>;
    /// The current connections (at most one), for EnumConnections.
    fn connections(&self) -> Vec<(u32, IUnknown)>;
}

impl<I: Interface + Clone> Slot for SinkSlot<I> {
    fn advise(&self, unk: &IUnknown) -> windows::core::Result<u32> {
        SinkSlot::advise(self, unk)
    }
    fn unadvise(&self, cookie: u32) -> windows::core::Result<()> {
        SinkSlot::unadvise(self, cookie)
    }
    fn connections(&self) -> Vec<(u32, IUnknown)> {
        SinkSlot::connections(self)
    }
}

#[implement(RawConnectionPoint)]
pub struct ConnectionPoint {
    iid: GUID,
    container: IConnectionPointContainer,
    slot: Arc<dyn Slot>,
}

impl ConnectionPoint {
    pub fn create(
        iid: GUID,
        container: IConnectionPointContainer,
        slot: Arc<dyn Slot>,
    ) -> IConnectionPoint {
        let point: RawConnectionPoint = ConnectionPoint {
            iid,
            container,
            slot,
        }
        .into();
        point.into()
    }
}

impl RawConnectionPoint_Impl for ConnectionPoint_Impl {
    unsafe fn GetConnectionInterface(&self, piid: *mut GUID) -> HRESULT {
        // SAFETY: `piid` is this method's [out] parameter.
        unsafe { abi::out_or_e_pointer(piid, self.iid) }
    }

    unsafe fn GetConnectionPointContainer(
        &self,
        ppcpc: *mut Option<IConnectionPointContainer>,
    ) -> HRESULT {
        // SAFETY: `ppcpc` is this method's [out] interface pointer.
        unsafe { abi::out_or_e_pointer(ppcpc, Some(self.container.clone())) }
    }

    unsafe fn Advise(&self, sink: *mut c_void, pdwcookie: *mut u32) -> HRESULT {
        // SAFETY: `pdwcookie` is this method's [out] parameter.
        unsafe { abi::clear_outs((pdwcookie,)) };
        if pdwcookie.is_null() {
            // Checked before connecting: a failed Advise makes no connection.
            return E_POINTER;
        }
        // SAFETY: `sink` is this method's [in] IUnknown*: NULL or an interface pointer
        // valid for the call.
        let Some(sink) = (unsafe { IUnknown::from_raw_borrowed(&sink) }) else {
            return E_POINTER;
        };
        match self.slot.advise(sink) {
            Ok(cookie) => {
                // SAFETY: checked non-null above.
                unsafe { abi::put(pdwcookie, cookie) };
                S_OK
            }
            Err(e) => e.into(),
        }
    }

    unsafe fn Unadvise(&self, cookie: u32) -> HRESULT {
        self.slot.unadvise(cookie).into()
    }

    unsafe fn EnumConnections(&self, ppenum: *mut Option<IEnumConnections>) -> HRESULT {
        // SAFETY: `ppenum` is this method's [out] interface pointer.
        unsafe { abi::clear_outs((ppenum,)) };
        if ppenum.is_null() {
            return E_POINTER;
        }
        let e = crate::com::enums::ConnectionEnum::create(self.slot.connections());
        // SAFETY: checked non-null above.
        unsafe { abi::put(ppenum, Some(e)) };
        S_OK
    }
}

/// IConnectionPointContainer::FindConnectionPoint for a container with the given (iid,
/// slot) points: `*ppCP` cleared first; E_POINTER for a NULL `riid` or `ppCP`,
/// CONNECT_E_NOCONNECTION for an IID without a point.
///
/// # Safety
/// `riid` is NULL or points to a GUID (the method's `[in] REFIID`); `ppcp` is NULL or
/// writable caller storage for one interface pointer (its `[out]`).
pub unsafe fn find(
    container: IConnectionPointContainer,
    points: &[(GUID, Arc<dyn Slot>)],
    riid: *const GUID,
    ppcp: *mut Option<IConnectionPoint>,
) -> HRESULT {
    // SAFETY: contract of this function.
    unsafe { abi::clear_outs((ppcp,)) };
    if riid.is_null() || ppcp.is_null() {
        return E_POINTER;
    }
    // SAFETY: checked non-null; an [in] REFIID.
    let riid = unsafe { *riid };
    let Some((iid, slot)) = points.iter().find(|(iid, _)| *iid == riid) else {
        return CONNECT_E_NOCONNECTION;
    };
    let point = ConnectionPoint::create(*iid, container, Arc::clone(slot));
    // SAFETY: checked non-null above.
    unsafe { abi::put(ppcp, Some(point)) };
    S_OK
}

/// IConnectionPointContainer::EnumConnectionPoints for a container with the given points:
/// E_POINTER for a NULL `ppEnum`.
///
/// # Safety
/// `ppenum` is NULL or writable caller storage for one interface pointer (the `[out]`).
pub unsafe fn enumerate(
    container: IConnectionPointContainer,
    points: &[(GUID, Arc<dyn Slot>)],
    ppenum: *mut Option<IEnumConnectionPoints>,
) -> HRESULT {
    // SAFETY: contract of this function.
    unsafe { abi::clear_outs((ppenum,)) };
    if ppenum.is_null() {
        return E_POINTER;
    }
    let cps = points
        .iter()
        .map(|(iid, slot)| ConnectionPoint::create(*iid, container.clone(), Arc::clone(slot)))
        .collect();
    // SAFETY: checked non-null above.
    unsafe { abi::put(ppenum, Some(ConnectionPointEnum::create(cps))) };
    S_OK
}
