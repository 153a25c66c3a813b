//! DA values (VARIANTs, `ctopc_core::Value`) as OPC UA variants, and back for writes; DA
//! canonical types as UA data types.
//!
//! VT_CY becomes Double (the scaled integer divided by 10,000); VT_DATE becomes DateTime;
//! VT_ERROR becomes Int32 (its SCODE); a 1-D SAFEARRAY becomes a one-dimensional array of
//! its element type (VT_VARIANT arrays: BaseDataType). A value a client writes is taken as
//! the nearest VARIANT and goes through the engine's one write conversion to the item's
//! canonical type; a variant with no VARIANT counterpart (Guid, ByteString, structures,
//! matrices) is Bad_TypeMismatch.

use ctopc_core::value::ArrayValue;
use ctopc_core::{Timestamp, Value, VarType};
use opcua::types::{
    Array, DataTypeId, DateTime, NodeId, StatusCode, UAString, Variant, VariantScalarTypeId,
};

/// A DA timestamp as a UA DateTime (both are 100 ns ticks since 1601-01-01 UTC).
pub fn timestamp_to_ua(t: Timestamp) -> DateTime {
    DateTime::from(t.filetime().max(0))
}

/// A UA DateTime as a DA timestamp.
pub fn timestamp_from_ua(t: &DateTime) -> Timestamp {
    Timestamp::from_filetime(t.checked_ticks())
}

fn ole_date_to_ua(d: f64) -> Variant {
    match Timestamp::from_ole_date(d) {
        Some(t) => Variant::from(timestamp_to_ua(t)),
        None => Variant::Empty,
    }
}

/// A DA value as a UA variant.
pub fn to_variant(v: &Value) -> Variant {
    match v {
        Value::Empty => Variant::Empty,
        Value::I1(x) => Variant::SByte(*x),
        Value::UI1(x) => Variant::Byte(*x),
        Value::I2(x) => Variant::Int16(*x),
        Value::UI2(x) => Variant::UInt16(*x),
        Value::I4(x) => Variant::Int32(*x),
        Value::UI4(x) => Variant::UInt32(*x),
        Value::I8(x) => Variant::Int64(*x),
        Value::UI8(x) => Variant::UInt64(*x),
        Value::R4(x) => Variant::Float(*x),
        Value::R8(x) => Variant::Double(*x),
        Value::Cy(x) => Variant::Double(*x as f64 / 10_000.0),
        Value::Date(d) => ole_date_to_ua(*d),
        Value::Bstr(s) => Variant::String(UAString::from(s.as_str())),
        Value::Bool(b) => Variant::Boolean(*b),
        Value::Error(e) => Variant::Int32(*e),
        Value::Array(a) => array_to_variant(a),
    }
}

fn array_to_variant(a: &ArrayValue) -> Variant {
    let values: Vec<Variant> = a.elements.iter().map(to_variant).collect();
    let scalar = match scalar_type(a.element_type) {
        Some(t) => t,
        None => VariantScalarTypeId::Variant,
    };
    // Elements of a VT_VARIANT array keep their own types: wrapped as Variants.
    let values = if scalar == VariantScalarTypeId::Variant {
        values
            .into_iter()
            .map(|v| Variant::Variant(Box::new(v)))
            .collect()
    } else {
        values
    };
    match Array::new(scalar, values) {
        Ok(arr) => Variant::Array(Box::new(arr)),
        Err(_) => Variant::Empty,
    }
}

fn scalar_type(t: VarType) -> Option<VariantScalarTypeId> {
    Some(match t {
        VarType::I1 => VariantScalarTypeId::SByte,
        VarType::UI1 => VariantScalarTypeId::Byte,
        VarType::I2 => VariantScalarTypeId::Int16,
        VarType::UI2 => VariantScalarTypeId::UInt16,
        VarType::I4 | VarType::ERROR => VariantScalarTypeId::Int32,
        VarType::UI4 => VariantScalarTypeId::UInt32,
        VarType::I8 => VariantScalarTypeId::Int64,
        VarType::UI8 => VariantScalarTypeId::UInt64,
        VarType::R4 => VariantScalarTypeId::Float,
        VarType::R8 | VarType::CY => VariantScalarTypeId::Double,
        VarType::DATE => VariantScalarTypeId::DateTime,
        VarType::BSTR => VariantScalarTypeId::String,
        VarType::BOOL => VariantScalarTypeId::Boolean,
        _ => return None,
    })
}

/// The UA DataType and ValueRank (-1 scalar, 1 one-dimensional array) of a canonical type.
pub fn data_type(t: VarType) -> (NodeId, i32) {
    let rank = if t.is_array() { 1 } else { -1 };
    let id = match t.element() {
        VarType::I1 => DataTypeId::SByte,
        VarType::UI1 => DataTypeId::Byte,
        VarType::I2 => DataTypeId::Int16,
        VarType::UI2 => DataTypeId::UInt16,
        VarType::I4 | VarType::ERROR => DataTypeId::Int32,
        VarType::UI4 => DataTypeId::UInt32,
        VarType::I8 => DataTypeId::Int64,
        VarType::UI8 => DataTypeId::UInt64,
        VarType::R4 => DataTypeId::Float,
        VarType::R8 | VarType::CY => DataTypeId::Double,
        VarType::DATE => DataTypeId::DateTime,
        VarType::BSTR => DataTypeId::String,
        VarType::BOOL => DataTypeId::Boolean,
        _ => DataTypeId::BaseDataType,
    };
    (id.into(), rank)
}

/// A UA variant a client writes, as the DA value the engine's write conversion takes.
pub fn from_variant(v: &Variant) -> Result<Value, StatusCode> {
    Ok(match v {
        Variant::Boolean(b) => Value::Bool(*b),
        Variant::SByte(x) => Value::I1(*x),
        Variant::Byte(x) => Value::UI1(*x),
        Variant::Int16(x) => Value::I2(*x),
        Variant::UInt16(x) => Value::UI2(*x),
        Variant::Int32(x) => Value::I4(*x),
        Variant::UInt32(x) => Value::UI4(*x),
        Variant::Int64(x) => Value::I8(*x),
        Variant::UInt64(x) => Value::UI8(*x),
        Variant::Float(x) => Value::R4(*x),
        Variant::Double(x) => Value::R8(*x),
        Variant::String(s) => Value::Bstr(s.as_ref().to_owned()),
        Variant::DateTime(d) => Value::date_from(timestamp_from_ua(d)),
        Variant::Variant(inner) => return from_variant(inner),
        _ => return Err(StatusCode::BadTypeMismatch),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalars_round_trip() {
        for v in [
            Value::Bool(true),
            Value::I2(-7),
            Value::I4(123_456),
            Value::UI4(7),
            Value::R4(1.5),
            Value::R8(-2.25),
            Value::Bstr("Kocioł".into()),
        ] {
            assert_eq!(from_variant(&to_variant(&v)), Ok(v.clone()), "{v:?}");
        }
    }

    #[test]
    fn currency_and_arrays() {
        assert_eq!(to_variant(&Value::Cy(12_345)), Variant::Double(1.2345));
        let a = Value::Array(ArrayValue {
            element_type: VarType::R4,
            elements: vec![Value::R4(1.0), Value::R4(2.0)],
        });
        match to_variant(&a) {
            Variant::Array(arr) => {
                assert_eq!(arr.value_type, VariantScalarTypeId::Float);
                assert_eq!(arr.values, vec![Variant::Float(1.0), Variant::Float(2.0)]);
            }
            other => panic!("not an array: {other:?}"),
        }
        assert_eq!(
            data_type(VarType::array_of(VarType::R4)),
            (DataTypeId::Float.into(), 1)
        );
        assert_eq!(data_type(VarType::I2), (DataTypeId::Int16.into(), -1));
    }

    #[test]
    fn timestamps_keep_their_ticks() {
        let t = Timestamp::from_unix_millis(1_700_000_000_123);
        assert_eq!(timestamp_from_ua(&timestamp_to_ua(t)), t);
    }

    #[test]
    fn variants_without_a_variant_counterpart_are_type_mismatch() {
        let v = Variant::ByteString(vec![1u8, 2].into());
        assert_eq!(from_variant(&v), Err(StatusCode::BadTypeMismatch));
    }
}
