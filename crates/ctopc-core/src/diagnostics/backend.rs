//! [`DiagBackend`]: the real backend with the `_Diagnostics` items answered beside it.
//!
//! Requests are split by item: the diagnostic ones (their source key starts with
//! `_Diagnostics.`, [`super::is_diagnostic_id`]) are answered from the current snapshot,
//! the rest go to the real backend unchanged (a request without diagnostic items is handed
//! over as it is). A read that mixes both is answered once, when the real backend's part
//! has come back. Subscribed diagnostic items get a sample when subscribed and one per
//! published snapshot (about once per second, whatever the rate asked for): the value with
//! quality GOOD and the snapshot's time, or BAD Not Connected once their client has gone.
//! Writes never reach here (the items are read-only, the engine answers OPC_E_BADRIGHTS);
//! should one come, its diagnostic items are refused the same way.
//!
//! The backend keeps its own `Arc` of the snapshot and reads the [`Board`]'s lock only when
//! the board's generation has changed: a step of the driver costs one atomic load more.

use std::collections::HashMap;
use std::sync::Arc;

use super::{is_diagnostic_id, Board, ChannelStatus, DiagItem, Snapshot};
use crate::model::datasource::{ReadItem, SourceItem, SourceKey, SourceReqId, SourceRequest};
use crate::source::{Backend, SourceOutput};
use crate::{OpcError, Quality, Timestamp, Vqt};

/// A request whose diagnostic part was answered at once, waiting for the real part.
struct Mixed<T> {
    /// The answers of every position; the real backend's fill the `None`s in order.
    results: Vec<Option<Result<T, OpcError>>>,
}

impl<T> Mixed<T> {
    fn merge(self, real: Vec<Result<T, OpcError>>) -> Vec<Result<T, OpcError>> {
        let mut real = real.into_iter();
        self.results
            .into_iter()
            .map(|r| r.unwrap_or_else(|| real.next().unwrap_or(Err(OpcError::Fail))))
            .collect()
    }
}

/// See the module doc.
pub struct DiagBackend {
    inner: Box<dyn Backend>,
    board: Arc<Board>,
    snapshot: Arc<Snapshot>,
    seen: u64,
    /// Subscribed diagnostic items, by key.
    subscribed: HashMap<SourceKey, Arc<str>>,
    /// Subscribed since the last poll: a sample at once.
    fresh: Vec<SourceKey>,
    reads: HashMap<SourceReqId, Mixed<Vqt>>,
    writes: HashMap<SourceReqId, Mixed<()>>,
    ready: SourceOutput,
}

impl DiagBackend {
    pub fn new(inner: Box<dyn Backend>, board: Arc<Board>) -> DiagBackend {
        DiagBackend {
            inner,
            snapshot: board.current(),
            seen: board.generation(),
            board,
            subscribed: HashMap::new(),
            fresh: Vec::new(),
            reads: HashMap::new(),
            writes: HashMap::new(),
            ready: SourceOutput::default(),
        }
    }

    fn vqt(&self, item_id: &str) -> Result<Vqt, OpcError> {
        let item = DiagItem::parse(item_id).ok_or(OpcError::UnknownItemId)?;
        let s = &self.snapshot;
        Ok(match s.value(&item) {
            Some(v) => Vqt::new(v, Quality::GOOD, s.taken),
            None => Vqt::new(Default::default(), Quality::BAD_NOT_CONNECTED, s.taken),
        })
    }

    /// Splits `items` into the diagnostic answers (by position) and the real part.
    fn split<I, T>(
        items: Vec<I>,
        item: impl Fn(&I) -> &SourceItem,
        answer: impl Fn(&SourceItem) -> Result<T, OpcError>,
    ) -> (Vec<Option<Result<T, OpcError>>>, Vec<I>) {
        let mut results = Vec::with_capacity(items.len());
        let mut real = Vec::new();
        for i in items {
            if is_diagnostic_id(&item(&i).item_id) {
                results.push(Some(answer(item(&i))));
            } else {
                results.push(None);
                real.push(i);
            }
        }
        (results, real)
    }

    /// The diagnostic item ID of a read's item, if it is one (a subscribed one by its key).
    fn read_diag<'a>(&'a self, r: &'a ReadItem) -> Option<&'a str> {
        match r {
            ReadItem::Subscribed(k) if !self.subscribed.is_empty() => {
                self.subscribed.get(k).map(|id| &**id)
            }
            ReadItem::Subscribed(_) => None,
            ReadItem::Item(i) => is_diagnostic_id(&i.item_id).then_some(&*i.item_id),
        }
    }

    fn has_diag<I>(items: &[I], item: impl Fn(&I) -> &SourceItem) -> bool {
        items.iter().any(|i| is_diagnostic_id(&item(i).item_id))
    }
}

fn first<T>(i: &(SourceItem, T)) -> &SourceItem {
    &i.0
}

/// Hands a request's real part on, or answers it whole when there is none.
fn route<T>(
    req_id: SourceReqId,
    results: Vec<Option<Result<T, OpcError>>>,
    real_empty: bool,
    pending: &mut HashMap<SourceReqId, Mixed<T>>,
) -> Option<Vec<Result<T, OpcError>>> {
    let mixed = Mixed { results };
    if real_empty {
        Some(mixed.merge(Vec::new()))
    } else {
        pending.insert(req_id, mixed);
        None
    }
}

impl Backend for DiagBackend {
    fn request(&mut self, now: Timestamp, req: SourceRequest) {
        match req {
            SourceRequest::Subscribe(subs)
                if subs.iter().any(|s| is_diagnostic_id(&s.item.item_id)) =>
            {
                let (diag, real): (Vec<_>, Vec<_>) = subs
                    .into_iter()
                    .partition(|s| is_diagnostic_id(&s.item.item_id));
                for s in diag {
                    self.subscribed.insert(s.item.key, s.item.item_id);
                    self.fresh.push(s.item.key);
                }
                if !real.is_empty() {
                    self.inner.request(now, SourceRequest::Subscribe(real));
                }
            }
            SourceRequest::SetSamplingRate(rates) if !self.subscribed.is_empty() => {
                let real: Vec<_> = rates
                    .into_iter()
                    .filter(|(k, _)| !self.subscribed.contains_key(k))
                    .collect();
                if !real.is_empty() {
                    self.inner
                        .request(now, SourceRequest::SetSamplingRate(real));
                }
            }
            SourceRequest::Unsubscribe(keys) if !self.subscribed.is_empty() => {
                let real: Vec<_> = keys
                    .into_iter()
                    .filter(|k| self.subscribed.remove(k).is_none())
                    .collect();
                if !real.is_empty() {
                    self.inner.request(now, SourceRequest::Unsubscribe(real));
                }
            }
            SourceRequest::Read { req_id, items }
                if items.iter().any(|r| self.read_diag(r).is_some()) =>
            {
                let mut results = Vec::with_capacity(items.len());
                let mut real = Vec::new();
                for r in items {
                    match self.read_diag(&r) {
                        Some(id) => results.push(Some(self.vqt(id))),
                        None => {
                            results.push(None);
                            real.push(r);
                        }
                    }
                }
                let empty = real.is_empty();
                if let Some(r) = route(req_id, results, empty, &mut self.reads) {
                    self.ready.read_results.push((req_id, r));
                } else {
                    self.inner.request(
                        now,
                        SourceRequest::Read {
                            req_id,
                            items: real,
                        },
                    );
                }
            }
            SourceRequest::Write { req_id, items } if Self::has_diag(&items, first) => {
                let (results, real) = Self::split(items, first, |_| Err(OpcError::BadRights));
                let empty = real.is_empty();
                if let Some(r) = route(req_id, results, empty, &mut self.writes) {
                    self.ready.write_results.push((req_id, r));
                } else {
                    self.inner.request(
                        now,
                        SourceRequest::Write {
                            req_id,
                            items: real,
                        },
                    );
                }
            }
            SourceRequest::WriteVqt { req_id, items } if Self::has_diag(&items, first) => {
                let (results, real) = Self::split(items, first, |_| Err(OpcError::BadRights));
                let empty = real.is_empty();
                if let Some(r) = route(req_id, results, empty, &mut self.writes) {
                    self.ready.write_results.push((req_id, r));
                } else {
                    self.inner.request(
                        now,
                        SourceRequest::WriteVqt {
                            req_id,
                            items: real,
                        },
                    );
                }
            }
            other => self.inner.request(now, other),
        }
    }

    fn poll(&mut self, now: Timestamp, out: &mut SourceOutput) {
        self.inner.poll(now, out);
        if !self.reads.is_empty() {
            for (id, r) in &mut out.read_results {
                if let Some(m) = self.reads.remove(id) {
                    *r = m.merge(std::mem::take(r));
                }
            }
        }
        if !self.writes.is_empty() {
            for (id, r) in &mut out.write_results {
                if let Some(m) = self.writes.remove(id) {
                    *r = m.merge(std::mem::take(r));
                }
            }
        }
        out.read_results.append(&mut self.ready.read_results);
        out.write_results.append(&mut self.ready.write_results);
        let generation = self.board.generation();
        if generation != self.seen {
            self.seen = generation;
            self.snapshot = self.board.current();
            self.fresh.clear();
            for (k, id) in &self.subscribed {
                if let Ok(v) = self.vqt(id) {
                    out.updates.push((*k, v));
                }
            }
        } else {
            for k in std::mem::take(&mut self.fresh) {
                if let Some(Ok(v)) = self.subscribed.get(&k).map(|id| self.vqt(id)) {
                    out.updates.push((k, v));
                }
            }
        }
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        self.inner.poll_timeout()
    }

    fn is_simulation(&self) -> bool {
        self.inner.is_simulation()
    }

    fn channels(&self) -> Vec<ChannelStatus> {
        self.inner.channels()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::browse::MatchCase;
    use crate::diagnostics::{ClientCounters, Input, Sampler, ServerCounters};
    use crate::model::datasource::Subscription;
    use crate::{Value, VarType};
    use std::sync::Mutex;

    /// A real backend that records its requests and answers reads with 7.0.
    #[derive(Default)]
    struct Fake {
        log: Arc<Mutex<Vec<SourceRequest>>>,
        answer: Vec<(SourceReqId, usize)>,
    }

    impl Backend for Fake {
        fn request(&mut self, _: Timestamp, req: SourceRequest) {
            if let SourceRequest::Read { req_id, items } = &req {
                self.answer.push((*req_id, items.len()));
            }
            self.log.lock().unwrap().push(req);
        }
        fn poll(&mut self, now: Timestamp, out: &mut SourceOutput) {
            for (id, n) in self.answer.drain(..) {
                let vqt = Vqt::new(Value::R8(7.0), Quality::GOOD, now);
                out.read_results.push((id, vec![Ok(vqt); n]));
            }
        }
        fn poll_timeout(&self) -> Option<Timestamp> {
            None
        }
    }

    fn item(index: u32, id: &str) -> SourceItem {
        SourceItem {
            key: SourceKey::new(index, 1),
            channel: Arc::from("*"),
            item_id: Arc::from(id),
            canonical_type: VarType::I4,
        }
    }

    fn t(ms: i64) -> Timestamp {
        Timestamp::from_unix_millis(ms)
    }

    fn publish(board: &Board, sampler: &mut Sampler, ms: i64, clients: u64, names: &[&str]) {
        board.publish(
            sampler.sample(
                t(ms),
                Input {
                    server: ServerCounters {
                        clients,
                        uptime_s: ms as u64 / 1000,
                        ..ServerCounters::default()
                    },
                    clients: names
                        .iter()
                        .enumerate()
                        .map(|(i, n)| ClientCounters {
                            session: i as u32,
                            name: Some((*n).to_owned()),
                            ..ClientCounters::default()
                        })
                        .collect(),
                    ..Input::default()
                },
            ),
        );
    }

    #[test]
    fn diagnostic_items_are_answered_here_and_the_rest_passes_through() {
        let board = Arc::new(Board::new());
        let mut sampler = Sampler::new(MatchCase::Insensitive);
        publish(&board, &mut sampler, 5_000, 2, &["HMI"]);
        let fake = Fake::default();
        let log = Arc::clone(&fake.log);
        let mut b = DiagBackend::new(Box::new(fake), Arc::clone(&board));
        let clients = item(1, "_Diagnostics.Server.Clients");
        let name = item(2, "_Diagnostics.Clients.HMI.Name");
        let real = item(3, "KW_A000");
        // A mixed read: one answer, in order, after the real part came back.
        b.request(
            t(5_000),
            SourceRequest::Read {
                req_id: SourceReqId(9),
                items: vec![
                    ReadItem::Item(clients.clone()),
                    ReadItem::Item(real.clone()),
                    ReadItem::Item(name.clone()),
                ],
            },
        );
        assert_eq!(
            log.lock().unwrap().as_slice(),
            [SourceRequest::Read {
                req_id: SourceReqId(9),
                items: vec![ReadItem::Item(real.clone())]
            }]
        );
        let mut out = SourceOutput::default();
        b.poll(t(5_001), &mut out);
        let (id, r) = &out.read_results[0];
        assert_eq!(*id, SourceReqId(9));
        let values: Vec<Value> = r
            .iter()
            .map(|v| v.as_ref().unwrap().value.clone())
            .collect();
        assert_eq!(
            values,
            [Value::I4(2), Value::R8(7.0), Value::Bstr("HMI".into())]
        );
        // A read of diagnostic items only never reaches the real backend.
        log.lock().unwrap().clear();
        b.request(
            t(5_002),
            SourceRequest::Read {
                req_id: SourceReqId(10),
                items: vec![ReadItem::Item(clients.clone())],
            },
        );
        assert!(log.lock().unwrap().is_empty());
        let mut out = SourceOutput::default();
        b.poll(t(5_002), &mut out);
        assert_eq!(out.read_results.len(), 1);
        // Subscribed items come by their key: a diagnostic one is answered here, a real
        // one passes through by its key.
        b.request(
            t(5_002),
            SourceRequest::Subscribe(vec![Subscription {
                item: clients.clone(),
                sampling_rate_ms: 1000,
            }]),
        );
        log.lock().unwrap().clear();
        b.request(
            t(5_002),
            SourceRequest::Read {
                req_id: SourceReqId(12),
                items: vec![
                    ReadItem::Subscribed(real.key),
                    ReadItem::Subscribed(clients.key),
                ],
            },
        );
        assert_eq!(
            log.lock().unwrap().as_slice(),
            [SourceRequest::Read {
                req_id: SourceReqId(12),
                items: vec![ReadItem::Subscribed(real.key)]
            }]
        );
        let mut out = SourceOutput::default();
        b.poll(t(5_003), &mut out);
        let read = out
            .read_results
            .iter()
            .find(|(id, _)| *id == SourceReqId(12));
        let values: Vec<Value> = read
            .map(|(_, r)| {
                r.iter()
                    .map(|v| v.as_ref().unwrap().value.clone())
                    .collect()
            })
            .unwrap_or_default();
        assert_eq!(values, [Value::R8(7.0), Value::I4(2)]);
        log.lock().unwrap().clear();
        // A write of a diagnostic item is refused.
        b.request(
            t(5_002),
            SourceRequest::Write {
                req_id: SourceReqId(11),
                items: vec![(clients.clone(), Value::I4(1))],
            },
        );
        let mut out = SourceOutput::default();
        b.poll(t(5_002), &mut out);
        assert_eq!(
            out.write_results,
            [(SourceReqId(11), vec![Err(OpcError::BadRights)])]
        );
        assert!(log.lock().unwrap().is_empty());
    }

    #[test]
    fn subscriptions_get_a_sample_at_once_and_one_per_snapshot() {
        let board = Arc::new(Board::new());
        let mut sampler = Sampler::new(MatchCase::Insensitive);
        publish(&board, &mut sampler, 1_000, 1, &["HMI"]);
        let fake = Fake::default();
        let log = Arc::clone(&fake.log);
        let mut b = DiagBackend::new(Box::new(fake), Arc::clone(&board));
        let up = item(1, "_Diagnostics.Server.Uptime");
        let name = item(2, "_Diagnostics.Clients.HMI.Name");
        let real = item(3, "KW_A000");
        let sub = |i: &SourceItem| crate::model::datasource::Subscription {
            item: i.clone(),
            sampling_rate_ms: 100,
        };
        b.request(
            t(1_000),
            SourceRequest::Subscribe(vec![sub(&up), sub(&real), sub(&name)]),
        );
        assert_eq!(
            log.lock().unwrap().as_slice(),
            [SourceRequest::Subscribe(vec![sub(&real)])]
        );
        let mut out = SourceOutput::default();
        b.poll(t(1_000), &mut out);
        assert_eq!(out.updates.len(), 2);
        // No new snapshot, no new samples.
        let mut out = SourceOutput::default();
        b.poll(t(1_500), &mut out);
        assert!(out.updates.is_empty());
        // The next snapshot: a sample each; the client that left is BAD Not Connected.
        publish(&board, &mut sampler, 2_000, 0, &[]);
        let mut out = SourceOutput::default();
        b.poll(t(2_000), &mut out);
        out.updates.sort_by_key(|u| u.0);
        assert_eq!(out.updates[0].0, up.key);
        assert_eq!(out.updates[0].1.value, Value::I4(2));
        assert_eq!(out.updates[0].1.timestamp, t(2_000));
        assert_eq!(out.updates[1].1.quality, Quality::BAD_NOT_CONNECTED);
        // Rates and unsubscriptions of diagnostic keys stay here.
        log.lock().unwrap().clear();
        b.request(t(2_000), SourceRequest::SetSamplingRate(vec![(up.key, 50)]));
        b.request(t(2_000), SourceRequest::Unsubscribe(vec![up.key, real.key]));
        assert_eq!(
            log.lock().unwrap().as_slice(),
            [SourceRequest::Unsubscribe(vec![real.key])]
        );
        publish(&board, &mut sampler, 3_000, 0, &[]);
        let mut out = SourceOutput::default();
        b.poll(t(3_000), &mut out);
        assert_eq!(out.updates.len(), 1, "only the client's item is left");
    }
}
