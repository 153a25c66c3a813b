//! VARIANT <-> core `Value`, including 1-D SAFEARRAYs (VT_ARRAY | element, and
//! VT_ARRAY | VT_VARIANT for mixed arrays such as the original's extended write
//! [value, quality, timestamp]).

use ctopc_core::limits;
use ctopc_core::value::ArrayValue;
use ctopc_core::{OpcError, Value, VarType};
use std::ffi::c_void;
use std::mem::ManuallyDrop;
use windows::core::BSTR;
use windows::Win32::Foundation::{VARIANT_BOOL, VARIANT_FALSE, VARIANT_TRUE};
use windows::Win32::System::Com::{CY, SAFEARRAY};
use windows::Win32::System::Ole::{
    SafeArrayAccessData, SafeArrayCreateVector, SafeArrayDestroy, SafeArrayGetDim,
    SafeArrayGetLBound, SafeArrayGetUBound, SafeArrayUnaccessData,
};
use windows::Win32::System::Variant::*;

/// Frees what a VARIANT owns and leaves it VT_EMPTY.
pub fn clear(v: &mut VARIANT) {
    // SAFETY: `v` is a valid, initialised VARIANT (zeroed or written by us / COM).
    let _ = unsafe { VariantClear(v) };
}

fn vt_of(v: &VARIANT) -> u16 {
    // SAFETY: every VARIANT starts with its VARTYPE; reading it is always valid.
    unsafe { v.Anonymous.Anonymous.vt.0 }
}

fn set(v: &mut VARIANT, vt: VARENUM, f: impl FnOnce(&mut VARIANT_0_0_0)) {
    let mut inner = VARIANT_0_0 {
        vt,
        ..Default::default()
    };
    f(&mut inner.Anonymous);
    v.Anonymous.Anonymous = ManuallyDrop::new(inner);
}

/// A new VARIANT holding `value` (owned by the caller: clear it or hand it out).
pub fn to_variant(value: &Value) -> windows::core::Result<VARIANT> {
    let mut v = VARIANT::default();
    match value {
        Value::Empty => {}
        Value::I1(x) => set(&mut v, VT_I1, |u| u.cVal = *x),
        Value::UI1(x) => set(&mut v, VT_UI1, |u| u.bVal = *x),
        Value::I2(x) => set(&mut v, VT_I2, |u| u.iVal = *x),
        Value::UI2(x) => set(&mut v, VT_UI2, |u| u.uiVal = *x),
        Value::I4(x) => set(&mut v, VT_I4, |u| u.lVal = *x),
        Value::UI4(x) => set(&mut v, VT_UI4, |u| u.ulVal = *x),
        Value::I8(x) => set(&mut v, VT_I8, |u| u.llVal = *x),
        Value::UI8(x) => set(&mut v, VT_UI8, |u| u.ullVal = *x),
        Value::R4(x) => set(&mut v, VT_R4, |u| u.fltVal = *x),
        Value::R8(x) => set(&mut v, VT_R8, |u| u.dblVal = *x),
        Value::Cy(x) => set(&mut v, VT_CY, |u| u.cyVal = CY { int64: *x }),
        Value::Date(x) => set(&mut v, VT_DATE, |u| u.date = *x),
        Value::Bool(x) => set(&mut v, VT_BOOL, |u| {
            u.boolVal = if *x { VARIANT_TRUE } else { VARIANT_FALSE }
        }),
        Value::Error(x) => set(&mut v, VT_ERROR, |u| u.scode = *x),
        Value::Bstr(s) => {
            let b = BSTR::from(s.as_str());
            set(&mut v, VT_BSTR, |u| u.bstrVal = ManuallyDrop::new(b));
        }
        Value::Array(a) => {
            let psa = to_safearray(a)?;
            set(&mut v, VARENUM(VT_ARRAY.0 | a.element_type.0), |u| {
                u.parray = psa
            });
        }
    }
    Ok(v)
}

/// Writes `value` into caller storage `dst` (which must not own anything yet).
///
/// # Safety
/// `dst` must be valid for writes of one VARIANT.
pub unsafe fn write_variant(dst: *mut VARIANT, value: &Value) -> windows::core::Result<()> {
    let v = to_variant(value)?;
    // SAFETY: the caller guarantees `dst` is writable; ownership moves into it.
    unsafe { dst.write(v) };
    Ok(())
}

fn element_size(vt: VarType) -> Option<usize> {
    Some(match vt {
        VarType::I1 | VarType::UI1 => 1,
        VarType::I2 | VarType::UI2 | VarType::BOOL => 2,
        VarType::I4 | VarType::UI4 | VarType::R4 | VarType::ERROR => 4,
        VarType::I8 | VarType::UI8 | VarType::R8 | VarType::CY | VarType::DATE => 8,
        VarType::BSTR => std::mem::size_of::<usize>(),
        VarType::VARIANT => std::mem::size_of::<VARIANT>(),
        _ => return None,
    })
}

fn to_safearray(a: &ArrayValue) -> windows::core::Result<*mut SAFEARRAY> {
    let bad = || windows::core::Error::from(windows::core::HRESULT(OpcError::BadType.hresult()));
    element_size(a.element_type).ok_or_else(bad)?;
    let n = u32::try_from(a.elements.len()).map_err(|_| bad())?;
    // SAFETY: plain constructor; null means out of memory.
    let psa = unsafe { SafeArrayCreateVector(VARENUM(a.element_type.0), 0, n) };
    if psa.is_null() {
        return Err(windows::Win32::Foundation::E_OUTOFMEMORY.into());
    }
    let fill = || -> windows::core::Result<()> {
        let mut data: *mut c_void = std::ptr::null_mut();
        // SAFETY: `psa` is a valid array; data is unlocked below.
        unsafe { SafeArrayAccessData(psa, &mut data)? };
        let mut result = Ok(());
        for (i, e) in a.elements.iter().enumerate() {
            let converted;
            let e = if a.element_type == VarType::VARIANT || e.var_type() == a.element_type {
                e
            } else {
                converted = e.convert(a.element_type).map_err(|err| {
                    windows::core::Error::from(windows::core::HRESULT(err.hresult()))
                });
                match &converted {
                    Ok(c) => c,
                    Err(err) => {
                        result = Err(err.clone());
                        break;
                    }
                }
            };
            // SAFETY: `data` points at `n` elements of the array's type; index i < n. Each
            // write moves an owned value (BSTR, VARIANT) into the array, which now owns it.
            let r = unsafe { write_element(data, i, a.element_type, e) };
            if let Err(err) = r {
                result = Err(err);
                break;
            }
        }
        // SAFETY: paired with the access above.
        unsafe { SafeArrayUnaccessData(psa)? };
        result
    };
    if let Err(e) = fill() {
        // SAFETY: destroys the array and whatever elements were written.
        let _ = unsafe { SafeArrayDestroy(psa) };
        return Err(e);
    }
    Ok(psa)
}

/// # Safety
/// `data` must point at an array of at least `i + 1` elements of type `vt`.
unsafe fn write_element(
    data: *mut c_void,
    i: usize,
    vt: VarType,
    e: &Value,
) -> windows::core::Result<()> {
    let mismatch =
        || windows::core::Error::from(windows::core::HRESULT(OpcError::BadType.hresult()));
    // SAFETY: (whole body) guaranteed by the caller; each arm writes one element of the
    // array's element type at index i.
    unsafe {
        match (vt, e) {
            (VarType::VARIANT, e) => data.cast::<VARIANT>().add(i).write(to_variant(e)?),
            (VarType::I1, Value::I1(x)) => data.cast::<i8>().add(i).write(*x),
            (VarType::UI1, Value::UI1(x)) => data.cast::<u8>().add(i).write(*x),
            (VarType::I2, Value::I2(x)) => data.cast::<i16>().add(i).write(*x),
            (VarType::UI2, Value::UI2(x)) => data.cast::<u16>().add(i).write(*x),
            (VarType::I4, Value::I4(x)) => data.cast::<i32>().add(i).write(*x),
            (VarType::UI4, Value::UI4(x)) => data.cast::<u32>().add(i).write(*x),
            (VarType::I8, Value::I8(x)) => data.cast::<i64>().add(i).write(*x),
            (VarType::UI8, Value::UI8(x)) => data.cast::<u64>().add(i).write(*x),
            (VarType::R4, Value::R4(x)) => data.cast::<f32>().add(i).write(*x),
            (VarType::R8, Value::R8(x)) => data.cast::<f64>().add(i).write(*x),
            (VarType::CY, Value::Cy(x)) => data.cast::<i64>().add(i).write(*x),
            (VarType::DATE, Value::Date(x)) => data.cast::<f64>().add(i).write(*x),
            (VarType::ERROR, Value::Error(x)) => data.cast::<i32>().add(i).write(*x),
            (VarType::BOOL, Value::Bool(x)) => data.cast::<VARIANT_BOOL>().add(i).write(if *x {
                VARIANT_TRUE
            } else {
                VARIANT_FALSE
            }),
            (VarType::BSTR, Value::Bstr(s)) => data
                .cast::<ManuallyDrop<BSTR>>()
                .add(i)
                .write(ManuallyDrop::new(BSTR::from(s.as_str()))),
            _ => return Err(mismatch()),
        }
    }
    Ok(())
}

/// The value a client passed in a VARIANT. VT_BYREF is followed; objects (VT_UNKNOWN,
/// VT_DISPATCH), VT_NULL, records and multi-dimensional arrays are `OPC_E_BADTYPE`.
///
/// The work is bounded by [`limits::DecodeBudget`]: more than
/// [`limits::MAX_VARIANT_DEPTH`] array levels (arrays inside VT_VARIANT elements, BYREF
/// VARIANTs) or more than [`limits::MAX_VARIANT_ELEMENTS`] elements in all are
/// `OPC_E_BADTYPE`, found before anything below the limit is read (so a VARIANT nested
/// 10,000 deep costs five levels of recursion, not a stack overflow).
pub fn from_variant(v: &VARIANT) -> Result<Value, OpcError> {
    decode(v, &mut limits::DecodeBudget::new())
}

/// One array level deeper (see [`from_variant`]); the refusal is logged.
fn enter(budget: &mut limits::DecodeBudget) -> Result<(), OpcError> {
    budget.enter().inspect_err(|_| {
        tracing::warn!(
            "a client VARIANT nested deeper than {} array levels: OPC_E_BADTYPE",
            limits::MAX_VARIANT_DEPTH
        );
    })
}

/// One level of [`from_variant`]: `budget` is entered for each array and BYREF VARIANT.
fn decode(v: &VARIANT, budget: &mut limits::DecodeBudget) -> Result<Value, OpcError> {
    let vt = vt_of(v);
    // SAFETY: each arm reads the union member that `vt` says is valid; BYREF pointers are
    // followed only when non-null.
    unsafe {
        let u = &v.Anonymous.Anonymous.Anonymous;
        if vt & VT_BYREF.0 != 0 {
            let base = vt & !VT_BYREF.0;
            if u.byref.is_null() {
                return Err(OpcError::BadType);
            }
            let p = u.byref;
            return Ok(match VARENUM(base) {
                VT_I1 => Value::I1(*p.cast::<i8>()),
                VT_UI1 => Value::UI1(*p.cast::<u8>()),
                VT_I2 => Value::I2(*p.cast::<i16>()),
                VT_UI2 => Value::UI2(*p.cast::<u16>()),
                VT_I4 | VT_INT => Value::I4(*p.cast::<i32>()),
                VT_UI4 | VT_UINT => Value::UI4(*p.cast::<u32>()),
                VT_I8 => Value::I8(*p.cast::<i64>()),
                VT_UI8 => Value::UI8(*p.cast::<u64>()),
                VT_R4 => Value::R4(*p.cast::<f32>()),
                VT_R8 => Value::R8(*p.cast::<f64>()),
                VT_CY => Value::Cy(*p.cast::<i64>()),
                VT_DATE => Value::Date(*p.cast::<f64>()),
                VT_ERROR => Value::Error(*p.cast::<i32>()),
                VT_BOOL => Value::Bool((*p.cast::<VARIANT_BOOL>()).0 != 0),
                VT_BSTR => Value::Bstr((*p.cast::<BSTR>()).to_string()),
                VT_VARIANT => {
                    enter(budget)?;
                    let r = decode(&*p.cast::<VARIANT>(), budget);
                    budget.leave();
                    return r;
                }
                _ => return Err(OpcError::BadType),
            });
        }
        if vt & VT_ARRAY.0 != 0 {
            enter(budget)?;
            let r = from_safearray(u.parray, VarType(vt & !VT_ARRAY.0), budget);
            budget.leave();
            return r;
        }
        Ok(match VARENUM(vt) {
            VT_EMPTY => Value::Empty,
            VT_I1 => Value::I1(u.cVal),
            VT_UI1 => Value::UI1(u.bVal),
            VT_I2 => Value::I2(u.iVal),
            VT_UI2 => Value::UI2(u.uiVal),
            VT_I4 | VT_INT => Value::I4(u.lVal),
            VT_UI4 | VT_UINT => Value::UI4(u.ulVal),
            VT_I8 => Value::I8(u.llVal),
            VT_UI8 => Value::UI8(u.ullVal),
            VT_R4 => Value::R4(u.fltVal),
            VT_R8 => Value::R8(u.dblVal),
            VT_CY => Value::Cy(u.cyVal.int64),
            VT_DATE => Value::Date(u.date),
            VT_ERROR => Value::Error(u.scode),
            VT_BOOL => Value::Bool(u.boolVal.0 != 0),
            VT_BSTR => Value::Bstr(u.bstrVal.to_string()),
            VT_DECIMAL => {
                let mut r8 = VARIANT::default();
                if VariantChangeType(&mut r8, v, VAR_CHANGE_FLAGS(0), VT_R8).is_err() {
                    return Err(OpcError::Overflow);
                }
                Value::R8(r8.Anonymous.Anonymous.Anonymous.dblVal)
            }
            _ => return Err(OpcError::BadType),
        })
    }
}

fn from_safearray(
    psa: *mut SAFEARRAY,
    elem: VarType,
    budget: &mut limits::DecodeBudget,
) -> Result<Value, OpcError> {
    if psa.is_null() {
        return Err(OpcError::BadType);
    }
    let size = element_size(elem).ok_or(OpcError::BadType)?;
    // SAFETY: `psa` is a non-null SAFEARRAY from a VARIANT; bounds come from the array.
    unsafe {
        if SafeArrayGetDim(psa) != 1 {
            return Err(OpcError::BadType);
        }
        let lo = SafeArrayGetLBound(psa, 1).map_err(|_| OpcError::BadType)?;
        let hi = SafeArrayGetUBound(psa, 1).map_err(|_| OpcError::BadType)?;
        let n = usize::try_from(i64::from(hi) - i64::from(lo) + 1).unwrap_or(0);
        if (*psa).cbElements as usize != size {
            return Err(OpcError::BadType);
        }
        budget.take(n).inspect_err(|_| {
            tracing::warn!(
                "a client VARIANT with more than {} elements: OPC_E_BADTYPE",
                limits::MAX_VARIANT_ELEMENTS
            );
        })?;
        let mut data: *mut c_void = std::ptr::null_mut();
        SafeArrayAccessData(psa, &mut data).map_err(|_| OpcError::BadType)?;
        let mut elements = Vec::with_capacity(n);
        let mut result = Ok(());
        for i in 0..n {
            let e = match elem {
                VarType::VARIANT => decode(&*data.cast::<VARIANT>().add(i), budget),
                VarType::I1 => Ok(Value::I1(*data.cast::<i8>().add(i))),
                VarType::UI1 => Ok(Value::UI1(*data.cast::<u8>().add(i))),
                VarType::I2 => Ok(Value::I2(*data.cast::<i16>().add(i))),
                VarType::UI2 => Ok(Value::UI2(*data.cast::<u16>().add(i))),
                VarType::I4 => Ok(Value::I4(*data.cast::<i32>().add(i))),
                VarType::UI4 => Ok(Value::UI4(*data.cast::<u32>().add(i))),
                VarType::I8 => Ok(Value::I8(*data.cast::<i64>().add(i))),
                VarType::UI8 => Ok(Value::UI8(*data.cast::<u64>().add(i))),
                VarType::R4 => Ok(Value::R4(*data.cast::<f32>().add(i))),
                VarType::R8 => Ok(Value::R8(*data.cast::<f64>().add(i))),
                VarType::CY => Ok(Value::Cy(*data.cast::<i64>().add(i))),
                VarType::DATE => Ok(Value::Date(*data.cast::<f64>().add(i))),
                VarType::ERROR => Ok(Value::Error(*data.cast::<i32>().add(i))),
                VarType::BOOL => Ok(Value::Bool((*data.cast::<VARIANT_BOOL>().add(i)).0 != 0)),
                VarType::BSTR => Ok(Value::Bstr((*data.cast::<BSTR>().add(i)).to_string())),
                _ => Err(OpcError::BadType),
            };
            match e {
                Ok(e) => elements.push(e),
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        let _ = SafeArrayUnaccessData(psa);
        result?;
        Ok(Value::Array(ArrayValue {
            element_type: elem,
            elements,
        }))
    }
}

/// The VARTYPE of a VARIANT.
pub fn var_type(v: &VARIANT) -> VarType {
    VarType(vt_of(v))
}

/// `v` wrapped in `levels` one-element VT_ARRAY | VT_VARIANT arrays, built without
/// recursion (for tests of the depth limit: a hostile client's VARIANT). The result owns
/// `v`; free it with [`clear_nested`] (VariantClear recurses once per level).
pub fn nest(v: VARIANT, levels: usize) -> windows::core::Result<VARIANT> {
    let mut v = v;
    for _ in 0..levels {
        // SAFETY: plain constructor; null means out of memory.
        let psa = unsafe { SafeArrayCreateVector(VT_VARIANT, 0, 1) };
        if psa.is_null() {
            clear_nested(v);
            return Err(windows::Win32::Foundation::E_OUTOFMEMORY.into());
        }
        // SAFETY: a new one-element VARIANT array: its data is one zeroed VARIANT, into
        // which `v` moves (the array owns it from then on).
        unsafe { (*psa).pvData.cast::<VARIANT>().write(v) };
        let mut outer = VARIANT::default();
        set(&mut outer, VARENUM(VT_ARRAY.0 | VT_VARIANT.0), |u| {
            u.parray = psa
        });
        v = outer;
    }
    Ok(v)
}

/// Frees a VARIANT made by [`nest`] one level at a time (no recursion however deep).
pub fn clear_nested(v: VARIANT) {
    let mut v = v;
    loop {
        let vt = vt_of(&v);
        // SAFETY: VT_ARRAY | VT_VARIANT means `parray` is the valid member.
        let psa = unsafe { v.Anonymous.Anonymous.Anonymous.parray };
        let one = vt == VT_ARRAY.0 | VT_VARIANT.0
            && !psa.is_null()
            // SAFETY: a non-null SAFEARRAY of a VARIANT.
            && unsafe { SafeArrayGetDim(psa) == 1 && (*psa).rgsabound[0].cElements == 1 };
        if !one {
            clear(&mut v);
            return;
        }
        // SAFETY: a one-element VARIANT array: its element moves out and is replaced by
        // VT_EMPTY, so destroying the array frees only the array itself.
        unsafe {
            let slot = (*psa).pvData.cast::<VARIANT>();
            let inner = slot.read();
            slot.write(VARIANT::default());
            clear(&mut v);
            v = inner;
        }
    }
}

#[cfg(test)]
mod tests {
    //! `from_variant(&to_variant(v)) == v` for every value kind, SAFEARRAYs included (run
    //! under Wine: `cargo xtask e2e -p ctopc-com`). Floats compare by their bits, so NaNs
    //! (any payload) and -0.0 must come back exactly as they went in.

    use super::*;
    use proptest::prelude::*;

    /// Equal, with floats compared bit for bit.
    fn same(a: &Value, b: &Value) -> bool {
        match (a, b) {
            (Value::R4(x), Value::R4(y)) => x.to_bits() == y.to_bits(),
            (Value::R8(x), Value::R8(y)) | (Value::Date(x), Value::Date(y)) => {
                x.to_bits() == y.to_bits()
            }
            (Value::Array(x), Value::Array(y)) => {
                x.element_type == y.element_type
                    && x.elements.len() == y.elements.len()
                    && x.elements.iter().zip(&y.elements).all(|(a, b)| same(a, b))
            }
            _ => a == b,
        }
    }

    fn any_f32() -> impl Strategy<Value = f32> {
        prop_oneof![
            any::<f32>(),
            any::<u32>().prop_map(f32::from_bits),
            Just(f32::NAN),
            Just(-0.0f32),
            Just(f32::INFINITY),
            Just(f32::MIN_POSITIVE / 2.0),
        ]
    }

    fn any_f64() -> impl Strategy<Value = f64> {
        prop_oneof![
            any::<f64>(),
            any::<u64>().prop_map(f64::from_bits),
            Just(f64::NAN),
            Just(-0.0f64),
            Just(f64::NEG_INFINITY),
            Just(f64::MIN_POSITIVE / 2.0),
        ]
    }

    /// Text as clients send it: ASCII, Polish letters, other planes (surrogate pairs),
    /// interior NULs, and the empty string (a NULL BSTR).
    fn any_text() -> impl Strategy<Value = String> {
        prop_oneof![
            Just(String::new()),
            "[a-zA-Z0-9 ._]{0,12}",
            "[ąćęłńóśźżĄĆĘŁŃÓŚŹŻ\\x00\u{FFFD}\u{1F600}\u{10FFFF}a-z]{0,8}",
            any::<String>(),
        ]
    }

    /// A scalar of the given VARTYPE (one that a SAFEARRAY can hold, VT_VARIANT aside).
    fn scalar_of(vt: VarType) -> BoxedStrategy<Value> {
        match vt {
            VarType::I1 => any::<i8>().prop_map(Value::I1).boxed(),
            VarType::UI1 => any::<u8>().prop_map(Value::UI1).boxed(),
            VarType::I2 => any::<i16>().prop_map(Value::I2).boxed(),
            VarType::UI2 => any::<u16>().prop_map(Value::UI2).boxed(),
            VarType::I4 => any::<i32>().prop_map(Value::I4).boxed(),
            VarType::UI4 => any::<u32>().prop_map(Value::UI4).boxed(),
            VarType::I8 => any::<i64>().prop_map(Value::I8).boxed(),
            VarType::UI8 => any::<u64>().prop_map(Value::UI8).boxed(),
            VarType::R4 => any_f32().prop_map(Value::R4).boxed(),
            VarType::R8 => any_f64().prop_map(Value::R8).boxed(),
            VarType::CY => any::<i64>().prop_map(Value::Cy).boxed(),
            VarType::DATE => any_f64().prop_map(Value::Date).boxed(),
            VarType::BSTR => any_text().prop_map(Value::Bstr).boxed(),
            VarType::BOOL => any::<bool>().prop_map(Value::Bool).boxed(),
            VarType::ERROR => any::<i32>().prop_map(Value::Error).boxed(),
            _ => Just(Value::Empty).boxed(),
        }
    }

    /// Every element type a typed SAFEARRAY can have.
    const ELEMENT_TYPES: [VarType; 15] = [
        VarType::I1,
        VarType::UI1,
        VarType::I2,
        VarType::UI2,
        VarType::I4,
        VarType::UI4,
        VarType::I8,
        VarType::UI8,
        VarType::R4,
        VarType::R8,
        VarType::CY,
        VarType::DATE,
        VarType::BSTR,
        VarType::BOOL,
        VarType::ERROR,
    ];

    fn any_scalar() -> impl Strategy<Value = Value> {
        prop_oneof![
            Just(Value::Empty),
            proptest::sample::select(&ELEMENT_TYPES[..]).prop_flat_map(scalar_of),
        ]
    }

    /// A typed array: every element of the array's element type (empty arrays included).
    fn typed_array() -> impl Strategy<Value = Value> {
        proptest::sample::select(&ELEMENT_TYPES[..]).prop_flat_map(|vt| {
            proptest::collection::vec(scalar_of(vt), 0..12).prop_map(move |elements| {
                Value::Array(ArrayValue {
                    element_type: vt,
                    elements,
                })
            })
        })
    }

    /// Any value: scalars, typed arrays, and VT_VARIANT arrays of any of these, nested up
    /// to three levels (a VARIANT array holding arrays holding arrays).
    fn any_value() -> impl Strategy<Value = Value> {
        let leaf = prop_oneof![3 => any_scalar(), 1 => typed_array()];
        leaf.prop_recursive(3, 48, 8, |inner| {
            proptest::collection::vec(inner, 0..8).prop_map(|elements| {
                Value::Array(ArrayValue {
                    element_type: VarType::VARIANT,
                    elements,
                })
            })
        })
    }

    /// The round trip through a VARIANT that is cleared afterwards (no leak: the VARIANT
    /// owns every BSTR and SAFEARRAY it holds, and VariantClear frees them all).
    fn round_trip(v: &Value) -> (VarType, Result<Value, OpcError>) {
        let mut var = match to_variant(v) {
            Ok(var) => var,
            Err(e) => panic!("to_variant({v:?}) failed: {e:?}"),
        };
        let vt = var_type(&var);
        let back = from_variant(&var);
        clear(&mut var);
        assert_eq!(var_type(&var), VarType::EMPTY, "cleared");
        (vt, back)
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 1000,
            failure_persistence: None,
            ..ProptestConfig::default()
        })]

        #[test]
        fn every_value_round_trips_through_a_variant(v in any_value()) {
            let (vt, back) = round_trip(&v);
            prop_assert_eq!(vt, v.var_type(), "the VARIANT's VARTYPE");
            let back = back.map_err(|e| TestCaseError::fail(format!("from_variant: {e:?}")))?;
            prop_assert!(same(&back, &v), "{:?} came back as {:?}", v, back);
        }

        #[test]
        fn write_variant_fills_caller_storage_with_the_same_value(v in any_value()) {
            let mut slot = VARIANT::default();
            // SAFETY: `slot` is a local VARIANT owning nothing; it is cleared below.
            let written = unsafe { write_variant(&mut slot, &v) };
            prop_assert!(written.is_ok());
            let back = from_variant(&slot);
            clear(&mut slot);
            prop_assert!(back.is_ok_and(|b| same(&b, &v)));
        }
    }

    /// `Value::I4(7)` inside `levels` VT_VARIANT arrays, decoded.
    fn decode_nested(levels: usize) -> Result<Value, OpcError> {
        let v = nest(to_variant(&Value::I4(7)).unwrap(), levels).unwrap();
        let r = from_variant(&v);
        clear_nested(v);
        r
    }

    #[test]
    fn variants_nested_to_the_depth_limit_decode_and_deeper_ones_are_bad_type() {
        let mut expect = Value::I4(7);
        for levels in 0..=limits::MAX_VARIANT_DEPTH {
            assert!(
                same(&decode_nested(levels).unwrap(), &expect),
                "{levels} levels"
            );
            expect = Value::Array(ArrayValue {
                element_type: VarType::VARIANT,
                elements: vec![expect],
            });
        }
        assert_eq!(
            decode_nested(limits::MAX_VARIANT_DEPTH + 1),
            Err(OpcError::BadType)
        );
        // Deep enough to overflow a thread's stack if decoded by recursion: 10,000 levels
        // answer at once, on a test thread's stack.
        let t = std::time::Instant::now();
        assert_eq!(decode_nested(10_000), Err(OpcError::BadType));
        assert!(t.elapsed() < std::time::Duration::from_secs(5));
    }

    #[test]
    fn a_byref_variant_pointing_at_itself_is_bad_type() {
        let mut v = VARIANT::default();
        let p: *mut VARIANT = &mut v;
        set(&mut v, VARENUM(VT_BYREF.0 | VT_VARIANT.0), |u| {
            u.pvarVal = p
        });
        assert_eq!(from_variant(&v), Err(OpcError::BadType));
        // VARIANT's Drop is VariantClear, which Wine's oleaut32 makes follow the cycle:
        // empty it first.
        set(&mut v, VT_EMPTY, |_| {});
    }

    /// A VT_ARRAY | VT_UI1 of `n` zero bytes.
    fn bytes(n: u32) -> VARIANT {
        // SAFETY: plain constructor.
        let psa = unsafe { SafeArrayCreateVector(VT_UI1, 0, n) };
        assert!(!psa.is_null());
        let mut v = VARIANT::default();
        set(&mut v, VARENUM(VT_ARRAY.0 | VT_UI1.0), |u| u.parray = psa);
        v
    }

    #[test]
    fn arrays_up_to_the_element_limit_decode_and_larger_ones_are_bad_type() {
        let max = limits::MAX_VARIANT_ELEMENTS as u32;
        let mut at = bytes(max);
        match from_variant(&at) {
            Ok(Value::Array(a)) => assert_eq!(a.elements.len(), max as usize),
            other => panic!("{other:?}"),
        }
        clear(&mut at);
        let mut over = bytes(max + 1);
        assert_eq!(from_variant(&over), Err(OpcError::BadType));
        clear(&mut over);
        // The limit counts the elements of every level together.
        let half = limits::MAX_VARIANT_ELEMENTS / 2 + 1;
        let v = Value::Array(ArrayValue {
            element_type: VarType::VARIANT,
            elements: vec![
                Value::Array(ArrayValue {
                    element_type: VarType::UI1,
                    elements: vec![Value::UI1(0); half],
                });
                2
            ],
        });
        let mut var = to_variant(&v).unwrap();
        assert_eq!(from_variant(&var), Err(OpcError::BadType));
        clear(&mut var);
    }

    #[test]
    fn every_kind_round_trips_at_its_edges() {
        let mut values = vec![
            Value::Empty,
            Value::I1(i8::MIN),
            Value::UI1(u8::MAX),
            Value::I2(i16::MIN),
            Value::UI2(u16::MAX),
            Value::I4(i32::MIN),
            Value::UI4(u32::MAX),
            Value::I8(i64::MIN),
            Value::UI8(u64::MAX),
            Value::R4(f32::NAN),
            Value::R4(-0.0),
            Value::R8(f64::from_bits(0x7FF0_0000_0000_0001)),
            Value::R8(f64::MAX),
            Value::Cy(i64::MAX),
            Value::Date(-657_434.0),
            Value::Date(2_958_465.999_99),
            Value::Bstr(String::new()),
            Value::Bstr("Wytwórnia \u{0} kwasu \u{1F600}".into()),
            Value::Bool(true),
            Value::Bool(false),
            Value::Error(0x8004_0007_u32 as i32),
        ];
        for vt in ELEMENT_TYPES {
            values.push(Value::Array(ArrayValue {
                element_type: vt,
                elements: Vec::new(),
            }));
        }
        // The original's extended write: [value, quality, timestamp] in a VARIANT array.
        values.push(Value::Array(ArrayValue {
            element_type: VarType::VARIANT,
            elements: vec![Value::R8(1.5), Value::I4(0xC0), Value::Date(45_000.25)],
        }));
        values.push(Value::Array(ArrayValue {
            element_type: VarType::VARIANT,
            elements: vec![
                Value::Empty,
                Value::Array(ArrayValue {
                    element_type: VarType::BSTR,
                    elements: vec![Value::Bstr("a".into()), Value::Bstr(String::new())],
                }),
            ],
        }));
        for v in values {
            let (vt, back) = round_trip(&v);
            assert_eq!(vt, v.var_type(), "{v:?}");
            match back {
                Ok(b) => assert!(same(&b, &v), "{v:?} came back as {b:?}"),
                Err(e) => panic!("{v:?}: from_variant failed with {e:?}"),
            }
        }
    }
}
