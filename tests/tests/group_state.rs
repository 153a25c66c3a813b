//! The group's state end to end: IOPCGroupStateMgt (GetState, SetState, SetName,
//! CloneGroup), IOPCGroupStateMgt2 (keep-alive), the group's COM identity.
#![cfg(windows)]

mod group_common;

use e2e_tests::{assert_alive, code, connect, interfaces::*};
use group_common::*;
use opc_client::{GroupStateChange, OpcGroup};
use windows::core::{IUnknown, Interface, BOOL, HSTRING, PCWSTR, PWSTR};
use windows::Win32::Foundation::{E_INVALIDARG, E_NOINTERFACE, E_NOTIMPL, S_OK};

#[test]
fn get_state_reports_what_add_group_set() {
    let (_com, server) = connect();
    let g = try_add_group(&server, "state-get", true, 2000, 4711).unwrap();
    let s = g.get_state().unwrap();
    assert_eq!(s.name.as_deref(), Some("state-get"));
    assert!(s.active);
    assert_eq!(s.update_rate, 2000);
    assert_eq!(s.update_rate, g.revised_rate);
    assert_eq!(s.client_handle, 4711);
    assert_eq!(s.server_handle, g.server_handle);
    assert_eq!(s.percent_deadband, 0.0);
    assert_eq!(s.lcid, 0x0409);
    assert_eq!(s.time_bias, 0);
    assert_alive(&server);
}

#[test]
fn set_state_changes_only_what_is_given() {
    let (_com, server) = connect();
    let g = add_group(&server, "state-set", true, 1);
    let (hr, rate) = g
        .set_state(&GroupStateChange {
            update_rate: Some(2500),
            ..Default::default()
        })
        .unwrap();
    assert_eq!((hr, rate), (S_OK, 2500));
    // Every pointer NULL: nothing changes, the current rate comes back.
    let (hr, rate) = g.set_state(&GroupStateChange::default()).unwrap();
    assert_eq!((hr, rate), (S_OK, 2500));
    let (hr, _) = g
        .set_state(&GroupStateChange {
            active: Some(false),
            time_bias: Some(-60),
            percent_deadband: Some(12.5),
            lcid: Some(0x0415),
            client_handle: Some(99),
            ..Default::default()
        })
        .unwrap();
    assert_eq!(hr, S_OK);
    let s = g.get_state().unwrap();
    assert_eq!(
        (
            s.update_rate,
            s.active,
            s.time_bias,
            s.percent_deadband,
            s.lcid,
            s.client_handle
        ),
        (2500, false, -60, 12.5, 0x0415, 99)
    );
    assert_eq!(s.name.as_deref(), Some("state-set"));
    assert_alive(&server);
}

#[test]
fn set_state_revises_too_fast_rates_and_rejects_bad_deadbands() {
    let (_com, server) = connect();
    let g = add_group(&server, "state-rate", true, 1);
    let (hr, rate) = g
        .set_state(&GroupStateChange {
            update_rate: Some(100),
            ..Default::default()
        })
        .unwrap();
    assert_eq!((hr, rate), (OPC_S_UNSUPPORTEDRATE, 1000));
    let (hr, rate) = g
        .set_state(&GroupStateChange {
            update_rate: Some(0),
            ..Default::default()
        })
        .unwrap();
    assert_eq!((hr, rate), (OPC_S_UNSUPPORTEDRATE, 1000));
    for bad in [101.0f32, -0.5, f32::NAN] {
        let r = g.set_state(&GroupStateChange {
            percent_deadband: Some(bad),
            active: Some(false),
            ..Default::default()
        });
        assert_eq!(code(&r), E_INVALIDARG, "deadband {bad}");
    }
    let s = g.get_state().unwrap();
    assert!(
        s.active && s.percent_deadband == 0.0,
        "a rejected SetState changes nothing: {s:?}"
    );
    // The revised-rate out-pointer is a required [out] pointer.
    // SAFETY: deliberately NULL [out] pointer.
    let hr = unsafe {
        g.state_mgt.SetState(
            std::ptr::null(),
            std::ptr::null_mut(),
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert!(hr == RPC_X_NULL_REF_POINTER || hr == E_INVALIDARG, "{hr:?}");
    assert_alive(&server);
}

#[test]
fn get_state_with_null_out_pointers_is_rejected() {
    let (_com, server) = connect();
    let g = add_group(&server, "state-null", true, 1);
    let (mut rate, mut active, mut name, mut bias, mut db, mut lcid, mut ch, mut sh) =
        (0u32, BOOL(0), PWSTR::null(), 0i32, 0f32, 0u32, 0u32, 0u32);
    // SAFETY: one deliberately NULL [out] pointer.
    let r = unsafe {
        g.state_mgt.GetState(
            &mut rate,
            &mut active,
            std::ptr::null_mut(),
            &mut bias,
            &mut db,
            &mut lcid,
            &mut ch,
            &mut sh,
        )
    };
    assert!(
        code(&r) == RPC_X_NULL_REF_POINTER || code(&r) == E_INVALIDARG,
        "{r:?}"
    );
    // SAFETY: as above.
    let r = unsafe {
        g.state_mgt.GetState(
            std::ptr::null_mut(),
            &mut active,
            &mut name,
            &mut bias,
            &mut db,
            &mut lcid,
            &mut ch,
            &mut sh,
        )
    };
    assert!(
        code(&r) == RPC_X_NULL_REF_POINTER || code(&r) == E_INVALIDARG,
        "{r:?}"
    );
    assert!(name.is_null());
    assert_eq!(g.get_state().unwrap().name.as_deref(), Some("state-null"));
    assert_alive(&server);
}

#[test]
fn set_name_renames_and_rejects_duplicates_and_empty_names() {
    let (_com, server) = connect();
    let a = add_group(&server, "name-a", true, 1);
    let _b = add_group(&server, "name-b", true, 2);
    a.set_name("name-a2 żółć").unwrap();
    assert_eq!(a.get_state().unwrap().name.as_deref(), Some("name-a2 żółć"));
    assert_eq!(code(&a.set_name("name-b")), OPC_E_DUPLICATENAME);
    assert_eq!(code(&a.set_name("")), E_INVALIDARG);
    // Its own name again is fine; names are case-sensitive.
    a.set_name("name-a2 żółć").unwrap();
    a.set_name("NAME-B").unwrap();
    // The old name is free again.
    let c = try_add_group(&server, "name-a2 żółć", true, 1000, 3).expect("the old name is free");
    assert_eq!(c.get_state().unwrap().name.as_deref(), Some("name-a2 żółć"));
    // A duplicate AddGroup name.
    assert_eq!(
        code(&try_add_group(&server, "name-b", true, 1000, 4)),
        OPC_E_DUPLICATENAME
    );
    // SAFETY: a deliberately NULL [in, string] pointer.
    let r = unsafe { a.state_mgt.SetName(PCWSTR::null()) };
    assert!(
        code(&r) == RPC_X_NULL_REF_POINTER || code(&r) == E_INVALIDARG,
        "{r:?}"
    );
    assert_eq!(a.get_state().unwrap().name.as_deref(), Some("NAME-B"));
    assert_alive(&server);
}

#[test]
fn clone_group_copies_items_and_properties_under_a_new_name() {
    let (_com, server) = connect();
    let g = try_add_group(&server, "clone-src", true, 3000, 7).unwrap();
    let h = add_ok(&g, &[item("KW_A000", 1), inactive("KW_A110", 2)]);
    assert_eq!(
        g.set_state(&GroupStateChange {
            percent_deadband: Some(5.0),
            ..Default::default()
        })
        .unwrap()
        .0,
        S_OK
    );
    let groups_before = server.status().unwrap().group_count;

    let c = g.clone_group("clone-dst").unwrap();
    let s = c.get_state().unwrap();
    assert_eq!(s.name.as_deref(), Some("clone-dst"));
    assert!(!s.active, "a clone starts inactive");
    assert_eq!(
        (s.update_rate, s.client_handle, s.percent_deadband, s.lcid),
        (3000, 7, 5.0, 0x0409)
    );
    assert_ne!(s.server_handle, g.server_handle);
    let items = c.item_attributes().unwrap();
    assert_eq!(
        items
            .iter()
            .map(|a| a.item_id.clone().unwrap())
            .collect::<Vec<_>>(),
        vec!["KW_A000", "KW_A110"]
    );
    assert_eq!(
        items
            .iter()
            .map(|a| (a.client_handle, a.active))
            .collect::<Vec<_>>(),
        vec![(1, true), (2, false)]
    );
    assert!(
        items.iter().all(|a| !h.contains(&a.server_handle)),
        "new server handles"
    );
    assert_eq!(server.status().unwrap().group_count, groups_before + 1);

    // An empty name: the server generates a unique one.
    let d = g.clone_group("").unwrap();
    let name = d.get_state().unwrap().name.unwrap();
    assert!(
        !name.is_empty() && name != "clone-src" && name != "clone-dst",
        "{name}"
    );
    // Asking for a specific interface works.
    let as_state = g
        .clone_group_as("clone-iid", &IOPCGroupStateMgt2::IID)
        .unwrap();
    assert!(as_state.cast::<IOPCGroupStateMgt2>().is_ok());
    let groups_now = server.status().unwrap().group_count;

    assert_eq!(code(&g.clone_group("clone-src")), OPC_E_DUPLICATENAME);
    // An interface the group does not have: E_NOINTERFACE and no group left behind.
    assert_eq!(
        code(&g.clone_group_as("clone-noif", &IOPCServer::IID)),
        E_NOINTERFACE
    );
    assert_eq!(
        server.status().unwrap().group_count,
        groups_now,
        "all-or-nothing"
    );
    let again = g
        .clone_group("clone-noif")
        .expect("the name of the failed clone is free");
    drop(again);
    assert_alive(&server);
}

#[test]
fn keep_alive_is_revised_to_the_minimum_rate() {
    let (_com, server) = connect();
    let g = add_group(&server, "keepalive", true, 1);
    assert_eq!(g.keep_alive().unwrap(), 0, "off by default");
    assert_eq!(
        g.set_keep_alive(300).unwrap(),
        (OPC_S_UNSUPPORTEDRATE, 1000)
    );
    assert_eq!(g.keep_alive().unwrap(), 1000);
    assert_eq!(g.set_keep_alive(4000).unwrap(), (S_OK, 4000));
    assert_eq!(g.keep_alive().unwrap(), 4000);
    assert_eq!(g.set_keep_alive(0).unwrap(), (S_OK, 0));
    assert_eq!(g.keep_alive().unwrap(), 0);
    let s2: IOPCGroupStateMgt2 = g.unknown.cast().unwrap();
    // SAFETY: deliberately NULL [out] pointers.
    let hr = unsafe { s2.SetKeepAlive(1000, std::ptr::null_mut()) };
    assert!(hr == RPC_X_NULL_REF_POINTER || hr == E_INVALIDARG, "{hr:?}");
    // SAFETY: as above.
    let r = unsafe { s2.GetKeepAlive(std::ptr::null_mut()) };
    assert!(
        code(&r) == RPC_X_NULL_REF_POINTER || code(&r) == E_INVALIDARG,
        "{r:?}"
    );
    assert_alive(&server);
}

#[test]
fn the_group_object_has_one_identity_and_every_group_interface() {
    let (_com, server) = connect();
    let g = add_group(&server, "identity", true, 1);
    let u1: IUnknown = g.item_mgt.cast().unwrap();
    let u2: IUnknown = g.state_mgt.cast().unwrap();
    assert_eq!(
        u1.as_raw(),
        u2.as_raw(),
        "QueryInterface(IUnknown) is the identity"
    );
    for iid in [
        IOPCItemMgt::IID,
        IOPCGroupStateMgt::IID,
        IOPCGroupStateMgt2::IID,
        IOPCSyncIO::IID,
        IOPCSyncIO2::IID,
        IOPCAsyncIO2::IID,
        IOPCAsyncIO3::IID,
        IOPCItemDeadbandMgt::IID,
        IOPCItemSamplingMgt::IID,
        windows::Win32::System::Com::IConnectionPointContainer::IID,
    ] {
        let mut p = std::ptr::null_mut();
        // SAFETY: valid IID and out-pointer; a returned pointer is released below.
        let hr = unsafe { g.unknown.query(&iid, &mut p) };
        assert_eq!(hr, S_OK, "{iid:?}");
        // SAFETY: an AddRef'd pointer from QueryInterface.
        drop(unsafe { IUnknown::from_raw(p) });
    }
    let mut p = std::ptr::null_mut();
    // SAFETY: as above.
    let hr = unsafe { g.unknown.query(&IOPCServer::IID, &mut p) };
    assert_eq!(hr, E_NOINTERFACE);
    assert!(p.is_null());

    // GetGroupByName (when the server object offers it) returns the same identity.
    let name = HSTRING::from("identity");
    let mut unk: Option<IUnknown> = None;
    // SAFETY: valid string, IID and out-pointer.
    let r = unsafe {
        server
            .server
            .GetGroupByName(PCWSTR(name.as_ptr()), &IUnknown::IID, &mut unk)
    };
    if code(&r) != E_NOTIMPL {
        r.unwrap();
        let by_name: IUnknown = unk.unwrap().cast().unwrap();
        assert_eq!(by_name.as_raw(), u1.as_raw(), "one COM identity per group");
    }
    assert_alive(&server);
}

#[test]
fn released_group_can_be_found_again_and_removed() {
    let (_com, server) = connect();
    let g = add_group(&server, "release-me", true, 1);
    let handle = g.server_handle;
    add_ok(&g, &[item("KW_A000", 1)]);
    drop(g);
    let name = HSTRING::from("release-me");
    let mut unk: Option<IUnknown> = None;
    // SAFETY: valid string, IID and out-pointer.
    let r = unsafe {
        server
            .server
            .GetGroupByName(PCWSTR(name.as_ptr()), &IUnknown::IID, &mut unk)
    };
    if code(&r) != E_NOTIMPL {
        r.unwrap();
        let g = OpcGroup::from_unknown(unk.unwrap()).unwrap();
        assert_eq!(g.get_state().unwrap().server_handle, handle);
        assert_eq!(
            g.item_attributes().unwrap().len(),
            1,
            "the group kept its items"
        );
        drop(g);
    }
    // SAFETY: plain values.
    let hr = unsafe { server.server.RemoveGroup(handle, false.into()) };
    assert!(hr == S_OK || hr == E_NOTIMPL, "{hr:?}");
    assert_alive(&server);
}
