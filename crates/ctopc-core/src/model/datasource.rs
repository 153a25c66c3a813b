//! The boundary between the engine and the data source (the asix network client, a
//! simulator, a test fake).
//!
//! The source **pushes** samples with [`Engine::handle_source_updates`] (the COM layer owns
//! the non-blocking queue between the backend thread and the engine and hands over batches)
//! and **learns** what to do from [`Engine::poll_source_request`]:
//!
//! - [`SourceRequest::Subscribe`]: these items became wanted (the first active item in an
//!   active group, over all sessions, referring to them), at the given sampling rate (the
//!   fastest any subscriber asks for). Push every sample from now on, changed or not (the
//!   engine does change detection and needs the sample times for MaxAge).
//! - [`SourceRequest::SetSamplingRate`]: the fastest requested rate of subscribed items
//!   changed.
//! - [`SourceRequest::Unsubscribe`]: the last subscriber went away.
//! - [`SourceRequest::Read`], [`SourceRequest::Write`], [`SourceRequest::WriteVqt`]: device
//!   I/O; answer with [`Engine::handle_source_read_result`] /
//!   [`Engine::handle_source_write_result`], one result per item in request order (ASKOM
//!   codes such as ASKOM_E_NetAnswerTimeout or ASKOM_E_WriteError belong here).
//!
//! Subscription changes are netted per item between two polls: an item added and removed
//! again before the backend polled is never announced. Constant items (database attributes,
//! [`crate::namespace::ItemDef::constant`]) never reach the source.
//!
//! A [`SourceKey`] is the engine's compact handle of a source item (no string hashing per
//! sample). It carries a generation: once an item is unsubscribed and no group refers to it
//! any more its slot may be reused for another item, and samples still queued under the old
//! key are dropped.

use std::sync::Arc;

use super::cache::{CachedValue, NEVER};
use super::engine::Engine;
use super::transactions::SlotOut;
use crate::{OpcError, Quality, Timestamp, Value, VarType, Vqt};

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
        items: Vec<SourceItem>,
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

impl Engine {
    /// Takes a batch of samples from the data source. Samples for unknown or stale keys
    /// and for constant items are ignored. Never blocks, allocates only for strings and
    /// arrays that changed.
    pub fn handle_source_updates<I>(&mut self, now: Timestamp, updates: I)
    where
        I: IntoIterator<Item = (SourceKey, Vqt)>,
    {
        for (key, vqt) in updates {
            match self.sources.get(key) {
                Some(e) if !e.is_constant() => {}
                _ => continue,
            }
            self.sources
                .apply(key.index(), vqt, now, &mut self.change_seq);
            if !self.buffer_refs.is_empty() {
                self.buffer_sample(key.index());
            }
        }
        self.wake_first_sample_waiters(now);
    }

    /// The next request for the data source, if any.
    pub fn poll_source_request(&mut self) -> Option<SourceRequest> {
        if self.requests.is_empty() {
            self.sources.flush(&mut self.requests);
        }
        self.requests.pop_front()
    }

    /// The source item behind a key (for backends that keep no table of their own).
    pub fn source_item(&self, key: SourceKey) -> Option<SourceItem> {
        self.sources.get(key)?;
        Some(self.sources.source_item(key.index()))
    }

    /// Answers a [`SourceRequest::Read`]: one result per requested item, in order (missing
    /// results count as E_FAIL). Good values also refresh the cache.
    pub fn handle_source_read_result(
        &mut self,
        now: Timestamp,
        req_id: SourceReqId,
        results: Vec<Result<Vqt, OpcError>>,
    ) {
        let Some(tid) = self.txns.by_req.remove(&req_id.0) else {
            return;
        };
        let Some(mut txn) = self.txns.map.remove(&tid) else {
            return;
        };
        let remote = std::mem::take(&mut txn.remote);
        let mut results = results.into_iter();
        for slot_idx in remote {
            let r = results.next().unwrap_or(Err(OpcError::Fail));
            let slot = &mut txn.slots[slot_idx as usize];
            slot.out = match r {
                Err(e) => SlotOut::Err(e),
                Ok(vqt) => {
                    let key = SourceKey::new(slot.source, slot.source_gen);
                    match self.sources.get(key) {
                        Some(e) if !e.is_constant() => {
                            self.sources
                                .apply(key.index(), vqt, now, &mut self.change_seq);
                            let s = self
                                .sources
                                .sample(&self.sources.entries[slot.source as usize]);
                            SlotOut::Raw {
                                value: s.value.into_owned(),
                                quality: s.quality,
                                timestamp: s.timestamp,
                            }
                        }
                        _ => SlotOut::Raw {
                            value: CachedValue::from_value(vqt.value),
                            quality: vqt.quality,
                            timestamp: vqt.timestamp,
                        },
                    }
                }
            };
        }
        self.complete_txn(now, tid, txn);
        self.wake_first_sample_waiters(now);
    }

    /// Answers a [`SourceRequest::Write`] or [`SourceRequest::WriteVqt`]: one result per
    /// item, in order (missing results count as E_FAIL).
    pub fn handle_source_write_result(
        &mut self,
        now: Timestamp,
        req_id: SourceReqId,
        results: Vec<Result<(), OpcError>>,
    ) {
        let Some(tid) = self.txns.by_req.remove(&req_id.0) else {
            return;
        };
        let Some(mut txn) = self.txns.map.remove(&tid) else {
            return;
        };
        let remote = std::mem::take(&mut txn.remote);
        let mut results = results.into_iter();
        for slot_idx in remote {
            let r = results.next().unwrap_or(Err(OpcError::Fail));
            txn.slots[slot_idx as usize].out = SlotOut::Written(r.err());
        }
        self.complete_txn(now, tid, txn);
    }

    /// Fails every item still waiting in a source request (timeout).
    pub(crate) fn fail_source_request(&mut self, now: Timestamp, req: u64, error: OpcError) {
        let Some(tid) = self.txns.by_req.remove(&req) else {
            return;
        };
        let Some(mut txn) = self.txns.map.remove(&tid) else {
            return;
        };
        let write = txn.kind.is_write();
        for slot_idx in std::mem::take(&mut txn.remote) {
            txn.slots[slot_idx as usize].out = if write {
                SlotOut::Written(Some(error))
            } else {
                SlotOut::Err(error)
            };
        }
        self.complete_txn(now, tid, txn);
    }
}

/// True when a cache entry was refreshed by the source within `max_age` ms of `now`.
pub(crate) fn fresh(refreshed_at: Timestamp, now: Timestamp, max_age: u32) -> bool {
    refreshed_at != NEVER && now.millis_since(refreshed_at) <= u64::from(max_age)
}
