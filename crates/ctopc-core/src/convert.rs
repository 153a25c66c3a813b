//! Value conversions with the observable semantics of Windows' `VariantChangeTypeEx`
//! (oleaut32), as an OPC server applies them to requested data types and writes.
//!
//! Reference: Wine's `dlls/oleaut32/variant.c` (`VARIANT_Coerce`), `vartype.c` and its
//! conformance tests, which run against native Windows. Rules:
//!
//! - **Overflow** (`DISP_E_OVERFLOW`): the value does not fit in the target type.
//!   Floating point (R4, R8, DATE) and CY convert to integers with banker's rounding
//!   (half to even) first, so 2.5 -> 2, 3.5 -> 4, -0.5 -> 0 (also for unsigned targets)
//!   and 255.5 -> UI1 overflows.
//! - **Type mismatch** (`DISP_E_TYPEMISMATCH`): the conversion is impossible (VT_ERROR to
//!   or from anything else, a string that is not a number, an array to a scalar, ...).
//! - **Signed <-> unsigned of the same size** is range-checked: -1 -> UI2 overflows. (Bare
//!   `VariantChangeType` reinterprets the bits there, -1 -> 65535; the OPC Foundation's
//!   sample server corrects that to DISP_E_OVERFLOW, and so do we.)
//! - **BOOL** is VARIANT_TRUE = -1 / 0: true -> I4 is -1, -> R8 -1.0, -> CY -1.0000, and,
//!   as VariantChangeType does, true -> UI1/UI2/UI4/UI8 is the all-ones value (255, ...).
//!   Any nonzero number (and NaN) -> true.
//! - **BOOL <-> BSTR**: "True"/"False" (the VARIANT_ALPHABOOL wording, always English);
//!   from BSTR also case-insensitive "true"/"false", "#TRUE#"/"#FALSE#" and any number
//!   ("-1", "0", "2.5" -> true).
//! - **Numbers -> BSTR**: integers in decimal; R4 with 7 and R8 with 15 significant digits
//!   (printf `%.7G` / `%.15G`: R4 1.1 -> "1.1", R8 0.1+0.2 -> "0.3", 1e20 -> "1E+20");
//!   CY with up to 4 decimals, trailing zeros dropped; never "-0". The decimal separator is
//!   the locale's (pl-PL: "1,5").
//! - **BSTR -> numbers**: `VarParseNumFromStr` syntax for the locale: surrounding white
//!   space, leading or trailing sign, parentheses for negative, the currency symbol,
//!   thousands separators after the first digit, one decimal separator, an exponent,
//!   `&H` hex and `&O` octal (hex/octal fill the target's bits: "&HFFFF" -> I2 is -1).
//!   Decimal digits are rounded exactly (banker's) to integer targets.
//! - **DATE** is the OLE automation date (days since 1899-12-30, valid from year 100 to
//!   9999); numbers outside that range overflow. DATE -> BSTR uses the locale's short date
//!   and long time ("1/2/1900 8:09:36 AM", pl-PL "02.01.1900 08:09:36"), date only when
//!   the time is midnight and time only on day 0.
//! - **CY** is an i64 scaled by 10,000; from floating point it rounds half to even at the
//!   fourth decimal.
//! - **EMPTY** converts to 0, "", false, DATE 0 and CY 0 (but not to ERROR).
//! - **Target EMPTY or VARIANT** returns the value unchanged (OPC: "the canonical type").
//! - **Arrays** (1-D SAFEARRAYs) convert element by element, including VT_ARRAY|VT_VARIANT
//!   in both directions; this is what OPC servers do (VariantChangeType itself refuses to
//!   convert arrays). An element's error is the array's error.

use crate::lang::Lang;
use crate::time::{civil_from_days, days_from_civil};
use crate::value::ArrayValue;
use crate::{OpcError, Value, VarType};

/// The number and date formats of a locale, for conversions to and from BSTR.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Locale {
    /// en-US (0x0409), also used as the invariant locale: "1,234.5", "$", "M/d/yyyy h:mm:ss tt".
    #[default]
    EnUs,
    /// pl-PL (0x0415): "1 234,5" (no-break space), "zł", "dd.MM.yyyy HH:mm:ss".
    PlPl,
}

impl Locale {
    /// The conversion locale for an LCID: Polish LCIDs are pl-PL; LOCALE_NEUTRAL,
    /// LOCALE_USER_DEFAULT and LOCALE_SYSTEM_DEFAULT are `system_default`; every other
    /// LCID uses en-US (the only other number format the server knows).
    pub const fn from_lcid(lcid: u32, system_default: Locale) -> Locale {
        match lcid & 0xFFFF {
            0x0000 | 0x0400 | 0x0800 => system_default,
            id if id & 0x03FF == 0x15 => Locale::PlPl,
            _ => Locale::EnUs,
        }
    }
    pub const fn decimal_separator(self) -> char {
        match self {
            Locale::EnUs => '.',
            Locale::PlPl => ',',
        }
    }
    /// The digit-group separator (pl-PL: U+00A0; a plain space is accepted too when parsing).
    pub const fn thousands_separator(self) -> char {
        match self {
            Locale::EnUs => ',',
            Locale::PlPl => '\u{A0}',
        }
    }
    pub const fn currency_symbol(self) -> &'static str {
        match self {
            Locale::EnUs => "$",
            Locale::PlPl => "zł",
        }
    }
}

impl From<Lang> for Locale {
    fn from(lang: Lang) -> Locale {
        match lang {
            Lang::Polish => Locale::PlPl,
            Lang::English => Locale::EnUs,
        }
    }
}

// VARTYPE codes this module needs beyond the `VarType` constants.
const VT_NULL: u16 = 1;
const VT_VOID: u16 = 24;
const VT_RECORD: u16 = 36;
const VT_CLSID: u16 = 72;
const VT_VECTOR: u16 = 0x1000;
const VT_BYREF: u16 = 0x4000;
const VT_RESERVED: u16 = 0x8000;

/// The first and last valid OLE dates (100-01-01 and 9999-12-31).
const DATE_MIN: f64 = -657_434.0;
const DATE_MAX: f64 = 2_958_465.0;
const CY_SCALE: i64 = 10_000;

impl Value {
    /// Converts to `to` as `VariantChangeTypeEx(.., LOCALE_INVARIANT / en-US, 0, to)` would,
    /// with the OPC rules in the [module documentation](crate::convert).
    pub fn convert(&self, to: VarType) -> Result<Value, OpcError> {
        self.convert_in(to, Locale::EnUs)
    }

    /// As [`Value::convert`], with `locale`'s number and date formats for BSTR.
    pub fn convert_in(&self, to: VarType, locale: Locale) -> Result<Value, OpcError> {
        validate_vartype(to)?;
        if to == VarType::EMPTY || to == VarType::VARIANT {
            return Ok(self.clone());
        }
        match (self, to.is_array()) {
            (Value::Array(a), true) => convert_array(a, to.element(), locale),
            (Value::Array(_), false) | (_, true) => Err(OpcError::TypeMismatch),
            (v, false) => coerce_scalar(v, to, locale),
        }
    }
}

/// A value a client writes (IOPCSyncIO::Write, IOPCAsyncIO2/3 Write, WriteVQT, the value
/// element of the asix extended write), converted to the item's canonical type `to` as
/// `VariantChangeTypeEx(.., lcid of the group, 0, to)` would, with the write rules of
/// OPC DA generic clients rely on:
///
/// - every integer and real type, CY (also from a DECIMAL, which the COM layer decodes)
///   and numeric text in the group's locale (pl-PL `"12,5"`, en-US `"12.5"`, blanks
///   around it, sign, exponent, thousands separators, `&H` hex: the `VarParseNumFromStr`
///   syntax of [`Value::convert_in`]) convert; then the range check: a value the target
///   cannot hold is `OPC_E_RANGE` (DISP_E_OVERFLOW of the conversion);
/// - BOOL written to an integer or real item is **TRUE -> 1, FALSE -> 0**. Here we depart
///   from VariantChangeType, which gives VARIANT_TRUE = -1 (and 255, 65535, ... for
///   unsigned targets): a client that writes TRUE to a process variable (a switch, a
///   set-point enable, an Excel check box) means "on", i.e. 1 in the PLC register, and -1
///   would be out of range of every unsigned or 0/1 variable;
/// - text that is not a number (also "True"/"False": VarI4FromStr refuses them too), DATE
///   (a point in time is no process value, although VariantChangeType would give its day
///   count), VT_ERROR, VT_EMPTY and arrays to a scalar item are `OPC_E_BADTYPE`;
/// - an item whose canonical type is not a number (other namespaces than asix) converts
///   as [`Value::convert_in`] does, its overflow `OPC_E_RANGE`, any other failure
///   `OPC_E_BADTYPE`.
pub fn convert_for_write(value: &Value, to: VarType, locale: Locale) -> Result<Value, OpcError> {
    let numeric_target = int_width(to).is_some() || to == VarType::R4 || to == VarType::R8;
    let value = match value {
        Value::Empty | Value::Error(_) => return Err(OpcError::BadType),
        _ if !numeric_target => value,
        Value::Date(_) | Value::Array(_) => return Err(OpcError::BadType),
        Value::Bool(b) => &Value::I4(i32::from(*b)),
        v => v,
    };
    if value.var_type() == to {
        return Ok(value.clone());
    }
    value.convert_in(to, locale).map_err(|e| match e {
        OpcError::Overflow => OpcError::Range,
        _ => OpcError::BadType,
    })
}

/// True for the types [`Value::convert`] can produce: EMPTY, VARIANT, the scalar types of
/// [`Value`] and 1-D arrays of them (or of VARIANT). OPC's AddItems/SetDatatypes use this
/// to answer OPC_E_BADTYPE up front.
pub fn is_supported_type(vt: VarType) -> bool {
    if vt.is_array() {
        let e = vt.element();
        e == VarType::VARIANT || (e != VarType::EMPTY && is_scalar(e))
    } else {
        vt == VarType::EMPTY || vt == VarType::VARIANT || is_scalar(vt)
    }
}

fn is_scalar(vt: VarType) -> bool {
    matches!(
        vt,
        VarType::I1
            | VarType::UI1
            | VarType::I2
            | VarType::UI2
            | VarType::I4
            | VarType::UI4
            | VarType::I8
            | VarType::UI8
            | VarType::R4
            | VarType::R8
            | VarType::CY
            | VarType::DATE
            | VarType::BSTR
            | VarType::BOOL
            | VarType::ERROR
    )
}

/// `VARIANT_ValidateType`: DISP_E_BADVARTYPE for codes that are no VARTYPE at all; valid
/// codes we cannot hold (VT_NULL, VT_DECIMAL, VT_DISPATCH, VT_BYREF ...) are type mismatches.
fn validate_vartype(vt: VarType) -> Result<(), OpcError> {
    let extra = vt.0 & 0xF000;
    let base = vt.0 & 0x0FFF;
    let valid_base = (base < VT_VOID || base == VT_RECORD || base == VT_CLSID) && base != 15;
    let array_of_nothing = extra & (VarType::ARRAY_FLAG | VT_BYREF) != 0 && base <= VT_NULL;
    if extra & (VT_VECTOR | VT_RESERVED) != 0 || !valid_base || array_of_nothing {
        return Err(OpcError::BadVarType);
    }
    if is_supported_type(vt) {
        Ok(())
    } else {
        Err(OpcError::TypeMismatch)
    }
}

fn convert_array(a: &ArrayValue, to_elem: VarType, locale: Locale) -> Result<Value, OpcError> {
    if to_elem == a.element_type && to_elem != VarType::VARIANT {
        return Ok(Value::Array(a.clone()));
    }
    let elements = if to_elem == VarType::VARIANT {
        a.elements.clone()
    } else {
        a.elements
            .iter()
            .map(|e| match e {
                Value::Array(_) => Err(OpcError::TypeMismatch),
                e if e.var_type() == to_elem => Ok(e.clone()),
                e => coerce_scalar(e, to_elem, locale),
            })
            .collect::<Result<Vec<_>, _>>()?
    };
    Ok(Value::Array(ArrayValue::new(to_elem, elements)))
}

/// A scalar source, reduced to what the conversion rules distinguish.
enum Num {
    /// Any integer type (exact).
    Int(i128),
    /// VARIANT_BOOL: -1 or 0.
    Bool(bool),
    /// R4 (widened exactly), R8 or DATE.
    Real(f64),
    /// Currency, scaled by 10,000.
    Cy(i64),
}

fn coerce_scalar(v: &Value, to: VarType, locale: Locale) -> Result<Value, OpcError> {
    if v.var_type() == to {
        return Ok(v.clone());
    }
    if to == VarType::ERROR {
        return Err(OpcError::TypeMismatch);
    }
    let num = match v {
        Value::Empty => return Ok(zero_of(to)),
        Value::Error(_) | Value::Array(_) => return Err(OpcError::TypeMismatch),
        Value::Bstr(s) => return from_bstr(s, to, locale),
        Value::I1(x) => Num::Int((*x).into()),
        Value::UI1(x) => Num::Int((*x).into()),
        Value::I2(x) => Num::Int((*x).into()),
        Value::UI2(x) => Num::Int((*x).into()),
        Value::I4(x) => Num::Int((*x).into()),
        Value::UI4(x) => Num::Int((*x).into()),
        Value::I8(x) => Num::Int((*x).into()),
        Value::UI8(x) => Num::Int((*x).into()),
        Value::R4(x) => Num::Real((*x).into()),
        Value::R8(x) => Num::Real(*x),
        Value::Cy(x) => Num::Cy(*x),
        Value::Date(d) if to == VarType::BSTR => return Ok(Value::Bstr(format_date(*d, locale)?)),
        Value::Date(d) => Num::Real(*d),
        Value::Bool(b) => Num::Bool(*b),
    };
    if to == VarType::BSTR {
        return Ok(Value::Bstr(match (v, num) {
            (Value::R4(x), _) => format_real(f64::from(*x), 7, locale),
            (_, Num::Real(x)) => format_real(x, 15, locale),
            (_, Num::Cy(c)) => format_cy(c, locale),
            (_, Num::Bool(b)) => if b { "True" } else { "False" }.to_owned(),
            (_, Num::Int(i)) => i.to_string(),
        }));
    }
    from_num(num, to)
}

fn zero_of(to: VarType) -> Value {
    match to {
        VarType::I1 => Value::I1(0),
        VarType::UI1 => Value::UI1(0),
        VarType::I2 => Value::I2(0),
        VarType::UI2 => Value::UI2(0),
        VarType::I4 => Value::I4(0),
        VarType::UI4 => Value::UI4(0),
        VarType::I8 => Value::I8(0),
        VarType::UI8 => Value::UI8(0),
        VarType::R4 => Value::R4(0.0),
        VarType::R8 => Value::R8(0.0),
        VarType::CY => Value::Cy(0),
        VarType::DATE => Value::Date(0.0),
        VarType::BSTR => Value::Bstr(String::new()),
        VarType::BOOL => Value::Bool(false),
        _ => Value::Empty,
    }
}

/// The integer `x` as `to`, or Overflow.
fn int_to(x: i128, to: VarType) -> Result<Value, OpcError> {
    let o = |_| OpcError::Overflow;
    Ok(match to {
        VarType::I1 => Value::I1(x.try_into().map_err(o)?),
        VarType::UI1 => Value::UI1(x.try_into().map_err(o)?),
        VarType::I2 => Value::I2(x.try_into().map_err(o)?),
        VarType::UI2 => Value::UI2(x.try_into().map_err(o)?),
        VarType::I4 => Value::I4(x.try_into().map_err(o)?),
        VarType::UI4 => Value::UI4(x.try_into().map_err(o)?),
        VarType::I8 => Value::I8(x.try_into().map_err(o)?),
        VarType::UI8 => Value::UI8(x.try_into().map_err(o)?),
        _ => return Err(OpcError::TypeMismatch),
    })
}

/// Bits of an integer VARTYPE and whether it is signed.
fn int_width(to: VarType) -> Option<(u32, bool)> {
    Some(match to {
        VarType::I1 => (8, true),
        VarType::UI1 => (8, false),
        VarType::I2 => (16, true),
        VarType::UI2 => (16, false),
        VarType::I4 => (32, true),
        VarType::UI4 => (32, false),
        VarType::I8 => (64, true),
        VarType::UI8 => (64, false),
        _ => return None,
    })
}

/// `x`'s low `bits` bits as the integer type `to` (two's complement for signed types).
fn bits_to(x: u64, to: VarType) -> Result<Value, OpcError> {
    let (bits, signed) = int_width(to).ok_or(OpcError::TypeMismatch)?;
    let shift = 64 - bits;
    let v = if signed {
        i128::from(((x << shift) as i64) >> shift)
    } else {
        i128::from((x << shift) >> shift)
    };
    int_to(v, to)
}

/// Round half to even, then range-check as `to`.
fn real_to_int(x: f64, to: VarType) -> Result<Value, OpcError> {
    if !x.is_finite() {
        return Err(OpcError::Overflow);
    }
    let r = x.round_ties_even();
    // ±2^127 bounds every target; the exact check happens in int_to.
    if r.abs() >= 1.7e38 {
        return Err(OpcError::Overflow);
    }
    int_to(r as i128, to)
}

/// Banker's rounding of `cy / 10_000`.
fn cy_to_int(cy: i64) -> i128 {
    let q = i128::from(cy / CY_SCALE);
    let r = cy % CY_SCALE;
    let half = CY_SCALE / 2;
    let odd = q & 1 != 0;
    if r > half || (r == half && odd) {
        q + 1
    } else if r < -half || (r == -half && odd) {
        q - 1
    } else {
        q
    }
}

/// `x * 10_000` rounded half to even, computed exactly from the binary value of `x`.
fn real_to_cy(x: f64) -> Result<i64, OpcError> {
    if !x.is_finite() {
        return Err(OpcError::Overflow);
    }
    if x == 0.0 {
        return Ok(0);
    }
    let bits = x.to_bits();
    let neg = bits >> 63 != 0;
    let exp = ((bits >> 52) & 0x7FF) as i32;
    let frac = bits & ((1u64 << 52) - 1);
    let (mant, e) = if exp == 0 {
        (frac, -1074)
    } else {
        (frac | (1u64 << 52), exp - 1075)
    };
    let num = u128::from(mant) * CY_SCALE as u128; // < 2^67
    let magnitude: u128 = if e >= 0 {
        if e > 60 {
            return Err(OpcError::Overflow);
        }
        num << e
    } else {
        let shift = (-e) as u32;
        if shift >= 100 {
            0 // below 2^-33: rounds to 0, no tie possible
        } else {
            let q = num >> shift;
            let rem = num & ((1u128 << shift) - 1);
            let half = 1u128 << (shift - 1);
            if rem > half || (rem == half && q & 1 == 1) {
                q + 1
            } else {
                q
            }
        }
    };
    let signed = if neg {
        -(magnitude as i128)
    } else {
        magnitude as i128
    };
    i64::try_from(signed).map_err(|_| OpcError::Overflow)
}

fn real_to_r4(x: f64) -> Result<Value, OpcError> {
    if x.abs() > f64::from(f32::MAX) {
        return Err(OpcError::Overflow);
    }
    Ok(Value::R4(x as f32))
}

fn real_to_date(x: f64) -> Result<Value, OpcError> {
    if x > DATE_MIN - 1.0 && x < DATE_MAX + 1.0 {
        Ok(Value::Date(x))
    } else {
        Err(OpcError::Overflow)
    }
}

fn from_num(num: Num, to: VarType) -> Result<Value, OpcError> {
    match num {
        Num::Int(i) => match to {
            VarType::R4 => Ok(Value::R4(i as f32)),
            VarType::R8 => Ok(Value::R8(i as f64)),
            VarType::CY => i
                .checked_mul(CY_SCALE.into())
                .and_then(|c| i64::try_from(c).ok())
                .map(Value::Cy)
                .ok_or(OpcError::Overflow),
            VarType::DATE => {
                if (DATE_MIN as i128..=DATE_MAX as i128).contains(&i) {
                    Ok(Value::Date(i as f64))
                } else {
                    Err(OpcError::Overflow)
                }
            }
            VarType::BOOL => Ok(Value::Bool(i != 0)),
            _ => int_to(i, to),
        },
        Num::Bool(b) => match to {
            // VARIANT_TRUE (-1) cast into the target, as oleaut32's VarXxxFromBool do.
            _ if int_width(to).is_some() => bits_to(if b { u64::MAX } else { 0 }, to),
            _ => from_num(if b { Num::Int(-1) } else { Num::Int(0) }, to),
        },
        Num::Real(x) => match to {
            VarType::R4 => real_to_r4(x),
            VarType::R8 => Ok(Value::R8(x)),
            VarType::CY => real_to_cy(x).map(Value::Cy),
            VarType::DATE => real_to_date(x),
            VarType::BOOL => Ok(Value::Bool(x != 0.0)),
            _ => real_to_int(x, to),
        },
        Num::Cy(c) => match to {
            VarType::R4 => real_to_r4(c as f64 / CY_SCALE as f64),
            VarType::R8 => Ok(Value::R8(c as f64 / CY_SCALE as f64)),
            VarType::DATE => real_to_date(c as f64 / CY_SCALE as f64),
            VarType::BOOL => Ok(Value::Bool(c != 0)),
            _ => int_to(cy_to_int(c), to),
        },
    }
}

// ---------------------------------------------------------------------------------------
// Numbers to text

/// printf `%.{p}G` without negative zero, with the locale's decimal separator.
fn format_real(x: f64, p: usize, locale: Locale) -> String {
    if x.is_nan() {
        return "NaN".to_owned();
    }
    if x.is_infinite() {
        return if x > 0.0 { "INF" } else { "-INF" }.to_owned();
    }
    if x == 0.0 {
        return "0".to_owned();
    }
    // Round to p significant digits first: that fixes the decimal exponent.
    let sci = format!("{:.*e}", p - 1, x);
    let (mantissa, exp) = sci.split_once('e').unwrap_or((sci.as_str(), "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let mut s = if exp < -4 || exp >= p as i32 {
        let m = trim_fraction(mantissa);
        format!(
            "{m}E{}{:02}",
            if exp < 0 { '-' } else { '+' },
            exp.unsigned_abs()
        )
    } else {
        let decimals = (p as i32 - 1 - exp).max(0) as usize;
        trim_fraction(&format!("{x:.decimals$}")).to_owned()
    };
    if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') {
        s = "0".to_owned();
    }
    localize_decimal(s, locale)
}

fn trim_fraction(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

fn localize_decimal(s: String, locale: Locale) -> String {
    match locale.decimal_separator() {
        '.' => s,
        sep => s.replace('.', &sep.to_string()),
    }
}

fn format_cy(c: i64, locale: Locale) -> String {
    let sign = if c < 0 { "-" } else { "" };
    let abs = c.unsigned_abs();
    let whole = abs / CY_SCALE as u64;
    let frac = abs % CY_SCALE as u64;
    let s = if frac == 0 {
        format!("{sign}{whole}")
    } else {
        let f = format!("{frac:04}");
        format!("{sign}{whole}.{}", f.trim_end_matches('0'))
    };
    localize_decimal(s, locale)
}

// ---------------------------------------------------------------------------------------
// Text to numbers (VarParseNumFromStr + VarNumFromParseNum)

/// A parsed number: decimal `±digits × 10^exp10`, or the bits of a hex/octal literal.
#[derive(Debug, PartialEq)]
enum Parsed {
    Decimal {
        neg: bool,
        digits: Vec<u8>,
        exp10: i32,
    },
    Radix(u64),
}

fn parse_number(s: &str, locale: Locale) -> Result<Parsed, OpcError> {
    let mismatch = OpcError::TypeMismatch;
    let dec = locale.decimal_separator();
    let thou = locale.thousands_separator();
    // A no-break space as group separator admits a plain space too (as oleaut32 does).
    let is_thou = |c: char| c == thou || (thou == '\u{A0}' && c == ' ');
    let chars: Vec<char> = s.chars().collect();
    let cur: Vec<char> = locale.currency_symbol().chars().collect();
    let at_currency = |i: usize| chars.get(i..i + cur.len()) == Some(&cur[..]);

    let mut i = 0;
    let (mut plus, mut minus, mut paren, mut currency, mut decimal) =
        (false, false, false, false, false);
    // Leading white space and symbols; a decimal separator ends them.
    while let Some(&c) = chars.get(i) {
        if c == dec {
            decimal = true;
            i += 1;
            break;
        } else if c.is_whitespace() {
            i += 1;
        } else if is_thou(c) {
            return Err(mismatch); // not allowed before the first digit
        } else if c == '+' && !plus {
            plus = true;
            i += 1;
        } else if c == '-' && !minus {
            minus = true;
            i += 1;
        } else if !currency && at_currency(i) {
            currency = true;
            i += cur.len();
        } else if c == '(' && !paren {
            paren = true;
            i += 1;
        } else {
            break;
        }
    }

    // &H hex and &O octal literals (the sign is ignored, as VarNumFromParseNum does).
    let radix = match (chars.get(i), chars.get(i + 1)) {
        (Some('&'), Some('H' | 'h')) if !currency && !decimal => 16,
        (Some('&'), Some('O' | 'o')) if !currency && !decimal => 8,
        _ => 10,
    };
    if radix != 10 {
        i += 2;
        let start = i;
        let mut bits: u64 = 0;
        while let Some(d) = chars.get(i).and_then(|c| c.to_digit(radix)) {
            bits = bits
                .checked_mul(u64::from(radix))
                .and_then(|v| v.checked_add(u64::from(d)))
                .ok_or(OpcError::Overflow)?;
            i += 1;
        }
        let (end, _) = skip_trailing(&chars, i, plus, minus, &mut paren, |_| false, |_| false, 0);
        if i == start || end != chars.len() || paren {
            return Err(mismatch);
        }
        return Ok(Parsed::Radix(bits));
    }

    // Digits with group separators, one decimal separator and an optional exponent.
    let mut digits: Vec<u8> = Vec::new();
    let mut exp10: i32 = 0;
    let mut any_digit = false;
    while let Some(&c) = chars.get(i) {
        if c.is_ascii_digit() {
            let d = c as u8 - b'0';
            any_digit = true;
            if !(digits.is_empty() && d == 0) {
                digits.push(d);
            }
            if decimal {
                exp10 -= 1;
            }
            i += 1;
        } else if is_thou(c) {
            i += 1;
        } else if c == dec && !decimal {
            decimal = true;
            i += 1;
        } else if (c == 'e' || c == 'E') && !currency {
            i += 1;
            let mut negative_exponent = false;
            while let Some(&sign @ ('+' | '-')) = chars.get(i) {
                negative_exponent |= sign == '-';
                i += 1;
            }
            let start = i;
            let mut e: i32 = 0;
            while let Some(d) = chars.get(i).filter(|c| c.is_ascii_digit()) {
                e = e
                    .saturating_mul(10)
                    .saturating_add(i32::from(*d as u8 - b'0'));
                i += 1;
            }
            if i == start {
                return Err(mismatch); // an exponent needs digits
            }
            exp10 = exp10.saturating_add(if negative_exponent { -e } else { e });
            break;
        } else {
            break;
        }
    }
    let (end, negative_suffix) = skip_trailing(
        &chars,
        i,
        plus,
        minus,
        &mut paren,
        is_thou,
        at_currency,
        cur.len(),
    );
    if end != chars.len() || paren || !any_digit {
        return Err(mismatch);
    }
    // Normalise: trailing zeros of the significand go into the exponent.
    while digits.last() == Some(&0) {
        digits.pop();
        exp10 = exp10.saturating_add(1);
    }
    if digits.is_empty() {
        exp10 = 0;
    }
    Ok(Parsed::Decimal {
        neg: (minus || negative_suffix) && !digits.is_empty(),
        digits,
        exp10,
    })
}

/// Consumes trailing group separators, white space, a sign, ')' and the currency symbol;
/// returns the index after them and whether a trailing '-' or a closing ')' made the
/// number negative.
#[allow(clippy::too_many_arguments)]
fn skip_trailing(
    chars: &[char],
    mut i: usize,
    leading_plus: bool,
    leading_minus: bool,
    paren: &mut bool,
    is_thou: impl Fn(char) -> bool,
    at_currency: impl Fn(usize) -> bool,
    currency_len: usize,
) -> (usize, bool) {
    let (mut plus, mut minus, mut currency, mut negative) =
        (leading_plus, leading_minus, false, false);
    while let Some(&c) = chars.get(i) {
        if is_thou(c) || c.is_whitespace() {
            i += 1;
        } else if c == '+' && !plus {
            plus = true;
            i += 1;
        } else if c == '-' && !minus {
            minus = true;
            negative = true;
            i += 1;
        } else if c == ')' && *paren {
            *paren = false;
            negative = true;
            i += 1;
        } else if currency_len > 0 && !currency && at_currency(i) {
            currency = true;
            i += currency_len;
        } else {
            break;
        }
    }
    (i, negative)
}

/// A parsed decimal as an integer, rounded half to even exactly; Overflow beyond ±2^127.
fn decimal_to_int(neg: bool, digits: &[u8], exp10: i32) -> Result<i128, OpcError> {
    let n = digits.len() as i64;
    let whole_len = n + i64::from(exp10);
    let mut whole: u128 = 0;
    if whole_len > 39 {
        return Err(OpcError::Overflow);
    }
    for k in 0..whole_len.max(0) {
        let d = digits.get(k as usize).copied().unwrap_or(0);
        whole = whole
            .checked_mul(10)
            .and_then(|w| w.checked_add(d.into()))
            .ok_or(OpcError::Overflow)?;
    }
    if whole_len >= 0 && (whole_len as usize) < digits.len() {
        let frac = &digits[whole_len as usize..];
        let up =
            frac[0] > 5 || (frac[0] == 5 && (frac[1..].iter().any(|&d| d != 0) || whole & 1 == 1));
        if up {
            whole += 1;
        }
    }
    let w = i128::try_from(whole).map_err(|_| OpcError::Overflow)?;
    Ok(if neg { -w } else { w })
}

fn decimal_to_f64(neg: bool, digits: &[u8], exp10: i32) -> f64 {
    if digits.is_empty() {
        return 0.0;
    }
    let mut s = String::with_capacity(digits.len() + 16);
    if neg {
        s.push('-');
    }
    s.extend(digits.iter().map(|d| char::from(b'0' + d)));
    s.push('e');
    s.push_str(&exp10.to_string());
    s.parse().unwrap_or(if neg {
        f64::NEG_INFINITY
    } else {
        f64::INFINITY
    })
}

/// The CY value of a parsed decimal (exact, half to even at the 4th decimal).
fn decimal_to_cy(neg: bool, digits: &[u8], exp10: i32) -> Result<i64, OpcError> {
    let scaled = decimal_to_int(neg, digits, exp10.saturating_add(4))?;
    i64::try_from(scaled).map_err(|_| OpcError::Overflow)
}

fn from_bstr(s: &str, to: VarType, locale: Locale) -> Result<Value, OpcError> {
    match to {
        VarType::BOOL => return parse_bool(s, locale).map(Value::Bool),
        VarType::DATE => return parse_date(s, locale).map(Value::Date),
        _ => {}
    }
    match parse_number(s, locale)? {
        Parsed::Radix(bits) => {
            if let Some((width, _)) = int_width(to) {
                // The literal fills the target's bits: "&HFFFF" -> I2 is -1.
                if width < 64 && bits >> width != 0 {
                    return Err(OpcError::Overflow);
                }
                bits_to(bits, to)
            } else {
                // Float targets read the literal as a VB Long (32 bits, two's complement).
                let v = u32::try_from(bits).map_err(|_| OpcError::Overflow)? as i32;
                from_num(Num::Int(v.into()), to)
            }
        }
        Parsed::Decimal { neg, digits, exp10 } => match to {
            VarType::R4 => real_to_r4(decimal_to_f64(neg, &digits, exp10)),
            VarType::R8 => {
                let x = decimal_to_f64(neg, &digits, exp10);
                if x.is_finite() {
                    Ok(Value::R8(x))
                } else {
                    Err(OpcError::Overflow)
                }
            }
            VarType::CY => decimal_to_cy(neg, &digits, exp10).map(Value::Cy),
            _ => int_to(decimal_to_int(neg, &digits, exp10)?, to),
        },
    }
}

/// VarBoolFromStr: "True"/"False" (any case), "#TRUE#"/"#FALSE#", else a number (nonzero = true).
fn parse_bool(s: &str, locale: Locale) -> Result<bool, OpcError> {
    if s.eq_ignore_ascii_case("true") || s == "#TRUE#" {
        return Ok(true);
    }
    if s.eq_ignore_ascii_case("false") || s == "#FALSE#" {
        return Ok(false);
    }
    match parse_number(s, locale)? {
        Parsed::Radix(bits) => Ok(bits != 0),
        Parsed::Decimal { digits, .. } => Ok(!digits.is_empty()),
    }
}

// ---------------------------------------------------------------------------------------
// Dates

/// Days from 1970-01-01 to the OLE epoch 1899-12-30.
const OLE_EPOCH_DAYS: i64 = -25_569;

struct Civil {
    year: i64,
    month: u32,
    day: u32,
    secs: u32, // seconds since midnight
}

/// VarUdateFromDate: the civil date and time of an OLE date, to the nearest second.
fn civil_from_ole(d: f64) -> Option<Civil> {
    if !(d > DATE_MIN - 1.0 && d < DATE_MAX + 1.0) {
        return None;
    }
    let whole = d.trunc();
    let frac = (d - whole).abs();
    let total = frac * 86_400.0;
    let mut secs = total.floor() as u32;
    if total - f64::from(secs) > 0.5 {
        secs += 1;
    }
    let mut days = whole as i64;
    if secs >= 86_400 {
        secs -= 86_400;
        days += 1;
    }
    let (year, month, day) = civil_from_days(days + OLE_EPOCH_DAYS);
    Some(Civil {
        year,
        month,
        day,
        secs,
    })
}

/// The OLE date of a civil date and time (negative dates count the time forwards).
fn ole_from_civil(year: i64, month: u32, day: u32, secs: u32) -> f64 {
    let days = (days_from_civil(year, month, day) - OLE_EPOCH_DAYS) as f64;
    let frac = f64::from(secs) / 86_400.0;
    if days < 0.0 {
        days - frac
    } else {
        days + frac
    }
}

/// VarBstrFromDate with the locale's short date and long time formats.
fn format_date(d: f64, locale: Locale) -> Result<String, OpcError> {
    let c = civil_from_ole(d).ok_or(OpcError::InvalidArg)?;
    let whole = d.trunc();
    let time_only = whole == 0.0;
    let date_only = (d - whole).abs() < 1e-12;
    let (h, m, s) = (c.secs / 3600, c.secs / 60 % 60, c.secs % 60);
    let date = match locale {
        Locale::EnUs => format!("{}/{}/{}", c.month, c.day, c.year),
        Locale::PlPl => format!("{:02}.{:02}.{}", c.day, c.month, c.year),
    };
    let time = match locale {
        Locale::EnUs => {
            let h12 = if h % 12 == 0 { 12 } else { h % 12 };
            format!("{h12}:{m:02}:{s:02} {}", if h < 12 { "AM" } else { "PM" })
        }
        Locale::PlPl => format!("{h:02}:{m:02}:{s:02}"),
    };
    Ok(if time_only {
        time
    } else if date_only {
        date
    } else {
        format!("{date} {time}")
    })
}

fn days_in_month(year: i64, month: u32) -> u32 {
    match month {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        _ if (year % 4 == 0 && year % 100 != 0) || year % 400 == 0 => 29,
        _ => 28,
    }
}

fn parse_uint(s: &str, max_len: usize) -> Option<u32> {
    if s.is_empty() || s.len() > max_len || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// Parses a date: `yyyy-MM-dd` and `yyyy/MM/dd` everywhere, `M/d/yyyy` (en-US) or
/// `d.M.yyyy` (pl-PL); two-digit years are 1930-2029.
fn parse_date_part(s: &str, locale: Locale) -> Option<(i64, u32, u32)> {
    let parts: Vec<&str> = s.split(['-', '/', '.']).collect();
    if parts.len() != 3 {
        return None;
    }
    let sep = s.chars().find(|c| matches!(c, '-' | '/' | '.'))?;
    if s.chars()
        .filter(|&c| matches!(c, '-' | '/' | '.'))
        .any(|c| c != sep)
    {
        return None;
    }
    let (y, m, d) = if parts[0].len() == 4 && sep != '.' {
        (
            parse_uint(parts[0], 4)?,
            parse_uint(parts[1], 2)?,
            parse_uint(parts[2], 2)?,
        )
    } else {
        let (m, d) = match (locale, sep) {
            (Locale::EnUs, '/') | (Locale::EnUs, '-') => (parts[0], parts[1]),
            (Locale::PlPl, '.') | (Locale::PlPl, '-') => (parts[1], parts[0]),
            _ => return None,
        };
        let y = match parts[2].len() {
            1 | 2 => {
                let yy = parse_uint(parts[2], 2)?;
                if yy < 30 {
                    2000 + yy
                } else {
                    1900 + yy
                }
            }
            3 | 4 => parse_uint(parts[2], 4)?,
            _ => return None,
        };
        (y, parse_uint(m, 2)?, parse_uint(d, 2)?)
    };
    let y = i64::from(y);
    if !(100..=9999).contains(&y) || !(1..=12).contains(&m) || d == 0 || d > days_in_month(y, m) {
        return None;
    }
    Some((y, m, d))
}

/// Parses `H:mm[:ss][ AM|PM]` into seconds since midnight.
fn parse_time_part(s: &str) -> Option<u32> {
    let upper = s.trim().to_ascii_uppercase();
    let (clock, ampm) = if let Some(c) = upper.strip_suffix("AM") {
        (c.trim_end(), Some(false))
    } else if let Some(c) = upper.strip_suffix("PM") {
        (c.trim_end(), Some(true))
    } else {
        (upper.as_str(), None)
    };
    let fields: Vec<&str> = clock.split(':').collect();
    if !(2..=3).contains(&fields.len()) {
        return None;
    }
    let mut h = parse_uint(fields[0], 2)?;
    let m = parse_uint(fields[1], 2)?;
    let s = if fields.len() == 3 {
        parse_uint(fields[2], 2)?
    } else {
        0
    };
    if m > 59 || s > 59 {
        return None;
    }
    match ampm {
        Some(pm) => {
            if h == 0 || h > 12 {
                return None;
            }
            h = match (h, pm) {
                (12, false) => 0,
                (12, true) => 12,
                (h, true) => h + 12,
                (h, false) => h,
            };
        }
        None if h > 23 => return None,
        None => {}
    }
    Some(h * 3600 + m * 60 + s)
}

/// VarDateFromStr for the formats [`format_date`] writes plus ISO 8601 (`T` or space).
fn parse_date(s: &str, locale: Locale) -> Result<f64, OpcError> {
    let t = s.trim();
    let (date_str, time_str) = match t.find([' ', 'T']) {
        Some(i) if !t[..i].contains(':') => (Some(&t[..i]), Some(t[i + 1..].trim())),
        _ if t.contains(':') => (None, Some(t)),
        _ => (Some(t), None),
    };
    let date = match date_str {
        Some(ds) => Some(parse_date_part(ds, locale).ok_or(OpcError::TypeMismatch)?),
        None => None,
    };
    let secs = match time_str {
        Some(ts) => parse_time_part(ts).ok_or(OpcError::TypeMismatch)?,
        None => 0,
    };
    Ok(match date {
        Some((y, m, d)) => ole_from_civil(y, m, d, secs),
        None => f64::from(secs) / 86_400.0,
    })
}

#[cfg(test)]
mod tests;
