//! `IOPCBrowseServerAddressSpace` (DA 2.05a) as a per-session cursor over a shared
//! [`AddressSpace`]. See the module documentation of `browse` for the rules chosen.

use std::sync::Arc;

use super::tree::{AddressSpace, NodeRef};
use super::{name_filter, passes, BrowseDirection, BrowseType, NamespaceType};
use crate::namespace::Namespace;
use crate::{OpcError, OpcResult, VarType};

/// The item filters of `BrowseOPCItemIDs` (see [`BrowseCursor::browse_opc_item_ids`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ItemFilter {
    /// VT_EMPTY: any type; otherwise the canonical type an item must have.
    pub data_type: VarType,
    /// 0: any; otherwise an item passes when its access rights share a bit with this mask.
    pub access_rights: u32,
}

impl ItemFilter {
    /// Neither filter is set.
    pub fn is_off(&self) -> bool {
        self.data_type == VarType::EMPTY && self.access_rights == 0
    }

    /// Whether an item with this canonical type and these access rights passes.
    pub fn admits(&self, canonical: VarType, access_rights: u32) -> bool {
        (self.data_type == VarType::EMPTY || self.data_type == canonical)
            && (self.access_rights == 0 || self.access_rights & access_rights != 0)
    }

    /// Whether item `item_id` passes, resolved through `ns` on the basic channel (an item
    /// that does not resolve passes only when the filter is off).
    pub fn passes(&self, ns: &dyn Namespace, item_id: &str) -> bool {
        if self.is_off() {
            return true;
        }
        ns.resolve(item_id, "")
            .is_ok_and(|d| self.admits(d.canonical_type, d.access_rights))
    }
}

/// The strings of one `BrowseOPCItemIDs`: nodes of the space it was taken from, each
/// shown as its short name (`OPC_BRANCH`, `OPC_LEAF`) or its item ID (`OPC_FLAT`, flat
/// spaces). The names stay in the space's arena, shared: a listing of 1,000,000 is 4 MB of
/// indexes, not a copy of every name, and it outlives a reload of the space.
#[derive(Debug, Clone)]
pub struct NameList {
    space: Arc<AddressSpace>,
    nodes: Vec<u32>,
    item_ids: bool,
}

impl NameList {
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The `i`-th string.
    pub fn get(&self, i: usize) -> Option<&str> {
        let n = self.space.node_ref(*self.nodes.get(i)?);
        Some(if self.item_ids { n.item_id() } else { n.name() })
    }

    pub fn iter(&self) -> impl Iterator<Item = &str> + '_ {
        (0..self.len()).filter_map(|i| self.get(i))
    }
}

/// One client session's browse position. Cheap to create; holds the space it browses, so a
/// reloaded space only affects cursors created afterwards.
#[derive(Debug, Clone)]
pub struct BrowseCursor {
    space: Arc<AddressSpace>,
    position: u32,
}

impl BrowseCursor {
    /// A cursor at the root.
    pub fn new(space: Arc<AddressSpace>) -> Self {
        BrowseCursor { space, position: 0 }
    }

    pub fn space(&self) -> &Arc<AddressSpace> {
        &self.space
    }

    /// The current branch (the root initially).
    pub fn position(&self) -> NodeRef<'_> {
        self.space.node_ref(self.position)
    }

    /// `QueryOrganization`.
    pub fn query_organization(&self) -> NamespaceType {
        if self.space.is_flat() {
            NamespaceType::Flat
        } else {
            NamespaceType::Hierarchical
        }
    }

    /// `ChangeBrowsePosition`. `name` is a child branch's name for `Down`, a branch's item
    /// ID (or `""` for the root) for `To`, and ignored for `Up`. On error the position is
    /// unchanged.
    pub fn change_browse_position(
        &mut self,
        direction: BrowseDirection,
        name: &str,
    ) -> OpcResult<()> {
        if self.space.is_flat() {
            return Err(OpcError::Fail);
        }
        let target = match direction {
            BrowseDirection::Up => self.position().parent().ok_or(OpcError::Fail)?,
            BrowseDirection::Down => self.position().child(name).ok_or(OpcError::InvalidArg)?,
            BrowseDirection::To => self.space.find_item_id(name).ok_or(OpcError::InvalidArg)?,
        };
        if !target.is_branch() {
            return Err(OpcError::InvalidArg);
        }
        self.position = target.raw();
        Ok(())
    }

    /// `BrowseOPCItemIDs`. An empty list is success: the COM layer returns it as `S_FALSE`
    /// with an empty enumerator.
    ///
    /// The item filters of DA 2.05a apply to the items listed (`OPC_LEAF`, `OPC_FLAT` and
    /// a flat space; `OPC_BRANCH` lists branches, which are no items, and ignores them),
    /// each item resolved through `ns` on the basic channel:
    /// - `access_rights_filter`: "The bits passed in the bitmask are 'ANDed' with the bits
    ///   that would be returned for this Item by AddItem, ValidateItem or
    ///   EnumOPCItemAttributes. If the result is non-zero then the item is returned. A 0
    ///   value in the bitmask indicates that the AccessRights bits should be ignored."
    /// - `data_type_filter`: VT_EMPTY is no filter; otherwise an item is listed when its
    ///   **canonical type** is that type. The spec's wording ("the available datatypes
    ///   (those that would succeed if passed to AddItem)") would also admit every type the
    ///   canonical one converts to; since every numeric type converts to every other one
    ///   and to VT_BSTR, that reading would list every asix variable for VT_R4 or VT_BSTR
    ///   alike, and a client filtering for VT_R4 wants the R4 variables. (The asix
    ///   original ignored both filters.)
    ///
    /// An item the namespace cannot resolve passes only when both filters are off.
    pub fn browse_opc_item_ids(
        &self,
        browse_type: BrowseType,
        filter_criteria: &str,
        data_type_filter: u16,
        access_rights_filter: u32,
        ns: &dyn Namespace,
    ) -> OpcResult<Vec<String>> {
        let list = self.browse_opc_item_id_list(
            browse_type,
            filter_criteria,
            data_type_filter,
            access_rights_filter,
            ns,
        )?;
        Ok(list.iter().map(str::to_owned).collect())
    }

    /// [`BrowseCursor::browse_opc_item_ids`] without copying a name: the listing as
    /// indexes into the space (what the COM enumerator hands out, a batch at a time).
    pub fn browse_opc_item_id_list(
        &self,
        browse_type: BrowseType,
        filter_criteria: &str,
        data_type_filter: u16,
        access_rights_filter: u32,
        ns: &dyn Namespace,
    ) -> OpcResult<NameList> {
        let filter = name_filter(filter_criteria, self.space.filter_case())?;
        let items = ItemFilter {
            data_type: VarType(data_type_filter),
            access_rights: access_rights_filter,
        };
        let keep = |s: &str| passes(&filter, s);
        let item_ok = |id: &str| items.passes(ns, id);
        let space = &*self.space;
        let by_id = |ids: &mut dyn Iterator<Item = u32>| -> Vec<u32> {
            ids.filter(|&id| {
                let s = space.node_ref(id).item_id();
                keep(s) && item_ok(s)
            })
            .collect()
        };
        let (nodes, item_ids) = if space.is_flat() {
            // "This parameter is ignored for FLAT address space."
            (by_id(&mut space.flat_items().iter().copied()), true)
        } else {
            match browse_type {
                BrowseType::Branch => (
                    self.position()
                        .children()
                        .filter(|c| c.is_branch() && keep(c.name()))
                        .map(|c| c.raw())
                        .collect(),
                    false,
                ),
                BrowseType::Leaf => (
                    self.position()
                        .children()
                        .filter(|c| !c.is_branch() && keep(c.name()) && item_ok(c.item_id()))
                        .map(|c| c.raw())
                        .collect(),
                    false,
                ),
                BrowseType::Flat => (
                    by_id(&mut space.items_below(self.position).into_iter()),
                    true,
                ),
            }
        };
        Ok(NameList {
            space: Arc::clone(&self.space),
            nodes,
            item_ids,
        })
    }

    /// `GetItemID`: the fully qualified item ID of a branch or leaf at the current level
    /// (for asix, the bare variable name). `""` gives the current position's ID. The item
    /// IDs `OPC_FLAT` lists at this position are accepted too. Anything else is
    /// `E_INVALIDARG`.
    pub fn get_item_id(&self, item_data_id: &str) -> OpcResult<String> {
        let space = &*self.space;
        if item_data_id.is_empty() {
            return Ok(self.position().item_id().to_owned());
        }
        if !space.is_flat() {
            if let Some(child) = self.position().child(item_data_id) {
                return Ok(child.item_id().to_owned());
            }
        }
        let below = space.nodes_with_item_id(item_data_id).any(|n| {
            n.is_item() && n.raw() != self.position && space.is_at_or_below(n.raw(), self.position)
        });
        if below {
            Ok(item_data_id.to_owned())
        } else {
            Err(OpcError::InvalidArg)
        }
    }

    /// `BrowseAccessPaths`: the asix server cannot browse access paths (channels).
    pub fn browse_access_paths(&self, _item_id: &str) -> OpcResult<Vec<String>> {
        Err(OpcError::NotImpl)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::browse::tree::NodeId;
    use crate::browse::MatchCase;
    use crate::namespace::{EuInfo, ItemDef, OPC_READABLE, OPC_WRITEABLE};

    /// Plant
    ///   Boiler: T1, T2, P1
    ///   Pump (also an item): Speed
    ///   Empty (group without variables)
    /// Top
    fn space() -> Arc<AddressSpace> {
        let mut b = AddressSpace::builder();
        for p in [
            "Plant.Boiler.T1",
            "Plant.Boiler.T2",
            "Plant.Boiler.P1",
            "Plant.Pump",
            "Plant.Pump.Speed",
            "Top",
        ] {
            b.add_path(p, '.').unwrap();
        }
        let plant = b.add_branch(NodeId::ROOT, "Plant", "Plant").unwrap();
        b.add_branch(plant, "Empty", "Plant.Empty").unwrap();
        Arc::new(b.build())
    }

    fn cursor() -> BrowseCursor {
        BrowseCursor::new(space())
    }

    /// The types and access rights of the items of [`space`], by the last name of the ID.
    struct Typed;

    impl Namespace for Typed {
        fn resolve(&self, item_id: &str, _access_path: &str) -> OpcResult<ItemDef> {
            let rw = OPC_READABLE | OPC_WRITEABLE;
            let (t, rights) = match item_id.rsplit('.').next().unwrap_or("") {
                "T1" => (VarType::R4, rw),
                "T2" => (VarType::R8, OPC_READABLE),
                "P1" => (VarType::R4, OPC_READABLE),
                "Pump" => (VarType::I2, rw),
                "Speed" => (VarType::R8, rw),
                "Top" => (VarType::BSTR, OPC_READABLE),
                "x" | "y" | "b" => (VarType::R8, rw),
                _ => return Err(OpcError::UnknownItemId),
            };
            Ok(ItemDef {
                source_key: item_id.to_owned(),
                channel: "*".to_owned(),
                canonical_type: t,
                access_rights: rights,
                eu: EuInfo::None,
                constant: None,
            })
        }
    }

    fn ids(c: &BrowseCursor, t: BrowseType, f: &str) -> Vec<String> {
        c.browse_opc_item_ids(t, f, 0, 0, &Typed).unwrap()
    }

    #[test]
    fn query_organization_is_hierarchical_unless_built_flat() {
        assert_eq!(cursor().query_organization(), NamespaceType::Hierarchical);
        let mut b = AddressSpace::builder();
        b.flat(true);
        assert_eq!(
            BrowseCursor::new(Arc::new(b.build())).query_organization(),
            NamespaceType::Flat
        );
    }

    #[test]
    fn change_browse_position_up_from_root_is_e_fail() {
        let mut c = cursor();
        assert_eq!(
            c.change_browse_position(BrowseDirection::Up, ""),
            Err(OpcError::Fail)
        );
        assert!(c.position().is_root());
    }

    #[test]
    fn change_browse_position_down_to_child_branch_and_up_again() {
        let mut c = cursor();
        c.change_browse_position(BrowseDirection::Down, "Plant")
            .unwrap();
        c.change_browse_position(BrowseDirection::Down, "Boiler")
            .unwrap();
        assert_eq!(c.position().item_id(), "Plant.Boiler");
        c.change_browse_position(BrowseDirection::Up, "ignored")
            .unwrap();
        assert_eq!(c.position().item_id(), "Plant");
        c.change_browse_position(BrowseDirection::Up, "").unwrap();
        assert!(c.position().is_root());
    }

    #[test]
    fn change_browse_position_down_to_leaf_unknown_or_empty_is_e_invalidarg() {
        let mut c = cursor();
        assert_eq!(
            c.change_browse_position(BrowseDirection::Down, "Top"),
            Err(OpcError::InvalidArg)
        );
        assert_eq!(
            c.change_browse_position(BrowseDirection::Down, "Nope"),
            Err(OpcError::InvalidArg)
        );
        assert_eq!(
            c.change_browse_position(BrowseDirection::Down, ""),
            Err(OpcError::InvalidArg)
        );
        assert_eq!(
            c.change_browse_position(BrowseDirection::Down, "plant"),
            Err(OpcError::InvalidArg)
        );
        assert!(c.position().is_root(), "position unchanged after errors");
    }

    #[test]
    fn change_browse_position_down_into_branch_that_is_also_an_item_and_empty_group() {
        let mut c = cursor();
        c.change_browse_position(BrowseDirection::To, "Plant")
            .unwrap();
        c.change_browse_position(BrowseDirection::Down, "Pump")
            .unwrap();
        assert_eq!(ids(&c, BrowseType::Leaf, ""), ["Speed"]);
        c.change_browse_position(BrowseDirection::To, "Plant")
            .unwrap();
        c.change_browse_position(BrowseDirection::Down, "Empty")
            .unwrap();
        assert!(ids(&c, BrowseType::Leaf, "").is_empty());
        assert!(ids(&c, BrowseType::Flat, "").is_empty());
    }

    #[test]
    fn change_browse_position_to_full_branch_id_or_root() {
        let mut c = cursor();
        c.change_browse_position(BrowseDirection::To, "Plant.Boiler")
            .unwrap();
        assert_eq!(c.position().name(), "Boiler");
        c.change_browse_position(BrowseDirection::To, "").unwrap();
        assert!(c.position().is_root());
    }

    #[test]
    fn change_browse_position_to_unknown_or_leaf_id_is_e_invalidarg() {
        let mut c = cursor();
        c.change_browse_position(BrowseDirection::To, "Plant")
            .unwrap();
        assert_eq!(
            c.change_browse_position(BrowseDirection::To, "Plant.Nope"),
            Err(OpcError::InvalidArg)
        );
        assert_eq!(
            c.change_browse_position(BrowseDirection::To, "Plant.Boiler.T1"),
            Err(OpcError::InvalidArg)
        );
        assert_eq!(
            c.change_browse_position(BrowseDirection::To, "Boiler"),
            Err(OpcError::InvalidArg),
            "short name is not an ID"
        );
        assert_eq!(c.position().item_id(), "Plant");
    }

    #[test]
    fn change_browse_position_on_flat_space_is_e_fail() {
        let mut b = AddressSpace::builder();
        b.add_path("a.b", '.').unwrap();
        b.flat(true);
        let mut c = BrowseCursor::new(Arc::new(b.build()));
        for d in [
            BrowseDirection::Up,
            BrowseDirection::Down,
            BrowseDirection::To,
        ] {
            assert_eq!(c.change_browse_position(d, "a"), Err(OpcError::Fail));
        }
    }

    #[test]
    fn browse_opc_item_ids_branch_and_leaf_return_short_names_in_order() {
        let mut c = cursor();
        assert_eq!(ids(&c, BrowseType::Branch, ""), ["Plant"]);
        assert_eq!(ids(&c, BrowseType::Leaf, ""), ["Top"]);
        c.change_browse_position(BrowseDirection::Down, "Plant")
            .unwrap();
        assert_eq!(ids(&c, BrowseType::Branch, ""), ["Boiler", "Pump", "Empty"]);
        assert!(
            ids(&c, BrowseType::Leaf, "").is_empty(),
            "Pump has children: not a leaf"
        );
        c.change_browse_position(BrowseDirection::Down, "Boiler")
            .unwrap();
        assert_eq!(ids(&c, BrowseType::Leaf, ""), ["T1", "T2", "P1"]);
        assert!(ids(&c, BrowseType::Branch, "").is_empty());
    }

    #[test]
    fn browse_opc_item_ids_flat_returns_full_ids_of_all_items_below_position() {
        let mut c = cursor();
        assert_eq!(
            ids(&c, BrowseType::Flat, ""),
            [
                "Plant.Boiler.T1",
                "Plant.Boiler.T2",
                "Plant.Boiler.P1",
                "Plant.Pump",
                "Plant.Pump.Speed",
                "Top"
            ]
        );
        c.change_browse_position(BrowseDirection::To, "Plant.Pump")
            .unwrap();
        assert_eq!(
            ids(&c, BrowseType::Flat, ""),
            ["Plant.Pump.Speed"],
            "the position itself is not below itself"
        );
    }

    #[test]
    fn browse_opc_item_ids_flat_lists_a_variable_in_two_groups_once() {
        let mut b = AddressSpace::builder();
        let g1 = b.add_branch(NodeId::ROOT, "G1", "G1").unwrap();
        let g2 = b.add_branch(NodeId::ROOT, "G2", "G2").unwrap();
        b.add_leaf(g1, "V", "V").unwrap();
        b.add_leaf(g2, "V", "V").unwrap();
        b.add_leaf(g2, "W", "W").unwrap();
        let c = BrowseCursor::new(Arc::new(b.build()));
        assert_eq!(ids(&c, BrowseType::Flat, ""), ["V", "W"]);
    }

    #[test]
    fn browse_opc_item_ids_name_filter_uses_match_pattern() {
        let mut c = cursor();
        c.change_browse_position(BrowseDirection::To, "Plant.Boiler")
            .unwrap();
        assert_eq!(ids(&c, BrowseType::Leaf, "T#"), ["T1", "T2"]);
        assert_eq!(ids(&c, BrowseType::Leaf, "[!T]*"), ["P1"]);
        assert_eq!(
            ids(&c, BrowseType::Leaf, "t?"),
            ["T1", "T2"],
            "case-insensitive by default"
        );
        assert_eq!(ids(&c, BrowseType::Leaf, "*"), ["T1", "T2", "P1"]);
        c.change_browse_position(BrowseDirection::To, "").unwrap();
        assert_eq!(
            ids(&c, BrowseType::Flat, "*.T?"),
            ["Plant.Boiler.T1", "Plant.Boiler.T2"],
            "FLAT filters the full ID"
        );
    }

    #[test]
    fn browse_opc_item_ids_case_sensitive_filter_when_configured() {
        let mut b = AddressSpace::builder();
        b.add_path("Abc", '.').unwrap();
        b.add_path("abd", '.').unwrap();
        b.filter_case(MatchCase::Sensitive);
        let c = BrowseCursor::new(Arc::new(b.build()));
        assert_eq!(ids(&c, BrowseType::Leaf, "a*"), ["abd"]);
    }

    #[test]
    fn browse_opc_item_ids_empty_result_is_success_reported_as_s_false() {
        let c = cursor();
        assert_eq!(
            c.browse_opc_item_ids(BrowseType::Leaf, "Nothing*", 0, 0, &Typed),
            Ok(vec![])
        );
    }

    #[test]
    fn browse_opc_item_ids_malformed_filter_is_opc_e_invalidfilter() {
        let c = cursor();
        assert_eq!(
            c.browse_opc_item_ids(BrowseType::Leaf, "[T", 0, 0, &Typed),
            Err(OpcError::InvalidFilter)
        );
    }

    /// Every data-type × access-rights filter combination on `OPC_LEAF`, `OPC_FLAT` and
    /// `OPC_BRANCH` (DA 2.05a defines them; the asix original ignores them, manual §6.6.2.3).
    #[test]
    fn browse_opc_item_ids_applies_the_data_type_and_access_rights_filters() {
        const R: u32 = OPC_READABLE;
        const W: u32 = OPC_WRITEABLE;
        const R4: u16 = 4;
        const R8: u16 = 5;
        const BSTR: u16 = 8;
        let mut c = cursor();
        c.change_browse_position(BrowseDirection::To, "Plant.Boiler")
            .unwrap();
        let leaf = |c: &BrowseCursor, vt: u16, rights: u32| {
            c.browse_opc_item_ids(BrowseType::Leaf, "", vt, rights, &Typed)
                .unwrap()
        };
        // T1 R4 read/write, T2 R8 read-only, P1 R4 read-only.
        let table: [(u16, u32, &[&str]); 12] = [
            (0, 0, &["T1", "T2", "P1"]),
            (0, R, &["T1", "T2", "P1"]),
            (0, W, &["T1"]),
            (0, R | W, &["T1", "T2", "P1"]),
            (R4, 0, &["T1", "P1"]),
            (R4, R, &["T1", "P1"]),
            (R4, W, &["T1"]),
            (R4, R | W, &["T1", "P1"]),
            (R8, 0, &["T2"]),
            (R8, W, &[]),
            (R8, R, &["T2"]),
            (BSTR, 0, &[]),
        ];
        for (vt, rights, want) in table {
            assert_eq!(leaf(&c, vt, rights), want, "vt {vt}, rights {rights}");
        }
        // The name filter and the item filters together.
        assert_eq!(
            c.browse_opc_item_ids(BrowseType::Leaf, "T*", R4, 0, &Typed)
                .unwrap(),
            ["T1"]
        );
        // OPC_FLAT at the root: every item below, filtered (Pump is I2 read/write, Speed R8
        // read/write, Top BSTR read-only).
        let root = cursor();
        let flat = |vt: u16, rights: u32| {
            root.browse_opc_item_ids(BrowseType::Flat, "", vt, rights, &Typed)
                .unwrap()
        };
        assert_eq!(
            flat(0, W),
            ["Plant.Boiler.T1", "Plant.Pump", "Plant.Pump.Speed"]
        );
        assert_eq!(flat(R8, 0), ["Plant.Boiler.T2", "Plant.Pump.Speed"]);
        assert_eq!(flat(R8, W), ["Plant.Pump.Speed"]);
        assert_eq!(flat(BSTR, R), ["Top"]);
        // OPC_BRANCH lists branches, which are no items: the item filters do not apply.
        let mut p = cursor();
        p.change_browse_position(BrowseDirection::To, "Plant")
            .unwrap();
        assert_eq!(
            p.browse_opc_item_ids(BrowseType::Branch, "", BSTR, W, &Typed)
                .unwrap(),
            ["Boiler", "Pump", "Empty"]
        );
        // An item the namespace does not know passes only without filters.
        let mut b = AddressSpace::builder();
        b.add_path("Unknown", '.').unwrap();
        let u = BrowseCursor::new(Arc::new(b.build()));
        assert_eq!(
            u.browse_opc_item_ids(BrowseType::Leaf, "", 0, 0, &Typed)
                .unwrap(),
            ["Unknown"]
        );
        assert!(u
            .browse_opc_item_ids(BrowseType::Leaf, "", 0, R, &Typed)
            .unwrap()
            .is_empty());
    }

    #[test]
    fn item_filter_rules() {
        let f = ItemFilter::default();
        assert!(f.is_off() && f.admits(VarType::R4, 0));
        let f = ItemFilter {
            data_type: VarType::R4,
            access_rights: OPC_WRITEABLE,
        };
        assert!(f.admits(VarType::R4, OPC_READABLE | OPC_WRITEABLE));
        assert!(!f.admits(VarType::R4, OPC_READABLE));
        assert!(!f.admits(VarType::R8, OPC_WRITEABLE));
        assert!(!f.admits(VarType::array_of(VarType::R4), OPC_WRITEABLE));
    }

    #[test]
    fn browse_opc_item_ids_on_flat_space_ignores_browse_type_and_lists_item_ids() {
        let mut b = AddressSpace::builder();
        for p in ["a.x", "a.y", "b"] {
            b.add_path(p, '.').unwrap();
        }
        b.flat(true);
        let c = BrowseCursor::new(Arc::new(b.build()));
        for t in [BrowseType::Branch, BrowseType::Leaf, BrowseType::Flat] {
            assert_eq!(ids(&c, t, ""), ["a.x", "a.y", "b"]);
        }
        assert_eq!(c.get_item_id("a.y"), Ok("a.y".into()));
        assert_eq!(c.get_item_id("y"), Err(OpcError::InvalidArg));
    }

    #[test]
    fn get_item_id_returns_full_id_of_child_branch_or_leaf() {
        let mut c = cursor();
        assert_eq!(c.get_item_id("Plant"), Ok("Plant".into()));
        assert_eq!(c.get_item_id("Top"), Ok("Top".into()));
        c.change_browse_position(BrowseDirection::To, "Plant.Boiler")
            .unwrap();
        assert_eq!(c.get_item_id("T1"), Ok("Plant.Boiler.T1".into()));
    }

    #[test]
    fn get_item_id_returns_bare_name_as_the_asix_original() {
        let mut b = AddressSpace::builder();
        let g = b
            .add_branch(NodeId::ROOT, "Kotlownia", "Kotlownia")
            .unwrap();
        b.add_leaf(g, "A001", "A001").unwrap();
        let mut c = BrowseCursor::new(Arc::new(b.build()));
        c.change_browse_position(BrowseDirection::Down, "Kotlownia")
            .unwrap();
        assert_eq!(c.get_item_id("A001"), Ok("A001".into()));
    }

    #[test]
    fn get_item_id_of_empty_name_is_current_position() {
        let mut c = cursor();
        assert_eq!(c.get_item_id(""), Ok(String::new()));
        c.change_browse_position(BrowseDirection::To, "Plant.Boiler")
            .unwrap();
        assert_eq!(c.get_item_id(""), Ok("Plant.Boiler".into()));
    }

    #[test]
    fn get_item_id_unknown_name_is_e_invalidarg() {
        let mut c = cursor();
        assert_eq!(c.get_item_id("Nope"), Err(OpcError::InvalidArg));
        assert_eq!(c.get_item_id("top"), Err(OpcError::InvalidArg));
        c.change_browse_position(BrowseDirection::To, "Plant.Boiler")
            .unwrap();
        assert_eq!(
            c.get_item_id("Top"),
            Err(OpcError::InvalidArg),
            "not at this level"
        );
        assert_eq!(
            c.get_item_id("Plant.Pump"),
            Err(OpcError::InvalidArg),
            "an item outside the position"
        );
    }

    #[test]
    fn get_item_id_accepts_every_string_flat_browse_returned() {
        let mut c = cursor();
        c.change_browse_position(BrowseDirection::To, "Plant")
            .unwrap();
        for id in ids(&c, BrowseType::Flat, "") {
            assert_eq!(c.get_item_id(&id), Ok(id.clone()));
        }
        for name in ids(&c, BrowseType::Branch, "")
            .into_iter()
            .chain(ids(&c, BrowseType::Leaf, ""))
        {
            assert!(c.get_item_id(&name).is_ok());
        }
    }

    #[test]
    fn browse_access_paths_is_e_notimpl() {
        assert_eq!(cursor().browse_access_paths("Top"), Err(OpcError::NotImpl));
    }

    #[test]
    fn cursors_are_independent_per_session() {
        let s = space();
        let mut a = BrowseCursor::new(s.clone());
        let b = BrowseCursor::new(s);
        a.change_browse_position(BrowseDirection::To, "Plant.Boiler")
            .unwrap();
        assert!(b.position().is_root());
        assert_eq!(a.position().name(), "Boiler");
    }

    #[test]
    fn the_name_list_is_the_listing_without_copies() {
        let mut c = cursor();
        for t in [BrowseType::Branch, BrowseType::Leaf, BrowseType::Flat] {
            let list = c.browse_opc_item_id_list(t, "", 0, 0, &Typed).unwrap();
            let strings: Vec<&str> = list.iter().collect();
            assert_eq!(strings, ids(&c, t, ""), "{t:?}");
            assert_eq!(list.len(), strings.len());
            assert_eq!(list.get(list.len()), None);
        }
        c.change_browse_position(BrowseDirection::Down, "Plant")
            .unwrap();
        let list = c
            .browse_opc_item_id_list(BrowseType::Leaf, "", 0, 0, &Typed)
            .unwrap();
        // The list keeps the space it was taken from, whatever the cursor does next.
        c.change_browse_position(BrowseDirection::Up, "").unwrap();
        assert_eq!(list.iter().collect::<Vec<_>>(), ids_at_plant_leaves());
    }

    fn ids_at_plant_leaves() -> Vec<String> {
        let mut c = cursor();
        c.change_browse_position(BrowseDirection::Down, "Plant")
            .unwrap();
        ids(&c, BrowseType::Leaf, "")
    }

    /// 100,000 variables in branches of 100 (the synthetic database's shape): the flat
    /// listing and one branch's leaves, as indexes. Prints the figures (`--nocapture`).
    #[test]
    fn a_listing_of_100000_names_is_indexes_into_the_space() {
        let mut b = AddressSpace::builder();
        for branch in 0..1000 {
            let id = format!("Sekcja {branch:05}");
            let n = b.add_branch(NodeId::ROOT, &id, &id).unwrap();
            for v in 0..100 {
                let name = format!("SC_{:07}", branch * 100 + v);
                b.add_leaf(n, &name, &name).unwrap();
            }
        }
        let c = BrowseCursor::new(Arc::new(b.build()));
        let start = std::time::Instant::now();
        let list = c
            .browse_opc_item_id_list(BrowseType::Flat, "", 0, 0, &Typed)
            .unwrap();
        let listed = start.elapsed();
        assert_eq!(list.len(), 100_000);
        let start = std::time::Instant::now();
        let bytes: usize = list.iter().map(str::len).sum();
        let walked = start.elapsed();
        assert_eq!(bytes, 100_000 * 10);
        assert_eq!(list.get(99_999), Some("SC_0099999"));
        let branches = c
            .browse_opc_item_id_list(BrowseType::Branch, "", 0, 0, &Typed)
            .unwrap();
        assert_eq!(branches.len(), 1000);
        println!(
            "OPC_FLAT of 100,000: listed in {listed:?} ({} B of indexes), walked in {walked:?}",
            list.len() * 4
        );
    }
}
