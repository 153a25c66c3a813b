//! `OPC.ServerList.1`, our own server browser (OpcEnum-compatible), served by
//! `OpcServerList.exe` (`src/main.rs`): `IOPCServerList` and `IOPCServerList2` over every
//! OPC server of the machine, read from **both registry views**
//! (`HKCR\CLSID\{..}\Implemented Categories` with `KEY_WOW64_64KEY` and
//! `KEY_WOW64_32KEY`, through `ctopc_com::winreg::RegKey`), merged and filtered by the
//! plain-Rust [`ctopc_registration::catalog`]. The COM plumbing (argument toolkit,
//! enumerator cursor, class factory, lifetime, serving, NT service) is ctopc-com's.
//!
//! Registration ([`register`], [`unregister`]) never replaces a server browser that is
//! not ours (the OPC Foundation's OpcEnum): the keys are `registration::server_list`,
//! filtered per view by whose `LocalServer32` is there.
//!
//! Errors, as OpcEnum answers them: an unknown CLSID in GetClassDetails is
//! `REGDB_E_CLASSNOTREG` (what `ProgIDFromCLSID` answers), an unknown ProgID in
//! CLSIDFromProgID `CO_E_CLASSSTRING` (what `CLSIDFromProgID` answers).
//! The registry is read at each call (no cache: a server installed while the browser runs
//! is listed at once).
#![cfg(windows)]

use ctopc_com::abi::{self, ComResult};
use ctopc_com::apartment::Apartment;
use ctopc_com::comdef::{RawEnumGUID, RawEnumGUID_Impl};
use ctopc_com::enums::{clone_out, next_into, Cursor};
use ctopc_com::factory::ClassFactory;
use ctopc_com::host::{
    exe_path, init_security, keep_interfaces_registered, serve_class, EXIT_LINGER, STARTUP_GRACE,
};
use ctopc_com::interfaces::{
    IOPCEnumGUID, IOPCEnumGUID_Impl, IOPCServerList, IOPCServerList2, IOPCServerList2_Impl,
    IOPCServerList_Impl,
};
use ctopc_com::lifetime::{ExitReason, Lifetime, ObjectGuard, StopSignal};
use ctopc_com::service;
use ctopc_com::winreg::{self, RegKey};
use ctopc_core::limits::TextLimit;
use ctopc_core::OpcError;
use ctopc_registration::catalog::{self, parse_guid, Catalog, ClassEntry};
use ctopc_registration::{self as registration, View, VIEWS};
use std::sync::Arc;
use windows::core::{implement, IUnknown, Interface, GUID, HRESULT, PCWSTR, PWSTR};
use windows::Win32::Foundation::{CO_E_CLASSSTRING, E_FAIL, E_POINTER, REGDB_E_CLASSNOTREG, S_OK};
use windows::Win32::System::Com::IEnumGUID;
use windows::Win32::System::Registry::HKEY_CLASSES_ROOT;

/// `OPC.ServerList.1`'s CLSID.
pub const CLSID_OPC_SERVER_LIST: GUID = GUID::from_u128(registration::CLSID_OPC_SERVER_LIST);

/// ProgIDs are short (COM: at most 39 characters); a longer text is no ProgID.
const PROGID: TextLimit = TextLimit {
    what: "ProgID",
    max_units: 1024,
    error: OpcError::InvalidArg,
};

// ---------------------------------------------------------------------------------------
// Reading the registry, one view at a time

fn categories(class: &RegKey, sub: &str, view: View) -> Vec<u128> {
    class
        .subkey(sub, view)
        .map(|k| k.subkeys().iter().filter_map(|s| parse_guid(s)).collect())
        .unwrap_or_default()
}

fn entry(clsids: &RegKey, name: &str, clsid: u128, view: View) -> Option<ClassEntry> {
    let class = clsids.subkey(name, view)?;
    Some(ClassEntry {
        clsid,
        implemented: categories(&class, "Implemented Categories", view),
        required: categories(&class, "Required Categories", view),
        progid: class.default_value("ProgID"),
        version_independent_progid: class.default_value("VersionIndependentProgID"),
        user_type: class.default_value(""),
    })
}

/// The classes of `view` that implement a component category.
fn read_view(view: View) -> Vec<ClassEntry> {
    let Some(clsids) = RegKey::open(HKEY_CLASSES_ROOT, "CLSID", view) else {
        return Vec::new();
    };
    clsids
        .subkeys()
        .iter()
        .filter_map(|name| {
            let clsid = parse_guid(name)?;
            // Most classes have no categories: look before reading the rest.
            clsids.subkey(&format!("{name}\\Implemented Categories"), view)?;
            entry(&clsids, name, clsid, view)
        })
        .collect()
}

/// Every class with component categories, both views merged (64-bit first).
pub fn machine_catalog() -> Catalog {
    Catalog::merge(VIEWS.iter().map(|&v| (v, read_view(v))).collect())
}

/// One class, registered in either view (with or without categories).
fn class_details(clsid: u128) -> Option<ClassEntry> {
    let name = registration::guid_string(clsid);
    let views = VIEWS
        .iter()
        .filter_map(|&v| {
            let clsids = RegKey::open(HKEY_CLASSES_ROOT, "CLSID", v)?;
            Some((v, vec![entry(&clsids, &name, clsid, v)?]))
        })
        .collect();
    Catalog::merge(views).entries.into_iter().next()
}

/// `HKCR\<progid>\CLSID`, else through `HKCR\<progid>\CurVer`
/// ([`catalog::resolve_progid`]), 64-bit view first.
fn clsid_of_progid(progid: &str) -> Option<u128> {
    VIEWS
        .iter()
        .find_map(|&v| catalog::resolve_progid(progid, |key| winreg::read_default(v, key)))
}

// ---------------------------------------------------------------------------------------
// The COM objects

/// The GUID enumerator EnumClassesOfCategories hands out: `IEnumGUID` (IOPCServerList) and
/// `IOPCEnumGUID` (IOPCServerList2) on one object, over a snapshot of the CLSIDs.
#[implement(RawEnumGUID, IOPCEnumGUID)]
pub struct GuidEnum {
    cursor: Cursor<GUID>,
    _guard: ObjectGuard,
}

impl GuidEnum {
    fn fork(&self) -> GuidEnum {
        GuidEnum {
            cursor: self.cursor.fork(),
            _guard: self._guard.clone(),
        }
    }

    /// As `IEnumGUID` (windows-rs' type of our [`RawEnumGUID`]).
    fn into_enum_guid(self) -> IEnumGUID {
        let e: RawEnumGUID = self.into();
        e.into()
    }
}

impl RawEnumGUID_Impl for GuidEnum_Impl {
    unsafe fn Next(&self, celt: u32, rgelt: *mut GUID, fetched: *mut u32) -> HRESULT {
        // SAFETY: this method's own parameters, under IEnumGUID::Next's contract.
        unsafe { next_into(&self.cursor, celt, rgelt, fetched, |g| *g) }
    }
    unsafe fn Skip(&self, celt: u32) -> HRESULT {
        self.cursor.skip(celt)
    }
    unsafe fn Reset(&self) -> HRESULT {
        self.cursor.reset();
        S_OK
    }
    unsafe fn Clone(&self, ppenum: *mut Option<IEnumGUID>) -> HRESULT {
        // SAFETY: `ppenum` is this method's [out] interface pointer.
        unsafe { clone_out(ppenum, || self.fork().into_enum_guid()) }
    }
}

impl IOPCEnumGUID_Impl for GuidEnum_Impl {
    unsafe fn Next(&self, celt: u32, rgelt: *mut GUID, fetched: *mut u32) -> HRESULT {
        // SAFETY: this method's own parameters, under IOPCEnumGUID::Next's contract.
        unsafe { next_into(&self.cursor, celt, rgelt, fetched, |g| *g) }
    }
    unsafe fn Skip(&self, celt: u32) -> HRESULT {
        self.cursor.skip(celt)
    }
    unsafe fn Reset(&self) -> windows::core::Result<()> {
        self.cursor.reset();
        Ok(())
    }
    unsafe fn Clone(&self, ppenum: *mut Option<IOPCEnumGUID>) -> windows::core::Result<()> {
        // SAFETY: `ppenum` is this method's [out] interface pointer.
        let hr = unsafe { clone_out(ppenum, || self.fork().into()) };
        if hr == E_POINTER {
            return Err(E_POINTER.into());
        }
        hr.ok()
    }
}

/// The server browser object, one per client.
#[implement(IOPCServerList, IOPCServerList2)]
pub struct ServerList {
    guard: ObjectGuard,
}

/// A category list of EnumClassesOfCategories: `(ULONG)-1` is "not checked" (as
/// ICatInformation has it).
///
/// # Safety
/// As [`abi::in_slice`].
unsafe fn category_list(count: u32, p: *const GUID) -> ComResult<Option<Vec<u128>>> {
    if count == u32::MAX {
        return Ok(None);
    }
    // SAFETY: contract of this function.
    let ids = unsafe { abi::in_slice(p, count) }?;
    Ok(Some(ids.iter().map(GUID::to_u128).collect()))
}

impl ServerList {
    /// The CLSIDs EnumClassesOfCategories lists, as an enumerator (both interfaces).
    ///
    /// # Safety
    /// The method's `[in, size_is]` category arrays.
    unsafe fn enumerate(
        &self,
        c_impl: u32,
        impl_ids: *const GUID,
        c_req: u32,
        req_ids: *const GUID,
    ) -> ComResult<GuidEnum> {
        // SAFETY: contract of this function.
        let implemented = unsafe { category_list(c_impl, impl_ids) }?;
        // SAFETY: contract of this function.
        let required = unsafe { category_list(c_req, req_ids) }?;
        let ids = machine_catalog()
            .classes_of_categories(implemented.as_deref(), required.as_deref())
            .into_iter()
            .map(GUID::from_u128)
            .collect();
        Ok(GuidEnum {
            cursor: Cursor::new(ids),
            _guard: self.guard.clone(),
        })
    }

    /// ProgID, user type and version-independent ProgID of a registered class.
    ///
    /// # Safety
    /// `clsid` is NULL or points to a GUID.
    unsafe fn details(clsid: *const GUID) -> ComResult<(String, String, String)> {
        abi::nonnull(clsid)?;
        // SAFETY: checked non-null; contract of this function.
        let id = unsafe { *clsid }.to_u128();
        let e = class_details(id)
            .filter(|e| e.progid.is_some())
            .ok_or_else(|| ctopc_com::error::error(REGDB_E_CLASSNOTREG, "class not registered"))?;
        let progid = e.progid.unwrap_or_default();
        Ok((
            progid,
            e.user_type.unwrap_or_default(),
            e.version_independent_progid.unwrap_or_default(),
        ))
    }

    /// # Safety
    /// `sz` is NULL or a NUL-terminated string; `out` NULL or writable for one GUID.
    unsafe fn clsid_from_progid(sz: PCWSTR, out: *mut GUID) -> ComResult<()> {
        // SAFETY: the caller's out-parameter (contract of this function).
        unsafe { abi::clear_outs((out,)) };
        abi::nonnull(out)?;
        // SAFETY: contract of this function.
        let progid = unsafe { abi::in_string(sz, PROGID) }?;
        let id = clsid_of_progid(&progid)
            .ok_or_else(|| ctopc_com::error::error(CO_E_CLASSSTRING, "unknown ProgID"))?;
        // SAFETY: checked non-null above.
        unsafe { abi::write_out(out, GUID::from_u128(id)) }
    }
}

impl IOPCServerList_Impl for ServerList_Impl {
    unsafe fn EnumClassesOfCategories(
        &self,
        c_impl: u32,
        impl_ids: *const GUID,
        c_req: u32,
        req_ids: *const GUID,
        ppenum: *mut Option<IEnumGUID>,
    ) -> windows::core::Result<()> {
        // SAFETY: the method's [out] parameter.
        unsafe { abi::clear_outs((ppenum,)) };
        abi::nonnull(ppenum)?;
        // SAFETY: the method's own [in] arrays.
        let e = unsafe { self.enumerate(c_impl, impl_ids, c_req, req_ids) }?;
        // SAFETY: checked non-null above.
        unsafe { abi::write_out(ppenum, Some(e.into_enum_guid())) }
    }

    unsafe fn GetClassDetails(
        &self,
        clsid: *const GUID,
        pp_progid: *mut PWSTR,
        pp_user_type: *mut PWSTR,
    ) -> windows::core::Result<()> {
        // SAFETY: the method's [out] parameters.
        unsafe { abi::clear_outs((pp_progid, pp_user_type)) };
        abi::nonnull(pp_progid)?;
        abi::nonnull(pp_user_type)?;
        // SAFETY: the method's [in] REFCLSID.
        let (progid, user_type, _) = unsafe { ServerList::details(clsid) }?;
        let progid = abi::OwnedWstr::new(&progid)?;
        let user_type = abi::OwnedWstr::new(&user_type)?;
        // SAFETY: both checked non-null above; every allocation has succeeded.
        unsafe {
            abi::put(pp_progid, progid.into_raw());
            abi::put(pp_user_type, user_type.into_raw());
        }
        Ok(())
    }

    unsafe fn CLSIDFromProgID(&self, sz: PCWSTR, clsid: *mut GUID) -> windows::core::Result<()> {
        // SAFETY: the method's own parameters.
        unsafe { ServerList::clsid_from_progid(sz, clsid) }
    }
}

impl IOPCServerList2_Impl for ServerList_Impl {
    unsafe fn EnumClassesOfCategories(
        &self,
        c_impl: u32,
        impl_ids: *const GUID,
        c_req: u32,
        req_ids: *const GUID,
        ppenum: *mut Option<IOPCEnumGUID>,
    ) -> windows::core::Result<()> {
        // SAFETY: the method's [out] parameter.
        unsafe { abi::clear_outs((ppenum,)) };
        abi::nonnull(ppenum)?;
        // SAFETY: the method's own [in] arrays.
        let e = unsafe { self.enumerate(c_impl, impl_ids, c_req, req_ids) }?;
        // SAFETY: checked non-null above.
        unsafe { abi::write_out(ppenum, Some(e.into())) }
    }

    unsafe fn GetClassDetails(
        &self,
        clsid: *const GUID,
        pp_progid: *mut PWSTR,
        pp_user_type: *mut PWSTR,
        pp_ver_ind: *mut PWSTR,
    ) -> windows::core::Result<()> {
        // SAFETY: the method's [out] parameters.
        unsafe { abi::clear_outs((pp_progid, pp_user_type, pp_ver_ind)) };
        abi::nonnull(pp_progid)?;
        abi::nonnull(pp_user_type)?;
        abi::nonnull(pp_ver_ind)?;
        // SAFETY: the method's [in] REFCLSID.
        let (progid, user_type, ver_ind) = unsafe { ServerList::details(clsid) }?;
        let progid = abi::OwnedWstr::new(&progid)?;
        let user_type = abi::OwnedWstr::new(&user_type)?;
        let ver_ind = abi::OwnedWstr::new(&ver_ind)?;
        // SAFETY: all three checked non-null above; every allocation has succeeded.
        unsafe {
            abi::put(pp_progid, progid.into_raw());
            abi::put(pp_user_type, user_type.into_raw());
            abi::put(pp_ver_ind, ver_ind.into_raw());
        }
        Ok(())
    }

    unsafe fn CLSIDFromProgID(&self, sz: PCWSTR, clsid: *mut GUID) -> windows::core::Result<()> {
        // SAFETY: the method's own parameters.
        unsafe { ServerList::clsid_from_progid(sz, clsid) }
    }
}

/// A new browser object counting in `lifetime` (the class factory's constructor; the
/// in-process tests call it directly).
pub fn create_instance(lifetime: &Arc<Lifetime>) -> ComResult<IUnknown> {
    let object: IOPCServerList = ServerList {
        guard: ObjectGuard::new(lifetime),
    }
    .into();
    object.cast()
}

// ---------------------------------------------------------------------------------------
// The exe's switches

fn our_registration<R>(
    service: Option<&str>,
    f: impl FnOnce(&registration::ServerRegistration) -> R,
) -> ComResult<R> {
    let exe = exe_path()?;
    Ok(f(&registration::server_list_as(&exe, service)))
}

/// `LocalServer32` of `{13486D51-...}` in each view.
fn local_servers() -> Vec<(View, Option<String>)> {
    let key = registration::server_list_local_server_key();
    VIEWS
        .iter()
        .map(|&v| (v, winreg::read_default(v, &key)))
        .collect()
}

fn view_name(v: View) -> &'static str {
    match v {
        View::Reg64 => "64-bit registry view",
        View::Reg32 => "32-bit registry view",
    }
}

/// `/RegServer`: registers `OPC.ServerList.1` in each view that has no server browser or
/// ours; a view with another one (the OPC Foundation's OpcEnum) is left alone, with a
/// message. Succeeds in both cases.
pub fn register() -> ComResult<()> {
    let _com = Apartment::mta_without_keepalive()?;
    register_as(None)
}

/// `/Service`: as `/RegServer` with the AppID naming the NT service `OpcServerList`
/// (on demand, as LocalService), which it installs: COM then starts the browser as that
/// service, which remote clients need (as the OPC Foundation's OpcEnum, a service too).
/// Where another browser serves both views nothing is installed.
pub fn register_service() -> ComResult<()> {
    let _com = Apartment::mta_without_keepalive()?;
    let foreign = registration::foreign_server_list_views(&local_servers());
    if foreign.len() == VIEWS.len() {
        println!("OpcServerList: no service installed (another server browser serves both views)");
        return Ok(());
    }
    let exe = exe_path()?;
    service::install_as(&service::SERVER_LIST, std::path::Path::new(&exe))
        .map_err(|e| ctopc_com::error::error(E_FAIL, &e))?;
    register_as(Some(service::SERVER_LIST.name))?;
    println!(
        "OpcServerList: runs as the NT service {}",
        service::SERVER_LIST.name
    );
    Ok(())
}

fn register_as(service: Option<&str>) -> ComResult<()> {
    let local = local_servers();
    let foreign = registration::foreign_server_list_views(&local);
    for (v, ls) in &local {
        if foreign.contains(v) {
            println!(
                "OpcServerList: {} already has a server browser that is not ours ({}); \
                 left as it is",
                view_name(*v),
                ls.as_deref().unwrap_or_default()
            );
        }
    }
    let keys = our_registration(service, |r| registration::server_list_keys(r, &foreign))?;
    winreg::write_keys(&keys)?;
    if foreign.len() == VIEWS.len() {
        println!("OpcServerList: not registered (another server browser serves both views)");
    } else {
        println!(
            "OpcServerList: registered {} ({})",
            registration::SERVER_LIST_PROGID_VERSIONED,
            winreg::guid_string(&CLSID_OPC_SERVER_LIST)
        );
    }
    Ok(())
}

/// `/UnregServer`: removes our browser only (a view whose `{13486D51-...}` is another
/// one's keeps it), and its NT service if `/Service` installed it.
pub fn unregister() -> ComResult<()> {
    let _com = Apartment::mta_without_keepalive()?;
    let local = local_servers();
    let foreign = registration::foreign_server_list_views(&local);
    let ours: Vec<View> = local
        .iter()
        .filter(|(_, ls)| ls.as_deref().is_some_and(registration::is_our_server_list))
        .map(|(v, _)| *v)
        .collect();
    let trees = our_registration(None, |r| {
        registration::server_list_trees(r, &ours, &foreign)
    })?;
    winreg::delete_trees(&trees)?;
    service::uninstall_as(&service::SERVER_LIST)
        .map_err(|e| ctopc_com::error::error(E_FAIL, &e))?;
    println!("OpcServerList: unregistered ours");
    Ok(())
}

/// `-Embedding`: serves `OPC.ServerList.1` until the last client has gone.
pub fn serve() -> ComResult<()> {
    serve_until(None)
}

/// `-ServiceRun` (the service control manager starts the exe so): serves
/// `OPC.ServerList.1` until the service is stopped.
pub fn serve_service() -> ComResult<()> {
    service::run_as(
        &service::SERVER_LIST,
        Box::new(|stop| serve_until(Some(stop)).map_err(|e| e.message())),
    )
    .map_err(|e| ctopc_com::error::error(E_FAIL, &e))
}

/// Serves until the last client has gone (`None`) or `stop` is triggered.
fn serve_until(stop: Option<StopSignal>) -> ComResult<()> {
    let _com = Apartment::mta_without_keepalive()?;
    init_security();
    keep_interfaces_registered();
    let lifetime = Lifetime::new();
    let for_factory = Arc::clone(&lifetime);
    let factory = ClassFactory::new(Arc::clone(&lifetime), move || create_instance(&for_factory));
    if let Some(stop) = &stop {
        lifetime.stop_on(stop);
    }
    serve_class(
        &CLSID_OPC_SERVER_LIST,
        &factory,
        &lifetime,
        || match &stop {
            Some(_) => {
                lifetime.wait_for_stop();
                ExitReason::StopRequested
            }
            None => lifetime.wait_until_unused(STARTUP_GRACE, EXIT_LINGER),
        },
    )?;
    Ok(())
}
