//! Server model: synchronous and asynchronous reads, writes and refreshes (IOPCSyncIO/2,
//! IOPCAsyncIO2/3), MaxAge, Cancel2, transaction limits and source timeouts.

mod model_util;

use ctopc_core::model::*;
use ctopc_core::{OpcError, Quality, Timestamp, Value, VarType, Vqt};
use model_util::*;

fn ready<T: std::fmt::Debug>(o: SyncOutcome<T>) -> T {
    match o {
        SyncOutcome::Ready(t) => t,
        SyncOutcome::Pending(id) => panic!("pending {id:?}"),
    }
}

fn pending<T: std::fmt::Debug>(o: SyncOutcome<T>) -> SyncId {
    match o {
        SyncOutcome::Pending(id) => id,
        SyncOutcome::Ready(t) => panic!("ready {t:?}"),
    }
}

fn good(x: f64, t: Timestamp) -> Result<Vqt, OpcError> {
    Ok(Vqt::new(Value::R8(x), Quality::GOOD, t))
}

#[test]
fn cache_read_of_inactive_item_or_group_is_out_of_service() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "A2"]);
    sim.push_good("A1", 1.0);
    sim.push_good("A2", 2.0);
    sim.e.set_active_state(sim.now, g, &[h[1]], false).unwrap();
    let r = ready(
        sim.e
            .read(sim.now, g, DataSource::Cache, &[h[0], h[1], 31337])
            .unwrap(),
    );
    let a = r[0].as_ref().unwrap();
    assert_eq!(
        (a.client_handle, &a.value, a.quality, a.timestamp),
        (100, &Value::R8(1.0), Quality::GOOD, sim.now)
    );
    let b = r[1].as_ref().unwrap();
    assert_eq!(
        (&b.value, b.quality),
        (&Value::R8(2.0), Quality::BAD_OUT_OF_SERVICE),
        "value from the cache, quality out of service"
    );
    assert_eq!(r[2], Err(OpcError::InvalidHandle));
    sim.e
        .set_group_state(
            sim.now,
            g,
            &SetGroupState {
                active: Some(false),
                ..Default::default()
            },
        )
        .unwrap();
    let r = ready(sim.e.read(sim.now, g, DataSource::Cache, &[h[0]]).unwrap());
    assert_eq!(r[0].as_ref().unwrap().quality, Quality::BAD_OUT_OF_SERVICE);
}

#[test]
fn device_read_waits_for_the_source_and_refreshes_the_cache() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "A2", "CONST"]);
    sim.tick();
    sim.events();
    let id = pending(
        sim.e
            .read(sim.now, g, DataSource::Device, &[h[0], 4711, h[1], h[2]])
            .unwrap(),
    );
    let (req, items) = sim.take_read();
    let ids: Vec<&str> = items.iter().map(|i| &*i.item_id).collect();
    assert_eq!(
        ids,
        vec!["A1", "A2"],
        "invalid handles and constants are not asked for"
    );
    assert!(sim.e.sync_pending(id));
    assert_eq!(sim.e.take_sync_result(id), None);
    assert_eq!(sim.e.poll_sync_completion(), None);
    sim.e.handle_source_read_result(
        sim.now,
        req,
        vec![good(11.0, sim.now), Err(OpcError::NetLinkToServer)],
    );
    assert!(!sim.e.sync_pending(id));
    assert_eq!(
        sim.e.poll_sync_completion(),
        Some(id),
        "the driver learns which waiter to wake"
    );
    assert_eq!(sim.e.poll_sync_completion(), None);
    let Some(SyncResult::Read(r)) = sim.e.take_sync_result(id) else {
        panic!()
    };
    assert_eq!(r[0].as_ref().unwrap().value, Value::R8(11.0));
    assert_eq!(r[1], Err(OpcError::InvalidHandle));
    assert_eq!(
        r[2],
        Err(OpcError::NetLinkToServer),
        "ASKOM codes reach the client per item"
    );
    assert_eq!(r[3].as_ref().unwrap().value, Value::R8(42.0));
    assert_eq!(sim.e.take_sync_result(id), None, "taken once");
    // The device value also went into the cache (and so to subscribers).
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(values(&dc[0]), vec![(100, Value::R8(11.0))]);
}

/// A device read names the items the source holds subscribed by their key alone (the
/// source knows them; an item ID would cost an allocation per item), the others whole.
#[test]
fn device_read_sends_subscribed_items_by_key_and_the_others_whole() {
    let mut sim = Sim::new();
    let s = sim.session();
    let active = sim.group(s, "active", 1000, 0.0);
    let h = sim.items(active, &["A1"]);
    let idle = sim.group(s, "idle", 1000, 0.0);
    let inactive = SetGroupState {
        active: Some(false),
        ..Default::default()
    };
    sim.e.set_group_state(sim.now, idle, &inactive).unwrap();
    let h2 = sim.items(idle, &["A2"]);
    sim.tick();
    sim.events();
    pending(sim.e.read(sim.now, active, DataSource::Device, &h).unwrap());
    let (_, items) = sim.take_read_items();
    let key = sim.keys["A1"];
    assert_eq!(items, vec![ReadItem::Subscribed(key)]);
    pending(sim.e.read(sim.now, idle, DataSource::Device, &h2).unwrap());
    let (_, items) = sim.take_read_items();
    match &items[..] {
        [ReadItem::Item(i)] => assert_eq!(&*i.item_id, "A2"),
        other => panic!("A2 is not subscribed, so it goes whole: {other:?}"),
    }
}

/// The namespace's reason for refusing writes by design, for the log line of a refused
/// write: given for the items that have one, by handle (unknown handles have none).
#[test]
fn write_refusals_name_the_items_refused_by_design() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let defs: Vec<ItemDefinition> = [("RO", "Camac"), ("RO", ""), ("A1", "Camac")]
        .iter()
        .map(|(id, path)| ItemDefinition {
            item_id: id,
            access_path: path,
            active: true,
            client_handle: 0,
            requested_type: VarType::EMPTY,
        })
        .collect();
    let h: Vec<u32> = sim
        .e
        .add_items(sim.now, g, &defs)
        .unwrap()
        .into_iter()
        .map(|r| r.unwrap().server_handle)
        .collect();
    let got = sim.e.write_refusals(g, &[h[0], h[1], h[2], 4711]);
    assert_eq!(
        got,
        vec![("RO".to_owned(), "Camac takes no writes".to_owned())]
    );
}

#[test]
fn device_read_times_out_with_net_answer_timeout() {
    let mut sim = Sim::with_config(EngineConfig {
        source_timeout_ms: 5000,
        ..Default::default()
    });
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    sim.tick();
    sim.events();
    let id = pending(sim.e.read(sim.now, g, DataSource::Device, &h).unwrap());
    let (req, _) = sim.take_read();
    sim.advance(4999);
    assert!(sim.e.sync_pending(id));
    sim.advance(1);
    assert_eq!(
        sim.e.take_sync_result(id),
        Some(SyncResult::Read(vec![Err(OpcError::NetAnswerTimeout)]))
    );
    // A late answer is ignored.
    sim.e
        .handle_source_read_result(sim.now, req, vec![good(1.0, sim.now)]);
    assert_eq!(sim.e.take_sync_result(id), None);
}

#[test]
fn abandoned_sync_read_is_forgotten() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    let id = pending(sim.e.read(sim.now, g, DataSource::Device, &h).unwrap());
    let (req, _) = sim.take_read();
    sim.e.abandon_sync(id);
    assert!(!sim.e.sync_pending(id));
    sim.e
        .handle_source_read_result(sim.now, req, vec![good(1.0, sim.now)]);
    assert_eq!(sim.e.take_sync_result(id), None);
    assert_eq!(sim.e.stats().pending_transactions, 0);
}

#[test]
fn read_max_age_uses_cache_when_fresh_and_device_when_stale() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "A2"]);
    sim.push_good("A1", 1.0);
    sim.push_good("A2", 2.0);
    sim.advance(3000);
    sim.events();
    // Age 3000 ms: MaxAge 5000 and MAX read the cache.
    let r = ready(
        sim.e
            .read_max_age(sim.now, g, &[(h[0], 5000), (h[1], MAX_AGE_CACHE)])
            .unwrap(),
    );
    assert_eq!(r[0].as_ref().unwrap().value, Value::R8(1.0));
    assert_eq!(r[1].as_ref().unwrap().value, Value::R8(2.0));
    // MaxAge 2000 is stale, 0 always goes to the device.
    let id = pending(
        sim.e
            .read_max_age(
                sim.now,
                g,
                &[(h[0], 2000), (h[1], MAX_AGE_DEVICE), (h[0], 3000)],
            )
            .unwrap(),
    );
    let (req, items) = sim.take_read();
    assert_eq!(items.len(), 2);
    sim.e
        .handle_source_read_result(sim.now, req, vec![good(10.0, sim.now), good(20.0, sim.now)]);
    let Some(SyncResult::Read(r)) = sim.e.take_sync_result(id) else {
        panic!()
    };
    let v: Vec<Value> = r.into_iter().map(|r| r.unwrap().value).collect();
    assert_eq!(v, vec![Value::R8(10.0), Value::R8(20.0), Value::R8(1.0)]);
}

#[test]
fn read_max_age_of_never_sampled_item_goes_to_the_device() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    pending(sim.e.read_max_age(sim.now, g, &[(h[0], 60_000)]).unwrap());
    let r = ready(
        sim.e
            .read_max_age(sim.now, g, &[(h[0], MAX_AGE_CACHE)])
            .unwrap(),
    );
    assert_eq!(
        r[0].as_ref().unwrap().quality,
        Quality::BAD_WAITING_FOR_INITIAL_DATA
    );
}

/// Items of an inactive group are never sampled: reads from the cache give the state at
/// AddItems (no value, waiting quality, the time they were added) until a device read
/// puts a value into the cache, which MaxAge reads then use; a removed and re-added item
/// starts again.
#[test]
fn inactive_items_have_no_sample_until_a_device_read() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let inactive = SetGroupState {
        active: Some(false),
        ..Default::default()
    };
    sim.e.set_group_state(sim.now, g, &inactive).unwrap();
    let added = sim.now;
    let h = sim.items(g, &["A1", "A2"]);
    sim.advance(500);
    let r = ready(sim.e.read(sim.now, g, DataSource::Cache, &h).unwrap());
    for x in &r {
        let x = x.as_ref().unwrap();
        assert_eq!(
            (&x.value, x.quality, x.timestamp),
            (&Value::Empty, Quality::BAD_OUT_OF_SERVICE, added)
        );
    }
    let cached = |sim: &mut Sim, h: u32| {
        let r = ready(
            sim.e
                .read_max_age(sim.now, g, &[(h, MAX_AGE_CACHE)])
                .unwrap(),
        );
        let x = r[0].clone().unwrap();
        (x.value, x.quality, x.timestamp)
    };
    assert_eq!(
        cached(&mut sim, h[0]),
        (Value::Empty, Quality::BAD_WAITING_FOR_INITIAL_DATA, added)
    );
    let id = pending(sim.e.read(sim.now, g, DataSource::Device, &h[..1]).unwrap());
    let (req, _) = sim.take_read();
    let sampled = sim.now;
    sim.e
        .handle_source_read_result(sim.now, req, vec![good(11.0, sampled)]);
    let Some(SyncResult::Read(r)) = sim.e.take_sync_result(id) else {
        panic!()
    };
    assert_eq!(r[0].as_ref().unwrap().value, Value::R8(11.0));
    sim.advance(1000);
    let r = ready(sim.e.read_max_age(sim.now, g, &[(h[0], 5000)]).unwrap());
    let x = r[0].as_ref().unwrap();
    assert_eq!(
        (&x.value, x.quality, x.timestamp),
        (&Value::R8(11.0), Quality::GOOD, sampled),
        "fresh enough: from the cache"
    );
    assert_eq!(
        cached(&mut sim, h[1]),
        (Value::Empty, Quality::BAD_WAITING_FOR_INITIAL_DATA, added),
        "A2 still has none"
    );
    pending(sim.e.read_max_age(sim.now, g, &[(h[1], 60_000)]).unwrap());
    // Removed (the cache entry goes) and added again: no value.
    sim.e.remove_items(sim.now, g, &h).unwrap();
    sim.tick();
    let again = sim.now;
    let h = sim.items(g, &["A1"]);
    assert_eq!(
        cached(&mut sim, h[0]),
        (Value::Empty, Quality::BAD_WAITING_FOR_INITIAL_DATA, again)
    );
}

#[test]
fn write_rejects_read_only_and_converts_to_canonical() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "RO", "D1", "A2"]);
    let out = sim
        .e
        .write(
            sim.now,
            g,
            &[
                (h[0], Value::I4(5)),
                (h[1], Value::R8(1.0)),
                (h[2], Value::Bstr("x".into())),
                (h[2], Value::R8(1e300)),
                (h[3], Value::Empty),
                (99, Value::R8(1.0)),
                (h[3], Value::Bstr("2.5".into())),
            ],
        )
        .unwrap();
    let id = pending(out);
    sim.pump();
    let Some(SourceRequest::Write { req_id, items }) = sim.io.pop() else {
        panic!("{:?}", sim.io)
    };
    let sent: Vec<(&str, Value)> = items
        .iter()
        .map(|(i, v)| (&*i.item_id, v.clone()))
        .collect();
    assert_eq!(
        sent,
        vec![("A1", Value::R8(5.0)), ("A2", Value::R8(2.5))],
        "converted to the canonical type"
    );
    sim.e.handle_source_write_result(
        sim.now,
        req_id,
        vec![Ok(()), Err(OpcError::WriteErrorDriverTimeout)],
    );
    let Some(SyncResult::Write(r)) = sim.e.take_sync_result(id) else {
        panic!()
    };
    assert_eq!(
        r,
        vec![
            Ok(()),
            Err(OpcError::BadRights),
            Err(OpcError::BadType),
            Err(OpcError::Range),
            Err(OpcError::BadType),
            Err(OpcError::InvalidHandle),
            Err(OpcError::WriteErrorDriverTimeout)
        ]
    );
}

#[test]
fn extended_write_array_becomes_write_vqt() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    let stamp = Timestamp::from_unix_millis(1_600_000_000_000);
    let arr = Value::Array(ctopc_core::value::ArrayValue::new(
        VarType::VARIANT,
        vec![
            Value::R4(7.5),
            Value::I4(0xD8),
            Value::Date(stamp.to_ole_date()),
        ],
    ));
    let id = pending(sim.e.write(sim.now, g, &[(h[0], arr)]).unwrap());
    sim.pump();
    let Some(SourceRequest::WriteVqt { req_id, items }) = sim.io.pop() else {
        panic!("{:?}", sim.io)
    };
    assert_eq!(items[0].1.value, Value::R8(7.5));
    assert_eq!(items[0].1.quality, Some(Quality::GOOD_LOCAL_OVERRIDE));
    assert_eq!(
        items[0].1.timestamp.map(|t| t.unix_millis()),
        Some(stamp.unix_millis())
    );
    sim.e
        .handle_source_write_result(sim.now, req_id, vec![Ok(())]);
    assert_eq!(
        sim.e.take_sync_result(id),
        Some(SyncResult::Write(vec![Ok(())]))
    );
}

#[test]
fn write_vqt_passes_quality_and_timestamp_and_source_may_refuse() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "A2"]);
    let vqt = ItemVqt {
        value: Value::R8(1.0),
        quality: Some(Quality::UNCERTAIN),
        timestamp: None,
    };
    let id = pending(
        sim.e
            .write_vqt(
                sim.now,
                g,
                &[(h[0], vqt.clone()), (h[1], ItemVqt::value(Value::R8(2.0)))],
            )
            .unwrap(),
    );
    sim.pump();
    let Some(SourceRequest::WriteVqt { req_id, items }) = sim.io.pop() else {
        panic!()
    };
    assert_eq!(items[0].1, vqt);
    assert_eq!(
        items[1].1,
        ItemVqt::value(Value::R8(2.0)),
        "plain values travel with no quality/timestamp"
    );
    sim.e
        .handle_source_write_result(sim.now, req_id, vec![Err(OpcError::NotSupported)]);
    assert_eq!(
        sim.e.take_sync_result(id),
        Some(SyncResult::Write(vec![
            Err(OpcError::NotSupported),
            Err(OpcError::Fail)
        ])),
        "missing results are E_FAIL"
    );
}

#[test]
fn async_calls_without_callback_are_noconnection() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim
        .e
        .add_group(sim.now, s, &GroupParams::default())
        .unwrap()
        .group;
    let h = sim.items(g, &["A1"]);
    let now = sim.now;
    assert_eq!(sim.e.async_read(now, g, 1, &h), Err(OpcError::NoConnection));
    assert_eq!(
        sim.e.async_read_max_age(now, g, 1, &[(h[0], 0)]),
        Err(OpcError::NoConnection)
    );
    assert_eq!(
        sim.e.async_write(now, g, 1, &[(h[0], Value::R8(1.0))]),
        Err(OpcError::NoConnection)
    );
    assert_eq!(
        sim.e
            .async_write_vqt(now, g, 1, &[(h[0], ItemVqt::value(Value::R8(1.0)))]),
        Err(OpcError::NoConnection)
    );
    assert_eq!(
        sim.e.refresh2(now, g, DataSource::Cache, 1),
        Err(OpcError::NoConnection)
    );
    assert_eq!(
        sim.e.refresh_max_age(now, g, 0, 1),
        Err(OpcError::NoConnection)
    );
    assert_eq!(sim.e.cancel2(g, 1), Err(OpcError::NoConnection));
}

#[test]
fn refresh2_sends_all_active_items_even_unchanged_with_transaction_id() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "A2", "A3"]);
    sim.e.set_active_state(sim.now, g, &[h[2]], false).unwrap();
    sim.push_good("A1", 1.0);
    sim.push_good("A2", 2.0);
    sim.tick();
    sim.events();
    let cancel = sim.e.refresh2(sim.now, g, DataSource::Cache, 4321).unwrap();
    assert_ne!(cancel, 0);
    let ev = sim.events();
    let [Event::DataChange(d)] = &ev[..] else {
        panic!("{ev:?}")
    };
    assert_eq!(
        (d.kind, d.transaction_id, d.cancel_id, d.client_group),
        (DataChangeKind::Refresh, 4321, cancel, 7)
    );
    assert_eq!(
        values(d),
        vec![(100, Value::R8(1.0)), (101, Value::R8(2.0))],
        "active items only, unchanged too"
    );
}

#[test]
fn refresh2_fails_for_inactive_group_or_no_active_items() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    assert_eq!(
        sim.e.refresh2(sim.now, g, DataSource::Cache, 1),
        Err(OpcError::Fail),
        "no items"
    );
    let h = sim.items(g, &["A1"]);
    sim.e.set_active_state(sim.now, g, &h, false).unwrap();
    assert_eq!(
        sim.e.refresh2(sim.now, g, DataSource::Device, 1),
        Err(OpcError::Fail),
        "no active items"
    );
    sim.e.set_active_state(sim.now, g, &h, true).unwrap();
    sim.e
        .set_group_state(
            sim.now,
            g,
            &SetGroupState {
                active: Some(false),
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(
        sim.e.refresh2(sim.now, g, DataSource::Cache, 1),
        Err(OpcError::Fail),
        "inactive group"
    );
    assert_eq!(
        sim.e.refresh_max_age(sim.now, g, 1000, 1),
        Err(OpcError::Fail)
    );
}

#[test]
fn refresh_values_become_last_sent() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 1.0);
    sim.tick();
    sim.events();
    sim.advance(500);
    sim.push_good("A1", 2.0);
    sim.e.refresh2(sim.now, g, DataSource::Cache, 1).unwrap();
    assert_eq!(sim.events().len(), 1);
    sim.advance(500);
    assert!(
        sim.data_changes().is_empty(),
        "the change went out with the refresh, not again"
    );
}

#[test]
fn refresh2_from_device_waits_for_the_source() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1", "CONST"]);
    sim.tick();
    sim.events();
    let cancel = sim.e.refresh2(sim.now, g, DataSource::Device, 8).unwrap();
    assert!(sim.events().is_empty());
    let (req, items) = sim.take_read();
    assert_eq!(items.len(), 1);
    sim.e
        .handle_source_read_result(sim.now, req, vec![Err(OpcError::NetAnswerTimeout)]);
    let ev = sim.events();
    let [Event::DataChange(d)] = &ev[..] else {
        panic!("{ev:?}")
    };
    assert_eq!(
        (d.transaction_id, d.cancel_id, d.master_error),
        (8, cancel, Some(OpcError::False))
    );
    assert_eq!(d.items[0].error, Some(OpcError::NetAnswerTimeout));
    assert_eq!(d.items[1].value, Value::R8(42.0));
}

#[test]
fn refresh_max_age_reads_stale_items_from_the_device() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1", "A2"]);
    sim.push_good("A1", 1.0);
    sim.advance(2000);
    sim.push_good("A2", 2.0);
    sim.events();
    sim.e.refresh_max_age(sim.now, g, 1000, 5).unwrap();
    let (req, items) = sim.take_read();
    assert_eq!(
        items.iter().map(|i| &*i.item_id).collect::<Vec<_>>(),
        vec!["A1"]
    );
    sim.e
        .handle_source_read_result(sim.now, req, vec![good(1.5, sim.now)]);
    let ev = sim.events();
    let [Event::DataChange(d)] = &ev[..] else {
        panic!("{ev:?}")
    };
    assert_eq!(
        values(d),
        vec![(100, Value::R8(1.5)), (101, Value::R8(2.0))]
    );
}

#[test]
fn async_read_completes_with_read_complete_and_excludes_invalid_handles() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "A2"]);
    sim.e.set_active_state(sim.now, g, &[h[1]], false).unwrap();
    sim.tick();
    sim.events();
    let started = sim.e.async_read(sim.now, g, 77, &[h[0], 5, h[1]]).unwrap();
    assert_ne!(started.cancel_id, 0);
    assert_eq!(
        started.results,
        vec![Ok(()), Err(OpcError::InvalidHandle), Ok(())]
    );
    let (req, items) = sim.take_read();
    assert_eq!(
        items.len(),
        2,
        "async Read reads inactive items from the device too"
    );
    sim.e
        .handle_source_read_result(sim.now, req, vec![good(1.0, sim.now), good(2.0, sim.now)]);
    let ev = sim.events();
    let [Event::ReadComplete(r)] = &ev[..] else {
        panic!("{ev:?}")
    };
    assert_eq!(
        (
            r.transaction_id,
            r.cancel_id,
            r.client_group,
            r.master_quality,
            r.master_error
        ),
        (77, started.cancel_id, 7, None, None)
    );
    assert_eq!(
        r.items
            .iter()
            .map(|i| (i.client_handle, i.value.clone()))
            .collect::<Vec<_>>(),
        vec![(100, Value::R8(1.0)), (101, Value::R8(2.0))]
    );
    // Only invalid handles: nothing queued, no callback.
    let none = sim.e.async_read(sim.now, g, 78, &[5]).unwrap();
    assert_eq!(
        none,
        AsyncStarted {
            cancel_id: 0,
            results: vec![Err(OpcError::InvalidHandle)]
        }
    );
    sim.pump();
    assert!(sim.io.is_empty() && sim.events().is_empty());
}

#[test]
fn async_read_max_age_from_cache_completes_at_once() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    sim.push_good("A1", 3.0);
    sim.tick();
    sim.events();
    let started = sim
        .e
        .async_read_max_age(sim.now, g, 9, &[(h[0], MAX_AGE_CACHE)])
        .unwrap();
    let ev = sim.events();
    assert!(
        matches!(&ev[..], [Event::ReadComplete(r)] if r.cancel_id == started.cancel_id && r.items[0].value == Value::R8(3.0))
    );
}

#[test]
fn async_write_completes_with_source_errors_per_item() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "RO", "A2"]);
    let started = sim
        .e
        .async_write(
            sim.now,
            g,
            55,
            &[
                (h[0], Value::R8(1.0)),
                (h[1], Value::R8(1.0)),
                (h[2], Value::R8(2.0)),
            ],
        )
        .unwrap();
    assert_eq!(
        started.results,
        vec![Ok(()), Err(OpcError::BadRights), Ok(())]
    );
    sim.pump();
    let Some(SourceRequest::Write { req_id, items }) = sim.io.pop() else {
        panic!()
    };
    assert_eq!(items.len(), 2);
    sim.e
        .handle_source_write_result(sim.now, req_id, vec![Ok(()), Err(OpcError::WriteError)]);
    let ev = sim.events();
    let [Event::WriteComplete(w)] = &ev[..] else {
        panic!("{ev:?}")
    };
    assert_eq!(
        (w.transaction_id, w.cancel_id, w.master_error),
        (55, started.cancel_id, Some(OpcError::False))
    );
    assert_eq!(
        w.items,
        vec![
            WriteResult {
                client_handle: 100,
                error: None
            },
            WriteResult {
                client_handle: 102,
                error: Some(OpcError::WriteError)
            }
        ]
    );
}

#[test]
fn cancel2_of_pending_transaction_sends_cancel_complete() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    sim.tick();
    sim.events();
    let started = sim.e.async_read(sim.now, g, 3, &h).unwrap();
    let (req, _) = sim.take_read();
    assert_eq!(sim.e.cancel2(g, started.cancel_id), Ok(()));
    let ev = sim.events();
    assert_eq!(
        ev,
        vec![Event::CancelComplete(CancelComplete {
            session: s,
            group: g,
            client_group: 7,
            transaction_id: 3,
            cancel_id: started.cancel_id
        })]
    );
    // The source's late answer produces no callback.
    sim.e
        .handle_source_read_result(sim.now, req, vec![good(1.0, sim.now)]);
    assert!(sim.events().is_empty());
    assert_eq!(sim.e.cancel2(g, started.cancel_id), Err(OpcError::Fail));
}

#[test]
fn cancel2_of_queued_completion_replaces_it_until_delivered() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 1.0);
    sim.tick();
    sim.events();
    let cancel = sim.e.refresh2(sim.now, g, DataSource::Cache, 12).unwrap();
    assert_eq!(sim.e.cancel2(g, cancel), Ok(()));
    let ev = sim.events();
    assert!(
        matches!(&ev[..], [Event::CancelComplete(c)] if c.transaction_id == 12 && c.cancel_id == cancel)
    );
    // The cancelled refresh did not count as sent.
    sim.advance(1000);
    assert_eq!(sim.data_changes().len(), 1);
}

#[test]
fn cancel2_of_completed_transaction_fails() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    sim.tick();
    sim.events();
    let cancel = sim.e.refresh2(sim.now, g, DataSource::Cache, 1).unwrap();
    assert_eq!(sim.events().len(), 1, "delivered");
    assert_eq!(sim.e.cancel2(g, cancel), Err(OpcError::Fail));
    assert_eq!(
        sim.e.cancel2(g, 0xDEAD),
        Err(OpcError::Fail),
        "unknown cancel ID"
    );
}

#[test]
fn cancel2_of_another_groups_transaction_fails() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g1 = sim.group(s, "g1", 1000, 0.0);
    let g2 = sim.group(s, "g2", 1000, 0.0);
    let h = sim.items(g1, &["A1"]);
    let started = sim.e.async_read(sim.now, g1, 1, &h).unwrap();
    assert_eq!(sim.e.cancel2(g2, started.cancel_id), Err(OpcError::Fail));
}

#[test]
fn outstanding_transactions_are_bounded_with_adviselimit() {
    let mut sim = Sim::with_config(EngineConfig {
        max_transactions_per_group: 3,
        ..Default::default()
    });
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let other = sim.group(s, "other", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    let ho = sim.items(other, &["A1"]);
    let ids: Vec<u32> = (0..3)
        .map(|t| sim.e.async_read(sim.now, g, t, &h).unwrap().cancel_id)
        .collect();
    let mut uniq = ids.clone();
    uniq.dedup();
    assert_eq!(uniq.len(), 3, "cancel IDs are unique");
    assert_eq!(
        sim.e.async_read(sim.now, g, 9, &h),
        Err(OpcError::AdviseLimit)
    );
    assert_eq!(
        sim.e.refresh2(sim.now, g, DataSource::Cache, 9),
        Err(OpcError::AdviseLimit)
    );
    assert!(
        sim.e.async_read(sim.now, other, 9, &ho).is_ok(),
        "the limit is per group"
    );
    // A completion taken with poll_event frees a place.
    let (req, _) = sim.take_read();
    let _ = req;
    let first = sim.io.iter().find_map(|r| match r {
        SourceRequest::Read { req_id, .. } => Some(*req_id),
        _ => None,
    });
    sim.e
        .handle_source_read_result(sim.now, first.unwrap(), vec![good(1.0, sim.now)]);
    assert_eq!(
        sim.e.async_read(sim.now, g, 9, &h),
        Err(OpcError::AdviseLimit),
        "completed but not yet delivered"
    );
    sim.events();
    assert!(sim.e.async_read(sim.now, g, 9, &h).is_ok());
}

#[test]
fn removing_a_group_drops_its_pending_transactions_and_callbacks() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    sim.push_good("A1", 1.0);
    sim.tick();
    sim.e.async_read(sim.now, g, 1, &h).unwrap();
    let (req, _) = sim.take_read();
    sim.e.remove_group(sim.now, s, g, true).unwrap();
    assert!(
        sim.events().is_empty(),
        "queued callbacks of a removed group are dropped"
    );
    sim.e
        .handle_source_read_result(sim.now, req, vec![good(1.0, sim.now)]);
    assert!(sim.events().is_empty());
    assert_eq!(sim.e.stats().pending_transactions, 0);
}

#[test]
fn async_transaction_times_out_per_item() {
    let mut sim = Sim::with_config(EngineConfig {
        source_timeout_ms: 2000,
        ..Default::default()
    });
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    sim.tick();
    sim.events();
    sim.e
        .async_write(sim.now, g, 4, &[(h[0], Value::R8(3.0))])
        .unwrap();
    sim.advance(2000);
    let ev = sim.events();
    assert!(
        matches!(&ev[..], [Event::WriteComplete(w)] if w.items[0].error == Some(OpcError::NetAnswerTimeout)),
        "{ev:?}"
    );
}

#[test]
fn sync_read_survives_group_removal() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    let id = pending(sim.e.read(sim.now, g, DataSource::Device, &h).unwrap());
    let (req, _) = sim.take_read();
    sim.e.remove_group(sim.now, s, g, true).unwrap();
    sim.e
        .handle_source_read_result(sim.now, req, vec![good(4.0, sim.now)]);
    let Some(SyncResult::Read(r)) = sim.e.take_sync_result(id) else {
        panic!()
    };
    assert_eq!(r[0].as_ref().unwrap().value, Value::R8(4.0));
}

#[test]
fn item_io_read_resolves_ids_and_releases_the_cache_afterwards() {
    let mut sim = Sim::new();
    let s = sim.session();
    let r = sim
        .e
        .item_io_read(sim.now, s, &[("CONST", 0), ("NOPE", 0), ("bad id", 0)])
        .unwrap();
    let r = ready(r);
    assert_eq!(r[0].as_ref().unwrap().value, Value::R8(42.0));
    assert_eq!(
        (r[1].clone().err(), r[2].clone().err()),
        (Some(OpcError::UnknownItemId), Some(OpcError::InvalidItemId))
    );
    let id = pending(
        sim.e
            .item_io_read(sim.now, s, &[("A1", MAX_AGE_DEVICE), ("A1", MAX_AGE_CACHE)])
            .unwrap(),
    );
    let (req, items) = sim.take_read();
    assert_eq!(items.len(), 1);
    sim.e
        .handle_source_read_result(sim.now, req, vec![good(8.0, sim.now)]);
    let Some(SyncResult::Read(r)) = sim.e.take_sync_result(id) else {
        panic!()
    };
    assert_eq!(r[0].as_ref().unwrap().value, Value::R8(8.0));
    assert_eq!(
        r[1].as_ref().unwrap().quality,
        Quality::BAD_WAITING_FOR_INITIAL_DATA,
        "the cache as it was at the call"
    );
    sim.pump();
    assert_eq!(
        sim.e.stats().source_items,
        0,
        "no group refers to the items: the cache entries are gone"
    );
    assert!(sim.sub_log.is_empty(), "IOPCItemIO never subscribes");
}

#[test]
fn item_io_write_vqt_checks_rights_and_converts() {
    let mut sim = Sim::new();
    let s = sim.session();
    let id = pending(
        sim.e
            .item_io_write_vqt(
                sim.now,
                s,
                &[
                    ("A1", ItemVqt::value(Value::I2(3))),
                    ("RO", ItemVqt::value(Value::R8(1.0))),
                    ("NOPE", ItemVqt::value(Value::R8(1.0))),
                ],
            )
            .unwrap(),
    );
    sim.pump();
    let Some(SourceRequest::Write { req_id, items }) = sim.io.pop() else {
        panic!("{:?}", sim.io)
    };
    assert_eq!(
        items
            .iter()
            .map(|(i, v)| (&*i.item_id, v.clone()))
            .collect::<Vec<_>>(),
        vec![("A1", Value::R8(3.0))]
    );
    sim.e
        .handle_source_write_result(sim.now, req_id, vec![Ok(())]);
    assert_eq!(
        sim.e.take_sync_result(id),
        Some(SyncResult::Write(vec![
            Ok(()),
            Err(OpcError::BadRights),
            Err(OpcError::UnknownItemId)
        ]))
    );
    assert_eq!(
        sim.e.item_io_read(sim.now, s, &[]),
        Err(OpcError::InvalidArg)
    );
}

#[test]
fn async_read_source_cache_answers_at_once_and_device_asks_the_source() {
    // IOPCAsyncIO::Read (DA 1.0a): OPC_DS_CACHE from the cache, an inactive item BAD Out
    // of Service as IOPCSyncIO::Read; OPC_DS_DEVICE as IOPCAsyncIO2::Read.
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "A2"]);
    sim.push_good("A1", 3.0);
    sim.tick();
    sim.events();
    sim.e.set_active_state(sim.now, g, &[h[1]], false).unwrap();
    let started = sim
        .e
        .async_read_source(sim.now, g, 0, DataSource::Cache, &[h[0], 5, h[1]])
        .unwrap();
    assert_eq!(
        started.results,
        vec![Ok(()), Err(OpcError::InvalidHandle), Ok(())]
    );
    let ev = sim.events();
    let [Event::ReadComplete(r)] = &ev[..] else {
        panic!("{ev:?}")
    };
    assert_eq!((r.cancel_id, r.transaction_id), (started.cancel_id, 0));
    assert_eq!(r.items[0].value, Value::R8(3.0));
    assert_eq!(r.items[1].quality, Quality::BAD_OUT_OF_SERVICE);
    let started = sim
        .e
        .async_read_source(sim.now, g, 0, DataSource::Device, &h)
        .unwrap();
    assert_ne!(started.cancel_id, 0);
    let (_, items) = sim.take_read();
    assert_eq!(items.len(), 2, "both from the device");
}
