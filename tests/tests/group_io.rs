//! Synchronous group I/O end to end (IOPCSyncIO, IOPCSyncIO2) against the embedded demo
//! plant (simulated): cache and device reads, MaxAge, writes with read-back, WriteVQT, the
//! asix extended write, and every failure code. After each failure the server still
//! answers.
#![cfg(windows)]

use ctopc_com::clock::now;
use ctopc_core::model::ItemVqt;
use ctopc_core::value::ArrayValue;
use ctopc_core::{Quality, Timestamp, Value, VarType};
use e2e_tests::io_support::*;
use e2e_tests::{assert_alive, code, connect, interfaces::*, Apartment, Server};
use opc_client::{self as client, ReadItem};
use std::time::{Duration, Instant};
use windows::core::HRESULT;
use windows::Win32::Foundation::{E_INVALIDARG, S_FALSE, S_OK};
use windows::Win32::System::Variant::{VARIANT, VT_BSTR, VT_I4, VT_R4, VT_R8};

/// A top-level [in]/[out] reference pointer that is NULL is rejected by the proxy before
/// the call reaches the server.
const RPC_X_NULL_REF_POINTER: HRESULT = HRESULT(0x800706F4u32 as i32);
const GOOD: u16 = 0xC0;
const BAD_OUT_OF_SERVICE: u16 = 0x1C;

/// Level of tank Z101 (R4, read-only).
const LEVEL: &str = "KW_A000";
/// Sulphur feed rate setpoint (R4 0..20 t/h, writable).
const SETPOINT: &str = "KW_A110";
/// A writable UI1 (0..2).
const UI1_WRITABLE: &str = "KW_D201";

struct Plant {
    _com: Apartment,
    server: Server,
    group: TestGroup,
    /// Server handles of LEVEL, SETPOINT, UI1_WRITABLE (client handles 1, 2, 3).
    h: Vec<u32>,
}

fn plant() -> Plant {
    let (com, server) = connect();
    let group = add_group(&server, "", true, 1000, 77).expect("AddGroup");
    let h = add_ok(
        &group,
        &[
            ItemSpec {
                id: LEVEL,
                client: 1,
                vt: 0,
                active: true,
            },
            ItemSpec {
                id: SETPOINT,
                client: 2,
                vt: 0,
                active: true,
            },
            ItemSpec {
                id: UI1_WRITABLE,
                client: 3,
                vt: 0,
                active: true,
            },
        ],
    );
    Plant {
        _com: com,
        server,
        group,
        h,
    }
}

/// Reads from the cache until every item has GOOD quality (the first samples arrive
/// shortly after AddItems).
fn cache_read_good(p: &Plant, handles: &[u32]) -> Vec<ReadItem> {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let (hr, items) =
            client::sync_read(&p.group.sync(), OPC_DS_CACHE, handles).expect("Read(CACHE)");
        if hr == S_OK && items.iter().all(|i| i.quality & 0xC0 == GOOD) {
            return items;
        }
        assert!(
            Instant::now() < deadline,
            "cache never became good: {hr:?} {items:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn device_read(p: &Plant, handles: &[u32]) -> Vec<ReadItem> {
    let (hr, items) =
        client::sync_read(&p.group.sync(), OPC_DS_DEVICE, handles).expect("Read(DEVICE)");
    assert_eq!(hr, S_OK, "{items:?}");
    items
}

fn r4(v: &Value) -> f32 {
    match v {
        Value::R4(x) => *x,
        other => panic!("not R4: {other:?}"),
    }
}

// ---- reads -------------------------------------------------------------------------------

#[test]
fn cache_read_returns_client_handles_values_in_the_canonical_type_and_good_quality() {
    let p = plant();
    let items = cache_read_good(&p, &p.h);
    assert_eq!(
        items.iter().map(|i| i.client_handle).collect::<Vec<_>>(),
        vec![1, 2, 3]
    );
    assert_eq!(items[0].vt, VT_R4.0);
    assert_eq!(items[1].vt, VT_R4.0);
    let level = r4(&items[0].value);
    assert!((0.0..=8.0).contains(&level), "{level}");
    assert!(items.iter().all(|i| i.error == S_OK));
    // Timestamps are the data source's, recent.
    assert!(
        items[0].timestamp.add_millis(60_000) >= now(),
        "{:?}",
        items[0]
    );
    assert_alive(&p.server);
}

#[test]
fn cache_read_of_an_inactive_item_or_group_is_bad_out_of_service() {
    let p = plant();
    let h_inactive = add_ok(
        &p.group,
        &[ItemSpec {
            id: LEVEL,
            client: 9,
            vt: 0,
            active: false,
        }],
    );
    let (hr, items) = client::sync_read(&p.group.sync(), OPC_DS_CACHE, &h_inactive).unwrap();
    assert_eq!(hr, S_OK, "quality is not an error");
    assert_eq!(items[0].quality, BAD_OUT_OF_SERVICE);
    assert_eq!(items[0].error, S_OK);

    cache_read_good(&p, &p.h[..1]);
    assert_eq!(set_active(&p.group, false), S_OK);
    let (hr, items) = client::sync_read(&p.group.sync(), OPC_DS_CACHE, &p.h).unwrap();
    assert_eq!(hr, S_OK);
    assert!(
        items.iter().all(|i| i.quality == BAD_OUT_OF_SERVICE),
        "{items:?}"
    );
    // From the device the group's state does not matter.
    let items = device_read(&p, &p.h);
    assert!(items.iter().all(|i| i.quality & 0xC0 == GOOD), "{items:?}");
    assert_alive(&p.server);
}

#[test]
fn device_read_answers_fresh_values_for_active_and_inactive_items() {
    let p = plant();
    let h = add_ok(
        &p.group,
        &[ItemSpec {
            id: LEVEL,
            client: 10,
            vt: 0,
            active: false,
        }],
    );
    let before = now();
    let items = device_read(&p, &[p.h[0], p.h[1], h[0]]);
    assert_eq!(
        items.iter().map(|i| i.client_handle).collect::<Vec<_>>(),
        vec![1, 2, 10]
    );
    for i in &items {
        assert_eq!(i.quality & 0xC0, GOOD, "{i:?}");
        assert_eq!(i.vt, VT_R4.0);
    }
    // The level is sampled at every plant tick (250 ms); the set point keeps the time
    // of its last write.
    for i in [&items[0], &items[2]] {
        assert!(i.timestamp.add_millis(2_000) >= before, "{i:?}");
    }
    assert_alive(&p.server);
}

#[test]
fn values_come_in_the_requested_type() {
    let p = plant();
    let h = add_ok(
        &p.group,
        &[
            ItemSpec {
                id: SETPOINT,
                client: 20,
                vt: VT_BSTR.0,
                active: true,
            },
            ItemSpec {
                id: SETPOINT,
                client: 21,
                vt: VT_R8.0,
                active: true,
            },
            ItemSpec {
                id: SETPOINT,
                client: 22,
                vt: VT_I4.0,
                active: true,
            },
        ],
    );
    let sync = p.group.sync();
    assert_eq!(
        client::sync_write(&sync, &[(p.h[1], Value::R4(12.25))])
            .unwrap()
            .0,
        S_OK
    );
    for source in [OPC_DS_DEVICE, OPC_DS_CACHE] {
        let deadline = Instant::now() + Duration::from_secs(10);
        let items = loop {
            let (hr, items) = client::sync_read(&sync, source, &h).unwrap();
            assert_eq!(hr, S_OK, "{items:?}");
            if items[1].value == Value::R8(12.25) {
                break items;
            }
            assert!(Instant::now() < deadline, "{source:?}: {items:?}");
            std::thread::sleep(Duration::from_millis(100));
        };
        assert_eq!(items[0].vt, VT_BSTR.0);
        assert_eq!(items[0].value, Value::Bstr("12.25".into()));
        assert_eq!(items[2].vt, VT_I4.0);
        assert_eq!(items[2].value, Value::I4(12));
    }
    assert_alive(&p.server);
}

#[test]
fn read_max_age_device_cache_and_in_between() {
    let p = plant();
    cache_read_good(&p, &p.h);
    let sync2 = p.group.sync2();
    for age in [0, u32::MAX, 5_000, 1] {
        let (hr, items) =
            client::read_max_age(&sync2, &[(p.h[0], age), (p.h[1], age)]).expect("ReadMaxAge");
        assert_eq!(hr, S_OK, "MaxAge {age}: {items:?}");
        for i in &items {
            assert_eq!(i.vt, VT_R4.0, "MaxAge {age}: {i:?}");
            assert_eq!(i.quality & 0xC0, GOOD, "MaxAge {age}: {i:?}");
            assert!(i.timestamp.0 > 0);
        }
    }
    // MaxAge 0 reads the device: the value written just before is there at once.
    assert_eq!(
        client::sync_write(&p.group.sync(), &[(p.h[1], Value::R4(3.5))])
            .unwrap()
            .0,
        S_OK
    );
    let (_, items) = client::read_max_age(&sync2, &[(p.h[1], 0)]).unwrap();
    assert_eq!(items[0].value, Value::R4(3.5));
    // Mixed ages and an invalid handle in one call.
    let (hr, items) =
        client::read_max_age(&sync2, &[(p.h[0], 0), (0xDEAD_BEEF, 0), (p.h[1], u32::MAX)]).unwrap();
    assert_eq!(hr, S_FALSE);
    assert_eq!(
        items.iter().map(|i| i.error).collect::<Vec<_>>(),
        vec![S_OK, OPC_E_INVALIDHANDLE, S_OK]
    );
    assert_eq!(items[1].vt, 0, "a failed item is VT_EMPTY");
    assert_alive(&p.server);
}

// ---- writes ------------------------------------------------------------------------------

#[test]
fn write_then_read_back_the_setpoint() {
    let p = plant();
    let sync = p.group.sync();
    for x in [7.5f32, 0.0, 20.0, 13.125] {
        let (hr, errors) = client::sync_write(&sync, &[(p.h[1], Value::R4(x))]).expect("Write");
        assert_eq!((hr, errors), (S_OK, vec![S_OK]));
        let items = device_read(&p, &p.h[1..2]);
        assert_eq!(items[0].value, Value::R4(x));
        assert_eq!(items[0].quality & 0xC0, GOOD);
    }
    // Other numeric VARIANT types are converted to the canonical R4.
    let (hr, _) =
        client::sync_write(&sync, &[(p.h[1], Value::I4(9)), (p.h[2], Value::R8(2.0))]).unwrap();
    assert_eq!(hr, S_OK);
    let items = device_read(&p, &p.h[1..3]);
    assert_eq!(items[0].value, Value::R4(9.0));
    assert_eq!(items[1].value, Value::UI1(2));
    // ...and the cache follows at the next update.
    let deadline = Instant::now() + Duration::from_secs(10);
    while client::sync_read(&sync, OPC_DS_CACHE, &p.h[1..2])
        .unwrap()
        .1[0]
        .value
        != Value::R4(9.0)
    {
        assert!(
            Instant::now() < deadline,
            "the cache never showed the written value"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_alive(&p.server);
}

#[test]
fn write_vqt_writes_value_quality_and_timestamp() {
    let p = plant();
    let sync2 = p.group.sync2();
    let stamp = Timestamp::from_unix_millis(1_700_000_123_000);
    let items = [(
        p.h[1],
        ItemVqt {
            value: Value::R4(4.75),
            quality: Some(Quality(0xD8)),
            timestamp: Some(stamp),
        },
    )];
    let (hr, errors) = client::write_vqt(&sync2, &items).expect("WriteVQT");
    assert_eq!((hr, errors), (S_OK, vec![S_OK]));
    let got = device_read(&p, &p.h[1..2]);
    assert_eq!(got[0].value, Value::R4(4.75));
    assert_eq!(got[0].quality, 0xD8, "GOOD Local Override as written");
    assert_eq!(got[0].timestamp, stamp);

    // Value only (neither quality nor timestamp specified): GOOD, stamped now.
    let before = now();
    let (hr, _) = client::write_vqt(&sync2, &[(p.h[1], ItemVqt::value(Value::R4(5.0)))]).unwrap();
    assert_eq!(hr, S_OK);
    let got = device_read(&p, &p.h[1..2]);
    assert_eq!(got[0].value, Value::R4(5.0));
    assert_eq!(got[0].quality & 0xC0, GOOD);
    assert!(got[0].timestamp.add_millis(2_000) >= before, "{got:?}");

    // Per-item failures.
    let (hr, errors) = client::write_vqt(
        &sync2,
        &[
            (p.h[0], ItemVqt::value(Value::R4(1.0))),
            (0xDEAD_BEEF, ItemVqt::value(Value::R4(1.0))),
            (
                p.h[1],
                ItemVqt {
                    value: Value::Bstr("abc".into()),
                    quality: Some(Quality::GOOD),
                    timestamp: None,
                },
            ),
            (p.h[1], ItemVqt::value(Value::R8(1e300))),
            (p.h[1], ItemVqt::value(Value::R4(6.0))),
        ],
    )
    .unwrap();
    assert_eq!(hr, S_FALSE);
    assert_eq!(
        errors,
        vec![
            OPC_E_BADRIGHTS,
            OPC_E_INVALIDHANDLE,
            OPC_E_BADTYPE,
            OPC_E_RANGE,
            S_OK
        ]
    );
    assert_alive(&p.server);
}

fn extended(elements: Vec<Value>, element_type: VarType) -> Value {
    Value::Array(ArrayValue::new(element_type, elements))
}

#[test]
fn extended_write_of_value_quality_and_timestamp_through_iopcsyncio_write() {
    let p = plant();
    let sync = p.group.sync();
    let stamp = Timestamp::from_unix_millis(1_650_000_000_000);
    // VT_ARRAY | VT_VARIANT: [R4 value, I4 quality, DATE timestamp].
    let arr = extended(
        vec![
            Value::R4(11.5),
            Value::I4(0x40),
            Value::Date(stamp.to_ole_date()),
        ],
        VarType::VARIANT,
    );
    let (hr, errors) = client::sync_write(&sync, &[(p.h[1], arr)]).expect("Write(extended)");
    assert_eq!((hr, errors), (S_OK, vec![S_OK]));
    let got = device_read(&p, &p.h[1..2]);
    assert_eq!(got[0].value, Value::R4(11.5));
    assert_eq!(got[0].quality, 0x40, "UNCERTAIN as written");
    assert_eq!(got[0].timestamp.unix_millis(), stamp.unix_millis());

    // Elements of convertible types: VT_ARRAY | VT_R8 [value, quality, timestamp as a date number].
    let stamp2 = Timestamp::from_unix_millis(1_660_000_000_000);
    let arr = extended(
        vec![
            Value::R8(2.25),
            Value::R8(192.0),
            Value::R8(stamp2.to_ole_date()),
        ],
        VarType::R8,
    );
    let (hr, _) = client::sync_write(&sync, &[(p.h[1], arr)]).unwrap();
    assert_eq!(hr, S_OK);
    let got = device_read(&p, &p.h[1..2]);
    assert_eq!(got[0].value, Value::R4(2.25));
    assert_eq!(got[0].quality, GOOD);
    assert_eq!(got[0].timestamp.unix_millis(), stamp2.unix_millis());

    // A non-numeric value element, and an unconvertible quality, are OPC_E_BADTYPE; a read-only item
    // is OPC_E_BADRIGHTS.
    let bad_value = extended(
        vec![
            Value::Bstr("x".into()),
            Value::I4(0xC0),
            Value::Date(stamp.to_ole_date()),
        ],
        VarType::VARIANT,
    );
    let bad_quality = extended(
        vec![
            Value::R4(1.0),
            Value::Bstr("good".into()),
            Value::Date(stamp.to_ole_date()),
        ],
        VarType::VARIANT,
    );
    let read_only = extended(
        vec![
            Value::R4(1.0),
            Value::I4(0xC0),
            Value::Date(stamp.to_ole_date()),
        ],
        VarType::VARIANT,
    );
    let (hr, errors) = client::sync_write(
        &sync,
        &[
            (p.h[1], bad_value),
            (p.h[1], bad_quality),
            (p.h[0], read_only),
        ],
    )
    .unwrap();
    assert_eq!(hr, S_FALSE);
    assert_eq!(errors, vec![OPC_E_BADTYPE, OPC_E_BADTYPE, OPC_E_BADRIGHTS]);
    assert_alive(&p.server);
}

#[test]
fn write_failures_reach_the_client_per_item() {
    let p = plant();
    let sync = p.group.sync();
    let (hr, errors) = client::sync_write(
        &sync,
        &[
            (p.h[0], Value::R4(1.0)),            // read-only level
            (p.h[1], Value::R8(1e300)),          // does not fit R4
            (p.h[2], Value::I4(70_000)),         // does not fit UI1
            (p.h[1], Value::Bstr("abc".into())), // not a number
            (p.h[1], Value::Bstr("5".into())),   // numeric text converts
            (p.h[1], Value::Bool(true)),         // TRUE is 1
            (p.h[1], Value::Date(45_000.0)),     // a date is no process value
            (p.h[1], Value::Empty),              // nothing
            (0, Value::R4(1.0)),                 // invalid handle
            (0xDEAD_BEEF, Value::R4(1.0)),       // invalid handle
            (p.h[1], Value::R4(8.0)),            // fine
        ],
    )
    .expect("Write");
    assert_eq!(hr, S_FALSE);
    assert_eq!(
        errors,
        vec![
            OPC_E_BADRIGHTS,
            OPC_E_RANGE,
            OPC_E_RANGE,
            OPC_E_BADTYPE,
            S_OK,
            S_OK,
            OPC_E_BADTYPE,
            OPC_E_BADTYPE,
            OPC_E_INVALIDHANDLE,
            OPC_E_INVALIDHANDLE,
            S_OK
        ]
    );
    assert_eq!(device_read(&p, &p.h[1..2])[0].value, Value::R4(8.0));
    assert_alive(&p.server);
}

// ---- failure codes of the calls ----------------------------------------------------------------

#[test]
fn invalid_handles_are_per_item_errors_with_s_false() {
    let p = plant();
    cache_read_good(&p, &p.h);
    for source in [OPC_DS_CACHE, OPC_DS_DEVICE] {
        let (hr, items) =
            client::sync_read(&p.group.sync(), source, &[p.h[0], 0, 12345678]).unwrap();
        assert_eq!(hr, S_FALSE);
        assert_eq!(
            items.iter().map(|i| i.error).collect::<Vec<_>>(),
            vec![S_OK, OPC_E_INVALIDHANDLE, OPC_E_INVALIDHANDLE]
        );
        assert_eq!(items[0].client_handle, 1);
        assert_eq!(items[1].vt, 0);
    }
    // A handle of another group is invalid here.
    let other = add_group(&p.server, "", true, 1000, 5).unwrap();
    let h_other = add_ok(
        &other,
        &[ItemSpec {
            id: LEVEL,
            client: 1,
            vt: 0,
            active: true,
        }],
    );
    if !p.h.contains(&h_other[0]) {
        let (hr, items) = client::sync_read(&p.group.sync(), OPC_DS_CACHE, &h_other).unwrap();
        assert_eq!(hr, S_FALSE);
        assert_eq!(items[0].error, OPC_E_INVALIDHANDLE);
    }
    assert_alive(&p.server);
}

#[test]
fn count_zero_and_invalid_source_are_e_invalidarg() {
    let p = plant();
    let sync = p.group.sync();
    assert_eq!(
        code(&client::sync_read(&sync, OPC_DS_CACHE, &[])),
        E_INVALIDARG
    );
    assert_eq!(code(&client::sync_write(&sync, &[])), E_INVALIDARG);
    assert_eq!(
        code(&client::read_max_age(&p.group.sync2(), &[])),
        E_INVALIDARG
    );
    assert_eq!(
        code(&client::write_vqt(&p.group.sync2(), &[])),
        E_INVALIDARG
    );
    assert_eq!(
        code(&client::sync_read(&sync, OPCDATASOURCE(3), &p.h)),
        E_INVALIDARG
    );
    assert_eq!(
        code(&client::sync_read(&sync, OPCDATASOURCE(0), &p.h)),
        E_INVALIDARG
    );
    assert_alive(&p.server);
}

fn null_rejected(hr: HRESULT) -> bool {
    hr == E_INVALIDARG || hr == RPC_X_NULL_REF_POINTER
}

#[test]
fn null_pointers_are_rejected_and_the_server_survives() {
    let p = plant();
    let sync = p.group.sync();
    let sync2 = p.group.sync2();
    let mut states: *mut OPCITEMSTATE;
    let mut errors: *mut HRESULT;
    let v = VARIANT::default();
    let age = 0u32;
    let mut values: *mut VARIANT;
    let mut qualities: *mut u16;
    let mut times: *mut windows::Win32::Foundation::FILETIME;
    let vqt = OPCITEMVQT::default();
    // SAFETY: deliberately NULL pointers; the valid ones are live for each call.
    // When the server rejects a call (E_INVALIDARG) every out-array it got is NULL. A call
    // the proxy rejects (RPC_X_NULL_REF_POINTER) never reaches the server; Wine's proxy
    // may then leave a non-NULL value in the other out-parameters, which says nothing
    // about the server.
    unsafe {
        let h = p.h.as_ptr();
        macro_rules! check {
            ($i:expr, $call:expr) => {{
                states = std::ptr::null_mut();
                errors = std::ptr::null_mut();
                values = std::ptr::null_mut();
                qualities = std::ptr::null_mut();
                times = std::ptr::null_mut();
                let hr: HRESULT = $call;
                assert!(null_rejected(hr), "call {}: {hr:?}", $i);
                assert!(
                    hr == RPC_X_NULL_REF_POINTER
                        || states.is_null()
                            && errors.is_null()
                            && values.is_null()
                            && qualities.is_null()
                            && times.is_null(),
                    "call {}: {hr:?}: {states:?} {errors:?} {values:?} {qualities:?} {times:?}",
                    $i
                );
                assert_alive(&p.server);
            }};
        }
        check!(
            0,
            sync.Read(OPC_DS_CACHE, 1, std::ptr::null(), &mut states, &mut errors)
        );
        check!(
            1,
            sync.Read(OPC_DS_CACHE, 1, h, std::ptr::null_mut(), &mut errors)
        );
        check!(
            2,
            sync.Read(OPC_DS_CACHE, 1, h, &mut states, std::ptr::null_mut())
        );
        check!(3, sync.Write(1, std::ptr::null(), &v, &mut errors));
        check!(4, sync.Write(1, h, std::ptr::null(), &mut errors));
        check!(5, sync.Write(1, h, &v, std::ptr::null_mut()));
        check!(
            6,
            sync2.ReadMaxAge(
                1,
                h,
                std::ptr::null(),
                &mut values,
                &mut qualities,
                &mut times,
                &mut errors
            )
        );
        check!(
            7,
            sync2.ReadMaxAge(
                1,
                h,
                &age,
                &mut values,
                std::ptr::null_mut(),
                &mut times,
                &mut errors
            )
        );
        check!(
            8,
            sync2.ReadMaxAge(
                1,
                h,
                &age,
                &mut values,
                &mut qualities,
                std::ptr::null_mut(),
                &mut errors
            )
        );
        check!(9, sync2.WriteVQT(1, h, std::ptr::null(), &mut errors));
        check!(10, sync2.WriteVQT(1, h, &vqt, std::ptr::null_mut()));
    }
    assert_alive(&p.server);
}

#[test]
fn a_removed_group_answers_e_fail_and_the_server_survives() {
    let p = plant();
    let sync = p.group.sync();
    assert!(remove_group(&p.server, p.group.server_handle).is_ok());
    let r = client::sync_read(&sync, OPC_DS_CACHE, &p.h);
    // The group object outlives its removal from the server; its I/O then fails as a whole
    // (E_FAIL), or per item when the implementation keeps the items.
    assert!(
        r.is_err() || r.as_ref().is_ok_and(|(hr, _)| *hr == S_FALSE),
        "{r:?}"
    );
    assert_alive(&p.server);
}
