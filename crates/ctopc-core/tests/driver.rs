//! The driver's step and the pacing bookkeeping (`ctopc_core::driver`), natively: a fake
//! backend that answers at once and a recording `Deliver` stand in for the COM layer's
//! data source, callback workers and clients.

mod model_util;

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use ctopc_core::driver::{dispatch, is_paced, Deliver, Driver, Report};
use ctopc_core::model::*;
use ctopc_core::source::{Backend, SourceOutput};
use ctopc_core::{Quality, Timestamp, Value, Vqt};
use model_util::{FakeNs, T0};

/// What the fake plant holds, shared with the test.
#[derive(Default)]
struct Plant {
    /// Current values by source item ID.
    values: HashMap<String, f64>,
    /// Subscribed items and their keys.
    subscribed: HashMap<String, SourceKey>,
    /// Values pushed already (a sample is pushed when the value changed).
    pushed: HashMap<String, f64>,
    /// Device reads to answer at the next poll.
    reads: Vec<(SourceReqId, Vec<String>)>,
    /// Every request, in order, by kind.
    log: Vec<&'static str>,
    /// What `poll_timeout` answers.
    timeout: Option<Timestamp>,
}

/// A backend over the plant that answers every request at the next poll (as the in-process
/// simulation does).
struct FakeSource(Arc<Mutex<Plant>>);

impl Backend for FakeSource {
    fn request(&mut self, _now: Timestamp, req: SourceRequest) {
        let mut p = self.0.lock().unwrap();
        match req {
            SourceRequest::Subscribe(subs) => {
                p.log.push("subscribe");
                for s in subs {
                    p.subscribed.insert(s.item.item_id.to_string(), s.item.key);
                }
            }
            SourceRequest::Unsubscribe(keys) => {
                p.log.push("unsubscribe");
                p.subscribed.retain(|_, k| !keys.contains(k));
            }
            SourceRequest::SetSamplingRate(_) => p.log.push("rate"),
            SourceRequest::Read { req_id, items } => {
                p.log.push("read");
                // A subscribed item comes by its key: the source holds its ID.
                let ids = items
                    .iter()
                    .map(|r| match r {
                        ReadItem::Item(i) => i.item_id.to_string(),
                        ReadItem::Subscribed(k) => p
                            .subscribed
                            .iter()
                            .find(|(_, v)| *v == k)
                            .map(|(id, _)| id.clone())
                            .unwrap_or_default(),
                    })
                    .collect();
                p.reads.push((req_id, ids));
            }
            SourceRequest::Write { .. } | SourceRequest::WriteVqt { .. } => p.log.push("write"),
        }
    }

    fn poll(&mut self, now: Timestamp, out: &mut SourceOutput) {
        let mut p = self.0.lock().unwrap();
        let p = &mut *p;
        for (id, key) in &p.subscribed {
            let Some(&v) = p.values.get(id) else { continue };
            if p.pushed.get(id) != Some(&v) {
                p.pushed.insert(id.clone(), v);
                out.updates
                    .push((*key, Vqt::new(Value::R8(v), Quality::GOOD, now)));
            }
        }
        for (req, ids) in p.reads.drain(..) {
            let results = ids
                .iter()
                .map(|id| {
                    let v = p.values.get(id).copied().unwrap_or(0.0);
                    Ok(Vqt::new(Value::R8(v), Quality::GOOD, now))
                })
                .collect();
            out.read_results.push((req, results));
        }
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        self.0.lock().unwrap().timeout
    }
}

/// A recording `Deliver`: every event handed over, whether it was paced, and whether it
/// was queued (`accept` false: no sink or worker for it).
#[derive(Default)]
struct Recorder {
    queued: Vec<(Event, bool)>,
    refused: Vec<Event>,
    refuse: bool,
}

impl Deliver for Recorder {
    fn deliver(&mut self, event: Event, paced: bool) -> bool {
        if self.refuse {
            self.refused.push(event);
            false
        } else {
            self.queued.push((event, paced));
            true
        }
    }
}

/// The server's engine (paced like the server) with the fake backend, a simulated clock and
/// the reports the next step gets.
struct Rig {
    d: Driver,
    plant: Arc<Mutex<Plant>>,
    now: Timestamp,
    out: Recorder,
    reports: Vec<Report>,
}

impl Rig {
    fn new() -> Rig {
        Rig::with_pacing(SERVER_PENDING_DATA_CHANGES)
    }

    fn with_pacing(max_pending_data_changes: u32) -> Rig {
        let cfg = EngineConfig {
            max_pending_data_changes,
            ..EngineConfig::default()
        };
        let plant = Arc::new(Mutex::new(Plant::default()));
        let source = Box::new(FakeSource(Arc::clone(&plant)));
        Rig {
            d: Driver::new(Engine::new(cfg, Arc::new(FakeNs)), source),
            plant,
            now: T0,
            out: Recorder::default(),
            reports: Vec::new(),
        }
    }

    /// One driver step at the current time, its events dispatched to the recorder; returns
    /// the subscription callbacks queued in it.
    fn step(&mut self) -> Vec<DataChange> {
        let before = self.out.queued.len();
        let step = self.d.step(self.now, std::mem::take(&mut self.reports));
        self.reports.extend(dispatch(step.events, &mut self.out));
        self.out.queued[before..]
            .iter()
            .filter_map(|(e, _)| match e {
                Event::DataChange(d) if d.kind == DataChangeKind::Subscription => Some(d.clone()),
                _ => None,
            })
            .collect()
    }

    /// Moves the clock by `ms` and steps there.
    fn at(&mut self, ms: u64) -> Vec<DataChange> {
        self.now = self.now.add_millis(ms);
        self.step()
    }

    fn set(&mut self, id: &str, v: f64) {
        self.plant.lock().unwrap().values.insert(id.into(), v);
    }

    /// A client's callback returned: what its worker reports.
    fn delivered(&mut self, g: GroupHandle) {
        self.reports.push(Report::Ended(g));
    }

    /// An active 1 s group, callback connected, with active items (client handle index +
    /// 100).
    fn group(&mut self, ids: &[&str]) -> (SessionHandle, GroupHandle) {
        let (s, g, _) = self.group_items(ids);
        (s, g)
    }

    /// The same, also returning the items' server handles.
    fn group_items(&mut self, ids: &[&str]) -> (SessionHandle, GroupHandle, Vec<u32>) {
        let s = self.d.engine.open_session();
        let params = GroupParams {
            name: "g",
            update_rate: 1000,
            client_handle: 7,
            ..Default::default()
        };
        let g = self.d.engine.add_group(self.now, s, &params).unwrap().group;
        self.d
            .engine
            .set_callback_connected(self.now, g, true)
            .unwrap();
        let defs: Vec<ItemDefinition> = ids
            .iter()
            .enumerate()
            .map(|(i, id)| ItemDefinition {
                item_id: id,
                access_path: "",
                active: true,
                client_handle: 100 + i as u32,
                requested_type: ctopc_core::VarType::EMPTY,
            })
            .collect();
        let added = self.d.engine.add_items(self.now, g, &defs).unwrap();
        let handles = added
            .into_iter()
            .map(|r| r.unwrap().server_handle)
            .collect();
        (s, g, handles)
    }
}

fn values(d: &DataChange) -> Vec<(u32, Value)> {
    d.items
        .iter()
        .map(|i| (i.client_handle, i.value.clone()))
        .collect()
}

#[test]
fn a_step_subscribes_pulls_the_source_and_delivers_the_due_on_data_change() {
    let mut r = Rig::new();
    let (s, g) = r.group(&["A1", "A2"]);
    r.set("A1", 1.0);
    r.set("A2", 2.0);
    // The group's first update runs before its items are subscribed: they have no value
    // yet and are held back (no placeholder callback). The Subscribe goes out in
    // the same step, the in-process source answers at once, and the first callback, in
    // the same step, carries the real values.
    let dc = r.step();
    assert_eq!(r.plant.lock().unwrap().log, vec!["subscribe"]);
    assert_eq!(dc.len(), 1);
    assert_eq!(
        values(&dc[0]),
        vec![(100, Value::R8(1.0)), (101, Value::R8(2.0))]
    );
    let (e, paced) = &r.out.queued[0];
    assert!(*paced, "a subscription update paces the scheduler");
    assert_eq!((e.session(), e.group()), (s, g));
    r.delivered(g);
    assert!(r.at(999).is_empty(), "not before the update rate");
    // Nothing changed: nothing to deliver at the next ticks.
    assert!(r.at(1).is_empty());
    r.delivered(g);
    assert!(r.at(1000).is_empty());
    r.set("A1", 1.5);
    let dc = r.at(1000);
    assert_eq!(values(&dc[0]), vec![(100, Value::R8(1.5))]);
}

#[test]
fn pacing_holds_a_third_callback_until_one_is_delivered() {
    let mut r = Rig::new();
    let (_, g) = r.group(&["A1"]);
    r.set("A1", 1.0);
    assert_eq!(r.step().len(), 1, "the first, travelling");
    r.set("A1", 2.0);
    assert_eq!(r.at(1000).len(), 1, "the second, prepared");
    for i in 0..5 {
        r.set("A1", 3.0 + f64::from(i));
        assert!(
            r.at(1000).is_empty(),
            "two under way: no third callback, however long the client takes"
        );
    }
    // The client returns from the first: the update that fell due meanwhile goes at once,
    // with the latest value only.
    r.delivered(g);
    let dc = r.at(100);
    assert_eq!(dc.len(), 1);
    assert_eq!(values(&dc[0]), vec![(100, Value::R8(7.0))]);
    r.set("A1", 8.0);
    assert!(r.at(1000).is_empty(), "two under way again");
}

#[test]
fn a_callback_that_cannot_be_queued_ends_at_once_and_holds_no_pacing_slot() {
    let mut r = Rig::new();
    let (_, g) = r.group(&["A1"]);
    // No worker or sink takes the group's callbacks (the client has not advised yet, or its
    // worker is gone).
    r.out.refuse = true;
    for i in 0..5 {
        r.set("A1", f64::from(i));
        let step = r.d.step(r.now, std::mem::take(&mut r.reports));
        assert_eq!(step.events.len(), 1, "update {i} is produced");
        let ended = dispatch(step.events, &mut r.out);
        assert_eq!(ended, vec![Report::Ended(g)], "and ended at once");
        r.reports.extend(ended);
        r.now = r.now.add_millis(1000);
    }
    assert_eq!(r.out.refused.len(), 5);
}

#[test]
fn only_scheduled_callbacks_are_paced_and_reported_when_not_queued() {
    let mut r = Rig::new();
    let (_, g, h) = r.group_items(&["A1"]);
    r.set("A1", 1.0);
    r.step();
    r.delivered(g);
    // A client's own asynchronous read completes with OnReadComplete: not paced.
    r.d.engine.async_read(r.now, g, 42, &h).unwrap();
    r.out.refuse = true;
    let step = r.d.step(r.now, std::mem::take(&mut r.reports));
    assert_eq!(step.events.len(), 1);
    assert!(matches!(step.events[0], Event::ReadComplete(_)));
    assert!(!is_paced(&step.events[0]));
    assert!(dispatch(step.events, &mut r.out).is_empty());
}

#[test]
fn a_disconnected_client_stops_its_group_callbacks_and_its_deliveries_end() {
    let mut r = Rig::new();
    let (_, g) = r.group(&["A1"]);
    r.set("A1", 1.0);
    assert_eq!(r.step().len(), 1);
    // The worker's call failed as disconnected: it dropped the sink and reports both.
    r.reports.push(Report::Disconnected(g));
    r.reports.push(Report::Ended(g));
    for i in 0..5 {
        r.set("A1", 2.0 + f64::from(i));
        assert!(
            r.at(1000).is_empty(),
            "nothing is scheduled for a lost sink"
        );
    }
    assert!(!r.d.engine.callback_connected(g).unwrap());
    // A new Advise resends everything, and pacing starts afresh (both slots free).
    r.d.engine.set_callback_connected(r.now, g, true).unwrap();
    let dc = r.step();
    assert_eq!(values(&dc[0]), vec![(100, Value::R8(6.0))]);
    r.set("A1", 7.0);
    assert_eq!(r.at(1000).len(), 1);
}

#[test]
fn reports_for_a_removed_group_are_ignored() {
    let mut r = Rig::new();
    let (s, g) = r.group(&["A1"]);
    r.set("A1", 1.0);
    r.step();
    r.d.engine.close_session(r.now, s).unwrap();
    r.reports.push(Report::Disconnected(g));
    r.reports.push(Report::Ended(g));
    let step = r.d.step(r.now, std::mem::take(&mut r.reports));
    assert!(step.events.is_empty());
}

#[test]
fn a_synchronous_device_read_completes_in_the_step_and_is_reported() {
    let mut r = Rig::new();
    let (_, g, h) = r.group_items(&["A1"]);
    r.set("A1", 5.0);
    r.step();
    let id = match r.d.engine.read(r.now, g, DataSource::Device, &h).unwrap() {
        SyncOutcome::Pending(id) => id,
        SyncOutcome::Ready(_) => panic!("a device read waits for the source"),
    };
    let step = r.d.step(r.now, []);
    assert_eq!(step.sync_completed, vec![id], "the waiter to wake");
    let Some(SyncResult::Read(results)) = r.d.engine.take_sync_result(id) else {
        panic!("the answer is there")
    };
    assert_eq!(results[0].as_ref().unwrap().value, Value::R8(5.0));
    assert!(
        r.d.step(r.now, []).sync_completed.is_empty(),
        "reported once"
    );
}

#[test]
fn the_next_step_is_the_earlier_of_the_engine_and_the_source_deadlines() {
    let mut r = Rig::new();
    assert_eq!(r.d.step(r.now, []).next, None, "idle: only when woken");
    r.plant.lock().unwrap().timeout = Some(T0.add_millis(250));
    assert_eq!(r.d.step(r.now, []).next, Some(T0.add_millis(250)));
    r.group(&["A1"]);
    r.set("A1", 1.0);
    let step = r.d.step(r.now, []);
    assert_eq!(
        step.next,
        Some(T0.add_millis(250)),
        "the source is due first"
    );
    r.plant.lock().unwrap().timeout = None;
    let next = r.d.step(r.now, []).next.expect("the group's next tick");
    assert!(next > T0 && next <= T0.add_millis(1000));
}
