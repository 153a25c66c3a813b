//! Which properties an item has and their values: the behaviour behind IOPCItemProperties
//! (DA 2.05a) and the property part of IOPCBrowse (DA 3.0 GetProperties, Browse with
//! properties). The COM layer (`ctopc-com/src/da/server/props.rs`) checks arguments, makes
//! one call here per method, does the one engine read for the live values and marshals.
//!
//! Which properties an item has (asix manual §6.6; the digest's §6):
//!
//! | ID | property | type | items |
//! |---|---|---|---|
//! | 1-6 | canonical type, value, quality, timestamp, access rights, server scan rate | I2, canonical, I2, DATE, I4, R4 | every item |
//! | 7 | EU type | I4 | items with EU information (analog range or enumeration) |
//! | 8 | EU info | BSTR array | enumerated items (the spec defines it for OPC_ENUMERATED only) |
//! | 100 | EU units | BSTR | items with a unit |
//! | 101 | description | BSTR | items with a description, in the session's language (`DescriptionEn` in English sessions, falling back to `Description`) |
//! | 102, 103 | high / low EU | R8 | items with an analog range |
//! | 307-310 | HiHi, Hi, Lo, LoLo limit | R8 | items whose [`LimitProps`](crate::namespace::LimitProps) hold that limit as a number (asix: value items only) |
//!
//! Values of 2-4 come from one IOPCItemIO-style read of the engine, made by the caller
//! ([`needs_read`], then [`fill_live`]): the cache when it was refreshed within
//! [`VALUE_MAX_AGE_FACTOR`] times the server scan rate (a subscribed item), otherwise a
//! device read. "Server scan rate" is the engine's minimum update rate (the fastest rate
//! the server obtains data at), in milliseconds.
//!
//! Item IDs of properties (LookupItemIDs, `OPCITEMPROPERTY.szItemID`) are the namespace's:
//! [`Namespace::property_item_id`] (asix: the attribute items `<V>.EU_UNIT`, `<V>.DESC`,
//! `<V>.HI_EU`, `<V>.LO_EU`, `<V>.AlarmHigh.CV`, ...; see `asix_model::namespace`). A
//! property without an item ID is, for LookupItemIDs, OPC_E_INVALID_PID, as the OPC
//! Foundation sample server answers for IDs 1-8 ("this DA 2 function requires an error
//! code in this case"): a property "is defined for the item" in LookupItemIDs' sense only
//! when it has an item ID ([`lookup_item_ids`]).

use super::{self as p, require_property};
use crate::lang::Lang;
use crate::model::ItemState;
use crate::namespace::{EuInfo, ItemDef, Namespace, PropertyAttributes};
use crate::value::ArrayValue;
use crate::{OpcError, OpcResult, Value, VarType};

/// Property values 2-4 may come from a cache refreshed within this many scan rates.
pub const VALUE_MAX_AGE_FACTOR: u32 = 2;

/// A resolved item, for its properties.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemInfo {
    /// The item ID as the client wrote it.
    pub item_id: String,
    pub def: ItemDef,
    pub attrs: PropertyAttributes,
}

/// One property of one item, ready for OPCITEMPROPERTY / the IOPCItemProperties arrays.
#[derive(Debug, Clone, PartialEq)]
pub struct Prop {
    pub id: u32,
    pub var_type: VarType,
    pub description: &'static str,
    pub item_id: Option<String>,
    /// VT_EMPTY when values were not asked for or `error` is set.
    pub value: Value,
    pub error: Option<OpcError>,
}

/// What the static (non-live) part of a property lookup needs: the namespace, the
/// session's language and the server scan rate (property 6).
#[derive(Clone, Copy)]
pub struct PropertyContext<'a> {
    pub ns: &'a dyn Namespace,
    pub lang: Lang,
    pub scan_rate_ms: u32,
}

/// Resolves an item ID (no access path: the basic channel). `""` is OPC_E_INVALIDITEMID.
pub fn resolve_item(cx: &PropertyContext<'_>, item_id: &str) -> OpcResult<ItemInfo> {
    if item_id.is_empty() {
        return Err(OpcError::InvalidItemId);
    }
    let (def, attrs) = cx.ns.resolve_with_attributes(item_id, "")?;
    Ok(ItemInfo {
        item_id: item_id.to_owned(),
        def,
        attrs,
    })
}

fn non_empty(s: &Option<String>) -> Option<&str> {
    s.as_deref().filter(|s| !s.is_empty())
}

/// The description in `lang`, falling back to the other language's.
fn description(attrs: &PropertyAttributes, lang: Lang) -> Option<&str> {
    match lang {
        Lang::English => non_empty(&attrs.description_en).or_else(|| non_empty(&attrs.description)),
        Lang::Polish => non_empty(&attrs.description).or_else(|| non_empty(&attrs.description_en)),
    }
}

/// The IDs of the properties the item has, ascending.
pub fn available_ids(info: &ItemInfo, lang: Lang) -> Vec<u32> {
    let mut ids = p::FIXED_PROPERTY_IDS.to_vec();
    if info.attrs.eu != EuInfo::None {
        ids.push(p::OPC_PROPERTY_EU_TYPE);
    }
    if matches!(info.attrs.eu, EuInfo::Enumerated(_)) {
        ids.push(p::OPC_PROPERTY_EU_INFO);
    }
    if non_empty(&info.attrs.eu_units).is_some() {
        ids.push(p::OPC_PROPERTY_EU_UNITS);
    }
    if description(&info.attrs, lang).is_some() {
        ids.push(p::OPC_PROPERTY_DESCRIPTION);
    }
    if matches!(info.attrs.eu, EuInfo::Analog { .. }) {
        ids.push(p::OPC_PROPERTY_HIGH_EU);
        ids.push(p::OPC_PROPERTY_LOW_EU);
    }
    for id in LIMIT_IDS {
        if limit(info, id).is_some() {
            ids.push(id);
        }
    }
    ids
}

/// HiHi, Hi, Lo, LoLo Limit, ascending.
const LIMIT_IDS: [u32; 4] = [
    p::OPC_PROPERTY_HIHI_LIMIT,
    p::OPC_PROPERTY_HI_LIMIT,
    p::OPC_PROPERTY_LO_LIMIT,
    p::OPC_PROPERTY_LOLO_LIMIT,
];

/// The limit behind a limit property (307-310), when the item has it as a number.
fn limit(info: &ItemInfo, id: u32) -> Option<f64> {
    let l = &info.attrs.limits;
    match id {
        p::OPC_PROPERTY_HIHI_LIMIT => l.hihi,
        p::OPC_PROPERTY_HI_LIMIT => l.hi,
        p::OPC_PROPERTY_LO_LIMIT => l.lo,
        p::OPC_PROPERTY_LOLO_LIMIT => l.lolo,
        _ => None,
    }
}

/// True for the properties whose values come from a read (value, quality, timestamp).
pub fn is_live(id: u32) -> bool {
    matches!(
        id,
        p::OPC_PROPERTY_VALUE | p::OPC_PROPERTY_QUALITY | p::OPC_PROPERTY_TIMESTAMP
    )
}

/// The value of a property that does not need a read; `None` when the item lacks it.
fn static_value(info: &ItemInfo, id: u32, cx: &PropertyContext<'_>) -> Option<Value> {
    let eu_type = |eu: &EuInfo| match eu {
        EuInfo::None => 0,
        EuInfo::Analog { .. } => 1,
        EuInfo::Enumerated(_) => 2,
    };
    Some(match id {
        p::OPC_PROPERTY_DATATYPE => Value::I2(info.def.canonical_type.0 as i16),
        p::OPC_PROPERTY_ACCESS_RIGHTS => Value::I4(info.def.access_rights as i32),
        p::OPC_PROPERTY_SCAN_RATE => Value::R4(cx.scan_rate_ms as f32),
        p::OPC_PROPERTY_EU_TYPE if info.attrs.eu != EuInfo::None => {
            Value::I4(eu_type(&info.attrs.eu))
        }
        p::OPC_PROPERTY_EU_INFO => match &info.attrs.eu {
            EuInfo::Enumerated(texts) => Value::Array(ArrayValue {
                element_type: VarType::BSTR,
                elements: texts.iter().cloned().map(Value::Bstr).collect(),
            }),
            _ => return None,
        },
        p::OPC_PROPERTY_EU_UNITS => Value::Bstr(non_empty(&info.attrs.eu_units)?.to_owned()),
        p::OPC_PROPERTY_DESCRIPTION => Value::Bstr(description(&info.attrs, cx.lang)?.to_owned()),
        p::OPC_PROPERTY_HIGH_EU => match info.attrs.eu {
            EuInfo::Analog { high, .. } => Value::R8(high),
            _ => return None,
        },
        p::OPC_PROPERTY_LOW_EU => match info.attrs.eu {
            EuInfo::Analog { low, .. } => Value::R8(low),
            _ => return None,
        },
        p::OPC_PROPERTY_HIHI_LIMIT..=p::OPC_PROPERTY_LOLO_LIMIT => Value::R8(limit(info, id)?),
        _ => return None,
    })
}

/// The item ID of a property (the namespace's, see the module documentation), if it has
/// one.
pub fn property_item_id(info: &ItemInfo, id: u32, cx: &PropertyContext<'_>) -> Option<String> {
    cx.ns.property_item_id(&info.item_id, &info.def, id)
}

/// The property `id` of an item without its live value: OPC_E_INVALID_PID for IDs that are
/// not OPC properties or that the item does not have. With `with_values` the static value
/// is filled in; live values (2-4) stay VT_EMPTY for [`fill_live`].
pub fn property(info: &ItemInfo, id: u32, with_values: bool, cx: &PropertyContext<'_>) -> Prop {
    let mut prop = Prop {
        id,
        var_type: VarType::EMPTY,
        description: "",
        item_id: None,
        value: Value::Empty,
        error: None,
    };
    let pinfo = match require_property(id) {
        Ok(pi) => pi,
        Err(e) => {
            prop.error = Some(e);
            return prop;
        }
    };
    if !available_ids(info, cx.lang).contains(&id) {
        prop.error = Some(OpcError::InvalidPid);
        return prop;
    }
    prop.description = pinfo.description(cx.lang);
    prop.var_type = if id == p::OPC_PROPERTY_VALUE {
        info.def.canonical_type
    } else {
        pinfo.var_type
    };
    prop.item_id = property_item_id(info, id, cx);
    if with_values && !is_live(id) {
        match static_value(info, id, cx) {
            Some(v) => prop.value = v,
            None => prop.error = Some(OpcError::InvalidPid),
        }
    }
    prop
}

/// Fills the live properties (2-4) of one item from its read result.
pub fn fill_live(props: &mut [Prop], read: &Result<ItemState, OpcError>) {
    for prop in props
        .iter_mut()
        .filter(|p| p.error.is_none() && is_live(p.id))
    {
        match read {
            Ok(s) => {
                prop.value = match prop.id {
                    p::OPC_PROPERTY_VALUE => s.value.clone(),
                    p::OPC_PROPERTY_QUALITY => Value::I2(s.quality.0 as i16),
                    _ => Value::date_from(s.timestamp),
                }
            }
            Err(e) => prop.error = Some(*e),
        }
    }
}

/// True when the properties include a live one that still needs its value.
pub fn needs_read(props: &[Prop]) -> bool {
    props.iter().any(|p| p.error.is_none() && is_live(p.id))
}

/// One item's properties for QueryAvailableProperties, GetItemProperties, GetProperties
/// and Browse: `ids` `None` means every property the item has. Live values are left for
/// [`fill_live`].
pub fn static_properties(
    cx: &PropertyContext<'_>,
    item_id: &str,
    ids: Option<&[u32]>,
    with_values: bool,
) -> OpcResult<Vec<Prop>> {
    let info = resolve_item(cx, item_id)?;
    let ids = match ids {
        Some(ids) => ids.to_vec(),
        None => available_ids(&info, cx.lang),
    };
    Ok(ids
        .into_iter()
        .map(|id| property(&info, id, with_values, cx))
        .collect())
}

/// LookupItemIDs: the item's error, or per property its item ID or its error:
/// OPC_E_INVALID_PID for a property that is not an OPC property, that the item does not
/// have, or that has no item ID.
pub fn lookup_item_ids(
    cx: &PropertyContext<'_>,
    item_id: &str,
    ids: &[u32],
) -> OpcResult<Vec<OpcResult<String>>> {
    let info = resolve_item(cx, item_id)?;
    Ok(ids
        .iter()
        .map(|&id| {
            let prop = property(&info, id, false, cx);
            match (prop.error, prop.item_id) {
                (Some(e), _) => Err(e),
                (None, Some(new_id)) => Ok(new_id),
                (None, None) => Err(OpcError::InvalidPid),
            }
        })
        .collect())
}

#[cfg(test)]
mod tests;
