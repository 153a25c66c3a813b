//! Monitored items of the Value attribute as items of engine groups.
//!
//! Every variable monitored by any UA client is one item of one engine group of the
//! front end's session: the group of the fastest sampling interval any monitored item of
//! that variable asks for (one group per rate, made on first use, active, callbacks
//! connected, no deadband). So the variable has one source subscription whichever UA
//! clients (and, through the engine's shared cache, DA clients) ask for it. The engine
//! reports each change at the group's rate ([`UaSink`]); the subscription cache of
//! async-opcua hands it to every monitored item of that node, applying each item's own
//! filter (DataChangeFilter with absolute or percent deadband), queue size and discard
//! policy.
//!
//! Locks: the monitor's table is taken before the runtime's `driver` lock (placing an
//! item calls the engine with the table held); the sink takes only the table, on a
//! runtime callback worker, which holds no runtime lock.

use crate::status::quality_to_status;
use crate::value::{timestamp_to_ua, to_variant};
use ctopc_core::compact::IntHasher;
use ctopc_core::model::{
    DataChangeKind, Event, GroupHandle, GroupParams, ItemDefinition, ItemState,
};
use ctopc_core::{OpcError, VarType};
use ctopc_runtime::{Delivery, GroupSink, Runtime};
use opcua::types::{AttributeId, DataValue, NodeId, UAString};
use std::collections::{BTreeMap, HashMap};
use std::hash::BuildHasherDefault;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

use crate::engine::EngineClient;

/// A DA item state as a UA data value.
pub fn state_to_data_value(s: &ItemState) -> DataValue {
    let now = opcua::types::DateTime::now();
    DataValue {
        value: Some(to_variant(&s.value)),
        status: Some(quality_to_status(s.quality)),
        source_timestamp: Some(timestamp_to_ua(s.timestamp)),
        source_picoseconds: None,
        server_timestamp: Some(now),
        server_picoseconds: None,
    }
}

/// Where data changes go: async-opcua's subscription cache (the server), or a test's
/// recorder.
pub trait Notify: Send + Sync {
    /// Changes of the Value attribute of nodes.
    fn data_changes(&self, changes: Vec<(NodeId, DataValue)>);
}

impl Notify for opcua::server::SubscriptionCache {
    fn data_changes(&self, changes: Vec<(NodeId, DataValue)>) {
        let (ids, values): (Vec<NodeId>, Vec<DataValue>) = changes.into_iter().unzip();
        self.notify_data_change(
            values
                .into_iter()
                .zip(&ids)
                .map(|(dv, id)| (dv, id, AttributeId::Value)),
        );
    }
}

#[derive(Default)]
struct Node {
    /// The client handle of the variable's engine item (the same in every group).
    client: u32,
    /// The sampling rates its monitored items ask for, fastest first, with how many ask
    /// for each (most variables have one: a small vector, not a tree, per variable).
    rates: Vec<(u32, u32)>,
    /// The group (by rate) and server handle it is an item of.
    placed: Option<(u32, u32)>,
}

impl Node {
    /// One monitored item at `rate` ms more.
    fn acquire(&mut self, rate: u32) {
        match self.rates.binary_search_by_key(&rate, |&(r, _)| r) {
            Ok(i) => self.rates[i].1 += 1,
            Err(i) => self.rates.insert(i, (rate, 1)),
        }
    }

    /// One monitored item at `rate` ms fewer (the rate gone with its last one).
    fn release(&mut self, rate: u32) {
        if let Ok(i) = self.rates.binary_search_by_key(&rate, |&(r, _)| r) {
            self.rates[i].1 -= 1;
            if self.rates[i].1 == 0 {
                self.rates.remove(i);
            }
        }
    }

    /// The fastest rate asked for: the group the variable belongs in.
    fn fastest(&self) -> Option<u32> {
        self.rates.first().map(|&(r, _)| r)
    }
}

#[derive(Default)]
struct State {
    groups: HashMap<u32, GroupHandle>,
    nodes: HashMap<String, Node>,
    /// By the engine item's client handle (ours: a multiplicative hash, not SipHash, on
    /// every data change).
    by_client: HashMap<u32, String, BuildHasherDefault<IntHasher>>,
    next_client: u32,
}

/// The monitored items of every UA session, over the front end's engine session.
pub struct Monitor {
    ns: u16,
    client: Arc<EngineClient>,
    /// The engine's minimum update rate (ms), fixed for the process.
    min_rate_ms: u32,
    /// async-opcua's subscription cache (known once the server is built).
    subscriptions: OnceLock<Arc<dyn Notify>>,
    state: Mutex<State>,
    me: std::sync::Weak<Monitor>,
}

fn lock(m: &Mutex<State>) -> MutexGuard<'_, State> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Monitor {
    pub fn new(ns: u16, client: Arc<EngineClient>) -> Arc<Monitor> {
        let min_rate_ms = client.runtime.lock().engine.config().min_update_rate_ms;
        Arc::new_cyclic(|me| Monitor {
            ns,
            client,
            min_rate_ms,
            subscriptions: OnceLock::new(),
            state: Mutex::new(State::default()),
            me: me.clone(),
        })
    }

    pub fn set_subscriptions(&self, cache: Arc<dyn Notify>) {
        let _ = self.subscriptions.set(cache);
    }

    fn runtime(&self) -> &Arc<Runtime> {
        &self.client.runtime
    }

    /// The engine's revision of a sampling interval (ms): at least its minimum update rate.
    pub fn revise(&self, sampling_ms: f64) -> u32 {
        let min = self.min_rate_ms;
        let ms = if sampling_ms.is_finite() && sampling_ms > 0.0 {
            sampling_ms.min(f64::from(u32::MAX)) as u32
        } else {
            0
        };
        ms.max(min)
    }

    /// A monitored item of `item_id` at `rate` ms was created: the variable is (or stays)
    /// an item of the group of its fastest rate. `Err`: the engine refused the item.
    pub fn add(&self, item_id: &str, rate: u32) -> Result<(), OpcError> {
        let mut st = lock(&self.state);
        let st = &mut *st;
        let node = st.nodes.entry(item_id.to_owned()).or_default();
        if node.rates.is_empty() {
            st.next_client = st.next_client.wrapping_add(1);
            node.client = st.next_client;
            st.by_client.insert(node.client, item_id.to_owned());
        }
        node.acquire(rate);
        let r = self.place(st, item_id);
        if r.is_err() {
            self.remove_locked(st, item_id, rate);
        }
        r
    }

    /// Monitored items created together, `(item ID, rate ms)` each: as [`Monitor::add`] of
    /// each in turn, but the variables newly placed in a group are added to it in one
    /// engine call (one lock of the engine, one source subscription request), not one
    /// call per item.
    pub fn add_many(&self, items: &[(&str, u32)]) -> Vec<Result<(), OpcError>> {
        let mut st = lock(&self.state);
        let st = &mut *st;
        for &(item_id, rate) in items {
            let node = st.nodes.entry(item_id.to_owned()).or_default();
            if node.rates.is_empty() {
                st.next_client = st.next_client.wrapping_add(1);
                node.client = st.next_client;
                st.by_client.insert(node.client, item_id.to_owned());
            }
            node.acquire(rate);
        }
        // The variables to place (each once), by the rate of the group they go to.
        let mut by_rate: BTreeMap<u32, Vec<&str>> = BTreeMap::new();
        let mut seen = std::collections::HashSet::new();
        for &(item_id, _) in items {
            if !seen.insert(item_id) {
                continue;
            }
            let node = &st.nodes[item_id];
            let Some(want) = node.fastest() else {
                continue;
            };
            if node.placed.is_some_and(|(r, _)| r == want) {
                continue;
            }
            by_rate.entry(want).or_default().push(item_id);
        }
        let mut failed: HashMap<&str, OpcError> = HashMap::new();
        for (rate, ids) in by_rate {
            if let Err(e) = self.place_many(st, rate, &ids, &mut failed) {
                failed.extend(ids.iter().map(|id| (*id, e)));
            }
        }
        items
            .iter()
            .map(|&(item_id, rate)| match failed.get(item_id) {
                Some(&e) => {
                    self.remove_locked(st, item_id, rate);
                    Err(e)
                }
                None => Ok(()),
            })
            .collect()
    }

    /// Places the variables `ids` (rates already counted) in the group of `rate` ms with
    /// one engine call; the variables the engine refused go to `failed`.
    fn place_many<'a>(
        &self,
        st: &mut State,
        rate: u32,
        ids: &[&'a str],
        failed: &mut HashMap<&'a str, OpcError>,
    ) -> Result<(), OpcError> {
        let group = self.group(st, rate)?;
        let defs: Vec<ItemDefinition<'_>> = ids
            .iter()
            .map(|id| ItemDefinition {
                item_id: id,
                access_path: "",
                active: true,
                client_handle: st.nodes[*id].client,
                requested_type: VarType::EMPTY,
            })
            .collect();
        let added = self
            .runtime()
            .with_engine(|e, now| e.add_items(now, group, &defs))?;
        for (i, id) in ids.iter().enumerate() {
            match added.get(i) {
                Some(Ok(r)) => {
                    let old = st
                        .nodes
                        .get_mut(*id)
                        .and_then(|node| node.placed.replace((rate, r.server_handle)));
                    if let Some((old_rate, handle)) = old {
                        self.unplace(st, old_rate, handle);
                    }
                }
                Some(Err(e)) => {
                    failed.insert(*id, *e);
                }
                None => {
                    failed.insert(*id, OpcError::Fail);
                }
            }
        }
        Ok(())
    }

    /// A monitored item of `item_id` at `rate` ms was deleted.
    pub fn remove(&self, item_id: &str, rate: u32) {
        let mut st = lock(&self.state);
        self.remove_locked(&mut st, item_id, rate);
    }

    /// Monitored items deleted together, `(item ID, rate ms)` each: as [`Monitor::remove`]
    /// of each in turn, but the engine items of the variables no item monitors any more
    /// are removed in one engine call per group, not one call per item.
    pub fn remove_many(&self, items: &[(&str, u32)]) {
        let mut st = lock(&self.state);
        let st = &mut *st;
        let mut gone: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
        let mut moved = Vec::new();
        for &(item_id, rate) in items {
            let Some(node) = st.nodes.get_mut(item_id) else {
                continue;
            };
            node.release(rate);
            if !node.rates.is_empty() {
                moved.push(item_id);
                continue;
            }
            if let Some(node) = st.nodes.remove(item_id) {
                st.by_client.remove(&node.client);
                if let Some((rate, handle)) = node.placed {
                    gone.entry(rate).or_default().push(handle);
                }
            }
        }
        for (rate, handles) in gone {
            if let Some(&g) = st.groups.get(&rate) {
                let _ = self
                    .runtime()
                    .with_engine(|e, now| e.remove_items(now, g, &handles));
            }
        }
        for item_id in moved {
            if st.nodes.contains_key(item_id) {
                if let Err(e) = self.place(st, item_id) {
                    tracing::warn!("OPC UA: cannot move {item_id} to another group: {e}");
                }
            }
        }
    }

    /// A monitored item's rate changed.
    pub fn change(&self, item_id: &str, from: u32, to: u32) {
        if from == to {
            return;
        }
        let mut st = lock(&self.state);
        let st = &mut *st;
        let Some(node) = st.nodes.get_mut(item_id) else {
            return;
        };
        node.release(from);
        node.acquire(to);
        if let Err(e) = self.place(st, item_id) {
            tracing::warn!("OPC UA: cannot move {item_id} to a {to} ms group: {e}");
        }
    }

    /// The number of variables monitored (each is one engine item).
    pub fn variables(&self) -> usize {
        lock(&self.state).nodes.len()
    }

    fn remove_locked(&self, st: &mut State, item_id: &str, rate: u32) {
        let Some(node) = st.nodes.get_mut(item_id) else {
            return;
        };
        node.release(rate);
        if !node.rates.is_empty() {
            if let Err(e) = self.place(st, item_id) {
                tracing::warn!("OPC UA: cannot move {item_id} to another group: {e}");
            }
            return;
        }
        if let Some(node) = st.nodes.remove(item_id) {
            st.by_client.remove(&node.client);
            if let Some((rate, handle)) = node.placed {
                self.unplace(st, rate, handle);
            }
        }
    }

    fn unplace(&self, st: &State, rate: u32, handle: u32) {
        if let Some(&g) = st.groups.get(&rate) {
            let _ = self
                .runtime()
                .with_engine(|e, now| e.remove_items(now, g, &[handle]));
        }
    }

    /// Makes the variable an item of the group of its fastest rate.
    fn place(&self, st: &mut State, item_id: &str) -> Result<(), OpcError> {
        let (want, client, placed) = {
            let node = &st.nodes[item_id];
            let Some(want) = node.fastest() else {
                return Ok(());
            };
            (want, node.client, node.placed)
        };
        if placed.is_some_and(|(r, _)| r == want) {
            return Ok(());
        }
        let group = self.group(st, want)?;
        let def = ItemDefinition {
            item_id,
            access_path: "",
            active: true,
            client_handle: client,
            requested_type: VarType::EMPTY,
        };
        let added = self
            .runtime()
            .with_engine(|e, now| e.add_items(now, group, std::slice::from_ref(&def)))?;
        let handle = match added.into_iter().next() {
            Some(Ok(r)) => r.server_handle,
            Some(Err(e)) => return Err(e),
            None => return Err(OpcError::Fail),
        };
        if let Some((rate, old)) = placed {
            self.unplace(st, rate, old);
        }
        if let Some(node) = st.nodes.get_mut(item_id) {
            node.placed = Some((want, handle));
        }
        Ok(())
    }

    /// The group of `rate` ms, made (active, callbacks connected) on first use.
    fn group(&self, st: &mut State, rate: u32) -> Result<GroupHandle, OpcError> {
        if let Some(&g) = st.groups.get(&rate) {
            return Ok(g);
        }
        let session = self.client.session;
        let name = format!("OPC UA {rate} ms");
        let params = GroupParams {
            name: &name,
            active: true,
            update_rate: rate,
            ..GroupParams::default()
        };
        let added = self
            .runtime()
            .with_engine(|e, now| e.add_group(now, session, &params))?;
        let g = added.group;
        let sink: Arc<dyn GroupSink> = Arc::new(UaSink {
            monitor: self.me.clone(),
        });
        self.runtime().set_group_sink(g, sink);
        self.runtime()
            .with_engine(|e, now| e.set_callback_connected(now, g, true))?;
        st.groups.insert(rate, g);
        Ok(g)
    }

    /// Hands a data change of the engine to the subscription cache.
    fn notify(&self, event: &Event) {
        let Event::DataChange(dc) = event else { return };
        if dc.kind == DataChangeKind::KeepAlive || dc.items.is_empty() {
            return;
        }
        let Some(cache) = self.subscriptions.get() else {
            return;
        };
        let changes: Vec<(NodeId, DataValue)> = {
            let st = lock(&self.state);
            dc.items
                .iter()
                .filter_map(|it| {
                    let item_id = st.by_client.get(&it.client_handle)?;
                    let mut dv = state_to_data_value(&ItemState {
                        client_handle: it.client_handle,
                        value: it.value.clone(),
                        quality: it.quality,
                        timestamp: it.timestamp,
                    });
                    if let Some(e) = it.error {
                        dv.value = None;
                        dv.status = Some(crate::status::error_to_status(e, false));
                    }
                    Some((NodeId::new(self.ns, UAString::from(item_id.as_str())), dv))
                })
                .collect()
        };
        if !changes.is_empty() {
            cache.data_changes(changes);
        }
    }
}

/// A group's sink: the engine's callbacks go to async-opcua's subscription cache, which
/// never blocks (the publish requests take them from there).
struct UaSink {
    monitor: std::sync::Weak<Monitor>,
}

impl GroupSink for UaSink {
    fn deliver(&self, _group: GroupHandle, event: Event) -> Delivery {
        match self.monitor.upgrade() {
            Some(m) => {
                m.notify(&event);
                Delivery {
                    called: true,
                    lost: false,
                }
            }
            None => Delivery {
                called: false,
                lost: true,
            },
        }
    }

    fn is_connected(&self) -> bool {
        self.monitor.strong_count() > 0
    }

    fn drop_listener(&self) -> bool {
        false
    }
}
