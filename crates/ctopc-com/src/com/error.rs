//! The one place where core errors become COM errors, for every object of the server.
//!
//! Decided once: a whole-call error carries a message object. [`to_com`] gives the
//! error's HRESULT (the client sees exactly [`hresult`]) plus an `IErrorInfo` with the
//! error's symbol as description, made with oleaut32's `CreateErrorInfo` and set on the
//! thread, so that it also reaches a client whose COM runtime transmits error objects.
//!
//! Why not `windows::core::Error::new(code, message)`: with a non-empty message it calls
//! combase's `RoOriginateErrorW`, which Wine 8 exports only as an unimplemented stub;
//! calling it aborts the whole server process. The `CreateErrorInfo` path of [`error`]
//! does not go near it: `CreateErrorInfo`/`SetErrorInfo` are plain oleaut32/ole32 calls
//! that Wine implements, and `Error::from(HRESULT)` only takes the thread's error object
//! back with `GetErrorInfo` (windows-result 0.4). Clippy's `disallowed_methods`
//! (`clippy.toml`) keeps `Error::new` out of every crate; only this module may allow it.
#![allow(clippy::disallowed_methods)]

use ctopc_core::OpcError;
use windows::core::HRESULT;

/// Maps a core error to a COM error (the single mapping point).
pub fn to_com(e: OpcError) -> windows::core::Error {
    error(hresult(e), e.symbol())
}

/// A COM error with a message, carried by an `IErrorInfo` from oleaut32's
/// `CreateErrorInfo` (set on the thread, so that the error also reaches a client whose COM
/// runtime transmits error objects).
///
/// Not `windows::core::Error::new`: with a message it calls combase's
/// `RoOriginateErrorW`, which Wine 8 exports only as an unimplemented stub, and calling
/// that aborts the whole server process.
pub fn error(code: HRESULT, message: &str) -> windows::core::Error {
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

/// The HRESULT of a core error (per-item codes, and methods that return a raw HRESULT).
pub fn hresult(e: OpcError) -> HRESULT {
    HRESULT(e.hresult())
}
