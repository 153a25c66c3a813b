//! The Asix.Evo REST server's answers, decoded: total (every input gives a value or an
//! error, never a panic), over a body the shell has already bounded
//! ([`super::MAX_BODY`]), with serde_json's recursion limit against deep nesting.
//!
//! Field names are matched case-insensitively (`readSucceeded`, `ReadSucceeded`, ...),
//! as ASKOM's demo client deserialises them; unknown fields are skipped. What a field
//! that is missing or of the wrong kind means:
//! - `id`: missing is an answer whose names cannot be checked ([`VarState::id`] `None`);
//! - `readSucceeded`: missing is `true` (the answer carries a value);
//! - `quality`: missing, negative or over 16 bits is BAD (0);
//! - `timeStamp`: missing or not ISO 8601 is `None` (the caller takes the poll's time);
//!   with `Z` or an offset it is converted to UTC; **without an offset it is taken as
//!   UTC** (the station's time zone is not known to the server, and .NET writes
//!   `DateTime`s of kind UTC with `Z`, so an offset-less time is not expected);
//! - `value`: a number, string, bool or null; an object or array is
//!   [`RestValue::Unsupported`] (a per-variable error, not a failed answer).

use std::fmt;

use ctopc_core::time::days_from_civil;
use ctopc_core::Timestamp;
use serde::de::{self, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};
use serde::Deserialize;

/// One element of a `variable/value` answer.
#[derive(Debug, Clone, PartialEq)]
pub struct VarState {
    /// The variable's name as the server gives it.
    pub id: Option<String>,
    pub read_succeeded: bool,
    /// `readStatusString`: why the read failed.
    pub status: String,
    /// The value's time, UTC.
    pub time: Option<Timestamp>,
    /// The OPC DA quality, vendor and limit bits included.
    pub quality: u16,
    pub value: RestValue,
}

/// A value as JSON gives it.
#[derive(Debug, Clone, PartialEq)]
pub enum RestValue {
    Null,
    Bool(bool),
    Int(i64),
    UInt(u64),
    Float(f64),
    Text(String),
    /// An object or an array: no asix variable holds one.
    Unsupported,
}

/// Why an answer could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodeError(pub String);

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "malformed answer: {}", self.0)
    }
}

impl std::error::Error for DecodeError {}

/// Decodes a `GET /asix/v1/variable/value` answer: a JSON array of variable states.
pub fn decode_values(body: &[u8]) -> Result<Vec<VarState>, DecodeError> {
    let mut de = serde_json::Deserializer::from_slice(body);
    let v = StatesSeed
        .deserialize(&mut de)
        .map_err(|e| DecodeError(short(&e)))?;
    de.end().map_err(|e| DecodeError(short(&e)))?;
    Ok(v)
}

/// serde_json's message, cut to a log line's size (it never quotes the input at length,
/// but a field name it quotes may be long).
fn short(e: &serde_json::Error) -> String {
    let mut s = e.to_string();
    if s.len() > 200 {
        let mut end = 200;
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        s.truncate(end);
        s.push('…');
    }
    s
}

struct StatesSeed;

impl<'de> de::DeserializeSeed<'de> for StatesSeed {
    type Value = Vec<VarState>;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_seq(StatesVisitor)
    }
}

use serde::de::DeserializeSeed as _;

struct StatesVisitor;

impl<'de> Visitor<'de> for StatesVisitor {
    type Value = Vec<VarState>;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an array of variable states")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        // No size hint taken: the element count comes from the (bounded) body itself.
        let mut out = Vec::new();
        while let Some(v) = seq.next_element::<VarState>()? {
            out.push(v);
        }
        Ok(out)
    }
}

impl<'de> Deserialize<'de> for VarState {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_map(StateVisitor)
    }
}

struct StateVisitor;

/// A field name, compared case-insensitively.
enum Field {
    Id,
    ReadSucceeded,
    Status,
    Time,
    Quality,
    Value,
    Other,
}

impl<'de> Deserialize<'de> for Field {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = Field;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a field name")
            }
            fn visit_str<E: de::Error>(self, s: &str) -> Result<Field, E> {
                let is = |n: &str| s.eq_ignore_ascii_case(n);
                Ok(if is("id") {
                    Field::Id
                } else if is("readSucceeded") {
                    Field::ReadSucceeded
                } else if is("readStatusString") {
                    Field::Status
                } else if is("timeStamp") {
                    Field::Time
                } else if is("quality") {
                    Field::Quality
                } else if is("value") {
                    Field::Value
                } else {
                    Field::Other
                })
            }
        }
        d.deserialize_identifier(V)
    }
}

/// Any JSON value, kept only when it is a string.
struct MaybeText(Option<String>);

impl<'de> Deserialize<'de> for MaybeText {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        match RestValue::deserialize(d)? {
            RestValue::Text(s) => Ok(MaybeText(Some(s))),
            _ => Ok(MaybeText(None)),
        }
    }
}

impl<'de> Visitor<'de> for StateVisitor {
    type Value = VarState;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a variable state object")
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<VarState, A::Error> {
        let mut s = VarState {
            id: None,
            read_succeeded: true,
            status: String::new(),
            time: None,
            quality: 0,
            value: RestValue::Null,
        };
        while let Some(k) = map.next_key::<Field>()? {
            match k {
                Field::Id => s.id = map.next_value::<MaybeText>()?.0,
                Field::ReadSucceeded => {
                    s.read_succeeded = !matches!(map.next_value()?, RestValue::Bool(false))
                }
                Field::Status => s.status = map.next_value::<MaybeText>()?.0.unwrap_or_default(),
                Field::Time => {
                    s.time = map
                        .next_value::<MaybeText>()?
                        .0
                        .and_then(|t| parse_iso8601(&t))
                }
                Field::Quality => {
                    s.quality = match map.next_value()? {
                        RestValue::Int(q) => u16::try_from(q).unwrap_or(0),
                        RestValue::UInt(q) => u16::try_from(q).unwrap_or(0),
                        _ => 0,
                    }
                }
                Field::Value => s.value = map.next_value()?,
                Field::Other => {
                    map.next_value::<IgnoredAny>()?;
                }
            }
        }
        Ok(s)
    }
}

impl<'de> Deserialize<'de> for RestValue {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = RestValue;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a value")
            }
            fn visit_bool<E>(self, v: bool) -> Result<RestValue, E> {
                Ok(RestValue::Bool(v))
            }
            fn visit_i64<E>(self, v: i64) -> Result<RestValue, E> {
                Ok(RestValue::Int(v))
            }
            fn visit_u64<E>(self, v: u64) -> Result<RestValue, E> {
                Ok(match i64::try_from(v) {
                    Ok(i) => RestValue::Int(i),
                    Err(_) => RestValue::UInt(v),
                })
            }
            fn visit_f64<E>(self, v: f64) -> Result<RestValue, E> {
                Ok(RestValue::Float(v))
            }
            fn visit_str<E>(self, v: &str) -> Result<RestValue, E> {
                Ok(RestValue::Text(v.to_owned()))
            }
            fn visit_string<E>(self, v: String) -> Result<RestValue, E> {
                Ok(RestValue::Text(v))
            }
            fn visit_unit<E>(self) -> Result<RestValue, E> {
                Ok(RestValue::Null)
            }
            fn visit_none<E>(self) -> Result<RestValue, E> {
                Ok(RestValue::Null)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<RestValue, A::Error> {
                while seq.next_element::<IgnoredAny>()?.is_some() {}
                Ok(RestValue::Unsupported)
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<RestValue, A::Error> {
                while map.next_entry::<IgnoredAny, IgnoredAny>()?.is_some() {}
                Ok(RestValue::Unsupported)
            }
        }
        d.deserialize_any(V)
    }
}

/// Parses `YYYY-MM-DDThh:mm:ss[.fraction][Z|±hh:mm|±hhmm|±hh]` (a space may stand for
/// `T`; seven fraction digits are kept, the 100 ns of a FILETIME, more are ignored) to
/// UTC; no offset means UTC. `None` for anything else or a time before 1601.
pub fn parse_iso8601(s: &str) -> Option<Timestamp> {
    let b = s.trim().as_bytes();
    let num = |r: std::ops::Range<usize>| -> Option<i64> {
        let d = b.get(r)?;
        if d.is_empty() || !d.iter().all(u8::is_ascii_digit) {
            return None;
        }
        Some(d.iter().fold(0i64, |a, &c| a * 10 + i64::from(c - b'0')))
    };
    if b.len() < 19 || b[4] != b'-' || b[7] != b'-' || !matches!(b[10], b'T' | b't' | b' ') {
        return None;
    }
    if b[13] != b':' || b[16] != b':' {
        return None;
    }
    let (y, mo, d) = (num(0..4)?, num(5..7)?, num(8..10)?);
    let (h, mi, sec) = (num(11..13)?, num(14..16)?, num(17..19)?);
    if !(1..=12).contains(&mo) || d < 1 || d > days_in_month(y, mo) || h > 23 || mi > 59 {
        return None;
    }
    if sec > 60 {
        return None;
    }
    let mut i = 19;
    let mut ticks_frac = 0i64;
    if b.get(i) == Some(&b'.') || b.get(i) == Some(&b',') {
        i += 1;
        let start = i;
        while b.get(i).is_some_and(u8::is_ascii_digit) {
            i += 1;
        }
        if i == start {
            return None;
        }
        for k in 0..7 {
            let digit = if start + k < i {
                i64::from(b[start + k] - b'0')
            } else {
                0
            };
            ticks_frac = ticks_frac * 10 + digit;
        }
    }
    let offset_s = match b.get(i) {
        None => 0,
        Some(b'Z' | b'z') if i + 1 == b.len() => 0,
        Some(&sign @ (b'+' | b'-')) => {
            let rest = &b[i + 1..];
            let (oh, om) = match rest.len() {
                2 => (num(i + 1..i + 3)?, 0),
                4 => (num(i + 1..i + 3)?, num(i + 3..i + 5)?),
                5 if rest[2] == b':' => (num(i + 1..i + 3)?, num(i + 4..i + 6)?),
                _ => return None,
            };
            if oh > 23 || om > 59 {
                return None;
            }
            let o = oh * 3600 + om * 60;
            if sign == b'+' {
                o
            } else {
                -o
            }
        }
        _ => return None,
    };
    let days = days_from_civil(y, mo as u32, d as u32);
    let secs = days * 86_400 + h * 3600 + mi * 60 + sec - offset_s;
    let ticks = Timestamp::UNIX_EPOCH_TICKS
        .checked_add(secs.checked_mul(10_000_000)?)?
        .checked_add(ticks_frac)?;
    (ticks >= 0).then_some(Timestamp(ticks))
}

fn days_in_month(y: i64, m: i64) -> i64 {
    match m {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        _ if (y % 4 == 0 && y % 100 != 0) || y % 400 == 0 => 29,
        _ => 28,
    }
}

/// Formats a UTC timestamp as `YYYY-MM-DDThh:mm:ss.fffffffZ` (the simulator's answers).
pub fn format_iso8601(t: Timestamp) -> String {
    let c = t.civil();
    let frac = (t.0 - Timestamp::UNIX_EPOCH_TICKS).rem_euclid(10_000_000);
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:07}Z",
        c.year, c.month, c.day, c.hour, c.minute, c.second, frac
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(s: &str) -> Option<i64> {
        parse_iso8601(s).map(|t| t.unix_millis())
    }

    #[test]
    fn times_convert_to_utc() {
        assert_eq!(t("1970-01-01T00:00:00Z"), Some(0));
        assert_eq!(t("1970-01-01T00:00:00"), Some(0), "no offset: UTC");
        assert_eq!(t("1970-01-01 01:00:00+01:00"), Some(0));
        assert_eq!(t("1970-01-01T01:00:00+0100"), Some(0));
        assert_eq!(t("1970-01-01T01:00:00+01"), Some(0));
        assert_eq!(t("1969-12-31T23:00:00-01:00"), Some(0));
        assert_eq!(t("2024-02-29T12:00:00.5Z"), Some(1_709_208_000_500));
        let ticks = parse_iso8601("2024-02-29T12:00:00.1234567891Z").unwrap();
        assert_eq!(ticks.0 % 10_000_000, 1_234_567);
        let now = Timestamp::from_unix_millis(1_764_900_000_123);
        assert_eq!(parse_iso8601(&format_iso8601(now)), Some(now));
        for bad in [
            "",
            "2024-02-30T00:00:00Z",
            "2023-02-29T00:00:00Z",
            "2024-13-01T00:00:00Z",
            "2024-01-01T24:00:00Z",
            "2024-01-01T00:00:00Zjunk",
            "2024-01-01T00:00:00+25:00",
            "2024-01-01T00:00:00.Z",
            "1600-12-31T23:59:59Z",
            "2024-01-01",
            "２０２４-01-01T00:00:00Z",
            "+024-01-01T00:00:00Z",
        ] {
            assert_eq!(parse_iso8601(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn states_decode_in_either_casing() {
        let camel = br#"[{"id":"A000","readSucceeded":true,"readStatusString":"","timeStamp":"1970-01-01T00:00:01Z","quality":216,"value":12.5}]"#;
        let pascal = br#"[{"Id":"A000","ReadSucceeded":true,"ReadStatusString":"","TimeStamp":"1970-01-01T00:00:01Z","Quality":216,"Value":12.5,"Extra":{"x":[1]}}]"#;
        for body in [&camel[..], &pascal[..]] {
            let v = decode_values(body).unwrap();
            assert_eq!(
                v,
                vec![VarState {
                    id: Some("A000".into()),
                    read_succeeded: true,
                    status: String::new(),
                    time: Some(Timestamp::from_unix_millis(1000)),
                    quality: 216,
                    value: RestValue::Float(12.5),
                }]
            );
        }
    }

    #[test]
    fn values_of_every_kind() {
        let v = decode_values(
            br#"[{"value":1},{"value":-1},{"value":18446744073709551615},{"value":"x"},{"value":true},{"value":null},{"value":[1,2]},{"value":{"a":1}},{}]"#,
        )
        .unwrap();
        let vals: Vec<_> = v.into_iter().map(|s| s.value).collect();
        assert_eq!(
            vals,
            vec![
                RestValue::Int(1),
                RestValue::Int(-1),
                RestValue::UInt(u64::MAX),
                RestValue::Text("x".into()),
                RestValue::Bool(true),
                RestValue::Null,
                RestValue::Unsupported,
                RestValue::Unsupported,
                RestValue::Null,
            ]
        );
    }

    #[test]
    fn odd_fields_have_their_documented_meaning() {
        let v = decode_values(
            br#"[{"id":5,"readSucceeded":"no","quality":-1,"timeStamp":"yesterday"},{"readSucceeded":false,"readStatusString":"Unknown variable","quality":70000}]"#,
        )
        .unwrap();
        assert_eq!(v[0].id, None);
        assert!(v[0].read_succeeded);
        assert_eq!((v[0].quality, v[0].time), (0, None));
        assert!(!v[1].read_succeeded);
        assert_eq!(v[1].status, "Unknown variable");
        assert_eq!(v[1].quality, 0);
    }

    #[test]
    fn bad_shapes_are_errors() {
        for bad in [
            &b""[..],
            b"{}",
            b"null",
            b"[1]",
            b"[[]]",
            b"[{\"id\":\"A\"}",
            b"[{\"id\":\"A\"}] x",
            b"\xff\xfe",
            b"[{\"value\":1e999}]",
        ] {
            assert!(
                decode_values(bad).is_err(),
                "{:?}",
                String::from_utf8_lossy(bad)
            );
        }
        // Deep nesting: skipped without recursion inside a value, refused around one.
        let deep = format!(
            "[{{\"value\":{}{}}}]",
            "[".repeat(100_000),
            "]".repeat(100_000)
        );
        assert_eq!(
            decode_values(deep.as_bytes()).unwrap()[0].value,
            RestValue::Unsupported
        );
        let deep = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
        assert!(decode_values(deep.as_bytes()).is_err());
        assert_eq!(decode_values(b" [ ] ").unwrap(), Vec::new());
    }
}
