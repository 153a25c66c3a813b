//! Derived values: `FormatedCV` (the value formatted by the `Format` attribute),
//! `PercentageCV` and `BarCVs`.
//!
//! # The `Format` attribute
//! asix formats numbers with C `printf` conversions (e.g. `%6.2f`). Accepted syntax:
//! literal text, exactly one conversion, literal text; `%%` is a literal `%`.
//!
//! ```text
//! %[flags][width][.precision][length]conversion
//! flags      any of  -  +  space  0  #
//! width      decimal, at most 64
//! precision  decimal, at most 64
//! length     h, hh, l, ll, L (accepted and ignored)
//! conversion d i u     integer (the value rounded half away from zero; u: like d)
//!            x X       hexadecimal of the rounded value (negative: 64-bit two's complement)
//!            f F       fixed point, precision 6 by default
//!            e E       exponent form d.dddde+XX
//!            g G       shortest of %e/%f as C does (trailing zeros removed unless #)
//! ```
//!
//! Examples: `%6.2f` of 3.14159 -> `  3.14`, `%.1f °C` -> `21.5 °C`, `%05d` -> `00042`,
//! `%+.3e` -> `+1.235e+03`, `0x%04X` -> `0x00FF`. Not accepted: `*` width or precision,
//! `%s`, `%c`, `%p`, `%n`, more than one conversion, no conversion. A variable without
//! (or with an unusable) `Format` gets the default: integers in decimal, reals in the
//! shortest form that reads back to the same number (`21.5`, `0.1`).
//! Non-finite reals print as `nan`/`inf`/`-inf` (`NAN`/`INF` for F, E, G).

use ctopc_core::Value;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Conv {
    Int,
    HexLower,
    HexUpper,
    Fixed { upper: bool },
    Exp { upper: bool },
    General { upper: bool },
}

/// A parsed `Format` attribute.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FormatSpec {
    prefix: String,
    suffix: String,
    left: bool,
    plus: bool,
    space: bool,
    zero: bool,
    alt: bool,
    width: usize,
    precision: Option<usize>,
    conv: Conv,
}

const MAX_WIDTH: usize = 64;

impl FormatSpec {
    /// Parses a `Format` attribute value (syntax in the module documentation).
    pub fn parse(text: &str) -> Result<FormatSpec, String> {
        let mut prefix = String::new();
        let mut suffix = String::new();
        let mut spec: Option<FormatSpec> = None;
        let mut chars = text.chars().peekable();
        while let Some(c) = chars.next() {
            if c != '%' {
                if spec.is_some() {
                    suffix.push(c)
                } else {
                    prefix.push(c)
                }
                continue;
            }
            if chars.peek() == Some(&'%') {
                chars.next();
                if spec.is_some() {
                    suffix.push('%')
                } else {
                    prefix.push('%')
                }
                continue;
            }
            if spec.is_some() {
                return Err(format!("`{text}` has more than one conversion"));
            }
            let mut s = FormatSpec {
                prefix: String::new(),
                suffix: String::new(),
                left: false,
                plus: false,
                space: false,
                zero: false,
                alt: false,
                width: 0,
                precision: None,
                conv: Conv::Int,
            };
            while let Some(&f) = chars.peek() {
                match f {
                    '-' => s.left = true,
                    '+' => s.plus = true,
                    ' ' => s.space = true,
                    '0' => s.zero = true,
                    '#' => s.alt = true,
                    _ => break,
                }
                chars.next();
            }
            let number =
                |chars: &mut std::iter::Peekable<std::str::Chars>| -> Result<usize, String> {
                    let mut n = 0usize;
                    while let Some(d) = chars.peek().and_then(|c| c.to_digit(10)) {
                        n = n * 10 + d as usize;
                        if n > MAX_WIDTH {
                            return Err(format!("`{text}`: width or precision over {MAX_WIDTH}"));
                        }
                        chars.next();
                    }
                    Ok(n)
                };
            s.width = number(&mut chars)?;
            if chars.peek() == Some(&'.') {
                chars.next();
                s.precision = Some(number(&mut chars)?);
            }
            while matches!(chars.peek(), Some('h' | 'l' | 'L')) {
                chars.next();
            }
            s.conv = match chars.next() {
                Some('d' | 'i' | 'u') => Conv::Int,
                Some('x') => Conv::HexLower,
                Some('X') => Conv::HexUpper,
                Some('f') => Conv::Fixed { upper: false },
                Some('F') => Conv::Fixed { upper: true },
                Some('e') => Conv::Exp { upper: false },
                Some('E') => Conv::Exp { upper: true },
                Some('g') => Conv::General { upper: false },
                Some('G') => Conv::General { upper: true },
                Some(other) => {
                    return Err(format!("`{text}`: conversion `%{other}` is not supported"))
                }
                None => return Err(format!("`{text}` ends inside a conversion")),
            };
            spec = Some(s);
        }
        let mut spec = spec.ok_or_else(|| format!("`{text}` has no conversion such as %6.2f"))?;
        spec.prefix = prefix;
        spec.suffix = suffix;
        Ok(spec)
    }

    /// Formats a real number.
    pub fn format_f64(&self, v: f64) -> String {
        let body = match self.conv {
            _ if !v.is_finite() => {
                let upper = matches!(
                    self.conv,
                    Conv::Fixed { upper: true }
                        | Conv::Exp { upper: true }
                        | Conv::General { upper: true }
                        | Conv::HexUpper
                );
                let t = if v.is_nan() { "nan" } else { "inf" };
                let t = if upper {
                    t.to_ascii_uppercase()
                } else {
                    t.to_owned()
                };
                return self.finish(v.is_sign_negative() && !v.is_nan(), "", t, false);
            }
            Conv::Int | Conv::HexLower | Conv::HexUpper => {
                let r = v.round().clamp(i64::MIN as f64, i64::MAX as f64) as i64;
                return self.format_i128(r as i128);
            }
            Conv::Fixed { .. } => fixed(v.abs(), self.precision.unwrap_or(6), self.alt),
            Conv::Exp { upper } => exp(v.abs(), self.precision.unwrap_or(6), self.alt, upper),
            Conv::General { upper } => {
                general(v.abs(), self.precision.unwrap_or(6), self.alt, upper)
            }
        };
        self.finish(v.is_sign_negative() && v != 0.0, "", body, true)
    }

    /// Formats an integer exactly (integer conversions) or as a real (the others).
    pub fn format_i128(&self, v: i128) -> String {
        match self.conv {
            Conv::Int => {
                let mut digits = v.unsigned_abs().to_string();
                if let Some(p) = self.precision {
                    while digits.len() < p {
                        digits.insert(0, '0');
                    }
                }
                self.finish(v < 0, "", digits, self.precision.is_none())
            }
            Conv::HexLower | Conv::HexUpper => {
                let bits = v as i64 as u64;
                let mut digits = if self.conv == Conv::HexUpper {
                    format!("{bits:X}")
                } else {
                    format!("{bits:x}")
                };
                if let Some(p) = self.precision {
                    while digits.len() < p {
                        digits.insert(0, '0');
                    }
                }
                let prefix = match (self.alt && bits != 0, self.conv) {
                    (false, _) => "",
                    (true, Conv::HexUpper) => "0X",
                    (true, _) => "0x",
                };
                self.finish(false, prefix, digits, self.precision.is_none())
            }
            _ => self.format_f64(v as f64),
        }
    }

    /// Formats a numeric value; `None` for non-numeric values.
    pub fn format_value(&self, v: &Value) -> Option<String> {
        match integer_of(v) {
            Some(i) => Some(self.format_i128(i)),
            None => value_as_f64(v).map(|f| self.format_f64(f)),
        }
    }

    /// Sign, padding and the literal text around the conversion.
    fn finish(
        &self,
        negative: bool,
        radix_prefix: &str,
        body: String,
        zero_pad_allowed: bool,
    ) -> String {
        let sign = if negative {
            "-"
        } else if self.plus && radix_prefix.is_empty() {
            "+"
        } else if self.space && radix_prefix.is_empty() {
            " "
        } else {
            ""
        };
        let len = sign.chars().count() + radix_prefix.len() + body.chars().count();
        let pad = self.width.saturating_sub(len);
        let mut out = String::with_capacity(self.prefix.len() + self.suffix.len() + len + pad);
        out.push_str(&self.prefix);
        if self.left {
            out.push_str(sign);
            out.push_str(radix_prefix);
            out.push_str(&body);
            push_n(&mut out, ' ', pad);
        } else if self.zero && zero_pad_allowed {
            out.push_str(sign);
            out.push_str(radix_prefix);
            push_n(&mut out, '0', pad);
            out.push_str(&body);
        } else {
            push_n(&mut out, ' ', pad);
            out.push_str(sign);
            out.push_str(radix_prefix);
            out.push_str(&body);
        }
        out.push_str(&self.suffix);
        out
    }
}

fn push_n(out: &mut String, c: char, n: usize) {
    for _ in 0..n {
        out.push(c);
    }
}

fn fixed(v: f64, precision: usize, alt: bool) -> String {
    let mut s = format!("{v:.precision$}");
    if alt && precision == 0 {
        s.push('.');
    }
    s
}

/// `d.ddde+XX` of a non-negative finite number.
fn exp(v: f64, precision: usize, alt: bool, upper: bool) -> String {
    let s = format!("{v:.precision$e}");
    let (mantissa, exponent) = s.split_once('e').unwrap_or((&s, "0"));
    let exponent: i32 = exponent.parse().unwrap_or(0);
    let mut out = mantissa.to_owned();
    if alt && precision == 0 {
        out.push('.');
    }
    out.push(if upper { 'E' } else { 'e' });
    out.push(if exponent < 0 { '-' } else { '+' });
    out.push_str(&format!("{:02}", exponent.unsigned_abs()));
    out
}

fn strip_fraction_zeros(s: &str) -> String {
    if !s.contains('.') {
        return s.to_owned();
    }
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}

/// C's `%g` of a non-negative finite number.
fn general(v: f64, precision: usize, alt: bool, upper: bool) -> String {
    let p = precision.max(1);
    let x: i32 = if v == 0.0 {
        0
    } else {
        let s = format!("{v:.prec$e}", prec = p - 1);
        s.split_once('e')
            .and_then(|(_, e)| e.parse().ok())
            .unwrap_or(0)
    };
    if (p as i32) > x && x >= -4 {
        let s = fixed(v, (p as i32 - 1 - x) as usize, alt);
        if alt {
            s
        } else {
            strip_fraction_zeros(&s)
        }
    } else {
        let s = exp(v, p - 1, alt, upper);
        if alt {
            return s;
        }
        let split = s.find(['e', 'E']).unwrap_or(s.len());
        format!("{}{}", strip_fraction_zeros(&s[..split]), &s[split..])
    }
}

/// The value of an integer VARIANT, exactly.
fn integer_of(v: &Value) -> Option<i128> {
    Some(match *v {
        Value::I1(x) => x as i128,
        Value::UI1(x) => x as i128,
        Value::I2(x) => x as i128,
        Value::UI2(x) => x as i128,
        Value::I4(x) => x as i128,
        Value::UI4(x) => x as i128,
        Value::I8(x) => x as i128,
        Value::UI8(x) => x as i128,
        _ => return None,
    })
}

/// A numeric value as f64 (integers, reals, currency); `None` for other types.
pub fn value_as_f64(v: &Value) -> Option<f64> {
    if let Some(i) = integer_of(v) {
        return Some(i as f64);
    }
    match *v {
        Value::R4(x) => Some(x as f64),
        Value::R8(x) => Some(x),
        Value::Cy(x) => Some(x as f64 / 10_000.0),
        _ => None,
    }
}

/// `FormatedCV`: `spec` when given, else the default form; `None` for non-numeric values.
pub fn format_value(spec: Option<&FormatSpec>, v: &Value) -> Option<String> {
    if let Some(spec) = spec {
        return spec.format_value(v);
    }
    if let Some(i) = integer_of(v) {
        return Some(i.to_string());
    }
    match *v {
        Value::R4(x) => Some(x.to_string()),
        _ => value_as_f64(v).map(|x| x.to_string()),
    }
}

/// `PercentageCV` = (v - low) / (high - low) * 100, not clamped; `None` when the range is
/// empty or the result is not finite.
pub fn percentage(v: f64, low: f64, high: f64) -> Option<f64> {
    let p = (v - low) / (high - low) * 100.0;
    (high != low && p.is_finite()).then_some(p)
}

/// `BarCVs` = [percent of `v` minus percent of `base`, percent of `base`]: the bar's signed
/// length from its base and where the base sits, both in percent of the range.
pub fn bar_values(v: f64, low: f64, high: f64, base: f64) -> Option<[f64; 2]> {
    let b = percentage(base, low, high)?;
    let p = percentage(v, low, high)?;
    Some([p - b, b])
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn printf_conversions() {
        let rows: &[(&str, f64, &str)] = &[
            ("%6.2f", 1.23456, "  1.23"),
            ("%.2f", -0.004, "-0.00"),
            ("%.1f °C", 21.45, "21.4 °C"), // binary 21.45 is below the midpoint
            ("%.1f °C", 21.55, "21.6 °C"),
            ("%f", 1.5, "1.500000"),
            ("%-8.1f|", 2.0, "2.0     |"),
            ("%+.1f", 2.0, "+2.0"),
            ("% .1f", 2.0, " 2.0"),
            ("%08.2f", -3.5, "-0003.50"),
            ("%#.0f", 3.0, "3."),
            ("%.0f", 2.5, "2"),
            ("%d", 41.5, "42"),
            ("%d", -41.5, "-42"),
            ("%05d", 42.0, "00042"),
            ("%5d", -42.0, "  -42"),
            ("%.3d", 7.0, "007"),
            ("%ld", 7.0, "7"),
            ("%u", 7.0, "7"),
            ("%x", 255.0, "ff"),
            ("0x%04X", 255.0, "0x00FF"),
            ("%#x", 255.0, "0xff"),
            ("%x", -1.0, "ffffffffffffffff"),
            ("%e", 1234.5678, "1.234568e+03"),
            ("%+.3e", 1234.5, "+1.234e+03"),
            ("%E", 0.000123, "1.230000E-04"),
            ("%.2e", 0.0, "0.00e+00"),
            ("%g", 1234567.0, "1.23457e+06"),
            ("%g", 123456.0, "123456"),
            ("%g", 0.0001, "0.0001"),
            ("%g", 0.00001, "1e-05"),
            ("%g", 100.0, "100"),
            ("%.3g", 1.23456, "1.23"),
            ("%G", 1e-10, "1E-10"),
            ("%#g", 1.0, "1.00000"),
            ("%g", 0.0, "0"),
            ("%.0g", 0.5, "0.5"),
            ("%lf", 1.25, "1.250000"),
            ("Poziom: %5.1f%%", 42.25, "Poziom:  42.2%"),
            ("%f", f64::NAN, "nan"),
            ("%F", f64::INFINITY, "INF"),
            ("%5.1f", f64::NEG_INFINITY, " -inf"),
        ];
        for (fmt, v, expected) in rows {
            let spec = FormatSpec::parse(fmt).unwrap_or_else(|e| panic!("{fmt}: {e}"));
            assert_eq!(spec.format_f64(*v), *expected, "{fmt} of {v}");
        }
    }

    #[test]
    fn invalid_formats() {
        for fmt in [
            "", "abc", "%", "%5", "%s", "%c", "%*d", "%d %d", "%.*f", "%100d", "%.99f", "%n",
        ] {
            assert!(FormatSpec::parse(fmt).is_err(), "{fmt}");
        }
    }

    #[test]
    fn values_integers_exact_and_defaults() {
        let spec = FormatSpec::parse("%d").unwrap();
        assert_eq!(
            spec.format_value(&Value::UI8(u64::MAX)).unwrap(),
            "18446744073709551615"
        );
        assert_eq!(spec.format_value(&Value::I2(-5)).unwrap(), "-5");
        assert_eq!(spec.format_value(&Value::Bstr("x".into())), None);
        let f = FormatSpec::parse("%.2f").unwrap();
        assert_eq!(f.format_value(&Value::I4(3)).unwrap(), "3.00");
        let rows: &[(Value, Option<&str>)] = &[
            (Value::R4(0.1), Some("0.1")),
            (Value::R8(21.5), Some("21.5")),
            (Value::R8(-3.0), Some("-3")),
            (Value::I4(-7), Some("-7")),
            (Value::UI1(200), Some("200")),
            (Value::Cy(12_345), Some("1.2345")),
            (Value::Bool(true), None),
            (Value::Empty, None),
        ];
        for (v, expected) in rows {
            assert_eq!(format_value(None, v).as_deref(), *expected, "{v:?}");
        }
    }

    #[test]
    fn percentage_and_bars() {
        assert_eq!(percentage(50.0, 0.0, 200.0), Some(25.0));
        assert_eq!(percentage(-10.0, -20.0, 20.0), Some(25.0));
        assert_eq!(percentage(250.0, 0.0, 200.0), Some(125.0));
        assert_eq!(percentage(1.0, 5.0, 5.0), None);
        assert_eq!(bar_values(50.0, 0.0, 200.0, 0.0), Some([25.0, 0.0]));
        assert_eq!(bar_values(-10.0, -20.0, 20.0, 0.0), Some([-25.0, 50.0]));
        assert_eq!(bar_values(1.0, 2.0, 2.0, 2.0), None);
    }

    proptest! {
        #[test]
        fn parse_and_format_never_panic(fmt in "[%a-zA-Z0-9.+ #-]{0,12}", v in any::<f64>(), i in any::<i64>()) {
            if let Ok(spec) = FormatSpec::parse(&fmt) {
                let _ = spec.format_f64(v);
                let _ = spec.format_i128(i as i128);
            }
        }
    }
}
