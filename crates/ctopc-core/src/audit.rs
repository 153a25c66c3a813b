//! The write audit: one log line per written item, in a stable format decided here (the COM
//! layer only logs the line, through `tracing` with the target [`TARGET`], so that a
//! deployment can route or filter it; `[Server] AuditWrites` turns it off).
//!
//! A line is `key=value` pairs separated by one space, in a fixed order:
//!
//! ```text
//! write time=2026-12-02T03:49:19.123Z client="Excel" identity="user:PLANT\\op" method=IOPCSyncIO::Write group="G1" item="Zbiornik.Poziom" value=R8:12.5 result=S_OK
//! write time=... client="session 3" identity="unknown (RPC_E_CALL_COMPLETE)" method=IOPCAsyncIO3::WriteVQT group="G1" item="A" value=I4:7 quality=0x00C0 timestamp=2026-12-02T03:00:00.000Z cancel=12 result=denied
//! write-complete time=... client="Excel" group="G1" cancel=12 transaction=5 handle=1001 result=OPC_E_BADRIGHTS
//! ```
//!
//! - texts a client chose (client and group names, item IDs, string values) are quoted,
//!   with `"`, `\` and control characters escaped, so one write is always one line;
//! - a value is `<VT>:<value>`; arrays `<VT>[n]:[a, b, ...]`; a value longer than
//!   [`MAX_VALUE_CHARS`] characters is cut and ends in `...(+N chars)`;
//! - `quality` and `timestamp` appear only when the client gave them (IOPCSyncIO2 and
//!   IOPCAsyncIO3 WriteVQT, IOPCItemIO::WriteVQT, or the extended `[value, quality,
//!   timestamp]` array write, which is logged as the array the client wrote);
//! - `identity` is who the caller is as the front end could tell
//!   ([`crate::write_rights::Caller`]'s text: `user:DOMAIN\name`, `unknown (<reason>)`),
//!   beside the name the client chose for itself; absent when the front end says nothing;
//! - `result` is the per-item HRESULT's symbolic name (`S_OK`, `OPC_E_BADRIGHTS`, ...),
//!   or `denied` for an item the write-rights policy refused (the client got
//!   OPC_E_BADRIGHTS);
//!   for an asynchronous write it is the call-time result (`cancel=` names the
//!   transaction) and the final one follows in a `write-complete` line with the item's
//!   client handle, when OnWriteComplete is sent.

use crate::{OpcError, Quality, Timestamp, Value};
use std::fmt::Write as _;

/// The `tracing` target of audit lines.
pub const TARGET: &str = "audit";

/// Values are cut after this many characters of their rendering.
pub const MAX_VALUE_CHARS: usize = 256;

/// Who wrote: the name the client gave with IOPCCommon::SetClientName, else its session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Client<'a> {
    Named(&'a str),
    Session(u32),
}

/// One written item.
#[derive(Debug, Clone, Copy)]
pub struct WriteRecord<'a> {
    pub time: Timestamp,
    pub client: Client<'a>,
    /// Who the caller is ([`crate::write_rights::Caller`]'s text), if the front end said.
    pub identity: Option<&'a str>,
    /// The COM method, e.g. `IOPCSyncIO::Write`.
    pub method: &'a str,
    /// The group's name; `None` for IOPCItemIO (no group).
    pub group: Option<&'a str>,
    /// The item ID; `None` when the server handle was not valid.
    pub item_id: Option<&'a str>,
    /// The server handle the client gave (logged when there is no item ID).
    pub server_handle: Option<u32>,
    pub value: &'a Value,
    pub quality: Option<Quality>,
    pub timestamp: Option<Timestamp>,
    /// The server's cancel ID of an asynchronous write (0: none was queued).
    pub cancel_id: Option<u32>,
    pub result: Result<(), OpcError>,
    /// The write-rights policy refused the item (`result` is then OPC_E_BADRIGHTS).
    pub denied: bool,
}

/// One item of an OnWriteComplete.
#[derive(Debug, Clone, Copy)]
pub struct CompleteRecord<'a> {
    pub time: Timestamp,
    pub client: Client<'a>,
    pub group: Option<&'a str>,
    pub cancel_id: u32,
    pub transaction_id: u32,
    pub client_handle: u32,
    pub result: Result<(), OpcError>,
}

/// The symbolic name of a per-item result.
pub fn result_name(r: Result<(), OpcError>) -> &'static str {
    match r {
        Ok(()) => "S_OK",
        Err(e) => e.symbol(),
    }
}

/// `2026-12-02T03:49:19.123Z` (UTC).
pub fn iso_time(t: Timestamp) -> String {
    let c = t.civil();
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}Z",
        c.year, c.month, c.day, c.hour, c.minute, c.second, c.millis
    )
}

/// `text` quoted, with `"`, `\` and control characters escaped (at most `max` characters
/// of it; the rest counted).
fn quoted(out: &mut String, text: &str, max: usize) {
    out.push('"');
    for (n, ch) in text.chars().enumerate() {
        if n == max {
            let rest = text.chars().count() - n;
            let _ = write!(out, "...(+{rest} chars)");
            break;
        }
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{{{:x}}}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

fn vt_name(v: &Value) -> &'static str {
    match v {
        Value::Empty => "EMPTY",
        Value::I1(_) => "I1",
        Value::UI1(_) => "UI1",
        Value::I2(_) => "I2",
        Value::UI2(_) => "UI2",
        Value::I4(_) => "I4",
        Value::UI4(_) => "UI4",
        Value::I8(_) => "I8",
        Value::UI8(_) => "UI8",
        Value::R4(_) => "R4",
        Value::R8(_) => "R8",
        Value::Cy(_) => "CY",
        Value::Date(_) => "DATE",
        Value::Bstr(_) => "BSTR",
        Value::Bool(_) => "BOOL",
        Value::Error(_) => "ERROR",
        Value::Array(_) => "ARRAY",
    }
}

/// The value without its type, into `out`; stops once `out` is longer than `budget`.
fn scalar(out: &mut String, v: &Value, budget: usize) {
    match v {
        Value::Empty => out.push_str("(empty)"),
        Value::I1(x) => push(out, x),
        Value::UI1(x) => push(out, x),
        Value::I2(x) => push(out, x),
        Value::UI2(x) => push(out, x),
        Value::I4(x) => push(out, x),
        Value::UI4(x) => push(out, x),
        Value::I8(x) => push(out, x),
        Value::UI8(x) => push(out, x),
        Value::R4(x) => push(out, x),
        Value::R8(x) => push(out, x),
        Value::Cy(x) => {
            let sign = if *x < 0 { "-" } else { "" };
            let a = x.unsigned_abs();
            let _ = write!(out, "{sign}{}.{:04}", a / 10_000, a % 10_000);
        }
        Value::Date(x) => push(out, x),
        Value::Bstr(s) => quoted(out, s, budget),
        Value::Bool(b) => push(out, b),
        Value::Error(e) => {
            let _ = write!(out, "0x{:08X}", *e as u32);
        }
        Value::Array(a) => {
            out.push('[');
            for (i, e) in a.elements.iter().enumerate() {
                if out.len() > budget {
                    let _ = write!(out, "...(+{} elements)", a.elements.len() - i);
                    break;
                }
                if i > 0 {
                    out.push_str(", ");
                }
                if matches!(e, Value::Array(_)) || a.element_type == crate::VarType::VARIANT {
                    value(out, e, budget);
                } else {
                    scalar(out, e, budget);
                }
            }
            out.push(']');
        }
    }
}

fn push(out: &mut String, x: impl std::fmt::Display) {
    let _ = write!(out, "{x}");
}

/// `<VT>:<value>` (arrays `ARRAY<n>:[...]`), bounded by `budget` characters.
fn value(out: &mut String, v: &Value, budget: usize) {
    out.push_str(vt_name(v));
    if let Value::Array(a) = v {
        let _ = write!(out, "[{}]", a.elements.len());
    }
    out.push(':');
    scalar(out, v, budget);
}

/// The rendering of a written value, at most [`MAX_VALUE_CHARS`] characters plus the
/// marker of what was cut.
pub fn format_value(v: &Value) -> String {
    let mut s = String::new();
    value(&mut s, v, MAX_VALUE_CHARS);
    if s.chars().count() > MAX_VALUE_CHARS + 32 {
        let total = s.chars().count();
        let mut cut: String = s.chars().take(MAX_VALUE_CHARS).collect();
        let _ = write!(cut, "...(+{} chars)", total - MAX_VALUE_CHARS);
        return cut;
    }
    s
}

fn client(out: &mut String, c: Client<'_>) {
    out.push_str(" client=");
    match c {
        Client::Named(n) => quoted(out, n, MAX_VALUE_CHARS),
        Client::Session(s) => {
            let _ = write!(out, "\"session {s}\"");
        }
    }
}

/// The audit line of one written item (see the module doc for the format).
pub fn format_write(r: &WriteRecord<'_>) -> String {
    let mut out = String::with_capacity(160);
    out.push_str("write time=");
    out.push_str(&iso_time(r.time));
    client(&mut out, r.client);
    if let Some(id) = r.identity {
        out.push_str(" identity=");
        quoted(&mut out, id, MAX_VALUE_CHARS);
    }
    out.push_str(" method=");
    out.push_str(r.method);
    if let Some(g) = r.group {
        out.push_str(" group=");
        quoted(&mut out, g, MAX_VALUE_CHARS);
    }
    match (r.item_id, r.server_handle) {
        (Some(id), _) => {
            out.push_str(" item=");
            quoted(&mut out, id, MAX_VALUE_CHARS);
        }
        (None, Some(h)) => {
            let _ = write!(out, " handle={h}");
        }
        (None, None) => out.push_str(" item=?"),
    }
    out.push_str(" value=");
    out.push_str(&format_value(r.value));
    if let Some(q) = r.quality {
        let _ = write!(out, " quality=0x{:04X}", q.0);
    }
    if let Some(t) = r.timestamp {
        out.push_str(" timestamp=");
        out.push_str(&iso_time(t));
    }
    if let Some(c) = r.cancel_id {
        let _ = write!(out, " cancel={c}");
    }
    out.push_str(" result=");
    out.push_str(if r.denied {
        "denied"
    } else {
        result_name(r.result)
    });
    out
}

/// The audit line of one item of OnWriteComplete.
pub fn format_complete(r: &CompleteRecord<'_>) -> String {
    let mut out = String::with_capacity(120);
    out.push_str("write-complete time=");
    out.push_str(&iso_time(r.time));
    client(&mut out, r.client);
    if let Some(g) = r.group {
        out.push_str(" group=");
        quoted(&mut out, g, MAX_VALUE_CHARS);
    }
    let _ = write!(
        out,
        " cancel={} transaction={} handle={} result={}",
        r.cancel_id,
        r.transaction_id,
        r.client_handle,
        result_name(r.result)
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::ArrayValue;
    use crate::VarType;

    fn t0() -> Timestamp {
        // 2026-12-02T03:49:19.123Z
        Timestamp::from_unix_millis(1_796_183_359_123)
    }

    fn record<'a>(v: &'a Value) -> WriteRecord<'a> {
        WriteRecord {
            time: t0(),
            client: Client::Named("Excel"),
            identity: None,
            method: "IOPCSyncIO::Write",
            group: Some("G1"),
            item_id: Some("Zbiornik.Poziom"),
            server_handle: Some(3),
            value: v,
            quality: None,
            timestamp: None,
            cancel_id: None,
            result: Ok(()),
            denied: false,
        }
    }

    #[test]
    fn a_sync_write_is_one_stable_line() {
        let v = Value::R8(12.5);
        assert_eq!(
            format_write(&record(&v)),
            "write time=2026-12-02T03:49:19.123Z client=\"Excel\" method=IOPCSyncIO::Write \
             group=\"G1\" item=\"Zbiornik.Poziom\" value=R8:12.5 result=S_OK"
        );
    }

    #[test]
    fn quality_timestamp_cancel_and_errors_are_shown_when_given() {
        let v = Value::I4(7);
        let r = WriteRecord {
            client: Client::Session(3),
            method: "IOPCAsyncIO3::WriteVQT",
            quality: Some(Quality(0xC0)),
            timestamp: Some(Timestamp::from_unix_millis(0)),
            cancel_id: Some(12),
            result: Err(OpcError::BadRights),
            ..record(&v)
        };
        assert_eq!(
            format_write(&r),
            "write time=2026-12-02T03:49:19.123Z client=\"session 3\" \
             method=IOPCAsyncIO3::WriteVQT group=\"G1\" item=\"Zbiornik.Poziom\" value=I4:7 \
             quality=0x00C0 timestamp=1970-01-01T00:00:00.000Z cancel=12 result=OPC_E_BADRIGHTS"
        );
    }

    #[test]
    fn identity_stands_beside_the_client_and_a_policy_refusal_is_denied() {
        let v = Value::R8(1.0);
        let r = WriteRecord {
            identity: Some("user:PLANT\\op"),
            result: Err(OpcError::BadRights),
            denied: true,
            ..record(&v)
        };
        assert_eq!(
            format_write(&r),
            "write time=2026-12-02T03:49:19.123Z client=\"Excel\" identity=\"user:PLANT\\\\op\" \
             method=IOPCSyncIO::Write group=\"G1\" item=\"Zbiornik.Poziom\" value=R8:1 result=denied"
        );
        let r = WriteRecord {
            identity: Some("unknown (RPC_E_CALL_COMPLETE)"),
            ..record(&v)
        };
        let line = format_write(&r);
        assert!(
            line.contains(" identity=\"unknown (RPC_E_CALL_COMPLETE)\" method="),
            "{line}"
        );
        assert!(line.ends_with(" result=S_OK"), "{line}");
    }

    #[test]
    fn an_invalid_handle_is_logged_by_its_number_and_item_io_has_no_group() {
        let v = Value::Bool(true);
        let r = WriteRecord {
            item_id: None,
            server_handle: Some(99),
            group: None,
            result: Err(OpcError::InvalidHandle),
            ..record(&v)
        };
        let line = format_write(&r);
        assert!(line.contains(" handle=99 value=BOOL:true result=OPC_E_INVALIDHANDLE"));
        assert!(!line.contains("group="));
    }

    #[test]
    fn client_texts_cannot_break_the_line() {
        let v = Value::Bstr("a\"b\\c\nd".into());
        let r = WriteRecord {
            client: Client::Named("evil\nwrite time=x"),
            ..record(&v)
        };
        let line = format_write(&r);
        assert!(!line.contains('\n'));
        assert!(line.contains("client=\"evil\\nwrite time=x\""));
        assert!(line.contains("value=BSTR:\"a\\\"b\\\\c\\nd\""));
    }

    #[test]
    fn the_extended_write_shows_its_array_and_long_values_are_cut() {
        let ext = Value::Array(ArrayValue::new(
            VarType::VARIANT,
            vec![Value::R8(1.5), Value::I4(192), Value::Date(46000.5)],
        ));
        assert_eq!(
            format_value(&ext),
            "ARRAY[3]:[R8:1.5, I4:192, DATE:46000.5]"
        );
        let big = Value::Array(ArrayValue::new(
            VarType::I4,
            (0..100_000).map(Value::I4).collect(),
        ));
        let s = format_value(&big);
        assert!(s.len() < MAX_VALUE_CHARS + 64, "{}", s.len());
        assert!(s.starts_with("ARRAY[100000]:[0, 1, 2"));
        assert!(s.contains("...(+"));
        let long = Value::Bstr("x".repeat(10_000));
        let s = format_value(&long);
        assert!(s.ends_with("...(+9744 chars)\""), "{s}");
        assert_eq!(format_value(&Value::Cy(-12_345)), "CY:-1.2345");
        assert_eq!(format_value(&Value::Cy(-5_000)), "CY:-0.5000");
    }

    #[test]
    fn write_complete_names_the_transaction_and_handle() {
        let r = CompleteRecord {
            time: t0(),
            client: Client::Named("HMI"),
            group: Some("G"),
            cancel_id: 4,
            transaction_id: 77,
            client_handle: 1001,
            result: Err(OpcError::BadRights),
        };
        assert_eq!(
            format_complete(&r),
            "write-complete time=2026-12-02T03:49:19.123Z client=\"HMI\" group=\"G\" cancel=4 \
             transaction=77 handle=1001 result=OPC_E_BADRIGHTS"
        );
    }
}
