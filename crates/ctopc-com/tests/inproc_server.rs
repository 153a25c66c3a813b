//! IOPCServer and IOPCCommon of the server object, in process (no proxy): every argument
//! branch with its exact HRESULT, out-parameters cleared on failure (all or nothing), and
//! each method's success path. The argument rules are the module doc of
//! `crates/ctopc-com/src/da/server.rs`; the group rules that of `server/groups.rs`. The
//! harness is `common/mod.rs`.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use ctopc_com::interfaces::*;
use opc_client::enum_strings;
use std::ptr::{null, null_mut};
use windows::Win32::System::Com::{IConnectionPointContainer, IEnumString, IEnumUnknown};

const EN: u32 = 0x0409;
const PL: u32 = 0x0415;
/// Not a locale Windows knows, nor one the server speaks.
const BAD_LCID: u32 = 0x7FFF_1234;
/// A failure code with no text anywhere (not OPC's, not the system's).
const NO_TEXT: HRESULT = HRESULT(0x8FFF_7E57u32 as i32);
const U32_POISON: u32 = 0xA5A5_A5A5;

fn identity(u: &IUnknown) -> *mut std::ffi::c_void {
    u.cast::<IUnknown>().expect("IUnknown").as_raw()
}

#[test]
fn the_class_factory_makes_a_server_object_with_the_opc_interfaces() {
    let unk = new_server();
    assert!(unk.cast::<IOPCServer>().is_ok());
    assert!(unk.cast::<IOPCCommon>().is_ok());
    assert!(unk.cast::<IOPCBrowseServerAddressSpace>().is_ok());
    assert!(unk.cast::<IOPCItemProperties>().is_ok());
    assert!(unk.cast::<IOPCBrowse>().is_ok());
    assert!(unk.cast::<IOPCItemIO>().is_ok());
    assert!(unk.cast::<IConnectionPointContainer>().is_ok());
    // Not implemented: public groups, and group interfaces.
    assert_eq!(code(&unk.cast::<IOPCServerPublicGroups>()), E_NOINTERFACE);
    assert_eq!(code(&unk.cast::<IOPCItemMgt>()), E_NOINTERFACE);
    // Every CreateInstance makes a new object.
    assert_ne!(identity(&unk), identity(&new_server()));
}

#[test]
fn the_group_helper_adds_a_group() {
    let (server, g) = server_with_group("harness");
    assert_eq!(g.code, S_OK);
    assert_ne!(g.server_handle, 0);
    assert_eq!(g.revised_rate, 1000);
    assert_eq!(
        // SAFETY: a valid handle of this client's group.
        unsafe { server.RemoveGroup(g.server_handle, true.into()) },
        S_OK
    );
}

// ---- AddGroup -------------------------------------------------------------------------

/// AddGroup's out-parameters, pre-filled with poison.
struct AddOut {
    handle: u32,
    revised: u32,
    unk: OutUnk,
}

impl AddOut {
    fn poisoned() -> AddOut {
        AddOut {
            handle: U32_POISON,
            revised: U32_POISON,
            unk: OutUnk::poisoned(),
        }
    }
    fn assert_cleared(&self, what: &str) {
        assert_eq!(
            (self.handle, self.revised, self.unk.is_null()),
            (0, 0, true),
            "{what}: out-parameters not cleared"
        );
    }
}

/// AddGroup with the given raw pointers (NULL where asked), defaults elsewhere.
#[allow(clippy::too_many_arguments)]
unsafe fn add_group_raw(
    s: &IOPCServer,
    name: PCWSTR,
    rate: u32,
    deadband: *const f32,
    lcid: u32,
    handle: *mut u32,
    revised: *mut u32,
    riid: *const GUID,
    unk: *mut Option<IUnknown>,
) -> HRESULT {
    // SAFETY: forwarded to the caller.
    unsafe {
        s.AddGroup(
            name,
            true.into(),
            rate,
            7,
            null(),
            deadband,
            lcid,
            handle,
            revised,
            riid,
            unk,
        )
    }
}

#[test]
fn add_group_null_pointers_are_invalidarg_and_clear_every_output() {
    let s = opc_server();
    let name = wide("g");
    for which in 0..5 {
        let mut o = AddOut::poisoned();
        let name_p = if which == 0 {
            PCWSTR::null()
        } else {
            pcwstr(&name)
        };
        let handle: *mut u32 = if which == 1 {
            null_mut()
        } else {
            &mut o.handle
        };
        let revised: *mut u32 = if which == 2 {
            null_mut()
        } else {
            &mut o.revised
        };
        let riid: *const GUID = if which == 3 { null() } else { &IUnknown::IID };
        let unk = if which == 4 {
            null_mut()
        } else {
            o.unk.as_out()
        };
        // SAFETY: every pointer is NULL or valid for the call.
        let hr = unsafe { add_group_raw(&s, name_p, 1000, null(), EN, handle, revised, riid, unk) };
        assert_eq!(hr, E_INVALIDARG, "NULL argument {which}");
        if which != 1 {
            assert_eq!(o.handle, 0, "NULL argument {which}: handle not cleared");
        }
        if which != 2 {
            assert_eq!(
                o.revised, 0,
                "NULL argument {which}: revised rate not cleared"
            );
        }
        if which != 4 {
            assert!(o.unk.is_null(), "NULL argument {which}: object not cleared");
        }
    }
    assert_eq!(client_of(&s).status().unwrap().group_count, 0);
}

fn client_of(s: &IOPCServer) -> opc_client::Server {
    opc_client::Server::from_unknown(s.cast().unwrap()).unwrap()
}

#[test]
fn add_group_unknown_lcid_is_invalidarg() {
    let s = opc_server();
    let name = wide("g");
    let mut o = AddOut::poisoned();
    // SAFETY: valid pointers.
    let hr = unsafe {
        add_group_raw(
            &s,
            pcwstr(&name),
            1000,
            null(),
            BAD_LCID,
            &mut o.handle,
            &mut o.revised,
            &IUnknown::IID,
            o.unk.as_out(),
        )
    };
    assert_eq!(hr, E_INVALIDARG);
    o.assert_cleared("unknown LCID");
    // A locale Windows knows is accepted (German), as are Polish and English.
    for (i, lcid) in [0x0407u32, PL, EN, 0].into_iter().enumerate() {
        let g = add_group_with(
            &s,
            &GroupArgs {
                lcid,
                ..GroupArgs::new(&format!("l{i}"))
            },
        );
        assert_eq!(g.code, S_OK, "LCID {lcid:#x}");
    }
}

#[test]
fn add_group_with_an_interface_groups_lack_is_e_nointerface_and_adds_nothing() {
    let s = opc_server();
    let name = wide("ni");
    let mut o = AddOut::poisoned();
    // SAFETY: valid pointers.
    let hr = unsafe {
        add_group_raw(
            &s,
            pcwstr(&name),
            1000,
            null(),
            EN,
            &mut o.handle,
            &mut o.revised,
            &IOPCServer::IID,
            o.unk.as_out(),
        )
    };
    assert_eq!(hr, E_NOINTERFACE);
    o.assert_cleared("E_NOINTERFACE");
    let c = client_of(&s);
    assert_eq!(
        c.status().unwrap().group_count,
        0,
        "the group was removed again"
    );
    // The name is free again.
    assert_eq!(add_group(&s, "ni").code, S_OK);
}

#[test]
fn add_group_duplicate_name_is_opc_e_duplicatename() {
    let s = opc_server();
    let _g = add_group(&s, "dup");
    let name = wide("dup");
    let mut o = AddOut::poisoned();
    // SAFETY: valid pointers.
    let hr = unsafe {
        add_group_raw(
            &s,
            pcwstr(&name),
            1000,
            null(),
            EN,
            &mut o.handle,
            &mut o.revised,
            &IUnknown::IID,
            o.unk.as_out(),
        )
    };
    assert_eq!(hr, OPC_E_DUPLICATENAME);
    o.assert_cleared("duplicate name");
    // Another client may use the same name.
    assert_eq!(add_group(&opc_server(), "dup").code, S_OK);
}

#[test]
fn add_group_bad_deadband_is_invalidarg() {
    let s = opc_server();
    let name = wide("db");
    for bad in [-1.0f32, 100.5, f32::NAN] {
        let mut o = AddOut::poisoned();
        // SAFETY: valid pointers.
        let hr = unsafe {
            add_group_raw(
                &s,
                pcwstr(&name),
                1000,
                &bad,
                EN,
                &mut o.handle,
                &mut o.revised,
                &IUnknown::IID,
                o.unk.as_out(),
            )
        };
        assert_eq!(hr, E_INVALIDARG, "deadband {bad}");
        o.assert_cleared("bad deadband");
    }
}

#[test]
fn add_group_success_paths() {
    let s = opc_server();
    // Defaults (NULL bias and deadband), the requested rate.
    let g = add_group(&s, "a");
    assert_eq!((g.code, g.revised_rate), (S_OK, 1000));
    assert_ne!(g.server_handle, 0);
    assert!(g.unknown.cast::<IOPCGroupStateMgt>().is_ok());
    // A rate below MinUpdateRate is raised, with OPC_S_UNSUPPORTEDRATE.
    let g2 = add_group_with(
        &s,
        &GroupArgs {
            rate_ms: 10,
            time_bias: Some(-60),
            deadband: Some(12.5),
            ..GroupArgs::new("b")
        },
    );
    assert_eq!((g2.code, g2.revised_rate), (OPC_S_UNSUPPORTEDRATE, 1000));
    assert_ne!(g2.server_handle, g.server_handle);
    // A specific interface.
    let name = wide("c");
    let mut o = AddOut::poisoned();
    // SAFETY: valid pointers.
    let hr = unsafe {
        add_group_raw(
            &s,
            pcwstr(&name),
            2000,
            null(),
            EN,
            &mut o.handle,
            &mut o.revised,
            &IOPCGroupStateMgt::IID,
            o.unk.as_out(),
        )
    };
    assert_eq!(hr, S_OK);
    assert_eq!(o.revised, 2000);
    let unk = o.unk.take().expect("a group object");
    assert!(unk.cast::<IOPCGroupStateMgt>().is_ok());
    assert_eq!(client_of(&s).status().unwrap().group_count, 3);
}

#[test]
fn add_group_with_an_empty_name_gets_a_unique_name() {
    // OPC DA 3.0 AddGroup: "If no name is provided (szName is a pointer to a NUL string)
    // the server will generate a unique name."
    let s = opc_server();
    let a = add_group(&s, "");
    let b = add_group(&s, "");
    let c = client_of(&s);
    let (_, names) = c.group_names(OPC_ENUM_ALL).unwrap();
    assert_eq!(names.len(), 2, "{names:?}");
    assert!(names.iter().all(|n| !n.is_empty()), "{names:?}");
    assert_ne!(names[0], names[1]);
    assert_ne!(a.server_handle, b.server_handle);
}

// ---- IOPCServer::GetErrorString --------------------------------------------------------

#[test]
fn server_get_error_string_null_out_is_invalidarg() {
    let s = opc_server();
    assert_eq!(
        // SAFETY: a NULL out-parameter is what is tested.
        hr(unsafe { s.GetErrorString(E_FAIL, EN, null_mut()) }),
        E_INVALIDARG
    );
}

#[test]
fn server_get_error_string_unknown_lcid_is_invalidarg_and_clears_the_out() {
    let s = opc_server();
    let mut p = PWSTR(poison());
    assert_eq!(
        // SAFETY: a valid out-pointer.
        hr(unsafe { s.GetErrorString(E_FAIL, BAD_LCID, &mut p) }),
        E_INVALIDARG
    );
    assert!(p.is_null(), "out-parameter not cleared");
}

#[test]
fn server_get_error_string_unknown_lcid_is_invalidarg() {
    let s = opc_server();
    let mut p = PWSTR::null();
    assert_eq!(
        // SAFETY: a valid out-pointer.
        hr(unsafe { s.GetErrorString(E_FAIL, BAD_LCID, &mut p) }),
        E_INVALIDARG
    );
    assert!(p.is_null());
}

#[test]
fn server_get_error_string_code_without_text_clears_the_out() {
    let s = opc_server();
    let mut p = PWSTR(poison());
    assert_eq!(
        // SAFETY: a valid out-pointer.
        hr(unsafe { s.GetErrorString(NO_TEXT, EN, &mut p) }),
        E_INVALIDARG
    );
    assert!(p.is_null(), "out-parameter not cleared");
}

#[test]
fn server_get_error_string_texts() {
    let s = opc_server();
    let text = |code: HRESULT, lcid: u32| {
        let mut p = PWSTR::null();
        // SAFETY: a valid out-pointer; the string is ours afterwards.
        let r = hr(unsafe { s.GetErrorString(code, lcid, &mut p) });
        // SAFETY: NULL or a CoTaskMem string handed out by the call.
        (r, unsafe { take_wstr(p) })
    };
    let (r, en) = text(OPC_E_INVALIDHANDLE, EN);
    assert_eq!(r, S_OK);
    let en = en.expect("a text");
    let (r, pl) = text(OPC_E_INVALIDHANDLE, PL);
    assert_eq!(r, S_OK);
    let pl = pl.expect("a text");
    assert!(!en.is_empty() && !pl.is_empty());
    assert_ne!(en, pl, "Polish and English texts differ");
    // A system code has the system's text.
    let (r, sys) = text(E_INVALIDARG, EN);
    assert_eq!(r, S_OK);
    assert!(!sys.expect("a text").is_empty());
    // A code without any text.
    assert_eq!(text(NO_TEXT, EN), (E_INVALIDARG, None));
}

// ---- GetGroupByName --------------------------------------------------------------------

#[test]
fn get_group_by_name_argument_branches() {
    let (s, g) = server_with_group("byname");
    let name = wide("byname");
    let nope = wide("nope");
    let cases: [(&str, PCWSTR, *const GUID, bool, HRESULT); 5] = [
        (
            "NULL name",
            PCWSTR::null(),
            &IUnknown::IID,
            false,
            E_INVALIDARG,
        ),
        ("NULL riid", pcwstr(&name), null(), false, E_INVALIDARG),
        (
            "NULL out",
            pcwstr(&name),
            &IUnknown::IID,
            true,
            E_INVALIDARG,
        ),
        (
            "unknown name",
            pcwstr(&nope),
            &IUnknown::IID,
            false,
            E_INVALIDARG,
        ),
        (
            "riid a group lacks",
            pcwstr(&name),
            &IOPCServer::IID,
            false,
            E_NOINTERFACE,
        ),
    ];
    for (what, n, riid, null_out, expected) in cases {
        let mut out = OutUnk::poisoned();
        let p = if null_out { null_mut() } else { out.as_out() };
        assert_eq!(
            // SAFETY: every pointer is NULL or valid for the call.
            hr(unsafe { s.GetGroupByName(n, riid, p) }),
            expected,
            "{what}"
        );
        if !null_out {
            assert!(out.is_null(), "{what}: out-parameter not cleared");
        }
    }
    // Success: the same COM identity as AddGroup's object.
    let mut out = OutUnk::poisoned();
    assert_eq!(
        // SAFETY: valid pointers.
        hr(unsafe { s.GetGroupByName(pcwstr(&name), &IOPCItemMgt::IID, out.as_out()) }),
        S_OK
    );
    let found = out.take().expect("the group");
    assert_eq!(identity(&found), identity(&g.unknown));
    // Another client does not see it.
    let other = opc_server();
    let mut out = OutUnk::poisoned();
    assert_eq!(
        // SAFETY: valid pointers.
        hr(unsafe { other.GetGroupByName(pcwstr(&name), &IUnknown::IID, out.as_out()) }),
        E_INVALIDARG
    );
    assert!(out.is_null());
}

// ---- GetStatus -------------------------------------------------------------------------

#[test]
fn get_status_null_out_is_invalidarg() {
    let s = opc_server();
    // SAFETY: a NULL out-parameter is what is tested.
    assert_eq!(hr(unsafe { s.GetStatus(null_mut()) }), E_INVALIDARG);
}

#[test]
fn get_status_success() {
    let s = opc_server();
    let _g = add_group(&s, "st");
    let mut p: *mut OPCSERVERSTATUS = poison();
    // SAFETY: a valid out-pointer.
    assert_eq!(hr(unsafe { s.GetStatus(&mut p) }), S_OK);
    assert!(!p.is_null() && p as usize != POISON);
    // SAFETY: one OPCSERVERSTATUS block handed out by the call, ours to free.
    let st = unsafe { take_array(p, 1) }[0];
    // SAFETY: the vendor string is a CoTaskMem string owned by us.
    let vendor = unsafe { take_wstr(st.szVendorInfo) };
    assert_eq!(vendor.as_deref(), Some(ctopc_com::server::VENDOR_INFO));
    assert_eq!(st.dwServerState, OPC_STATUS_TEST, "the simulated demo");
    assert_eq!(st.dwGroupCount, 1);
    assert_eq!(st.dwBandWidth, u32::MAX);
    let ft = |f: windows::Win32::Foundation::FILETIME| {
        (u64::from(f.dwHighDateTime) << 32) | u64::from(f.dwLowDateTime)
    };
    assert!(ft(st.ftStartTime) > 0);
    assert!(ft(st.ftCurrentTime) >= ft(st.ftStartTime));
    assert_eq!(
        ft(st.ftLastUpdateTime),
        ft(st.ftStartTime),
        "no callback yet"
    );
    let v: Vec<u16> = env!("CARGO_PKG_VERSION")
        .split('.')
        .map(|x| x.parse().unwrap())
        .collect();
    assert_eq!(
        (st.wMajorVersion, st.wMinorVersion, st.wBuildNumber),
        (v[0], v[1], v[2])
    );
}

// ---- RemoveGroup -----------------------------------------------------------------------

#[test]
fn remove_group_unknown_handles_are_invalidarg() {
    let (s, g) = server_with_group("rm");
    let (_other_server, other) = server_with_group("rm");
    for (what, h) in [
        ("0", 0u32),
        ("never issued", 0x7FFF_FFF0),
        ("another client's group", other.server_handle),
    ] {
        for force in [false, true] {
            // SAFETY: plain values.
            let r = unsafe { s.RemoveGroup(h, force.into()) };
            assert_eq!(r, E_INVALIDARG, "{what}, force {force}");
        }
    }
    // The group and the other client's are still there.
    assert_eq!(client_of(&s).status().unwrap().group_count, 1);
    drop(g);
}

#[test]
fn remove_group_in_use_and_forced() {
    let s = opc_server();
    let g = add_group(&s, "inuse");
    // Referenced: marked deleted, OPC_S_INUSE; the name is gone at once.
    assert_eq!(
        // SAFETY: plain values.
        unsafe { s.RemoveGroup(g.server_handle, false.into()) },
        OPC_S_INUSE
    );
    let name = wide("inuse");
    let mut out = OutUnk::poisoned();
    assert_eq!(
        // SAFETY: valid pointers.
        hr(unsafe { s.GetGroupByName(pcwstr(&name), &IUnknown::IID, out.as_out()) }),
        E_INVALIDARG
    );
    assert!(out.is_null());
    // Removed again: no longer a group of this client.
    assert_eq!(
        // SAFETY: plain values.
        unsafe { s.RemoveGroup(g.server_handle, true.into()) },
        E_INVALIDARG
    );
    // Forced removal of a referenced group, and of an unreferenced one.
    let g2 = add_group(&s, "forced");
    assert_eq!(
        // SAFETY: plain values.
        unsafe { s.RemoveGroup(g2.server_handle, true.into()) },
        S_OK
    );
    let h3 = {
        let g3 = add_group(&s, "free");
        g3.server_handle
    };
    // SAFETY: plain values.
    assert_eq!(unsafe { s.RemoveGroup(h3, false.into()) }, S_OK);
    // SAFETY: plain values.
    assert_eq!(unsafe { s.RemoveGroup(h3, false.into()) }, E_INVALIDARG);
}

// ---- CreateGroupEnumerator ---------------------------------------------------------------

#[test]
fn create_group_enumerator_argument_branches() {
    let (s, _g) = server_with_group("en");
    let cases: [(&str, OPCENUMSCOPE, *const GUID, bool, HRESULT); 6] = [
        ("NULL riid", OPC_ENUM_ALL, null(), false, E_INVALIDARG),
        (
            "NULL out",
            OPC_ENUM_ALL,
            &IEnumString::IID,
            true,
            E_INVALIDARG,
        ),
        (
            "scope 0",
            OPCENUMSCOPE(0),
            &IEnumString::IID,
            false,
            E_INVALIDARG,
        ),
        (
            "scope 7",
            OPCENUMSCOPE(7),
            &IEnumString::IID,
            false,
            E_INVALIDARG,
        ),
        (
            "scope -1",
            OPCENUMSCOPE(-1),
            &IEnumString::IID,
            false,
            E_INVALIDARG,
        ),
        (
            "riid IOPCServer",
            OPC_ENUM_ALL,
            &IOPCServer::IID,
            false,
            E_NOINTERFACE,
        ),
    ];
    for (what, scope, riid, null_out, expected) in cases {
        let mut out = OutUnk::poisoned();
        let p = if null_out { null_mut() } else { out.as_out() };
        // SAFETY: every pointer is NULL or valid for the call.
        let r = unsafe { s.CreateGroupEnumerator(scope, riid, p) };
        assert_eq!(r, expected, "{what}");
        if !null_out {
            assert!(out.is_null(), "{what}: out-parameter not cleared");
        }
    }
}

#[test]
fn create_group_enumerator_success() {
    let s = opc_server();
    let enumerate = |scope: OPCENUMSCOPE, riid: &GUID| {
        let mut out = OutUnk::poisoned();
        // SAFETY: valid pointers.
        let r = unsafe { s.CreateGroupEnumerator(scope, riid, out.as_out()) };
        (r, out.take().expect("an enumerator, also when empty"))
    };
    // No groups: S_FALSE with an empty enumerator.
    let (r, e) = enumerate(OPC_ENUM_ALL, &IEnumString::IID);
    assert_eq!(r, S_FALSE);
    assert!(enum_strings(&e.cast().unwrap()).unwrap().is_empty());
    let a = add_group(&s, "A");
    let b = add_group(&s, "B");
    for scope in [
        OPC_ENUM_PRIVATE_CONNECTIONS,
        OPC_ENUM_ALL_CONNECTIONS,
        OPC_ENUM_PRIVATE,
        OPC_ENUM_ALL,
    ] {
        let (r, e) = enumerate(scope, &IEnumString::IID);
        assert_eq!(r, S_OK, "{scope:?}");
        let mut names = enum_strings(&e.cast().unwrap()).unwrap();
        names.sort();
        assert_eq!(names, ["A", "B"], "{scope:?}");
    }
    // No public groups: the public scopes are empty.
    for scope in [OPC_ENUM_PUBLIC_CONNECTIONS, OPC_ENUM_PUBLIC] {
        let (r, e) = enumerate(scope, &IEnumString::IID);
        assert_eq!(r, S_FALSE, "{scope:?}");
        assert!(enum_strings(&e.cast().unwrap()).unwrap().is_empty());
    }
    // IEnumUnknown: the group objects themselves.
    let (r, e) = enumerate(OPC_ENUM_ALL, &IEnumUnknown::IID);
    assert_eq!(r, S_OK);
    let objects = opc_client::enum_unknowns(&e.cast().unwrap()).unwrap();
    let mut ids: Vec<_> = objects.iter().map(identity).collect();
    ids.sort();
    let mut expected = vec![identity(&a.unknown), identity(&b.unknown)];
    expected.sort();
    assert_eq!(ids, expected);
}

// ---- IOPCCommon --------------------------------------------------------------------------

#[test]
fn set_locale_id_accepts_only_languages_the_server_speaks() {
    let c = server::<IOPCCommon>();
    // SAFETY: plain values.
    unsafe {
        assert_eq!(hr(c.SetLocaleID(BAD_LCID)), E_INVALIDARG);
        // German is a locale Windows knows, but not a language of the server.
        assert_eq!(hr(c.SetLocaleID(0x0407)), E_INVALIDARG);
        assert_eq!(hr(c.SetLocaleID(PL)), S_OK);
    }
    let mut lcid = U32_POISON;
    // SAFETY: a valid out-pointer.
    assert_eq!(hr(unsafe { c.GetLocaleID(&mut lcid) }), S_OK);
    assert_eq!(lcid, PL);
    // SAFETY: plain values.
    unsafe {
        assert_eq!(hr(c.SetLocaleID(0x0809)), S_OK, "any English");
        assert_eq!(hr(c.SetLocaleID(BAD_LCID)), E_INVALIDARG);
    }
    // SAFETY: a valid out-pointer.
    assert_eq!(hr(unsafe { c.GetLocaleID(&mut lcid) }), S_OK);
    assert_eq!(lcid, 0x0809, "a rejected SetLocaleID changes nothing");
}

#[test]
fn get_locale_id_null_out_is_invalidarg() {
    let c = server::<IOPCCommon>();
    // SAFETY: a NULL out-parameter is what is tested.
    assert_eq!(hr(unsafe { c.GetLocaleID(null_mut()) }), E_INVALIDARG);
}

#[test]
fn query_available_locale_ids_null_pointers_are_invalidarg() {
    let c = server::<IOPCCommon>();
    let mut n = U32_POISON;
    let mut p: *mut u32 = null_mut();
    // SAFETY: NULL out-parameters are what is tested; the others valid.
    unsafe {
        assert_eq!(
            hr(c.QueryAvailableLocaleIDs(null_mut(), &mut p)),
            E_INVALIDARG
        );
        assert_eq!(
            hr(c.QueryAvailableLocaleIDs(&mut n, null_mut())),
            E_INVALIDARG
        );
        assert_eq!(
            hr(c.QueryAvailableLocaleIDs(null_mut(), null_mut())),
            E_INVALIDARG
        );
    }
    assert!(p.is_null());
}

#[test]
fn query_available_locale_ids_clears_the_other_out_on_failure() {
    let c = server::<IOPCCommon>();
    let mut n = U32_POISON;
    let mut p: *mut u32 = poison();
    // SAFETY: NULL out-parameters are what is tested; the others valid.
    unsafe {
        assert_eq!(
            hr(c.QueryAvailableLocaleIDs(null_mut(), &mut p)),
            E_INVALIDARG
        );
        assert_eq!(
            hr(c.QueryAvailableLocaleIDs(&mut n, null_mut())),
            E_INVALIDARG
        );
    }
    assert_eq!((n, p.is_null()), (0, true));
}

#[test]
fn query_available_locale_ids_success() {
    let c = server::<IOPCCommon>();
    let mut n = U32_POISON;
    let mut p: *mut u32 = poison();
    assert_eq!(
        // SAFETY: valid out-pointers.
        hr(unsafe { c.QueryAvailableLocaleIDs(&mut n, &mut p) }),
        S_OK
    );
    // SAFETY: a CoTaskMem array of `n` LCIDs, ours.
    let ids = unsafe { take_array(p, n as usize) };
    assert_eq!(ids, ctopc_core::Lang::available_lcids());
    assert!(ids.contains(&PL) && ids.contains(&EN), "{ids:x?}");
    // Each is accepted by SetLocaleID.
    for id in ids {
        // SAFETY: plain value.
        assert_eq!(hr(unsafe { c.SetLocaleID(id) }), S_OK, "{id:#x}");
    }
}

#[test]
fn common_get_error_string_branches() {
    let c = server::<IOPCCommon>();
    assert_eq!(
        // SAFETY: a NULL out-parameter is what is tested.
        hr(unsafe { c.GetErrorString(E_FAIL, null_mut()) }),
        E_INVALIDARG
    );
    let text = |code: HRESULT| {
        let mut p = PWSTR::null();
        // SAFETY: a valid out-pointer.
        let r = hr(unsafe { c.GetErrorString(code, &mut p) });
        // SAFETY: NULL or a CoTaskMem string handed out by the call.
        (r, unsafe { take_wstr(p) })
    };
    assert_eq!(text(NO_TEXT), (E_INVALIDARG, None));
    // The session's locale chooses the language.
    // SAFETY: plain value.
    assert_eq!(hr(unsafe { c.SetLocaleID(PL) }), S_OK);
    let (r, pl) = text(OPC_E_UNKNOWNITEMID);
    assert_eq!(r, S_OK);
    // SAFETY: plain value.
    assert_eq!(hr(unsafe { c.SetLocaleID(EN) }), S_OK);
    let (r, en) = text(OPC_E_UNKNOWNITEMID);
    assert_eq!(r, S_OK);
    assert!(pl.is_some() && en.is_some());
    assert_ne!(pl, en);
    // The same text as IOPCServer::GetErrorString in that locale.
    let s: IOPCServer = c.cast().unwrap();
    let mut p = PWSTR::null();
    assert_eq!(
        // SAFETY: a valid out-pointer.
        hr(unsafe { s.GetErrorString(OPC_E_UNKNOWNITEMID, EN, &mut p) }),
        S_OK
    );
    // SAFETY: a CoTaskMem string handed out by the call.
    assert_eq!(unsafe { take_wstr(p) }, en);
}

#[test]
fn common_get_error_string_code_without_text_clears_the_out() {
    let c = server::<IOPCCommon>();
    let mut p = PWSTR(poison());
    assert_eq!(
        // SAFETY: a valid out-pointer.
        hr(unsafe { c.GetErrorString(NO_TEXT, &mut p) }),
        E_INVALIDARG
    );
    assert!(p.is_null(), "out-parameter not cleared");
}

#[test]
fn set_client_name_branches() {
    let c = server::<IOPCCommon>();
    // SAFETY: a NULL [in, string] is what is tested.
    assert_eq!(hr(unsafe { c.SetClientName(PCWSTR::null()) }), E_INVALIDARG);
    // Not valid UTF-16 (an unpaired surrogate).
    let bad: [u16; 3] = [0x0041, 0xD800, 0];
    assert_eq!(
        // SAFETY: a NUL-terminated UTF-16 buffer alive for the call.
        hr(unsafe { c.SetClientName(PCWSTR(bad.as_ptr())) }),
        E_INVALIDARG
    );
    let name = wide("Klient łódzki");
    // SAFETY: a valid string.
    assert_eq!(hr(unsafe { c.SetClientName(pcwstr(&name)) }), S_OK);
    let empty = wide("");
    // SAFETY: a valid string.
    assert_eq!(hr(unsafe { c.SetClientName(pcwstr(&empty)) }), S_OK);
}

#[test]
fn add_group_name_that_is_not_utf16_is_invalidarg() {
    let s = opc_server();
    let mut o = AddOut::poisoned();
    // SAFETY: valid pointers; the name is a NUL-terminated (invalid) UTF-16 string.
    let r = unsafe {
        add_group_raw(
            &s,
            bad_utf16(),
            1000,
            null(),
            EN,
            &mut o.handle,
            &mut o.revised,
            &IUnknown::IID,
            o.unk.as_out(),
        )
    };
    assert_eq!(r, E_INVALIDARG);
    o.assert_cleared("invalid UTF-16 name");
    let mut out = OutUnk::poisoned();
    assert_eq!(
        // SAFETY: valid pointers.
        hr(unsafe { s.GetGroupByName(bad_utf16(), &IUnknown::IID, out.as_out()) }),
        E_INVALIDARG
    );
    assert!(out.is_null());
}
