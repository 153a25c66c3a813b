//! Browsing the server address space: the tree ([`AddressSpace`]), the DA 2.05a
//! `IOPCBrowseServerAddressSpace` cursor ([`BrowseCursor`]), DA 3.0 `IOPCBrowse::Browse`
//! ([`AddressSpace::browse`]) and the `MatchPattern` name filter ([`pattern`]).
//!
//! The asix original (manual §6.6.2.3): the selected variable set is a hierarchical space —
//! groups are branches, variables leaves (with "attributes visible as items", variables are
//! branches whose leaves are value, description, unit, high and low range); branch / leaf /
//! flat filters; a `MatchPattern` name filter; no data-type or access-rights filtering;
//! `GetItemID` returns the bare variable name; `BrowseAccessPaths` says access paths cannot
//! be browsed.
//!
//! Behaviour where the specification is terse, and the evidence for each choice (OPC
//! Foundation sample server `COpcDaServer.cpp` / `COpcDaCache.cpp`, "sample" below):
//! - `ChangeBrowsePosition`: UP at the root is `E_FAIL` (spec text, sample); DOWN to an
//!   unknown name, a leaf or `""` is `E_INVALIDARG` (sample); TO `""` is the root, TO an
//!   unknown ID or a leaf's ID is `E_INVALIDARG` (sample); any call on a flat space is
//!   `E_FAIL` (spec: "will return E_FAIL if called for a FLAT space").
//! - `BrowseOPCItemIDs`: an empty result is success with an empty list, which the COM layer
//!   returns as `S_FALSE` with an empty enumerator (sample: `(uCount > 0) ? S_OK : S_FALSE`).
//!   `OPC_LEAF` lists nodes without children (sample), so a branch that is also an item
//!   shows under `OPC_BRANCH` only; `OPC_FLAT` lists the item IDs of every item at and below
//!   the position (sample), once per item ID; the name filter is matched against the
//!   returned string (short name, or item ID for `OPC_FLAT`). A malformed filter is
//!   `OPC_E_INVALIDFILTER` (a listed return code of the method) rather than an empty list.
//!   Unlike the original, the data-type and access-rights filters apply (DA 2.05a; the
//!   data type matched against the canonical type, see
//!   [`BrowseCursor::browse_opc_item_ids`] for why).
//! - `GetItemID("")` is the current position's ID (`""` at the root; spec and sample). It
//!   also accepts the strings `OPC_FLAT` returned at this position (item IDs below it).
//! - `IOPCBrowse::Browse`: `""` is the root; an ID not in the tree is
//!   `OPC_E_UNKNOWNITEMID`; browsing a leaf is success with no elements (sample); a
//!   continuation point that is malformed, from another address space or from a different
//!   item/filter set is `OPC_E_INVALIDCONTINUATIONPOINT`. Continuation points are supported,
//!   so `pbMoreElements` stays FALSE (spec: TRUE is for servers *without* continuation
//!   points; sample does the same); a continuation point is only returned when another
//!   matching element exists. The vendor filter is ignored. `HASCHILDREN` is set for every
//!   branch, even an empty group (the spec allows it as a hint).
//! - `MatchPattern` case: the OPC Foundation `OpcMatchPattern` defaults to case-insensitive
//!   and its sample browses with that default, so browse filters are case-insensitive unless
//!   the space is built with [`MatchCase::Sensitive`]. Names themselves (DOWN, GetItemID,
//!   item IDs) are compared exactly: asix names are case-sensitive.

pub mod browse3;
pub mod pattern;
pub mod server_browse;
pub mod tree;

pub use browse3::{BrowseElement, BrowseRequest, BrowseResult, PropertySelection};
pub use pattern::{escape, match_pattern, MatchCase, Pattern, PatternError};
pub use server_browse::{BrowseCursor, ItemFilter, NameList};
pub use tree::{AddressSpace, AddressSpaceBuilder, BuildError, NodeId, NodeRef};

use crate::OpcError;

/// `OPCBROWSEELEMENT.dwFlagValue` bit: the element has children (can be browsed).
pub const OPC_BROWSE_HASCHILDREN: u32 = 0x01;
/// `OPCBROWSEELEMENT.dwFlagValue` bit: the element is an item.
pub const OPC_BROWSE_ISITEM: u32 = 0x02;

macro_rules! opc_enum {
    ($(#[$m:meta])* $name:ident { $( $(#[$vm:meta])* $v:ident = $n:literal ),* $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[repr(u32)]
        pub enum $name { $( $(#[$vm])* $v = $n ),* }

        impl TryFrom<u32> for $name {
            type Error = OpcError;
            /// Unknown values are `E_INVALIDARG`.
            fn try_from(v: u32) -> Result<Self, OpcError> {
                match v { $( $n => Ok($name::$v), )* _ => Err(OpcError::InvalidArg) }
            }
        }

        impl From<$name> for u32 {
            fn from(v: $name) -> u32 { v as u32 }
        }
    };
}

opc_enum! {
    /// `OPCNAMESPACETYPE`, the answer of `QueryOrganization`.
    NamespaceType { Hierarchical = 1, Flat = 2 }
}

opc_enum! {
    /// `OPCBROWSEDIRECTION` of `ChangeBrowsePosition`.
    BrowseDirection { Up = 1, Down = 2, To = 3 }
}

opc_enum! {
    /// `OPCBROWSETYPE` of `BrowseOPCItemIDs`.
    BrowseType {
        /// Children that are branches.
        Branch = 1,
        /// Children without children.
        Leaf = 2,
        /// Item IDs of all items at and below the position.
        Flat = 3,
    }
}

opc_enum! {
    /// `OPCBROWSEFILTER` of `IOPCBrowse::Browse`.
    BrowseFilter {
        All = 1,
        /// Elements with `OPC_BROWSE_HASCHILDREN`.
        Branches = 2,
        /// Elements with `OPC_BROWSE_ISITEM`.
        Items = 3,
    }
}

/// Compiles a browse name filter: `""` is no filter; a malformed pattern is
/// `OPC_E_INVALIDFILTER`.
pub(crate) fn name_filter(filter: &str, case: MatchCase) -> Result<Option<Pattern>, OpcError> {
    if filter.is_empty() {
        return Ok(None);
    }
    let p = Pattern::new(filter, case).map_err(|_| OpcError::InvalidFilter)?;
    Ok((!p.matches_everything()).then_some(p))
}

/// Whether `name` passes an optional compiled filter.
pub(crate) fn passes(filter: &Option<Pattern>, name: &str) -> bool {
    match filter {
        Some(p) => p.matches(name),
        None => true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enum_values_are_the_idl_values_and_unknown_values_are_invalidarg() {
        assert_eq!(u32::from(NamespaceType::Hierarchical), 1);
        assert_eq!(u32::from(NamespaceType::Flat), 2);
        assert_eq!(BrowseDirection::try_from(1), Ok(BrowseDirection::Up));
        assert_eq!(BrowseDirection::try_from(3), Ok(BrowseDirection::To));
        assert_eq!(BrowseDirection::try_from(0), Err(OpcError::InvalidArg));
        assert_eq!(BrowseType::try_from(3), Ok(BrowseType::Flat));
        assert_eq!(BrowseType::try_from(4), Err(OpcError::InvalidArg));
        assert_eq!(BrowseFilter::try_from(2), Ok(BrowseFilter::Branches));
        assert_eq!(BrowseFilter::try_from(0), Err(OpcError::InvalidArg));
        assert_eq!(OPC_BROWSE_HASCHILDREN | OPC_BROWSE_ISITEM, 3);
    }

    #[test]
    fn empty_filter_is_no_filter_and_malformed_filter_is_invalidfilter() {
        assert_eq!(name_filter("", MatchCase::Insensitive), Ok(None));
        assert_eq!(name_filter("*", MatchCase::Insensitive), Ok(None));
        assert!(name_filter("a*", MatchCase::Insensitive).unwrap().is_some());
        assert_eq!(
            name_filter("[a", MatchCase::Insensitive),
            Err(OpcError::InvalidFilter)
        );
    }
}
