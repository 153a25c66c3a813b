//! `IOPCBrowse::Browse` (DA 3.0): stateless browsing of one branch, with paging through
//! opaque continuation points. Item properties are the caller's: it passes a closure that
//! resolves them for each returned item (see [`AddressSpace::browse_with_properties`]).

use super::tree::{AddressSpace, NodeRef};
use super::{name_filter, passes, BrowseFilter, OPC_BROWSE_HASCHILDREN, OPC_BROWSE_ISITEM};
use crate::{OpcError, OpcResult};

/// The arguments of `IOPCBrowse::Browse` that shape the element list.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BrowseRequest<'a> {
    /// The branch to browse: `""` is the root, otherwise an item ID from a previous Browse.
    pub item_id: &'a str,
    /// `""` on the first call; afterwards what the previous call returned.
    pub continuation_point: &'a str,
    /// At most this many elements; 0 = no limit.
    pub max_elements: u32,
    pub filter: BrowseFilter,
    /// `MatchPattern` on element names; `""` = no filter.
    pub element_name_filter: &'a str,
    /// Server-specific; ignored by this server.
    pub vendor_filter: &'a str,
}

impl<'a> BrowseRequest<'a> {
    /// Everything under `item_id`, unfiltered, in one call.
    pub fn new(item_id: &'a str) -> Self {
        BrowseRequest {
            item_id,
            continuation_point: "",
            max_elements: 0,
            filter: BrowseFilter::All,
            element_name_filter: "",
            vendor_filter: "",
        }
    }
}

/// One `OPCBROWSEELEMENT`.
#[derive(Debug, Clone, PartialEq)]
pub struct BrowseElement<P = ()> {
    /// Short display name (the item ID itself in a flat space).
    pub name: String,
    /// Fully qualified ID, for Browse (branches) and AddItems (items).
    pub item_id: String,
    pub has_children: bool,
    pub is_item: bool,
    /// What the caller's resolver returned; `None` for elements that are not items and when
    /// no properties were requested.
    pub properties: Option<P>,
}

impl<P> BrowseElement<P> {
    /// `dwFlagValue`: [`OPC_BROWSE_HASCHILDREN`] | [`OPC_BROWSE_ISITEM`].
    pub fn flags(&self) -> u32 {
        (if self.has_children {
            OPC_BROWSE_HASCHILDREN
        } else {
            0
        }) | (if self.is_item { OPC_BROWSE_ISITEM } else { 0 })
    }
}

/// The outputs of `IOPCBrowse::Browse`.
#[derive(Debug, Clone, PartialEq)]
pub struct BrowseResult<P = ()> {
    pub elements: Vec<BrowseElement<P>>,
    /// `""` when the browse is complete; otherwise pass it back to continue.
    pub continuation_point: String,
    /// `pbMoreElements`: always false, since continuation points are supported (the spec
    /// reserves TRUE for servers without them).
    pub more_elements: bool,
}

/// Which properties `Browse` was asked for (`bReturnAllProperties`, `pdwPropertyIDs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PropertySelection<'a> {
    All,
    Ids(&'a [u32]),
}

impl<'a> PropertySelection<'a> {
    /// `None` when no properties are wanted (`bReturnAllProperties` FALSE and no IDs):
    /// then call [`AddressSpace::browse`]; otherwise [`AddressSpace::browse_with_properties`].
    pub fn from_args(return_all_properties: bool, property_ids: &'a [u32]) -> Option<Self> {
        if return_all_properties {
            Some(PropertySelection::All)
        } else if property_ids.is_empty() {
            None
        } else {
            Some(PropertySelection::Ids(property_ids))
        }
    }
}

const CP_PREFIX: &str = "ctopc1";

/// FNV-1a over the parts, with separators: deterministic in every process.
fn fnv(parts: &[&[u8]]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for part in parts {
        for &b in part.iter().chain(&[0xFFu8]) {
            h ^= b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

impl AddressSpace {
    /// `IOPCBrowse::Browse` without properties.
    ///
    /// Errors: `OPC_E_UNKNOWNITEMID` (item ID not in the address space),
    /// `OPC_E_INVALIDCONTINUATIONPOINT`, `OPC_E_INVALIDFILTER` (malformed name filter).
    /// Browsing a leaf is success with no elements.
    pub fn browse(&self, req: &BrowseRequest<'_>) -> OpcResult<BrowseResult> {
        self.browse_impl::<()>(req, None)
    }

    /// `IOPCBrowse::Browse` with properties: `resolve(item_id)` is called for every returned
    /// element that is an item, in order, and its result stored in
    /// [`BrowseElement::properties`]. The caller builds the closure from its
    /// [`PropertySelection`] and `bReturnPropertyValues`.
    pub fn browse_with_properties<P>(
        &self,
        req: &BrowseRequest<'_>,
        mut resolve: impl FnMut(&str) -> P,
    ) -> OpcResult<BrowseResult<P>> {
        self.browse_impl(req, Some(&mut resolve))
    }

    fn browse_impl<P>(
        &self,
        req: &BrowseRequest<'_>,
        mut resolve: Option<&mut dyn FnMut(&str) -> P>,
    ) -> OpcResult<BrowseResult<P>> {
        let filter = name_filter(req.element_name_filter, self.filter_case())?;
        let node = self.browse_target(req.item_id)?;
        let flat_root = self.is_flat() && node.is_root();
        let candidates: usize = if flat_root {
            self.flat_items().len()
        } else if self.is_flat() {
            0
        } else {
            node.child_count()
        };
        // Children are contiguous, so the k-th candidate is found in O(1).
        let first_child = node.children().next().map_or(0, |c| c.raw());
        let candidate = |k: usize| -> NodeRef<'_> {
            if flat_root {
                self.node_ref(self.flat_items()[k])
            } else {
                self.node_ref(first_child + k as u32)
            }
        };

        let request_hash = fnv(&[
            &(req.filter as u32).to_le_bytes(),
            req.element_name_filter.as_bytes(),
        ]);
        let start = if req.continuation_point.is_empty() {
            0
        } else {
            self.parse_continuation_point(
                req.continuation_point,
                node.raw(),
                request_hash,
                candidates,
            )?
        };

        let mut elements = Vec::new();
        let mut continuation_point = String::new();
        for k in start..candidates {
            let c = candidate(k);
            let has_children = !flat_root && c.is_branch();
            let is_item = c.is_item();
            let wanted = match req.filter {
                BrowseFilter::All => true,
                BrowseFilter::Branches => has_children,
                BrowseFilter::Items => is_item,
            };
            let name = if flat_root { c.item_id() } else { c.name() };
            if !wanted || !passes(&filter, name) {
                continue;
            }
            if req.max_elements != 0 && elements.len() == req.max_elements as usize {
                continuation_point = format!(
                    "{CP_PREFIX}:{:016x}:{:x}:{:x}:{:016x}",
                    self.fingerprint(),
                    node.raw(),
                    k,
                    request_hash
                );
                break;
            }
            let properties = match (&mut resolve, is_item) {
                (Some(r), true) => Some(r(c.item_id())),
                _ => None,
            };
            elements.push(BrowseElement {
                name: name.to_owned(),
                item_id: c.item_id().to_owned(),
                has_children,
                is_item,
                properties,
            });
        }
        Ok(BrowseResult {
            elements,
            continuation_point,
            more_elements: false,
        })
    }

    /// The node `Browse` lists the children of.
    fn browse_target(&self, item_id: &str) -> OpcResult<NodeRef<'_>> {
        if item_id.is_empty() {
            return Ok(self.root());
        }
        let node = self.find_item_id(item_id).ok_or(OpcError::UnknownItemId)?;
        // A flat space shows items only, all under the root.
        if self.is_flat() && !node.is_item() {
            return Err(OpcError::UnknownItemId);
        }
        Ok(node)
    }

    /// The index to resume from; any mismatch is `OPC_E_INVALIDCONTINUATIONPOINT`.
    fn parse_continuation_point(
        &self,
        cp: &str,
        node: u32,
        request_hash: u64,
        candidates: usize,
    ) -> OpcResult<usize> {
        let bad = OpcError::InvalidContinuationPoint;
        let mut parts = cp.split(':');
        let (Some(prefix), Some(fp), Some(n), Some(k), Some(h), None) = (
            parts.next(),
            parts.next(),
            parts.next(),
            parts.next(),
            parts.next(),
            parts.next(),
        ) else {
            return Err(bad);
        };
        let hex = |s: &str| {
            if s.is_empty() || s.len() > 16 {
                None
            } else {
                u64::from_str_radix(s, 16).ok()
            }
        };
        let (Some(fp), Some(n), Some(k), Some(h)) = (hex(fp), hex(n), hex(k), hex(h)) else {
            return Err(bad);
        };
        if prefix != CP_PREFIX
            || fp != self.fingerprint()
            || n != node as u64
            || h != request_hash
            || k >= candidates as u64
        {
            return Err(bad);
        }
        Ok(k as usize)
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
    ///   Empty (group)
    /// Top
    fn space() -> AddressSpace {
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
        b.build()
    }

    fn names<P>(r: &BrowseResult<P>) -> Vec<&str> {
        r.elements.iter().map(|e| e.name.as_str()).collect()
    }

    #[test]
    fn browse_empty_item_id_is_the_root() {
        let r = space().browse(&BrowseRequest::new("")).unwrap();
        assert_eq!(names(&r), ["Plant", "Top"]);
        assert_eq!(r.continuation_point, "");
        assert!(!r.more_elements);
        let plant = &r.elements[0];
        assert_eq!(
            (plant.item_id.as_str(), plant.has_children, plant.is_item),
            ("Plant", true, false)
        );
        assert_eq!(plant.flags(), OPC_BROWSE_HASCHILDREN);
        let top = &r.elements[1];
        assert_eq!(
            (top.item_id.as_str(), top.has_children, top.is_item),
            ("Top", false, true)
        );
        assert_eq!(top.flags(), OPC_BROWSE_ISITEM);
        assert_eq!(top.properties, None);
    }

    #[test]
    fn browse_branch_by_item_id_returns_flags_and_full_ids() {
        let r = space().browse(&BrowseRequest::new("Plant")).unwrap();
        let got: Vec<_> = r
            .elements
            .iter()
            .map(|e| (e.name.as_str(), e.item_id.as_str(), e.flags()))
            .collect();
        assert_eq!(
            got,
            [
                ("Boiler", "Plant.Boiler", OPC_BROWSE_HASCHILDREN),
                (
                    "Pump",
                    "Plant.Pump",
                    OPC_BROWSE_HASCHILDREN | OPC_BROWSE_ISITEM
                ),
                ("Empty", "Plant.Empty", OPC_BROWSE_HASCHILDREN),
            ]
        );
    }

    #[test]
    fn browse_unknown_item_id_is_opc_e_unknownitemid() {
        assert_eq!(
            space().browse(&BrowseRequest::new("Plant.Nope")),
            Err(OpcError::UnknownItemId)
        );
        assert_eq!(
            space().browse(&BrowseRequest::new("plant")),
            Err(OpcError::UnknownItemId)
        );
    }

    #[test]
    fn browse_leaf_is_success_with_no_elements() {
        let r = space()
            .browse(&BrowseRequest::new("Plant.Boiler.T1"))
            .unwrap();
        assert!(r.elements.is_empty());
        assert_eq!(r.continuation_point, "");
    }

    #[test]
    fn browse_filter_branches_returns_elements_with_children() {
        let req = BrowseRequest {
            filter: BrowseFilter::Branches,
            ..BrowseRequest::new("Plant")
        };
        assert_eq!(
            names(&space().browse(&req).unwrap()),
            ["Boiler", "Pump", "Empty"]
        );
        let req = BrowseRequest {
            filter: BrowseFilter::Branches,
            ..BrowseRequest::new("")
        };
        assert_eq!(names(&space().browse(&req).unwrap()), ["Plant"]);
    }

    #[test]
    fn browse_filter_items_returns_elements_that_are_items() {
        let req = BrowseRequest {
            filter: BrowseFilter::Items,
            ..BrowseRequest::new("Plant")
        };
        assert_eq!(names(&space().browse(&req).unwrap()), ["Pump"]);
        let req = BrowseRequest {
            filter: BrowseFilter::Items,
            ..BrowseRequest::new("")
        };
        assert_eq!(names(&space().browse(&req).unwrap()), ["Top"]);
    }

    #[test]
    fn browse_element_name_filter_uses_match_pattern() {
        let s = space();
        let req = BrowseRequest {
            element_name_filter: "T#",
            ..BrowseRequest::new("Plant.Boiler")
        };
        assert_eq!(names(&s.browse(&req).unwrap()), ["T1", "T2"]);
        let req = BrowseRequest {
            element_name_filter: "p*",
            ..BrowseRequest::new("Plant.Boiler")
        };
        assert_eq!(
            names(&s.browse(&req).unwrap()),
            ["P1"],
            "case-insensitive by default"
        );
        let req = BrowseRequest {
            element_name_filter: "[T",
            ..BrowseRequest::new("Plant.Boiler")
        };
        assert_eq!(s.browse(&req), Err(OpcError::InvalidFilter));
    }

    /// Every combination of the browse filter, the element name filter and the vendor
    /// filter (which has no meaning here, whatever its text), at "Plant" (Boiler: branch;
    /// Pump: branch and item; Empty: branch) and at the root (Plant: branch; Top: item).
    #[test]
    fn browse_filter_combinations() {
        let s = space();
        type Row = (
            &'static str,
            BrowseFilter,
            &'static str,
            &'static [&'static str],
        );
        let rows: &[Row] = &[
            ("Plant", BrowseFilter::All, "", &["Boiler", "Pump", "Empty"]),
            (
                "Plant",
                BrowseFilter::Branches,
                "",
                &["Boiler", "Pump", "Empty"],
            ),
            ("Plant", BrowseFilter::Items, "", &["Pump"]),
            ("Plant", BrowseFilter::All, "*p*", &["Pump", "Empty"]),
            ("Plant", BrowseFilter::Branches, "*p*", &["Pump", "Empty"]),
            ("Plant", BrowseFilter::Items, "*p*", &["Pump"]),
            ("Plant", BrowseFilter::All, "B*", &["Boiler"]),
            ("Plant", BrowseFilter::Items, "B*", &[]),
            ("", BrowseFilter::All, "", &["Plant", "Top"]),
            ("", BrowseFilter::Branches, "", &["Plant"]),
            ("", BrowseFilter::Items, "", &["Top"]),
            ("", BrowseFilter::Items, "P*", &[]),
            ("", BrowseFilter::Branches, "t?p", &[]),
            ("", BrowseFilter::All, "t?p", &["Top"]),
        ];
        for &(item_id, filter, name, want) in rows {
            for vendor in ["", "anything", "[[["] {
                let req = BrowseRequest {
                    filter,
                    element_name_filter: name,
                    vendor_filter: vendor,
                    ..BrowseRequest::new(item_id)
                };
                assert_eq!(
                    names(&s.browse(&req).unwrap()),
                    want,
                    "{item_id:?} {filter:?} {name:?} {vendor:?}"
                );
                // With properties requested: the same elements, properties on items only.
                let r = s.browse_with_properties(&req, |id| id.len()).unwrap();
                assert_eq!(names(&r), want);
                assert!(r
                    .elements
                    .iter()
                    .all(|e| e.properties.is_some() == e.is_item));
            }
        }
    }

    #[test]
    fn browse_vendor_filter_is_ignored() {
        let req = BrowseRequest {
            vendor_filter: "[[[garbage",
            ..BrowseRequest::new("Plant.Boiler")
        };
        assert_eq!(names(&space().browse(&req).unwrap()), ["T1", "T2", "P1"]);
    }

    #[test]
    fn browse_max_elements_pages_with_continuation_points() {
        let s = space();
        let mut req = BrowseRequest {
            max_elements: 2,
            ..BrowseRequest::new("Plant.Boiler")
        };
        let first = s.browse(&req).unwrap();
        assert_eq!(names(&first), ["T1", "T2"]);
        assert!(!first.continuation_point.is_empty());
        assert!(
            !first.more_elements,
            "continuation points are supported: pbMoreElements stays FALSE"
        );
        req.continuation_point = &first.continuation_point;
        let second = s.browse(&req).unwrap();
        assert_eq!(names(&second), ["P1"]);
        assert_eq!(second.continuation_point, "");
    }

    #[test]
    fn browse_max_elements_equal_to_count_returns_no_continuation_point() {
        let req = BrowseRequest {
            max_elements: 3,
            ..BrowseRequest::new("Plant.Boiler")
        };
        let r = space().browse(&req).unwrap();
        assert_eq!(r.elements.len(), 3);
        assert_eq!(
            r.continuation_point, "",
            "no continuation point without another element"
        );
    }

    #[test]
    fn browse_max_elements_zero_means_all() {
        let req = BrowseRequest {
            max_elements: 0,
            ..BrowseRequest::new("Plant.Boiler")
        };
        assert_eq!(space().browse(&req).unwrap().elements.len(), 3);
    }

    #[test]
    fn browse_continuation_point_skips_filtered_elements() {
        let s = space();
        let mut req = BrowseRequest {
            max_elements: 1,
            element_name_filter: "?1",
            ..BrowseRequest::new("Plant.Boiler")
        };
        let first = s.browse(&req).unwrap();
        assert_eq!(names(&first), ["T1"]);
        req.continuation_point = &first.continuation_point;
        let second = s.browse(&req).unwrap();
        assert_eq!(names(&second), ["P1"]);
        assert_eq!(second.continuation_point, "");
    }

    #[test]
    fn browse_continuation_point_survives_an_identical_rebuild_and_other_sessions() {
        let first = space()
            .browse(&BrowseRequest {
                max_elements: 1,
                ..BrowseRequest::new("Plant")
            })
            .unwrap();
        let rebuilt = space();
        let req = BrowseRequest {
            max_elements: 1,
            continuation_point: &first.continuation_point,
            ..BrowseRequest::new("Plant")
        };
        assert_eq!(names(&rebuilt.browse(&req).unwrap()), ["Pump"]);
    }

    #[test]
    fn browse_invalid_continuation_point_is_opc_e_invalidcontinuationpoint() {
        let s = space();
        let first = s
            .browse(&BrowseRequest {
                max_elements: 1,
                ..BrowseRequest::new("Plant")
            })
            .unwrap();
        let cp = first.continuation_point.as_str();
        let bad = |req: BrowseRequest<'_>| {
            assert_eq!(
                s.browse(&req),
                Err(OpcError::InvalidContinuationPoint),
                "{req:?}"
            )
        };
        bad(BrowseRequest {
            continuation_point: "garbage",
            ..BrowseRequest::new("Plant")
        });
        bad(BrowseRequest {
            continuation_point: "ctopc1:0:0:0:0",
            ..BrowseRequest::new("Plant")
        });
        bad(BrowseRequest {
            continuation_point: &cp.replace("ctopc1", "ctopc2"),
            ..BrowseRequest::new("Plant")
        });
        bad(BrowseRequest {
            continuation_point: &format!("{cp}:0"),
            ..BrowseRequest::new("Plant")
        });
        // another branch
        bad(BrowseRequest {
            continuation_point: cp,
            ..BrowseRequest::new("Plant.Boiler")
        });
        // another filter set
        bad(BrowseRequest {
            continuation_point: cp,
            filter: BrowseFilter::Items,
            ..BrowseRequest::new("Plant")
        });
        bad(BrowseRequest {
            continuation_point: cp,
            element_name_filter: "P*",
            ..BrowseRequest::new("Plant")
        });
        // another address space
        let other = AddressSpace::from_paths(["Plant.X", "Plant.Y"], '.').unwrap();
        let req = BrowseRequest {
            continuation_point: cp,
            ..BrowseRequest::new("Plant")
        };
        assert_eq!(other.browse(&req), Err(OpcError::InvalidContinuationPoint));
        // index out of range
        let parts: Vec<_> = cp.split(':').collect();
        let far = format!("{}:{}:{}:ff:{}", parts[0], parts[1], parts[2], parts[4]);
        bad(BrowseRequest {
            continuation_point: &far,
            ..BrowseRequest::new("Plant")
        });
    }

    #[test]
    fn browse_with_properties_resolves_items_only() {
        let mut asked = Vec::new();
        let r = space()
            .browse_with_properties(&BrowseRequest::new("Plant"), |id| {
                asked.push(id.to_owned());
                id.len()
            })
            .unwrap();
        assert_eq!(asked, ["Plant.Pump"]);
        let props: Vec<_> = r.elements.iter().map(|e| e.properties).collect();
        assert_eq!(props, [None, Some("Plant.Pump".len()), None]);
    }

    #[test]
    fn browse_with_properties_not_called_for_elements_beyond_the_page() {
        let mut calls = 0;
        let req = BrowseRequest {
            max_elements: 1,
            ..BrowseRequest::new("Plant.Boiler")
        };
        space()
            .browse_with_properties(&req, |_| calls += 1)
            .unwrap();
        assert_eq!(calls, 1);
    }

    #[test]
    fn property_selection_from_browse_arguments() {
        assert_eq!(PropertySelection::from_args(false, &[]), None);
        assert_eq!(
            PropertySelection::from_args(true, &[1, 2]),
            Some(PropertySelection::All)
        );
        assert_eq!(
            PropertySelection::from_args(false, &[1, 2]),
            Some(PropertySelection::Ids(&[1, 2]))
        );
    }

    #[test]
    fn browse_flat_space_lists_all_items_under_the_root() {
        let mut b = AddressSpace::builder();
        for p in ["a.x", "a.y", "b"] {
            b.add_path(p, '.').unwrap();
        }
        b.flat(true).filter_case(MatchCase::Sensitive);
        let s = b.build();
        let r = s.browse(&BrowseRequest::new("")).unwrap();
        let got: Vec<_> = r
            .elements
            .iter()
            .map(|e| (e.name.as_str(), e.item_id.as_str(), e.flags()))
            .collect();
        assert_eq!(
            got,
            [
                ("a.x", "a.x", OPC_BROWSE_ISITEM),
                ("a.y", "a.y", OPC_BROWSE_ISITEM),
                ("b", "b", OPC_BROWSE_ISITEM)
            ]
        );
        assert!(s
            .browse(&BrowseRequest::new("a.x"))
            .unwrap()
            .elements
            .is_empty());
        assert_eq!(
            s.browse(&BrowseRequest::new("a")),
            Err(OpcError::UnknownItemId)
        );
        let mut req = BrowseRequest {
            max_elements: 2,
            ..BrowseRequest::new("")
        };
        let first = s.browse(&req).unwrap();
        req.continuation_point = &first.continuation_point;
        assert_eq!(names(&s.browse(&req).unwrap()), ["b"]);
    }

    proptest::proptest! {
        #[test]
        fn browse_pages_concatenate_to_the_unpaged_result(
            kinds in proptest::collection::vec(0u8..3, 0..40),
            max in 1u32..7,
            filter in 1u32..4,
            name_filter in proptest::sample::select(vec!["", "*", "?1*", "[!B]*", "#*", "L*"]),
        ) {
            // children of "G": leaves, empty branches, branches that are items
            let mut b = AddressSpace::builder();
            let g = b.add_branch(NodeId::ROOT, "G", "G").unwrap();
            for (i, k) in kinds.iter().enumerate() {
                let name = format!("{}{}", ["L", "B", "I"][*k as usize], i);
                let id = format!("G.{name}");
                let n = match k {
                    0 => b.add_leaf(g, &name, &id).unwrap(),
                    _ => b.add_branch(g, &name, &id).unwrap(),
                };
                if *k == 2 {
                    b.set_is_item(n, true).unwrap();
                }
            }
            let s = b.build();
            let filter = BrowseFilter::try_from(filter).unwrap();
            let all = s
                .browse(&BrowseRequest { filter, element_name_filter: name_filter, ..BrowseRequest::new("G") })
                .unwrap();
            proptest::prop_assert_eq!(&all.continuation_point, "");
            let mut paged = Vec::new();
            let mut cp = String::new();
            loop {
                let req = BrowseRequest {
                    filter,
                    element_name_filter: name_filter,
                    max_elements: max,
                    continuation_point: &cp,
                    ..BrowseRequest::new("G")
                };
                let r = s.browse(&req).unwrap();
                proptest::prop_assert!(r.elements.len() <= max as usize);
                proptest::prop_assert!(r.continuation_point.is_empty() || r.elements.len() == max as usize);
                paged.extend(r.elements);
                if r.continuation_point.is_empty() {
                    break;
                }
                cp = r.continuation_point;
            }
            proptest::prop_assert_eq!(paged, all.elements);
        }
    }

    #[test]
    fn browse_large_branch_in_pages_returns_every_element_once() {
        let mut b = AddressSpace::builder();
        let g = b.add_branch(NodeId::ROOT, "G", "G").unwrap();
        for v in 0..2500 {
            let n = format!("V{v:05}");
            b.add_leaf(g, &n, &n).unwrap();
        }
        let s = b.build();
        let mut all = Vec::new();
        let mut cp = String::new();
        loop {
            let req = BrowseRequest {
                max_elements: 1000,
                continuation_point: &cp,
                ..BrowseRequest::new("G")
            };
            let r = s.browse(&req).unwrap();
            all.extend(r.elements.into_iter().map(|e| e.name));
            if r.continuation_point.is_empty() {
                break;
            }
            cp = r.continuation_point;
        }
        assert_eq!(all.len(), 2500);
        assert_eq!(all[0], "V00000");
        assert_eq!(all[2499], "V02499");
    }
}
