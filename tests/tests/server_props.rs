//! Item properties end to end: IOPCItemProperties (QueryAvailableProperties,
//! GetItemProperties, LookupItemIDs) and IOPCBrowse::GetProperties, over the demo plant
//! (KW_A000: read-only R4 level 0..8 m; KW_A110: writable R4 setpoint 0..20 t/h; KW_D000:
//! I2 0..1 without a unit).
#![cfg(windows)]

use ctopc_com::clock::now;
use ctopc_core::{Timestamp, Value};
use e2e_tests::{assert_alive, assert_invalid_arg_or_null_ref, code, connect, interfaces::*};
use opc_client::Server;
use windows::core::{HRESULT, HSTRING, PCWSTR, PWSTR};
use windows::Win32::Foundation::{E_INVALIDARG, S_FALSE, S_OK};
use windows::Win32::System::Variant::VARIANT;

const LCID_POLISH: u32 = 0x0415;
const LCID_ENGLISH_US: u32 = 0x0409;

fn english() -> (ctopc_com::apartment::Apartment, Server) {
    let (com, server) = connect();
    server.set_locale(LCID_ENGLISH_US).unwrap();
    (com, server)
}

// ---- IOPCItemProperties ----------------------------------------------------------------

#[test]
fn available_properties_of_an_analog_item_with_unit() {
    let (_com, server) = english();
    let props = server
        .query_available_properties("KW_A000")
        .expect("QueryAvailableProperties");
    let ids: Vec<u32> = props.iter().map(|p| p.0).collect();
    assert_eq!(
        ids,
        [1, 2, 3, 4, 5, 6, 7, 100, 101, 102, 103, 307, 308, 309, 310]
    );
    let by_id = |id: u32| props.iter().find(|p| p.0 == id).unwrap();
    assert_eq!(by_id(1).1.as_deref(), Some("Item Canonical Data Type"));
    assert_eq!(by_id(101).1.as_deref(), Some("Item Description"));
    assert_eq!(
        (
            by_id(1).2,
            by_id(2).2,
            by_id(3).2,
            by_id(4).2,
            by_id(5).2,
            by_id(6).2
        ),
        (2, 4, 2, 7, 3, 4),
        "VARTYPEs"
    );
    assert_eq!((by_id(100).2, by_id(102).2), (8, 5));
    assert_eq!(
        (by_id(307).1.as_deref(), by_id(307).2),
        (Some("HiHi Limit"), 5),
        "the asix alarm limit, VT_R8"
    );
    // Limits held in variables (KW_A100's high limits: KW_L001, KW_L002) are not properties.
    let a100: Vec<u32> = server
        .query_available_properties("KW_A100")
        .unwrap()
        .iter()
        .map(|p| p.0)
        .collect();
    assert_eq!(a100, [1, 2, 3, 4, 5, 6, 7, 100, 101, 102, 103, 309, 310]);
    // Without a unit: no EU Units; the same call with the same IDs otherwise.
    let d000: Vec<u32> = server
        .query_available_properties("KW_D000")
        .unwrap()
        .iter()
        .map(|p| p.0)
        .collect();
    assert_eq!(d000, [1, 2, 3, 4, 5, 6, 7, 101, 102, 103]);
    // Attribute items are plain constants.
    let desc: Vec<u32> = server
        .query_available_properties("KW_A000.DESC")
        .unwrap()
        .iter()
        .map(|p| p.0)
        .collect();
    assert_eq!(desc, [1, 2, 3, 4, 5, 6, 101]);
}

#[test]
fn property_descriptions_follow_the_session_language() {
    let (_com, server) = connect();
    server.set_locale(LCID_POLISH).unwrap();
    let props = server.query_available_properties("KW_A000").unwrap();
    assert_eq!(
        props.iter().find(|p| p.0 == 101).unwrap().1.as_deref(),
        Some("Opis elementu")
    );
    let (hr, v) = server.get_item_properties("KW_A000", &[101]).unwrap();
    assert_eq!(
        (hr, v[0].clone()),
        (
            S_OK,
            (
                Value::Bstr("Poziom siarki ciekłej w zbiorniku Z101".into()),
                S_OK
            )
        )
    );
    server.set_locale(LCID_ENGLISH_US).unwrap();
    let (_, v) = server.get_item_properties("KW_A000", &[101]).unwrap();
    assert_eq!(
        v[0].0,
        Value::Bstr("Liquid sulphur level in tank Z101".into())
    );
}

#[test]
fn item_property_values() {
    let (_com, server) = english();
    let before = now();
    let (hr, v) = server
        .get_item_properties("KW_A000", &[1, 2, 3, 4, 5, 6, 7, 100, 102, 103])
        .expect("GetItemProperties");
    assert_eq!(hr, S_OK, "{v:?}");
    assert!(v.iter().all(|(_, e)| *e == S_OK), "{v:?}");
    assert_eq!(v[0].0, Value::I2(4), "VT_R4");
    assert!(
        matches!(v[1].0, Value::R4(x) if (0.0..=8.0).contains(&x)),
        "{:?}",
        v[1].0
    );
    assert!(
        matches!(v[2].0, Value::I2(q) if q & 0xC0 == 0xC0),
        "good quality from the simulation: {:?}",
        v[2].0
    );
    let Value::Date(d) = v[3].0 else {
        panic!("timestamp is VT_DATE: {:?}", v[3].0)
    };
    let ts = Timestamp::from_ole_date(d).unwrap();
    assert!(
        ts <= now().add_millis(2000) && ts.add_millis(60_000) >= before,
        "timestamp {ts:?}"
    );
    assert_eq!(v[4].0, Value::I4(OPC_READABLE as i32));
    assert_eq!(
        v[5].0,
        Value::R4(1000.0),
        "server scan rate: the minimum update rate"
    );
    assert_eq!(v[6].0, Value::I4(OPC_ANALOG.0));
    assert_eq!(v[7].0, Value::Bstr("m".into()));
    assert_eq!(
        (v[8].0.clone(), v[9].0.clone()),
        (Value::R8(8.0), Value::R8(0.0))
    );
    // The asix limits: HiHi = AlarmHigh, Hi = WarnHigh, Lo = WarnLow, LoLo = AlarmLow.
    let (hr, v) = server
        .get_item_properties("KW_A000", &[307, 308, 309, 310])
        .unwrap();
    assert_eq!(hr, S_OK, "{v:?}");
    let got: Vec<Value> = v.into_iter().map(|(x, _)| x).collect();
    assert_eq!(
        got,
        [
            Value::R8(7.5),
            Value::R8(7.0),
            Value::R8(1.0),
            Value::R8(0.5)
        ]
    );
    // A limit held in a variable is no property of the item: OPC_E_INVALID_PID.
    let (hr, v) = server.get_item_properties("KW_A100", &[308, 309]).unwrap();
    assert_eq!(
        (hr, v[0].1, v[1].clone()),
        (S_FALSE, OPC_E_INVALID_PID, (Value::R8(900.0), S_OK))
    );
    // A writable setpoint.
    let (_, v) = server
        .get_item_properties("KW_A110", &[5, 100, 102])
        .unwrap();
    assert_eq!(
        v,
        [
            (Value::I4((OPC_READABLE | OPC_WRITEABLE) as i32), S_OK),
            (Value::Bstr("t/h".into()), S_OK),
            (Value::R8(20.0), S_OK)
        ]
    );
}

#[test]
fn unsupported_property_ids_are_opc_e_invalid_pid_per_item() {
    let (_com, server) = english();
    let (hr, v) = server
        .get_item_properties("KW_A000", &[1, 8, 9999, 104, 0, 100])
        .unwrap();
    assert_eq!(hr, S_FALSE);
    let errors: Vec<HRESULT> = v.iter().map(|x| x.1).collect();
    assert_eq!(
        errors,
        [
            S_OK,
            OPC_E_INVALID_PID,
            OPC_E_INVALID_PID,
            OPC_E_INVALID_PID,
            OPC_E_INVALID_PID,
            S_OK
        ]
    );
    assert_eq!(v[1].0, Value::Empty);
    // KW_D000 has no unit.
    let (hr, v) = server.get_item_properties("KW_D000", &[100]).unwrap();
    assert_eq!((hr, v[0].1), (S_FALSE, OPC_E_INVALID_PID));
    assert_alive(&server);
}

#[test]
fn unknown_and_invalid_item_ids() {
    let (_com, server) = english();
    for (id, want) in [
        ("KW_A999", OPC_E_UNKNOWNITEMID),
        ("KW_A000.", OPC_E_INVALIDITEMID),
        ("", OPC_E_INVALIDITEMID),
        ("KW_A000.DESC.CV", OPC_E_INVALIDITEMID),
    ] {
        assert_eq!(
            code(&server.query_available_properties(id)),
            want,
            "QueryAvailableProperties({id:?})"
        );
        assert_eq!(
            code(&server.get_item_properties(id, &[1])),
            want,
            "GetItemProperties({id:?})"
        );
        assert_eq!(
            code(&server.lookup_item_ids(id, &[101])),
            want,
            "LookupItemIDs({id:?})"
        );
        assert_alive(&server);
    }
}

#[test]
fn lookup_item_ids_of_attribute_properties() {
    let (_com, server) = english();
    let (hr, v) = server
        .lookup_item_ids("KW_A000", &[1, 100, 101, 102, 103, 9999, 2, 307, 310])
        .expect("LookupItemIDs");
    assert_eq!(hr, S_FALSE);
    let want: Vec<(Option<String>, HRESULT)> = vec![
        (None, OPC_E_INVALID_PID),
        (Some("KW_A000.EU_UNIT".into()), S_OK),
        (Some("KW_A000.DESC".into()), S_OK),
        (Some("KW_A000.HI_EU".into()), S_OK),
        (Some("KW_A000.LO_EU".into()), S_OK),
        (None, OPC_E_INVALID_PID),
        (None, OPC_E_INVALID_PID),
        (Some("KW_A000.AlarmHigh.CV".into()), S_OK),
        (Some("KW_A000.AlarmLow.CV".into()), S_OK),
    ];
    assert_eq!(v, want);
    // `.CV` is the same item; its attribute IDs are the variable's.
    let (hr, v) = server.lookup_item_ids("KW_A000.CV", &[101]).unwrap();
    assert_eq!((hr, v[0].0.as_deref()), (S_OK, Some("KW_A000.DESC")));
    // The returned IDs are items: reading one gives the property's value.
    let (hr, items) = server
        .item_read(&[
            ("KW_A000.EU_UNIT", u32::MAX),
            ("KW_A000.HI_EU", u32::MAX),
            ("KW_A000.AlarmHigh.CV", u32::MAX),
        ])
        .unwrap();
    assert_eq!(hr, S_OK);
    assert_eq!(
        (
            items[0].value.clone(),
            items[1].value.clone(),
            items[2].value.clone()
        ),
        (Value::Bstr("m".into()), Value::R8(8.0), Value::R8(7.5))
    );
}

#[test]
fn count_zero_and_null_pointers() {
    let (_com, server) = english();
    let ip = server.item_properties_itf().unwrap();
    let id = HSTRING::from("KW_A000");
    let ids = [1u32];
    let mut data: *mut VARIANT = std::ptr::null_mut();
    let mut errors: *mut HRESULT = std::ptr::null_mut();
    let mut new_ids: *mut PWSTR = std::ptr::null_mut();
    // SAFETY: valid or deliberately NULL pointers; nothing is returned on these failures.
    unsafe {
        let p = PCWSTR(id.as_ptr());
        assert_eq!(
            ip.GetItemProperties(p, 0, ids.as_ptr(), &mut data, &mut errors),
            E_INVALIDARG,
            "count 0"
        );
        assert_eq!(
            ip.LookupItemIDs(p, 0, ids.as_ptr(), &mut new_ids, &mut errors),
            E_INVALIDARG,
            "count 0"
        );
        assert_alive(&server);
        assert_invalid_arg_or_null_ref(
            ip.GetItemProperties(PCWSTR::null(), 1, ids.as_ptr(), &mut data, &mut errors),
            "szItemID",
        );
        assert_invalid_arg_or_null_ref(
            ip.GetItemProperties(p, 1, std::ptr::null(), &mut data, &mut errors),
            "pdwPropertyIDs",
        );
        assert_invalid_arg_or_null_ref(
            ip.GetItemProperties(p, 1, ids.as_ptr(), std::ptr::null_mut(), &mut errors),
            "ppvData",
        );
        assert_alive(&server);
        assert_invalid_arg_or_null_ref(
            ip.LookupItemIDs(p, 1, ids.as_ptr(), std::ptr::null_mut(), &mut errors),
            "ppszNewItemIDs",
        );
        let mut n = 0u32;
        let (mut pids, mut descs, mut types) = (
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        );
        let r =
            ip.QueryAvailableProperties(p, std::ptr::null_mut(), &mut pids, &mut descs, &mut types);
        assert_invalid_arg_or_null_ref(code(&r), "pdwCount");
        let r =
            ip.QueryAvailableProperties(PCWSTR::null(), &mut n, &mut pids, &mut descs, &mut types);
        assert_invalid_arg_or_null_ref(code(&r), "szItemID");
        assert_alive(&server);
    }
}

// ---- IOPCBrowse::GetProperties ---------------------------------------------------------

#[test]
fn get_properties_of_several_items_with_item_level_errors() {
    let (_com, server) = english();
    let (hr, items) = server
        .get_properties(&["KW_A000", "KW_A999", "KW_A000.", "KW_A110"], true, &[])
        .expect("GetProperties");
    assert_eq!(hr, S_FALSE);
    let errors: Vec<HRESULT> = items.iter().map(|i| i.error).collect();
    assert_eq!(
        errors,
        [S_OK, OPC_E_UNKNOWNITEMID, OPC_E_INVALIDITEMID, S_OK]
    );
    assert!(items[1].properties.is_empty() && items[2].properties.is_empty());
    let ids: Vec<u32> = items[0].properties.iter().map(|p| p.id).collect();
    assert_eq!(
        ids,
        [1, 2, 3, 4, 5, 6, 7, 100, 101, 102, 103, 307, 308, 309, 310],
        "every property when none are named"
    );
    let a110 = &items[3].properties;
    let get = |id: u32| a110.iter().find(|p| p.id == id).unwrap();
    assert_eq!(get(5).value, Value::I4(3));
    assert_eq!(get(102).value, Value::R8(20.0));
    assert_eq!(
        get(101).value,
        Value::Bstr("Sulphur feed rate setpoint".into())
    );
    assert_eq!(get(101).item_id.as_deref(), Some("KW_A110.DESC"));
    assert_eq!(get(2).vt, 4);
    assert!(matches!(get(2).value, Value::R4(_)), "{:?}", get(2).value);
    assert!(a110
        .iter()
        .all(|p| p.error == S_OK && p.description.is_some()));
}

#[test]
fn get_properties_named_ids_values_and_bad_ids() {
    let (_com, server) = english();
    let (hr, items) = server
        .get_properties(&["KW_A000"], true, &[2, 3, 4, 9999])
        .unwrap();
    assert_eq!(hr, S_FALSE);
    assert_eq!(items[0].error, S_FALSE, "item level: a property failed");
    let p = &items[0].properties;
    assert_eq!(
        p.iter().map(|x| x.error).collect::<Vec<_>>(),
        [S_OK, S_OK, S_OK, OPC_E_INVALID_PID]
    );
    assert!(matches!(p[1].value, Value::I2(_)) && matches!(p[2].value, Value::Date(_)));
    // Without values.
    let (hr, items) = server
        .get_properties(&["KW_A000"], false, &[1, 100])
        .unwrap();
    assert_eq!(hr, S_OK);
    assert!(items[0]
        .properties
        .iter()
        .all(|x| x.value == Value::Empty && x.error == S_OK));
    assert_eq!(items[0].properties[1].vt, 8);
}

#[test]
fn get_properties_count_zero_and_null_pointers() {
    let (_com, server) = english();
    let b = server.browse_itf().unwrap();
    let id = HSTRING::from("KW_A000");
    let ids = [PCWSTR(id.as_ptr())];
    let pids = [1u32];
    let mut out: *mut OPCITEMPROPERTIES = std::ptr::null_mut();
    // SAFETY: valid or deliberately NULL pointers; nothing is returned on these failures.
    unsafe {
        assert_eq!(
            b.GetProperties(0, ids.as_ptr(), true.into(), 1, pids.as_ptr(), &mut out),
            E_INVALIDARG
        );
        assert_invalid_arg_or_null_ref(
            b.GetProperties(
                1,
                ids.as_ptr(),
                true.into(),
                1,
                pids.as_ptr(),
                std::ptr::null_mut(),
            ),
            "ppItemProperties",
        );
        assert_invalid_arg_or_null_ref(
            b.GetProperties(1, std::ptr::null(), true.into(), 1, pids.as_ptr(), &mut out),
            "pszItemIDs",
        );
    }
    assert!(out.is_null());
    assert_alive(&server);
}
