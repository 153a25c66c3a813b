//! Under Wine only: keeps every interface the process serves registered with the RPC
//! runtime for the process's whole life, so that Wine's combase never unregisters one.
//!
//! Why (docs/limits.md, "The soak stall"): Wine 8.0's combase registers an interface with
//! rpcrt4 when the first stub of that IID in the process is made (`rpc_register_interface`,
//! a count per IID) and, when the last one goes (`stub_manager_delete_ifstub`, e.g. in
//! `RemRelease` of a client's last release), calls `RpcServerUnregisterIf(.., TRUE)`,
//! which waits with no timeout for the calls on that interface, while holding the
//! process-wide `csRegIf` that every marshal of an interface needs. Rarely that wait never
//! ends, and every call of the process that returns an interface queues behind it: the
//! server (or a client, in its `CoUninitialize`) hangs for good.
//!
//! The workaround: one static keep-alive object, never freed, that answers
//! QueryInterface for every IID of [`SERVER_IIDS`] and [`CLIENT_IIDS`], marshalled once per
//! IID of the process's role with `MSHLFLAGS_TABLESTRONG` into a stream that is never
//! released. Its stubs hold one registration of each IID, so the count never reaches 0 and
//! `RpcServerUnregisterIf` is never called. Nobody can unmarshal the streams (they never
//! leave the process), so the object's methods beyond IUnknown are never called; the stub
//! buffers only QueryInterface it. Clients also take `CoIncrementMTAUsage`, so that their
//! last `CoUninitialize` does not tear the MTA (and its stubs) down.
//!
//! On Windows (no `wine_get_version` in ntdll) it does nothing: combase is Microsoft's.

use std::ffi::c_void;
use std::sync::Mutex;
use windows::core::{s, w};
use windows::Win32::Foundation::{E_NOINTERFACE, E_POINTER, S_OK};
use windows::Win32::System::Com::Marshal::CoMarshalInterface;
use windows::Win32::System::Com::StructuredStorage::CreateStreamOnHGlobal;
use windows::Win32::System::Com::{
    CoGetApartmentType, CoIncrementMTAUsage, IAdviseSink, IClassFactory, IConnectionPoint,
    IConnectionPointContainer, IDataObject, IEnumConnectionPoints, IEnumConnections, IEnumGUID,
    IEnumSTATDATA, IEnumString, IEnumUnknown, APTTYPEQUALIFIER, APTTYPE_MTA, MSHCTX_LOCAL,
    MSHLFLAGS_TABLESTRONG,
};
use windows::Win32::System::LibraryLoader::{GetModuleHandleW, GetProcAddress};
use windows_core::{IUnknown, IUnknown_Vtbl, Interface, GUID, HRESULT};

use crate::com::interfaces::{
    IEnumOPCItemAttributes, IOPCAsyncIO, IOPCAsyncIO2, IOPCAsyncIO3, IOPCBrowse,
    IOPCBrowseServerAddressSpace, IOPCCommon, IOPCDataCallback, IOPCEnumGUID, IOPCGroupStateMgt,
    IOPCGroupStateMgt2, IOPCItemDeadbandMgt, IOPCItemIO, IOPCItemMgt, IOPCItemProperties,
    IOPCItemSamplingMgt, IOPCServer, IOPCServerList, IOPCServerList2, IOPCShutdown, IOPCSyncIO,
    IOPCSyncIO2,
};

/// True when this process runs under Wine: its ntdll exports `wine_get_version`.
pub fn under_wine() -> bool {
    // SAFETY: a NUL-terminated literal; ntdll is loaded in every process, and the handle is
    // not reference-counted (nothing to free).
    let Ok(ntdll) = (unsafe { GetModuleHandleW(w!("ntdll.dll")) }) else {
        return false;
    };
    // SAFETY: a module handle of this process and a NUL-terminated literal; the address is
    // only compared with None, never called.
    unsafe { GetProcAddress(ntdll, s!("wine_get_version")) }.is_some()
}

/// Every interface a server process of ours (ServerCTOPC.exe, the server browser) hands
/// out of the process: the server, the group, their connection points and enumerators,
/// the server browser's, and the class object's.
pub const SERVER_IIDS: &[GUID] = &[
    IUnknown::IID,
    IClassFactory::IID,
    IOPCServer::IID,
    IOPCCommon::IID,
    IOPCBrowseServerAddressSpace::IID,
    IOPCItemProperties::IID,
    IOPCBrowse::IID,
    IOPCItemIO::IID,
    IConnectionPointContainer::IID,
    IConnectionPoint::IID,
    IEnumConnectionPoints::IID,
    IEnumConnections::IID,
    IOPCItemMgt::IID,
    IOPCGroupStateMgt::IID,
    IOPCGroupStateMgt2::IID,
    IOPCSyncIO::IID,
    IOPCSyncIO2::IID,
    IOPCAsyncIO::IID,
    IOPCAsyncIO2::IID,
    IOPCAsyncIO3::IID,
    IOPCItemDeadbandMgt::IID,
    IOPCItemSamplingMgt::IID,
    IDataObject::IID,
    IEnumSTATDATA::IID,
    IEnumString::IID,
    IEnumUnknown::IID,
    IEnumOPCItemAttributes::IID,
    IOPCServerList::IID,
    IOPCServerList2::IID,
    IEnumGUID::IID,
    IOPCEnumGUID::IID,
];

/// Every interface a client process of ours (opcdiag, the tests, the benchmark) serves:
/// its sinks (Advise passes a sink as IUnknown; the server then asks for its interface).
pub const CLIENT_IIDS: &[GUID] = &[
    IUnknown::IID,
    IOPCDataCallback::IID,
    IOPCShutdown::IID,
    IAdviseSink::IID,
];

/// Which interfaces a process keeps registered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// [`SERVER_IIDS`] (from `host::serve_as` and the server browser's host).
    Server,
    /// [`CLIENT_IIDS`] and the MTA kept (from `apartment::Apartment::mta`).
    Client,
}

impl Role {
    fn iids(self) -> &'static [GUID] {
        match self {
            Role::Server => SERVER_IIDS,
            Role::Client => CLIENT_IIDS,
        }
    }
}

/// Which roles this process has kept (marshalled) already.
static DONE: Mutex<[bool; 2]> = Mutex::new([false; 2]);

/// Under Wine, once per process and role: marshals the keep-alive object for each IID of
/// `role` (and, for a client, takes an MTA usage that is never given back). Call it on a
/// thread in the MTA, after `CoInitializeSecurity` (a marshal makes that call too late).
/// Returns how many IIDs it registered now (0 outside Wine or when done before); an error
/// names the IIDs that could not be marshalled (the others are kept).
pub fn keep_registered(role: Role) -> Result<usize, String> {
    if !under_wine() {
        return Ok(0);
    }
    let mut done = DONE.lock().unwrap_or_else(|e| e.into_inner());
    let slot = &mut done[role as usize];
    if *slot {
        return Ok(0);
    }
    if !in_mta() {
        return Err("the keep-alive must be marshalled on a thread in the MTA".into());
    }
    *slot = true;
    if role == Role::Client {
        // SAFETY: no arguments; the cookie is never given back (the MTA lives as long as
        // the process).
        if let Err(e) = unsafe { CoIncrementMTAUsage() } {
            tracing::warn!("wine keep-alive: CoIncrementMTAUsage: {e}");
        }
    }
    let failed: Vec<String> = marshal_each(role.iids())
        .into_iter()
        .filter_map(|(iid, r)| r.err().map(|e| format!("{iid:?}: {e}")))
        .collect();
    if failed.is_empty() {
        Ok(role.iids().len())
    } else {
        Err(format!(
            "wine keep-alive: not marshalled: {}",
            failed.join(", ")
        ))
    }
}

/// Whether the calling thread is in the multithreaded apartment.
fn in_mta() -> bool {
    let mut kind = Default::default();
    let mut qualifier = APTTYPEQUALIFIER::default();
    // SAFETY: two valid out-pointers for the call.
    let ok = unsafe { CoGetApartmentType(&mut kind, &mut qualifier) }.is_ok();
    ok && kind == APTTYPE_MTA
}

/// Marshals the keep-alive object once for each of `iids`, table-strong, into a stream
/// that is never released (leaked on purpose: the registration must outlive everything).
fn marshal_each(iids: &[GUID]) -> Vec<(GUID, windows::core::Result<()>)> {
    let object = keepalive();
    iids.iter()
        .map(|iid| {
            let r = (|| {
                // SAFETY: no HGLOBAL given, so the stream allocates (and owns) its own.
                let stream = unsafe { CreateStreamOnHGlobal(Default::default(), true)? };
                // SAFETY: `iid` is a valid reference for the call; the object is static and
                // answers QueryInterface for `iid`; marshalled from the MTA (the caller).
                unsafe {
                    CoMarshalInterface(
                        &stream,
                        iid,
                        object,
                        MSHCTX_LOCAL.0 as u32,
                        None,
                        MSHLFLAGS_TABLESTRONG.0 as u32,
                    )?
                };
                // Never released: releasing it (or CoReleaseMarshalData) would let the
                // stub, and the IID's registration, go.
                std::mem::forget(stream);
                Ok(())
            })();
            (*iid, r)
        })
        .collect()
}

/// The keep-alive object: a COM object with only IUnknown's vtable, never freed.
#[repr(C)]
struct KeepAlive {
    vtable: &'static IUnknown_Vtbl,
}

static VTABLE: IUnknown_Vtbl = IUnknown_Vtbl {
    QueryInterface: query_interface,
    AddRef: add_ref,
    Release: release,
};

static OBJECT: KeepAlive = KeepAlive { vtable: &VTABLE };

/// The keep-alive object as an IUnknown (borrowed: it is static, there is nothing to
/// release).
fn keepalive() -> &'static IUnknown {
    static PTR: PtrToObject = PtrToObject(&OBJECT as *const KeepAlive as *mut c_void);
    // SAFETY: PTR points to a static object whose first field is an IUnknown vtable; it is
    // never freed and never null.
    unsafe { IUnknown::from_raw_borrowed(&PTR.0) }.unwrap_or_else(|| unreachable!())
}

/// The object's address, in a static (a raw pointer is not `Sync` by itself).
struct PtrToObject(*mut c_void);
// SAFETY: the pointer is to an immutable static; the object's methods touch no state.
unsafe impl Sync for PtrToObject {}

/// Whether the keep-alive object answers `iid`.
fn answers(iid: &GUID) -> bool {
    SERVER_IIDS.contains(iid) || CLIENT_IIDS.contains(iid)
}

unsafe extern "system" fn query_interface(
    this: *mut c_void,
    iid: *const GUID,
    out: *mut *mut c_void,
) -> HRESULT {
    if out.is_null() {
        return E_POINTER;
    }
    // SAFETY: `out` is non-null, a caller's out-parameter: cleared first (COM's rule).
    unsafe { out.write(std::ptr::null_mut()) };
    if iid.is_null() {
        return E_POINTER;
    }
    // SAFETY: a non-null IID from the caller; read unaligned (the RPC runtime has passed
    // 2-byte-aligned IIDs, see the root Cargo.toml).
    let iid = unsafe { iid.read_unaligned() };
    if !answers(&iid) {
        return E_NOINTERFACE;
    }
    // SAFETY: as above; `this` is the static object (AddRef would be a no-op).
    unsafe { out.write(this) };
    S_OK
}

/// The object is static: its count is fixed (never 0, so nobody thinks it gone).
unsafe extern "system" fn add_ref(_this: *mut c_void) -> u32 {
    2
}

unsafe extern "system" fn release(_this: *mut c_void) -> u32 {
    1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::com::apartment::Apartment;

    /// The IIDs of both lists are distinct within each list.
    #[test]
    fn the_lists_have_no_repeats() {
        for list in [SERVER_IIDS, CLIENT_IIDS] {
            for (i, a) in list.iter().enumerate() {
                assert!(!list[i + 1..].contains(a), "{a:?} twice");
            }
        }
    }

    /// Under the test runner (Wine) ntdll has `wine_get_version`; the runner sets
    /// WINEPREFIX (xtask/src/wine.rs), which Windows would not.
    #[test]
    fn under_wine_is_detected() {
        assert_eq!(under_wine(), std::env::var_os("WINEPREFIX").is_some());
    }

    /// QueryInterface: the same pointer for IUnknown and every listed IID, E_NOINTERFACE
    /// and NULL for others (IMarshal: the standard marshaler must be used), E_POINTER for
    /// NULL arguments; AddRef/Release never reach 0 however often they are called.
    #[test]
    fn the_object_answers_its_iids_only_and_is_never_freed() {
        let unk = keepalive();
        let this = unk.as_raw();
        for iid in SERVER_IIDS.iter().chain(CLIENT_IIDS) {
            let mut out = std::ptr::null_mut();
            // SAFETY: valid pointers for the call.
            let hr = unsafe { query_interface(this, iid, &mut out) };
            assert_eq!((hr, out), (S_OK, this), "{iid:?}");
        }
        for iid in [
            windows::Win32::System::Com::Marshal::IMarshal::IID,
            GUID::from_u128(7),
        ] {
            let mut out = std::ptr::dangling_mut::<c_void>();
            // SAFETY: valid pointers for the call.
            let hr = unsafe { query_interface(this, &iid, &mut out) };
            assert_eq!((hr, out), (E_NOINTERFACE, std::ptr::null_mut()), "{iid:?}");
        }
        // SAFETY: a NULL out-parameter and a NULL IID are what is tested.
        let hr = unsafe { query_interface(this, &IUnknown::IID, std::ptr::null_mut()) };
        assert_eq!(hr, E_POINTER);
        let mut out = std::ptr::dangling_mut::<c_void>();
        // SAFETY: as above.
        let hr = unsafe { query_interface(this, std::ptr::null(), &mut out) };
        assert_eq!((hr, out), (E_POINTER, std::ptr::null_mut()));
        for _ in 0..1000 {
            // SAFETY: the static object's own methods; they touch nothing.
            let (a, r) = unsafe { (add_ref(this), release(this)) };
            assert!(a > 0 && r > 0);
            // SAFETY: as above.
            unsafe { release(this) };
        }
        // Through windows-rs as a client would: a cast and the drop of its result.
        let common: IOPCCommon = unk.cast().expect("listed IID");
        assert_eq!(common.as_raw(), this);
        drop(common);
        assert!(unk.cast::<windows::Win32::System::Com::IPersist>().is_err());
    }

    /// Every IID of both roles marshals (its proxy/stub is registered in this registry view
    /// and the stub buffer connects to the object), from the MTA; not from an STA.
    #[test]
    fn every_iid_marshals_from_the_mta_and_install_runs_once() {
        let _com = Apartment::mta().expect("MTA");
        for (iid, r) in marshal_each(SERVER_IIDS)
            .into_iter()
            .chain(marshal_each(CLIENT_IIDS))
        {
            assert!(r.is_ok(), "{iid:?}: {r:?}");
        }
        // Apartment::mta kept the client role already; the server role now, once.
        assert_eq!(keep_registered(Role::Client), Ok(0));
        let expected = if under_wine() { SERVER_IIDS.len() } else { 0 };
        assert_eq!(keep_registered(Role::Server), Ok(expected));
        assert_eq!(keep_registered(Role::Server), Ok(0));
        let sta = std::thread::spawn(|| {
            let _com = Apartment::sta().expect("STA");
            in_mta()
        });
        assert!(!sta.join().unwrap());
        assert!(in_mta());
    }
}
