//! IOPCItemProperties and IOPCItemIO of the server object, in process (no proxy): every
//! NULL pointer, count of 0 and bad item ID with its exact HRESULT, out-parameters cleared
//! on failure (all or nothing), and the success paths over the simulated demo plant
//! (KW_A000: read-only R4 level 0..8 m; KW_A110: writable R4 setpoint). The rules are the
//! module docs of `crates/ctopc-com/src/da/server.rs`, `server/props.rs` and
//! `server/itemio.rs`.
#![cfg(windows)]
// Test code (helpers included): a panic fails the test, it crosses no COM boundary.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use ctopc_com::interfaces::*;
use ctopc_core::model::ItemVqt;
use ctopc_core::Value;
use std::ptr::{null, null_mut};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Variant::VARIANT;

const U32_POISON: u32 = 0xA5A5_A5A5;

// ---- QueryAvailableProperties ----------------------------------------------------------

struct QapOut {
    count: u32,
    ids: *mut u32,
    descriptions: *mut PWSTR,
    types: *mut VARTYPE,
}

fn qap(p: &IOPCItemProperties, item: PCWSTR, null_at: Option<usize>) -> (HRESULT, QapOut) {
    let mut o = QapOut {
        count: U32_POISON,
        ids: poison(),
        descriptions: poison(),
        types: poison(),
    };
    let n = |i: usize| null_at == Some(i);
    // SAFETY: every pointer is NULL or valid for the call.
    let r = hr(unsafe {
        p.QueryAvailableProperties(
            item,
            if n(0) { null_mut() } else { &mut o.count },
            if n(1) { null_mut() } else { &mut o.ids },
            if n(2) {
                null_mut()
            } else {
                &mut o.descriptions
            },
            if n(3) { null_mut() } else { &mut o.types },
        )
    });
    (r, o)
}

fn assert_qap_cleared(o: &QapOut, null_at: Option<usize>, what: &str) {
    let n = |i: usize| null_at == Some(i);
    if !n(0) {
        assert_eq!(o.count, 0, "{what}: count not cleared");
    }
    if !n(1) {
        assert!(o.ids.is_null(), "{what}: IDs not cleared");
    }
    if !n(2) {
        assert!(o.descriptions.is_null(), "{what}: descriptions not cleared");
    }
    if !n(3) {
        assert!(o.types.is_null(), "{what}: types not cleared");
    }
}

#[test]
fn query_available_properties_argument_branches() {
    let p = server::<IOPCItemProperties>();
    let id = wide("KW_A000");
    for i in 0..4 {
        let (r, o) = qap(&p, pcwstr(&id), Some(i));
        assert_eq!(r, E_INVALIDARG, "NULL out-parameter {i}");
        assert_qap_cleared(&o, Some(i), &format!("NULL out-parameter {i}"));
    }
    let unknown = wide("KW_A999");
    let invalid = wide("KW_A000.");
    for (what, item, expected) in [
        ("NULL szItemID", PCWSTR::null(), E_INVALIDARG),
        ("unknown item", pcwstr(&unknown), OPC_E_UNKNOWNITEMID),
        ("invalid item ID", pcwstr(&invalid), OPC_E_INVALIDITEMID),
    ] {
        let (r, o) = qap(&p, item, None);
        assert_eq!(r, expected, "{what}");
        assert_qap_cleared(&o, None, what);
    }
}

#[test]
fn query_available_properties_success() {
    let p = server::<IOPCItemProperties>();
    let common: IOPCCommon = p.cast().unwrap();
    // SAFETY: plain value (English descriptions).
    assert_eq!(hr(unsafe { common.SetLocaleID(0x0409) }), S_OK);
    let id = wide("KW_A000");
    let (r, o) = qap(&p, pcwstr(&id), None);
    assert_eq!(r, S_OK);
    let n = o.count as usize;
    // SAFETY: three CoTaskMem arrays of `n` elements handed out by the call, ours.
    let (ids, descriptions, types) = unsafe {
        (
            take_array(o.ids, n),
            take_wstr_array(o.descriptions, n),
            take_array(o.types, n),
        )
    };
    assert_eq!(
        ids,
        [1, 2, 3, 4, 5, 6, 7, 100, 101, 102, 103, 307, 308, 309, 310]
    );
    assert!(descriptions
        .iter()
        .all(|d| d.as_deref().is_some_and(|d| !d.is_empty())));
    assert_eq!(descriptions[0].as_deref(), Some("Item Canonical Data Type"));
    assert_eq!(
        (types[7].0, types[9].0),
        (8, 5),
        "EU units BSTR, high EU R8"
    );
}

// ---- GetItemProperties -----------------------------------------------------------------

#[test]
fn get_item_properties_argument_branches() {
    let p = server::<IOPCItemProperties>();
    let id = wide("KW_A000");
    let ids = [1u32, 2];
    let mut data: *mut VARIANT = poison();
    let mut errors: *mut HRESULT = poison();
    // SAFETY: NULL out-parameters are what is tested.
    unsafe {
        assert_eq!(
            p.GetItemProperties(pcwstr(&id), 2, ids.as_ptr(), null_mut(), &mut errors),
            E_INVALIDARG
        );
        assert!(errors.is_null(), "ppErrors not cleared");
        assert_eq!(
            p.GetItemProperties(pcwstr(&id), 2, ids.as_ptr(), &mut data, null_mut()),
            E_INVALIDARG
        );
        assert!(data.is_null(), "ppvData not cleared");
    }
    let unknown = wide("KW_A999");
    let cases: [(&str, PCWSTR, u32, *const u32, HRESULT); 4] = [
        ("count 0", pcwstr(&id), 0, ids.as_ptr(), E_INVALIDARG),
        ("NULL property IDs", pcwstr(&id), 2, null(), E_INVALIDARG),
        (
            "NULL szItemID",
            PCWSTR::null(),
            2,
            ids.as_ptr(),
            E_INVALIDARG,
        ),
        (
            "unknown item",
            pcwstr(&unknown),
            2,
            ids.as_ptr(),
            OPC_E_UNKNOWNITEMID,
        ),
    ];
    for (what, item, n, pids, expected) in cases {
        let mut data: *mut VARIANT = poison();
        let mut errors: *mut HRESULT = poison();
        // SAFETY: every pointer is NULL or valid for its count.
        let r = unsafe { p.GetItemProperties(item, n, pids, &mut data, &mut errors) };
        assert_eq!(r, expected, "{what}");
        assert!(
            data.is_null() && errors.is_null(),
            "{what}: out-parameters not cleared"
        );
    }
}

/// Frees a VARIANT array of `n` handed out by the server, returning the values.
///
/// # Safety
/// `p` is NULL or a CoTaskMem array of `n` VARIANTs owned by the caller.
unsafe fn take_variants(p: *mut VARIANT, n: usize) -> Vec<Value> {
    if p.is_null() {
        return Vec::new();
    }
    // SAFETY: contract of this function; each VARIANT is cleared once, then the array freed.
    unsafe {
        let s = std::slice::from_raw_parts_mut(p, n);
        let values = s
            .iter_mut()
            .map(|v| {
                let value = ctopc_com::variant::from_variant(v).unwrap_or(Value::Empty);
                ctopc_com::variant::clear(v);
                value
            })
            .collect();
        task_free(p);
        values
    }
}

#[test]
fn get_item_properties_success_and_per_property_errors() {
    let p = server::<IOPCItemProperties>();
    let id = wide("KW_A000");
    let ids = [1u32, 9999, 5, 100];
    let mut data: *mut VARIANT = poison();
    let mut errors: *mut HRESULT = poison();
    // SAFETY: valid pointers for the call.
    let r = unsafe { p.GetItemProperties(pcwstr(&id), 4, ids.as_ptr(), &mut data, &mut errors) };
    assert_eq!(r, S_FALSE, "one property failed");
    // SAFETY: CoTaskMem arrays of 4 handed out by the call, ours.
    let (values, errors) = unsafe { (take_variants(data, 4), take_array(errors, 4)) };
    assert_eq!(errors, [S_OK, OPC_E_INVALID_PID, S_OK, S_OK]);
    assert_eq!(values[0], Value::I2(4), "canonical type VT_R4");
    assert_eq!(values[1], Value::Empty, "VT_EMPTY for the failed property");
    assert_eq!(values[2], Value::I4(OPC_READABLE as i32));
    assert_eq!(values[3], Value::Bstr("m".into()));
}

// ---- LookupItemIDs ---------------------------------------------------------------------

#[test]
fn lookup_item_ids_argument_branches() {
    let p = server::<IOPCItemProperties>();
    let id = wide("KW_A000");
    let ids = [100u32];
    let mut new_ids: *mut PWSTR = poison();
    let mut errors: *mut HRESULT = poison();
    // SAFETY: NULL out-parameters are what is tested.
    unsafe {
        assert_eq!(
            p.LookupItemIDs(pcwstr(&id), 1, ids.as_ptr(), null_mut(), &mut errors),
            E_INVALIDARG
        );
        assert!(errors.is_null(), "ppErrors not cleared");
        assert_eq!(
            p.LookupItemIDs(pcwstr(&id), 1, ids.as_ptr(), &mut new_ids, null_mut()),
            E_INVALIDARG
        );
        assert!(new_ids.is_null(), "ppszNewItemIDs not cleared");
    }
    let unknown = wide("KW_A999");
    let cases: [(&str, PCWSTR, u32, *const u32, HRESULT); 4] = [
        ("count 0", pcwstr(&id), 0, ids.as_ptr(), E_INVALIDARG),
        ("NULL property IDs", pcwstr(&id), 1, null(), E_INVALIDARG),
        (
            "NULL szItemID",
            PCWSTR::null(),
            1,
            ids.as_ptr(),
            E_INVALIDARG,
        ),
        (
            "unknown item",
            pcwstr(&unknown),
            1,
            ids.as_ptr(),
            OPC_E_UNKNOWNITEMID,
        ),
    ];
    for (what, item, n, pids, expected) in cases {
        let mut new_ids: *mut PWSTR = poison();
        let mut errors: *mut HRESULT = poison();
        // SAFETY: every pointer is NULL or valid for its count.
        let r = unsafe { p.LookupItemIDs(item, n, pids, &mut new_ids, &mut errors) };
        assert_eq!(r, expected, "{what}");
        assert!(
            new_ids.is_null() && errors.is_null(),
            "{what}: out-parameters not cleared"
        );
    }
}

#[test]
fn lookup_item_ids_success() {
    let p = server::<IOPCItemProperties>();
    let id = wide("KW_A000");
    let ids = [100u32, 1, 101, 9999];
    let mut new_ids: *mut PWSTR = poison();
    let mut errors: *mut HRESULT = poison();
    // SAFETY: valid pointers for the call.
    let r = unsafe { p.LookupItemIDs(pcwstr(&id), 4, ids.as_ptr(), &mut new_ids, &mut errors) };
    assert_eq!(r, S_FALSE);
    // SAFETY: CoTaskMem arrays of 4 handed out by the call, ours.
    let (names, errors) = unsafe { (take_wstr_array(new_ids, 4), take_array(errors, 4)) };
    assert_eq!(errors, [S_OK, OPC_E_INVALID_PID, S_OK, OPC_E_INVALID_PID]);
    assert_eq!(
        names,
        [
            Some("KW_A000.EU_UNIT".to_string()),
            None,
            Some("KW_A000.DESC".to_string()),
            None
        ]
    );
}

// ---- IOPCItemIO::Read ------------------------------------------------------------------

struct ReadOut {
    values: *mut VARIANT,
    qualities: *mut u16,
    times: *mut FILETIME,
    errors: *mut HRESULT,
}

impl ReadOut {
    fn poisoned() -> ReadOut {
        ReadOut {
            values: poison(),
            qualities: poison(),
            times: poison(),
            errors: poison(),
        }
    }
}

fn read_raw(
    io: &IOPCItemIO,
    n: u32,
    ids: *const PCWSTR,
    ages: *const u32,
    null_at: Option<usize>,
) -> (HRESULT, ReadOut) {
    let mut o = ReadOut::poisoned();
    let z = |i: usize| null_at == Some(i);
    // SAFETY: every pointer is NULL or valid for its count.
    let r = unsafe {
        io.Read(
            n,
            ids,
            ages,
            if z(0) { null_mut() } else { &mut o.values },
            if z(1) { null_mut() } else { &mut o.qualities },
            if z(2) { null_mut() } else { &mut o.times },
            if z(3) { null_mut() } else { &mut o.errors },
        )
    };
    (r, o)
}

fn assert_read_cleared(o: &ReadOut, null_at: Option<usize>, what: &str) {
    let z = |i: usize| null_at == Some(i);
    if !z(0) {
        assert!(o.values.is_null(), "{what}: ppvValues not cleared");
    }
    if !z(1) {
        assert!(o.qualities.is_null(), "{what}: ppwQualities not cleared");
    }
    if !z(2) {
        assert!(o.times.is_null(), "{what}: ppftTimeStamps not cleared");
    }
    if !z(3) {
        assert!(o.errors.is_null(), "{what}: ppErrors not cleared");
    }
}

#[test]
fn item_io_read_argument_branches() {
    let io = server::<IOPCItemIO>();
    let id = wide("KW_A000");
    let ids = [pcwstr(&id)];
    let ages = [0u32];
    for i in 0..4 {
        let (r, o) = read_raw(&io, 1, ids.as_ptr(), ages.as_ptr(), Some(i));
        assert_eq!(r, E_INVALIDARG, "NULL out-parameter {i}");
        assert_read_cleared(&o, Some(i), &format!("NULL out-parameter {i}"));
    }
    for (what, n, pids, pages) in [
        ("count 0", 0, ids.as_ptr(), ages.as_ptr()),
        ("NULL pszItemIDs", 1, null(), ages.as_ptr()),
        ("NULL pdwMaxAge", 1, ids.as_ptr(), null()),
    ] {
        let (r, o) = read_raw(&io, n, pids, pages, None);
        assert_eq!(r, E_INVALIDARG, "{what}");
        assert_read_cleared(&o, None, what);
    }
}

#[test]
fn item_io_read_success_and_per_item_errors() {
    let io = server::<IOPCItemIO>();
    let good = wide("KW_A000");
    let unknown = wide("KW_A999");
    let invalid = wide("KW_A000.");
    let ids = [
        pcwstr(&good),
        PCWSTR::null(),
        pcwstr(&unknown),
        pcwstr(&invalid),
    ];
    let ages = [0u32, 0, 0, u32::MAX];
    let (r, o) = read_raw(&io, 4, ids.as_ptr(), ages.as_ptr(), None);
    assert_eq!(r, S_FALSE);
    // SAFETY: four CoTaskMem arrays of 4 handed out by the call, ours.
    let (values, qualities, times, errors) = unsafe {
        (
            take_variants(o.values, 4),
            take_array(o.qualities, 4),
            take_array(o.times, 4),
            take_array(o.errors, 4),
        )
    };
    assert_eq!(
        errors,
        [
            S_OK,
            OPC_E_INVALIDITEMID,
            OPC_E_UNKNOWNITEMID,
            OPC_E_INVALIDITEMID
        ]
    );
    assert!(
        matches!(values[0], Value::R4(v) if (0.0..=8.0).contains(&v)),
        "{:?}",
        values[0]
    );
    assert_eq!(qualities[0] & 0xC0, 0xC0, "good quality");
    assert_ne!(times[0].dwHighDateTime, 0);
    for i in 1..4 {
        assert_eq!(values[i], Value::Empty, "item {i}");
        assert_eq!(qualities[i], 0, "item {i}");
        assert_eq!((times[i].dwLowDateTime, times[i].dwHighDateTime), (0, 0));
    }
    // All good: S_OK.
    let c = client();
    let (r, items) = c.item_read(&[("KW_A000", 0), ("KW_A000.DESC", 0)]).unwrap();
    assert_eq!(r, S_OK, "{items:?}");
}

// ---- IOPCItemIO::WriteVQT --------------------------------------------------------------

#[test]
fn item_io_write_vqt_argument_branches() {
    let io = server::<IOPCItemIO>();
    let id = wide("KW_A110");
    let ids = [pcwstr(&id)];
    let vqt = [OPCITEMVQT::default()];
    assert_eq!(
        // SAFETY: a NULL out-parameter is what is tested.
        unsafe { io.WriteVQT(1, ids.as_ptr(), vqt.as_ptr(), null_mut()) },
        E_INVALIDARG
    );
    for (what, n, pids, pvqt) in [
        ("count 0", 0, ids.as_ptr(), vqt.as_ptr()),
        ("NULL pszItemIDs", 1, null(), vqt.as_ptr()),
        ("NULL pItemVQT", 1, ids.as_ptr(), null()),
    ] {
        let mut errors: *mut HRESULT = poison();
        // SAFETY: every pointer is NULL or valid for its count.
        let r = unsafe { io.WriteVQT(n, pids, pvqt, &mut errors) };
        assert_eq!(r, E_INVALIDARG, "{what}");
        assert!(errors.is_null(), "{what}: ppErrors not cleared");
    }
}

#[test]
fn item_io_write_vqt_success_and_per_item_errors() {
    let io = server::<IOPCItemIO>();
    let setpoint = wide("KW_A110");
    let read_only = wide("KW_A000");
    let unknown = wide("KW_A999");
    let ids = [
        pcwstr(&setpoint),
        PCWSTR::null(),
        pcwstr(&read_only),
        pcwstr(&unknown),
    ];
    let v = |x: f64| OPCITEMVQT {
        vDataValue: ctopc_com::variant::to_variant(&Value::R8(x)).unwrap(),
        ..Default::default()
    };
    let mut vqt = [v(12.5), v(1.0), v(1.0), v(1.0)];
    let mut errors: *mut HRESULT = poison();
    // SAFETY: valid arrays of 4 (a NULL item ID is what is tested).
    let r = unsafe { io.WriteVQT(4, ids.as_ptr(), vqt.as_ptr(), &mut errors) };
    for x in &mut vqt {
        ctopc_com::variant::clear(&mut x.vDataValue);
    }
    assert_eq!(r, S_FALSE);
    // SAFETY: a CoTaskMem array of 4 handed out by the call, ours.
    let errors = unsafe { take_array(errors, 4) };
    assert_eq!(
        errors,
        [
            S_OK,
            OPC_E_INVALIDITEMID,
            OPC_E_BADRIGHTS,
            OPC_E_UNKNOWNITEMID
        ]
    );
    let c = client();
    let (_, items) = c.item_read(&[("KW_A110", 0)]).unwrap();
    assert_eq!(items[0].value, Value::R4(12.5));
    // The client library's path: S_OK when every item was written.
    let (r, errors) = c
        .item_write_vqt(&[("KW_A110", ItemVqt::value(Value::I4(7)))])
        .unwrap();
    assert_eq!((r, errors), (S_OK, vec![S_OK]));
}

/// One WriteVQT of the text `text` to KW_A110 through `io`; its per-item error.
fn write_text(io: &IOPCItemIO, text: &str) -> HRESULT {
    let id = wide("KW_A110");
    let ids = [pcwstr(&id)];
    let mut vqt = [OPCITEMVQT {
        vDataValue: ctopc_com::variant::to_variant(&Value::Bstr(text.into())).unwrap(),
        ..Default::default()
    }];
    let mut errors: *mut HRESULT = poison();
    // SAFETY: valid arrays of 1.
    let r = unsafe { io.WriteVQT(1, ids.as_ptr(), vqt.as_ptr(), &mut errors) };
    ctopc_com::variant::clear(&mut vqt[0].vDataValue);
    assert!(r == S_OK || r == S_FALSE, "{text}: {r:?}");
    // SAFETY: a CoTaskMem array of 1 handed out by the call, ours.
    let errors = unsafe { take_array(errors, 1) };
    errors[0]
}

/// IOPCItemIO has no group: WriteVQT converts text in the LCID the client set on this
/// server object with IOPCCommon::SetLocaleID, per server object; a refused
/// SetLocaleID changes nothing.
#[test]
fn item_io_write_vqt_converts_text_in_the_server_objects_locale() {
    let pl = server::<IOPCItemIO>();
    let en = server::<IOPCItemIO>();
    let set = |io: &IOPCItemIO, lcid: u32| {
        let c: IOPCCommon = io.cast().unwrap();
        // SAFETY: plain value.
        hr(unsafe { c.SetLocaleID(lcid) })
    };
    assert_eq!(set(&pl, 0x0415), S_OK);
    assert_eq!(set(&en, 0x0409), S_OK);
    let reader = client();
    let setpoint = || {
        reader.item_read(&[("KW_A110", 0)]).unwrap().1[0]
            .value
            .clone()
    };

    assert_eq!(write_text(&pl, "1,5"), S_OK);
    assert_eq!(
        setpoint(),
        Value::R4(1.5),
        "Polish: ',' is the decimal separator"
    );
    assert_eq!(write_text(&en, "1,5"), S_OK);
    assert_eq!(setpoint(), Value::R4(15.0), "English: ',' groups digits");
    assert_eq!(write_text(&en, "2.5"), S_OK);
    assert_eq!(setpoint(), Value::R4(2.5));
    assert_eq!(
        write_text(&pl, "2.5"),
        OPC_E_BADTYPE,
        "not a number in Polish"
    );
    assert_eq!(set(&pl, 0x0407), E_INVALIDARG);
    assert_eq!(
        write_text(&pl, " 3,5 "),
        S_OK,
        "still Polish after a refused LCID"
    );
    assert_eq!(setpoint(), Value::R4(3.5));
}

#[test]
fn item_ids_that_are_not_utf16() {
    let p = server::<IOPCItemProperties>();
    let (r, o) = qap(&p, bad_utf16(), None);
    assert_eq!(r, OPC_E_INVALIDITEMID, "QueryAvailableProperties");
    assert_qap_cleared(&o, None, "invalid UTF-16");
    let ids = [1u32];
    let mut data: *mut VARIANT = poison();
    let mut errors: *mut HRESULT = poison();
    // SAFETY: valid pointers; a NUL-terminated (invalid) UTF-16 item ID.
    let r = unsafe { p.GetItemProperties(bad_utf16(), 1, ids.as_ptr(), &mut data, &mut errors) };
    assert_eq!(r, OPC_E_INVALIDITEMID, "GetItemProperties");
    assert!(data.is_null() && errors.is_null());
    let mut new_ids: *mut PWSTR = poison();
    let mut errors: *mut HRESULT = poison();
    // SAFETY: as above.
    let r = unsafe { p.LookupItemIDs(bad_utf16(), 1, ids.as_ptr(), &mut new_ids, &mut errors) };
    assert_eq!(r, OPC_E_INVALIDITEMID, "LookupItemIDs");
    assert!(new_ids.is_null() && errors.is_null());
    // IOPCItemIO: a per-item OPC_E_INVALIDITEMID.
    let io: IOPCItemIO = p.cast().unwrap();
    let ids = [bad_utf16()];
    let ages = [0u32];
    let (r, o) = read_raw(&io, 1, ids.as_ptr(), ages.as_ptr(), None);
    assert_eq!(r, S_FALSE, "Read");
    // SAFETY: four CoTaskMem arrays of 1 handed out by the call, ours.
    let errors = unsafe {
        take_variants(o.values, 1);
        take_array(o.qualities, 1);
        take_array(o.times, 1);
        take_array(o.errors, 1)
    };
    assert_eq!(errors, [OPC_E_INVALIDITEMID]);
    let vqt = [OPCITEMVQT::default()];
    let mut errors: *mut HRESULT = poison();
    // SAFETY: valid arrays of 1.
    let r = unsafe { io.WriteVQT(1, ids.as_ptr(), vqt.as_ptr(), &mut errors) };
    assert_eq!(r, S_FALSE, "WriteVQT");
    // SAFETY: a CoTaskMem array of 1 handed out by the call, ours.
    assert_eq!(unsafe { take_array(errors, 1) }, [OPC_E_INVALIDITEMID]);
}

#[test]
fn write_vqt_of_a_variant_type_the_server_cannot_take_is_opc_e_badtype() {
    let io = server::<IOPCItemIO>();
    let id = wide("KW_A110");
    let ids = [pcwstr(&id)];
    // VT_UNKNOWN (13) with a NULL pointer: no value the server converts.
    let mut vqt = [OPCITEMVQT::default()];
    // SAFETY: writes the VARTYPE of a zeroed VARIANT (its first 16 bits).
    unsafe { *(&mut vqt[0].vDataValue as *mut VARIANT).cast::<u16>() = 13 };
    let mut errors: *mut HRESULT = poison();
    // SAFETY: valid arrays of 1.
    let r = unsafe { io.WriteVQT(1, ids.as_ptr(), vqt.as_ptr(), &mut errors) };
    assert_eq!(r, S_FALSE);
    // SAFETY: a CoTaskMem array of 1 handed out by the call, ours.
    assert_eq!(unsafe { take_array(errors, 1) }, [OPC_E_BADTYPE]);
}
