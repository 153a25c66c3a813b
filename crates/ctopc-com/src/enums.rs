//! Snapshot enumerators (IEnumString, IEnumUnknown, IEnumConnectionPoints,
//! IEnumConnections): the list is taken when the enumerator is created; clones share it
//! and copy the position.

use std::sync::{Arc, Mutex};
use windows::core::{implement, IUnknown, HRESULT, PWSTR};
use windows::Win32::Foundation::{E_INVALIDARG, E_POINTER, S_FALSE, S_OK};
use windows::Win32::System::Com::{
    IConnectionPoint, IEnumConnectionPoints, IEnumConnectionPoints_Impl, IEnumConnections,
    IEnumConnections_Impl, IEnumString, IEnumString_Impl, IEnumUnknown, IEnumUnknown_Impl,
    CONNECTDATA,
};

/// A position in a shared snapshot.
pub struct Cursor<T> {
    items: Arc<Vec<T>>,
    pos: Mutex<usize>,
}

impl<T> Cursor<T> {
    pub fn new(items: Vec<T>) -> Self {
        Cursor {
            items: Arc::new(items),
            pos: Mutex::new(0),
        }
    }

    fn pos(&self) -> std::sync::MutexGuard<'_, usize> {
        self.pos.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A copy sharing the snapshot, at the same position.
    pub fn fork(&self) -> Self {
        Cursor {
            items: Arc::clone(&self.items),
            pos: Mutex::new(*self.pos()),
        }
    }

    /// Takes up to `n` items: the slice and the position after it is committed by `commit`.
    pub fn peek(&self, n: u32) -> (usize, usize) {
        let pos = *self.pos();
        let end = pos.saturating_add(n as usize).min(self.items.len());
        (pos, end)
    }

    pub fn items(&self) -> &[T] {
        &self.items
    }

    pub fn commit(&self, end: usize) {
        *self.pos() = end;
    }

    /// IEnum*::Skip: S_FALSE when fewer than `n` remained.
    pub fn skip(&self, n: u32) -> HRESULT {
        let (pos, end) = self.peek(n);
        self.commit(end);
        if end - pos == n as usize {
            S_OK
        } else {
            S_FALSE
        }
    }

    /// Skip for the `Result`-returning IEnum*::Skip methods: S_FALSE travels as the error
    /// (an `Ok` would become S_OK).
    pub fn skip_result(&self, n: u32) -> windows::core::Result<()> {
        match self.skip(n) {
            S_OK => Ok(()),
            hr => Err(hr.into()),
        }
    }

    pub fn reset(&self) {
        self.commit(0);
    }
}

/// Checks the arguments of an IEnum*::Next: `rgelt` non-null, and `pceltFetched` may be
/// null only when one element is asked for (COM rule).
pub fn check_next<T>(celt: u32, rgelt: *mut T, fetched: *mut u32) -> Result<(), HRESULT> {
    if rgelt.is_null() {
        return Err(E_POINTER);
    }
    if fetched.is_null() && celt != 1 {
        return Err(E_INVALIDARG);
    }
    Ok(())
}

/// Writes `*pceltFetched` (if asked for) and answers S_OK or S_FALSE.
///
/// # Safety
/// `fetched` is NULL or writable storage for one `u32` (IEnum*::Next's `pceltFetched`).
unsafe fn finish(fetched: *mut u32, got: usize, asked: u32) -> HRESULT {
    if !fetched.is_null() {
        // SAFETY: a non-null pceltFetched points to caller storage.
        unsafe { *fetched = got as u32 };
    }
    if got == asked as usize {
        S_OK
    } else {
        S_FALSE
    }
}

/// IEnum*::Next for elements that cannot fail to copy (interface pointers, AddRef'd by
/// `make`): the next `celt` elements into `rgelt`.
///
/// # Safety
/// IEnum*::Next's contract: `rgelt` is NULL or room for `celt` elements, `fetched` NULL or
/// writable storage for one `u32`.
unsafe fn next_into<T, U>(
    cursor: &Cursor<T>,
    celt: u32,
    rgelt: *mut U,
    fetched: *mut u32,
    make: impl Fn(&T) -> U,
) -> HRESULT {
    if let Err(hr) = check_next(celt, rgelt, fetched) {
        return hr;
    }
    let (pos, end) = cursor.peek(celt);
    for (i, item) in cursor.items()[pos..end].iter().enumerate() {
        // SAFETY: rgelt has room for `celt` >= end - pos elements (COM contract); the
        // elements are uninitialised out-storage, written without dropping.
        unsafe { rgelt.add(i).write(make(item)) };
    }
    cursor.commit(end);
    // SAFETY: contract of this function.
    unsafe { finish(fetched, end - pos, celt) }
}

#[implement(IEnumString)]
pub struct StringEnum(Cursor<String>);

impl StringEnum {
    pub fn create(items: Vec<String>) -> IEnumString {
        StringEnum(Cursor::new(items)).into()
    }
}

impl IEnumString_Impl for StringEnum_Impl {
    // windows-rs declares the IEnum* methods safe although they take raw pointers: the COM
    // runtime passes them under the interface's contract; they are dereferenced only in
    // the `unsafe fn`s of this module, each with its SAFETY argument.
    #[allow(clippy::not_unsafe_ptr_arg_deref)]
    fn Next(&self, celt: u32, rgelt: *mut PWSTR, fetched: *mut u32) -> HRESULT {
        if let Err(hr) = check_next(celt, rgelt, fetched) {
            return hr;
        }
        let (pos, end) = self.0.peek(celt);
        let mut out: Vec<PWSTR> = Vec::with_capacity(end - pos);
        for s in &self.0.items()[pos..end] {
            match crate::abi::alloc_wstr(s) {
                Ok(p) => out.push(p),
                Err(e) => {
                    out.into_iter().for_each(crate::abi::free_wstr);
                    return e.code();
                }
            }
        }
        for (i, p) in out.iter().enumerate() {
            // SAFETY: rgelt has room for `celt` >= end - pos elements (COM contract).
            unsafe { *rgelt.add(i) = *p };
        }
        self.0.commit(end);
        // SAFETY: `fetched` is this method's pceltFetched.
        unsafe { finish(fetched, end - pos, celt) }
    }
    fn Skip(&self, celt: u32) -> HRESULT {
        self.0.skip(celt)
    }
    fn Reset(&self) -> windows::core::Result<()> {
        self.0.reset();
        Ok(())
    }
    fn Clone(&self) -> windows::core::Result<IEnumString> {
        Ok(StringEnum(self.0.fork()).into())
    }
}

#[implement(IEnumUnknown)]
pub struct UnknownEnum(Cursor<IUnknown>);

impl UnknownEnum {
    pub fn create(items: Vec<IUnknown>) -> IEnumUnknown {
        UnknownEnum(Cursor::new(items)).into()
    }
}

impl IEnumUnknown_Impl for UnknownEnum_Impl {
    // windows-rs declares the IEnum* methods safe although they take raw pointers: the COM
    // runtime passes them under the interface's contract; they are dereferenced only in
    // the `unsafe fn`s of this module, each with its SAFETY argument.
    #[allow(clippy::not_unsafe_ptr_arg_deref)]
    fn Next(&self, celt: u32, rgelt: *mut Option<IUnknown>, fetched: *mut u32) -> HRESULT {
        // SAFETY: this method's parameters, under the IEnum*::Next contract.
        unsafe { next_into(&self.0, celt, rgelt, fetched, |u| Some(u.clone())) }
    }
    fn Skip(&self, celt: u32) -> windows::core::Result<()> {
        self.0.skip_result(celt)
    }
    fn Reset(&self) -> windows::core::Result<()> {
        self.0.reset();
        Ok(())
    }
    fn Clone(&self) -> windows::core::Result<IEnumUnknown> {
        Ok(UnknownEnum(self.0.fork()).into())
    }
}

#[implement(IEnumConnectionPoints)]
pub struct ConnectionPointEnum(Cursor<IConnectionPoint>);

impl ConnectionPointEnum {
    pub fn create(items: Vec<IConnectionPoint>) -> IEnumConnectionPoints {
        ConnectionPointEnum(Cursor::new(items)).into()
    }
}

impl IEnumConnectionPoints_Impl for ConnectionPointEnum_Impl {
    // windows-rs declares the IEnum* methods safe although they take raw pointers: the COM
    // runtime passes them under the interface's contract; they are dereferenced only in
    // the `unsafe fn`s of this module, each with its SAFETY argument.
    #[allow(clippy::not_unsafe_ptr_arg_deref)]
    fn Next(&self, celt: u32, rgelt: *mut Option<IConnectionPoint>, fetched: *mut u32) -> HRESULT {
        // SAFETY: this method's parameters, under the IEnum*::Next contract.
        unsafe { next_into(&self.0, celt, rgelt, fetched, |cp| Some(cp.clone())) }
    }
    fn Skip(&self, celt: u32) -> windows::core::Result<()> {
        self.0.skip_result(celt)
    }
    fn Reset(&self) -> windows::core::Result<()> {
        self.0.reset();
        Ok(())
    }
    fn Clone(&self) -> windows::core::Result<IEnumConnectionPoints> {
        Ok(ConnectionPointEnum(self.0.fork()).into())
    }
}

/// IConnectionPoint::EnumConnections: (cookie, sink) pairs.
#[implement(IEnumConnections)]
pub struct ConnectionEnum(Cursor<(u32, IUnknown)>);

impl ConnectionEnum {
    pub fn create(items: Vec<(u32, IUnknown)>) -> IEnumConnections {
        ConnectionEnum(Cursor::new(items)).into()
    }
}

impl IEnumConnections_Impl for ConnectionEnum_Impl {
    // windows-rs declares the IEnum* methods safe although they take raw pointers: the COM
    // runtime passes them under the interface's contract; they are dereferenced only in
    // the `unsafe fn`s of this module, each with its SAFETY argument.
    #[allow(clippy::not_unsafe_ptr_arg_deref)]
    fn Next(&self, celt: u32, rgcd: *mut CONNECTDATA, fetched: *mut u32) -> HRESULT {
        // SAFETY: this method's parameters, under the IEnum*::Next contract.
        unsafe {
            next_into(&self.0, celt, rgcd, fetched, |(cookie, unk)| CONNECTDATA {
                pUnk: std::mem::ManuallyDrop::new(Some(unk.clone())),
                dwCookie: *cookie,
            })
        }
    }
    fn Skip(&self, celt: u32) -> windows::core::Result<()> {
        self.0.skip_result(celt)
    }
    fn Reset(&self) -> windows::core::Result<()> {
        self.0.reset();
        Ok(())
    }
    fn Clone(&self) -> windows::core::Result<IEnumConnections> {
        Ok(ConnectionEnum(self.0.fork()).into())
    }
}
