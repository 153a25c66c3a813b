//! What one group of many items costs the server natively (no COM, no Wine): the engine
//! over the in-process simulation of the synthetic database (`asix_model::synthetic`,
//! 200,000 variables; `SCALE_ITEMS_VARIABLES=N` for another size), `cargo bench -p asix-net
//! --bench scale_items`. `SCALE_ITEMS_RULES=1`: the channel checks limits and control
//! variables (`CheckLimits`, `CheckControlVariables`; off by default, as in the asix
//! configuration). `SCALE_ITEMS_NO_PEEK=1`: the simulation cannot tell a variable's
//! current value (`VariableSource::peek`), as the network cannot, so that the backend
//! keeps each variable's last sample the network's way.
//!
//! Std only (harness = false). A counting global allocator gives the live heap, and
//! `/proc/self/statm` the resident memory (Linux; glibc's heap, not Wine's), per item of
//! 100,000 items:
//! 1. added to an inactive group (one AddItems): the engine alone;
//! 2. the group made active (subscribed at the simulation, first samples in, the first
//!    OnDataChange delivered), split into what the engine's calls and the backend's calls
//!    left allocated, and the pending OnDataChange while it is under way;
//! 3. after [`CYCLES`] update cycles at 1 s, each OnDataChange delivered (acknowledged
//!    with `data_change_delivered`) before the next: the growth over those cycles.
//!
//! These are the server-side shares of the figures `scale-client` measures from outside
//! under Wine; the rest is the COM transport and Wine's heap.

use std::sync::Arc;

use asix_model::synthetic::{synthetic_database, variable_name};
use asix_model::AsixNamespace;
use asix_model::ItemKey;
use asix_net::backend::{AsixBackend, RawId, RawOutput, VariableSource};
use asix_net::inproc::{InProcessSim, PlantSource};
use ctopc_core::model::datasource::ItemVqt;
use ctopc_core::model::{
    Engine, EngineConfig, Event, GroupHandle, GroupParams, ItemDefinition, SetGroupState,
};
use ctopc_core::model::{SourceKey, SourceRequest, Subscription};
use ctopc_core::source::{Backend, SourceOutput};
use ctopc_core::{Timestamp, VarType, Vqt};

#[global_allocator]
static GLOBAL: &stats_alloc::StatsAlloc<std::alloc::System> = &stats_alloc::INSTRUMENTED_SYSTEM;

mod support;

fn live() -> isize {
    support::live(GLOBAL)
}

/// The synthetic database's size (`SCALE_ITEMS_VARIABLES` overrides it).
fn variables() -> usize {
    std::env::var("SCALE_ITEMS_VARIABLES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200_000)
}
/// Whether the channel checks the quality rules (`SCALE_ITEMS_RULES=1`).
fn rules() -> bool {
    std::env::var("SCALE_ITEMS_RULES").is_ok_and(|v| v == "1")
}
const ITEMS: usize = 100_000;
/// Update cycles at 1 s after the first OnDataChange.
const CYCLES: usize = 5;

fn namespace() -> Arc<AsixNamespace> {
    let dir = std::env::temp_dir().join(format!("scale_items_{}", variables()));
    let zez = dir.join("synthetic.zez");
    if !zez.exists() {
        std::fs::create_dir_all(&dir).expect("temp dir");
        let g = synthetic_database(variables());
        std::fs::write(dir.join("atrybuty.csv"), g.csv).expect("csv");
        std::fs::write(&zez, g.zez).expect("zez");
    }
    let rules = if rules() {
        "CheckLimits = tak\nCheckControlVariables = tak\n"
    } else {
        ""
    };
    let ini = format!(
        "[Server]\nSimulateCurrentData = tak\n[Channel:*]\nItemsDatabase = {}\n{rules}",
        zez.display()
    );
    let (cfg, _) = asix_model::parse_config(ini.as_bytes(), "scale.ini").expect("ini");
    let (ns, w) = AsixNamespace::load(cfg);
    assert!(w.is_empty(), "{w:?}");
    Arc::new(ns)
}

/// The heap an `Arc<str>` frees when it is dropped, if nothing else holds it.
fn made_for(s: &Arc<str>) -> usize {
    if Arc::strong_count(s) > 1 || Arc::weak_count(s) > 0 {
        return 0;
    }
    // The two counts and the bytes, at the counts' alignment.
    (2 * size_of::<usize>() + s.len()).next_multiple_of(align_of::<usize>())
}

fn per_item(bytes: isize) -> f64 {
    bytes as f64 / ITEMS as f64
}

/// The engine and the backend stepped as the driver does, with the live heap each side's
/// calls left behind counted apart (ownership moving between them, such as a request the
/// backend consumes, counts where it is freed).
/// The simulation without [`VariableSource::peek`] (`SCALE_ITEMS_NO_PEEK=1`).
struct NoPeek(PlantSource);

impl VariableSource for NoPeek {
    type Var = u32;
    type Part = ();
    fn lookup(&self, channel: &Arc<str>, key: &ItemKey) -> Option<u32> {
        self.0.lookup(channel, key)
    }
    fn part(&self, _var: &u32) {}
    fn subscribe(&mut self, now: Timestamp, vars: Vec<(u32, u32)>) {
        self.0.subscribe(now, vars)
    }
    fn unsubscribe(&mut self, now: Timestamp, vars: Vec<u32>) {
        self.0.unsubscribe(now, vars)
    }
    fn read(&mut self, now: Timestamp, id: RawId, vars: Vec<u32>) {
        self.0.read(now, id, vars)
    }
    fn write(&mut self, now: Timestamp, id: RawId, items: Vec<(u32, ItemVqt)>) {
        self.0.write(now, id, items)
    }
    fn poll(&mut self, now: Timestamp, out: &mut RawOutput<u32>) {
        self.0.poll(now, out)
    }
    fn poll_timeout(&self) -> Option<Timestamp> {
        self.0.poll_timeout()
    }
}

struct Rig<S: VariableSource> {
    e: Engine,
    sim: AsixBackend<S>,
    engine_bytes: isize,
    backend_bytes: isize,
}

impl<S: VariableSource> Rig<S> {
    fn engine<T>(&mut self, f: impl FnOnce(&mut Engine) -> T) -> T {
        let b = live();
        let r = f(&mut self.e);
        self.engine_bytes += live() - b;
        r
    }

    fn backend<T>(&mut self, f: impl FnOnce(&mut AsixBackend<S>) -> T) -> T {
        let b = live();
        let r = f(&mut self.sim);
        self.backend_bytes += live() - b;
        r
    }

    fn step(&mut self, now: Timestamp, events: &mut Vec<Event>) {
        for _ in 0..3 {
            while let Some(r) = self.engine(|e| e.poll_source_request()) {
                // The request is the engine's until the backend has taken it in, with the
                // item IDs made for it (the backend drops them).
                let handed = match &r {
                    SourceRequest::Subscribe(v) => {
                        v.capacity() * size_of::<Subscription>()
                            + v.iter().map(|s| made_for(&s.item.item_id)).sum::<usize>()
                    }
                    _ => 0,
                } as isize;
                self.engine_bytes -= handed;
                self.backend_bytes += handed;
                self.backend(|s| s.request(now, r));
            }
            let out = self.backend(|s| {
                let mut out = SourceOutput::default();
                s.poll(now, &mut out);
                out
            });
            // The samples are the backend's output until the engine has taken them in.
            let handed = (out.updates.capacity() * size_of::<(SourceKey, Vqt)>()) as isize;
            self.backend_bytes -= handed;
            self.engine_bytes += handed;
            self.engine(|e| {
                e.handle_source_updates(now, out.updates);
                e.handle_timeout(now);
                while let Some(ev) = e.poll_event() {
                    events.push(ev);
                }
            });
        }
    }

    /// Delivers the events (drops them) and acknowledges the scheduled OnDataChanges.
    fn deliver(&mut self, now: Timestamp, g: GroupHandle, events: &mut Vec<Event>) -> usize {
        let mut values = 0;
        for ev in events.drain(..) {
            if let Event::DataChange(d) = ev {
                values += d.items.len();
                let scheduled = d.kind.is_scheduled();
                // The event is the engine's output until delivered.
                self.engine(|e| {
                    drop(d);
                    if scheduled {
                        e.data_change_delivered(now, g);
                    }
                });
            }
        }
        values
    }
}

fn main() {
    let ns = namespace();
    let now = Timestamp::from_filetime_parts(0, 0x01DC_0000);
    let no_peek = std::env::var("SCALE_ITEMS_NO_PEEK").is_ok_and(|v| v == "1");
    if no_peek {
        let source = NoPeek(PlantSource::new(&ns, 1, now));
        run(
            ns.clone(),
            now,
            AsixBackend::from_source(ns, source),
            "cannot peek",
        );
    } else {
        run(ns.clone(), now, InProcessSim::new(ns, 1, now), "peeks");
    }
}

fn run<S: VariableSource>(
    ns: Arc<AsixNamespace>,
    mut now: Timestamp,
    sim: AsixBackend<S>,
    peek: &str,
) {
    let mut rig = Rig {
        e: Engine::new(EngineConfig::default(), ns),
        sim,
        engine_bytes: 0,
        backend_bytes: 0,
    };
    let s = rig.e.open_session();
    let params = GroupParams {
        name: "",
        active: false,
        update_rate: 1000,
        ..Default::default()
    };
    let g = rig.e.add_group(now, s, &params).expect("group").group;
    rig.e.set_callback_connected(now, g, true).expect("connect");
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
        "engine + in-process simulation ({peek}), {} synthetic variables, {ITEMS} items, \
         quality rules {}, natively",
        variables(),
        if rules() { "checked" } else { "off" },
    );
    println!(
        "sizes: Value {} B, Vqt {} B, ItemValue {} B, SourceItem {} B, \
         Resolution<u32> {} B",
        std::mem::size_of::<ctopc_core::Value>(),
        std::mem::size_of::<ctopc_core::Vqt>(),
        std::mem::size_of::<ctopc_core::model::ItemValue>(),
        std::mem::size_of::<ctopc_core::model::SourceItem>(),
        std::mem::size_of::<asix_net::pipeline::Resolution<u32>>(),
    );

    let mut events = Vec::new();
    let (heap0, rss0) = (live(), support::resident());
    rig.engine(|e| {
        let added = e.add_items(now, g, &defs).expect("add");
        assert!(added.iter().all(Result::is_ok));
    });
    rig.step(now, &mut events);
    assert!(events.is_empty());
    let (heap1, rss1) = (live(), support::resident());
    println!(
        "1. inactive group item:      heap {:>6.1} B/item (engine {:.1}, backend {:.1}), \
         resident {:>6.1} B/item",
        per_item(heap1 - heap0),
        per_item(rig.engine_bytes),
        per_item(rig.backend_bytes),
        per_item(rss1 - rss0),
    );

    (rig.engine_bytes, rig.backend_bytes) = (0, 0);
    let active = SetGroupState {
        active: Some(true),
        ..Default::default()
    };
    rig.engine(|e| e.set_group_state(now, g, &active).expect("activate"));
    rig.step(now, &mut events);
    now = now.add_millis(1000);
    rig.step(now, &mut events);
    let pending = live();
    let values = rig.deliver(now, g, &mut events);
    assert!(values >= ITEMS, "the first OnDataChange reports every item");
    let (heap2, rss2) = (live(), support::resident());
    println!(
        "2. active, subscribed item:  heap {:>6.1} B/item more (engine {:.1}, backend {:.1}), \
         resident {:>6.1} B/item more; the pending OnDataChanges {:.1} B/item ({values} values)",
        per_item(heap2 - heap1),
        per_item(rig.engine_bytes),
        per_item(rig.backend_bytes),
        per_item(rss2 - rss1),
        per_item(pending - heap2),
    );

    (rig.engine_bytes, rig.backend_bytes) = (0, 0);
    let mut peak = 0;
    let mut delivered = 0;
    for _ in 0..CYCLES {
        now = now.add_millis(1000);
        rig.step(now, &mut events);
        peak = peak.max(live() - heap2);
        delivered += rig.deliver(now, g, &mut events);
    }
    let (heap3, rss3) = (live(), support::resident());
    println!(
        "3. after {CYCLES} cycles at 1 s:    heap {:>6.1} B/item more (engine {:.1}, backend \
         {:.1}), resident {:>6.1} B/item more; peak while pending {:.1} B/item ({delivered} \
         values)",
        per_item(heap3 - heap2),
        per_item(rig.engine_bytes),
        per_item(rig.backend_bytes),
        per_item(rss3 - rss2),
        per_item(peak),
    );
    println!(
        "total from AddItems to after the cycles: heap {:.1} B/item, resident {:.1} B/item",
        per_item(heap3 - heap0),
        per_item(rss3 - rss0),
    );
}
