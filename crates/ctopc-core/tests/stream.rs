//! The DA 1.0a stream layouts (`ctopc_core::stream`), byte by byte for each value type,
//! and the decoder as their inverse.

use ctopc_core::stream::*;
use ctopc_core::value::ArrayValue;
use ctopc_core::{Quality, Timestamp, Value, VarType};

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}
fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

fn item(h: u32, value: Value) -> StreamItem {
    StreamItem {
        client_handle: h,
        quality: Quality(0xC0),
        timestamp: Timestamp::from_filetime_parts(0x1122_3344, 0x0155_6677),
        value,
    }
}

fn one(format: DataFormat, value: Value) -> Vec<u8> {
    let b = encode_data(format, 7, 9, 0, &[item(42, value.clone())]);
    let back = decode_data(format, &b).unwrap();
    assert_eq!(back.items.len(), 1);
    assert_eq!(back.items[0].value, value, "round trip");
    b
}

#[test]
fn group_header_and_item_header1_with_time() {
    let b = encode_data(
        DataFormat::DataTime,
        0xAABB,
        0x1234,
        1,
        &[item(5, Value::I4(-2)), item(6, Value::R8(1.5))],
    );
    assert_eq!(u32_at(&b, 0) as usize, b.len(), "dwSize");
    assert_eq!(u32_at(&b, 4), 2, "dwItemCount");
    assert_eq!(u32_at(&b, 8), 0xAABB, "hClientGroup");
    assert_eq!(u32_at(&b, 12), 0x1234, "dwTransactionID");
    assert_eq!(u32_at(&b, 16), 1, "hrStatus");
    // OPCITEMHEADER1 at 20 and 40.
    assert_eq!(u32_at(&b, 20), 5);
    let off0 = u32_at(&b, 24) as usize;
    assert_eq!(off0, GROUP_HEADER + 2 * ITEM_HEADER1);
    assert_eq!(u16_at(&b, 28), 0xC0);
    assert_eq!(u16_at(&b, 30), 0);
    assert_eq!(u32_at(&b, 32), 0x1122_3344);
    assert_eq!(u32_at(&b, 36), 0x0155_6677);
    assert_eq!(u32_at(&b, 40), 6);
    let off1 = u32_at(&b, 44) as usize;
    assert_eq!(off1, off0 + VARIANT_SIZE);
    // The VARIANTs.
    assert_eq!(u16_at(&b, off0), VarType::I4.0);
    assert_eq!(&b[off0 + 2..off0 + 8], &[0; 6]);
    assert_eq!(u32_at(&b, off0 + 8) as i32, -2);
    assert_eq!(u16_at(&b, off1), VarType::R8.0);
    assert_eq!(&b[off1 + 8..off1 + 16], &1.5f64.to_le_bytes());
    assert_eq!(b.len(), off1 + VARIANT_SIZE);
    let d = decode_data(DataFormat::DataTime, &b).unwrap();
    assert_eq!(d.client_group, 0xAABB);
    assert_eq!(d.transaction_id, 0x1234);
    assert_eq!(d.status, 1);
    assert_eq!(d.items[0], item(5, Value::I4(-2)));
}

#[test]
fn item_header2_without_time() {
    let b = encode_data(DataFormat::Data, 1, 0, 0, &[item(5, Value::UI1(200))]);
    assert_eq!(u32_at(&b, 20), 5);
    assert_eq!(u32_at(&b, 24) as usize, GROUP_HEADER + ITEM_HEADER2);
    assert_eq!(u16_at(&b, 28), 0xC0);
    assert_eq!(b.len(), GROUP_HEADER + ITEM_HEADER2 + VARIANT_SIZE);
    assert_eq!(b[GROUP_HEADER + ITEM_HEADER2 + 8], 200);
    let d = decode_data(DataFormat::Data, &b).unwrap();
    assert_eq!(d.items[0].timestamp, Timestamp(0));
}

#[test]
fn every_fixed_size_type() {
    let v = GROUP_HEADER + ITEM_HEADER2;
    let cases: Vec<(Value, Vec<u8>)> = vec![
        (Value::Empty, vec![]),
        (Value::I1(-3), vec![0xFD]),
        (Value::UI1(7), vec![7]),
        (Value::I2(-2), (-2i16).to_le_bytes().to_vec()),
        (Value::UI2(65000), 65000u16.to_le_bytes().to_vec()),
        (Value::I4(-70000), (-70000i32).to_le_bytes().to_vec()),
        (
            Value::UI4(4_000_000_000),
            4_000_000_000u32.to_le_bytes().to_vec(),
        ),
        (Value::I8(-5), (-5i64).to_le_bytes().to_vec()),
        (Value::UI8(u64::MAX), u64::MAX.to_le_bytes().to_vec()),
        (Value::R4(2.5), 2.5f32.to_le_bytes().to_vec()),
        (Value::R8(-0.25), (-0.25f64).to_le_bytes().to_vec()),
        (Value::Cy(12_345), 12_345i64.to_le_bytes().to_vec()),
        (Value::Date(45000.5), 45000.5f64.to_le_bytes().to_vec()),
        (Value::Bool(true), vec![0xFF, 0xFF]),
        (Value::Bool(false), vec![0, 0]),
        (
            Value::Error(0x8000_4005u32 as i32),
            0x8000_4005u32.to_le_bytes().to_vec(),
        ),
    ];
    for (value, data) in cases {
        let b = one(DataFormat::Data, value.clone());
        assert_eq!(b.len(), v + VARIANT_SIZE, "{value:?}");
        assert_eq!(u16_at(&b, v), value.var_type().0, "{value:?}");
        let mut want = [0u8; 8];
        want[..data.len()].copy_from_slice(&data);
        assert_eq!(&b[v + 8..v + 16], &want, "{value:?}");
    }
}

#[test]
fn bstr_follows_its_variant() {
    let v = GROUP_HEADER + ITEM_HEADER2;
    let b = one(DataFormat::Data, Value::Bstr("Zbiornik ł".into()));
    assert_eq!(u16_at(&b, v), VarType::BSTR.0);
    assert_eq!(&b[v + 8..v + 16], &[0; 8], "no pointer");
    let n = u32_at(&b, v + 16) as usize;
    assert_eq!(n, 10 * 2, "byte count without the NUL");
    assert_eq!(u16_at(&b, v + 20), u16::from(b'Z'));
    assert_eq!(u16_at(&b, v + 20 + 18), 'ł' as u16);
    assert_eq!(u16_at(&b, v + 20 + n), 0, "NUL");
    assert_eq!(b.len(), v + 16 + 4 + n + 2 + 2, "padded to 4");
    assert_eq!(u32_at(&b, 0) as usize, b.len());
    one(DataFormat::DataTime, Value::Bstr(String::new()));
}

#[test]
fn values_after_a_text_start_at_a_multiple_of_4() {
    let items = [item(1, Value::Bstr("abc".into())), item(2, Value::I2(3))];
    let b = encode_data(DataFormat::DataTime, 0, 0, 0, &items);
    let off1 = u32_at(&b, GROUP_HEADER + ITEM_HEADER1 + 4) as usize;
    assert_eq!(off1 % 4, 0);
    assert_eq!(u16_at(&b, off1), VarType::I2.0);
    assert_eq!(decode_data(DataFormat::DataTime, &b).unwrap().items, items);
}

#[test]
fn arrays_have_a_safearray_and_their_elements() {
    let v = GROUP_HEADER + ITEM_HEADER2;
    let arr = Value::Array(ArrayValue {
        element_type: VarType::R4,
        elements: vec![Value::R4(1.0), Value::R4(2.0), Value::R4(3.0)],
    });
    let b = one(DataFormat::Data, arr);
    assert_eq!(u16_at(&b, v), 0x2000 | VarType::R4.0);
    let sa = v + VARIANT_SIZE;
    assert_eq!(u16_at(&b, sa), 1, "cDims");
    assert_eq!(u32_at(&b, sa + 4), 4, "cbElements");
    assert_eq!(u32_at(&b, sa + 16), 3, "cElements");
    assert_eq!(u32_at(&b, sa + 20), 0, "lLbound");
    let data = sa + SAFEARRAY_SIZE;
    assert_eq!(&b[data + 4..data + 8], &2.0f32.to_le_bytes());
    assert_eq!(b.len(), data + 12);

    for (t, el) in [
        (VarType::I1, Value::I1(-1)),
        (VarType::UI1, Value::UI1(1)),
        (VarType::I2, Value::I2(-1)),
        (VarType::UI2, Value::UI2(1)),
        (VarType::BOOL, Value::Bool(true)),
        (VarType::I4, Value::I4(-1)),
        (VarType::UI4, Value::UI4(1)),
        (VarType::I8, Value::I8(-1)),
        (VarType::UI8, Value::UI8(1)),
        (VarType::R8, Value::R8(0.5)),
        (VarType::CY, Value::Cy(10_000)),
        (VarType::DATE, Value::Date(1.0)),
        (VarType::ERROR, Value::Error(5)),
    ] {
        one(
            DataFormat::DataTime,
            Value::Array(ArrayValue {
                element_type: t,
                elements: vec![el.clone(), el],
            }),
        );
    }
}

#[test]
fn bstr_and_variant_arrays() {
    let v = GROUP_HEADER + ITEM_HEADER2;
    let b = one(
        DataFormat::Data,
        Value::Array(ArrayValue {
            element_type: VarType::BSTR,
            elements: vec![Value::Bstr("ab".into()), Value::Bstr(String::new())],
        }),
    );
    let data = v + VARIANT_SIZE + SAFEARRAY_SIZE;
    assert_eq!(u32_at(&b, data), 4);
    assert_eq!(u16_at(&b, data + 4), u16::from(b'a'));
    assert_eq!(u16_at(&b, data + 8), 0);
    assert_eq!(u32_at(&b, data + 10), 0, "the empty text");
    let mixed = Value::Array(ArrayValue {
        element_type: VarType::VARIANT,
        elements: vec![Value::I4(1), Value::Bstr("x".into()), Value::Empty],
    });
    let b = one(DataFormat::Data, mixed);
    let data = v + VARIANT_SIZE + SAFEARRAY_SIZE;
    assert_eq!(u32_at(&b, v + VARIANT_SIZE + 4), VARIANT_SIZE as u32);
    assert_eq!(u16_at(&b, data), VarType::I4.0);
    assert_eq!(u16_at(&b, data + 16), VarType::BSTR.0);
}

#[test]
fn write_completion_stream() {
    let b = encode_write(3, 77, 1, &[(10, 0), (11, 0xC004_0007u32 as i32)]);
    assert_eq!(b.len(), GROUP_HEADER_WRITE + 2 * ITEM_HEADER_WRITE);
    assert_eq!(u32_at(&b, 0), 2, "dwItemCount");
    assert_eq!(u32_at(&b, 4), 3, "hClientGroup");
    assert_eq!(u32_at(&b, 8), 77, "dwTransactionID");
    assert_eq!(u32_at(&b, 12), 1, "hrStatus");
    assert_eq!(u32_at(&b, 16), 10);
    assert_eq!(u32_at(&b, 20), 0);
    assert_eq!(u32_at(&b, 24), 11);
    assert_eq!(u32_at(&b, 28), 0xC004_0007);
    let w = decode_write(&b).unwrap();
    assert_eq!(w.items, vec![(10, 0), (11, 0xC004_0007u32 as i32)]);
    assert_eq!((w.client_group, w.transaction_id, w.status), (3, 77, 1));
}

#[test]
fn empty_streams() {
    let b = encode_data(DataFormat::DataTime, 1, 2, 0, &[]);
    assert_eq!(b.len(), GROUP_HEADER);
    assert!(decode_data(DataFormat::DataTime, &b)
        .unwrap()
        .items
        .is_empty());
    assert_eq!(encode_write(1, 2, 0, &[]).len(), GROUP_HEADER_WRITE);
}

#[test]
fn the_decoder_is_total() {
    let b = encode_data(
        DataFormat::DataTime,
        1,
        2,
        0,
        &[item(1, Value::Bstr("hello".into())), item(2, Value::I4(1))],
    );
    for n in 0..b.len() {
        assert!(
            decode_data(DataFormat::DataTime, &b[..n]).is_err(),
            "cut at {n}"
        );
    }
    let mut bad = b.clone();
    bad[GROUP_HEADER + 4] = 0xFF; // a value offset past the end
    assert!(decode_data(DataFormat::DataTime, &bad).is_err());
    assert!(decode_write(&[1, 0, 0, 0]).is_err());
}
