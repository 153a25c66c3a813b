//! The group object's IConnectionPointContainer and its IOPCDataCallback connection point,
//! in process (no proxy): FindConnectionPoint and EnumConnectionPoints, Advise with a NULL
//! sink or a sink without IOPCDataCallback, the advise limit, Unadvise of unknown cookies,
//! EnumConnections, and subscription callbacks (OnDataChange) received by an in-process
//! sink. Harness: `common/mod.rs`; group helpers: `inproc_group_support/mod.rs`.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
mod inproc_group_support;

use common::*;
use ctopc_com::interfaces::*;
use inproc_group_support::*;
use std::ffi::c_void;
use std::time::Duration;
use windows::Win32::System::Com::{
    IConnectionPoint, IConnectionPointContainer, IEnumConnectionPoints, IEnumConnections,
    CONNECTDATA,
};
use windows::Win32::System::Ole::{
    CONNECT_E_ADVISELIMIT, CONNECT_E_CANNOTCONNECT, CONNECT_E_NOCONNECTION,
};

const WAIT: Duration = Duration::from_secs(10);

fn container(g: &Group) -> IConnectionPointContainer {
    iface(g)
}

/// The raw FindConnectionPoint(riid, ppCP), for NULL arguments and the out-parameter.
fn raw_find(cpc: &IConnectionPointContainer, riid: *const GUID, out: &mut OutUnk) -> HRESULT {
    // SAFETY: a valid interface pointer; `riid` is NULL or a valid GUID and `out` a valid
    // out-pointer for one interface pointer.
    unsafe {
        (Interface::vtable(cpc).FindConnectionPoint)(
            cpc.as_raw(),
            riid,
            out.as_out::<IConnectionPoint>().cast(),
        )
    }
}

/// The raw Advise(pUnkSink, pdwCookie).
fn raw_advise(cp: &IConnectionPoint, sink: *mut c_void, cookie: *mut u32) -> HRESULT {
    // SAFETY: a valid interface pointer; `sink` is NULL or a valid interface pointer and
    // `cookie` a valid out-pointer.
    unsafe { (Interface::vtable(cp).Advise)(cp.as_raw(), sink, cookie) }
}

/// Every connection of a point, through EnumConnections (cookie, sink).
fn connections(cp: &IConnectionPoint) -> Vec<(u32, IUnknown)> {
    // SAFETY: a valid interface pointer.
    let e: IEnumConnections = unsafe { cp.EnumConnections() }.expect("EnumConnections");
    let mut all = Vec::new();
    loop {
        let mut one = [CONNECTDATA::default()];
        let mut fetched = POISON_U32;
        // SAFETY: room for one element and a valid fetched count.
        let hr = unsafe { e.Next(&mut one, &mut fetched) };
        let [cd] = one;
        let unk = std::mem::ManuallyDrop::into_inner(cd.pUnk);
        if fetched == 0 {
            assert_eq!(hr, S_FALSE);
            assert!(unk.is_none());
            break;
        }
        assert_eq!((hr, fetched), (S_OK, 1));
        all.push((cd.dwCookie, unk.expect("a connection's sink")));
        assert!(all.len() < 10, "an endless enumeration");
    }
    all
}

#[test]
fn find_connection_point_argument_branches() {
    let (_s, g) = server_with_group("cp-find-args");
    let cpc = container(&g);
    let mut out = OutUnk::null();
    assert_eq!(raw_find(&cpc, std::ptr::null(), &mut out), E_POINTER);
    assert!(out.is_null());
    for iid in [IOPCShutdown::IID, IUnknown::IID, IOPCItemMgt::IID] {
        let mut out = OutUnk::null();
        assert_eq!(
            raw_find(&cpc, &iid, &mut out),
            CONNECT_E_NOCONNECTION,
            "{iid:?}"
        );
        assert!(out.is_null());
    }
}

#[test]
fn find_connection_point_failure_clears_the_out_parameter() {
    let (_s, g) = server_with_group("cp-find-clear");
    let cpc = container(&g);
    let mut out = OutUnk::poisoned();
    assert_eq!(raw_find(&cpc, std::ptr::null(), &mut out), E_POINTER);
    assert!(out.is_null(), "NULL riid");
    let mut out = OutUnk::poisoned();
    assert_eq!(
        raw_find(&cpc, &IOPCShutdown::IID, &mut out),
        CONNECT_E_NOCONNECTION
    );
    assert!(out.is_null(), "unknown IID");
}

#[test]
fn the_data_callback_point_and_its_container() {
    let (_s, g) = server_with_group("cp-point");
    let cpc = container(&g);
    let cp = data_point(&g);
    assert_eq!(
        // SAFETY: a valid interface pointer.
        unsafe { cp.GetConnectionInterface() }.expect("GetConnectionInterface"),
        IOPCDataCallback::IID
    );
    // SAFETY: as above.
    let back = unsafe { cp.GetConnectionPointContainer() }.expect("GetConnectionPointContainer");
    assert_eq!(
        back.cast::<IUnknown>().ok(),
        Some(g.unknown.clone()),
        "the container is the group object (one COM identity)"
    );
    // EnumConnectionPoints: exactly the one point.
    // SAFETY: a valid interface pointer.
    let e: IEnumConnectionPoints =
        unsafe { cpc.EnumConnectionPoints() }.expect("EnumConnectionPoints");
    let mut points = [None, None];
    let mut fetched = POISON_U32;
    // SAFETY: room for two elements and a valid fetched count.
    let hr = unsafe { e.Next(&mut points, &mut fetched) };
    assert_eq!((hr, fetched), (S_FALSE, 1));
    let [first, second] = points;
    assert!(second.is_none());
    let first = first.expect("the point");
    assert_eq!(
        // SAFETY: a valid interface pointer.
        unsafe { first.GetConnectionInterface() }.expect("GetConnectionInterface"),
        IOPCDataCallback::IID
    );
}

#[test]
fn get_connection_interface_with_null_is_e_pointer() {
    let (_s, g) = server_with_group("cp-null-iid");
    let cp = data_point(&g);
    // SAFETY: a deliberately NULL out-pointer (the server must check it).
    let hr = unsafe {
        (Interface::vtable(&cp).GetConnectionInterface)(cp.as_raw(), std::ptr::null_mut())
    };
    assert_eq!(hr, E_POINTER);
}

#[test]
fn the_other_null_out_parameters_are_e_pointer_and_clones_work() {
    let (_s, g) = server_with_group("cp-null-outs");
    let cpc = container(&g);
    let cp = data_point(&g);
    let null = std::ptr::null_mut();
    // SAFETY: deliberately NULL out-pointers (the server must check them).
    unsafe {
        assert_eq!(
            (Interface::vtable(&cp).GetConnectionPointContainer)(cp.as_raw(), null),
            E_POINTER
        );
        assert_eq!(
            (Interface::vtable(&cp).EnumConnections)(cp.as_raw(), null),
            E_POINTER
        );
        assert_eq!(
            (Interface::vtable(&cpc).EnumConnectionPoints)(cpc.as_raw(), null),
            E_POINTER
        );
    }
    // The enumerators' Clone: E_POINTER for NULL, else a copy at the same position.
    // SAFETY: a valid interface pointer.
    let points: IEnumConnectionPoints =
        unsafe { cpc.EnumConnectionPoints() }.expect("EnumConnectionPoints");
    // SAFETY: a deliberately NULL out-pointer.
    let r = unsafe { (Interface::vtable(&points).Clone)(points.as_raw(), null) };
    assert_eq!(r, E_POINTER);
    // SAFETY: a plain count.
    assert!(unsafe { points.Skip(1) }.is_ok());
    // SAFETY: a valid interface pointer.
    let copy = unsafe { points.Clone() }.expect("Clone");
    let mut one = [None];
    let mut fetched = POISON_U32;
    // SAFETY: room for one element and a valid fetched count.
    let hr = unsafe { copy.Next(&mut one, &mut fetched) };
    assert_eq!(
        (hr, fetched),
        (S_FALSE, 0),
        "the copy is past the one point too"
    );
    // SAFETY: a valid interface pointer.
    let conns: IEnumConnections = unsafe { cp.EnumConnections() }.expect("EnumConnections");
    // SAFETY: a deliberately NULL out-pointer.
    let r = unsafe { (Interface::vtable(&conns).Clone)(conns.as_raw(), null) };
    assert_eq!(r, E_POINTER);
    // SAFETY: a valid interface pointer.
    assert!(unsafe { conns.Clone() }.is_ok());
}

#[test]
fn advise_argument_branches_and_the_advise_limit() {
    let (_s, g) = server_with_group("cp-advise");
    let cp = data_point(&g);
    // A NULL sink: E_POINTER.
    let mut cookie = 0u32;
    assert_eq!(
        raw_advise(&cp, std::ptr::null_mut(), &mut cookie),
        E_POINTER
    );
    // A sink without IOPCDataCallback (here an item enumerator): CONNECT_E_CANNOTCONNECT.
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let _ = unsafe {
        g.item_mgt
            .CreateEnumerator(&IEnumOPCItemAttributes::IID, out.as_out())
    };
    let not_a_sink = out.take().expect("an enumerator");
    assert_eq!(
        raw_advise(&cp, not_a_sink.as_raw(), &mut cookie),
        CONNECT_E_CANNOTCONNECT
    );
    assert!(connections(&cp).is_empty(), "no connection was made");
    // A sink: a non-zero cookie; a second one: CONNECT_E_ADVISELIMIT.
    let sink = Recording::new().sink();
    let sink_unk = IUnknown::from(&sink);
    let mut first = POISON_U32;
    assert_eq!(raw_advise(&cp, sink_unk.as_raw(), &mut first), S_OK);
    assert!(first != 0 && first != POISON_U32);
    let other = Recording::new().sink();
    let other_unk = IUnknown::from(&other);
    assert_eq!(
        raw_advise(&cp, other_unk.as_raw(), &mut cookie),
        CONNECT_E_ADVISELIMIT
    );
    assert_eq!(
        raw_advise(&cp, sink_unk.as_raw(), &mut cookie),
        CONNECT_E_ADVISELIMIT,
        "the same sink twice"
    );
    let conns = connections(&cp);
    assert_eq!(conns.len(), 1);
    assert_eq!(conns[0].0, first);
    assert_eq!(
        conns[0].1, sink_unk,
        "EnumConnections gives the sink's identity"
    );
    // Through a second FindConnectionPoint the same connection is seen.
    assert_eq!(connections(&data_point(&g)).len(), 1);
}

#[test]
fn advise_failure_clears_the_cookie() {
    let (_s, g) = server_with_group("cp-advise-clear");
    let cp = data_point(&g);
    let mut cookie = POISON_U32;
    assert_eq!(
        raw_advise(&cp, std::ptr::null_mut(), &mut cookie),
        E_POINTER
    );
    assert_eq!(cookie, 0);
}

#[test]
fn unadvise_of_unknown_cookies_and_advise_again() {
    let (_s, g) = server_with_group("cp-unadvise");
    let cp = data_point(&g);
    // Nothing connected: every cookie is unknown.
    for c in [0u32, 1, POISON_U32] {
        // SAFETY: a plain value.
        assert_eq!(hr(unsafe { cp.Unadvise(c) }), CONNECT_E_NOCONNECTION, "{c}");
    }
    let (cookie, _rec) = advise(&g);
    for c in [0u32, cookie.wrapping_add(1), u32::MAX] {
        // SAFETY: a plain value.
        assert_eq!(hr(unsafe { cp.Unadvise(c) }), CONNECT_E_NOCONNECTION, "{c}");
    }
    assert_eq!(connections(&cp).len(), 1, "still connected");
    // SAFETY: a plain value.
    assert_eq!(hr(unsafe { cp.Unadvise(cookie) }), S_OK);
    assert_eq!(
        // SAFETY: a plain value.
        hr(unsafe { cp.Unadvise(cookie) }),
        CONNECT_E_NOCONNECTION,
        "twice"
    );
    assert!(connections(&cp).is_empty());
    // Free again: a new connection with a new cookie; asynchronous calls work again.
    let (again, rec) = advise(&g);
    assert_ne!(again, cookie);
    let mut enabled = BOOL(7);
    let a2: IOPCAsyncIO2 = iface(&g);
    // SAFETY: a valid out-pointer.
    assert_eq!(hr(unsafe { a2.GetEnable(&mut enabled) }), S_OK);
    assert!(enabled.as_bool());
    drop(rec);
}

#[test]
fn an_in_process_sink_receives_on_data_change() {
    let (_s, g, h) = group_with("cp-data-change", &[LEVEL, SETPOINT, TEXT]);
    let (_cookie, rec) = advise(&g);
    let first = rec
        .wait_for(WAIT, |c| {
            matches!(c, Callback::DataChange { transaction: 0, .. })
        })
        .expect("an OnDataChange");
    let Callback::DataChange {
        group,
        master_quality,
        master_error,
        items,
        ..
    } = first
    else {
        unreachable!()
    };
    assert_eq!(group, 1, "the group's client handle");
    assert_eq!(master_error, S_OK);
    let mut handles: Vec<u32> = items.iter().map(|i| i.client_handle).collect();
    handles.sort_unstable();
    // The first update has every active item (as soon as each has a value).
    assert!(!handles.is_empty() && handles.iter().all(|c| (1..=3).contains(c)));
    if master_quality == S_OK {
        assert!(items
            .iter()
            .all(|i| i.error == S_OK && i.quality & 0xC0 == GOOD));
    }
    assert_eq!(h.len(), 3);
    // Unadvised: no further callbacks.
    let cp = data_point(&g);
    // SAFETY: a plain value.
    assert_eq!(hr(unsafe { cp.Unadvise(_cookie) }), S_OK);
    std::thread::sleep(Duration::from_millis(300)); // one already under way may still land
    let before = rec.all().len();
    std::thread::sleep(Duration::from_millis(2500));
    assert_eq!(rec.all().len(), before, "no callbacks after Unadvise");
}

#[test]
fn releasing_the_group_releases_a_sink_that_was_not_unadvised() {
    let s = opc_server();
    let g = add_group(&s, "cp-release");
    let sink = Recording::new().sink();
    let sink_unk = IUnknown::from(&sink);
    // SAFETY: a valid sink.
    let cookie = unsafe { data_point(&g).Advise(&sink_unk) }.expect("Advise");
    assert_ne!(cookie, 0);
    let weak = sink_unk.downgrade().expect("a weak reference");
    drop(sink_unk);
    drop(sink);
    assert!(weak.upgrade().is_some(), "the group holds the sink");
    assert_eq!(
        // SAFETY: a valid handle of this client's group.
        unsafe { s.RemoveGroup(g.server_handle, false.into()) },
        OPC_S_INUSE
    );
    drop(g);
    assert!(
        weak.upgrade().is_none(),
        "the last group reference released the sink"
    );
}
