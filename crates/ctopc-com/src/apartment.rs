//! The one guard of a thread's COM apartment, for the servers, the client library and the
//! tests: COM is initialised (`CoInitializeEx`) when the guard is made and uninitialised
//! (`CoUninitialize`) when it is dropped, on the same thread.
//!
//! Under Wine, [`Apartment::mta`] also enters the process's keep-alive
//! (`wine_keepalive`, role `Client`); [`Apartment::mta_without_keepalive`] does not, for a
//! server's main thread, which enters it itself after setting the process's COM security.

use std::marker::PhantomData;
use windows::Win32::System::Com::{
    CoInitializeEx, CoUninitialize, COINIT_APARTMENTTHREADED, COINIT_MULTITHREADED,
};

/// COM initialised on this thread for the lifetime of the value (not `Send`: it is
/// uninitialised on the thread that initialised it).
pub struct Apartment(PhantomData<*const ()>);

impl Apartment {
    /// Joins the multithreaded apartment. Under Wine, the first time in the process, keeps
    /// the sinks' interfaces registered and the MTA up for the process's life
    /// (`wine_keepalive`, role `Client`: Wine's combase can hang when it unregisters one).
    /// For clients, and for the server's runtime threads, which call clients.
    pub fn mta() -> windows::core::Result<Apartment> {
        let apartment = Self::mta_without_keepalive()?;
        if let Err(e) = crate::wine_keepalive::keep_registered(crate::wine_keepalive::Role::Client)
        {
            tracing::warn!("{e}");
        }
        Ok(apartment)
    }

    /// Joins the multithreaded apartment, nothing more: for a server's main thread, which
    /// sets the process's COM security next (`host::init_security` must come before any
    /// marshal, and the keep-alive marshals: the server enters it afterwards,
    /// `host::keep_registered_under_wine`), and for registering and unregistering.
    pub fn mta_without_keepalive() -> windows::core::Result<Apartment> {
        // SAFETY: paired with CoUninitialize in Drop, on this thread (the guard is not Send).
        unsafe { CoInitializeEx(None, COINIT_MULTITHREADED).ok()? };
        Ok(Apartment(PhantomData))
    }

    /// Makes this thread a single-threaded apartment (it must pump messages to get
    /// callbacks).
    pub fn sta() -> windows::core::Result<Apartment> {
        // SAFETY: as in `mta_without_keepalive`.
        unsafe { CoInitializeEx(None, COINIT_APARTMENTTHREADED).ok()? };
        Ok(Apartment(PhantomData))
    }
}

impl Drop for Apartment {
    fn drop(&mut self) {
        // SAFETY: this thread initialised COM when the guard was made.
        unsafe { CoUninitialize() };
    }
}
