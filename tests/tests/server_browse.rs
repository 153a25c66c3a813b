//! Browsing end to end over the embedded demo plant: IOPCBrowseServerAddressSpace (DA
//! 2.05a, a per-client cursor) and IOPCBrowse::Browse (DA 3.0, continuation points,
//! filters, properties).
#![cfg(windows)]

use ctopc_core::Value;
use e2e_tests::{assert_alive, assert_invalid_arg_or_null_ref, code, connect, interfaces::*};
use opc_client::{BrowseArgs, Server};
use windows::core::{HRESULT, HSTRING, PCWSTR, PWSTR};
use windows::Win32::Foundation::{E_FAIL, E_INVALIDARG, E_NOTIMPL, S_FALSE, S_OK};
use windows::Win32::System::Com::IEnumString;

const RPC_X_BAD_STUB_DATA: HRESULT = HRESULT(0x800706F5u32 as i32);

const SULPHUR: &str = "Magazyn siarki";
const Z101: &str = "Zbiornik siarki ciekłej Z101";
const Z101_ID: &str = "Magazyn siarki/Zbiornik siarki ciekłej Z101";

fn to_z101(server: &Server) {
    server
        .change_browse_position(OPC_BROWSE_DOWN, SULPHUR)
        .expect("DOWN Magazyn siarki");
    server
        .change_browse_position(OPC_BROWSE_DOWN, Z101)
        .expect("DOWN Z101");
}

// ---- IOPCBrowseServerAddressSpace ------------------------------------------------------

#[test]
fn organization_is_hierarchical() {
    let (_com, server) = connect();
    assert_eq!(server.query_organization().unwrap(), OPC_NS_HIERARCHIAL);
}

#[test]
fn root_lists_the_plant_areas_as_branches() {
    let (_com, server) = connect();
    let (hr, branches) = server.browse_item_ids(OPC_BRANCH, "", 0, 0).unwrap();
    assert_eq!(hr, S_OK);
    for area in [
        SULPHUR,
        "Spalanie siarki",
        "Węzeł kontaktowy",
        "Absorpcja i suszenie",
        "Magazyn kwasu i ekspedycja",
        "Media",
    ] {
        assert!(
            branches.iter().any(|b| b == area),
            "{area} missing in {branches:?}"
        );
    }
    // Nothing but branches at the root: S_FALSE with an empty enumerator.
    assert_eq!(
        server.browse_item_ids(OPC_LEAF, "", 0, 0).unwrap(),
        (S_FALSE, vec![])
    );
}

#[test]
fn down_up_and_item_ids() {
    let (_com, server) = connect();
    to_z101(&server);
    let (hr, leaves) = server.browse_item_ids(OPC_LEAF, "", 0, 0).unwrap();
    assert_eq!(
        (hr, leaves.clone()),
        (
            S_OK,
            vec!["KW_A000".to_string(), "KW_A001".into(), "KW_A002".into()]
        )
    );
    assert_eq!(
        server.get_item_id("KW_A001").unwrap().as_deref(),
        Some("KW_A001"),
        "GetItemID is the bare name"
    );
    // "" is the position's own ID, with its Polish characters intact.
    assert_eq!(server.get_item_id("").unwrap().as_deref(), Some(Z101_ID));
    server.change_browse_position(OPC_BROWSE_UP, "").unwrap();
    assert_eq!(server.get_item_id("").unwrap().as_deref(), Some(SULPHUR));
    server.change_browse_position(OPC_BROWSE_UP, "").unwrap();
    assert_eq!(server.get_item_id("").unwrap().as_deref(), Some(""));
    assert_eq!(
        code(&server.change_browse_position(OPC_BROWSE_UP, "")),
        E_FAIL,
        "UP at the root"
    );
    assert_alive(&server);
}

#[test]
fn browse_to_an_item_id_and_bad_positions() {
    let (_com, server) = connect();
    server
        .change_browse_position(OPC_BROWSE_TO, Z101_ID)
        .expect("TO Z101");
    assert_eq!(
        server.browse_item_ids(OPC_LEAF, "", 0, 0).unwrap().1.len(),
        3
    );
    server
        .change_browse_position(OPC_BROWSE_TO, "")
        .expect("TO root");
    assert_eq!(server.get_item_id("").unwrap().as_deref(), Some(""));
    assert_eq!(
        code(&server.change_browse_position(OPC_BROWSE_TO, "Nie ma takiej gałęzi")),
        E_INVALIDARG
    );
    assert_eq!(
        code(&server.change_browse_position(OPC_BROWSE_TO, "KW_A000")),
        E_INVALIDARG,
        "TO a leaf"
    );
    assert_eq!(
        code(&server.change_browse_position(OPC_BROWSE_DOWN, "Nie ma")),
        E_INVALIDARG
    );
    to_z101(&server);
    assert_eq!(
        code(&server.change_browse_position(OPC_BROWSE_DOWN, "KW_A000")),
        E_INVALIDARG,
        "DOWN to a leaf"
    );
    for d in [0, 4] {
        let hr = code(&server.change_browse_position(OPCBROWSEDIRECTION(d), ""));
        assert!(
            hr == E_INVALIDARG || hr == RPC_X_BAD_STUB_DATA,
            "direction {d}: {hr:?}"
        );
    }
    // Failures leave the position where it was.
    assert_eq!(server.get_item_id("").unwrap().as_deref(), Some(Z101_ID));
    assert_eq!(code(&server.get_item_id("KW_A999")), E_INVALIDARG);
    assert_alive(&server);
}

#[test]
fn flat_listing_and_filters() {
    let (_com, server) = connect();
    let (hr, all) = server.browse_item_ids(OPC_FLAT, "", 0, 0).unwrap();
    assert_eq!(hr, S_OK);
    assert!(all.len() >= 200, "{}", all.len());
    assert!(all.iter().any(|i| i == "KW_A110") && all.iter().any(|i| i == "KW_A000"));
    let (_, a11) = server.browse_item_ids(OPC_FLAT, "KW_A11?", 0, 0).unwrap();
    assert!(
        !a11.is_empty() && a11.iter().all(|i| i.starts_with("KW_A11") && i.len() == 7),
        "{a11:?}"
    );
    to_z101(&server);
    let (_, leaves) = server.browse_item_ids(OPC_LEAF, "*[12]", 0, 0).unwrap();
    assert_eq!(leaves, ["KW_A001", "KW_A002"]);
    // Filters are case-insensitive (MatchPattern default); KW_A000 is R4 and readable.
    let (_, leaves) = server
        .browse_item_ids(OPC_LEAF, "kw_a000", VT_R4_U16, OPC_READABLE)
        .unwrap();
    assert_eq!(leaves, ["KW_A000"]);
    // The access-rights and data-type filters (DA 2.05a).
    // Z101's variables are read-only R4s.
    assert_eq!(
        server
            .browse_item_ids(OPC_LEAF, "", 0, OPC_WRITEABLE)
            .unwrap(),
        (S_FALSE, vec![])
    );
    assert_eq!(
        server.browse_item_ids(OPC_LEAF, "", 17, 0).unwrap(),
        (S_FALSE, vec![]),
        "no UI1 there"
    );
    assert_eq!(
        server
            .browse_item_ids(OPC_LEAF, "", VT_R4_U16, 0)
            .unwrap()
            .1
            .len(),
        3
    );
    server.change_browse_position(OPC_BROWSE_TO, "").unwrap();
    let (_, writable) = server
        .browse_item_ids(OPC_FLAT, "", 0, OPC_WRITEABLE)
        .unwrap();
    assert!(
        writable.iter().any(|i| i == "KW_A110") && !writable.iter().any(|i| i == "KW_A000"),
        "{writable:?}"
    );
    assert!(writable.len() < all.len());
    let (_, ui1) = server.browse_item_ids(OPC_FLAT, "", 17, 0).unwrap();
    assert!(ui1.iter().any(|i| i == "KW_D201") && !ui1.iter().any(|i| i == "KW_A000"));
    let (_, both) = server
        .browse_item_ids(OPC_FLAT, "", 17, OPC_WRITEABLE)
        .unwrap();
    assert!(both.iter().any(|i| i == "KW_D201") && both.len() <= ui1.len());
    to_z101(&server);
    assert_eq!(
        server.browse_item_ids(OPC_LEAF, "nic*", 0, 0).unwrap(),
        (S_FALSE, vec![])
    );
    assert_eq!(
        code(&server.browse_item_ids(OPC_LEAF, "[a", 0, 0)),
        OPC_E_INVALIDFILTER
    );
    assert_eq!(
        code(&server.browse_item_ids(OPC_LEAF, "", 0, 4)),
        E_INVALIDARG,
        "unknown rights bits"
    );
    for t in [0, 4] {
        let hr = code(&server.browse_item_ids(OPCBROWSETYPE(t), "", 0, 0));
        assert!(
            hr == E_INVALIDARG || hr == RPC_X_BAD_STUB_DATA,
            "type {t}: {hr:?}"
        );
    }
    assert_alive(&server);
}

const VT_R4_U16: u16 = 4;

#[test]
fn each_client_has_its_own_position() {
    let (_com, a) = connect();
    let (_com2, b) = connect();
    to_z101(&a);
    assert_eq!(a.get_item_id("").unwrap().as_deref(), Some(Z101_ID));
    assert_eq!(b.get_item_id("").unwrap().as_deref(), Some(""));
}

#[test]
fn access_paths_are_not_browsable() {
    let (_com, server) = connect();
    assert_eq!(code(&server.browse_access_paths("KW_A000")), E_NOTIMPL);
    assert_alive(&server);
}

#[test]
fn address_space_null_pointers() {
    let (_com, server) = connect();
    let bsas = server.address_space().unwrap();
    // SAFETY: deliberately NULL pointers (what the test checks).
    unsafe {
        assert_invalid_arg_or_null_ref(
            code(&bsas.QueryOrganization(std::ptr::null_mut())),
            "QueryOrganization",
        );
        assert_alive(&server);
        assert_invalid_arg_or_null_ref(
            code(&bsas.ChangeBrowsePosition(OPC_BROWSE_DOWN, PCWSTR::null())),
            "ChangeBrowsePosition",
        );
        assert_alive(&server);
        let empty = HSTRING::from("");
        let hr = bsas.BrowseOPCItemIDs(
            OPC_BRANCH,
            PCWSTR(empty.as_ptr()),
            VT_EMPTY_VARTYPE,
            0,
            std::ptr::null_mut(),
        );
        assert_invalid_arg_or_null_ref(hr, "BrowseOPCItemIDs(ppIEnumString)");
        assert_alive(&server);
        let mut e: Option<IEnumString> = None;
        let hr = bsas.BrowseOPCItemIDs(OPC_BRANCH, PCWSTR::null(), VT_EMPTY_VARTYPE, 0, &mut e);
        assert_invalid_arg_or_null_ref(hr, "BrowseOPCItemIDs(szFilterCriteria)");
        assert_alive(&server);
        assert_invalid_arg_or_null_ref(
            code(&bsas.GetItemID(PCWSTR(empty.as_ptr()), std::ptr::null_mut())),
            "GetItemID(out)",
        );
        let mut p = PWSTR::null();
        assert_invalid_arg_or_null_ref(
            code(&bsas.GetItemID(PCWSTR::null(), &mut p)),
            "GetItemID(in)",
        );
        assert_alive(&server);
    }
}

const VT_EMPTY_VARTYPE: VARTYPE = windows::Win32::System::Variant::VT_EMPTY;

// ---- IOPCBrowse::Browse ----------------------------------------------------------------

fn names(page: &opc_client::BrowsePage) -> Vec<String> {
    page.elements
        .iter()
        .map(|e| e.name.clone().unwrap_or_default())
        .collect()
}

fn complete(cp: &Option<String>) -> bool {
    cp.as_deref().unwrap_or("").is_empty()
}

#[test]
fn browse_root_and_a_branch() {
    let (_com, server) = connect();
    let page = server.browse(&BrowseArgs::all("")).expect("Browse root");
    assert_eq!(page.code, S_OK);
    assert!(!page.more_elements);
    assert!(
        complete(&page.continuation_point),
        "{:?}",
        page.continuation_point
    );
    let sulphur = page
        .elements
        .iter()
        .find(|e| e.name.as_deref() == Some(SULPHUR))
        .expect("Magazyn siarki");
    assert_eq!(sulphur.item_id.as_deref(), Some(SULPHUR));
    assert_eq!(sulphur.flags, OPC_BROWSE_HASCHILDREN);
    let page = server.browse(&BrowseArgs::all(Z101_ID)).unwrap();
    assert_eq!(names(&page), ["KW_A000", "KW_A001", "KW_A002"]);
    for e in &page.elements {
        assert_eq!(e.flags, OPC_BROWSE_ISITEM);
        assert_eq!(e.item_id, e.name);
        assert!(e.properties.properties.is_empty());
    }
    // Browsing a leaf is success with nothing in it.
    let page = server.browse(&BrowseArgs::all("KW_A000")).unwrap();
    assert_eq!((page.code, page.elements.len()), (S_OK, 0));
}

#[test]
fn browse_filters() {
    let (_com, server) = connect();
    let branches = server
        .browse(&BrowseArgs {
            filter: OPC_BROWSE_FILTER_BRANCHES.0,
            ..BrowseArgs::all(SULPHUR)
        })
        .unwrap();
    assert!(branches
        .elements
        .iter()
        .all(|e| e.flags & OPC_BROWSE_HASCHILDREN != 0));
    assert!(names(&branches).contains(&Z101.to_string()));
    let items = server
        .browse(&BrowseArgs {
            filter: OPC_BROWSE_FILTER_ITEMS.0,
            ..BrowseArgs::all(SULPHUR)
        })
        .unwrap();
    assert_eq!(items.elements.len(), 0, "only groups under Magazyn siarki");
    let some = server
        .browse(&BrowseArgs {
            name_filter: "KW_A00[02]".into(),
            ..BrowseArgs::all(Z101_ID)
        })
        .unwrap();
    assert_eq!(names(&some), ["KW_A000", "KW_A002"]);
    let vendor = server
        .browse(&BrowseArgs {
            vendor_filter: "cokolwiek".into(),
            ..BrowseArgs::all(Z101_ID)
        })
        .unwrap();
    assert_eq!(vendor.elements.len(), 3, "the vendor filter is ignored");
}

#[test]
fn browse_pages_with_continuation_points() {
    let (_com, server) = connect();
    let all = names(&server.browse(&BrowseArgs::all(SULPHUR)).unwrap());
    assert!(all.len() >= 5, "{all:?}");
    let mut got = Vec::new();
    let mut cp: Option<String> = None;
    let mut pages = 0;
    loop {
        let page = server
            .browse(&BrowseArgs {
                max_elements: 2,
                continuation_point: cp.clone(),
                ..BrowseArgs::all(SULPHUR)
            })
            .unwrap();
        assert!(page.elements.len() <= 2);
        assert!(
            !page.more_elements,
            "continuation points are supported: pbMoreElements stays FALSE"
        );
        got.extend(names(&page));
        pages += 1;
        if complete(&page.continuation_point) {
            break;
        }
        cp = page.continuation_point;
        assert!(pages < 20);
    }
    assert_eq!(got, all);
    assert_eq!(pages, all.len().div_ceil(2));
}

#[test]
fn browse_errors() {
    let (_com, server) = connect();
    assert_eq!(
        code(&server.browse(&BrowseArgs::all("Nie ma takiego"))),
        OPC_E_UNKNOWNITEMID
    );
    assert_eq!(
        code(&server.browse(&BrowseArgs {
            continuation_point: Some("zły punkt".into()),
            ..BrowseArgs::all(SULPHUR)
        })),
        OPC_E_INVALIDCONTINUATIONPOINT
    );
    // A continuation point of another branch.
    let page = server
        .browse(&BrowseArgs {
            max_elements: 1,
            ..BrowseArgs::all(SULPHUR)
        })
        .unwrap();
    let cp = page.continuation_point.clone();
    assert!(!complete(&cp));
    assert_eq!(
        code(&server.browse(&BrowseArgs {
            continuation_point: cp,
            max_elements: 1,
            ..BrowseArgs::all("")
        })),
        OPC_E_INVALIDCONTINUATIONPOINT
    );
    assert_eq!(
        code(&server.browse(&BrowseArgs {
            name_filter: "[a".into(),
            ..BrowseArgs::all("")
        })),
        OPC_E_INVALIDFILTER
    );
    for f in [0, 4] {
        let hr = code(&server.browse(&BrowseArgs {
            filter: f,
            ..BrowseArgs::all("")
        }));
        assert!(
            hr == E_INVALIDARG || hr == RPC_X_BAD_STUB_DATA,
            "filter {f}: {hr:?}"
        );
    }
    assert_alive(&server);
}

#[test]
fn browse_with_all_properties_and_values() {
    let (_com, server) = connect();
    let page = server
        .browse(&BrowseArgs {
            all_properties: true,
            property_values: true,
            ..BrowseArgs::all(Z101_ID)
        })
        .unwrap();
    assert_eq!(page.code, S_OK);
    let a000 = &page.elements[0];
    assert_eq!(a000.properties.error, S_OK);
    let ids: Vec<u32> = a000.properties.properties.iter().map(|p| p.id).collect();
    assert_eq!(
        ids,
        [1, 2, 3, 4, 5, 6, 7, 100, 101, 102, 103, 307, 308, 309, 310]
    );
    let prop = |id: u32| {
        a000.properties
            .properties
            .iter()
            .find(|p| p.id == id)
            .unwrap()
    };
    assert_eq!(prop(1).value, Value::I2(4), "canonical type VT_R4");
    assert_eq!(
        prop(2).vt,
        4,
        "the value property has the item's canonical type"
    );
    assert!(
        matches!(prop(2).value, Value::R4(v) if (0.0..=8.0).contains(&v)),
        "{:?}",
        prop(2).value
    );
    assert_eq!(prop(5).value, Value::I4(1), "KW_A000 is read-only");
    assert_eq!(prop(100).value, Value::Bstr("m".into()));
    assert_eq!(prop(100).item_id.as_deref(), Some("KW_A000.EU_UNIT"));
    assert_eq!(prop(102).value, Value::R8(8.0));
    assert_eq!(prop(103).value, Value::R8(0.0));
    assert_eq!(
        prop(1).description.as_deref(),
        Some("Item Canonical Data Type")
    );
    assert!(a000.properties.properties.iter().all(|p| p.error == S_OK));
}

#[test]
fn browse_with_chosen_properties_without_values_and_a_bad_id() {
    let (_com, server) = connect();
    let page = server
        .browse(&BrowseArgs {
            property_ids: vec![1, 101, 9999],
            ..BrowseArgs::all(Z101_ID)
        })
        .unwrap();
    assert_eq!(page.code, S_FALSE, "a property failed");
    for e in &page.elements {
        assert_eq!(e.properties.error, S_FALSE);
        let p = &e.properties.properties;
        assert_eq!(p.iter().map(|p| p.id).collect::<Vec<_>>(), [1, 101, 9999]);
        assert_eq!(
            (p[0].error, p[0].vt, p[0].value.clone()),
            (S_OK, 2, Value::Empty),
            "no values asked for"
        );
        assert_eq!(p[2].error, OPC_E_INVALID_PID);
    }
    // Branches carry no properties.
    let page = server
        .browse(&BrowseArgs {
            all_properties: true,
            ..BrowseArgs::all(SULPHUR)
        })
        .unwrap();
    assert!(page
        .elements
        .iter()
        .all(|e| e.properties.properties.is_empty()));
}

#[test]
fn browse_null_pointers() {
    let (_com, server) = connect();
    let b = server.browse_itf().unwrap();
    let empty = HSTRING::from("");
    let mut cp = PWSTR::null();
    let (mut more, mut count) = (windows::core::BOOL(0), 0u32);
    let mut elements: *mut OPCBROWSEELEMENT = std::ptr::null_mut();
    let dummy = 0u32;
    // SAFETY: deliberately NULL pointers, one at a time.
    unsafe {
        let e = PCWSTR(empty.as_ptr());
        let f = OPC_BROWSE_FILTER_ALL;
        let hr = b.Browse(
            e,
            std::ptr::null_mut(),
            0,
            f,
            e,
            e,
            false.into(),
            false.into(),
            0,
            &dummy,
            &mut more,
            &mut count,
            &mut elements,
        );
        assert_invalid_arg_or_null_ref(hr, "pszContinuationPoint");
        assert_alive(&server);
        let hr = b.Browse(
            e,
            &mut cp,
            0,
            f,
            e,
            e,
            false.into(),
            false.into(),
            0,
            &dummy,
            std::ptr::null_mut(),
            &mut count,
            &mut elements,
        );
        assert_invalid_arg_or_null_ref(hr, "pbMoreElements");
        assert_alive(&server);
        let hr = b.Browse(
            PCWSTR::null(),
            &mut cp,
            0,
            f,
            e,
            e,
            false.into(),
            false.into(),
            0,
            &dummy,
            &mut more,
            &mut count,
            &mut elements,
        );
        assert_invalid_arg_or_null_ref(hr, "szItemID");
        assert_alive(&server);
    }
    // SAFETY: NULL or a CoTaskMem string a failed call may have handed out, ours.
    unsafe { opc_client::take_wstr(cp) };
    // SAFETY: a CoTaskMem array of that many elements, just handed out by the call.
    unsafe { opc_client::take_array(elements, count as usize) };
}
