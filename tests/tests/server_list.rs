//! OPC.ServerList.1, our server browser (OpcServerList.exe, registered by xtask), out of
//! process through the proxy/stub: listing by category (DA 1.0, 2.0, 3.0) through
//! IOPCServerList (IEnumGUID) and IOPCServerList2 (IOPCEnumGUID), GetClassDetails,
//! CLSIDFromProgID (also through a version-independent ProgID's `CurVer`), a client
//! matching the original's ProgID by name, the errors for an unknown CLSID / ProgID, a server registered only in
//! the 32-bit registry view, and /RegServer leaving another browser alone. Runs as a
//! 64-bit and as a 32-bit client (`E2E_32`).
//!
//! Spec: OPC Common 1.10 IOPCServerList (EnumClassesOfCategories, GetClassDetails,
//! CLSIDFromProgID), IOPCServerList2 and IOPCEnumGUID, as the OPC Foundation's OpcEnum
//! serves them; OPC DA 2.05a §5.1 Component Categories (the categories listed).
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_com::interfaces::{IOPCEnumGUID, IOPCServerList2};
use ctopc_com::winreg;
use ctopc_registration::{
    self as registration, guid_string, Key, View, CATID_OPC_DA_SERVER_10, CATID_OPC_DA_SERVER_20,
    CATID_OPC_DA_SERVER_30, CLSID_SERVERCTOPC,
};
use e2e_tests::start::StartRetrying;
use e2e_tests::{artifact, Apartment};
use opc_client::server_list::{opc_enum_guids, ServerBrowser};
use windows::core::GUID;
use windows::Win32::Foundation::{CO_E_CLASSSTRING, REGDB_E_CLASSNOTREG, S_FALSE, S_OK};

const DA10: GUID = GUID::from_u128(CATID_OPC_DA_SERVER_10);
const DA20: GUID = GUID::from_u128(CATID_OPC_DA_SERVER_20);
const DA30: GUID = GUID::from_u128(CATID_OPC_DA_SERVER_30);
const OURS: GUID = GUID::from_u128(CLSID_SERVERCTOPC);

fn browser() -> (Apartment, ServerBrowser) {
    let com = Apartment::mta().expect("CoInitializeEx");
    let b = ServerBrowser::connect().expect("CoCreateInstance(OPC.ServerList.1)");
    (com, b)
}

/// Both interfaces' answer, checked equal.
fn list(b: &ServerBrowser, implemented: &[GUID]) -> Vec<GUID> {
    let one = b.classes(implemented, &[]).expect("IOPCServerList");
    let two = b
        .classes2(implemented, &[])
        .expect("IOPCServerList2")
        .expect("IOPCServerList2::EnumClassesOfCategories");
    assert_eq!(one, two, "IEnumGUID and IOPCEnumGUID list the same");
    one
}

/// A fake OPC server registered in one view only (removed on drop).
struct FakeServer {
    view: View,
    clsid: u128,
    progid: &'static str,
}

impl FakeServer {
    fn register(view: View, clsid: u128, progid: &'static str, cats: &[u128]) -> FakeServer {
        let c = format!("CLSID\\{}", guid_string(clsid));
        let key = |path: String, values: &[(&str, &str)]| Key {
            view,
            path,
            values: values
                .iter()
                .map(|(n, d)| (n.to_string(), d.to_string()))
                .collect(),
        };
        let mut keys = vec![
            key(c.clone(), &[("", "Fake OPC server")]),
            key(format!("{c}\\ProgID"), &[("", progid)]),
            key(format!("{c}\\Implemented Categories"), &[]),
            key(progid.to_string(), &[("", "Fake OPC server")]),
            key(format!("{progid}\\CLSID"), &[("", &guid_string(clsid))]),
        ];
        for cat in cats {
            keys.push(key(
                format!("{c}\\Implemented Categories\\{}", guid_string(*cat)),
                &[],
            ));
        }
        winreg::write_keys(&keys).expect("write the fake server's keys");
        FakeServer {
            view,
            clsid,
            progid,
        }
    }
}

impl Drop for FakeServer {
    fn drop(&mut self) {
        let _ = winreg::delete_trees(&[
            (self.view, format!("CLSID\\{}", guid_string(self.clsid))),
            (self.view, self.progid.to_string()),
        ]);
    }
}

#[test]
fn serverctopc_is_listed_for_da_2_and_3_not_for_da_1() {
    let (_com, b) = browser();
    assert!(b.list2.is_some(), "IOPCServerList2 is offered");
    assert!(list(&b, &[DA20]).contains(&OURS));
    assert!(list(&b, &[DA30]).contains(&OURS));
    assert!(!list(&b, &[DA10]).contains(&OURS));
    let both = list(&b, &[DA20, DA30]);
    assert_eq!(
        both.iter().filter(|c| **c == OURS).count(),
        1,
        "listed once"
    );
    let required_da30 = b.classes(&[DA20], &[DA30]).unwrap();
    assert!(required_da30.contains(&OURS));
}

#[test]
fn a_server_in_the_32_bit_view_only_is_listed_with_its_details() {
    const FAKE: u128 = 0x5eb00c1a_0001_4e5e_9a11_000000000032;
    let _fake = FakeServer::register(
        View::Reg32,
        FAKE,
        "CtopcTest.Only32.1",
        &[CATID_OPC_DA_SERVER_10, CATID_OPC_DA_SERVER_20],
    );
    let fake = GUID::from_u128(FAKE);
    let (_com, b) = browser();
    assert!(list(&b, &[DA10]).contains(&fake), "DA 1.0");
    assert!(list(&b, &[DA20]).contains(&fake), "DA 2.0");
    assert!(!list(&b, &[DA30]).contains(&fake), "not DA 3.0");
    let d = b.details(&fake).unwrap();
    assert_eq!(d.progid, "CtopcTest.Only32.1");
    assert_eq!(d.user_type, "Fake OPC server");
    assert_eq!(b.clsid_from_progid("CtopcTest.Only32.1").unwrap(), fake);
}

#[test]
fn a_server_in_the_64_bit_view_only_is_listed_too() {
    const FAKE: u128 = 0x5eb00c1a_0002_4e5e_9a11_000000000064;
    let _fake = FakeServer::register(
        View::Reg64,
        FAKE,
        "CtopcTest.Only64.1",
        &[CATID_OPC_DA_SERVER_30],
    );
    let (_com, b) = browser();
    assert!(list(&b, &[DA30]).contains(&GUID::from_u128(FAKE)));
    assert!(!list(&b, &[DA10]).contains(&GUID::from_u128(FAKE)));
}

#[test]
fn class_details_of_serverctopc() {
    let (_com, b) = browser();
    let d = b.details(&OURS).unwrap();
    // The original's ProgID, which plants' client configurations hold and match by name.
    assert_eq!(d.progid, registration::PROGID);
    assert_eq!(d.user_type, registration::DESCRIPTION);
    assert_eq!(
        d.version_independent_progid.as_deref(),
        Some(registration::PROGID)
    );
    let d1 = b.details1(&OURS).unwrap();
    assert_eq!(d1.progid, registration::PROGID);
    assert_eq!(d1.user_type, registration::DESCRIPTION);
}

/// A client configured with the original's ProgID, as plants' HMI configurations hold it,
/// that lists the DA servers through the browser, picks the one whose registered ProgID
/// is that name, and connects to it by the CLSID the browser gave.
#[test]
fn a_client_matching_the_originals_progid_by_name_finds_and_connects() {
    let (_com, b) = browser();
    let mut matched = Vec::new();
    for clsid in list(&b, &[DA20]) {
        let d = b.details(&clsid).unwrap();
        if d.progid == "ServerCTOPC.App" {
            matched.push(clsid);
        }
    }
    assert_eq!(
        matched,
        vec![OURS],
        "exactly one server named ServerCTOPC.App"
    );
    // SAFETY: the CLSID is a valid GUID; COM is initialised by the apartment above.
    let unknown: windows::core::IUnknown = unsafe {
        windows::Win32::System::Com::CoCreateInstance(
            &matched[0],
            None,
            windows::Win32::System::Com::CLSCTX_LOCAL_SERVER,
        )
    }
    .expect("CoCreateInstance by the browsed CLSID");
    let server = opc_client::Server::from_unknown(unknown).expect("IOPCServer");
    assert!(
        server.status().is_ok(),
        "the browsed server answers GetStatus"
    );
}

#[test]
fn clsid_from_progid_finds_both_progids() {
    let (_com, b) = browser();
    assert_eq!(b.clsid_from_progid("ServerCTOPC.App").unwrap(), OURS);
    assert_eq!(b.clsid_from_progid("ServerCTOPC.App.1").unwrap(), OURS);
    assert_eq!(b.clsid_from_progid("serverctopc.app").unwrap(), OURS);
}

/// A version-independent ProgID with only a `CurVer` (no `CLSID` of its own, as some
/// vendors register theirs) resolves to the CLSID of the ProgID `CurVer` names.
#[test]
fn clsid_from_progid_follows_cur_ver() {
    const FAKE: u128 = 0x5eb00c1a_0003_4e5e_9a11_0000000c0e1e;
    let _fake = FakeServer::register(
        View::Reg64,
        FAKE,
        "CtopcTest.CurVer.2",
        &[CATID_OPC_DA_SERVER_20],
    );
    let vi = Key {
        view: View::Reg64,
        path: "CtopcTest.CurVer\\CurVer".into(),
        values: vec![(String::new(), "CtopcTest.CurVer.2".into())],
    };
    winreg::write_keys(&[vi]).expect("write the CurVer key");
    let (_com, b) = browser();
    let found = b.clsid_from_progid("CtopcTest.CurVer");
    let versioned = b.clsid_from_progid("CtopcTest.CurVer.2");
    let _ = winreg::delete_trees(&[(View::Reg64, "CtopcTest.CurVer".to_string())]);
    assert_eq!(found.unwrap(), GUID::from_u128(FAKE), "through CurVer");
    assert_eq!(versioned.unwrap(), GUID::from_u128(FAKE));
}

#[test]
fn unknown_clsid_and_progid_fail_as_opcenum_does() {
    let (_com, b) = browser();
    let unknown = GUID::from_u128(0x5eb00c1a_dead_4e5e_9a11_000000000000);
    assert_eq!(b.details(&unknown).unwrap_err().code(), REGDB_E_CLASSNOTREG);
    assert_eq!(
        b.details1(&unknown).unwrap_err().code(),
        REGDB_E_CLASSNOTREG
    );
    assert_eq!(
        b.clsid_from_progid("No.Such.Server.1").unwrap_err().code(),
        CO_E_CLASSSTRING
    );
}

#[test]
fn the_opc_enumerator_skips_resets_and_clones() {
    let (_com, b) = browser();
    let list2: &IOPCServerList2 = b.list2.as_ref().unwrap();
    let mut e: Option<IOPCEnumGUID> = None;
    // SAFETY: a one-element array living for the call; `e` receives the enumerator.
    unsafe {
        list2
            .EnumClassesOfCategories(1, &DA20, 0, std::ptr::null(), &mut e)
            .unwrap()
    };
    let e = e.unwrap();
    let all = opc_enum_guids(&e).unwrap();
    assert!(all.contains(&OURS));
    // SAFETY: plain calls on the enumerator; `c` receives the clone.
    unsafe {
        assert_eq!(e.Skip(1), S_FALSE, "at the end");
        e.Reset().unwrap();
        assert_eq!(e.Skip(all.len() as u32), S_OK);
        e.Reset().unwrap();
        assert_eq!(e.Skip(1), S_OK);
        let mut c: Option<IOPCEnumGUID> = None;
        e.Clone(&mut c).unwrap();
        let rest = opc_enum_guids(&c.unwrap()).unwrap();
        assert_eq!(rest, all[1..]);
    }
}

fn run_server_list(args: &[&str]) -> std::process::Output {
    std::process::Command::new(artifact("OpcServerList.exe"))
        .args(args)
        .output_retrying()
        .expect("run OpcServerList.exe")
}

/// Restores our registration however the test ends.
struct Reregister;
impl Drop for Reregister {
    fn drop(&mut self) {
        let _ = winreg::delete_trees(&[
            (View::Reg64, registration::server_list_local_server_key()),
            (View::Reg32, registration::server_list_local_server_key()),
        ]);
        let _ = run_server_list(&["/RegServer"]);
    }
}

#[test]
fn registration_leaves_another_server_browser_alone() {
    let _restore = Reregister;
    let theirs = "C:\\windows\\system32\\OpcEnum.exe";
    let key = registration::server_list_local_server_key();
    winreg::write_keys(&[Key {
        view: View::Reg32,
        path: key.clone(),
        values: vec![(String::new(), theirs.to_string())],
    }])
    .unwrap();
    let out = run_server_list(&["/RegServer"]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("not ours"), "{text}");
    let read = |v: View| ctopc_com::winreg::read_default(v, &key);
    assert_eq!(read(View::Reg32).as_deref(), Some(theirs), "left alone");
    assert!(
        read(View::Reg64).is_some_and(|l| registration::is_our_server_list(&l)),
        "the free view gets ours"
    );
    let out = run_server_list(&["/UnregServer"]);
    assert!(out.status.success(), "{out:?}");
    assert_eq!(read(View::Reg32).as_deref(), Some(theirs), "not removed");
    assert_eq!(read(View::Reg64), None, "ours removed");
}

#[test]
fn registering_twice_is_harmless() {
    for _ in 0..2 {
        let out = run_server_list(&["/RegServer"]);
        assert!(out.status.success(), "{out:?}");
    }
    let key = registration::server_list_local_server_key();
    for v in registration::VIEWS {
        let ls = ctopc_com::winreg::read_default(v, &key).unwrap();
        assert!(registration::is_our_server_list(&ls), "{v:?}: {ls}");
    }
}
