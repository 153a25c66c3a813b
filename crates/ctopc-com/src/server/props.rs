//! Item properties: IOPCItemProperties (DA 2.05a) and the property part of IOPCBrowse
//! (DA 3.0 GetProperties, Browse with properties).
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
//!
//! Values of 2-4 come from one IOPCItemIO-style read of the engine ([`read_values`]): the
//! cache when it was refreshed within [`VALUE_MAX_AGE_FACTOR`] times the server scan rate
//! (a subscribed item), otherwise a device read. "Server scan rate" is the engine's
//! minimum update rate (the fastest rate the server obtains data at), in milliseconds.
//!
//! Item IDs of properties (LookupItemIDs, `OPCITEMPROPERTY.szItemID`): the asix attribute
//! items `<V>.EU_UNIT` (100), `<V>.DESC` (101), `<V>.HI_EU` (102) and `<V>.LO_EU` (103), for
//! the value items of database variables (`<V>` and `<V>.CV`, aliases included) when that
//! ID resolves. Every other property has no item ID; LookupItemIDs answers
//! OPC_E_INVALID_PID for it, as the OPC Foundation sample server does for IDs 1-8 ("this DA
//! 2 function requires an error code in this case"): a property "is defined for the item"
//! in LookupItemIDs' sense only when it has an item ID.

use super::{OpcServer, OpcServer_Impl};
use crate::abi::TaskMem;
use crate::abi::{
    self, clear, in_slice, in_string, nonnull, opt_wstr, put, s_false_if_any, OwnedArray, OwnedWstr,
};
use crate::interfaces::*;
use crate::variant;
use ctopc_core::lang::Lang;
use ctopc_core::model::ItemState;
use ctopc_core::namespace::{EuInfo, ItemAttributes, ItemDef, Namespace};
use ctopc_core::properties::{self as p, require_property};
use ctopc_core::value::ArrayValue;
use ctopc_core::{OpcError, OpcResult, Value, VarType};
use windows::core::{HRESULT, PCWSTR, PWSTR};
use windows::Win32::Foundation::{S_FALSE, S_OK};
use windows::Win32::System::Variant::{VARENUM, VARIANT};

/// Property values 2-4 may come from a cache refreshed within this many scan rates.
pub const VALUE_MAX_AGE_FACTOR: u32 = 2;

/// A resolved item, for its properties.
pub struct ItemInfo {
    /// The item ID as the client wrote it.
    pub item_id: String,
    pub def: ItemDef,
    pub attrs: ItemAttributes,
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

/// What the static (non-live) part of a property lookup needs.
pub struct Ctx<'a> {
    pub ns: &'a dyn AttributeSource,
    pub lang: Lang,
    pub scan_rate_ms: u32,
}

/// The namespace operations properties need (the asix namespace; a seam for reading).
pub trait AttributeSource {
    fn resolve_with_attributes(&self, item_id: &str) -> OpcResult<(ItemDef, ItemAttributes)>;
    fn resolves(&self, item_id: &str) -> OpcResult<ItemDef>;
}

impl AttributeSource for std::sync::Arc<dyn Namespace> {
    fn resolve_with_attributes(&self, item_id: &str) -> OpcResult<(ItemDef, ItemAttributes)> {
        Namespace::resolve_with_attributes(&**self, item_id, "")
    }
    fn resolves(&self, item_id: &str) -> OpcResult<ItemDef> {
        Namespace::resolve(&**self, item_id, "")
    }
}

/// Resolves an item ID (no access path: the basic channel). `""` is OPC_E_INVALIDITEMID.
pub fn resolve(cx: &Ctx<'_>, item_id: &str) -> OpcResult<ItemInfo> {
    if item_id.is_empty() {
        return Err(OpcError::InvalidItemId);
    }
    let (def, attrs) = cx.ns.resolve_with_attributes(item_id)?;
    Ok(ItemInfo {
        item_id: item_id.to_owned(),
        def,
        attrs,
    })
}

fn non_empty(s: &Option<String>) -> Option<&str> {
    s.as_deref().filter(|s| !s.is_empty())
}

fn description(attrs: &ItemAttributes, lang: Lang) -> Option<&str> {
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

/// The asix limit behind a limit property (307-310), when the item has it as a number.
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
fn static_value(info: &ItemInfo, id: u32, cx: &Ctx<'_>) -> Option<Value> {
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

/// The item ID of a property (see the module documentation), if it has one.
pub fn property_item_id(info: &ItemInfo, id: u32, cx: &Ctx<'_>) -> Option<String> {
    let suffix = match id {
        p::OPC_PROPERTY_EU_UNITS => "EU_UNIT",
        p::OPC_PROPERTY_DESCRIPTION => "DESC",
        p::OPC_PROPERTY_HIGH_EU => "HI_EU",
        p::OPC_PROPERTY_LOW_EU => "LO_EU",
        // The numeric attribute as an item (a constant).
        p::OPC_PROPERTY_HIHI_LIMIT => "AlarmHigh.CV",
        p::OPC_PROPERTY_HI_LIMIT => "WarnHigh.CV",
        p::OPC_PROPERTY_LO_LIMIT => "WarnLow.CV",
        p::OPC_PROPERTY_LOLO_LIMIT => "AlarmLow.CV",
        _ => return None,
    };
    // Only the value items of database variables: live, keyed by the bare asix name.
    if info.def.constant.is_some() || info.def.source_key.contains('.') {
        return None;
    }
    let base = info.item_id.strip_suffix(".CV").unwrap_or(&info.item_id);
    let same = cx
        .ns
        .resolves(base)
        .is_ok_and(|d| d.source_key == info.def.source_key && d.constant.is_none());
    if !same {
        return None;
    }
    let candidate = format!("{base}.{suffix}");
    cx.ns.resolves(&candidate).is_ok().then_some(candidate)
}

/// The property `id` of an item without its live value: OPC_E_INVALID_PID for IDs that are
/// not OPC properties or that the item does not have. With `with_values` the static value
/// is filled in; live values (2-4) stay VT_EMPTY for [`fill_live`].
pub fn property(info: &ItemInfo, id: u32, with_values: bool, cx: &Ctx<'_>) -> Prop {
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

impl OpcServer {
    /// The session's language (descriptions, texts).
    pub(super) fn lang(&self) -> Lang {
        self.lang_for(self.session().lcid)
            .unwrap_or(self.ctx.default_lang)
    }

    /// The engine's minimum update rate (the "Server Scan Rate" property).
    pub(super) fn scan_rate_ms(&self) -> u32 {
        self.ctx.runtime.lock().engine.config().min_update_rate_ms
    }

    /// Reads value, quality and timestamp of `item_ids` for their properties: one engine
    /// read for all of them (see the module documentation for the MaxAge used).
    pub(super) fn read_values(&self, item_ids: &[&str]) -> Vec<Result<ItemState, OpcError>> {
        if item_ids.is_empty() {
            return Vec::new();
        }
        let max_age = self.scan_rate_ms().saturating_mul(VALUE_MAX_AGE_FACTOR);
        let items: Vec<(&str, u32)> = item_ids.iter().map(|id| (*id, max_age)).collect();
        self.item_io_read(&items)
    }
}

/// One item's properties for GetProperties / Browse: `ids` `None` means every property
/// the item has. Live values are left for [`OpcServer::fill_live_values`].
pub fn static_properties(
    cx: &Ctx<'_>,
    item_id: &str,
    ids: Option<&[u32]>,
    with_values: bool,
) -> OpcResult<Vec<Prop>> {
    let info = resolve(cx, item_id)?;
    let ids = match ids {
        Some(ids) => ids.to_vec(),
        None => available_ids(&info, cx.lang),
    };
    Ok(ids
        .into_iter()
        .map(|id| property(&info, id, with_values, cx))
        .collect())
}

/// The item-level code of GetProperties / Browse: the item's error, S_FALSE when a
/// property failed, else S_OK.
pub fn item_code(r: &OpcResult<Vec<Prop>>) -> HRESULT {
    match r {
        Err(e) => crate::error::hresult(*e),
        Ok(props) if props.iter().any(|p| p.error.is_some()) => S_FALSE,
        Ok(_) => S_OK,
    }
}

/// The OPCITEMPROPERTIES of one item (owning its array and strings: store it in an
/// [`OwnedArray`] at once).
pub fn item_properties(r: &OpcResult<Vec<Prop>>) -> windows::core::Result<OPCITEMPROPERTIES> {
    let hr = item_code(r);
    let props = match r {
        Ok(p) => p.as_slice(),
        Err(_) => &[],
    };
    let mut arr = OwnedArray::<OPCITEMPROPERTY>::zeroed(props.len())?;
    for (slot, prop) in arr.as_mut_slice().iter_mut().zip(props) {
        slot.dwPropertyID = prop.id;
        slot.hrErrorID = prop.error.map_or(S_OK, crate::error::hresult);
        if prop.error.is_none() {
            slot.vtDataType = VARENUM(prop.var_type.0);
            slot.szDescription = opt_wstr(Some(prop.description))?;
            slot.szItemID = opt_wstr(prop.item_id.as_deref())?;
            slot.vValue = variant::to_variant(&prop.value)?;
        }
    }
    Ok(OPCITEMPROPERTIES {
        hrErrorID: hr,
        dwNumProperties: props.len() as u32,
        pItemProperties: arr.into_raw(),
        dwReserved: 0,
    })
}

impl OpcServer {
    /// The context for property lookups in this session.
    pub(super) fn props_ctx(&self) -> Ctx<'_> {
        Ctx {
            ns: &self.ctx.namespace,
            lang: self.lang(),
            scan_rate_ms: self.scan_rate_ms(),
        }
    }

    /// Fills the live properties (2-4) of every item that asked for them, with one read.
    pub(super) fn fill_live_values(&self, items: &mut [(&str, &mut Vec<Prop>)]) {
        let wanted: Vec<usize> = (0..items.len())
            .filter(|&i| needs_read(items[i].1))
            .collect();
        let ids: Vec<&str> = wanted.iter().map(|&i| items[i].0).collect();
        let reads = self.read_values(&ids);
        for (&i, read) in wanted.iter().zip(&reads) {
            fill_live(items[i].1, read);
        }
    }
}

impl IOPCItemProperties_Impl for OpcServer_Impl {
    unsafe fn QueryAvailableProperties(
        &self,
        pitem_id: PCWSTR,
        pcount: *mut u32,
        ppids: *mut *mut u32,
        ppdescriptions: *mut *mut PWSTR,
        pptypes: *mut *mut VARTYPE,
    ) -> windows::core::Result<()> {
        clear(pcount, 0);
        clear(ppids, std::ptr::null_mut());
        clear(ppdescriptions, std::ptr::null_mut());
        clear(pptypes, std::ptr::null_mut());
        nonnull(pcount)?;
        nonnull(ppids)?;
        nonnull(ppdescriptions)?;
        nonnull(pptypes)?;
        let item_id = in_string(pitem_id, OpcError::InvalidItemId)?;
        let cx = self.props_ctx();
        let props = static_properties(&cx, &item_id, None, false).map_err(crate::error::to_com)?;
        let n = props.len();
        let mut ids = TaskMem::<u32>::zeroed(n)?;
        let mut types = TaskMem::<VARTYPE>::zeroed(n)?;
        let mut descriptions = OwnedArray::<PWSTR>::zeroed(n)?;
        for (i, prop) in props.iter().enumerate() {
            ids.as_mut_slice()[i] = prop.id;
            types.as_mut_slice()[i] = VARENUM(prop.var_type.0);
            descriptions.as_mut_slice()[i] = OwnedWstr::new(prop.description)?.into_raw();
        }
        // SAFETY: all four checked non-null; every allocation has succeeded.
        unsafe {
            put(pcount, n as u32);
            put(ppids, ids.into_raw());
            put(ppdescriptions, descriptions.into_raw());
            put(pptypes, types.into_raw());
        }
        Ok(())
    }

    unsafe fn GetItemProperties(
        &self,
        pitem_id: PCWSTR,
        count: u32,
        pids: *const u32,
        ppdata: *mut *mut VARIANT,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        clear(ppdata, std::ptr::null_mut());
        clear(pperrors, std::ptr::null_mut());
        abi::hresult((|| {
            nonnull(ppdata)?;
            nonnull(pperrors)?;
            if count == 0 {
                return Err(abi::invalid_arg());
            }
            let ids = in_slice(pids, count)?;
            let item_id = in_string(pitem_id, OpcError::InvalidItemId)?;
            let cx = self.props_ctx();
            let mut props =
                static_properties(&cx, &item_id, Some(ids), true).map_err(crate::error::to_com)?;
            self.fill_live_values(&mut [(item_id.as_str(), &mut props)]);
            let mut data = OwnedArray::<VARIANT>::zeroed(props.len())?;
            let mut errors = TaskMem::<HRESULT>::zeroed(props.len())?;
            for (i, prop) in props.iter().enumerate() {
                errors.as_mut_slice()[i] = prop.error.map_or(S_OK, crate::error::hresult);
                if prop.error.is_none() {
                    data.as_mut_slice()[i] = variant::to_variant(&prop.value)?;
                }
            }
            let hr = s_false_if_any(errors.as_mut_slice());
            // SAFETY: both checked non-null; every allocation has succeeded.
            unsafe {
                put(ppdata, data.into_raw());
                put(pperrors, errors.into_raw());
            }
            Ok(hr)
        })())
    }

    unsafe fn LookupItemIDs(
        &self,
        pitem_id: PCWSTR,
        count: u32,
        pids: *const u32,
        ppnew_ids: *mut *mut PWSTR,
        pperrors: *mut *mut HRESULT,
    ) -> HRESULT {
        clear(ppnew_ids, std::ptr::null_mut());
        clear(pperrors, std::ptr::null_mut());
        abi::hresult((|| {
            nonnull(ppnew_ids)?;
            nonnull(pperrors)?;
            if count == 0 {
                return Err(abi::invalid_arg());
            }
            let ids = in_slice(pids, count)?;
            let item_id = in_string(pitem_id, OpcError::InvalidItemId)?;
            let cx = self.props_ctx();
            let info = resolve(&cx, &item_id).map_err(crate::error::to_com)?;
            let mut new_ids = OwnedArray::<PWSTR>::zeroed(ids.len())?;
            let mut errors = TaskMem::<HRESULT>::zeroed(ids.len())?;
            for (i, &id) in ids.iter().enumerate() {
                let prop = property(&info, id, false, &cx);
                match (prop.error, prop.item_id) {
                    (None, Some(new_id)) => {
                        new_ids.as_mut_slice()[i] = OwnedWstr::new(&new_id)?.into_raw();
                        errors.as_mut_slice()[i] = S_OK;
                    }
                    (Some(e), _) => errors.as_mut_slice()[i] = crate::error::hresult(e),
                    (None, None) => {
                        errors.as_mut_slice()[i] = crate::error::hresult(OpcError::InvalidPid)
                    }
                }
            }
            let hr = s_false_if_any(errors.as_mut_slice());
            // SAFETY: both checked non-null; every allocation has succeeded.
            unsafe {
                put(ppnew_ids, new_ids.into_raw());
                put(pperrors, errors.into_raw());
            }
            Ok(hr)
        })())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ctopc_core::Quality;

    struct Fake;

    impl AttributeSource for Fake {
        fn resolve_with_attributes(&self, item_id: &str) -> OpcResult<(ItemDef, ItemAttributes)> {
            let var = |key: &str| ItemDef {
                source_key: key.into(),
                channel: "*".into(),
                canonical_type: VarType::R4,
                access_rights: 1,
                eu: EuInfo::Analog {
                    low: 0.0,
                    high: 8.0,
                },
                constant: None,
            };
            let attrs = ItemAttributes {
                description: Some("Poziom".into()),
                description_en: Some("Level".into()),
                eu_units: Some("m".into()),
                eu: EuInfo::Analog {
                    low: 0.0,
                    high: 8.0,
                },
                limits: ctopc_core::namespace::LimitProps {
                    hihi: Some(7.5),
                    hi: Some(7.0),
                    lo: Some(1.0),
                    lolo: None,
                },
            };
            match item_id {
                "V" | "V.CV" | "A" => Ok((var("V"), attrs)),
                "V.DESC" | "V.EU_UNIT" | "V.HI_EU" | "V.LO_EU" | "A.DESC" | "V.AlarmHigh.CV"
                | "V.WarnLow.CV" => {
                    let mut d = var(item_id);
                    d.constant = Some(Value::Bstr("x".into()));
                    Ok((d, ItemAttributes::default()))
                }
                "V.PercentageCV" => Ok((
                    var("V.PercentageCV"),
                    ItemAttributes {
                        eu_units: Some("%".into()),
                        ..Default::default()
                    },
                )),
                "" | "V." => Err(OpcError::InvalidItemId),
                _ => Err(OpcError::UnknownItemId),
            }
        }
        fn resolves(&self, item_id: &str) -> OpcResult<ItemDef> {
            self.resolve_with_attributes(item_id).map(|(d, _)| d)
        }
    }

    fn cx(lang: Lang) -> Ctx<'static> {
        Ctx {
            ns: &Fake,
            lang,
            scan_rate_ms: 1000,
        }
    }

    #[test]
    fn available_properties_follow_the_item() {
        let c = cx(Lang::English);
        let v = resolve(&c, "V").unwrap();
        assert_eq!(
            available_ids(&v, c.lang),
            [1, 2, 3, 4, 5, 6, 7, 100, 101, 102, 103, 307, 308, 309]
        );
        let pct = resolve(&c, "V.PercentageCV").unwrap();
        assert_eq!(available_ids(&pct, c.lang), [1, 2, 3, 4, 5, 6, 100]);
        assert_eq!(resolve(&c, "").err(), Some(OpcError::InvalidItemId));
        assert_eq!(resolve(&c, "W").err(), Some(OpcError::UnknownItemId));
    }

    #[test]
    fn static_values_descriptions_in_the_session_language_and_bad_ids() {
        let en = cx(Lang::English);
        let v = resolve(&en, "V").unwrap();
        let d = property(&v, 101, true, &en);
        assert_eq!(
            (d.value.clone(), d.description, d.error),
            (Value::Bstr("Level".into()), "Item Description", None)
        );
        let pl = cx(Lang::Polish);
        let d = property(&v, 101, true, &pl);
        assert_eq!(
            (d.value, d.description),
            (Value::Bstr("Poziom".into()), "Opis elementu")
        );
        assert_eq!(property(&v, 102, true, &en).value, Value::R8(8.0));
        assert_eq!(
            (
                property(&v, 307, true, &en).value,
                property(&v, 307, true, &en).description
            ),
            (Value::R8(7.5), "HiHi Limit")
        );
        assert_eq!(
            (
                property(&v, 308, true, &en).value,
                property(&v, 309, true, &en).value
            ),
            (Value::R8(7.0), Value::R8(1.0))
        );
        assert_eq!(
            property(&v, 310, true, &en).error,
            Some(OpcError::InvalidPid),
            "no LoLo limit"
        );
        assert_eq!(
            property(&v, 1, true, &en).value,
            Value::I2(VarType::R4.0 as i16)
        );
        assert_eq!(property(&v, 6, true, &en).value, Value::R4(1000.0));
        assert_eq!(property(&v, 2, true, &en).var_type, VarType::R4);
        assert_eq!(property(&v, 2, true, &en).value, Value::Empty);
        assert_eq!(
            property(&v, 8, true, &en).error,
            Some(OpcError::InvalidPid),
            "analog: no EU info"
        );
        assert_eq!(
            property(&v, 9999, true, &en).error,
            Some(OpcError::InvalidPid)
        );
        assert_eq!(property(&v, 101, false, &en).value, Value::Empty);
    }

    #[test]
    fn item_ids_of_attribute_properties() {
        let c = cx(Lang::English);
        let v = resolve(&c, "V.CV").unwrap();
        assert_eq!(property_item_id(&v, 101, &c).as_deref(), Some("V.DESC"));
        assert_eq!(property_item_id(&v, 100, &c).as_deref(), Some("V.EU_UNIT"));
        assert_eq!(property_item_id(&v, 2, &c), None);
        assert_eq!(
            property_item_id(&v, 307, &c).as_deref(),
            Some("V.AlarmHigh.CV")
        );
        assert_eq!(
            property_item_id(&v, 309, &c).as_deref(),
            Some("V.WarnLow.CV")
        );
        assert_eq!(
            property_item_id(&v, 308, &c),
            None,
            "V.WarnHigh.CV does not resolve here"
        );
        let a = resolve(&c, "A").unwrap();
        assert_eq!(property_item_id(&a, 101, &c).as_deref(), Some("A.DESC"));
        assert_eq!(
            property_item_id(&a, 100, &c),
            None,
            "A.EU_UNIT does not resolve"
        );
        let pct = resolve(&c, "V.PercentageCV").unwrap();
        assert_eq!(property_item_id(&pct, 100, &c), None);
    }

    #[test]
    fn live_values_come_from_the_read() {
        let c = cx(Lang::English);
        let v = resolve(&c, "V").unwrap();
        let mut props: Vec<Prop> = [2, 3, 4, 5]
            .iter()
            .map(|&id| property(&v, id, true, &c))
            .collect();
        assert!(needs_read(&props));
        let t = ctopc_core::Timestamp::from_unix_millis(1_700_000_000_000);
        let state = ItemState {
            client_handle: 0,
            value: Value::R4(2.5),
            quality: Quality::GOOD,
            timestamp: t,
        };
        fill_live(&mut props, &Ok(state));
        assert_eq!(props[0].value, Value::R4(2.5));
        assert_eq!(props[1].value, Value::I2(0xC0));
        assert_eq!(props[2].value, Value::date_from(t));
        let mut props: Vec<Prop> = [2, 5]
            .iter()
            .map(|&id| property(&v, id, true, &c))
            .collect();
        fill_live(&mut props, &Err(OpcError::NetAnswerTimeout));
        assert_eq!(
            (props[0].error, props[1].error),
            (Some(OpcError::NetAnswerTimeout), None)
        );
    }
}
