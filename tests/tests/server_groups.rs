//! IOPCServer group management end to end: AddGroup, GetGroupByName, RemoveGroup,
//! CreateGroupEnumerator (and the group count of GetStatus).
//!
//! Spec: OPC DA 2.05a §4.4.4 IOPCServer (AddGroup, GetGroupByName, RemoveGroup,
//! CreateGroupEnumerator) and §6.7.5 OPCSERVERSTATUS (dwGroupCount).
#![cfg(windows)]

use e2e_tests::{assert_alive, code, connect, interfaces::*};
use opc_client::{GroupSpec, OpcGroup};
use windows::core::{IUnknown, Interface};
use windows::Win32::Foundation::{E_INVALIDARG, S_FALSE, S_OK};
use windows::Win32::System::Com::IEnumUnknown;

fn spec(name: &str) -> GroupSpec {
    GroupSpec::new(name)
}

fn identity(u: &IUnknown) -> *mut std::ffi::c_void {
    // The IUnknown of an object is its identity (also through proxies).
    u.cast::<IUnknown>()
        .map(|u| u.as_raw())
        .unwrap_or(std::ptr::null_mut())
}

#[test]
fn add_group_returns_handle_rate_and_a_group_object() {
    let (_com, server) = connect();
    let g = server.add_group(&spec("Kocioł")).expect("AddGroup");
    assert_eq!(g.code, S_OK);
    assert_ne!(g.server_handle, 0);
    assert_eq!(g.revised_rate, 1000);
    let group = OpcGroup::from_unknown(g.object.clone())
        .expect("the object is a group (IOPCItemMgt, IOPCGroupStateMgt)");
    let state = group.get_state().expect("GetState");
    assert_eq!(state.name.as_deref(), Some("Kocioł"));
    assert_eq!(state.server_handle, g.server_handle);
    assert_eq!(server.status().unwrap().group_count, 1);
    // Asking for a specific interface works too.
    let g2 = server
        .add_group_as(&spec("Drugi"), &IOPCGroupStateMgt::IID)
        .expect("AddGroup(IID_IOPCGroupStateMgt)");
    assert!(g2.object.cast::<IOPCGroupStateMgt>().is_ok());
    assert_eq!(server.status().unwrap().group_count, 2);
}

#[test]
fn get_group_by_name_gives_the_same_object() {
    let (_com, server) = connect();
    let g = server.add_group(&spec("Zbiornik Z101")).unwrap();
    let found = server
        .group_by_name("Zbiornik Z101")
        .expect("GetGroupByName");
    assert_eq!(
        identity(&found),
        identity(&g.object),
        "one COM identity per group"
    );
    let as_state = server
        .group_by_name_as("Zbiornik Z101", &IOPCGroupStateMgt::IID)
        .expect("GetGroupByName(IID_IOPCGroupStateMgt)");
    assert!(as_state.cast::<IOPCGroupStateMgt>().is_ok());
    // After the client released every reference, the name still finds the group (a new
    // object for the same engine group).
    let handle = g.server_handle;
    drop((g, found, as_state));
    let again = OpcGroup::from_unknown(server.group_by_name("Zbiornik Z101").unwrap()).unwrap();
    assert_eq!(again.get_state().unwrap().server_handle, handle);
}

#[test]
fn remove_group_without_references_is_s_ok() {
    let (_com, server) = connect();
    let g = server.add_group(&spec("usuń")).unwrap();
    let handle = g.server_handle;
    drop(g);
    assert_eq!(server.remove_group(handle, false).unwrap(), S_OK);
    assert_eq!(server.status().unwrap().group_count, 0);
    assert_eq!(code(&server.group_by_name("usuń")), E_INVALIDARG);
}

#[test]
fn remove_group_while_referenced_is_opc_s_inuse_until_released() {
    let (_com, server) = connect();
    let g = server.add_group(&spec("w użyciu")).unwrap();
    let group = OpcGroup::from_unknown(g.object.clone()).unwrap();
    assert_eq!(
        server.remove_group(g.server_handle, false).unwrap(),
        OPC_S_INUSE
    );
    // Gone for the server: no name, not enumerated, not counted; the name is free.
    assert_eq!(code(&server.group_by_name("w użyciu")), E_INVALIDARG);
    assert_eq!(
        server.group_names(OPC_ENUM_ALL).unwrap().1,
        Vec::<String>::new()
    );
    assert_eq!(server.status().unwrap().group_count, 0);
    assert!(
        group.get_state().is_err(),
        "the object of a removed group fails its calls"
    );
    let again = server
        .add_group(&spec("w użyciu"))
        .expect("the name is free");
    assert_ne!(again.server_handle, g.server_handle);
    drop((g, group));
    assert_eq!(server.status().unwrap().group_count, 1);
    assert_alive(&server);
}

#[test]
fn group_enumerators_list_names_and_objects() {
    let (_com, server) = connect();
    // No groups: S_FALSE with an empty enumerator.
    assert_eq!(server.group_names(OPC_ENUM_ALL).unwrap(), (S_FALSE, vec![]));
    let (hr, objs) = server.group_objects(OPC_ENUM_ALL).unwrap();
    assert_eq!((hr, objs.len()), (S_FALSE, 0));
    // An empty IEnumUnknown answers S_FALSE with nothing.
    let (_, e) = server
        .group_enumerator(OPC_ENUM_ALL, &IEnumUnknown::IID)
        .unwrap();
    let e: IEnumUnknown = e.cast().unwrap();
    let mut one: [Option<IUnknown>; 1] = Default::default();
    // SAFETY: room for one element.
    assert_eq!(unsafe { e.Next(&mut one, None) }, S_FALSE);
    assert!(one[0].is_none());
    let a = server.add_group(&spec("Piec")).unwrap();
    let b = server.add_group(&spec("Kocioł odzysknicowy")).unwrap();
    for scope in [
        OPC_ENUM_PRIVATE_CONNECTIONS,
        OPC_ENUM_ALL_CONNECTIONS,
        OPC_ENUM_PRIVATE,
        OPC_ENUM_ALL,
    ] {
        let (hr, mut names) = server.group_names(scope).unwrap();
        names.sort();
        assert_eq!(
            (hr, names),
            (
                S_OK,
                vec!["Kocioł odzysknicowy".to_string(), "Piec".to_string()]
            ),
            "{scope:?}"
        );
        let (hr, objs) = server.group_objects(scope).unwrap();
        assert_eq!(hr, S_OK);
        let mut ids: Vec<_> = objs.iter().map(identity).collect();
        ids.sort();
        let mut want = vec![identity(&a.object), identity(&b.object)];
        want.sort();
        assert_eq!(
            ids, want,
            "{scope:?}: the enumerated objects are the groups"
        );
    }
    // No public groups.
    for scope in [OPC_ENUM_PUBLIC_CONNECTIONS, OPC_ENUM_PUBLIC] {
        assert_eq!(
            server.group_names(scope).unwrap(),
            (S_FALSE, vec![]),
            "{scope:?}"
        );
        assert_eq!(server.group_objects(scope).unwrap().1.len(), 0);
    }
}
