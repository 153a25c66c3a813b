//! The in-process simulation behind the engine, against the demo database: subscribed
//! values arrive and change, device reads and writes reach the plant, read-only and
//! derived items refuse writes.

use asix_net::inproc::InProcessSim;
use ctopc_core::asix::{parse_config, AsixNamespace};
use ctopc_core::model::{DataSource, Engine, EngineConfig, GroupParams, ItemDefinition, SyncOutcome};
use ctopc_core::source::{Backend, SourceOutput};
use ctopc_core::{Timestamp, Value, VarType};
use std::sync::Arc;

fn demo() -> Arc<AsixNamespace> {
    let db = concat!(env!("CARGO_MANIFEST_DIR"), "/../../demo/wytwornia_kwasu/wytwornia_kwasu.zez");
    let ini = format!("[Channel:*]\nItemsDatabase = {db}\nCheckLimits = tak\n");
    let (cfg, _) = parse_config(ini.as_bytes(), "test.ini").unwrap();
    Arc::new(AsixNamespace::load(cfg).0)
}

/// One driver step, as the server's runtime does it.
fn step(e: &mut Engine, s: &mut InProcessSim, now: Timestamp) {
    let mut out = SourceOutput::default();
    s.poll(now, &mut out);
    e.handle_source_updates(now, out.updates);
    if e.poll_timeout().is_some_and(|t| t <= now) {
        e.handle_timeout(now);
    }
    while let Some(r) = e.poll_source_request() {
        s.request(now, r);
    }
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

fn setup() -> (Engine, InProcessSim, Timestamp, ctopc_core::model::GroupHandle, Vec<u32>) {
    let ns = demo();
    let t0 = Timestamp::from_unix_millis(1_700_000_000_000);
    let mut e = Engine::new(EngineConfig::default(), ns.clone());
    let s = InProcessSim::new(ns, 7, t0);
    let session = e.open_session();
    let g = e
        .add_group(t0, session, &GroupParams { name: "g", active: true, update_rate: 1000, client_handle: 1, time_bias: 0, percent_deadband: 0.0, lcid: 0x409 })
        .unwrap()
        .group;
    let ids = ["KW_A000", "KW_A110", "KW_A000.PercentageCV", "KW_A000.DESC"];
    let defs: Vec<ItemDefinition> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| ItemDefinition { item_id: id, access_path: "", active: true, client_handle: i as u32, requested_type: VarType::EMPTY })
        .collect();
    let handles = e.add_items(t0, g, &defs).unwrap().into_iter().map(|r| r.unwrap().server_handle).collect();
    (e, s, t0, g, handles)
}

#[test]
fn subscribed_demo_values_arrive_good_and_evolve() {
    let (mut e, mut s, t0, g, h) = setup();
    let mut seen = Vec::new();
    for k in 0..40 {
        let now = t0.add_millis(k * 500);
        step(&mut e, &mut s, now);
        let SyncOutcome::Ready(r) = e.read(now, g, DataSource::Cache, &h[..1]).unwrap() else { panic!("cache read pends") };
        let st = r[0].as_ref().unwrap();
        if k > 0 {
            assert!(st.quality.is_good() || st.quality.is_uncertain(), "{:?}", st.quality);
            seen.push(st.value.clone());
        }
    }
    seen.dedup();
    assert!(seen.len() > 3, "the tank level should move over 20 s: {seen:?}");
    assert!(matches!(seen[0], Value::R4(_)));
}

#[test]
fn derived_items_and_attributes_come_through() {
    let (mut e, mut s, t0, g, h) = setup();
    for k in 0..4 {
        step(&mut e, &mut s, t0.add_millis(k * 500));
    }
    let now = t0.add_millis(2000);
    let SyncOutcome::Ready(r) = e.read(now, g, DataSource::Cache, &h).unwrap() else { panic!() };
    let level = r[0].as_ref().unwrap().value.as_f64().unwrap();
    let pct = r[2].as_ref().unwrap().value.as_f64().unwrap();
    assert!((pct - level / 8.0 * 100.0).abs() < 1e-3, "level {level} m of 0..8 m is {pct} %");
    assert!(matches!(&r[3].as_ref().unwrap().value, Value::Bstr(d) if d.contains("Z101")));
}

#[test]
fn device_write_reaches_the_plant_and_read_only_items_refuse() {
    let (mut e, mut s, t0, g, h) = setup();
    step(&mut e, &mut s, t0);
    let now = t0.add_millis(100);
    let out = e.write(now, g, &[(h[1], Value::R8(12.5)), (h[0], Value::R8(1.0)), (h[2], Value::R8(5.0))]).unwrap();
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
    assert!(results[1].is_err(), "KW_A000 is not writable: {:?}", results[1]);
    assert!(results[2].is_err(), "a derived item is read-only: {:?}", results[2]);
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
