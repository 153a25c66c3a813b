//! The class object registered with CoRegisterClassObject (REGCLS_MULTIPLEUSE): every
//! CreateInstance makes a new server object for that client, through a constructor that
//! captures what it needs (the server's: its `Arc<Context>`, `server::class_factory`);
//! LockServer counts in the [`Lifetime`] it is given.

use crate::com::lifetime::Lifetime;
use std::ffi::c_void;
use std::sync::Arc;
use windows::core::{implement, IUnknown, Interface, Ref, BOOL, GUID};
use windows::Win32::Foundation::{CLASS_E_NOAGGREGATION, E_POINTER};
use windows::Win32::System::Com::{IClassFactory, IClassFactory_Impl};

/// Makes a new object for one client.
pub type Constructor = Box<dyn Fn() -> windows::core::Result<IUnknown> + Send + Sync>;

#[implement(IClassFactory)]
pub struct ClassFactory {
    create: Constructor,
    lifetime: Arc<Lifetime>,
}

impl ClassFactory {
    /// A class object whose CreateInstance calls `create`, and whose LockServer locks
    /// count in `lifetime`.
    #[allow(clippy::new_ret_no_self)] // a class object is only used through IClassFactory
    pub fn new(
        lifetime: Arc<Lifetime>,
        create: impl Fn() -> windows::core::Result<IUnknown> + Send + Sync + 'static,
    ) -> IClassFactory {
        ClassFactory {
            create: Box::new(create),
            lifetime,
        }
        .into()
    }
}

impl IClassFactory_Impl for ClassFactory_Impl {
    // windows-rs declares IClassFactory's methods safe although they take raw pointers: the
    // COM runtime passes them under the interface's contract (checked non-null here).
    #[allow(clippy::not_unsafe_ptr_arg_deref)]
    fn CreateInstance(
        &self,
        outer: Ref<IUnknown>,
        riid: *const GUID,
        ppv: *mut *mut c_void,
    ) -> windows::core::Result<()> {
        if ppv.is_null() {
            return Err(E_POINTER.into());
        }
        // SAFETY: ppv checked non-null; the out-parameter is cleared before anything can fail.
        unsafe { *ppv = std::ptr::null_mut() };
        if riid.is_null() {
            return Err(E_POINTER.into());
        }
        if outer.is_some() {
            return Err(CLASS_E_NOAGGREGATION.into());
        }
        let object = (self.create)()?;
        // SAFETY: riid and ppv are valid pointers (checked above); on failure QueryInterface
        // leaves *ppv null and returns E_NOINTERFACE, and the object is released on drop.
        unsafe { object.query(riid, ppv).ok() }
    }

    fn LockServer(&self, lock: BOOL) -> windows::core::Result<()> {
        self.lifetime.lock_server(lock.as_bool());
        Ok(())
    }
}
