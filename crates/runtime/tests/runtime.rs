//! The runtime's threads natively: the driver, the callback workers, the synchronous
//! waits, the callback watch's verdicts and the shutdown request, over the in-process
//! simulation of the demo plant, with recording front-end sinks in place of COM.
//! Every wait is on a condition, with a deadline.

use asix_model::{parse_config, AsixNamespace};
use asix_net::inproc::InProcessSim;
use ctopc_core::browse::MatchCase;
use ctopc_core::metrics::CallbackKind;
use ctopc_core::model::*;
use ctopc_core::ops::OpsConfig;
use ctopc_core::VarType;
use ctopc_runtime::frontend::no_thread_state;
use ctopc_runtime::{Delivery, GroupSink, Runtime, SessionSink};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const SEED: u64 = 7;

/// The demo plant's acid factory database, simulated, with `ops`.
fn start(ops: OpsConfig) -> Arc<Runtime> {
    let db = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../demo/wytwornia_kwasu/wytwornia_kwasu.zez"
    );
    let ini = format!("[Server]\nSimulateCurrentData = tak\n[Channel:*]\nItemsDatabase = {db}\n");
    let (cfg, warnings) = parse_config(ini.as_bytes(), "runtime.ini").unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let engine_config = cfg.server.engine_config();
    let ns = Arc::new(AsixNamespace::load(cfg).0);
    let for_source = Arc::clone(&ns);
    let started = ctopc_runtime::start(
        ns,
        MatchCase::Insensitive,
        engine_config,
        &ops,
        no_thread_state,
        Box::new(move |_wake| {
            let sim = InProcessSim::new(for_source, SEED, ctopc_runtime::clock::now());
            Ok(Box::new(sim) as Box<dyn ctopc_core::source::Backend>)
        }),
    )
    .unwrap();
    assert!(started.simulation);
    started.runtime
}

/// Waits until `done` holds, at most 10 s.
fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// A session with an active group of two demo variables at `rate` ms, its callback
/// connected.
fn subscribe(rt: &Runtime, rate: u32) -> (SessionHandle, GroupHandle) {
    let session = rt.open_session();
    let group = rt.with_engine(|e, now| {
        let g = e
            .add_group(
                now,
                session,
                &GroupParams {
                    name: "g",
                    active: true,
                    update_rate: rate,
                    client_handle: 77,
                    ..GroupParams::default()
                },
            )
            .unwrap()
            .group;
        let items: Vec<ItemDefinition<'_>> = ["KW_A000", "KW_A110"]
            .iter()
            .enumerate()
            .map(|(i, id)| ItemDefinition {
                item_id: id,
                access_path: "",
                active: true,
                client_handle: i as u32 + 1,
                requested_type: VarType::EMPTY,
            })
            .collect();
        let added = e.add_items(now, g, &items).unwrap();
        assert!(added.iter().all(Result::is_ok), "{added:?}");
        e.set_callback_connected(now, g, true).unwrap();
        g
    });
    (session, group)
}

/// A front end's group sink that records what it is handed and how.
#[derive(Default)]
struct Recorder {
    events: Mutex<Vec<(GroupHandle, Event, String)>>,
    /// Each call blocks this long (a slow client).
    delay: Mutex<Duration>,
    /// The next call finds the client gone.
    lose: AtomicBool,
    connected: AtomicBool,
    dropped: AtomicUsize,
}

impl Recorder {
    fn data_changes(&self) -> usize {
        let events = self.events.lock().unwrap();
        events
            .iter()
            .filter(|(_, e, _)| matches!(e, Event::DataChange(_)))
            .count()
    }
}

impl GroupSink for Recorder {
    fn deliver(&self, group: GroupHandle, event: Event) -> Delivery {
        let thread = std::thread::current().name().unwrap_or("").to_owned();
        self.events.lock().unwrap().push((group, event, thread));
        let delay = *self.delay.lock().unwrap();
        std::thread::sleep(delay);
        if self.lose.swap(false, Ordering::SeqCst) {
            self.connected.store(false, Ordering::SeqCst);
            return Delivery {
                called: true,
                lost: true,
            };
        }
        Delivery {
            called: true,
            lost: false,
        }
    }
    fn is_connected(&self) -> bool {
        self.connected.load(Ordering::SeqCst)
    }
    fn drop_listener(&self) -> bool {
        self.dropped.fetch_add(1, Ordering::SeqCst);
        self.connected.swap(false, Ordering::SeqCst)
    }
}

fn recorder() -> Arc<Recorder> {
    let r = Arc::new(Recorder::default());
    r.connected.store(true, Ordering::SeqCst);
    r
}

#[test]
fn subscription_updates_reach_the_group_sink_on_the_sessions_worker_paced() {
    let rt = start(OpsConfig::default());
    let (session, group) = subscribe(&rt, 50);
    let sink = recorder();
    rt.set_group_sink(group, sink.clone());
    // More updates than the engine lets be under way at once
    // (`max_pending_data_changes`): each delivery's end was reported back.
    let pending = rt.lock().engine.config().max_pending_data_changes as usize;
    wait_until("updates", || sink.data_changes() > pending + 2);
    let events = sink.events.lock().unwrap();
    let worker = format!("callbacks-{}", session.0);
    for (g, e, thread) in events.iter() {
        assert_eq!(*g, group);
        assert_eq!(e.session(), session);
        assert_eq!(thread, &worker, "delivered on the session's worker");
    }
    let Event::DataChange(first) = &events[0].1 else {
        panic!("{:?}", events[0].1)
    };
    assert_eq!(first.client_group, 77);
    assert_eq!(first.items.len(), 2, "the first update carries every item");
    drop(events);
    let m = rt.metrics.snapshot(Default::default());
    let i = CallbackKind::ALL
        .iter()
        .position(|k| *k == CallbackKind::DataChange)
        .unwrap();
    assert!(m.callbacks[i] >= pending as u64 + 2, "{:?}", m.callbacks);
    rt.stop_driver();
}

#[test]
fn a_device_read_waits_for_the_source_and_gets_its_answer() {
    let rt = start(OpsConfig::default());
    let (_, group) = subscribe(&rt, 1000);
    let outcome = rt
        .with_engine(|e, now| e.read(now, group, DataSource::Device, &[1, 2]))
        .unwrap();
    let results = match outcome {
        SyncOutcome::Ready(r) => r,
        SyncOutcome::Pending(id) => {
            match rt.wait_for(Duration::from_secs(10), |e| e.take_sync_result(id)) {
                Some(SyncResult::Read(r)) => r,
                other => panic!("{other:?}"),
            }
        }
    };
    assert_eq!(results.len(), 2);
    assert!(results.iter().all(Result::is_ok), "{results:?}");
    rt.stop_driver();
}

#[test]
fn a_lost_listener_is_reported_to_the_engine_which_stops_the_groups_updates() {
    let rt = start(OpsConfig::default());
    let (_, group) = subscribe(&rt, 50);
    let sink = recorder();
    sink.lose.store(true, Ordering::SeqCst);
    rt.set_group_sink(group, sink.clone());
    wait_until("the engine to hear of the loss", || {
        !rt.lock().engine.callback_connected(group).unwrap()
    });
    let m = rt.metrics.snapshot(Default::default());
    assert_eq!(m.dropped_disconnected, 1);
    // No update is scheduled for the group any more.
    let seen = sink.data_changes();
    let later = Instant::now() + Duration::from_millis(300);
    wait_until("300 ms", || Instant::now() >= later);
    assert_eq!(sink.data_changes(), seen);
    rt.stop_driver();
}

#[test]
fn a_loss_reported_after_the_listener_came_back_is_stale() {
    let rt = start(OpsConfig::default());
    let (_, group) = subscribe(&rt, 50);
    let sink = recorder();
    // The sink reports the loss but says it is connected again (a new Advise came
    // between the failed call and the driver's next step).
    sink.lose.store(true, Ordering::SeqCst);
    struct Readvised(Arc<Recorder>);
    impl GroupSink for Readvised {
        fn deliver(&self, group: GroupHandle, event: Event) -> Delivery {
            let d = self.0.deliver(group, event);
            self.0.connected.store(true, Ordering::SeqCst);
            d
        }
        fn is_connected(&self) -> bool {
            self.0.is_connected()
        }
        fn drop_listener(&self) -> bool {
            self.0.drop_listener()
        }
    }
    rt.set_group_sink(group, Arc::new(Readvised(sink.clone())));
    let seen = |n| move || sink.data_changes() >= n;
    wait_until("updates after the loss", seen(4));
    assert!(rt.lock().engine.callback_connected(group).unwrap());
    rt.stop_driver();
}

#[test]
fn a_client_over_its_callback_timeout_loses_its_listeners_at_the_failure_limit() {
    let rt = start(OpsConfig {
        callback_timeout_ms: 50,
        callback_failures: 2,
        ..OpsConfig::default()
    });
    let (session, group) = subscribe(&rt, 20);
    let sink = recorder();
    *sink.delay.lock().unwrap() = Duration::from_millis(300);
    rt.set_group_sink(group, sink.clone());
    wait_until("the listener dropped", || {
        sink.dropped.load(Ordering::SeqCst) >= 1
    });
    wait_until("the engine told", || {
        !rt.lock().engine.callback_connected(group).unwrap()
    });
    let m = rt.metrics.snapshot(Default::default());
    assert!(m.callback_failures >= 2, "{}", m.callback_failures);
    assert_eq!(m.dropped_failures, 1);
    let counters = rt.clients.client_counters(&[(session, 1, 2)]);
    assert!(counters[0].failures >= 2, "{counters:?}");
    rt.stop_driver();
}

#[test]
fn shutdown_asks_every_session_and_stops_the_driver() {
    #[derive(Default)]
    struct Asked(Mutex<Vec<String>>);
    impl SessionSink for Asked {
        fn shutdown_request(&self, reason: &str) {
            self.0.lock().unwrap().push(reason.to_owned());
        }
    }
    let rt = start(OpsConfig::default());
    let asked: Vec<Arc<Asked>> = (0..2).map(|_| Arc::default()).collect();
    for a in &asked {
        let s = rt.open_session();
        rt.set_session_sink(s, a.clone());
    }
    // A closed session is not asked.
    let closed = Arc::new(Asked::default());
    let s = rt.open_session();
    rt.set_session_sink(s, closed.clone());
    rt.close_session(s);
    rt.shutdown("bye");
    for a in &asked {
        assert_eq!(*a.0.lock().unwrap(), ["bye"]);
    }
    assert!(closed.0.lock().unwrap().is_empty());
    rt.stop_driver();
}

#[test]
fn a_closed_session_gets_no_more_callbacks() {
    let rt = start(OpsConfig::default());
    let (session, group) = subscribe(&rt, 20);
    let sink = recorder();
    rt.set_group_sink(group, sink.clone());
    wait_until("an update", || sink.data_changes() >= 1);
    rt.close_session(session);
    rt.remove_group_sink(group);
    let seen = sink.data_changes();
    let later = Instant::now() + Duration::from_millis(200);
    wait_until("200 ms", || Instant::now() >= later);
    // At most what was queued before the close.
    assert!(sink.data_changes() <= seen + 2);
    assert_eq!(rt.lock().engine.stats().sessions, 0);
    rt.stop_driver();
}

/// A synchronous write of one value to the writable item of `subscribe`'s group
/// (KW_A110), waited for.
fn write_set_point(rt: &Runtime, group: GroupHandle) -> Vec<Result<(), ctopc_core::OpcError>> {
    let outcome = rt.with_engine(|e, now| {
        let h = e.item_attributes(group).unwrap()[1].server_handle;
        e.write(now, group, &[(h, ctopc_core::Value::R8(1.0))])
            .unwrap()
    });
    match outcome {
        SyncOutcome::Ready(r) => r,
        SyncOutcome::Pending(id) => {
            match rt.wait_for(Duration::from_secs(10), |e| e.take_sync_result(id)) {
                Some(SyncResult::Write(r)) => r,
                other => panic!("{other:?}"),
            }
        }
    }
}

#[test]
fn the_write_rights_policy_decides_by_the_caller_the_front_end_names() {
    use ctopc_core::write_rights::{Caller, Channels, Principal, Rule, WriteRights};
    let rights = WriteRights::new(vec![Rule::new(
        Channels::All,
        Principal::parse("group:Operators").unwrap(),
    )]);
    let rt = start(OpsConfig {
        write_rights: Arc::new(rights),
        ..OpsConfig::default()
    });
    let (session, group) = subscribe(&rt, 1000);
    // Until told, the caller is unknown: refused.
    assert_eq!(
        write_set_point(&rt, group),
        [Err(ctopc_core::OpcError::BadRights)]
    );
    rt.set_caller(
        session,
        Caller::Windows {
            account: "PLANT\\op".into(),
            groups: vec!["PLANT\\Operators".into()],
        },
    );
    assert_eq!(write_set_point(&rt, group), [Ok(())]);
    let counters = rt.clients.client_counters(&[(session, 1, 2)]);
    assert_eq!(counters[0].identity.as_deref(), Some("user:PLANT\\op"));
    assert_eq!(
        rt.clients.identity(session).as_deref(),
        Some("user:PLANT\\op")
    );

    rt.set_caller(session, Caller::unknown("RPC_E_CALL_COMPLETE"));
    assert_eq!(
        write_set_point(&rt, group),
        [Err(ctopc_core::OpcError::BadRights)]
    );
    let h = rt.with_engine(|e, _| e.item_attributes(group).unwrap()[1].server_handle);
    assert_eq!(rt.lock().engine.denied_by_policy(group, &[h]), [true]);
    assert_eq!(
        rt.clients.identity(session).as_deref(),
        Some("unknown (RPC_E_CALL_COMPLETE)")
    );
    rt.close_session(session);
    assert_eq!(rt.clients.identity(session), None);
    rt.stop_driver();
}
