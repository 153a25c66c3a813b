//! IConnectionPointContainer of the server object: one connection point, IOPCShutdown.
//! The sink slot is registered with the runtime when the object is made;
//! `Runtime::shutdown` (a requested stop: Ctrl+C / Ctrl+Break on the console, a service
//! stop) calls `ShutdownRequest(reason)` on every connected client before the server exits.

use super::OpcServer_Impl;
use crate::connpoint::{self, Slot};
use crate::interfaces::IOPCShutdown;
use std::sync::Arc;
use windows::core::{IUnknownImpl, Interface, GUID};
use windows::Win32::System::Com::{
    IConnectionPoint, IConnectionPointContainer, IConnectionPointContainer_Impl,
    IEnumConnectionPoints,
};

impl OpcServer_Impl {
    fn points(&self) -> [(GUID, Arc<dyn Slot>); 1] {
        [(
            IOPCShutdown::IID,
            Arc::clone(&self.shutdown) as Arc<dyn Slot>,
        )]
    }
}

impl IConnectionPointContainer_Impl for OpcServer_Impl {
    fn EnumConnectionPoints(&self) -> windows::core::Result<IEnumConnectionPoints> {
        let container: IConnectionPointContainer = self.to_interface();
        Ok(connpoint::enumerate(container, &self.points()))
    }

    // windows-rs declares IConnectionPointContainer's methods safe although they take raw
    // pointers: the COM runtime passes them under the interface's contract; `find` checks
    // and reads the REFIID.
    #[allow(clippy::not_unsafe_ptr_arg_deref)]
    fn FindConnectionPoint(&self, riid: *const GUID) -> windows::core::Result<IConnectionPoint> {
        let container: IConnectionPointContainer = self.to_interface();
        // SAFETY: `riid` is this method's [in] REFIID.
        unsafe { connpoint::find(container, &self.points(), riid) }
    }
}
