//! The marshal probe: a test COM server whose objects return a
//! distinct, non-ASCII text in every string out-parameter of every OPC interface, so that
//! an out-of-process client can check that each one crosses the project's proxy/stub DLL
//! (`opc_ps.dll`, built from `idl/` by `cargo xtask proxy`) non-NULL and intact.
//! See `tests/tests/marshal_strings.rs`, which drives `marshal-probe.exe` (crate e2e-tests).
//!
//! * The server object ([`create_instance`]) implements IOPCCommon, IOPCServer,
//!   IOPCServerList, IOPCServerList2, IOPCBrowseServerAddressSpace, IOPCItemProperties and
//!   IOPCBrowse. `IOPCServer::AddGroup` returns a probe group (IOPCGroupStateMgt2 with its
//!   base IOPCGroupStateMgt, and IOPCItemMgt, whose `CreateEnumerator` returns an
//!   IEnumOPCItemAttributes). Enumerations of names are IEnumString objects.
//! * The text of a parameter is [`text`]`(name)`, the name written as in the table of the
//!   test (`Interface::Method(param)`, `.field` for structure members, `[i]` for array
//!   elements): `format!("{name}{SUFFIX}")`, with Polish diacritics and U+1F3ED (a UTF-16
//!   surrogate pair).
//! * Methods without string outputs return `E_NOTIMPL`. Out-parameters are all-or-nothing
//!   and CoTaskMem-allocated, as in the real server.
//!
//! [`client`] and the client library `opc_client` hold safe readers of the same
//! outputs for the test (every raw call and every CoTaskMem free of the test is there, so
//! that the test itself has no `unsafe`).

// A COM server like the product's: a panic would cross COM (clippy.toml allows unwrap in
// its tests).
#![deny(clippy::unwrap_used, clippy::expect_used)]

use ctopc_com::abi::{self, nonnull, put, OwnedArray, OwnedWstr, TaskMem};
use ctopc_com::apartment::Apartment;
use ctopc_com::factory::ClassFactory;
use ctopc_com::interfaces::*;
use ctopc_com::lifetime::{Lifetime, ObjectGuard};
use ctopc_com::winreg::{self, ServerRegistration};
use ctopc_com::{clock, error};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;
use windows::core::{implement, IUnknown, Interface, BOOL, GUID, HRESULT, PCWSTR, PWSTR};
use windows::Win32::Foundation::{E_INVALIDARG, E_NOTIMPL, E_POINTER, S_FALSE, S_OK};
use windows::Win32::System::Com::{CoRevokeClassObject, IEnumString, IEnumString_Impl};
use windows::Win32::System::Variant::{VARIANT, VT_BSTR, VT_I4, VT_R8};

/// CLSID of `ServerCTOPC.MarshalProbe` (also its AppID).
pub const CLSID_MARSHAL_PROBE: GUID = GUID::from_u128(0x4a55eb1b_c24e_4023_85fe_9c8ff38a0a3c);
pub const PROGID: &str = "ServerCTOPC.MarshalProbe";
pub const PROGID_VERSIONED: &str = "ServerCTOPC.MarshalProbe.1";
pub const DESCRIPTION: &str = "ServerCTOPC marshal probe (test server for string out-parameters)";
pub const EXE_NAME: &str = "marshal-probe.exe";
/// How long a probe started by COM waits for its first client.
pub const STARTUP_GRACE: Duration = Duration::from_secs(30);
/// How long the probe outlives its last client (see [`serve`]).
pub const LINGER: Duration = Duration::from_secs(5);

/// Appended to every parameter name: Polish diacritics (2-byte UTF-8, 1 UTF-16 unit) and
/// U+1F3ED FACTORY (4-byte UTF-8, a UTF-16 surrogate pair).
pub const SUFFIX: &str = " – Wytwórnia Kwasu żółć 🏭";

/// The text the probe returns in the string named `param`.
pub fn text(param: &str) -> String {
    format!("{param}{SUFFIX}")
}

/// The text of element `i` of the string array (or array of structures) named `param`.
pub fn text_at(param: &str, i: usize) -> String {
    text(&format!("{param}[{i}]"))
}

/// The text of member `j` of element `i` (properties of an item / of a browse element).
pub fn text_at2(param: &str, i: usize, j: usize) -> String {
    text(&format!("{param}[{i}][{j}]"))
}

/// The names of the probe's string outputs (the keys of [`text`]).
pub mod param {
    pub const COMMON_GET_ERROR_STRING: &str = "IOPCCommon::GetErrorString(ppString)";
    pub const SERVER_GET_ERROR_STRING: &str = "IOPCServer::GetErrorString(ppString)";
    pub const SERVER_STATUS_VENDOR_INFO: &str =
        "IOPCServer::GetStatus(ppServerStatus).szVendorInfo";
    pub const SERVER_GROUP_NAMES: &str =
        "IOPCServer::CreateGroupEnumerator(ppUnk)->IEnumString::Next(rgelt)";
    pub const LIST_PROGID: &str = "IOPCServerList::GetClassDetails(ppszProgID)";
    pub const LIST_USER_TYPE: &str = "IOPCServerList::GetClassDetails(ppszUserType)";
    pub const LIST2_PROGID: &str = "IOPCServerList2::GetClassDetails(ppszProgID)";
    pub const LIST2_USER_TYPE: &str = "IOPCServerList2::GetClassDetails(ppszUserType)";
    pub const LIST2_VER_IND_PROGID: &str = "IOPCServerList2::GetClassDetails(ppszVerIndProgID)";
    pub const BSAS_ITEM_ID: &str = "IOPCBrowseServerAddressSpace::GetItemID(szItemID)";
    pub const BSAS_ITEM_IDS: &str =
        "IOPCBrowseServerAddressSpace::BrowseOPCItemIDs(ppIEnumString)->IEnumString::Next(rgelt)";
    pub const BSAS_ACCESS_PATHS: &str =
        "IOPCBrowseServerAddressSpace::BrowseAccessPaths(ppIEnumString)->IEnumString::Next(rgelt)";
    pub const PROPS_DESCRIPTIONS: &str =
        "IOPCItemProperties::QueryAvailableProperties(ppDescriptions)";
    pub const PROPS_NEW_ITEM_IDS: &str = "IOPCItemProperties::LookupItemIDs(ppszNewItemIDs)";
    pub const BROWSE_CONTINUATION_POINT: &str = "IOPCBrowse::Browse(pszContinuationPoint)";
    pub const BROWSE_NAME: &str = "IOPCBrowse::Browse(ppBrowseElements).szName";
    pub const BROWSE_ITEM_ID: &str = "IOPCBrowse::Browse(ppBrowseElements).szItemID";
    pub const BROWSE_PROPERTY_ITEM_ID: &str =
        "IOPCBrowse::Browse(ppBrowseElements).ItemProperties.pItemProperties.szItemID";
    pub const BROWSE_PROPERTY_DESCRIPTION: &str =
        "IOPCBrowse::Browse(ppBrowseElements).ItemProperties.pItemProperties.szDescription";
    pub const GET_PROPERTIES_ITEM_ID: &str =
        "IOPCBrowse::GetProperties(ppItemProperties).pItemProperties.szItemID";
    pub const GET_PROPERTIES_DESCRIPTION: &str =
        "IOPCBrowse::GetProperties(ppItemProperties).pItemProperties.szDescription";
    pub const GROUP_NAME: &str = "IOPCGroupStateMgt::GetState(ppName)";
    pub const ITEM_ACCESS_PATH: &str = "IEnumOPCItemAttributes::Next(ppItemArray).szAccessPath";
    pub const ITEM_ITEM_ID: &str = "IEnumOPCItemAttributes::Next(ppItemArray).szItemID";
}

/// How many names each IEnumString of the probe yields.
pub const ENUM_STRING_LEN: usize = 3;
/// `QueryAvailableProperties` reports these property IDs (with [`PROPERTY_TYPES`]).
pub const AVAILABLE_PROPERTIES: [u32; 3] = [
    OPC_PROPERTY_DATATYPE,
    OPC_PROPERTY_VALUE,
    OPC_PROPERTY_EU_UNITS,
];
const PROPERTY_TYPES: [windows::Win32::System::Variant::VARENUM; 3] = [
    windows::Win32::System::Variant::VT_I2,
    windows::Win32::System::Variant::VT_VARIANT,
    VT_BSTR,
];
/// `LookupItemIDs` fails with `OPC_E_INVALID_PID` for property IDs below this (the OPC
/// "fixed" properties 1..=99 have no item ID) and returns a text for the others.
pub const FIRST_PROPERTY_WITH_ITEM_ID: u32 = 100;
/// The properties `IOPCBrowse` returns when the client asks for all of them.
pub const ALL_PROPERTIES: [u32; 2] = [OPC_PROPERTY_VALUE, OPC_PROPERTY_DESCRIPTION];
/// `IOPCBrowse::Browse` returns the elements `0..BROWSE_ELEMENTS` in pages of
/// [`BROWSE_PAGE`], the first page for a NULL/empty continuation point, the next one for
/// the continuation point returned with the previous page.
pub const BROWSE_ELEMENTS: usize = 3;
pub const BROWSE_PAGE: usize = 2;
/// `IEnumOPCItemAttributes` enumerates this many items.
pub const ITEM_COUNT: usize = 2;

/// The continuation point returned with the page that starts at element `next` (the text
/// of `pszContinuationPoint` for the first page, numbered after that).
pub fn continuation_point(next: usize) -> String {
    if next == BROWSE_PAGE {
        text(param::BROWSE_CONTINUATION_POINT)
    } else {
        text(&format!("{}#{next}", param::BROWSE_CONTINUATION_POINT))
    }
}

fn page_start(cp: Option<&str>) -> Option<usize> {
    match cp {
        None | Some("") => Some(0),
        Some(cp) => (BROWSE_PAGE..BROWSE_ELEMENTS)
            .step_by(BROWSE_PAGE)
            .find(|&n| continuation_point(n) == cp),
    }
}

/// Hands `object` out through an `[out, iid_is(riid)] IUnknown**` as a raw HRESULT.
///
/// # Safety
/// As [`abi::query_out`].
unsafe fn query_out(object: &IUnknown, riid: *const GUID, out: *mut Option<IUnknown>) -> HRESULT {
    // SAFETY: contract of this function.
    abi::hresult(unsafe { abi::query_out(object, riid, out) }.map(|()| S_OK))
}

fn properties(
    param_item: &str,
    param_desc: &str,
    i: usize,
    ids: &[u32],
) -> windows::core::Result<OPCITEMPROPERTIES> {
    let mut props = OwnedArray::<OPCITEMPROPERTY>::zeroed(ids.len())?;
    for (j, (slot, &id)) in props.as_mut_slice().iter_mut().zip(ids).enumerate() {
        slot.vtDataType = VT_I4;
        slot.dwPropertyID = id;
        slot.szItemID = OwnedWstr::new(&text_at2(param_item, i, j))?.into_raw();
        slot.szDescription = OwnedWstr::new(&text_at2(param_desc, i, j))?.into_raw();
        slot.hrErrorID = S_OK;
    }
    Ok(OPCITEMPROPERTIES {
        hrErrorID: S_OK,
        dwNumProperties: ids.len() as u32,
        pItemProperties: props.into_raw(),
        dwReserved: 0,
    })
}

/// The property IDs a client asked for (`dwPropertyCount` of `pdwPropertyIDs`).
///
/// # Safety
/// As [`abi::in_slice`].
unsafe fn requested_ids(count: u32, ids: *const u32) -> windows::core::Result<Vec<u32>> {
    // SAFETY: contract of this function.
    Ok(unsafe { abi::in_slice(ids, count) }?.to_vec())
}

// ---------------------------------------------------------------------------------------
// Server object
// ---------------------------------------------------------------------------------------

#[implement(
    IOPCCommon,
    IOPCServer,
    IOPCServerList,
    IOPCServerList2,
    IOPCBrowseServerAddressSpace,
    IOPCItemProperties,
    IOPCBrowse
)]
pub struct ProbeServer {
    _guard: ObjectGuard,
}

/// The probe process's lifetime counts (the probe is a test server with one class object
/// per process, so one static suffices here).
fn probe_lifetime() -> &'static Arc<Lifetime> {
    static LIFETIME: OnceLock<Arc<Lifetime>> = OnceLock::new();
    LIFETIME.get_or_init(Lifetime::new)
}

/// The class factory's constructor: a new probe server object.
pub fn create_instance() -> windows::core::Result<IUnknown> {
    Ok(ProbeServer {
        _guard: ObjectGuard::new(probe_lifetime()),
    }
    .into())
}

/// # Safety
/// `out` is NULL or the method's `[out] LPWSTR*`.
unsafe fn error_string(name: &str, out: *mut PWSTR) -> windows::core::Result<()> {
    nonnull(out)?;
    let s = OwnedWstr::new(&text(name))?;
    // SAFETY: checked non-null; the only allocation has succeeded.
    unsafe { put(out, s.into_raw()) };
    Ok(())
}

/// `GetClassDetails` of both server-list interfaces: every requested output or none.
///
/// # Safety
/// Each pointer is NULL or the method's `[out] LPWSTR*`.
unsafe fn class_details(outs: &[(*mut PWSTR, &str)]) -> windows::core::Result<()> {
    for (p, _) in outs {
        nonnull(*p)?;
    }
    let mut texts = Vec::with_capacity(outs.len());
    for (_, name) in outs {
        texts.push(OwnedWstr::new(&text(name))?);
    }
    for ((p, _), s) in outs.iter().zip(texts) {
        // SAFETY: checked non-null above; every allocation has succeeded.
        unsafe { put(*p, s.into_raw()) };
    }
    Ok(())
}

/// # Safety
/// As [`abi::query_out`].
unsafe fn string_enum(name: &str, riid: *const GUID, out: *mut Option<IUnknown>) -> HRESULT {
    let items = (0..ENUM_STRING_LEN).map(|i| text_at(name, i)).collect();
    let e: IUnknown = StringEnum {
        items,
        pos: Mutex::new(0),
        _guard: ObjectGuard::new(probe_lifetime()),
    }
    .into();
    // SAFETY: contract of this function.
    unsafe { query_out(&e, riid, out) }
}

impl IOPCCommon_Impl for ProbeServer_Impl {
    unsafe fn SetLocaleID(&self, _lcid: u32) -> windows::core::Result<()> {
        Ok(())
    }

    unsafe fn GetLocaleID(&self, _plcid: *mut u32) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }

    unsafe fn QueryAvailableLocaleIDs(
        &self,
        _pcount: *mut u32,
        _plcids: *mut *mut u32,
    ) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }

    unsafe fn GetErrorString(
        &self,
        _code: HRESULT,
        pstring: *mut PWSTR,
    ) -> windows::core::Result<()> {
        error_string(param::COMMON_GET_ERROR_STRING, pstring)
    }

    unsafe fn SetClientName(&self, _name: PCWSTR) -> windows::core::Result<()> {
        Ok(())
    }
}

impl IOPCServer_Impl for ProbeServer_Impl {
    unsafe fn AddGroup(
        &self,
        _name: PCWSTR,
        _active: BOOL,
        rate: u32,
        _client: u32,
        _bias: *const i32,
        _deadband: *const f32,
        _lcid: u32,
        server: *mut u32,
        revised: *mut u32,
        riid: *const GUID,
        unk: *mut Option<IUnknown>,
    ) -> HRESULT {
        if server.is_null() || revised.is_null() {
            return E_INVALIDARG;
        }
        let group: IUnknown = ProbeGroup {
            _guard: ObjectGuard::new(probe_lifetime()),
        }
        .into();
        let hr = query_out(&group, riid, unk);
        if hr.is_ok() {
            // SAFETY: checked non-null above; nothing can fail after the interface is out.
            unsafe {
                put(server, 1);
                put(revised, rate);
            }
        }
        hr
    }

    unsafe fn GetErrorString(
        &self,
        _code: HRESULT,
        _lcid: u32,
        pstring: *mut PWSTR,
    ) -> windows::core::Result<()> {
        error_string(param::SERVER_GET_ERROR_STRING, pstring)
    }

    unsafe fn GetGroupByName(
        &self,
        _name: PCWSTR,
        _riid: *const GUID,
        _unk: *mut Option<IUnknown>,
    ) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }

    unsafe fn GetStatus(&self, pstatus: *mut *mut OPCSERVERSTATUS) -> windows::core::Result<()> {
        nonnull(pstatus)?;
        let mut block = TaskMem::<OPCSERVERSTATUS>::zeroed(1)?;
        let vendor = OwnedWstr::new(&text(param::SERVER_STATUS_VENDOR_INFO))?;
        let now = clock::filetime(clock::now());
        block.as_mut_slice()[0] = OPCSERVERSTATUS {
            ftStartTime: now,
            ftCurrentTime: now,
            ftLastUpdateTime: now,
            dwServerState: OPC_STATUS_TEST,
            dwBandWidth: u32::MAX,
            szVendorInfo: vendor.into_raw(),
            ..Default::default()
        };
        // SAFETY: checked non-null; every allocation has succeeded.
        unsafe { put(pstatus, block.into_raw()) };
        Ok(())
    }

    unsafe fn RemoveGroup(&self, _server_group: u32, _force: BOOL) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn CreateGroupEnumerator(
        &self,
        _scope: OPCENUMSCOPE,
        riid: *const GUID,
        unk: *mut Option<IUnknown>,
    ) -> HRESULT {
        string_enum(param::SERVER_GROUP_NAMES, riid, unk)
    }
}

impl IOPCServerList_Impl for ProbeServer_Impl {
    unsafe fn EnumClassesOfCategories(
        &self,
        _c_impl: u32,
        _impl: *const GUID,
        _c_req: u32,
        _req: *const GUID,
        _enum: *mut Option<windows::Win32::System::Com::IEnumGUID>,
    ) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }

    unsafe fn GetClassDetails(
        &self,
        _clsid: *const GUID,
        progid: *mut PWSTR,
        user_type: *mut PWSTR,
    ) -> windows::core::Result<()> {
        class_details(&[
            (progid, param::LIST_PROGID),
            (user_type, param::LIST_USER_TYPE),
        ])
    }

    unsafe fn CLSIDFromProgID(
        &self,
        _progid: PCWSTR,
        _clsid: *mut GUID,
    ) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }
}

impl IOPCServerList2_Impl for ProbeServer_Impl {
    unsafe fn EnumClassesOfCategories(
        &self,
        _c_impl: u32,
        _impl: *const GUID,
        _c_req: u32,
        _req: *const GUID,
        _enum: *mut Option<IOPCEnumGUID>,
    ) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }

    unsafe fn GetClassDetails(
        &self,
        _clsid: *const GUID,
        progid: *mut PWSTR,
        user_type: *mut PWSTR,
        ver_ind_progid: *mut PWSTR,
    ) -> windows::core::Result<()> {
        class_details(&[
            (progid, param::LIST2_PROGID),
            (user_type, param::LIST2_USER_TYPE),
            (ver_ind_progid, param::LIST2_VER_IND_PROGID),
        ])
    }

    unsafe fn CLSIDFromProgID(
        &self,
        _progid: PCWSTR,
        _clsid: *mut GUID,
    ) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }
}

impl IOPCBrowseServerAddressSpace_Impl for ProbeServer_Impl {
    unsafe fn QueryOrganization(&self, _ns: *mut OPCNAMESPACETYPE) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }

    unsafe fn ChangeBrowsePosition(
        &self,
        _dir: OPCBROWSEDIRECTION,
        _s: PCWSTR,
    ) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }

    unsafe fn BrowseOPCItemIDs(
        &self,
        _filter_type: OPCBROWSETYPE,
        _criteria: PCWSTR,
        _vt: VARTYPE,
        _rights: u32,
        out: *mut Option<IEnumString>,
    ) -> HRESULT {
        string_enum(
            param::BSAS_ITEM_IDS,
            &IEnumString::IID,
            out.cast::<Option<IUnknown>>(),
        )
    }

    unsafe fn GetItemID(&self, _data_id: PCWSTR, item_id: *mut PWSTR) -> windows::core::Result<()> {
        error_string(param::BSAS_ITEM_ID, item_id)
    }

    unsafe fn BrowseAccessPaths(&self, _item_id: PCWSTR, out: *mut Option<IEnumString>) -> HRESULT {
        string_enum(
            param::BSAS_ACCESS_PATHS,
            &IEnumString::IID,
            out.cast::<Option<IUnknown>>(),
        )
    }
}

impl IOPCItemProperties_Impl for ProbeServer_Impl {
    unsafe fn QueryAvailableProperties(
        &self,
        _item_id: PCWSTR,
        pcount: *mut u32,
        pids: *mut *mut u32,
        pdescriptions: *mut *mut PWSTR,
        ptypes: *mut *mut VARTYPE,
    ) -> windows::core::Result<()> {
        nonnull(pcount)?;
        nonnull(pids)?;
        nonnull(pdescriptions)?;
        nonnull(ptypes)?;
        let n = AVAILABLE_PROPERTIES.len();
        let mut ids = TaskMem::<u32>::zeroed(n)?;
        ids.as_mut_slice().copy_from_slice(&AVAILABLE_PROPERTIES);
        let mut types = TaskMem::<VARTYPE>::zeroed(n)?;
        types.as_mut_slice().copy_from_slice(&PROPERTY_TYPES);
        let mut descriptions = OwnedArray::<PWSTR>::zeroed(n)?;
        for (i, slot) in descriptions.as_mut_slice().iter_mut().enumerate() {
            *slot = OwnedWstr::new(&text_at(param::PROPS_DESCRIPTIONS, i))?.into_raw();
        }
        // SAFETY: all four checked non-null; every allocation has succeeded.
        unsafe {
            put(pcount, n as u32);
            put(pids, ids.into_raw());
            put(pdescriptions, descriptions.into_raw());
            put(ptypes, types.into_raw());
        }
        Ok(())
    }

    unsafe fn GetItemProperties(
        &self,
        _item_id: PCWSTR,
        _count: u32,
        _ids: *const u32,
        _data: *mut *mut VARIANT,
        _errors: *mut *mut HRESULT,
    ) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn LookupItemIDs(
        &self,
        _item_id: PCWSTR,
        count: u32,
        pids: *const u32,
        pnew_ids: *mut *mut PWSTR,
        perrors: *mut *mut HRESULT,
    ) -> HRESULT {
        abi::hresult((|| {
            nonnull(pnew_ids)?;
            nonnull(perrors)?;
            if count == 0 {
                return Err(E_INVALIDARG.into());
            }
            let ids = requested_ids(count, pids)?;
            let mut new_ids = OwnedArray::<PWSTR>::zeroed(ids.len())?;
            let mut errors = TaskMem::<HRESULT>::zeroed(ids.len())?;
            let mut all_ok = true;
            for (i, ((slot, err), &id)) in new_ids
                .as_mut_slice()
                .iter_mut()
                .zip(errors.as_mut_slice())
                .zip(&ids)
                .enumerate()
            {
                if id < FIRST_PROPERTY_WITH_ITEM_ID {
                    *err = OPC_E_INVALID_PID;
                    all_ok = false;
                } else {
                    *slot = OwnedWstr::new(&text_at(param::PROPS_NEW_ITEM_IDS, i))?.into_raw();
                    *err = S_OK;
                }
            }
            // SAFETY: both checked non-null; every allocation has succeeded.
            unsafe {
                put(pnew_ids, new_ids.into_raw());
                put(perrors, errors.into_raw());
            }
            Ok(if all_ok { S_OK } else { S_FALSE })
        })())
    }
}

impl IOPCBrowse_Impl for ProbeServer_Impl {
    unsafe fn GetProperties(
        &self,
        count: u32,
        item_ids: *const PCWSTR,
        _return_values: BOOL,
        property_count: u32,
        property_ids: *const u32,
        pitem_properties: *mut *mut OPCITEMPROPERTIES,
    ) -> HRESULT {
        abi::hresult((|| {
            nonnull(pitem_properties)?;
            if count == 0 || item_ids.is_null() {
                return Err(E_INVALIDARG.into());
            }
            let mut ids = requested_ids(property_count, property_ids)?;
            if ids.is_empty() {
                ids = ALL_PROPERTIES.to_vec();
            }
            let mut items = OwnedArray::<OPCITEMPROPERTIES>::zeroed(count as usize)?;
            for (i, slot) in items.as_mut_slice().iter_mut().enumerate() {
                *slot = properties(
                    param::GET_PROPERTIES_ITEM_ID,
                    param::GET_PROPERTIES_DESCRIPTION,
                    i,
                    &ids,
                )?;
            }
            // SAFETY: checked non-null; every allocation has succeeded.
            unsafe { put(pitem_properties, items.into_raw()) };
            Ok(S_OK)
        })())
    }

    unsafe fn Browse(
        &self,
        _item_id: PCWSTR,
        pcontinuation_point: *mut PWSTR,
        max_elements: u32,
        _filter: OPCBROWSEFILTER,
        _name_filter: PCWSTR,
        _vendor_filter: PCWSTR,
        return_all_properties: BOOL,
        _return_values: BOOL,
        property_count: u32,
        property_ids: *const u32,
        pmore: *mut BOOL,
        pcount: *mut u32,
        pelements: *mut *mut OPCBROWSEELEMENT,
    ) -> HRESULT {
        abi::hresult((|| {
            nonnull(pcontinuation_point)?;
            nonnull(pmore)?;
            nonnull(pcount)?;
            nonnull(pelements)?;
            // SAFETY: checked non-null: the [in, out] continuation point is a CoTaskMem
            // string or null, owned by this call until replaced below.
            let incoming = unsafe { *pcontinuation_point };
            let cp = if incoming.is_null() {
                None
            } else {
                // SAFETY: a non-null [in, out, string] is a NUL-terminated UTF-16 string.
                Some(
                    unsafe { incoming.to_string() }
                        .map_err(|_| windows::core::Error::from(OPC_E_INVALIDCONTINUATIONPOINT))?,
                )
            };
            let start = page_start(cp.as_deref())
                .ok_or_else(|| windows::core::Error::from(OPC_E_INVALIDCONTINUATIONPOINT))?;
            let page = if max_elements == 0 {
                BROWSE_PAGE
            } else {
                (max_elements as usize).min(BROWSE_PAGE)
            };
            let end = (start + page).min(BROWSE_ELEMENTS);
            let mut ids = requested_ids(property_count, property_ids)?;
            if ids.is_empty() && return_all_properties.as_bool() {
                ids = ALL_PROPERTIES.to_vec();
            }
            let mut elements = OwnedArray::<OPCBROWSEELEMENT>::zeroed(end - start)?;
            for (k, slot) in (start..end).zip(elements.as_mut_slice()) {
                slot.szName = OwnedWstr::new(&text_at(param::BROWSE_NAME, k))?.into_raw();
                slot.szItemID = OwnedWstr::new(&text_at(param::BROWSE_ITEM_ID, k))?.into_raw();
                slot.dwFlagValue = OPC_BROWSE_ISITEM;
                slot.ItemProperties = properties(
                    param::BROWSE_PROPERTY_ITEM_ID,
                    param::BROWSE_PROPERTY_DESCRIPTION,
                    k,
                    &ids,
                )?;
            }
            let more = end < BROWSE_ELEMENTS;
            let next = if more {
                Some(OwnedWstr::new(&continuation_point(end))?)
            } else {
                None
            };
            // SAFETY: all checked non-null; every allocation has succeeded. The incoming
            // continuation point is freed exactly once and replaced.
            unsafe {
                abi::free_wstr(incoming);
                put(
                    pcontinuation_point,
                    next.map_or(PWSTR::null(), OwnedWstr::into_raw),
                );
                put(pmore, BOOL::from(more));
                put(pcount, (end - start) as u32);
                put(pelements, elements.into_raw());
            }
            Ok(S_OK)
        })())
    }
}

// ---------------------------------------------------------------------------------------
// Group object and its item enumerator
// ---------------------------------------------------------------------------------------

#[implement(IOPCGroupStateMgt2, IOPCItemMgt)]
pub struct ProbeGroup {
    _guard: ObjectGuard,
}

/// The probe group's update rate, client and server handles (`GetState`).
pub const GROUP_UPDATE_RATE: u32 = 1000;
pub const GROUP_CLIENT_HANDLE: u32 = 7;
pub const GROUP_SERVER_HANDLE: u32 = 1;

impl IOPCGroupStateMgt_Impl for ProbeGroup_Impl {
    unsafe fn GetState(
        &self,
        prate: *mut u32,
        pactive: *mut BOOL,
        pname: *mut PWSTR,
        pbias: *mut i32,
        pdeadband: *mut f32,
        plcid: *mut u32,
        pclient: *mut u32,
        pserver: *mut u32,
    ) -> windows::core::Result<()> {
        nonnull(prate)?;
        nonnull(pactive)?;
        nonnull(pname)?;
        nonnull(pbias)?;
        nonnull(pdeadband)?;
        nonnull(plcid)?;
        nonnull(pclient)?;
        nonnull(pserver)?;
        let name = OwnedWstr::new(&text(param::GROUP_NAME))?;
        // SAFETY: all checked non-null; the only allocation has succeeded.
        unsafe {
            put(prate, GROUP_UPDATE_RATE);
            put(pactive, BOOL::from(true));
            put(pname, name.into_raw());
            put(pbias, 0);
            put(pdeadband, 0.0);
            put(plcid, 0x0415);
            put(pclient, GROUP_CLIENT_HANDLE);
            put(pserver, GROUP_SERVER_HANDLE);
        }
        Ok(())
    }

    unsafe fn SetState(
        &self,
        _rate: *const u32,
        _revised: *mut u32,
        _active: *const BOOL,
        _bias: *const i32,
        _deadband: *const f32,
        _lcid: *const u32,
        _client: *const u32,
    ) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn SetName(&self, _name: PCWSTR) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }

    unsafe fn CloneGroup(
        &self,
        _name: PCWSTR,
        _riid: *const GUID,
        _unk: *mut Option<IUnknown>,
    ) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }
}

impl IOPCGroupStateMgt2_Impl for ProbeGroup_Impl {
    unsafe fn SetKeepAlive(&self, _time: u32, _revised: *mut u32) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn GetKeepAlive(&self, _time: *mut u32) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }
}

impl IOPCItemMgt_Impl for ProbeGroup_Impl {
    unsafe fn AddItems(
        &self,
        _n: u32,
        _items: *const OPCITEMDEF,
        _results: *mut *mut OPCITEMRESULT,
        _errors: *mut *mut HRESULT,
    ) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn ValidateItems(
        &self,
        _n: u32,
        _items: *const OPCITEMDEF,
        _blob: BOOL,
        _results: *mut *mut OPCITEMRESULT,
        _errors: *mut *mut HRESULT,
    ) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn RemoveItems(
        &self,
        _n: u32,
        _server: *const u32,
        _errors: *mut *mut HRESULT,
    ) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn SetActiveState(
        &self,
        _n: u32,
        _server: *const u32,
        _active: BOOL,
        _errors: *mut *mut HRESULT,
    ) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn SetClientHandles(
        &self,
        _n: u32,
        _server: *const u32,
        _client: *const u32,
        _errors: *mut *mut HRESULT,
    ) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn SetDatatypes(
        &self,
        _n: u32,
        _server: *const u32,
        _types: *const VARTYPE,
        _errors: *mut *mut HRESULT,
    ) -> HRESULT {
        E_NOTIMPL
    }

    unsafe fn CreateEnumerator(&self, riid: *const GUID, unk: *mut Option<IUnknown>) -> HRESULT {
        let e: IUnknown = ItemEnum {
            pos: Mutex::new(0),
            _guard: ObjectGuard::new(probe_lifetime()),
        }
        .into();
        query_out(&e, riid, unk)
    }
}

#[implement(IEnumOPCItemAttributes)]
struct ItemEnum {
    pos: Mutex<usize>,
    _guard: ObjectGuard,
}

impl ItemEnum {
    fn pos(&self) -> std::sync::MutexGuard<'_, usize> {
        self.pos.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Item `k` of the probe group's enumerator.
fn item_attributes(slot: &mut OPCITEMATTRIBUTES, k: usize) -> windows::core::Result<()> {
    slot.szAccessPath = OwnedWstr::new(&text_at(param::ITEM_ACCESS_PATH, k))?.into_raw();
    slot.szItemID = OwnedWstr::new(&text_at(param::ITEM_ITEM_ID, k))?.into_raw();
    slot.bActive = BOOL::from(true);
    slot.hClient = k as u32;
    slot.hServer = 100 + k as u32;
    slot.dwAccessRights = OPC_READABLE;
    slot.vtCanonicalDataType = VT_R8;
    slot.dwEUType = OPC_NOENUM;
    Ok(())
}

impl IEnumOPCItemAttributes_Impl for ItemEnum_Impl {
    unsafe fn Next(
        &self,
        celt: u32,
        pitems: *mut *mut OPCITEMATTRIBUTES,
        pfetched: *mut u32,
    ) -> HRESULT {
        abi::hresult((|| {
            nonnull(pitems)?;
            nonnull(pfetched)?;
            let mut pos = self.pos();
            let start = *pos;
            let end = start.saturating_add(celt as usize).min(ITEM_COUNT);
            let n = end.saturating_sub(start);
            let mut items = OwnedArray::<OPCITEMATTRIBUTES>::zeroed(n)?;
            for (k, slot) in (start..end).zip(items.as_mut_slice()) {
                item_attributes(slot, k)?;
            }
            let array = if n == 0 {
                std::ptr::null_mut()
            } else {
                items.into_raw()
            };
            // SAFETY: both checked non-null; every allocation has succeeded.
            unsafe {
                put(pitems, array);
                put(pfetched, n as u32);
            }
            *pos = end.max(start);
            Ok(if n == celt as usize { S_OK } else { S_FALSE })
        })())
    }

    unsafe fn Skip(&self, celt: u32) -> HRESULT {
        let mut pos = self.pos();
        let end = pos.saturating_add(celt as usize).min(ITEM_COUNT);
        let skipped = end.saturating_sub(*pos);
        *pos = end.max(*pos);
        if skipped == celt as usize {
            S_OK
        } else {
            S_FALSE
        }
    }

    unsafe fn Reset(&self) -> windows::core::Result<()> {
        *self.pos() = 0;
        Ok(())
    }

    unsafe fn Clone(&self, _out: *mut Option<IEnumOPCItemAttributes>) -> windows::core::Result<()> {
        Err(E_NOTIMPL.into())
    }
}

/// An IEnumString over fixed texts (group names, item IDs, access paths).
#[implement(IEnumString)]
struct StringEnum {
    items: Vec<String>,
    pos: Mutex<usize>,
    _guard: ObjectGuard,
}

impl StringEnum {
    fn pos(&self) -> std::sync::MutexGuard<'_, usize> {
        self.pos.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl IEnumString_Impl for StringEnum_Impl {
    fn Next(&self, celt: u32, rgelt: *mut PWSTR, pfetched: *mut u32) -> HRESULT {
        if rgelt.is_null() || (pfetched.is_null() && celt != 1) {
            return E_POINTER;
        }
        let mut pos = self.pos();
        let start = (*pos).min(self.items.len());
        let end = start.saturating_add(celt as usize).min(self.items.len());
        let mut out = Vec::with_capacity(end - start);
        for s in &self.items[start..end] {
            match OwnedWstr::new(s) {
                Ok(w) => out.push(w),
                Err(e) => return e.code(),
            }
        }
        let n = out.len();
        for (i, w) in out.into_iter().enumerate() {
            // SAFETY: `rgelt` is the caller's array of `celt` elements and `i < n <= celt`.
            unsafe { put(rgelt.add(i), w.into_raw()) };
        }
        if !pfetched.is_null() {
            // SAFETY: checked non-null.
            unsafe { put(pfetched, n as u32) };
        }
        *pos = end;
        if n == celt as usize {
            S_OK
        } else {
            S_FALSE
        }
    }

    fn Skip(&self, celt: u32) -> HRESULT {
        let mut pos = self.pos();
        let end = pos.saturating_add(celt as usize).min(self.items.len());
        let skipped = end.saturating_sub(*pos);
        *pos = end.max(*pos);
        if skipped == celt as usize {
            S_OK
        } else {
            S_FALSE
        }
    }

    fn Reset(&self) -> windows::core::Result<()> {
        *self.pos() = 0;
        Ok(())
    }

    fn Clone(&self) -> windows::core::Result<IEnumString> {
        let pos = *self.pos();
        Ok(StringEnum {
            items: self.items.clone(),
            pos: Mutex::new(pos),
            _guard: ObjectGuard::new(probe_lifetime()),
        }
        .into())
    }
}

// ---------------------------------------------------------------------------------------
// marshal-probe.exe: /RegServer, /UnregServer, -Embedding
// ---------------------------------------------------------------------------------------

fn with_registration<R>(f: impl FnOnce(&ServerRegistration) -> R) -> windows::core::Result<R> {
    let exe = std::env::current_exe()
        .map_err(|e| error::error(windows::Win32::Foundation::E_FAIL, &e.to_string()))?;
    let exe = exe.to_string_lossy();
    let reg = ServerRegistration {
        clsid: CLSID_MARSHAL_PROBE.to_u128(),
        appid: CLSID_MARSHAL_PROBE.to_u128(),
        progid: PROGID,
        progid_versioned: PROGID_VERSIONED,
        class_progid: PROGID_VERSIONED,
        description: DESCRIPTION,
        exe_path: &exe,
        exe_name: EXE_NAME,
        service_name: None,
        categories: &[],
        opc_key_vendor: None,
    };
    Ok(f(&reg))
}

/// `/RegServer`.
pub fn register() -> windows::core::Result<()> {
    let _com = Apartment::mta()?;
    with_registration(winreg::register)??;
    println!(
        "marshal-probe: registered {PROGID} ({})",
        winreg::guid_string(&CLSID_MARSHAL_PROBE)
    );
    Ok(())
}

/// `/UnregServer`.
pub fn unregister() -> windows::core::Result<()> {
    let _com = Apartment::mta()?;
    with_registration(winreg::unregister)??;
    println!("marshal-probe: unregistered {PROGID}");
    Ok(())
}

/// `-Embedding`: serve until the last client has gone (as ServerCTOPC.exe does).
pub fn serve() -> windows::core::Result<()> {
    let _com = Apartment::mta()?;
    ctopc_com::host::init_security();
    let factory = ClassFactory::new(Arc::clone(probe_lifetime()), create_instance);
    let cookie = ctopc_com::host::register_class(&CLSID_MARSHAL_PROBE, &factory)?;
    let reason = probe_lifetime().wait_until_unused(STARTUP_GRACE, LINGER);
    // SAFETY: the cookie came from CoRegisterClassObject above.
    unsafe { CoRevokeClassObject(cookie)? };
    eprintln!("marshal-probe: exiting ({reason:?})");
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Safe readers for the test
// ---------------------------------------------------------------------------------------

/// Safe readers of the string outputs the probe produces that the client library
/// (`opc_client::Server`, which reads GetItemID, QueryAvailableProperties,
/// LookupItemIDs, GetProperties and Browse for the test) has no reader for: each calls one
/// method through the given interface pointer (a proxy when the object lives in another
/// process), copies what arrived and frees it. A string that arrived NULL is `None` (also
/// in an enumeration); one that is not valid UTF-16 is reported as `<invalid UTF-16 ...>`.
pub mod client {
    use ctopc_com::abi::{free_array, OwnsTaskMem};
    use ctopc_com::interfaces::*;
    use windows::core::{IUnknown, Interface, BOOL, GUID, PCWSTR, PWSTR};
    use windows::Win32::Foundation::{E_POINTER, S_FALSE};
    use windows::Win32::System::Com::IEnumString;

    /// Copies a string out-parameter without freeing it.
    fn copy_wstr(p: PWSTR) -> Option<String> {
        if p.is_null() {
            return None;
        }
        // SAFETY: a non-null string out-parameter is a NUL-terminated UTF-16 string.
        let units = unsafe { p.as_wide() };
        Some(String::from_utf16(units).unwrap_or_else(|_| format!("<invalid UTF-16 {units:04x?}>")))
    }

    /// Copies and frees a string out-parameter.
    fn take_wstr(mut p: PWSTR) -> Option<String> {
        let s = copy_wstr(p);
        // SAFETY: string out-parameters are CoTaskMem blocks owned by the caller.
        unsafe { p.free_owned() };
        s
    }

    fn wide(s: &str) -> Vec<u16> {
        s.encode_utf16().chain(std::iter::once(0)).collect()
    }

    /// `IOPCServerList::GetClassDetails`: (ppszProgID, ppszUserType).
    pub fn class_details(
        list: &IOPCServerList,
        clsid: &GUID,
    ) -> windows::core::Result<(Option<String>, Option<String>)> {
        let (mut a, mut b) = (PWSTR::null(), PWSTR::null());
        // SAFETY: valid pointers for the call; the strings are ours afterwards.
        unsafe { list.GetClassDetails(clsid, &mut a, &mut b)? };
        Ok((take_wstr(a), take_wstr(b)))
    }

    /// `IOPCServerList2::GetClassDetails`: (ppszProgID, ppszUserType, ppszVerIndProgID).
    pub fn class_details2(
        list: &IOPCServerList2,
        clsid: &GUID,
    ) -> windows::core::Result<(Option<String>, Option<String>, Option<String>)> {
        let (mut a, mut b, mut c) = (PWSTR::null(), PWSTR::null(), PWSTR::null());
        // SAFETY: valid pointers for the call; the strings are ours afterwards.
        unsafe { list.GetClassDetails(clsid, &mut a, &mut b, &mut c)? };
        Ok((take_wstr(a), take_wstr(b), take_wstr(c)))
    }

    /// Every string of an IEnumString, fetched `chunk` at a time.
    pub fn drain(e: &IEnumString, chunk: usize) -> windows::core::Result<Vec<Option<String>>> {
        let mut all = Vec::new();
        loop {
            let mut buf = vec![PWSTR::null(); chunk.max(1)];
            let mut fetched = 0u32;
            // SAFETY: `buf` has room for `buf.len()` pointers; valid count pointer.
            let hr = unsafe { e.Next(&mut buf, Some(&mut fetched as *mut u32)) };
            hr.ok()?;
            let n = (fetched as usize).min(buf.len());
            all.extend(buf.into_iter().take(n).map(take_wstr));
            if hr == S_FALSE || n == 0 {
                return Ok(all);
            }
        }
    }

    /// `IOPCServer::CreateGroupEnumerator(IEnumString)`: the names.
    pub fn group_names(server: &IOPCServer) -> windows::core::Result<Vec<Option<String>>> {
        let mut unk: Option<IUnknown> = None;
        // SAFETY: valid IID and out-pointer.
        unsafe {
            server
                .CreateGroupEnumerator(OPC_ENUM_ALL, &IEnumString::IID, &mut unk)
                .ok()?
        };
        drain(
            &unk.ok_or_else(|| windows::core::Error::from(E_POINTER))?
                .cast::<IEnumString>()?,
            2,
        )
    }

    /// `IOPCBrowseServerAddressSpace::BrowseOPCItemIDs(OPC_FLAT, "")`: the item IDs.
    pub fn browse_item_ids(
        bsas: &IOPCBrowseServerAddressSpace,
    ) -> windows::core::Result<Vec<Option<String>>> {
        let filter = wide("");
        let mut e: Option<IEnumString> = None;
        // SAFETY: NUL-terminated input alive for the call; valid out-pointer.
        unsafe {
            bsas.BrowseOPCItemIDs(
                OPC_FLAT,
                PCWSTR(filter.as_ptr()),
                Default::default(),
                0,
                &mut e,
            )
            .ok()?
        };
        drain(&e.ok_or_else(|| windows::core::Error::from(E_POINTER))?, 2)
    }

    /// `IOPCBrowseServerAddressSpace::BrowseAccessPaths`: the access paths.
    pub fn browse_access_paths(
        bsas: &IOPCBrowseServerAddressSpace,
        item_id: &str,
    ) -> windows::core::Result<Vec<Option<String>>> {
        let item = wide(item_id);
        let mut e: Option<IEnumString> = None;
        // SAFETY: NUL-terminated input alive for the call; valid out-pointer.
        unsafe { bsas.BrowseAccessPaths(PCWSTR(item.as_ptr()), &mut e).ok()? };
        drain(&e.ok_or_else(|| windows::core::Error::from(E_POINTER))?, 2)
    }

    /// `IOPCServer::AddGroup` asking for `riid`; returns the group.
    pub fn add_group(
        server: &IOPCServer,
        name: &str,
        riid: &GUID,
    ) -> windows::core::Result<IUnknown> {
        let name = wide(name);
        let (mut h, mut rate) = (0u32, 0u32);
        let mut unk: Option<IUnknown> = None;
        // SAFETY: inputs valid for the call; valid out-pointers.
        unsafe {
            server
                .AddGroup(
                    PCWSTR(name.as_ptr()),
                    BOOL::from(true),
                    1000,
                    7,
                    std::ptr::null(),
                    std::ptr::null(),
                    0x0415,
                    &mut h,
                    &mut rate,
                    riid,
                    &mut unk,
                )
                .ok()?
        };
        unk.ok_or_else(|| E_POINTER.into())
    }

    /// `IOPCGroupStateMgt::GetState`: the group's name (`ppName`), with the other outputs
    /// (update rate, client handle, server handle) to check they were not disturbed.
    pub fn group_state_name(
        group: &IOPCGroupStateMgt,
    ) -> windows::core::Result<(Option<String>, u32, u32, u32)> {
        let (mut rate, mut bias, mut lcid, mut client, mut server) = (0u32, 0i32, 0u32, 0u32, 0u32);
        let mut active = BOOL::default();
        let mut deadband = 0f32;
        let mut name = PWSTR::null();
        // SAFETY: valid out-pointers; the name is ours afterwards.
        unsafe {
            group.GetState(
                &mut rate,
                &mut active,
                &mut name,
                &mut bias,
                &mut deadband,
                &mut lcid,
                &mut client,
                &mut server,
            )?
        };
        Ok((take_wstr(name), rate, client, server))
    }

    /// One `OPCITEMATTRIBUTES` (the strings and handles), owned.
    #[derive(Debug, Clone, PartialEq)]
    pub struct ItemAttributes {
        pub access_path: Option<String>,
        pub item_id: Option<String>,
        pub client: u32,
        pub server: u32,
    }

    /// `IOPCItemMgt::CreateEnumerator(IEnumOPCItemAttributes)`, then `Next(celt)` until the
    /// enumerator is exhausted.
    pub fn item_attributes(
        items: &IOPCItemMgt,
        celt: u32,
    ) -> windows::core::Result<Vec<ItemAttributes>> {
        let mut unk: Option<IUnknown> = None;
        // SAFETY: valid IID and out-pointer.
        unsafe {
            items
                .CreateEnumerator(&IEnumOPCItemAttributes::IID, &mut unk)
                .ok()?
        };
        let e = unk
            .ok_or_else(|| windows::core::Error::from(E_POINTER))?
            .cast::<IEnumOPCItemAttributes>()?;
        let mut all = Vec::new();
        loop {
            let mut p: *mut OPCITEMATTRIBUTES = std::ptr::null_mut();
            let mut fetched = 0u32;
            // SAFETY: valid out-pointers; the array is ours afterwards.
            let hr = unsafe { e.Next(celt, &mut p, &mut fetched) };
            let n = fetched as usize;
            if !p.is_null() {
                // SAFETY: `n` elements were returned.
                all.extend(unsafe { std::slice::from_raw_parts(p, n) }.iter().map(|a| {
                    ItemAttributes {
                        access_path: copy_wstr(a.szAccessPath),
                        item_id: copy_wstr(a.szItemID),
                        client: a.hClient,
                        server: a.hServer,
                    }
                }));
            }
            // SAFETY: the CoTaskMem array and everything in it is ours.
            unsafe { free_array(p, n) };
            hr.ok()?;
            if hr == S_FALSE || n == 0 {
                return Ok(all);
            }
        }
    }
}
