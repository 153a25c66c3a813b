//! The bounds on what a client can make the server work on.
//!
//! Every text and every VARIANT a client sends is checked once, where the COM layer
//! decodes it, against one of these limits; a text over its limit fails with the OPC
//! error a malformed value of that kind fails with (an item ID too long is
//! `OPC_E_INVALIDITEMID`, as a malformed one is), so a client sees nothing new, only an
//! answer instead of unbounded work. The limits are far above anything a real asix item
//! ID, access path or name reaches (the longest in the demo plant is under 100
//! characters) and documented in `docs/limits.md`.
//!
//! Lengths count UTF-16 code units, what the client sent, before decoding: the check
//! costs nothing and a string over the limit is never decoded.

use crate::OpcError;

/// A bound on the length of one kind of client text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TextLimit {
    /// What the text is, for the log line (`"item ID"`, `"access path"`, ...).
    pub what: &'static str,
    /// The longest accepted text, in UTF-16 code units.
    pub max_units: usize,
    /// The error a longer text fails with.
    pub error: OpcError,
}

impl TextLimit {
    /// `Ok` for a text of `units` UTF-16 code units within the limit, else the limit's
    /// error.
    pub fn check_units(&self, units: usize) -> Result<(), OpcError> {
        if units <= self.max_units {
            Ok(())
        } else {
            Err(self.error)
        }
    }

    /// As [`TextLimit::check_units`] for a decoded text.
    pub fn check(&self, s: &str) -> Result<(), OpcError> {
        // A UTF-8 text has at least as many bytes as UTF-16 units: only count when needed.
        if s.len() <= self.max_units {
            return Ok(());
        }
        self.check_units(s.encode_utf16().count())
    }

    /// The same limit failing with another error (e.g. an item ID where the method's
    /// contract names E_INVALIDARG for a malformed one).
    pub const fn with_error(self, error: OpcError) -> TextLimit {
        TextLimit { error, ..self }
    }
}

/// Item IDs (AddItems, ValidateItems, IOPCItemIO, item properties, browse positions):
/// 4096 UTF-16 units, `OPC_E_INVALIDITEMID`.
pub const ITEM_ID: TextLimit = TextLimit {
    what: "item ID",
    max_units: 4096,
    error: OpcError::InvalidItemId,
};

/// Access paths of OPCITEMDEF: 4096 UTF-16 units, `OPC_E_UNKNOWNPATH`.
pub const ACCESS_PATH: TextLimit = TextLimit {
    what: "access path",
    max_units: 4096,
    error: OpcError::UnknownPath,
};

/// Group names (AddGroup, GetGroupByName, SetName, CloneGroup): 1024 UTF-16 units,
/// `E_INVALIDARG`.
pub const GROUP_NAME: TextLimit = TextLimit {
    what: "group name",
    max_units: 1024,
    error: OpcError::InvalidArg,
};

/// The client name (IOPCCommon::SetClientName): 1024 UTF-16 units, `E_INVALIDARG`.
pub const CLIENT_NAME: TextLimit = TextLimit {
    what: "client name",
    max_units: 1024,
    error: OpcError::InvalidArg,
};

/// Browse filters (name and vendor filters, MatchPattern patterns): 1024 UTF-16 units,
/// `OPC_E_INVALIDFILTER`.
pub const FILTER: TextLimit = TextLimit {
    what: "browse filter",
    max_units: 1024,
    error: OpcError::InvalidFilter,
};

/// Continuation points of IOPCBrowse::Browse (the server's own are far shorter): 4096
/// UTF-16 units, `OPC_E_INVALIDCONTINUATIONPOINT`.
pub const CONTINUATION_POINT: TextLimit = TextLimit {
    what: "continuation point",
    max_units: 4096,
    error: OpcError::InvalidContinuationPoint,
};

/// Array levels one VARIANT may hold: a VT_ARRAY is one level, an array inside one of
/// its VT_VARIANT elements another, and a VT_BYREF VT_VARIANT counts as one too. The
/// original's extended write `[value, quality, timestamp]` is one level, two with an
/// array value; four leaves room for a VARIANT array of such arrays. A deeper value
/// fails for its item with `OPC_E_BADTYPE` before anything is decoded below the limit.
pub const MAX_VARIANT_DEPTH: usize = 4;

/// Elements (at every level together) one VARIANT may hold: 1,048,576. A larger value
/// fails for its item with `OPC_E_BADTYPE`.
pub const MAX_VARIANT_ELEMENTS: usize = 1 << 20;

/// The work budget of decoding one client VARIANT: its depth and element count, against
/// [`MAX_VARIANT_DEPTH`] and [`MAX_VARIANT_ELEMENTS`]. The COM decoder enters one level
/// per array (or BYREF VARIANT) and takes the elements of each array before reading
/// them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodeBudget {
    depth: usize,
    elements: usize,
}

impl Default for DecodeBudget {
    fn default() -> Self {
        DecodeBudget::new()
    }
}

impl DecodeBudget {
    /// A full budget for one value.
    pub const fn new() -> DecodeBudget {
        DecodeBudget {
            depth: 0,
            elements: 0,
        }
    }

    /// One level deeper; `OPC_E_BADTYPE` past [`MAX_VARIANT_DEPTH`]. Pair with
    /// [`DecodeBudget::leave`].
    pub fn enter(&mut self) -> Result<(), OpcError> {
        if self.depth >= MAX_VARIANT_DEPTH {
            return Err(OpcError::BadType);
        }
        self.depth += 1;
        Ok(())
    }

    /// Back up one level.
    pub fn leave(&mut self) {
        self.depth = self.depth.saturating_sub(1);
    }

    /// `n` more elements; `OPC_E_BADTYPE` past [`MAX_VARIANT_ELEMENTS`] in all.
    pub fn take(&mut self, n: usize) -> Result<(), OpcError> {
        match self.elements.checked_add(n) {
            Some(total) if total <= MAX_VARIANT_ELEMENTS => {
                self.elements = total;
                Ok(())
            }
            _ => Err(OpcError::BadType),
        }
    }

    /// The current depth (0 at the top-level VARIANT).
    pub fn depth(&self) -> usize {
        self.depth
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texts_at_the_limit_pass_and_one_unit_more_fails_with_the_limits_error() {
        for limit in [
            ITEM_ID,
            ACCESS_PATH,
            GROUP_NAME,
            CLIENT_NAME,
            FILTER,
            CONTINUATION_POINT,
        ] {
            let at = "a".repeat(limit.max_units);
            let over = "a".repeat(limit.max_units + 1);
            assert_eq!(limit.check(&at), Ok(()), "{}", limit.what);
            assert_eq!(limit.check(&over), Err(limit.error), "{}", limit.what);
            assert_eq!(limit.check_units(limit.max_units), Ok(()));
            assert_eq!(limit.check_units(limit.max_units + 1), Err(limit.error));
        }
        assert_eq!(ITEM_ID.error, OpcError::InvalidItemId);
        assert_eq!(ACCESS_PATH.error, OpcError::UnknownPath);
        assert_eq!(GROUP_NAME.error, OpcError::InvalidArg);
        assert_eq!(CLIENT_NAME.error, OpcError::InvalidArg);
        assert_eq!(FILTER.error, OpcError::InvalidFilter);
    }

    #[test]
    fn lengths_count_utf16_units_not_bytes() {
        // 'ł' is 2 bytes in UTF-8, 1 unit in UTF-16; an emoji is 4 bytes, 2 units.
        let polish = "ł".repeat(ITEM_ID.max_units);
        assert_eq!(ITEM_ID.check(&polish), Ok(()));
        let emoji = "\u{1F600}".repeat(ITEM_ID.max_units / 2);
        assert_eq!(ITEM_ID.check(&emoji), Ok(()));
        let emoji_over = format!("{emoji}a");
        assert_eq!(ITEM_ID.check(&emoji_over), Err(OpcError::InvalidItemId));
    }

    #[test]
    fn with_error_keeps_the_bound() {
        let l = ITEM_ID.with_error(OpcError::InvalidArg);
        assert_eq!(l.max_units, ITEM_ID.max_units);
        assert_eq!(l.check(&"x".repeat(5000)), Err(OpcError::InvalidArg));
    }

    #[test]
    fn the_budget_allows_max_depth_levels_and_refuses_one_more() {
        let mut b = DecodeBudget::new();
        for _ in 0..MAX_VARIANT_DEPTH {
            assert_eq!(b.enter(), Ok(()));
        }
        assert_eq!(b.depth(), MAX_VARIANT_DEPTH);
        assert_eq!(b.enter(), Err(OpcError::BadType));
        b.leave();
        assert_eq!(b.enter(), Ok(()));
        for _ in 0..=MAX_VARIANT_DEPTH {
            b.leave();
        }
        assert_eq!(b.depth(), 0);
    }

    #[test]
    fn the_budget_counts_elements_over_all_levels() {
        let mut b = DecodeBudget::new();
        assert_eq!(b.take(MAX_VARIANT_ELEMENTS - 1), Ok(()));
        assert_eq!(b.take(1), Ok(()));
        assert_eq!(b.take(1), Err(OpcError::BadType));
        let mut b = DecodeBudget::new();
        assert_eq!(b.take(usize::MAX), Err(OpcError::BadType));
    }
}
