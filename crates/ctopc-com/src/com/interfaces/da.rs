//! OPC Data Access 2.05a / 3.00 interfaces (`opcda.idl`).
//!
//! Conventions (see `mod.rs`): methods that may return `S_FALSE` or an `OPC_S_*` success code
//! return a raw [`HRESULT`]; the others return `Result<()>`. `[iid_is(riid), out] LPUNKNOWN*`
//! parameters are `*mut Option<IUnknown>`: the pointer written there is of interface `riid`
//! (valid as an `IUnknown` for `AddRef`/`Release`/`QueryInterface`; `cast` it to use it).
//!
//! Vtable order and arity are checked against `idl/` by `xtask/tests/interfaces_match_idl.rs`.

use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Com::IEnumString;
use windows::Win32::System::Variant::VARIANT;
use windows_core::{
    interface, IUnknown, IUnknown_Vtbl, Result, BOOL, GUID, HRESULT, PCWSTR, PWSTR,
};

use super::types::{
    LCID, OPCBROWSEDIRECTION, OPCBROWSEELEMENT, OPCBROWSEFILTER, OPCBROWSETYPE, OPCDATASOURCE,
    OPCENUMSCOPE, OPCHANDLE, OPCITEMATTRIBUTES, OPCITEMDEF, OPCITEMPROPERTIES, OPCITEMRESULT,
    OPCITEMSTATE, OPCITEMVQT, OPCNAMESPACETYPE, OPCSERVERSTATUS, VARTYPE,
};

// ---------------------------------------------------------------------------------------
// Server object
// ---------------------------------------------------------------------------------------

/// `IOPCServer`: groups, status and error strings (DA 1.0+).
#[interface("39c13a4d-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCServer: IUnknown {
    /// May return `OPC_S_UNSUPPORTEDRATE`.
    pub fn AddGroup(
        &self,
        szName: PCWSTR,
        bActive: BOOL,
        dwRequestedUpdateRate: u32,
        hClientGroup: OPCHANDLE,
        pTimeBias: *const i32,
        pPercentDeadband: *const f32,
        dwLCID: LCID,
        phServerGroup: *mut OPCHANDLE,
        pRevisedUpdateRate: *mut u32,
        riid: *const GUID,
        ppUnk: *mut Option<IUnknown>,
    ) -> HRESULT;
    pub fn GetErrorString(
        &self,
        dwError: HRESULT,
        dwLocale: LCID,
        ppString: *mut PWSTR,
    ) -> Result<()>;
    pub fn GetGroupByName(
        &self,
        szName: PCWSTR,
        riid: *const GUID,
        ppUnk: *mut Option<IUnknown>,
    ) -> Result<()>;
    pub fn GetStatus(&self, ppServerStatus: *mut *mut OPCSERVERSTATUS) -> Result<()>;
    /// May return `OPC_S_INUSE`.
    pub fn RemoveGroup(&self, hServerGroup: OPCHANDLE, bForce: BOOL) -> HRESULT;
    /// `S_FALSE` with an empty enumerator when no group matches.
    pub fn CreateGroupEnumerator(
        &self,
        dwScope: OPCENUMSCOPE,
        riid: *const GUID,
        ppUnk: *mut Option<IUnknown>,
    ) -> HRESULT;
}

/// `IOPCServerPublicGroups` (optional, DA 1.0/2.0).
#[interface("39c13a4e-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCServerPublicGroups: IUnknown {
    pub fn GetPublicGroupByName(
        &self,
        szName: PCWSTR,
        riid: *const GUID,
        ppUnk: *mut Option<IUnknown>,
    ) -> Result<()>;
    /// May return `OPC_S_INUSE`.
    pub fn RemovePublicGroup(&self, hServerGroup: OPCHANDLE, bForce: BOOL) -> HRESULT;
}

/// `IOPCBrowseServerAddressSpace` (DA 2.0 browsing).
#[interface("39c13a4f-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCBrowseServerAddressSpace: IUnknown {
    pub fn QueryOrganization(&self, pNameSpaceType: *mut OPCNAMESPACETYPE) -> Result<()>;
    pub fn ChangeBrowsePosition(
        &self,
        dwBrowseDirection: OPCBROWSEDIRECTION,
        szString: PCWSTR,
    ) -> Result<()>;
    /// `S_FALSE` with an empty enumerator when nothing matches.
    pub fn BrowseOPCItemIDs(
        &self,
        dwBrowseFilterType: OPCBROWSETYPE,
        szFilterCriteria: PCWSTR,
        vtDataTypeFilter: VARTYPE,
        dwAccessRightsFilter: u32,
        ppIEnumString: *mut Option<IEnumString>,
    ) -> HRESULT;
    pub fn GetItemID(&self, szItemDataID: PCWSTR, szItemID: *mut PWSTR) -> Result<()>;
    /// `S_FALSE` with an empty enumerator when the item has no access paths.
    pub fn BrowseAccessPaths(
        &self,
        szItemID: PCWSTR,
        ppIEnumString: *mut Option<IEnumString>,
    ) -> HRESULT;
}

/// `IOPCItemProperties` (DA 2.0; superseded by `IOPCBrowse` in DA 3.00).
#[interface("39c13a72-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCItemProperties: IUnknown {
    pub fn QueryAvailableProperties(
        &self,
        szItemID: PCWSTR,
        pdwCount: *mut u32,
        ppPropertyIDs: *mut *mut u32,
        ppDescriptions: *mut *mut PWSTR,
        ppvtDataTypes: *mut *mut VARTYPE,
    ) -> Result<()>;
    pub fn GetItemProperties(
        &self,
        szItemID: PCWSTR,
        dwCount: u32,
        pdwPropertyIDs: *const u32,
        ppvData: *mut *mut VARIANT,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn LookupItemIDs(
        &self,
        szItemID: PCWSTR,
        dwCount: u32,
        pdwPropertyIDs: *const u32,
        ppszNewItemIDs: *mut *mut PWSTR,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
}

/// `IOPCBrowse` (DA 3.00 browsing and properties).
#[interface("39227004-a18f-4b57-8b0a-5235670f4468")]
pub unsafe trait IOPCBrowse: IUnknown {
    pub fn GetProperties(
        &self,
        dwItemCount: u32,
        pszItemIDs: *const PCWSTR,
        bReturnPropertyValues: BOOL,
        dwPropertyCount: u32,
        pdwPropertyIDs: *const u32,
        ppItemProperties: *mut *mut OPCITEMPROPERTIES,
    ) -> HRESULT;
    /// `pszContinuationPoint` is `[in, out]`: the server frees the client's string and may
    /// write a new one.
    pub fn Browse(
        &self,
        szItemID: PCWSTR,
        pszContinuationPoint: *mut PWSTR,
        dwMaxElementsReturned: u32,
        dwBrowseFilter: OPCBROWSEFILTER,
        szElementNameFilter: PCWSTR,
        szVendorFilter: PCWSTR,
        bReturnAllProperties: BOOL,
        bReturnPropertyValues: BOOL,
        dwPropertyCount: u32,
        pdwPropertyIDs: *const u32,
        pbMoreElements: *mut BOOL,
        pdwCount: *mut u32,
        ppBrowseElements: *mut *mut OPCBROWSEELEMENT,
    ) -> HRESULT;
}

/// `IOPCItemIO` (DA 3.00): read/write by item ID without a group.
#[interface("85c0b427-2893-4cbc-bd78-e5fc5146f08f")]
pub unsafe trait IOPCItemIO: IUnknown {
    pub fn Read(
        &self,
        dwCount: u32,
        pszItemIDs: *const PCWSTR,
        pdwMaxAge: *const u32,
        ppvValues: *mut *mut VARIANT,
        ppwQualities: *mut *mut u16,
        ppftTimeStamps: *mut *mut FILETIME,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn WriteVQT(
        &self,
        dwCount: u32,
        pszItemIDs: *const PCWSTR,
        pItemVQT: *const OPCITEMVQT,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
}

// ---------------------------------------------------------------------------------------
// Group object
// ---------------------------------------------------------------------------------------

/// `IOPCGroupStateMgt`: update rate, active state, name, deadband, ... of a group.
#[interface("39c13a50-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCGroupStateMgt: IUnknown {
    pub fn GetState(
        &self,
        pUpdateRate: *mut u32,
        pActive: *mut BOOL,
        ppName: *mut PWSTR,
        pTimeBias: *mut i32,
        pPercentDeadband: *mut f32,
        pLCID: *mut LCID,
        phClientGroup: *mut OPCHANDLE,
        phServerGroup: *mut OPCHANDLE,
    ) -> Result<()>;
    /// May return `OPC_S_UNSUPPORTEDRATE`. All `[in, unique]` pointers may be null.
    pub fn SetState(
        &self,
        pRequestedUpdateRate: *const u32,
        pRevisedUpdateRate: *mut u32,
        pActive: *const BOOL,
        pTimeBias: *const i32,
        pPercentDeadband: *const f32,
        pLCID: *const LCID,
        phClientGroup: *const OPCHANDLE,
    ) -> HRESULT;
    pub fn SetName(&self, szName: PCWSTR) -> Result<()>;
    pub fn CloneGroup(
        &self,
        szName: PCWSTR,
        riid: *const GUID,
        ppUnk: *mut Option<IUnknown>,
    ) -> Result<()>;
}

/// `IOPCGroupStateMgt2` (DA 3.00): keep-alive.
#[interface("8e368666-d72e-4f78-87ed-647611c61c9f")]
pub unsafe trait IOPCGroupStateMgt2: IOPCGroupStateMgt {
    /// May return `OPC_S_UNSUPPORTEDRATE`.
    pub fn SetKeepAlive(&self, dwKeepAliveTime: u32, pdwRevisedKeepAliveTime: *mut u32) -> HRESULT;
    pub fn GetKeepAlive(&self, pdwKeepAliveTime: *mut u32) -> Result<()>;
}

/// `IOPCPublicGroupStateMgt` (optional, DA 1.0/2.0).
#[interface("39c13a51-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCPublicGroupStateMgt: IUnknown {
    pub fn GetState(&self, pPublic: *mut BOOL) -> Result<()>;
    pub fn MoveToPublic(&self) -> Result<()>;
}

/// `IOPCSyncIO`: synchronous read/write of group items.
#[interface("39c13a52-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCSyncIO: IUnknown {
    pub fn Read(
        &self,
        dwSource: OPCDATASOURCE,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        ppItemValues: *mut *mut OPCITEMSTATE,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn Write(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pItemValues: *const VARIANT,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
}

/// `IOPCSyncIO2` (DA 3.00): max-age reads and VQT writes.
#[interface("730f5f0f-55b1-4c81-9e18-ff8a0904e1fa")]
pub unsafe trait IOPCSyncIO2: IOPCSyncIO {
    pub fn ReadMaxAge(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pdwMaxAge: *const u32,
        ppvValues: *mut *mut VARIANT,
        ppwQualities: *mut *mut u16,
        ppftTimeStamps: *mut *mut FILETIME,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn WriteVQT(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pItemVQT: *const OPCITEMVQT,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
}

/// `IOPCAsyncIO` (DA 1.0, `IDataObject`-based; obsolete, kept for the vtable).
#[interface("39c13a53-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCAsyncIO: IUnknown {
    pub fn Read(
        &self,
        dwConnection: u32,
        dwSource: OPCDATASOURCE,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pTransactionID: *mut u32,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn Write(
        &self,
        dwConnection: u32,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pItemValues: *const VARIANT,
        pTransactionID: *mut u32,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn Refresh(
        &self,
        dwConnection: u32,
        dwSource: OPCDATASOURCE,
        pTransactionID: *mut u32,
    ) -> Result<()>;
    pub fn Cancel(&self, dwTransactionID: u32) -> Result<()>;
}

/// `IOPCAsyncIO2` (DA 2.0): asynchronous I/O through `IOPCDataCallback`.
#[interface("39c13a71-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCAsyncIO2: IUnknown {
    pub fn Read(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        dwTransactionID: u32,
        pdwCancelID: *mut u32,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn Write(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pItemValues: *const VARIANT,
        dwTransactionID: u32,
        pdwCancelID: *mut u32,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn Refresh2(
        &self,
        dwSource: OPCDATASOURCE,
        dwTransactionID: u32,
        pdwCancelID: *mut u32,
    ) -> Result<()>;
    pub fn Cancel2(&self, dwCancelID: u32) -> Result<()>;
    pub fn SetEnable(&self, bEnable: BOOL) -> Result<()>;
    pub fn GetEnable(&self, pbEnable: *mut BOOL) -> Result<()>;
}

/// `IOPCAsyncIO3` (DA 3.00): asynchronous max-age reads and VQT writes.
#[interface("0967b97b-36ef-423e-b6f8-6bff1e40d39d")]
pub unsafe trait IOPCAsyncIO3: IOPCAsyncIO2 {
    pub fn ReadMaxAge(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pdwMaxAge: *const u32,
        dwTransactionID: u32,
        pdwCancelID: *mut u32,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn WriteVQT(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pItemVQT: *const OPCITEMVQT,
        dwTransactionID: u32,
        pdwCancelID: *mut u32,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn RefreshMaxAge(
        &self,
        dwMaxAge: u32,
        dwTransactionID: u32,
        pdwCancelID: *mut u32,
    ) -> Result<()>;
}

/// `IOPCItemMgt`: add, validate, remove and configure the items of a group.
#[interface("39c13a54-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCItemMgt: IUnknown {
    pub fn AddItems(
        &self,
        dwCount: u32,
        pItemArray: *const OPCITEMDEF,
        ppAddResults: *mut *mut OPCITEMRESULT,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn ValidateItems(
        &self,
        dwCount: u32,
        pItemArray: *const OPCITEMDEF,
        bBlobUpdate: BOOL,
        ppValidationResults: *mut *mut OPCITEMRESULT,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn RemoveItems(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn SetActiveState(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        bActive: BOOL,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn SetClientHandles(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        phClient: *const OPCHANDLE,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn SetDatatypes(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pRequestedDatatypes: *const VARTYPE,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    /// `S_FALSE` with an empty enumerator when the group has no items.
    pub fn CreateEnumerator(&self, riid: *const GUID, ppUnk: *mut Option<IUnknown>) -> HRESULT;
}

/// `IEnumOPCItemAttributes`: enumerator returned by `IOPCItemMgt::CreateEnumerator`.
#[interface("39c13a55-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IEnumOPCItemAttributes: IUnknown {
    /// `S_FALSE` when fewer than `celt` elements were returned.
    pub fn Next(
        &self,
        celt: u32,
        ppItemArray: *mut *mut OPCITEMATTRIBUTES,
        pceltFetched: *mut u32,
    ) -> HRESULT;
    /// `S_FALSE` when fewer than `celt` elements were skipped.
    pub fn Skip(&self, celt: u32) -> HRESULT;
    pub fn Reset(&self) -> Result<()>;
    pub fn Clone(&self, ppEnumItemAttributes: *mut Option<IEnumOPCItemAttributes>) -> Result<()>;
}

/// `IOPCItemDeadbandMgt` (DA 3.00): per-item percent deadband.
#[interface("5946da93-8b39-4ec8-ab3d-aa73df5bc86f")]
pub unsafe trait IOPCItemDeadbandMgt: IUnknown {
    pub fn SetItemDeadband(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pPercentDeadband: *const f32,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn GetItemDeadband(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        ppPercentDeadband: *mut *mut f32,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn ClearItemDeadband(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
}

/// `IOPCItemSamplingMgt` (DA 3.00, optional): per-item sampling rate and buffering.
#[interface("3e22d313-f08b-41a5-86c8-95e95cb49ffc")]
pub unsafe trait IOPCItemSamplingMgt: IUnknown {
    pub fn SetItemSamplingRate(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pdwRequestedSamplingRate: *const u32,
        ppdwRevisedSamplingRate: *mut *mut u32,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn GetItemSamplingRate(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        ppdwSamplingRate: *mut *mut u32,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn ClearItemSamplingRate(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn SetItemBufferEnable(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        pbEnable: *const BOOL,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
    pub fn GetItemBufferEnable(
        &self,
        dwCount: u32,
        phServer: *const OPCHANDLE,
        ppbEnable: *mut *mut BOOL,
        ppErrors: *mut *mut HRESULT,
    ) -> HRESULT;
}

// ---------------------------------------------------------------------------------------
// Client callback
// ---------------------------------------------------------------------------------------

/// `IOPCDataCallback`: implemented by the client, advised on the group's connection point.
/// The server calls it; every array is `[size_is(dwCount), in]` and owned by the caller.
#[interface("39c13a70-011e-11d0-9675-0020afd8adb3")]
pub unsafe trait IOPCDataCallback: IUnknown {
    pub fn OnDataChange(
        &self,
        dwTransid: u32,
        hGroup: OPCHANDLE,
        hrMasterquality: HRESULT,
        hrMastererror: HRESULT,
        dwCount: u32,
        phClientItems: *const OPCHANDLE,
        pvValues: *const VARIANT,
        pwQualities: *const u16,
        pftTimeStamps: *const FILETIME,
        pErrors: *const HRESULT,
    ) -> Result<()>;
    pub fn OnReadComplete(
        &self,
        dwTransid: u32,
        hGroup: OPCHANDLE,
        hrMasterquality: HRESULT,
        hrMastererror: HRESULT,
        dwCount: u32,
        phClientItems: *const OPCHANDLE,
        pvValues: *const VARIANT,
        pwQualities: *const u16,
        pftTimeStamps: *const FILETIME,
        pErrors: *const HRESULT,
    ) -> Result<()>;
    pub fn OnWriteComplete(
        &self,
        dwTransid: u32,
        hGroup: OPCHANDLE,
        hrMastererr: HRESULT,
        dwCount: u32,
        pClienthandles: *const OPCHANDLE,
        pErrors: *const HRESULT,
    ) -> Result<()>;
    pub fn OnCancelComplete(&self, dwTransid: u32, hGroup: OPCHANDLE) -> Result<()>;
}
