//! The COM methods' one toolkit for arguments and out-parameters (server, groups,
//! enumerators, and the e2e-tests' marshal probe).
//!
//! - **Arguments**: the readers of raw pointers ([`in_string`], [`item_id_at`],
//!   [`in_slice`], [`in_array`], [`in_opt`]) and the writers ([`put`], [`clear`],
//!   [`write_out`], [`OutArray`], [`query_out`]) are `unsafe fn`s whose `# Safety` is the
//!   IDL's contract for the parameter (`[in, size_is(n)]`, `[in, string]`, `[out]`): a COM
//!   method, itself `unsafe`, passes its own parameters on with that contract. They answer
//!   E_INVALIDARG for a NULL where OPC wants it. One argument order: pointer, then count.
//! - **Results**: one result type, [`ComResult`] (`windows::core::Result`); whole-call
//!   errors from the core go through [`crate::com::error::to_com`] (the one mapping), per-item
//!   codes through [`item_hr`]; [`hresult`] turns a method's result into its raw HRESULT
//!   for methods that may return S_FALSE.
//! - **Out-parameters are cleared first**: a method's first statement is
//!   [`clear_outs`]`((p1, p2, ..))`, which sets every non-NULL out-parameter to 0 / NULL /
//!   `None` before any check can return (a NULL sibling included), so that every failure
//!   leaves them all cleared.
//! - **Out-parameters are all-or-nothing**: everything a method hands out is first built
//!   in owners ([`TaskMem`], [`OwnedArray`], [`OwnedWstr`]) that free it all on drop; only
//!   after every allocation of the call has succeeded are the pointers written to the
//!   caller's out-parameters (`into_raw`).

use crate::com::error;
use ctopc_core::limits::{self, TextLimit};
use ctopc_core::OpcError;
use std::ffi::c_void;
use windows::core::{IUnknown, Interface, BOOL, GUID, HRESULT, PCWSTR, PWSTR};
use windows::Win32::Foundation::{E_INVALIDARG, E_OUTOFMEMORY, E_POINTER, S_FALSE, S_OK};
use windows::Win32::System::Com::{CoTaskMemAlloc, CoTaskMemFree};
use windows::Win32::System::Variant::VARIANT;

use crate::com::interfaces::{
    OPCBROWSEELEMENT, OPCITEMATTRIBUTES, OPCITEMPROPERTIES, OPCITEMPROPERTY, OPCITEMSTATE,
};

/// The one result type of the COM layer.
pub type ComResult<T> = windows::core::Result<T>;

/// E_INVALIDARG as an error (NULL pointers, count 0, out-of-range enumerations).
pub fn invalid_arg() -> windows::core::Error {
    E_INVALIDARG.into()
}

/// E_INVALIDARG when `p` is NULL (the pointer is not read).
pub fn nonnull<T>(p: *const T) -> ComResult<()> {
    if p.is_null() {
        Err(invalid_arg())
    } else {
        Ok(())
    }
}

/// A method's result as its raw HRESULT (for methods that may return S_FALSE or OPC_S_*).
pub fn hresult(r: ComResult<HRESULT>) -> HRESULT {
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
///
/// # Safety
/// `p` is NULL or points to writable caller-owned storage for a `T` whose old value needs
/// no drop (an `[out]` parameter of the call).
pub unsafe fn clear<T>(p: *mut T, value: T) {
    if !p.is_null() {
        // SAFETY: contract of this function; the values written here (zeros, nulls,
        // `None`) own nothing.
        unsafe { p.write(value) };
    }
}

/// The value an out-parameter holds after a failed call: 0, NULL, `None`, GUID_NULL.
pub trait Cleared {
    /// The cleared value (owns nothing).
    fn cleared() -> Self;
}

macro_rules! cleared_as {
    ($($t:ty => $v:expr),+ $(,)?) => {
        $(impl Cleared for $t {
            fn cleared() -> Self {
                $v
            }
        })+
    };
}

cleared_as! {
    u32 => 0,
    i32 => 0,
    f32 => 0.0,
    HRESULT => HRESULT(0),
    PWSTR => PWSTR::null(),
    GUID => GUID::zeroed(),
    BOOL => BOOL(0),
}

impl<T> Cleared for *mut T {
    fn cleared() -> Self {
        std::ptr::null_mut()
    }
}

impl<I: Interface> Cleared for Option<I> {
    fn cleared() -> Self {
        None
    }
}

/// The out-parameters of one call, as a tuple of raw pointers: see [`clear_outs`].
pub trait OutParams {
    /// # Safety
    /// As [`clear_outs`].
    unsafe fn clear_all(self);
}

macro_rules! out_params_tuple {
    ($($p:ident: $t:ident),+) => {
        impl<$($t: Cleared),+> OutParams for ($(*mut $t,)+) {
            unsafe fn clear_all(self) {
                let ($($p,)+) = self;
                // SAFETY: forwarded contract of `clear_outs`: each pointer is NULL or
                // writable caller storage whose old value needs no drop.
                unsafe { $(clear($p, $t::cleared());)+ }
            }
        }
    };
}

out_params_tuple!(a: A);
out_params_tuple!(a: A, b: B);
out_params_tuple!(a: A, b: B, c: C);
out_params_tuple!(a: A, b: B, c: C, d: D);
out_params_tuple!(a: A, b: B, c: C, d: D, e: E);
out_params_tuple!(a: A, b: B, c: C, d: D, e: E, f: F);

/// Clears every non-NULL out-parameter of a call (0, NULL, `None`) **before any check can
/// return**, so that a call failing for any reason, a NULL sibling out-parameter included,
/// leaves all of them cleared: the first statement of a method with out-parameters.
/// `outs` is a tuple of the method's `[out]` pointers, e.g. `(pcount, ppids)`.
///
/// # Safety
/// Each pointer is NULL or writable caller-owned storage for its type whose old value
/// needs no drop (an `[out]` parameter of the call: the callee never reads it).
pub unsafe fn clear_outs(outs: impl OutParams) {
    // SAFETY: contract of this function.
    unsafe { outs.clear_all() }
}

/// Writes one plain required `[out]` value; E_INVALIDARG (nothing written) for NULL.
///
/// # Safety
/// As [`clear`]: `p` is NULL or writable caller storage for one `T`.
pub unsafe fn write_out<T>(p: *mut T, value: T) -> ComResult<()> {
    nonnull(p)?;
    // SAFETY: checked non-null; contract of this function.
    unsafe { p.write(value) };
    Ok(())
}

/// A required `[in, string]` parameter: E_INVALIDARG when NULL, `limit.error` when it is
/// longer than `limit` allows (see [`ctopc_core::limits`]) or not valid UTF-16 (an
/// unpaired surrogate).
///
/// # Safety
/// `p` is NULL or a NUL-terminated UTF-16 string that lives for the call.
pub unsafe fn in_string(p: PCWSTR, limit: TextLimit) -> ComResult<String> {
    if p.is_null() {
        return Err(invalid_arg());
    }
    // SAFETY: contract of this function (non-null checked above).
    unsafe { limited_wide(p.as_wide(), limit) }.map_err(error::to_com)
}

/// One element of an `[in, size_is(n)] LPWSTR*` array of item IDs: NULL, longer than
/// [`limits::ITEM_ID`] or not valid UTF-16 is OPC_E_INVALIDITEMID for that item.
///
/// # Safety
/// As [`in_string`].
pub unsafe fn item_id_at(p: PCWSTR) -> Result<String, OpcError> {
    if p.is_null() {
        return Err(OpcError::InvalidItemId);
    }
    // SAFETY: contract of this function (non-null checked above).
    limited_wide(unsafe { p.as_wide() }, limits::ITEM_ID)
}

/// Decodes a client's UTF-16 text after checking its length against `limit` (so an
/// over-long text costs its length count only); over the limit or invalid UTF-16 is
/// `limit.error`. An over-long text is logged.
pub fn limited_wide(wide: &[u16], limit: TextLimit) -> Result<String, OpcError> {
    limit.check_units(wide.len()).inspect_err(|e| {
        tracing::warn!(
            "a client {} of {} UTF-16 units, over the limit of {}: {}",
            limit.what,
            wide.len(),
            limit.max_units,
            e.symbol()
        );
    })?;
    String::from_utf16(wide).map_err(|_| limit.error)
}

/// An `[in, size_is(count)]` array that may be empty: E_INVALIDARG when NULL with a
/// non-zero count; empty for a count of 0 (the pointer is not read then).
///
/// # Safety
/// `p` is NULL or points to `count` initialised elements that stay valid and unchanged
/// for `'a` (the call: the stub or the in-process caller owns them).
pub unsafe fn in_slice<'a, T>(p: *const T, count: u32) -> ComResult<&'a [T]> {
    if count == 0 {
        return Ok(&[]);
    }
    nonnull(p)?;
    // SAFETY: contract of this function (non-null checked above).
    Ok(unsafe { std::slice::from_raw_parts(p, count as usize) })
}

/// An `[in, size_is(count)]` array that must not be empty: E_INVALIDARG for a count of 0
/// or a NULL pointer (the group's per-item methods).
///
/// # Safety
/// As [`in_slice`].
pub unsafe fn in_array<'a, T>(p: *const T, count: u32) -> ComResult<&'a [T]> {
    if count == 0 {
        return Err(invalid_arg());
    }
    // SAFETY: contract of this function.
    unsafe { in_slice(p, count) }
}

/// An `[in, unique]` value: None for NULL.
///
/// # Safety
/// `p` is NULL or points to one initialised `T` alive for the call.
pub unsafe fn in_opt<T: Copy>(p: *const T) -> Option<T> {
    if p.is_null() {
        None
    } else {
        // SAFETY: contract of this function (non-null checked above).
        Some(unsafe { *p })
    }
}

/// A required `[out]` pointer to a callee-allocated CoTaskMem array (or string):
/// null-checked (E_INVALIDARG) and set to NULL when made, before anything else can fail,
/// so that every failure leaves NULL behind; [`OutArray::set`] hands the result out.
pub struct OutArray<T>(*mut *mut T);

impl<T> OutArray<T> {
    /// # Safety
    /// `pp` is NULL or writable caller storage for one pointer that stays valid for the
    /// call (an `[out] T**` parameter).
    pub unsafe fn new(pp: *mut *mut T) -> ComResult<Self> {
        nonnull(pp)?;
        // SAFETY: checked non-null; contract of this function.
        unsafe { pp.write(std::ptr::null_mut()) };
        Ok(OutArray(pp))
    }

    /// Hands the array to the caller (who then owns it).
    pub fn set(self, array: impl IntoTaskMem<T>) {
        let p = array.into_task_mem();
        // SAFETY: `self.0` was checked non-null in `new`, whose contract keeps it writable
        // for the call; the old value is the NULL written there.
        unsafe { self.0.write(p) };
    }
}

/// An owner of a CoTaskMem array that can hand its block out (to [`OutArray::set`]).
pub trait IntoTaskMem<T> {
    /// The block, no longer owned by `self` (the caller's from now on).
    fn into_task_mem(self) -> *mut T;
}

impl<T> IntoTaskMem<T> for TaskMem<T> {
    fn into_task_mem(self) -> *mut T {
        self.into_raw()
    }
}

impl<T: OwnsTaskMem> IntoTaskMem<T> for OwnedArray<T> {
    fn into_task_mem(self) -> *mut T {
        self.into_raw()
    }
}

/// Hands `object` out as interface `riid` through an `[out, iid_is(riid)] IUnknown**`.
/// E_INVALIDARG for NULL pointers; E_NOINTERFACE (and NULL written) when the object does
/// not implement `riid`.
///
/// # Safety
/// `riid` is NULL or points to a GUID; `out` is NULL or writable caller storage for one
/// interface pointer.
pub unsafe fn query_out(
    object: &IUnknown,
    riid: *const GUID,
    out: *mut Option<IUnknown>,
) -> ComResult<()> {
    nonnull(riid)?;
    nonnull(out)?;
    // SAFETY: both pointers checked non-null (contract of this function); QueryInterface
    // writes a pointer of interface `riid` (or null on failure) to `out`, which has the
    // layout of a `*mut c_void`.
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
        // SAFETY: contract of `free_owned`: a non-null string is a CoTaskMem block owned by
        // this element alone, cleared right after.
        unsafe { free_wstr(*self) };
        *self = PWSTR::null();
    }
}

impl OwnsTaskMem for VARIANT {
    unsafe fn free_owned(&mut self) {
        crate::com::variant::clear(self);
    }
}

impl OwnsTaskMem for OPCITEMPROPERTY {
    unsafe fn free_owned(&mut self) {
        // SAFETY: forwarded contract of this function.
        unsafe {
            self.szItemID.free_owned();
            self.szDescription.free_owned();
        }
        crate::com::variant::clear(&mut self.vValue);
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

impl OwnsTaskMem for OPCITEMSTATE {
    unsafe fn free_owned(&mut self) {
        crate::com::variant::clear(&mut self.vDataValue);
    }
}

impl OwnsTaskMem for OPCITEMATTRIBUTES {
    unsafe fn free_owned(&mut self) {
        // SAFETY: forwarded contract of this function.
        unsafe {
            self.szAccessPath.free_owned();
            self.szItemID.free_owned();
        }
        if !self.pBlob.is_null() {
            // SAFETY: forwarded contract: a CoTaskMem block owned by this element.
            unsafe { CoTaskMemFree(Some(self.pBlob.cast::<c_void>())) };
            self.pBlob = std::ptr::null_mut();
        }
        crate::com::variant::clear(&mut self.vEUInfo);
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
pub unsafe fn free_array<T: OwnsTaskMem>(p: *mut T, n: usize) {
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
    pub fn zeroed(n: usize) -> ComResult<Self> {
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
    pub fn new(s: &str) -> ComResult<Self> {
        Ok(OwnedWstr(alloc_wstr(s)?))
    }

    pub fn into_raw(self) -> PWSTR {
        let p = self.0;
        std::mem::forget(self);
        p
    }
}

impl Drop for OwnedWstr {
    fn drop(&mut self) {
        // SAFETY: the string came from `alloc_wstr` and was not handed out (`into_raw`
        // forgets the owner).
        unsafe { free_wstr(self.0) };
    }
}

/// A CoTaskMem copy of `s`, or NULL for `None`.
pub fn opt_wstr(s: Option<&str>) -> ComResult<PWSTR> {
    match s {
        Some(s) => Ok(OwnedWstr::new(s)?.into_raw()),
        None => Ok(PWSTR::null()),
    }
}

/// The per-item HRESULT of a core result (S_OK for success).
pub fn item_hr<T>(r: &Result<T, OpcError>) -> HRESULT {
    match r {
        Ok(_) => S_OK,
        Err(e) => error::hresult(*e),
    }
}

/// S_FALSE when some item failed, else S_OK.
pub fn s_false_if(any_failed: bool) -> HRESULT {
    if any_failed {
        S_FALSE
    } else {
        S_OK
    }
}

/// S_FALSE when any per-item code is a failure, else S_OK.
pub fn s_false_if_any(errors: &[HRESULT]) -> HRESULT {
    s_false_if(errors.iter().any(|e| e.is_err()))
}

// ---------------------------------------------------------------------------------------
// CoTaskMem blocks and strings
// ---------------------------------------------------------------------------------------

/// A CoTaskMem block owned until handed out with [`TaskMem::into_raw`].
pub struct TaskMem<T> {
    ptr: *mut T,
    len: usize,
}

impl<T> TaskMem<T> {
    /// A zeroed array of `len` elements (`len` may be 0: then a valid 1-byte block).
    pub fn zeroed(len: usize) -> ComResult<TaskMem<T>> {
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
pub fn alloc_wstr(s: &str) -> ComResult<PWSTR> {
    let wide: Vec<u16> = s.encode_utf16().chain(std::iter::once(0)).collect();
    let mut mem = TaskMem::<u16>::zeroed(wide.len())?;
    mem.as_mut_slice().copy_from_slice(&wide);
    Ok(PWSTR(mem.into_raw()))
}

/// Frees a string from [`alloc_wstr`] (for error paths after a partial success), or an
/// `[in, out]` string a client handed in.
///
/// # Safety
/// `p` is NULL or a CoTaskMem block (CoTaskMemAlloc) that the caller owns, not yet freed
/// and not used afterwards.
pub unsafe fn free_wstr(p: PWSTR) {
    if !p.is_null() {
        // SAFETY: contract of this function: a CoTaskMem block of the caller's, freed once.
        unsafe { CoTaskMemFree(Some(p.0.cast::<c_void>())) };
    }
}

/// Writes one `[out]` value of a COM-defined method: E_POINTER (nothing written) for NULL.
///
/// # Safety
/// As [`clear`]: `p` is NULL or writable caller storage for one `T`.
pub unsafe fn out_or_e_pointer<T>(p: *mut T, value: T) -> HRESULT {
    if p.is_null() {
        return E_POINTER;
    }
    // SAFETY: checked non-null; contract of this function.
    unsafe { put(p, value) };
    S_OK
}
