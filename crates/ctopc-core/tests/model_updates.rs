//! Server model: change detection, deadband, the update scheduler, keep-alive and the
//! subscription counting towards the data source.

mod model_util;

use ctopc_core::model::*;
use ctopc_core::{OpcError, Quality, Timestamp, Value, VarType, Vqt};
use model_util::*;
use proptest::prelude::*;

#[test]
fn first_update_sends_all_active_items_then_only_changes() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1", "A2"]);
    sim.push_good("A1", 1.0);
    sim.push_good("A2", 2.0);
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(dc.len(), 1);
    assert_eq!(
        values(&dc[0]),
        vec![(100, Value::R8(1.0)), (101, Value::R8(2.0))]
    );
    assert_eq!(
        (
            dc[0].transaction_id,
            dc[0].client_group,
            dc[0].master_quality,
            dc[0].master_error
        ),
        (0, 7, None, None)
    );
    // Nothing changed: no callback at the next ticks.
    sim.push_good("A1", 1.0);
    sim.advance(2000);
    assert!(sim.data_changes().is_empty());
    sim.push_good("A2", 2.5);
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(dc.len(), 1);
    assert_eq!(values(&dc[0]), vec![(101, Value::R8(2.5))]);
}

/// The first OnDataChange of a new item waits (bounded) for its first sample from
/// the source, and goes as soon as it arrives, not at the next tick.
#[test]
fn the_first_callback_waits_for_the_first_sample_and_goes_when_it_arrives() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1", "A2"]);
    sim.tick();
    assert!(
        sim.data_changes().is_empty(),
        "held: no placeholder callback"
    );
    sim.advance(300);
    assert!(sim.data_changes().is_empty());
    sim.push_good("A1", 3.0);
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(dc.len(), 1, "at once, 300 ms after the tick");
    assert_eq!(values(&dc[0]), vec![(100, Value::R8(3.0))]);
    assert_eq!(
        (dc[0].items[0].quality, dc[0].master_quality),
        (Quality::GOOD, None)
    );
    // A2 is still held; A1's changes keep the update rate.
    sim.push_good("A1", 4.0);
    sim.advance(100);
    assert!(sim.data_changes().is_empty(), "a change waits for the tick");
    sim.push_good("A2", 5.0);
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(
        values(&dc[0]),
        vec![(101, Value::R8(5.0))],
        "A2 at once, alone"
    );
    sim.advance(600);
    let dc = sim.data_changes();
    assert_eq!(
        values(&dc[0]),
        vec![(100, Value::R8(4.0))],
        "A1 at its tick"
    );
}

/// Items still without data when the wait ends go as they are (BAD Waiting for Initial
/// Data); the real value follows as a change. Items with data are never held.
#[test]
fn items_without_data_at_the_bound_go_as_they_are() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1", "CONST"]);
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(
        values(&dc[0]),
        vec![(101, Value::R8(42.0))],
        "the constant at once"
    );
    sim.advance(u64::from(DEFAULT_FIRST_SAMPLE_WAIT_MS) - 1);
    assert!(sim.data_changes().is_empty(), "A1 held until the bound");
    sim.advance(1);
    let dc = sim.data_changes();
    assert_eq!(dc.len(), 1, "at the bound, between ticks");
    assert_eq!(
        dc[0].items[0].quality,
        Quality::BAD_WAITING_FOR_INITIAL_DATA
    );
    assert_eq!(dc[0].master_quality, Some(OpcError::False));
    sim.push_good("A1", 3.0);
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(
        (dc[0].items[0].quality, dc[0].master_quality),
        (Quality::GOOD, None)
    );
}

/// Refresh2 and cache reads in the window answer from the cache, as DA defines them: a
/// held item is BAD Waiting for Initial Data there; the refresh counts as its first report.
#[test]
fn refresh_and_cache_reads_in_the_window_answer_from_the_cache() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    sim.tick();
    assert!(sim.data_changes().is_empty());
    let SyncOutcome::Ready(r) = sim.e.read(sim.now, g, DataSource::Cache, &h).unwrap() else {
        panic!("a cache read answers at once")
    };
    assert_eq!(
        r[0].as_ref().unwrap().quality,
        Quality::BAD_WAITING_FOR_INITIAL_DATA
    );
    sim.e.refresh2(sim.now, g, DataSource::Cache, 9).unwrap();
    let refreshed: Vec<DataChange> = sim
        .events()
        .into_iter()
        .filter_map(|e| match e {
            Event::DataChange(d) if d.kind == DataChangeKind::Refresh => Some(d),
            _ => None,
        })
        .collect();
    assert_eq!(
        refreshed[0].items[0].quality,
        Quality::BAD_WAITING_FOR_INITIAL_DATA
    );
    // Sent by the refresh: not held any more; its value follows as a change at the tick.
    sim.push_good("A1", 1.0);
    sim.tick();
    assert!(sim.data_changes().is_empty());
    sim.advance(1000);
    assert_eq!(values(&sim.data_changes()[0]), vec![(100, Value::R8(1.0))]);
}

/// `first_sample_wait_ms = 0`: no wait, the placeholder goes at once.
#[test]
fn without_a_wait_items_waiting_for_initial_data_report_bad_waiting_quality() {
    let mut sim = Sim::with_config(EngineConfig {
        first_sample_wait_ms: 0,
        ..EngineConfig::default()
    });
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(
        dc[0].items[0].quality,
        Quality::BAD_WAITING_FOR_INITIAL_DATA
    );
    assert_eq!(dc[0].master_quality, Some(OpcError::False));
    sim.push_good("A1", 3.0);
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(
        (dc[0].items[0].quality, dc[0].master_quality),
        (Quality::GOOD, None)
    );
}

#[test]
fn updates_are_sent_at_most_once_per_update_rate() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 2000, 0.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 0.0);
    sim.tick();
    assert_eq!(sim.data_changes().len(), 1);
    let start = sim.now;
    let mut callbacks = Vec::new();
    for i in 1..=40 {
        sim.advance(100);
        sim.push_good("A1", i as f64);
        for d in sim.data_changes() {
            callbacks.push((sim.now.millis_since(start), d.items[0].value.clone()));
        }
    }
    // Ticks at 2000, 4000: each sends the value as it is at the tick (sampled, not queued).
    let times: Vec<u64> = callbacks.iter().map(|c| c.0).collect();
    assert_eq!(times, vec![2000, 4000]);
    assert_eq!(callbacks[0].1, Value::R8(19.0));
}

#[test]
fn late_handle_timeout_skips_missed_periods() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    sim.tick();
    sim.events();
    let t0 = sim.now;
    assert_eq!(sim.e.poll_timeout(), Some(t0.add_millis(1000)));
    // The driver oversleeps by 3.5 periods: one update, then the phase is kept.
    sim.push_good("A1", 5.0);
    sim.e.handle_timeout(t0.add_millis(4500));
    assert_eq!(sim.data_changes().len(), 1);
    assert_eq!(sim.e.poll_timeout(), Some(t0.add_millis(5000)));
}

#[test]
fn deadband_suppresses_change_within_percent_of_eu_range() {
    let mut sim = Sim::new();
    let s = sim.session();
    // 10 % of EU 0..100 = 10.
    let g = sim.group(s, "g", 1000, 10.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 50.0);
    sim.tick();
    assert_eq!(sim.data_changes().len(), 1);
    // After 60.01 is sent, 50.5 is within 10 of it and 49.0 is not.
    for (v, reported) in [
        (55.0, false),
        (60.0, false),
        (40.0, false),
        (60.01, true),
        (50.5, false),
        (49.0, true),
        (55.0, false),
    ] {
        sim.push_good("A1", v);
        sim.advance(1000);
        let dc = sim.data_changes();
        assert_eq!(!dc.is_empty(), reported, "value {v}");
    }
}

#[test]
fn deadband_compares_against_last_sent_not_last_sample() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 5.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 0.0);
    sim.tick();
    sim.events();
    // Creeping by 2 per tick: each step is within 5, but the third exceeds 5 from the
    // last value sent (0).
    let mut reported = Vec::new();
    for i in 1..=6 {
        sim.push_good("A1", 2.0 * i as f64);
        sim.advance(1000);
        for d in sim.data_changes() {
            reported.push(d.items[0].value.clone());
        }
    }
    assert_eq!(reported, vec![Value::R8(6.0), Value::R8(12.0)]);
}

#[test]
fn item_deadband_overrides_group_deadband() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 50.0);
    let h = sim.items(g, &["A1", "A2"]);
    sim.push_good("A1", 0.0);
    sim.push_good("A2", 0.0);
    sim.tick();
    sim.events();
    sim.e.set_item_deadband(g, &[(h[0], 1.0)]).unwrap();
    sim.push_good("A1", 2.0);
    sim.push_good("A2", 2.0);
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(
        values(&dc[0]),
        vec![(100, Value::R8(2.0))],
        "A1 uses its 1 %, A2 the group's 50 %"
    );
    // Clearing the item deadband: the group's applies again.
    sim.e.clear_item_deadband(g, &[h[0]]).unwrap();
    sim.push_good("A1", 4.0);
    sim.advance(1000);
    assert!(sim.data_changes().is_empty());
    // A lower group deadband lets the pending A2 change through without a new sample.
    sim.e
        .set_group_state(
            sim.now,
            g,
            &SetGroupState {
                percent_deadband: Some(1.0),
                ..Default::default()
            },
        )
        .unwrap();
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(
        values(&dc[0]),
        vec![(100, Value::R8(4.0)), (101, Value::R8(2.0))]
    );
}

#[test]
fn quality_change_is_reported_even_without_value_change() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 50.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 1.0);
    sim.tick();
    sim.events();
    sim.push("A1", Value::R8(1.0), Quality::BAD_COMM_FAILURE);
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(dc[0].items[0].quality, Quality::BAD_COMM_FAILURE);
    assert_eq!(dc[0].master_quality, Some(OpcError::False));
    // Limit bits are part of the quality word.
    sim.push(
        "A1",
        Value::R8(1.0),
        Quality::BAD_COMM_FAILURE.with_limit(Quality::LIMIT_HIGH),
    );
    sim.advance(1000);
    assert_eq!(sim.data_changes().len(), 1);
    // A new timestamp alone is not a change.
    sim.advance(10);
    sim.push(
        "A1",
        Value::R8(1.0),
        Quality::BAD_COMM_FAILURE.with_limit(Quality::LIMIT_HIGH),
    );
    sim.advance(1000);
    assert!(sim.data_changes().is_empty());
}

#[test]
fn non_analog_items_report_any_change_despite_deadband() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 90.0);
    sim.items(g, &["D1", "S1"]);
    sim.push("D1", Value::R4(1.0), Quality::GOOD);
    sim.push("S1", Value::Bstr("a".into()), Quality::GOOD);
    sim.tick();
    sim.events();
    sim.push("D1", Value::R4(1.001), Quality::GOOD);
    sim.push("S1", Value::Bstr("b".into()), Quality::GOOD);
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(
        values(&dc[0]),
        vec![(100, Value::R4(1.001)), (101, Value::Bstr("b".into()))]
    );
    sim.push("S1", Value::Bstr("b".into()), Quality::GOOD);
    sim.advance(1000);
    assert!(
        sim.data_changes().is_empty(),
        "an equal string is no change"
    );
}

/// The last value sent of a string item (kept apart from the item): equal strings are no
/// change, a number after a string and a string after a number are; a removed and re-added
/// item and a clone's items report their value afresh.
#[test]
fn string_values_sent_last_follow_their_items() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["S1", "S2"]);
    let text = |t: &str| Value::Bstr(t.into());
    sim.push("S1", text("a"), Quality::GOOD);
    sim.push("S2", text("b"), Quality::GOOD);
    sim.tick();
    assert_eq!(
        values(&sim.data_changes()[0]),
        vec![(100, text("a")), (101, text("b"))]
    );
    let step = |sim: &mut Sim, id: &str, v: Value| {
        sim.push(id, v, Quality::GOOD);
        sim.advance(1000);
        sim.data_changes().first().map(values).unwrap_or_default()
    };
    assert_eq!(step(&mut sim, "S2", text("b")), vec![]);
    assert_eq!(
        step(&mut sim, "S2", Value::I4(1)),
        vec![(101, Value::I4(1))]
    );
    assert_eq!(step(&mut sim, "S2", Value::I4(1)), vec![]);
    assert_eq!(step(&mut sim, "S2", text("c")), vec![(101, text("c"))]);
    assert_eq!(step(&mut sim, "S2", text("c")), vec![]);
    sim.e.remove_items(sim.now, g, &h[..1]).unwrap();
    sim.items(g, &["S1"]);
    assert_eq!(step(&mut sim, "S1", text("a")), vec![(100, text("a"))]);
    assert_eq!(step(&mut sim, "S1", text("a")), vec![]);
    let c = sim.e.clone_group(sim.now, g, "copy").unwrap();
    sim.e.set_callback_connected(sim.now, c, true).unwrap();
    let active = SetGroupState {
        active: Some(true),
        ..Default::default()
    };
    sim.e.set_group_state(sim.now, c, &active).unwrap();
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(dc.len(), 1, "the clone only");
    let mut v = values(&dc[0]);
    v.sort_by_key(|(c, _)| *c);
    assert_eq!(v, vec![(100, text("a")), (101, text("c"))]);
    assert_eq!(step(&mut sim, "S2", text("c")), vec![]);
}

#[test]
fn inactive_items_are_not_reported_and_reactivated_items_are_resent() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "A2"]);
    sim.push_good("A1", 1.0);
    sim.push_good("A2", 1.0);
    sim.tick();
    sim.events();
    sim.e.set_active_state(sim.now, g, &[h[0]], false).unwrap();
    sim.push_good("A2", 2.0);
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(values(&dc[0]), vec![(101, Value::R8(2.0))]);
    sim.advance(1000);
    assert!(sim.data_changes().is_empty());
    // Reactivated: reported at the next update although unchanged.
    assert_eq!(
        sim.e
            .set_active_state(sim.now, g, &[h[0], 555], true)
            .unwrap(),
        vec![Ok(()), Err(OpcError::InvalidHandle)]
    );
    sim.push_good("A1", 1.0);
    sim.advance(1000);
    let dc = sim.data_changes();
    assert_eq!(values(&dc[0]), vec![(100, Value::R8(1.0))]);
}

#[test]
fn group_activation_resends_all_active_items() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1", "A2"]);
    sim.push_good("A1", 1.0);
    sim.push_good("A2", 2.0);
    sim.tick();
    assert_eq!(sim.data_changes().len(), 1);
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
    sim.pump();
    assert!(
        sim.subscribed.is_empty(),
        "an inactive group does not subscribe"
    );
    sim.advance(5000);
    assert!(
        sim.events().is_empty(),
        "no callbacks for an inactive group"
    );
    assert_eq!(sim.e.poll_timeout(), None);
    sim.e
        .set_group_state(
            sim.now,
            g,
            &SetGroupState {
                active: Some(true),
                ..Default::default()
            },
        )
        .unwrap();
    sim.push_good("A1", 1.0);
    sim.push_good("A2", 2.0);
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(
        values(&dc[0]),
        vec![(100, Value::R8(1.0)), (101, Value::R8(2.0))],
        "all items, unchanged ones too, at once"
    );
}

#[test]
fn disabled_callbacks_suppress_updates_until_enabled() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 1.0);
    sim.tick();
    sim.events();
    assert_eq!(sim.e.get_enable(g), Ok(true));
    sim.e.set_enable(sim.now, g, false).unwrap();
    assert_eq!(sim.e.get_enable(g), Ok(false));
    sim.push_good("A1", 2.0);
    sim.advance(3000);
    assert!(sim.events().is_empty());
    // Refresh still calls back while disabled.
    let cancel = sim.e.refresh2(sim.now, g, DataSource::Cache, 99).unwrap();
    let ev = sim.events();
    assert!(
        matches!(&ev[..], [Event::DataChange(d)] if d.kind == DataChangeKind::Refresh && d.transaction_id == 99 && d.cancel_id == cancel)
    );
    sim.push_good("A1", 3.0);
    sim.e.set_enable(sim.now, g, true).unwrap();
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(
        values(&dc[0]),
        vec![(100, Value::R8(3.0))],
        "changed since the last value sent (by the refresh)"
    );
}

#[test]
fn set_enable_without_callback_is_noconnection() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim
        .e
        .add_group(sim.now, s, &GroupParams::default())
        .unwrap()
        .group;
    assert_eq!(
        sim.e.set_enable(sim.now, g, false),
        Err(OpcError::NoConnection)
    );
    assert_eq!(sim.e.get_enable(g), Err(OpcError::NoConnection));
}

#[test]
fn no_callbacks_without_a_sink_and_a_new_sink_gets_everything() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 1.0);
    sim.tick();
    assert_eq!(sim.data_changes().len(), 1);
    sim.e.set_callback_connected(sim.now, g, false).unwrap();
    sim.advance(5000);
    assert!(sim.events().is_empty());
    sim.e.set_callback_connected(sim.now, g, true).unwrap();
    sim.tick();
    assert_eq!(values(&sim.data_changes()[0]), vec![(100, Value::R8(1.0))]);
}

#[test]
fn values_are_converted_to_the_requested_type() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1", "A2", "D1"]);
    sim.e
        .set_datatypes(
            g,
            &[
                (h[0], VarType::I2),
                (h[1], VarType::BSTR),
                (h[2], VarType::UI1),
            ],
        )
        .unwrap();
    sim.push_good("A1", 2.5);
    sim.push_good("A2", 0.5);
    sim.push("D1", Value::R4(300.0), Quality::GOOD);
    sim.tick();
    let dc = sim.data_changes();
    let items = &dc[0].items;
    assert_eq!(items[0].value, Value::I2(2), "banker's rounding");
    assert_eq!(items[1].value, Value::Bstr("0.5".into()));
    assert_eq!(
        (items[2].value.clone(), items[2].error, items[2].quality),
        (Value::Empty, Some(OpcError::Overflow), Quality::BAD)
    );
    assert_eq!(dc[0].master_error, Some(OpcError::False));
}

#[test]
fn group_lcid_selects_the_string_format() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim
        .e
        .add_group(
            sim.now,
            s,
            &GroupParams {
                lcid: 0x0415,
                ..Default::default()
            },
        )
        .unwrap()
        .group;
    sim.e.set_callback_connected(sim.now, g, true).unwrap();
    let h = sim.items(g, &["A1"]);
    sim.e.set_datatypes(g, &[(h[0], VarType::BSTR)]).unwrap();
    sim.push_good("A1", 1.5);
    sim.tick();
    assert_eq!(
        sim.data_changes()[0].items[0].value,
        Value::Bstr("1,5".into())
    );
}

#[test]
fn keepalive_sends_empty_callback_when_nothing_changed() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 1.0);
    sim.tick();
    sim.events();
    let start = sim.now;
    sim.e.set_keep_alive(sim.now, g, 2500).unwrap();
    let mut log = Vec::new();
    for _ in 0..80 {
        sim.advance(100);
        for e in sim.events() {
            if let Event::DataChange(d) = e {
                log.push((
                    sim.now.millis_since(start),
                    d.kind,
                    d.items.len(),
                    d.transaction_id,
                ));
            }
        }
    }
    assert_eq!(
        log,
        vec![
            (2500, DataChangeKind::KeepAlive, 0, 0),
            (5000, DataChangeKind::KeepAlive, 0, 0),
            (7500, DataChangeKind::KeepAlive, 0, 0)
        ]
    );
}

#[test]
fn keepalive_timer_restarts_after_a_data_callback() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 1.0);
    sim.tick();
    sim.events();
    let start = sim.now;
    sim.e.set_keep_alive(sim.now, g, 3000).unwrap();
    let mut log = Vec::new();
    for step in 1..=90 {
        sim.advance(100);
        if step == 20 {
            sim.push_good("A1", 2.0); // after the 2000 ms tick: reported at 3000 ms
        }
        for e in sim.events() {
            if let Event::DataChange(d) = e {
                log.push((sim.now.millis_since(start), d.kind));
            }
        }
    }
    assert_eq!(
        log,
        vec![
            (3000, DataChangeKind::Subscription),
            (6000, DataChangeKind::KeepAlive),
            (9000, DataChangeKind::KeepAlive)
        ]
    );
}

#[test]
fn keepalive_is_not_sent_for_inactive_or_disabled_groups() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.e.set_keep_alive(sim.now, g, 1000).unwrap();
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
    sim.advance(5000);
    assert!(sim.events().is_empty());
    sim.e
        .set_group_state(
            sim.now,
            g,
            &SetGroupState {
                active: Some(true),
                ..Default::default()
            },
        )
        .unwrap();
    sim.e.set_enable(sim.now, g, false).unwrap();
    sim.advance(5000);
    assert!(sim.events().is_empty());
    sim.e.set_enable(sim.now, g, true).unwrap();
    sim.advance(1000);
    assert!(
        matches!(&sim.events()[..], [Event::DataChange(d)] if d.kind == DataChangeKind::KeepAlive)
    );
}

#[test]
fn constant_items_never_reach_the_source_and_read_good_constant() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["CONST"]);
    sim.pump();
    assert!(sim.sub_log.is_empty(), "no subscription for a constant");
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(dc[0].items[0].value, Value::R8(42.0));
    assert_eq!(
        dc[0].items[0].quality,
        Quality::GOOD.with_limit(Quality::LIMIT_CONST)
    );
    let r = sim.e.read(sim.now, g, DataSource::Device, &h).unwrap();
    let SyncOutcome::Ready(r) = r else {
        panic!("constants answer at once")
    };
    assert_eq!(r[0].as_ref().unwrap().value, Value::R8(42.0));
    sim.pump();
    assert!(sim.io.is_empty(), "no device read for a constant");
    let w = sim.e.write(sim.now, g, &[(h[0], Value::R8(1.0))]).unwrap();
    assert_eq!(w, SyncOutcome::Ready(vec![Err(OpcError::BadRights)]));
}

#[test]
fn first_subscriber_subscribes_last_unsubscribes() {
    let mut sim = Sim::new();
    let s1 = sim.session();
    let s2 = sim.session();
    let g1 = sim.group(s1, "g", 1000, 0.0);
    let g2 = sim.group(s2, "g", 1000, 0.0);
    let h1 = sim.items(g1, &["A1"]);
    assert_eq!(sim.sub_log.len(), 1);
    assert!(
        matches!(&sim.sub_log[0], SourceRequest::Subscribe(v) if v.len() == 1 && &*v[0].item.item_id == "A1" && v[0].sampling_rate_ms == 1000)
    );
    let h2 = sim.items(g2, &["A1", "alias.A1"]);
    let h3 = sim.items(g1, &["A1"]);
    assert_eq!(
        sim.sub_log.len(),
        1,
        "later subscribers do not reach the source"
    );
    sim.e.remove_items(sim.now, g1, &h1).unwrap();
    sim.e.set_active_state(sim.now, g2, &h2, false).unwrap();
    sim.pump();
    assert_eq!(sim.sub_log.len(), 1, "one subscriber is left");
    sim.e.remove_items(sim.now, g1, &h3).unwrap();
    sim.pump();
    assert_eq!(sim.sub_log.len(), 2);
    assert!(matches!(&sim.sub_log[1], SourceRequest::Unsubscribe(v) if v.len() == 1));
    assert!(sim.subscribed.is_empty());
    // The inactive items still hold the cache entry.
    assert_eq!(sim.e.stats().source_items, 1);
    sim.e.set_active_state(sim.now, g2, &h2, true).unwrap();
    sim.pump();
    assert_eq!(sim.subscribed.len(), 1);
}

#[test]
fn subscription_changes_between_polls_are_netted() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let defs = [ItemDefinition {
        item_id: "A1",
        access_path: "",
        active: true,
        client_handle: 1,
        requested_type: VarType::EMPTY,
    }];
    let h: Vec<u32> = sim
        .e
        .add_items(sim.now, g, &defs)
        .unwrap()
        .into_iter()
        .map(|r| r.unwrap().server_handle)
        .collect();
    sim.e.remove_items(sim.now, g, &h).unwrap();
    sim.pump();
    assert!(sim.sub_log.is_empty());
    assert_eq!(sim.e.stats().source_items, 0);
}

#[test]
fn fastest_sampling_rate_is_requested_from_the_source() {
    let mut sim = Sim::new();
    let s = sim.session();
    let slow = sim.group(s, "slow", 5000, 0.0);
    let fast = sim.group(s, "fast", 2000, 0.0);
    let hs = sim.items(slow, &["A1"]);
    assert_eq!(sim.subscribed["A1"], 5000);
    let hf = sim.items(fast, &["A1"]);
    assert_eq!(sim.subscribed["A1"], 2000);
    assert!(
        matches!(sim.sub_log.last(), Some(SourceRequest::SetSamplingRate(v)) if v[0].1 == 2000)
    );
    sim.e
        .set_item_sampling_rate(slow, &[(hs[0], 1000)])
        .unwrap();
    sim.pump();
    assert_eq!(sim.subscribed["A1"], 1000);
    sim.e.clear_item_sampling_rate(slow, &hs).unwrap();
    sim.pump();
    assert_eq!(sim.subscribed["A1"], 2000);
    sim.e
        .set_group_state(
            sim.now,
            fast,
            &SetGroupState {
                update_rate: Some(10_000),
                ..Default::default()
            },
        )
        .unwrap();
    sim.pump();
    assert_eq!(sim.subscribed["A1"], 5000);
    sim.e.remove_items(sim.now, slow, &hs).unwrap();
    sim.pump();
    assert_eq!(sim.subscribed["A1"], 10_000);
    sim.e.remove_items(sim.now, fast, &hf).unwrap();
    sim.pump();
    assert!(sim.subscribed.is_empty());
}

#[test]
fn samples_for_stale_source_keys_are_ignored() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let h = sim.items(g, &["A1"]);
    let old = sim.keys["A1"];
    sim.e.remove_items(sim.now, g, &h).unwrap();
    sim.pump();
    sim.items(g, &["A2"]);
    let new = sim.keys["A2"];
    assert_eq!(old.index(), new.index(), "the slot is reused");
    assert_ne!(old, new, "with a new generation");
    sim.tick();
    sim.events();
    sim.e.handle_source_updates(
        sim.now,
        [(old, Vqt::new(Value::R8(666.0), Quality::GOOD, sim.now))],
    );
    sim.advance(1000);
    assert!(
        sim.data_changes().is_empty(),
        "the late sample of A1 does not land in A2"
    );
    assert!(sim.e.source_item(old).is_none());
    assert_eq!(&*sim.e.source_item(new).unwrap().item_id, "A2");
}

#[test]
fn one_cache_entry_serves_many_groups() {
    let mut sim = Sim::new();
    let s = sim.session();
    let groups: Vec<GroupHandle> = (0..3)
        .map(|i| sim.group(s, &format!("g{i}"), 1000, 0.0))
        .collect();
    for g in &groups {
        sim.items(*g, &["A1"]);
    }
    assert_eq!(sim.e.stats().source_items, 1);
    assert_eq!(sim.e.stats().group_items, 3);
    sim.push_good("A1", 9.0);
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(dc.len(), 3);
    assert!(dc.iter().all(|d| d.items[0].value == Value::R8(9.0)));
    let gs: Vec<GroupHandle> = dc.iter().map(|d| d.group).collect();
    assert_eq!(gs.len(), 3);
    assert!(groups.iter().all(|g| gs.contains(g)));
}

#[test]
fn last_update_time_follows_data_callbacks() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    assert_eq!(sim.e.last_update_time(s), Ok(Timestamp(0)));
    sim.items(g, &["A1"]);
    sim.push_good("A1", 1.0);
    sim.advance(1000);
    assert!(sim.e.last_update_time(s).unwrap() > Timestamp(0));
}

// The deadband rule through the whole engine: for any sequence of samples, each reported
// value differs from the previously reported one by more than the band, and each value
// present at a tick but not reported is within the band of the last reported one.
proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn engine_reports_exactly_the_changes_beyond_the_deadband(
        deadband in 0.0f32..=40.0,
        samples in proptest::collection::vec(-20.0f64..120.0, 1..40),
    ) {
        let mut sim = Sim::new();
        let s = sim.session();
        let g = sim.group(s, "g", 1000, deadband);
        sim.items(g, &["A1"]);
        let threshold = 100.0 * f64::from(deadband) / 100.0;
        let mut last_sent: Option<f64> = None;
        for v in samples {
            sim.push_good("A1", v);
            sim.advance(1000);
            let dc = sim.data_changes();
            let reported = dc.iter().flat_map(|d| d.items.iter()).map(|i| i.value.clone()).next_back();
            match (last_sent, reported) {
                (None, Some(Value::R8(x))) => { prop_assert_eq!(x, v); last_sent = Some(x); }
                (Some(prev), Some(Value::R8(x))) => {
                    prop_assert_eq!(x, v);
                    prop_assert!((x - prev).abs() > threshold || (deadband == 0.0 && x != prev));
                    last_sent = Some(x);
                }
                (Some(prev), None) => prop_assert!((v - prev).abs() <= threshold || (deadband == 0.0 && v == prev)),
                (None, None) => {
                    // The first tick already reported the initial (waiting) state.
                    last_sent = None;
                }
                (_, other) => prop_assert!(false, "unexpected {:?}", other),
            }
        }
    }
}

/// An engine whose subscription callbacks wait for their delivery, one at a time.
fn paced() -> Sim {
    Sim::with_config(EngineConfig {
        max_pending_data_changes: 1,
        ..EngineConfig::default()
    })
}

/// A paced engine with a 1 s group of one item, A1 (client handle 100), whose first
/// OnDataChange (A1 = 1.0) was just produced and is still being delivered.
fn paced_group_with_a_callback_under_way() -> (Sim, SessionHandle, GroupHandle) {
    let mut sim = paced();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    sim.push_good("A1", 1.0);
    sim.tick();
    assert_eq!(sim.data_changes().len(), 1);
    (sim, s, g)
}

#[test]
fn paced_callbacks_coalesce_while_the_client_is_busy_and_resume_when_it_returns() {
    let mut sim = paced();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1", "A2"]);
    sim.push_good("A1", 1.0);
    sim.push_good("A2", 2.0);
    sim.tick();
    assert_eq!(sim.data_changes().len(), 1);
    let start = sim.now;
    // The client takes 3.5 update periods over that callback; the values keep changing.
    for i in 1..=35 {
        sim.advance(100);
        sim.push_good("A1", 1.0 + f64::from(i));
        assert!(
            sim.data_changes().is_empty(),
            "nothing is queued while the callback is delivered"
        );
    }
    sim.push_good("A2", 2.5);
    sim.e.data_change_delivered(sim.now, g);
    sim.tick();
    // One callback at once, with the latest values only (no backlog of the missed updates).
    let dc = sim.data_changes();
    assert_eq!(dc.len(), 1);
    assert_eq!(
        values(&dc[0]),
        vec![(100, Value::R8(36.0)), (101, Value::R8(2.5))]
    );
    assert_eq!(sim.now.millis_since(start), 3500);
    // Delivered at once this time: the next update keeps the update rate from then on.
    sim.e.data_change_delivered(sim.now, g);
    sim.push_good("A1", 40.0);
    sim.advance(999);
    assert!(
        sim.data_changes().is_empty(),
        "no callback sooner than the update rate"
    );
    sim.advance(1);
    assert_eq!(values(&sim.data_changes()[0]), vec![(100, Value::R8(40.0))]);
}

#[test]
fn paced_callbacks_wait_for_the_next_tick_when_the_delivery_was_quick() {
    let (mut sim, _, g) = paced_group_with_a_callback_under_way();
    sim.advance(300);
    sim.push_good("A1", 2.0);
    sim.e.data_change_delivered(sim.now, g);
    sim.tick();
    assert!(
        sim.data_changes().is_empty(),
        "an early return does not bring the update forward"
    );
    sim.advance(700);
    assert_eq!(values(&sim.data_changes()[0]), vec![(100, Value::R8(2.0))]);
}

#[test]
fn paced_keepalive_is_not_sent_while_a_callback_is_under_way() {
    let (mut sim, _, g) = paced_group_with_a_callback_under_way();
    sim.e.set_keep_alive(sim.now, g, 2000).unwrap();
    // The data callback is never acknowledged: no keep-alive piles up behind it.
    sim.advance(10_000);
    assert!(sim.events().is_empty());
    // Once it returns, keep-alives resume, one at a time, each after the previous returned.
    sim.e.data_change_delivered(sim.now, g);
    let start = sim.now;
    let mut log = Vec::new();
    for _ in 0..60 {
        sim.advance(100);
        for e in sim.events() {
            if let Event::DataChange(d) = e {
                log.push((sim.now.millis_since(start), d.kind));
                sim.e.data_change_delivered(sim.now, g);
            }
        }
    }
    assert_eq!(
        log,
        vec![
            (2000, DataChangeKind::KeepAlive),
            (4000, DataChangeKind::KeepAlive),
            (6000, DataChangeKind::KeepAlive)
        ]
    );
}

#[test]
fn paced_acknowledgements_of_unknown_or_removed_groups_are_ignored() {
    let (mut sim, s, g) = paced_group_with_a_callback_under_way();
    sim.e.data_change_delivered(sim.now, GroupHandle(9999));
    sim.advance(1000);
    sim.push_good("A1", 2.0);
    sim.advance(1000);
    assert!(
        sim.data_changes().is_empty(),
        "another group's acknowledgement does not release this one"
    );
    sim.e.remove_group(sim.now, s, g, true).unwrap();
    sim.e.data_change_delivered(sim.now, g);
    sim.advance(2000);
    assert!(sim.events().is_empty());
}

#[test]
fn unpaced_engine_sends_at_every_update_without_acknowledgements() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    let mut n = 0;
    for i in 0..5 {
        sim.push_good("A1", f64::from(i));
        sim.advance(1000);
        n += sim.data_changes().len();
    }
    assert_eq!(n, 5);
}

#[test]
fn paced_with_two_pending_prepares_the_next_callback_while_one_travels() {
    let mut sim = Sim::with_config(EngineConfig {
        max_pending_data_changes: SERVER_PENDING_DATA_CHANGES,
        ..EngineConfig::default()
    });
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1"]);
    let mut sent = Vec::new();
    for i in 0..6 {
        sim.push_good("A1", f64::from(i));
        sim.advance(1000);
        sent.extend(sim.data_changes().iter().map(|d| values(d)[0].1.clone()));
    }
    // Nothing acknowledged: two callbacks were produced, then nothing more.
    assert_eq!(sent, vec![Value::R8(0.0), Value::R8(1.0)]);
    // One returns: the missed update at once, with the latest value.
    sim.push_good("A1", 9.0);
    sim.e.data_change_delivered(sim.now, g);
    sim.tick();
    assert_eq!(values(&sim.data_changes()[0]), vec![(100, Value::R8(9.0))]);
    sim.push_good("A1", 10.0);
    sim.advance(1000);
    assert!(sim.data_changes().is_empty(), "two under way again");
}

/// The same wait when a group becomes active: items subscribed then are held until their
/// first sample; items reactivated with a value in the cache are not.
#[test]
fn the_first_callback_after_a_group_becomes_active_waits_too() {
    let mut sim = Sim::new();
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let set_active = |sim: &mut Sim, on: bool| {
        sim.e
            .set_group_state(
                sim.now,
                g,
                &SetGroupState {
                    active: Some(on),
                    ..Default::default()
                },
            )
            .unwrap();
        sim.pump();
    };
    set_active(&mut sim, false);
    sim.items(g, &["A1"]);
    set_active(&mut sim, true);
    sim.tick();
    assert!(sim.data_changes().is_empty(), "held");
    sim.push_good("A1", 2.0);
    sim.tick();
    assert_eq!(values(&sim.data_changes()[0]), vec![(100, Value::R8(2.0))]);
    set_active(&mut sim, false);
    sim.advance(5000);
    set_active(&mut sim, true);
    sim.tick();
    assert_eq!(
        values(&sim.data_changes()[0]),
        vec![(100, Value::R8(2.0))],
        "the cached sample at once"
    );
}

/// A sample (or the end of the wait) arriving while the client is still busy with the
/// group's callbacks waits for the delivery's end, as every update does (and the
/// scheduler does not spin on it).
#[test]
fn held_items_wait_for_the_pacing_slot() {
    let mut sim = Sim::with_config(EngineConfig {
        max_pending_data_changes: 1,
        ..EngineConfig::default()
    });
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    sim.items(g, &["A1", "A2"]);
    sim.push_good("A1", 1.0);
    sim.tick();
    assert_eq!(values(&sim.data_changes()[0]), vec![(100, Value::R8(1.0))]);
    sim.push_good("A2", 2.0);
    sim.advance(100);
    assert!(sim.data_changes().is_empty(), "the client has not returned");
    sim.advance(u64::from(DEFAULT_FIRST_SAMPLE_WAIT_MS));
    assert!(sim.data_changes().is_empty(), "nor at the bound");
    sim.e.data_change_delivered(sim.now, g);
    sim.tick();
    assert_eq!(values(&sim.data_changes()[0]), vec![(101, Value::R8(2.0))]);
}

#[test]
fn session_stats_count_each_clients_groups_and_items() {
    let mut sim = Sim::new();
    let a = sim.session();
    let b = sim.session();
    let _idle = sim.session();
    let g1 = sim.group(a, "g1", 1000, 0.0);
    let g2 = sim.group(a, "g2", 1000, 0.0);
    sim.items(g1, &["A1", "A2"]);
    sim.items(g2, &["A1"]);
    let g3 = sim.group(b, "g3", 1000, 0.0);
    sim.items(g3, &["A3"]);
    let stats = sim.e.session_stats();
    let counts: Vec<(usize, usize)> = stats.iter().map(|s| (s.1, s.2)).collect();
    assert_eq!(counts, [(2, 3), (1, 1), (0, 0)]);
    assert_eq!(stats[0].0, a);
    let total = sim.e.stats();
    assert_eq!(total.groups, 3);
    assert_eq!(total.group_items, 4);
}
