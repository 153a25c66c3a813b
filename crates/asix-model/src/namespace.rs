//! [`AsixNamespace`]: the asix item model behind [`Namespace`]: configuration, the
//! channels' variable databases, item-ID resolution, the browse tree and item attributes.
//!
//! Resolution of `(item ID, access path)`:
//! 1. the access path selects the channel ([`AsixConfig::resolve_channel`]; unknown ->
//!    `OPC_E_UNKNOWNPATH`); database IDs use that channel's database (`ANY...`, `*` and
//!    empty use channel `*`'s; `NEW...` channels have none, so only descriptive IDs work);
//! 2. the ID is parsed ([`parse_item_id`]) with the longest-prefix rule over the visible
//!    (alias) names;
//! 3. the item is built:
//!
//! | ID | type | rights | value | EU |
//! |---|---|---|---|---|
//! | `<V>`, `<V>.CV` | `DataType` (default R4) | R, +W unless `Writable=nie` | live | Analog [RangeFrom, RangeTo] if set |
//! | `<V>.DATA_TYPE` | I2 | R | constant: the VARTYPE code | - |
//! | `<V>.EU_UNIT`, `.DESC` | BSTR | R | constant `Unit`, `Description` | - |
//! | `<V>.HI_EU`, `.LO_EU` | R8 | R | constant `RangeTo`, `RangeFrom`; no range -> unknown item | - |
//! | `<V>.<A>` | R8 if the cell is a number, else BSTR | R | constant cell | - |
//! | `<V>.FormatedCV` | BSTR | R | live, derived | - |
//! | `<V>.PercentageCV` | R8 | R | live, derived; no range -> unknown item | Analog [0, 100] |
//! | `<V>.BarCVs` | R8 array | R | live, derived; no range -> unknown item | - |
//! | `<V>.<A>.CV[.S]`, cell a number n | R8 / BSTR / R8 / R8 array | R | constant: n, formatted by V's `Format`, percent or bars of V's range | - |
//! | `<V>.<A>.CV[.S]`, cell a variable name W | as `W[.S]` | as `W[.S]` | as `W[.S]` | as `W[.S]` |
//! | `asmen.<ch>.<var>.<T>` | T | R+W | live | - |
//!
//! An attribute that is not a column, an empty cell under `.CV`, or a cell naming no
//! variable is `OPC_E_UNKNOWNITEMID`; `.CV.<A2>` on a numeric cell too. Indirect targets
//! are looked up by their asix name (attribute cells hold asix names), hidden (alias-less)
//! variables included.
//!
//! `ItemDef::source_key` is the canonical ID with asix names: `.CV` dropped, aliases and
//! indirections resolved (`LI101.WarnHigh.CV.PercentageCV` -> `KW_L001.PercentageCV`),
//! descriptive IDs as `asmen.<ch>.<var>.<T>`. [`AsixNamespace::live_item`] turns a live
//! source key back into what to subscribe and how to derive the item's value.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use super::config::{AsixConfig, BASIC_CHANNEL};
use super::format::{bar_values, format_value, percentage, value_as_f64, FormatSpec};
use super::itemid::{parse_item_id, ItemId, Suffix, VarItem};
use super::text::{parse_number, Warning};
use super::vardb::{load_database_file, DbError, GroupNode, VarDatabase, Variable};
use ctopc_core::namespace::{EuInfo, ItemDef, Namespace, OPC_READABLE, OPC_WRITEABLE};
pub use ctopc_core::namespace::{LimitProps, PropertyAttributes};
use ctopc_core::properties as p;
use ctopc_core::value::ArrayValue;
use ctopc_core::{OpcError, OpcResult, Value, VarType};

/// The database state of one channel.
#[derive(Debug, Clone)]
pub enum ChannelDatabase {
    /// The channel has no `ItemsDatabase`.
    NotConfigured,
    Loaded(Arc<VarDatabase>),
    /// `ItemsDatabase` is set but could not be loaded.
    Failed(DbError),
}

/// The variable's limits as the OPC limit properties 307-310.
fn limit_props(var: &Variable) -> LimitProps {
    let n = |l: &Option<crate::vardb::Limit>| l.as_ref().and_then(|l| l.value());
    LimitProps {
        hihi: n(&var.alarm_high),
        hi: n(&var.warn_high),
        lo: n(&var.warn_low),
        lolo: n(&var.alarm_low),
    }
}

/// How a live item's value is computed from its asix variable's value.
#[derive(Debug, Clone, PartialEq)]
pub enum Derivation {
    /// The value itself.
    Value,
    /// `FormatedCV`: formatted by the variable's `Format` (default form when `None`).
    /// Boxed: a data source keeps a derivation per subscribed item, and the format is
    /// rare and large (80 bytes a derivation unboxed, 32 boxed).
    Formatted(Option<Box<FormatSpec>>),
    /// `PercentageCV`.
    Percentage { low: f64, high: f64 },
    /// `BarCVs`.
    Bars { low: f64, high: f64, base: f64 },
}

impl Derivation {
    /// The item value for a variable value; `None` when it cannot be derived (non-numeric
    /// value): the caller reports BAD (config error) quality.
    pub fn apply(&self, v: &Value) -> Option<Value> {
        match self {
            Derivation::Value => Some(v.clone()),
            Derivation::Formatted(spec) => format_value(spec.as_deref(), v).map(Value::Bstr),
            Derivation::Percentage { low, high } => {
                percentage(value_as_f64(v)?, *low, *high).map(Value::R8)
            }
            Derivation::Bars { low, high, base } => {
                bar_values(value_as_f64(v)?, *low, *high, *base).map(r8_pair)
            }
        }
    }
}

fn r8_pair(b: [f64; 2]) -> Value {
    Value::Array(ArrayValue {
        element_type: VarType::R8,
        elements: vec![Value::R8(b[0]), Value::R8(b[1])],
    })
}

/// What the data source subscribes for a live item.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveItem {
    /// The asix variable name.
    pub variable: String,
    /// Descriptive IDs: the asix (Asmen) channel; `None` for database variables.
    pub asmen_channel: Option<String>,
    /// The type of the asix variable's value.
    pub var_type: VarType,
    pub derivation: Derivation,
    /// The database definition (quality rules, control variable); `None` for descriptive IDs.
    pub definition: Option<Variable>,
}

/// One node of the browse tree, in pre-order (a branch before its contents).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BrowseNode {
    /// Names from the root; the last is this node's browse name.
    pub path: Vec<String>,
    /// The fully qualified item ID; `None` for groups.
    pub item_id: Option<String>,
    pub is_leaf: bool,
}

/// The asix namespace: configuration plus the channels' databases.
#[derive(Debug, Clone)]
pub struct AsixNamespace {
    config: AsixConfig,
    databases: BTreeMap<String, ChannelDatabase>,
}

const DESCRIPTIVE_RIGHTS: u32 = OPC_READABLE | OPC_WRITEABLE;

impl AsixNamespace {
    /// A namespace with no database loaded (every channel [`ChannelDatabase::NotConfigured`]).
    pub fn new(config: AsixConfig) -> Self {
        AsixNamespace {
            config,
            databases: BTreeMap::new(),
        }
    }

    /// Sets a channel's database state (for callers that load databases themselves).
    pub fn set_database(&mut self, channel: &str, db: ChannelDatabase) {
        self.databases.insert(channel.to_owned(), db);
    }

    /// Loads the database of every channel that names one (channels naming the same file
    /// with the same alias attribute share it). Failures are kept as
    /// [`ChannelDatabase::Failed`]; database warnings are returned for logging.
    pub fn load(config: AsixConfig) -> (Self, Vec<Warning>) {
        let mut ns = AsixNamespace::new(config);
        let mut warnings = Vec::new();
        let mut cache: BTreeMap<(PathBuf, Option<String>), ChannelDatabase> = BTreeMap::new();
        let wanted: Vec<(String, String, Option<String>)> = ns
            .config
            .channels
            .iter()
            .filter_map(|(name, o)| {
                Some((
                    name.clone(),
                    o.items_database.clone()?,
                    o.alias_attribute_name.clone(),
                ))
            })
            .collect();
        for (channel, file, alias) in wanted {
            let key = (ns.config.resolve_path(&file), alias);
            let state = cache
                .entry(key.clone())
                .or_insert_with(|| match load_database_file(&key.0, key.1.as_deref()) {
                    Ok((db, w)) => {
                        warnings.extend(w);
                        ChannelDatabase::Loaded(Arc::new(db))
                    }
                    Err(e) => ChannelDatabase::Failed(e),
                })
                .clone();
            ns.databases.insert(channel, state);
        }
        (ns, warnings)
    }

    pub fn config(&self) -> &AsixConfig {
        &self.config
    }

    /// The database state of a (resolved) channel name.
    pub fn database_state(&self, channel: &str) -> &ChannelDatabase {
        const NONE: &ChannelDatabase = &ChannelDatabase::NotConfigured;
        self.databases.get(channel).unwrap_or(NONE)
    }

    /// The loaded database of a (resolved) channel name.
    pub fn database(&self, channel: &str) -> Option<&Arc<VarDatabase>> {
        match self.database_state(channel) {
            ChannelDatabase::Loaded(db) => Some(db),
            _ => None,
        }
    }

    /// Every loaded database once (channels may share one), in the order of the
    /// configuration's channels.
    pub fn databases(&self) -> impl Iterator<Item = &Arc<VarDatabase>> + '_ {
        let mut seen = std::collections::HashSet::new();
        self.config
            .channels
            .keys()
            .filter_map(|name| self.database(name))
            .filter(move |db| seen.insert(Arc::as_ptr(db)))
    }

    /// Why the server runs without configuration (`OPC_STATUS_NOCONFIG`): `None` when
    /// channel `*` has its database, else the reason for the log.
    pub fn no_config_reason(&self) -> Option<String> {
        match self.database_state(BASIC_CHANNEL) {
            ChannelDatabase::Loaded(_) => None,
            ChannelDatabase::NotConfigured => {
                Some("no ItemsDatabase is configured for channel *".to_owned())
            }
            ChannelDatabase::Failed(e) => Some(e.to_string()),
        }
    }

    /// Resolves an item and its attribute values (see the module documentation). The
    /// items of a channel that reads from Asix.Evo REST servers are read-only
    /// (`OPC_READABLE`): the REST API documents no write request.
    pub fn resolve_with_attributes(
        &self,
        item_id: &str,
        access_path: &str,
    ) -> OpcResult<(ItemDef, PropertyAttributes)> {
        let (mut def, attrs) = self.resolve_item(item_id, access_path)?;
        if self
            .config
            .resolve_channel(access_path)?
            .options
            .is_asix_evo_rest()
        {
            def.access_rights &= !OPC_WRITEABLE;
        }
        Ok((def, attrs))
    }

    fn resolve_item(
        &self,
        item_id: &str,
        access_path: &str,
    ) -> OpcResult<(ItemDef, PropertyAttributes)> {
        let channel = self.config.resolve_channel(access_path)?;
        let db = self.database(channel.name).map(Arc::as_ref);
        let id = parse_item_id(item_id, |n| {
            db.is_some_and(|db| db.find_public_index(n).is_some())
        })?;
        let ctx = Ctx {
            channel: channel.name,
        };
        match (id, db) {
            (ItemId::Descriptive(d), _) => {
                let def = ItemDef {
                    source_key: ItemId::Descriptive(d.clone()).to_string(),
                    channel: channel.name.to_owned(),
                    canonical_type: d.var_type.var_type(),
                    access_rights: DESCRIPTIVE_RIGHTS,
                    eu: EuInfo::None,
                    constant: None,
                };
                Ok((def, PropertyAttributes::default()))
            }
            (ItemId::Variable { variable, item }, Some(db)) => {
                let var = db
                    .find_public_index(&variable)
                    .map(|i| decoded(db, i))
                    .ok_or(OpcError::UnknownItemId)?;
                match item {
                    VarItem::Direct(s) => ctx.suffix_item(db, &var, &s),
                    VarItem::ViaAttribute { attribute, then } => {
                        let cell = db
                            .attribute(&var, &attribute)
                            .ok_or(OpcError::UnknownItemId)?
                            .trim();
                        if cell.is_empty() {
                            return Err(OpcError::UnknownItemId);
                        }
                        if let Some(n) = parse_number(cell) {
                            return ctx.numeric_attribute_item(&var, &attribute, n, then.as_ref());
                        }
                        let target = db
                            .find_real_index(cell)
                            .map(|i| decoded(db, i))
                            .ok_or(OpcError::UnknownItemId)?;
                        ctx.suffix_item(db, &target, then.as_ref().unwrap_or(&Suffix::Value))
                    }
                }
            }
            // Parsing found a variable, so there is a database; kept total for safety.
            (ItemId::Variable { .. }, None) => Err(OpcError::UnknownItemId),
        }
    }

    /// The OPC item-property values of an item.
    pub fn item_attributes(
        &self,
        item_id: &str,
        access_path: &str,
    ) -> OpcResult<PropertyAttributes> {
        self.resolve_with_attributes(item_id, access_path)
            .map(|(_, a)| a)
    }

    /// What to subscribe for a live item: `channel` and `source_key` as in its [`ItemDef`].
    /// `None` for constants and unknown keys.
    pub fn live_item(&self, channel: &str, source_key: &str) -> Option<LiveItem> {
        let db = self.database(channel).map(Arc::as_ref);
        let id = parse_item_id(source_key, |n| {
            db.is_some_and(|db| db.find_real_index(n).is_some())
        })
        .ok()?;
        match id {
            ItemId::Descriptive(d) => Some(LiveItem {
                variable: d.variable,
                asmen_channel: Some(d.channel),
                var_type: d.var_type.var_type(),
                derivation: Derivation::Value,
                definition: None,
            }),
            ItemId::Variable {
                variable,
                item: VarItem::Direct(s),
            } => {
                let db = db?;
                let var = decoded(db, db.find_real_index(&variable)?);
                let derivation = match s {
                    Suffix::Value => Derivation::Value,
                    Suffix::Formatted => Derivation::Formatted(var.format.clone().map(Box::new)),
                    Suffix::Percentage => {
                        let (low, high) = var.range?;
                        Derivation::Percentage { low, high }
                    }
                    Suffix::Bars => {
                        let (low, high) = var.range?;
                        Derivation::Bars {
                            low,
                            high,
                            base: var.effective_bar_base()?,
                        }
                    }
                    _ => return None,
                };
                Some(LiveItem {
                    variable: var.name.clone(),
                    asmen_channel: None,
                    var_type: var.data_type,
                    derivation,
                    definition: Some(var),
                })
            }
            ItemId::Variable { .. } => None,
        }
    }

    /// The browse tree of channel `*`'s database, in pre-order: groups are branches,
    /// variables leaves; with `AttributesAsItems` variables are branches with the leaves
    /// `CV`, `DESC`, `EU_UNIT`, `HI_EU`, `LO_EU` (the last two only with a range).
    /// Groups without visible variables are left out. Empty without a database.
    pub fn browse_nodes(&self) -> impl Iterator<Item = BrowseNode> {
        let mut out = Vec::new();
        let _ = self.walk_browse_tree(|path, item_id, is_leaf| {
            out.push(BrowseNode {
                path: path.iter().map(|s| (*s).to_owned()).collect(),
                item_id: item_id.map(str::to_owned),
                is_leaf,
            });
            Ok::<(), std::convert::Infallible>(())
        });
        out.into_iter()
    }

    /// [`AsixNamespace::browse_nodes`] without copies: calls `visit(path, item_id,
    /// is_leaf)` for each node in the same pre-order, with names borrowed from the
    /// database. An error of `visit` ends the walk.
    pub fn walk_browse_tree<E>(
        &self,
        mut visit: impl FnMut(&[&str], Option<&str>, bool) -> Result<(), E>,
    ) -> Result<(), E> {
        match self.database(BASIC_CHANNEL) {
            Some(db) => {
                let mut path = Vec::new();
                walk(
                    db,
                    &db.root,
                    &mut path,
                    self.config.server.attributes_as_items,
                    &mut visit,
                )
            }
            None => Ok(()),
        }
    }
}

/// Groups with no (visible) variable anywhere below are not browsed.
fn has_variables(g: &GroupNode) -> bool {
    !g.variables.is_empty() || g.groups.iter().any(has_variables)
}

fn walk<'a, E>(
    db: &'a VarDatabase,
    node: &'a GroupNode,
    path: &mut Vec<&'a str>,
    attributes_as_items: bool,
    visit: &mut impl FnMut(&[&str], Option<&str>, bool) -> Result<(), E>,
) -> Result<(), E> {
    for g in node.groups.iter().filter(|g| has_variables(g)) {
        path.push(&g.name);
        visit(path, None, false)?;
        walk(db, g, path, attributes_as_items, visit)?;
        path.pop();
    }
    for &i in &node.variables {
        let var = db.variables.view(i as usize);
        let name = var.public_name();
        path.push(name);
        visit(path, Some(name), !attributes_as_items)?;
        if attributes_as_items {
            let mut leaves = vec!["CV", "DESC", "EU_UNIT"];
            if var.range().is_some() {
                leaves.extend(["HI_EU", "LO_EU"]);
            }
            for leaf in leaves {
                path.push(leaf);
                visit(path, Some(&format!("{name}.{leaf}")), true)?;
                path.pop();
            }
        }
        path.pop();
    }
    Ok(())
}

/// Variable `i` of `db`, decoded for one resolution and not kept: [`VarDatabase::find_public`]
/// keeps every variable it decodes (about 1.2 KB each), so resolving through it would make
/// every item a client ever added cost that much for the life of the server.
fn decoded(db: &VarDatabase, i: usize) -> Variable {
    db.variables.view(i).decode()
}

struct Ctx<'a> {
    channel: &'a str,
}

impl Ctx<'_> {
    fn def(
        &self,
        source_key: String,
        canonical_type: VarType,
        access_rights: u32,
        eu: EuInfo,
        constant: Option<Value>,
    ) -> ItemDef {
        ItemDef {
            source_key,
            channel: self.channel.to_owned(),
            canonical_type,
            access_rights,
            eu,
            constant,
        }
    }

    fn constant(&self, key: String, value: Value) -> ItemDef {
        self.def(
            key,
            value.var_type(),
            OPC_READABLE,
            EuInfo::None,
            Some(value),
        )
    }

    fn attrs(var: &Variable) -> PropertyAttributes {
        let opt = |s: &str| (!s.is_empty()).then(|| s.to_owned());
        PropertyAttributes {
            description: opt(&var.description),
            description_en: opt(&var.description_en),
            eu_units: None,
            eu: EuInfo::None,
            limits: LimitProps::default(),
        }
    }

    fn suffix_item(
        &self,
        db: &VarDatabase,
        var: &Variable,
        s: &Suffix,
    ) -> OpcResult<(ItemDef, PropertyAttributes)> {
        let key = |suffix: &str| format!("{}.{suffix}", var.name);
        let mut attrs = Self::attrs(var);
        let range = var.range;
        let def = match s {
            Suffix::Value => {
                let eu = range.map_or(EuInfo::None, |(low, high)| EuInfo::Analog { low, high });
                attrs.eu_units = (!var.unit.is_empty()).then(|| var.unit.clone());
                attrs.eu = eu.clone();
                attrs.limits = limit_props(var);
                let rights = if var.writable {
                    OPC_READABLE | OPC_WRITEABLE
                } else {
                    OPC_READABLE
                };
                self.def(var.name.clone(), var.data_type, rights, eu, None)
            }
            Suffix::DataType => self.constant(key("DATA_TYPE"), Value::I2(var.data_type.0 as i16)),
            Suffix::EuUnit => self.constant(key("EU_UNIT"), Value::Bstr(var.unit.clone())),
            Suffix::Desc => self.constant(key("DESC"), Value::Bstr(var.description.clone())),
            Suffix::HiEu => self.constant(
                key("HI_EU"),
                Value::R8(range.ok_or(OpcError::UnknownItemId)?.1),
            ),
            Suffix::LoEu => self.constant(
                key("LO_EU"),
                Value::R8(range.ok_or(OpcError::UnknownItemId)?.0),
            ),
            Suffix::Formatted => self.def(
                key("FormatedCV"),
                VarType::BSTR,
                OPC_READABLE,
                EuInfo::None,
                None,
            ),
            Suffix::Percentage => {
                range.ok_or(OpcError::UnknownItemId)?;
                let eu = EuInfo::Analog {
                    low: 0.0,
                    high: 100.0,
                };
                attrs.eu_units = Some("%".to_owned());
                attrs.eu = eu.clone();
                self.def(key("PercentageCV"), VarType::R8, OPC_READABLE, eu, None)
            }
            Suffix::Bars => {
                range.ok_or(OpcError::UnknownItemId)?;
                self.def(
                    key("BarCVs"),
                    VarType::array_of(VarType::R8),
                    OPC_READABLE,
                    EuInfo::None,
                    None,
                )
            }
            Suffix::Attribute(a) => {
                let cell = db.attribute(var, a).ok_or(OpcError::UnknownItemId)?;
                let value = match parse_number(cell) {
                    Some(n) => Value::R8(n),
                    None => Value::Bstr(cell.to_owned()),
                };
                self.constant(key(a), value)
            }
        };
        Ok((def, attrs))
    }

    fn numeric_attribute_item(
        &self,
        var: &Variable,
        attribute: &str,
        n: f64,
        then: Option<&Suffix>,
    ) -> OpcResult<(ItemDef, PropertyAttributes)> {
        let key = format!("{}.{attribute}.CV", var.name);
        let attrs = Self::attrs(var);
        let def = match then {
            None => self.constant(key, Value::R8(n)),
            Some(Suffix::Formatted) => {
                let text = format_value(var.format.as_ref(), &Value::R8(n))
                    .ok_or(OpcError::UnknownItemId)?;
                self.constant(key + ".FormatedCV", Value::Bstr(text))
            }
            Some(Suffix::Percentage) => {
                let (low, high) = var.range.ok_or(OpcError::UnknownItemId)?;
                let p = percentage(n, low, high).ok_or(OpcError::UnknownItemId)?;
                self.constant(key + ".PercentageCV", Value::R8(p))
            }
            Some(Suffix::Bars) => {
                let (low, high) = var.range.ok_or(OpcError::UnknownItemId)?;
                let base = var.effective_bar_base().ok_or(OpcError::UnknownItemId)?;
                let b = bar_values(n, low, high, base).ok_or(OpcError::UnknownItemId)?;
                self.constant(key + ".BarCVs", r8_pair(b))
            }
            Some(_) => return Err(OpcError::UnknownItemId),
        };
        Ok((def, attrs))
    }
}

impl Namespace for AsixNamespace {
    fn resolve(&self, item_id: &str, access_path: &str) -> OpcResult<ItemDef> {
        self.resolve_with_attributes(item_id, access_path)
            .map(|(def, _)| def)
    }

    /// The items of a channel that reads from Asix.Evo REST servers: the REST API
    /// documents no write request.
    fn write_refusal(&self, _item_id: &str, access_path: &str) -> Option<String> {
        let channel = self.config.resolve_channel(access_path).ok()?;
        channel.options.is_asix_evo_rest().then(|| {
            format!(
                "channel {} reads from Asix.Evo REST servers, whose API documents no write \
                 request: its items are read-only",
                channel.name
            )
        })
    }

    fn resolve_with_attributes(
        &self,
        item_id: &str,
        access_path: &str,
    ) -> OpcResult<(ItemDef, PropertyAttributes)> {
        AsixNamespace::resolve_with_attributes(self, item_id, access_path)
    }

    /// AsixConnect §5: values written must be integer or real.
    fn check_write_value(&self, value: &Value) -> OpcResult<()> {
        super::quality_rules::check_write_value(value)
    }

    /// The asix attribute items of properties 100-103 and 307-310: see
    /// [`property_item_id_via`].
    fn property_item_id(&self, item_id: &str, def: &ItemDef, property_id: u32) -> Option<String> {
        property_item_id_via(
            |id| Namespace::resolve(self, id, ""),
            item_id,
            def,
            property_id,
        )
    }
}

/// The asix item-ID suffixes of the properties that are attribute items of a variable
/// (`<V>.<suffix>`): EU units, description, high and low EU, and the numeric warning and
/// alarm limits as items (`<V>.<Attr>.CV`, a constant).
pub const PROPERTY_ITEM_SUFFIXES: [(u32, &str); 8] = [
    (p::OPC_PROPERTY_EU_UNITS, "EU_UNIT"),
    (p::OPC_PROPERTY_DESCRIPTION, "DESC"),
    (p::OPC_PROPERTY_HIGH_EU, "HI_EU"),
    (p::OPC_PROPERTY_LOW_EU, "LO_EU"),
    (p::OPC_PROPERTY_HIHI_LIMIT, "AlarmHigh.CV"),
    (p::OPC_PROPERTY_HI_LIMIT, "WarnHigh.CV"),
    (p::OPC_PROPERTY_LO_LIMIT, "WarnLow.CV"),
    (p::OPC_PROPERTY_LOLO_LIMIT, "AlarmLow.CV"),
];

/// The item ID of property `property_id` of the item `item_id` (resolved to `def`), with
/// `resolve` resolving on the basic channel: `<V>.<suffix>` ([`PROPERTY_ITEM_SUFFIXES`])
/// for the value items of database variables (`<V>` and `<V>.CV`, aliases included: live,
/// keyed by the bare asix name) when that ID resolves; `None` for every other property
/// and item.
pub fn property_item_id_via(
    resolve: impl Fn(&str) -> OpcResult<ItemDef>,
    item_id: &str,
    def: &ItemDef,
    property_id: u32,
) -> Option<String> {
    let (_, suffix) = PROPERTY_ITEM_SUFFIXES
        .iter()
        .find(|(id, _)| *id == property_id)?;
    // Only the value items of database variables: live, keyed by the bare asix name.
    if def.constant.is_some() || def.source_key.contains('.') {
        return None;
    }
    let base = item_id.strip_suffix(".CV").unwrap_or(item_id);
    let same = resolve(base).is_ok_and(|d| d.source_key == def.source_key && d.constant.is_none());
    if !same {
        return None;
    }
    let candidate = format!("{base}.{suffix}");
    resolve(&candidate).is_ok().then_some(candidate)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ctopc_core::properties::{lookup_item_ids, static_properties, PropertyContext};
    use ctopc_core::Lang;

    /// The namespace of the property tests: `V` (alias `A`) and some of its attribute
    /// items.
    fn fake(item_id: &str) -> OpcResult<ItemDef> {
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
        match item_id {
            "V" | "V.CV" | "A" => Ok(var("V")),
            "V.DESC" | "V.EU_UNIT" | "V.HI_EU" | "V.LO_EU" | "A.DESC" | "V.AlarmHigh.CV"
            | "V.WarnLow.CV" => {
                let mut d = var(item_id);
                d.constant = Some(Value::Bstr("x".into()));
                Ok(d)
            }
            "V.PercentageCV" => Ok(var("V.PercentageCV")),
            "" | "V." => Err(OpcError::InvalidItemId),
            _ => Err(OpcError::UnknownItemId),
        }
    }

    fn id_of(item_id: &str, property_id: u32) -> Option<String> {
        let def = fake(item_id).unwrap();
        property_item_id_via(fake, item_id, &def, property_id)
    }

    #[test]
    fn item_ids_of_attribute_properties() {
        assert_eq!(id_of("V.CV", 101).as_deref(), Some("V.DESC"));
        assert_eq!(id_of("V.CV", 100).as_deref(), Some("V.EU_UNIT"));
        assert_eq!(id_of("V.CV", 2), None);
        assert_eq!(id_of("V.CV", 307).as_deref(), Some("V.AlarmHigh.CV"));
        assert_eq!(id_of("V.CV", 309).as_deref(), Some("V.WarnLow.CV"));
        assert_eq!(
            id_of("V.CV", 308),
            None,
            "V.WarnHigh.CV does not resolve here"
        );
        assert_eq!(id_of("A", 101).as_deref(), Some("A.DESC"));
        assert_eq!(id_of("A", 100), None, "A.EU_UNIT does not resolve");
        assert_eq!(id_of("V.PercentageCV", 100), None);
    }

    #[test]
    fn attribute_items_and_unknown_properties_have_no_item_ids() {
        // A constant (an attribute item) has none, even where `<id>.<suffix>` resolves.
        assert_eq!(id_of("V.DESC", 101), None);
        for id in [1, 3, 4, 5, 6, 7, 8, 104, 311, 9999] {
            assert_eq!(id_of("V", id), None, "{id}");
        }
        let ids: Vec<u32> = PROPERTY_ITEM_SUFFIXES.iter().map(|(id, _)| *id).collect();
        assert_eq!(ids, [100, 101, 102, 103, 307, 308, 309, 310]);
    }

    fn demo() -> AsixNamespace {
        crate::embedded_demo().expect("the embedded demo").namespace
    }

    #[test]
    fn items_of_an_asix_evo_rest_channel_are_read_only() {
        let base = demo();
        let mut cfg = base.config().clone();
        let mut evo = cfg.basic().clone();
        evo.asix_evo_rest = vec!["http://evo".into()];
        cfg.channels.insert("EVO".into(), evo);
        let mut ns = AsixNamespace::new(cfg);
        ns.set_database("*", base.database_state("*").clone());
        ns.set_database("EVO", base.database_state("*").clone());
        let writable = base
            .database("*")
            .unwrap()
            .variables
            .views()
            .map(|v| v.public_name().to_owned())
            .find(|n| {
                ns.resolve_with_attributes(n, "*")
                    .is_ok_and(|(d, _)| d.access_rights == OPC_READABLE | OPC_WRITEABLE)
            })
            .expect("a writable demo variable");
        for id in [writable.as_str(), "ASMEN.K.v.ui1"] {
            let (net, _) = ns.resolve_with_attributes(id, "*").unwrap();
            assert_eq!(net.access_rights, OPC_READABLE | OPC_WRITEABLE, "{id}");
            let (rest, _) = ns.resolve_with_attributes(id, "EVO").unwrap();
            assert_eq!(rest.access_rights, OPC_READABLE, "{id}");
            // The log says why a write of it is refused; the network channel's items
            // have no such reason.
            let why = Namespace::write_refusal(&ns, id, "EVO").expect("a reason");
            assert!(
                why.contains("EVO") && why.contains("Asix.Evo REST"),
                "{why}"
            );
            assert_eq!(Namespace::write_refusal(&ns, id, "*"), None);
        }
    }

    #[test]
    fn demo_property_item_ids_and_lookup() {
        let ns = demo();
        let cx = PropertyContext {
            ns: &ns,
            lang: Lang::English,
            scan_rate_ms: 1000,
        };
        let got =
            lookup_item_ids(&cx, "KW_A000", &[1, 100, 101, 102, 103, 9999, 2, 307, 310]).unwrap();
        assert_eq!(
            got,
            [
                Err(OpcError::InvalidPid),
                Ok("KW_A000.EU_UNIT".to_owned()),
                Ok("KW_A000.DESC".to_owned()),
                Ok("KW_A000.HI_EU".to_owned()),
                Ok("KW_A000.LO_EU".to_owned()),
                Err(OpcError::InvalidPid),
                Err(OpcError::InvalidPid),
                Ok("KW_A000.AlarmHigh.CV".to_owned()),
                Ok("KW_A000.AlarmLow.CV".to_owned()),
            ]
        );
        assert_eq!(
            lookup_item_ids(&cx, "KW_A000.CV", &[101]).unwrap(),
            [Ok("KW_A000.DESC".to_owned())]
        );
        // The attribute item itself has no property item IDs.
        assert_eq!(
            lookup_item_ids(&cx, "KW_A000.DESC", &[101]).unwrap(),
            [Err(OpcError::InvalidPid)]
        );
        assert_eq!(
            lookup_item_ids(&cx, "NO_SUCH_VARIABLE", &[101]),
            Err(OpcError::UnknownItemId)
        );
    }

    #[test]
    fn demo_limits_are_properties_of_value_items_only() {
        let ns = demo();
        let cx = PropertyContext {
            ns: &ns,
            lang: Lang::English,
            scan_rate_ms: 1000,
        };
        let values = |item_id: &str, ids: &[u32]| -> Vec<Option<Value>> {
            static_properties(&cx, item_id, Some(ids), true)
                .unwrap()
                .into_iter()
                .map(|p| p.error.is_none().then_some(p.value))
                .collect()
        };
        let limits = [307, 308, 309, 310];
        assert_eq!(
            values("KW_A000", &limits),
            [7.5, 7.0, 1.0, 0.5].map(|x| Some(Value::R8(x)))
        );
        // A limit held in a variable is no property.
        assert_eq!(
            values("KW_A100", &[308, 309]),
            [None, Some(Value::R8(900.0))]
        );
        // Attribute items (constants) and derived items have none.
        for id in ["KW_A000.DESC", "KW_A000.HI_EU", "KW_A000.PercentageCV"] {
            assert_eq!(values(id, &limits), [None, None, None, None], "{id}");
        }
    }
}
