//! The client side of a server browser (`OPC.ServerList.1`: ours, OpcServerList.exe, or the
//! OPC Foundation's OpcEnum), and the component categories manager (`ICatInformation`) as
//! the fallback where no browser is registered: used by `opcdiag servers` and the tests.

use super::take_wstr;
use ctopc_com::interfaces::{IOPCEnumGUID, IOPCServerList, IOPCServerList2};
use ctopc_registration::CLSID_OPC_SERVER_LIST;
use windows::core::{Interface, GUID, HSTRING, PWSTR};
use windows::Win32::Foundation::S_OK;
use windows::Win32::System::Com::{
    CoCreateInstance, ICatInformation, IEnumGUID, CLSCTX_INPROC_SERVER, CLSCTX_LOCAL_SERVER,
};

/// `CLSID_StdComponentCategoriesMgr` (comcat.h).
pub const CLSID_STD_COMPONENT_CATEGORIES_MGR: GUID =
    GUID::from_u128(0x0002e005_0000_0000_c000_000000000046);

/// What `GetClassDetails` tells about a class.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClassDetails {
    pub progid: String,
    pub user_type: String,
    /// IOPCServerList2 only (`None` through IOPCServerList).
    pub version_independent_progid: Option<String>,
}

/// A connection to the machine's server browser.
pub struct ServerBrowser {
    pub list: IOPCServerList,
    /// `None` for a browser without IOPCServerList2 (OpcEnum before 2.0).
    pub list2: Option<IOPCServerList2>,
}

/// Drains an `IEnumGUID`-shaped enumerator (`next` is its Next with a batch of 16).
fn drain(
    mut next: impl FnMut(&mut [GUID; 16], &mut u32) -> windows::core::HRESULT,
) -> windows::core::Result<Vec<GUID>> {
    let mut out = Vec::new();
    loop {
        let mut batch = [GUID::zeroed(); 16];
        let mut got = 0u32;
        let hr = next(&mut batch, &mut got);
        hr.ok()?;
        out.extend_from_slice(&batch[..(got as usize).min(batch.len())]);
        if hr != S_OK || got == 0 {
            return Ok(out);
        }
    }
}

/// Every GUID of an `IEnumGUID`.
pub fn enum_guids(e: &IEnumGUID) -> windows::core::Result<Vec<GUID>> {
    // SAFETY: `batch` has room for 16 GUIDs, `got` receives the count.
    drain(|batch, got| unsafe { e.Next(batch, Some(got)) })
}

/// Every GUID of an `IOPCEnumGUID`.
pub fn opc_enum_guids(e: &IOPCEnumGUID) -> windows::core::Result<Vec<GUID>> {
    // SAFETY: `batch` has room for 16 GUIDs, `got` receives the count.
    drain(|batch, got| unsafe { e.Next(16, batch.as_mut_ptr(), got) })
}

impl ServerBrowser {
    /// Creates `OPC.ServerList.1` (by its CLSID, as clients do).
    pub fn connect() -> windows::core::Result<ServerBrowser> {
        let clsid = GUID::from_u128(CLSID_OPC_SERVER_LIST);
        // SAFETY: a plain activation of a registered class.
        let list: IOPCServerList = unsafe { CoCreateInstance(&clsid, None, CLSCTX_LOCAL_SERVER)? };
        let list2 = list.cast::<IOPCServerList2>().ok();
        Ok(ServerBrowser { list, list2 })
    }

    /// The CLSIDs implementing any of `implemented` (and requiring only `required`),
    /// through IOPCServerList (IEnumGUID).
    pub fn classes(
        &self,
        implemented: &[GUID],
        required: &[GUID],
    ) -> windows::core::Result<Vec<GUID>> {
        let mut e: Option<IEnumGUID> = None;
        // SAFETY: the arrays live for the call; `e` receives the enumerator.
        unsafe {
            self.list.EnumClassesOfCategories(
                implemented.len() as u32,
                implemented.as_ptr(),
                required.len() as u32,
                required.as_ptr(),
                &mut e,
            )?
        };
        match e {
            Some(e) => enum_guids(&e),
            None => Ok(Vec::new()),
        }
    }

    /// As [`Self::classes`], through IOPCServerList2 (IOPCEnumGUID); `None` without it.
    pub fn classes2(
        &self,
        implemented: &[GUID],
        required: &[GUID],
    ) -> Option<windows::core::Result<Vec<GUID>>> {
        let list2 = self.list2.as_ref()?;
        let mut e: Option<IOPCEnumGUID> = None;
        // SAFETY: the arrays live for the call; `e` receives the enumerator.
        let r = unsafe {
            list2.EnumClassesOfCategories(
                implemented.len() as u32,
                implemented.as_ptr(),
                required.len() as u32,
                required.as_ptr(),
                &mut e,
            )
        };
        Some(r.and_then(|()| match e {
            Some(e) => opc_enum_guids(&e),
            None => Ok(Vec::new()),
        }))
    }

    /// GetClassDetails: IOPCServerList2's (with the version-independent ProgID) when the
    /// browser has it, else IOPCServerList's.
    pub fn details(&self, clsid: &GUID) -> windows::core::Result<ClassDetails> {
        let (mut progid, mut user_type, mut ver) = (PWSTR::null(), PWSTR::null(), PWSTR::null());
        if let Some(list2) = &self.list2 {
            // SAFETY: valid GUID and out-pointers; the strings are taken over below.
            let r = unsafe { list2.GetClassDetails(clsid, &mut progid, &mut user_type, &mut ver) };
            // SAFETY: NULL or the CoTaskMem strings the call handed out, ours, taken once.
            let (p, u, v) = unsafe { (take_wstr(progid), take_wstr(user_type), take_wstr(ver)) };
            r?;
            return Ok(ClassDetails {
                progid: p.unwrap_or_default(),
                user_type: u.unwrap_or_default(),
                version_independent_progid: Some(v.unwrap_or_default()),
            });
        }
        self.details1(clsid)
    }

    /// GetClassDetails through IOPCServerList.
    pub fn details1(&self, clsid: &GUID) -> windows::core::Result<ClassDetails> {
        let (mut progid, mut user_type) = (PWSTR::null(), PWSTR::null());
        // SAFETY: valid GUID and out-pointers; the strings are taken over below.
        let r = unsafe {
            self.list
                .GetClassDetails(clsid, &mut progid, &mut user_type)
        };
        // SAFETY: NULL or the CoTaskMem strings the call handed out, ours, taken once.
        let (p, u) = unsafe { (take_wstr(progid), take_wstr(user_type)) };
        r?;
        Ok(ClassDetails {
            progid: p.unwrap_or_default(),
            user_type: u.unwrap_or_default(),
            version_independent_progid: None,
        })
    }

    /// CLSIDFromProgID through IOPCServerList.
    pub fn clsid_from_progid(&self, progid: &str) -> windows::core::Result<GUID> {
        let p = HSTRING::from(progid);
        let mut clsid = GUID::zeroed();
        // SAFETY: a NUL-terminated string and a GUID out-parameter.
        unsafe {
            self.list
                .CLSIDFromProgID(windows::core::PCWSTR(p.as_ptr()), &mut clsid)?
        };
        Ok(clsid)
    }
}

/// The fallback without a browser: `ICatInformation::EnumClassesOfCategories` (this
/// process's registry view only).
pub fn classes_by_category_manager(implemented: &[GUID]) -> windows::core::Result<Vec<GUID>> {
    // SAFETY: a plain activation of the system's component categories manager.
    let cat: ICatInformation = unsafe {
        CoCreateInstance(
            &CLSID_STD_COMPONENT_CATEGORIES_MGR,
            None,
            CLSCTX_INPROC_SERVER,
        )?
    };
    // SAFETY: the array lives for the call.
    let e = unsafe { cat.EnumClassesOfCategories(implemented, &[])? };
    enum_guids(&e)
}
