//! The NT service: `/Service` installs it (on demand, as LocalService) with AppID
//! LocalService, COM starts it when a client activates the server, stopping it sends
//! IOPCShutdown::ShutdownRequest to connected clients, and `/UnregServer` removes it.
//!
//! Under Wine, services.exe (and every service) ends with the last ordinary Wine process,
//! so the service is controlled from inside this test process while it is alive.
//!
//! Spec: OPC Common 1.10 IOPCShutdown::ShutdownRequest (OPC DA 2.05a §4.6.2) when the
//! service stops; OPC DA 2.05a §5.2 Registry Entries for Custom Interface, with the AppID's
//! LocalService.
#![cfg(windows)]

use e2e_tests::start::StartRetrying;
use e2e_tests::{artifact, assert_alive, connect, interfaces::*, wait_for_no_other_server};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use test_support::wait::wait_until;
use windows::core::{implement, Interface, PCWSTR};
use windows::Win32::System::Com::IConnectionPointContainer;
use windows::Win32::System::Registry::{
    RegGetValueW, HKEY_CLASSES_ROOT, HKEY_LOCAL_MACHINE, RRF_RT_REG_SZ,
};
use windows::Win32::System::Services::{
    CloseServiceHandle, ControlService, OpenSCManagerW, OpenServiceW, QueryServiceStatus,
    SC_HANDLE, SC_MANAGER_CONNECT, SERVICE_CONTROL_STOP, SERVICE_QUERY_STATUS, SERVICE_RUNNING,
    SERVICE_STATUS, SERVICE_STOP, SERVICE_STOPPED,
};

const SERVICE: windows::core::PCWSTR = windows::core::w!("ServerCTOPC");

fn server_exe(arg: &str) -> std::process::ExitStatus {
    std::process::Command::new(artifact("ServerCTOPC.exe"))
        .arg(arg)
        .status_retrying()
        .expect("run ServerCTOPC.exe")
}

/// Restores the ordinary COM registration whatever happens (other test binaries need it).
struct Restore;
impl Drop for Restore {
    fn drop(&mut self) {
        let _ = server_exe("/UnregServer");
        let _ = server_exe("/RegServer");
    }
}

fn reg_string(
    root: windows::Win32::System::Registry::HKEY,
    key: &str,
    value: &str,
) -> Option<String> {
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

#[implement(IOPCShutdown)]
struct ShutdownSink(Arc<Mutex<Vec<String>>>);

impl IOPCShutdown_Impl for ShutdownSink_Impl {
    unsafe fn ShutdownRequest(&self, reason: PCWSTR) -> windows::core::Result<()> {
        // SAFETY: the server passes a NUL-terminated string.
        let text = unsafe { reason.to_string() }.unwrap_or_default();
        self.0.lock().unwrap().push(text);
        Ok(())
    }
}

#[test]
fn the_service_is_installed_started_by_com_stopped_with_shutdown_requests_and_removed() {
    let _restore = Restore;
    assert!(server_exe("/Service").success(), "/Service");
    assert!(server_exe("/Service").success(), "/Service is idempotent");
    let key = r"System\CurrentControlSet\Services\ServerCTOPC";
    let image = reg_string(HKEY_LOCAL_MACHINE, key, "ImagePath").expect("service ImagePath");
    assert!(
        image.contains("ServerCTOPC.exe") && image.ends_with("-ServiceRun"),
        "{image}"
    );
    assert_eq!(
        reg_string(HKEY_LOCAL_MACHINE, key, "ObjectName").as_deref(),
        Some(r"NT AUTHORITY\LocalService")
    );
    assert_eq!(
        reg_string(
            HKEY_CLASSES_ROOT,
            r"AppID\{3277B556-BA68-4BDE-8687-8EE4E4B46336}",
            "LocalService"
        )
        .as_deref(),
        Some("ServerCTOPC")
    );

    // COM activation starts the service (once no earlier test's server lingers: Wine hands
    // activations to the first server that registered the class).
    wait_for_no_other_server();
    let (_com, server) = connect();
    assert_alive(&server);
    assert_eq!(
        service_state(),
        Some(SERVICE_RUNNING.0),
        "the server runs as the service"
    );

    // A client connected to IOPCShutdown hears about the service stop.
    let got = Arc::new(Mutex::new(Vec::new()));
    let sink: IOPCShutdown = ShutdownSink(Arc::clone(&got)).into();
    let cpc: IConnectionPointContainer = server.unknown.cast().expect("IConnectionPointContainer");
    // SAFETY: valid IID pointer.
    let cp = unsafe { cpc.FindConnectionPoint(&IOPCShutdown::IID) }
        .expect("IOPCShutdown connection point");
    let sink_unknown: windows::core::IUnknown = sink.cast().unwrap();
    // SAFETY: valid sink.
    let cookie = unsafe { cp.Advise(&sink_unknown) }.expect("Advise");
    assert_ne!(cookie, 0);
    {
        let (_m, s) = open_service(SERVICE_STOP).expect("open the service to stop it");
        let mut st = SERVICE_STATUS::default();
        // SAFETY: valid handle and out struct.
        unsafe { ControlService(s.0, SERVICE_CONTROL_STOP, &mut st) }
            .expect("ControlService(STOP)");
    }
    assert!(
        wait_until(Duration::from_secs(20), || !got.lock().unwrap().is_empty()),
        "no ShutdownRequest within 20 s of the service stop"
    );
    let reasons = got.lock().unwrap().clone();
    assert!(reasons[0].contains("service"), "{reasons:?}");
    assert!(
        wait_until(Duration::from_secs(20), || service_state()
            == Some(SERVICE_STOPPED.0)),
        "the service did not stop"
    );
    drop(server);

    // /UnregServer removes the service and the registration, quietly, twice.
    assert!(server_exe("/UnregServer").success());
    assert!(
        server_exe("/UnregServer").success(),
        "unregistering what is not registered succeeds"
    );
    assert_eq!(service_state(), None, "the service is gone");
    assert_eq!(reg_string(HKEY_LOCAL_MACHINE, key, "ImagePath"), None);
}
