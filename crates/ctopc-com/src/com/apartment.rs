//! The one guard of a thread's COM apartment, for the servers, the client library and the
//! tests: COM is initialised (`CoInitializeEx`) when the guard is made and uninitialised
//! (`CoUninitialize`) when it is dropped, on the same thread.
//!
//! Under Wine, [`Apartment::mta`] also enters the process's keep-alive
//! (`platform::wine`, role `Client`); [`Apartment::mta_without_keepalive`] does not, for a
//! server's main thread, which enters it itself after setting the process's COM security.

use crate::com::platform::wine;
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
    /// (`platform::wine`, role `Client`: Wine's combase can hang when it unregisters one).
    /// For clients, and for the server's runtime threads, which call clients.
    pub fn mta() -> windows::core::Result<Apartment> {
        let apartment = Self::mta_without_keepalive()?;
        if let Err(e) = wine::keep_registered(wine::Role::Client) {
            tracing::warn!("{e}");
        }
        Ok(apartment)
    }

    /// The process serves COM objects: under Wine, keeps every interface a server hands
    /// out registered with RPC for the process's life (`platform::wine`, role `Server`).
    /// On a thread in the MTA, after the process's COM security is set (the keep-alive
    /// marshals). Returns how many interfaces it keeps (0 elsewhere than under Wine).
    pub fn keep_server_interfaces() -> Result<usize, String> {
        wine::keep_registered(wine::Role::Server)
    }

    /// Joins the multithreaded apartment, nothing more: for a server's main thread, which
    /// sets the process's COM security next (`host::init_security` must come before any
    /// marshal, and the keep-alive marshals: the server enters it afterwards,
    /// `host::keep_interfaces_registered`), and for registering and unregistering.
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
