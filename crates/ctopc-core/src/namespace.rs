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

/// Resolves (item ID, access path) to an item, or to OPC_E_INVALIDITEMID (bad syntax),
/// OPC_E_UNKNOWNITEMID (no such item) or OPC_E_UNKNOWNPATH (no such access path).
pub trait Namespace: Send + Sync {
    fn resolve(&self, item_id: &str, access_path: &str) -> OpcResult<ItemDef>;

    /// Checks a value a client writes to a writable item, as the client sent it (before
    /// the conversion to the canonical type; for the asix extended write, the value
    /// element). The default accepts every value; asix accepts only integers and reals
    /// (OPC_E_BADTYPE otherwise).
    fn check_write_value(&self, _value: &Value) -> OpcResult<()> {
        Ok(())
    }
}
