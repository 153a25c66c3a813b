//! OPC Common 1.10 interfaces (`opccomn.idl`).
//!
//! Vtable order and arity are checked against `idl/` by `xtask/tests/interfaces_match_idl.rs`.

use windows::Win32::System::Com::IEnumGUID;
use windows_core::{interface, IUnknown, IUnknown_Vtbl, Result, GUID, HRESULT, PCWSTR, PWSTR};

use super::types::LCID;

/// `IOPCShutdown`: implemented by the client; the server calls it before shutting down.
#[interface("f31dfde1-07b6-11d2-b2d8-0060083ba1fb")]
pub unsafe trait IOPCShutdown: IUnknown {
    pub fn ShutdownRequest(&self, szReason: PCWSTR) -> Result<()>;
}

/// `IOPCCommon`: locale, error strings and client name (every OPC server).
#[interface("f31dfde2-07b6-11d2-b2d8-0060083ba1fb")]
pub unsafe trait IOPCCommon: IUnknown {
    pub fn SetLocaleID(&self, dwLcid: LCID) -> Result<()>;
    pub fn GetLocaleID(&self, pdwLcid: *mut LCID) -> Result<()>;
    pub fn QueryAvailableLocaleIDs(
        &self,
        pdwCount: *mut u32,
        pdwLcid: *mut *mut LCID,
    ) -> Result<()>;
    pub fn GetErrorString(&self, dwError: HRESULT, ppString: *mut PWSTR) -> Result<()>;
    pub fn SetClientName(&self, szName: PCWSTR) -> Result<()>;
}

/// `IOPCServerList` (OPCEnum): lists OPC servers by component category.
#[interface("13486d50-4821-11d2-a494-3cb306c10000")]
pub unsafe trait IOPCServerList: IUnknown {
    pub fn EnumClassesOfCategories(
        &self,
        cImplemented: u32,
        rgcatidImpl: *const GUID,
        cRequired: u32,
        rgcatidReq: *const GUID,
        ppenumClsid: *mut Option<IEnumGUID>,
    ) -> Result<()>;
    pub fn GetClassDetails(
        &self,
        clsid: *const GUID,
        ppszProgID: *mut PWSTR,
        ppszUserType: *mut PWSTR,
    ) -> Result<()>;
    pub fn CLSIDFromProgID(&self, szProgId: PCWSTR, clsid: *mut GUID) -> Result<()>;
}

/// `IOPCEnumGUID`: OPCEnum's own GUID enumerator (used by [`IOPCServerList2`]).
#[interface("55c382c8-21c7-4e88-96c1-becfb1e3f483")]
pub unsafe trait IOPCEnumGUID: IUnknown {
    /// `S_FALSE` when fewer than `celt` GUIDs were returned.
    pub fn Next(&self, celt: u32, rgelt: *mut GUID, pceltFetched: *mut u32) -> HRESULT;
    /// `S_FALSE` when fewer than `celt` GUIDs were skipped.
    pub fn Skip(&self, celt: u32) -> HRESULT;
    pub fn Reset(&self) -> Result<()>;
    pub fn Clone(&self, ppenum: *mut Option<IOPCEnumGUID>) -> Result<()>;
}

/// `IOPCServerList2` (OPCEnum): [`IOPCServerList`] with `IOPCEnumGUID` and the
/// version-independent ProgID. Derives from `IUnknown`, not from `IOPCServerList`.
#[interface("9dd0b56c-ad9e-43ee-8305-487f3188bf7a")]
pub unsafe trait IOPCServerList2: IUnknown {
    pub fn EnumClassesOfCategories(
        &self,
        cImplemented: u32,
        rgcatidImpl: *const GUID,
        cRequired: u32,
        rgcatidReq: *const GUID,
        ppenumClsid: *mut Option<IOPCEnumGUID>,
    ) -> Result<()>;
    pub fn GetClassDetails(
        &self,
        clsid: *const GUID,
        ppszProgID: *mut PWSTR,
        ppszUserType: *mut PWSTR,
        ppszVerIndProgID: *mut PWSTR,
    ) -> Result<()>;
    pub fn CLSIDFromProgID(&self, szProgId: PCWSTR, clsid: *mut GUID) -> Result<()>;
}
