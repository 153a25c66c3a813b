//! Item identifiers of current data (manual §6.1-6.2), parsed into a typed [`ItemId`];
//! [`ItemKey`], the asix variable (channel and name) behind them.
//!
//! ```text
//! asmen.<channel>.<var>.<R4|I2|UI2|I4|UI4|UI1>   descriptive (no database needed)
//! <V> | <V>.CV                                    current value
//! <V>.DATA_TYPE | .EU_UNIT | .DESC | .HI_EU | .LO_EU
//! <V>.FormatedCV | .PercentageCV | .BarCVs
//! <V>.<A>                                         attribute value
//! <V>.<A>.CV                                      numeric attribute, or the current value
//!                                                 of the variable the attribute names
//! <V>.<A>.CV.<S>                                  S: FormatedCV, PercentageCV, BarCV(s),
//!                                                 or any one-segment suffix above
//!                                                 (CV, DESC, ..., <A2>)
//! ```
//!
//! Rules:
//! - Variable names, channel names and attribute names are case-sensitive, and so are
//!   the keywords `CV`, `DATA_TYPE`, `EU_UNIT`, `DESC`, `HI_EU`, `LO_EU`, `FormatedCV`
//!   (the original's spelling; `FormattedCV` is accepted too), `PercentageCV`, `BarCVs`
//!   (`BarCV` accepted at both levels). A keyword always wins over an attribute of the
//!   same name.
//! - The `asmen.` prefix and the type code of a descriptive ID are ASCII
//!   case-insensitive (they are not names). The channel is the text up to the first dot
//!   after `asmen.`, the type the text after the last dot, the variable everything between
//!   (so variable names may contain dots, channel names may not). An ID starting with
//!   `asmen.` is always descriptive.
//! - Variable names may contain dots: the **longest** prefix of the ID that is a known
//!   variable name and is followed by the end or a dot is the variable.
//! - Syntax errors (`OPC_E_INVALIDITEMID`): empty ID, control characters, surrounding
//!   blanks, an empty dot-separated part (leading/trailing dot, `..`), a descriptive ID
//!   without three parts or with an unknown type code, a suffix outside the grammar
//!   (`<V>.DESC.x`, `<V>.<A>.x`, `<V>.<A>.CV.x.y`).
//! - A well-formed ID naming no known variable: `OPC_E_UNKNOWNITEMID`.

use std::fmt;
use std::sync::Arc;

use ctopc_core::{OpcError, OpcResult, VarType};

/// The type code of a descriptive ID.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AsmenType {
    R4,
    I2,
    UI2,
    I4,
    UI4,
    UI1,
}

impl AsmenType {
    pub const ALL: [AsmenType; 6] = [
        AsmenType::R4,
        AsmenType::I2,
        AsmenType::UI2,
        AsmenType::I4,
        AsmenType::UI4,
        AsmenType::UI1,
    ];

    /// Parses a code (ASCII case-insensitive).
    pub fn parse(code: &str) -> Option<AsmenType> {
        Self::ALL
            .into_iter()
            .find(|t| t.code().eq_ignore_ascii_case(code))
    }
    pub const fn code(self) -> &'static str {
        match self {
            AsmenType::R4 => "R4",
            AsmenType::I2 => "I2",
            AsmenType::UI2 => "UI2",
            AsmenType::I4 => "I4",
            AsmenType::UI4 => "UI4",
            AsmenType::UI1 => "UI1",
        }
    }
    /// The canonical VARTYPE.
    pub const fn var_type(self) -> VarType {
        match self {
            AsmenType::R4 => VarType::R4,
            AsmenType::I2 => VarType::I2,
            AsmenType::UI2 => VarType::UI2,
            AsmenType::I4 => VarType::I4,
            AsmenType::UI4 => VarType::UI4,
            AsmenType::UI1 => VarType::UI1,
        }
    }
}

/// `asmen.<channel>.<variable>.<type>`.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct DescriptiveId {
    /// The asix (Asmen) channel.
    pub channel: String,
    pub variable: String,
    pub var_type: AsmenType,
}

/// A one-segment suffix after a variable.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Suffix {
    /// none, or `CV`
    Value,
    /// `DATA_TYPE`
    DataType,
    /// `EU_UNIT`
    EuUnit,
    /// `DESC`
    Desc,
    /// `HI_EU`
    HiEu,
    /// `LO_EU`
    LoEu,
    /// `FormatedCV`
    Formatted,
    /// `PercentageCV`
    Percentage,
    /// `BarCVs` / `BarCV`
    Bars,
    /// Any other name: an attribute (a column of the attribute table).
    Attribute(String),
}

impl Suffix {
    /// A keyword, or an attribute name.
    pub fn parse(segment: &str) -> Suffix {
        match segment {
            "CV" => Suffix::Value,
            "DATA_TYPE" => Suffix::DataType,
            "EU_UNIT" => Suffix::EuUnit,
            "DESC" => Suffix::Desc,
            "HI_EU" => Suffix::HiEu,
            "LO_EU" => Suffix::LoEu,
            "FormatedCV" | "FormattedCV" => Suffix::Formatted,
            "PercentageCV" => Suffix::Percentage,
            "BarCVs" | "BarCV" => Suffix::Bars,
            other => Suffix::Attribute(other.to_owned()),
        }
    }

    /// The canonical text (`None` for [`Suffix::Value`], which is written as nothing).
    pub fn text(&self) -> Option<&str> {
        Some(match self {
            Suffix::Value => return None,
            Suffix::DataType => "DATA_TYPE",
            Suffix::EuUnit => "EU_UNIT",
            Suffix::Desc => "DESC",
            Suffix::HiEu => "HI_EU",
            Suffix::LoEu => "LO_EU",
            Suffix::Formatted => "FormatedCV",
            Suffix::Percentage => "PercentageCV",
            Suffix::Bars => "BarCVs",
            Suffix::Attribute(a) => a,
        })
    }
}

/// What of a variable an ID designates.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum VarItem {
    /// `<V>`, `<V>.<S>`.
    Direct(Suffix),
    /// `<V>.<A>.CV` (`then: None`) or `<V>.<A>.CV.<S>`: through the value of attribute
    /// `A`, a number or the name of an indirect variable.
    ViaAttribute {
        attribute: String,
        then: Option<Suffix>,
    },
}

/// A parsed item ID.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum ItemId {
    Descriptive(DescriptiveId),
    Variable { variable: String, item: VarItem },
}

impl fmt::Display for ItemId {
    /// The canonical form: `.CV` after a variable is dropped, keywords in their canonical
    /// spelling, type codes upper case.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ItemId::Descriptive(d) => write!(
                f,
                "asmen.{}.{}.{}",
                d.channel,
                d.variable,
                d.var_type.code()
            ),
            ItemId::Variable { variable, item } => {
                write!(f, "{variable}")?;
                match item {
                    VarItem::Direct(s) => {
                        if let Some(t) = s.text() {
                            write!(f, ".{t}")?;
                        }
                    }
                    VarItem::ViaAttribute { attribute, then } => {
                        write!(f, ".{attribute}.CV")?;
                        if let Some(t) = then.as_ref().and_then(Suffix::text) {
                            write!(f, ".{t}")?;
                        }
                    }
                }
                Ok(())
            }
        }
    }
}

/// An asix process variable: channel plus variable name (both case-sensitive), the key
/// the data sources (network client, simulation) and the adapter know a variable by.
/// Cloning is two reference-count increments.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ItemKey {
    pub channel: Arc<str>,
    pub variable: Arc<str>,
}

impl ItemKey {
    pub fn new(channel: &str, variable: &str) -> Self {
        ItemKey {
            channel: channel.into(),
            variable: variable.into(),
        }
    }
}

impl fmt::Display for ItemKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.channel, self.variable)
    }
}

/// Parses an item ID. `is_variable` says whether a name is a known variable (for the
/// longest-prefix rule); without a database pass `|_| false`.
pub fn parse_item_id(id: &str, is_variable: impl Fn(&str) -> bool) -> OpcResult<ItemId> {
    if id.is_empty() || id.trim() != id || id.chars().any(char::is_control) {
        return Err(OpcError::InvalidItemId);
    }
    if id.split('.').any(str::is_empty) {
        return Err(OpcError::InvalidItemId);
    }
    if id.len() >= 6 && id.is_char_boundary(6) && id[..6].eq_ignore_ascii_case("asmen.") {
        return parse_descriptive(&id[6..]).map(ItemId::Descriptive);
    }
    // Longest known variable prefix, ending at the end of the ID or before a dot.
    let ends = std::iter::once(id.len()).chain(
        id.char_indices()
            .rev()
            .filter(|&(_, c)| c == '.')
            .map(|(i, _)| i),
    );
    let Some(end) = ends.into_iter().find(|&end| is_variable(&id[..end])) else {
        return Err(OpcError::UnknownItemId);
    };
    let variable = id[..end].to_owned();
    let rest: Vec<&str> = if end == id.len() {
        Vec::new()
    } else {
        id[end + 1..].split('.').collect()
    };
    let keyword = |s: &str| !matches!(Suffix::parse(s), Suffix::Attribute(_));
    let item = match rest.as_slice() {
        [] => VarItem::Direct(Suffix::Value),
        [s] => VarItem::Direct(Suffix::parse(s)),
        [a, "CV"] if !keyword(a) => VarItem::ViaAttribute {
            attribute: (*a).to_owned(),
            then: None,
        },
        [a, "CV", s] if !keyword(a) => {
            let then = match Suffix::parse(s) {
                Suffix::Value => None,
                other => Some(other),
            };
            VarItem::ViaAttribute {
                attribute: (*a).to_owned(),
                then,
            }
        }
        _ => return Err(OpcError::InvalidItemId),
    };
    Ok(ItemId::Variable { variable, item })
}

fn parse_descriptive(rest: &str) -> OpcResult<DescriptiveId> {
    let (channel, tail) = rest.split_once('.').ok_or(OpcError::InvalidItemId)?;
    let (variable, code) = tail.rsplit_once('.').ok_or(OpcError::InvalidItemId)?;
    let var_type = AsmenType::parse(code).ok_or(OpcError::InvalidItemId)?;
    Ok(DescriptiveId {
        channel: channel.to_owned(),
        variable: variable.to_owned(),
        var_type,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const VARS: &[&str] = &["KW_A000", "KW_A110", "Z101", "Z101.Poziom", "a.b.c"];

    fn parse(id: &str) -> OpcResult<ItemId> {
        parse_item_id(id, |n| VARS.contains(&n))
    }

    fn var(v: &str, item: VarItem) -> OpcResult<ItemId> {
        Ok(ItemId::Variable {
            variable: v.to_owned(),
            item,
        })
    }

    fn via(v: &str, a: &str, then: Option<Suffix>) -> OpcResult<ItemId> {
        var(
            v,
            VarItem::ViaAttribute {
                attribute: a.to_owned(),
                then,
            },
        )
    }

    fn asmen(ch: &str, v: &str, t: AsmenType) -> OpcResult<ItemId> {
        Ok(ItemId::Descriptive(DescriptiveId {
            channel: ch.into(),
            variable: v.into(),
            var_type: t,
        }))
    }

    #[test]
    fn every_form_of_the_grammar() {
        use Suffix::*;
        use VarItem::Direct;
        let rows: Vec<(&str, OpcResult<ItemId>, &str)> = vec![
            ("KW_A000", var("KW_A000", Direct(Value)), "KW_A000"),
            ("KW_A000.CV", var("KW_A000", Direct(Value)), "KW_A000"),
            (
                "KW_A000.DATA_TYPE",
                var("KW_A000", Direct(DataType)),
                "KW_A000.DATA_TYPE",
            ),
            (
                "KW_A000.EU_UNIT",
                var("KW_A000", Direct(EuUnit)),
                "KW_A000.EU_UNIT",
            ),
            ("KW_A000.DESC", var("KW_A000", Direct(Desc)), "KW_A000.DESC"),
            (
                "KW_A000.HI_EU",
                var("KW_A000", Direct(HiEu)),
                "KW_A000.HI_EU",
            ),
            (
                "KW_A000.LO_EU",
                var("KW_A000", Direct(LoEu)),
                "KW_A000.LO_EU",
            ),
            (
                "KW_A000.Unit",
                var("KW_A000", Direct(Attribute("Unit".into()))),
                "KW_A000.Unit",
            ),
            (
                "KW_A000.FormatedCV",
                var("KW_A000", Direct(Formatted)),
                "KW_A000.FormatedCV",
            ),
            (
                "KW_A000.FormattedCV",
                var("KW_A000", Direct(Formatted)),
                "KW_A000.FormatedCV",
            ),
            (
                "KW_A000.PercentageCV",
                var("KW_A000", Direct(Percentage)),
                "KW_A000.PercentageCV",
            ),
            (
                "KW_A000.BarCVs",
                var("KW_A000", Direct(Bars)),
                "KW_A000.BarCVs",
            ),
            (
                "KW_A000.BarCV",
                var("KW_A000", Direct(Bars)),
                "KW_A000.BarCVs",
            ),
            (
                "KW_A000.WarnHigh.CV",
                via("KW_A000", "WarnHigh", None),
                "KW_A000.WarnHigh.CV",
            ),
            (
                "KW_A000.WarnHigh.CV.CV",
                via("KW_A000", "WarnHigh", None),
                "KW_A000.WarnHigh.CV",
            ),
            (
                "KW_A000.WarnHigh.CV.FormatedCV",
                via("KW_A000", "WarnHigh", Some(Formatted)),
                "KW_A000.WarnHigh.CV.FormatedCV",
            ),
            (
                "KW_A000.WarnHigh.CV.PercentageCV",
                via("KW_A000", "WarnHigh", Some(Percentage)),
                "KW_A000.WarnHigh.CV.PercentageCV",
            ),
            (
                "KW_A000.WarnHigh.CV.BarCV",
                via("KW_A000", "WarnHigh", Some(Bars)),
                "KW_A000.WarnHigh.CV.BarCVs",
            ),
            (
                "KW_A000.WarnHigh.CV.BarCVs",
                via("KW_A000", "WarnHigh", Some(Bars)),
                "KW_A000.WarnHigh.CV.BarCVs",
            ),
            (
                "KW_A000.WarnHigh.CV.Unit",
                via("KW_A000", "WarnHigh", Some(Attribute("Unit".into()))),
                "KW_A000.WarnHigh.CV.Unit",
            ),
            (
                "KW_A000.WarnHigh.CV.DESC",
                via("KW_A000", "WarnHigh", Some(Desc)),
                "KW_A000.WarnHigh.CV.DESC",
            ),
            (
                "asmen.Camac.06C_A111AF00.R4",
                asmen("Camac", "06C_A111AF00", AsmenType::R4),
                "asmen.Camac.06C_A111AF00.R4",
            ),
            (
                "asmen.K.v.I2",
                asmen("K", "v", AsmenType::I2),
                "asmen.K.v.I2",
            ),
            (
                "asmen.K.v.UI2",
                asmen("K", "v", AsmenType::UI2),
                "asmen.K.v.UI2",
            ),
            (
                "asmen.K.v.I4",
                asmen("K", "v", AsmenType::I4),
                "asmen.K.v.I4",
            ),
            (
                "asmen.K.v.UI4",
                asmen("K", "v", AsmenType::UI4),
                "asmen.K.v.UI4",
            ),
            (
                "asmen.K.v.UI1",
                asmen("K", "v", AsmenType::UI1),
                "asmen.K.v.UI1",
            ),
            (
                "ASMEN.K.v.ui1",
                asmen("K", "v", AsmenType::UI1),
                "asmen.K.v.UI1",
            ),
            (
                "asmen.K.a.b.R4",
                asmen("K", "a.b", AsmenType::R4),
                "asmen.K.a.b.R4",
            ),
            // Longest known prefix wins.
            ("Z101", var("Z101", Direct(Value)), "Z101"),
            (
                "Z101.Poziom",
                var("Z101.Poziom", Direct(Value)),
                "Z101.Poziom",
            ),
            (
                "Z101.Poziom.DESC",
                var("Z101.Poziom", Direct(Desc)),
                "Z101.Poziom.DESC",
            ),
            (
                "Z101.Temp",
                var("Z101", Direct(Attribute("Temp".into()))),
                "Z101.Temp",
            ),
            ("a.b.c.CV", var("a.b.c", Direct(Value)), "a.b.c"),
        ];
        for (id, expected, canonical) in rows {
            let got = parse(id);
            assert_eq!(got, expected, "{id}");
            assert_eq!(got.unwrap().to_string(), canonical, "{id}");
        }
    }

    #[test]
    fn errors() {
        let rows: &[(&str, OpcError)] = &[
            ("", OpcError::InvalidItemId),
            (" KW_A000", OpcError::InvalidItemId),
            ("KW_A000 ", OpcError::InvalidItemId),
            ("KW_A000\t", OpcError::InvalidItemId),
            ("KW_\u{1}A000", OpcError::InvalidItemId),
            (".KW_A000", OpcError::InvalidItemId),
            ("KW_A000.", OpcError::InvalidItemId),
            ("KW_A000..CV", OpcError::InvalidItemId),
            ("KW_A000.DESC.CV", OpcError::InvalidItemId),
            ("KW_A000.CV.DESC", OpcError::InvalidItemId),
            ("KW_A000.Unit.X", OpcError::InvalidItemId),
            ("KW_A000.WarnHigh.CV.X.Y", OpcError::InvalidItemId),
            ("KW_A000.a.b.c.d", OpcError::InvalidItemId),
            ("asmen.Camac.R4", OpcError::InvalidItemId),
            ("asmen.Camac", OpcError::InvalidItemId),
            ("asmen.Camac.v.R8", OpcError::InvalidItemId),
            ("asmen.Camac.v.", OpcError::InvalidItemId),
            ("asmen..v.R4", OpcError::InvalidItemId),
            ("kw_a000", OpcError::UnknownItemId),
            ("KW_A999", OpcError::UnknownItemId),
            ("KW_A999.DESC", OpcError::UnknownItemId),
            ("Z10", OpcError::UnknownItemId),
            ("a.b", OpcError::UnknownItemId),
        ];
        for (id, e) in rows {
            assert_eq!(parse(id), Err(*e), "{id:?}");
        }
        // Without a database only descriptive IDs parse.
        assert_eq!(
            parse_item_id("KW_A000", |_| false),
            Err(OpcError::UnknownItemId)
        );
        assert!(parse_item_id("asmen.Camac.x.R4", |_| false).is_ok());
    }

    proptest! {
        #[test]
        fn never_panics_and_canonical_form_round_trips(id in "(asmen\\.|KW_A000|Z101|\\.|CV|DESC|Warn|[a-zA-Z0-9_ ]|ł){0,12}") {
            if let Ok(parsed) = parse(&id) {
                let canonical = parsed.to_string();
                prop_assert_eq!(parse(&canonical), Ok(parsed));
            }
        }

        #[test]
        fn never_panics_on_any_string(id in any::<String>()) {
            let _ = parse(&id);
        }
    }
}
