//! Test harness for the server model: a fake namespace, a fake data source and a simulated
//! clock that steps to `poll_timeout()` and drains events.
#![allow(dead_code)]

use std::collections::HashMap;
use std::sync::Arc;

use ctopc_core::model::*;
use ctopc_core::namespace::{EuInfo, ItemDef, Namespace, OPC_READABLE, OPC_WRITEABLE};
use ctopc_core::{OpcError, OpcResult, Quality, Timestamp, Value, VarType, Vqt};

/// Items:
/// - `A1`..: analog R8, EU 0..100, read/write
/// - `D1`..: R4 without EU info (OPC_NOENUM)
/// - `S1`..: BSTR
/// - `RO`: read-only R8
/// - `CONST`: constant R8 42.0 (database attribute)
/// - `alias.X`: the same source item as `X`
/// - `bad id`: invalid syntax; unknown IDs: OPC_E_UNKNOWNITEMID
///
/// Access paths: "" and "*" are the basic channel, "Camac" another; others unknown.
pub struct FakeNs;

impl Namespace for FakeNs {
    fn resolve(&self, item_id: &str, access_path: &str) -> OpcResult<ItemDef> {
        let channel = match access_path {
            "" | "*" => "*",
            "Camac" => "Camac",
            _ => return Err(OpcError::UnknownPath),
        };
        if item_id.contains(' ') {
            return Err(OpcError::InvalidItemId);
        }
        let id = item_id.strip_prefix("alias.").unwrap_or(item_id);
        let rw = OPC_READABLE | OPC_WRITEABLE;
        let def = |t: VarType, access: u32, eu: EuInfo, constant: Option<Value>| ItemDef {
            source_key: id.to_string(),
            channel: channel.to_string(),
            canonical_type: t,
            access_rights: access,
            eu,
            constant,
        };
        let analog = EuInfo::Analog {
            low: 0.0,
            high: 100.0,
        };
        match id {
            "RO" => Ok(def(VarType::R8, OPC_READABLE, analog, None)),
            "CONST" => Ok(def(
                VarType::R8,
                OPC_READABLE,
                EuInfo::None,
                Some(Value::R8(42.0)),
            )),
            "ARR" => Ok(def(VarType::array_of(VarType::R8), rw, analog, None)),
            _ if id.starts_with('A') && id[1..].parse::<u32>().is_ok() => {
                Ok(def(VarType::R8, rw, analog, None))
            }
            _ if id.starts_with('D') && id[1..].parse::<u32>().is_ok() => {
                Ok(def(VarType::R4, rw, EuInfo::None, None))
            }
            _ if id.starts_with('S') && id[1..].parse::<u32>().is_ok() => {
                Ok(def(VarType::BSTR, rw, EuInfo::None, None))
            }
            _ => Err(OpcError::UnknownItemId),
        }
    }

    /// `RO` on channel `Camac`: read-only by design (a source that takes no writes).
    fn write_refusal(&self, item_id: &str, access_path: &str) -> Option<String> {
        (item_id == "RO" && access_path == "Camac").then(|| "Camac takes no writes".to_owned())
    }
}

pub const T0: Timestamp = Timestamp::from_unix_millis(1_700_000_000_000);

pub fn ts(ms: u64) -> Timestamp {
    T0.add_millis(ms)
}

/// The engine plus a fake backend and a simulated clock.
pub struct Sim {
    pub e: Engine,
    pub now: Timestamp,
    /// Source keys by source item ID, from Subscribe (and Read/Write) requests.
    pub keys: HashMap<String, SourceKey>,
    /// Currently subscribed source items with their rate.
    pub subscribed: HashMap<String, u32>,
    /// Every request other than subscription management, in order.
    pub io: Vec<SourceRequest>,
    /// Every subscription request, in order.
    pub sub_log: Vec<SourceRequest>,
}

impl Sim {
    pub fn new() -> Sim {
        Sim::with_config(EngineConfig::default())
    }

    pub fn with_config(cfg: EngineConfig) -> Sim {
        Sim {
            e: Engine::new(cfg, Arc::new(FakeNs)),
            now: T0,
            keys: HashMap::new(),
            subscribed: HashMap::new(),
            io: Vec::new(),
            sub_log: Vec::new(),
        }
    }

    /// Runs every deadline up to `now + ms` (stepping to each `poll_timeout`), then sets the
    /// clock there.
    pub fn advance(&mut self, ms: u64) {
        let end = self.now.add_millis(ms);
        while let Some(t) = self.e.poll_timeout() {
            if t > end {
                break;
            }
            self.now = self.now.max(t);
            self.e.handle_timeout(self.now);
        }
        self.now = end;
        self.pump();
    }

    /// Runs what is due now.
    pub fn tick(&mut self) {
        self.advance(0);
    }

    pub fn events(&mut self) -> Vec<Event> {
        std::iter::from_fn(|| self.e.poll_event()).collect()
    }

    /// Subscription-callback (transaction 0) data changes only, as (client handle, value,
    /// quality) lists per callback.
    pub fn data_changes(&mut self) -> Vec<DataChange> {
        self.events()
            .into_iter()
            .filter_map(|e| match e {
                Event::DataChange(d) if d.kind == DataChangeKind::Subscription => Some(d),
                _ => None,
            })
            .collect()
    }

    /// Takes the engine's source requests into the fake backend.
    pub fn pump(&mut self) {
        while let Some(r) = self.e.poll_source_request() {
            match &r {
                SourceRequest::Subscribe(subs) => {
                    for s in subs {
                        self.keys.insert(s.item.item_id.to_string(), s.item.key);
                        self.subscribed
                            .insert(s.item.item_id.to_string(), s.sampling_rate_ms);
                    }
                    self.sub_log.push(r);
                }
                SourceRequest::SetSamplingRate(v) => {
                    for (k, rate) in v {
                        let id = self.id_of(*k);
                        self.subscribed.insert(id, *rate);
                    }
                    self.sub_log.push(r);
                }
                SourceRequest::Unsubscribe(v) => {
                    for k in v {
                        let id = self.id_of(*k);
                        self.subscribed.remove(&id);
                    }
                    self.sub_log.push(r);
                }
                SourceRequest::Read { items, .. } => {
                    for i in items.iter().filter_map(ReadItem::item) {
                        self.keys.insert(i.item_id.to_string(), i.key);
                    }
                    self.io.push(r);
                }
                SourceRequest::Write { items, .. } => {
                    for (i, _) in items {
                        self.keys.insert(i.item_id.to_string(), i.key);
                    }
                    self.io.push(r);
                }
                SourceRequest::WriteVqt { items, .. } => {
                    for (i, _) in items {
                        self.keys.insert(i.item_id.to_string(), i.key);
                    }
                    self.io.push(r);
                }
            }
        }
    }

    fn id_of(&self, k: SourceKey) -> String {
        self.keys
            .iter()
            .find(|(_, v)| **v == k)
            .map(|(id, _)| id.clone())
            .expect("known key")
    }

    /// The data source pushes a sample of a subscribed item.
    pub fn push(&mut self, id: &str, value: Value, quality: Quality) {
        self.pump();
        let key = *self
            .keys
            .get(id)
            .unwrap_or_else(|| panic!("{id} has no key"));
        let vqt = Vqt::new(value, quality, self.now);
        self.e.handle_source_updates(self.now, [(key, vqt)]);
    }

    pub fn push_good(&mut self, id: &str, x: f64) {
        self.push(id, Value::R8(x), Quality::GOOD);
    }

    /// The last device read request taken from the engine, its items whole (those sent
    /// by key as the engine has them).
    pub fn take_read(&mut self) -> (SourceReqId, Vec<SourceItem>) {
        let (req_id, items) = self.take_read_items();
        let items = items
            .into_iter()
            .map(|r| match r {
                ReadItem::Item(i) => i,
                ReadItem::Subscribed(k) => self.e.source_item(k).expect("a live key"),
            })
            .collect();
        (req_id, items)
    }

    /// The last device read request taken from the engine, as sent.
    pub fn take_read_items(&mut self) -> (SourceReqId, Vec<ReadItem>) {
        self.pump();
        let pos = self
            .io
            .iter()
            .rposition(|r| matches!(r, SourceRequest::Read { .. }))
            .expect("a read request");
        match self.io.remove(pos) {
            SourceRequest::Read { req_id, items } => (req_id, items),
            _ => unreachable!(),
        }
    }

    pub fn session(&mut self) -> SessionHandle {
        self.e.open_session()
    }

    /// An active group with the given rate and deadband, callback connected.
    pub fn group(&mut self, s: SessionHandle, name: &str, rate: u32, deadband: f32) -> GroupHandle {
        let r = self
            .e
            .add_group(
                self.now,
                s,
                &GroupParams {
                    name,
                    update_rate: rate,
                    percent_deadband: deadband,
                    client_handle: 7,
                    ..Default::default()
                },
            )
            .unwrap();
        self.e
            .set_callback_connected(self.now, r.group, true)
            .unwrap();
        r.group
    }

    /// Adds active items (client handle = index + 100); returns the server handles.
    pub fn items(&mut self, g: GroupHandle, ids: &[&str]) -> Vec<u32> {
        let defs: Vec<ItemDefinition> = ids
            .iter()
            .enumerate()
            .map(|(i, id)| ItemDefinition {
                item_id: id,
                access_path: "",
                active: true,
                client_handle: 100 + i as u32,
                requested_type: VarType::EMPTY,
            })
            .collect();
        let r = self.e.add_items(self.now, g, &defs).unwrap();
        self.pump();
        r.into_iter().map(|r| r.unwrap().server_handle).collect()
    }
}

/// (client handle, value) pairs of a callback.
pub fn values(d: &DataChange) -> Vec<(u32, Value)> {
    d.items
        .iter()
        .map(|i| (i.client_handle, i.value.clone()))
        .collect()
}
