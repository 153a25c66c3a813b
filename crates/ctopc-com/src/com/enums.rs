//! Snapshot enumerators (IEnumString, IEnumUnknown, IEnumConnectionPoints,
//! IEnumConnections, IEnumSTATDATA): the list is taken when the enumerator is created; clones share it
//! and copy the position.
//!
//! They implement our own definitions of the interfaces (`crate::com::comdef`): `Clone` with a
//! NULL out-parameter is E_POINTER (windows-rs' shim wrote through it), and every
//! out-parameter is cleared first and filled on success only.

use crate::com::abi;
use crate::com::abi::out_or_e_pointer;
use crate::com::comdef::{
    RawEnumConnectionPoints, RawEnumConnectionPoints_Impl, RawEnumConnections,
    RawEnumConnections_Impl, RawEnumSTATDATA, RawEnumSTATDATA_Impl, RawEnumString,
    RawEnumString_Impl, RawEnumUnknown, RawEnumUnknown_Impl,
};
use std::sync::{Arc, Mutex};
use windows::core::{implement, IUnknown, HRESULT, PWSTR};
use windows::Win32::Foundation::{E_INVALIDARG, E_POINTER, S_FALSE, S_OK};
use windows::Win32::System::Com::{
    IAdviseSink, IConnectionPoint, IEnumConnectionPoints, IEnumConnections, IEnumSTATDATA,
    IEnumString, IEnumUnknown, CONNECTDATA, FORMATETC, STATDATA,
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
pub unsafe fn next_into<T, U>(
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

/// IEnum*::Clone: `*ppenum` is a new enumerator sharing the snapshot at the same position;
/// E_POINTER (nothing made) for a NULL `ppenum`.
///
/// # Safety
/// `ppenum` is NULL or writable caller storage for one interface pointer (the `[out]`).
pub unsafe fn clone_out<I>(ppenum: *mut Option<I>, make: impl FnOnce() -> I) -> HRESULT {
    if ppenum.is_null() {
        return E_POINTER;
    }
    // SAFETY: contract of this function (non-null checked above).
    unsafe { out_or_e_pointer(ppenum, Some(make())) }
}

/// The strings an [`StringEnum`] hands out: a snapshot shared by its clones.
pub trait StringList: Send + Sync {
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The `i`-th string (`None` past the end).
    fn get(&self, i: usize) -> Option<&str>;
}

impl StringList for Vec<String> {
    fn len(&self) -> usize {
        Vec::len(self)
    }
    fn get(&self, i: usize) -> Option<&str> {
        self.as_slice().get(i).map(String::as_str)
    }
}

/// A `BrowseOPCItemIDs` listing: indexes into the address space, the names never copied
/// until `Next` hands them out.
impl StringList for ctopc_core::browse::NameList {
    fn len(&self) -> usize {
        ctopc_core::browse::NameList::len(self)
    }
    fn get(&self, i: usize) -> Option<&str> {
        ctopc_core::browse::NameList::get(self, i)
    }
}

/// A `BrowseOPCItemIDs` listing with the `_Diagnostics` branch: the parts of both
/// address spaces, as indexes.
impl StringList for ctopc_core::diagnostics::browse::Listing {
    fn len(&self) -> usize {
        ctopc_core::diagnostics::browse::Listing::len(self)
    }
    fn get(&self, i: usize) -> Option<&str> {
        ctopc_core::diagnostics::browse::Listing::get(self, i)
    }
}

/// IEnumString over a shared [`StringList`]: `Next(celt)` allocates the `celt` strings
/// straight into the caller's array (one pass, no copy of the listing), `Clone` shares the
/// list.
#[implement(RawEnumString)]
pub struct StringEnum {
    list: Arc<dyn StringList>,
    pos: Mutex<usize>,
}

impl StringEnum {
    pub fn create(items: Vec<String>) -> IEnumString {
        StringEnum::of(Arc::new(items))
    }

    /// An enumerator over `list` from its start.
    pub fn of(list: Arc<dyn StringList>) -> IEnumString {
        StringEnum::at(list, 0)
    }

    fn at(list: Arc<dyn StringList>, pos: usize) -> IEnumString {
        let e: RawEnumString = StringEnum {
            list,
            pos: Mutex::new(pos),
        }
        .into();
        e.into()
    }

    fn pos(&self) -> std::sync::MutexGuard<'_, usize> {
        self.pos.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl RawEnumString_Impl for StringEnum_Impl {
    unsafe fn Next(&self, celt: u32, rgelt: *mut PWSTR, fetched: *mut u32) -> HRESULT {
        if let Err(hr) = check_next(celt, rgelt, fetched) {
            return hr;
        }
        let mut pos = self.pos();
        let end = pos.saturating_add(celt as usize).min(self.list.len());
        for (i, k) in (*pos..end).enumerate() {
            match abi::alloc_wstr(self.list.get(k).unwrap_or_default()) {
                // SAFETY: rgelt has room for `celt` >= end - pos elements (COM contract).
                Ok(p) => unsafe { *rgelt.add(i) = p },
                Err(e) => {
                    for j in 0..i {
                        // SAFETY: elements 0..i were written above with strings of ours;
                        // each is freed once and the slot cleared (nothing handed out).
                        unsafe {
                            abi::free_wstr(*rgelt.add(j));
                            *rgelt.add(j) = PWSTR::null();
                        }
                    }
                    return e.code();
                }
            }
        }
        let got = end - *pos;
        *pos = end;
        drop(pos);
        // SAFETY: `fetched` is this method's pceltFetched.
        unsafe { finish(fetched, got, celt) }
    }
    unsafe fn Skip(&self, celt: u32) -> HRESULT {
        let mut pos = self.pos();
        let end = pos.saturating_add(celt as usize).min(self.list.len());
        let skipped = end - *pos;
        *pos = end;
        if skipped == celt as usize {
            S_OK
        } else {
            S_FALSE
        }
    }
    unsafe fn Reset(&self) -> HRESULT {
        *self.pos() = 0;
        S_OK
    }
    unsafe fn Clone(&self, ppenum: *mut Option<IEnumString>) -> HRESULT {
        let pos = *self.pos();
        // SAFETY: `ppenum` is this method's [out] interface pointer.
        unsafe { clone_out(ppenum, || StringEnum::at(Arc::clone(&self.list), pos)) }
    }
}

#[implement(RawEnumUnknown)]
pub struct UnknownEnum(Cursor<IUnknown>);

impl UnknownEnum {
    pub fn create(items: Vec<IUnknown>) -> IEnumUnknown {
        UnknownEnum::from_cursor(Cursor::new(items))
    }

    fn from_cursor(cursor: Cursor<IUnknown>) -> IEnumUnknown {
        let e: RawEnumUnknown = UnknownEnum(cursor).into();
        e.into()
    }
}

impl RawEnumUnknown_Impl for UnknownEnum_Impl {
    unsafe fn Next(&self, celt: u32, rgelt: *mut Option<IUnknown>, fetched: *mut u32) -> HRESULT {
        // SAFETY: this method's parameters, under the IEnum*::Next contract.
        unsafe { next_into(&self.0, celt, rgelt, fetched, |u| Some(u.clone())) }
    }
    unsafe fn Skip(&self, celt: u32) -> HRESULT {
        self.0.skip(celt)
    }
    unsafe fn Reset(&self) -> HRESULT {
        self.0.reset();
        S_OK
    }
    unsafe fn Clone(&self, ppenum: *mut Option<IEnumUnknown>) -> HRESULT {
        // SAFETY: `ppenum` is this method's [out] interface pointer.
        unsafe { clone_out(ppenum, || UnknownEnum::from_cursor(self.0.fork())) }
    }
}

#[implement(RawEnumConnectionPoints)]
pub struct ConnectionPointEnum(Cursor<IConnectionPoint>);

impl ConnectionPointEnum {
    pub fn create(items: Vec<IConnectionPoint>) -> IEnumConnectionPoints {
        ConnectionPointEnum::from_cursor(Cursor::new(items))
    }

    fn from_cursor(cursor: Cursor<IConnectionPoint>) -> IEnumConnectionPoints {
        let e: RawEnumConnectionPoints = ConnectionPointEnum(cursor).into();
        e.into()
    }
}

impl RawEnumConnectionPoints_Impl for ConnectionPointEnum_Impl {
    unsafe fn Next(
        &self,
        celt: u32,
        rgelt: *mut Option<IConnectionPoint>,
        fetched: *mut u32,
    ) -> HRESULT {
        // SAFETY: this method's parameters, under the IEnum*::Next contract.
        unsafe { next_into(&self.0, celt, rgelt, fetched, |cp| Some(cp.clone())) }
    }
    unsafe fn Skip(&self, celt: u32) -> HRESULT {
        self.0.skip(celt)
    }
    unsafe fn Reset(&self) -> HRESULT {
        self.0.reset();
        S_OK
    }
    unsafe fn Clone(&self, ppenum: *mut Option<IEnumConnectionPoints>) -> HRESULT {
        // SAFETY: `ppenum` is this method's [out] interface pointer.
        unsafe { clone_out(ppenum, || ConnectionPointEnum::from_cursor(self.0.fork())) }
    }
}

/// IConnectionPoint::EnumConnections: (cookie, sink) pairs.
#[implement(RawEnumConnections)]
pub struct ConnectionEnum(Cursor<(u32, IUnknown)>);

impl ConnectionEnum {
    pub fn create(items: Vec<(u32, IUnknown)>) -> IEnumConnections {
        ConnectionEnum::from_cursor(Cursor::new(items))
    }

    fn from_cursor(cursor: Cursor<(u32, IUnknown)>) -> IEnumConnections {
        let e: RawEnumConnections = ConnectionEnum(cursor).into();
        e.into()
    }
}

impl RawEnumConnections_Impl for ConnectionEnum_Impl {
    unsafe fn Next(&self, celt: u32, rgcd: *mut CONNECTDATA, fetched: *mut u32) -> HRESULT {
        // SAFETY: this method's parameters, under the IEnum*::Next contract.
        unsafe {
            next_into(&self.0, celt, rgcd, fetched, |(cookie, unk)| CONNECTDATA {
                pUnk: std::mem::ManuallyDrop::new(Some(unk.clone())),
                dwCookie: *cookie,
            })
        }
    }
    unsafe fn Skip(&self, celt: u32) -> HRESULT {
        self.0.skip(celt)
    }
    unsafe fn Reset(&self) -> HRESULT {
        self.0.reset();
        S_OK
    }
    unsafe fn Clone(&self, ppenum: *mut Option<IEnumConnections>) -> HRESULT {
        // SAFETY: `ppenum` is this method's [out] interface pointer.
        unsafe { clone_out(ppenum, || ConnectionEnum::from_cursor(self.0.fork())) }
    }
}

/// IDataObject::EnumDAdvise: (format, advise flags, sink, connection) of each DA 1.0a
/// advise connection.
#[implement(RawEnumSTATDATA)]
pub struct StatDataEnum(Cursor<(FORMATETC, u32, IAdviseSink, u32)>);

// SAFETY: FORMATETC's only pointer (`ptd`) is always NULL here; the sinks are MTA
// proxies, as in `connpoint::SinkSlot`.
unsafe impl Send for StatDataEnum {}
// SAFETY: as above; the cursor guards its position with a mutex.
unsafe impl Sync for StatDataEnum {}

impl StatDataEnum {
    pub fn create(items: Vec<(FORMATETC, u32, IAdviseSink, u32)>) -> IEnumSTATDATA {
        StatDataEnum::from_cursor(Cursor::new(items))
    }

    fn from_cursor(cursor: Cursor<(FORMATETC, u32, IAdviseSink, u32)>) -> IEnumSTATDATA {
        let e: RawEnumSTATDATA = StatDataEnum(cursor).into();
        e.into()
    }
}

impl RawEnumSTATDATA_Impl for StatDataEnum_Impl {
    unsafe fn Next(&self, celt: u32, rgelt: *mut STATDATA, fetched: *mut u32) -> HRESULT {
        // SAFETY: this method's parameters, under the IEnum*::Next contract.
        unsafe {
            next_into(&self.0, celt, rgelt, fetched, |(f, advf, sink, c)| {
                STATDATA {
                    formatetc: *f,
                    advf: *advf,
                    pAdvSink: std::mem::ManuallyDrop::new(Some(sink.clone())),
                    dwConnection: *c,
                }
            })
        }
    }
    unsafe fn Skip(&self, celt: u32) -> HRESULT {
        self.0.skip(celt)
    }
    unsafe fn Reset(&self) -> HRESULT {
        self.0.reset();
        S_OK
    }
    unsafe fn Clone(&self, ppenum: *mut Option<IEnumSTATDATA>) -> HRESULT {
        // SAFETY: `ppenum` is this method's [out] interface pointer.
        unsafe { clone_out(ppenum, || StatDataEnum::from_cursor(self.0.fork())) }
    }
}
