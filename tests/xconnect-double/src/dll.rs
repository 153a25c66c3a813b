//! The DLL's exports: the class object, registration of the class, the ProgID
//! `XConnect.ServerCT` and the type library (`xconnect_double.tlb` beside the DLL, made by
//! widl from `xconnect.idl`), and unregistration.

use crate::server::{ServerCT, CLSID, LIBID};
use ctopc_com::factory::ClassFactory;
use ctopc_com::lifetime::Lifetime;
use std::ffi::c_void;
use std::path::PathBuf;
use windows::core::{Interface, GUID, HRESULT, HSTRING, PCWSTR};
use windows::Win32::Foundation::{
    CLASS_E_CLASSNOTAVAILABLE, ERROR_FILE_NOT_FOUND, ERROR_SUCCESS, E_POINTER, HMODULE, S_FALSE,
    S_OK, WIN32_ERROR,
};
use windows::Win32::System::Com::{ITypeLib, SYS_WIN32};
use windows::Win32::System::LibraryLoader::{
    GetModuleFileNameW, GetModuleHandleExW, GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS,
    GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
};
use windows::Win32::System::Ole::{
    LoadTypeLibEx, UnRegisterTypeLib, REGKIND_NONE, REGKIND_REGISTER, SELFREG_E_CLASS,
    SELFREG_E_TYPELIB,
};
use windows::Win32::System::Registry::{
    RegDeleteTreeW, RegSetKeyValueW, HKEY_CLASSES_ROOT, REG_SZ,
};

const PROGID: &str = "XConnect.ServerCT";
const DESCRIPTION: &str = "XConnect.ServerCT (test double)";

/// This DLL's full path.
fn module_path() -> Option<PathBuf> {
    let mut module = HMODULE::default();
    // SAFETY: the address of a function of this DLL names it; the reference count is not
    // changed; `module` is our local.
    unsafe {
        GetModuleHandleExW(
            GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS | GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
            PCWSTR(module_path as *const () as *const u16),
            &mut module,
        )
        .ok()?;
    }
    let mut buf = vec![0u16; 1024];
    // SAFETY: `buf` is writable for its length.
    let n = unsafe { GetModuleFileNameW(Some(module), &mut buf) } as usize;
    (n > 0 && n < buf.len()).then(|| PathBuf::from(String::from_utf16_lossy(&buf[..n])))
}

/// The type library beside the DLL.
fn typelib_path() -> Option<PathBuf> {
    Some(module_path()?.with_file_name("xconnect_double.tlb"))
}

fn load_typelib(kind: windows::Win32::System::Ole::REGKIND) -> windows::core::Result<ITypeLib> {
    let path = typelib_path().ok_or_else(|| windows::core::Error::from(SELFREG_E_TYPELIB))?;
    let wide = HSTRING::from(path.as_os_str());
    // SAFETY: a NUL-terminated path that lives for the call.
    unsafe { LoadTypeLibEx(PCWSTR(wide.as_ptr()), kind) }
}

fn guid(g: &GUID) -> String {
    format!("{{{g:?}}}")
}

fn set(path: &str, name: Option<&str>, value: &str) -> windows::core::Result<()> {
    let wpath = HSTRING::from(path);
    let wname = name.map(HSTRING::from);
    let data: Vec<u16> = value.encode_utf16().chain(Some(0)).collect();
    // SAFETY: NUL-terminated strings and a data buffer of the given size, all live for
    // the call; the key is created if absent.
    let err = unsafe {
        RegSetKeyValueW(
            HKEY_CLASSES_ROOT,
            PCWSTR(wpath.as_ptr()),
            wname
                .as_ref()
                .map_or(PCWSTR::null(), |n| PCWSTR(n.as_ptr())),
            REG_SZ.0,
            Some(data.as_ptr().cast()),
            (data.len() * 2) as u32,
        )
    };
    if err == ERROR_SUCCESS {
        Ok(())
    } else {
        Err(windows::core::Error::from(err.to_hresult()))
    }
}

fn delete_tree(path: &str) -> WIN32_ERROR {
    let wpath = HSTRING::from(path);
    // SAFETY: a NUL-terminated key path under HKCR.
    unsafe { RegDeleteTreeW(HKEY_CLASSES_ROOT, PCWSTR(wpath.as_ptr())) }
}

fn register() -> windows::core::Result<()> {
    let dll = module_path().ok_or_else(|| windows::core::Error::from(SELFREG_E_CLASS))?;
    let clsid = format!("CLSID\\{}", guid(&CLSID));
    set(&clsid, None, DESCRIPTION)?;
    set(
        &format!("{clsid}\\InprocServer32"),
        None,
        &dll.to_string_lossy(),
    )?;
    set(
        &format!("{clsid}\\InprocServer32"),
        Some("ThreadingModel"),
        "Apartment",
    )?;
    set(&format!("{clsid}\\ProgID"), None, PROGID)?;
    set(&format!("{clsid}\\TypeLib"), None, &guid(&LIBID))?;
    set(PROGID, None, DESCRIPTION)?;
    set(&format!("{PROGID}\\CLSID"), None, &guid(&CLSID))?;
    load_typelib(REGKIND_REGISTER).map_err(|_| windows::core::Error::from(SELFREG_E_TYPELIB))?;
    Ok(())
}

#[no_mangle]
pub extern "system" fn DllRegisterServer() -> HRESULT {
    match register() {
        Ok(()) => S_OK,
        Err(e) => e.code(),
    }
}

#[no_mangle]
pub extern "system" fn DllUnregisterServer() -> HRESULT {
    for path in [format!("CLSID\\{}", guid(&CLSID)), PROGID.to_owned()] {
        let err = delete_tree(&path);
        if err != ERROR_SUCCESS && err != ERROR_FILE_NOT_FOUND {
            return err.to_hresult();
        }
        let _ = delete_tree(&path);
    }
    // SAFETY: our library's identity; absent registrations are fine.
    let _ = unsafe { UnRegisterTypeLib(&LIBID, 1, 0, 0, SYS_WIN32) };
    S_OK
}

#[no_mangle]
pub extern "system" fn DllCanUnloadNow() -> HRESULT {
    // Stays loaded: a test double, loaded once per test process.
    S_FALSE
}

/// # Safety
/// COM's contract: `rclsid` and `riid` point to GUIDs, `ppv` to writable storage.
#[no_mangle]
pub unsafe extern "system" fn DllGetClassObject(
    rclsid: *const GUID,
    riid: *const GUID,
    ppv: *mut *mut c_void,
) -> HRESULT {
    if ppv.is_null() {
        return E_POINTER;
    }
    // SAFETY: checked non-null; cleared before anything can fail.
    unsafe { *ppv = std::ptr::null_mut() };
    if rclsid.is_null() || riid.is_null() {
        return E_POINTER;
    }
    // SAFETY: checked non-null.
    if unsafe { *rclsid } != CLSID {
        return CLASS_E_CLASSNOTAVAILABLE;
    }
    let factory = ClassFactory::new(Lifetime::new(), || {
        ServerCT::create(load_typelib(REGKIND_NONE)?)
    });
    // SAFETY: `riid` and `ppv` checked non-null; on failure QueryInterface leaves *ppv null.
    unsafe { factory.query(riid, ppv) }
}
