//! IOPCGroupStateMgt/IOPCGroupStateMgt2, IOPCItemDeadbandMgt and IOPCItemSamplingMgt of the
//! group object, in process (no proxy): every argument branch with its exact HRESULT,
//! out-parameters cleared on failure, per-item codes, and each method's success path.
//! Harness: `common/mod.rs`; group helpers: `inproc_group_support/mod.rs`.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
mod inproc_group_support;

use common::*;
use ctopc_com::interfaces::*;
use inproc_group_support::*;

/// What GetState reports.
#[derive(Debug, Clone, PartialEq)]
struct State {
    rate: u32,
    active: bool,
    name: String,
    time_bias: i32,
    deadband: f32,
    lcid: u32,
    client: u32,
    server: u32,
}

fn state_mgt(g: &Group) -> IOPCGroupStateMgt2 {
    iface(g)
}

fn get_state(sm: &IOPCGroupStateMgt) -> State {
    let (mut rate, mut active, mut name) = (0u32, BOOL(0), PWSTR::null());
    let (mut bias, mut db, mut lcid, mut client, mut server) = (0i32, 0f32, 0u32, 0u32, 0u32);
    // SAFETY: every out-pointer is valid.
    let r = unsafe {
        sm.GetState(
            &mut rate,
            &mut active,
            &mut name,
            &mut bias,
            &mut db,
            &mut lcid,
            &mut client,
            &mut server,
        )
    };
    assert_eq!(hr(r), S_OK);
    State {
        rate,
        active: active.as_bool(),
        // SAFETY: a CoTaskMem string handed out by GetState.
        name: unsafe { take_wstr(name) }.expect("a group name"),
        time_bias: bias,
        deadband: db,
        lcid,
        client,
        server,
    }
}

/// SetState with every `[in, unique]` value optional: (HRESULT, revised rate).
#[derive(Default, Clone, Copy)]
struct SetArgs {
    rate: Option<u32>,
    active: Option<bool>,
    time_bias: Option<i32>,
    deadband: Option<f32>,
    lcid: Option<u32>,
    client: Option<u32>,
}

fn opt<T>(v: &Option<T>) -> *const T {
    v.as_ref().map_or(std::ptr::null(), |v| v as *const T)
}

fn set_state(sm: &IOPCGroupStateMgt, a: SetArgs) -> (HRESULT, u32) {
    let active = a.active.map(BOOL::from);
    let mut revised = POISON_U32;
    // SAFETY: every pointer is NULL or points to a local value.
    let hr = unsafe {
        sm.SetState(
            opt(&a.rate),
            &mut revised,
            opt(&active),
            opt(&a.time_bias),
            opt(&a.deadband),
            opt(&a.lcid),
            opt(&a.client),
        )
    };
    (hr, revised)
}

// ---- GetState ---------------------------------------------------------------------------

#[test]
fn get_state_reports_what_add_group_set() {
    let s = opc_server();
    let mut args = GroupArgs::new("state-get");
    args.rate_ms = 2500;
    args.client_handle = 42;
    args.time_bias = Some(-60);
    args.deadband = Some(1.5);
    args.lcid = 0x0415;
    let g = add_group_with(&s, &args);
    let st = get_state(&iface(&g));
    assert_eq!(
        st,
        State {
            rate: 2500,
            active: true,
            name: "state-get".into(),
            time_bias: -60,
            deadband: 1.5,
            lcid: 0x0415,
            client: 42,
            server: g.server_handle,
        }
    );
}

#[test]
fn get_state_with_any_null_out_parameter_is_e_invalidarg_and_writes_nothing() {
    let (_s, g) = server_with_group("state-get-null");
    let sm: IOPCGroupStateMgt = iface(&g);
    for null in 0..8 {
        let (mut rate, mut active, mut name) = (POISON_U32, BOOL(7), poison::<u16>());
        let (mut bias, mut db, mut lcid) = (-7i32, -7f32, POISON_U32);
        let (mut client, mut server) = (POISON_U32, POISON_U32);
        fn p<T>(i: usize, null: usize, r: &mut T) -> *mut T {
            if i == null {
                std::ptr::null_mut()
            } else {
                r
            }
        }
        let mut pname = PWSTR(name);
        // SAFETY: every out-pointer is valid but the one deliberately NULL.
        let r = unsafe {
            sm.GetState(
                p(0, null, &mut rate),
                p(1, null, &mut active),
                p(2, null, &mut pname),
                p(3, null, &mut bias),
                p(4, null, &mut db),
                p(5, null, &mut lcid),
                p(6, null, &mut client),
                p(7, null, &mut server),
            )
        };
        assert_eq!(hr(r), E_INVALIDARG, "out-parameter {null} NULL");
        name = pname.0;
        assert_eq!(
            (
                rate,
                active.0,
                name as usize,
                bias,
                db,
                lcid,
                client,
                server
            ),
            (POISON_U32, 7, POISON, -7, -7.0, POISON_U32, POISON_U32, POISON_U32),
            "out-parameter {null} NULL: nothing written"
        );
    }
}

// ---- SetState ---------------------------------------------------------------------------

#[test]
fn set_state_with_null_revised_rate_is_e_invalidarg_and_changes_nothing() {
    let (_s, g) = server_with_group("state-set-null");
    let sm: IOPCGroupStateMgt = iface(&g);
    let before = get_state(&sm);
    let (rate, active) = (5000u32, BOOL(0));
    // SAFETY: valid [in] pointers; a deliberately NULL pRevisedUpdateRate.
    let hr = unsafe {
        sm.SetState(
            &rate,
            std::ptr::null_mut(),
            &active,
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(hr, E_INVALIDARG);
    assert_eq!(get_state(&sm), before);
}

#[test]
fn set_state_changes_what_it_is_given_and_revises_the_rate() {
    let (_s, g) = server_with_group("state-set");
    let sm: IOPCGroupStateMgt = iface(&g);
    // Nothing given: S_OK, the current rate.
    assert_eq!(set_state(&sm, SetArgs::default()), (S_OK, 1000));
    let before = get_state(&sm);
    assert_eq!(
        set_state(
            &sm,
            SetArgs {
                rate: Some(3000),
                active: Some(false),
                time_bias: Some(120),
                deadband: Some(12.5),
                lcid: Some(0x0409),
                client: Some(99),
            }
        ),
        (S_OK, 3000)
    );
    let st = get_state(&sm);
    assert_eq!(
        st,
        State {
            rate: 3000,
            active: false,
            time_bias: 120,
            deadband: 12.5,
            client: 99,
            ..before.clone()
        }
    );
    // Below the minimum update rate (1000 ms): raised, OPC_S_UNSUPPORTEDRATE.
    assert_eq!(
        set_state(
            &sm,
            SetArgs {
                rate: Some(10),
                ..Default::default()
            }
        ),
        (OPC_S_UNSUPPORTEDRATE, 1000)
    );
    assert_eq!(get_state(&sm).rate, 1000);
    // Deadbands 0 and 100 are valid.
    for d in [0.0f32, 100.0] {
        let (hr, _) = set_state(
            &sm,
            SetArgs {
                deadband: Some(d),
                ..Default::default()
            },
        );
        assert_eq!(hr, S_OK, "deadband {d}");
    }
}

#[test]
fn set_state_with_a_deadband_out_of_range_is_e_invalidarg_and_changes_nothing() {
    let (_s, g) = server_with_group("state-set-deadband");
    let sm: IOPCGroupStateMgt = iface(&g);
    let before = get_state(&sm);
    for d in [-0.5f32, 100.5, f32::NAN, f32::INFINITY] {
        let (hr, _) = set_state(
            &sm,
            SetArgs {
                rate: Some(4000),
                deadband: Some(d),
                ..Default::default()
            },
        );
        assert_eq!(hr, E_INVALIDARG, "deadband {d}");
        assert_eq!(get_state(&sm), before, "deadband {d}: nothing changed");
    }
}

/// SetState validates the LCID as AddGroup does (both refuse 0xDEADBEEF): E_INVALIDARG
/// and nothing changed; the LCIDs AddGroup takes are taken.
#[test]
fn set_state_validates_the_lcid_as_add_group_does() {
    let (_s, g) = server_with_group("state-set-lcid");
    let sm: IOPCGroupStateMgt = iface(&g);
    let before = get_state(&sm);
    // AddGroup's refusal of the same LCID: inproc_server.rs, add_group_unknown_lcid_is_invalidarg.
    for lcid in [0xDEAD_BEEFu32, 0x7FFF_1234] {
        let (hr, _) = set_state(
            &sm,
            SetArgs {
                rate: Some(4000),
                lcid: Some(lcid),
                ..Default::default()
            },
        );
        assert_eq!(hr, E_INVALIDARG, "lcid {lcid:#x}");
        assert_eq!(get_state(&sm), before, "lcid {lcid:#x}: nothing changed");
    }
    for lcid in [0x0415u32, 0x0409, 0x0809, 0x0407, 0x0800, 0x0400, 0x0000] {
        let (hr, _) = set_state(
            &sm,
            SetArgs {
                lcid: Some(lcid),
                ..Default::default()
            },
        );
        assert_eq!(hr, S_OK, "lcid {lcid:#x}");
        assert_eq!(get_state(&sm).lcid, lcid);
    }
}

#[test]
fn set_state_failure_clears_the_revised_rate() {
    let (_s, g) = server_with_group("state-set-clear");
    let (hr, revised) = set_state(
        &iface(&g),
        SetArgs {
            deadband: Some(101.0),
            ..Default::default()
        },
    );
    assert_eq!(hr, E_INVALIDARG);
    assert_eq!(revised, 0);
}

// ---- SetName ----------------------------------------------------------------------------

#[test]
fn set_name_argument_branches_and_success() {
    let s = opc_server();
    let g = add_group(&s, "name-a");
    let _other = add_group(&s, "name-b");
    let sm: IOPCGroupStateMgt = iface(&g);
    // SAFETY: a deliberately NULL name.
    assert_eq!(hr(unsafe { sm.SetName(PCWSTR::null()) }), E_INVALIDARG);
    let empty = wide("");
    // SAFETY: a valid string.
    assert_eq!(hr(unsafe { sm.SetName(pcwstr(&empty)) }), E_INVALIDARG);
    let bad: [u16; 2] = [0xD800, 0];
    assert_eq!(
        // SAFETY: a NUL-terminated (invalid UTF-16) string.
        hr(unsafe { sm.SetName(PCWSTR(bad.as_ptr())) }),
        E_INVALIDARG
    );
    let taken = wide("name-b");
    assert_eq!(
        // SAFETY: a valid string.
        hr(unsafe { sm.SetName(pcwstr(&taken)) }),
        OPC_E_DUPLICATENAME
    );
    assert_eq!(get_state(&sm).name, "name-a", "nothing changed");
    let same = wide("name-a");
    // SAFETY: a valid string.
    assert_eq!(hr(unsafe { sm.SetName(pcwstr(&same)) }), S_OK);
    let new = wide("name-c");
    // SAFETY: a valid string.
    assert_eq!(hr(unsafe { sm.SetName(pcwstr(&new)) }), S_OK);
    assert_eq!(get_state(&sm).name, "name-c");
    // The old name is free again, the new one is the group's.
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let r = unsafe { s.GetGroupByName(pcwstr(&new), &IUnknown::IID, out.as_out()) };
    assert_eq!(hr(r), S_OK);
    assert_eq!(out.take().as_ref(), Some(&g.unknown), "one COM identity");
    let _c = add_group(&s, "name-a");
}

// ---- CloneGroup -------------------------------------------------------------------------

fn group_exists(s: &IOPCServer, name: &str) -> bool {
    let n = wide(name);
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let r = unsafe { s.GetGroupByName(pcwstr(&n), &IUnknown::IID, out.as_out()) };
    let found = r.is_ok();
    if found {
        out.take();
    }
    found
}

#[test]
fn clone_group_argument_branches() {
    let s = opc_server();
    let g = add_group(&s, "clone-src");
    let _b = add_group(&s, "clone-taken");
    let sm: IOPCGroupStateMgt = iface(&g);
    let name = wide("clone-new");
    // NULL riid / NULL ppUnk: E_INVALIDARG.
    // SAFETY: a deliberately NULL riid.
    let r = unsafe { sm.CloneGroup(pcwstr(&name), std::ptr::null(), OutUnk::null().as_out()) };
    assert_eq!(hr(r), E_INVALIDARG);
    // SAFETY: a deliberately NULL ppUnk.
    let r = unsafe { sm.CloneGroup(pcwstr(&name), &IUnknown::IID, std::ptr::null_mut()) };
    assert_eq!(hr(r), E_INVALIDARG);
    // NULL name: E_INVALIDARG, ppUnk cleared.
    let mut out = OutUnk::poisoned();
    // SAFETY: a deliberately NULL name.
    let r = unsafe { sm.CloneGroup(PCWSTR::null(), &IUnknown::IID, out.as_out()) };
    assert_eq!(hr(r), E_INVALIDARG);
    assert!(out.is_null());
    // A name another group has: OPC_E_DUPLICATENAME, ppUnk cleared.
    let taken = wide("clone-taken");
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let r = unsafe { sm.CloneGroup(pcwstr(&taken), &IUnknown::IID, out.as_out()) };
    assert_eq!(hr(r), OPC_E_DUPLICATENAME);
    assert!(out.is_null());
    // An interface the group does not have: E_NOINTERFACE, ppUnk cleared, no group left.
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let r = unsafe { sm.CloneGroup(pcwstr(&name), &IOPCServer::IID, out.as_out()) };
    assert_eq!(hr(r), E_NOINTERFACE);
    assert!(out.is_null());
    assert!(
        !group_exists(&s, "clone-new"),
        "the failed clone was removed"
    );
}

#[test]
fn clone_group_with_null_riid_clears_the_out_parameter() {
    let (_s, g) = server_with_group("clone-null-riid");
    let sm: IOPCGroupStateMgt = iface(&g);
    let name = wide("clone-null-riid-2");
    let mut out = OutUnk::poisoned();
    // SAFETY: a deliberately NULL riid.
    let r = unsafe { sm.CloneGroup(pcwstr(&name), std::ptr::null(), out.as_out()) };
    assert_eq!(hr(r), E_INVALIDARG);
    assert!(out.is_null());
}

#[test]
fn clone_group_makes_an_inactive_copy_with_new_handles() {
    let s = opc_server();
    let g = add_group(&s, "clone-full");
    let h = add_ok(&g, &[LEVEL, SETPOINT]);
    let sm: IOPCGroupStateMgt = iface(&g);
    let name = wide("clone-full-copy");
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let r = unsafe { sm.CloneGroup(pcwstr(&name), &IOPCGroupStateMgt::IID, out.as_out()) };
    assert_eq!(hr(r), S_OK);
    let clone = out.take().expect("the clone");
    let csm: IOPCGroupStateMgt = clone.cast().expect("IOPCGroupStateMgt");
    let (src, st) = (get_state(&sm), get_state(&csm));
    assert_eq!(st.name, "clone-full-copy");
    assert!(!st.active, "a clone is inactive");
    assert_ne!(st.server, src.server);
    assert_eq!(
        (st.rate, st.client, st.lcid),
        (src.rate, src.client, src.lcid)
    );
    // Its items: the same IDs and client handles, new server handles.
    let items: IOPCItemMgt = clone.cast().expect("IOPCItemMgt");
    let (hr_, errs) = errors_of(2, |e| {
        // SAFETY: valid pointers (the source's handles are no items of the clone).
        unsafe { items.RemoveItems(2, h.as_ptr(), e) }
    });
    assert_eq!(hr_, S_FALSE);
    assert!(errs.iter().all(|e| *e == OPC_E_INVALIDHANDLE), "{errs:x?}");
    // An empty name: the server makes one.
    let empty = wide("");
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let r = unsafe { sm.CloneGroup(pcwstr(&empty), &IUnknown::IID, out.as_out()) };
    assert_eq!(hr(r), S_OK);
    let unnamed = out.take().expect("the clone");
    let st = get_state(&unnamed.cast().expect("IOPCGroupStateMgt"));
    assert!(!st.name.is_empty() && st.name != "clone-full" && st.name != "clone-full-copy");
}

// ---- SetKeepAlive / GetKeepAlive --------------------------------------------------------

#[test]
fn keep_alive_argument_branches_and_revision() {
    let (_s, g) = server_with_group("keepalive");
    let sm = state_mgt(&g);
    assert_eq!(
        // SAFETY: a deliberately NULL out-pointer.
        unsafe { sm.SetKeepAlive(5000, std::ptr::null_mut()) },
        E_INVALIDARG
    );
    assert_eq!(
        // SAFETY: a deliberately NULL out-pointer.
        hr(unsafe { sm.GetKeepAlive(std::ptr::null_mut()) }),
        E_INVALIDARG
    );
    let get = || {
        let mut t = POISON_U32;
        // SAFETY: a valid out-pointer.
        assert_eq!(hr(unsafe { sm.GetKeepAlive(&mut t) }), S_OK);
        t
    };
    assert_eq!(get(), 0, "no keep-alive by default");
    let set = |ms: u32| {
        let mut revised = POISON_U32;
        // SAFETY: a valid out-pointer.
        let hr = unsafe { sm.SetKeepAlive(ms, &mut revised) };
        (hr, revised)
    };
    assert_eq!(set(3000), (S_OK, 3000));
    assert_eq!(get(), 3000);
    assert_eq!(set(10), (OPC_S_UNSUPPORTEDRATE, 1000));
    assert_eq!(get(), 1000);
    assert_eq!(set(0), (S_OK, 0));
    assert_eq!(get(), 0);
}

// ---- IOPCItemDeadbandMgt ----------------------------------------------------------------

#[test]
fn item_deadband_argument_branches() {
    let (_s, g, h) = group_with("deadband-args", &[LEVEL, SETPOINT]);
    let d: IOPCItemDeadbandMgt = iface(&g);
    let db = [1.0f32, 2.0];
    check_count_and_handles("SetItemDeadband", &h, |n, p, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { d.SetItemDeadband(n, p, db.as_ptr(), e) }
    });
    check_count_and_handles("ClearItemDeadband", &h, |n, p, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { d.ClearItemDeadband(n, p, e) }
    });
    // SetItemDeadband with a NULL deadband array.
    let mut errors = poison::<HRESULT>();
    // SAFETY: a deliberately NULL pPercentDeadband.
    let r = unsafe { d.SetItemDeadband(2, h.as_ptr(), std::ptr::null(), &mut errors) };
    assert_eq!(r, E_INVALIDARG);
    assert!(errors.is_null());
    // GetItemDeadband: NULL ppPercentDeadband, NULL ppErrors, count 0, NULL handles.
    let mut values = poison::<f32>();
    let mut errors: *mut HRESULT = std::ptr::null_mut();
    // SAFETY: a deliberately NULL values out-pointer.
    let r = unsafe { d.GetItemDeadband(2, h.as_ptr(), std::ptr::null_mut(), &mut errors) };
    assert_eq!(r, E_INVALIDARG);
    // SAFETY: a deliberately NULL error out-pointer.
    let r = unsafe { d.GetItemDeadband(2, h.as_ptr(), &mut values, std::ptr::null_mut()) };
    assert_eq!(r, E_INVALIDARG);
    assert!(values.is_null());
    for (n, p) in [(0u32, h.as_ptr()), (2, std::ptr::null())] {
        let (mut values, mut errors) = (poison::<f32>(), poison::<HRESULT>());
        // SAFETY: valid out-pointers; count 0 or a NULL handle array.
        let r = unsafe { d.GetItemDeadband(n, p, &mut values, &mut errors) };
        assert_eq!(r, E_INVALIDARG, "count {n}");
        assert!(values.is_null() && errors.is_null(), "count {n}");
    }
    // Nothing was set by the failed calls.
    let (hr_, v) = get_deadband(&d, &h);
    assert_eq!(hr_, S_FALSE);
    assert!(v.iter().all(|(_, e)| *e == OPC_E_DEADBANDNOTSET));
}

fn get_deadband(d: &IOPCItemDeadbandMgt, h: &[u32]) -> (HRESULT, Vec<(f32, HRESULT)>) {
    let (mut values, mut errors) = (poison::<f32>(), poison::<HRESULT>());
    // SAFETY: valid pointers.
    let r = unsafe { d.GetItemDeadband(h.len() as u32, h.as_ptr(), &mut values, &mut errors) };
    assert!(r == S_OK || r == S_FALSE, "{r:?}");
    // SAFETY: a successful call handed out both arrays.
    let v = unsafe { take_array(values, h.len()) };
    (
        r,
        v.into_iter().zip(take_errors(r, errors, h.len())).collect(),
    )
}

#[test]
fn item_deadband_set_get_clear() {
    let (_s, g, h) = group_with("deadband", &[LEVEL, TEXT, SETPOINT]);
    let d: IOPCItemDeadbandMgt = iface(&g);
    let (analog, text, other) = (h[0], h[1], h[2]);
    let set = |pairs: &[(u32, f32)]| {
        let hs: Vec<u32> = pairs.iter().map(|p| p.0).collect();
        let ds: Vec<f32> = pairs.iter().map(|p| p.1).collect();
        errors_of(hs.len(), |e| {
            // SAFETY: valid arrays of the same length.
            unsafe { d.SetItemDeadband(hs.len() as u32, hs.as_ptr(), ds.as_ptr(), e) }
        })
    };
    assert_eq!(
        set(&[
            (analog, 2.5),
            (text, 1.0),
            (other, 101.0),
            (BAD_HANDLE, 1.0),
            (other, -1.0)
        ]),
        (
            S_FALSE,
            vec![
                S_OK,
                OPC_E_DEADBANDNOTSUPPORTED,
                E_INVALIDARG,
                OPC_E_INVALIDHANDLE,
                E_INVALIDARG
            ]
        )
    );
    let (hr_, v) = get_deadband(&d, &[analog, text, other, BAD_HANDLE]);
    assert_eq!(hr_, S_FALSE);
    assert_eq!(v[0], (2.5, S_OK));
    assert_eq!(
        v[1..].iter().map(|p| p.1).collect::<Vec<_>>(),
        vec![
            OPC_E_DEADBANDNOTSUPPORTED,
            OPC_E_DEADBANDNOTSET,
            OPC_E_INVALIDHANDLE
        ]
    );
    assert_eq!(get_deadband(&d, &[analog]), (S_OK, vec![(2.5, S_OK)]));
    assert_eq!(set(&[(other, 5.0)]), (S_OK, vec![S_OK]));
    let (hr_, errs) = errors_of(4, |e| {
        let hs = [analog, other, text, BAD_HANDLE];
        // SAFETY: valid pointers.
        unsafe { d.ClearItemDeadband(4, hs.as_ptr(), e) }
    });
    assert_eq!(
        (hr_, errs),
        (
            S_FALSE,
            vec![S_OK, S_OK, OPC_E_DEADBANDNOTSUPPORTED, OPC_E_INVALIDHANDLE]
        )
    );
    let (_, v) = get_deadband(&d, &[analog, other]);
    assert!(v.iter().all(|p| p.1 == OPC_E_DEADBANDNOTSET));
    let (hr_, errs) = errors_of(1, |e| {
        // SAFETY: valid pointers.
        unsafe { d.ClearItemDeadband(1, [analog].as_ptr(), e) }
    });
    assert_eq!((hr_, errs), (S_FALSE, vec![OPC_E_DEADBANDNOTSET]));
}

// ---- IOPCItemSamplingMgt ----------------------------------------------------------------

#[test]
fn item_sampling_argument_branches() {
    let (_s, g, h) = group_with("sampling-args", &[LEVEL, SETPOINT]);
    let sm: IOPCItemSamplingMgt = iface(&g);
    check_count_and_handles("ClearItemSamplingRate", &h, |n, p, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { sm.ClearItemSamplingRate(n, p, e) }
    });
    let enable = [BOOL(0), BOOL(0)];
    check_count_and_handles("SetItemBufferEnable", &h, |n, p, e| {
        // SAFETY: the pointers are NULL or valid for the call.
        unsafe { sm.SetItemBufferEnable(n, p, enable.as_ptr(), e) }
    });
    let mut errors = poison::<HRESULT>();
    // SAFETY: a deliberately NULL pbEnable.
    let r = unsafe { sm.SetItemBufferEnable(2, h.as_ptr(), std::ptr::null(), &mut errors) };
    assert_eq!(r, E_INVALIDARG);
    assert!(errors.is_null());

    // The calls with a value out-array: NULL values, NULL errors, count 0, NULL handles
    // (and SetItemSamplingRate's NULL rate array).
    let rates = [2000u32, 2000];
    type Call<'a> = Box<dyn Fn(u32, *const u32, *mut *mut u32, *mut *mut HRESULT) -> HRESULT + 'a>;
    let calls: Vec<(&str, Call)> = vec![
        (
            "SetItemSamplingRate",
            Box::new(|n, p, v, e| {
                // SAFETY: the pointers are NULL or valid for the call.
                unsafe { sm.SetItemSamplingRate(n, p, rates.as_ptr(), v, e) }
            }),
        ),
        (
            "GetItemSamplingRate",
            Box::new(|n, p, v, e| {
                // SAFETY: as above.
                unsafe { sm.GetItemSamplingRate(n, p, v, e) }
            }),
        ),
        (
            "GetItemBufferEnable",
            Box::new(|n, p, v, e| {
                // SAFETY: as above (BOOL and u32 have the same layout).
                unsafe { sm.GetItemBufferEnable(n, p, v.cast(), e) }
            }),
        ),
    ];
    for (what, call) in &calls {
        let mut errors: *mut HRESULT = std::ptr::null_mut();
        assert_eq!(
            call(2, h.as_ptr(), std::ptr::null_mut(), &mut errors),
            E_INVALIDARG,
            "{what}: NULL values"
        );
        let mut values = poison::<u32>();
        assert_eq!(
            call(2, h.as_ptr(), &mut values, std::ptr::null_mut()),
            E_INVALIDARG,
            "{what}: NULL errors"
        );
        assert!(values.is_null(), "{what}: NULL errors left the values");
        for (n, p) in [(0u32, h.as_ptr()), (2, std::ptr::null())] {
            let (mut values, mut errors) = (poison::<u32>(), poison::<HRESULT>());
            assert_eq!(
                call(n, p, &mut values, &mut errors),
                E_INVALIDARG,
                "{what}: count {n}"
            );
            assert!(values.is_null() && errors.is_null(), "{what}: count {n}");
        }
    }
    let (mut values, mut errors) = (poison::<u32>(), poison::<HRESULT>());
    // SAFETY: a deliberately NULL pdwRequestedSamplingRate.
    let r = unsafe {
        sm.SetItemSamplingRate(2, h.as_ptr(), std::ptr::null(), &mut values, &mut errors)
    };
    assert_eq!(r, E_INVALIDARG);
    assert!(values.is_null() && errors.is_null());
    // Nothing was set by the failed calls.
    let (hr_, v) = get_sampling(&sm, &h);
    assert_eq!(hr_, S_FALSE);
    assert!(v.iter().all(|p| p.1 == OPC_E_RATENOTSET));
}

fn get_sampling(sm: &IOPCItemSamplingMgt, h: &[u32]) -> (HRESULT, Vec<(u32, HRESULT)>) {
    let (mut values, mut errors) = (poison::<u32>(), poison::<HRESULT>());
    // SAFETY: valid pointers.
    let r = unsafe { sm.GetItemSamplingRate(h.len() as u32, h.as_ptr(), &mut values, &mut errors) };
    assert!(r == S_OK || r == S_FALSE, "{r:?}");
    // SAFETY: a successful call handed out both arrays.
    let v = unsafe { take_array(values, h.len()) };
    (
        r,
        v.into_iter().zip(take_errors(r, errors, h.len())).collect(),
    )
}

#[test]
fn item_sampling_rate_and_buffering() {
    let (_s, g, h) = group_with("sampling", &[LEVEL, SETPOINT]);
    let sm: IOPCItemSamplingMgt = iface(&g);
    let set = |pairs: &[(u32, u32)]| {
        let hs: Vec<u32> = pairs.iter().map(|p| p.0).collect();
        let rs: Vec<u32> = pairs.iter().map(|p| p.1).collect();
        let (mut values, mut errors) = (poison::<u32>(), poison::<HRESULT>());
        // SAFETY: valid arrays of the same length and out-pointers.
        let r = unsafe {
            sm.SetItemSamplingRate(
                hs.len() as u32,
                hs.as_ptr(),
                rs.as_ptr(),
                &mut values,
                &mut errors,
            )
        };
        // SAFETY: a successful call handed out both arrays.
        let v = unsafe { take_array(values, hs.len()) };
        (
            r,
            v.into_iter()
                .zip(take_errors(r, errors, hs.len()))
                .collect::<Vec<_>>(),
        )
    };
    // Below the 1 s minimum: raised, OPC_S_UNSUPPORTEDRATE (a success: not S_FALSE).
    assert_eq!(
        set(&[(h[0], 200), (h[1], 5000)]),
        (S_OK, vec![(1000, OPC_S_UNSUPPORTEDRATE), (5000, S_OK)])
    );
    assert_eq!(
        set(&[(h[0], 2000), (BAD_HANDLE, 2000)]),
        (S_FALSE, vec![(2000, S_OK), (0, OPC_E_INVALIDHANDLE)])
    );
    assert_eq!(
        get_sampling(&sm, &[h[0], h[1], BAD_HANDLE]),
        (
            S_FALSE,
            vec![(2000, S_OK), (5000, S_OK), (0, OPC_E_INVALIDHANDLE)]
        )
    );
    let clear = |hs: &[u32]| {
        errors_of(hs.len(), |e| {
            // SAFETY: valid pointers.
            unsafe { sm.ClearItemSamplingRate(hs.len() as u32, hs.as_ptr(), e) }
        })
    };
    assert_eq!(clear(&[h[0]]), (S_OK, vec![S_OK]));
    assert_eq!(
        clear(&[h[0], BAD_HANDLE]),
        (S_FALSE, vec![OPC_E_RATENOTSET, OPC_E_INVALIDHANDLE])
    );
    // Buffering: enabling and disabling succeed per item; Get reads it back.
    let hs = [h[0], h[1], BAD_HANDLE];
    let en = [BOOL(1), BOOL(0), BOOL(0)];
    let (r, errs) = errors_of(3, |e| {
        // SAFETY: valid arrays of the same length.
        unsafe { sm.SetItemBufferEnable(3, hs.as_ptr(), en.as_ptr(), e) }
    });
    assert_eq!((r, errs), (S_FALSE, vec![S_OK, S_OK, OPC_E_INVALIDHANDLE]));
    let (mut values, mut errors) = (poison::<BOOL>(), poison::<HRESULT>());
    // SAFETY: valid pointers.
    let r = unsafe { sm.GetItemBufferEnable(3, hs.as_ptr(), &mut values, &mut errors) };
    assert_eq!(r, S_FALSE);
    // SAFETY: a successful call handed out both arrays.
    let v: Vec<bool> = unsafe { take_array(values, 3) }
        .into_iter()
        .map(|b| b.as_bool())
        .collect();
    assert_eq!(v, vec![true, false, false]);
    assert_eq!(
        take_errors(r, errors, 3),
        vec![S_OK, S_OK, OPC_E_INVALIDHANDLE]
    );
}

#[test]
fn a_null_value_out_array_clears_the_error_array() {
    let (_s, g, h) = group_with("null-values-clear", &[LEVEL]);
    let d: IOPCItemDeadbandMgt = iface(&g);
    let sm: IOPCItemSamplingMgt = iface(&g);
    let rates = [2000u32];
    let mut failures = Vec::new();
    let mut check = |what: &str, call: &dyn Fn(*mut *mut HRESULT) -> HRESULT| {
        let mut errors = poison::<HRESULT>();
        assert_eq!(call(&mut errors), E_INVALIDARG, "{what}");
        if !errors.is_null() {
            failures.push(what.to_string());
        }
    };
    // SAFETY (each call): a deliberately NULL value out-array, other pointers valid.
    // SAFETY: a deliberately NULL value out-array, other pointers valid.
    check("GetItemDeadband", &|e| unsafe {
        d.GetItemDeadband(1, h.as_ptr(), std::ptr::null_mut(), e)
    });
    // SAFETY: a deliberately NULL value out-array, other pointers valid.
    check("SetItemSamplingRate", &|e| unsafe {
        sm.SetItemSamplingRate(1, h.as_ptr(), rates.as_ptr(), std::ptr::null_mut(), e)
    });
    // SAFETY: a deliberately NULL value out-array, other pointers valid.
    check("GetItemSamplingRate", &|e| unsafe {
        sm.GetItemSamplingRate(1, h.as_ptr(), std::ptr::null_mut(), e)
    });
    // SAFETY: a deliberately NULL value out-array, other pointers valid.
    check("GetItemBufferEnable", &|e| unsafe {
        sm.GetItemBufferEnable(1, h.as_ptr(), std::ptr::null_mut(), e)
    });
    assert!(failures.is_empty(), "*ppErrors not cleared by {failures:?}");
}

#[test]
fn set_state_client_handle_and_active_reach_the_callbacks() {
    let (_s, g, _h) = group_with("state-callbacks", &[LEVEL, SETPOINT]);
    let (_cookie, rec) = advise(&g);
    let sm: IOPCGroupStateMgt = iface(&g);
    assert_eq!(
        set_state(
            &sm,
            SetArgs {
                client: Some(55),
                ..Default::default()
            }
        ),
        (S_OK, 1000)
    );
    let a2: IOPCAsyncIO2 = iface(&g);
    let mut cancel = 0u32;
    // SAFETY: a valid out-pointer.
    let r = unsafe { a2.Refresh2(OPC_DS_DEVICE, 71, &mut cancel) };
    assert_eq!(hr(r), S_OK);
    let wait = std::time::Duration::from_secs(10);
    let c = rec
        .wait_for(wait, |c| c.transaction() == 71)
        .expect("the refresh");
    let Callback::DataChange { group, items, .. } = c else {
        panic!("{c:?}")
    };
    assert_eq!(group, 55, "the new client group handle");
    assert_eq!(items.len(), 2);
    // Inactive: a refresh is E_FAIL; active again: it works.
    let set_active = |a: bool| {
        set_state(
            &sm,
            SetArgs {
                active: Some(a),
                ..Default::default()
            },
        )
        .0
    };
    assert_eq!(set_active(false), S_OK);
    // SAFETY: a valid out-pointer.
    let r = unsafe { a2.Refresh2(OPC_DS_CACHE, 72, &mut cancel) };
    assert_eq!(hr(r), E_FAIL);
    assert_eq!(set_active(true), S_OK);
    // SAFETY: a valid out-pointer.
    let r = unsafe { a2.Refresh2(OPC_DS_CACHE, 73, &mut cancel) };
    assert_eq!(hr(r), S_OK);
    assert!(rec.wait_for(wait, |c| c.transaction() == 73).is_some());
}
