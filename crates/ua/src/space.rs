//! The lazy address space: what a NodeId of our namespace names, its attributes and its
//! references, answered from the namespace (`ctopc_core::namespace::Namespace`) and the
//! browse tree (`ctopc_core::browse::AddressSpace`) on each request. No node object is
//! kept per variable.
//!
//! NodeIds (`ns` = our namespace index):
//! - `ns;i=1`: the `ServerCTOPC` folder, organized by the Objects folder;
//! - `ns;s=<item ID>`: a branch of the browse tree that is not an item (a FolderType
//!   object), or an item (a variable: AnalogItemType when it has an analog EU range or
//!   units, DataItemType otherwise). Any item ID the namespace resolves is a variable,
//!   browsed or not: an item ID and a NodeId name the same thing;
//! - the derived items of a variable's value item `<V>` ([`DERIVED`]: `<V>.FormatedCV`,
//!   `<V>.PercentageCV`, `<V>.BarCVs`, the limit attributes' `<V>.<A>.CV`) are its
//!   components (HasComponent), those of them the namespace resolves, named by their
//!   suffix;
//! - `ns;s=_Diagnostics...`: the `_Diagnostics` branch (`ctopc_core::diagnostics`),
//!   organized by the `ServerCTOPC` folder before the real branches: its branches are
//!   folders of the board's current tree, its items variables like any other;
//! - `ns;b=<DA property ID, 4 bytes little-endian><item ID>`: a property of an item
//!   (HasProperty, PropertyType): `EURange` (DA 102/103), `EngineeringUnits` (100), and
//!   every other DA property the item has beyond those that are attributes (1-6:
//!   DataType, Value, AccessLevel, MinimumSamplingInterval; 101: Description).
//!
//! Texts come in the language each call is given (the session's: see the node manager),
//! their LocalizedText's locale saying which (`pl`, `en`): Descriptions of variables
//! (theirs, a derived item's its variable's), of the `ServerCTOPC` folder and of the
//! `_Diagnostics` branches and items, and the properties' DisplayName and Description
//! (the DA property's description). Names (BrowseNames, variables' and folders'
//! DisplayNames) are the same in every language.

use crate::value::{data_type, to_variant};
use ctopc_core::browse::{AddressSpace, NodeRef};
use ctopc_core::diagnostics::{self, branch_description, is_diagnostic_id, Board};
use ctopc_core::lang::Lang;
use ctopc_core::namespace::{EuInfo, ItemDef, Namespace, OPC_WRITEABLE};
use ctopc_core::properties::{self as props, ItemInfo, PropertyContext};
use opcua::nodes::AccessLevel;
use opcua::types::{
    AttributeId, ByteString, EUInformation, ExtensionObject, Identifier, LocalizedText, NodeClass,
    NodeId, ObjectId, ObjectTypeId, QualifiedName, Range, ReferenceTypeId, StatusCode, UAString,
    VariableTypeId, Variant,
};
use std::sync::Arc;

/// The numeric id of the `ServerCTOPC` folder in our namespace.
pub const ROOT_ID: u32 = 1;
/// The browse name of that folder.
pub const ROOT_NAME: &str = "ServerCTOPC";
/// The namespace URI of the address space.
pub const NAMESPACE_URI: &str = "urn:askom:ServerCTOPC";
/// The description of that folder, in Polish and in English.
pub const ROOT_DESCRIPTION: [&str; 2] = [
    "Zmienne systemu asix udostępniane przez ServerCTOPC",
    "The asix system's variables served by ServerCTOPC",
];

/// The suffixes of the derived items of a variable's value item `<V>`, served as its
/// components (`<V>.<suffix>`), in this order: the value formatted by `Format`, the
/// percentage of the range, the bar values, and the current values of the limit
/// attributes (a number, or the value of the variable the attribute names).
pub const DERIVED: [&str; 7] = [
    "FormatedCV",
    "PercentageCV",
    "BarCVs",
    "AlarmHigh.CV",
    "WarnHigh.CV",
    "WarnLow.CV",
    "AlarmLow.CV",
];

/// True for the value item of a variable (live, keyed by a bare variable name), the
/// items that have derived items.
fn is_value_item(def: &ItemDef) -> bool {
    def.constant.is_none() && !def.source_key.contains('.')
}

/// DA property IDs served as UA attributes, not as property nodes.
const ATTRIBUTE_PROPERTIES: [u32; 9] = [
    props::OPC_PROPERTY_DATATYPE,
    props::OPC_PROPERTY_VALUE,
    props::OPC_PROPERTY_QUALITY,
    props::OPC_PROPERTY_TIMESTAMP,
    props::OPC_PROPERTY_ACCESS_RIGHTS,
    props::OPC_PROPERTY_SCAN_RATE,
    props::OPC_PROPERTY_DESCRIPTION,
    // EURange stands for both.
    props::OPC_PROPERTY_LOW_EU,
    props::OPC_PROPERTY_EU_INFO,
];

/// What a NodeId of our namespace names.
#[derive(Debug, Clone, PartialEq)]
pub enum Parsed {
    Root,
    /// An item ID (a branch or a variable).
    Item(String),
    /// A property (DA property ID) of an item.
    Property(u32, String),
}

/// A node's identity, for references and the browse results.
#[derive(Debug, Clone)]
pub struct Meta {
    pub node_id: NodeId,
    pub node_class: NodeClass,
    pub browse_name: QualifiedName,
    pub display_name: LocalizedText,
    pub type_definition: NodeId,
}

/// One reference from a node.
#[derive(Debug, Clone)]
pub struct Reference {
    pub reference_type: NodeId,
    pub forward: bool,
    pub target: Meta,
}

/// The resolved kind of an item node.
#[derive(Debug, Clone)]
pub enum Resolved {
    Root,
    Folder(String),
    Variable(Box<ItemInfo>),
    Property(u32, Box<ItemInfo>),
}

/// The lazy address space over a namespace and its browse tree.
pub struct Space {
    pub ns: u16,
    pub namespace: Arc<dyn Namespace>,
    pub tree: Arc<AddressSpace>,
    /// The server scan rate (the engine's minimum update rate), ms: MinimumSamplingInterval.
    pub scan_rate_ms: u32,
    /// The `_Diagnostics` board: the branch's current browse tree.
    pub diag: Arc<Board>,
}

impl Space {
    pub fn parse(&self, id: &NodeId) -> Option<Parsed> {
        if id.namespace != self.ns {
            return None;
        }
        match &id.identifier {
            Identifier::Numeric(n) if *n == ROOT_ID => Some(Parsed::Root),
            Identifier::String(s) if !s.is_empty() => Some(Parsed::Item(s.as_ref().to_owned())),
            Identifier::ByteString(b) => {
                let bytes = b.value.as_deref()?;
                if bytes.len() <= 4 {
                    return None;
                }
                let pid = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
                let item = std::str::from_utf8(&bytes[4..]).ok()?;
                Some(Parsed::Property(pid, item.to_owned()))
            }
            _ => None,
        }
    }

    pub fn item_node_id(&self, item_id: &str) -> NodeId {
        NodeId::new(self.ns, UAString::from(item_id))
    }

    pub fn property_node_id(&self, pid: u32, item_id: &str) -> NodeId {
        let mut bytes = pid.to_le_bytes().to_vec();
        bytes.extend_from_slice(item_id.as_bytes());
        NodeId::new(self.ns, ByteString::from(bytes))
    }

    fn cx(&self, lang: Lang) -> PropertyContext<'_> {
        PropertyContext {
            ns: &*self.namespace,
            lang,
            scan_rate_ms: self.scan_rate_ms,
        }
    }

    /// The node a NodeId names, or Bad_NodeIdUnknown.
    pub fn resolve(&self, id: &NodeId) -> Result<Resolved, StatusCode> {
        match self.parse(id).ok_or(StatusCode::BadNodeIdUnknown)? {
            Parsed::Root => Ok(Resolved::Root),
            Parsed::Item(item) => {
                if let Some(n) = self.tree_of(&item).find_item_id(&item) {
                    if !n.is_item() {
                        return Ok(Resolved::Folder(item));
                    }
                }
                let info = props::resolve_item(&self.cx(Lang::English), &item)
                    .map_err(|_| StatusCode::BadNodeIdUnknown)?;
                Ok(Resolved::Variable(Box::new(info)))
            }
            Parsed::Property(pid, item) => {
                let info = props::resolve_item(&self.cx(Lang::English), &item)
                    .map_err(|_| StatusCode::BadNodeIdUnknown)?;
                if !self.property_ids(&info).contains(&pid) {
                    return Err(StatusCode::BadNodeIdUnknown);
                }
                Ok(Resolved::Property(pid, Box::new(info)))
            }
        }
    }

    /// The item a node's Value attribute reads when the node names one of our items (a
    /// string NodeId of our namespace), without resolving the item's attributes: the
    /// engine resolves it again when it reads, and answers an unknown one. What else the
    /// node is (a folder, a property, nothing) is [`Space::resolve`]'s to say, which the
    /// caller asks when the engine does not know the item.
    pub fn value_item(&self, id: &NodeId) -> Option<String> {
        match self.parse(id)? {
            Parsed::Item(item) => Some(item),
            Parsed::Root | Parsed::Property(..) => None,
        }
    }

    /// The browse tree an item ID belongs to: the `_Diagnostics` branch's current tree, or
    /// the real one.
    fn tree_of(&self, item_id: &str) -> Arc<AddressSpace> {
        if is_diagnostic_id(item_id) {
            self.diag.space()
        } else {
            Arc::clone(&self.tree)
        }
    }

    /// The derived items of an item that the namespace resolves (none unless it is a
    /// variable's value item), with their suffixes.
    pub fn derived_children(&self, info: &ItemInfo) -> Vec<(String, &'static str)> {
        if !is_value_item(&info.def) || is_diagnostic_id(&info.item_id) {
            return Vec::new();
        }
        DERIVED
            .iter()
            .map(|s| (format!("{}.{s}", info.item_id), *s))
            .filter(|(id, _)| self.namespace.resolve(id, "").is_ok())
            .collect()
    }

    /// The value item a derived item belongs to, and the derived item's suffix.
    pub fn derived_parent(&self, item_id: &str) -> Option<(String, &'static str)> {
        DERIVED.iter().find_map(|s| {
            let base = item_id.strip_suffix(s)?.strip_suffix('.')?;
            let def = self.namespace.resolve(base, "").ok()?;
            is_value_item(&def).then(|| (base.to_owned(), *s))
        })
    }

    /// The DA properties of an item served as property nodes (EURange for 102/103).
    pub fn property_ids(&self, info: &ItemInfo) -> Vec<u32> {
        props::available_ids(info, Lang::English)
            .into_iter()
            .filter(|id| !ATTRIBUTE_PROPERTIES.contains(id))
            .collect()
    }

    fn is_analog(info: &ItemInfo) -> bool {
        matches!(info.attrs.eu, EuInfo::Analog { .. })
            || info
                .attrs
                .eu_units
                .as_deref()
                .is_some_and(|u| !u.is_empty())
    }

    fn property_name(pid: u32) -> String {
        match pid {
            props::OPC_PROPERTY_HIGH_EU => "EURange".into(),
            props::OPC_PROPERTY_EU_UNITS => "EngineeringUnits".into(),
            _ => props::property_info(pid)
                .map(|p| p.description(Lang::English).replace(' ', ""))
                .unwrap_or_else(|| format!("Property{pid}")),
        }
    }

    /// The display name of a property node in `lang`: the DA property's description
    /// (`EURange` and `EngineeringUnits`, OPC UA's own properties, keep their names).
    fn property_display_name(pid: u32, lang: Lang) -> LocalizedText {
        match pid {
            props::OPC_PROPERTY_HIGH_EU | props::OPC_PROPERTY_EU_UNITS => {
                LocalizedText::new("", &Self::property_name(pid))
            }
            _ => match props::property_info(pid) {
                Some(p) => LocalizedText::new(lang.locale_id(), p.description(lang)),
                None => LocalizedText::new("", &Self::property_name(pid)),
            },
        }
    }

    /// The browse name and display name of a tree node (or of an item not in the tree).
    fn item_names(&self, item_id: &str) -> String {
        match self.tree_of(item_id).find_item_id(item_id) {
            Some(n) if !n.is_root() => n.name().to_owned(),
            _ => match self.derived_parent(item_id) {
                Some((_, suffix)) => suffix.to_owned(),
                None => item_id.to_owned(),
            },
        }
    }

    /// The identity of the variable `item_id` under the name `name`.
    fn variable_meta(&self, item_id: &str, name: &str) -> Meta {
        let analog = self
            .namespace
            .resolve_with_attributes(item_id, "")
            .map(|(_, attrs)| {
                matches!(attrs.eu, EuInfo::Analog { .. })
                    || attrs.eu_units.as_deref().is_some_and(|u| !u.is_empty())
            })
            .unwrap_or(false);
        let ty = if analog {
            VariableTypeId::AnalogItemType
        } else {
            VariableTypeId::DataItemType
        };
        Meta {
            node_id: self.item_node_id(item_id),
            node_class: NodeClass::Variable,
            browse_name: QualifiedName::new(self.ns, name),
            display_name: LocalizedText::new("", name),
            type_definition: ty.into(),
        }
    }

    pub fn root_meta(&self) -> Meta {
        Meta {
            node_id: NodeId::new(self.ns, ROOT_ID),
            node_class: NodeClass::Object,
            browse_name: QualifiedName::new(self.ns, ROOT_NAME),
            display_name: LocalizedText::new("", ROOT_NAME),
            type_definition: ObjectTypeId::FolderType.into(),
        }
    }

    fn tree_meta(&self, n: NodeRef<'_>) -> Meta {
        if n.is_root() {
            return self.root_meta();
        }
        if n.is_item() {
            return self.variable_meta(n.item_id(), n.name());
        }
        Meta {
            node_id: self.item_node_id(n.item_id()),
            node_class: NodeClass::Object,
            browse_name: QualifiedName::new(self.ns, n.name()),
            display_name: LocalizedText::new("", n.name()),
            type_definition: ObjectTypeId::FolderType.into(),
        }
    }

    fn property_meta(&self, pid: u32, item_id: &str, lang: Lang) -> Meta {
        let name = Self::property_name(pid);
        Meta {
            node_id: self.property_node_id(pid, item_id),
            node_class: NodeClass::Variable,
            browse_name: QualifiedName::new(0, name.as_str()),
            display_name: Self::property_display_name(pid, lang),
            type_definition: VariableTypeId::PropertyType.into(),
        }
    }

    /// The identity of a resolved node; `lang`: the language of the display names that
    /// have one (the properties').
    pub fn meta(&self, r: &Resolved, lang: Lang) -> Meta {
        match r {
            Resolved::Root => self.root_meta(),
            Resolved::Folder(item) => match self.tree_of(item).find_item_id(item) {
                Some(n) => self.tree_meta(n),
                None => self.root_meta(),
            },
            Resolved::Variable(info) => {
                let name = self.item_names(&info.item_id);
                let ty = if Self::is_analog(info) {
                    VariableTypeId::AnalogItemType
                } else {
                    VariableTypeId::DataItemType
                };
                Meta {
                    node_id: self.item_node_id(&info.item_id),
                    node_class: NodeClass::Variable,
                    browse_name: QualifiedName::new(self.ns, name.as_str()),
                    display_name: LocalizedText::new("", &name),
                    type_definition: ty.into(),
                }
            }
            Resolved::Property(pid, info) => self.property_meta(*pid, &info.item_id, lang),
        }
    }

    /// Every reference of a node (forward and inverse, hierarchical and type
    /// definitions), in a stable order: the browse's filters and continuation points
    /// apply over this list. `lang`: the language of the targets' display names.
    pub fn references(&self, r: &Resolved, lang: Lang) -> Vec<Reference> {
        let mut out = Vec::new();
        let meta = self.meta(r, lang);
        out.push(Reference {
            reference_type: ReferenceTypeId::HasTypeDefinition.into(),
            forward: true,
            target: Meta {
                node_id: meta.type_definition.clone(),
                node_class: if meta.node_class == NodeClass::Object {
                    NodeClass::ObjectType
                } else {
                    NodeClass::VariableType
                },
                browse_name: QualifiedName::null(),
                display_name: LocalizedText::null(),
                type_definition: NodeId::null(),
            },
        });
        match r {
            Resolved::Root => {
                out.push(Reference {
                    reference_type: ReferenceTypeId::Organizes.into(),
                    forward: false,
                    target: objects_folder_meta(),
                });
                let diag = self.diag.space();
                if let Some(n) = diag.find_item_id(diagnostics::ROOT) {
                    out.push(Reference {
                        reference_type: ReferenceTypeId::Organizes.into(),
                        forward: true,
                        target: self.tree_meta(n),
                    });
                }
                self.children(self.tree.root(), ReferenceTypeId::Organizes, &mut out);
            }
            Resolved::Folder(item) => {
                let tree = self.tree_of(item);
                if let Some(n) = tree.find_item_id(item) {
                    self.parent(n, &mut out);
                    self.children(n, ReferenceTypeId::Organizes, &mut out);
                }
            }
            Resolved::Variable(info) => {
                let tree = self.tree_of(&info.item_id);
                let in_tree = tree.find_item_id(&info.item_id);
                if let Some(n) = in_tree {
                    self.parent(n, &mut out);
                    self.children(n, ReferenceTypeId::HasComponent, &mut out);
                } else if let Some((base, _)) = self.derived_parent(&info.item_id) {
                    let name = self.item_names(&base);
                    out.push(Reference {
                        reference_type: ReferenceTypeId::HasComponent.into(),
                        forward: false,
                        target: self.variable_meta(&base, &name),
                    });
                }
                for (id, suffix) in self.derived_children(info) {
                    let target = self.variable_meta(&id, suffix);
                    if out
                        .iter()
                        .any(|r| r.forward && r.target.node_id == target.node_id)
                    {
                        continue;
                    }
                    out.push(Reference {
                        reference_type: ReferenceTypeId::HasComponent.into(),
                        forward: true,
                        target,
                    });
                }
                for pid in self.property_ids(info) {
                    out.push(Reference {
                        reference_type: ReferenceTypeId::HasProperty.into(),
                        forward: true,
                        target: self.property_meta(pid, &info.item_id, lang),
                    });
                }
            }
            Resolved::Property(_, info) => {
                let parent = Resolved::Variable(info.clone());
                out.push(Reference {
                    reference_type: ReferenceTypeId::HasProperty.into(),
                    forward: false,
                    target: self.meta(&parent, lang),
                });
            }
        }
        out
    }

    fn parent(&self, n: NodeRef<'_>, out: &mut Vec<Reference>) {
        let Some(p) = n.parent() else { return };
        let reference_type = if p.is_item() && !p.is_root() {
            ReferenceTypeId::HasComponent
        } else {
            ReferenceTypeId::Organizes
        };
        out.push(Reference {
            reference_type: reference_type.into(),
            forward: false,
            target: self.tree_meta(p),
        });
    }

    fn children(&self, n: NodeRef<'_>, item_ref: ReferenceTypeId, out: &mut Vec<Reference>) {
        for c in n.children() {
            let reference_type = if c.is_item() {
                item_ref
            } else {
                ReferenceTypeId::Organizes
            };
            out.push(Reference {
                reference_type: reference_type.into(),
                forward: true,
                target: self.tree_meta(c),
            });
        }
    }

    /// A non-Value attribute of a node (the Value of variables comes from the engine: see
    /// the node manager). `may_write`: the session's user may write variables.
    pub fn attribute(
        &self,
        r: &Resolved,
        attribute: AttributeId,
        may_write: bool,
        lang: Lang,
    ) -> Result<Variant, StatusCode> {
        let meta = self.meta(r, lang);
        let common = match attribute {
            AttributeId::NodeId => Some(Variant::from(meta.node_id.clone())),
            AttributeId::NodeClass => Some(Variant::Int32(meta.node_class as i32)),
            AttributeId::BrowseName => Some(Variant::from(meta.browse_name.clone())),
            AttributeId::DisplayName => Some(Variant::from(meta.display_name.clone())),
            AttributeId::WriteMask | AttributeId::UserWriteMask => Some(Variant::UInt32(0)),
            _ => None,
        };
        if let Some(v) = common {
            return Ok(v);
        }
        match r {
            Resolved::Root | Resolved::Folder(_) => match attribute {
                AttributeId::Description => Ok(Variant::from(folder_description(r, lang))),
                AttributeId::EventNotifier => Ok(Variant::Byte(0)),
                _ => Err(StatusCode::BadAttributeIdInvalid),
            },
            Resolved::Variable(info) => self.variable_attribute(info, attribute, may_write, lang),
            Resolved::Property(pid, info) => self.property_attribute(*pid, info, attribute, lang),
        }
    }

    fn variable_attribute(
        &self,
        info: &ItemInfo,
        attribute: AttributeId,
        may_write: bool,
        lang: Lang,
    ) -> Result<Variant, StatusCode> {
        let writable = info.def.access_rights & OPC_WRITEABLE != 0;
        let access = |user: bool| {
            let mut a = AccessLevel::CURRENT_READ;
            if writable && (!user || may_write) {
                a |= AccessLevel::CURRENT_WRITE;
            }
            Variant::Byte(a.bits())
        };
        let (dt, rank) = data_type(info.def.canonical_type);
        Ok(match attribute {
            AttributeId::Description => Variant::from(description(info, lang)),
            AttributeId::DataType => Variant::from(dt),
            AttributeId::ValueRank => Variant::Int32(rank),
            AttributeId::ArrayDimensions => {
                if rank == 1 {
                    Variant::from(vec![0u32])
                } else {
                    Variant::Empty
                }
            }
            AttributeId::AccessLevel => access(false),
            AttributeId::UserAccessLevel => access(true),
            AttributeId::AccessLevelEx => {
                let a = if writable { 3u32 } else { 1u32 };
                Variant::UInt32(a)
            }
            AttributeId::MinimumSamplingInterval => Variant::Double(f64::from(self.scan_rate_ms)),
            AttributeId::Historizing => Variant::Boolean(false),
            _ => return Err(StatusCode::BadAttributeIdInvalid),
        })
    }

    fn property_attribute(
        &self,
        pid: u32,
        info: &ItemInfo,
        attribute: AttributeId,
        lang: Lang,
    ) -> Result<Variant, StatusCode> {
        let value = self.property_value(pid, info, lang)?;
        let (dt, rank) = match pid {
            props::OPC_PROPERTY_HIGH_EU => (opcua::types::DataTypeId::Range.into(), -1),
            props::OPC_PROPERTY_EU_UNITS => (opcua::types::DataTypeId::EUInformation.into(), -1),
            _ => {
                let vt = props::property_info(pid)
                    .map(|p| p.var_type)
                    .unwrap_or(ctopc_core::VarType::VARIANT);
                data_type(vt)
            }
        };
        Ok(match attribute {
            AttributeId::Value => value,
            AttributeId::Description => Variant::from(match props::property_info(pid) {
                Some(p) => LocalizedText::new(lang.locale_id(), p.description(lang)),
                None => LocalizedText::null(),
            }),
            AttributeId::DataType => Variant::from(dt),
            AttributeId::ValueRank => Variant::Int32(rank),
            AttributeId::ArrayDimensions => Variant::Empty,
            AttributeId::AccessLevel | AttributeId::UserAccessLevel => {
                Variant::Byte(AccessLevel::CURRENT_READ.bits())
            }
            AttributeId::AccessLevelEx => Variant::UInt32(1),
            AttributeId::MinimumSamplingInterval => Variant::Double(0.0),
            AttributeId::Historizing => Variant::Boolean(false),
            _ => return Err(StatusCode::BadAttributeIdInvalid),
        })
    }

    /// The value of a property node.
    pub fn property_value(
        &self,
        pid: u32,
        info: &ItemInfo,
        lang: Lang,
    ) -> Result<Variant, StatusCode> {
        match pid {
            props::OPC_PROPERTY_HIGH_EU => match info.attrs.eu {
                EuInfo::Analog { low, high } => {
                    Ok(Variant::from(ExtensionObject::from_message(Range {
                        low,
                        high,
                    })))
                }
                _ => Err(StatusCode::BadNodeIdUnknown),
            },
            props::OPC_PROPERTY_EU_UNITS => {
                let unit = info.attrs.eu_units.clone().unwrap_or_default();
                Ok(Variant::from(ExtensionObject::from_message(
                    EUInformation {
                        namespace_uri: UAString::from(
                            "http://www.opcfoundation.org/UA/units/un/cefact",
                        ),
                        unit_id: -1,
                        display_name: LocalizedText::new("", &unit),
                        description: LocalizedText::new("", &unit),
                    },
                )))
            }
            _ => {
                let p = props::property(info, pid, true, &self.cx(lang));
                match p.error {
                    None => Ok(to_variant(&p.value)),
                    Some(_) => Err(StatusCode::BadNodeIdUnknown),
                }
            }
        }
    }
}

/// The description of a folder in `lang`: the `ServerCTOPC` folder's, a `_Diagnostics`
/// branch's; none for the branches of the variable set (the namespace has no text for
/// them).
pub fn folder_description(r: &Resolved, lang: Lang) -> LocalizedText {
    let text = match r {
        Resolved::Root => Some(match lang {
            Lang::Polish => ROOT_DESCRIPTION[0].to_owned(),
            Lang::English => ROOT_DESCRIPTION[1].to_owned(),
        }),
        Resolved::Folder(item) => branch_description(item, lang),
        _ => None,
    };
    match text {
        Some(t) => LocalizedText::new(lang.locale_id(), &t),
        None => LocalizedText::null(),
    }
}

/// The item's description in `lang` (the other language's when it has none), with the
/// locale of the text given.
pub fn description(info: &ItemInfo, lang: Lang) -> LocalizedText {
    let pl = info.attrs.description.as_deref().filter(|s| !s.is_empty());
    let en = info
        .attrs
        .description_en
        .as_deref()
        .filter(|s| !s.is_empty());
    let pick = match lang {
        Lang::English => en
            .map(|t| (Lang::English, t))
            .or(pl.map(|t| (Lang::Polish, t))),
        Lang::Polish => pl
            .map(|t| (Lang::Polish, t))
            .or(en.map(|t| (Lang::English, t))),
    };
    match pick {
        Some((l, text)) => LocalizedText::new(l.locale_id(), text),
        None => LocalizedText::null(),
    }
}

fn objects_folder_meta() -> Meta {
    Meta {
        node_id: ObjectId::ObjectsFolder.into(),
        node_class: NodeClass::Object,
        browse_name: QualifiedName::new(0, "Objects"),
        display_name: LocalizedText::new("", "Objects"),
        type_definition: ObjectTypeId::FolderType.into(),
    }
}
