//! The platform's quirks, one file per platform, entered from the apartment guard
//! (`super::apartment`), from the caller's identity (`super::caller`, which asks why a
//! call has no security context) and from the files of secrets (`super::secret_file`,
//! which asks what a file's DACL read back means): nothing else in the product asks which
//! platform it runs on.

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

/// Whether a file's DACL read back is the one written. Not under Wine: upstream Wine (8)
/// keeps no security descriptor of a file (the `user.wine.sd` extended attribute is a
/// wine-staging patch); it maps a DACL set on a file onto the Unix mode (an ACE for
/// Everyone becomes the others' bits) and, when asked, makes a DACL from the mode: full
/// control for SYSTEM and the owner, Everyone for the others' bits, never protected, no
/// inheritance flags.
pub fn keeps_file_dacls() -> bool {
    !wine::under_wine()
}

/// A file's descriptor as read back, judged as Windows would keep it: under Wine (see
/// [`keeps_file_dacls`]) the protection cannot be read, so it is taken as written, and
/// what Wine can tell (who besides the owner may read, from the mode) is judged.
pub fn file_descriptor_as_kept(
    mut d: ctopc_registration::security::Descriptor,
) -> ctopc_registration::security::Descriptor {
    if !keeps_file_dacls() {
        d.protected = true;
    }
    d
}
