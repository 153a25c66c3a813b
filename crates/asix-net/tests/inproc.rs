//! The in-process simulation behind the engine, against the demo database: subscribed
//! values arrive and change, device reads and writes reach the plant, read-only and
//! derived items refuse writes; a slow device (`SimulationDeviceDelay`) answers late,
//! the engine times it out at `SourceTimeout`, and Cancel2 beats it.

use asix_model::{parse_config, AsixNamespace};
use asix_net::inproc::InProcessSim;
use ctopc_core::model::{
    DataSource, Engine, EngineConfig, Event, GroupHandle, GroupParams, ItemDefinition,
    SourceRequest, SyncOutcome, SyncResult,
};
use ctopc_core::source::{Backend, SourceOutput};
use ctopc_core::{OpcError, Timestamp, Value, VarType};
use std::sync::Arc;

fn demo() -> Arc<AsixNamespace> {
    let db = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../demo/wytwornia_kwasu/wytwornia_kwasu.zez"
    );
    let ini = format!("[Channel:*]\nItemsDatabase = {db}\nCheckLimits = tak\n");
    let (cfg, _) = parse_config(ini.as_bytes(), "test.ini").unwrap();
    Arc::new(AsixNamespace::load(cfg).0)
}

/// Moves everything the simulation has ready by `now` into the engine.
fn pull(e: &mut Engine, s: &mut InProcessSim, now: Timestamp) {
    let mut out = SourceOutput::default();
    s.poll(now, &mut out);
    e.handle_source_updates(now, out.updates);
    for (id, r) in out.read_results {
        e.handle_source_read_result(now, id, r);
    }
    for (id, r) in out.write_results {
        e.handle_source_write_result(now, id, r);
    }
}

/// One driver step, as the server's runtime does it: source in (answers held by a slow
/// device come out here), timers, requests out, source in again.
fn step(e: &mut Engine, s: &mut InProcessSim, now: Timestamp) {
    pull(e, s, now);
    if e.poll_timeout().is_some_and(|t| t <= now) {
        e.handle_timeout(now);
    }
    while let Some(r) = e.poll_source_request() {
        s.request(now, r);
    }
    pull(e, s, now);
}

fn setup() -> (
    Engine,
    InProcessSim,
    Timestamp,
    ctopc_core::model::GroupHandle,
    Vec<u32>,
) {
    let ns = demo();
    let t0 = Timestamp::from_unix_millis(1_700_000_000_000);
    let mut e = Engine::new(EngineConfig::default(), ns.clone());
    let s = InProcessSim::new(ns, 7, t0);
    let session = e.open_session();
    let g = e
        .add_group(
            t0,
            session,
            &GroupParams {
                name: "g",
                active: true,
                update_rate: 1000,
                client_handle: 1,
                time_bias: 0,
                percent_deadband: 0.0,
                lcid: 0x409,
            },
        )
        .unwrap()
        .group;
    let ids = ["KW_A000", "KW_A110", "KW_A000.PercentageCV", "KW_A000.DESC"];
    let defs: Vec<ItemDefinition> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| ItemDefinition {
            item_id: id,
            access_path: "",
            active: true,
            client_handle: i as u32,
            requested_type: VarType::EMPTY,
        })
        .collect();
    let handles = e
        .add_items(t0, g, &defs)
        .unwrap()
        .into_iter()
        .map(|r| r.unwrap().server_handle)
        .collect();
    (e, s, t0, g, handles)
}

#[test]
fn subscribed_demo_values_arrive_good_and_evolve() {
    let (mut e, mut s, t0, g, h) = setup();
    let mut seen = Vec::new();
    for k in 0..40 {
        let now = t0.add_millis(k * 500);
        step(&mut e, &mut s, now);
        let SyncOutcome::Ready(r) = e.read(now, g, DataSource::Cache, &h[..1]).unwrap() else {
            panic!("cache read pends")
        };
        let st = r[0].as_ref().unwrap();
        if k > 0 {
            assert!(
                st.quality.is_good() || st.quality.is_uncertain(),
                "{:?}",
                st.quality
            );
            seen.push(st.value.clone());
        }
    }
    seen.dedup();
    assert!(
        seen.len() > 3,
        "the tank level should move over 20 s: {seen:?}"
    );
    assert!(matches!(seen[0], Value::R4(_)));
}

#[test]
fn derived_items_and_attributes_come_through() {
    let (mut e, mut s, t0, g, h) = setup();
    for k in 0..4 {
        step(&mut e, &mut s, t0.add_millis(k * 500));
    }
    let now = t0.add_millis(2000);
    let SyncOutcome::Ready(r) = e.read(now, g, DataSource::Cache, &h).unwrap() else {
        panic!()
    };
    let level = r[0].as_ref().unwrap().value.as_f64().unwrap();
    let pct = r[2].as_ref().unwrap().value.as_f64().unwrap();
    assert!(
        (pct - level / 8.0 * 100.0).abs() < 1e-3,
        "level {level} m of 0..8 m is {pct} %"
    );
    assert!(matches!(&r[3].as_ref().unwrap().value, Value::Bstr(d) if d.contains("Z101")));
}

#[test]
fn device_write_reaches_the_plant_and_read_only_items_refuse() {
    let (mut e, mut s, t0, g, h) = setup();
    step(&mut e, &mut s, t0);
    let now = t0.add_millis(100);
    let out = e
        .write(
            now,
            g,
            &[
                (h[1], Value::R8(12.5)),
                (h[0], Value::R8(1.0)),
                (h[2], Value::R8(5.0)),
            ],
        )
        .unwrap();
    let results = match out {
        SyncOutcome::Ready(r) => r,
        SyncOutcome::Pending(id) => {
            step(&mut e, &mut s, now);
            match e.take_sync_result(id) {
                Some(ctopc_core::model::SyncResult::Write(r)) => r,
                other => panic!("{other:?}"),
            }
        }
    };
    assert_eq!(results[0], Ok(()));
    assert!(
        results[1].is_err(),
        "KW_A000 is not writable: {:?}",
        results[1]
    );
    assert!(
        results[2].is_err(),
        "a derived item is read-only: {:?}",
        results[2]
    );
    let now = t0.add_millis(200);
    let r = match e.read(now, g, DataSource::Device, &h[1..2]).unwrap() {
        SyncOutcome::Ready(r) => r,
        SyncOutcome::Pending(id) => {
            step(&mut e, &mut s, now);
            match e.take_sync_result(id) {
                Some(ctopc_core::model::SyncResult::Read(r)) => r,
                other => panic!("{other:?}"),
            }
        }
    };
    assert_eq!(r[0].as_ref().unwrap().value.as_f64(), Some(12.5));
}

/// The server state comes from the backend (`Backend::is_simulation`): the in-process
/// simulation is simulated data, OPC_STATUS_TEST.
#[test]
fn the_simulation_says_it_simulates() {
    let s = InProcessSim::new(demo(), 1, Timestamp::from_unix_millis(1_700_000_000_000));
    assert!(s.is_simulation());
}

// ---- a slow device: SimulationDeviceDelay and SourceTimeout ---------------------------

/// The demo plant with these `[Server]` options, built as the server builds it: the
/// engine configured from the options, the simulation with their SimulationDeviceDelay.
/// One group (inactive unless `active`: no subscriptions then, so the simulation's only
/// timers are its held answers) with KW_A000 (read-only) and KW_A110 (writable).
fn slow_setup(
    server_options: &str,
    active: bool,
) -> (Engine, InProcessSim, Timestamp, GroupHandle, Vec<u32>) {
    let db = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../demo/wytwornia_kwasu/wytwornia_kwasu.zez"
    );
    let ini = format!("[Server]\nSimulateCurrentData = tak\n{server_options}\n[Channel:*]\nItemsDatabase = {db}\n");
    let (cfg, w) = parse_config(ini.as_bytes(), "slow.ini").unwrap();
    assert!(w.is_empty(), "{w:?}");
    let delay = cfg.server.simulation_device_delay_ms;
    let engine_config = cfg.server.engine_config();
    let ns = Arc::new(AsixNamespace::load(cfg).0);
    let t0 = Timestamp::from_unix_millis(1_700_000_000_000);
    let mut e = Engine::new(engine_config, ns.clone());
    let s = InProcessSim::new(ns, 7, t0).with_device_delay(delay);
    let session = e.open_session();
    let g = e
        .add_group(
            t0,
            session,
            &GroupParams {
                name: "slow",
                active,
                update_rate: 1000,
                client_handle: 77,
                time_bias: 0,
                percent_deadband: 0.0,
                lcid: 0x409,
            },
        )
        .unwrap()
        .group;
    let defs: Vec<ItemDefinition> = ["KW_A000", "KW_A110"]
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
    let handles = e
        .add_items(t0, g, &defs)
        .unwrap()
        .into_iter()
        .map(|r| r.unwrap().server_handle)
        .collect();
    e.set_callback_connected(t0, g, true).unwrap();
    (e, s, t0, g, handles)
}

fn pending<T: std::fmt::Debug>(o: SyncOutcome<T>) -> ctopc_core::model::SyncId {
    match o {
        SyncOutcome::Pending(id) => id,
        SyncOutcome::Ready(r) => panic!("a device operation answered without the source: {r:?}"),
    }
}

/// The engine's device requests (and nothing else).
fn device_requests(e: &mut Engine) -> Vec<SourceRequest> {
    let mut v = Vec::new();
    while let Some(r) = e.poll_source_request() {
        assert!(
            matches!(
                r,
                SourceRequest::Read { .. }
                    | SourceRequest::Write { .. }
                    | SourceRequest::WriteVqt { .. }
            ),
            "{r:?}"
        );
        v.push(r);
    }
    v
}

#[test]
fn a_slow_device_holds_its_answers_until_due_and_says_when() {
    let (mut e, mut s, t0, g, h) = slow_setup("SimulationDeviceDelay = 1500", false);
    assert_eq!(
        s.poll_timeout(),
        None,
        "an inactive group subscribes nothing"
    );
    // A write at t0, then a device read of the same item at t0 + 10.
    let write = pending(e.write(t0, g, &[(h[1], Value::R8(12.5))]).unwrap());
    for r in device_requests(&mut e) {
        s.request(t0, r);
    }
    let t1 = t0.add_millis(10);
    let read = pending(e.read(t1, g, DataSource::Device, &h).unwrap());
    for r in device_requests(&mut e) {
        s.request(t1, r);
    }
    assert_eq!(
        s.poll_timeout(),
        Some(t0.add_millis(1500)),
        "the earliest due answer wakes the driver"
    );

    let mut out = SourceOutput::default();
    s.poll(t0.add_millis(1499), &mut out);
    assert!(out.is_empty(), "nothing before the delay: {out:?}");
    s.poll(t0.add_millis(1500), &mut out);
    assert_eq!((out.write_results.len(), out.read_results.len()), (1, 0));
    assert_eq!(out.write_results[0].1, vec![Ok(())]);
    assert_eq!(s.poll_timeout(), Some(t1.add_millis(1500)));
    let mut late = SourceOutput::default();
    s.poll(t1.add_millis(1499), &mut late);
    assert!(late.is_empty());
    s.poll(t1.add_millis(1500), &mut late);
    assert_eq!((late.write_results.len(), late.read_results.len()), (0, 1));
    assert_eq!(s.poll_timeout(), None, "nothing held any more");
    // The write took effect when it was requested: the read made 10 ms later sees it.
    let values: Vec<Option<f64>> = late.read_results[0]
        .1
        .iter()
        .map(|r| r.as_ref().unwrap().value.as_f64())
        .collect();
    assert_eq!(values.len(), 2);
    assert_eq!(values[1], Some(12.5));

    // The engine takes the late answers as any others.
    let now = t1.add_millis(1500);
    for (id, r) in out.write_results {
        e.handle_source_write_result(now, id, r);
    }
    for (id, r) in late.read_results {
        e.handle_source_read_result(now, id, r);
    }
    assert_eq!(
        e.take_sync_result(write),
        Some(SyncResult::Write(vec![Ok(())]))
    );
    let Some(SyncResult::Read(r)) = e.take_sync_result(read) else {
        panic!("no read result")
    };
    assert_eq!(r[1].as_ref().unwrap().value.as_f64(), Some(12.5));
}

#[test]
fn a_slow_device_with_the_same_inputs_answers_the_same() {
    let run = || {
        let (mut e, mut s, t0, g, h) = slow_setup("SimulationDeviceDelay = 700", false);
        let mut answers = Vec::new();
        for k in 0..4u64 {
            let now = t0.add_millis(k * 300);
            let _ = pending(e.read(now, g, DataSource::Device, &h).unwrap());
            for r in device_requests(&mut e) {
                s.request(now, r);
            }
            let mut out = SourceOutput::default();
            s.poll(now, &mut out);
            answers.push((
                now,
                s.poll_timeout(),
                out.read_results
                    .into_iter()
                    .map(|(_, r)| r)
                    .collect::<Vec<_>>(),
            ));
        }
        let mut out = SourceOutput::default();
        s.poll(t0.add_millis(10_000), &mut out);
        answers.push((
            t0,
            s.poll_timeout(),
            out.read_results.into_iter().map(|(_, r)| r).collect(),
        ));
        answers
    };
    let a = run();
    assert_eq!(a, run());
    // At 0, 300, 600, 900 ms: the first answer (due 700) comes out at the poll of 900.
    let released: Vec<usize> = a.iter().map(|(_, _, r)| r.len()).collect();
    assert_eq!(released, vec![0, 0, 0, 1, 3]);
    assert_eq!(a[0].1, Some(a[0].0.add_millis(700)));
    assert_eq!(a[4].1, None);
}

#[test]
fn source_timeout_from_the_ini_fails_a_read_and_a_write_the_device_answers_too_late() {
    let (mut e, mut s, t0, g, h) =
        slow_setup("SourceTimeout = 1000\nSimulationDeviceDelay = 3000", false);
    assert_eq!(
        e.config().source_timeout_ms,
        1000,
        "SourceTimeout reaches the engine"
    );
    let read = pending(e.read(t0, g, DataSource::Device, &h).unwrap());
    let write = pending(e.write(t0, g, &[(h[1], Value::R8(3.0))]).unwrap());
    step(&mut e, &mut s, t0);
    step(&mut e, &mut s, t0.add_millis(999));
    assert_eq!(e.take_sync_result(read), None, "still waiting at 999 ms");
    step(&mut e, &mut s, t0.add_millis(1000));
    assert_eq!(
        e.take_sync_result(read),
        Some(SyncResult::Read(vec![Err(OpcError::NetAnswerTimeout); 2]))
    );
    assert_eq!(
        e.take_sync_result(write),
        Some(SyncResult::Write(vec![Err(OpcError::NetAnswerTimeout)]))
    );
    // The answers arriving at 3000 ms belong to nobody any more: dropped quietly.
    for ms in [2999, 3000, 3001] {
        step(&mut e, &mut s, t0.add_millis(ms));
    }
    assert_eq!(e.poll_event(), None);
    assert_eq!(e.stats().pending_transactions, 0);

    // Within the timeout the late answer is the answer.
    let (mut e, mut s, t0, g, h) =
        slow_setup("SourceTimeout = 1000\nSimulationDeviceDelay = 600", false);
    let read = pending(e.read(t0, g, DataSource::Device, &h).unwrap());
    step(&mut e, &mut s, t0);
    step(&mut e, &mut s, t0.add_millis(599));
    assert_eq!(e.take_sync_result(read), None);
    step(&mut e, &mut s, t0.add_millis(600));
    let Some(SyncResult::Read(r)) = e.take_sync_result(read) else {
        panic!("no answer at 600 ms")
    };
    assert!(r.iter().all(Result::is_ok), "{r:?}");
}

#[test]
fn cancel2_beats_a_slow_device_and_no_read_complete_follows() {
    let (mut e, mut s, t0, g, h) = slow_setup("SimulationDeviceDelay = 1500", false);
    let started = e.async_read(t0, g, 7, &h).unwrap();
    assert_ne!(started.cancel_id, 0);
    step(&mut e, &mut s, t0);
    step(&mut e, &mut s, t0.add_millis(100));
    assert_eq!(e.poll_event(), None, "the device has not answered yet");
    e.cancel2(g, started.cancel_id).unwrap();
    match e.poll_event() {
        Some(Event::CancelComplete(c)) => {
            assert_eq!(
                (c.transaction_id, c.client_group, c.group, c.cancel_id),
                (7, 77, g, started.cancel_id)
            );
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        e.cancel2(g, started.cancel_id),
        Err(OpcError::Fail),
        "cancelled already"
    );
    // The device's answer (1500 ms) and the engine's timeout (10 s) pass without a callback.
    for ms in (200..=12_000).step_by(100) {
        step(&mut e, &mut s, t0.add_millis(ms));
        assert_eq!(e.poll_event(), None, "at {ms} ms");
    }

    // Not cancelled: OnReadComplete at the delay, not before.
    let t1 = t0.add_millis(20_000);
    let started = e.async_read(t1, g, 8, &h).unwrap();
    step(&mut e, &mut s, t1);
    step(&mut e, &mut s, t1.add_millis(1499));
    assert_eq!(e.poll_event(), None);
    step(&mut e, &mut s, t1.add_millis(1500));
    match e.poll_event() {
        Some(Event::ReadComplete(r)) => {
            assert_eq!(
                (r.transaction_id, r.cancel_id, r.items.len()),
                (8, started.cancel_id, 2)
            );
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        e.cancel2(g, started.cancel_id),
        Err(OpcError::Fail),
        "completed already"
    );
}

/// The pipeline's rule for limit variables, in the simulation as over the network
/// (`engine_adapter.rs`, `a_limit_variable_without_a_value_is_an_unknown_limit`): a limit
/// variable whose value is BAD is an unknown limit. KW_A342 (0..2000) has WarnHigh
/// KW_L005 and AlarmHigh KW_L006, no low limits; both limits are written as -1, so that
/// any plant value is above them, then made BAD one after the other.
#[test]
fn a_bad_limit_variable_is_an_unknown_limit_in_the_simulation() {
    use ctopc_core::model::datasource::ItemVqt;
    use ctopc_core::Quality;
    let (mut e, mut s, t0, _, _) = setup();
    let session = e.open_session();
    let g = e
        .add_group(
            t0,
            session,
            &GroupParams {
                name: "limits",
                active: true,
                update_rate: 1000,
                client_handle: 2,
                time_bias: 0,
                percent_deadband: 0.0,
                lcid: 0x409,
            },
        )
        .unwrap()
        .group;
    let defs: Vec<ItemDefinition> = ["KW_A342", "KW_L005", "KW_L006"]
        .iter()
        .enumerate()
        .map(|(i, id)| ItemDefinition {
            item_id: id,
            access_path: "",
            active: true,
            client_handle: i as u32,
            requested_type: VarType::EMPTY,
        })
        .collect();
    let h: Vec<u32> = e
        .add_items(t0, g, &defs)
        .unwrap()
        .into_iter()
        .map(|r| r.unwrap().server_handle)
        .collect();
    step(&mut e, &mut s, t0);
    let mut now = t0;
    let mut quality_after = |l005: Quality, l006: Quality| {
        now = now.add_millis(100);
        let limit = |q| ItemVqt {
            value: Value::R4(-1.0),
            quality: Some(q),
            timestamp: None,
        };
        let items = [(h[1], limit(l005)), (h[2], limit(l006))];
        if let SyncOutcome::Pending(id) = e.write_vqt(now, g, &items).unwrap() {
            step(&mut e, &mut s, now);
            match e.take_sync_result(id) {
                Some(SyncResult::Write(r)) => assert_eq!(r, vec![Ok(()), Ok(())]),
                other => panic!("{other:?}"),
            }
        }
        let r = match e.read(now, g, DataSource::Device, &h[..1]).unwrap() {
            SyncOutcome::Ready(r) => r,
            SyncOutcome::Pending(id) => {
                step(&mut e, &mut s, now);
                match e.take_sync_result(id) {
                    Some(SyncResult::Read(r)) => r,
                    other => panic!("{other:?}"),
                }
            }
        };
        r[0].as_ref().unwrap().quality
    };
    let high = Quality::GOOD.with_limit(Quality::LIMIT_HIGH);
    assert_eq!(
        quality_after(Quality::GOOD, Quality::GOOD),
        high.with_vendor(Quality::VENDOR_SECOND_LIMIT)
    );
    assert_eq!(quality_after(Quality::GOOD, Quality::BAD), high);
    assert_eq!(quality_after(Quality::BAD, Quality::BAD), Quality::GOOD);
}

/// The adapter's rule for an item without a plant variable, in the simulation: one
/// BAD_CONFIG_ERROR sample when subscribed (the cache shows it), and no sampling of it
/// afterwards (nothing about it changes).
#[test]
fn an_item_without_a_plant_variable_is_config_error_once() {
    let ns = demo();
    let t0 = Timestamp::from_unix_millis(1_700_000_000_000);
    let mut e = Engine::new(EngineConfig::default(), ns.clone());
    let mut s = InProcessSim::new(ns, 7, t0);
    let session = e.open_session();
    let params = GroupParams {
        name: "g",
        active: true,
        update_rate: 1000,
        ..Default::default()
    };
    let g = e.add_group(t0, session, &params).unwrap().group;
    let def = ItemDefinition {
        item_id: "asmen.NIC.NIE_MA.R4",
        access_path: "",
        active: true,
        client_handle: 1,
        requested_type: VarType::EMPTY,
    };
    let h = e.add_items(t0, g, &[def]).unwrap()[0]
        .as_ref()
        .unwrap()
        .server_handle;
    while let Some(r) = e.poll_source_request() {
        s.request(t0, r);
    }
    let mut out = SourceOutput::default();
    s.poll(t0, &mut out);
    assert_eq!(out.updates.len(), 1);
    assert_eq!(
        out.updates[0].1.quality,
        ctopc_core::Quality::BAD_CONFIG_ERROR
    );
    e.handle_source_updates(t0, out.updates);
    let SyncOutcome::Ready(r) = e.read(t0, g, DataSource::Cache, &[h]).unwrap() else {
        panic!("cache read pends")
    };
    assert_eq!(
        r[0].as_ref().unwrap().quality,
        ctopc_core::Quality::BAD_CONFIG_ERROR
    );
    assert_eq!(s.poll_timeout(), None, "nothing to sample");
    for k in 1..10 {
        let mut out = SourceOutput::default();
        s.poll(t0.add_millis(k * 1000), &mut out);
        assert!(out.is_empty(), "{out:?}");
    }
}

#[test]
fn the_simulation_reports_itself_as_one_channel_with_its_subscriptions() {
    let (mut e, mut s, t0, _, _) = setup();
    let before = s.channels();
    assert_eq!(before.len(), 1);
    assert_eq!(before[0].name, "Simulation");
    assert_eq!(
        before[0].link,
        ctopc_core::diagnostics::LinkState::Simulation
    );
    assert_eq!(before[0].subscriptions, 0);
    step(&mut e, &mut s, t0);
    // KW_A000 (its value and PercentageCV) and KW_A110, and the rule variables with them;
    // the DESC constant is never subscribed.
    let after = s.channels();
    assert!(after[0].subscriptions >= 2, "{after:?}");
    assert_eq!(after[0].failovers, 0);
    assert!(after[0].last_error.is_empty());
}
