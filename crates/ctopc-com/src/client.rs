//! A safe OPC DA client over the raw interfaces: used by the end-to-end tests, the
//! benchmarks and the `opcdiag` diagnostic client. It works against any OPC DA server.

use crate::interfaces::*;
use ctopc_core::Timestamp;
use std::ffi::c_void;
use windows::core::{Interface, IUnknown, HSTRING, PWSTR};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Com::{
    CLSIDFromProgID, CoCreateInstance, CoInitializeEx, CoTaskMemFree, CoUninitialize, CLSCTX_LOCAL_SERVER,
    COINIT_APARTMENTTHREADED, COINIT_MULTITHREADED,
};

/// COM initialised on this thread for the lifetime of the value.
pub struct ComThread(());

impl ComThread {
    /// Joins the multithreaded apartment.
    pub fn mta() -> windows::core::Result<ComThread> {
        // SAFETY: paired with CoUninitialize in Drop, on this thread.
        unsafe { CoInitializeEx(None, COINIT_MULTITHREADED).ok()? };
        Ok(ComThread(()))
    }
    /// Makes this thread a single-threaded apartment (it must pump messages to get callbacks).
    pub fn sta() -> windows::core::Result<ComThread> {
        // SAFETY: as above.
        unsafe { CoInitializeEx(None, COINIT_APARTMENTTHREADED).ok()? };
        Ok(ComThread(()))
    }
}

impl Drop for ComThread {
    fn drop(&mut self) {
        // SAFETY: this thread initialised COM in the constructor.
        unsafe { CoUninitialize() };
    }
}

/// Takes ownership of a CoTaskMem string: returns its text and frees it.
pub fn take_wstr(p: PWSTR) -> Option<String> {
    if p.is_null() {
        return None;
    }
    // SAFETY: a non-null string out-parameter is a NUL-terminated CoTaskMem UTF-16 string
    // owned by the caller from now on; read once, then freed once.
    let s = unsafe { p.to_string() }.ok();
    // SAFETY: see above.
    unsafe { CoTaskMemFree(Some(p.0 as *const c_void)) };
    s
}

/// Takes ownership of a CoTaskMem array of `n` elements: copies it out and frees it.
pub fn take_array<T: Copy>(p: *mut T, n: usize) -> Vec<T> {
    if p.is_null() {
        return Vec::new();
    }
    // SAFETY: the callee allocated `n` elements with CoTaskMemAlloc; copied, then freed once.
    let v = unsafe { std::slice::from_raw_parts(p, n) }.to_vec();
    // SAFETY: as above.
    unsafe { CoTaskMemFree(Some(p as *const c_void)) };
    v
}

pub fn timestamp(ft: FILETIME) -> Timestamp {
    Timestamp::from_filetime_parts(ft.dwLowDateTime, ft.dwHighDateTime)
}

/// `OPCSERVERSTATUS`, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct ServerStatus {
    pub start_time: Timestamp,
    pub current_time: Timestamp,
    pub last_update_time: Timestamp,
    pub state: u32,
    pub group_count: u32,
    pub band_width: u32,
    pub version: (u16, u16, u16),
    pub vendor_info: Option<String>,
}

/// A connection to one OPC DA server object.
pub struct Server {
    pub unknown: IUnknown,
    pub server: IOPCServer,
    pub common: IOPCCommon,
}

impl Server {
    /// Creates the server registered under `progid` (out of process) and asks it for
    /// IOPCServer and IOPCCommon.
    pub fn connect(progid: &str) -> windows::core::Result<Server> {
        let progid = HSTRING::from(progid);
        // SAFETY: valid string; COM is initialised by the caller (ComThread).
        let clsid = unsafe { CLSIDFromProgID(&progid)? };
        // SAFETY: as above.
        let unknown: IUnknown = unsafe { CoCreateInstance(&clsid, None, CLSCTX_LOCAL_SERVER)? };
        Self::from_unknown(unknown)
    }

    pub fn from_unknown(unknown: IUnknown) -> windows::core::Result<Server> {
        let server = unknown.cast::<IOPCServer>()?;
        let common = unknown.cast::<IOPCCommon>()?;
        Ok(Server { unknown, server, common })
    }

    pub fn status(&self) -> windows::core::Result<ServerStatus> {
        let mut p: *mut OPCSERVERSTATUS = std::ptr::null_mut();
        // SAFETY: `p` is a valid out-pointer; on success it holds a CoTaskMem block.
        unsafe { self.server.GetStatus(&mut p)? };
        if p.is_null() {
            return Err(windows::Win32::Foundation::E_POINTER.into());
        }
        // SAFETY: non-null block of one OPCSERVERSTATUS from the server.
        let s = unsafe { *p };
        let vendor_info = take_wstr(s.szVendorInfo);
        take_array(p, 1);
        Ok(ServerStatus {
            start_time: timestamp(s.ftStartTime),
            current_time: timestamp(s.ftCurrentTime),
            last_update_time: timestamp(s.ftLastUpdateTime),
            state: s.dwServerState.0 as u32,
            group_count: s.dwGroupCount,
            band_width: s.dwBandWidth,
            version: (s.wMajorVersion, s.wMinorVersion, s.wBuildNumber),
            vendor_info,
        })
    }

    pub fn set_locale(&self, lcid: u32) -> windows::core::Result<()> {
        // SAFETY: plain value argument.
        unsafe { self.common.SetLocaleID(lcid) }
    }

    pub fn locale(&self) -> windows::core::Result<u32> {
        let mut lcid = 0;
        // SAFETY: valid out-pointer.
        unsafe { self.common.GetLocaleID(&mut lcid)? };
        Ok(lcid)
    }

    pub fn available_locales(&self) -> windows::core::Result<Vec<u32>> {
        let mut n = 0u32;
        let mut p: *mut u32 = std::ptr::null_mut();
        // SAFETY: valid out-pointers; the array is CoTaskMem owned by us afterwards.
        unsafe { self.common.QueryAvailableLocaleIDs(&mut n, &mut p)? };
        Ok(take_array(p, n as usize))
    }

    pub fn set_client_name(&self, name: &str) -> windows::core::Result<()> {
        let name = HSTRING::from(name);
        // SAFETY: valid NUL-terminated string for the call.
        unsafe { self.common.SetClientName(windows::core::PCWSTR(name.as_ptr())) }
    }

    /// IOPCCommon::GetErrorString (in the session's locale).
    pub fn error_string(&self, code: windows::core::HRESULT) -> windows::core::Result<Option<String>> {
        let mut p = PWSTR::null();
        // SAFETY: valid out-pointer.
        unsafe { self.common.GetErrorString(code, &mut p)? };
        Ok(take_wstr(p))
    }

    /// IOPCServer::GetErrorString in `lcid`.
    pub fn error_string_in(&self, code: windows::core::HRESULT, lcid: u32) -> windows::core::Result<Option<String>> {
        let mut p = PWSTR::null();
        // SAFETY: valid out-pointer.
        unsafe { self.server.GetErrorString(code, lcid, &mut p)? };
        Ok(take_wstr(p))
    }
}
