//! Text decoding of the configuration and database files, and the warning type the
//! readers return.
//!
//! asix tools on Polish Windows write Windows-1250; hand editors write UTF-8, with or
//! without a byte-order mark. [`decode_text`] accepts all three (plus UTF-16 LE with a
//! BOM, which `WritePrivateProfileString` produces for Unicode INI files): valid UTF-8 is
//! taken as UTF-8, anything else as Windows-1250 (every byte decodes, so decoding never
//! fails).

use std::fmt;

/// The encoding [`decode_text`] recognised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TextEncoding {
    /// UTF-8 without a byte-order mark (plain ASCII is reported as this).
    Utf8,
    /// UTF-8 with the `EF BB BF` byte-order mark.
    Utf8Bom,
    /// UTF-16 little-endian with the `FF FE` byte-order mark.
    Utf16LeBom,
    /// Windows-1250 (Central European): bytes that are not valid UTF-8.
    Windows1250,
}

/// Decodes file bytes to text (see the module documentation for the rules).
pub fn decode_text(bytes: &[u8]) -> (String, TextEncoding) {
    if let Some(rest) = bytes.strip_prefix(&[0xEF, 0xBB, 0xBF]) {
        return (
            String::from_utf8_lossy(rest).into_owned(),
            TextEncoding::Utf8Bom,
        );
    }
    if let Some(rest) = bytes.strip_prefix(&[0xFF, 0xFE]) {
        let units = rest
            .chunks(2)
            .map(|c| u16::from_le_bytes([c[0], *c.get(1).unwrap_or(&0)]));
        let text = char::decode_utf16(units)
            .map(|r| r.unwrap_or('\u{FFFD}'))
            .collect();
        return (text, TextEncoding::Utf16LeBom);
    }
    match std::str::from_utf8(bytes) {
        Ok(s) => (s.to_owned(), TextEncoding::Utf8),
        Err(_) => (decode_windows_1250(bytes), TextEncoding::Windows1250),
    }
}

/// Decodes Windows-1250 bytes. The five bytes the code page leaves undefined
/// (0x81, 0x83, 0x88, 0x90, 0x98) become U+FFFD.
pub fn decode_windows_1250(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len());
    decode_windows_1250_into(bytes, &mut s);
    s
}

/// [`decode_windows_1250`] appending to `out`.
pub fn decode_windows_1250_into(bytes: &[u8], out: &mut String) {
    decode_into(bytes, &CP1250_HIGH, out);
}

/// Appends single-byte text: ASCII as it is, the high half through `high`.
fn decode_into(bytes: &[u8], high: &[u16; 128], out: &mut String) {
    out.extend(bytes.iter().map(|&b| {
        if b < 0x80 {
            b as char
        } else {
            char::from_u32(u32::from(high[usize::from(b - 0x80)])).unwrap_or('\u{FFFD}')
        }
    }));
}

/// Windows-1250 bytes 0x80..=0xFF as Unicode scalar values.
const CP1250_HIGH: [u16; 128] = [
    0x20AC, 0xFFFD, 0x201A, 0xFFFD, 0x201E, 0x2026, 0x2020, 0x2021, //
    0xFFFD, 0x2030, 0x0160, 0x2039, 0x015A, 0x0164, 0x017D, 0x0179, //
    0xFFFD, 0x2018, 0x2019, 0x201C, 0x201D, 0x2022, 0x2013, 0x2014, //
    0xFFFD, 0x2122, 0x0161, 0x203A, 0x015B, 0x0165, 0x017E, 0x017A, //
    0x00A0, 0x02C7, 0x02D8, 0x0141, 0x00A4, 0x0104, 0x00A6, 0x00A7, //
    0x00A8, 0x00A9, 0x015E, 0x00AB, 0x00AC, 0x00AD, 0x00AE, 0x017B, //
    0x00B0, 0x00B1, 0x02DB, 0x0142, 0x00B4, 0x00B5, 0x00B6, 0x00B7, //
    0x00B8, 0x0105, 0x015F, 0x00BB, 0x013D, 0x02DD, 0x013E, 0x017C, //
    0x0154, 0x00C1, 0x00C2, 0x0102, 0x00C4, 0x0139, 0x0106, 0x00C7, //
    0x010C, 0x00C9, 0x0118, 0x00CB, 0x011A, 0x00CD, 0x00CE, 0x010E, //
    0x0110, 0x0143, 0x0147, 0x00D3, 0x00D4, 0x0150, 0x00D6, 0x00D7, //
    0x0158, 0x016E, 0x00DA, 0x0170, 0x00DC, 0x00DD, 0x0162, 0x00DF, //
    0x0155, 0x00E1, 0x00E2, 0x0103, 0x00E4, 0x013A, 0x0107, 0x00E7, //
    0x010D, 0x00E9, 0x0119, 0x00EB, 0x011B, 0x00ED, 0x00EE, 0x010F, //
    0x0111, 0x0144, 0x0148, 0x00F3, 0x00F4, 0x0151, 0x00F6, 0x00F7, //
    0x0159, 0x016F, 0x00FA, 0x0171, 0x00FC, 0x00FD, 0x0163, 0x02D9, //
];

/// Decodes CP852 (DOS Latin-2) bytes, the code page of Polish DOS-era Paradox tables.
/// Every byte decodes.
pub fn decode_cp852(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len());
    decode_cp852_into(bytes, &mut s);
    s
}

/// [`decode_cp852`] appending to `out`.
pub fn decode_cp852_into(bytes: &[u8], out: &mut String) {
    decode_into(bytes, &CP852_HIGH, out);
}

/// CP852 bytes 0x80..=0xFF as Unicode scalar values (the code page as glibc's iconv and
/// Python's `cp852` codec map it).
const CP852_HIGH: [u16; 128] = [
    0x00C7, 0x00FC, 0x00E9, 0x00E2, 0x00E4, 0x016F, 0x0107, 0x00E7, //
    0x0142, 0x00EB, 0x0150, 0x0151, 0x00EE, 0x0179, 0x00C4, 0x0106, //
    0x00C9, 0x0139, 0x013A, 0x00F4, 0x00F6, 0x013D, 0x013E, 0x015A, //
    0x015B, 0x00D6, 0x00DC, 0x0164, 0x0165, 0x0141, 0x00D7, 0x010D, //
    0x00E1, 0x00ED, 0x00F3, 0x00FA, 0x0104, 0x0105, 0x017D, 0x017E, //
    0x0118, 0x0119, 0x00AC, 0x017A, 0x010C, 0x015F, 0x00AB, 0x00BB, //
    0x2591, 0x2592, 0x2593, 0x2502, 0x2524, 0x00C1, 0x00C2, 0x011A, //
    0x015E, 0x2563, 0x2551, 0x2557, 0x255D, 0x017B, 0x017C, 0x2510, //
    0x2514, 0x2534, 0x252C, 0x251C, 0x2500, 0x253C, 0x0102, 0x0103, //
    0x255A, 0x2554, 0x2569, 0x2566, 0x2560, 0x2550, 0x256C, 0x00A4, //
    0x0111, 0x0110, 0x010E, 0x00CB, 0x010F, 0x0147, 0x00CD, 0x00CE, //
    0x011B, 0x2518, 0x250C, 0x2588, 0x2584, 0x0162, 0x016E, 0x2580, //
    0x00D3, 0x00DF, 0x00D4, 0x0143, 0x0144, 0x0148, 0x0160, 0x0161, //
    0x0154, 0x00DA, 0x0155, 0x0170, 0x00FD, 0x00DD, 0x0163, 0x00B4, //
    0x00AD, 0x02DD, 0x02DB, 0x02C7, 0x02D8, 0x00A7, 0x00F7, 0x00B8, //
    0x00B0, 0x00A8, 0x02D9, 0x0171, 0x0158, 0x0159, 0x25A0, 0x00A0, //
];

/// A problem that did not stop a reader (unknown option, duplicate key, ...). The caller
/// logs it. `line` is 1-based; 0 when the warning concerns the file as a whole.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Warning {
    pub file: String,
    pub line: usize,
    pub message: String,
}

impl Warning {
    pub(crate) fn new(file: &str, line: usize, message: impl Into<String>) -> Self {
        Warning {
            file: file.to_owned(),
            line,
            message: message.into(),
        }
    }
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            write!(f, "{}: {}", self.file, self.message)
        } else {
            write!(f, "{}:{}: {}", self.file, self.line, self.message)
        }
    }
}

/// Parses a boolean the asix way: `tak`/`true`/`1` and `nie`/`false`/`0`, ASCII
/// case-insensitive, surrounding blanks ignored.
/// `text.trim()`, without looking at a char when both ends are ASCII and not blank (the
/// usual cell).
pub fn trim(text: &str) -> &str {
    let plain = |b: Option<&u8>| b.is_some_and(|&b| b.is_ascii() && !(b as char).is_whitespace());
    let b = text.as_bytes();
    if b.is_empty() || plain(b.first()) && plain(b.last()) {
        text
    } else {
        text.trim()
    }
}

pub fn parse_bool(text: &str) -> Option<bool> {
    let t = trim(text);
    for yes in ["tak", "true", "1"] {
        if t.eq_ignore_ascii_case(yes) {
            return Some(true);
        }
    }
    for no in ["nie", "false", "0"] {
        if t.eq_ignore_ascii_case(no) {
            return Some(false);
        }
    }
    None
}

/// Parses a real number as written in the database: `.` decimal point, or `,` when the
/// text has exactly one comma and no point (Polish spreadsheets write `12,5`); an
/// optional exponent. Surrounding blanks ignored; NaN and infinities are rejected.
pub fn parse_number(text: &str) -> Option<f64> {
    let t = trim(text);
    if t.is_empty() {
        return None;
    }
    // The usual cell, an integer of up to 15 digits, read exactly without the float parser
    // (a million rows hold several numbers each).
    let (negative, digits) = match t.as_bytes()[0] {
        b'-' => (true, &t[1..]),
        b'+' => (false, &t[1..]),
        _ => (false, t),
    };
    if !digits.is_empty() && digits.len() <= 15 && digits.bytes().all(|b| b.is_ascii_digit()) {
        let v = digits
            .bytes()
            .fold(0u64, |a, b| a * 10 + u64::from(b - b'0')) as f64;
        return Some(if negative { -v } else { v });
    }
    let owned;
    let t = if !t.contains('.') && t.matches(',').count() == 1 {
        owned = t.replace(',', ".");
        owned.as_str()
    } else {
        t
    };
    // Rust's parser accepts "inf", "nan", "infinity": only digits, sign, point and exponent here.
    if !t
        .bytes()
        .all(|b| b.is_ascii_digit() || matches!(b, b'+' | b'-' | b'.' | b'e' | b'E'))
    {
        return None;
    }
    t.parse::<f64>().ok().filter(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_utf8_bom_utf16_and_windows_1250() {
        let cases: &[(&[u8], &str, TextEncoding)] = &[
            (b"abc", "abc", TextEncoding::Utf8),
            ("Wytwórnia".as_bytes(), "Wytwórnia", TextEncoding::Utf8),
            (
                b"\xEF\xBB\xBFZa\xC5\xBC\xC3\xB3\xC5\x82\xC4\x87",
                "Zażółć",
                TextEncoding::Utf8Bom,
            ),
            (b"\xFF\xFEP\x00\x05\x01", "Pą", TextEncoding::Utf16LeBom),
            // "Zażółć gęślą jaźń" in Windows-1250.
            (
                b"Za\xBF\xF3\xB3\xE6 g\xEA\x9Cl\xB9 ja\x9F\xF1",
                "Zażółć gęślą jaźń",
                TextEncoding::Windows1250,
            ),
            (
                b"\xA5\xC6\xCA\xA3\xD1\xD3\x8C\x8F\xAF",
                "ĄĆĘŁŃÓŚŹŻ",
                TextEncoding::Windows1250,
            ),
            (b"\x80\x81", "€\u{FFFD}", TextEncoding::Windows1250),
        ];
        for (bytes, text, enc) in cases {
            assert_eq!(decode_text(bytes), (text.to_string(), *enc), "{bytes:?}");
        }
    }

    #[test]
    fn decodes_cp852() {
        // "Zażółć gęślą jaźń" and the Polish capitals in CP852 (iconv -t CP852).
        assert_eq!(
            decode_cp852(b"Za\xBE\xA2\x88\x86 g\xA9\x98l\xA5 ja\xAB\xE4"),
            "Zażółć gęślą jaźń"
        );
        assert_eq!(
            decode_cp852(b"\xA4\x8F\xA8\x9D\xE3\xE0\x97\x8D\xBD"),
            "ĄĆĘŁŃÓŚŹŻ"
        );
        assert_eq!(decode_cp852(b"abc\xFF"), "abc\u{A0}");
    }

    #[test]
    fn booleans_and_numbers() {
        for (t, v) in [
            ("tak", Some(true)),
            (" TAK ", Some(true)),
            ("True", Some(true)),
            ("1", Some(true)),
        ] {
            assert_eq!(parse_bool(t), v, "{t}");
        }
        for (t, v) in [
            ("nie", Some(false)),
            ("NIE", Some(false)),
            ("false", Some(false)),
            ("0", Some(false)),
        ] {
            assert_eq!(parse_bool(t), v, "{t}");
        }
        for t in ["", "yes", "no", "2", "t"] {
            assert_eq!(parse_bool(t), None, "{t}");
        }
        let nums = [
            ("12.5", Some(12.5)),
            ("12,5", Some(12.5)),
            (" -3 ", Some(-3.0)),
            ("1e3", Some(1000.0)),
        ];
        for (t, v) in nums {
            assert_eq!(parse_number(t), v, "{t}");
        }
        for t in [
            "", "1,000.5", "1,2,3", "inf", "NaN", "KW_L101", "0x10", "1e999",
        ] {
            assert_eq!(parse_number(t), None, "{t}");
        }
    }

    /// Integers (read without the float parser) read as the float parser reads them, the
    /// sign of -0 included, up to the 15 digits of the fast path and past them.
    #[test]
    fn integers_read_as_the_float_parser_reads_them() {
        for t in [
            "0",
            "-0",
            "+0",
            "7",
            "-7",
            "+7",
            "100",
            "007",
            "999999999999999",
            "-999999999999999",
            "1000000000000000",
            "12345678901234567890",
            " 42 ",
        ] {
            let want = t.trim().parse::<f64>().ok();
            let got = parse_number(t);
            assert_eq!(got, want, "{t}");
            assert_eq!(
                got.map(f64::is_sign_negative),
                want.map(f64::is_sign_negative),
                "{t}"
            );
        }
        for t in ["-", "+", "--1", "1-", "+-1"] {
            assert_eq!(parse_number(t), None, "{t}");
        }
    }
}
