//! The OPC address space of the asix namespace: channel `*`'s variable-set tree, with
//! groups as branches and variables as leaves (or, with `AttributesAsItems`, variables
//! as branches that are also items, with attribute leaves).

use super::namespace::AsixNamespace;
use ctopc_core::browse::{AddressSpace, BuildError, NodeId};

/// Separator of the item IDs given to group branches (groups are not items; the ID only
/// serves OPC_BROWSE_TO and IOPCBrowse::Browse): the group path joined with `/`.
pub const GROUP_PATH_SEPARATOR: &str = "/";

/// Builds the address space from [`AsixNamespace::walk_browse_tree`] (the nodes of
/// [`AsixNamespace::browse_nodes`], streamed: no path is copied). Without a database it
/// is an empty root (descriptive IDs still work; they are not browsable).
pub fn build_address_space(ns: &AsixNamespace) -> Result<AddressSpace, BuildError> {
    let mut b = AddressSpace::builder();
    if let Some(db) = ns.database(crate::BASIC_CHANNEL) {
        // A leaf per variable (a branch and up to five leaves with AttributesAsItems),
        // and about a group per hundred variables.
        let per = if ns.config().server.attributes_as_items {
            6
        } else {
            1
        };
        b.reserve(db.variables.len() * per + db.variables.len() / 64);
    }
    // The node at each depth of the path being walked (pre-order: parents come first).
    let mut stack: Vec<NodeId> = Vec::new();
    ns.walk_browse_tree(|path, item_id, is_leaf| {
        let Some((name, parent_path)) = path.split_last() else {
            return Ok(());
        };
        stack.truncate(parent_path.len());
        let parent = if parent_path.is_empty() || stack.len() < parent_path.len() {
            NodeId::ROOT
        } else {
            stack[parent_path.len() - 1]
        };
        let id = match (item_id, is_leaf) {
            (Some(item), true) => b.add_leaf(parent, name, item)?,
            (Some(item), false) => {
                let id = b.add_branch(parent, name, item)?;
                b.set_is_item(id, true)?;
                id
            }
            (None, _) => b.add_branch(parent, name, &path.join(GROUP_PATH_SEPARATOR))?,
        };
        stack.push(id);
        Ok(())
    })?;
    Ok(b.build())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{parse_config, ChannelDatabase};
    use ctopc_core::browse::{BrowseCursor, BrowseDirection, BrowseType};
    use std::sync::Arc;

    fn demo(attributes_as_items: bool) -> AsixNamespace {
        let dir = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../demo/wytwornia_kwasu/wytwornia_kwasu.zez"
        );
        let ini = format!(
            "[Server]\nAttributesAsItems = {}\n[Channel:*]\nItemsDatabase = {dir}\n",
            if attributes_as_items { "tak" } else { "nie" }
        );
        let (cfg, _) = parse_config(ini.as_bytes(), "test.ini").unwrap();
        let (ns, _) = AsixNamespace::load(cfg);
        assert!(matches!(ns.database_state("*"), ChannelDatabase::Loaded(_)));
        ns
    }

    #[test]
    fn groups_are_branches_and_variables_leaves() {
        let ns = demo(false);
        let space = Arc::new(build_address_space(&ns).unwrap());
        let mut c = BrowseCursor::new(space);
        let top = c
            .browse_opc_item_ids(BrowseType::Branch, "", 0, 0, &ns)
            .unwrap();
        assert!(top.iter().any(|n| n == "Magazyn siarki"), "{top:?}");
        c.change_browse_position(BrowseDirection::Down, "Magazyn siarki")
            .unwrap();
        c.change_browse_position(BrowseDirection::Down, "Zbiornik siarki ciekłej Z101")
            .unwrap();
        let leaves = c
            .browse_opc_item_ids(BrowseType::Leaf, "", 0, 0, &ns)
            .unwrap();
        assert!(!leaves.is_empty());
        // GetItemID returns the bare variable ID (names are unique).
        let id = c.get_item_id(&leaves[0]).unwrap();
        assert!(!id.contains('/'), "{id}");
        let flat = BrowseCursor::new(Arc::new(build_address_space(&ns).unwrap()))
            .browse_opc_item_ids(BrowseType::Flat, "", 0, 0, &ns)
            .unwrap();
        assert!(flat.len() >= 200, "{}", flat.len());
    }

    #[test]
    fn attributes_as_items_makes_variables_branches_with_attribute_leaves() {
        let ns = demo(true);
        let space = Arc::new(build_address_space(&ns).unwrap());
        let mut c = BrowseCursor::new(Arc::clone(&space));
        c.change_browse_position(BrowseDirection::Down, "Magazyn siarki")
            .unwrap();
        c.change_browse_position(BrowseDirection::Down, "Zbiornik siarki ciekłej Z101")
            .unwrap();
        let vars = c
            .browse_opc_item_ids(BrowseType::Branch, "", 0, 0, &ns)
            .unwrap();
        assert!(!vars.is_empty());
        c.change_browse_position(BrowseDirection::Down, &vars[0])
            .unwrap();
        let leaves = c
            .browse_opc_item_ids(BrowseType::Leaf, "", 0, 0, &ns)
            .unwrap();
        for want in ["CV", "DESC", "EU_UNIT"] {
            assert!(
                leaves.iter().any(|l| l == want),
                "{want} missing in {leaves:?}"
            );
        }
    }

    /// The BrowseOPCItemIDs filters over the demo plant: OPC_WRITEABLE lists
    /// only the writable variables, a data type only the variables of that canonical type.
    #[test]
    fn item_filters_over_the_demo_plant() {
        use ctopc_core::namespace::{Namespace, OPC_WRITEABLE};
        let ns = demo(false);
        let c = BrowseCursor::new(Arc::new(build_address_space(&ns).unwrap()));
        let flat = |vt: u16, rights: u32| {
            c.browse_opc_item_ids(BrowseType::Flat, "", vt, rights, &ns)
                .unwrap()
        };
        let all = flat(0, 0);
        let writable = flat(0, OPC_WRITEABLE);
        assert!(!writable.is_empty() && writable.len() < all.len());
        for id in &writable {
            let d = ns.resolve(id, "").unwrap();
            assert_ne!(d.access_rights & OPC_WRITEABLE, 0, "{id}");
        }
        let r4 = flat(4, 0);
        assert!(r4.len() < all.len(), "{} of {}", r4.len(), all.len());
        for id in &r4 {
            assert_eq!(ns.resolve(id, "").unwrap().canonical_type.0, 4, "{id}");
        }
        let typed: usize = [2u16, 3, 4, 5, 11, 17, 18, 19]
            .into_iter()
            .map(|vt| flat(vt, 0).len())
            .sum();
        assert_eq!(typed, all.len(), "every variable has one canonical type");
        assert!(flat(8, 0).is_empty(), "no BSTR variables");
    }
}
