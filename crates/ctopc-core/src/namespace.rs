//! The contract between the group/item model and whatever defines which items exist
//! (the asix variable database and item-ID grammar of crate `asix-model`, or a test fake).

use crate::{OpcResult, Value, VarType};

/// OPC access rights bits (OPC_READABLE, OPC_WRITEABLE).
pub const OPC_READABLE: u32 = 1;
pub const OPC_WRITEABLE: u32 = 2;

/// OPC EU type (OPCEUTYPE).
#[derive(Debug, Clone, PartialEq, Default)]
pub enum EuInfo {
    /// OPC_NOENUM: no EU information.
    #[default]
    None,
    /// OPC_ANALOG: [low, high] range; percent deadband applies.
    Analog { low: f64, high: f64 },
    /// OPC_ENUMERATED: the texts of the values 0..n.
    Enumerated(Vec<String>),
}

/// Everything the model needs to know about one resolved item.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemDef {
    /// The item ID as the data source knows it (normalised: e.g. an alias resolved to the variable).
    pub source_key: String,
    /// The channel (resolved access path) the item is read through; `*` for the basic channel.
    pub channel: String,
    /// Canonical data type.
    pub canonical_type: VarType,
    /// OPC_READABLE | OPC_WRITEABLE.
    pub access_rights: u32,
    pub eu: EuInfo,
    /// A constant value (database attribute items): never subscribed at the data source,
    /// reported with quality Good + Limit Constant.
    pub constant: Option<Value>,
}

/// The attribute values behind an item's OPC item properties: descriptions, EU units and
/// info, limits (asix: from the variable database's attribute table). The attributes of
/// an item in a group (OPCITEMATTRIBUTES) are [`crate::model::ItemAttributes`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PropertyAttributes {
    /// `Description` of the variable behind the item (Polish, the asix original).
    pub description: Option<String>,
    /// `DescriptionEn`, when given.
    pub description_en: Option<String>,
    /// EU units (value items: `Unit`; `PercentageCV`: `%`).
    pub eu_units: Option<String>,
    /// EU type with high/low EU (value items with a range; `PercentageCV`: 0..100).
    pub eu: EuInfo,
    /// The variable's numeric warning and alarm limits (value items only), the item
    /// properties 307-310. A limit held in a variable (`KW_Lnnn`) is not a property: it is
    /// read as the item `<var>.<Attr>.CV`.
    pub limits: LimitProps,
}

/// The OPC limit properties: HiHi (307, `AlarmHigh`), Hi (308, `WarnHigh`), Lo (309,
/// `WarnLow`) and LoLo (310, `AlarmLow`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LimitProps {
    pub hihi: Option<f64>,
    pub hi: Option<f64>,
    pub lo: Option<f64>,
    pub lolo: Option<f64>,
}

/// Resolves (item ID, access path) to an item, or to OPC_E_INVALIDITEMID (bad syntax),
/// OPC_E_UNKNOWNITEMID (no such item) or OPC_E_UNKNOWNPATH (no such access path).
pub trait Namespace: Send + Sync {
    fn resolve(&self, item_id: &str, access_path: &str) -> OpcResult<ItemDef>;

    /// Checks a value a client writes to a writable item, after its conversion to the
    /// item's canonical type ([`crate::convert::convert_for_write`]: numeric text, BOOL,
    /// CY and every number convert; for the asix extended write, the value element). The
    /// default accepts every value; asix accepts only integers and reals (OPC_E_BADTYPE
    /// otherwise), which every converted value of an asix variable is.
    fn check_write_value(&self, _value: &Value) -> OpcResult<()> {
        Ok(())
    }

    /// Why writes of an item are refused by design, if they are (an item of a data source
    /// that takes no writes): the reason the log gives beside a refused write. `item_id`
    /// as the source knows it, `access_path` its channel. The default: none.
    fn write_refusal(&self, _item_id: &str, _access_path: &str) -> Option<String> {
        None
    }

    /// Resolves an item with the attribute values behind its OPC item properties
    /// (descriptions, EU units, limits). The default has none.
    fn resolve_with_attributes(
        &self,
        item_id: &str,
        access_path: &str,
    ) -> OpcResult<(ItemDef, PropertyAttributes)> {
        Ok((
            self.resolve(item_id, access_path)?,
            PropertyAttributes::default(),
        ))
    }

    /// The item ID under which property `property_id` of an item can be read as an item
    /// of its own (IOPCItemProperties::LookupItemIDs, `OPCITEMPROPERTY.szItemID`), if it
    /// has one. `item_id` is the ID as the client wrote it and `def` what it resolved to
    /// on the basic channel (property calls have no access path). Called only for
    /// properties the item has (`crate::properties::available_ids`). The default: no
    /// property has an item ID (LookupItemIDs then answers OPC_E_INVALID_PID); asix names
    /// its attribute items (`<V>.DESC`, `<V>.AlarmHigh.CV`, ...).
    fn property_item_id(
        &self,
        _item_id: &str,
        _def: &ItemDef,
        _property_id: u32,
    ) -> Option<String> {
        None
    }
}
