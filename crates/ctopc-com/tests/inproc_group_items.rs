//! IOPCItemMgt of the group object and the IEnumOPCItemAttributes it returns, in process
//! (no proxy): every argument branch with its exact HRESULT, out-parameters cleared on
//! failure, per-item codes (S_FALSE), and each method's success path with the
//! out-parameters read and freed. Harness: `common/mod.rs`; group helpers:
//! `inproc_group_support/mod.rs`.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
mod inproc_group_support;

use common::*;
use ctopc_com::interfaces::*;
use inproc_group_support::*;
use windows::Win32::System::Variant::{VariantClear, VARENUM};

const VT_EMPTY: u16 = 0;
const VT_R4: u16 = 4;
const VT_R8: u16 = 5;
const VT_DISPATCH: u16 = 9;
const VT_BSTR: u16 = 8;

/// One element of IEnumOPCItemAttributes::Next, copied (strings and VARIANT freed).
#[derive(Debug, Clone, PartialEq)]
struct Attr {
    access_path: Option<String>,
    item_id: Option<String>,
    active: bool,
    client: u32,
    server: u32,
    rights: u32,
    requested: u16,
    canonical: u16,
    eu_type: OPCEUTYPE,
    eu: ctopc_core::Value,
}

/// Copies and frees an OPCITEMATTRIBUTES array.
///
/// # Safety
/// `p` is NULL or a CoTaskMem array of `n` elements owned by the caller.
unsafe fn take_attrs(p: *mut OPCITEMATTRIBUTES, n: usize) -> Vec<Attr> {
    if p.is_null() {
        return Vec::new();
    }
    // SAFETY: contract of this function.
    let items = unsafe { std::slice::from_raw_parts_mut(p, n) };
    let out = items
        .iter_mut()
        .map(|a| {
            assert!(a.pBlob.is_null() && a.dwBlobSize == 0);
            let eu = ctopc_com::variant::from_variant(&a.vEUInfo).expect("vEUInfo");
            // SAFETY: the element's VARIANT and strings are the caller's.
            assert!(unsafe { VariantClear(&mut a.vEUInfo) }.is_ok());
            Attr {
                // SAFETY: NULL or CoTaskMem strings owned by the caller.
                access_path: unsafe { take_wstr(a.szAccessPath) },
                // SAFETY: as above.
                item_id: unsafe { take_wstr(a.szItemID) },
                active: a.bActive.as_bool(),
                client: a.hClient,
                server: a.hServer,
                rights: a.dwAccessRights,
                requested: a.vtRequestedDataType.0,
                canonical: a.vtCanonicalDataType.0,
                eu_type: a.dwEUType,
                eu,
            }
        })
        .collect();
    // SAFETY: the block is the caller's; what its elements owned is freed above.
    unsafe { task_free(p) };
    out
}

/// CreateEnumerator(IID_IEnumOPCItemAttributes): (HRESULT, enumerator).
fn enumerator(g: &Group) -> (HRESULT, IEnumOPCItemAttributes) {
    let mut out = OutUnk::poisoned();
    // SAFETY: valid IID and out-pointer.
    let hr = unsafe {
        g.item_mgt
            .CreateEnumerator(&IEnumOPCItemAttributes::IID, out.as_out())
    };
    let e = out
        .take()
        .expect("an enumerator")
        .cast::<IEnumOPCItemAttributes>()
        .expect("IEnumOPCItemAttributes");
    (hr, e)
}

/// Next(celt) with a fetched count: (HRESULT, elements).
fn next(e: &IEnumOPCItemAttributes, celt: u32) -> (HRESULT, Vec<Attr>) {
    let mut items = poison::<OPCITEMATTRIBUTES>();
    let mut fetched = POISON_U32;
    // SAFETY: valid out-pointers.
    let hr = unsafe { e.Next(celt, &mut items, &mut fetched) };
    assert!(hr == S_OK || hr == S_FALSE, "Next: {hr:?}");
    assert!(fetched <= celt);
    if fetched == 0 {
        assert!(items.is_null(), "Next of nothing hands out no array");
    }
    // SAFETY: `fetched` elements handed out.
    (hr, unsafe { take_attrs(items, fetched as usize) })
}

/// Every item attribute of the group.
fn attributes(g: &Group) -> Vec<Attr> {
    let (_, e) = enumerator(g);
    next(&e, 1000).1
}

fn raw_add(
    g: &Group,
    n: u32,
    defs: *const OPCITEMDEF,
    results: *mut *mut OPCITEMRESULT,
    errors: *mut *mut HRESULT,
) -> HRESULT {
    // SAFETY: the pointers are NULL or valid for the call.
    unsafe { g.item_mgt.AddItems(n, defs, results, errors) }
}

fn raw_validate(
    g: &Group,
    n: u32,
    defs: *const OPCITEMDEF,
    results: *mut *mut OPCITEMRESULT,
    errors: *mut *mut HRESULT,
) -> HRESULT {
    // SAFETY: the pointers are NULL or valid for the call.
    unsafe {
        g.item_mgt
            .ValidateItems(n, defs, false.into(), results, errors)
    }
}

// ---- AddItems / ValidateItems -----------------------------------------------------------

#[test]
fn add_items_returns_handles_canonical_types_and_rights() {
    let (_s, g) = server_with_group("items-add");
    let d = defs(&[LEVEL, SETPOINT, TEXT]);
    let (hr, out) = add_items(&g, &d);
    assert_eq!(hr, S_OK);
    assert_eq!(out.len(), 3);
    assert!(out.iter().all(|(r, e)| *e == S_OK && r.hServer != 0));
    let handles: Vec<u32> = out.iter().map(|(r, _)| r.hServer).collect();
    assert!(handles[0] != handles[1] && handles[1] != handles[2]);
    assert_eq!(out[0].0.vtCanonicalDataType.0, VT_R4);
    assert_eq!(out[0].0.dwAccessRights, OPC_READABLE);
    assert_eq!(out[1].0.dwAccessRights, OPC_READABLE | OPC_WRITEABLE);
    assert_eq!(out[2].0.vtCanonicalDataType.0, VT_BSTR);
    let attrs = attributes(&g);
    assert_eq!(attrs.iter().map(|a| a.server).collect::<Vec<_>>(), handles);
}

#[test]
fn add_items_reports_each_failure_per_item_with_s_false() {
    let (_s, g) = server_with_group("items-add-fail");
    let mut d = defs_of(&[
        def(LEVEL, 1),
        def("KW_A999", 2),
        def("KW_A000..CV", 3),
        Def {
            path: "NoSuchChannel",
            ..def(LEVEL, 4)
        },
        Def {
            vt: VT_DISPATCH,
            ..def(LEVEL, 5)
        },
        def("", 6),
        def(LEVEL, 7),
        def(LEVEL, 8),
        def(SETPOINT, 9),
    ]);
    // A NULL item ID (an embedded [unique] pointer): OPC_E_INVALIDITEMID.
    d.defs[6].szItemID = PWSTR::null();
    // Invalid UTF-16 (a lone surrogate) in the item ID and in the access path.
    let bad_id: [u16; 3] = [0x4B, 0xD800, 0];
    let bad_path: [u16; 2] = [0xDC00, 0];
    d.defs[7].szItemID = PWSTR(bad_id.as_ptr() as *mut u16);
    d.defs[8].szAccessPath = PWSTR(bad_path.as_ptr() as *mut u16);
    let (hr, out) = add_items(&g, &d);
    assert_eq!(hr, S_FALSE);
    let errors: Vec<HRESULT> = out.iter().map(|(_, e)| *e).collect();
    assert_eq!(
        errors,
        vec![
            S_OK,
            OPC_E_UNKNOWNITEMID,
            OPC_E_INVALIDITEMID,
            OPC_E_UNKNOWNPATH,
            OPC_E_BADTYPE,
            OPC_E_INVALIDITEMID,
            OPC_E_INVALIDITEMID,
            OPC_E_INVALIDITEMID,
            OPC_E_UNKNOWNPATH,
        ]
    );
    assert_ne!(out[0].0.hServer, 0);
    for (r, _) in &out[1..] {
        assert_eq!(
            *r,
            OPCITEMRESULT::default(),
            "a failed item's result is zero"
        );
    }
    assert_eq!(attributes(&g).len(), 1, "only the good item was added");
    // Every item failing is S_FALSE too, not a call failure.
    let (hr, out) = add_items(&g, &defs(&["KW_A999", "asmen"]));
    assert_eq!(hr, S_FALSE);
    assert!(out.iter().all(|(r, e)| e.is_err() && r.hServer == 0));
}

/// The argument branches AddItems and ValidateItems share.
fn check_item_def_args(
    what: &str,
    call: impl Fn(u32, *const OPCITEMDEF, *mut *mut OPCITEMRESULT, *mut *mut HRESULT) -> HRESULT,
) {
    let d = defs(&[LEVEL]);
    let (mut results, mut errors) = (poison::<OPCITEMRESULT>(), poison::<HRESULT>());
    // NULL ppErrors: E_INVALIDARG, the result array cleared.
    assert_eq!(
        call(1, d.defs.as_ptr(), &mut results, std::ptr::null_mut()),
        E_INVALIDARG,
        "{what}: NULL ppErrors"
    );
    assert!(results.is_null(), "{what}: NULL ppErrors left the results");
    // NULL results: E_INVALIDARG.
    let mut errors2: *mut HRESULT = std::ptr::null_mut();
    assert_eq!(
        call(1, d.defs.as_ptr(), std::ptr::null_mut(), &mut errors2),
        E_INVALIDARG,
        "{what}: NULL results"
    );
    assert!(errors2.is_null());
    // Count 0: E_INVALIDARG, both cleared.
    results = poison();
    assert_eq!(
        call(0, d.defs.as_ptr(), &mut results, &mut errors),
        E_INVALIDARG,
        "{what}: count 0"
    );
    assert!(results.is_null() && errors.is_null(), "{what}: count 0");
    // NULL item array: E_INVALIDARG, both cleared.
    let (mut results, mut errors) = (poison::<OPCITEMRESULT>(), poison::<HRESULT>());
    assert_eq!(
        call(1, std::ptr::null(), &mut results, &mut errors),
        E_INVALIDARG,
        "{what}: NULL pItemArray"
    );
    assert!(results.is_null() && errors.is_null(), "{what}: NULL array");
}

#[test]
fn add_items_argument_branches() {
    let (_s, g) = server_with_group("items-add-args");
    check_item_def_args("AddItems", |n, d, r, e| raw_add(&g, n, d, r, e));
    assert!(attributes(&g).is_empty(), "no failed call added an item");
}

#[test]
fn validate_items_argument_branches() {
    let (_s, g) = server_with_group("items-validate-args");
    check_item_def_args("ValidateItems", |n, d, r, e| raw_validate(&g, n, d, r, e));
}

#[test]
fn validate_items_checks_without_adding() {
    let (_s, g) = server_with_group("items-validate");
    let d = defs_of(&[
        def(LEVEL, 1),
        def(SETPOINT, 2),
        def("KW_A999", 3),
        Def {
            vt: VT_DISPATCH,
            ..def(LEVEL, 4)
        },
    ]);
    let (mut results, mut errors) = (poison::<OPCITEMRESULT>(), poison::<HRESULT>());
    let hr = raw_validate(&g, 4, d.defs.as_ptr(), &mut results, &mut errors);
    let (hr, out) = take_results(hr, results, errors, 4);
    assert_eq!(hr, S_FALSE);
    assert_eq!(
        out.iter().map(|(_, e)| *e).collect::<Vec<_>>(),
        vec![S_OK, S_OK, OPC_E_UNKNOWNITEMID, OPC_E_BADTYPE]
    );
    assert_eq!(out[0].0.vtCanonicalDataType.0, VT_R4);
    assert_eq!(out[0].0.dwAccessRights, OPC_READABLE);
    assert_eq!(out[1].0.dwAccessRights, OPC_READABLE | OPC_WRITEABLE);
    let (hr, e) = enumerator(&g);
    assert_eq!(hr, S_FALSE, "nothing was added");
    assert!(next(&e, 10).1.is_empty());
    // All valid: S_OK. bBlobUpdate TRUE changes nothing: this server has no blobs.
    let d = defs(&[LEVEL]);
    for blob in [false, true] {
        let (mut results, mut errors) = (poison::<OPCITEMRESULT>(), poison::<HRESULT>());
        // SAFETY: valid pointers.
        let hr = unsafe {
            g.item_mgt
                .ValidateItems(1, d.defs.as_ptr(), blob.into(), &mut results, &mut errors)
        };
        let (hr, out) = take_results(hr, results, errors, 1);
        assert_eq!((hr, out[0].1), (S_OK, S_OK), "bBlobUpdate {blob}");
        assert_eq!(out[0].0.vtCanonicalDataType.0, VT_R4);
    }
}

// ---- RemoveItems / SetActiveState / SetClientHandles / SetDatatypes ---------------------

#[test]
fn remove_items_argument_branches_and_unknown_handles() {
    let (_s, g, h) = group_with("items-remove", &[LEVEL, SETPOINT, UI1_WRITABLE]);
    check_count_and_handles("RemoveItems", &h, |n, p, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { g.item_mgt.RemoveItems(n, p, e) }
    });
    assert_eq!(attributes(&g).len(), 3, "no failed call removed an item");
    let remove = |hs: &[u32]| {
        errors_of(hs.len(), |e| {
            // SAFETY: valid handles and out-pointer.
            unsafe { g.item_mgt.RemoveItems(hs.len() as u32, hs.as_ptr(), e) }
        })
    };
    assert_eq!(
        remove(&[h[0], BAD_HANDLE, h[2]]),
        (S_FALSE, vec![S_OK, OPC_E_INVALIDHANDLE, S_OK])
    );
    assert_eq!(remove(&[h[0]]), (S_FALSE, vec![OPC_E_INVALIDHANDLE]));
    assert_eq!(
        attributes(&g).iter().map(|a| a.server).collect::<Vec<_>>(),
        vec![h[1]]
    );
    assert_eq!(remove(&[h[1]]), (S_OK, vec![S_OK]));
    assert!(attributes(&g).is_empty());
}

#[test]
fn set_active_state_argument_branches_and_success() {
    let (_s, g, h) = group_with("items-active", &[LEVEL, SETPOINT]);
    check_count_and_handles("SetActiveState", &h, |n, p, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { g.item_mgt.SetActiveState(n, p, false.into(), e) }
    });
    assert!(attributes(&g).iter().all(|a| a.active), "nothing changed");
    let set = |hs: &[u32], active: bool| {
        errors_of(hs.len(), |e| {
            // SAFETY: valid handles and out-pointer.
            unsafe {
                g.item_mgt
                    .SetActiveState(hs.len() as u32, hs.as_ptr(), active.into(), e)
            }
        })
    };
    assert_eq!(
        set(&[h[0], BAD_HANDLE], false),
        (S_FALSE, vec![S_OK, OPC_E_INVALIDHANDLE])
    );
    let a = attributes(&g);
    assert!(!a[0].active && a[1].active);
    assert_eq!(set(&[h[0], h[1]], true), (S_OK, vec![S_OK, S_OK]));
    assert!(attributes(&g).iter().all(|a| a.active));
}

#[test]
fn set_client_handles_argument_branches_and_success() {
    let (_s, g, h) = group_with("items-client", &[LEVEL, SETPOINT]);
    let clients = [100u32, 200];
    check_count_and_handles("SetClientHandles", &h, |n, p, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { g.item_mgt.SetClientHandles(n, p, clients.as_ptr(), e) }
    });
    // A NULL phClient: E_INVALIDARG, the error array cleared.
    let mut errors = poison::<HRESULT>();
    // SAFETY: valid pointers but a deliberately NULL phClient.
    let hr = unsafe {
        g.item_mgt
            .SetClientHandles(2, h.as_ptr(), std::ptr::null(), &mut errors)
    };
    assert_eq!(hr, E_INVALIDARG);
    assert!(errors.is_null());
    assert_eq!(
        attributes(&g).iter().map(|a| a.client).collect::<Vec<_>>(),
        vec![1, 2],
        "nothing changed"
    );
    let set = |pairs: &[(u32, u32)]| {
        let (hs, cs): (Vec<u32>, Vec<u32>) = pairs.iter().copied().unzip();
        errors_of(hs.len(), |e| {
            // SAFETY: valid arrays of the same length and out-pointer.
            unsafe {
                g.item_mgt
                    .SetClientHandles(hs.len() as u32, hs.as_ptr(), cs.as_ptr(), e)
            }
        })
    };
    assert_eq!(set(&[(h[0], 100), (h[1], 200)]), (S_OK, vec![S_OK, S_OK]));
    assert_eq!(
        set(&[(BAD_HANDLE, 1), (h[1], 300)]),
        (S_FALSE, vec![OPC_E_INVALIDHANDLE, S_OK])
    );
    assert_eq!(
        attributes(&g).iter().map(|a| a.client).collect::<Vec<_>>(),
        vec![100, 300]
    );
}

#[test]
fn set_datatypes_argument_branches_and_success() {
    let (_s, g, h) = group_with("items-types", &[LEVEL, SETPOINT]);
    let types = [VARENUM(VT_R8), VARENUM(VT_R8)];
    check_count_and_handles("SetDatatypes", &h, |n, p, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { g.item_mgt.SetDatatypes(n, p, types.as_ptr(), e) }
    });
    let mut errors = poison::<HRESULT>();
    // SAFETY: valid pointers but a deliberately NULL pRequestedDatatypes.
    let hr = unsafe {
        g.item_mgt
            .SetDatatypes(2, h.as_ptr(), std::ptr::null(), &mut errors)
    };
    assert_eq!(hr, E_INVALIDARG);
    assert!(errors.is_null());
    assert!(attributes(&g).iter().all(|a| a.requested == VT_EMPTY));
    let set = |pairs: &[(u32, u16)]| {
        let hs: Vec<u32> = pairs.iter().map(|p| p.0).collect();
        let ts: Vec<VARENUM> = pairs.iter().map(|p| VARENUM(p.1)).collect();
        errors_of(hs.len(), |e| {
            // SAFETY: valid arrays of the same length and out-pointer.
            unsafe {
                g.item_mgt
                    .SetDatatypes(hs.len() as u32, hs.as_ptr(), ts.as_ptr(), e)
            }
        })
    };
    assert_eq!(
        set(&[(h[0], VT_BSTR), (h[1], VT_DISPATCH), (BAD_HANDLE, VT_R8)]),
        (S_FALSE, vec![S_OK, OPC_E_BADTYPE, OPC_E_INVALIDHANDLE])
    );
    let a = attributes(&g);
    assert_eq!(a[0].requested, VT_BSTR);
    assert_eq!(a[1].requested, VT_EMPTY, "a failed item changes nothing");
    assert_eq!(set(&[(h[1], VT_R8)]), (S_OK, vec![S_OK]));
    assert_eq!(attributes(&g)[1].requested, VT_R8);
}

#[test]
fn handles_of_another_group_are_invalid_here() {
    let s = opc_server();
    let a = add_group(&s, "items-a");
    let b = add_group(&s, "items-b");
    let ha = add_ok(&a, &[LEVEL]);
    let (hr, errs) = errors_of(1, |e| {
        // SAFETY: valid pointers.
        unsafe { b.item_mgt.SetActiveState(1, ha.as_ptr(), false.into(), e) }
    });
    assert_eq!((hr, errs), (S_FALSE, vec![OPC_E_INVALIDHANDLE]));
    let (hr, errs) = errors_of(1, |e| {
        // SAFETY: valid pointers.
        unsafe { b.item_mgt.RemoveItems(1, ha.as_ptr(), e) }
    });
    assert_eq!((hr, errs), (S_FALSE, vec![OPC_E_INVALIDHANDLE]));
    assert_eq!(attributes(&a).len(), 1);
    assert!(attributes(&a)[0].active, "group A's item is untouched");
}

// ---- CreateEnumerator and IEnumOPCItemAttributes ---------------------------------------

#[test]
fn create_enumerator_argument_branches() {
    let (_s, g, _h) = group_with("items-enum-args", &[LEVEL]);
    let mut out = OutUnk::poisoned();
    // SAFETY: a deliberately NULL riid; a valid out-pointer.
    let hr = unsafe { g.item_mgt.CreateEnumerator(std::ptr::null(), out.as_out()) };
    assert_eq!(hr, E_INVALIDARG);
    // SAFETY: a valid IID; a deliberately NULL out-pointer.
    let hr = unsafe {
        g.item_mgt
            .CreateEnumerator(&IEnumOPCItemAttributes::IID, std::ptr::null_mut())
    };
    assert_eq!(hr, E_INVALIDARG);
    // Any other IID: E_NOINTERFACE, and the out-parameter NULL.
    for iid in [
        IUnknown::IID,
        windows::Win32::System::Com::IEnumString::IID,
        IOPCItemMgt::IID,
    ] {
        let mut out = OutUnk::poisoned();
        // SAFETY: valid pointers.
        let hr = unsafe { g.item_mgt.CreateEnumerator(&iid, out.as_out()) };
        assert_eq!(hr, E_NOINTERFACE, "{iid:?}");
        assert!(out.is_null(), "{iid:?}: out-parameter not cleared");
    }
}

#[test]
fn create_enumerator_with_null_riid_clears_the_out_parameter() {
    let (_s, g) = server_with_group("items-enum-args-clear");
    let mut out = OutUnk::poisoned();
    // SAFETY: a deliberately NULL riid; a valid out-pointer.
    let hr = unsafe { g.item_mgt.CreateEnumerator(std::ptr::null(), out.as_out()) };
    assert_eq!(hr, E_INVALIDARG);
    assert!(out.is_null());
}

#[test]
fn enumerator_of_an_empty_group_is_s_false_and_empty() {
    let (_s, g) = server_with_group("items-enum-empty");
    let (hr, e) = enumerator(&g);
    assert_eq!(hr, S_FALSE);
    assert_eq!(next(&e, 5), (S_FALSE, vec![]));
    // SAFETY: a valid enumerator.
    assert_eq!(unsafe { e.Skip(1) }, S_FALSE);
}

#[test]
fn enumerator_lists_the_items_next_skip_reset_clone() {
    let (_s, g, h) = group_with("items-enum", &[LEVEL, SETPOINT, TEXT]);
    let (hr, e) = enumerator(&g);
    assert_eq!(hr, S_OK);
    let (hr, first) = next(&e, 2);
    assert_eq!((hr, first.len()), (S_OK, 2));
    let a = &first[0];
    assert_eq!(a.item_id.as_deref(), Some(LEVEL));
    assert_eq!(a.access_path.as_deref(), Some(""));
    assert!(a.active);
    assert_eq!((a.client, a.server), (1, h[0]));
    assert_eq!(a.rights, OPC_READABLE);
    assert_eq!((a.requested, a.canonical), (VT_EMPTY, VT_R4));
    assert_eq!(a.eu_type, OPC_ANALOG);
    match &a.eu {
        ctopc_core::Value::Array(arr) => assert_eq!(
            arr.elements,
            vec![ctopc_core::Value::R8(0.0), ctopc_core::Value::R8(8.0)]
        ),
        other => panic!("vEUInfo {other:?}"),
    }
    assert_eq!(first[1].item_id.as_deref(), Some(SETPOINT));
    assert_eq!(first[1].rights, OPC_READABLE | OPC_WRITEABLE);
    let (hr, rest) = next(&e, 2);
    assert_eq!((hr, rest.len()), (S_FALSE, 1));
    assert_eq!(rest[0].item_id.as_deref(), Some(TEXT));
    assert_eq!((rest[0].canonical, rest[0].eu_type), (VT_BSTR, OPC_NOENUM));
    assert_eq!(rest[0].eu, ctopc_core::Value::Empty);
    assert_eq!(next(&e, 1), (S_FALSE, vec![]));

    // Reset, Skip, Clone (the clone copies the position).
    // SAFETY: a valid enumerator.
    assert!(unsafe { e.Reset() }.is_ok());
    // SAFETY: as above.
    assert_eq!(unsafe { e.Skip(2) }, S_OK);
    let mut c = OutUnk::poisoned();
    // SAFETY: a valid out-pointer.
    assert!(unsafe { e.Clone(c.as_out()) }.is_ok());
    let c = c
        .take()
        .expect("a clone")
        .cast::<IEnumOPCItemAttributes>()
        .expect("IEnumOPCItemAttributes");
    let (hr, from_clone) = next(&c, 5);
    assert_eq!(hr, S_FALSE);
    assert_eq!(
        from_clone.iter().map(|a| a.server).collect::<Vec<_>>(),
        vec![h[2]]
    );
    // The original is where it was.
    assert_eq!(next(&e, 1).1.len(), 1);
    // SAFETY: as above.
    assert!(unsafe { e.Reset() }.is_ok());
    // SAFETY: as above.
    assert_eq!(unsafe { e.Skip(5) }, S_FALSE);
    // Next(0): S_OK, nothing.
    // SAFETY: as above.
    assert!(unsafe { e.Reset() }.is_ok());
    assert_eq!(next(&e, 0), (S_OK, vec![]));
    // Next(1) without pceltFetched (allowed for one element).
    let mut one = poison::<OPCITEMATTRIBUTES>();
    // SAFETY: a valid array out-pointer; pceltFetched NULL with celt 1.
    let hr = unsafe { e.Next(1, &mut one, std::ptr::null_mut()) };
    assert_eq!(hr, S_OK);
    // SAFETY: one element handed out.
    let one = unsafe { take_attrs(one, 1) };
    assert_eq!(one[0].server, h[0]);
    // The snapshot is taken at CreateEnumerator: later changes are not in it.
    // SAFETY: valid handles.
    let (hr, _) = errors_of(1, |er| unsafe { g.item_mgt.RemoveItems(1, h.as_ptr(), er) });
    assert_eq!(hr, S_OK);
    assert_eq!(next(&e, 5).1.len(), 2);
}

#[test]
fn enumerator_next_and_clone_argument_branches() {
    let (_s, g, _h) = group_with("items-enum-next", &[LEVEL, SETPOINT]);
    let (_, e) = enumerator(&g);
    let mut fetched = POISON_U32;
    // NULL array: E_POINTER (IEnum*::Next's contract).
    // SAFETY: a deliberately NULL array out-pointer.
    let hr = unsafe { e.Next(1, std::ptr::null_mut(), &mut fetched) };
    assert_eq!(hr, E_POINTER);
    // pceltFetched NULL with celt > 1: E_INVALIDARG.
    let mut items: *mut OPCITEMATTRIBUTES = std::ptr::null_mut();
    // SAFETY: a valid array out-pointer; pceltFetched deliberately NULL.
    let hr = unsafe { e.Next(2, &mut items, std::ptr::null_mut()) };
    assert_eq!(hr, E_INVALIDARG);
    assert!(items.is_null());
    // Nothing was consumed by the failed calls.
    assert_eq!(next(&e, 5).1.len(), 2);
    // Next(0) without pceltFetched: E_INVALIDARG (only one element may go without it).
    let mut items: *mut OPCITEMATTRIBUTES = std::ptr::null_mut();
    // SAFETY: a valid array out-pointer; pceltFetched deliberately NULL.
    let hr = unsafe { e.Next(0, &mut items, std::ptr::null_mut()) };
    assert_eq!(hr, E_INVALIDARG);
    assert!(items.is_null());
    // Clone(NULL): E_INVALIDARG.
    assert_eq!(
        // SAFETY: a deliberately NULL out-pointer.
        code(&unsafe { e.Clone(std::ptr::null_mut()) }),
        E_INVALIDARG
    );
}

#[test]
fn enumerator_next_failure_clears_the_array_out_parameter() {
    let (_s, g, _h) = group_with("items-enum-next-clear", &[LEVEL, SETPOINT]);
    let (_, e) = enumerator(&g);
    let mut items = poison::<OPCITEMATTRIBUTES>();
    // SAFETY: a valid array out-pointer; pceltFetched deliberately NULL.
    let hr = unsafe { e.Next(2, &mut items, std::ptr::null_mut()) };
    assert_eq!(hr, E_INVALIDARG);
    assert!(items.is_null());
}

#[test]
fn add_items_null_results_clears_the_error_array() {
    let (_s, g) = server_with_group("items-add-clear");
    let d = defs(&[LEVEL]);
    for (what, f) in [
        ("AddItems", raw_add as fn(_, _, _, _, _) -> _),
        ("ValidateItems", raw_validate),
    ] {
        let mut errors = poison::<HRESULT>();
        let hr = f(&g, 1, d.defs.as_ptr(), std::ptr::null_mut(), &mut errors);
        assert_eq!(hr, E_INVALIDARG, "{what}");
        assert!(errors.is_null(), "{what}: ppErrors not cleared");
    }
}

#[test]
fn many_items_in_one_call() {
    let (_s, g) = server_with_group("items-many");
    let ids: Vec<&str> = std::iter::repeat_n(LEVEL, 2000).collect();
    let h = add_ok(&g, &ids);
    assert_eq!(h.len(), 2000);
    let mut sorted = h.clone();
    sorted.sort_unstable();
    sorted.dedup();
    assert_eq!(sorted.len(), 2000, "distinct server handles");
    let (hr, errs) = errors_of(h.len(), |e| {
        // SAFETY: valid handles and out-pointer.
        unsafe { g.item_mgt.RemoveItems(h.len() as u32, h.as_ptr(), e) }
    });
    assert_eq!(hr, S_OK);
    assert!(errs.iter().all(|e| *e == S_OK));
}
