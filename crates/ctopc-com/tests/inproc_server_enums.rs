//! The enumerators the server object hands out (IEnumString from BrowseOPCItemIDs and
//! CreateGroupEnumerator, IEnumUnknown from CreateGroupEnumerator, IEnumConnectionPoints),
//! in process: Next's NULL and count rules (`enums.rs`: NULL rgelt is E_POINTER, a NULL
//! pceltFetched only for one element, else E_INVALIDARG), Skip past the end, Reset, and
//! Clone keeping the position.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use ctopc_com::interfaces::*;
use std::ptr::null_mut;
use windows::Win32::System::Com::{IConnectionPointContainer, IEnumString, IEnumUnknown};
use windows::Win32::System::Variant::VARENUM;

const Z101_ID: &str = "Magazyn siarki/Zbiornik siarki ciekłej Z101";

/// The IEnumString of BrowseOPCItemIDs(OPC_LEAF) at Z101: KW_A000, KW_A001, KW_A002.
fn leaves() -> IEnumString {
    let a = server::<IOPCBrowseServerAddressSpace>();
    let to = wide(Z101_ID);
    assert_eq!(
        // SAFETY: a valid string.
        hr(unsafe { a.ChangeBrowsePosition(OPC_BROWSE_TO, pcwstr(&to)) }),
        S_OK
    );
    let empty = wide("");
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let r = unsafe { a.BrowseOPCItemIDs(OPC_LEAF, pcwstr(&empty), VARENUM(0), 0, out.as_out()) };
    assert_eq!(r, S_OK);
    out.take().unwrap().cast().unwrap()
}

/// Next(celt) into a buffer, freeing the strings: (HRESULT, fetched, strings).
fn next(e: &IEnumString, celt: u32) -> (HRESULT, u32, Vec<String>) {
    let mut buf = vec![PWSTR::null(); celt as usize];
    let mut fetched = 0xA5A5_A5A5u32;
    // SAFETY: room for `celt` strings and a fetched count.
    let r =
        unsafe { (Interface::vtable(e).Next)(e.as_raw(), celt, buf.as_mut_ptr(), &mut fetched) };
    let strings = buf
        .into_iter()
        .take(fetched.min(celt) as usize)
        // SAFETY: each fetched element is a CoTaskMem string, ours.
        .filter_map(|p| unsafe { take_wstr(p) })
        .collect();
    (r, fetched, strings)
}

#[test]
fn enum_string_next_argument_branches() {
    let e = leaves();
    let mut fetched = 0u32;
    // SAFETY: a NULL rgelt is what is tested.
    let r = unsafe { (Interface::vtable(&e).Next)(e.as_raw(), 1, null_mut(), &mut fetched) };
    assert_eq!(r, E_POINTER, "NULL rgelt");
    let mut buf = [PWSTR::null(); 2];
    // SAFETY: room for 2; a NULL pceltFetched with celt 2 is what is tested.
    let r = unsafe { (Interface::vtable(&e).Next)(e.as_raw(), 2, buf.as_mut_ptr(), null_mut()) };
    assert_eq!(r, E_INVALIDARG, "NULL pceltFetched with celt 2");
    assert!(buf.iter().all(|p| p.is_null()), "nothing handed out");
    // One element may go without pceltFetched.
    // SAFETY: room for 1.
    let r = unsafe { (Interface::vtable(&e).Next)(e.as_raw(), 1, buf.as_mut_ptr(), null_mut()) };
    assert_eq!(r, S_OK);
    // SAFETY: the fetched CoTaskMem string, ours.
    assert_eq!(unsafe { take_wstr(buf[0]) }.as_deref(), Some("KW_A000"));
    // celt 0: S_OK, nothing fetched.
    assert_eq!(next(&e, 0), (S_OK, 0, vec![]));
}

#[test]
fn enum_string_next_skip_reset_clone() {
    let e = leaves();
    assert_eq!(
        next(&e, 2),
        (S_OK, 2, vec!["KW_A000".into(), "KW_A001".into()])
    );
    // SAFETY: a valid interface.
    let c = unsafe { e.Clone() }.unwrap();
    assert_eq!(next(&e, 5), (S_FALSE, 1, vec!["KW_A002".into()]));
    assert_eq!(next(&e, 1), (S_FALSE, 0, vec![]));
    // The clone kept the position.
    assert_eq!(next(&c, 1), (S_OK, 1, vec!["KW_A002".into()]));
    // SAFETY: a valid interface.
    unsafe {
        assert_eq!(e.Reset(), Ok(()));
        assert_eq!(e.Skip(2), S_OK);
        assert_eq!(e.Skip(2), S_FALSE, "only one left");
        assert_eq!(e.Reset(), Ok(()));
    }
    assert_eq!(next(&e, 3).2, ["KW_A000", "KW_A001", "KW_A002"]);
}

#[test]
fn enum_unknown_of_groups() {
    let s = opc_server();
    let a = add_group(&s, "A");
    let _b = add_group(&s, "B");
    let mut out = OutUnk::poisoned();
    // SAFETY: valid pointers.
    let r = unsafe { s.CreateGroupEnumerator(OPC_ENUM_ALL, &IEnumUnknown::IID, out.as_out()) };
    assert_eq!(r, S_OK);
    let e: IEnumUnknown = out.take().unwrap().cast().unwrap();
    let v = Interface::vtable(&e);
    // SAFETY: NULL rgelt / NULL pceltFetched with celt 2 are what is tested.
    unsafe {
        let mut fetched = 0u32;
        assert_eq!((v.Next)(e.as_raw(), 1, null_mut(), &mut fetched), E_POINTER);
        let mut buf: [*mut std::ffi::c_void; 2] = [null_mut(); 2];
        assert_eq!(
            (v.Next)(e.as_raw(), 2, buf.as_mut_ptr().cast(), null_mut()),
            E_INVALIDARG
        );
        assert!(buf.iter().all(|p| p.is_null()));
    }
    let mut got: [Option<IUnknown>; 3] = [None, None, None];
    let mut fetched = 0u32;
    // SAFETY: room for 3 and a fetched count.
    let r = unsafe { e.Next(&mut got, Some(&mut fetched)) };
    assert_eq!((r, fetched), (S_FALSE, 2));
    let ids: Vec<_> = got
        .iter()
        .flatten()
        .map(|u| u.cast::<IUnknown>().unwrap().as_raw())
        .collect();
    assert!(ids.contains(&a.unknown.cast::<IUnknown>().unwrap().as_raw()));
    // SAFETY: a valid interface.
    unsafe {
        // (Skip's raw HRESULT: S_FALSE is a success code the Result wrapper cannot show.)
        assert_eq!((v.Skip)(e.as_raw(), 1), S_FALSE, "at the end: S_FALSE");
        e.Reset().unwrap();
        e.Skip(1).unwrap();
        let c = e.Clone().unwrap();
        let mut one: [Option<IUnknown>; 1] = [None];
        assert_eq!(c.Next(&mut one, None), S_OK, "the clone is at the second");
        assert_eq!(c.Next(&mut one, None), S_FALSE);
    }
}

#[test]
fn enum_connection_points_next_argument_branches() {
    let cpc = server::<IConnectionPointContainer>();
    // SAFETY: a valid interface.
    let e = unsafe { cpc.EnumConnectionPoints() }.unwrap();
    let v = Interface::vtable(&e);
    // SAFETY: NULL rgelt / NULL pceltFetched with celt 2 are what is tested.
    unsafe {
        let mut fetched = 0u32;
        assert_eq!((v.Next)(e.as_raw(), 1, null_mut(), &mut fetched), E_POINTER);
        let mut buf: [*mut std::ffi::c_void; 2] = [null_mut(); 2];
        assert_eq!(
            (v.Next)(e.as_raw(), 2, buf.as_mut_ptr().cast(), null_mut()),
            E_INVALIDARG
        );
        assert!(buf.iter().all(|p| p.is_null()));
        // (Skip's raw HRESULT: S_FALSE is a success code the Result wrapper cannot show.)
        assert_eq!((v.Skip)(e.as_raw(), 1), S_OK);
        assert_eq!((v.Skip)(e.as_raw(), 1), S_FALSE);
        e.Reset().unwrap();
        assert_eq!((v.Skip)(e.as_raw(), 2), S_FALSE);
    }
}

#[test]
#[ignore = "run by enum_clone_null_out_is_e_pointer in a child process"]
fn child_enum_clone_null_out() {
    if !in_child("child_enum_clone_null_out") {
        return;
    }
    let e = leaves();
    // SAFETY: a NULL out-parameter is what is tested.
    let r = unsafe { (Interface::vtable(&e).Clone)(e.as_raw(), null_mut()) };
    assert_eq!(r, E_POINTER);
}

#[test]
fn enum_clone_null_out_is_e_pointer() {
    assert!(passes_in_child("child_enum_clone_null_out"));
}
