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

pub use super::boundary::{
    ItemVqt, ReadItem, SourceItem, SourceKey, SourceReqId, SourceRequest, Subscription,
};
use super::cache::{CachedValue, NEVER};
use super::engine::Engine;
use super::transactions::SlotOut;
use crate::{OpcError, Timestamp, Vqt};

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
