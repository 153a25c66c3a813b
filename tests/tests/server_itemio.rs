//! IOPCItemIO (DA 3.0) end to end: Read with MaxAge and WriteVQT by item ID, without a
//! group, over the simulated demo plant. (IOPCItemIO has no access path: OPC_E_UNKNOWNPATH
//! cannot occur.)
//!
//! Spec: OPC DA 3.0 IOPCItemIO (Read, WriteVQT) and OPCITEMVQT; OPC DA 2.05a §4.2.7 CACHE
//! data, DEVICE data and TimeStamps (MaxAge 0 is the device).
#![cfg(windows)]

use ctopc_com::clock::now;
use ctopc_core::model::ItemVqt;
use ctopc_core::{Quality, Value};
use e2e_tests::connect;
use windows::Win32::Foundation::S_OK;

const VT_R4: u16 = 4;

#[test]
fn read_from_the_device_and_from_the_cache() {
    let (_com, server) = connect();
    let before = now();
    let (hr, items) = server
        .item_read(&[("KW_A000", 0), ("KW_A110", 0), ("KW_A000.DESC", 0)])
        .expect("Read");
    assert_eq!(hr, S_OK, "{items:?}");
    for it in &items[..2] {
        assert_eq!((it.error, it.vt), (S_OK, VT_R4), "{it:?}");
        assert_eq!(it.quality & 0xC0, 0xC0, "good quality: {it:?}");
    }
    // A live measurement is stamped now (a setpoint keeps the time of its last write).
    let it = &items[0];
    assert!(
        it.timestamp.add_millis(60_000) >= before && it.timestamp <= now().add_millis(2000),
        "{it:?}"
    );
    assert!(
        matches!(items[0].value, Value::R4(v) if (0.0..=8.0).contains(&v)),
        "{:?}",
        items[0].value
    );
    assert_eq!(
        items[2].value,
        Value::Bstr("Poziom siarki ciekłej w zbiorniku Z101".into())
    );
    // A cache read right after: the value the device read left there.
    let (hr, cached) = server
        .item_read(&[("KW_A000.DESC", u32::MAX), ("KW_A000", 60_000)])
        .unwrap();
    assert_eq!(hr, S_OK);
    assert_eq!(cached[0].value, items[2].value);
    assert_eq!(cached[1].vt, VT_R4);
}

#[test]
fn write_then_read_back() {
    let (_com, server) = connect();
    let (hr, errors) = server
        .item_write_vqt(&[("KW_A110", ItemVqt::value(Value::R8(12.5)))])
        .expect("WriteVQT");
    assert_eq!((hr, errors.clone()), (S_OK, vec![S_OK]));
    let (_, items) = server.item_read(&[("KW_A110", 0)]).unwrap();
    assert_eq!(items[0].value, Value::R4(12.5));
    let (hr, _) = server
        .item_write_vqt(&[("KW_A110", ItemVqt::value(Value::I4(7)))])
        .unwrap();
    assert_eq!(hr, S_OK, "integers convert to the canonical type");
    let (_, items) = server.item_read(&[("KW_A110", 0)]).unwrap();
    assert_eq!(items[0].value, Value::R4(7.0));
}

#[test]
fn write_with_quality_and_timestamp() {
    let (_com, server) = connect();
    let t = now();
    let vqt = ItemVqt {
        value: Value::R4(3.0),
        quality: Some(Quality(0xC0)),
        timestamp: Some(t),
    };
    let (hr, errors) = server.item_write_vqt(&[("KW_A110", vqt)]).unwrap();
    // The asix extended write carries quality and timestamp; the simulation accepts it.
    assert_eq!((hr, errors.clone()), (S_OK, vec![S_OK]), "{errors:?}");
    let (_, items) = server.item_read(&[("KW_A110", 0)]).unwrap();
    assert_eq!(items[0].value, Value::R4(3.0));
}
