//! IOPCServer group management end to end: AddGroup, GetGroupByName, RemoveGroup,
//! CreateGroupEnumerator (and the group count of GetStatus).
#![cfg(windows)]

use e2e_tests::{assert_alive, assert_invalid_arg_or_null_ref, code, connect, interfaces::*};
use opc_client::{GroupSpec, OpcGroup, Server};
use windows::core::{IUnknown, Interface, BOOL, GUID, HRESULT, HSTRING, PCWSTR};
use windows::Win32::Foundation::{E_INVALIDARG, E_NOINTERFACE, S_FALSE, S_OK};
use windows::Win32::System::Com::{IEnumString, IEnumUnknown};

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
fn update_rates_below_the_minimum_are_raised_with_unsupportedrate() {
    let (_com, server) = connect();
    for (i, rate) in [0u32, 1, 250, 999].into_iter().enumerate() {
        let g = server
            .add_group(&GroupSpec {
                rate_ms: rate,
                ..spec(&format!("r{i}"))
            })
            .expect("AddGroup");
        assert_eq!(
            (g.code, g.revised_rate),
            (OPC_S_UNSUPPORTEDRATE, 1000),
            "rate {rate}"
        );
    }
    let g = server
        .add_group(&GroupSpec {
            rate_ms: 2500,
            ..spec("slow")
        })
        .unwrap();
    assert_eq!((g.code, g.revised_rate), (S_OK, 2500));
}

#[test]
fn empty_name_makes_the_server_choose_a_unique_one() {
    let (_com, server) = connect();
    let a = OpcGroup::from_unknown(server.add_group(&spec("")).unwrap().object).unwrap();
    let b = OpcGroup::from_unknown(server.add_group(&spec("")).unwrap().object).unwrap();
    let (na, nb) = (
        a.get_state().unwrap().name.unwrap(),
        b.get_state().unwrap().name.unwrap(),
    );
    assert!(!na.is_empty() && !nb.is_empty());
    assert_ne!(na, nb);
}

#[test]
fn duplicate_name_is_opc_e_duplicatename() {
    let (_com, server) = connect();
    let _g = server.add_group(&spec("Pompa")).unwrap();
    assert_eq!(code(&server.add_group(&spec("Pompa"))), OPC_E_DUPLICATENAME);
    assert_eq!(server.status().unwrap().group_count, 1);
    // Names are per client: another client may use it.
    let (_com2, other) = connect();
    assert!(other.add_group(&spec("Pompa")).is_ok());
    assert_alive(&server);
}

#[test]
fn null_time_bias_and_deadband_are_the_machine_bias_and_zero() {
    use windows::Win32::System::Time::{GetTimeZoneInformation, TIME_ZONE_INFORMATION};
    let (_com, server) = connect();
    let mut tz = TIME_ZONE_INFORMATION::default();
    // SAFETY: a valid out-structure.
    unsafe { GetTimeZoneInformation(&mut tz) };
    let g = OpcGroup::from_unknown(server.add_group(&spec("domyślne")).unwrap().object).unwrap();
    let s = g.get_state().unwrap();
    assert_eq!((s.time_bias, s.percent_deadband), (tz.Bias, 0.0));
    let g = OpcGroup::from_unknown(
        server
            .add_group(&GroupSpec {
                time_bias: Some(-120),
                deadband: Some(12.5),
                ..spec("jawne")
            })
            .unwrap()
            .object,
    )
    .unwrap();
    let s = g.get_state().unwrap();
    assert_eq!((s.time_bias, s.percent_deadband), (-120, 12.5));
}

#[test]
fn deadband_outside_0_to_100_is_e_invalidarg() {
    let (_com, server) = connect();
    for d in [-0.5f32, 100.5, f32::NAN] {
        assert_eq!(
            code(&server.add_group(&GroupSpec {
                deadband: Some(d),
                ..spec("d")
            })),
            E_INVALIDARG,
            "{d}"
        );
    }
    assert_eq!(server.status().unwrap().group_count, 0);
    assert_alive(&server);
}

#[test]
fn lcid_must_be_a_known_locale() {
    let (_com, server) = connect();
    for (i, lcid) in [0x0415u32, 0x0409, 0x0809, 0x0000, 0x0400, 0x0800, 0x0407]
        .into_iter()
        .enumerate()
    {
        let g = server.add_group(&GroupSpec {
            lcid,
            ..spec(&format!("l{i}"))
        });
        assert!(g.is_ok(), "LCID {lcid:#x}: {:?}", code(&g));
    }
    for lcid in [0x0012_3456u32, 0xFFFF_FFFF, 0x7777] {
        assert_eq!(
            code(&server.add_group(&GroupSpec { lcid, ..spec("x") })),
            E_INVALIDARG,
            "LCID {lcid:#x}"
        );
    }
    let g = OpcGroup::from_unknown(
        server
            .add_group(&GroupSpec {
                lcid: 0x0415,
                ..spec("pl")
            })
            .unwrap()
            .object,
    )
    .unwrap();
    assert_eq!(g.get_state().unwrap().lcid, 0x0415);
    assert_alive(&server);
}

#[test]
fn unsupported_riid_is_e_nointerface_and_leaves_no_group() {
    let (_com, server) = connect();
    assert_eq!(
        code(&server.add_group_as(&spec("Filtr"), &IOPCServer::IID)),
        E_NOINTERFACE
    );
    assert_eq!(server.status().unwrap().group_count, 0);
    assert_eq!(code(&server.group_by_name("Filtr")), E_INVALIDARG);
    // The name is free again.
    assert!(server.add_group(&spec("Filtr")).is_ok());
}

/// AddGroup with raw arguments (NULL where `null` says so).
fn raw_add_group(
    server: &Server,
    null_name: bool,
    null_handle: bool,
    null_rate: bool,
    null_riid: bool,
) -> HRESULT {
    let name = HSTRING::from("raw");
    let (mut handle, mut revised) = (0u32, 0u32);
    let mut unk: Option<IUnknown> = None;
    let iid = IUnknown::IID;
    // SAFETY: every pointer is valid or deliberately NULL (what the test checks).
    unsafe {
        server.server.AddGroup(
            if null_name {
                PCWSTR::null()
            } else {
                PCWSTR(name.as_ptr())
            },
            BOOL(1),
            1000,
            1,
            std::ptr::null(),
            std::ptr::null(),
            0x0409,
            if null_handle {
                std::ptr::null_mut()
            } else {
                &mut handle
            },
            if null_rate {
                std::ptr::null_mut()
            } else {
                &mut revised
            },
            if null_riid {
                std::ptr::null()
            } else {
                &iid as *const GUID
            },
            &mut unk,
        )
    }
}

#[test]
fn null_pointers_are_rejected_and_the_server_still_answers() {
    let (_com, server) = connect();
    let cases = [
        (true, false, false, false, "szName"),
        (false, true, false, false, "phServerGroup"),
        (false, false, true, false, "pRevisedUpdateRate"),
        (false, false, false, true, "riid"),
    ];
    for (a, b, c, d, what) in cases {
        assert_invalid_arg_or_null_ref(raw_add_group(&server, a, b, c, d), what);
        assert_alive(&server);
        assert_eq!(
            server.status().unwrap().group_count,
            0,
            "{what}: no group was made"
        );
    }
    // Not tested out of process: a NULL ppUnk. Wine's proxy does not check it on the way
    // out; the server receives a stub-allocated pointer, makes the group and answers S_OK;
    // the proxy then fails to write the interface to NULL and answers the client
    // RPC_X_NULL_REF_POINTER. The server cannot tell, and the reference the stub marshaled
    // is never released (no DCOM ping under Wine), so that server process could not exit.
    // (In process, a NULL ppUnk is E_INVALIDARG before anything is made.)
    // GetGroupByName / CreateGroupEnumerator with NULL out-pointers.
    let name = HSTRING::from("raw");
    // SAFETY: deliberately NULL out-pointer.
    let r = unsafe {
        server
            .server
            .GetGroupByName(PCWSTR(name.as_ptr()), &IUnknown::IID, std::ptr::null_mut())
    };
    assert_invalid_arg_or_null_ref(code(&r), "GetGroupByName(ppUnk)");
    // SAFETY: deliberately NULL out-pointer.
    let hr = unsafe {
        server
            .server
            .CreateGroupEnumerator(OPC_ENUM_ALL, &IEnumString::IID, std::ptr::null_mut())
    };
    assert_invalid_arg_or_null_ref(hr, "CreateGroupEnumerator(ppUnk)");
    assert_alive(&server);
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
fn get_group_by_name_unknown_name_is_e_invalidarg_and_bad_riid_e_nointerface() {
    let (_com, server) = connect();
    let _g = server.add_group(&spec("A")).unwrap();
    assert_eq!(code(&server.group_by_name("B")), E_INVALIDARG);
    assert_eq!(
        code(&server.group_by_name("a")),
        E_INVALIDARG,
        "names are case-sensitive"
    );
    assert_eq!(
        code(&server.group_by_name_as("A", &IOPCServer::IID)),
        E_NOINTERFACE
    );
    assert_alive(&server);
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
    assert_eq!(
        code(&server.remove_group(handle, false)),
        E_INVALIDARG,
        "already removed"
    );
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
    assert_eq!(
        code(&server.remove_group(g.server_handle, false)),
        E_INVALIDARG,
        "removed already"
    );
    drop((g, group));
    assert_eq!(server.status().unwrap().group_count, 1);
    assert_alive(&server);
}

#[test]
fn remove_group_with_force_removes_a_referenced_group() {
    let (_com, server) = connect();
    let g = server.add_group(&spec("siłą")).unwrap();
    assert_eq!(server.remove_group(g.server_handle, true).unwrap(), S_OK);
    assert_eq!(server.status().unwrap().group_count, 0);
    let group = OpcGroup::from_unknown(g.object.clone()).unwrap();
    assert!(group.get_state().is_err());
    assert_eq!(
        code(&server.remove_group(g.server_handle, true)),
        E_INVALIDARG
    );
    assert_alive(&server);
}

#[test]
fn remove_group_bad_handle_is_e_invalidarg() {
    let (_com, server) = connect();
    let (_com2, other) = connect();
    let theirs = other.add_group(&spec("cudza")).unwrap();
    for h in [0u32, 0xDEAD_BEEF, theirs.server_handle] {
        assert_eq!(
            code(&server.remove_group(h, false)),
            E_INVALIDARG,
            "handle {h:#x}"
        );
        assert_eq!(
            code(&server.remove_group(h, true)),
            E_INVALIDARG,
            "handle {h:#x}"
        );
    }
    assert_eq!(
        other.status().unwrap().group_count,
        1,
        "another client's group is untouched"
    );
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

#[test]
fn group_enumerator_bad_riid_and_scope() {
    let (_com, server) = connect();
    let _a = server.add_group(&spec("g")).unwrap();
    assert_eq!(
        code(&server.group_enumerator(OPC_ENUM_ALL, &IOPCServer::IID)),
        E_NOINTERFACE
    );
    assert_eq!(
        code(
            &server
                .group_enumerator(OPC_ENUM_ALL, &IEnumUnknown::IID)
                .map(|_| ())
        ),
        S_OK
    );
    // (Values above 0x7FFF do not reach the server: the proxy marshals IDL enums as 16 bits.)
    for scope in [OPCENUMSCOPE(0), OPCENUMSCOPE(7), OPCENUMSCOPE(0x7FFF)] {
        assert_eq!(
            code(&server.group_enumerator(scope, &IEnumString::IID)),
            E_INVALIDARG,
            "{scope:?}"
        );
    }
    assert_alive(&server);
}
