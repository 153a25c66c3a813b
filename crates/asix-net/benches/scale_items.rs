//! What one group of many items costs the server natively (no COM, no Wine): the engine
//! over the in-process simulation of the synthetic database (`asix_model::synthetic`,
//! 200,000 variables), `cargo bench -p asix-net --bench scale_items`.
//!
//! Std only (harness = false). A counting global allocator gives the live heap: bytes per item of 100,000 items added to an inactive group (one
//! AddItems), of the same group made active (subscribed at the simulation, first samples
//! in), and of the first OnDataChange of every item while it is pending. These are the
//! server-side shares of the figures `scale-client` measures from outside under Wine
//! (issue 16); the rest is the COM transport and Wine's heap.

use std::sync::Arc;

use asix_model::synthetic::{synthetic_database, variable_name};
use asix_model::AsixNamespace;
use asix_net::inproc::InProcessSim;
use ctopc_core::model::{Engine, EngineConfig, Event, GroupParams, ItemDefinition, SetGroupState};
use ctopc_core::source::{Backend, SourceOutput};
use ctopc_core::{Timestamp, VarType};

#[global_allocator]
static GLOBAL: &stats_alloc::StatsAlloc<std::alloc::System> = &stats_alloc::INSTRUMENTED_SYSTEM;

fn live() -> isize {
    let s = GLOBAL.stats();
    s.bytes_allocated as isize - s.bytes_deallocated as isize
}

const VARIABLES: usize = 200_000;
const ITEMS: usize = 100_000;

fn namespace() -> Arc<AsixNamespace> {
    let dir = std::env::temp_dir().join(format!("scale_items_{VARIABLES}"));
    let zez = dir.join("synthetic.zez");
    if !zez.exists() {
        std::fs::create_dir_all(&dir).expect("temp dir");
        let g = synthetic_database(VARIABLES);
        std::fs::write(dir.join("atrybuty.csv"), g.csv).expect("csv");
        std::fs::write(&zez, g.zez).expect("zez");
    }
    let ini = format!(
        "[Server]\nSimulateCurrentData = tak\n[Channel:*]\nItemsDatabase = {}\n",
        zez.display()
    );
    let (cfg, _) = asix_model::parse_config(ini.as_bytes(), "scale.ini").expect("ini");
    let (ns, w) = AsixNamespace::load(cfg);
    assert!(w.is_empty(), "{w:?}");
    Arc::new(ns)
}

fn per_item(bytes: isize) -> f64 {
    bytes as f64 / ITEMS as f64
}

fn main() {
    let ns = namespace();
    let mut now = Timestamp::from_filetime_parts(0, 0x01DC_0000);
    let mut e = Engine::new(EngineConfig::default(), ns.clone());
    let mut sim = InProcessSim::new(ns, 1, now);
    let mut step = |e: &mut Engine, now: Timestamp, events: &mut Vec<Event>| {
        for _ in 0..3 {
            while let Some(r) = e.poll_source_request() {
                sim.request(now, r);
            }
            let mut out = SourceOutput::default();
            sim.poll(now, &mut out);
            e.handle_source_updates(now, out.updates);
            e.handle_timeout(now);
            while let Some(ev) = e.poll_event() {
                events.push(ev);
            }
        }
    };
    let s = e.open_session();
    let params = GroupParams {
        name: "",
        active: false,
        update_rate: 1000,
        ..Default::default()
    };
    let g = e.add_group(now, s, &params).expect("group").group;
    e.set_callback_connected(now, g, true).expect("connect");
    let names: Vec<String> = (0..ITEMS).map(variable_name).collect();
    let defs: Vec<ItemDefinition> = names
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
    println!(
        "engine + in-process simulation, {VARIABLES} synthetic variables, {ITEMS} items, natively"
    );

    let before = live();
    let added = e.add_items(now, g, &defs).expect("add");
    assert!(added.iter().all(Result::is_ok));
    drop(added);
    let mut events = Vec::new();
    step(&mut e, now, &mut events);
    let after_add = live();
    println!(
        "inactive group: live {:>6.0} B/item",
        per_item(after_add - before)
    );

    let active = SetGroupState {
        active: Some(true),
        ..Default::default()
    };
    e.set_group_state(now, g, &active).expect("activate");
    step(&mut e, now, &mut events);
    now = now.add_millis(1000);
    step(&mut e, now, &mut events);
    let values: usize = events
        .iter()
        .map(|ev| match ev {
            Event::DataChange(d) => d.items.len(),
            _ => 0,
        })
        .sum();
    let with_events = live();
    drop(events);
    println!(
        "activated: live {:>6.0} B/item more (subscription), {:>6.0} B/item more with the \
         pending OnDataChange ({values} values)",
        per_item(live() - after_add),
        per_item(with_events - live()),
    );
}
