//! The `_Diagnostics` branch in every browse path, beside the real address space: a
//! per-session [`Cursor`] for IOPCBrowseServerAddressSpace and [`browse`] for IOPCBrowse.
//! The real space is never copied or rebuilt; the branch is the snapshot's small space
//! ([`super::Snapshot::space`]), whose root holds `_Diagnostics` only, and each call is
//! answered by the one space it concerns (both, at the real root).
//!
//! At the real root: `OPC_BRANCH` lists `_Diagnostics` first, then the real branches;
//! `OPC_FLAT` (and a flat real space) lists the real item IDs, then the diagnostic ones;
//! `Browse("")` returns the `_Diagnostics` element first (with a continuation point of its
//! own when `dwMaxElementsReturned` is 1). Inside the branch, everything is the branch's
//! space with the rules of `crate::browse`.
//!
//! The position inside the branch is kept as its item ID, since the branch changes as
//! clients come and go. A cursor inside the branch of a client that has left stays there:
//! `BrowseOPCItemIDs` lists nothing (S_FALSE), `GetItemID("")` still gives its ID, any
//! other name is E_INVALIDARG, UP goes to `_Diagnostics.Clients`, DOWN is E_INVALIDARG, TO
//! works as anywhere. Continuation points of `Browse` inside the branch are invalid
//! (OPC_E_INVALIDCONTINUATIONPOINT) once a client or channel came or went.

use std::sync::Arc;

use super::{is_diagnostic_id, ROOT};
use crate::browse::{
    AddressSpace, BrowseCursor, BrowseDirection, BrowseRequest, BrowseResult, BrowseType, NameList,
    NamespaceType,
};
use crate::namespace::Namespace;
use crate::{OpcError, OpcResult};

/// The continuation point after the `_Diagnostics` element when it filled the page.
const AFTER_BRANCH_CP: &str = "ctopc-diag:after-branch";

/// A listing of `BrowseOPCItemIDs` made of the parts of both spaces, in order.
#[derive(Debug, Clone)]
pub struct Listing {
    parts: Vec<NameList>,
}

impl Listing {
    pub fn len(&self) -> usize {
        self.parts.iter().map(NameList::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.parts.iter().all(NameList::is_empty)
    }

    /// The `i`-th string.
    pub fn get(&self, mut i: usize) -> Option<&str> {
        for p in &self.parts {
            if i < p.len() {
                return p.get(i);
            }
            i -= p.len();
        }
        None
    }

    pub fn iter(&self) -> impl Iterator<Item = &str> + '_ {
        self.parts.iter().flat_map(NameList::iter)
    }
}

/// One session's browse position over the real space and the branch.
#[derive(Debug, Clone)]
pub struct Cursor {
    real: BrowseCursor,
    /// Inside the branch: the position's item ID.
    diag: Option<String>,
}

/// The parent of an item ID of the branch (`None`: `_Diagnostics` itself, whose parent is
/// the real root).
fn parent_id(id: &str) -> Option<&str> {
    id.rsplit_once('.').map(|(p, _)| p)
}

impl Cursor {
    /// A cursor at the real root.
    pub fn new(real: Arc<AddressSpace>) -> Cursor {
        Cursor {
            real: BrowseCursor::new(real),
            diag: None,
        }
    }

    /// The position's item ID (`""`: the root).
    pub fn position(&self) -> &str {
        match &self.diag {
            Some(id) => id,
            None => self.real.position().item_id(),
        }
    }

    pub fn query_organization(&self) -> NamespaceType {
        self.real.query_organization()
    }

    /// A cursor of the branch at `id`, if that branch exists in `diag`.
    fn diag_cursor(diag: &Arc<AddressSpace>, id: &str) -> Option<BrowseCursor> {
        let mut c = BrowseCursor::new(Arc::clone(diag));
        c.change_browse_position(BrowseDirection::To, id).ok()?;
        Some(c)
    }

    fn at_real_root(&self) -> bool {
        self.diag.is_none() && self.real.position().is_root()
    }

    /// `ChangeBrowsePosition` (see the module doc); on error the position is unchanged.
    pub fn change_browse_position(
        &mut self,
        direction: BrowseDirection,
        name: &str,
        diag: &Arc<AddressSpace>,
    ) -> OpcResult<()> {
        if self.real.space().is_flat() {
            return Err(OpcError::Fail);
        }
        match (direction, &self.diag) {
            (BrowseDirection::To, _) if is_diagnostic_id(name) => {
                let c = Self::diag_cursor(diag, name).ok_or(OpcError::InvalidArg)?;
                self.real.change_browse_position(BrowseDirection::To, "")?;
                self.diag = Some(c.position().item_id().to_owned());
                Ok(())
            }
            (BrowseDirection::To, _) => {
                self.real.change_browse_position(direction, name)?;
                self.diag = None;
                Ok(())
            }
            (BrowseDirection::Down, None) if self.at_real_root() && name == ROOT => {
                self.diag = Some(ROOT.to_owned());
                Ok(())
            }
            (_, None) => self.real.change_browse_position(direction, name),
            (BrowseDirection::Up, Some(id)) => {
                self.diag = parent_id(id).map(str::to_owned);
                Ok(())
            }
            (BrowseDirection::Down, Some(id)) => {
                let mut c = Self::diag_cursor(diag, id).ok_or(OpcError::InvalidArg)?;
                c.change_browse_position(BrowseDirection::Down, name)?;
                self.diag = Some(c.position().item_id().to_owned());
                Ok(())
            }
        }
    }

    /// `BrowseOPCItemIDs` over both spaces (see the module doc; the rules of each part are
    /// [`BrowseCursor::browse_opc_item_id_list`]'s). `ns` resolves the items of both for
    /// the item filters.
    pub fn browse_opc_item_id_list(
        &self,
        browse_type: BrowseType,
        filter: &str,
        data_type_filter: u16,
        access_rights_filter: u32,
        ns: &dyn Namespace,
        diag: &Arc<AddressSpace>,
    ) -> OpcResult<Listing> {
        let list = |c: &BrowseCursor, t: BrowseType| {
            c.browse_opc_item_id_list(t, filter, data_type_filter, access_rights_filter, ns)
        };
        if let Some(id) = &self.diag {
            let parts = match Self::diag_cursor(diag, id) {
                Some(c) => vec![list(&c, browse_type)?],
                // The client of this branch has left: nothing (the filter is still checked).
                None => {
                    list(&self.real, browse_type)?;
                    Vec::new()
                }
            };
            return Ok(Listing { parts });
        }
        let real = list(&self.real, browse_type)?;
        let flat = self.real.space().is_flat();
        if !flat && !self.at_real_root() {
            return Ok(Listing { parts: vec![real] });
        }
        let branch = BrowseCursor::new(Arc::clone(diag));
        let parts = match (flat, browse_type) {
            (false, BrowseType::Branch) => vec![list(&branch, BrowseType::Branch)?, real],
            (false, BrowseType::Leaf) => vec![real],
            _ => vec![real, list(&branch, BrowseType::Flat)?],
        };
        Ok(Listing { parts })
    }

    /// `GetItemID`: at the real root also `_Diagnostics` and the diagnostic IDs (as
    /// `OPC_FLAT` lists them); inside the branch, the branch's rules.
    pub fn get_item_id(&self, item_data_id: &str, diag: &Arc<AddressSpace>) -> OpcResult<String> {
        if let Some(id) = &self.diag {
            return match Self::diag_cursor(diag, id) {
                Some(c) => c.get_item_id(item_data_id),
                None if item_data_id.is_empty() => Ok(id.clone()),
                None => Err(OpcError::InvalidArg),
            };
        }
        let real = self.real.get_item_id(item_data_id);
        if real.is_ok() || !(self.at_real_root() || self.real.space().is_flat()) {
            return real;
        }
        let branch = BrowseCursor::new(Arc::clone(diag));
        branch.get_item_id(item_data_id).or(real)
    }

    /// `BrowseAccessPaths`: not supported (asix channels are not browsable).
    pub fn browse_access_paths(&self, item_id: &str) -> OpcResult<Vec<String>> {
        self.real.browse_access_paths(item_id)
    }
}

/// `IOPCBrowse::Browse` over both spaces (see the module doc). `run` browses one space
/// with a request (`AddressSpace::browse`, or `browse_with_properties` with the caller's
/// property closure).
pub fn browse<P>(
    real: &AddressSpace,
    diag: &AddressSpace,
    req: &BrowseRequest<'_>,
    mut run: impl FnMut(&AddressSpace, &BrowseRequest<'_>) -> OpcResult<BrowseResult<P>>,
) -> OpcResult<BrowseResult<P>> {
    if is_diagnostic_id(req.item_id) {
        return run(diag, req);
    }
    if !req.item_id.is_empty() {
        return run(real, req);
    }
    match req.continuation_point {
        "" => {}
        AFTER_BRANCH_CP => {
            return run(
                real,
                &BrowseRequest {
                    continuation_point: "",
                    ..*req
                },
            )
        }
        _ => return run(real, req),
    }
    let mut first = run(diag, req)?;
    let n = first.elements.len() as u32;
    if req.max_elements != 0 && n >= req.max_elements {
        // Only when the real root has something after it.
        let rest = run(
            real,
            &BrowseRequest {
                max_elements: 1,
                ..*req
            },
        )?;
        if !rest.elements.is_empty() {
            first.continuation_point = AFTER_BRANCH_CP.to_owned();
        }
        return Ok(first);
    }
    let rest = run(
        real,
        &BrowseRequest {
            max_elements: if req.max_elements == 0 {
                0
            } else {
                req.max_elements - n
            },
            ..*req
        },
    )?;
    first.elements.extend(rest.elements);
    first.continuation_point = rest.continuation_point;
    first.more_elements = rest.more_elements;
    Ok(first)
}

#[cfg(test)]
mod tests {
    use super::super::{ClientCounters, Input, Sampler};
    use super::*;
    use crate::browse::{BrowseFilter, MatchCase};
    use crate::diagnostics::{Board, DiagNamespace};
    use crate::namespace::{EuInfo, ItemDef, OPC_READABLE, OPC_WRITEABLE};
    use crate::{Timestamp, VarType};

    struct Plain;
    impl Namespace for Plain {
        fn resolve(&self, item_id: &str, _: &str) -> OpcResult<ItemDef> {
            Ok(ItemDef {
                source_key: item_id.to_owned(),
                channel: "*".to_owned(),
                canonical_type: VarType::R8,
                access_rights: OPC_READABLE | OPC_WRITEABLE,
                eu: EuInfo::None,
                constant: None,
            })
        }
    }

    fn real(flat: bool) -> Arc<AddressSpace> {
        let mut b = AddressSpace::builder();
        b.flat(flat);
        for p in ["Plant.A1", "Plant.A2", "Top"] {
            b.add_path(p, '.').unwrap();
        }
        Arc::new(b.build())
    }

    fn board(names: &[Option<&str>]) -> (Arc<Board>, Arc<AddressSpace>) {
        let mut s = Sampler::new(MatchCase::Insensitive);
        let input = Input {
            clients: names
                .iter()
                .enumerate()
                .map(|(i, n)| ClientCounters {
                    session: i as u32 + 1,
                    name: n.map(str::to_owned),
                    ..ClientCounters::default()
                })
                .collect(),
            ..Input::default()
        };
        let b = Arc::new(Board::new());
        b.publish(s.sample(Timestamp::from_unix_millis(1), input));
        let space = b.space();
        (b, space)
    }

    fn ns(b: &Arc<Board>) -> DiagNamespace {
        DiagNamespace::new(Arc::new(Plain), Arc::clone(b))
    }

    fn names(l: &Listing) -> Vec<&str> {
        l.iter().collect()
    }

    #[test]
    fn the_root_lists_the_branch_first_and_flat_lists_every_diagnostic_item() {
        let (b, d) = board(&[Some("HMI")]);
        let ns = ns(&b);
        let c = Cursor::new(real(false));
        let l = |t| c.browse_opc_item_id_list(t, "", 0, 0, &ns, &d).unwrap();
        assert_eq!(names(&l(BrowseType::Branch)), ["_Diagnostics", "Plant"]);
        assert_eq!(names(&l(BrowseType::Leaf)), ["Top"]);
        let flat = l(BrowseType::Flat);
        assert_eq!(flat.len(), 3 + 9 + 7);
        assert_eq!(flat.get(0), Some("Plant.A1"));
        assert!(names(&flat).contains(&"_Diagnostics.Server.Uptime"));
        assert!(names(&flat).contains(&"_Diagnostics.Clients.HMI.Failures"));
        assert_eq!(flat.get(flat.len()), None);
        // The item filters apply to the diagnostic items too (they are read-only).
        let writable = c
            .browse_opc_item_id_list(BrowseType::Flat, "", 0, OPC_WRITEABLE, &ns, &d)
            .unwrap();
        assert_eq!(names(&writable), ["Plant.A1", "Plant.A2", "Top"]);
        let strings = c
            .browse_opc_item_id_list(BrowseType::Flat, "", VarType::BSTR.0, 0, &ns, &d)
            .unwrap();
        assert_eq!(
            names(&strings),
            [
                "_Diagnostics.Clients.HMI.Name",
                "_Diagnostics.Clients.HMI.Identity"
            ]
        );
        // The name filter too.
        let f = c
            .browse_opc_item_id_list(BrowseType::Branch, "_diag*", 0, 0, &ns, &d)
            .unwrap();
        assert_eq!(names(&f), ["_Diagnostics"]);
    }

    #[test]
    fn down_into_the_branch_and_a_client_and_back_up() {
        let (b, d) = board(&[Some("HMI"), None]);
        let ns = ns(&b);
        let mut c = Cursor::new(real(false));
        let l = |c: &Cursor, t| {
            names(&c.browse_opc_item_id_list(t, "", 0, 0, &ns, &d).unwrap())
                .into_iter()
                .map(str::to_owned)
                .collect::<Vec<_>>()
        };
        c.change_browse_position(BrowseDirection::Down, ROOT, &d)
            .unwrap();
        assert_eq!(c.position(), ROOT);
        assert_eq!(l(&c, BrowseType::Branch), ["Server", "Clients", "Channels"]);
        assert!(l(&c, BrowseType::Leaf).is_empty());
        c.change_browse_position(BrowseDirection::Down, "Clients", &d)
            .unwrap();
        assert_eq!(l(&c, BrowseType::Branch), ["Client2", "HMI"]);
        c.change_browse_position(BrowseDirection::Down, "HMI", &d)
            .unwrap();
        assert_eq!(c.position(), "_Diagnostics.Clients.HMI");
        assert_eq!(
            l(&c, BrowseType::Leaf),
            [
                "Name",
                "Groups",
                "Items",
                "LastCallbackLatency",
                "CallbacksPending",
                "Failures",
                "Identity"
            ]
        );
        assert_eq!(
            c.get_item_id("Items", &d).unwrap(),
            "_Diagnostics.Clients.HMI.Items"
        );
        assert_eq!(c.get_item_id("", &d).unwrap(), "_Diagnostics.Clients.HMI");
        assert_eq!(c.get_item_id("Plant", &d), Err(OpcError::InvalidArg));
        assert_eq!(
            c.change_browse_position(BrowseDirection::Down, "Items", &d),
            Err(OpcError::InvalidArg)
        );
        for up in ["_Diagnostics.Clients", ROOT, ""] {
            c.change_browse_position(BrowseDirection::Up, "", &d)
                .unwrap();
            assert_eq!(c.position(), up);
        }
        assert_eq!(
            c.change_browse_position(BrowseDirection::Up, "", &d),
            Err(OpcError::Fail)
        );
        assert_eq!(l(&c, BrowseType::Branch), ["_Diagnostics", "Plant"]);
        // TO into the branch and out again.
        c.change_browse_position(BrowseDirection::To, "_Diagnostics.Server", &d)
            .unwrap();
        assert_eq!(l(&c, BrowseType::Leaf).len(), 9);
        assert_eq!(
            c.change_browse_position(BrowseDirection::To, "_Diagnostics.Server.Uptime", &d),
            Err(OpcError::InvalidArg)
        );
        c.change_browse_position(BrowseDirection::To, "Plant", &d)
            .unwrap();
        assert_eq!(l(&c, BrowseType::Leaf), ["A1", "A2"]);
        // Below the real root there is no branch, and DOWN to it is refused.
        assert_eq!(
            c.change_browse_position(BrowseDirection::Down, ROOT, &d),
            Err(OpcError::InvalidArg)
        );
        // GetItemID at the root knows the branch and the diagnostic IDs.
        c.change_browse_position(BrowseDirection::To, "", &d)
            .unwrap();
        assert_eq!(c.get_item_id(ROOT, &d).unwrap(), ROOT);
        assert_eq!(
            c.get_item_id("_Diagnostics.Server.Uptime", &d).unwrap(),
            "_Diagnostics.Server.Uptime"
        );
        assert_eq!(c.get_item_id("Top", &d).unwrap(), "Top");
        assert_eq!(c.get_item_id("nothing", &d), Err(OpcError::InvalidArg));
    }

    #[test]
    fn a_cursor_in_the_branch_of_a_client_that_left_lists_nothing_and_goes_up() {
        let (b, d) = board(&[Some("HMI")]);
        let ns = ns(&b);
        let mut c = Cursor::new(real(false));
        c.change_browse_position(BrowseDirection::To, "_Diagnostics.Clients.HMI", &d)
            .unwrap();
        let (_, gone) = board(&[]);
        let l = c
            .browse_opc_item_id_list(BrowseType::Leaf, "", 0, 0, &ns, &gone)
            .unwrap();
        assert!(l.is_empty());
        assert_eq!(
            c.get_item_id("", &gone).unwrap(),
            "_Diagnostics.Clients.HMI"
        );
        assert_eq!(c.get_item_id("Name", &gone), Err(OpcError::InvalidArg));
        assert_eq!(
            c.change_browse_position(BrowseDirection::Down, "Name", &gone),
            Err(OpcError::InvalidArg)
        );
        assert_eq!(
            c.change_browse_position(BrowseDirection::To, "_Diagnostics.Clients.HMI", &gone),
            Err(OpcError::InvalidArg)
        );
        c.change_browse_position(BrowseDirection::Up, "", &gone)
            .unwrap();
        assert_eq!(c.position(), "_Diagnostics.Clients");
        assert!(c
            .browse_opc_item_id_list(BrowseType::Branch, "", 0, 0, &ns, &gone)
            .unwrap()
            .is_empty());
    }

    #[test]
    fn a_flat_space_lists_the_diagnostic_ids_after_its_own() {
        let (b, d) = board(&[]);
        let ns = ns(&b);
        let mut c = Cursor::new(real(true));
        assert_eq!(c.query_organization(), NamespaceType::Flat);
        let l = c
            .browse_opc_item_id_list(BrowseType::Branch, "", 0, 0, &ns, &d)
            .unwrap();
        assert_eq!(l.len(), 3 + 9);
        assert_eq!(l.get(3), Some("_Diagnostics.Server.Uptime"));
        assert_eq!(
            c.change_browse_position(BrowseDirection::Down, ROOT, &d),
            Err(OpcError::Fail)
        );
        assert_eq!(
            c.get_item_id("_Diagnostics.Server.Items", &d).unwrap(),
            "_Diagnostics.Server.Items"
        );
    }

    fn ids(r: &BrowseResult) -> Vec<&str> {
        r.elements.iter().map(|e| e.item_id.as_str()).collect()
    }

    #[test]
    fn browse_shows_the_branch_first_pages_through_both_and_descends() {
        let (_, d) = board(&[Some("HMI")]);
        let r = real(false);
        let run = |s: &AddressSpace, q: &BrowseRequest<'_>| s.browse(q);
        let all = browse(&r, &d, &BrowseRequest::new(""), run).unwrap();
        assert_eq!(ids(&all), ["_Diagnostics", "Plant", "Top"]);
        assert!(all.elements[0].has_children && !all.elements[0].is_item);
        // One at a time: the branch, then the real root's own continuation points.
        let mut seen = Vec::new();
        let mut cp = String::new();
        loop {
            let req = BrowseRequest {
                continuation_point: &cp,
                max_elements: 1,
                ..BrowseRequest::new("")
            };
            let page = browse(&r, &d, &req, run).unwrap();
            seen.extend(ids(&page).into_iter().map(str::to_owned));
            if page.continuation_point.is_empty() {
                break;
            }
            cp = page.continuation_point;
        }
        assert_eq!(seen, ["_Diagnostics", "Plant", "Top"]);
        let two = BrowseRequest {
            max_elements: 2,
            ..BrowseRequest::new("")
        };
        let page = browse(&r, &d, &two, run).unwrap();
        assert_eq!(ids(&page), ["_Diagnostics", "Plant"]);
        assert!(!page.continuation_point.is_empty());
        // Filters.
        let items = BrowseRequest {
            filter: BrowseFilter::Items,
            ..BrowseRequest::new("")
        };
        assert_eq!(ids(&browse(&r, &d, &items, run).unwrap()), ["Top"]);
        // Inside.
        let inside = browse(&r, &d, &BrowseRequest::new(ROOT), run).unwrap();
        assert_eq!(
            ids(&inside),
            [
                "_Diagnostics.Server",
                "_Diagnostics.Clients",
                "_Diagnostics.Channels"
            ]
        );
        let client = browse(&r, &d, &BrowseRequest::new("_Diagnostics.Clients.HMI"), run).unwrap();
        assert_eq!(client.elements.len(), 7);
        assert!(client.elements.iter().all(|e| e.is_item && !e.has_children));
        assert_eq!(
            browse(
                &r,
                &d,
                &BrowseRequest::new("_Diagnostics.Clients.Gone"),
                run
            )
            .unwrap_err(),
            OpcError::UnknownItemId
        );
        assert_eq!(
            ids(&browse(&r, &d, &BrowseRequest::new("Plant"), run).unwrap()).len(),
            2
        );
    }
}
