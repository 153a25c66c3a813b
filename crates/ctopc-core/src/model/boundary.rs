//! The types at the boundary between the engine and the data source: the key of a source
//! item, what the engine asks of the source, and the values it writes. A leaf: the item
//! cache (`cache.rs`) makes requests of them without the engine's side of the boundary
//! (`datasource.rs`, which re-exports them).

use std::sync::Arc;

use crate::{Quality, Timestamp, Value, VarType};

/// The engine's handle of a source item (index plus generation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SourceKey {
    index: u32,
    generation: u32,
}

impl SourceKey {
    /// The key of slot `index` in its `generation`: a backend that keeps an item's
    /// generation in a table of its own at the index makes the key again from both (a key
    /// the engine did not hand out is unknown to it).
    pub const fn new(index: u32, generation: u32) -> Self {
        SourceKey { index, generation }
    }
    /// Slot index (dense, small: a backend may use it to index its own tables).
    pub const fn index(self) -> u32 {
        self.index
    }
    pub const fn generation(self) -> u32 {
        self.generation
    }
}

/// Identifies one device read or write request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SourceReqId(pub u64);

/// A source item as the backend needs to address it.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceItem {
    pub key: SourceKey,
    /// The asix channel (resolved access path), `*` for the basic channel.
    pub channel: Arc<str>,
    /// The item as the data source knows it ([`crate::namespace::ItemDef::source_key`]).
    pub item_id: Arc<str>,
    pub canonical_type: VarType,
}

/// An item of a device read ([`SourceRequest::Read`]).
#[derive(Debug, Clone, PartialEq)]
pub enum ReadItem {
    /// A key the source holds: its [`SourceRequest::Subscribe`] came before this request,
    /// and no [`SourceRequest::Unsubscribe`] since. The engine names it by its key alone,
    /// as the source knows it already (an item ID would cost an allocation per item and
    /// read).
    Subscribed(SourceKey),
    /// An item the source does not hold.
    Item(SourceItem),
}

impl ReadItem {
    /// The item's key.
    pub fn key(&self) -> SourceKey {
        match self {
            ReadItem::Subscribed(k) => *k,
            ReadItem::Item(i) => i.key,
        }
    }

    /// The whole item, when the request carries it.
    pub fn item(&self) -> Option<&SourceItem> {
        match self {
            ReadItem::Subscribed(_) => None,
            ReadItem::Item(i) => Some(i),
        }
    }
}

/// A subscription: push samples of `item` at least every `sampling_rate_ms`.
#[derive(Debug, Clone, PartialEq)]
pub struct Subscription {
    pub item: SourceItem,
    pub sampling_rate_ms: u32,
}

/// A value to write with optional quality and timestamp (OPCITEMVQT). Both `None` is a
/// simple write (asix stamps time and good quality).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ItemVqt {
    pub value: Value,
    pub quality: Option<Quality>,
    pub timestamp: Option<Timestamp>,
}

impl ItemVqt {
    pub fn value(value: Value) -> Self {
        ItemVqt {
            value,
            quality: None,
            timestamp: None,
        }
    }
}

/// What the engine asks of the data source.
#[derive(Debug, Clone, PartialEq)]
pub enum SourceRequest {
    Subscribe(Vec<Subscription>),
    SetSamplingRate(Vec<(SourceKey, u32)>),
    Unsubscribe(Vec<SourceKey>),
    /// Read from the device; answer with `handle_source_read_result(req_id, ..)`.
    Read {
        req_id: SourceReqId,
        items: Vec<ReadItem>,
    },
    /// Write values (already converted to the canonical type); answer with
    /// `handle_source_write_result(req_id, ..)`.
    Write {
        req_id: SourceReqId,
        items: Vec<(SourceItem, Value)>,
    },
    /// Write values with quality and/or timestamp (WriteVQT, or the asix extended write
    /// through a 3-element array); answer with `handle_source_write_result(req_id, ..)`.
    WriteVqt {
        req_id: SourceReqId,
        items: Vec<(SourceItem, ItemVqt)>,
    },
}
