//! The group object after IOPCServer::RemoveGroup while the client still holds it (with
//! and without bForce): every method of every group interface answers E_FAIL (the engine
//! has no live group behind the object) with its out-parameters cleared, and releasing the
//! object then frees the group. In process, no proxy. Harness: `common/mod.rs`; group
//! helpers: `inproc_group_support/mod.rs`.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
mod inproc_group_support;

use common::*;
use ctopc_com::interfaces::*;
use inproc_group_support::*;
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Com::IConnectionPointContainer;
use windows::Win32::System::Variant::VARIANT;

/// A group with two items, removed from its server while this test still holds it.
fn removed(name: &str, force: bool) -> (IOPCServer, Group, Vec<u32>) {
    let (s, g, h) = group_with(name, &[LEVEL, SETPOINT]);
    // SAFETY: a valid handle of this client's group.
    let r = unsafe { s.RemoveGroup(g.server_handle, force.into()) };
    assert_eq!(r, if force { S_OK } else { OPC_S_INUSE }, "force {force}");
    (s, g, h)
}

fn check_every_method_fails(g: &Group, h: &[u32]) {
    let n = h.len() as u32;
    let hp = h.as_ptr();

    // IOPCGroupStateMgt / 2.
    let sm: IOPCGroupStateMgt2 = iface(g);
    let (mut rate, mut active, mut name) = (0u32, BOOL(0), PWSTR(poison()));
    let (mut bias, mut db, mut lcid, mut client, mut server) = (0i32, 0f32, 0u32, 0u32, 0u32);
    // SAFETY: valid out-pointers.
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
    assert_eq!(hr(r), E_FAIL, "GetState");
    assert!(name.is_null(), "GetState: the name cleared");
    let mut revised = 0u32;
    // SAFETY: valid pointers.
    let r = unsafe {
        sm.SetState(
            std::ptr::null(),
            &mut revised,
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    assert_eq!(r, E_FAIL, "SetState");
    let new_name = wide("removed-renamed");
    assert_eq!(
        // SAFETY: a valid string.
        hr(unsafe { sm.SetName(pcwstr(&new_name)) }),
        E_FAIL,
        "SetName"
    );
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let r = unsafe { sm.CloneGroup(pcwstr(&new_name), &IUnknown::IID, out.as_out()) };
    assert_eq!(hr(r), E_FAIL, "CloneGroup");
    assert!(out.is_null(), "CloneGroup: ppUnk cleared");
    assert_eq!(
        // SAFETY: a valid out-pointer.
        unsafe { sm.SetKeepAlive(1000, &mut revised) },
        E_FAIL,
        "SetKeepAlive"
    );
    assert_eq!(
        // SAFETY: a valid out-pointer.
        hr(unsafe { sm.GetKeepAlive(&mut revised) }),
        E_FAIL,
        "GetKeepAlive"
    );

    // IOPCItemMgt.
    let d = defs(&[LEVEL]);
    for validate in [false, true] {
        let (mut results, mut errors) = (poison::<OPCITEMRESULT>(), poison::<HRESULT>());
        // SAFETY: valid pointers.
        let r = unsafe {
            if validate {
                g.item_mgt.ValidateItems(
                    1,
                    d.defs.as_ptr(),
                    false.into(),
                    &mut results,
                    &mut errors,
                )
            } else {
                g.item_mgt
                    .AddItems(1, d.defs.as_ptr(), &mut results, &mut errors)
            }
        };
        assert_eq!(r, E_FAIL, "AddItems/ValidateItems ({validate})");
        assert!(results.is_null() && errors.is_null());
    }
    let clients = [7u32, 8];
    let types = [windows::Win32::System::Variant::VARENUM(5); 2];
    let deadbands = [1.0f32; 2];
    let rates = [2000u32; 2];
    let enable = [BOOL(0); 2];
    let dm: IOPCItemDeadbandMgt = iface(g);
    let sam: IOPCItemSamplingMgt = iface(g);
    type Call<'a> = Box<dyn Fn(*mut *mut HRESULT) -> HRESULT + 'a>;
    let error_only: Vec<(&str, Call)> = vec![
        (
            "RemoveItems",
            // SAFETY: valid arrays of `n` elements and a valid error out-pointer.
            Box::new(|e| unsafe { g.item_mgt.RemoveItems(n, hp, e) }),
        ),
        (
            "SetActiveState",
            // SAFETY: valid arrays of `n` elements and a valid error out-pointer.
            Box::new(|e| unsafe { g.item_mgt.SetActiveState(n, hp, true.into(), e) }),
        ),
        (
            "SetClientHandles",
            // SAFETY: valid arrays of `n` elements and a valid error out-pointer.
            Box::new(|e| unsafe { g.item_mgt.SetClientHandles(n, hp, clients.as_ptr(), e) }),
        ),
        (
            "SetDatatypes",
            // SAFETY: valid arrays of `n` elements and a valid error out-pointer.
            Box::new(|e| unsafe { g.item_mgt.SetDatatypes(n, hp, types.as_ptr(), e) }),
        ),
        (
            "SetItemDeadband",
            // SAFETY: valid arrays of `n` elements and a valid error out-pointer.
            Box::new(|e| unsafe { dm.SetItemDeadband(n, hp, deadbands.as_ptr(), e) }),
        ),
        (
            "ClearItemDeadband",
            // SAFETY: valid arrays of `n` elements and a valid error out-pointer.
            Box::new(|e| unsafe { dm.ClearItemDeadband(n, hp, e) }),
        ),
        (
            "ClearItemSamplingRate",
            // SAFETY: valid arrays of `n` elements and a valid error out-pointer.
            Box::new(|e| unsafe { sam.ClearItemSamplingRate(n, hp, e) }),
        ),
        (
            "SetItemBufferEnable",
            // SAFETY: valid arrays of `n` elements and a valid error out-pointer.
            Box::new(|e| unsafe { sam.SetItemBufferEnable(n, hp, enable.as_ptr(), e) }),
        ),
    ];
    for (what, call) in &error_only {
        let mut errors = poison::<HRESULT>();
        assert_eq!(call(&mut errors), E_FAIL, "{what}");
        assert!(errors.is_null(), "{what}: ppErrors cleared");
    }
    type ValCall<'a> = Box<dyn Fn(*mut *mut u32, *mut *mut HRESULT) -> HRESULT + 'a>;
    // SAFETY (each call): valid arrays and out-pointers (f32, u32 and BOOL arrays alike
    // are 4-byte elements; nothing is handed out on failure).
    let with_values: Vec<(&str, ValCall)> = vec![
        (
            "GetItemDeadband",
            // SAFETY: valid arrays and out-pointers (f32, u32 and BOOL arrays alike
            Box::new(|v, e| unsafe { dm.GetItemDeadband(n, hp, v.cast(), e) }),
        ),
        (
            "SetItemSamplingRate",
            // SAFETY: valid arrays and out-pointers (f32, u32 and BOOL arrays alike
            Box::new(|v, e| unsafe { sam.SetItemSamplingRate(n, hp, rates.as_ptr(), v, e) }),
        ),
        (
            "GetItemSamplingRate",
            // SAFETY: valid arrays and out-pointers (f32, u32 and BOOL arrays alike
            Box::new(|v, e| unsafe { sam.GetItemSamplingRate(n, hp, v, e) }),
        ),
        (
            "GetItemBufferEnable",
            // SAFETY: valid arrays and out-pointers (f32, u32 and BOOL arrays alike
            Box::new(|v, e| unsafe { sam.GetItemBufferEnable(n, hp, v.cast(), e) }),
        ),
    ];
    for (what, call) in &with_values {
        let (mut values, mut errors) = (poison::<u32>(), poison::<HRESULT>());
        assert_eq!(call(&mut values, &mut errors), E_FAIL, "{what}");
        assert!(
            values.is_null() && errors.is_null(),
            "{what}: outputs cleared"
        );
    }
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let r = unsafe {
        g.item_mgt
            .CreateEnumerator(&IEnumOPCItemAttributes::IID, out.as_out())
    };
    assert_eq!(r, E_FAIL, "CreateEnumerator");
    assert!(out.is_null(), "CreateEnumerator: ppUnk cleared");

    // Sync I/O.
    let sync: IOPCSyncIO2 = iface(g);
    for src in [OPC_DS_CACHE, OPC_DS_DEVICE] {
        let (mut values, mut errors) = (poison::<OPCITEMSTATE>(), poison::<HRESULT>());
        // SAFETY: valid pointers.
        let r = unsafe { sync.Read(src, n, hp, &mut values, &mut errors) };
        assert_eq!(r, E_FAIL, "Read({src:?})");
        assert!(values.is_null() && errors.is_null());
    }
    let ages = [0u32; 2];
    let (mut v, mut q, mut t, mut e) = (
        poison::<VARIANT>(),
        poison::<u16>(),
        poison::<FILETIME>(),
        poison::<HRESULT>(),
    );
    // SAFETY: valid pointers.
    let r = unsafe { sync.ReadMaxAge(n, hp, ages.as_ptr(), &mut v, &mut q, &mut t, &mut e) };
    assert_eq!(r, E_FAIL, "ReadMaxAge");
    assert!(v.is_null() && q.is_null() && t.is_null() && e.is_null());
    let mut vars = [
        var(&ctopc_core::Value::R4(1.0)),
        var(&ctopc_core::Value::R4(1.0)),
    ];
    let mut errors = poison::<HRESULT>();
    assert_eq!(
        // SAFETY: valid pointers.
        unsafe { sync.Write(n, hp, vars.as_ptr(), &mut errors) },
        E_FAIL,
        "Write"
    );
    assert!(errors.is_null());
    let vqts = [OPCITEMVQT::default(), OPCITEMVQT::default()];
    let mut errors = poison::<HRESULT>();
    assert_eq!(
        // SAFETY: valid pointers.
        unsafe { sync.WriteVQT(n, hp, vqts.as_ptr(), &mut errors) },
        E_FAIL,
        "WriteVQT"
    );
    assert!(errors.is_null());

    // Async I/O (before any connection check: there is no group).
    let a3: IOPCAsyncIO3 = iface(g);
    type AsyncCall<'a> = Box<dyn Fn(*mut u32, *mut *mut HRESULT) -> HRESULT + 'a>;
    let asyncs: Vec<(&str, AsyncCall)> = vec![
        // SAFETY: valid arrays and out-pointers.
        ("Read", Box::new(|c, e| unsafe { a3.Read(n, hp, 1, c, e) })),
        (
            "Write",
            // SAFETY: valid arrays and out-pointers.
            Box::new(|c, e| unsafe { a3.Write(n, hp, vars.as_ptr(), 1, c, e) }),
        ),
        (
            "ReadMaxAge",
            // SAFETY: valid arrays and out-pointers.
            Box::new(|c, e| unsafe { a3.ReadMaxAge(n, hp, ages.as_ptr(), 1, c, e) }),
        ),
        (
            "WriteVQT",
            // SAFETY: valid arrays and out-pointers.
            Box::new(|c, e| unsafe { a3.WriteVQT(n, hp, vqts.as_ptr(), 1, c, e) }),
        ),
    ];
    for (what, call) in &asyncs {
        let (mut cancel, mut errors) = (POISON_U32, poison::<HRESULT>());
        assert_eq!(call(&mut cancel, &mut errors), E_FAIL, "async {what}");
        assert!(errors.is_null(), "async {what}: ppErrors cleared");
        assert_eq!(cancel, 0, "async {what}: cancel ID cleared");
    }
    drop(asyncs);
    clear_all(&mut vars);
    let mut cancel = POISON_U32;
    assert_eq!(
        // SAFETY: a valid out-pointer.
        hr(unsafe { a3.Refresh2(OPC_DS_CACHE, 1, &mut cancel) }),
        E_FAIL
    );
    assert_eq!(cancel, 0, "Refresh2: cancel ID cleared");
    let mut cancel = POISON_U32;
    // SAFETY: a valid out-pointer.
    assert_eq!(hr(unsafe { a3.RefreshMaxAge(0, 1, &mut cancel) }), E_FAIL);
    assert_eq!(cancel, 0, "RefreshMaxAge: cancel ID cleared");
    // SAFETY: a plain value.
    assert_eq!(hr(unsafe { a3.Cancel2(1) }), E_FAIL, "Cancel2");
    assert_eq!(
        // SAFETY: a plain value.
        hr(unsafe { a3.SetEnable(true.into()) }),
        E_FAIL,
        "SetEnable"
    );
    let mut b = BOOL(0);
    // SAFETY: a valid out-pointer.
    assert_eq!(hr(unsafe { a3.GetEnable(&mut b) }), E_FAIL, "GetEnable");

    // The connection point: Advise cannot connect a group that is gone.
    let cpc: IConnectionPointContainer = iface(g);
    // SAFETY: a valid IID.
    let cp = unsafe { cpc.FindConnectionPoint(&IOPCDataCallback::IID) }.expect("the point");
    let sink = Recording::new().sink();
    // SAFETY: a valid sink.
    let r = unsafe { cp.Advise(&IUnknown::from(&sink)) };
    assert_eq!(code(&r), E_FAIL, "Advise");
}

#[test]
fn every_method_of_a_group_removed_while_in_use_fails() {
    let (s, g, h) = removed("removed-inuse", false);
    check_every_method_fails(&g, &h);
    // The name is free for a new group at once; the old object still fails.
    let again = add_group(&s, "removed-inuse");
    assert_ne!(again.server_handle, g.server_handle);
    check_every_method_fails(&g, &h);
}

#[test]
fn every_method_of_a_group_removed_with_force_fails() {
    let (_s, g, h) = removed("removed-force", true);
    check_every_method_fails(&g, &h);
}

#[test]
fn remove_group_of_a_removed_group_is_e_invalidarg() {
    let (s, g, _h) = removed("removed-twice", false);
    for force in [false, true] {
        // SAFETY: a handle that was this client's group.
        let r = unsafe { s.RemoveGroup(g.server_handle, force.into()) };
        assert_eq!(r, E_INVALIDARG, "force {force}");
    }
}
