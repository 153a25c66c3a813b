//! Conversion tables pinned to VariantChangeTypeEx's observable behaviour (Wine's
//! oleaut32 conformance tests, which pass on native Windows) plus the OPC corrections
//! listed in the module documentation.

use super::*;
use crate::Value::*;
use proptest::prelude::*;

const OVF: OpcError = OpcError::Overflow;
const MIS: OpcError = OpcError::TypeMismatch;

fn s(x: &str) -> Value {
    Bstr(x.to_owned())
}

/// Runs (from, to, expected) rows in `locale`; R4/R8/DATE compare bit-exactly.
fn check(locale: Locale, rows: &[(Value, VarType, Result<Value, OpcError>)]) {
    for (from, to, expected) in rows {
        let got = from.convert_in(*to, locale);
        let same = match (&got, expected) {
            (Ok(R8(a)), Ok(R8(b))) | (Ok(Date(a)), Ok(Date(b))) => a.to_bits() == b.to_bits(),
            (Ok(R4(a)), Ok(R4(b))) => a.to_bits() == b.to_bits(),
            _ => got == *expected,
        };
        assert!(
            same,
            "{locale:?}: {from:?} -> {to:?}: expected {expected:?}, got {got:?}"
        );
    }
}

fn en(rows: &[(Value, VarType, Result<Value, OpcError>)]) {
    check(Locale::EnUs, rows)
}

#[test]
fn integer_widening_always_succeeds() {
    en(&[
        (I1(-128), VarType::I2, Ok(I2(-128))),
        (I1(-128), VarType::I4, Ok(I4(-128))),
        (I1(-128), VarType::I8, Ok(I8(-128))),
        (UI1(255), VarType::I2, Ok(I2(255))),
        (UI1(255), VarType::UI2, Ok(UI2(255))),
        (I2(-32768), VarType::I4, Ok(I4(-32768))),
        (UI2(65535), VarType::I4, Ok(I4(65535))),
        (UI2(65535), VarType::UI4, Ok(UI4(65535))),
        (I4(i32::MIN), VarType::I8, Ok(I8(i32::MIN.into()))),
        (UI4(u32::MAX), VarType::I8, Ok(I8(u32::MAX.into()))),
        (UI4(u32::MAX), VarType::UI8, Ok(UI8(u32::MAX.into()))),
        (I4(-7), VarType::R8, Ok(R8(-7.0))),
        (I2(12345), VarType::R4, Ok(R4(12345.0))),
        (R4(1.1), VarType::R8, Ok(R8(f64::from(1.1f32)))),
    ]);
}

#[test]
fn integer_narrowing_overflows_exactly_outside_the_range() {
    en(&[
        (I2(127), VarType::I1, Ok(I1(127))),
        (I2(128), VarType::I1, Err(OVF)),
        (I2(-128), VarType::I1, Ok(I1(-128))),
        (I2(-129), VarType::I1, Err(OVF)),
        (I4(255), VarType::UI1, Ok(UI1(255))),
        (I4(256), VarType::UI1, Err(OVF)),
        (I4(32767), VarType::I2, Ok(I2(32767))),
        (I4(32768), VarType::I2, Err(OVF)),
        (I8(i64::from(i32::MAX) + 1), VarType::I4, Err(OVF)),
        (UI8(u64::from(u32::MAX)), VarType::UI4, Ok(UI4(u32::MAX))),
        (UI8(u64::from(u32::MAX) + 1), VarType::UI4, Err(OVF)),
        (UI8(u64::MAX), VarType::I8, Err(OVF)),
        (UI8(i64::MAX as u64), VarType::I8, Ok(I8(i64::MAX))),
    ]);
}

#[test]
fn signed_and_unsigned_of_the_same_size_are_range_checked_not_reinterpreted() {
    // Bare VariantChangeType gives 255 / 65535 / ... here; OPC servers report overflow.
    en(&[
        (I1(-1), VarType::UI1, Err(OVF)),
        (UI1(128), VarType::I1, Err(OVF)),
        (UI1(127), VarType::I1, Ok(I1(127))),
        (I2(-1), VarType::UI2, Err(OVF)),
        (UI2(32768), VarType::I2, Err(OVF)),
        (I4(-1), VarType::UI4, Err(OVF)),
        (UI4(0x8000_0000), VarType::I4, Err(OVF)),
        (I8(-1), VarType::UI8, Err(OVF)),
        (UI8(1 << 63), VarType::I8, Err(OVF)),
        (I4(i32::MAX), VarType::UI4, Ok(UI4(i32::MAX as u32))),
    ]);
}

#[test]
fn floating_point_to_integer_rounds_half_to_even() {
    en(&[
        (R8(0.5), VarType::I4, Ok(I4(0))),
        (R8(1.5), VarType::I4, Ok(I4(2))),
        (R8(2.5), VarType::I4, Ok(I4(2))),
        (R8(3.5), VarType::I4, Ok(I4(4))),
        (R8(-0.5), VarType::I4, Ok(I4(0))),
        (R8(-1.5), VarType::I4, Ok(I4(-2))),
        (R8(-2.5), VarType::I4, Ok(I4(-2))),
        (R8(2.4999999), VarType::I4, Ok(I4(2))),
        (R8(2.5000001), VarType::I4, Ok(I4(3))),
        (R8(-0.6), VarType::I2, Ok(I2(-1))),
        (R4(-0.5), VarType::UI1, Ok(UI1(0))), // Wine: VarUI1FromR4(-0.5) = 0
        (R4(-0.51), VarType::UI1, Err(OVF)),
        (R4(255.49), VarType::UI1, Ok(UI1(255))),
        (R4(255.5), VarType::UI1, Err(OVF)), // rounds to 256
        (R8(127.5), VarType::I1, Err(OVF)),
        (R8(-128.5), VarType::I1, Ok(I1(-128))),
        (R8(2147483647.4), VarType::I4, Ok(I4(i32::MAX))),
        (R8(2147483647.5), VarType::I4, Err(OVF)),
        (R8(-2147483648.5), VarType::I4, Ok(I4(i32::MIN))),
        (R8(4294967295.0), VarType::UI4, Ok(UI4(u32::MAX))),
        (
            R8(9007199254740993.0),
            VarType::I8,
            Ok(I8(9007199254740992)),
        ),
        (R8(9.3e18), VarType::I8, Err(OVF)),
        (
            R8(1.8e19),
            VarType::UI8,
            Ok(UI8(18_000_000_000_000_000_000)),
        ),
        (R8(f64::NAN), VarType::I4, Err(OVF)),
        (R8(f64::INFINITY), VarType::I2, Err(OVF)),
        (Date(2.5), VarType::I4, Ok(I4(2))),
        (Date(45000.75), VarType::I4, Ok(I4(45001))),
    ]);
}

#[test]
fn bool_is_minus_one_and_nonzero_is_true() {
    en(&[
        (Bool(true), VarType::I1, Ok(I1(-1))),
        (Bool(true), VarType::I2, Ok(I2(-1))),
        (Bool(true), VarType::I4, Ok(I4(-1))),
        (Bool(true), VarType::I8, Ok(I8(-1))),
        // VarUI1FromBool(VARIANT_TRUE) = 255 ("conversions from bool overflow!")
        (Bool(true), VarType::UI1, Ok(UI1(255))),
        (Bool(true), VarType::UI2, Ok(UI2(u16::MAX))),
        (Bool(true), VarType::UI4, Ok(UI4(u32::MAX))),
        (Bool(true), VarType::UI8, Ok(UI8(u64::MAX))),
        (Bool(false), VarType::UI1, Ok(UI1(0))),
        (Bool(true), VarType::R4, Ok(R4(-1.0))),
        (Bool(true), VarType::R8, Ok(R8(-1.0))),
        (Bool(true), VarType::CY, Ok(Cy(-10_000))),
        (Bool(true), VarType::DATE, Ok(Date(-1.0))),
        (Bool(false), VarType::R8, Ok(R8(0.0))),
        (I4(0), VarType::BOOL, Ok(Bool(false))),
        (I4(2), VarType::BOOL, Ok(Bool(true))),
        (I1(-1), VarType::BOOL, Ok(Bool(true))),
        (UI8(1 << 40), VarType::BOOL, Ok(Bool(true))),
        (R8(0.0), VarType::BOOL, Ok(Bool(false))),
        (R8(-0.0), VarType::BOOL, Ok(Bool(false))),
        (R8(0.001), VarType::BOOL, Ok(Bool(true))),
        (R4(f32::NAN), VarType::BOOL, Ok(Bool(true))),
        (Cy(1), VarType::BOOL, Ok(Bool(true))),
        (Date(0.0), VarType::BOOL, Ok(Bool(false))),
    ]);
}

#[test]
fn bool_and_bstr_use_true_false_text_and_numbers() {
    en(&[
        (Bool(true), VarType::BSTR, Ok(s("True"))),
        (Bool(false), VarType::BSTR, Ok(s("False"))),
        (s("True"), VarType::BOOL, Ok(Bool(true))),
        (s("false"), VarType::BOOL, Ok(Bool(false))),
        (s("TRUE"), VarType::BOOL, Ok(Bool(true))),
        (s("#TRUE#"), VarType::BOOL, Ok(Bool(true))),
        (s("#FALSE#"), VarType::BOOL, Ok(Bool(false))),
        (s("-1"), VarType::BOOL, Ok(Bool(true))),
        (s("0"), VarType::BOOL, Ok(Bool(false))),
        (s("0.0"), VarType::BOOL, Ok(Bool(false))),
        (s("2.5"), VarType::BOOL, Ok(Bool(true))),
        (s(" 1 "), VarType::BOOL, Ok(Bool(true))),
        (s("&H0"), VarType::BOOL, Ok(Bool(false))),
        (s("yes"), VarType::BOOL, Err(MIS)),
        (s("Prawda"), VarType::BOOL, Err(MIS)),
        (s(""), VarType::BOOL, Err(MIS)),
    ]);
    // pl-PL still answers in English (VARIANT_ALPHABOOL) and reads Polish decimals.
    check(
        Locale::PlPl,
        &[
            (Bool(true), VarType::BSTR, Ok(s("True"))),
            (s("0,0"), VarType::BOOL, Ok(Bool(false))),
            (s("0,5"), VarType::BOOL, Ok(Bool(true))),
        ],
    );
}

#[test]
fn numbers_to_bstr_use_7_and_15_significant_digits() {
    en(&[
        (I4(-123), VarType::BSTR, Ok(s("-123"))),
        (UI8(u64::MAX), VarType::BSTR, Ok(s("18446744073709551615"))),
        (I8(i64::MIN), VarType::BSTR, Ok(s("-9223372036854775808"))),
        (I1(-128), VarType::BSTR, Ok(s("-128"))),
        (R8(1.5), VarType::BSTR, Ok(s("1.5"))),
        (R4(1.1), VarType::BSTR, Ok(s("1.1"))),
        (R4(0.1), VarType::BSTR, Ok(s("0.1"))),
        (R4(16777217.0), VarType::BSTR, Ok(s("1.677722E+07"))),
        (R4(1234567.0), VarType::BSTR, Ok(s("1234567"))),
        (R4(12345678.0), VarType::BSTR, Ok(s("1.234568E+07"))),
        (R8(0.1 + 0.2), VarType::BSTR, Ok(s("0.3"))),
        (R8(1.0 / 3.0), VarType::BSTR, Ok(s("0.333333333333333"))),
        (R8(2.0 / 3.0), VarType::BSTR, Ok(s("0.666666666666667"))),
        (
            R8(123456789012345.0),
            VarType::BSTR,
            Ok(s("123456789012345")),
        ),
        (R8(1e15), VarType::BSTR, Ok(s("1E+15"))),
        (R8(1e20), VarType::BSTR, Ok(s("1E+20"))),
        (R8(1.5e-7), VarType::BSTR, Ok(s("1.5E-07"))),
        (R8(0.0001), VarType::BSTR, Ok(s("0.0001"))),
        (R8(0.00001), VarType::BSTR, Ok(s("1E-05"))),
        (R8(-2.5e300), VarType::BSTR, Ok(s("-2.5E+300"))),
        (R8(100.0), VarType::BSTR, Ok(s("100"))),
        (R8(-0.0), VarType::BSTR, Ok(s("0"))),
        (R8(-1e-320), VarType::BSTR, Ok(s("-9.99988867182683E-321"))),
        (Cy(15_000), VarType::BSTR, Ok(s("1.5"))),
        (Cy(10_000), VarType::BSTR, Ok(s("1"))),
        (Cy(15), VarType::BSTR, Ok(s("0.0015"))),
        (Cy(-12_345_678), VarType::BSTR, Ok(s("-1234.5678"))),
        (Cy(i64::MIN), VarType::BSTR, Ok(s("-922337203685477.5808"))),
    ]);
}

#[test]
fn pl_pl_writes_and_reads_a_decimal_comma() {
    check(
        Locale::PlPl,
        &[
            (R8(1.5), VarType::BSTR, Ok(s("1,5"))),
            (R4(-0.25), VarType::BSTR, Ok(s("-0,25"))),
            (R8(1.5e-7), VarType::BSTR, Ok(s("1,5E-07"))),
            (Cy(15_000), VarType::BSTR, Ok(s("1,5"))),
            (I4(1234567), VarType::BSTR, Ok(s("1234567"))),
            (s("1,5"), VarType::R8, Ok(R8(1.5))),
            (s("-1 234,5"), VarType::R8, Ok(R8(-1234.5))),
            (s("1\u{A0}234\u{A0}567"), VarType::I4, Ok(I4(1234567))),
            (s("2,5"), VarType::I4, Ok(I4(2))),
            (s("12,5 zł"), VarType::CY, Ok(Cy(125_000))),
            (s("1.5"), VarType::R8, Err(MIS)),
            (s("1,5E+2"), VarType::R8, Ok(R8(150.0))),
        ],
    );
    en(&[
        (s("1,5"), VarType::R8, Ok(R8(15.0))), // ',' groups digits in en-US
        (s("1,234.5"), VarType::R8, Ok(R8(1234.5))),
    ]);
}

#[test]
fn bstr_number_syntax_follows_var_parse_num_from_str() {
    en(&[
        (s("42"), VarType::I4, Ok(I4(42))),
        (s("  42  "), VarType::I4, Ok(I4(42))),
        (s("+42"), VarType::I4, Ok(I4(42))),
        (s("-42"), VarType::I2, Ok(I2(-42))),
        (s("42-"), VarType::I4, Ok(I4(-42))),
        (s("(42)"), VarType::I4, Ok(I4(-42))),
        (s("(42"), VarType::I4, Err(MIS)),
        (s("$1,000"), VarType::I4, Ok(I4(1000))),
        (s("1,000,000"), VarType::I4, Ok(I4(1_000_000))),
        (s(",5"), VarType::I4, Err(MIS)), // no group separator before the first digit
        (s(".5"), VarType::R8, Ok(R8(0.5))),
        (s("-.5"), VarType::R8, Ok(R8(-0.5))),
        (s("5."), VarType::R8, Ok(R8(5.0))),
        (s("1e3"), VarType::I4, Ok(I4(1000))),
        (s("1.5E+2"), VarType::I4, Ok(I4(150))),
        (s("15e-1"), VarType::I4, Ok(I4(2))),
        (s("25e-1"), VarType::I4, Ok(I4(2))),
        (s("35e-1"), VarType::I4, Ok(I4(4))),
        (s("1e"), VarType::R8, Err(MIS)),
        (s("2.5"), VarType::I4, Ok(I4(2))),
        (s("2.50001"), VarType::I4, Ok(I4(3))),
        (s("-0.5"), VarType::UI1, Ok(UI1(0))),
        (s("0.06"), VarType::I4, Ok(I4(0))),
        (s("-1"), VarType::UI4, Err(OVF)),
        (s("256"), VarType::UI1, Err(OVF)),
        (s("-129"), VarType::I1, Err(OVF)),
        (s("18446744073709551615"), VarType::UI8, Ok(UI8(u64::MAX))),
        (s("18446744073709551616"), VarType::UI8, Err(OVF)),
        (s("-9223372036854775808"), VarType::I8, Ok(I8(i64::MIN))),
        (s("0000123"), VarType::I4, Ok(I4(123))),
        (s("0"), VarType::I4, Ok(I4(0))),
        (s("-0"), VarType::I4, Ok(I4(0))),
        (s("&HFF"), VarType::I4, Ok(I4(255))),
        (s("&hff"), VarType::UI1, Ok(UI1(255))),
        (s("&HFFFF"), VarType::I2, Ok(I2(-1))),
        (s("&H10000"), VarType::I2, Err(OVF)),
        (s("&O17"), VarType::I4, Ok(I4(15))),
        (s("&HFFFFFFFF"), VarType::R8, Ok(R8(-1.0))),
        (s("&H"), VarType::I4, Err(MIS)),
        (s(""), VarType::I4, Err(MIS)),
        (s("   "), VarType::R8, Err(MIS)),
        (s("abc"), VarType::R8, Err(MIS)),
        (s("12abc"), VarType::I4, Err(MIS)),
        (s("1.2.3"), VarType::R8, Err(MIS)),
        (s("1e400"), VarType::R8, Err(OVF)),
        (s("1e39"), VarType::R4, Err(OVF)),
        (s("3.4e38"), VarType::R4, Ok(R4(3.4e38))),
        (s("0.1"), VarType::R8, Ok(R8(0.1))),
        (s("0.1"), VarType::R4, Ok(R4(0.1))),
        (s("1.00005"), VarType::CY, Ok(Cy(10_000))), // half to even at the 4th decimal
        (s("1.00015"), VarType::CY, Ok(Cy(10_002))),
        (s("922337203685477.5807"), VarType::CY, Ok(Cy(i64::MAX))),
        (s("922337203685477.5808"), VarType::CY, Err(OVF)),
        (s("True"), VarType::I4, Err(MIS)),
    ]);
}

#[test]
fn currency_scales_by_ten_thousand_and_rounds_half_to_even() {
    en(&[
        (I4(5), VarType::CY, Ok(Cy(50_000))),
        (
            I8(922_337_203_685_477),
            VarType::CY,
            Ok(Cy(9_223_372_036_854_770_000)),
        ),
        (I8(922_337_203_685_478), VarType::CY, Err(OVF)),
        (UI8(u64::MAX), VarType::CY, Err(OVF)),
        (R8(1.23456), VarType::CY, Ok(Cy(12_346))),
        (R8(0.00005), VarType::CY, Ok(Cy(1))), // 0.00005 is slightly above in binary
        (R8(0.5), VarType::CY, Ok(Cy(5_000))),
        (R8(-1.00015), VarType::CY, Ok(Cy(-10_002))),
        (R8(1e15), VarType::CY, Err(OVF)),
        (R8(f64::NAN), VarType::CY, Err(OVF)),
        (R4(0.1), VarType::CY, Ok(Cy(1_000))),
        (Cy(25_000), VarType::I4, Ok(I4(2))),
        (Cy(35_000), VarType::I4, Ok(I4(4))),
        (Cy(-25_000), VarType::I4, Ok(I4(-2))),
        (Cy(-15_000), VarType::I4, Ok(I4(-2))),
        (Cy(-10_000), VarType::I8, Ok(I8(-1))),
        (Cy(15_001), VarType::I2, Ok(I2(2))),
        (Cy(-4_999), VarType::UI1, Ok(UI1(0))),
        (Cy(-5_001), VarType::UI1, Err(OVF)),
        (Cy(12_345), VarType::R8, Ok(R8(1.2345))),
        (Cy(12_345), VarType::R4, Ok(R4(1.2345))),
        (Cy(10_000), VarType::DATE, Ok(Date(1.0))),
    ]);
}

#[test]
fn real_narrowing_and_date_range_overflow() {
    en(&[
        (R8(3.4e38), VarType::R4, Ok(R4(3.4e38))),
        (R8(3.5e38), VarType::R4, Err(OVF)),
        (R8(-1e300), VarType::R4, Err(OVF)),
        (R8(f64::INFINITY), VarType::R4, Err(OVF)),
        (R8(1e-50), VarType::R4, Ok(R4(0.0))),
        (UI8(u64::MAX), VarType::R4, Ok(R4(1.8446744e19))),
        (R8(45000.5), VarType::DATE, Ok(Date(45000.5))),
        (R8(-657434.0), VarType::DATE, Ok(Date(-657434.0))),
        (R8(-657434.9), VarType::DATE, Ok(Date(-657434.9))),
        (R8(-657435.0), VarType::DATE, Err(OVF)),
        (R8(2958465.99), VarType::DATE, Ok(Date(2958465.99))),
        (R8(2958466.0), VarType::DATE, Err(OVF)),
        (R8(f64::NAN), VarType::DATE, Err(OVF)),
        (I4(2958465), VarType::DATE, Ok(Date(2958465.0))),
        (I4(2958466), VarType::DATE, Err(OVF)),
        (I4(-657435), VarType::DATE, Err(OVF)),
        (Date(1.25), VarType::R8, Ok(R8(1.25))),
        (Date(-1.25), VarType::R4, Ok(R4(-1.25))),
        (Date(1.5), VarType::CY, Ok(Cy(15_000))),
    ]);
}

#[test]
fn dates_format_like_var_bstr_from_date() {
    // Wine's test_VarBstrFromDate vectors (en-US).
    en(&[
        (Date(0.0), VarType::BSTR, Ok(s("12:00:00 AM"))),
        (Date(3.34), VarType::BSTR, Ok(s("1/2/1900 8:09:36 AM"))),
        (Date(3339.34), VarType::BSTR, Ok(s("2/20/1909 8:09:36 AM"))),
        (Date(365.0), VarType::BSTR, Ok(s("12/30/1900"))),
        (Date(365.25), VarType::BSTR, Ok(s("12/30/1900 6:00:00 AM"))),
        (Date(1461.0), VarType::BSTR, Ok(s("12/31/1903"))),
        (Date(1461.5), VarType::BSTR, Ok(s("12/31/1903 12:00:00 PM"))),
        (
            Date(-49192.24),
            VarType::BSTR,
            Ok(s("4/24/1765 5:45:36 AM")),
        ),
        (Date(-657434.0), VarType::BSTR, Ok(s("1/1/100"))),
        (Date(2958465.0), VarType::BSTR, Ok(s("12/31/9999"))),
        (Date(0.75), VarType::BSTR, Ok(s("6:00:00 PM"))),
        (Date(1.0 - 1e-9), VarType::BSTR, Ok(s("12:00:00 AM"))), // rounds into the next day
        (Date(2958466.0), VarType::BSTR, Err(OpcError::InvalidArg)),
        (Date(f64::NAN), VarType::BSTR, Err(OpcError::InvalidArg)),
    ]);
    check(
        Locale::PlPl,
        &[
            (Date(3.34), VarType::BSTR, Ok(s("02.01.1900 08:09:36"))),
            (Date(365.0), VarType::BSTR, Ok(s("30.12.1900"))),
            (Date(0.75), VarType::BSTR, Ok(s("18:00:00"))),
            (Date(45306.5), VarType::BSTR, Ok(s("15.01.2024 12:00:00"))),
        ],
    );
}

#[test]
fn dates_parse_from_the_formats_they_are_written_in_and_iso() {
    en(&[
        (
            s("1/2/1900 8:09:36 AM"),
            VarType::DATE,
            Ok(Date(3.0 + 29376.0 / 86400.0)),
        ),
        (s("12/30/1900"), VarType::DATE, Ok(Date(365.0))),
        (s("12:00:00 PM"), VarType::DATE, Ok(Date(0.5))),
        (s("6:00 pm"), VarType::DATE, Ok(Date(0.75))),
        (s("18:00"), VarType::DATE, Ok(Date(0.75))),
        (s("2024-01-15"), VarType::DATE, Ok(Date(45306.0))),
        (s("2024-01-15T12:00:00"), VarType::DATE, Ok(Date(45306.5))),
        (s("2024-01-15 06:00:00"), VarType::DATE, Ok(Date(45306.25))),
        (s("1/15/24"), VarType::DATE, Ok(Date(45306.0))),
        (
            s("4/24/1765 6:00:00 AM"),
            VarType::DATE,
            Ok(Date(-49192.25)),
        ),
        (s("2/29/2023"), VarType::DATE, Err(MIS)),
        (s("2/29/2024"), VarType::DATE, Ok(Date(45351.0))),
        (s("13/1/2024"), VarType::DATE, Err(MIS)),
        (s("25:00"), VarType::DATE, Err(MIS)),
        (s("13:00 PM"), VarType::DATE, Err(MIS)),
        (s("tomorrow"), VarType::DATE, Err(MIS)),
        (s(""), VarType::DATE, Err(MIS)),
        (s("15.01.2024"), VarType::DATE, Err(MIS)),
    ]);
    check(
        Locale::PlPl,
        &[
            (s("15.01.2024 12:00:00"), VarType::DATE, Ok(Date(45306.5))),
            (
                s("02.01.1900 08:09:36"),
                VarType::DATE,
                Ok(Date(3.0 + 29376.0 / 86400.0)),
            ),
            (s("2024-01-15"), VarType::DATE, Ok(Date(45306.0))),
            (s("1/15/2024"), VarType::DATE, Err(MIS)),
        ],
    );
}

#[test]
fn empty_converts_to_zero_empty_string_and_false() {
    en(&[
        (Empty, VarType::I1, Ok(I1(0))),
        (Empty, VarType::UI8, Ok(UI8(0))),
        (Empty, VarType::R4, Ok(R4(0.0))),
        (Empty, VarType::R8, Ok(R8(0.0))),
        (Empty, VarType::CY, Ok(Cy(0))),
        (Empty, VarType::DATE, Ok(Date(0.0))),
        (Empty, VarType::BSTR, Ok(s(""))),
        (Empty, VarType::BOOL, Ok(Bool(false))),
        (Empty, VarType::ERROR, Err(MIS)),
    ]);
}

#[test]
fn error_converts_only_to_itself() {
    let scode = Error(0x8002_0004_u32 as i32);
    let mut rows = vec![(scode.clone(), VarType::ERROR, Ok(scode.clone()))];
    for to in [
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
    ] {
        rows.push((scode.clone(), to, Err(MIS)));
    }
    for from in [I4(1), R8(1.0), s("1"), Bool(true), Cy(1), Date(1.0)] {
        rows.push((from, VarType::ERROR, Err(MIS)));
    }
    en(&rows);
}

#[test]
fn empty_and_variant_targets_keep_the_canonical_value() {
    for v in [
        Empty,
        I2(7),
        s("x"),
        Error(5),
        Value::Array(ArrayValue::new(VarType::R4, vec![R4(1.0)])),
    ] {
        assert_eq!(v.convert(VarType::EMPTY), Ok(v.clone()));
        assert_eq!(v.convert(VarType::VARIANT), Ok(v.clone()));
        assert_eq!(v.convert(v.var_type()), Ok(v.clone()));
    }
}

#[test]
fn arrays_convert_element_by_element() {
    let arr = |t: VarType, e: Vec<Value>| Value::Array(ArrayValue::new(t, e));
    let r8s = arr(VarType::R8, vec![R8(1.5), R8(2.5), R8(-3.0)]);
    let mixed = arr(VarType::VARIANT, vec![I2(1), s("2,5"), Bool(true), Empty]);
    en(&[
        (
            r8s.clone(),
            VarType::array_of(VarType::I4),
            Ok(arr(VarType::I4, vec![I4(2), I4(2), I4(-3)])),
        ),
        (
            r8s.clone(),
            VarType::array_of(VarType::BSTR),
            Ok(arr(VarType::BSTR, vec![s("1.5"), s("2.5"), s("-3")])),
        ),
        (r8s.clone(), VarType::array_of(VarType::UI1), Err(OVF)),
        (r8s.clone(), VarType::array_of(VarType::ERROR), Err(MIS)),
        (
            r8s.clone(),
            VarType::array_of(VarType::VARIANT),
            Ok(arr(VarType::VARIANT, vec![R8(1.5), R8(2.5), R8(-3.0)])),
        ),
        (r8s.clone(), VarType::R8, Err(MIS)),
        (r8s.clone(), VarType::BSTR, Err(MIS)),
        (R8(1.0), VarType::array_of(VarType::R8), Err(MIS)),
        (
            arr(VarType::I4, vec![]),
            VarType::array_of(VarType::R8),
            Ok(arr(VarType::R8, vec![])),
        ),
        (
            arr(VarType::VARIANT, vec![I2(1), s("2.5"), Bool(true), Empty]),
            VarType::array_of(VarType::R8),
            Ok(arr(VarType::R8, vec![R8(1.0), R8(2.5), R8(-1.0), R8(0.0)])),
        ),
        (
            arr(VarType::VARIANT, vec![I4(1), arr(VarType::I4, vec![I4(2)])]),
            VarType::array_of(VarType::I4),
            Err(MIS),
        ),
    ]);
    check(
        Locale::PlPl,
        &[(
            mixed,
            VarType::array_of(VarType::R4),
            Ok(arr(VarType::R4, vec![R4(1.0), R4(2.5), R4(-1.0), R4(0.0)])),
        )],
    );
}

#[test]
fn vartypes_that_are_not_types_are_bad_and_unsupported_ones_mismatch() {
    let bad = [
        VarType(15),
        VarType(24),     // VT_VOID
        VarType(64),     // VT_FILETIME
        VarType(0x1003), // VT_VECTOR | VT_I4
        VarType::array_of(VarType::EMPTY),
        VarType::array_of(VarType(1)),
    ];
    for vt in bad {
        assert_eq!(I4(1).convert(vt), Err(OpcError::BadVarType), "{vt:?}");
        assert!(!is_supported_type(vt));
    }
    let unsupported = [
        VarType(1),
        VarType(9),
        VarType(13),
        VarType(14),
        VarType(22),
        VarType(0x4003),
    ];
    for vt in unsupported {
        assert_eq!(I4(1).convert(vt), Err(MIS), "{vt:?}");
        assert!(!is_supported_type(vt));
    }
    for vt in [
        VarType::EMPTY,
        VarType::VARIANT,
        VarType::R8,
        VarType::array_of(VarType::VARIANT),
        VarType::array_of(VarType::BOOL),
    ] {
        assert!(is_supported_type(vt), "{vt:?}");
    }
}

#[test]
fn locale_follows_the_lcid() {
    assert_eq!(Locale::from_lcid(0x0415, Locale::EnUs), Locale::PlPl);
    assert_eq!(Locale::from_lcid(0x0409, Locale::PlPl), Locale::EnUs);
    assert_eq!(Locale::from_lcid(0x0407, Locale::PlPl), Locale::EnUs);
    assert_eq!(Locale::from_lcid(0x0800, Locale::PlPl), Locale::PlPl);
    assert_eq!(Locale::from_lcid(0x0400, Locale::EnUs), Locale::EnUs);
    assert_eq!(Locale::from(Lang::Polish), Locale::PlPl);
    assert_eq!(Locale::default(), Locale::EnUs);
}

// ---------------------------------------------------------------------------------------
// Properties

const INT_TYPES: [VarType; 8] = [
    VarType::I1,
    VarType::UI1,
    VarType::I2,
    VarType::UI2,
    VarType::I4,
    VarType::UI4,
    VarType::I8,
    VarType::UI8,
];

fn range_of(vt: VarType) -> (i128, i128) {
    match vt {
        VarType::I1 => (i8::MIN.into(), i8::MAX.into()),
        VarType::UI1 => (0, u8::MAX.into()),
        VarType::I2 => (i16::MIN.into(), i16::MAX.into()),
        VarType::UI2 => (0, u16::MAX.into()),
        VarType::I4 => (i32::MIN.into(), i32::MAX.into()),
        VarType::UI4 => (0, u32::MAX.into()),
        VarType::I8 => (i64::MIN.into(), i64::MAX.into()),
        VarType::UI8 => (0, u64::MAX.into()),
        _ => unreachable!(),
    }
}

fn as_i128(v: &Value) -> Option<i128> {
    Some(match *v {
        I1(x) => x.into(),
        UI1(x) => x.into(),
        I2(x) => x.into(),
        UI2(x) => x.into(),
        I4(x) => x.into(),
        UI4(x) => x.into(),
        I8(x) => x.into(),
        UI8(x) => x.into(),
        _ => return None,
    })
}

fn any_int() -> impl Strategy<Value = Value> {
    prop_oneof![
        any::<i8>().prop_map(I1),
        any::<u8>().prop_map(UI1),
        any::<i16>().prop_map(I2),
        any::<u16>().prop_map(UI2),
        any::<i32>().prop_map(I4),
        any::<u32>().prop_map(UI4),
        any::<i64>().prop_map(I8),
        any::<u64>().prop_map(UI8),
    ]
}

fn any_int_type() -> impl Strategy<Value = VarType> {
    prop::sample::select(INT_TYPES.to_vec())
}

fn any_locale() -> impl Strategy<Value = Locale> {
    prop_oneof![Just(Locale::EnUs), Just(Locale::PlPl)]
}

proptest! {
    #[test]
    fn integer_conversion_fails_exactly_outside_the_target_range(v in any_int(), to in any_int_type()) {
        let x = as_i128(&v).unwrap();
        let (lo, hi) = range_of(to);
        match v.convert(to) {
            Ok(r) => {
                prop_assert!((lo..=hi).contains(&x));
                prop_assert_eq!(r.var_type(), to);
                prop_assert_eq!(as_i128(&r), Some(x));
            }
            Err(e) => {
                prop_assert_eq!(e, OpcError::Overflow);
                prop_assert!(!(lo..=hi).contains(&x));
            }
        }
    }

    #[test]
    fn integers_round_trip_through_r8(v in any_int()) {
        let x = as_i128(&v).unwrap();
        let r8 = v.convert(VarType::R8).unwrap();
        prop_assert_eq!(&r8, &R8(x as f64));
        if x.abs() <= 1 << 53 {
            prop_assert_eq!(r8.convert(v.var_type()), Ok(v));
        }
    }

    #[test]
    fn widening_never_fails(v in any_int()) {
        for to in [VarType::R8, VarType::R4, VarType::BSTR, VarType::BOOL, VarType::VARIANT] {
            prop_assert!(v.convert(to).is_ok(), "{:?} -> {:?}", v, to);
        }
        let wider: &[VarType] = match v {
            I1(_) => &[VarType::I2, VarType::I4, VarType::I8],
            UI1(_) => &[VarType::I2, VarType::UI2, VarType::I4, VarType::UI4, VarType::I8, VarType::UI8],
            I2(_) => &[VarType::I4, VarType::I8],
            UI2(_) => &[VarType::I4, VarType::UI4, VarType::I8, VarType::UI8],
            I4(_) => &[VarType::I8, VarType::CY],
            UI4(_) => &[VarType::I8, VarType::UI8, VarType::CY],
            _ => &[],
        };
        for &to in wider {
            prop_assert!(v.convert(to).is_ok(), "{:?} -> {:?}", v, to);
        }
    }

    #[test]
    fn reals_round_half_to_even_or_overflow(x in -1e10f64..1e10, to in any_int_type()) {
        let (lo, hi) = range_of(to);
        let r = x.round_ties_even() as i128;
        match R8(x).convert(to) {
            Ok(v) => prop_assert_eq!(as_i128(&v), Some(r)),
            Err(e) => {
                prop_assert_eq!(e, OpcError::Overflow);
                prop_assert!(r < lo || r > hi);
            }
        }
    }

    #[test]
    fn integers_round_trip_through_bstr(v in any_int(), locale in any_locale()) {
        let text = v.convert_in(VarType::BSTR, locale).unwrap();
        prop_assert_eq!(text.convert_in(v.var_type(), locale), Ok(v));
    }

    #[test]
    fn r8_round_trips_through_bstr_to_15_digits(x in any::<f64>().prop_filter("finite", |x| x.is_finite()), locale in any_locale()) {
        let text = R8(x).convert_in(VarType::BSTR, locale).unwrap();
        let Ok(R8(back)) = text.convert_in(VarType::R8, locale) else {
            return Err(TestCaseError::fail(format!("{text:?} did not parse back")));
        };
        let tolerance = x.abs() * 1e-14 + f64::MIN_POSITIVE;
        prop_assert!((back - x).abs() <= tolerance, "{} -> {:?} -> {}", x, text, back);
    }

    #[test]
    fn r4_round_trips_through_bstr_to_7_digits(x in any::<f32>().prop_filter("finite", |x| x.is_finite())) {
        let text = R4(x).convert(VarType::BSTR).unwrap();
        let Ok(R4(back)) = text.convert(VarType::R4) else {
            return Err(TestCaseError::fail(format!("{text:?} did not parse back")));
        };
        prop_assert!((back - x).abs() <= x.abs() * 1e-6 + f32::MIN_POSITIVE, "{} -> {:?} -> {}", x, text, back);
    }

    #[test]
    fn dates_round_trip_through_bstr_to_the_second(days in -657_434i64..=2_958_465, secs in 0u32..86_400, locale in any_locale()) {
        let d = ole_from_civil_for_test(days, secs);
        let text = Date(d).convert_in(VarType::BSTR, locale).unwrap();
        let Ok(Date(back)) = text.convert_in(VarType::DATE, locale) else {
            return Err(TestCaseError::fail(format!("{text:?} did not parse back")));
        };
        prop_assert!((back - d).abs() < 1e-9 * d.abs().max(1.0), "{} -> {:?} -> {}", d, text, back);
    }

    #[test]
    fn cy_round_trips_through_bstr_exactly(c in any::<i64>(), locale in any_locale()) {
        let text = Cy(c).convert_in(VarType::BSTR, locale).unwrap();
        prop_assert_eq!(text.convert_in(VarType::CY, locale), Ok(Cy(c)));
    }

    #[test]
    fn conversion_never_panics(v in any_scalar(), to in any_target(), locale in any_locale()) {
        let _ = v.convert_in(to, locale);
    }
}

/// An OLE date for a day number and seconds since midnight (whole seconds).
fn ole_from_civil_for_test(days: i64, secs: u32) -> f64 {
    let frac = f64::from(secs) / 86_400.0;
    if days < 0 {
        days as f64 - frac
    } else {
        days as f64 + frac
    }
}

fn any_scalar() -> impl Strategy<Value = Value> {
    prop_oneof![
        Just(Empty),
        any_int(),
        any::<f32>().prop_map(R4),
        any::<f64>().prop_map(R8),
        any::<i64>().prop_map(Cy),
        any::<f64>().prop_map(Date),
        ".{0,12}".prop_map(Bstr),
        "[-+ (&$hHoO0-9.,eE)]{0,16}".prop_map(Bstr),
        any::<bool>().prop_map(Bool),
        any::<i32>().prop_map(Error),
    ]
}

fn any_target() -> impl Strategy<Value = VarType> {
    prop_oneof![
        any::<u16>().prop_map(VarType),
        (0u16..=21).prop_map(VarType)
    ]
}

/// Writes ([`convert_for_write`]): every VARIANT kind a client may send × the canonical
/// types of process variables × the group's locale (pl-PL 0x0415, en-US 0x0409, and the
/// system default/neutral LCIDs, which take the server's default locale).
#[test]
fn writes_convert_as_variant_change_type_ex_with_the_groups_locale() {
    const RANGE: OpcError = OpcError::Range;
    const BAD: OpcError = OpcError::BadType;
    type Row = (Value, VarType, Result<Value, OpcError>);
    let run = |locale: Locale, rows: &[Row]| {
        for (from, to, expected) in rows {
            let got = convert_for_write(from, *to, locale);
            assert_eq!(&got, expected, "{locale:?}: {from:?} -> {to:?}");
        }
    };
    // The same in every locale.
    let common: Vec<Row> = vec![
        // Every integer and real type, into every canonical type, range-checked.
        (I2(3), VarType::R8, Ok(R8(3.0))),
        (I1(-5), VarType::I2, Ok(I2(-5))),
        (UI1(200), VarType::I2, Ok(I2(200))),
        (UI2(65535), VarType::I4, Ok(I4(65535))),
        (UI4(7), VarType::UI2, Ok(UI2(7))),
        (I8(-1), VarType::UI2, Err(RANGE)),
        (UI8(1 << 40), VarType::I4, Err(RANGE)),
        (I4(70000), VarType::I2, Err(RANGE)),
        (R8(2.5), VarType::I2, Ok(I2(2))),
        (R8(1e300), VarType::R4, Err(RANGE)),
        (R4(1.5), VarType::R8, Ok(R8(1.5))),
        (R8(-7.25), VarType::R8, Ok(R8(-7.25))),
        // BOOL: TRUE -> 1 (not VariantChangeType's -1), FALSE -> 0.
        (Bool(true), VarType::I2, Ok(I2(1))),
        (Bool(true), VarType::UI2, Ok(UI2(1))),
        (Bool(true), VarType::R4, Ok(R4(1.0))),
        (Bool(false), VarType::R8, Ok(R8(0.0))),
        (Bool(false), VarType::UI1, Ok(UI1(0))),
        // CY (and DECIMAL, which reaches the core as R8).
        (Cy(125_000), VarType::R8, Ok(R8(12.5))),
        (Cy(125_000), VarType::I4, Ok(I4(12))),
        (Cy(i64::MAX), VarType::I2, Err(RANGE)),
        // Text with blanks around, sign, exponent, hex; not a number stays BADTYPE.
        (s(" 42 "), VarType::I4, Ok(I4(42))),
        (s("-3"), VarType::UI2, Err(RANGE)),
        (s("1e3"), VarType::R8, Ok(R8(1000.0))),
        (s("&H10"), VarType::I2, Ok(I2(16))),
        (s("70000"), VarType::I2, Err(RANGE)),
        (s("abc"), VarType::R8, Err(BAD)),
        (s(""), VarType::R8, Err(BAD)),
        (s("True"), VarType::I2, Err(BAD)),
        // DATE, EMPTY, ERROR and arrays are no process value.
        (Date(1.0), VarType::R8, Err(BAD)),
        (Date(1.0), VarType::I4, Err(BAD)),
        (Empty, VarType::R8, Err(BAD)),
        (Error(0), VarType::I4, Err(BAD)),
        (
            Array(ArrayValue::new(VarType::R8, vec![R8(1.0)])),
            VarType::R8,
            Err(BAD),
        ),
    ];
    let pl: Vec<Row> = vec![
        (s("12,5"), VarType::R4, Ok(R4(12.5))),
        (s(" 12,5 "), VarType::R8, Ok(R8(12.5))),
        (s("-0,25"), VarType::R8, Ok(R8(-0.25))),
        (s("1\u{A0}234,5"), VarType::R8, Ok(R8(1234.5))),
        (s("12,5"), VarType::I2, Ok(I2(12))),
        (s("13,5"), VarType::I2, Ok(I2(14))),
        // "12.5" is no Polish number.
        (s("12.5"), VarType::R8, Err(BAD)),
    ];
    let en_rows: Vec<Row> = vec![
        (s("12.5"), VarType::R4, Ok(R4(12.5))),
        (s("\t12.5 "), VarType::R8, Ok(R8(12.5))),
        (s("1,234.5"), VarType::R8, Ok(R8(1234.5))),
        // As VariantChangeTypeEx in en-US: the comma is the thousands separator.
        (s("12,5"), VarType::R8, Ok(R8(125.0))),
    ];
    for lcid in [0x0415, 0x0409, 0x0800, 0x0400, 0x0000] {
        for default in [Locale::PlPl, Locale::EnUs] {
            let locale = Locale::from_lcid(lcid, default);
            run(locale, &common);
            match locale {
                Locale::PlPl => run(locale, &pl),
                Locale::EnUs => run(locale, &en_rows),
            }
        }
    }
    assert_eq!(Locale::from_lcid(0x0800, Locale::PlPl), Locale::PlPl);
    assert_eq!(Locale::from_lcid(0x0415, Locale::EnUs), Locale::PlPl);
    assert_eq!(Locale::from_lcid(0x0409, Locale::PlPl), Locale::EnUs);
    // A canonical type that is not a number (other namespaces) converts as VariantChangeType.
    run(
        Locale::EnUs,
        &[
            (I4(5), VarType::BSTR, Ok(s("5"))),
            (Bool(true), VarType::I4, Ok(I4(1))),
            (s("yes"), VarType::BOOL, Err(BAD)),
            (Date(1.0), VarType::DATE, Ok(Date(1.0))),
        ],
    );
}
