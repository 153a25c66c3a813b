//! Our own definitions of the COM-defined interfaces that the server implements
//! (IConnectionPointContainer, IConnectionPoint, IEnumString, IEnumUnknown,
//! IEnumConnectionPoints, IEnumConnections, IEnumGUID, IDataObject), for the implementing
//! side only; and IAdviseSink (with `STGMEDIUM`), which the group calls and the DA 1.0a
//! test client implements.
//!
//! Why: windows-rs' generated vtable shims of these interfaces (`IConnectionPoint_Impl`
//! and the others) turn methods with one out-parameter into `fn(..) -> Result<T>` and
//! write the result through the caller's pointer **without a NULL check** (a NULL
//! out-parameter would crash the server), and leave it as it was on failure (COM wants NULL).
//! Here every out-parameter is a raw pointer and every method returns its raw HRESULT, so
//! the checks are ours: out-parameters are cleared first (`abi::clear_outs`), a NULL one
//! is E_POINTER (these methods' contracts name it), and they are filled on success only.
//!
//! Each interface has the IID and the vtable order of the SDK's (`ocidl.idl`,
//! `objidl.idl`); parameter types have the layout of the SDK's (`*mut Option<I>` is an
//! interface pointer out-parameter). A client (the proxy, the in-process tests, our own
//! client code) keeps using windows-rs' types: COM matches by IID and vtable layout, and
//! [`From`] turns one of ours into windows-rs' type of the same interface.

#![allow(non_snake_case)]

use std::ffi::c_void;
use windows::Win32::System::Com::{
    IAdviseSink, IConnectionPoint, IConnectionPointContainer, IDataObject, IEnumConnectionPoints,
    IEnumConnections, IEnumFORMATETC, IEnumGUID, IEnumSTATDATA, IEnumString, IEnumUnknown,
    CONNECTDATA, FORMATETC, STATDATA,
};
use windows_core::{interface, IUnknown, IUnknown_Vtbl, Interface, BOOL, GUID, HRESULT, PWSTR};

/// `IConnectionPointContainer` (`ocidl.idl`).
#[interface("b196b284-bab4-101a-b69c-00aa00341d07")]
pub unsafe trait RawConnectionPointContainer: IUnknown {
    pub fn EnumConnectionPoints(&self, ppenum: *mut Option<IEnumConnectionPoints>) -> HRESULT;
    pub fn FindConnectionPoint(
        &self,
        riid: *const GUID,
        ppcp: *mut Option<IConnectionPoint>,
    ) -> HRESULT;
}

/// `IConnectionPoint` (`ocidl.idl`).
#[interface("b196b286-bab4-101a-b69c-00aa00341d07")]
pub unsafe trait RawConnectionPoint: IUnknown {
    pub fn GetConnectionInterface(&self, piid: *mut GUID) -> HRESULT;
    pub fn GetConnectionPointContainer(
        &self,
        ppcpc: *mut Option<IConnectionPointContainer>,
    ) -> HRESULT;
    pub fn Advise(&self, punksink: *mut c_void, pdwcookie: *mut u32) -> HRESULT;
    pub fn Unadvise(&self, dwcookie: u32) -> HRESULT;
    pub fn EnumConnections(&self, ppenum: *mut Option<IEnumConnections>) -> HRESULT;
}

/// `IEnumString` (`objidl.idl`).
#[interface("00000101-0000-0000-c000-000000000046")]
pub unsafe trait RawEnumString: IUnknown {
    pub fn Next(&self, celt: u32, rgelt: *mut PWSTR, pceltfetched: *mut u32) -> HRESULT;
    pub fn Skip(&self, celt: u32) -> HRESULT;
    pub fn Reset(&self) -> HRESULT;
    pub fn Clone(&self, ppenum: *mut Option<IEnumString>) -> HRESULT;
}

/// `IEnumUnknown` (`objidl.idl`).
#[interface("00000100-0000-0000-c000-000000000046")]
pub unsafe trait RawEnumUnknown: IUnknown {
    pub fn Next(&self, celt: u32, rgelt: *mut Option<IUnknown>, pceltfetched: *mut u32) -> HRESULT;
    pub fn Skip(&self, celt: u32) -> HRESULT;
    pub fn Reset(&self) -> HRESULT;
    pub fn Clone(&self, ppenum: *mut Option<IEnumUnknown>) -> HRESULT;
}

/// `IEnumConnectionPoints` (`ocidl.idl`).
#[interface("b196b285-bab4-101a-b69c-00aa00341d07")]
pub unsafe trait RawEnumConnectionPoints: IUnknown {
    pub fn Next(
        &self,
        cconnections: u32,
        ppcp: *mut Option<IConnectionPoint>,
        pcfetched: *mut u32,
    ) -> HRESULT;
    pub fn Skip(&self, cconnections: u32) -> HRESULT;
    pub fn Reset(&self) -> HRESULT;
    pub fn Clone(&self, ppenum: *mut Option<IEnumConnectionPoints>) -> HRESULT;
}

/// `IEnumConnections` (`ocidl.idl`).
#[interface("b196b287-bab4-101a-b69c-00aa00341d07")]
pub unsafe trait RawEnumConnections: IUnknown {
    pub fn Next(&self, cconnections: u32, rgcd: *mut CONNECTDATA, pcfetched: *mut u32) -> HRESULT;
    pub fn Skip(&self, cconnections: u32) -> HRESULT;
    pub fn Reset(&self) -> HRESULT;
    pub fn Clone(&self, ppenum: *mut Option<IEnumConnections>) -> HRESULT;
}

/// Our definition and windows-rs' of the same interface: the IIDs are checked equal at
/// compile time, and `From` hands one of ours out as windows-rs' type.
macro_rules! same_interface {
    ($($ours:ident => $theirs:ident),+ $(,)?) => {
        $(
            const _: () = assert!(
                <$ours as Interface>::IID.to_u128() == <$theirs as Interface>::IID.to_u128()
            );

            impl From<$ours> for $theirs {
                fn from(ours: $ours) -> $theirs {
                    // SAFETY: the same COM interface (the IIDs are equal, asserted above,
                    // and the vtables have the SDK's method order and parameter layout):
                    // the owned reference is handed over as it is.
                    unsafe { $theirs::from_raw(ours.into_raw()) }
                }
            }
        )+
    };
}

same_interface! {
    RawConnectionPointContainer => IConnectionPointContainer,
    RawConnectionPoint => IConnectionPoint,
    RawEnumString => IEnumString,
    RawEnumUnknown => IEnumUnknown,
    RawEnumConnectionPoints => IEnumConnectionPoints,
    RawEnumConnections => IEnumConnections,
    RawEnumGUID => IEnumGUID,
}

/// `IEnumGUID` (`comcat.idl`): the server browser's `IOPCServerList` enumerator.
#[interface("0002e000-0000-0000-c000-000000000046")]
pub unsafe trait RawEnumGUID: IUnknown {
    pub fn Next(&self, celt: u32, rgelt: *mut GUID, pceltfetched: *mut u32) -> HRESULT;
    pub fn Skip(&self, celt: u32) -> HRESULT;
    pub fn Reset(&self) -> HRESULT;
    pub fn Clone(&self, ppenum: *mut Option<IEnumGUID>) -> HRESULT;
}

// ---- DA 1.0a: IDataObject and IAdviseSink ---------------------------------------------

/// `STGMEDIUM` (`objidl.idl`) with its union as the one pointer-sized handle it is: the
/// group only ever passes `TYMED_HGLOBAL` (windows-rs' `STGMEDIUM` needs the GDI bindings
/// for the union's other members).
#[repr(C)]
#[derive(Debug)]
pub struct StgMedium {
    pub tymed: u32,
    /// `hGlobal` for `TYMED_HGLOBAL`.
    pub handle: *mut c_void,
    /// `pUnkForRelease` (NULL: the receiver frees nothing, the caller frees the medium).
    pub unk_for_release: *mut c_void,
}

/// `IDataObject` (`objidl.idl`): the DA 1.0a group's data transfer (`group::dataobject`).
#[interface("0000010e-0000-0000-c000-000000000046")]
pub unsafe trait RawDataObject: IUnknown {
    pub fn GetData(&self, pformatetcin: *const FORMATETC, pmedium: *mut StgMedium) -> HRESULT;
    pub fn GetDataHere(&self, pformatetc: *const FORMATETC, pmedium: *mut StgMedium) -> HRESULT;
    pub fn QueryGetData(&self, pformatetc: *const FORMATETC) -> HRESULT;
    pub fn GetCanonicalFormatEtc(
        &self,
        pformatectin: *const FORMATETC,
        pformatetcout: *mut FORMATETC,
    ) -> HRESULT;
    pub fn SetData(
        &self,
        pformatetc: *const FORMATETC,
        pmedium: *const StgMedium,
        frelease: BOOL,
    ) -> HRESULT;
    pub fn EnumFormatEtc(
        &self,
        dwdirection: u32,
        ppenumformatetc: *mut Option<IEnumFORMATETC>,
    ) -> HRESULT;
    pub fn DAdvise(
        &self,
        pformatetc: *const FORMATETC,
        advf: u32,
        padvsink: *mut c_void,
        pdwconnection: *mut u32,
    ) -> HRESULT;
    pub fn DUnadvise(&self, dwconnection: u32) -> HRESULT;
    pub fn EnumDAdvise(&self, ppenumadvise: *mut Option<IEnumSTATDATA>) -> HRESULT;
}

/// `IAdviseSink` (`objidl.idl`): called by the group for the DA 1.0a streams, implemented
/// by DA 1.0a clients (the e2e tests' own). Its methods return nothing.
#[interface("0000010f-0000-0000-c000-000000000046")]
pub unsafe trait RawAdviseSink: IUnknown {
    pub fn OnDataChange(&self, pformatetc: *const FORMATETC, pstgmed: *const StgMedium);
    pub fn OnViewChange(&self, dwaspect: u32, lindex: i32);
    pub fn OnRename(&self, pmk: *mut c_void);
    pub fn OnSave(&self);
    pub fn OnClose(&self);
}

/// `IEnumSTATDATA` (`objidl.idl`): IDataObject::EnumDAdvise's enumerator.
#[interface("00000105-0000-0000-c000-000000000046")]
pub unsafe trait RawEnumSTATDATA: IUnknown {
    pub fn Next(&self, celt: u32, rgelt: *mut STATDATA, pceltfetched: *mut u32) -> HRESULT;
    pub fn Skip(&self, celt: u32) -> HRESULT;
    pub fn Reset(&self) -> HRESULT;
    pub fn Clone(&self, ppenum: *mut Option<IEnumSTATDATA>) -> HRESULT;
}

same_interface! {
    RawDataObject => IDataObject,
    RawAdviseSink => IAdviseSink,
    RawEnumSTATDATA => IEnumSTATDATA,
}
