//! A safe OPC DA client over the raw interfaces (`ctopc_com::interfaces`): used by the
//! end-to-end tests, the benchmarks and the `opcdiag` diagnostic client. It works against
//! any OPC DA server. Windows only; a thread joins COM through
//! `ctopc_com::apartment::Apartment` before it calls.
#![cfg(windows)]

use ctopc_com::interfaces::*;
use ctopc_core::Timestamp;
use std::ffi::c_void;
use windows::core::{IUnknown, Interface, HSTRING, PWSTR};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Com::{
    CLSIDFromProgID, CoCreateInstance, CoTaskMemFree, CLSCTX_LOCAL_SERVER,
};

/// Takes ownership of a CoTaskMem string: returns its text and frees it.
///
/// # Safety
/// `p` is NULL or a NUL-terminated UTF-16 string in a CoTaskMem block that the caller owns
/// (a string out-parameter a call has just handed out), not yet freed and not used
/// afterwards.
pub unsafe fn take_wstr(p: PWSTR) -> Option<String> {
    if p.is_null() {
        return None;
    }
    // SAFETY: contract of this function: a NUL-terminated string, read once, then freed once.
    let s = unsafe { p.to_string() }.ok();
    // SAFETY: as above.
    unsafe { CoTaskMemFree(Some(p.0 as *const c_void)) };
    s
}

/// Takes ownership of a CoTaskMem array of `n` elements: copies it out and frees it.
///
/// # Safety
/// `p` is NULL or a CoTaskMem block of at least `n` initialised elements that the caller
/// owns (an out-array a call has just handed out) and does not use afterwards.
pub unsafe fn take_array<T: Copy>(p: *mut T, n: usize) -> Vec<T> {
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
        // SAFETY: valid string; COM is initialised by the caller (`Apartment`).
        let clsid = unsafe { CLSIDFromProgID(&progid)? };
        // SAFETY: as above.
        let unknown: IUnknown = unsafe { CoCreateInstance(&clsid, None, CLSCTX_LOCAL_SERVER)? };
        Self::from_unknown(unknown)
    }

    pub fn from_unknown(unknown: IUnknown) -> windows::core::Result<Server> {
        let server = unknown.cast::<IOPCServer>()?;
        let common = unknown.cast::<IOPCCommon>()?;
        Ok(Server {
            unknown,
            server,
            common,
        })
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
        // SAFETY: the block's vendor string (NULL or CoTaskMem) is ours, taken once.
        let vendor_info = unsafe { take_wstr(s.szVendorInfo) };
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        unsafe { take_array(p, 1) };
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
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        Ok(unsafe { take_array(p, n as usize) })
    }

    pub fn set_client_name(&self, name: &str) -> windows::core::Result<()> {
        let name = HSTRING::from(name);
        // SAFETY: valid NUL-terminated string for the call.
        unsafe {
            self.common
                .SetClientName(windows::core::PCWSTR(name.as_ptr()))
        }
    }

    /// IOPCCommon::GetErrorString (in the session's locale).
    pub fn error_string(
        &self,
        code: windows::core::HRESULT,
    ) -> windows::core::Result<Option<String>> {
        let mut p = PWSTR::null();
        // SAFETY: valid out-pointer.
        unsafe { self.common.GetErrorString(code, &mut p)? };
        // SAFETY: NULL or the CoTaskMem string the call handed out, ours.
        Ok(unsafe { take_wstr(p) })
    }

    /// IOPCServer::GetErrorString in `lcid`.
    pub fn error_string_in(
        &self,
        code: windows::core::HRESULT,
        lcid: u32,
    ) -> windows::core::Result<Option<String>> {
        let mut p = PWSTR::null();
        // SAFETY: valid out-pointer.
        unsafe { self.server.GetErrorString(code, lcid, &mut p)? };
        // SAFETY: NULL or the CoTaskMem string the call handed out, ours.
        Ok(unsafe { take_wstr(p) })
    }
}

// ---- group I/O: IOPCSyncIO/IOPCSyncIO2 and IOPCAsyncIO2/IOPCAsyncIO3 --------------------

/// One item of a synchronous read (an OPCITEMSTATE, or one position of ReadMaxAge's
/// arrays), owned. `client_handle` is 0 for ReadMaxAge (it returns none).
#[derive(Debug, Clone, PartialEq)]
pub struct ReadItem {
    pub client_handle: u32,
    /// The VARTYPE the server sent.
    pub vt: u16,
    /// The value (`Value::Empty` when VT_EMPTY or not representable).
    pub value: ctopc_core::Value,
    pub quality: u16,
    pub timestamp: Timestamp,
    pub error: windows::core::HRESULT,
}

/// The HRESULT of a per-item method: failure codes become `Err`, S_OK / S_FALSE stay.
fn per_item_hr(hr: windows::core::HRESULT) -> windows::core::Result<windows::core::HRESULT> {
    if hr.is_err() {
        Err(hr.into())
    } else {
        Ok(hr)
    }
}

/// Takes a CoTaskMem VARIANT array of `n` elements: converts, clears and frees it.
///
/// # Safety
/// As [`take_array`], the elements initialised VARIANTs.
pub unsafe fn take_variants(
    p: *mut windows::Win32::System::Variant::VARIANT,
    n: usize,
) -> Vec<(u16, ctopc_core::Value)> {
    if p.is_null() {
        return Vec::new();
    }
    // SAFETY: the callee allocated `n` initialised VARIANTs with CoTaskMemAlloc; each is
    // read, then cleared once, then the block is freed once.
    let slice = unsafe { std::slice::from_raw_parts_mut(p, n) };
    let out = slice
        .iter_mut()
        .map(|v| {
            let r = (
                ctopc_com::variant::var_type(v).0,
                ctopc_com::variant::from_variant(v).unwrap_or(ctopc_core::Value::Empty),
            );
            ctopc_com::variant::clear(v);
            r
        })
        .collect();
    // SAFETY: as above.
    unsafe { CoTaskMemFree(Some(p as *const c_void)) };
    out
}

/// VARIANTs for values to write, cleared on drop.
struct InVariants(Vec<windows::Win32::System::Variant::VARIANT>);

impl InVariants {
    fn new<'a>(
        values: impl Iterator<Item = &'a ctopc_core::Value>,
    ) -> windows::core::Result<InVariants> {
        let mut v = InVariants(Vec::new());
        for value in values {
            v.0.push(ctopc_com::variant::to_variant(value)?);
        }
        Ok(v)
    }
}

impl Drop for InVariants {
    fn drop(&mut self) {
        for v in &mut self.0 {
            ctopc_com::variant::clear(v);
        }
    }
}

/// IOPCSyncIO::Read: (S_OK or S_FALSE, one item per handle).
pub fn sync_read(
    io: &IOPCSyncIO,
    source: OPCDATASOURCE,
    handles: &[u32],
) -> windows::core::Result<(windows::core::HRESULT, Vec<ReadItem>)> {
    let mut states: *mut OPCITEMSTATE = std::ptr::null_mut();
    let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
    // SAFETY: `handles` holds `len` elements; valid out-pointers.
    let hr = per_item_hr(unsafe {
        io.Read(
            source,
            handles.len() as u32,
            handles.as_ptr(),
            &mut states,
            &mut errors,
        )
    })?;
    let n = handles.len();
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    let errors = unsafe { take_array(errors, n) };
    let mut out = Vec::with_capacity(n);
    if !states.is_null() {
        // SAFETY: the server allocated `n` OPCITEMSTATEs; each VARIANT is read and cleared
        // once, then the block is freed once.
        let slice = unsafe { std::slice::from_raw_parts_mut(states, n) };
        for (i, s) in slice.iter_mut().enumerate() {
            out.push(ReadItem {
                client_handle: s.hClient,
                vt: ctopc_com::variant::var_type(&s.vDataValue).0,
                value: ctopc_com::variant::from_variant(&s.vDataValue)
                    .unwrap_or(ctopc_core::Value::Empty),
                quality: s.wQuality,
                timestamp: timestamp(s.ftTimeStamp),
                error: errors.get(i).copied().unwrap_or_default(),
            });
            ctopc_com::variant::clear(&mut s.vDataValue);
        }
        // SAFETY: as above.
        unsafe { CoTaskMemFree(Some(states as *const c_void)) };
    }
    Ok((hr, out))
}

/// IOPCSyncIO::Write: (S_OK or S_FALSE, per-item errors).
pub fn sync_write(
    io: &IOPCSyncIO,
    items: &[(u32, ctopc_core::Value)],
) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
    let handles: Vec<u32> = items.iter().map(|(h, _)| *h).collect();
    let values = InVariants::new(items.iter().map(|(_, v)| v))?;
    let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
    // SAFETY: both arrays hold `len` elements and live for the call; valid out-pointer.
    let hr = per_item_hr(unsafe {
        io.Write(
            handles.len() as u32,
            handles.as_ptr(),
            values.0.as_ptr(),
            &mut errors,
        )
    })?;
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    Ok((hr, unsafe { take_array(errors, handles.len()) }))
}

/// IOPCSyncIO2::ReadMaxAge for `(server handle, MaxAge ms)` items.
pub fn read_max_age(
    io: &IOPCSyncIO2,
    items: &[(u32, u32)],
) -> windows::core::Result<(windows::core::HRESULT, Vec<ReadItem>)> {
    let handles: Vec<u32> = items.iter().map(|i| i.0).collect();
    let ages: Vec<u32> = items.iter().map(|i| i.1).collect();
    let n = items.len();
    let mut values = std::ptr::null_mut();
    let mut qualities: *mut u16 = std::ptr::null_mut();
    let mut times: *mut FILETIME = std::ptr::null_mut();
    let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
    // SAFETY: the arrays hold `n` elements; valid out-pointers.
    let hr = per_item_hr(unsafe {
        io.ReadMaxAge(
            n as u32,
            handles.as_ptr(),
            ages.as_ptr(),
            &mut values,
            &mut qualities,
            &mut times,
            &mut errors,
        )
    })?;
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    let values = unsafe { take_variants(values, n) };
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    let qualities = unsafe { take_array(qualities, n) };
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    let times = unsafe { take_array(times, n) };
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    let errors = unsafe { take_array(errors, n) };
    let out = (0..n)
        .map(|i| {
            let (vt, value) = values
                .get(i)
                .cloned()
                .unwrap_or((0, ctopc_core::Value::Empty));
            ReadItem {
                client_handle: 0,
                vt,
                value,
                quality: qualities.get(i).copied().unwrap_or(0),
                timestamp: times.get(i).copied().map(timestamp).unwrap_or_default(),
                error: errors.get(i).copied().unwrap_or_default(),
            }
        })
        .collect();
    Ok((hr, out))
}

/// OPCITEMVQTs for `items` (the VARIANTs are owned by `values`).
fn item_vqts(items: &[(u32, ctopc_core::model::ItemVqt)], values: &InVariants) -> Vec<OPCITEMVQT> {
    items
        .iter()
        .zip(&values.0)
        .map(|((_, vqt), v)| OPCITEMVQT {
            // A bitwise copy: `values` keeps ownership and clears it.
            // SAFETY: VARIANT is plain data; the copy is never cleared.
            vDataValue: unsafe { std::ptr::read(v) },
            bQualitySpecified: vqt.quality.is_some().into(),
            wQuality: vqt.quality.map_or(0, |q| q.0),
            wReserved: 0,
            bTimeStampSpecified: vqt.timestamp.is_some().into(),
            dwReserved: 0,
            ftTimeStamp: vqt
                .timestamp
                .map(|t| {
                    let (lo, hi) = t.filetime_parts();
                    FILETIME {
                        dwLowDateTime: lo,
                        dwHighDateTime: hi,
                    }
                })
                .unwrap_or_default(),
        })
        .collect()
}

/// IOPCSyncIO2::WriteVQT: (S_OK or S_FALSE, per-item errors).
pub fn write_vqt(
    io: &IOPCSyncIO2,
    items: &[(u32, ctopc_core::model::ItemVqt)],
) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
    let handles: Vec<u32> = items.iter().map(|(h, _)| *h).collect();
    let values = InVariants::new(items.iter().map(|(_, v)| &v.value))?;
    let vqts = item_vqts(items, &values);
    let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
    // SAFETY: both arrays hold `len` elements and live for the call; valid out-pointer.
    let hr = per_item_hr(unsafe {
        io.WriteVQT(
            handles.len() as u32,
            handles.as_ptr(),
            vqts.as_ptr(),
            &mut errors,
        )
    })?;
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    Ok((hr, unsafe { take_array(errors, handles.len()) }))
}

/// What an asynchronous call returns: S_OK or S_FALSE, the server's cancel ID, per-item
/// errors.
pub type AsyncCall = (windows::core::HRESULT, u32, Vec<windows::core::HRESULT>);

/// IOPCAsyncIO2::Read.
pub fn async_read(
    io: &IOPCAsyncIO2,
    handles: &[u32],
    transaction: u32,
) -> windows::core::Result<AsyncCall> {
    let mut cancel = 0u32;
    let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
    // SAFETY: `handles` holds `len` elements; valid out-pointers.
    let hr = per_item_hr(unsafe {
        io.Read(
            handles.len() as u32,
            handles.as_ptr(),
            transaction,
            &mut cancel,
            &mut errors,
        )
    })?;
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    Ok((hr, cancel, unsafe { take_array(errors, handles.len()) }))
}

/// IOPCAsyncIO2::Write.
pub fn async_write(
    io: &IOPCAsyncIO2,
    items: &[(u32, ctopc_core::Value)],
    transaction: u32,
) -> windows::core::Result<AsyncCall> {
    let handles: Vec<u32> = items.iter().map(|(h, _)| *h).collect();
    let values = InVariants::new(items.iter().map(|(_, v)| v))?;
    let mut cancel = 0u32;
    let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
    // SAFETY: both arrays hold `len` elements and live for the call; valid out-pointers.
    let hr = per_item_hr(unsafe {
        io.Write(
            handles.len() as u32,
            handles.as_ptr(),
            values.0.as_ptr(),
            transaction,
            &mut cancel,
            &mut errors,
        )
    })?;
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    Ok((hr, cancel, unsafe { take_array(errors, handles.len()) }))
}

/// IOPCAsyncIO2::Refresh2: the server's cancel ID.
pub fn refresh2(
    io: &IOPCAsyncIO2,
    source: OPCDATASOURCE,
    transaction: u32,
) -> windows::core::Result<u32> {
    let mut cancel = 0u32;
    // SAFETY: valid out-pointer.
    unsafe { io.Refresh2(source, transaction, &mut cancel)? };
    Ok(cancel)
}

/// IOPCAsyncIO2::GetEnable.
pub fn get_enable(io: &IOPCAsyncIO2) -> windows::core::Result<bool> {
    let mut b = windows::core::BOOL(0);
    // SAFETY: valid out-pointer.
    unsafe { io.GetEnable(&mut b)? };
    Ok(b.as_bool())
}

/// IOPCAsyncIO3::ReadMaxAge for `(server handle, MaxAge ms)` items.
pub fn async_read_max_age(
    io: &IOPCAsyncIO3,
    items: &[(u32, u32)],
    transaction: u32,
) -> windows::core::Result<AsyncCall> {
    let handles: Vec<u32> = items.iter().map(|i| i.0).collect();
    let ages: Vec<u32> = items.iter().map(|i| i.1).collect();
    let mut cancel = 0u32;
    let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
    // SAFETY: the arrays hold `len` elements; valid out-pointers.
    let hr = per_item_hr(unsafe {
        io.ReadMaxAge(
            handles.len() as u32,
            handles.as_ptr(),
            ages.as_ptr(),
            transaction,
            &mut cancel,
            &mut errors,
        )
    })?;
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    Ok((hr, cancel, unsafe { take_array(errors, handles.len()) }))
}

/// IOPCAsyncIO3::WriteVQT.
pub fn async_write_vqt(
    io: &IOPCAsyncIO3,
    items: &[(u32, ctopc_core::model::ItemVqt)],
    transaction: u32,
) -> windows::core::Result<AsyncCall> {
    let handles: Vec<u32> = items.iter().map(|(h, _)| *h).collect();
    let values = InVariants::new(items.iter().map(|(_, v)| &v.value))?;
    let vqts = item_vqts(items, &values);
    let mut cancel = 0u32;
    let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
    // SAFETY: both arrays hold `len` elements and live for the call; valid out-pointers.
    let hr = per_item_hr(unsafe {
        io.WriteVQT(
            handles.len() as u32,
            handles.as_ptr(),
            vqts.as_ptr(),
            transaction,
            &mut cancel,
            &mut errors,
        )
    })?;
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    Ok((hr, cancel, unsafe { take_array(errors, handles.len()) }))
}

/// IOPCAsyncIO3::RefreshMaxAge: the server's cancel ID.
pub fn refresh_max_age(
    io: &IOPCAsyncIO3,
    max_age: u32,
    transaction: u32,
) -> windows::core::Result<u32> {
    let mut cancel = 0u32;
    // SAFETY: valid out-pointer.
    unsafe { io.RefreshMaxAge(max_age, transaction, &mut cancel)? };
    Ok(cancel)
}

/// Connects an IOPCDataCallback sink to a group (its IConnectionPointContainer):
/// the Advise cookie.
pub fn advise_data_callback(
    group: &IUnknown,
    sink: &IOPCDataCallback,
) -> windows::core::Result<u32> {
    let cpc: windows::Win32::System::Com::IConnectionPointContainer = group.cast()?;
    // SAFETY: a valid IID pointer for the call.
    let cp = unsafe { cpc.FindConnectionPoint(&IID_IOPCDataCallback)? };
    // SAFETY: `sink` is a live interface pointer.
    unsafe { cp.Advise(&sink.cast::<IUnknown>()?) }
}

/// Disconnects the sink that `advise_data_callback` connected.
pub fn unadvise_data_callback(group: &IUnknown, cookie: u32) -> windows::core::Result<()> {
    let cpc: windows::Win32::System::Com::IConnectionPointContainer = group.cast()?;
    // SAFETY: a valid IID pointer for the call.
    let cp = unsafe { cpc.FindConnectionPoint(&IID_IOPCDataCallback)? };
    // SAFETY: plain value.
    unsafe { cp.Unadvise(cookie) }
}

// ---- group object: IOPCItemMgt, IOPCGroupStateMgt/2, IOPCItemDeadbandMgt, ----------------
// ---- IOPCItemSamplingMgt -------------------------------------------------------------------

/// An item to add or validate (OPCITEMDEF without a blob), owned.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemDef {
    pub item_id: String,
    pub access_path: String,
    pub active: bool,
    pub client_handle: u32,
    /// VT_EMPTY (0): the canonical type.
    pub requested_type: u16,
}

impl ItemDef {
    /// An active item in the default channel with its canonical type.
    pub fn new(item_id: &str, client_handle: u32) -> ItemDef {
        ItemDef {
            item_id: item_id.into(),
            access_path: String::new(),
            active: true,
            client_handle,
            requested_type: 0,
        }
    }
}

/// One OPCITEMRESULT with its per-item HRESULT.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ItemOutcome {
    pub server_handle: u32,
    pub canonical_type: u16,
    pub access_rights: u32,
    pub blob_size: u32,
    pub error: windows::core::HRESULT,
}

/// One OPCITEMATTRIBUTES, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemAttrs {
    pub access_path: Option<String>,
    pub item_id: Option<String>,
    pub active: bool,
    pub client_handle: u32,
    pub server_handle: u32,
    pub access_rights: u32,
    pub requested_type: u16,
    pub canonical_type: u16,
    pub eu_type: i32,
    /// The VARTYPE of vEUInfo and its value.
    pub eu_vt: u16,
    pub eu_info: ctopc_core::Value,
}

/// IOPCGroupStateMgt::GetState, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct GroupStateInfo {
    pub update_rate: u32,
    pub active: bool,
    pub name: Option<String>,
    pub time_bias: i32,
    pub percent_deadband: f32,
    pub lcid: u32,
    pub client_handle: u32,
    pub server_handle: u32,
}

/// IOPCGroupStateMgt::SetState arguments; `None` passes NULL (leave unchanged).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GroupStateChange {
    pub update_rate: Option<u32>,
    pub active: Option<bool>,
    pub time_bias: Option<i32>,
    pub percent_deadband: Option<f32>,
    pub lcid: Option<u32>,
    pub client_handle: Option<u32>,
}

/// Per-item HRESULT of a group method: failure codes become `Err`, S_OK / S_FALSE stay.
fn group_call_hr(hr: windows::core::HRESULT) -> windows::core::Result<windows::core::HRESULT> {
    if hr.is_err() {
        Err(hr.into())
    } else {
        Ok(hr)
    }
}

/// A group object's management interfaces (items, state, deadband, sampling).
pub struct OpcGroup {
    pub unknown: IUnknown,
    pub item_mgt: IOPCItemMgt,
    pub state_mgt: IOPCGroupStateMgt,
}

impl OpcGroup {
    pub fn from_unknown(unknown: IUnknown) -> windows::core::Result<OpcGroup> {
        let item_mgt = unknown.cast::<IOPCItemMgt>()?;
        let state_mgt = unknown.cast::<IOPCGroupStateMgt>()?;
        Ok(OpcGroup {
            unknown,
            item_mgt,
            state_mgt,
        })
    }

    fn item_call(
        &self,
        items: &[ItemDef],
        f: impl FnOnce(
            u32,
            *const OPCITEMDEF,
            *mut *mut OPCITEMRESULT,
            *mut *mut windows::core::HRESULT,
        ) -> windows::core::HRESULT,
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<ItemOutcome>)> {
        let ids: Vec<HSTRING> = items
            .iter()
            .map(|i| HSTRING::from(i.item_id.as_str()))
            .collect();
        let paths: Vec<HSTRING> = items
            .iter()
            .map(|i| HSTRING::from(i.access_path.as_str()))
            .collect();
        let defs: Vec<OPCITEMDEF> = items
            .iter()
            .zip(ids.iter().zip(&paths))
            .map(|(i, (id, path))| OPCITEMDEF {
                szAccessPath: PWSTR(path.as_ptr() as *mut u16),
                szItemID: PWSTR(id.as_ptr() as *mut u16),
                bActive: i.active.into(),
                hClient: i.client_handle,
                dwBlobSize: 0,
                pBlob: std::ptr::null_mut(),
                vtRequestedDataType: windows::Win32::System::Variant::VARENUM(i.requested_type),
                wReserved: 0,
            })
            .collect();
        let mut results: *mut OPCITEMRESULT = std::ptr::null_mut();
        let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
        let hr = group_call_hr(f(
            defs.len() as u32,
            defs.as_ptr(),
            &mut results,
            &mut errors,
        ))?;
        let n = items.len();
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let errors = unsafe { take_array(errors, n) };
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let results = unsafe { take_array(results, n) };
        let out = (0..n)
            .map(|i| {
                let r = results.get(i).copied().unwrap_or_default();
                if !r.pBlob.is_null() {
                    // SAFETY: a blob the server returned is CoTaskMem owned by us now.
                    unsafe { CoTaskMemFree(Some(r.pBlob as *const c_void)) };
                }
                ItemOutcome {
                    server_handle: r.hServer,
                    canonical_type: r.vtCanonicalDataType.0,
                    access_rights: r.dwAccessRights,
                    blob_size: r.dwBlobSize,
                    error: errors.get(i).copied().unwrap_or_default(),
                }
            })
            .collect();
        Ok((hr, out))
    }

    /// IOPCItemMgt::AddItems: (S_OK or S_FALSE, one outcome per item).
    pub fn add_items(
        &self,
        items: &[ItemDef],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<ItemOutcome>)> {
        // SAFETY: the definitions and their strings live for the call; valid out-pointers.
        self.item_call(items, |n, d, r, e| unsafe {
            self.item_mgt.AddItems(n, d, r, e)
        })
    }

    /// IOPCItemMgt::ValidateItems (no blob update).
    pub fn validate_items(
        &self,
        items: &[ItemDef],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<ItemOutcome>)> {
        // SAFETY: as above.
        self.item_call(items, |n, d, r, e| unsafe {
            self.item_mgt.ValidateItems(n, d, false.into(), r, e)
        })
    }

    fn errors_call(
        n: usize,
        f: impl FnOnce(*mut *mut windows::core::HRESULT) -> windows::core::HRESULT,
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
        let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
        let hr = group_call_hr(f(&mut errors))?;
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        Ok((hr, unsafe { take_array(errors, n) }))
    }

    fn values_call<T: Copy>(
        n: usize,
        f: impl FnOnce(*mut *mut T, *mut *mut windows::core::HRESULT) -> windows::core::HRESULT,
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<(T, windows::core::HRESULT)>)> {
        let mut values: *mut T = std::ptr::null_mut();
        let mut errors: *mut windows::core::HRESULT = std::ptr::null_mut();
        let hr = group_call_hr(f(&mut values, &mut errors))?;
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let values = unsafe { take_array(values, n) };
        // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
        let errors = unsafe { take_array(errors, n) };
        Ok((hr, values.into_iter().zip(errors).collect()))
    }

    pub fn remove_items(
        &self,
        handles: &[u32],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
        // SAFETY: `handles` lives for the call; valid out-pointer.
        Self::errors_call(handles.len(), |e| unsafe {
            self.item_mgt
                .RemoveItems(handles.len() as u32, handles.as_ptr(), e)
        })
    }

    pub fn set_active_state(
        &self,
        handles: &[u32],
        active: bool,
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
        // SAFETY: as above.
        Self::errors_call(handles.len(), |e| unsafe {
            self.item_mgt
                .SetActiveState(handles.len() as u32, handles.as_ptr(), active.into(), e)
        })
    }

    /// SetClientHandles for `(server handle, client handle)` pairs.
    pub fn set_client_handles(
        &self,
        items: &[(u32, u32)],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
        let (h, c): (Vec<u32>, Vec<u32>) = items.iter().copied().unzip();
        // SAFETY: both arrays hold `len` elements and live for the call.
        Self::errors_call(h.len(), |e| unsafe {
            self.item_mgt
                .SetClientHandles(h.len() as u32, h.as_ptr(), c.as_ptr(), e)
        })
    }

    /// SetDatatypes for `(server handle, VARTYPE)` pairs.
    pub fn set_datatypes(
        &self,
        items: &[(u32, u16)],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
        let h: Vec<u32> = items.iter().map(|i| i.0).collect();
        let t: Vec<VARTYPE> = items
            .iter()
            .map(|i| windows::Win32::System::Variant::VARENUM(i.1))
            .collect();
        // SAFETY: both arrays hold `len` elements and live for the call.
        Self::errors_call(h.len(), |e| unsafe {
            self.item_mgt
                .SetDatatypes(h.len() as u32, h.as_ptr(), t.as_ptr(), e)
        })
    }

    /// IOPCItemMgt::CreateEnumerator(IID_IEnumOPCItemAttributes): the HRESULT (S_FALSE
    /// when the group has no items) and the enumerator.
    pub fn item_enumerator(
        &self,
    ) -> windows::core::Result<(windows::core::HRESULT, IEnumOPCItemAttributes)> {
        let mut unk: Option<IUnknown> = None;
        // SAFETY: valid IID and out-pointer.
        let hr = group_call_hr(unsafe {
            self.item_mgt
                .CreateEnumerator(&IEnumOPCItemAttributes::IID, &mut unk)
        })?;
        let unk =
            unk.ok_or_else(|| windows::core::Error::from(windows::Win32::Foundation::E_POINTER))?;
        Ok((hr, unk.cast()?))
    }

    /// IEnumOPCItemAttributes::Next(celt): (S_OK or S_FALSE, the items).
    pub fn next_attributes(
        e: &IEnumOPCItemAttributes,
        celt: u32,
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<ItemAttrs>)> {
        let mut p: *mut OPCITEMATTRIBUTES = std::ptr::null_mut();
        let mut fetched = 0u32;
        // SAFETY: valid out-pointers.
        let hr = group_call_hr(unsafe { e.Next(celt, &mut p, &mut fetched) })?;
        let mut out = Vec::with_capacity(fetched as usize);
        if !p.is_null() {
            // SAFETY: the server allocated `fetched` OPCITEMATTRIBUTES; each string is taken
            // once, each VARIANT read and cleared once, then the block freed once.
            let slice = unsafe { std::slice::from_raw_parts_mut(p, fetched as usize) };
            for a in slice.iter_mut() {
                out.push(ItemAttrs {
                    // SAFETY: each element's strings are NULL or CoTaskMem, ours, taken once
                    // (see the slice above).
                    access_path: unsafe { take_wstr(a.szAccessPath) },
                    // SAFETY: as above.
                    item_id: unsafe { take_wstr(a.szItemID) },
                    active: a.bActive.as_bool(),
                    client_handle: a.hClient,
                    server_handle: a.hServer,
                    access_rights: a.dwAccessRights,
                    requested_type: a.vtRequestedDataType.0,
                    canonical_type: a.vtCanonicalDataType.0,
                    eu_type: a.dwEUType.0,
                    eu_vt: ctopc_com::variant::var_type(&a.vEUInfo).0,
                    eu_info: ctopc_com::variant::from_variant(&a.vEUInfo)
                        .unwrap_or(ctopc_core::Value::Empty),
                });
                ctopc_com::variant::clear(&mut a.vEUInfo);
            }
            // SAFETY: as above.
            unsafe { CoTaskMemFree(Some(p as *const c_void)) };
        }
        Ok((hr, out))
    }

    /// Every item's attributes (CreateEnumerator, then Next until it is exhausted).
    pub fn item_attributes(&self) -> windows::core::Result<Vec<ItemAttrs>> {
        let (_, e) = self.item_enumerator()?;
        let mut all = Vec::new();
        loop {
            let (hr, items) = Self::next_attributes(&e, 100)?;
            let done = items.is_empty() || hr != windows::Win32::Foundation::S_OK;
            all.extend(items);
            if done {
                return Ok(all);
            }
        }
    }

    pub fn get_state(&self) -> windows::core::Result<GroupStateInfo> {
        let (
            mut rate,
            mut active,
            mut name,
            mut bias,
            mut deadband,
            mut lcid,
            mut client,
            mut server,
        ) = (
            0u32,
            windows::core::BOOL(0),
            PWSTR::null(),
            0i32,
            0f32,
            0u32,
            0u32,
            0u32,
        );
        // SAFETY: valid out-pointers; the name is CoTaskMem owned by us afterwards.
        unsafe {
            self.state_mgt.GetState(
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
        Ok(GroupStateInfo {
            update_rate: rate,
            active: active.as_bool(),
            // SAFETY: NULL or the CoTaskMem name GetState handed out, ours.
            name: unsafe { take_wstr(name) },
            time_bias: bias,
            percent_deadband: deadband,
            lcid,
            client_handle: client,
            server_handle: server,
        })
    }

    /// IOPCGroupStateMgt::SetState: (S_OK or OPC_S_UNSUPPORTEDRATE, revised update rate).
    pub fn set_state(
        &self,
        c: &GroupStateChange,
    ) -> windows::core::Result<(windows::core::HRESULT, u32)> {
        fn opt<T>(o: &Option<T>) -> *const T {
            o.as_ref().map_or(std::ptr::null(), |v| v as *const T)
        }
        let active = c.active.map(windows::core::BOOL::from);
        let mut revised = 0u32;
        // SAFETY: each pointer is NULL or points to a value alive for the call.
        let hr = group_call_hr(unsafe {
            self.state_mgt.SetState(
                opt(&c.update_rate),
                &mut revised,
                opt(&active),
                opt(&c.time_bias),
                opt(&c.percent_deadband),
                opt(&c.lcid),
                opt(&c.client_handle),
            )
        })?;
        Ok((hr, revised))
    }

    pub fn set_name(&self, name: &str) -> windows::core::Result<()> {
        let name = HSTRING::from(name);
        // SAFETY: valid NUL-terminated string for the call.
        unsafe { self.state_mgt.SetName(windows::core::PCWSTR(name.as_ptr())) }
    }

    /// IOPCGroupStateMgt::CloneGroup, asking for `riid`.
    pub fn clone_group_as(
        &self,
        name: &str,
        riid: &windows::core::GUID,
    ) -> windows::core::Result<IUnknown> {
        let name = HSTRING::from(name);
        let mut unk: Option<IUnknown> = None;
        // SAFETY: valid string, IID and out-pointer.
        unsafe {
            self.state_mgt
                .CloneGroup(windows::core::PCWSTR(name.as_ptr()), riid, &mut unk)?
        };
        unk.ok_or_else(|| windows::Win32::Foundation::E_POINTER.into())
    }

    pub fn clone_group(&self, name: &str) -> windows::core::Result<OpcGroup> {
        OpcGroup::from_unknown(self.clone_group_as(name, &IUnknown::IID)?)
    }

    /// IOPCGroupStateMgt2::SetKeepAlive: (S_OK or OPC_S_UNSUPPORTEDRATE, revised time).
    pub fn set_keep_alive(&self, ms: u32) -> windows::core::Result<(windows::core::HRESULT, u32)> {
        let s2 = self.unknown.cast::<IOPCGroupStateMgt2>()?;
        let mut revised = 0u32;
        // SAFETY: valid out-pointer.
        let hr = group_call_hr(unsafe { s2.SetKeepAlive(ms, &mut revised) })?;
        Ok((hr, revised))
    }

    pub fn keep_alive(&self) -> windows::core::Result<u32> {
        let s2 = self.unknown.cast::<IOPCGroupStateMgt2>()?;
        let mut t = 0u32;
        // SAFETY: valid out-pointer.
        unsafe { s2.GetKeepAlive(&mut t)? };
        Ok(t)
    }

    /// SetItemDeadband for `(server handle, percent)` pairs.
    pub fn set_item_deadband(
        &self,
        items: &[(u32, f32)],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
        let d = self.unknown.cast::<IOPCItemDeadbandMgt>()?;
        let h: Vec<u32> = items.iter().map(|i| i.0).collect();
        let v: Vec<f32> = items.iter().map(|i| i.1).collect();
        // SAFETY: both arrays hold `len` elements and live for the call.
        Self::errors_call(h.len(), |e| unsafe {
            d.SetItemDeadband(h.len() as u32, h.as_ptr(), v.as_ptr(), e)
        })
    }

    pub fn get_item_deadband(
        &self,
        handles: &[u32],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<(f32, windows::core::HRESULT)>)> {
        let d = self.unknown.cast::<IOPCItemDeadbandMgt>()?;
        // SAFETY: `handles` lives for the call; valid out-pointers.
        Self::values_call(handles.len(), |v, e| unsafe {
            d.GetItemDeadband(handles.len() as u32, handles.as_ptr(), v, e)
        })
    }

    pub fn clear_item_deadband(
        &self,
        handles: &[u32],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
        let d = self.unknown.cast::<IOPCItemDeadbandMgt>()?;
        // SAFETY: as above.
        Self::errors_call(handles.len(), |e| unsafe {
            d.ClearItemDeadband(handles.len() as u32, handles.as_ptr(), e)
        })
    }

    /// SetItemSamplingRate for `(server handle, rate ms)`: per item (revised rate, HRESULT).
    pub fn set_item_sampling_rate(
        &self,
        items: &[(u32, u32)],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<(u32, windows::core::HRESULT)>)> {
        let s = self.unknown.cast::<IOPCItemSamplingMgt>()?;
        let h: Vec<u32> = items.iter().map(|i| i.0).collect();
        let r: Vec<u32> = items.iter().map(|i| i.1).collect();
        // SAFETY: both arrays hold `len` elements and live for the call; valid out-pointers.
        Self::values_call(h.len(), |v, e| unsafe {
            s.SetItemSamplingRate(h.len() as u32, h.as_ptr(), r.as_ptr(), v, e)
        })
    }

    pub fn get_item_sampling_rate(
        &self,
        handles: &[u32],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<(u32, windows::core::HRESULT)>)> {
        let s = self.unknown.cast::<IOPCItemSamplingMgt>()?;
        // SAFETY: `handles` lives for the call; valid out-pointers.
        Self::values_call(handles.len(), |v, e| unsafe {
            s.GetItemSamplingRate(handles.len() as u32, handles.as_ptr(), v, e)
        })
    }

    pub fn clear_item_sampling_rate(
        &self,
        handles: &[u32],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
        let s = self.unknown.cast::<IOPCItemSamplingMgt>()?;
        // SAFETY: as above.
        Self::errors_call(handles.len(), |e| unsafe {
            s.ClearItemSamplingRate(handles.len() as u32, handles.as_ptr(), e)
        })
    }

    pub fn set_item_buffer_enable(
        &self,
        items: &[(u32, bool)],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<windows::core::HRESULT>)> {
        let s = self.unknown.cast::<IOPCItemSamplingMgt>()?;
        let h: Vec<u32> = items.iter().map(|i| i.0).collect();
        let b: Vec<windows::core::BOOL> = items.iter().map(|i| i.1.into()).collect();
        // SAFETY: both arrays hold `len` elements and live for the call.
        Self::errors_call(h.len(), |e| unsafe {
            s.SetItemBufferEnable(h.len() as u32, h.as_ptr(), b.as_ptr(), e)
        })
    }

    pub fn get_item_buffer_enable(
        &self,
        handles: &[u32],
    ) -> windows::core::Result<(windows::core::HRESULT, Vec<(bool, windows::core::HRESULT)>)> {
        let s = self.unknown.cast::<IOPCItemSamplingMgt>()?;
        // SAFETY: `handles` lives for the call; valid out-pointers.
        let (hr, v) = Self::values_call::<windows::core::BOOL>(handles.len(), |v, e| unsafe {
            s.GetItemBufferEnable(handles.len() as u32, handles.as_ptr(), v, e)
        })?;
        Ok((hr, v.into_iter().map(|(b, e)| (b.as_bool(), e)).collect()))
    }
}

// ---- server object: groups, browsing, item properties, item I/O, shutdown ---------------

mod server_ext;
pub use server_ext::{
    enum_strings, enum_strings_each, enum_unknowns, AddedGroup, BrowseArgs, BrowseElement,
    BrowsePage, GroupSpec, ItemProperties, NewItemId, Property, STRING_BATCH,
};

// ---- console clients (opcdiag): a data-change sink, Ctrl+C, local time -----------------

pub mod diag;
pub mod server_list;
