//! Registration of an out-of-process COM server: CLSID with LocalServer32, ProgID with
//! CurVer and the version-dependent ProgID, AppID, component categories (through the
//! component category manager) and the legacy `HKCR\<ProgID>\OPC` key.
//! Both directions are idempotent; unregistering what is not there succeeds.

use windows::core::{GUID, HSTRING, PCWSTR};
use windows::Win32::Foundation::{ERROR_FILE_NOT_FOUND, ERROR_SUCCESS, WIN32_ERROR};
use windows::Win32::System::Com::{
    CoCreateInstance, ICatRegister, CATEGORYINFO, CLSCTX_INPROC_SERVER,
};
use windows::Win32::System::Registry::{
    RegCloseKey, RegCreateKeyExW, RegDeleteTreeW, RegSetValueExW, HKEY, HKEY_CLASSES_ROOT,
    KEY_WRITE, REG_OPTION_NON_VOLATILE, REG_SZ,
};

/// `CLSID_StdComponentCategoriesMgr`.
const CLSID_STD_COMPONENT_CATEGORIES_MGR: GUID =
    GUID::from_u128(0x0002e005_0000_0000_c000_000000000046);

/// A component category to implement, with the description it is registered under.
pub struct Category {
    pub catid: GUID,
    pub description: &'static str,
}

/// What one out-of-process server writes into the registry.
pub struct ServerRegistration<'a> {
    pub clsid: GUID,
    pub appid: GUID,
    /// Version-independent ProgID, e.g. `ServerCTOPC.App`.
    pub progid: &'a str,
    /// Version-dependent ProgID, e.g. `ServerCTOPC.App.1`.
    pub progid_versioned: &'a str,
    pub description: &'a str,
    /// Full path of the server executable.
    pub exe_path: &'a str,
    /// The exe's file name, for `HKCR\AppID\<exe>`.
    pub exe_name: &'a str,
    /// `AppID\{..}\LocalService` when installed as an NT service.
    pub service_name: Option<&'a str>,
    pub categories: &'a [Category],
    /// Write `HKCR\<ProgID>\OPC` (with `Vendor`) for OPC 1.0-era clients.
    pub opc_key_vendor: Option<&'a str>,
}

pub fn guid_string(g: &GUID) -> String {
    format!("{{{g:?}}}")
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

/// Creates (or opens) `HKCR\<path>` and sets its default value (when given) and named values.
fn set_key(
    path: &str,
    default: Option<&str>,
    values: &[(&str, &str)],
) -> windows::core::Result<()> {
    let mut key = HKEY::default();
    let wpath = HSTRING::from(path);
    check(
        // SAFETY: all pointers are valid for the call; `key` receives an open handle on success.
        unsafe {
            RegCreateKeyExW(
                HKEY_CLASSES_ROOT,
                &wpath,
                None,
                PCWSTR::null(),
                REG_OPTION_NON_VOLATILE,
                KEY_WRITE,
                None,
                &mut key,
                None,
            )
        },
        path,
    )?;
    let mut result = Ok(());
    let all = default
        .map(|d| ("", d))
        .into_iter()
        .chain(values.iter().copied());
    for (name, value) in all {
        let wide: Vec<u16> = value.encode_utf16().chain(std::iter::once(0)).collect();
        // SAFETY: REG_SZ data is the UTF-16 string with its terminator, viewed as bytes.
        let bytes =
            unsafe { std::slice::from_raw_parts(wide.as_ptr().cast::<u8>(), wide.len() * 2) };
        let wname = HSTRING::from(name);
        let name_ptr = if name.is_empty() {
            PCWSTR::null()
        } else {
            PCWSTR(wname.as_ptr())
        };
        // SAFETY: `key` is open; `bytes` outlives the call.
        let r = check(
            unsafe { RegSetValueExW(key, name_ptr, None, REG_SZ, Some(bytes)) },
            path,
        );
        if r.is_err() {
            result = r;
            break;
        }
    }
    // SAFETY: `key` was opened above and is closed once.
    unsafe {
        let _ = RegCloseKey(key);
    }
    result
}

/// Deletes `HKCR\<path>` and everything below it; absent keys are fine.
fn delete_tree(path: &str) -> windows::core::Result<()> {
    let wpath = HSTRING::from(path);
    // SAFETY: valid root and string.
    let err = unsafe { RegDeleteTreeW(HKEY_CLASSES_ROOT, &wpath) };
    if err == ERROR_FILE_NOT_FOUND {
        return Ok(());
    }
    check(err, path)
}

fn category_manager() -> windows::core::Result<ICatRegister> {
    // SAFETY: COM is initialised by the caller; standard in-proc class.
    unsafe {
        CoCreateInstance(
            &CLSID_STD_COMPONENT_CATEGORIES_MGR,
            None,
            CLSCTX_INPROC_SERVER,
        )
    }
}

/// Writes every key of `r`. COM must be initialised on this thread.
pub fn register(r: &ServerRegistration) -> windows::core::Result<()> {
    let clsid = guid_string(&r.clsid);
    let appid = guid_string(&r.appid);
    let clsid_key = format!("CLSID\\{clsid}");
    set_key(&clsid_key, Some(r.description), &[("AppID", &appid)])?;
    set_key(
        &format!("{clsid_key}\\LocalServer32"),
        Some(&format!("\"{}\"", r.exe_path)),
        &[],
    )?;
    set_key(
        &format!("{clsid_key}\\ProgID"),
        Some(r.progid_versioned),
        &[],
    )?;
    set_key(
        &format!("{clsid_key}\\VersionIndependentProgID"),
        Some(r.progid),
        &[],
    )?;
    set_key(r.progid, Some(r.description), &[])?;
    set_key(&format!("{}\\CLSID", r.progid), Some(&clsid), &[])?;
    set_key(
        &format!("{}\\CurVer", r.progid),
        Some(r.progid_versioned),
        &[],
    )?;
    set_key(r.progid_versioned, Some(r.description), &[])?;
    set_key(&format!("{}\\CLSID", r.progid_versioned), Some(&clsid), &[])?;
    if let Some(vendor) = r.opc_key_vendor {
        for p in [r.progid, r.progid_versioned] {
            set_key(&format!("{p}\\OPC"), None, &[])?;
            set_key(&format!("{p}\\OPC\\Vendor"), Some(vendor), &[])?;
        }
    }
    let mut appid_values: Vec<(&str, &str)> = Vec::new();
    if let Some(svc) = r.service_name {
        appid_values.push(("LocalService", svc));
    }
    set_key(
        &format!("AppID\\{appid}"),
        Some(r.description),
        &appid_values,
    )?;
    set_key(
        &format!("AppID\\{}", r.exe_name),
        None,
        &[("AppID", &appid)],
    )?;

    if !r.categories.is_empty() {
        let mgr = category_manager()?;
        let infos: Vec<CATEGORYINFO> = r
            .categories
            .iter()
            .map(|c| {
                let mut info = CATEGORYINFO {
                    catid: c.catid,
                    lcid: 0x0409,
                    szDescription: [0; 128],
                };
                for (dst, src) in info
                    .szDescription
                    .iter_mut()
                    .zip(c.description.encode_utf16().take(127))
                {
                    *dst = src;
                }
                info
            })
            .collect();
        let cats = infos;
        let ids: Vec<GUID> = r.categories.iter().map(|c| c.catid).collect();
        // SAFETY: slices are valid for the calls.
        unsafe {
            mgr.RegisterCategories(&cats)?;
            mgr.RegisterClassImplCategories(&r.clsid, &ids)?;
        }
    }
    Ok(())
}

/// Removes every key `register` wrote (the category definitions themselves stay: other
/// servers implement them too). Succeeds quietly when nothing is registered.
pub fn unregister(r: &ServerRegistration) -> windows::core::Result<()> {
    if !r.categories.is_empty() {
        if let Ok(mgr) = category_manager() {
            let ids: Vec<GUID> = r.categories.iter().map(|c| c.catid).collect();
            // SAFETY: slice valid for the call; failure (not registered) is ignored.
            let _ = unsafe { mgr.UnRegisterClassImplCategories(&r.clsid, &ids) };
        }
    }
    delete_tree(&format!("CLSID\\{}", guid_string(&r.clsid)))?;
    delete_tree(r.progid)?;
    delete_tree(r.progid_versioned)?;
    delete_tree(&format!("AppID\\{}", guid_string(&r.appid)))?;
    delete_tree(&format!("AppID\\{}", r.exe_name))?;
    Ok(())
}
