//! Reads, writes and refreshes: IOPCSyncIO/2 and IOPCAsyncIO2/3.
//!
//! Every operation that needs the data source becomes a transaction holding one slot per
//! item and (at most) one source request. Synchronous calls answer at once when everything
//! comes from the cache or from constants ([`SyncOutcome::Ready`]); otherwise they return a
//! [`SyncId`] and the COM layer waits (with the engine unlocked) until
//! [`Engine::take_sync_result`] has the answer: the backend answered, or the engine timed
//! the request out ([`super::EngineConfig::source_timeout_ms`]). The thread driving the
//! engine learns from [`Engine::poll_sync_completion`] which operations completed in a
//! step ([`crate::driver::Step::sync_completed`]) and wakes the waiters only then; a waiter
//! that gives up (its own NetTimeout) calls [`Engine::abandon_sync`].
//!
//! Asynchronous calls return a server-generated cancel ID and complete through
//! [`Engine::poll_event`] (OnReadComplete, OnDataChange for refreshes, OnWriteComplete).
//! Items whose handle or access fails at call time are answered in the call's per-item
//! results and left out of the callback. Cancel2 succeeds until the completion event has
//! been taken with `poll_event` (then OnCancelComplete replaces it); afterwards, or for an
//! unknown cancel ID, it fails with E_FAIL.

use super::cache::{CachedValue, SourceEntry};
use super::datasource::{fresh, ItemVqt, ReadItem, SourceItem, SourceReqId, SourceRequest};
use super::engine::{Engine, GroupHandle, SessionHandle};
use super::events::{
    master_codes, CancelComplete, DataChange, DataChangeKind, Event, ItemState, ItemValue,
    ReadComplete, WriteComplete, WriteResult,
};
use super::group::Group;
use super::item::ItemFlags;
use super::util::IntMap;
use super::MAX_AGE_CACHE;
use crate::convert::{convert_for_write, Locale};
use crate::namespace::Namespace;
use crate::{OpcError, Quality, Timestamp, Value, VarType};

/// OPCDATASOURCE.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataSource {
    Cache,
    Device,
}

/// A synchronous operation waiting for the data source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SyncId(pub u64);

/// Per-item results of a synchronous read, in input order.
pub type ReadResults = Vec<Result<ItemState, OpcError>>;
/// Per-item results of a synchronous write, in input order.
pub type WriteResults = Vec<Result<(), OpcError>>;

/// A synchronous call's answer: now, or later through [`Engine::take_sync_result`].
#[derive(Debug, Clone, PartialEq)]
pub enum SyncOutcome<T> {
    Ready(T),
    Pending(SyncId),
}

/// The answer of a synchronous operation that waited for the data source.
#[derive(Debug, Clone, PartialEq)]
pub enum SyncResult {
    Read(ReadResults),
    Write(WriteResults),
}

/// An asynchronous call was accepted.
#[derive(Debug, Clone, PartialEq)]
pub struct AsyncStarted {
    /// The server's cancel ID; 0 when no item was valid (nothing queued, no callback).
    pub cancel_id: u32,
    /// Per-item results of the call, in input order.
    pub results: Vec<Result<(), OpcError>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum TxnKind {
    SyncRead,
    SyncWrite,
    Read,
    Refresh,
    Write,
}

impl TxnKind {
    pub fn is_write(self) -> bool {
        matches!(self, TxnKind::SyncWrite | TxnKind::Write)
    }
    pub fn is_sync(self) -> bool {
        matches!(self, TxnKind::SyncRead | TxnKind::SyncWrite)
    }
}

#[derive(Debug)]
pub(crate) enum SlotOut {
    Pending,
    Raw {
        value: CachedValue,
        quality: Quality,
        timestamp: Timestamp,
    },
    Err(OpcError),
    Written(Option<OpcError>),
}

#[derive(Debug)]
pub(crate) struct Slot {
    pub item: u32,
    pub client: u32,
    pub source: u32,
    pub source_gen: u32,
    pub req_type: VarType,
    pub out: SlotOut,
}

#[derive(Debug)]
pub(crate) struct Txn {
    pub kind: TxnKind,
    pub session: SessionHandle,
    pub group: GroupHandle,
    pub client_group: u32,
    pub transaction_id: u32,
    pub cancel_id: u32,
    pub locale: Locale,
    pub slots: Vec<Slot>,
    /// Slots waiting for the source, in request order.
    pub remote: Vec<u32>,
    pub req: u64,
    /// The transaction holds a cache reference per slot (IOPCItemIO: no group item keeps
    /// the entries alive); released when it ends.
    pub holds_refs: bool,
}

#[derive(Default)]
pub(crate) struct Txns {
    pub map: IntMap<u64, Txn>,
    next_id: u64,
    pub by_req: IntMap<u64, u64>,
    pub by_cancel: IntMap<u32, u64>,
    next_req: u64,
    next_cancel: u32,
    pub sync_done: IntMap<u64, SyncResult>,
    /// Synchronous operations completed since the last `poll_sync_completion`.
    pub sync_completed: std::collections::VecDeque<SyncId>,
}

impl Txns {
    fn new_id(&mut self) -> u64 {
        self.next_id += 1;
        self.next_id
    }
    fn new_req(&mut self) -> u64 {
        self.next_req += 1;
        self.next_req
    }
    fn new_cancel(&mut self) -> u32 {
        loop {
            self.next_cancel = self.next_cancel.wrapping_add(1);
            if self.next_cancel != 0 && !self.by_cancel.contains_key(&self.next_cancel) {
                return self.next_cancel;
            }
        }
    }
    /// Drops the asynchronous transactions of a removed group (synchronous ones still
    /// complete: a COM thread waits for them).
    pub fn drop_group(&mut self, group: GroupHandle) {
        let ids: Vec<u64> = self
            .map
            .iter()
            .filter(|(_, t)| t.group == group && !t.kind.is_sync())
            .map(|(id, _)| *id)
            .collect();
        for id in ids {
            if let Some(t) = self.map.remove(&id) {
                self.by_cancel.remove(&t.cancel_id);
                self.by_req.remove(&t.req);
            }
        }
    }
}

/// The cached value converted for a client.
pub(crate) fn item_value(
    client: u32,
    value: &CachedValue,
    quality: Quality,
    timestamp: Timestamp,
    req: VarType,
    locale: Locale,
) -> ItemValue {
    let v = value.to_value();
    let converted = if req == VarType::EMPTY || req == VarType::VARIANT || req == v.var_type() {
        Ok(v)
    } else {
        v.convert_in(req, locale)
    };
    match converted {
        Ok(value) => ItemValue {
            client_handle: client,
            value,
            quality,
            timestamp,
            error: None,
        },
        Err(e) => ItemValue {
            client_handle: client,
            value: Value::Empty,
            quality: Quality::BAD,
            timestamp,
            error: Some(e),
        },
    }
}

fn slot_item_value(slot: &Slot, locale: Locale) -> ItemValue {
    match &slot.out {
        SlotOut::Raw {
            value,
            quality,
            timestamp,
        } => item_value(
            slot.client,
            value,
            *quality,
            *timestamp,
            slot.req_type,
            locale,
        ),
        SlotOut::Err(e) => ItemValue {
            client_handle: slot.client,
            value: Value::Empty,
            quality: Quality::BAD,
            timestamp: Timestamp(0),
            error: Some(*e),
        },
        SlotOut::Pending | SlotOut::Written(_) => ItemValue {
            client_handle: slot.client,
            value: Value::Empty,
            quality: Quality::BAD,
            timestamp: Timestamp(0),
            error: Some(OpcError::Fail),
        },
    }
}

/// How a read picks between cache and device.
#[derive(Clone, Copy)]
enum ReadMode {
    /// OPC_DS_CACHE: inactive items or groups read BAD Out of Service.
    Cache,
    Device,
    MaxAge(u32),
}

/// A value prepared for writing: converted to the canonical type.
struct PreparedWrite {
    value: Value,
    quality: Option<Quality>,
    timestamp: Option<Timestamp>,
}

/// Checks and converts a value to write. A 1-D 3-element array written to a scalar item is
/// the asix extended write [value, quality, timestamp (DATE)]. The value is converted to
/// the canonical type by [`convert_for_write`] (numeric text in the group's locale, BOOL
/// as 1/0, CY, every number; range-checked: OPC_E_RANGE; DATE and other text:
/// OPC_E_BADTYPE), and the converted value must pass the namespace's
/// [`Namespace::check_write_value`].
///
/// A VT_EMPTY value with a quality or a timestamp (WriteVQT/WriteVQE "quality only",
/// "timestamp only", or the extended write's value element) asks to write the quality
/// or the timestamp without a value: the data source cannot (an asix write always carries
/// a value), so it is OPC_E_NOTSUPPORTED, DA 3.0's code for "the server does not support
/// writing of quality and/or timestamp"; VT_EMPTY alone stays OPC_E_BADTYPE. The
/// extended write's quality must fit the 16 bits of an OPC quality (OPC_E_RANGE
/// otherwise: it is not truncated).
///
/// `allowed` is the write-rights policy's answer for the caller
/// ([`Engine::may_write`]): a refused write is OPC_E_BADRIGHTS, after the item's own
/// access rights and before any conversion.
fn prepare_write(
    ns: &dyn Namespace,
    e: &SourceEntry,
    w: &ItemVqt,
    locale: Locale,
    allowed: bool,
) -> Result<PreparedWrite, OpcError> {
    if !e.writable() || !allowed {
        return Err(OpcError::BadRights);
    }
    let (value, mut quality, mut timestamp) = (&w.value, w.quality, w.timestamp);
    let value = match value {
        Value::Array(a)
            if !e.canonical.is_array()
                && a.elements.len() == 3
                && quality.is_none()
                && timestamp.is_none() =>
        {
            let q = match a.elements[1].convert_in(VarType::UI2, locale) {
                Ok(Value::UI2(q)) => q,
                Err(OpcError::Overflow) => return Err(OpcError::Range),
                _ => return Err(OpcError::BadType),
            };
            let t = a.elements[2]
                .convert_in(VarType::DATE, locale)
                .map_err(|_| OpcError::BadType)?;
            let Value::Date(t) = t else {
                return Err(OpcError::BadType);
            };
            quality = Some(Quality(q));
            timestamp = Some(Timestamp::from_ole_date(t).ok_or(OpcError::BadType)?);
            &a.elements[0]
        }
        v => v,
    };
    if matches!(value, Value::Empty) {
        return Err(if quality.is_some() || timestamp.is_some() {
            OpcError::NotSupported
        } else {
            OpcError::BadType
        });
    }
    let value = convert_for_write(value, e.canonical, locale)?;
    ns.check_write_value(&value)?;
    Ok(PreparedWrite {
        value,
        quality,
        timestamp,
    })
}

impl Engine {
    fn txn_header(&mut self, kind: TxnKind, slot: usize, transaction_id: u32) -> Txn {
        let cancel_id = if kind.is_sync() {
            0
        } else {
            self.txns.new_cancel()
        };
        let g = self.group(slot);
        Txn {
            kind,
            session: g.session,
            group: g.handle,
            client_group: g.client_handle,
            transaction_id,
            cancel_id,
            locale: self.locale(g.lcid),
            slots: Vec::new(),
            remote: Vec::new(),
            req: 0,
            holds_refs: false,
        }
    }

    /// Drops the cache references an IOPCItemIO transaction holds.
    fn release_txn_refs(&mut self, txn: &Txn) {
        if txn.holds_refs {
            for s in &txn.slots {
                if s.source != u32::MAX {
                    self.sources.release(s.source);
                }
            }
        }
    }

    /// A read slot for one item: answered from the cache (or constant), or pending.
    fn read_slot(&self, g: &Group, handle: u32, mode: ReadMode, now: Timestamp) -> Slot {
        let Some(i) = g.find(handle) else {
            return Slot {
                item: handle,
                client: 0,
                source: u32::MAX,
                source_gen: 0,
                req_type: VarType::EMPTY,
                out: SlotOut::Err(OpcError::InvalidHandle),
            };
        };
        let it = &g.items[i];
        let e = &self.sources.entries[it.source as usize];
        let mut slot = Slot {
            item: handle,
            client: it.client,
            source: it.source,
            source_gen: e.generation,
            req_type: it.req_type,
            out: SlotOut::Pending,
        };
        if !e.readable() {
            slot.out = SlotOut::Err(OpcError::BadRights);
            return slot;
        }
        let from_cache = match mode {
            ReadMode::Cache => true,
            ReadMode::Device => e.is_constant(),
            ReadMode::MaxAge(age) => {
                e.is_constant()
                    || age == MAX_AGE_CACHE
                    || (age != 0 && fresh(self.sources.sample(e).refreshed_at, now, age))
            }
        };
        if from_cache {
            let s = self.sources.sample(e);
            let mut quality = s.quality;
            if matches!(mode, ReadMode::Cache) && (!g.active || !it.active()) {
                quality = Quality::BAD_OUT_OF_SERVICE;
            }
            slot.out = SlotOut::Raw {
                value: s.value.into_owned(),
                quality,
                timestamp: s.timestamp,
            };
        }
        slot
    }

    fn check_async(&self, slot: usize) -> Result<(), OpcError> {
        let g = self.group(slot);
        if !g.connected {
            return Err(OpcError::NoConnection);
        }
        if g.outstanding >= self.cfg.max_transactions_per_group {
            return Err(OpcError::AdviseLimit);
        }
        Ok(())
    }

    /// Registers a transaction whose slots in `remote` wait for `request`.
    fn launch(
        &mut self,
        now: Timestamp,
        mut txn: Txn,
        remote: Vec<u32>,
        request: impl FnOnce(SourceReqId) -> SourceRequest,
    ) -> u64 {
        let req = self.txns.new_req();
        let tid = self.txns.new_id();
        txn.remote = remote;
        txn.req = req;
        if txn.cancel_id != 0 {
            self.txns.by_cancel.insert(txn.cancel_id, tid);
        }
        self.txns.by_req.insert(req, tid);
        self.txns.map.insert(tid, txn);
        self.requests.push_back(request(SourceReqId(req)));
        self.sched.timeouts.push(std::cmp::Reverse((
            now.add_millis(u64::from(self.cfg.source_timeout_ms)),
            req,
        )));
        tid
    }

    /// Starts a read-type transaction from prepared slots.
    fn start_read(&mut self, now: Timestamp, txn: Txn) -> Result<u64, Txn> {
        let remote: Vec<u32> = txn
            .slots
            .iter()
            .enumerate()
            .filter(|(_, s)| matches!(s.out, SlotOut::Pending))
            .map(|(i, _)| i as u32)
            .collect();
        if remote.is_empty() {
            return Err(txn);
        }
        // Items the source holds go by their key alone: a subscription announced to the
        // source was queued before this request ([`ReadItem::Subscribed`]).
        let items: Vec<ReadItem> = remote
            .iter()
            .map(|&i| {
                let idx = txn.slots[i as usize].source;
                if self.sources.announced_rate(idx) > 0 {
                    ReadItem::Subscribed(self.sources.key_of(idx))
                } else {
                    ReadItem::Item(self.sources.source_item(idx))
                }
            })
            .collect();
        Ok(self.launch(now, txn, remote, |req_id| SourceRequest::Read {
            req_id,
            items,
        }))
    }

    /// Starts a write-type transaction: `writes` are (slot index, prepared value).
    fn start_write(
        &mut self,
        now: Timestamp,
        txn: Txn,
        writes: Vec<(u32, PreparedWrite)>,
    ) -> Result<u64, Txn> {
        if writes.is_empty() {
            return Err(txn);
        }
        let remote: Vec<u32> = writes.iter().map(|(i, _)| *i).collect();
        let vqt = writes
            .iter()
            .any(|(_, w)| w.quality.is_some() || w.timestamp.is_some());
        let items: Vec<(SourceItem, PreparedWrite)> = writes
            .into_iter()
            .map(|(i, w)| (self.sources.source_item(txn.slots[i as usize].source), w))
            .collect();
        Ok(self.launch(now, txn, remote, move |req_id| {
            if vqt {
                SourceRequest::WriteVqt {
                    req_id,
                    items: items
                        .into_iter()
                        .map(|(s, w)| {
                            (
                                s,
                                ItemVqt {
                                    value: w.value,
                                    quality: w.quality,
                                    timestamp: w.timestamp,
                                },
                            )
                        })
                        .collect(),
                }
            } else {
                SourceRequest::Write {
                    req_id,
                    items: items.into_iter().map(|(s, w)| (s, w.value)).collect(),
                }
            }
        }))
    }

    fn sync_read_results(txn: &Txn) -> ReadResults {
        txn.slots
            .iter()
            .map(|s| {
                let v = slot_item_value(s, txn.locale);
                match v.error {
                    Some(e) => Err(e),
                    None => Ok(ItemState {
                        client_handle: v.client_handle,
                        value: v.value,
                        quality: v.quality,
                        timestamp: v.timestamp,
                    }),
                }
            })
            .collect()
    }

    fn sync_write_results(txn: &Txn) -> WriteResults {
        txn.slots
            .iter()
            .map(|s| match s.out {
                SlotOut::Written(None) => Ok(()),
                SlotOut::Written(Some(e)) | SlotOut::Err(e) => Err(e),
                _ => Err(OpcError::Fail),
            })
            .collect()
    }

    /// A transaction whose source request was answered (or timed out).
    pub(crate) fn complete_txn(&mut self, now: Timestamp, tid: u64, txn: Txn) {
        if txn.cancel_id != 0 {
            self.txns.by_cancel.remove(&txn.cancel_id);
        }
        self.release_txn_refs(&txn);
        match txn.kind {
            TxnKind::SyncRead => {
                self.txns
                    .sync_done
                    .insert(tid, SyncResult::Read(Self::sync_read_results(&txn)));
                self.txns.sync_completed.push_back(SyncId(tid));
            }
            TxnKind::SyncWrite => {
                self.txns
                    .sync_done
                    .insert(tid, SyncResult::Write(Self::sync_write_results(&txn)));
                self.txns.sync_completed.push_back(SyncId(tid));
            }
            _ => self.finish_async(now, txn),
        }
    }

    /// Queues the callback of a completed asynchronous transaction.
    fn finish_async(&mut self, now: Timestamp, txn: Txn) {
        // The group's current client handle (SetState may have changed it).
        let slot = self.group_slots.get(&txn.group.0).map(|&s| s as usize);
        let client_group = slot
            .and_then(|s| self.groups[s].as_ref())
            .map_or(txn.client_group, |g| g.client_handle);
        let event = match txn.kind {
            TxnKind::Write => {
                let items: Vec<WriteResult> = txn
                    .slots
                    .iter()
                    .map(|s| WriteResult {
                        client_handle: s.client,
                        error: match s.out {
                            SlotOut::Written(e) => e,
                            SlotOut::Err(e) => Some(e),
                            _ => Some(OpcError::Fail),
                        },
                    })
                    .collect();
                let master_error = items
                    .iter()
                    .any(|i| i.error.is_some())
                    .then_some(OpcError::False);
                Event::WriteComplete(WriteComplete {
                    session: txn.session,
                    group: txn.group,
                    client_group,
                    transaction_id: txn.transaction_id,
                    cancel_id: txn.cancel_id,
                    master_error,
                    items,
                })
            }
            TxnKind::Read | TxnKind::Refresh => {
                let items: Vec<ItemValue> = txn
                    .slots
                    .iter()
                    .map(|s| slot_item_value(s, txn.locale))
                    .collect();
                let (master_quality, master_error) = master_codes(&items);
                if txn.kind == TxnKind::Refresh {
                    // Refreshed values become the last values sent (OPC DA 2.05a Refresh2).
                    if let Some(g) = slot.and_then(|s| self.groups[s].as_mut()) {
                        for s in &txn.slots {
                            if let (SlotOut::Raw { value, quality, .. }, Some(i)) =
                                (&s.out, g.find(s.item))
                            {
                                let it = &mut g.items[i];
                                it.set_last(&mut g.lasts, value.clone(), *quality);
                                it.flags.insert(ItemFlags::SENT);
                            }
                        }
                        g.last_callback = now;
                        let session = g.session;
                        if let Some(sess) = self.sessions.get_mut(&session.0) {
                            sess.last_update = now;
                        }
                    }
                    Event::DataChange(DataChange {
                        session: txn.session,
                        group: txn.group,
                        client_group,
                        kind: DataChangeKind::Refresh,
                        transaction_id: txn.transaction_id,
                        cancel_id: txn.cancel_id,
                        master_quality,
                        master_error,
                        items,
                    })
                } else {
                    Event::ReadComplete(ReadComplete {
                        session: txn.session,
                        group: txn.group,
                        client_group,
                        transaction_id: txn.transaction_id,
                        cancel_id: txn.cancel_id,
                        master_quality,
                        master_error,
                        items,
                    })
                }
            }
            TxnKind::SyncRead | TxnKind::SyncWrite => return,
        };
        self.events.push_back(event);
    }

    // ---- synchronous I/O -------------------------------------------------------------

    fn sync_read(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        items: &[(u32, ReadMode)],
    ) -> Result<SyncOutcome<ReadResults>, OpcError> {
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = self.live_slot(group)?;
        let mut txn = self.txn_header(TxnKind::SyncRead, slot, 0);
        let g = self.group(slot);
        txn.slots = items
            .iter()
            .map(|&(h, mode)| self.read_slot(g, h, mode, now))
            .collect();
        match self.start_read(now, txn) {
            Ok(tid) => Ok(SyncOutcome::Pending(SyncId(tid))),
            Err(txn) => Ok(SyncOutcome::Ready(Self::sync_read_results(&txn))),
        }
    }

    /// IOPCSyncIO::Read. From CACHE, items that are inactive or in an inactive group read
    /// with quality BAD Out of Service (value and timestamp from the cache); from DEVICE the
    /// data source is asked (constants answer at once).
    pub fn read(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        source: DataSource,
        handles: &[u32],
    ) -> Result<SyncOutcome<ReadResults>, OpcError> {
        let mode = match source {
            DataSource::Cache => ReadMode::Cache,
            DataSource::Device => ReadMode::Device,
        };
        let items: Vec<(u32, ReadMode)> = handles.iter().map(|&h| (h, mode)).collect();
        self.sync_read(now, group, &items)
    }

    /// IOPCSyncIO2::ReadMaxAge: per item `(server handle, MaxAge ms)`; from the cache when
    /// it was refreshed within MaxAge ([`MAX_AGE_CACHE`]: always), else from the device
    /// ([`super::MAX_AGE_DEVICE`]: always).
    pub fn read_max_age(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        items: &[(u32, u32)],
    ) -> Result<SyncOutcome<ReadResults>, OpcError> {
        let items: Vec<(u32, ReadMode)> = items
            .iter()
            .map(|&(h, a)| (h, ReadMode::MaxAge(a)))
            .collect();
        self.sync_read(now, group, &items)
    }

    fn sync_write(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        items: &[(u32, ItemVqt)],
    ) -> Result<SyncOutcome<WriteResults>, OpcError> {
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = self.live_slot(group)?;
        let mut txn = self.txn_header(TxnKind::SyncWrite, slot, 0);
        txn.slots.reserve_exact(items.len());
        let mut writes = Vec::with_capacity(items.len());
        let g = self.group(slot);
        for (n, (h, w)) in items.iter().enumerate() {
            let mut s = Slot {
                item: *h,
                client: 0,
                source: u32::MAX,
                source_gen: 0,
                req_type: VarType::EMPTY,
                out: SlotOut::Pending,
            };
            match g.find(*h) {
                None => s.out = SlotOut::Err(OpcError::InvalidHandle),
                Some(i) => {
                    let it = &g.items[i];
                    let e = &self.sources.entries[it.source as usize];
                    s.client = it.client;
                    s.source = it.source;
                    s.source_gen = e.generation;
                    let allowed = self.may_write(txn.session, it.source);
                    match prepare_write(&*self.ns, e, w, txn.locale, allowed) {
                        Ok(p) => writes.push((n as u32, p)),
                        Err(err) => s.out = SlotOut::Err(err),
                    }
                }
            }
            txn.slots.push(s);
        }
        match self.start_write(now, txn, writes) {
            Ok(tid) => Ok(SyncOutcome::Pending(SyncId(tid))),
            Err(txn) => Ok(SyncOutcome::Ready(Self::sync_write_results(&txn))),
        }
    }

    /// IOPCSyncIO::Write. Per item: OPC_E_INVALIDHANDLE, OPC_E_BADRIGHTS (not writable,
    /// constant), OPC_E_BADTYPE / OPC_E_RANGE (no conversion to the canonical type), or
    /// the data source's answer. A 3-element array [value, quality, timestamp] written to
    /// a scalar item is the asix extended write (sent as [`SourceRequest::WriteVqt`]).
    pub fn write(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        items: &[(u32, Value)],
    ) -> Result<SyncOutcome<WriteResults>, OpcError> {
        let items: Vec<(u32, ItemVqt)> = items
            .iter()
            .map(|(h, v)| (*h, ItemVqt::value(v.clone())))
            .collect();
        self.sync_write(now, group, &items)
    }

    /// IOPCSyncIO2::WriteVQT (quality and timestamp optional per item).
    pub fn write_vqt(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        items: &[(u32, ItemVqt)],
    ) -> Result<SyncOutcome<WriteResults>, OpcError> {
        self.sync_write(now, group, items)
    }

    /// The answer of a pending synchronous operation, once available (taken once).
    pub fn take_sync_result(&mut self, id: SyncId) -> Option<SyncResult> {
        self.txns.sync_done.remove(&id.0)
    }

    /// The next synchronous operation whose result became available; its result is then in
    /// `take_sync_result`. The driver collects these after each step
    /// ([`crate::driver::Step::sync_completed`]) so that waiters are woken only when one of
    /// them has its answer.
    pub fn poll_sync_completion(&mut self) -> Option<SyncId> {
        self.txns.sync_completed.pop_front()
    }

    /// True while a synchronous operation still waits for the data source.
    pub fn sync_pending(&self, id: SyncId) -> bool {
        self.txns.map.contains_key(&id.0)
    }

    /// Forgets a synchronous operation whose caller stopped waiting.
    pub fn abandon_sync(&mut self, id: SyncId) {
        if let Some(t) = self.txns.map.remove(&id.0) {
            self.txns.by_req.remove(&t.req);
            self.release_txn_refs(&t);
        }
        self.txns.sync_done.remove(&id.0);
    }

    // ---- IOPCItemIO (DA 3.0: by item ID, without a group) --------------------------------

    /// A group-less transaction of `session` (the caller checked that it exists); its
    /// conversions use the session's LCID (IOPCCommon::SetLocaleID).
    fn item_io_header(&self, kind: TxnKind, session: SessionHandle) -> Txn {
        let lcid = self
            .sessions
            .get(&session.0)
            .map_or(crate::lang::LOCALE_SYSTEM_DEFAULT, |s| s.lcid);
        Txn {
            kind,
            session,
            group: GroupHandle(0),
            client_group: 0,
            transaction_id: 0,
            cancel_id: 0,
            locale: self.locale(lcid),
            slots: Vec::new(),
            remote: Vec::new(),
            req: 0,
            holds_refs: true,
        }
    }

    /// Resolves an item ID for IOPCItemIO and takes a cache reference on it.
    fn item_io_slot(&mut self, now: Timestamp, item_id: &str) -> Slot {
        let mut slot = Slot {
            item: 0,
            client: 0,
            source: u32::MAX,
            source_gen: 0,
            req_type: VarType::EMPTY,
            out: SlotOut::Pending,
        };
        let def = if item_id.is_empty() {
            Err(OpcError::InvalidItemId)
        } else {
            self.ns.resolve(item_id, "")
        };
        match def {
            Err(e) => slot.out = SlotOut::Err(e),
            Ok(def) => match self.sources.find_or_insert(&def, now) {
                Err(e) => slot.out = SlotOut::Err(e),
                Ok(src) => {
                    self.sources.add_ref(src);
                    slot.source = src;
                    slot.source_gen = self.sources.entries[src as usize].generation;
                }
            },
        }
        slot
    }

    /// IOPCItemIO::Read: per item `(item ID, MaxAge ms)`, in the canonical type; item IDs
    /// resolve on the basic channel (IOPCItemIO has no access paths). Per-item namespace
    /// errors as for AddItems.
    pub fn item_io_read(
        &mut self,
        now: Timestamp,
        session: SessionHandle,
        items: &[(&str, u32)],
    ) -> Result<SyncOutcome<ReadResults>, OpcError> {
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        if !self.sessions.contains_key(&session.0) {
            return Err(OpcError::Fail);
        }
        let mut txn = self.item_io_header(TxnKind::SyncRead, session);
        for &(id, max_age) in items {
            let mut slot = self.item_io_slot(now, id);
            if slot.source != u32::MAX {
                let e = &self.sources.entries[slot.source as usize];
                let s = self.sources.sample(e);
                if !e.readable() {
                    slot.out = SlotOut::Err(OpcError::BadRights);
                } else if e.is_constant()
                    || max_age == MAX_AGE_CACHE
                    || (max_age != 0 && fresh(s.refreshed_at, now, max_age))
                {
                    slot.out = SlotOut::Raw {
                        value: s.value.into_owned(),
                        quality: s.quality,
                        timestamp: s.timestamp,
                    };
                }
            }
            txn.slots.push(slot);
        }
        match self.start_read(now, txn) {
            Ok(tid) => Ok(SyncOutcome::Pending(SyncId(tid))),
            Err(txn) => {
                self.release_txn_refs(&txn);
                Ok(SyncOutcome::Ready(Self::sync_read_results(&txn)))
            }
        }
    }

    /// IOPCItemIO::WriteVQT: per item `(item ID, value with optional quality/timestamp)`;
    /// values convert as for a group's writes, in the session's locale
    /// ([`Engine::set_session_lcid`]).
    pub fn item_io_write_vqt(
        &mut self,
        now: Timestamp,
        session: SessionHandle,
        items: &[(&str, ItemVqt)],
    ) -> Result<SyncOutcome<WriteResults>, OpcError> {
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        if !self.sessions.contains_key(&session.0) {
            return Err(OpcError::Fail);
        }
        let mut txn = self.item_io_header(TxnKind::SyncWrite, session);
        txn.slots.reserve_exact(items.len());
        let mut writes = Vec::with_capacity(items.len());
        for (n, (id, w)) in items.iter().enumerate() {
            let mut slot = self.item_io_slot(now, id);
            if slot.source != u32::MAX {
                match prepare_write(
                    &*self.ns,
                    &self.sources.entries[slot.source as usize],
                    w,
                    txn.locale,
                    self.may_write(session, slot.source),
                ) {
                    Ok(p) => writes.push((n as u32, p)),
                    Err(e) => slot.out = SlotOut::Err(e),
                }
            }
            txn.slots.push(slot);
        }
        match self.start_write(now, txn, writes) {
            Ok(tid) => Ok(SyncOutcome::Pending(SyncId(tid))),
            Err(txn) => {
                self.release_txn_refs(&txn);
                Ok(SyncOutcome::Ready(Self::sync_write_results(&txn)))
            }
        }
    }

    // ---- asynchronous I/O ------------------------------------------------------------

    fn async_read_impl(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        transaction_id: u32,
        items: &[(u32, ReadMode)],
    ) -> Result<AsyncStarted, OpcError> {
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = self.live_slot(group)?;
        self.check_async(slot)?;
        let mut txn = self.txn_header(TxnKind::Read, slot, transaction_id);
        let g = self.group(slot);
        let mut results = Vec::with_capacity(items.len());
        for &(h, mode) in items {
            let s = self.read_slot(g, h, mode, now);
            match s.out {
                SlotOut::Err(e) if matches!(e, OpcError::InvalidHandle | OpcError::BadRights) => {
                    results.push(Err(e))
                }
                _ => {
                    results.push(Ok(()));
                    txn.slots.push(s);
                }
            }
        }
        Ok(self.start_async(now, slot, txn, None, results))
    }

    /// Queues an asynchronous transaction (or completes it at once from the cache).
    fn start_async(
        &mut self,
        now: Timestamp,
        slot: usize,
        txn: Txn,
        writes: Option<Vec<(u32, PreparedWrite)>>,
        results: Vec<Result<(), OpcError>>,
    ) -> AsyncStarted {
        if txn.slots.is_empty() {
            return AsyncStarted {
                cancel_id: 0,
                results,
            };
        }
        let cancel_id = txn.cancel_id;
        self.group_mut(slot).outstanding += 1;
        let started = match writes {
            Some(w) => self.start_write(now, txn, w),
            None => self.start_read(now, txn),
        };
        if let Err(txn) = started {
            self.finish_async(now, txn);
        }
        AsyncStarted { cancel_id, results }
    }

    /// IOPCAsyncIO2::Read (always from the device; constants answer at once). The
    /// callback is OnReadComplete with `transaction_id`. CONNECT_E_NOCONNECTION without a
    /// callback sink, CONNECT_E_ADVISELIMIT when the group has too many outstanding
    /// transactions.
    pub fn async_read(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        transaction_id: u32,
        handles: &[u32],
    ) -> Result<AsyncStarted, OpcError> {
        let items: Vec<(u32, ReadMode)> = handles.iter().map(|&h| (h, ReadMode::Device)).collect();
        self.async_read_impl(now, group, transaction_id, &items)
    }

    /// IOPCAsyncIO::Read (DA 1.0a): as [`Engine::async_read`], from the cache or the
    /// device as `source` says (a cache read of an inactive group or item is
    /// OPC_QUALITY_OUT_OF_SERVICE, as IOPCSyncIO::Read's).
    pub fn async_read_source(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        transaction_id: u32,
        source: DataSource,
        handles: &[u32],
    ) -> Result<AsyncStarted, OpcError> {
        let mode = match source {
            DataSource::Cache => ReadMode::Cache,
            DataSource::Device => ReadMode::Device,
        };
        let items: Vec<(u32, ReadMode)> = handles.iter().map(|&h| (h, mode)).collect();
        self.async_read_impl(now, group, transaction_id, &items)
    }

    /// IOPCAsyncIO3::ReadMaxAge: per item `(server handle, MaxAge ms)`.
    pub fn async_read_max_age(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        transaction_id: u32,
        items: &[(u32, u32)],
    ) -> Result<AsyncStarted, OpcError> {
        let items: Vec<(u32, ReadMode)> = items
            .iter()
            .map(|&(h, a)| (h, ReadMode::MaxAge(a)))
            .collect();
        self.async_read_impl(now, group, transaction_id, &items)
    }

    fn async_write_impl(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        transaction_id: u32,
        items: &[(u32, ItemVqt)],
    ) -> Result<AsyncStarted, OpcError> {
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = self.live_slot(group)?;
        self.check_async(slot)?;
        let mut txn = self.txn_header(TxnKind::Write, slot, transaction_id);
        let g = self.group(slot);
        let mut results = Vec::with_capacity(items.len());
        let mut writes = Vec::with_capacity(items.len());
        for (h, w) in items {
            let Some(i) = g.find(*h) else {
                results.push(Err(OpcError::InvalidHandle));
                continue;
            };
            let it = &g.items[i];
            let e = &self.sources.entries[it.source as usize];
            let allowed = self.may_write(txn.session, it.source);
            match prepare_write(&*self.ns, e, w, txn.locale, allowed) {
                Err(err) => results.push(Err(err)),
                Ok(p) => {
                    results.push(Ok(()));
                    writes.push((txn.slots.len() as u32, p));
                    txn.slots.push(Slot {
                        item: *h,
                        client: it.client,
                        source: it.source,
                        source_gen: e.generation,
                        req_type: it.req_type,
                        out: SlotOut::Pending,
                    });
                }
            }
        }
        Ok(self.start_async(now, slot, txn, Some(writes), results))
    }

    /// IOPCAsyncIO2::Write; completes with OnWriteComplete. Call-time per-item errors as
    /// for [`Engine::write`].
    pub fn async_write(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        transaction_id: u32,
        items: &[(u32, Value)],
    ) -> Result<AsyncStarted, OpcError> {
        let items: Vec<(u32, ItemVqt)> = items
            .iter()
            .map(|(h, v)| (*h, ItemVqt::value(v.clone())))
            .collect();
        self.async_write_impl(now, group, transaction_id, &items)
    }

    /// IOPCAsyncIO3::WriteVQT.
    pub fn async_write_vqt(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        transaction_id: u32,
        items: &[(u32, ItemVqt)],
    ) -> Result<AsyncStarted, OpcError> {
        self.async_write_impl(now, group, transaction_id, items)
    }

    fn refresh_impl(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        transaction_id: u32,
        mode: ReadMode,
    ) -> Result<u32, OpcError> {
        let slot = self.live_slot(group)?;
        if !self.group(slot).connected {
            return Err(OpcError::NoConnection);
        }
        let g = self.group(slot);
        if !g.active || !g.items.iter().any(|it| it.active()) {
            return Err(OpcError::Fail);
        }
        self.check_async(slot)?;
        let mut txn = self.txn_header(TxnKind::Refresh, slot, transaction_id);
        let g = self.group(slot);
        txn.slots = g
            .items
            .iter()
            .filter(|it| it.active())
            .map(|it| self.read_slot(g, it.handle, mode, now))
            .collect();
        Ok(self.start_async(now, slot, txn, None, Vec::new()).cancel_id)
    }

    /// IOPCAsyncIO2::Refresh2: an OnDataChange with `transaction_id` for every active item,
    /// changed or not, from the cache or the device; the values become the last sent.
    /// E_FAIL when the group is inactive or has no active items.
    pub fn refresh2(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        source: DataSource,
        transaction_id: u32,
    ) -> Result<u32, OpcError> {
        let mode = match source {
            DataSource::Cache => ReadMode::Cache,
            DataSource::Device => ReadMode::Device,
        };
        self.refresh_impl(now, group, transaction_id, mode)
    }

    /// IOPCAsyncIO3::RefreshMaxAge: as Refresh2, each item from the cache when refreshed
    /// within `max_age` ms, else from the device.
    pub fn refresh_max_age(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        max_age: u32,
        transaction_id: u32,
    ) -> Result<u32, OpcError> {
        self.refresh_impl(now, group, transaction_id, ReadMode::MaxAge(max_age))
    }

    /// IOPCAsyncIO2::Cancel2: OnCancelComplete replaces the transaction's completion.
    /// E_FAIL when the cancel ID is unknown or the completion was already delivered.
    pub fn cancel2(&mut self, group: GroupHandle, cancel_id: u32) -> Result<(), OpcError> {
        let slot = self.live_slot(group)?;
        if !self.group(slot).connected {
            return Err(OpcError::NoConnection);
        }
        if let Some(&tid) = self.txns.by_cancel.get(&cancel_id) {
            if self.txns.map.get(&tid).is_some_and(|t| t.group == group) {
                let t = self.txns.map.remove(&tid).expect("txn");
                self.txns.by_cancel.remove(&cancel_id);
                self.txns.by_req.remove(&t.req);
                self.events.push_back(Event::CancelComplete(CancelComplete {
                    session: t.session,
                    group,
                    client_group: self.group(slot).client_handle,
                    transaction_id: t.transaction_id,
                    cancel_id,
                }));
                return Ok(());
            }
        }
        let queued = self.events.iter().position(|e| {
            e.group() == group
                && e.cancel_id() == cancel_id
                && cancel_id != 0
                && !matches!(e, Event::CancelComplete(_))
        });
        let Some(pos) = queued else {
            return Err(OpcError::Fail);
        };
        let (session, transaction_id, refresh) = match &self.events[pos] {
            Event::DataChange(d) => (d.session, d.transaction_id, true),
            Event::ReadComplete(r) => (r.session, r.transaction_id, false),
            Event::WriteComplete(w) => (w.session, w.transaction_id, false),
            Event::CancelComplete(_) => return Err(OpcError::Fail),
        };
        let client_group = self.group(slot).client_handle;
        self.events[pos] = Event::CancelComplete(CancelComplete {
            session,
            group,
            client_group,
            transaction_id,
            cancel_id,
        });
        if refresh {
            // The refreshed values never reach the client: they are not the last sent.
            self.group_mut(slot).resend_all();
        }
        Ok(())
    }
}
