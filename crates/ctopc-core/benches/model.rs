//! Benchmark of the server model: `cargo bench -p ctopc-core --bench model`.
//!
//! Std only (harness = false). Prints medians of several runs:
//! - memory per item: 1,000,000 items over 1,000 groups (all distinct source items), counted
//!   with a counting global allocator; then the same items added to 1,000 more groups of a
//!   second session (what one more group item costs when the cache entry is shared);
//! - updates applied per second into the 1,000,000 subscribed items, with change detection
//!   and a 1 % deadband (half the items move beyond the band each round, half within it):
//!   applying the samples, then the update tick that compares every changed item with the
//!   value last sent to its group and builds the OnDataChange callbacks;
//! - scheduler cost of one tick with 100,000 changed items, and with none.

use std::sync::Arc;
use std::time::{Duration, Instant};

use ctopc_core::model::*;
use ctopc_core::namespace::{EuInfo, ItemDef, Namespace, OPC_READABLE, OPC_WRITEABLE};
use ctopc_core::{OpcError, OpcResult, Quality, Timestamp, Value, VarType, Vqt};

/// Counts live heap bytes (stats_alloc wraps the system allocator, so the bench needs no
/// `unsafe` of its own: that lives only in the COM crate).
#[global_allocator]
static GLOBAL: &stats_alloc::StatsAlloc<std::alloc::System> = &stats_alloc::INSTRUMENTED_SYSTEM;

fn live() -> isize {
    let s = GLOBAL.stats();
    // Reallocation deltas are already counted in bytes_allocated / bytes_deallocated.
    s.bytes_allocated as isize - s.bytes_deallocated as isize
}

/// Every `V<n>` is an analog R8 item with EU 0..100 on the basic channel.
struct BenchNs;

impl Namespace for BenchNs {
    fn resolve(&self, item_id: &str, _access_path: &str) -> OpcResult<ItemDef> {
        if !item_id.starts_with('V') {
            return Err(OpcError::UnknownItemId);
        }
        Ok(ItemDef {
            source_key: item_id.to_string(),
            channel: "*".to_string(),
            canonical_type: VarType::R8,
            access_rights: OPC_READABLE | OPC_WRITEABLE,
            eu: EuInfo::Analog {
                low: 0.0,
                high: 100.0,
            },
            constant: None,
        })
    }
}

const GROUPS: usize = 1_000;
const PER_GROUP: usize = 1_000;
const ITEMS: usize = GROUPS * PER_GROUP;
const RUNS: usize = 7;
const DEADBAND: f32 = 1.0; // 1 % of 0..100 = 1.0

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn add_groups(e: &mut Engine, now: Timestamp, s: SessionHandle, prefix: &str) -> Vec<GroupHandle> {
    (0..GROUPS)
        .map(|i| {
            let name = format!("{prefix}{i}");
            let g = e
                .add_group(
                    now,
                    s,
                    &GroupParams {
                        name: &name,
                        update_rate: 1000,
                        percent_deadband: DEADBAND,
                        ..Default::default()
                    },
                )
                .unwrap()
                .group;
            e.set_callback_connected(now, g, true).unwrap();
            g
        })
        .collect()
}

fn add_items(e: &mut Engine, now: Timestamp, groups: &[GroupHandle], defs: &[ItemDefinition<'_>]) {
    for (gi, g) in groups.iter().enumerate() {
        let r = e
            .add_items(now, *g, &defs[gi * PER_GROUP..(gi + 1) * PER_GROUP])
            .unwrap();
        debug_assert!(r.iter().all(|r| r.is_ok()));
    }
}

/// Drains every queued callback; returns (callbacks, items).
fn drain_events(e: &mut Engine) -> (usize, usize) {
    let (mut n, mut items) = (0, 0);
    while let Some(ev) = e.poll_event() {
        n += 1;
        if let Event::DataChange(d) = &ev {
            items += d.items.len();
        }
    }
    (n, items)
}

fn main() {
    println!("ctopc-core model benchmark: {GROUPS} groups x {PER_GROUP} items = {ITEMS} items, deadband {DEADBAND} %, medians of {RUNS} runs");
    let mut now = Timestamp::from_unix_millis(1_700_000_000_000);
    let mut e = Engine::new(EngineConfig::default(), Arc::new(BenchNs));

    // ---- memory ------------------------------------------------------------------------
    let ids: Vec<String> = (0..ITEMS).map(|i| format!("V{i}")).collect();
    let defs: Vec<ItemDefinition<'_>> = ids
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
    let mut keys: Vec<SourceKey> = Vec::with_capacity(ITEMS);
    let s1 = e.open_session();
    let g0 = live();
    let groups = add_groups(&mut e, now, s1, "G");
    let per_group = (live() - g0) as f64 / GROUPS as f64;
    let before = live();
    let t = Instant::now();
    add_items(&mut e, now, &groups, &defs);
    let add_time = t.elapsed();
    while let Some(r) = e.poll_source_request() {
        if let SourceRequest::Subscribe(subs) = r {
            keys.extend(subs.iter().map(|s| s.item.key));
        }
    }
    let total = (live() - before) as f64 / ITEMS as f64;
    assert_eq!(keys.len(), ITEMS);
    assert_eq!(e.stats().subscribed_items, ITEMS);

    let s2 = e.open_session();
    let groups2 = add_groups(&mut e, now, s2, "H");
    let before2 = live();
    add_items(&mut e, now, &groups2, &defs);
    while e.poll_source_request().is_some() {}
    let shared = (live() - before2) as f64 / ITEMS as f64;
    e.close_session(now, s2).unwrap();
    while e.poll_source_request().is_some() {}
    drop(groups2);

    println!();
    println!("memory (counting allocator)");
    println!("  per group (empty, with name)              {per_group:8.0} bytes");
    println!("  per item, 1 group item + its cache entry   {total:8.1} bytes   (goal <= 200)");
    println!("  per additional group item, shared cache    {shared:8.1} bytes   (goal <= 200)");
    println!(
        "  AddItems of {ITEMS} items (1000 calls)   {:8.1} ms",
        ms(add_time)
    );

    // ---- update throughput -------------------------------------------------------------
    // The backend pushes samples in an order unrelated to the groups: shuffle the keys.
    let mut order: Vec<u32> = (0..ITEMS as u32).collect();
    let mut seed = 0x2545_F491_4F6C_DD1Du64;
    for i in (1..order.len()).rev() {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        order.swap(i, (seed % (i as u64 + 1)) as usize);
    }
    // First tick sends everything (initial values).
    let base = |i: u32| 10.0 + f64::from(i % 80);
    e.handle_source_updates(
        now,
        order.iter().map(|&i| {
            (
                keys[i as usize],
                Vqt::new(Value::R8(base(i)), Quality::GOOD, now),
            )
        }),
    );
    now = now.add_millis(1000);
    e.handle_timeout(now);
    drain_events(&mut e);

    let mut apply = Vec::new();
    let mut tick = Vec::new();
    let mut total_rate = Vec::new();
    let mut reported = 0;
    for round in 1..=RUNS {
        // Even items move 5.0 (beyond the band), odd ones 0.3 (within it), alternating.
        let up = round % 2 == 1;
        let value = |i: u32| {
            let d = if i & 1 == 0 { 5.0 } else { 0.3 };
            base(i) + if up { d } else { 0.0 }
        };
        let t = Instant::now();
        e.handle_source_updates(
            now,
            order.iter().map(|&i| {
                (
                    keys[i as usize],
                    Vqt::new(Value::R8(value(i)), Quality::GOOD, now),
                )
            }),
        );
        let ta = t.elapsed();
        now = now.add_millis(1000);
        let t = Instant::now();
        e.handle_timeout(now);
        let (_, n) = drain_events(&mut e);
        let tt = t.elapsed();
        reported = n;
        apply.push(ITEMS as f64 / ta.as_secs_f64());
        tick.push(ms(tt));
        total_rate.push(ITEMS as f64 / (ta + tt).as_secs_f64());
    }
    // The same, with samples arriving in subscription order (as a backend answering its
    // Subscribe batches would push them).
    let mut apply_ordered = Vec::new();
    for round in 1..=RUNS {
        let up = round % 2 == 0;
        let t = Instant::now();
        e.handle_source_updates(
            now,
            (0..ITEMS as u32).map(|i| {
                let d = if i & 1 == 0 { 5.0 } else { 0.3 };
                (
                    keys[i as usize],
                    Vqt::new(
                        Value::R8(base(i) + if up { d } else { 0.0 }),
                        Quality::GOOD,
                        now,
                    ),
                )
            }),
        );
        apply_ordered.push(ITEMS as f64 / t.elapsed().as_secs_f64());
        now = now.add_millis(1000);
        e.handle_timeout(now);
        drain_events(&mut e);
    }
    println!();
    println!("updates into {ITEMS} subscribed items (shuffled order), every sample a change, {reported} reported per round");
    println!(
        "  apply samples (handle_source_updates)      {:8.2} M updates/s",
        median(apply) / 1e6
    );
    println!(
        "  update tick: detect + deadband + callbacks {:8.1} ms for 1000 groups",
        median(tick)
    );
    println!(
        "  end to end (apply + tick)                  {:8.2} M updates/s   (goal >= 2)",
        median(total_rate) / 1e6
    );
    println!(
        "  apply, samples in subscription order       {:8.2} M updates/s",
        median(apply_ordered) / 1e6
    );

    // ---- scheduler cost per tick -------------------------------------------------------
    let mut changed_tick = Vec::new();
    let mut idle_tick = Vec::new();
    let mut reported = 0;
    for round in 1..=RUNS {
        let up = round % 2 == 1;
        // 100,000 changed items: every 10th source item, beyond the band.
        e.handle_source_updates(
            now,
            (0..ITEMS as u32).step_by(10).map(|i| {
                (
                    keys[i as usize],
                    Vqt::new(
                        Value::R8(base(i) + if up { 7.0 } else { 0.0 }),
                        Quality::GOOD,
                        now,
                    ),
                )
            }),
        );
        now = now.add_millis(1000);
        let t = Instant::now();
        e.handle_timeout(now);
        let (_, n) = drain_events(&mut e);
        changed_tick.push(ms(t.elapsed()));
        reported = n;
        now = now.add_millis(1000);
        let t = Instant::now();
        e.handle_timeout(now);
        drain_events(&mut e);
        idle_tick.push(ms(t.elapsed()));
    }
    println!();
    println!("scheduler tick over 1000 groups / {ITEMS} items");
    println!(
        "  100,000 changed items ({reported} reported)    {:8.2} ms",
        median(changed_tick)
    );
    println!(
        "  nothing changed                            {:8.3} ms",
        median(idle_tick)
    );
    let _ = e.stats();
}
