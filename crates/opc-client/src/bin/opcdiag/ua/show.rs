//! How `opcdiag --url` reads its arguments and shows OPC UA data (pure, tested natively):
//! NodeIds or DA item IDs, StatusCodes, values and their types, timestamps, and the value
//! to write (the DA commands' en-US conversion, `text::parse_value`).

use crate::text;
use ctopc_core::{Timestamp, Value, VarType};
use opcua::types::{DataTypeId, DateTime, NodeId, StatusCode, Variant};
use std::str::FromStr;

/// ServerCTOPC's namespace: its NodeIds are `ns=<this namespace's index>;s=<DA item ID>`.
pub const NAMESPACE_URI: &str = "urn:askom:ServerCTOPC";

/// A node as the command line names it.
#[derive(Debug, Clone, PartialEq)]
pub enum NodeArg {
    /// A full NodeId (`ns=2;s=KW_A000`, `i=85`, `s=...`, `g=...`, `b=...`).
    Id(NodeId),
    /// A DA item ID: `ns=<NAMESPACE_URI's index>;s=<item>`.
    Item(String),
}

/// What `arg` names: a NodeId when it is written as one, else a DA item ID.
pub fn node_arg(arg: &str) -> NodeArg {
    let looks_like_id =
        arg.starts_with("ns=") || ["i=", "s=", "g=", "b="].iter().any(|p| arg.starts_with(p));
    match NodeId::from_str(arg) {
        Ok(id) if looks_like_id => NodeArg::Id(id),
        _ => NodeArg::Item(arg.to_string()),
    }
}

/// How a node is shown: its DA item ID when it is one of ServerCTOPC's (`ns` = the index
/// of [`NAMESPACE_URI`]), else the NodeId.
pub fn node_label(id: &NodeId, ns: Option<u16>) -> String {
    match (&id.identifier, ns) {
        (opcua::types::Identifier::String(s), Some(ns)) if id.namespace == ns => s.to_string(),
        _ => id.to_string(),
    }
}

/// A StatusCode for people: "Good", "BadNodeIdUnknown (0x80340000)", with the limit and
/// other bits its name carries ("Good, Low").
pub fn status_text(s: StatusCode) -> String {
    if s.bits() == 0 {
        "Good".into()
    } else {
        format!("{s} (0x{:08X})", s.bits())
    }
}

/// An error StatusCode with its meaning: "BadUserAccessDenied (0x801F0000): User does not
/// have permission to perform the requested operation."
pub fn status_error(s: StatusCode) -> String {
    let meaning = s.sub_code().description();
    if meaning.is_empty() {
        status_text(s)
    } else {
        format!("{}: {meaning}", status_text(s))
    }
}

/// What to do about an error StatusCode of a write or read, where opcdiag knows.
pub fn status_hint(s: StatusCode) -> Option<&'static str> {
    Some(match s.sub_code() {
        opcua::types::SubStatusCode::BadUserAccessDenied => {
            "the user's role does not allow writing this variable (ServerCTOPC: role writer)"
        }
        opcua::types::SubStatusCode::BadNotWritable => "the variable is read-only",
        opcua::types::SubStatusCode::BadNodeIdUnknown => {
            "no such node: check the item ID or NodeId (opcdiag --url ... browse)"
        }
        opcua::types::SubStatusCode::BadTypeMismatch => {
            "the value's type does not fit the variable: try --type"
        }
        opcua::types::SubStatusCode::BadOutOfRange => "the value is outside the variable's range",
        _ => return None,
    })
}

/// The UA DateTime as a [`Timestamp`] (both count 100 ns since 1601-01-01 UTC); a null
/// DateTime is the zero timestamp (shown as "(none)").
pub fn timestamp(t: Option<&DateTime>) -> Timestamp {
    Timestamp(t.map_or(0, DateTime::checked_ticks))
}

/// An ISO 8601 time in UTC with milliseconds: "2026-01-05T12:04:05.120+00:00", "(none)".
pub fn time_text(t: Option<&DateTime>) -> String {
    text::local_iso(timestamp(t), 0)
}

/// The value as the DA commands show values: numbers as Rust prints them, strings in
/// quotes, arrays in brackets; other UA types as async-opcua prints them.
pub fn value_text(v: &Variant) -> String {
    match v {
        Variant::Array(a) => {
            let items: Vec<String> = a.values.iter().map(value_text).collect();
            format!("[{}]", items.join(", "))
        }
        Variant::String(s) => format!("{:?}", s.as_ref()),
        Variant::DateTime(d) => time_text(Some(d)),
        Variant::StatusCode(s) => status_text(*s),
        v => match da_value(v) {
            Some(value) => text::value_text(&value),
            None => v.to_string(),
        },
    }
}

/// The scalar as a DA value, where there is one.
fn da_value(v: &Variant) -> Option<Value> {
    Some(match v {
        Variant::Empty => Value::Empty,
        Variant::Boolean(b) => Value::Bool(*b),
        Variant::SByte(x) => Value::I1(*x),
        Variant::Byte(x) => Value::UI1(*x),
        Variant::Int16(x) => Value::I2(*x),
        Variant::UInt16(x) => Value::UI2(*x),
        Variant::Int32(x) => Value::I4(*x),
        Variant::UInt32(x) => Value::UI4(*x),
        Variant::Int64(x) => Value::I8(*x),
        Variant::UInt64(x) => Value::UI8(*x),
        Variant::Float(x) => Value::R4(*x),
        Variant::Double(x) => Value::R8(*x),
        _ => return None,
    })
}

/// The value's UA type: "Float", "String", "Double[]", "(empty)".
pub fn type_text(v: &Variant) -> String {
    match v {
        Variant::Empty => "(empty)".into(),
        Variant::Array(a) => format!("{:?}[]", a.value_type),
        v => match v.scalar_type_id() {
            Some(t) => format!("{t:?}"),
            None => "?".into(),
        },
    }
}

/// The DA type that stands for a variable's UA DataType when its value is written (the
/// same en-US conversion as the DA `write`); `None` for a type opcdiag cannot write.
pub fn vartype_of(data_type: &NodeId) -> Option<VarType> {
    let id = match &data_type.identifier {
        opcua::types::Identifier::Numeric(n) if data_type.namespace == 0 => {
            DataTypeId::try_from(*n).ok()?
        }
        _ => return None,
    };
    Some(match id {
        DataTypeId::Boolean => VarType::BOOL,
        DataTypeId::SByte => VarType::I1,
        DataTypeId::Byte => VarType::UI1,
        DataTypeId::Int16 => VarType::I2,
        DataTypeId::UInt16 => VarType::UI2,
        DataTypeId::Int32 => VarType::I4,
        DataTypeId::UInt32 => VarType::UI4,
        DataTypeId::Int64 => VarType::I8,
        DataTypeId::UInt64 => VarType::UI8,
        DataTypeId::Float => VarType::R4,
        DataTypeId::Double => VarType::R8,
        DataTypeId::String => VarType::BSTR,
        DataTypeId::DateTime => VarType::DATE,
        _ => return None,
    })
}

/// `text` converted to `vt` (en-US text, as the DA `write`) as the UA value to write.
pub fn parse_value(text: &str, vt: VarType) -> Result<Variant, String> {
    Ok(match text::parse_value(text, vt)? {
        Value::Bool(b) => Variant::Boolean(b),
        Value::I1(x) => Variant::SByte(x),
        Value::UI1(x) => Variant::Byte(x),
        Value::I2(x) => Variant::Int16(x),
        Value::UI2(x) => Variant::UInt16(x),
        Value::I4(x) => Variant::Int32(x),
        Value::UI4(x) => Variant::UInt32(x),
        Value::I8(x) => Variant::Int64(x),
        Value::UI8(x) => Variant::UInt64(x),
        Value::R4(x) => Variant::Float(x),
        Value::R8(x) => Variant::Double(x),
        Value::Bstr(s) => Variant::from(s),
        Value::Date(d) => match Timestamp::from_ole_date(d) {
            Some(t) => Variant::from(DateTime::from(t.0)),
            None => return Err(format!("{text:?} is not a valid date")),
        },
        other => {
            return Err(format!(
                "{text:?}: a {} cannot be written over OPC UA",
                text::vartype_name(other.var_type().0)
            ))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_ids_and_item_ids() {
        assert_eq!(
            node_arg("ns=2;s=KW_A000"),
            NodeArg::Id(NodeId::new(2, "KW_A000"))
        );
        assert_eq!(node_arg("i=85"), NodeArg::Id(NodeId::new(0, 85u32)));
        assert_eq!(node_arg("KW_A000"), NodeArg::Item("KW_A000".into()));
        // An item ID with dots, colons or '=' later on stays an item ID.
        assert_eq!(node_arg("KW_A000.CV"), NodeArg::Item("KW_A000.CV".into()));
        assert_eq!(node_arg("a=b"), NodeArg::Item("a=b".into()));
        assert_eq!(node_arg("ns=x;s=y"), NodeArg::Item("ns=x;s=y".into()));
        assert_eq!(node_label(&NodeId::new(2, "KW_A000"), Some(2)), "KW_A000");
        assert_eq!(
            node_label(&NodeId::new(3, "KW_A000"), Some(2)),
            "ns=3;s=KW_A000"
        );
        assert_eq!(node_label(&NodeId::new(0, 85u32), Some(2)), "i=85");
    }

    #[test]
    fn status_codes_by_name_and_hex_with_their_meaning() {
        assert_eq!(status_text(StatusCode::Good), "Good");
        assert_eq!(
            status_text(StatusCode::BadNodeIdUnknown),
            "BadNodeIdUnknown (0x80340000)"
        );
        let denied = status_error(StatusCode::BadUserAccessDenied);
        assert!(
            denied.starts_with("BadUserAccessDenied (0x801F0000): "),
            "{denied}"
        );
        assert!(status_hint(StatusCode::BadUserAccessDenied).is_some_and(|h| h.contains("role")));
        assert_eq!(status_hint(StatusCode::BadTimeout), None);
    }

    #[test]
    fn values_and_types_as_the_da_commands_show_them() {
        assert_eq!(value_text(&Variant::Float(12.5)), "12.5");
        assert_eq!(type_text(&Variant::Float(12.5)), "Float");
        assert_eq!(value_text(&Variant::Boolean(true)), "true");
        assert_eq!(value_text(&Variant::from("Z101")), "\"Z101\"");
        assert_eq!(type_text(&Variant::from("Z101")), "String");
        assert_eq!(value_text(&Variant::Empty), "(empty)");
        let a = Variant::from(vec![1.5f64, 2.0]);
        assert_eq!(value_text(&a), "[1.5, 2]");
        assert_eq!(type_text(&a), "Double[]");
    }

    #[test]
    fn timestamps_are_utc_iso_8601() {
        let t = DateTime::from(Timestamp::from_unix_millis(1_767_614_645_120).0);
        assert_eq!(time_text(Some(&t)), "2026-01-05T12:04:05.120+00:00");
        assert_eq!(time_text(None), "(none)");
        assert_eq!(time_text(Some(&DateTime::null())), "(none)");
    }

    #[test]
    fn values_to_write_follow_the_variables_data_type() {
        let float = NodeId::from(DataTypeId::Float);
        let vt = vartype_of(&float).unwrap();
        assert_eq!(parse_value("12.5", vt), Ok(Variant::Float(12.5)));
        assert!(parse_value("x", vt).is_err());
        let b = vartype_of(&NodeId::from(DataTypeId::Boolean)).unwrap();
        assert_eq!(parse_value("true", b), Ok(Variant::Boolean(true)));
        let i = vartype_of(&NodeId::from(DataTypeId::Int16)).unwrap();
        assert_eq!(parse_value("-3", i), Ok(Variant::Int16(-3)));
        assert!(parse_value("70000", i)
            .unwrap_err()
            .contains("out of range"));
        let s = vartype_of(&NodeId::from(DataTypeId::String)).unwrap();
        assert_eq!(parse_value("a b", s), Ok(Variant::from("a b")));
        assert_eq!(vartype_of(&NodeId::from(DataTypeId::LocalizedText)), None);
    }
}
