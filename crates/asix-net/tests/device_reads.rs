//! A device read of many items is one request to the data source per
//! call (per part of the source: one in the simulation, one per asix channel on the
//! network), never one per item or per variable. The engine and the asix adapter
//! (`AsixBackend`) over a counting fake source, with a synthetic database of 10,000
//! variables (`asix_model::synthetic`) whose `Channel` attribute spreads them over 100
//! asix channels.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::Arc;

use asix_model::synthetic::{synthetic_database, variable_name};
use asix_model::ItemKey;
use asix_model::{parse_config, AsixNamespace};
use asix_net::backend::{AsixBackend, RawId, RawOutput, VariableSource};
use ctopc_core::model::{
    DataSource, Engine, EngineConfig, GroupHandle, GroupParams, ItemDefinition, ItemVqt,
    SourceRequest, SyncOutcome,
};
use ctopc_core::source::{Backend, SourceOutput};
use ctopc_core::{Quality, Timestamp, Value, VarType, Vqt};

const N: usize = 10_000;

/// A source that counts its device reads and answers each with good values.
struct Counting {
    /// Parts by asix channel (the network's way), else one part (the simulation's).
    by_channel: bool,
    /// Every device read: its variables.
    reads: Vec<Vec<(Arc<str>, u32)>>,
    out: RawOutput<(Arc<str>, u32)>,
}

impl VariableSource for Counting {
    type Var = (Arc<str>, u32);
    type Part = Arc<str>;
    fn lookup(&self, _channel: &Arc<str>, key: &ItemKey) -> Option<(Arc<str>, u32)> {
        let i = key.variable.strip_prefix("SC_")?.parse().ok()?;
        Some((Arc::clone(&key.channel), i))
    }
    fn part(&self, var: &(Arc<str>, u32)) -> Arc<str> {
        if self.by_channel {
            Arc::clone(&var.0)
        } else {
            Arc::from("")
        }
    }
    fn subscribe(&mut self, _now: Timestamp, _vars: Vec<((Arc<str>, u32), u32)>) {}
    fn unsubscribe(&mut self, _now: Timestamp, _vars: Vec<(Arc<str>, u32)>) {}
    fn read(&mut self, now: Timestamp, id: RawId, vars: Vec<(Arc<str>, u32)>) {
        let answers = vars
            .iter()
            .map(|(_, i)| {
                Ok(Vqt {
                    value: if i % 10 == 9 {
                        Value::I2((i % 100) as i16)
                    } else {
                        Value::R4(*i as f32)
                    },
                    quality: Quality::GOOD,
                    timestamp: now,
                })
            })
            .collect();
        self.out.reads.push((id, answers));
        self.reads.push(vars);
    }
    fn write(&mut self, _now: Timestamp, id: RawId, items: Vec<((Arc<str>, u32), ItemVqt)>) {
        self.out.writes.push((id, vec![Ok(()); items.len()]));
    }
    fn poll(&mut self, _now: Timestamp, out: &mut RawOutput<(Arc<str>, u32)>) {
        let o = std::mem::take(&mut self.out);
        out.samples.extend(o.samples);
        out.reads.extend(o.reads);
        out.writes.extend(o.writes);
    }
    fn poll_timeout(&self) -> Option<Timestamp> {
        (!self.out.is_empty()).then_some(Timestamp(0))
    }
}

fn namespace() -> Arc<AsixNamespace> {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("device_reads");
    let zez = dir.join("synthetic.zez");
    // The tests of this file run at once, and in a clean target nobody has written the
    // database yet: each file is written aside and renamed into place (the csv first), so
    // no test ever reads a half-written one (seen in a clean clone: UnknownItemId).
    static WRITTEN: std::sync::OnceLock<()> = std::sync::OnceLock::new();
    WRITTEN.get_or_init(|| {
        if zez.exists() {
            return;
        }
        std::fs::create_dir_all(&dir).unwrap();
        let g = synthetic_database(N);
        let put = |name: &str, text: &str| {
            let tmp = dir.join(format!("{name}.{}.tmp", std::process::id()));
            std::fs::write(&tmp, text).unwrap();
            std::fs::rename(&tmp, dir.join(name)).unwrap();
        };
        put("atrybuty.csv", &g.csv);
        put("synthetic.zez", &g.zez);
    });
    let ini = format!("[Channel:*]\nItemsDatabase = {}\n", zez.display());
    let (cfg, _) = parse_config(ini.as_bytes(), "test.ini").unwrap();
    let (ns, w) = AsixNamespace::load(cfg);
    assert!(w.is_empty(), "{w:?}");
    Arc::new(ns)
}

struct Rig {
    e: Engine,
    b: AsixBackend<Counting>,
    now: Timestamp,
    /// Read requests the engine made.
    engine_reads: usize,
}

impl Rig {
    fn new(by_channel: bool) -> Rig {
        let ns = namespace();
        Rig {
            e: Engine::new(EngineConfig::default(), ns.clone()),
            b: AsixBackend::from_source(
                ns,
                Counting {
                    by_channel,
                    reads: Vec::new(),
                    out: RawOutput::default(),
                },
            ),
            now: Timestamp::from_filetime_parts(0, 0x01DC_0000),
            engine_reads: 0,
        }
    }

    fn step(&mut self) {
        for _ in 0..4 {
            while let Some(r) = self.e.poll_source_request() {
                if matches!(r, SourceRequest::Read { .. }) {
                    self.engine_reads += 1;
                }
                self.b.request(self.now, r);
            }
            let mut out = SourceOutput::default();
            self.b.poll(self.now, &mut out);
            self.e.handle_source_updates(self.now, out.updates);
            for (id, r) in out.read_results {
                self.e.handle_source_read_result(self.now, id, r);
            }
            for (id, r) in out.write_results {
                self.e.handle_source_write_result(self.now, id, r);
            }
        }
    }

    /// A group with every variable of the database, active or not.
    fn group(&mut self, active: bool) -> (GroupHandle, Vec<u32>) {
        let s = self.e.open_session();
        let params = GroupParams {
            name: "",
            active,
            update_rate: 1000,
            ..Default::default()
        };
        let g = self.e.add_group(self.now, s, &params).unwrap().group;
        self.e.set_callback_connected(self.now, g, true).unwrap();
        let names: Vec<String> = (0..N).map(variable_name).collect();
        let defs: Vec<ItemDefinition> = names
            .iter()
            .enumerate()
            .map(|(i, id)| ItemDefinition {
                item_id: id,
                access_path: "",
                active,
                client_handle: i as u32,
                requested_type: VarType::EMPTY,
            })
            .collect();
        let handles = self
            .e
            .add_items(self.now, g, &defs)
            .unwrap()
            .into_iter()
            .map(|r| r.unwrap().server_handle)
            .collect();
        self.step();
        (g, handles)
    }

    fn device_reads(&self) -> usize {
        self.b.source().reads.len()
    }
}

#[test]
fn a_sync_device_read_of_10000_items_is_one_request_to_a_one_part_source() {
    for active in [true, false] {
        let mut r = Rig::new(false);
        let (g, h) = r.group(active);
        let before = (r.engine_reads, r.device_reads());
        let o = r.e.read(r.now, g, DataSource::Device, &h).unwrap();
        let SyncOutcome::Pending(id) = o else {
            panic!("a device read waits for the source");
        };
        r.step();
        let result = r.e.take_sync_result(id).expect("answered");
        assert_eq!(
            (r.engine_reads - before.0, r.device_reads() - before.1),
            (1, 1),
            "active {active}: one request from the engine, one to the source"
        );
        let last = r.b.source().reads.last().unwrap();
        assert_eq!(last.len(), N, "every variable in the one request");
        let _ = result;
    }
}

#[test]
fn a_device_read_goes_once_to_each_asix_channel() {
    let mut r = Rig::new(true);
    let (g, h) = r.group(true);
    let before = r.device_reads();
    let o = r.e.read(r.now, g, DataSource::Device, &h).unwrap();
    let SyncOutcome::Pending(id) = o else {
        panic!("a device read waits for the source");
    };
    r.step();
    assert!(r.e.take_sync_result(id).is_some());
    let reads = &r.b.source().reads[before..];
    // The synthetic database spreads its variables over channels K00..K99.
    assert_eq!(reads.len(), 100, "one request per asix channel");
    let channels: BTreeSet<&str> = reads.iter().map(|v| &*v[0].0).collect();
    assert_eq!(channels.len(), 100);
    assert!(reads.iter().all(|v| v.iter().all(|x| x.0 == v[0].0)));
    assert_eq!(reads.iter().map(Vec::len).sum::<usize>(), N);
}

#[test]
fn async_reads_of_10000_items_are_one_request_each() {
    let mut r = Rig::new(false);
    let (g, h) = r.group(true);
    let before = (r.engine_reads, r.device_reads());
    // IOPCAsyncIO2::Read and IOPCAsyncIO3::ReadMaxAge with MaxAge 0 (from the device).
    let started = r.e.async_read(r.now, g, 1, &h).unwrap();
    assert!(started.results.iter().all(Result::is_ok));
    r.step();
    let max_age: Vec<(u32, u32)> = h.iter().map(|&x| (x, 0)).collect();
    let started = r.e.async_read_max_age(r.now, g, 2, &max_age).unwrap();
    assert!(started.results.iter().all(Result::is_ok));
    r.step();
    assert_eq!(
        (r.engine_reads - before.0, r.device_reads() - before.1),
        (2, 2),
        "one request per call"
    );
}
