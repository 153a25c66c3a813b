//! IOPCItemIO (DA 3.0) end to end: Read with MaxAge and WriteVQT by item ID, without a
//! group, over the simulated demo plant. (IOPCItemIO has no access path: OPC_E_UNKNOWNPATH
//! cannot occur.)
#![cfg(windows)]

use ctopc_com::clock::now;
use ctopc_core::model::ItemVqt;
use ctopc_core::{Quality, Value};
use e2e_tests::{assert_alive, assert_invalid_arg_or_null_ref, connect, interfaces::*};
use windows::core::{HRESULT, HSTRING, PCWSTR};
use windows::Win32::Foundation::{E_INVALIDARG, FILETIME, S_FALSE, S_OK};
use windows::Win32::System::Variant::VARIANT;

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
fn read_per_item_errors() {
    let (_com, server) = connect();
    let (hr, items) = server
        .item_read(&[
            ("KW_A999", 0),
            ("KW_A000.", 0),
            ("", 0),
            ("KW_A000", 0),
            ("asmen.Camac.x.R8", 0),
        ])
        .unwrap();
    assert_eq!(hr, S_FALSE);
    let errors: Vec<HRESULT> = items.iter().map(|i| i.error).collect();
    assert_eq!(
        errors,
        [
            OPC_E_UNKNOWNITEMID,
            OPC_E_INVALIDITEMID,
            OPC_E_INVALIDITEMID,
            S_OK,
            OPC_E_INVALIDITEMID
        ]
    );
    for i in [0, 1, 2, 4] {
        assert_eq!(
            (items[i].vt, items[i].value.clone()),
            (0, Value::Empty),
            "failed items are VT_EMPTY"
        );
    }
    assert_alive(&server);
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

/// IOPCItemIO has no group, so its writes convert text in the server object's LCID
/// (IOPCCommon::SetLocaleID): "1,5" is 1.5 for a Polish client and 15 for an
/// English one (',' groups digits in en-US), each client its own.
#[test]
fn write_text_in_the_clients_locale() {
    let (_com, pl) = connect();
    let en = e2e_tests::Server::connect(e2e_tests::PROGID).expect("a second client");
    pl.set_locale(0x0415).expect("SetLocaleID(pl)");
    en.set_locale(0x0409).expect("SetLocaleID(en-US)");
    let text = |s: &str| ItemVqt::value(Value::Bstr(s.into()));
    let read = |server: &e2e_tests::Server| {
        server.item_read(&[("KW_A111", 0)]).unwrap().1[0]
            .value
            .clone()
    };
    let (hr, errors) = pl.item_write_vqt(&[("KW_A111", text("1,5"))]).unwrap();
    assert_eq!((hr, errors), (S_OK, vec![S_OK]));
    assert_eq!(read(&en), Value::R4(1.5), "Polish decimal comma");
    let (hr, errors) = en.item_write_vqt(&[("KW_A111", text("1,5"))]).unwrap();
    assert_eq!((hr, errors), (S_OK, vec![S_OK]));
    assert_eq!(read(&pl), Value::R4(15.0), "English digit grouping");
    let (hr, errors) = pl.item_write_vqt(&[("KW_A111", text("2.5"))]).unwrap();
    assert_eq!(
        (hr, errors),
        (S_FALSE, vec![OPC_E_BADTYPE]),
        "not a number in Polish"
    );
    let (hr, _) = en.item_write_vqt(&[("KW_A111", text(" 2.5 "))]).unwrap();
    assert_eq!(hr, S_OK);
    assert_eq!(read(&pl), Value::R4(2.5));
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

#[test]
fn write_per_item_errors() {
    let (_com, server) = connect();
    let v = |x: f64| ItemVqt::value(Value::R8(x));
    let (hr, errors) = server
        .item_write_vqt(&[
            ("KW_A000", v(1.0)),
            ("KW_A999", v(1.0)),
            ("KW_A000.", v(1.0)),
            ("KW_A110", v(5.0)),
            ("KW_A110", ItemVqt::value(Value::Bstr("abc".into()))),
        ])
        .unwrap();
    assert_eq!(hr, S_FALSE);
    assert_eq!(
        errors[..4],
        [
            OPC_E_BADRIGHTS,
            OPC_E_UNKNOWNITEMID,
            OPC_E_INVALIDITEMID,
            S_OK
        ]
    );
    // asix writes numbers only (AsixConnect §5): a string is refused for that item.
    assert!(errors[4].is_err(), "a string: {:?}", errors[4]);
    assert_alive(&server);
}

#[test]
fn count_zero_and_null_pointers() {
    let (_com, server) = connect();
    let io = server.item_io().unwrap();
    let id = HSTRING::from("KW_A000");
    let ids = [PCWSTR(id.as_ptr())];
    let ages = [0u32];
    let (mut values, mut qualities, mut times, mut errors): (
        *mut VARIANT,
        *mut u16,
        *mut FILETIME,
        *mut HRESULT,
    ) = (
        std::ptr::null_mut(),
        std::ptr::null_mut(),
        std::ptr::null_mut(),
        std::ptr::null_mut(),
    );
    let vqt = [OPCITEMVQT::default()];
    // SAFETY: valid or deliberately NULL pointers; nothing is returned on these failures.
    unsafe {
        assert_eq!(
            io.Read(
                0,
                ids.as_ptr(),
                ages.as_ptr(),
                &mut values,
                &mut qualities,
                &mut times,
                &mut errors
            ),
            E_INVALIDARG
        );
        assert_eq!(
            io.WriteVQT(0, ids.as_ptr(), vqt.as_ptr(), &mut errors),
            E_INVALIDARG
        );
        assert_alive(&server);
        assert_invalid_arg_or_null_ref(
            io.Read(
                1,
                std::ptr::null(),
                ages.as_ptr(),
                &mut values,
                &mut qualities,
                &mut times,
                &mut errors,
            ),
            "pszItemIDs",
        );
        assert_invalid_arg_or_null_ref(
            io.Read(
                1,
                ids.as_ptr(),
                std::ptr::null(),
                &mut values,
                &mut qualities,
                &mut times,
                &mut errors,
            ),
            "pdwMaxAge",
        );
        assert_invalid_arg_or_null_ref(
            io.Read(
                1,
                ids.as_ptr(),
                ages.as_ptr(),
                std::ptr::null_mut(),
                &mut qualities,
                &mut times,
                &mut errors,
            ),
            "ppvValues",
        );
        assert_invalid_arg_or_null_ref(
            io.Read(
                1,
                ids.as_ptr(),
                ages.as_ptr(),
                &mut values,
                &mut qualities,
                &mut times,
                std::ptr::null_mut(),
            ),
            "ppErrors",
        );
        assert_alive(&server);
        assert_invalid_arg_or_null_ref(
            io.WriteVQT(1, ids.as_ptr(), std::ptr::null(), &mut errors),
            "pItemVQT",
        );
        assert_invalid_arg_or_null_ref(
            io.WriteVQT(1, ids.as_ptr(), vqt.as_ptr(), std::ptr::null_mut()),
            "ppErrors",
        );
        assert_alive(&server);
    }
}
