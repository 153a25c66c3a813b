//! Rust definitions of the OPC Common and OPC Data Access custom interfaces, mirroring the
//! project's IDL (`idl/opccomn.idl`, `idl/opcda.idl`), from which the proxy/stub DLL is built.
//!
//! * IIDs and method order come from the OPC Foundation's `opccomn.idl` / `opcda.idl`
//!   (DA 3.00 edition, which also contains the DA 1.0/2.05a interfaces).
//!   `xtask/tests/interfaces_match_idl.rs` fails when an interface, IID, base interface,
//!   method order or method arity here drifts from `idl/`.
//! * Methods that may return `S_FALSE` or an `OPC_S_*` success code (per-item operations,
//!   enumerators' `Next`/`Skip`, empty-enumerator creation, `AddGroup`/`SetState` with
//!   `OPC_S_UNSUPPORTEDRATE`, `RemoveGroup` with `OPC_S_INUSE`) return a raw `HRESULT`; the
//!   others return `windows_core::Result<()>`.
//! * Strings: `[in, string]` are `PCWSTR`, `[out, string]` are `*mut PWSTR` (CoTaskMem).
//!   Arrays are raw pointers: `[in, size_is]` as `*const T`, `[out, size_is, size_is]` as
//!   `*mut *mut T` (CoTaskMem, allocated by the callee).
//! * Interface out-parameters are `*mut Option<I>`; `[iid_is(riid)]` ones are
//!   `*mut Option<IUnknown>` holding a pointer of interface `riid`.
//! * IDL names are kept (methods, parameters, struct fields, constants).

#![allow(
    non_snake_case,
    non_camel_case_types,
    non_upper_case_globals,
    clippy::too_many_arguments,
    clippy::upper_case_acronyms
)]

pub mod common;
pub mod da;
pub mod errors;
pub mod types;

pub use common::*;
pub use da::*;
pub use errors::*;
pub use types::*;

use windows_core::{Interface, GUID};

macro_rules! iid_consts {
    ($($iid:ident => $itf:ident),+ $(,)?) => {
        $(
            #[doc = concat!("`IID_", stringify!($itf), "`.")]
            pub const $iid: GUID = <$itf as Interface>::IID;
        )+
    };
}

iid_consts! {
    IID_IOPCShutdown => IOPCShutdown,
    IID_IOPCCommon => IOPCCommon,
    IID_IOPCServerList => IOPCServerList,
    IID_IOPCEnumGUID => IOPCEnumGUID,
    IID_IOPCServerList2 => IOPCServerList2,
    IID_IOPCServer => IOPCServer,
    IID_IOPCServerPublicGroups => IOPCServerPublicGroups,
    IID_IOPCBrowseServerAddressSpace => IOPCBrowseServerAddressSpace,
    IID_IOPCGroupStateMgt => IOPCGroupStateMgt,
    IID_IOPCGroupStateMgt2 => IOPCGroupStateMgt2,
    IID_IOPCPublicGroupStateMgt => IOPCPublicGroupStateMgt,
    IID_IOPCSyncIO => IOPCSyncIO,
    IID_IOPCSyncIO2 => IOPCSyncIO2,
    IID_IOPCAsyncIO => IOPCAsyncIO,
    IID_IOPCAsyncIO2 => IOPCAsyncIO2,
    IID_IOPCAsyncIO3 => IOPCAsyncIO3,
    IID_IOPCItemMgt => IOPCItemMgt,
    IID_IEnumOPCItemAttributes => IEnumOPCItemAttributes,
    IID_IOPCDataCallback => IOPCDataCallback,
    IID_IOPCItemProperties => IOPCItemProperties,
    IID_IOPCItemDeadbandMgt => IOPCItemDeadbandMgt,
    IID_IOPCItemSamplingMgt => IOPCItemSamplingMgt,
    IID_IOPCBrowse => IOPCBrowse,
    IID_IOPCItemIO => IOPCItemIO,
}
