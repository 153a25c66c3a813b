//! asix-gate.exe as an NT service: `/Service --config FILE` installs it (automatic start,
//! LocalService, started with `-ServiceRun --config FILE`), the service manager starts
//! it and it serves (its channel's `XConnect.ServerCT`, the test double, opened in the
//! service process; its TCP port accepts links), the service manager's stop ends it
//! cleanly, and `/UnregServer` removes it (quietly when there is none).
//!
//! Under Wine, services.exe (and every service) ends with the last ordinary Wine process,
//! so the service is controlled from inside this test process while it is alive (as
//! `service.rs` does for the server). asix-gate and the double are 32-bit, so this file
//! runs only as a 32-bit client (`cargo xtask e2e --x86 -p e2e-tests --test gate_service`).
#![cfg(all(windows, target_pointer_width = "32"))]

use e2e_tests::own_artifact;
use e2e_tests::server_config::read_log;
use e2e_tests::start::StartRetrying;
use std::path::{Path, PathBuf};
use std::time::Duration;
use test_support::wait::{wait_for, wait_until};
use windows::core::PCWSTR;
use windows::Win32::System::Registry::{
    RegGetValueW, HKEY_LOCAL_MACHINE, RRF_RT_REG_DWORD, RRF_RT_REG_SZ,
};
use windows::Win32::System::Services::{
    CloseServiceHandle, ControlService, OpenSCManagerW, OpenServiceW, QueryServiceStatus,
    StartServiceW, SC_HANDLE, SC_MANAGER_CONNECT, SERVICE_CONTROL_STOP, SERVICE_QUERY_STATUS,
    SERVICE_RUNNING, SERVICE_START, SERVICE_STATUS, SERVICE_STOP, SERVICE_STOPPED,
};

const SERVICE: PCWSTR = windows::core::w!("AsixGate");
const KEY: &str = r"System\CurrentControlSet\Services\AsixGate";
/// SERVICE_AUTO_START.
const AUTO_START: u32 = 2;

fn gate(args: &[&str]) -> std::process::ExitStatus {
    std::process::Command::new(own_artifact("asix-gate.exe"))
        .args(args)
        .status_retrying()
        .expect("run asix-gate.exe")
}

/// Removes the service whatever happens (the next run starts clean).
struct Remove;
impl Drop for Remove {
    fn drop(&mut self) {
        let _ = gate(&["/UnregServer"]);
    }
}

fn wide(s: &str) -> Vec<u16> {
    s.encode_utf16().chain([0]).collect()
}

fn reg_string(key: &str, value: &str) -> Option<String> {
    let (key, value) = (wide(key), wide(value));
    let mut buf = vec![0u16; 2048];
    let mut len = (buf.len() * 2) as u32;
    // SAFETY: valid NUL-terminated strings and a buffer of `len` bytes.
    let r = unsafe {
        RegGetValueW(
            HKEY_LOCAL_MACHINE,
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

fn reg_dword(key: &str, value: &str) -> Option<u32> {
    let (key, value) = (wide(key), wide(value));
    let mut v = 0u32;
    let mut len = 4u32;
    // SAFETY: valid NUL-terminated strings and a 4-byte out value.
    let r = unsafe {
        RegGetValueW(
            HKEY_LOCAL_MACHINE,
            PCWSTR(key.as_ptr()),
            PCWSTR(value.as_ptr()),
            RRF_RT_REG_DWORD,
            None,
            Some((&mut v as *mut u32).cast()),
            Some(&mut len),
        )
    };
    r.is_ok().then_some(v)
}

struct Scm(SC_HANDLE);
impl Drop for Scm {
    fn drop(&mut self) {
        // SAFETY: a handle opened below.
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
    // SAFETY: a valid handle and out struct.
    unsafe { QueryServiceStatus(s.0, &mut st).ok()? };
    Some(st.dwCurrentState.0)
}

/// A gate configuration in a folder of its own: a TLS identity, links and discovery on
/// loopback ports the system picks, one channel on the double, the log in `Log`.
fn gate_dir() -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("gate-service-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let id = asix_net::tls::generate("GATE-SVC", None).expect("a TLS identity");
    std::fs::write(dir.join("gate-cert.pem"), &id.cert_pem).unwrap();
    std::fs::write(dir.join("gate-key.pem"), &id.key_pem).unwrap();
    let ini = dir.join("asix-gate.ini");
    std::fs::write(
        &ini,
        "[ASIX-GATE]\r\nServerName = GATE-SVC\r\nListen = 127.0.0.1:0\r\n\
         Discovery = 127.0.0.1:0\r\nCertificate = gate-cert.pem\r\nPrivateKey = gate-key.pem\r\n\
         StatePollMs = 100\r\nTimeZone = UTC\r\nLanguage = EN\r\nLogDir = Log\r\n\r\n\
         [K1]\r\nInit = Vars=A;PeriodMs=1000\r\n",
    )
    .unwrap();
    (dir, ini)
}

/// The TCP address on the gate's "serving" log line (`tcp=127.0.0.1:PORT`).
fn serving_tcp(dir: &Path) -> Option<std::net::SocketAddr> {
    let log = read_log(dir);
    let line = log.lines().find(|l| l.contains("asix-gate serving"))?;
    line.split_whitespace()
        .find_map(|w| w.strip_prefix("tcp="))
        .and_then(|a| a.parse().ok())
}

#[test]
fn the_gate_is_installed_as_a_service_serves_stops_and_is_removed() {
    let _remove = Remove;
    let (dir, ini) = gate_dir();
    let ini_text = ini.to_str().unwrap();
    assert!(
        gate(&["/Service", "--config", ini_text]).success(),
        "/Service"
    );
    assert!(
        gate(&["/Service", "--config", ini_text]).success(),
        "/Service is idempotent"
    );
    let image = reg_string(KEY, "ImagePath").expect("the service's ImagePath");
    assert!(
        image.contains("asix-gate.exe") && image.contains("-ServiceRun --config "),
        "{image}"
    );
    assert!(
        image.contains(ini_text),
        "the configuration's path: {image}"
    );
    assert_eq!(
        reg_string(KEY, "ObjectName").as_deref(),
        Some(r"NT AUTHORITY\LocalService")
    );
    assert_eq!(reg_dword(KEY, "Start"), Some(AUTO_START), "automatic start");

    // The service manager starts it; it serves: the channel's object opened in the service
    // process, and its port accepts a link.
    {
        let (_m, s) = open_service(SERVICE_START).expect("open the service to start it");
        // SAFETY: a valid handle; no arguments.
        unsafe { StartServiceW(s.0, None) }.expect("StartService");
    }
    assert!(
        wait_until(Duration::from_secs(30), || service_state()
            == Some(SERVICE_RUNNING.0)),
        "the service runs"
    );
    let tcp = wait_for(Duration::from_secs(30), || serving_tcp(&dir))
        .unwrap_or_else(|| panic!("no serving line in the log: {}", read_log(&dir)));
    assert!(
        std::net::TcpStream::connect_timeout(&tcp, Duration::from_secs(10)).is_ok(),
        "the service's link port {tcp} accepts"
    );
    assert!(
        wait_until(Duration::from_secs(30), || read_log(&dir)
            .contains("channel open")),
        "the channel's XConnect.ServerCT opened in the service: {}",
        read_log(&dir)
    );

    // The service manager's stop ends it cleanly.
    {
        let (_m, s) = open_service(SERVICE_STOP).expect("open the service to stop it");
        let mut st = SERVICE_STATUS::default();
        // SAFETY: a valid handle and out struct.
        unsafe { ControlService(s.0, SERVICE_CONTROL_STOP, &mut st) }
            .expect("ControlService(STOP)");
    }
    assert!(
        wait_until(Duration::from_secs(30), || service_state()
            == Some(SERVICE_STOPPED.0)),
        "the service stops"
    );
    // (The log is written by a background thread: the lines may follow the state.)
    assert!(
        wait_until(Duration::from_secs(10), || {
            let log = read_log(&dir);
            log.contains("the asix-gate service is stopping") && log.contains("asix-gate stopping")
        }),
        "the stop logged: {}",
        read_log(&dir)
    );

    // /UnregServer removes it, quietly, twice.
    assert!(gate(&["/UnregServer"]).success());
    assert!(
        gate(&["/UnregServer"]).success(),
        "removing what is not there"
    );
    assert_eq!(service_state(), None, "the service is gone");
    assert_eq!(reg_string(KEY, "ImagePath"), None);
    let _ = std::fs::remove_dir_all(&dir);
}
