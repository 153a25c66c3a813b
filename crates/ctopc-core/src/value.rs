//! OPC values: a VARIANT-like type and the VARTYPE codes.
//! (Conversions with VariantChangeType semantics: see `convert`.)

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
}
