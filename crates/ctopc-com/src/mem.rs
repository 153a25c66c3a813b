//! CoTaskMem allocation for out-parameters, and the one place where core errors become
//! HRESULTs.
//!
//! Out-parameters are all-or-nothing: allocate into [`TaskMem`] owners, which free
//! everything on drop unless `into_raw` hands the memory to the caller after every
//! allocation of the call has succeeded.

use ctopc_core::{OpcError, Timestamp};
use std::ffi::c_void;
use windows::core::PWSTR;
use windows::Win32::Foundation::{E_OUTOFMEMORY, FILETIME};
use windows::Win32::System::Com::{CoTaskMemAlloc, CoTaskMemFree};

/// Maps a core error to a COM error (the single mapping point).
pub fn to_com(e: OpcError) -> windows::core::Error {
    error(windows::core::HRESULT(e.hresult()), e.symbol())
}

/// A COM error with a message, carried by an `IErrorInfo` from oleaut32's
/// `CreateErrorInfo` (set on the thread, so that the error also reaches a client whose COM
/// runtime transmits error objects).
///
/// Not `windows::core::Error::new`: with a message it calls combase's
/// `RoOriginateErrorW`, which Wine 8 exports only as an unimplemented stub, and calling
/// that aborts the whole server process.
pub fn error(code: windows::core::HRESULT, message: &str) -> windows::core::Error {
    use windows::core::Interface;
    let text = windows::core::HSTRING::from(message);
    // SAFETY: plain COM calls on a new error object; `text` lives for the call.
    unsafe {
        if let Ok(info) = windows::Win32::System::Ole::CreateErrorInfo() {
            let _ = info.SetDescription(windows::core::PCWSTR(text.as_ptr()));
            if let Ok(info) = info.cast::<windows::Win32::System::Com::IErrorInfo>() {
                let _ = windows::Win32::System::Com::SetErrorInfo(0, &info);
            }
        }
    }
    // Takes the thread's error object (the one just set).
    windows::core::Error::from(code)
}

pub fn hresult(e: OpcError) -> windows::core::HRESULT {
    windows::core::HRESULT(e.hresult())
}

/// A CoTaskMem block owned until handed out with [`TaskMem::into_raw`].
pub struct TaskMem<T> {
    ptr: *mut T,
    len: usize,
}

impl<T> TaskMem<T> {
    /// A zeroed array of `len` elements (`len` may be 0: then a valid 1-byte block).
    pub fn zeroed(len: usize) -> windows::core::Result<TaskMem<T>> {
        let bytes = std::mem::size_of::<T>()
            .checked_mul(len)
            .ok_or_else(|| windows::core::Error::from(E_OUTOFMEMORY))?;
        // SAFETY: CoTaskMemAlloc returns null or a block of at least `bytes.max(1)` bytes.
        let ptr = unsafe { CoTaskMemAlloc(bytes.max(1)) }.cast::<T>();
        if ptr.is_null() {
            return Err(E_OUTOFMEMORY.into());
        }
        // SAFETY: the block has `bytes` writable bytes.
        unsafe { std::ptr::write_bytes(ptr.cast::<u8>(), 0, bytes) };
        Ok(TaskMem { ptr, len })
    }

    pub fn as_mut_slice(&mut self) -> &mut [T] {
        // SAFETY: `ptr` holds `len` zero-initialised elements of a type for which all-zero is
        // valid (callers use only C structs, integers and pointers).
        unsafe { std::slice::from_raw_parts_mut(self.ptr, self.len) }
    }

    pub fn into_raw(self) -> *mut T {
        let p = self.ptr;
        std::mem::forget(self);
        p
    }
}

impl<T> Drop for TaskMem<T> {
    fn drop(&mut self) {
        // SAFETY: the block came from CoTaskMemAlloc and was not handed out.
        unsafe { CoTaskMemFree(Some(self.ptr.cast::<c_void>())) };
    }
}

/// A CoTaskMem copy of `s` as a NUL-terminated UTF-16 string.
pub fn alloc_wstr(s: &str) -> windows::core::Result<PWSTR> {
    let wide: Vec<u16> = s.encode_utf16().chain(std::iter::once(0)).collect();
    let mut mem = TaskMem::<u16>::zeroed(wide.len())?;
    mem.as_mut_slice().copy_from_slice(&wide);
    Ok(PWSTR(mem.into_raw()))
}

/// Frees a string from [`alloc_wstr`] (for error paths after a partial success).
pub fn free_wstr(p: PWSTR) {
    if !p.is_null() {
        // SAFETY: `p` came from CoTaskMemAlloc.
        unsafe { CoTaskMemFree(Some(p.0.cast::<c_void>())) };
    }
}

pub fn filetime(t: Timestamp) -> FILETIME {
    let (lo, hi) = t.filetime_parts();
    FILETIME {
        dwLowDateTime: lo,
        dwHighDateTime: hi,
    }
}

/// The current UTC time (the only clock read of the COM layer's data path).
pub fn now() -> Timestamp {
    let since = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    Timestamp::from_unix_millis(0).add_micros_saturating(since.as_micros())
}

trait AddMicros {
    fn add_micros_saturating(self, us: u128) -> Timestamp;
}

impl AddMicros for Timestamp {
    fn add_micros_saturating(self, us: u128) -> Timestamp {
        let ticks = i64::try_from(us.saturating_mul(10)).unwrap_or(i64::MAX);
        Timestamp(self.0.saturating_add(ticks))
    }
}

/// Today's local date (year, month, day), for the names of the log files.
pub fn local_date() -> (i32, u32, u32) {
    // SAFETY: no arguments; fills and returns a SYSTEMTIME.
    let t = unsafe { windows::Win32::System::SystemInformation::GetLocalTime() };
    (i32::from(t.wYear), u32::from(t.wMonth), u32::from(t.wDay))
}
