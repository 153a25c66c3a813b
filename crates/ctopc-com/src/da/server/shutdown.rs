//! IConnectionPointContainer of the server object: one connection point, IOPCShutdown.
//! The sink slot is registered with the runtime when the object is made;
//! `Runtime::shutdown` (a requested stop: Ctrl+C / Ctrl+Break on the console, a service
//! stop) calls `ShutdownRequest(reason)` on every connected client before the server exits.

use super::OpcServer_Impl;
use crate::com::comdef::{RawConnectionPointContainer, RawConnectionPointContainer_Impl};
use crate::com::connpoint::{self, Slot};
use crate::com::interfaces::IOPCShutdown;
use std::sync::Arc;
use windows::core::{IUnknownImpl, Interface, GUID, HRESULT};
use windows::Win32::System::Com::{IConnectionPoint, IEnumConnectionPoints};

impl OpcServer_Impl {
    fn points(&self) -> [(GUID, Arc<dyn Slot>); 1] {
        [(
            IOPCShutdown::IID,
            Arc::clone(&self.shutdown) as Arc<dyn Slot>,
        )]
    }
}

impl RawConnectionPointContainer_Impl for OpcServer_Impl {
    unsafe fn EnumConnectionPoints(&self, ppenum: *mut Option<IEnumConnectionPoints>) -> HRESULT {
        let container = self.to_interface::<RawConnectionPointContainer>().into();
        // SAFETY: `ppenum` is this method's [out] interface pointer.
        unsafe { connpoint::enumerate(container, &self.points(), ppenum) }
    }

    unsafe fn FindConnectionPoint(
        &self,
        riid: *const GUID,
        ppcp: *mut Option<IConnectionPoint>,
    ) -> HRESULT {
        let container = self.to_interface::<RawConnectionPointContainer>().into();
        // SAFETY: `riid` is this method's [in] REFIID, `ppcp` its [out] interface pointer.
        unsafe { connpoint::find(container, &self.points(), riid, ppcp) }
    }
}
