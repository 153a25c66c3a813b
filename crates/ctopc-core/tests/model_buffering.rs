//! Server model: item buffering (IOPCItemSamplingMgt::SetItemBufferEnable) with a
//! stepped clock: a 1000 ms group, items sampled at 100 ms.

mod model_util;

use ctopc_core::model::*;
use ctopc_core::{OpcError, Value};
use model_util::*;

/// A 1000 ms group with A1 and A2, both sampled at 100 ms, A1 buffered; the first callback
/// (A1 = 0, A2 = 0) already taken at t = 0.
fn setup(deadband: f32) -> (Sim, GroupHandle, Vec<u32>) {
    let mut sim = Sim::with_config(EngineConfig {
        min_update_rate_ms: 100,
        ..EngineConfig::default()
    });
    let s = sim.session();
    let g = sim.group(s, "g", 1000, deadband);
    let h = sim.items(g, &["A1", "A2"]);
    let r = sim
        .e
        .set_item_sampling_rate(g, &[(h[0], 100), (h[1], 100)])
        .unwrap();
    assert!(r.iter().all(|r| r.is_ok()));
    assert_eq!(
        sim.e.set_item_buffer_enable(g, &[(h[0], true)]).unwrap(),
        vec![Ok(())]
    );
    sim.pump();
    sim.push_good("A1", 0.0);
    sim.push_good("A2", 0.0);
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(
        values(&dc[0]),
        vec![(100, Value::R8(0.0)), (101, Value::R8(0.0))]
    );
    (sim, g, h)
}

/// Pushes `A1 = xs[k]` (and `A2` likewise) every 100 ms from t + 100, then steps to the
/// next tick; returns the subscription callbacks.
fn run_period(sim: &mut Sim, xs: &[f64], also_a2: bool) -> Vec<DataChange> {
    for &x in xs {
        sim.advance(100);
        sim.push_good("A1", x);
        if also_a2 {
            sim.push_good("A2", x);
        }
    }
    sim.advance(1000 - 100 * xs.len() as u64);
    sim.data_changes()
}

fn a1_values(d: &DataChange) -> Vec<f64> {
    d.items
        .iter()
        .filter(|i| i.client_handle == 100)
        .map(|i| match i.value {
            Value::R8(x) => x,
            ref v => panic!("{v:?}"),
        })
        .collect()
}

#[test]
fn a_buffered_item_carries_every_sample_oldest_first_the_unbuffered_one_the_last() {
    let (mut sim, g, h) = setup(0.0);
    assert_eq!(
        sim.e
            .get_item_buffer_enable(g, &[h[0], h[1], 9999])
            .unwrap(),
        vec![Ok(true), Ok(false), Err(OpcError::InvalidHandle)]
    );
    let xs: Vec<f64> = (1..=9).map(f64::from).collect();
    let dc = run_period(&mut sim, &xs, true);
    assert_eq!(dc.len(), 1, "one callback per update period");
    assert_eq!(a1_values(&dc[0]), xs, "every sample, oldest first");
    let a1: Vec<_> = dc[0]
        .items
        .iter()
        .filter(|i| i.client_handle == 100)
        .collect();
    assert!(a1.windows(2).all(|w| w[0].timestamp < w[1].timestamp));
    assert_eq!(a1[0].timestamp, ts(100));
    assert!(a1.iter().all(|i| i.error.is_none()));
    let a2: Vec<_> = dc[0]
        .items
        .iter()
        .filter(|i| i.client_handle == 101)
        .collect();
    assert_eq!(a2.len(), 1, "not buffered: the last value only");
    assert_eq!(a2[0].value, Value::R8(9.0));
    assert_eq!((dc[0].master_quality, dc[0].master_error), (None, None));
    // Nothing new: no callback; then one change is one sample.
    assert!(run_period(&mut sim, &[], false).is_empty());
    let dc = run_period(&mut sim, &[5.0, 5.0, 6.0], false);
    assert_eq!(
        a1_values(&dc[0]),
        vec![5.0, 6.0],
        "unchanged samples are no changes"
    );
}

#[test]
fn an_overflowing_buffer_keeps_the_newest_and_marks_the_oldest_kept_sample() {
    let (mut sim, _g, _h) = setup(0.0);
    let n = ITEM_BUFFER_SAMPLES + 5;
    sim.advance(100);
    for k in 1..=n {
        sim.push_good("A1", k as f64);
    }
    sim.advance(900);
    let dc = sim.data_changes();
    assert_eq!(dc.len(), 1);
    let v = a1_values(&dc[0]);
    assert_eq!(v.len(), ITEM_BUFFER_SAMPLES);
    assert_eq!(
        (v[0], v[v.len() - 1]),
        (6.0, n as f64),
        "the oldest five went"
    );
    assert_eq!(dc[0].items[0].error, Some(OpcError::DataQueueOverflow));
    assert_eq!(dc[0].items[0].quality, ctopc_core::Quality::GOOD);
    assert!(dc[0].items[1..].iter().all(|i| i.error.is_none()));
    assert_eq!(dc[0].master_error, Some(OpcError::False));
    assert_eq!(dc[0].master_quality, None);
    // The next period did not overflow.
    let dc = run_period(&mut sim, &[1.0, 2.0], false);
    assert_eq!(a1_values(&dc[0]), vec![1.0, 2.0]);
    assert!(dc[0].items.iter().all(|i| i.error.is_none()));
}

#[test]
fn the_group_bound_caps_all_buffered_items_together() {
    let mut sim = Sim::with_config(EngineConfig {
        min_update_rate_ms: 100,
        ..EngineConfig::default()
    });
    let s = sim.session();
    let g = sim.group(s, "g", 1000, 0.0);
    let n_items = GROUP_BUFFER_SAMPLES / ITEM_BUFFER_SAMPLES + 1;
    let ids: Vec<String> = (1..=n_items).map(|k| format!("A{k}")).collect();
    let refs: Vec<&str> = ids.iter().map(String::as_str).collect();
    let h = sim.items(g, &refs);
    let rates: Vec<(u32, u32)> = h.iter().map(|&h| (h, 100)).collect();
    sim.e.set_item_sampling_rate(g, &rates).unwrap();
    let on: Vec<(u32, bool)> = h.iter().map(|&h| (h, true)).collect();
    sim.e.set_item_buffer_enable(g, &on).unwrap();
    for id in &refs {
        sim.push_good(id, 0.0);
    }
    sim.tick();
    assert_eq!(sim.data_changes()[0].items.len(), n_items);
    sim.advance(100);
    for k in 1..=ITEM_BUFFER_SAMPLES {
        for id in &refs {
            sim.push_good(id, k as f64);
        }
    }
    sim.advance(900);
    let dc = sim.data_changes();
    assert_eq!(dc[0].items.len(), GROUP_BUFFER_SAMPLES);
    let overflowed = dc[0]
        .items
        .iter()
        .filter(|i| i.error == Some(OpcError::DataQueueOverflow))
        .count();
    assert!(overflowed >= 1, "the last item's samples did not fit");
}

#[test]
fn deadband_applies_to_each_sample() {
    // EU 0..100, 10 %: a sample is kept when it moved more than 10 from the last kept one.
    let (mut sim, _g, _h) = setup(10.0);
    let dc = run_period(&mut sim, &[5.0, 11.0, 15.0, 22.0, 40.0, 35.0], false);
    assert_eq!(a1_values(&dc[0]), vec![11.0, 22.0, 40.0]);
}

#[test]
fn disabling_mid_way_drops_the_buffer_and_restores_the_plain_behaviour() {
    let (mut sim, g, h) = setup(0.0);
    sim.advance(100);
    sim.push_good("A1", 1.0);
    sim.advance(100);
    sim.push_good("A1", 2.0);
    assert_eq!(
        sim.e
            .set_item_buffer_enable(g, &[(h[0], false), (4242, false)])
            .unwrap(),
        vec![Ok(()), Err(OpcError::InvalidHandle)]
    );
    assert_eq!(
        sim.e.get_item_buffer_enable(g, &[h[0]]).unwrap(),
        vec![Ok(false)]
    );
    sim.advance(100);
    sim.push_good("A1", 3.0);
    sim.advance(700);
    let dc = sim.data_changes();
    assert_eq!(a1_values(&dc[0]), vec![3.0], "the last value only");
    // And on again: buffered from now.
    sim.e.set_item_buffer_enable(g, &[(h[0], true)]).unwrap();
    let dc = run_period(&mut sim, &[4.0, 5.0], false);
    assert_eq!(a1_values(&dc[0]), vec![4.0, 5.0]);
}

#[test]
fn a_removed_item_leaves_nothing_behind() {
    let (mut sim, g, h) = setup(0.0);
    sim.advance(100);
    sim.push_good("A1", 1.0);
    sim.push_good("A2", 1.0);
    sim.e.remove_items(sim.now, g, &[h[0]]).unwrap();
    sim.advance(100);
    sim.push_good("A2", 2.0);
    sim.advance(800);
    let dc = sim.data_changes();
    assert_eq!(values(&dc[0]), vec![(101, Value::R8(2.0))]);
    // A new item on the same source item, not buffered: the plain behaviour.
    let h2 = sim.items(g, &["alias.A1"]);
    sim.e.set_item_sampling_rate(g, &[(h2[0], 100)]).unwrap();
    sim.tick();
    sim.data_changes();
    let dc = run_period(&mut sim, &[7.0, 8.0], false);
    assert_eq!(values(&dc[0]), vec![(100, Value::R8(8.0))]);
}

#[test]
fn an_inactive_item_or_group_buffers_nothing() {
    let (mut sim, g, h) = setup(0.0);
    sim.e.set_active_state(sim.now, g, &[h[0]], false).unwrap();
    sim.advance(100);
    sim.push_good("A1", 1.0);
    sim.advance(100);
    sim.push_good("A1", 2.0);
    sim.e.set_active_state(sim.now, g, &[h[0]], true).unwrap();
    sim.advance(800);
    let dc = sim.data_changes();
    assert_eq!(
        a1_values(&dc[0]),
        vec![2.0],
        "reactivated: the current value"
    );
    let dc = run_period(&mut sim, &[3.0, 4.0], false);
    assert_eq!(a1_values(&dc[0]), vec![3.0, 4.0], "buffered again");

    let off = SetGroupState {
        active: Some(false),
        ..Default::default()
    };
    sim.e.set_group_state(sim.now, g, &off).unwrap();
    sim.advance(100);
    sim.push_good("A1", 5.0);
    sim.advance(100);
    sim.push_good("A1", 6.0);
    assert!(sim.data_changes().is_empty());
    let on = SetGroupState {
        active: Some(true),
        ..Default::default()
    };
    sim.e.set_group_state(sim.now, g, &on).unwrap();
    sim.tick();
    let dc = sim.data_changes();
    assert_eq!(
        a1_values(&dc[0]),
        vec![6.0],
        "group reactivated: the current value"
    );
}

#[test]
fn refresh_is_not_buffered_and_leaves_the_buffer_for_the_next_update() {
    let (mut sim, g, _h) = setup(0.0);
    for x in [1.0, 2.0, 3.0] {
        sim.advance(100);
        sim.push_good("A1", x);
    }
    sim.e.refresh2(sim.now, g, DataSource::Cache, 77).unwrap();
    let refresh: Vec<DataChange> = sim
        .events()
        .into_iter()
        .filter_map(|e| match e {
            Event::DataChange(d) if d.kind == DataChangeKind::Refresh => Some(d),
            _ => None,
        })
        .collect();
    assert_eq!(refresh.len(), 1);
    assert_eq!(a1_values(&refresh[0]), vec![3.0], "one value per item");
    sim.advance(700);
    let dc = sim.data_changes();
    assert_eq!(a1_values(&dc[0]), vec![1.0, 2.0, 3.0]);
}

#[test]
fn buffering_needs_a_sampling_rate_faster_than_the_update_rate() {
    let (mut sim, g, h) = setup(0.0);
    sim.e.clear_item_sampling_rate(g, &[h[0]]).unwrap();
    let dc = run_period(&mut sim, &[1.0, 2.0, 3.0], false);
    assert_eq!(a1_values(&dc[0]), vec![3.0]);
    sim.e.set_item_sampling_rate(g, &[(h[0], 1000)]).unwrap();
    let dc = run_period(&mut sim, &[4.0, 5.0], false);
    assert_eq!(a1_values(&dc[0]), vec![5.0]);
    // Enabling is accepted either way (it takes effect with a faster rate).
    assert_eq!(
        sim.e.get_item_buffer_enable(g, &[h[0]]).unwrap(),
        vec![Ok(true)]
    );
}
