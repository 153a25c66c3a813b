//! `IOPCBrowseServerAddressSpace` (DA 2.05a) as a per-session cursor over a shared
//! [`AddressSpace`]. See the module documentation of `browse` for the rules chosen.

use std::sync::Arc;

use super::tree::{AddressSpace, NodeRef};
use super::{name_filter, passes, BrowseDirection, BrowseType, NamespaceType};
use crate::{OpcError, OpcResult};

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

    /// `BrowseOPCItemIDs`. The data-type and access-rights filters are accepted and ignored
    /// (as the asix original documents). An empty list is success: the COM layer returns it
    /// as `S_FALSE` with an empty enumerator.
    pub fn browse_opc_item_ids(
        &self,
        browse_type: BrowseType,
        filter_criteria: &str,
        _data_type_filter: u16,
        _access_rights_filter: u32,
    ) -> OpcResult<Vec<String>> {
        let filter = name_filter(filter_criteria, self.space.filter_case())?;
        let keep = |s: &str| passes(&filter, s);
        let space = &*self.space;
        let out = if space.is_flat() {
            // "This parameter is ignored for FLAT address space."
            space
                .flat_items()
                .iter()
                .map(|&id| space.node_ref(id).item_id())
                .filter(|s| keep(s))
                .map(str::to_owned)
                .collect()
        } else {
            match browse_type {
                BrowseType::Branch | BrowseType::Leaf => {
                    let want_branch = browse_type == BrowseType::Branch;
                    self.position()
                        .children()
                        .filter(|c| c.is_branch() == want_branch && keep(c.name()))
                        .map(|c| c.name().to_owned())
                        .collect()
                }
                BrowseType::Flat => space
                    .items_below(self.position)
                    .into_iter()
                    .map(|id| space.node_ref(id).item_id())
                    .filter(|s| keep(s))
                    .map(str::to_owned)
                    .collect(),
            }
        };
        Ok(out)
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

    fn ids(c: &BrowseCursor, t: BrowseType, f: &str) -> Vec<String> {
        c.browse_opc_item_ids(t, f, 0, 0).unwrap()
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
            c.browse_opc_item_ids(BrowseType::Leaf, "Nothing*", 0, 0),
            Ok(vec![])
        );
    }

    #[test]
    fn browse_opc_item_ids_malformed_filter_is_opc_e_invalidfilter() {
        let c = cursor();
        assert_eq!(
            c.browse_opc_item_ids(BrowseType::Leaf, "[T", 0, 0),
            Err(OpcError::InvalidFilter)
        );
    }

    #[test]
    fn browse_opc_item_ids_ignores_data_type_and_access_rights_filters() {
        let mut c = cursor();
        c.change_browse_position(BrowseDirection::To, "Plant.Boiler")
            .unwrap();
        assert_eq!(
            c.browse_opc_item_ids(
                BrowseType::Leaf,
                "",
                5, /* VT_R8 */
                2  /* WRITEABLE */
            )
            .unwrap(),
            ["T1", "T2", "P1"]
        );
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
}
