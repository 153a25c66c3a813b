//! The server's engine over the in-process simulation, natively (no COM, no Wine):
//! `cargo bench -p asix-net --bench sim_items`.
//!
//! Std only (harness = false). Prints:
//! - live heap bytes per item (counting global allocator) for 80,000 items over the demo
//!   plant's variables (repeated) and for 80,000 distinct descriptive IDs, engine and
//!   simulation together, after the subscriptions reached the simulation;
//! - medians of a synchronous Write of 10,000 items (engine -> simulation -> engine) and of
//!   a synchronous Read of 10,000 items from cache and from device, with a baseline (one
//!   Write of a single item) measured in the same run and the ratio to it.
//!
//! These are the server-side shares of the COM figures of `cargo xtask bench`; the rest is
//! the COM transport.

use std::sync::Arc;
use std::time::{Duration, Instant};

use asix_model::{AsixNamespace, BASIC_CHANNEL};
use asix_net::inproc::InProcessSim;
use ctopc_core::model::{
    DataSource, Engine, EngineConfig, GroupHandle, GroupParams, ItemDefinition, SyncOutcome,
};
use ctopc_core::source::{Backend, SourceOutput};
use ctopc_core::{Timestamp, Value, VarType};

#[global_allocator]
static GLOBAL: &stats_alloc::StatsAlloc<std::alloc::System> = &stats_alloc::INSTRUMENTED_SYSTEM;

mod support;

fn live() -> isize {
    support::live(GLOBAL)
}

const MEMORY_ITEMS: usize = 80_000;
const N: usize = 10_000;
const RUNS: usize = 15;

/// The embedded demo configuration of the server (`asix_model::embedded_demo`).
fn demo_namespace() -> Arc<AsixNamespace> {
    Arc::new(
        asix_model::embedded_demo()
            .expect("the embedded demo")
            .namespace,
    )
}

/// The server's driver thread, in miniature (crates/runtime/src/runtime.rs).
struct Driver {
    e: Engine,
    sim: InProcessSim,
    now: Timestamp,
}

impl Driver {
    fn step(&mut self) {
        while let Some(r) = self.e.poll_source_request() {
            self.sim.request(self.now, r);
        }
        let mut out = SourceOutput::default();
        self.sim.poll(self.now, &mut out);
        self.e.handle_source_updates(self.now, out.updates);
        for (id, r) in out.read_results {
            self.e.handle_source_read_result(self.now, id, r);
        }
        for (id, r) in out.write_results {
            self.e.handle_source_write_result(self.now, id, r);
        }
    }

    fn settle<T>(&mut self, o: SyncOutcome<T>) -> Option<ctopc_core::model::SyncResult> {
        match o {
            SyncOutcome::Ready(_) => None,
            SyncOutcome::Pending(id) => {
                self.step();
                self.e.take_sync_result(id)
            }
        }
    }

    fn group(&mut self) -> GroupHandle {
        let s = self.e.open_session();
        let g = self
            .e
            .add_group(
                self.now,
                s,
                &GroupParams {
                    name: "",
                    active: true,
                    update_rate: 1000,
                    ..Default::default()
                },
            )
            .expect("group")
            .group;
        self.e
            .set_callback_connected(self.now, g, true)
            .expect("connect");
        g
    }

    fn add_engine_only(&mut self, g: GroupHandle, ids: &[String]) {
        for chunk in ids.chunks(N) {
            let defs: Vec<ItemDefinition> = chunk
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
            for r in self.e.add_items(self.now, g, &defs).expect("add") {
                r.expect("item");
            }
        }
    }

    fn add(&mut self, g: GroupHandle, ids: &[String]) -> Vec<u32> {
        let mut handles = Vec::with_capacity(ids.len());
        for chunk in ids.chunks(N) {
            let defs: Vec<ItemDefinition> = chunk
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
            for r in self.e.add_items(self.now, g, &defs).expect("add") {
                handles.push(r.expect("item").server_handle);
            }
            self.step();
        }
        handles
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn time(runs: usize, mut f: impl FnMut()) -> f64 {
    median(
        (0..runs)
            .map(|_| {
                let t = Instant::now();
                f();
                ms(t.elapsed())
            })
            .collect(),
    )
}

fn main() {
    let ns = demo_namespace();
    let names: Vec<String> = ns
        .database(BASIC_CHANNEL)
        .expect("db")
        .variables
        .iter()
        .map(|v| v.name.clone())
        .collect();
    let writable: Vec<String> = ns
        .database(BASIC_CHANNEL)
        .expect("db")
        .variables
        .iter()
        .filter(|v| v.writable && v.data_type == VarType::R4)
        .map(|v| v.name.clone())
        .collect();
    let now = Timestamp::from_filetime_parts(0, 0x01DC_0000);
    let mut d = Driver {
        e: Engine::new(EngineConfig::default(), ns.clone()),
        sim: InProcessSim::new(ns.clone(), 1, now),
        now,
    };
    println!(
        "engine + in-process simulation of the demo plant ({} variables), natively",
        names.len()
    );

    // Memory per item.
    let repeated: Vec<String> = names.iter().cycle().take(MEMORY_ITEMS).cloned().collect();
    let distinct: Vec<String> = (0..MEMORY_ITEMS)
        .map(|i| format!("asmen.BENCH.V{i:06}.R4"))
        .collect();
    for (what, ids) in [
        ("over the demo's variables, repeated", &repeated),
        ("distinct descriptive IDs", &distinct),
    ] {
        let s = d.e.open_session();
        let g =
            d.e.add_group(
                d.now,
                s,
                &GroupParams {
                    name: "",
                    active: true,
                    update_rate: 1000,
                    ..Default::default()
                },
            )
            .expect("group")
            .group;
        d.e.set_callback_connected(d.now, g, true).expect("connect");
        let before = live();
        d.add_engine_only(g, ids);
        let engine = (live() - before) as f64 / MEMORY_ITEMS as f64;
        d.step();
        println!("  (engine alone {engine:.0} B/item)");
        let per = (live() - before) as f64 / MEMORY_ITEMS as f64;
        println!(
            "memory per item, {MEMORY_ITEMS} items {what:<36} {per:>8.0} B/item (goal <= 300)"
        );
        d.e.remove_group(d.now, s, g, true).expect("remove");
        d.step();
    }

    // Sync Write / Read of 10,000 items.
    let g = d.group();
    let wh = d.add(
        g,
        &writable.iter().cycle().take(N).cloned().collect::<Vec<_>>(),
    );
    let rh = d.add(
        g,
        &names.iter().cycle().take(N).cloned().collect::<Vec<_>>(),
    );
    d.step();
    let values: Vec<(u32, Value)> = wh
        .iter()
        .enumerate()
        .map(|(i, &h)| (h, Value::R4((i % 10) as f32)))
        .collect();
    let base = time(RUNS * 10, || {
        let o = d.e.write(d.now, g, &values[..1]).expect("write");
        assert!(d.settle(o).is_some());
    });
    println!("baseline: Write of 1 item                         median {base:>9.4} ms");
    let w = time(RUNS, || {
        let o = d.e.write(d.now, g, &values).expect("write");
        assert!(d.settle(o).is_some());
    });
    println!("Write 10,000 (engine + simulation)                median {w:>9.3} ms  = {:>6.0} x baseline", w / base);
    let rc = time(RUNS, || {
        let _ = d.e.read(d.now, g, DataSource::Cache, &rh).expect("read");
    });
    println!("Read 10,000 from CACHE                            median {rc:>9.3} ms  = {:>6.0} x baseline", rc / base);
    let rd = time(RUNS, || {
        let o = d.e.read(d.now, g, DataSource::Device, &rh).expect("read");
        assert!(d.settle(o).is_some());
    });
    println!("Read 10,000 from DEVICE (engine + simulation)     median {rd:>9.3} ms  = {:>6.0} x baseline", rd / base);
}
