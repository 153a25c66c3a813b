//! How opcdiag shows OPC data: values, data types, qualities, timestamps, server states,
//! HRESULTs and the browse tree (pure, tested natively).
// Natively only the tests use what the Windows commands show.
#![cfg_attr(not(windows), allow(dead_code))]

use ctopc_core::convert::Locale;
use ctopc_core::{OpcError, Quality, Timestamp, Value, VarType};

/// The name of a VARTYPE: "R4", "BSTR", "R4[]" for arrays, "VT 77" for others.
pub fn vartype_name(vt: u16) -> String {
    let t = VarType(vt);
    let base = match t.element() {
        VarType::EMPTY => "EMPTY",
        VarType::I1 => "I1",
        VarType::UI1 => "UI1",
        VarType::I2 => "I2",
        VarType::UI2 => "UI2",
        VarType::I4 => "I4",
        VarType::UI4 => "UI4",
        VarType::I8 => "I8",
        VarType::UI8 => "UI8",
        VarType::R4 => "R4",
        VarType::R8 => "R8",
        VarType::CY => "CY",
        VarType::DATE => "DATE",
        VarType::BSTR => "BSTR",
        VarType::BOOL => "BOOL",
        VarType::ERROR => "ERROR",
        VarType::VARIANT => "VARIANT",
        other => return format!("VT {}", other.0 | (vt & VarType::ARRAY_FLAG)),
    };
    if t.is_array() {
        format!("{base}[]")
    } else {
        base.to_string()
    }
}

/// A value as a person reads it: numbers as Rust prints them (shortest exact form: 12.5,
/// 4.27), BSTR in quotes, BOOL true/false, CY with its decimals, DATE as
/// `yyyy-mm-dd hh:mm:ss` (an OLE date carries no time zone), arrays in brackets.
pub fn value_text(v: &Value) -> String {
    match v {
        Value::Empty => "(empty)".into(),
        Value::I1(x) => x.to_string(),
        Value::UI1(x) => x.to_string(),
        Value::I2(x) => x.to_string(),
        Value::UI2(x) => x.to_string(),
        Value::I4(x) => x.to_string(),
        Value::UI4(x) => x.to_string(),
        Value::I8(x) => x.to_string(),
        Value::UI8(x) => x.to_string(),
        Value::R4(x) => x.to_string(),
        Value::R8(x) => x.to_string(),
        Value::Cy(x) => cy_text(*x),
        Value::Date(d) => match Timestamp::from_ole_date(*d) {
            Some(t) => {
                let (date, time) = civil(t, 0);
                format!("{date} {}", &time[..8])
            }
            None => format!("(date {d})"),
        },
        Value::Bstr(s) => format!("{s:?}"),
        Value::Bool(b) => b.to_string(),
        Value::Error(e) => format!("error 0x{:08X}", *e as u32),
        Value::Array(a) => {
            let items: Vec<String> = a.elements.iter().map(value_text).collect();
            format!("[{}]", items.join(", "))
        }
    }
}

/// As [`value_text`], with R4 and R8 rounded to `decimals` places (for live displays).
pub fn value_rounded(v: &Value, decimals: usize) -> String {
    let x = match v {
        Value::R4(x) => f64::from(*x),
        Value::R8(x) => *x,
        other => return value_text(other),
    };
    let s = format!("{x:.decimals$}");
    // No "-0.00": a value that rounds to zero shows as zero.
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

fn cy_text(units: i64) -> String {
    let sign = if units < 0 { "-" } else { "" };
    let abs = units.unsigned_abs();
    let frac = format!("{:04}", abs % 10_000);
    let frac = frac.trim_end_matches('0');
    if frac.is_empty() {
        format!("{sign}{}", abs / 10_000)
    } else {
        format!("{sign}{}.{frac}", abs / 10_000)
    }
}

/// The value to write: `text` converted to `vt` as en-US text (VariantChangeType rules: a
/// '.' decimal point, true/false or a number for BOOL); BSTR keeps the text as is.
pub fn parse_value(text: &str, vt: VarType) -> Result<Value, String> {
    let s = Value::Bstr(text.to_string());
    if vt == VarType::BSTR || vt == VarType::EMPTY || vt == VarType::VARIANT {
        return Ok(s);
    }
    s.convert_in(vt, Locale::EnUs).map_err(|e| {
        let why = match e {
            OpcError::Overflow => "out of range",
            _ => "not a valid value",
        };
        format!("{text:?} is {why} for {}", vartype_name(vt.0))
    })
}

/// The quality as text: "GOOD", "BAD Comm Failure [Low limit]", "UNCERTAIN EU Units
/// Exceeded [High limit] +SecondLimit"; the bits in hex unless it is plain GOOD.
pub fn quality_text(q: u16) -> String {
    if q == Quality::GOOD.0 {
        "GOOD".into()
    } else {
        format!("{} (0x{q:04X})", Quality(q))
    }
}

/// The name of an OPCSERVERSTATE.
pub fn state_name(state: u32) -> String {
    match state {
        1 => "RUNNING".into(),
        2 => "FAILED".into(),
        3 => "NOCONFIG".into(),
        4 => "SUSPENDED".into(),
        5 => "TEST".into(),
        6 => "COMM_FAULT".into(),
        n => format!("unknown ({n})"),
    }
}

/// What a state means, for `status`.
pub fn state_meaning(state: u32) -> &'static str {
    match state {
        1 => "running normally",
        2 => "a vendor-specific fatal error",
        3 => "running without configuration (variable database missing or broken)",
        4 => "suspended",
        5 => "test mode: simulated data",
        6 => "running, but no communication with the data source",
        _ => "not defined by OPC DA",
    }
}

/// ("yyyy-mm-dd", "hh:mm:ss.mmm") of `t` shifted by `offset_min` minutes.
fn civil(t: Timestamp, offset_min: i32) -> (String, String) {
    let shifted = Timestamp(t.0.saturating_add(i64::from(offset_min) * 60 * 10_000_000));
    let c = shifted.civil();
    (
        format!("{:04}-{:02}-{:02}", c.year, c.month, c.day),
        format!(
            "{:02}:{:02}:{:02}.{:03}",
            c.hour, c.minute, c.second, c.millis
        ),
    )
}

/// `t` in local time as ISO 8601 with milliseconds and the offset:
/// "2026-01-05T13:04:05.120+01:00"; "(none)" for a zero timestamp.
pub fn local_iso(t: Timestamp, offset_min: i32) -> String {
    if t.0 == 0 {
        return "(none)".into();
    }
    let (date, time) = civil(t, offset_min);
    let sign = if offset_min < 0 { '-' } else { '+' };
    let off = offset_min.unsigned_abs();
    format!("{date}T{time}{sign}{:02}:{:02}", off / 60, off % 60)
}

/// The local time of day of `t`: "13:04:05.120".
pub fn local_time_of_day(t: Timestamp, offset_min: i32) -> String {
    civil(t, offset_min).1
}

/// The symbolic name of a well-known HRESULT (OPC, OPC Common, COM, ASKOM), if any.
pub fn hresult_symbol(hr: i32) -> Option<&'static str> {
    if let Some(e) = OpcError::from_hresult(hr) {
        return Some(e.symbol());
    }
    Some(match hr as u32 {
        0x0000_0000 => "S_OK",
        0x8000_4002 => "E_NOINTERFACE",
        0x8000_FFFF => "E_UNEXPECTED",
        0x8007_0005 => "E_ACCESSDENIED",
        0x8004_0154 => "REGDB_E_CLASSNOTREG",
        0x8008_0005 => "CO_E_SERVER_EXEC_FAILURE",
        0x8004_01F3 => "CO_E_CLASSSTRING",
        0x8007_06BA => "RPC_S_SERVER_UNAVAILABLE",
        0x8001_0108 => "RPC_E_DISCONNECTED",
        0x8002_0005 => "DISP_E_TYPEMISMATCH",
        0x8002_000A => "DISP_E_OVERFLOW",
        _ => return None,
    })
}

/// An HRESULT for people: "0xC0040007 OPC_E_UNKNOWNITEMID: The item ID is not defined
/// ..." with the server's text, else the system's, else none.
pub fn hresult_text(hr: i32, text: Option<&str>) -> String {
    let mut s = format!("0x{:08X}", hr as u32);
    if let Some(sym) = hresult_symbol(hr) {
        s.push(' ');
        s.push_str(sym);
    }
    if let Some(t) = text.map(str::trim).filter(|t| !t.is_empty()) {
        s.push_str(": ");
        s.push_str(t);
    }
    s
}

/// One node of a browsed tree.
#[derive(Debug, Clone, PartialEq)]
pub struct TreeLine {
    pub depth: usize,
    pub name: String,
    /// The item ID, for leaves whose ID differs from the name.
    pub item_id: Option<String>,
    pub branch: bool,
}

/// The tree as indented lines: two spaces per level, branches end with '/', a leaf's item
/// ID after '=' when it differs from its name.
pub fn render_tree(lines: &[TreeLine]) -> String {
    let mut out = String::new();
    for l in lines {
        out.push_str(&"  ".repeat(l.depth));
        out.push_str(&l.name);
        if l.branch {
            out.push('/');
        }
        if let Some(id) = l.item_id.as_deref().filter(|id| *id != l.name) {
            out.push_str("  = ");
            out.push_str(id);
        }
        out.push('\n');
    }
    out
}

/// Splits `--branch` into names to walk down (separators '/' and '\'; empty parts dropped).
pub fn branch_steps(path: &str) -> Vec<String> {
    path.split(['/', '\\'])
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(String::from)
        .collect()
}

/// The access rights (OPC_READABLE 1, OPC_WRITEABLE 2) as text.
pub fn rights_text(rights: u32) -> String {
    match rights & 3 {
        1 => "read".into(),
        2 => "write".into(),
        3 => "read/write".into(),
        _ => format!("none (0x{rights:X})"),
    }
}

/// A property value for `props`: data type codes by name, qualities and rights as text.
pub fn property_value_text(id: u32, v: &Value) -> String {
    match (id, v) {
        (1, Value::I2(t)) => format!("{} ({t})", vartype_name(*t as u16)),
        (3, Value::I2(q)) => quality_text(*q as u16),
        (3, Value::UI2(q)) => quality_text(*q),
        (5, Value::I4(r)) => rights_text(*r as u32),
        (5, Value::UI4(r)) => rights_text(*r),
        _ => value_text(v),
    }
}

/// Pads `s` on the right to `width` characters (not bytes: Polish letters count as one).
pub fn pad(s: &str, width: usize) -> String {
    let n = s.chars().count();
    if n >= width {
        s.to_string()
    } else {
        format!("{s}{}", " ".repeat(width - n))
    }
}

/// One server of `opcdiag servers`.
#[derive(Debug, Clone, PartialEq)]
pub struct ServerRow {
    pub progid: String,
    /// The DA versions implemented, e.g. `["2.0", "3.0"]`.
    pub versions: Vec<&'static str>,
    pub description: String,
    /// `{...}`, as the registry spells it.
    pub clsid: String,
}

/// The table of `opcdiag servers`: a header, then one line per server (ProgID, DA
/// versions, description, CLSID), columns padded.
pub fn servers_table(rows: &[ServerRow]) -> String {
    let versions: Vec<String> = rows.iter().map(|r| r.versions.join(", ")).collect();
    let w_progid = rows
        .iter()
        .map(|r| r.progid.chars().count())
        .chain([6])
        .max()
        .unwrap_or(6);
    let w_da = versions
        .iter()
        .map(|v| v.chars().count())
        .chain([2])
        .max()
        .unwrap_or(2);
    let w_desc = rows
        .iter()
        .map(|r| r.description.chars().count())
        .chain([11])
        .max()
        .unwrap_or(11);
    let line = |a: &str, b: &str, c: &str, d: &str| {
        format!(
            "{}  {}  {}  {d}\n",
            pad(a, w_progid),
            pad(b, w_da),
            pad(c, w_desc)
        )
    };
    let mut out = line("ProgID", "DA", "Description", "CLSID");
    for (r, v) in rows.iter().zip(&versions) {
        out.push_str(&line(&r.progid, v, &r.description, &r.clsid));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ctopc_core::value::ArrayValue;

    #[test]
    fn values_read_as_people_write_them() {
        assert_eq!(value_text(&Value::R4(12.5)), "12.5");
        assert_eq!(value_text(&Value::R4(4.27)), "4.27");
        assert_eq!(value_text(&Value::R8(0.1 + 0.2)), "0.30000000000000004");
        assert_eq!(value_text(&Value::I2(-3)), "-3");
        assert_eq!(value_text(&Value::UI4(4_000_000_000)), "4000000000");
        assert_eq!(value_text(&Value::Bool(true)), "true");
        assert_eq!(
            value_text(&Value::Bstr("Zbiornik \"Z101\"".into())),
            "\"Zbiornik \\\"Z101\\\"\""
        );
        assert_eq!(value_text(&Value::Empty), "(empty)");
        assert_eq!(value_text(&Value::Cy(12_500)), "1.25");
        assert_eq!(value_text(&Value::Cy(-20_000)), "-2");
        assert_eq!(
            value_text(&Value::Error(0xC004_0007u32 as i32)),
            "error 0xC0040007"
        );
        // 2026-01-05 13:04:05 as an OLE date.
        let t = Timestamp::from_unix_millis(1_767_618_245_000);
        assert_eq!(value_text(&Value::date_from(t)), "2026-01-05 13:04:05");
        let a = Value::Array(ArrayValue::new(
            VarType::I2,
            vec![Value::I2(1), Value::I2(2)],
        ));
        assert_eq!(value_text(&a), "[1, 2]");
        assert_eq!(value_rounded(&Value::R4(5.396_091_5), 2), "5.40");
        assert_eq!(value_rounded(&Value::R8(-0.004), 2), "0.00");
        assert_eq!(value_rounded(&Value::R8(-1.005), 1), "-1.0");
        assert_eq!(value_rounded(&Value::I2(1), 2), "1");
    }

    #[test]
    fn vartype_names_include_arrays_and_unknown_codes() {
        assert_eq!(vartype_name(4), "R4");
        assert_eq!(vartype_name(8), "BSTR");
        assert_eq!(vartype_name(0x2002), "I2[]");
        assert_eq!(vartype_name(0x200C), "VARIANT[]");
        assert_eq!(vartype_name(77), "VT 77");
    }

    #[test]
    fn values_to_write_convert_as_en_us_text() {
        assert_eq!(parse_value("12.5", VarType::R4), Ok(Value::R4(12.5)));
        assert_eq!(parse_value("-7", VarType::I2), Ok(Value::I2(-7)));
        assert_eq!(parse_value("true", VarType::BOOL), Ok(Value::Bool(true)));
        assert_eq!(parse_value("0", VarType::BOOL), Ok(Value::Bool(false)));
        assert_eq!(
            parse_value("12,5", VarType::BSTR),
            Ok(Value::Bstr("12,5".into()))
        );
        assert_eq!(
            parse_value("x", VarType::EMPTY),
            Ok(Value::Bstr("x".into()))
        );
        assert_eq!(
            parse_value("300", VarType::UI1),
            Err("\"300\" is out of range for UI1".into())
        );
        assert_eq!(
            parse_value("abc", VarType::R8),
            Err("\"abc\" is not a valid value for R8".into())
        );
    }

    #[test]
    fn qualities_as_text() {
        assert_eq!(quality_text(0xC0), "GOOD");
        assert_eq!(quality_text(0x19), "BAD Comm Failure [Low limit] (0x0019)");
        assert_eq!(quality_text(0x20), "BAD Waiting for Initial Data (0x0020)");
        assert_eq!(
            quality_text(0x08C2),
            "GOOD [High limit] +SecondLimit (0x08C2)"
        );
        assert_eq!(
            quality_text(0x56),
            "UNCERTAIN EU Units Exceeded [High limit] (0x0056)"
        );
    }

    #[test]
    fn timestamps_in_local_time() {
        let t = Timestamp::from_unix_millis(1_767_618_245_120); // 2026-01-05T13:04:05.120Z
        assert_eq!(local_iso(t, 0), "2026-01-05T13:04:05.120+00:00");
        assert_eq!(local_iso(t, 60), "2026-01-05T14:04:05.120+01:00");
        assert_eq!(local_iso(t, -330), "2026-01-05T07:34:05.120-05:30");
        assert_eq!(local_iso(t, 11 * 60), "2026-01-06T00:04:05.120+11:00");
        assert_eq!(local_time_of_day(t, 120), "15:04:05.120");
        assert_eq!(local_iso(Timestamp(0), 60), "(none)");
        // Leap day and the turn of a century.
        assert_eq!(
            local_iso(Timestamp::from_unix_millis(951_782_400_000), 0),
            "2000-02-29T00:00:00.000+00:00"
        );
        assert_eq!(
            local_iso(Timestamp::from_unix_millis(-1), 0),
            "1969-12-31T23:59:59.999+00:00"
        );
    }

    #[test]
    fn hresults_with_symbol_and_text() {
        assert_eq!(
            hresult_text(0xC004_0007u32 as i32, Some("The item ID is not defined.")),
            "0xC0040007 OPC_E_UNKNOWNITEMID: The item ID is not defined."
        );
        assert_eq!(
            hresult_text(0x8004_01F3u32 as i32, Some("Invalid class string\r\n")),
            "0x800401F3 CO_E_CLASSSTRING: Invalid class string"
        );
        assert_eq!(hresult_text(0x8123_4567u32 as i32, None), "0x81234567");
        assert_eq!(
            hresult_text(0x8123_4567u32 as i32, Some("  ")),
            "0x81234567"
        );
        assert_eq!(
            hresult_symbol(0xC004_0006u32 as i32),
            Some("OPC_E_BADRIGHTS")
        );
        assert_eq!(hresult_symbol(0), Some("S_OK"));
    }

    #[test]
    fn server_states() {
        assert_eq!(state_name(5), "TEST");
        assert_eq!(state_name(1), "RUNNING");
        assert_eq!(state_name(6), "COMM_FAULT");
        assert_eq!(state_name(9), "unknown (9)");
        assert!(state_meaning(3).contains("without configuration"));
    }

    #[test]
    fn the_tree_is_indented_with_branches_marked() {
        let lines = vec![
            TreeLine {
                depth: 0,
                name: "Magazyn siarki".into(),
                item_id: None,
                branch: true,
            },
            TreeLine {
                depth: 1,
                name: "Zbiornik Z101".into(),
                item_id: None,
                branch: true,
            },
            TreeLine {
                depth: 2,
                name: "KW_A000".into(),
                item_id: Some("KW_A000".into()),
                branch: false,
            },
            TreeLine {
                depth: 2,
                name: "LI101".into(),
                item_id: Some("asmen.X.KW_A000".into()),
                branch: false,
            },
        ];
        assert_eq!(
            render_tree(&lines),
            "Magazyn siarki/\n  Zbiornik Z101/\n    KW_A000\n    LI101  = asmen.X.KW_A000\n"
        );
        assert_eq!(
            branch_steps("/Magazyn siarki/ Zbiornik Z101 /"),
            vec!["Magazyn siarki", "Zbiornik Z101"]
        );
        assert_eq!(branch_steps("A\\B"), vec!["A", "B"]);
    }

    #[test]
    fn properties_show_types_qualities_and_rights_by_name() {
        assert_eq!(property_value_text(1, &Value::I2(4)), "R4 (4)");
        assert_eq!(property_value_text(3, &Value::I2(0xC0)), "GOOD");
        assert_eq!(property_value_text(5, &Value::I4(3)), "read/write");
        assert_eq!(property_value_text(5, &Value::I4(1)), "read");
        assert_eq!(property_value_text(100, &Value::Bstr("m".into())), "\"m\"");
        assert_eq!(rights_text(0), "none (0x0)");
    }

    #[test]
    fn padding_counts_characters() {
        assert_eq!(pad("łąka", 6), "łąka  ");
        assert_eq!(pad("toolong", 3), "toolong");
    }

    #[test]
    fn the_servers_table_lines_up() {
        let rows = [
            ServerRow {
                progid: "ServerCTOPC.App.1".into(),
                versions: vec!["2.0", "3.0"],
                description: "ServerCTOPC OPC DA Server for asix".into(),
                clsid: "{3277B556-BA68-4BDE-8687-8EE4E4B46336}".into(),
            },
            ServerRow {
                progid: "Old.1".into(),
                versions: vec!["1.0"],
                description: "Stara stacja".into(),
                clsid: "{00000000-0000-0000-0000-000000000001}".into(),
            },
        ];
        let t = servers_table(&rows);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 3);
        assert!(lines[0].starts_with("ProgID             DA        Description"));
        assert!(lines[1].starts_with(
            "ServerCTOPC.App.1  2.0, 3.0  ServerCTOPC OPC DA Server for asix  {3277B556"
        ));
        assert!(lines[2].starts_with("Old.1              1.0       Stara stacja "));
        let clsid_col = lines[0].find("CLSID").unwrap();
        assert_eq!(lines[2].find('{'), Some(clsid_col));
        assert_eq!(servers_table(&[]), "ProgID  DA  Description  CLSID\n");
    }
}
