//! The server browser as an NT service (for remote clients, as the OPC
//! Foundation's OpcEnum runs): `OpcServerList.exe /Service` installs the service
//! `OpcServerList` (on demand, as LocalService) with AppID LocalService, COM starts it when
//! a client creates `OPC.ServerList.1`, it serves until stopped, and `/UnregServer` removes
//! it. As tests/tests/service.rs does for the server: under Wine services.exe ends with the
//! last ordinary Wine process, so the service is controlled from this test process.
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_registration::{
    guid_string, APPID_SERVER_LIST, CATID_OPC_DA_SERVER_20, CLSID_SERVERCTOPC,
};
use e2e_tests::start::StartRetrying;
use e2e_tests::{artifact, processes_named, Apartment};
use opc_client::server_list::ServerBrowser;
use std::time::{Duration, Instant};
use windows::core::{GUID, PCWSTR};
use windows::Win32::System::Registry::{
    RegGetValueW, HKEY, HKEY_CLASSES_ROOT, HKEY_LOCAL_MACHINE, RRF_RT_REG_SZ,
};
use windows::Win32::System::Services::{
    CloseServiceHandle, ControlService, OpenSCManagerW, OpenServiceW, QueryServiceStatus,
    SC_HANDLE, SC_MANAGER_CONNECT, SERVICE_CONTROL_STOP, SERVICE_QUERY_STATUS, SERVICE_RUNNING,
    SERVICE_STATUS, SERVICE_STOP, SERVICE_STOPPED,
};

const SERVICE: PCWSTR = windows::core::w!("OpcServerList");
const EXE: &str = "OpcServerList.exe";

fn browser_exe(arg: &str) -> std::process::ExitStatus {
    std::process::Command::new(artifact(EXE))
        .arg(arg)
        .status_retrying()
        .expect("run OpcServerList.exe")
}

/// Restores the ordinary registration whatever happens (other test binaries need it).
struct Restore;
impl Drop for Restore {
    fn drop(&mut self) {
        let _ = browser_exe("/UnregServer");
        let _ = browser_exe("/RegServer");
    }
}

fn reg_string(root: HKEY, key: &str, value: &str) -> Option<String> {
    let key: Vec<u16> = key.encode_utf16().chain([0]).collect();
    let value: Vec<u16> = value.encode_utf16().chain([0]).collect();
    let mut buf = vec![0u16; 1024];
    let mut len = (buf.len() * 2) as u32;
    // SAFETY: valid strings and buffer.
    let r = unsafe {
        RegGetValueW(
            root,
            PCWSTR(key.as_ptr()),
            PCWSTR(value.as_ptr()),
            RRF_RT_REG_SZ,
            None,
            Some(buf.as_mut_ptr().cast()),
            Some(&mut len),
        )
    };
    if r.is_err() {
        return None;
    }
    Some(String::from_utf16_lossy(
        &buf[..(len as usize / 2).saturating_sub(1)],
    ))
}

struct Scm(SC_HANDLE);
impl Drop for Scm {
    fn drop(&mut self) {
        // SAFETY: handle opened below.
        let _ = unsafe { CloseServiceHandle(self.0) };
    }
}

fn open_service(access: u32) -> Option<(Scm, Scm)> {
    // SAFETY: plain Win32 calls with valid arguments.
    unsafe {
        let m = Scm(OpenSCManagerW(None, None, SC_MANAGER_CONNECT).ok()?);
        let s = Scm(OpenServiceW(m.0, SERVICE, access).ok()?);
        Some((m, s))
    }
}

fn service_state() -> Option<u32> {
    let (_m, s) = open_service(SERVICE_QUERY_STATUS)?;
    let mut st = SERVICE_STATUS::default();
    // SAFETY: valid handle and out struct.
    unsafe { QueryServiceStatus(s.0, &mut st).ok()? };
    Some(st.dwCurrentState.0)
}

/// Waits until no browser started by COM for an earlier test lingers (an activation would
/// reach it instead of the service).
fn wait_for_no_browser() {
    let deadline = Instant::now() + Duration::from_secs(60);
    while !processes_named(EXE).is_empty() {
        assert!(Instant::now() < deadline, "an OpcServerList.exe still runs");
        std::thread::sleep(Duration::from_millis(300));
    }
}

#[test]
fn the_browser_service_is_installed_started_by_com_stopped_and_removed() {
    let _restore = Restore;
    wait_for_no_browser();
    assert!(browser_exe("/Service").success(), "/Service");
    assert!(browser_exe("/Service").success(), "/Service is idempotent");
    let key = r"System\CurrentControlSet\Services\OpcServerList";
    let image = reg_string(HKEY_LOCAL_MACHINE, key, "ImagePath").expect("service ImagePath");
    assert!(
        image.contains(EXE) && image.ends_with("-ServiceRun"),
        "{image}"
    );
    assert_eq!(
        reg_string(HKEY_LOCAL_MACHINE, key, "ObjectName").as_deref(),
        Some(r"NT AUTHORITY\LocalService")
    );
    let appid = format!("AppID\\{}", guid_string(APPID_SERVER_LIST));
    assert_eq!(
        reg_string(HKEY_CLASSES_ROOT, &appid, "LocalService").as_deref(),
        Some("OpcServerList")
    );

    // COM activation starts the service, which lists the machine's servers.
    let com = Apartment::mta().expect("CoInitializeEx");
    let b = ServerBrowser::connect().expect("CoCreateInstance(OPC.ServerList.1)");
    assert_eq!(
        service_state(),
        Some(SERVICE_RUNNING.0),
        "the browser runs as the service"
    );
    let listed = b
        .classes(&[GUID::from_u128(CATID_OPC_DA_SERVER_20)], &[])
        .expect("EnumClassesOfCategories");
    assert!(listed.contains(&GUID::from_u128(CLSID_SERVERCTOPC)));

    // The service control manager's stop ends it.
    {
        let (_m, s) = open_service(SERVICE_STOP).expect("open the service to stop it");
        let mut st = SERVICE_STATUS::default();
        // SAFETY: valid handle and out struct.
        unsafe { ControlService(s.0, SERVICE_CONTROL_STOP, &mut st) }
            .expect("ControlService(STOP)");
    }
    let deadline = Instant::now() + Duration::from_secs(20);
    while service_state() != Some(SERVICE_STOPPED.0) {
        assert!(Instant::now() < deadline, "the service did not stop");
        std::thread::sleep(Duration::from_millis(200));
    }
    drop(b);
    drop(com);

    // /UnregServer removes the service and the AppID's LocalService, quietly, twice.
    assert!(browser_exe("/UnregServer").success());
    assert!(
        browser_exe("/UnregServer").success(),
        "unregistering what is not registered succeeds"
    );
    assert_eq!(service_state(), None, "the service is gone");
    assert_eq!(reg_string(HKEY_LOCAL_MACHINE, key, "ImagePath"), None);
    assert_eq!(reg_string(HKEY_CLASSES_ROOT, &appid, "LocalService"), None);
}
