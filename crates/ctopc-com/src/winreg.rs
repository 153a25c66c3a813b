//! Registration of an out-of-process COM server: applies the keys and tree deletions that
//! [`ctopc_registration`] computes (CLSID with LocalServer32, AppID, Implemented
//! Categories and the category definitions, ProgID with CurVer and the version-dependent
//! ProgID, the legacy `HKCR\<ProgID>\OPC` key), in both registry views.
//! Both directions are idempotent; unregistering what is not there succeeds.

pub use ctopc_registration::{Category, Key, ServerRegistration, View};
use windows::core::{GUID, HSTRING, PCWSTR};
use windows::Win32::Foundation::{ERROR_FILE_NOT_FOUND, ERROR_SUCCESS, WIN32_ERROR};
use windows::Win32::System::Registry::{
    RegCloseKey, RegCreateKeyExW, RegDeleteKeyExW, RegDeleteTreeW, RegOpenKeyExW, RegSetValueExW,
    HKEY, HKEY_CLASSES_ROOT, KEY_ALL_ACCESS, KEY_WOW64_32KEY, KEY_WOW64_64KEY, KEY_WRITE,
    REG_OPTION_NON_VOLATILE, REG_SAM_FLAGS, REG_SZ,
};

pub fn guid_string(g: &GUID) -> String {
    ctopc_registration::guid_string(g.to_u128())
}

fn view_flag(view: View) -> REG_SAM_FLAGS {
    match view {
        View::Reg64 => KEY_WOW64_64KEY,
        View::Reg32 => KEY_WOW64_32KEY,
    }
}

fn check(err: WIN32_ERROR, what: &str) -> windows::core::Result<()> {
    if err == ERROR_SUCCESS {
        Ok(())
    } else {
        Err(crate::error::error(
            err.to_hresult(),
            &format!("registry: {what}: error {}", err.0),
        ))
    }
}

/// Creates (or opens) `HKCR\<key.path>` in `key.view` and sets its values.
fn set_key(key: &Key) -> windows::core::Result<()> {
    let mut hkey = HKEY::default();
    let wpath = HSTRING::from(key.path.as_str());
    check(
        // SAFETY: all pointers are valid for the call; `hkey` receives an open handle on success.
        unsafe {
            RegCreateKeyExW(
                HKEY_CLASSES_ROOT,
                &wpath,
                None,
                PCWSTR::null(),
                REG_OPTION_NON_VOLATILE,
                KEY_WRITE | view_flag(key.view),
                None,
                &mut hkey,
                None,
            )
        },
        &key.path,
    )?;
    let mut result = Ok(());
    for (name, value) in &key.values {
        let wide: Vec<u16> = value.encode_utf16().chain(std::iter::once(0)).collect();
        // SAFETY: REG_SZ data is the UTF-16 string with its terminator, viewed as bytes.
        let bytes =
            unsafe { std::slice::from_raw_parts(wide.as_ptr().cast::<u8>(), wide.len() * 2) };
        let wname = HSTRING::from(name.as_str());
        let name_ptr = if name.is_empty() {
            PCWSTR::null()
        } else {
            PCWSTR(wname.as_ptr())
        };
        // SAFETY: `hkey` is open; `bytes` outlives the call.
        let r = check(
            unsafe { RegSetValueExW(hkey, name_ptr, None, REG_SZ, Some(bytes)) },
            &key.path,
        );
        if r.is_err() {
            result = r;
            break;
        }
    }
    // SAFETY: `hkey` was opened above and is closed once.
    unsafe {
        let _ = RegCloseKey(hkey);
    }
    result
}

/// Deletes `HKCR\<path>` of `view` and everything below it; absent keys are fine.
/// (`RegDeleteTreeW` takes no view: the key is opened in its view first, emptied, then
/// deleted with `RegDeleteKeyExW`, which takes one.)
fn delete_tree(view: View, path: &str) -> windows::core::Result<()> {
    let wpath = HSTRING::from(path);
    let mut hkey = HKEY::default();
    // SAFETY: valid root, string and out handle.
    let err = unsafe {
        RegOpenKeyExW(
            HKEY_CLASSES_ROOT,
            &wpath,
            None,
            KEY_ALL_ACCESS | view_flag(view),
            &mut hkey,
        )
    };
    if err == ERROR_FILE_NOT_FOUND {
        return Ok(());
    }
    check(err, path)?;
    // SAFETY: `hkey` is open; a NULL subkey empties the key itself.
    let err = unsafe { RegDeleteTreeW(hkey, PCWSTR::null()) };
    // SAFETY: `hkey` was opened above and is closed once.
    unsafe {
        let _ = RegCloseKey(hkey);
    }
    check(err, path)?;
    // SAFETY: valid root and string.
    let err = unsafe { RegDeleteKeyExW(HKEY_CLASSES_ROOT, &wpath, view_flag(view).0, None) };
    if err == ERROR_FILE_NOT_FOUND {
        return Ok(());
    }
    check(err, path)
}

/// Writes every key of `r` ([`ServerRegistration::keys`]), both views.
pub fn register(r: &ServerRegistration) -> windows::core::Result<()> {
    r.keys().iter().try_for_each(set_key)
}

/// Removes every key `register` wrote ([`ServerRegistration::trees`], both views; the
/// category definitions stay: other servers implement them too). Succeeds quietly when
/// nothing is registered.
pub fn unregister(r: &ServerRegistration) -> windows::core::Result<()> {
    r.trees()
        .iter()
        .try_for_each(|(view, path)| delete_tree(*view, path))
}

/// Writes `keys` (parents before children), e.g. the server browser's filtered
/// `registration::server_list_keys`.
pub fn write_keys(keys: &[Key]) -> windows::core::Result<()> {
    keys.iter().try_for_each(set_key)
}

/// Deletes each tree of `trees` in its view (absent ones are fine).
pub fn delete_trees(trees: &[(View, String)]) -> windows::core::Result<()> {
    trees
        .iter()
        .try_for_each(|(view, path)| delete_tree(*view, path))
}

#[cfg(test)]
mod tests {
    use crate::interfaces::{CATID_OPCDAServer20, CATID_OPCDAServer30};
    use ctopc_registration::{CATID_OPC_DA_SERVER_20, CATID_OPC_DA_SERVER_30};
    use windows::core::GUID;

    #[test]
    fn the_registrations_categories_are_the_interface_definitions() {
        assert_eq!(GUID::from_u128(CATID_OPC_DA_SERVER_20), CATID_OPCDAServer20);
        assert_eq!(GUID::from_u128(CATID_OPC_DA_SERVER_30), CATID_OPCDAServer30);
    }
}
