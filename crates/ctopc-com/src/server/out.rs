//! Argument reading and all-or-nothing out-parameters for the server object's methods.
//!
//! Everything a method hands out is first built in owners ([`OwnedArray`], [`OwnedWstr`],
//! `TaskMem`) that free it all on drop; only after every allocation of the call has
//! succeeded are the pointers written to the caller's out-parameters (`into_raw`).

use crate::mem::{self, TaskMem};
use ctopc_core::OpcError;
use std::ffi::c_void;
use windows::core::{IUnknown, Interface, GUID, HRESULT, PCWSTR, PWSTR};
use windows::Win32::Foundation::E_INVALIDARG;
use windows::Win32::System::Com::CoTaskMemFree;
use windows::Win32::System::Variant::VARIANT;

use crate::interfaces::{OPCBROWSEELEMENT, OPCITEMPROPERTIES, OPCITEMPROPERTY};

/// A core error as a COM error: the code of `mem::hresult` (the one mapping), without an
/// error message object. `mem::to_com` attaches its message with `RoOriginateErrorW`,
/// which Wine 8's combase does not implement: calling it aborts the calling thread's
/// process ("unimplemented function combase.dll.RoOriginateErrorW"), so a server method
/// that failed through it would never answer. (The group object does the same.)
pub fn com_err(e: OpcError) -> windows::core::Error {
    windows::core::Error::from_hresult(mem::hresult(e))
}

/// E_INVALIDARG as an error (NULL pointers, count 0, out-of-range enumerations).
pub fn invalid_arg() -> windows::core::Error {
    E_INVALIDARG.into()
}

/// E_INVALIDARG when `p` is NULL.
pub fn nonnull<T>(p: *const T) -> windows::core::Result<()> {
    if p.is_null() {
        Err(invalid_arg())
    } else {
        Ok(())
    }
}

/// A method's result as its raw HRESULT (for methods that may return S_FALSE or OPC_S_*).
pub fn hresult(r: windows::core::Result<HRESULT>) -> HRESULT {
    r.unwrap_or_else(|e| e.code())
}

/// Writes `value` to an out-parameter.
///
/// # Safety
/// `p` is non-null and points to writable caller-owned storage for a `T` whose old value
/// needs no drop.
pub unsafe fn put<T>(p: *mut T, value: T) {
    // SAFETY: contract of this function.
    unsafe { p.write(value) };
}

/// Writes `value` to an out-parameter if the pointer is non-null (to clear outputs before
/// anything can fail).
pub fn clear<T>(p: *mut T, value: T) {
    if !p.is_null() {
        // SAFETY: non-null out-parameters point to caller-owned storage; the values written
        // here (zeros, nulls, `None`) own nothing.
        unsafe { p.write(value) };
    }
}

/// A required `[in, string]` parameter: E_INVALIDARG when NULL, `invalid` when it is not
/// valid UTF-16 (an unpaired surrogate).
pub fn in_string(p: PCWSTR, invalid: OpcError) -> windows::core::Result<String> {
    if p.is_null() {
        return Err(invalid_arg());
    }
    // SAFETY: a non-null `[in, string]` parameter is a NUL-terminated UTF-16 string that
    // lives for the call.
    unsafe { p.to_string() }.map_err(|_| com_err(invalid))
}

/// One element of an `[in, size_is(n)] LPWSTR*` array of item IDs: NULL or not valid
/// UTF-16 is OPC_E_INVALIDITEMID for that item.
pub fn item_id_at(p: PCWSTR) -> Result<String, OpcError> {
    if p.is_null() {
        return Err(OpcError::InvalidItemId);
    }
    // SAFETY: non-null elements of the array are NUL-terminated UTF-16 strings alive for
    // the call.
    unsafe { p.to_string() }.map_err(|_| OpcError::InvalidItemId)
}

/// An `[in, size_is(count)]` array: E_INVALIDARG when NULL with a non-zero count; empty for
/// a count of 0 (the pointer is not read then).
pub fn in_slice<'a, T>(p: *const T, count: u32) -> windows::core::Result<&'a [T]> {
    if count == 0 {
        return Ok(&[]);
    }
    nonnull(p)?;
    // SAFETY: `[in, size_is(count)]`: `count` initialised elements, alive for the call.
    Ok(unsafe { std::slice::from_raw_parts(p, count as usize) })
}

/// Hands `object` out as interface `riid` through an `[out, iid_is(riid)] IUnknown**`
/// (checked non-null by the caller). E_NOINTERFACE (and NULL written) when the object does
/// not implement `riid`.
pub fn query_out(
    object: &IUnknown,
    riid: *const GUID,
    out: *mut Option<IUnknown>,
) -> windows::core::Result<()> {
    nonnull(riid)?;
    nonnull(out)?;
    // SAFETY: both pointers checked non-null; QueryInterface writes a pointer of interface
    // `riid` (or null on failure) to `out`, which has the layout of a `*mut c_void`.
    unsafe { object.query(riid, out.cast::<*mut c_void>()) }.ok()
}

/// An element of a CoTaskMem array whose members may own further CoTaskMem blocks.
pub trait OwnsTaskMem {
    /// Frees every block the element's members own (not the element itself) and leaves
    /// them empty.
    ///
    /// # Safety
    /// Every non-null pointer member was allocated with CoTaskMemAlloc (arrays with the
    /// element count stored next to them) and is owned by this element alone.
    unsafe fn free_owned(&mut self);
}

impl OwnsTaskMem for PWSTR {
    unsafe fn free_owned(&mut self) {
        mem::free_wstr(*self);
        *self = PWSTR::null();
    }
}

impl OwnsTaskMem for VARIANT {
    unsafe fn free_owned(&mut self) {
        crate::variant::clear(self);
    }
}

impl OwnsTaskMem for OPCITEMPROPERTY {
    unsafe fn free_owned(&mut self) {
        // SAFETY: forwarded contract of this function.
        unsafe {
            self.szItemID.free_owned();
            self.szDescription.free_owned();
        }
        crate::variant::clear(&mut self.vValue);
    }
}

impl OwnsTaskMem for OPCITEMPROPERTIES {
    unsafe fn free_owned(&mut self) {
        // SAFETY: forwarded contract: `pItemProperties` holds `dwNumProperties` elements.
        unsafe { free_array(self.pItemProperties, self.dwNumProperties as usize) };
        self.pItemProperties = std::ptr::null_mut();
        self.dwNumProperties = 0;
    }
}

impl OwnsTaskMem for OPCBROWSEELEMENT {
    unsafe fn free_owned(&mut self) {
        // SAFETY: forwarded contract of this function.
        unsafe {
            self.szName.free_owned();
            self.szItemID.free_owned();
            self.ItemProperties.free_owned();
        }
    }
}

/// Frees a CoTaskMem array of `n` elements and everything they own.
///
/// # Safety
/// `p` is null or a CoTaskMem array of at least `n` initialised elements satisfying the
/// contract of [`OwnsTaskMem::free_owned`], owned by the caller and not used afterwards.
unsafe fn free_array<T: OwnsTaskMem>(p: *mut T, n: usize) {
    if p.is_null() {
        return;
    }
    for i in 0..n {
        // SAFETY: `i < n` elements of the array (contract of this function).
        unsafe { (*p.add(i)).free_owned() };
    }
    // SAFETY: the block came from CoTaskMemAlloc and is owned by the caller.
    unsafe { CoTaskMemFree(Some(p.cast::<c_void>())) };
}

/// A zeroed CoTaskMem array that frees its elements' blocks and itself on drop unless it
/// is handed out with `into_raw`. All-zero elements own nothing.
pub struct OwnedArray<T: OwnsTaskMem> {
    mem: Option<TaskMem<T>>,
}

impl<T: OwnsTaskMem> OwnedArray<T> {
    pub fn zeroed(n: usize) -> windows::core::Result<Self> {
        Ok(OwnedArray {
            mem: Some(TaskMem::zeroed(n)?),
        })
    }

    pub fn as_mut_slice(&mut self) -> &mut [T] {
        match self.mem.as_mut() {
            Some(m) => m.as_mut_slice(),
            None => &mut [],
        }
    }

    pub fn into_raw(mut self) -> *mut T {
        self.mem
            .take()
            .map_or(std::ptr::null_mut(), TaskMem::into_raw)
    }
}

impl<T: OwnsTaskMem> Drop for OwnedArray<T> {
    fn drop(&mut self) {
        for e in self.as_mut_slice() {
            // SAFETY: every pointer member was set by this module's callers from CoTaskMem
            // allocations (or is still null) and has not been handed out.
            unsafe { e.free_owned() };
        }
    }
}

/// One CoTaskMem string, freed on drop unless handed out.
pub struct OwnedWstr(PWSTR);

impl OwnedWstr {
    pub fn new(s: &str) -> windows::core::Result<Self> {
        Ok(OwnedWstr(mem::alloc_wstr(s)?))
    }

    pub fn into_raw(self) -> PWSTR {
        let p = self.0;
        std::mem::forget(self);
        p
    }
}

impl Drop for OwnedWstr {
    fn drop(&mut self) {
        mem::free_wstr(self.0);
    }
}

/// A CoTaskMem copy of `s`, or NULL for `None`.
pub fn opt_wstr(s: Option<&str>) -> windows::core::Result<PWSTR> {
    match s {
        Some(s) => Ok(OwnedWstr::new(s)?.into_raw()),
        None => Ok(PWSTR::null()),
    }
}

/// The per-item HRESULT of a core result (S_OK for success).
pub fn item_hr<T>(r: &Result<T, OpcError>) -> HRESULT {
    match r {
        Ok(_) => HRESULT(0),
        Err(e) => mem::hresult(*e),
    }
}

/// S_FALSE when any per-item code is a failure, else S_OK.
pub fn s_false_if_any(errors: &[HRESULT]) -> HRESULT {
    if errors.iter().any(|e| e.is_err()) {
        windows::Win32::Foundation::S_FALSE
    } else {
        windows::Win32::Foundation::S_OK
    }
}
