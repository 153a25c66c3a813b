//! Foundation: activation through COM, GetStatus and IOPCCommon end to end.
#![cfg(windows)]

use ctopc_com::apartment::Apartment;
use ctopc_com::clock;
use e2e_tests::{assert_alive, code, connect, interfaces::*, PROGID};
use opc_client::Server;
use std::time::Duration;
use windows::core::{IUnknown, Interface, GUID, HRESULT};
use windows::Win32::Foundation::{E_INVALIDARG, E_NOINTERFACE};
use windows::Win32::System::Com::{
    CLSIDFromProgID, CoCreateInstance, CoGetClassObject, IClassFactory, CLSCTX_LOCAL_SERVER,
};

const LCID_POLISH: u32 = 0x0415;
const LCID_ENGLISH_US: u32 = 0x0409;

#[test]
fn get_status_reports_vendor_times_version_and_state() {
    let (_com, server) = connect();
    let before = clock::now();
    let s = server.status().expect("GetStatus");
    let after = clock::now();
    assert_eq!(
        s.vendor_info.as_deref(),
        Some(ctopc_com::server::VENDOR_INFO)
    );
    assert!(s.start_time <= s.current_time, "{s:?}");
    // UTC: the server's current time lies within the client's call window (same machine).
    assert!(
        s.current_time.add_millis(2000) >= before && s.current_time <= after.add_millis(2000),
        "{s:?}"
    );
    assert!(
        s.start_time.add_millis(120_000) >= before,
        "started long ago? {s:?}"
    );
    let v: Vec<u16> = env!("CARGO_PKG_VERSION")
        .split('.')
        .map(|x| x.parse().unwrap())
        .collect();
    assert_eq!(s.version, (v[0], v[1], v[2]));
    assert_eq!(s.group_count, 0);
    // No ASIXConnect.ini next to the test build: the embedded demo plant, simulated.
    assert_eq!(s.state, OPC_STATUS_TEST.0 as u32);
}

#[test]
fn locales_polish_and_english_are_available_and_settable() {
    let (_com, server) = connect();
    let ids = server.available_locales().expect("QueryAvailableLocaleIDs");
    assert!(
        ids.contains(&LCID_POLISH) && ids.contains(&LCID_ENGLISH_US),
        "{ids:x?}"
    );
    server.set_locale(LCID_POLISH).expect("SetLocaleID(pl)");
    assert_eq!(server.locale().unwrap(), LCID_POLISH);
    server
        .set_locale(LCID_ENGLISH_US)
        .expect("SetLocaleID(en-US)");
    assert_eq!(server.locale().unwrap(), LCID_ENGLISH_US);
    // Other English variants are accepted as English.
    server.set_locale(0x0809).expect("SetLocaleID(en-GB)");
    assert_eq!(server.locale().unwrap(), 0x0809);
}

#[test]
fn unavailable_locale_is_e_invalidarg_and_keeps_the_old_one() {
    let (_com, server) = connect();
    server.set_locale(LCID_POLISH).unwrap();
    assert_eq!(
        code(&server.set_locale(0x0407)),
        E_INVALIDARG,
        "German is not available"
    );
    assert_eq!(server.locale().unwrap(), LCID_POLISH);
    assert_alive(&server);
}

#[test]
fn set_client_name_accepts_non_ascii_names() {
    let (_com, server) = connect();
    server
        .set_client_name("Stanowisko operatora – Wytwórnia Kwasu żółć")
        .expect("SetClientName");
    assert_alive(&server);
}

#[test]
fn error_strings_come_in_polish_and_english() {
    let (_com, server) = connect();
    let invalid_handle = HRESULT(OPC_E_INVALIDHANDLE.0);
    let en = server
        .error_string_in(invalid_handle, LCID_ENGLISH_US)
        .unwrap()
        .expect("non-NULL string");
    let pl = server
        .error_string_in(invalid_handle, LCID_POLISH)
        .unwrap()
        .expect("non-NULL string");
    assert!(en.to_lowercase().contains("handle"), "{en}");
    assert_ne!(en, pl);
    assert!(
        pl.chars().any(|c| "ąćęłńóśźżĄĆĘŁŃÓŚŹŻ".contains(c)) || pl.contains("uchwyt"),
        "{pl}"
    );
    server.set_locale(LCID_POLISH).unwrap();
    assert_eq!(
        server.error_string(invalid_handle).unwrap().as_deref(),
        Some(pl.as_str())
    );
    // A locale the server does not offer is E_INVALIDARG.
    assert_eq!(
        code(&server.error_string_in(invalid_handle, 0x0407)),
        E_INVALIDARG
    );
    assert_alive(&server);
}

#[test]
fn each_client_gets_its_own_server_object() {
    let (_com, a) = connect();
    let b = Server::connect(PROGID).unwrap();
    a.set_locale(LCID_POLISH).unwrap();
    b.set_locale(LCID_ENGLISH_US).unwrap();
    assert_eq!(a.locale().unwrap(), LCID_POLISH);
    assert_eq!(b.locale().unwrap(), LCID_ENGLISH_US);
    // ...in one process: the same start time.
    assert_eq!(
        a.status().unwrap().start_time,
        b.status().unwrap().start_time
    );
}

#[test]
fn create_instance_for_an_interface_the_server_lacks_is_e_nointerface() {
    let _com = Apartment::mta().unwrap();
    // SAFETY: valid ProgID string.
    let clsid = unsafe { CLSIDFromProgID(windows::core::w!("ServerCTOPC.App")) }.unwrap();
    // IOPCServerList is OPCEnum's interface, never the server's.
    let r: windows::core::Result<IOPCServerList> =
        // SAFETY: a CLSID on a thread in the MTA (`_com`); no outer object.
        unsafe { CoCreateInstance(&clsid, None, CLSCTX_LOCAL_SERVER) };
    assert_eq!(code(&r), E_NOINTERFACE);
    // A GUID nobody defines.
    let unknown = GUID::from_u128(0x0badc0de_0000_4000_8000_000000000001);
    let server = Server::connect(PROGID).unwrap();
    let mut out: *mut std::ffi::c_void = std::ptr::null_mut();
    // SAFETY: valid IID and out-pointer.
    let hr = unsafe { server.unknown.query(&unknown, &mut out) };
    assert_eq!(hr, E_NOINTERFACE);
    assert!(out.is_null());
    assert_alive(&server);
}

#[test]
fn server_exits_when_the_last_client_is_gone_and_restarts_on_demand() {
    let _com = Apartment::mta().unwrap();
    let first = Server::connect(PROGID)
        .unwrap()
        .status()
        .unwrap()
        .start_time;
    // Every server object of this test binary is released by now (other tests ran
    // sequentially and dropped theirs), so the process exits; a new one starts later.
    // Each new client restarts the server's exit linger, so wait longer than it between tries.
    let pause = ctopc_com::host::EXIT_LINGER + Duration::from_secs(2);
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    loop {
        std::thread::sleep(pause);
        let s = Server::connect(PROGID).unwrap().status().unwrap();
        if s.start_time > first {
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the server process did not exit after its last client left"
        );
    }
}

/// A client that got the class object just before the server decided to exit (linger
/// over, class object revoked) and calls CreateInstance after the revoke is served: the
/// server registers its class object again and serves on (`host::serve_class`), instead
/// of exiting under the new object.
#[test]
fn a_client_that_creates_an_instance_right_after_the_revoke_is_served_on() {
    let _com = Apartment::mta().unwrap();
    // SAFETY: a valid ProgID string; COM is initialised above.
    let clsid = unsafe { CLSIDFromProgID(&windows::core::HSTRING::from(PROGID)) }.unwrap();
    let server = Server::connect(PROGID).unwrap();
    let first = server.status().unwrap().start_time;
    // SAFETY: a valid CLSID; COM is initialised above.
    let factory: IClassFactory =
        unsafe { CoGetClassObject(&clsid, CLSCTX_LOCAL_SERVER, None) }.expect("the class object");
    let (y, m, d) = ctopc_com::clock::local_date();
    let log = e2e_tests::artifact(&format!("Log/ServerCTOPC.{y:04}{m:02}{d:02}.log"));
    let count = |what: &str| {
        std::fs::read_to_string(&log)
            .unwrap_or_default()
            .matches(what)
            .count()
    };
    let (revoked, served_on) = (ctopc_com::host::REVOKED_LOG, "serving on");
    let (revoked_before, served_on_before) = (count(revoked), count(served_on));
    // The last object of this binary goes: the server lingers, then revokes its class
    // object (the class factory proxy held here does not count as a client).
    drop(server);
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    while count(revoked) == revoked_before {
        assert!(
            std::time::Instant::now() < deadline,
            "the server did not revoke its class object after its last client left"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // SAFETY: no aggregation; the factory is a live proxy.
    let unknown: IUnknown = unsafe { factory.CreateInstance(None) }
        .expect("CreateInstance on the class object got just before the revoke");
    let again = Server::from_unknown(unknown).unwrap();
    // Well past the settle time: the same process still serves this client.
    std::thread::sleep(ctopc_com::host::REVOKE_SETTLE + Duration::from_secs(1));
    let s = again.status().expect("GetStatus after the settle time");
    assert_eq!(s.start_time, first, "the same server process serves on");
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while count(served_on) == served_on_before {
        assert!(
            std::time::Instant::now() < deadline,
            "the server did not log that it serves on"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_alive(&again);
}

#[test]
fn the_server_object_answers_queryinterface_for_its_interfaces() {
    let (_com, server) = connect();
    let unk: &IUnknown = &server.unknown;
    assert!(unk.cast::<IOPCServer>().is_ok());
    assert!(unk.cast::<IOPCCommon>().is_ok());
}

#[test]
fn the_server_logs_its_start_to_the_days_log_file_in_the_install_folder() {
    let (_com, server) = connect();
    assert_alive(&server);
    let (y, m, d) = ctopc_com::clock::local_date();
    let log = e2e_tests::artifact(&format!("Log/ServerCTOPC.{y:04}{m:02}{d:02}.log"));
    // The writer thread flushes asynchronously: give it a moment.
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    loop {
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        if text.contains("ServerCTOPC starting") && text.contains("configuration") {
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "no start lines in {}: {text}",
            log.display()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}
