//! What generic OPC clients rely on, end to end against the embedded demo plant:
//!
//! - writes convert as `VariantChangeTypeEx` with the group's LCID would: numeric text
//!   (`"12,5"` in a Polish group, `"12.5"` in an English one, blanks around it), BOOL
//!   (TRUE = 1), CY, every number; through IOPCSyncIO::Write, IOPCAsyncIO2::Write,
//!   IOPCSyncIO2::WriteVQT, IOPCItemIO::WriteVQT and the extended [value, quality,
//!   timestamp] write; text that is not a number and DATE stay OPC_E_BADTYPE, a value out
//!   of range is OPC_E_RANGE;
//! - WriteVQT with a VT_EMPTY value (quality or timestamp only) is OPC_E_NOTSUPPORTED; the
//!   extended write refuses a quality outside 16 bits; SetState refuses the LCIDs AddGroup
//!   refuses;
//! - the first OnDataChange after AddItems carries the items' first real samples, not
//!   `BAD Waiting for Initial Data`.
//!
//! The tests that write take one lock: they write the same setpoints.
#![cfg(windows)]

use ctopc_core::model::ItemVqt;
use ctopc_core::value::ArrayValue;
use ctopc_core::{Quality, Timestamp, Value, VarType};
use e2e_tests::io_support::*;
use e2e_tests::{assert_alive, connect, interfaces::*, Apartment, Server};
use opc_client as client;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};
use windows::core::HRESULT;
use windows::Win32::Foundation::{E_INVALIDARG, S_FALSE, S_OK};

/// Sulphur feed rate setpoint (R4 0..20 t/h, writable).
const SETPOINT: &str = "KW_A110";
/// Heater mode (UI1 0..2, writable).
const MODE: &str = "KW_D201";

static WRITES: Mutex<()> = Mutex::new(());

fn writes() -> MutexGuard<'static, ()> {
    WRITES.lock().unwrap_or_else(|p| p.into_inner())
}

struct Plant {
    _com: Apartment,
    server: Server,
    group: TestGroup,
    /// SETPOINT, MODE.
    h: Vec<u32>,
}

/// A group with SETPOINT and MODE, its LCID set with SetState (0: AddGroup's 0x0409).
fn plant(lcid: u32) -> Plant {
    let (com, server) = connect();
    let group = add_group(&server, "", true, 1000, 15).expect("AddGroup");
    if lcid != 0 {
        assert_eq!(set_lcid(&group, lcid), S_OK, "SetState(LCID {lcid:#x})");
    }
    let spec = |id, client| ItemSpec {
        id,
        client,
        vt: 0,
        active: true,
    };
    let h = add_ok(&group, &[spec(SETPOINT, 1), spec(MODE, 2)]);
    Plant {
        _com: com,
        server,
        group,
        h,
    }
}

fn set_lcid(group: &TestGroup, lcid: u32) -> HRESULT {
    let st: IOPCGroupStateMgt = group.cast();
    let mut revised = 0u32;
    // SAFETY: valid in/out pointers; the others are [unique] NULL.
    unsafe {
        st.SetState(
            std::ptr::null(),
            &mut revised,
            std::ptr::null(),
            std::ptr::null(),
            std::ptr::null(),
            &lcid,
            std::ptr::null(),
        )
    }
}

/// The device values of `handles`.
fn device(p: &Plant, handles: &[u32]) -> Vec<Value> {
    let (hr, items) =
        client::sync_read(&p.group.sync(), OPC_DS_DEVICE, handles).expect("Read(DEVICE)");
    assert_eq!(hr, S_OK, "{items:?}");
    items.into_iter().map(|i| i.value).collect()
}

fn text(s: &str) -> Value {
    Value::Bstr(s.into())
}

#[test]
fn sync_write_converts_text_bool_and_cy_in_the_groups_locale() {
    let _w = writes();
    // English group (0x0409).
    let p = plant(0);
    let (sp, mode) = (p.h[0], p.h[1]);
    let sync = p.group.sync();
    let write = |items: &[(u32, Value)]| client::sync_write(&sync, items).expect("Write");
    assert_eq!(write(&[(sp, text(" 12.5 "))]), (S_OK, vec![S_OK]));
    assert_eq!(device(&p, &[sp]), [Value::R4(12.5)]);
    assert_eq!(write(&[(mode, Value::Bool(true))]), (S_OK, vec![S_OK]));
    assert_eq!(device(&p, &[mode]), [Value::UI1(1)], "TRUE is 1, not -1");
    assert_eq!(write(&[(mode, Value::Bool(false))]), (S_OK, vec![S_OK]));
    assert_eq!(device(&p, &[mode]), [Value::UI1(0)]);
    assert_eq!(write(&[(sp, Value::Cy(35_000))]), (S_OK, vec![S_OK]));
    assert_eq!(device(&p, &[sp]), [Value::R4(3.5)]);
    assert_eq!(write(&[(mode, text("2"))]), (S_OK, vec![S_OK]));
    assert_eq!(device(&p, &[mode]), [Value::UI1(2)]);
    // What stays refused.
    assert_eq!(
        write(&[
            (sp, text("abc")),
            (sp, Value::Date(45_000.0)),
            (mode, text("300")),
            (mode, text("-1")),
            (sp, text("1e39")),
        ]),
        (
            S_FALSE,
            vec![
                OPC_E_BADTYPE,
                OPC_E_BADTYPE,
                OPC_E_RANGE,
                OPC_E_RANGE,
                OPC_E_RANGE
            ]
        )
    );
    assert_eq!(device(&p, &[sp, mode]), [Value::R4(3.5), Value::UI1(2)]);
    drop(p);

    // Polish group: the decimal comma.
    let p = plant(0x0415);
    let sync = p.group.sync();
    let (hr, errors) = client::sync_write(&sync, &[(p.h[0], text("12,5"))]).unwrap();
    assert_eq!((hr, errors), (S_OK, vec![S_OK]));
    assert_eq!(device(&p, &[p.h[0]]), [Value::R4(12.5)]);
    let (hr, errors) = client::sync_write(&sync, &[(p.h[0], text("7.25"))]).unwrap();
    assert_eq!(
        (hr, errors),
        (S_FALSE, vec![OPC_E_BADTYPE]),
        "no Polish number"
    );
    assert_alive(&p.server);
}

#[test]
fn async_write_write_vqt_item_io_and_the_extended_write_convert_the_same() {
    let _w = writes();
    let p = plant(0);
    let (sp, mode) = (p.h[0], p.h[1]);

    // IOPCAsyncIO2::Write: call-time errors, then OnWriteComplete.
    let rec = Recorder::recording();
    let sink = TestSink::create(&rec);
    let cookie = client::advise_data_callback(&p.group.unknown, &sink).expect("Advise");
    let (hr, _, errors) = client::async_write(
        &p.group.async2(),
        &[
            (sp, text("4.5")),
            (mode, Value::Bool(true)),
            (sp, text("x")),
        ],
        151,
    )
    .expect("async Write");
    assert_eq!((hr, errors), (S_FALSE, vec![S_OK, S_OK, OPC_E_BADTYPE]));
    let done = rec
        .wait_for(Duration::from_secs(10), |c| c.transaction() == 151)
        .expect("OnWriteComplete");
    let Callback::WriteComplete { items, .. } = done else {
        panic!("not a write completion: {done:?}")
    };
    assert!(items.iter().all(|(_, e)| *e == S_OK), "{items:?}");
    assert_eq!(device(&p, &[sp, mode]), [Value::R4(4.5), Value::UI1(1)]);
    client::unadvise_data_callback(&p.group.unknown, cookie).expect("Unadvise");

    // IOPCSyncIO2::WriteVQT.
    let vqt = |value: Value| ItemVqt {
        value,
        quality: Some(Quality::GOOD),
        timestamp: None,
    };
    let (hr, errors) = client::write_vqt(
        &p.group.sync2(),
        &[(sp, vqt(text("5.5"))), (mode, vqt(Value::Cy(0)))],
    )
    .expect("WriteVQT");
    assert_eq!((hr, errors), (S_OK, vec![S_OK, S_OK]));
    assert_eq!(device(&p, &[sp, mode]), [Value::R4(5.5), Value::UI1(0)]);

    // IOPCItemIO::WriteVQT (no group: the server's locale, English here).
    let (hr, errors) = p
        .server
        .item_write_vqt(&[(SETPOINT, vqt(text("6.5"))), (MODE, vqt(Value::Bool(true)))])
        .expect("IOPCItemIO::WriteVQT");
    assert_eq!((hr, errors), (S_OK, vec![S_OK, S_OK]));
    assert_eq!(device(&p, &[sp, mode]), [Value::R4(6.5), Value::UI1(1)]);

    // The extended write's value element.
    let stamp = Timestamp::from_unix_millis(1_650_000_000_000);
    let ext = Value::Array(ArrayValue::new(
        VarType::VARIANT,
        vec![
            text("7.5"),
            Value::I4(0xC0),
            Value::Date(stamp.to_ole_date()),
        ],
    ));
    let (hr, errors) = client::sync_write(&p.group.sync(), &[(sp, ext)]).unwrap();
    assert_eq!((hr, errors), (S_OK, vec![S_OK]));
    assert_eq!(device(&p, &[sp]), [Value::R4(7.5)]);
    assert_alive(&p.server);
}

/// DA 3.0, IOPCSyncIO2::WriteVQT / IOPCItemIO::WriteVQT, per-item OPC_E_NOTSUPPORTED: "If a
/// client attempts to write any value, quality, timestamp combination and the server does
/// not support the requested combination (which could be a single quantity such as just
/// timestamp), then the server will not perform any write and will return this error code."
/// The asix network always writes a value: quality only and timestamp only are such
/// combinations. (Core test: `model_write_check.rs`.)
#[test]
fn write_vqt_with_an_empty_value_is_not_supported_and_qualities_keep_16_bits() {
    let _w = writes();
    let p = plant(0);
    let sp = p.h[0];
    let empty = |q: Option<Quality>, t: Option<Timestamp>| ItemVqt {
        value: Value::Empty,
        quality: q,
        timestamp: t,
    };
    let stamp = Timestamp::from_unix_millis(1_650_000_000_000);
    let (hr, errors) = client::write_vqt(
        &p.group.sync2(),
        &[
            (sp, empty(Some(Quality::GOOD), None)),
            (sp, empty(None, Some(stamp))),
            (sp, empty(None, None)),
        ],
    )
    .unwrap();
    assert_eq!(
        (hr, errors),
        (
            S_FALSE,
            vec![OPC_E_NOTSUPPORTED, OPC_E_NOTSUPPORTED, OPC_E_BADTYPE]
        )
    );
    let (hr, errors) = p
        .server
        .item_write_vqt(&[(SETPOINT, empty(Some(Quality::GOOD), Some(stamp)))])
        .unwrap();
    assert_eq!((hr, errors), (S_FALSE, vec![OPC_E_NOTSUPPORTED]));

    // The extended write: 0x100C0 is no 16-bit quality (refused, not truncated to 0xC0).
    let ext = |q: i32| {
        Value::Array(ArrayValue::new(
            VarType::VARIANT,
            vec![
                Value::R4(1.0),
                Value::I4(q),
                Value::Date(stamp.to_ole_date()),
            ],
        ))
    };
    let (hr, errors) = client::sync_write(&p.group.sync(), &[(sp, ext(0x100C0))]).unwrap();
    assert_eq!((hr, errors), (S_FALSE, vec![OPC_E_RANGE]));
    assert_alive(&p.server);
}

#[test]
fn set_state_refuses_the_lcids_add_group_refuses() {
    let p = plant(0);
    assert_eq!(set_lcid(&p.group, 0xDEAD_BEEF), E_INVALIDARG);
    for lcid in [0x0415, 0x0409, 0x0407, 0x0800] {
        assert_eq!(set_lcid(&p.group, lcid), S_OK, "{lcid:#x}");
    }
    assert_alive(&p.server);
}

/// The first OnDataChange after AddItems on an active group with a connected sink carries
/// the first samples (not BAD Waiting for Initial Data, 0x20, with the values one update
/// later).
#[test]
fn the_first_on_data_change_after_add_items_carries_real_values() {
    let (_com, server) = connect();
    let group = add_group(&server, "", true, 1000, 16).expect("AddGroup");
    let rec = Recorder::recording();
    let sink = TestSink::create(&rec);
    let cookie = client::advise_data_callback(&group.unknown, &sink).expect("Advise");
    let start = Instant::now();
    // Items no other test of this file subscribes (so the cache has no sample of them).
    let spec = |id, client| ItemSpec {
        id,
        client,
        vt: 0,
        active: true,
    };
    add_ok(&group, &[spec("KW_A002", 1), spec("KW_A005", 2)]);
    let first = rec
        .wait_for(Duration::from_secs(10), |c| {
            matches!(c, Callback::DataChange { transaction: 0, items, .. } if !items.is_empty())
        })
        .expect("OnDataChange");
    let Callback::DataChange {
        items,
        master_quality,
        ..
    } = first
    else {
        unreachable!()
    };
    assert_eq!(master_quality, S_OK, "{items:?}");
    assert_eq!(items.len(), 2, "both in the first callback: {items:?}");
    for i in &items {
        assert_eq!(i.quality & 0xC0, 0xC0, "a real sample: {i:?}");
        assert!(matches!(i.value, Value::R4(_)), "{i:?}");
    }
    assert!(
        start.elapsed() < Duration::from_secs(3),
        "not held to the bound: {:?}",
        start.elapsed()
    );
    client::unadvise_data_callback(&group.unknown, cookie).expect("Unadvise");
    assert_alive(&server);
}
