//! The server browser object (`src/lib.rs`) in process, without the proxy: the
//! argument checks a proxy would not let through (NULL out-parameters, a NULL category
//! array with a count), out-parameters cleared on failure, and the enumerator's NULL
//! checks. Listing itself is tested end to end (tests/tests/server_list.rs).
#![cfg(windows)]
// Test code: a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_com::interfaces::*;
use ctopc_com::lifetime::Lifetime;
use opc_server_list::create_instance;
use std::ptr::{null, null_mut};
use windows::core::{Interface, GUID, PCWSTR, PWSTR};
use windows::Win32::Foundation::{E_INVALIDARG, E_POINTER, REGDB_E_CLASSNOTREG};
use windows::Win32::System::Com::{CoInitializeEx, IEnumGUID, COINIT_MULTITHREADED};

fn browser() -> (IOPCServerList, IOPCServerList2) {
    // SAFETY: joins the MTA for this test thread (never uninitialised: the process ends).
    let _ = unsafe { CoInitializeEx(None, COINIT_MULTITHREADED) };
    let unknown = create_instance(&Lifetime::new()).unwrap();
    (unknown.cast().unwrap(), unknown.cast().unwrap())
}

#[test]
fn null_arguments_are_e_invalidarg_and_outs_stay_cleared() {
    let (list, list2) = browser();
    let mut e: Option<IEnumGUID> = None;
    // SAFETY: a NULL array with a count of 1 is what is tested.
    let r = unsafe { list.EnumClassesOfCategories(1, null(), 0, null(), &mut e) };
    assert_eq!(r.unwrap_err().code(), E_INVALIDARG);
    assert!(e.is_none());
    // SAFETY: a NULL out-parameter is what is tested.
    let r = unsafe { list.EnumClassesOfCategories(0, null(), 0, null(), null_mut()) };
    assert_eq!(r.unwrap_err().code(), E_INVALIDARG);
    let mut e2: Option<IOPCEnumGUID> = None;
    // SAFETY: as above, through IOPCServerList2.
    let r = unsafe { list2.EnumClassesOfCategories(0, null(), 1, null(), &mut e2) };
    assert_eq!(r.unwrap_err().code(), E_INVALIDARG);
    assert!(e2.is_none());

    let (mut p, mut u, mut v) = (PWSTR::null(), PWSTR::null(), PWSTR::null());
    // SAFETY: a NULL CLSID is what is tested.
    let r = unsafe { list2.GetClassDetails(null(), &mut p, &mut u, &mut v) };
    assert_eq!(r.unwrap_err().code(), E_INVALIDARG);
    assert!(p.is_null() && u.is_null() && v.is_null());
    let unknown = GUID::from_u128(0x5eb00c1a_beef_4e5e_9a11_000000000000);
    // SAFETY: a NULL sibling out-parameter is what is tested.
    let r = unsafe { list.GetClassDetails(&unknown, &mut p, null_mut()) };
    assert_eq!(r.unwrap_err().code(), E_INVALIDARG);
    assert!(p.is_null());
    // SAFETY: valid arguments, an unregistered class.
    let r = unsafe { list.GetClassDetails(&unknown, &mut p, &mut u) };
    assert_eq!(r.unwrap_err().code(), REGDB_E_CLASSNOTREG);
    assert!(p.is_null() && u.is_null());

    let mut clsid = GUID::from_u128(1);
    // SAFETY: a NULL ProgID is what is tested.
    let r = unsafe { list.CLSIDFromProgID(PCWSTR::null(), &mut clsid) };
    assert_eq!(r.unwrap_err().code(), E_INVALIDARG);
    assert_eq!(clsid, GUID::zeroed(), "cleared first");
    let name: Vec<u16> = "X.1".encode_utf16().chain([0]).collect();
    // SAFETY: a NULL out-parameter is what is tested.
    let r = unsafe { list.CLSIDFromProgID(PCWSTR(name.as_ptr()), null_mut()) };
    assert_eq!(r.unwrap_err().code(), E_INVALIDARG);
}

#[test]
fn the_enumerators_check_their_pointers() {
    let (list, list2) = browser();
    let mut e: Option<IEnumGUID> = None;
    // SAFETY: an empty category list: an empty enumerator.
    unsafe { list.EnumClassesOfCategories(0, null(), 0, null(), &mut e) }.unwrap();
    let e = e.unwrap();
    let raw = Interface::vtable(&e);
    let mut fetched = 7u32;
    // SAFETY: a NULL array is what is tested.
    let hr = unsafe { (raw.Next)(e.as_raw(), 1, null_mut(), &mut fetched) };
    assert_eq!(hr, E_POINTER);
    // SAFETY: a NULL out-parameter is what is tested.
    let hr = unsafe { (raw.Clone)(e.as_raw(), null_mut()) };
    assert_eq!(hr, E_POINTER);
    let mut e2: Option<IOPCEnumGUID> = None;
    // SAFETY: as above, the OPC enumerator.
    unsafe { list2.EnumClassesOfCategories(0, null(), 0, null(), &mut e2) }.unwrap();
    let e2 = e2.unwrap();
    // SAFETY: a NULL out-parameter is what is tested.
    let r = unsafe { e2.Clone(null_mut()) };
    assert_eq!(r.unwrap_err().code(), E_POINTER);
    let mut g = GUID::zeroed();
    let mut n = 5u32;
    // SAFETY: room for one GUID; an empty list gives none.
    let hr = unsafe { e2.Next(1, &mut g, &mut n) };
    assert_eq!((hr.0, n), (1, 0), "S_FALSE, nothing fetched");
    // Both interfaces are one object.
    assert!(e2.cast::<IEnumGUID>().is_ok());
}
