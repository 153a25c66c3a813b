//! Connection points to the letter: the sink is QueryInterfaced for the expected
//! interface, one connection per point (CONNECT_E_ADVISELIMIT beyond), non-zero cookies,
//! unknown cookies rejected. The container holds only the sink slots, never the
//! IConnectionPoint objects, so there is no reference cycle: each FindConnectionPoint
//! makes a small connection point that holds the container.

use crate::enums::ConnectionPointEnum;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use windows::core::{implement, IUnknown, Interface, Ref, GUID};
use windows::Win32::Foundation::E_POINTER;
use windows::Win32::System::Com::{
    IConnectionPoint, IConnectionPointContainer, IConnectionPoint_Impl, IEnumConnections,
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
        self.lock()
            .as_ref()
            .and_then(|(c, s)| s.cast::<IUnknown>().ok().map(|u| (*c, u)))
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

#[implement(IConnectionPoint)]
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
        ConnectionPoint {
            iid,
            container,
            slot,
        }
        .into()
    }
}

impl IConnectionPoint_Impl for ConnectionPoint_Impl {
    fn GetConnectionInterface(&self) -> windows::core::Result<GUID> {
        Ok(self.iid)
    }
    fn GetConnectionPointContainer(&self) -> windows::core::Result<IConnectionPointContainer> {
        Ok(self.container.clone())
    }
    fn Advise(&self, sink: Ref<IUnknown>) -> windows::core::Result<u32> {
        let sink = sink
            .ok()
            .map_err(|_| windows::core::Error::from(E_POINTER))?;
        self.slot.advise(sink)
    }
    fn Unadvise(&self, cookie: u32) -> windows::core::Result<()> {
        self.slot.unadvise(cookie)
    }
    fn EnumConnections(&self) -> windows::core::Result<IEnumConnections> {
        Ok(crate::enums::ConnectionEnum::create(
            self.slot.connections(),
        ))
    }
}

/// FindConnectionPoint for a container with the given (iid, slot) points.
///
/// # Safety
/// `riid` is NULL or points to a GUID (the method's `[in] REFIID`).
pub unsafe fn find(
    container: IConnectionPointContainer,
    points: &[(GUID, Arc<dyn Slot>)],
    riid: *const GUID,
) -> windows::core::Result<IConnectionPoint> {
    if riid.is_null() {
        return Err(E_POINTER.into());
    }
    // SAFETY: checked non-null; an [in] REFIID.
    let riid = unsafe { *riid };
    points
        .iter()
        .find(|(iid, _)| *iid == riid)
        .map(|(iid, slot)| ConnectionPoint::create(*iid, container.clone(), Arc::clone(slot)))
        .ok_or_else(|| CONNECT_E_NOCONNECTION.into())
}

/// EnumConnectionPoints for a container with the given points.
pub fn enumerate(
    container: IConnectionPointContainer,
    points: &[(GUID, Arc<dyn Slot>)],
) -> windows::Win32::System::Com::IEnumConnectionPoints {
    let cps = points
        .iter()
        .map(|(iid, slot)| ConnectionPoint::create(*iid, container.clone(), Arc::clone(slot)))
        .collect();
    ConnectionPointEnum::create(cps)
}
