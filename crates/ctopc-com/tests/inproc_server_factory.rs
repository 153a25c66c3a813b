//! The class factory and QueryInterface of the server object, in process: the factory's
//! own NULL and aggregation branches (`factory.rs`), and the COM identity rules of
//! QueryInterface (NULL → E_POINTER; an interface the object lacks → E_NOINTERFACE with
//! the out-parameter NULL; one IUnknown per object).
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use ctopc_com::interfaces::*;
use std::ffi::c_void;
use std::ptr::{null, null_mut};
use windows::Win32::System::Com::{IClassFactory, IConnectionPointContainer};

/// The raw CreateInstance, for NULL arguments.
unsafe fn create_raw(
    f: &IClassFactory,
    outer: *mut c_void,
    riid: *const GUID,
    ppv: *mut *mut c_void,
) -> HRESULT {
    // SAFETY: forwarded to the caller.
    unsafe { (Interface::vtable(f).CreateInstance)(f.as_raw(), outer, riid, ppv) }
}

#[test]
fn create_instance_null_out_is_e_pointer() {
    let f = factory();
    assert_eq!(
        // SAFETY: a NULL out-parameter is what is tested.
        unsafe { create_raw(&f, null_mut(), &IUnknown::IID, null_mut()) },
        E_POINTER
    );
    assert_eq!(
        // SAFETY: as above, with a NULL riid too.
        unsafe { create_raw(&f, null_mut(), null(), null_mut()) },
        E_POINTER
    );
}

#[test]
fn create_instance_failures_set_the_out_to_null() {
    let f = factory();
    let outer = new_server();
    for (what, outer, riid, expected) in [
        ("NULL riid", null_mut(), null(), E_POINTER),
        (
            "aggregation",
            outer.as_raw(),
            &IUnknown::IID as *const GUID,
            CLASS_E_NOAGGREGATION,
        ),
        (
            "an interface the server lacks",
            null_mut(),
            &IOPCItemMgt::IID as *const GUID,
            E_NOINTERFACE,
        ),
    ] {
        let mut out: *mut c_void = poison();
        // SAFETY: a valid out-pointer; `outer` NULL or a live object; riid NULL or valid.
        let r = unsafe { create_raw(&f, outer, riid, &mut out) };
        assert_eq!(r, expected, "{what}");
        assert!(out.is_null(), "{what}: out-parameter not NULL");
    }
}

#[test]
fn create_instance_success_for_each_server_interface() {
    let f = factory();
    for iid in [
        IUnknown::IID,
        IID_IOPCServer,
        IID_IOPCCommon,
        IID_IOPCBrowseServerAddressSpace,
        IID_IOPCItemProperties,
        IID_IOPCBrowse,
        IID_IOPCItemIO,
        IConnectionPointContainer::IID,
    ] {
        let mut out: *mut c_void = poison();
        assert_eq!(
            // SAFETY: valid pointers.
            unsafe { create_raw(&f, null_mut(), &iid, &mut out) },
            S_OK,
            "{iid:?}"
        );
        assert!(!out.is_null() && out as usize != POISON);
        // SAFETY: an owned interface pointer of `iid`, also an IUnknown.
        let unk = unsafe { IUnknown::from_raw(out) };
        assert!(unk.cast::<IOPCServer>().is_ok(), "{iid:?}");
    }
}

#[test]
fn lock_server_succeeds() {
    let f = factory();
    // SAFETY: plain values, balanced.
    unsafe {
        assert_eq!(hr(f.LockServer(true)), S_OK);
        assert_eq!(hr(f.LockServer(false)), S_OK);
    }
}

#[test]
fn query_interface_null_arguments_are_e_pointer() {
    let unk = new_server();
    let mut out: *mut c_void = null_mut();
    // SAFETY: NULL arguments are what is tested; the others valid.
    unsafe {
        assert_eq!(raw_query(&unk, null(), &mut out), E_POINTER, "NULL iid");
        assert_eq!(
            raw_query(&unk, &IID_IOPCServer, null_mut()),
            E_POINTER,
            "NULL out"
        );
        assert_eq!(raw_query(&unk, null(), null_mut()), E_POINTER, "both NULL");
    }
    assert!(out.is_null());
    // Through another interface of the object too.
    let common: IOPCCommon = unk.cast().unwrap();
    let common_unk: &IUnknown = &common.into();
    assert_eq!(
        // SAFETY: as above.
        unsafe { raw_query(common_unk, null(), &mut out) },
        E_POINTER
    );
}

#[test]
fn query_interface_unknown_iid_is_e_nointerface_with_null_out() {
    let unk = new_server();
    for iid in [
        IID_IOPCItemMgt,
        IID_IOPCServerPublicGroups,
        IID_IOPCShutdown,
        IID_IOPCDataCallback,
        GUID::from_u128(0x01234567_89ab_cdef_0123_456789abcdef),
    ] {
        let mut out: *mut c_void = poison();
        assert_eq!(
            // SAFETY: valid pointers.
            unsafe { raw_query(&unk, &iid, &mut out) },
            E_NOINTERFACE,
            "{iid:?}"
        );
        assert!(out.is_null(), "{iid:?}: out-parameter not NULL");
    }
}

#[test]
fn query_interface_keeps_one_identity() {
    let unk = new_server();
    let via = |i: &IUnknown| i.cast::<IUnknown>().unwrap().as_raw();
    let base = via(&unk);
    let server: IOPCServer = unk.cast().unwrap();
    let browse: IOPCBrowse = server.cast().unwrap();
    let cpc: IConnectionPointContainer = browse.cast().unwrap();
    assert_eq!(via(&server.cast().unwrap()), base);
    assert_eq!(via(&browse.cast().unwrap()), base);
    assert_eq!(via(&cpc.cast().unwrap()), base);
    // Round trip: every interface reaches every other.
    assert!(cpc.cast::<IOPCItemIO>().is_ok());
}
