//! Who is calling: the Windows account and groups of the client of the COM call this thread
//! is serving, from the call's security context, for the write-rights policy
//! (`ctopc_core::write_rights`), the write audit and `_Diagnostics`.
//!
//! [`current`] asks `CoQueryClientBlanket` for the call's authentication level (an
//! unauthenticated caller, level NONE, has no identity worth the name), impersonates the
//! caller (`CoImpersonateClient`) only for as long as it takes to open the thread's token,
//! reverts (`CoRevertToSelf`, always, by a guard), and reads the token's user and enabled
//! groups (`GetTokenInformation`), named by `LookupAccountSidW` (`DOMAIN\name`; a SID
//! without a name is shown as `S-1-...`). Names are cached per SID (bounded), since a
//! lookup may ask a domain controller.
//!
//! Whatever fails, the answer is [`Caller::Unknown`] with the reason (outside a call, an
//! unauthenticated legacy caller, a platform without DCOM call security: Wine, see
//! `platform::caller_context_reason`); never an error of the call that asked.

use crate::com::platform;
use ctopc_core::write_rights::Caller;
use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::Mutex;
use windows::core::PWSTR;
use windows::Win32::Foundation::{CloseHandle, ERROR_INSUFFICIENT_BUFFER, HANDLE};
use windows::Win32::Security::{
    GetLengthSid, GetTokenInformation, IsValidSid, LookupAccountNameW, LookupAccountSidW,
    TokenGroups, TokenUser, PSID, SID_AND_ATTRIBUTES, SID_NAME_USE, TOKEN_GROUPS,
    TOKEN_INFORMATION_CLASS, TOKEN_QUERY, TOKEN_USER,
};
use windows::Win32::System::Com::{CoImpersonateClient, CoQueryClientBlanket, CoRevertToSelf};
use windows::Win32::System::SystemServices::{SE_GROUP_ENABLED, SE_GROUP_LOGON_ID};
use windows::Win32::System::Threading::{GetCurrentThread, OpenThreadToken};

/// `RPC_C_AUTHN_LEVEL_NONE`: the caller did not authenticate.
const AUTHN_LEVEL_NONE: u32 = 1;
/// A token's information is read into at most this many bytes.
const MAX_TOKEN_INFO: u32 = 1 << 20;
/// At most this many groups are read of a token.
const MAX_GROUPS: usize = 1024;
/// At most this many SIDs' names are cached (the cache starts over when full).
const MAX_CACHED_NAMES: usize = 4096;

/// Who the caller of the COM call in progress on this thread is (see the module doc).
pub fn current() -> Caller {
    match query() {
        Ok(c) => c,
        Err(reason) => Caller::unknown(reason),
    }
}

fn query() -> Result<Caller, String> {
    let mut level = 0u32;
    // SAFETY: every pointer but the level's is None (not asked); the level's points to a
    // live u32.
    let blanket =
        unsafe { CoQueryClientBlanket(None, None, None, Some(&mut level), None, None, None) };
    if let Err(e) = blanket {
        return Err(platform::caller_context_reason(
            "CoQueryClientBlanket",
            e.code(),
        ));
    }
    if level == AUTHN_LEVEL_NONE {
        return Err("unauthenticated caller (authentication level none)".into());
    }
    let token = caller_token()?;
    let user = token_info(&token, TokenUser)?;
    if user.len() < std::mem::size_of::<TOKEN_USER>() {
        return Err("the caller's token has no user".into());
    }
    // SAFETY: `user` holds what GetTokenInformation(TokenUser) wrote, at least one
    // TOKEN_USER, 8-byte aligned (a Vec<u64>); its SID points into the same buffer.
    let user_sid = unsafe { (*(user.as_ptr() as *const TOKEN_USER)).User.Sid };
    let account = sid_name(user_sid).ok_or("the caller's token has an invalid user SID")?;
    let groups = token_groups(&token);
    Ok(Caller::Windows { account, groups })
}

/// A handle closed when dropped.
struct Owned(HANDLE);

impl Drop for Owned {
    fn drop(&mut self) {
        // SAFETY: a handle this module opened and nobody else closes.
        unsafe {
            let _ = CloseHandle(self.0);
        }
    }
}

/// Reverts the thread's impersonation when dropped.
struct Impersonation;

impl Drop for Impersonation {
    fn drop(&mut self) {
        // SAFETY: the thread impersonates (CoImpersonateClient succeeded); reverting ends it.
        if let Err(e) = unsafe { CoRevertToSelf() } {
            tracing::error!("CoRevertToSelf failed: {:#010x}", e.code().0 as u32);
        }
    }
}

/// The caller's token, opened while impersonating it; the impersonation ends before this
/// returns.
fn caller_token() -> Result<Owned, String> {
    // SAFETY: no arguments; it fails outside a COM call.
    if let Err(e) = unsafe { CoImpersonateClient() } {
        return Err(platform::caller_context_reason(
            "CoImpersonateClient",
            e.code(),
        ));
    }
    let _revert = Impersonation;
    let mut token = HANDLE::default();
    // SAFETY: the pseudo handle of this thread; `token` is a live out-parameter. OpenAsSelf:
    // the access check is the server's, not the caller's.
    unsafe { OpenThreadToken(GetCurrentThread(), TOKEN_QUERY, true, &mut token) }
        .map_err(|e| format!("OpenThreadToken: {:#010x}", e.code().0 as u32))?;
    Ok(Owned(token))
}

/// The token's information of `class`, in an 8-byte aligned buffer.
fn token_info(token: &Owned, class: TOKEN_INFORMATION_CLASS) -> Result<Vec<u64>, String> {
    let mut needed = 0u32;
    // SAFETY: a size query: no buffer, `needed` a live out-parameter. It fails with
    // ERROR_INSUFFICIENT_BUFFER, saying the size.
    let _ = unsafe { GetTokenInformation(token.0, class, None, 0, &mut needed) };
    if needed == 0 || needed > MAX_TOKEN_INFO {
        return Err(format!("GetTokenInformation({}): size {needed}", class.0));
    }
    let mut buf = vec![0u64; (needed as usize).div_ceil(8)];
    // SAFETY: `buf` has room for `needed` bytes.
    unsafe {
        GetTokenInformation(
            token.0,
            class,
            Some(buf.as_mut_ptr() as *mut c_void),
            needed,
            &mut needed,
        )
    }
    .map_err(|e| {
        format!(
            "GetTokenInformation({}): {:#010x}",
            class.0,
            e.code().0 as u32
        )
    })?;
    Ok(buf)
}

/// The token's enabled groups, by name (the logon-session SID left out); none when they
/// cannot be read.
fn token_groups(token: &Owned) -> Vec<String> {
    let Ok(buf) = token_info(token, TokenGroups) else {
        return Vec::new();
    };
    let bytes = buf.len() * 8;
    let head = std::mem::offset_of!(TOKEN_GROUPS, Groups);
    if bytes < head {
        return Vec::new();
    }
    // SAFETY: the buffer holds a TOKEN_GROUPS (at least its count, checked above).
    let count = unsafe { (*(buf.as_ptr() as *const TOKEN_GROUPS)).GroupCount } as usize;
    let fits = (bytes - head) / std::mem::size_of::<SID_AND_ATTRIBUTES>();
    let count = count.min(fits).min(MAX_GROUPS);
    // SAFETY: `count` entries of the array lie within the buffer (checked above).
    let entries = unsafe {
        std::slice::from_raw_parts(
            (buf.as_ptr() as *const u8).add(head) as *const SID_AND_ATTRIBUTES,
            count,
        )
    };
    entries
        .iter()
        .filter(|g| {
            let a = g.Attributes;
            a & SE_GROUP_ENABLED as u32 != 0
                && a & SE_GROUP_LOGON_ID as u32 != SE_GROUP_LOGON_ID as u32
        })
        .filter_map(|g| sid_name(g.Sid))
        .collect()
}

static NAMES: Mutex<Option<HashMap<Vec<u8>, String>>> = Mutex::new(None);

/// `DOMAIN\name` of a SID (cached), its `S-1-...` text when it has no name, `None` for an
/// invalid SID.
fn sid_name(sid: PSID) -> Option<String> {
    // SAFETY: `sid` points into a token information buffer alive for this call.
    if sid.is_invalid() || !unsafe { IsValidSid(sid) }.as_bool() {
        return None;
    }
    // SAFETY: a valid SID (checked above).
    let len = unsafe { GetLengthSid(sid) } as usize;
    // SAFETY: a valid SID is `len` bytes long.
    let bytes = unsafe { std::slice::from_raw_parts(sid.0 as *const u8, len) }.to_vec();
    if let Some(n) = cached(&bytes) {
        return Some(n);
    }
    let name = lookup(sid).unwrap_or_else(|| sid_text(&bytes));
    let mut g = NAMES.lock().unwrap_or_else(|p| p.into_inner());
    let map = g.get_or_insert_with(HashMap::new);
    if map.len() >= MAX_CACHED_NAMES {
        map.clear();
    }
    map.insert(bytes, name.clone());
    Some(name)
}

fn cached(sid: &[u8]) -> Option<String> {
    let g = NAMES.lock().unwrap_or_else(|p| p.into_inner());
    g.as_ref()?.get(sid).cloned()
}

/// `LookupAccountSidW` on this machine: `DOMAIN\name`, or `name` without a domain.
fn lookup(sid: PSID) -> Option<String> {
    let (mut name_len, mut domain_len) = (256u32, 256u32);
    for _ in 0..2 {
        let mut name = vec![0u16; name_len as usize];
        let mut domain = vec![0u16; domain_len as usize];
        let mut kind = SID_NAME_USE::default();
        // SAFETY: the buffers hold `name_len` / `domain_len` UTF-16 units, the lengths are
        // live in/out parameters; `sid` is valid (checked by the caller).
        let r = unsafe {
            LookupAccountSidW(
                windows::core::PCWSTR::null(),
                sid,
                Some(PWSTR(name.as_mut_ptr())),
                &mut name_len,
                Some(PWSTR(domain.as_mut_ptr())),
                &mut domain_len,
                &mut kind,
            )
        };
        match r {
            Ok(()) => {
                let n = String::from_utf16_lossy(&name[..(name_len as usize).min(name.len())]);
                let d =
                    String::from_utf16_lossy(&domain[..(domain_len as usize).min(domain.len())]);
                return Some(if d.is_empty() { n } else { format!("{d}\\{n}") });
            }
            Err(e) if e.code() == ERROR_INSUFFICIENT_BUFFER.to_hresult() => {
                if name_len > 4096 || domain_len > 4096 {
                    return None;
                }
            }
            Err(_) => return None,
        }
    }
    None
}

/// The SID (binary) of the account this process runs as, from its token's user; `Err`
/// says which call failed.
pub fn process_user_sid() -> Result<Vec<u8>, String> {
    use windows::Win32::System::Threading::{GetCurrentProcess, OpenProcessToken};
    let mut token = HANDLE::default();
    // SAFETY: the pseudo handle of this process; `token` is a live out-parameter.
    unsafe { OpenProcessToken(GetCurrentProcess(), TOKEN_QUERY, &mut token) }
        .map_err(|e| format!("OpenProcessToken: {:#010x}", e.code().0 as u32))?;
    let token = Owned(token);
    let user = token_info(&token, TokenUser)?;
    if user.len() * 8 < std::mem::size_of::<TOKEN_USER>() {
        return Err("the process's token has no user".into());
    }
    // SAFETY: `user` holds what GetTokenInformation(TokenUser) wrote, at least one
    // TOKEN_USER, 8-byte aligned (a Vec<u64>); its SID points into the same buffer.
    let sid = unsafe { (*(user.as_ptr() as *const TOKEN_USER)).User.Sid };
    // SAFETY: `sid` points into `user`, alive for this call.
    if sid.is_invalid() || !unsafe { IsValidSid(sid) }.as_bool() {
        return Err("the process's token has an invalid user SID".into());
    }
    // SAFETY: a valid SID (checked above).
    let len = unsafe { GetLengthSid(sid) } as usize;
    // SAFETY: a valid SID is `len` bytes long.
    Ok(unsafe { std::slice::from_raw_parts(sid.0 as *const u8, len) }.to_vec())
}

/// The SID of the account or group `name` on this machine (`LookupAccountNameW`), `None`
/// when there is none; for registration's clients' group.
pub fn account_sid(name: &str) -> Option<Vec<u8>> {
    let wname = windows::core::HSTRING::from(name);
    let mut sid = vec![0u8; 68];
    let mut sid_len = sid.len() as u32;
    let mut domain = vec![0u16; 256];
    let mut domain_len = domain.len() as u32;
    let mut kind = SID_NAME_USE::default();
    // SAFETY: the buffers hold `sid_len` bytes and `domain_len` UTF-16 units (the largest
    // SID is 68 bytes), the lengths and kind are live out-parameters.
    unsafe {
        LookupAccountNameW(
            windows::core::PCWSTR::null(),
            &wname,
            Some(PSID(sid.as_mut_ptr().cast())),
            &mut sid_len,
            Some(PWSTR(domain.as_mut_ptr())),
            &mut domain_len,
            &mut kind,
        )
    }
    .ok()?;
    sid.truncate(sid_len as usize);
    Some(sid)
}

/// What [`create_local_group`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GroupAdded {
    /// The group is new.
    Created,
    /// It existed already (its members are kept).
    Existed,
}

/// Creates the local group `name` with `comment` (`NetLocalGroupAdd`, level 1, on this
/// machine); `Err` carries the `NET_API_STATUS` (5: access denied, run as administrator).
/// Whether it can then be found is [`account_sid`]'s answer: Wine's netapi32 answers
/// success and creates nothing (`platform::local_group_missing_reason`).
pub fn create_local_group(name: &str, comment: &str) -> Result<GroupAdded, u32> {
    use windows::Win32::NetworkManagement::NetManagement::{
        NERR_GroupExists, NetLocalGroupAdd, LOCALGROUP_INFO_1,
    };
    let mut wname: Vec<u16> = name.encode_utf16().chain([0]).collect();
    let mut wcomment: Vec<u16> = comment.encode_utf16().chain([0]).collect();
    let info = LOCALGROUP_INFO_1 {
        lgrpi1_name: PWSTR(wname.as_mut_ptr()),
        lgrpi1_comment: PWSTR(wcomment.as_mut_ptr()),
    };
    let mut parm_err = 0u32;
    // SAFETY: level 1 takes a LOCALGROUP_INFO_1, whose two strings are NUL-terminated
    // buffers alive for the call (only read); `parm_err` is a live out-parameter.
    let status = unsafe {
        NetLocalGroupAdd(
            windows::core::PCWSTR::null(),
            1,
            (&raw const info).cast(),
            Some(&raw mut parm_err),
        )
    };
    const ERROR_ALIAS_EXISTS: u32 = 1379;
    match status {
        0 => Ok(GroupAdded::Created),
        s if s == NERR_GroupExists || s == ERROR_ALIAS_EXISTS => Ok(GroupAdded::Existed),
        s => Err(s),
    }
}

/// The `S-1-<authority>-<sub>...` text of a SID's bytes (MS-DTYP 2.4.2.2).
pub fn sid_text(sid: &[u8]) -> String {
    if sid.len() < 8 {
        return "S-?".into();
    }
    let authority = sid[2..8].iter().fold(0u64, |a, b| (a << 8) | u64::from(*b));
    let mut out = format!("S-{}-{authority}", sid[0]);
    for sub in sid[8..].chunks_exact(4).take(usize::from(sid[1])) {
        out.push_str(&format!(
            "-{}",
            u32::from_le_bytes([sub[0], sub[1], sub[2], sub[3]])
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outside_a_call_the_caller_is_unknown_with_the_reason() {
        let _apt = crate::com::apartment::Apartment::mta_without_keepalive();
        let c = current();
        let text = c.to_string();
        assert!(c.is_unknown(), "{text}");
        assert!(
            text.starts_with("unknown (CoQueryClientBlanket: 0x"),
            "{text}"
        );
        // The next ask answers the same (no impersonation left behind).
        assert_eq!(current().to_string(), text);
    }

    #[test]
    fn sids_print_as_the_spec_writes_them() {
        // S-1-5-32-544 (BUILTIN\Administrators), MS-DTYP 2.4.2.4.
        let admins = [1, 2, 0, 0, 0, 0, 0, 5, 32, 0, 0, 0, 0x20, 2, 0, 0];
        assert_eq!(sid_text(&admins), "S-1-5-32-544");
        assert_eq!(sid_text(&[1, 1, 0, 0, 0, 0, 0, 5, 18, 0, 0, 0]), "S-1-5-18");
        assert_eq!(sid_text(&[1, 0]), "S-?");
    }
}
