//! IOPCBrowseServerAddressSpace and IOPCBrowse of the server object, in process (no
//! proxy): every NULL pointer, count of 0 and enumeration value outside the IDL's reaches
//! the server and answers its exact HRESULT, with out-parameters cleared on failure; and
//! the success paths over the embedded demo plant. The rules are the module docs of
//! `crates/ctopc-com/src/da/server.rs` and `server/browse.rs`.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use ctopc_com::interfaces::*;
use opc_client::{enum_strings, BrowseArgs};
use std::ptr::{null, null_mut};
use windows::Win32::Foundation::E_NOTIMPL;
use windows::Win32::System::Com::IEnumString;
use windows::Win32::System::Variant::VARENUM;

const SULPHUR: &str = "Magazyn siarki";
const Z101: &str = "Zbiornik siarki ciekłej Z101";
const Z101_ID: &str = "Magazyn siarki/Zbiornik siarki ciekłej Z101";
const U32_POISON: u32 = 0xA5A5_A5A5;

fn space() -> IOPCBrowseServerAddressSpace {
    server::<IOPCBrowseServerAddressSpace>()
}

fn item_id_at(a: &IOPCBrowseServerAddressSpace, data_id: &str) -> (HRESULT, Option<String>) {
    let s = wide(data_id);
    let mut p = PWSTR(poison());
    // SAFETY: valid pointers.
    let r = hr(unsafe { a.GetItemID(pcwstr(&s), &mut p) });
    assert_ne!(
        p.0 as usize, POISON,
        "GetItemID did not write its out-parameter"
    );
    // SAFETY: NULL or a CoTaskMem string handed out by the call.
    (r, unsafe { take_wstr(p) })
}

fn position(a: &IOPCBrowseServerAddressSpace) -> String {
    let (r, id) = item_id_at(a, "");
    assert_eq!(r, S_OK);
    id.expect("the position's item ID")
}

fn change(a: &IOPCBrowseServerAddressSpace, d: OPCBROWSEDIRECTION, name: &str) -> HRESULT {
    let s = wide(name);
    // SAFETY: a valid string.
    hr(unsafe { a.ChangeBrowsePosition(d, pcwstr(&s)) })
}

// ---- QueryOrganization ----------------------------------------------------------------

#[test]
fn query_organization_null_and_success() {
    let a = space();
    // SAFETY: a NULL out-parameter is what is tested.
    assert_eq!(hr(unsafe { a.QueryOrganization(null_mut()) }), E_INVALIDARG);
    let mut ns = OPCNAMESPACETYPE(0x55);
    // SAFETY: a valid out-pointer.
    assert_eq!(hr(unsafe { a.QueryOrganization(&mut ns) }), S_OK);
    assert_eq!(ns, OPC_NS_HIERARCHIAL);
}

// ---- ChangeBrowsePosition --------------------------------------------------------------

#[test]
fn change_browse_position_argument_branches() {
    let a = space();
    assert_eq!(change(&a, OPC_BROWSE_DOWN, SULPHUR), S_OK);
    for d in [0, 4, -1] {
        assert_eq!(
            change(&a, OPCBROWSEDIRECTION(d), ""),
            E_INVALIDARG,
            "direction {d}"
        );
    }
    for d in [OPC_BROWSE_UP, OPC_BROWSE_DOWN, OPC_BROWSE_TO] {
        // SAFETY: a NULL [in, string] is what is tested.
        let r = hr(unsafe { a.ChangeBrowsePosition(d, PCWSTR::null()) });
        assert_eq!(r, E_INVALIDARG, "{d:?} with NULL");
    }
    assert_eq!(change(&a, OPC_BROWSE_DOWN, "Nie ma"), E_INVALIDARG);
    assert_eq!(
        change(&a, OPC_BROWSE_TO, "Nie ma takiej gałęzi"),
        E_INVALIDARG
    );
    assert_eq!(
        change(&a, OPC_BROWSE_TO, "KW_A000"),
        E_INVALIDARG,
        "TO a leaf"
    );
    // Failures leave the position where it was.
    assert_eq!(position(&a), SULPHUR);
}

#[test]
fn change_browse_position_success() {
    let a = space();
    assert_eq!(position(&a), "");
    assert_eq!(change(&a, OPC_BROWSE_UP, ""), E_FAIL, "UP at the root");
    assert_eq!(change(&a, OPC_BROWSE_DOWN, SULPHUR), S_OK);
    assert_eq!(change(&a, OPC_BROWSE_DOWN, Z101), S_OK);
    assert_eq!(position(&a), Z101_ID);
    assert_eq!(
        change(&a, OPC_BROWSE_DOWN, "KW_A000"),
        E_INVALIDARG,
        "a leaf"
    );
    assert_eq!(change(&a, OPC_BROWSE_UP, ""), S_OK);
    assert_eq!(position(&a), SULPHUR);
    assert_eq!(change(&a, OPC_BROWSE_TO, Z101_ID), S_OK);
    assert_eq!(position(&a), Z101_ID);
    assert_eq!(change(&a, OPC_BROWSE_TO, ""), S_OK);
    assert_eq!(position(&a), "");
    // Each server object has its own position.
    assert_eq!(change(&a, OPC_BROWSE_TO, Z101_ID), S_OK);
    assert_eq!(position(&space()), "");
}

// ---- BrowseOPCItemIDs ------------------------------------------------------------------

fn browse_ids(
    a: &IOPCBrowseServerAddressSpace,
    t: OPCBROWSETYPE,
    filter: PCWSTR,
    rights: u32,
) -> (HRESULT, OutUnk) {
    let mut out = OutUnk::poisoned();
    // SAFETY: `filter` is NULL or a valid string; a valid out-pointer.
    let r = unsafe { a.BrowseOPCItemIDs(t, filter, VARENUM(0), rights, out.as_out()) };
    (r, out)
}

#[test]
fn browse_opc_item_ids_argument_branches() {
    let a = space();
    let empty = wide("");
    let bad_filter = wide("[a");
    // SAFETY: a NULL out-parameter is what is tested.
    let r = unsafe { a.BrowseOPCItemIDs(OPC_FLAT, pcwstr(&empty), VARENUM(0), 0, null_mut()) };
    assert_eq!(r, E_INVALIDARG, "NULL ppIEnumString");
    let cases: [(&str, OPCBROWSETYPE, PCWSTR, u32, HRESULT); 7] = [
        ("type 0", OPCBROWSETYPE(0), pcwstr(&empty), 0, E_INVALIDARG),
        ("type 4", OPCBROWSETYPE(4), pcwstr(&empty), 0, E_INVALIDARG),
        (
            "type -1",
            OPCBROWSETYPE(-1),
            pcwstr(&empty),
            0,
            E_INVALIDARG,
        ),
        (
            "unknown rights bits",
            OPC_LEAF,
            pcwstr(&empty),
            4,
            E_INVALIDARG,
        ),
        (
            "every rights bit",
            OPC_LEAF,
            pcwstr(&empty),
            u32::MAX,
            E_INVALIDARG,
        ),
        ("NULL filter", OPC_LEAF, PCWSTR::null(), 0, E_INVALIDARG),
        (
            "bad filter",
            OPC_LEAF,
            pcwstr(&bad_filter),
            0,
            OPC_E_INVALIDFILTER,
        ),
    ];
    for (what, t, f, rights, expected) in cases {
        let (r, out) = browse_ids(&a, t, f, rights);
        assert_eq!(r, expected, "{what}");
        assert!(out.is_null(), "{what}: out-parameter not cleared");
    }
}

/// The enumerator of BrowseOPCItemIDs hands out thousands of strings in one `Next`
/// (S_FALSE with the rest when fewer remain), the same strings as one at a time; a clone
/// shares the listing at its position; Skip and Reset move through it.
#[test]
fn browse_opc_item_ids_enumerator_hands_out_large_batches() {
    let a = space();
    let f = wide("");
    let (r, mut out) = browse_ids(&a, OPC_FLAT, pcwstr(&f), 0);
    assert_eq!(r, S_OK);
    let e = out.take().unwrap().cast::<IEnumString>().unwrap();
    let next = |e: &IEnumString, celt: usize| {
        let mut batch = vec![PWSTR::null(); celt];
        let mut fetched = U32_POISON;
        // SAFETY: `batch` has room for `celt` strings; a valid pceltFetched.
        let r = unsafe { e.Next(&mut batch, Some(&mut fetched)) };
        let got: Vec<String> = batch[..fetched as usize]
            .iter()
            // SAFETY: CoTaskMem strings handed out by the call, each taken once.
            .map(|p| unsafe { take_wstr(*p) }.unwrap())
            .collect();
        (r, got)
    };
    let mut one_by_one = Vec::new();
    loop {
        let (r, got) = next(&e, 1);
        one_by_one.extend(got);
        if r != S_OK {
            break;
        }
    }
    assert!(one_by_one.len() > 200, "{}", one_by_one.len());
    // SAFETY: no arguments.
    assert_eq!(hr(unsafe { e.Reset() }), S_OK);
    let (r, all) = next(&e, 4096);
    assert_eq!(r, S_FALSE, "fewer than 4096 remained");
    assert_eq!(all, one_by_one);
    assert_eq!(next(&e, 4096), (S_FALSE, vec![]));

    // SAFETY: no arguments.
    assert_eq!(hr(unsafe { e.Reset() }), S_OK);
    let (r, first) = next(&e, 10);
    assert_eq!(r, S_OK);
    assert_eq!(first, all[..10]);
    // SAFETY: no arguments.
    let c = unsafe { e.Clone() }.unwrap();
    let (_, rest) = next(&c, 4096);
    assert_eq!(rest, all[10..], "the clone starts where the original was");
    let (_, rest) = next(&e, 4096);
    assert_eq!(rest, all[10..], "the original kept its own position");
    // SAFETY: no arguments.
    unsafe {
        assert_eq!(hr(c.Reset()), S_OK);
        assert_eq!(c.Skip(5), S_OK);
        assert_eq!(c.Skip(100_000), S_FALSE);
    }
    assert_eq!(next(&c, 1), (S_FALSE, vec![]));
}

#[test]
fn browse_opc_item_ids_success() {
    let a = space();
    let names = |t: OPCBROWSETYPE, filter: &str, rights: u32| {
        let f = wide(filter);
        let (r, mut out) = browse_ids(&a, t, pcwstr(&f), rights);
        let e = out.take().expect("an enumerator, also when empty");
        (r, enum_strings(&e.cast::<IEnumString>().unwrap()).unwrap())
    };
    let (r, root) = names(OPC_BRANCH, "", 0);
    assert_eq!(r, S_OK);
    assert!(root.iter().any(|n| n == SULPHUR), "{root:?}");
    // Only branches at the root: S_FALSE with an empty enumerator.
    assert_eq!(names(OPC_LEAF, "", 0), (S_FALSE, vec![]));
    let (r, flat) = names(OPC_FLAT, "", OPC_READABLE | OPC_WRITEABLE);
    assert_eq!(r, S_OK);
    assert!(flat.len() >= 200, "{}", flat.len());
    assert_eq!(change(&a, OPC_BROWSE_TO, Z101_ID), S_OK);
    assert_eq!(
        names(OPC_LEAF, "", OPC_READABLE),
        (
            S_OK,
            vec!["KW_A000".into(), "KW_A001".into(), "KW_A002".into()]
        )
    );
    assert_eq!(names(OPC_LEAF, "*[12]", 0).1, ["KW_A001", "KW_A002"]);
    assert_eq!(names(OPC_LEAF, "nic*", 0), (S_FALSE, vec![]));
    // The access-rights filter applies: Z101's variables are read-only.
    assert_eq!(names(OPC_LEAF, "", OPC_WRITEABLE), (S_FALSE, vec![]));
    assert_eq!(change(&a, OPC_BROWSE_TO, ""), S_OK);
    let (_, writable) = names(OPC_FLAT, "", OPC_WRITEABLE);
    assert!(!writable.is_empty() && writable.len() < flat.len());
    assert!(writable.iter().any(|i| i == "KW_A110"));
    assert!(!writable.iter().any(|i| i == "KW_A000"));
}

// ---- GetItemID -------------------------------------------------------------------------

#[test]
fn get_item_id_argument_branches() {
    let a = space();
    let empty = wide("");
    assert_eq!(
        // SAFETY: a NULL out-parameter is what is tested.
        hr(unsafe { a.GetItemID(pcwstr(&empty), null_mut()) }),
        E_INVALIDARG
    );
    let mut p = PWSTR(poison());
    assert_eq!(
        // SAFETY: a NULL [in, string] is what is tested; a valid out-pointer.
        hr(unsafe { a.GetItemID(PCWSTR::null(), &mut p) }),
        E_INVALIDARG
    );
    assert!(p.is_null(), "out-parameter not cleared");
    assert_eq!(change(&a, OPC_BROWSE_TO, Z101_ID), S_OK);
    assert_eq!(item_id_at(&a, "KW_A999"), (E_INVALIDARG, None));
}

#[test]
fn get_item_id_success() {
    let a = space();
    assert_eq!(item_id_at(&a, ""), (S_OK, Some(String::new())));
    assert_eq!(item_id_at(&a, SULPHUR), (S_OK, Some(SULPHUR.into())));
    assert_eq!(change(&a, OPC_BROWSE_TO, Z101_ID), S_OK);
    assert_eq!(item_id_at(&a, "KW_A000"), (S_OK, Some("KW_A000".into())));
    assert_eq!(item_id_at(&a, ""), (S_OK, Some(Z101_ID.into())));
}

// ---- BrowseAccessPaths -----------------------------------------------------------------

#[test]
fn browse_access_paths_branches() {
    let a = space();
    let id = wide("KW_A000");
    assert_eq!(
        // SAFETY: a NULL out-parameter is what is tested.
        unsafe { a.BrowseAccessPaths(pcwstr(&id), null_mut()) },
        E_INVALIDARG
    );
    let mut out = OutUnk::poisoned();
    assert_eq!(
        // SAFETY: a NULL [in, string] is what is tested; a valid out-pointer.
        unsafe { a.BrowseAccessPaths(PCWSTR::null(), out.as_out()) },
        E_INVALIDARG
    );
    assert!(out.is_null());
    // asix channels are not browsable: E_NOTIMPL, as the original; no enumerator.
    let mut out = OutUnk::poisoned();
    assert_eq!(
        // SAFETY: valid pointers.
        unsafe { a.BrowseAccessPaths(pcwstr(&id), out.as_out()) },
        E_NOTIMPL
    );
    assert!(out.is_null());
}

// ---- IOPCBrowse::GetProperties ---------------------------------------------------------

/// GetProperties with raw arguments; the out-parameter pre-filled with poison.
unsafe fn get_properties_raw(
    b: &IOPCBrowse,
    count: u32,
    ids: *const PCWSTR,
    property_count: u32,
    property_ids: *const u32,
    out: *mut *mut OPCITEMPROPERTIES,
) -> HRESULT {
    // SAFETY: forwarded to the caller.
    unsafe { b.GetProperties(count, ids, false.into(), property_count, property_ids, out) }
}

#[test]
fn get_properties_argument_branches() {
    let b = server::<IOPCBrowse>();
    let id = wide("KW_A000");
    let ids = [pcwstr(&id)];
    // SAFETY: a NULL out-parameter is what is tested.
    let r = unsafe { get_properties_raw(&b, 1, ids.as_ptr(), 0, null(), null_mut()) };
    assert_eq!(r, E_INVALIDARG, "NULL ppItemProperties");
    let cases: [(&str, u32, *const PCWSTR, u32, *const u32); 3] = [
        ("count 0", 0, ids.as_ptr(), 0, null()),
        ("NULL item IDs", 1, null(), 0, null()),
        ("NULL property IDs", 1, ids.as_ptr(), 2, null()),
    ];
    for (what, n, p, pn, pp) in cases {
        let mut out: *mut OPCITEMPROPERTIES = poison();
        // SAFETY: every pointer is NULL or valid for its count.
        let r = unsafe { get_properties_raw(&b, n, p, pn, pp, &mut out) };
        assert_eq!(r, E_INVALIDARG, "{what}");
        assert!(out.is_null(), "{what}: out-parameter not cleared");
    }
    // A property count of 0 with NULL IDs means every property.
    let c = client();
    let (r, items) = c.get_properties(&["KW_A000"], false, &[]).unwrap();
    assert_eq!(r, S_OK);
    assert!(items[0].properties.len() >= 6);
}

#[test]
fn get_properties_per_item_errors() {
    let b = server::<IOPCBrowse>();
    let good = wide("KW_A000");
    let unknown = wide("KW_A999");
    let ids = [pcwstr(&good), PCWSTR::null(), pcwstr(&unknown)];
    let props = [1u32, 101];
    let mut out: *mut OPCITEMPROPERTIES = poison();
    // SAFETY: valid arrays of their counts (a NULL element is what is tested).
    let r = unsafe { get_properties_raw(&b, 3, ids.as_ptr(), 2, props.as_ptr(), &mut out) };
    assert_eq!(r, S_FALSE);
    assert!(!out.is_null() && out as usize != POISON);
    // SAFETY: a CoTaskMem array of 3 OPCITEMPROPERTIES handed out by the call.
    let items = unsafe { take_array(out, 3) };
    let errors: Vec<HRESULT> = items.iter().map(|i| i.hrErrorID).collect();
    assert_eq!(errors, [S_OK, OPC_E_INVALIDITEMID, OPC_E_UNKNOWNITEMID]);
    assert_eq!(items[0].dwNumProperties, 2);
    for it in &items[1..] {
        assert_eq!(it.dwNumProperties, 0);
        // (An empty CoTaskMem block or NULL: the client frees it either way.)
        // SAFETY: NULL or a CoTaskMem block of the failed item, ours.
        unsafe { task_free(it.pItemProperties) };
    }
    // SAFETY: the first element's properties: a CoTaskMem array of 2, ours; each
    // member is freed once, then the array.
    unsafe {
        let p = std::slice::from_raw_parts_mut(items[0].pItemProperties, 2);
        for prop in p.iter_mut() {
            assert_eq!(prop.hrErrorID, S_OK);
            take_wstr(prop.szItemID);
            take_wstr(prop.szDescription);
            ctopc_com::variant::clear(&mut prop.vValue);
        }
        task_free(items[0].pItemProperties);
    }
}

// ---- IOPCBrowse::Browse ----------------------------------------------------------------

/// Browse's raw arguments, valid by default (every element of the root, no properties).
struct BrowseRaw {
    item_id: HSTRING,
    name_filter: HSTRING,
    vendor_filter: HSTRING,
    filter: OPCBROWSEFILTER,
    property_ids: Vec<u32>,
    null_item_id: bool,
    null_name_filter: bool,
    null_vendor_filter: bool,
    null_property_ids: bool,
    property_count: u32,
}

impl BrowseRaw {
    fn new() -> BrowseRaw {
        BrowseRaw {
            item_id: wide(""),
            name_filter: wide(""),
            vendor_filter: wide(""),
            filter: OPC_BROWSE_FILTER_ALL,
            property_ids: vec![],
            null_item_id: false,
            null_name_filter: false,
            null_vendor_filter: false,
            null_property_ids: false,
            property_count: 0,
        }
    }
}

/// Browse's out-parameters, pre-filled with poison (the continuation point with a string
/// of the client's, which a failed call must leave alone).
struct BrowseOut {
    cp: PWSTR,
    more: BOOL,
    count: u32,
    elements: *mut OPCBROWSEELEMENT,
}

/// Which out-parameter to pass as NULL.
#[derive(Clone, Copy, PartialEq, Debug)]
enum NullOut {
    None,
    ContinuationPoint,
    More,
    Count,
    Elements,
}

fn browse_raw(b: &IOPCBrowse, a: &BrowseRaw, null_out: NullOut) -> (HRESULT, BrowseOut) {
    let mut o = BrowseOut {
        cp: mem_wstr("client's"),
        more: BOOL(7),
        count: U32_POISON,
        elements: poison(),
    };
    let s = |h: &HSTRING, null: bool| if null { PCWSTR::null() } else { pcwstr(h) };
    let pick = |which: NullOut| which == null_out;
    let ids = if a.null_property_ids {
        null()
    } else {
        a.property_ids.as_ptr()
    };
    // SAFETY: every pointer is NULL or valid for the call.
    let r = unsafe {
        b.Browse(
            s(&a.item_id, a.null_item_id),
            if pick(NullOut::ContinuationPoint) {
                null_mut()
            } else {
                &mut o.cp
            },
            0,
            a.filter,
            s(&a.name_filter, a.null_name_filter),
            s(&a.vendor_filter, a.null_vendor_filter),
            false.into(),
            false.into(),
            a.property_count,
            ids,
            if pick(NullOut::More) {
                null_mut()
            } else {
                &mut o.more
            },
            if pick(NullOut::Count) {
                null_mut()
            } else {
                &mut o.count
            },
            if pick(NullOut::Elements) {
                null_mut()
            } else {
                &mut o.elements
            },
        )
    };
    (r, o)
}

/// A CoTaskMem copy of `s` (a continuation point the client owns).
fn mem_wstr(s: &str) -> PWSTR {
    ctopc_com::abi::alloc_wstr(s).expect("CoTaskMemAlloc")
}

fn assert_failed_cleanly(
    r: HRESULT,
    o: BrowseOut,
    expected: HRESULT,
    null_out: NullOut,
    what: &str,
) {
    assert_eq!(r, expected, "{what}");
    if null_out != NullOut::More {
        assert_eq!(o.more, BOOL(0), "{what}: pbMoreElements not cleared");
    }
    if null_out != NullOut::Count {
        assert_eq!(o.count, 0, "{what}: pdwCount not cleared");
    }
    if null_out != NullOut::Elements {
        assert!(o.elements.is_null(), "{what}: ppBrowseElements not cleared");
    }
    // The client's continuation point is untouched (still ours to free).
    assert_eq!(
        // SAFETY: the string this test allocated; the failed call did not free it.
        unsafe { take_wstr(o.cp) }.as_deref(),
        Some("client's"),
        "{what}"
    );
}

#[test]
fn browse_null_out_parameters_are_invalidarg() {
    let b = server::<IOPCBrowse>();
    for which in [
        NullOut::ContinuationPoint,
        NullOut::More,
        NullOut::Count,
        NullOut::Elements,
    ] {
        let (r, o) = browse_raw(&b, &BrowseRaw::new(), which);
        assert_failed_cleanly(r, o, E_INVALIDARG, which, &format!("NULL {which:?}"));
    }
}

#[test]
fn browse_in_argument_branches() {
    let b = server::<IOPCBrowse>();
    let cases: Vec<(&str, BrowseRaw, HRESULT)> = vec![
        (
            "filter 0",
            BrowseRaw {
                filter: OPCBROWSEFILTER(0),
                ..BrowseRaw::new()
            },
            E_INVALIDARG,
        ),
        (
            "filter 4",
            BrowseRaw {
                filter: OPCBROWSEFILTER(4),
                ..BrowseRaw::new()
            },
            E_INVALIDARG,
        ),
        (
            "filter -1",
            BrowseRaw {
                filter: OPCBROWSEFILTER(-1),
                ..BrowseRaw::new()
            },
            E_INVALIDARG,
        ),
        (
            "NULL szItemID",
            BrowseRaw {
                null_item_id: true,
                ..BrowseRaw::new()
            },
            E_INVALIDARG,
        ),
        (
            "NULL szElementNameFilter",
            BrowseRaw {
                null_name_filter: true,
                ..BrowseRaw::new()
            },
            E_INVALIDARG,
        ),
        (
            "NULL szVendorFilter",
            BrowseRaw {
                null_vendor_filter: true,
                ..BrowseRaw::new()
            },
            E_INVALIDARG,
        ),
        (
            "NULL pdwPropertyIDs with a count",
            BrowseRaw {
                null_property_ids: true,
                property_count: 2,
                ..BrowseRaw::new()
            },
            E_INVALIDARG,
        ),
        (
            "unknown item ID",
            BrowseRaw {
                item_id: wide("Nie ma takiego"),
                ..BrowseRaw::new()
            },
            OPC_E_UNKNOWNITEMID,
        ),
        (
            "bad name filter",
            BrowseRaw {
                name_filter: wide("[a"),
                ..BrowseRaw::new()
            },
            OPC_E_INVALIDFILTER,
        ),
    ];
    for (what, a, expected) in cases {
        let (r, o) = browse_raw(&b, &a, NullOut::None);
        assert_failed_cleanly(r, o, expected, NullOut::None, what);
    }
}

#[test]
fn browse_rejects_a_continuation_point_it_did_not_make() {
    let c = client();
    let r = c.browse(&BrowseArgs {
        continuation_point: Some("zły punkt".into()),
        ..BrowseArgs::all(SULPHUR)
    });
    assert_eq!(code(&r), OPC_E_INVALIDCONTINUATIONPOINT);
}

#[test]
fn browse_success_and_paging() {
    let c = client();
    let page = c.browse(&BrowseArgs::all(SULPHUR)).unwrap();
    assert_eq!(page.code, S_OK);
    assert!(!page.more_elements);
    assert_eq!(page.continuation_point.as_deref(), Some(""), "complete");
    let all: Vec<String> = page
        .elements
        .iter()
        .filter_map(|e| e.name.clone())
        .collect();
    assert!(all.iter().any(|n| n == Z101), "{all:?}");
    let z101 = c.browse(&BrowseArgs::all(Z101_ID)).unwrap();
    let leaves: Vec<_> = z101
        .elements
        .iter()
        .map(|e| (e.name.clone(), e.flags))
        .collect();
    assert_eq!(
        leaves,
        ["KW_A000", "KW_A001", "KW_A002"].map(|n| (Some(n.to_string()), OPC_BROWSE_ISITEM))
    );
    // Page by one through the continuation point.
    let mut cp = None;
    let mut got = Vec::new();
    for _ in 0..10 {
        let page = c
            .browse(&BrowseArgs {
                continuation_point: cp.clone(),
                max_elements: 1,
                ..BrowseArgs::all(Z101_ID)
            })
            .unwrap();
        assert!(page.elements.len() <= 1);
        got.extend(page.elements.iter().filter_map(|e| e.name.clone()));
        cp = page.continuation_point.clone();
        if cp.as_deref().is_none_or(str::is_empty) {
            break;
        }
    }
    assert_eq!(got, ["KW_A000", "KW_A001", "KW_A002"]);
    // Properties of items, chosen by ID.
    let page = c
        .browse(&BrowseArgs {
            property_ids: vec![1, 9999],
            filter: OPC_BROWSE_FILTER_ITEMS.0,
            ..BrowseArgs::all(Z101_ID)
        })
        .unwrap();
    assert_eq!(page.code, S_FALSE, "a property failed");
    for e in &page.elements {
        let errors: Vec<_> = e.properties.properties.iter().map(|p| p.error).collect();
        assert_eq!(errors, [S_OK, OPC_E_INVALID_PID]);
    }
}

#[test]
fn strings_that_are_not_utf16_answer_each_methods_code() {
    let a = space();
    // ChangeBrowsePosition, GetItemID: E_INVALIDARG.
    assert_eq!(
        // SAFETY: a NUL-terminated (invalid) UTF-16 string.
        hr(unsafe { a.ChangeBrowsePosition(OPC_BROWSE_DOWN, bad_utf16()) }),
        E_INVALIDARG
    );
    let mut p = PWSTR(poison());
    assert_eq!(
        // SAFETY: as above; a valid out-pointer.
        hr(unsafe { a.GetItemID(bad_utf16(), &mut p) }),
        E_INVALIDARG
    );
    assert!(p.is_null());
    // BrowseOPCItemIDs: a filter is OPC_E_INVALIDFILTER.
    let (r, out) = browse_ids(&a, OPC_FLAT, bad_utf16(), 0);
    assert_eq!(r, OPC_E_INVALIDFILTER);
    assert!(out.is_null());
    // BrowseAccessPaths: OPC_E_INVALIDITEMID.
    let mut out = OutUnk::poisoned();
    assert_eq!(
        // SAFETY: as above; a valid out-pointer.
        unsafe { a.BrowseAccessPaths(bad_utf16(), out.as_out()) },
        OPC_E_INVALIDITEMID
    );
    assert!(out.is_null());
}

#[test]
fn browse_strings_that_are_not_utf16() {
    let b = server::<IOPCBrowse>();
    let bad = || HSTRING::from_wide(&UNPAIRED_SURROGATE[..3]);
    for (what, a, expected) in [
        (
            "szItemID",
            BrowseRaw {
                item_id: bad(),
                ..BrowseRaw::new()
            },
            OPC_E_UNKNOWNITEMID,
        ),
        (
            "szElementNameFilter",
            BrowseRaw {
                name_filter: bad(),
                ..BrowseRaw::new()
            },
            OPC_E_INVALIDFILTER,
        ),
        (
            "szVendorFilter",
            BrowseRaw {
                vendor_filter: bad(),
                ..BrowseRaw::new()
            },
            OPC_E_INVALIDFILTER,
        ),
    ] {
        let (r, o) = browse_raw(&b, &a, NullOut::None);
        assert_failed_cleanly(r, o, expected, NullOut::None, what);
    }
    // A continuation point that is not UTF-16: OPC_E_INVALIDCONTINUATIONPOINT, and the
    // client's string is left alone.
    let a = BrowseRaw::new();
    let mut cp = PWSTR(UNPAIRED_SURROGATE.as_ptr() as *mut u16);
    let (mut more, mut count) = (BOOL(7), U32_POISON);
    let mut elements: *mut OPCBROWSEELEMENT = poison();
    // SAFETY: valid pointers; the continuation point is a static the call must not free
    // on failure (a failed call leaves it to the client).
    let r = unsafe {
        b.Browse(
            pcwstr(&a.item_id),
            &mut cp,
            0,
            a.filter,
            pcwstr(&a.name_filter),
            pcwstr(&a.vendor_filter),
            false.into(),
            false.into(),
            0,
            null(),
            &mut more,
            &mut count,
            &mut elements,
        )
    };
    assert_eq!(r, OPC_E_INVALIDCONTINUATIONPOINT);
    assert_eq!(
        cp.0 as *const u16,
        UNPAIRED_SURROGATE.as_ptr(),
        "left alone"
    );
    assert_eq!((more, count, elements.is_null()), (BOOL(0), 0, true));
}
