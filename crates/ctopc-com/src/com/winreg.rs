//! The Windows registry, in both registry views. Writing: the registration of an
//! out-of-process COM server, applying the keys and tree deletions that
//! [`ctopc_registration`] computes (CLSID with LocalServer32, AppID, Implemented
//! Categories and the category definitions, ProgID with CurVer and the version-dependent
//! ProgID, the legacy `HKCR\<ProgID>\OPC` key); both directions are idempotent,
//! unregistering what is not there succeeds. Reading: keys and values of one view
//! ([`RegKey`], [`key_exists`], [`read_value`], [`read_default`], [`read_machine_value`]),
//! for the server browser and `opcdiag doctor`.

pub use ctopc_registration::security::{Data, DefaultValue};
pub use ctopc_registration::{Category, Key, ServerRegistration, View};
use windows::core::PWSTR;
use windows::core::{GUID, HSTRING, PCWSTR};
use windows::Win32::Foundation::{
    ERROR_FILE_NOT_FOUND, ERROR_MORE_DATA, ERROR_NO_MORE_ITEMS, ERROR_SUCCESS, WIN32_ERROR,
};
use windows::Win32::System::Registry::{
    RegCloseKey, RegCreateKeyExW, RegDeleteKeyExW, RegDeleteTreeW, RegEnumKeyExW, RegGetValueW,
    RegOpenKeyExW, RegSetValueExW, HKEY, HKEY_CLASSES_ROOT, HKEY_LOCAL_MACHINE, KEY_ALL_ACCESS,
    KEY_READ, KEY_WOW64_32KEY, KEY_WOW64_64KEY, KEY_WRITE, REG_BINARY, REG_DWORD,
    REG_OPTION_NON_VOLATILE, REG_SAM_FLAGS, REG_SZ, RRF_RT_ANY, RRF_RT_REG_BINARY,
    RRF_RT_REG_DWORD, RRF_RT_REG_SZ,
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
        Err(crate::com::error::error(
            err.to_hresult(),
            &format!("registry: {what}: error {}", err.0),
        ))
    }
}

/// Creates (or opens) `HKCR\<key.path>` in `key.view` and sets its values.
fn set_key(key: &Key) -> windows::core::Result<()> {
    let opened = create_key(key.view, &key.path, KEY_WRITE)?;
    let hkey = opened.0;
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
    result
}

/// Creates (or opens) `HKCR\<path>` in `view` with `access`; closed when the [`RegKey`]
/// drops.
fn create_key(view: View, path: &str, access: REG_SAM_FLAGS) -> windows::core::Result<RegKey> {
    let mut hkey = HKEY::default();
    let wpath = HSTRING::from(path);
    check(
        // SAFETY: all pointers are valid for the call; `hkey` receives an open handle on success.
        unsafe {
            RegCreateKeyExW(
                HKEY_CLASSES_ROOT,
                &wpath,
                None,
                PCWSTR::null(),
                REG_OPTION_NON_VOLATILE,
                access | view_flag(view),
                None,
                &mut hkey,
                None,
            )
        },
        path,
    )?;
    Ok(RegKey(hkey))
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

/// Writes each value of `values` (`REG_BINARY` / `REG_DWORD`) only where its key does not
/// have a value of that name yet, creating the key if needed: what an administrator set
/// stays. Returns how many were written.
pub fn write_absent(values: &[DefaultValue]) -> windows::core::Result<usize> {
    let mut written = 0;
    for v in values {
        let key = create_key(v.view, &v.path, KEY_READ | KEY_WRITE)?;
        let wname = HSTRING::from(v.name);
        // SAFETY: `key` is open; a size-only query of a value (no data buffer).
        let present =
            unsafe { RegGetValueW(key.0, PCWSTR::null(), &wname, RRF_RT_ANY, None, None, None) }
                == ERROR_SUCCESS;
        if present {
            continue;
        }
        let dword;
        let (kind, bytes): (_, &[u8]) = match &v.data {
            Data::Binary(b) => (REG_BINARY, b),
            Data::Dword(d) => {
                dword = d.to_le_bytes();
                (REG_DWORD, &dword)
            }
        };
        check(
            // SAFETY: `key` is open; `bytes` outlives the call.
            unsafe { RegSetValueExW(key.0, &wname, None, kind, Some(bytes)) },
            &v.path,
        )?;
        written += 1;
    }
    Ok(written)
}

/// Deletes each tree of `trees` in its view (absent ones are fine).
pub fn delete_trees(trees: &[(View, String)]) -> windows::core::Result<()> {
    trees
        .iter()
        .try_for_each(|(view, path)| delete_tree(*view, path))
}

// ---------------------------------------------------------------------------------------
// Reading, one view at a time

/// An open registry key, closed on drop.
pub struct RegKey(HKEY);

impl RegKey {
    /// `parent\path` of `view` for reading; `None` when absent (or not readable).
    pub fn open(parent: HKEY, path: &str, view: View) -> Option<RegKey> {
        let wpath = HSTRING::from(path);
        let mut hkey = HKEY::default();
        // SAFETY: valid parent handle, string and out handle for the call.
        let err =
            unsafe { RegOpenKeyExW(parent, &wpath, None, KEY_READ | view_flag(view), &mut hkey) };
        (err == ERROR_SUCCESS).then_some(RegKey(hkey))
    }

    /// `self\path` of `view` for reading; `None` when absent (or not readable).
    pub fn subkey(&self, path: &str, view: View) -> Option<RegKey> {
        RegKey::open(self.0, path, view)
    }

    /// The names of the subkeys.
    pub fn subkeys(&self) -> Vec<String> {
        let mut out = Vec::new();
        // Key names are at most 255 characters.
        let mut buf = [0u16; 256];
        for index in 0u32.. {
            let mut len = buf.len() as u32;
            // SAFETY: `buf` has room for `len` characters; the other out-parameters are
            // not asked for.
            let err = unsafe {
                RegEnumKeyExW(
                    self.0,
                    index,
                    Some(PWSTR(buf.as_mut_ptr())),
                    &mut len,
                    None,
                    None,
                    None,
                    None,
                )
            };
            if err == ERROR_NO_MORE_ITEMS {
                break;
            }
            if err == ERROR_SUCCESS {
                let n = (len as usize).min(buf.len());
                out.push(String::from_utf16_lossy(&buf[..n]));
            } else if err != ERROR_MORE_DATA {
                break;
            }
        }
        out
    }

    /// The default (`REG_SZ`) value of the subkey `sub` (`""`: of this key).
    pub fn default_value(&self, sub: &str) -> Option<String> {
        self.text_value(sub, "")
    }

    /// The `REG_SZ` value `name` (`""`: the default value) of the subkey `sub`.
    fn text_value(&self, sub: &str, name: &str) -> Option<String> {
        let wsub = HSTRING::from(sub);
        let wname = HSTRING::from(name);
        let name_ptr = if name.is_empty() {
            PCWSTR::null()
        } else {
            PCWSTR(wname.as_ptr())
        };
        let mut bytes = 0u32;
        // SAFETY: a size query: no data buffer, `bytes` receives the size.
        let err = unsafe {
            RegGetValueW(
                self.0,
                &wsub,
                name_ptr,
                RRF_RT_REG_SZ,
                None,
                None,
                Some(&mut bytes),
            )
        };
        if err != ERROR_SUCCESS || bytes == 0 {
            return None;
        }
        let mut buf = vec![0u16; (bytes as usize).div_ceil(2) + 1];
        let mut len = (buf.len() * 2) as u32;
        // SAFETY: `buf` has room for `len` bytes.
        let err = unsafe {
            RegGetValueW(
                self.0,
                &wsub,
                name_ptr,
                RRF_RT_REG_SZ,
                None,
                Some(buf.as_mut_ptr().cast()),
                Some(&mut len),
            )
        };
        if err != ERROR_SUCCESS {
            return None;
        }
        let units = (len as usize / 2).min(buf.len());
        let text = &buf[..units];
        let end = text.iter().position(|&c| c == 0).unwrap_or(text.len());
        Some(String::from_utf16_lossy(&text[..end]))
    }

    /// The `REG_DWORD` value `name` of this key.
    fn dword_value(&self, name: &str) -> Option<u32> {
        let wname = HSTRING::from(name);
        let mut data = 0u32;
        let mut len = std::mem::size_of::<u32>() as u32;
        // SAFETY: `data` has room for the `len` bytes of a DWORD.
        let err = unsafe {
            RegGetValueW(
                self.0,
                PCWSTR::null(),
                &wname,
                RRF_RT_REG_DWORD,
                None,
                Some((&raw mut data).cast()),
                Some(&mut len),
            )
        };
        (err == ERROR_SUCCESS).then_some(data)
    }
}

impl Drop for RegKey {
    fn drop(&mut self) {
        // SAFETY: the handle was opened by `open` and is closed once.
        unsafe {
            let _ = RegCloseKey(self.0);
        }
    }
}

/// Whether `HKCR\path` exists in `view` (and is readable).
pub fn key_exists(view: View, path: &str) -> bool {
    RegKey::open(HKEY_CLASSES_ROOT, path, view).is_some()
}

/// The `REG_SZ` value `name` (`""`: the default value) of `HKCR\path` in `view`.
pub fn read_value(view: View, path: &str, name: &str) -> Option<String> {
    RegKey::open(HKEY_CLASSES_ROOT, path, view)?.text_value("", name)
}

/// A value of `HKLM\path` in `view` as text: a `REG_SZ` as it is, a `REG_DWORD` in
/// decimal (machine-wide settings such as `Software\Microsoft\Ole`, for `opcdiag doctor`).
pub fn read_machine_value(view: View, path: &str, name: &str) -> Option<String> {
    let key = RegKey::open(HKEY_LOCAL_MACHINE, path, view)?;
    key.text_value("", name)
        .or_else(|| key.dword_value(name).map(|d| d.to_string()))
}

/// The `REG_BINARY` value `name` of `HKCR\path` in `view` (at most 64 KiB).
pub fn read_binary(view: View, path: &str, name: &str) -> Option<Vec<u8>> {
    let key = RegKey::open(HKEY_CLASSES_ROOT, path, view)?;
    let wname = HSTRING::from(name);
    let mut len = 0u32;
    // SAFETY: `key` is open; a size query.
    let err = unsafe {
        RegGetValueW(
            key.0,
            PCWSTR::null(),
            &wname,
            RRF_RT_REG_BINARY,
            None,
            None,
            Some(&mut len),
        )
    };
    if err != ERROR_SUCCESS || len > 65_536 {
        return None;
    }
    let mut buf = vec![0u8; len as usize];
    // SAFETY: `buf` has room for `len` bytes.
    let err = unsafe {
        RegGetValueW(
            key.0,
            PCWSTR::null(),
            &wname,
            RRF_RT_REG_BINARY,
            None,
            Some(buf.as_mut_ptr().cast()),
            Some(&mut len),
        )
    };
    if err != ERROR_SUCCESS {
        return None;
    }
    buf.truncate(len as usize);
    Some(buf)
}

/// The `REG_DWORD` value `name` of `HKCR\path` in `view`.
pub fn read_dword(view: View, path: &str, name: &str) -> Option<u32> {
    RegKey::open(HKEY_CLASSES_ROOT, path, view)?.dword_value(name)
}

/// The default value of `HKCR\path` in `view`.
pub fn read_default(view: View, path: &str) -> Option<String> {
    let (parent, leaf) = match path.rsplit_once('\\') {
        Some((p, l)) => (RegKey::open(HKEY_CLASSES_ROOT, p, view)?, l),
        None => (RegKey::open(HKEY_CLASSES_ROOT, path, view)?, ""),
    };
    parent.default_value(leaf)
}

#[cfg(test)]
mod tests {
    use crate::com::interfaces::{CATID_OPCDAServer20, CATID_OPCDAServer30};
    use ctopc_registration::{CATID_OPC_DA_SERVER_20, CATID_OPC_DA_SERVER_30};
    use windows::core::GUID;

    #[test]
    fn the_registrations_categories_are_the_interface_definitions() {
        assert_eq!(GUID::from_u128(CATID_OPC_DA_SERVER_20), CATID_OPCDAServer20);
        assert_eq!(GUID::from_u128(CATID_OPC_DA_SERVER_30), CATID_OPCDAServer30);
    }
}
