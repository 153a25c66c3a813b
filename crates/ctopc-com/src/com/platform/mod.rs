//! The platform's quirks, one file per platform, entered from the apartment guard
//! (`super::apartment`) and from the caller's identity (`super::caller`, which asks why a
//! call has no security context): nothing else in the product asks which platform it runs
//! on.

pub mod wine;

/// Why the call's security context could not be read: `api` failed with `hr`; under Wine
/// (no DCOM call security: `CoQueryClientBlanket` and `CoImpersonateClient` have no call
/// context to answer from) the text says so.
pub fn caller_context_reason(api: &str, hr: windows_core::HRESULT) -> String {
    let code = hr.0 as u32;
    let name = match code {
        0x8001_0117 => " RPC_E_CALL_COMPLETE",
        0x8000_4001 => " E_NOTIMPL",
        0x8000_4002 => " E_NOINTERFACE",
        0x8007_0005 => " E_ACCESSDENIED",
        _ => "",
    };
    if wine::under_wine() {
        format!("{api}: {code:#010x}{name}; Wine has no DCOM call security")
    } else {
        format!("{api}: {code:#010x}{name}")
    }
}
