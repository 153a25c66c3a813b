//! OPC DA result codes (`opcerror.h`): `FACILITY_ITF` (0x004), codes 0x0001..0x04FF.
//!
//! `OPC_S_*` are success codes: a method returning one of them must be declared to return a
//! raw `HRESULT` (a `Result<()>` would turn them into `S_OK`).

use windows_core::HRESULT;

const fn hr(code: u32) -> HRESULT {
    HRESULT(code as i32)
}

/// The value of the handle is invalid.
pub const OPC_E_INVALIDHANDLE: HRESULT = hr(0xC004_0001);
/// The server cannot convert the data between the specified format and/or requested data type
/// and the canonical data type.
pub const OPC_E_BADTYPE: HRESULT = hr(0xC004_0004);
/// The requested operation cannot be done on a public group.
pub const OPC_E_PUBLIC: HRESULT = hr(0xC004_0005);
/// The item's access rights do not allow the operation.
pub const OPC_E_BADRIGHTS: HRESULT = hr(0xC004_0006);
/// The item ID is not defined in the server address space or no longer exists in it.
pub const OPC_E_UNKNOWNITEMID: HRESULT = hr(0xC004_0007);
/// The item ID does not conform to the server's syntax.
pub const OPC_E_INVALIDITEMID: HRESULT = hr(0xC004_0008);
/// The filter string was not valid.
pub const OPC_E_INVALIDFILTER: HRESULT = hr(0xC004_0009);
/// The item's access path is not known to the server.
pub const OPC_E_UNKNOWNPATH: HRESULT = hr(0xC004_000A);
/// The value was out of range.
pub const OPC_E_RANGE: HRESULT = hr(0xC004_000B);
/// Duplicate name not allowed.
pub const OPC_E_DUPLICATENAME: HRESULT = hr(0xC004_000C);
/// The server does not support the requested data rate but will use the closest available rate.
pub const OPC_S_UNSUPPORTEDRATE: HRESULT = hr(0x0004_000D);
/// A value passed to write was accepted but the output was clamped.
pub const OPC_S_CLAMP: HRESULT = hr(0x0004_000E);
/// The operation cannot be performed because the object is being referenced.
pub const OPC_S_INUSE: HRESULT = hr(0x0004_000F);
/// The server's configuration file is an invalid format.
pub const OPC_E_INVALIDCONFIGFILE: HRESULT = hr(0xC004_0010);
/// The requested object (e.g. a public group) was not found.
pub const OPC_E_NOTFOUND: HRESULT = hr(0xC004_0011);
/// The specified property ID is not valid for the item.
pub const OPC_E_INVALID_PID: HRESULT = hr(0xC004_0203);
/// The item deadband has not been set for this item (DA 3.00).
pub const OPC_E_DEADBANDNOTSET: HRESULT = hr(0xC004_0400);
/// The item does not support deadband (DA 3.00).
pub const OPC_E_DEADBANDNOTSUPPORTED: HRESULT = hr(0xC004_0401);
/// The server does not support buffering of data items that are collected at a faster rate
/// than the group update rate (DA 3.00).
pub const OPC_E_NOBUFFERING: HRESULT = hr(0xC004_0402);
/// The continuation point is not valid (DA 3.00).
pub const OPC_E_INVALIDCONTINUATIONPOINT: HRESULT = hr(0xC004_0403);
/// Not every detected change has been returned since the server's buffer reached its limit and
/// had to purge out the oldest data (DA 3.00).
pub const OPC_S_DATAQUEUEOVERFLOW: HRESULT = hr(0x0004_0404);
/// There is no sampling rate set for the specified item (DA 3.00).
pub const OPC_E_RATENOTSET: HRESULT = hr(0xC004_0405);
/// The server does not support writing of quality and/or timestamp (DA 3.00).
pub const OPC_E_NOTSUPPORTED: HRESULT = hr(0xC004_0406);
/// The dictionary and/or type description for the item has changed (Complex Data).
pub const OPCCPX_E_TYPE_CHANGED: HRESULT = hr(0xC004_0407);
/// A data filter item with the specified name already exists (Complex Data).
pub const OPCCPX_E_FILTER_DUPLICATE: HRESULT = hr(0xC004_0408);
/// The data filter value does not conform to the server's syntax (Complex Data).
pub const OPCCPX_E_FILTER_INVALID: HRESULT = hr(0xC004_0409);
/// An error occurred when the filter value was applied to the source data (Complex Data).
pub const OPCCPX_E_FILTER_ERROR: HRESULT = hr(0xC004_040A);
/// The item value is empty because the data filter has excluded all fields (Complex Data).
pub const OPCCPX_S_FILTER_NO_DATA: HRESULT = hr(0x0004_040B);
