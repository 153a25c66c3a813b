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

/// Why the local group `name` cannot be found right after `NetLocalGroupAdd` answered
/// success: under Wine, whose netapi32 `NetLocalGroupAdd` is a stub (it answers
/// `NERR_Success` and creates nothing; Wine has no local account database), the text says
/// so; elsewhere it names the lookup that failed.
pub fn local_group_missing_reason(name: &str) -> String {
    if wine::under_wine() {
        format!("Wine's NetLocalGroupAdd is a stub: it reports success and creates no group, so LookupAccountName finds no \"{name}\"")
    } else {
        format!("LookupAccountName finds no \"{name}\" after NetLocalGroupAdd reported success")
    }
}
