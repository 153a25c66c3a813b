//! OPC values: a VARIANT-like type, the VARTYPE codes and the value-quality-timestamp triple.
//! (Conversions with VariantChangeType semantics: see [`crate::convert`].)

use crate::{Quality, Timestamp};

/// A COM VARTYPE code for the types OPC DA uses. Arrays are `base | VT_ARRAY`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct VarType(pub u16);

impl VarType {
    pub const EMPTY: VarType = VarType(0);
    pub const I2: VarType = VarType(2);
    pub const I4: VarType = VarType(3);
    pub const R4: VarType = VarType(4);
    pub const R8: VarType = VarType(5);
    pub const CY: VarType = VarType(6);
    pub const DATE: VarType = VarType(7);
    pub const BSTR: VarType = VarType(8);
    pub const ERROR: VarType = VarType(10);
    pub const BOOL: VarType = VarType(11);
    pub const VARIANT: VarType = VarType(12);
    pub const I1: VarType = VarType(16);
    pub const UI1: VarType = VarType(17);
    pub const UI2: VarType = VarType(18);
    pub const UI4: VarType = VarType(19);
    pub const I8: VarType = VarType(20);
    pub const UI8: VarType = VarType(21);
    pub const ARRAY_FLAG: u16 = 0x2000;

    pub const fn array_of(base: VarType) -> VarType {
        VarType(base.0 | Self::ARRAY_FLAG)
    }
    pub const fn is_array(self) -> bool {
        self.0 & Self::ARRAY_FLAG != 0
    }
    pub const fn element(self) -> VarType {
        VarType(self.0 & !Self::ARRAY_FLAG)
    }
}

/// A value as OPC DA carries it in a VARIANT.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Value {
    #[default]
    Empty,
    I1(i8),
    UI1(u8),
    I2(i16),
    UI2(u16),
    I4(i32),
    UI4(u32),
    I8(i64),
    UI8(u64),
    R4(f32),
    R8(f64),
    /// Currency: a 64-bit integer scaled by 10,000.
    Cy(i64),
    /// OLE automation date.
    Date(f64),
    Bstr(String),
    Bool(bool),
    /// An SCODE (VT_ERROR).
    Error(i32),
    /// A 1-D array (SAFEARRAY) whose elements all have `element_type`
    /// (VT_VARIANT for mixed arrays).
    Array(ArrayValue),
}

/// A 1-D array of values of one element type.
#[derive(Debug, Clone, PartialEq)]
pub struct ArrayValue {
    pub element_type: VarType,
    pub elements: Vec<Value>,
}

impl Value {
    /// The VARTYPE of this value.
    pub fn var_type(&self) -> VarType {
        match self {
            Value::Empty => VarType::EMPTY,
            Value::I1(_) => VarType::I1,
            Value::UI1(_) => VarType::UI1,
            Value::I2(_) => VarType::I2,
            Value::UI2(_) => VarType::UI2,
            Value::I4(_) => VarType::I4,
            Value::UI4(_) => VarType::UI4,
            Value::I8(_) => VarType::I8,
            Value::UI8(_) => VarType::UI8,
            Value::R4(_) => VarType::R4,
            Value::R8(_) => VarType::R8,
            Value::Cy(_) => VarType::CY,
            Value::Date(_) => VarType::DATE,
            Value::Bstr(_) => VarType::BSTR,
            Value::Bool(_) => VarType::BOOL,
            Value::Error(_) => VarType::ERROR,
            Value::Array(a) => VarType::array_of(a.element_type),
        }
    }

    /// The value as a number for deadband checks: every integer type, R4, R8, CY (in
    /// currency units) and BOOL (VARIANT_TRUE = -1, as VariantChangeType converts it).
    /// `None` for EMPTY, DATE, BSTR, ERROR and arrays.
    pub fn as_f64(&self) -> Option<f64> {
        Some(match *self {
            Value::I1(v) => v.into(),
            Value::UI1(v) => v.into(),
            Value::I2(v) => v.into(),
            Value::UI2(v) => v.into(),
            Value::I4(v) => v.into(),
            Value::UI4(v) => v.into(),
            Value::I8(v) => v as f64,
            Value::UI8(v) => v as f64,
            Value::R4(v) => v.into(),
            Value::R8(v) => v,
            Value::Cy(v) => v as f64 / 10_000.0,
            Value::Bool(b) => {
                if b {
                    -1.0
                } else {
                    0.0
                }
            }
            Value::Empty | Value::Date(_) | Value::Bstr(_) | Value::Error(_) | Value::Array(_) => {
                return None
            }
        })
    }
}

impl Value {
    /// A VT_DATE value for a UTC timestamp (OLE automation date; OPC's "Item Timestamp"
    /// property and the timestamp element of an extended write).
    pub fn date_from(t: Timestamp) -> Value {
        Value::Date(t.to_ole_date())
    }

    /// This value as a timestamp: it is converted to VT_DATE first (so a BSTR date or a
    /// number of days works too). DISP_E_OVERFLOW for dates before 1601 (no FILETIME).
    pub fn to_timestamp(&self) -> Result<Timestamp, crate::OpcError> {
        match self.convert(VarType::DATE)? {
            Value::Date(d) => Timestamp::from_ole_date(d).ok_or(crate::OpcError::Overflow),
            _ => Err(crate::OpcError::TypeMismatch),
        }
    }
}

impl ArrayValue {
    pub fn new(element_type: VarType, elements: Vec<Value>) -> Self {
        ArrayValue {
            element_type,
            elements,
        }
    }
}

/// A value with its quality and UTC timestamp, as the data source delivers it and the
/// cache holds it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Vqt {
    pub value: Value,
    pub quality: Quality,
    pub timestamp: Timestamp,
}

impl Vqt {
    pub fn new(value: Value, quality: Quality, timestamp: Timestamp) -> Self {
        Vqt {
            value,
            quality,
            timestamp,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn as_f64_covers_numbers_and_bool_only() {
        let table: &[(Value, Option<f64>)] = &[
            (Value::I1(-5), Some(-5.0)),
            (Value::UI1(200), Some(200.0)),
            (Value::I2(-300), Some(-300.0)),
            (Value::UI2(60000), Some(60000.0)),
            (Value::I4(-70000), Some(-70000.0)),
            (Value::UI4(4_000_000_000), Some(4e9)),
            (Value::I8(-1 << 40), Some(-(2f64.powi(40)))),
            (Value::UI8(1 << 40), Some(2f64.powi(40))),
            (Value::R4(1.5), Some(1.5)),
            (Value::R8(-2.25), Some(-2.25)),
            (Value::Cy(12_345), Some(1.2345)),
            (Value::Bool(true), Some(-1.0)),
            (Value::Bool(false), Some(0.0)),
            (Value::Empty, None),
            (Value::Date(45_000.5), None),
            (Value::Bstr("1".into()), None),
            (Value::Error(1), None),
            (
                Value::Array(ArrayValue::new(VarType::R8, vec![Value::R8(1.0)])),
                None,
            ),
        ];
        for (v, expected) in table {
            assert_eq!(v.as_f64(), *expected, "{v:?}");
        }
    }

    #[test]
    fn timestamps_convert_to_and_from_ole_dates() {
        let epoch = Timestamp::from_unix_millis(0);
        assert_eq!(Value::date_from(epoch), Value::Date(25_569.0));
        assert_eq!(
            Value::Date(25_569.5).to_timestamp(),
            Ok(Timestamp::from_unix_millis(43_200_000))
        );
        assert_eq!(
            Value::Bstr("1/1/1970 12:00:00 PM".into()).to_timestamp(),
            Ok(Timestamp::from_unix_millis(43_200_000))
        );
        assert_eq!(Value::R8(25_569.0).to_timestamp(), Ok(epoch));
        assert_eq!(Value::Date(-109_205.0).to_timestamp(), Ok(Timestamp(0))); // 1601-01-01
        assert_eq!(
            Value::Date(-109_206.0).to_timestamp(),
            Err(crate::OpcError::Overflow)
        );
        assert_eq!(
            Value::Bstr("x".into()).to_timestamp(),
            Err(crate::OpcError::TypeMismatch)
        );
        assert_eq!(
            Value::Error(0).to_timestamp(),
            Err(crate::OpcError::TypeMismatch)
        );
    }

    #[test]
    fn var_type_of_arrays_carries_the_array_flag() {
        let a = Value::Array(ArrayValue::new(
            VarType::VARIANT,
            vec![Value::I4(1), Value::Bstr("x".into())],
        ));
        assert_eq!(a.var_type(), VarType(0x200C));
        assert!(a.var_type().is_array());
        assert_eq!(a.var_type().element(), VarType::VARIANT);
    }
}
