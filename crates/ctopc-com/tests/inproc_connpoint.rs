//! The server object's IConnectionPointContainer and its IOPCShutdown connection point,
//! in process (no proxy): NULL arguments, unknown IIDs and cookies, sinks of the wrong
//! interface, the one-connection limit, and the success paths. `connpoint.rs` says the
//! rules ("connection points to the letter"); the COM contracts name E_POINTER for NULL
//! pointers and NULL for interface out-parameters of a failed call.
//!
//! Calls that would write through a NULL out-parameter run in a child process
//! (`common::passes_in_child`), so a crash fails one test instead of the binary.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use ctopc_com::interfaces::*;
use std::ffi::c_void;
use std::ptr::{null, null_mut};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use windows::core::implement;
use windows::Win32::System::Com::{
    IConnectionPoint, IConnectionPointContainer, IEnumConnectionPoints, IEnumConnections,
    CONNECTDATA,
};
use windows::Win32::System::Ole::{
    CONNECT_E_ADVISELIMIT, CONNECT_E_CANNOTCONNECT, CONNECT_E_NOCONNECTION,
};

/// A client's IOPCShutdown that counts the requests.
#[implement(IOPCShutdown)]
struct Sink {
    calls: Arc<AtomicUsize>,
}

impl IOPCShutdown_Impl for Sink_Impl {
    unsafe fn ShutdownRequest(&self, _reason: PCWSTR) -> windows::core::Result<()> {
        self.calls.fetch_add(1, Ordering::SeqCst);
        Ok(())
    }
}

fn sink() -> IUnknown {
    let s: IOPCShutdown = Sink {
        calls: Arc::default(),
    }
    .into();
    s.cast().unwrap()
}

fn container() -> IConnectionPointContainer {
    server::<IConnectionPointContainer>()
}

fn shutdown_point(c: &IConnectionPointContainer) -> IConnectionPoint {
    // SAFETY: a valid IID pointer.
    unsafe { c.FindConnectionPoint(&IID_IOPCShutdown) }.expect("the IOPCShutdown point")
}

fn identity(u: &impl Interface) -> *mut c_void {
    u.cast::<IUnknown>().unwrap().as_raw()
}

/// The raw FindConnectionPoint, for NULL arguments.
unsafe fn find_raw(
    c: &IConnectionPointContainer,
    riid: *const GUID,
    out: *mut *mut c_void,
) -> HRESULT {
    // SAFETY: forwarded to the caller.
    unsafe { (Interface::vtable(c).FindConnectionPoint)(c.as_raw(), riid, out) }
}

// ---- IConnectionPointContainer ---------------------------------------------------------

#[test]
fn enum_connection_points_lists_the_shutdown_point() {
    let c = container();
    // SAFETY: a valid interface.
    let e: IEnumConnectionPoints = unsafe { c.EnumConnectionPoints() }.unwrap();
    let mut cps = [None, None];
    let mut fetched = U32_SENTINEL;
    // SAFETY: room for 2 elements and a fetched count.
    let r = unsafe { e.Next(&mut cps, &mut fetched) };
    assert_eq!((r, fetched), (S_FALSE, 1), "one point only");
    let cp = cps[0].take().expect("the point");
    assert!(cps[1].is_none());
    assert_eq!(
        // SAFETY: a valid interface.
        unsafe { cp.GetConnectionInterface() }.unwrap(),
        IID_IOPCShutdown
    );
}

const U32_SENTINEL: u32 = 0xA5A5_A5A5;

#[test]
fn find_connection_point_null_riid_is_e_pointer() {
    let c = container();
    // SAFETY: a NULL REFIID is what is tested.
    assert_eq!(code(&unsafe { c.FindConnectionPoint(null()) }), E_POINTER);
}

#[test]
fn find_connection_point_unknown_iid_is_connect_e_noconnection() {
    let c = container();
    for iid in [IID_IOPCDataCallback, IUnknown::IID, IID_IOPCServer] {
        // SAFETY: a valid IID pointer.
        let r = unsafe { c.FindConnectionPoint(&iid) };
        assert_eq!(code(&r), CONNECT_E_NOCONNECTION, "{iid:?}");
    }
}

#[test]
fn find_connection_point_failures_set_the_out_to_null() {
    let c = container();
    for (what, riid) in [
        ("NULL riid", null()),
        ("unknown IID", &IID_IOPCDataCallback as *const GUID),
    ] {
        let mut out: *mut c_void = poison();
        // SAFETY: a valid out-pointer; the REFIID NULL or valid.
        let r = unsafe { find_raw(&c, riid, &mut out) };
        assert!(r.is_err(), "{what}");
        assert!(out.is_null(), "{what}: out-parameter not NULL");
    }
}

#[test]
#[ignore = "run by find_connection_point_null_out_is_e_pointer in a child process"]
fn child_find_connection_point_null_out() {
    if !in_child("child_find_connection_point_null_out") {
        return;
    }
    let c = container();
    // SAFETY: a NULL out-parameter is what is tested.
    let r = unsafe { find_raw(&c, &IID_IOPCShutdown, null_mut()) };
    assert_eq!(r, E_POINTER);
}

#[test]
fn find_connection_point_null_out_is_e_pointer() {
    assert!(passes_in_child("child_find_connection_point_null_out"));
}

#[test]
#[ignore = "run by enum_connection_points_null_out_is_e_pointer in a child process"]
fn child_enum_connection_points_null_out() {
    if !in_child("child_enum_connection_points_null_out") {
        return;
    }
    let c = container();
    // SAFETY: a NULL out-parameter is what is tested.
    let r = unsafe { (Interface::vtable(&c).EnumConnectionPoints)(c.as_raw(), null_mut()) };
    assert_eq!(r, E_POINTER);
}

#[test]
fn enum_connection_points_null_out_is_e_pointer() {
    assert!(passes_in_child("child_enum_connection_points_null_out"));
}

// ---- IConnectionPoint of IOPCShutdown --------------------------------------------------

#[test]
fn the_point_names_its_interface_and_container() {
    let c = container();
    let cp = shutdown_point(&c);
    assert_eq!(
        // SAFETY: a valid interface.
        unsafe { cp.GetConnectionInterface() }.unwrap(),
        IID_IOPCShutdown
    );
    // SAFETY: a valid interface.
    let back = unsafe { cp.GetConnectionPointContainer() }.unwrap();
    assert_eq!(identity(&back), identity(&c));
}

#[test]
fn advise_argument_branches() {
    let c = container();
    let cp = shutdown_point(&c);
    // NULL sink: E_POINTER.
    let mut cookie = U32_SENTINEL;
    // SAFETY: a NULL sink is what is tested; a valid out-pointer.
    let r = unsafe { (Interface::vtable(&cp).Advise)(cp.as_raw(), null_mut(), &mut cookie) };
    assert_eq!(r, E_POINTER);
    // A sink without IOPCShutdown: CONNECT_E_CANNOTCONNECT.
    let not_a_sink = new_server();
    assert_eq!(
        // SAFETY: a valid interface.
        code(&unsafe { cp.Advise(&not_a_sink) }),
        CONNECT_E_CANNOTCONNECT
    );
    // One connection per point.
    let s1 = sink();
    // SAFETY: a valid interface.
    let c1 = unsafe { cp.Advise(&s1) }.expect("Advise");
    assert_ne!(c1, 0, "cookies are non-zero");
    let s2 = sink();
    // SAFETY: a valid interface.
    assert_eq!(code(&unsafe { cp.Advise(&s2) }), CONNECT_E_ADVISELIMIT);
    // SAFETY: plain value.
    assert_eq!(hr(unsafe { cp.Unadvise(c1) }), S_OK);
    // SAFETY: a valid interface.
    let c2 = unsafe { cp.Advise(&s2) }.expect("Advise after Unadvise");
    assert_ne!(c2, c1);
    // SAFETY: plain value.
    assert_eq!(hr(unsafe { cp.Unadvise(c2) }), S_OK);
}

#[test]
#[ignore = "run by advise_null_cookie_is_e_pointer in a child process"]
fn child_advise_null_cookie() {
    if !in_child("child_advise_null_cookie") {
        return;
    }
    let cp = shutdown_point(&container());
    let s = sink();
    // SAFETY: a NULL out-parameter is what is tested.
    let r = unsafe { (Interface::vtable(&cp).Advise)(cp.as_raw(), s.as_raw(), null_mut()) };
    assert_eq!(r, E_POINTER);
}

#[test]
fn advise_null_cookie_is_e_pointer() {
    assert!(passes_in_child("child_advise_null_cookie"));
}

#[test]
fn unadvise_unknown_cookies_are_connect_e_noconnection() {
    let c = container();
    let cp = shutdown_point(&c);
    for cookie in [0u32, 1, 0x7FFF_FFFF, u32::MAX] {
        assert_eq!(
            // SAFETY: plain value.
            hr(unsafe { cp.Unadvise(cookie) }),
            CONNECT_E_NOCONNECTION,
            "{cookie}"
        );
    }
    let s = sink();
    // SAFETY: a valid interface.
    let cookie = unsafe { cp.Advise(&s) }.unwrap();
    // A cookie of another server object's point is unknown here.
    let other = shutdown_point(&container());
    assert_eq!(
        // SAFETY: plain value.
        hr(unsafe { other.Unadvise(cookie) }),
        CONNECT_E_NOCONNECTION
    );
    // SAFETY: plain value.
    assert_eq!(hr(unsafe { cp.Unadvise(cookie) }), S_OK);
    assert_eq!(
        // SAFETY: plain value.
        hr(unsafe { cp.Unadvise(cookie) }),
        CONNECT_E_NOCONNECTION,
        "twice"
    );
}

fn connections(cp: &IConnectionPoint) -> Vec<(u32, IUnknown)> {
    // SAFETY: a valid interface.
    let e: IEnumConnections = unsafe { cp.EnumConnections() }.expect("EnumConnections");
    let mut v = Vec::new();
    loop {
        let mut one = [CONNECTDATA::default()];
        let mut fetched = U32_SENTINEL;
        // SAFETY: room for one element and a fetched count.
        let r = unsafe { e.Next(&mut one, &mut fetched) };
        let [cd] = one;
        let unk = std::mem::ManuallyDrop::into_inner(cd.pUnk);
        if r == S_FALSE {
            assert_eq!(fetched, 0);
            assert!(unk.is_none());
            return v;
        }
        assert_eq!((r, fetched), (S_OK, 1));
        v.push((cd.dwCookie, unk.expect("the sink")));
        assert!(v.len() <= 1, "at most one connection");
    }
}

#[test]
fn enum_connections_lists_the_connection() {
    let c = container();
    let cp = shutdown_point(&c);
    assert!(connections(&cp).is_empty());
    let s = sink();
    // SAFETY: a valid interface.
    let cookie = unsafe { cp.Advise(&s) }.unwrap();
    let list = connections(&cp);
    assert_eq!(list.len(), 1);
    assert_eq!(list[0].0, cookie);
    assert_eq!(identity(&list[0].1), identity(&s));
    // Another FindConnectionPoint sees the same connection (the slot is the server's).
    assert_eq!(connections(&shutdown_point(&c))[0].0, cookie);
    // SAFETY: plain value.
    assert_eq!(hr(unsafe { cp.Unadvise(cookie) }), S_OK);
    assert!(connections(&cp).is_empty());
}

#[test]
#[ignore = "run by connection_point_null_outs_are_e_pointer in a child process"]
fn child_connection_point_null_outs() {
    if !in_child("child_connection_point_null_outs") {
        return;
    }
    let cp = shutdown_point(&container());
    let v = Interface::vtable(&cp);
    // SAFETY: NULL out-parameters are what is tested.
    unsafe {
        assert_eq!(
            (v.GetConnectionInterface)(cp.as_raw(), null_mut()),
            E_POINTER
        );
        assert_eq!(
            (v.GetConnectionPointContainer)(cp.as_raw(), null_mut()),
            E_POINTER
        );
        assert_eq!((v.EnumConnections)(cp.as_raw(), null_mut()), E_POINTER);
    }
}

#[test]
fn connection_point_null_outs_are_e_pointer() {
    assert!(passes_in_child("child_connection_point_null_outs"));
}
