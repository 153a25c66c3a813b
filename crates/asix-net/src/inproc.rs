//! Simulation of current data inside the server (the original's "symulacja danych
//! bieżących"): an in-process [`Backend`] driven by the same plant model as `asix-sim`,
//! with the asix item semantics applied on the way (derived items such as PercentageCV or
//! FormatedCV, the CheckLimits / CheckControlVariables quality rules, write checks).
//! The server reports OPC_STATUS_TEST while it is in use.
//!
//! Deterministic: the plant advances in fixed ticks computed from `now`; nothing here
//! reads a clock or blocks.

use crate::sim::plant::{channels_from_database, numeric, ChannelDef, Plant};
use ctopc_core::asix::{apply_quality_rules_with, check_write_value, AsixNamespace, Derivation, LiveItem, RuleOptions, Variable};
use ctopc_core::model::datasource::{ItemVqt, SourceItem, SourceKey, SourceRequest};
use ctopc_core::source::{Backend, SourceOutput};
use ctopc_core::{OpcError, Quality, Timestamp, Value, Vqt};
use std::collections::HashMap;
use std::sync::Arc;

/// Plant tick of the in-process simulation.
pub const TICK_MS: u64 = 250;
/// The plant channel of database variables that name no `Channel` attribute.
pub const DEFAULT_PLANT_CHANNEL: &str = "*";

/// A source item resolved once: its asix item, plant variable, control variable and rules.
struct Resolved {
    /// Plant variable index; `None` for a variable the plant does not know.
    var: Option<usize>,
    live: Option<LiveItem>,
    control: Option<usize>,
    rules: RuleOptions,
}

struct Sub {
    r: Arc<Resolved>,
    rate_ms: u32,
    next_due: Timestamp,
}

/// Resolutions kept at most (keys carry a generation, so a stale entry never matches a
/// reused slot; the cache is simply cleared when it grows beyond this).
const MAX_RESOLVED: usize = 1_000_000;

/// The in-process simulated data source.
pub struct InProcessSim {
    plant: Plant,
    epoch: Timestamp,
    ns: Arc<AsixNamespace>,
    subs: HashMap<SourceKey, Sub>,
    resolved: HashMap<SourceKey, Arc<Resolved>>,
    ready: SourceOutput,
}

impl InProcessSim {
    /// A plant with every variable of every loaded database (channels from the `Channel`
    /// attribute, else `*`), seeded deterministically, starting at `now`.
    pub fn new(ns: Arc<AsixNamespace>, seed: u64, now: Timestamp) -> InProcessSim {
        let mut channels: Vec<ChannelDef> = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for name in ns.config().channels.keys() {
            if let Some(db) = ns.database(name) {
                if seen.insert(Arc::as_ptr(db)) {
                    channels.extend(channels_from_database(db, DEFAULT_PLANT_CHANNEL));
                }
            }
        }
        InProcessSim { plant: Plant::new(&channels, seed, TICK_MS, now), epoch: now, ns, subs: HashMap::new(), resolved: HashMap::new(), ready: SourceOutput::default() }
    }

    fn advance(&mut self, now: Timestamp) {
        let t = now.millis_since(self.epoch) / TICK_MS;
        if t > self.plant.tick() {
            self.plant.advance_to(t);
        }
    }

    fn find_var(&self, asmen_channel: Option<&str>, variable: &str) -> Option<usize> {
        match asmen_channel {
            Some(ch) => self.plant.lookup(ch, variable),
            None => self.plant.channels().iter().find_map(|ch| self.plant.lookup(ch, variable)),
        }
    }

    fn rules_for(&self, channel: &str) -> RuleOptions {
        match self.ns.config().resolve_channel(channel) {
            Ok(r) => RuleOptions::from(r.options),
            Err(_) => RuleOptions::default(),
        }
    }

    /// The item's resolution, computed on first use (parsing the item ID and looking the
    /// variables up costs far more than the simulation itself).
    fn resolve(&mut self, item: &SourceItem) -> Arc<Resolved> {
        if let Some(r) = self.resolved.get(&item.key) {
            return Arc::clone(r);
        }
        let live = self.ns.live_item(&item.channel, &item.item_id);
        let var = live.as_ref().and_then(|l| self.find_var(l.asmen_channel.as_deref(), &l.variable));
        let control = live
            .as_ref()
            .and_then(|l| l.definition.as_ref())
            .and_then(|d| d.control_variable.as_deref())
            .and_then(|c| self.find_var(None, c));
        let r = Arc::new(Resolved { var, live, control, rules: self.rules_for(&item.channel) });
        if self.resolved.len() >= MAX_RESOLVED {
            self.resolved.clear();
        }
        self.resolved.insert(item.key, Arc::clone(&r));
        r
    }

    fn subscribe(&mut self, now: Timestamp, item: &SourceItem, rate_ms: u32) {
        let r = self.resolve(item);
        self.subs.insert(item.key, Sub { r, rate_ms: rate_ms.max(1), next_due: now });
    }

    /// The item's current VQT: the plant variable's, derived and with the quality rules.
    fn sample(&self, var: Option<usize>, live: Option<&LiveItem>, control: Option<usize>, rules: RuleOptions) -> Vqt {
        let (Some(i), Some(live)) = (var, live) else {
            // Not a variable of the plant: asix would answer "unknown item".
            return Vqt { value: Value::Empty, quality: Quality::BAD_CONFIG_ERROR, timestamp: self.plant.time_of(self.plant.tick()) };
        };
        let raw = self.plant.vqt(i);
        let control_value = control.map(|c| self.plant.vqt(c).value);
        let quality = match &live.definition {
            // Limits held as variable names (asix limit variables) read the plant's values.
            Some(def) => apply_quality_rules_with(def, &raw.value, raw.quality, control_value.as_ref(), rules, &|name| {
                self.find_var(None, name).and_then(|v| self.plant.vqt(v).value.as_f64())
            }),
            None => raw.quality,
        };
        match live.derivation.apply(&raw.value) {
            Some(value) => Vqt { value, quality, timestamp: raw.timestamp },
            None => Vqt { value: Value::Empty, quality: Quality::BAD_CONFIG_ERROR, timestamp: raw.timestamp },
        }
    }

    fn read(&mut self, item: &SourceItem) -> Result<Vqt, OpcError> {
        let r = self.resolve(item);
        if r.live.is_none() || r.var.is_none() {
            return Err(OpcError::ItemUnknown);
        }
        Ok(self.sample(r.var, r.live.as_ref(), r.control, r.rules))
    }

    fn write(&mut self, item: &SourceItem, vqt: &ItemVqt) -> Result<(), OpcError> {
        let r = self.resolve(item);
        let live = r.live.as_ref().ok_or(OpcError::ItemUnknown)?;
        if live.derivation != Derivation::Value {
            return Err(OpcError::BadRights);
        }
        check_write_value(&vqt.value)?;
        let var = r.var.ok_or(OpcError::ItemUnknown)?;
        let writable = live.definition.as_ref().is_none_or(|d: &Variable| d.writable) && self.plant.vars()[var].spec.writable;
        if !writable {
            return Err(OpcError::WriteErrorDeviceRequestIllegal);
        }
        let x = numeric(&vqt.value).ok_or(OpcError::BadType)?;
        self.plant.set(var, x, vqt.quality, vqt.timestamp);
        Ok(())
    }
}

impl Backend for InProcessSim {
    fn request(&mut self, now: Timestamp, req: SourceRequest) {
        self.advance(now);
        match req {
            SourceRequest::Subscribe(subs) => {
                for s in subs {
                    self.subscribe(now, &s.item, s.sampling_rate_ms);
                }
            }
            SourceRequest::SetSamplingRate(rates) => {
                for (key, rate) in rates {
                    if let Some(s) = self.subs.get_mut(&key) {
                        s.rate_ms = rate.max(1);
                    }
                }
            }
            SourceRequest::Unsubscribe(keys) => {
                for k in keys {
                    self.subs.remove(&k);
                    self.resolved.remove(&k);
                }
            }
            SourceRequest::Read { req_id, items } => {
                let results = items.iter().map(|i| self.read(i)).collect::<Vec<_>>();
                self.ready.read_results.push((req_id, results));
            }
            SourceRequest::Write { req_id, items } => {
                let results = items.iter().map(|(i, v)| self.write(i, &ItemVqt::value(v.clone()))).collect();
                self.ready.write_results.push((req_id, results));
            }
            SourceRequest::WriteVqt { req_id, items } => {
                let results = items.iter().map(|(i, v)| self.write(i, v)).collect();
                self.ready.write_results.push((req_id, results));
            }
        }
    }

    fn poll(&mut self, now: Timestamp, out: &mut SourceOutput) {
        self.advance(now);
        let mut due = Vec::new();
        for (key, s) in self.subs.iter_mut() {
            if s.next_due <= now {
                due.push(*key);
                // Keep the phase; skip missed periods instead of bursting.
                while s.next_due <= now {
                    s.next_due = s.next_due.add_millis(u64::from(s.rate_ms));
                }
            }
        }
        for key in due {
            if let Some(s) = self.subs.get(&key) {
                let vqt = self.sample(s.r.var, s.r.live.as_ref(), s.r.control, s.r.rules);
                out.updates.push((key, vqt));
            }
        }
        let ready = std::mem::take(&mut self.ready);
        out.updates.extend(ready.updates);
        out.read_results.extend(ready.read_results);
        out.write_results.extend(ready.write_results);
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        if !self.ready.is_empty() {
            return Some(Timestamp(0));
        }
        self.subs.values().map(|s| s.next_due).min()
    }

    fn is_simulation(&self) -> bool {
        true
    }
}
