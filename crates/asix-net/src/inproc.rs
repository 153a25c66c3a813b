//! Simulation of current data inside the server (the original's "symulacja danych
//! bieżących"): an in-process [`Backend`] driven by the same plant model as `asix-sim`,
//! with the asix item semantics applied on the way (derived items such as PercentageCV or
//! FormatedCV, the CheckLimits / CheckControlVariables quality rules, write checks).
//! The server reports OPC_STATUS_TEST while it is in use.
//!
//! Deterministic: the plant advances in fixed ticks computed from `now`; nothing here
//! reads a clock or blocks.
//!
//! A slow device (`SimulationDeviceDelay`, [`InProcessSim::with_device_delay`]): device
//! reads and writes are carried out when requested, but their answers are held until
//! `now + delay` and only then handed out by `poll` (and announced by `poll_timeout`), so
//! that the engine's source timeout and Cancel2 can be exercised. Subscriptions are not
//! delayed.

use crate::pipeline::{self, Resolution};
use crate::sim::plant::{channels_from_database, numeric, ChannelDef, Plant};
use asix_model::{AsixNamespace, Derivation};
use ctopc_core::model::datasource::{ItemVqt, SourceItem, SourceKey, SourceReqId, SourceRequest};
use ctopc_core::source::{Backend, SourceOutput};
use ctopc_core::{OpcError, Quality, Timestamp, Value, Vqt};
use std::sync::Arc;

/// Plant tick of the in-process simulation.
pub const TICK_MS: u64 = 250;
/// The plant channel of database variables that name no `Channel` attribute.
pub const DEFAULT_PLANT_CHANNEL: &str = "*";

/// A source item resolved once by the asix pipeline ([`crate::pipeline`]), with plant
/// variable indices as handles.
type Res = Resolution<u32>;

/// The shared resolutions of items without a plant variable: they differ only in how a
/// write is refused (unknown item, or a derived item that is never writable), so that many
/// distinct unknown items cost only their [`Slot`].
struct Unserved {
    not_live: Arc<Res>,
    value: Arc<Res>,
    derived: Arc<Res>,
}

impl Unserved {
    fn new() -> Unserved {
        Unserved {
            not_live: Arc::new(Resolution::NotLive),
            value: Arc::new(Resolution::NoVariable(Derivation::Value)),
            derived: Arc::new(Resolution::NoVariable(Derivation::Formatted(None))),
        }
    }
}

/// One source item known to the simulation, at its [`SourceKey::index`].
struct Slot {
    key: SourceKey,
    /// Sampling rate in ms; 0 when not subscribed (resolved for a read or write only).
    rate_ms: u32,
    next_due: Timestamp,
    r: Arc<Res>,
}

/// A device answer held back until its due time (see [`InProcessSim::with_device_delay`]).
enum Held {
    Read(SourceReqId, Vec<Result<Vqt, OpcError>>),
    Write(SourceReqId, Vec<Result<(), OpcError>>),
}

/// The in-process simulated data source.
pub struct InProcessSim {
    plant: Plant,
    epoch: Timestamp,
    ns: Arc<AsixNamespace>,
    /// Indexed by [`SourceKey::index`] (dense: the engine reuses freed indices).
    slots: Vec<Option<Slot>>,
    unserved: Unserved,
    /// No subscribed slot is due before this (the scan over the slots is skipped until
    /// then; every change that could make a slot due earlier lowers it).
    next_due: Option<Timestamp>,
    ready: SourceOutput,
    /// How long device reads and writes take to answer, ms (0: at once).
    device_delay_ms: u64,
    /// Answers not yet due, in request order, with their due times.
    held: Vec<(Timestamp, Held)>,
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
        InProcessSim {
            plant: Plant::new(&channels, seed, TICK_MS, now),
            epoch: now,
            ns,
            slots: Vec::new(),
            unserved: Unserved::new(),
            next_due: None,
            ready: SourceOutput::default(),
            device_delay_ms: 0,
            held: Vec::new(),
        }
    }

    /// A slow device: answers of device reads and writes (`SourceRequest::Read`, `Write`,
    /// `WriteVqt`) are released by `poll` only `delay_ms` after the request (0: at once,
    /// the default). The operation itself happens at request time: a read samples the
    /// plant then, a write sets the value then; only the answer is late.
    pub fn with_device_delay(mut self, delay_ms: u32) -> InProcessSim {
        self.device_delay_ms = u64::from(delay_ms);
        self
    }

    /// Hands a device answer out at the next `poll`, or holds it until it is due.
    fn answer(&mut self, now: Timestamp, answer: Held) {
        if self.device_delay_ms > 0 {
            self.held
                .push((now.add_millis(self.device_delay_ms), answer));
            return;
        }
        match answer {
            Held::Read(id, r) => self.ready.read_results.push((id, r)),
            Held::Write(id, r) => self.ready.write_results.push((id, r)),
        }
    }

    /// Moves the held answers due by `now` to `out`, in request order.
    fn release_due(&mut self, now: Timestamp, out: &mut SourceOutput) {
        if self.held.iter().all(|(due, _)| *due > now) {
            return;
        }
        let (due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut self.held)
            .into_iter()
            .partition(|(t, _)| *t <= now);
        self.held = later;
        for (_, answer) in due {
            match answer {
                Held::Read(id, r) => out.read_results.push((id, r)),
                Held::Write(id, r) => out.write_results.push((id, r)),
            }
        }
    }

    fn advance(&mut self, now: Timestamp) {
        let t = now.millis_since(self.epoch) / TICK_MS;
        if t > self.plant.tick() {
            self.plant.advance_to(t);
        }
    }

    /// The item's slot, resolved on first use (parsing the item ID and looking the
    /// variables up costs far more than the simulation itself); a slot left by an earlier
    /// item at the same index (older generation) is replaced.
    fn slot(&mut self, item: &SourceItem) -> &mut Slot {
        let i = item.key.index() as usize;
        if self.slots.len() <= i {
            if self.slots.capacity() <= i {
                // Grow by a quarter, not double (large configurations: see the engine's
                // source table).
                self.slots.reserve_exact(
                    (i + 1 - self.slots.len())
                        .max(self.slots.len() / 4)
                        .max(1024),
                );
            }
            self.slots.resize_with(i + 1, || None);
        }
        let key = item.key;
        let r = match &self.slots[i] {
            Some(s) if s.key == key => None,
            _ => Some(self.resolve(item)),
        };
        let entry = &mut self.slots[i];
        if let Some(r) = r {
            return entry.insert(Slot {
                key,
                rate_ms: 0,
                next_due: Timestamp(0),
                r,
            });
        }
        entry.get_or_insert_with(|| Slot {
            key,
            rate_ms: 0,
            next_due: Timestamp(0),
            r: Arc::clone(&self.unserved.not_live),
        })
    }

    fn resolve(&self, item: &SourceItem) -> Arc<Res> {
        let plant = &self.plant;
        match pipeline::resolve(&self.ns, item, |k| {
            plant
                .lookup(&k.channel, &k.variable)
                .and_then(|i| u32::try_from(i).ok())
        }) {
            Resolution::NotLive => Arc::clone(&self.unserved.not_live),
            Resolution::NoVariable(Derivation::Value) => Arc::clone(&self.unserved.value),
            Resolution::NoVariable(_) => Arc::clone(&self.unserved.derived),
            r @ Resolution::Resolved(_) => Arc::new(r),
        }
    }

    fn subscribe(&mut self, now: Timestamp, item: &SourceItem, rate_ms: u32) {
        let s = self.slot(item);
        s.rate_ms = rate_ms.max(1);
        s.next_due = now;
        self.next_due = Some(self.next_due.map_or(now, |t| t.min(now)));
    }

    /// The item's current VQT: the plant variable's, through the pipeline (quality rules
    /// over the plant's control and limit variables, derivation).
    fn sample(&self, r: &Res) -> Vqt {
        let Resolution::Resolved(r) = r else {
            // Not a variable of the plant: asix would answer "unknown item".
            return Vqt {
                value: Value::Empty,
                quality: Quality::BAD_CONFIG_ERROR,
                timestamp: self.plant.time_of(self.plant.tick()),
            };
        };
        r.sample(self.plant.vqt(r.key as usize), |&i| {
            Some(self.plant.vqt(i as usize))
        })
    }

    fn read(&mut self, item: &SourceItem) -> Result<Vqt, OpcError> {
        let r = Arc::clone(&self.slot(item).r);
        match *r {
            Resolution::Resolved(_) => Ok(self.sample(&r)),
            Resolution::NotLive | Resolution::NoVariable(_) => Err(OpcError::ItemUnknown),
        }
    }

    fn write(&mut self, item: &SourceItem, vqt: &ItemVqt) -> Result<(), OpcError> {
        let r = Arc::clone(&self.slot(item).r);
        let r = match &*r {
            Resolution::NotLive => return Err(OpcError::ItemUnknown),
            Resolution::NoVariable(d) => {
                pipeline::check_write(d, None, &vqt.value)?;
                return Err(OpcError::ItemUnknown);
            }
            Resolution::Resolved(r) => r,
        };
        r.check_write(&vqt.value)?;
        let var = r.key as usize;
        if !self.plant.vars()[var].spec.writable {
            return Err(OpcError::WriteErrorDeviceRequestIllegal);
        }
        let x = numeric(&vqt.value).ok_or(OpcError::BadType)?;
        self.plant.set(var, x, vqt.quality, vqt.timestamp);
        Ok(())
    }

    /// The slot of a key still current (same generation).
    fn slot_of(&mut self, key: SourceKey) -> Option<&mut Slot> {
        self.slots
            .get_mut(key.index() as usize)?
            .as_mut()
            .filter(|s| s.key == key)
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
                    if let Some(s) = self.slot_of(key).filter(|s| s.rate_ms != 0) {
                        s.rate_ms = rate.max(1);
                    }
                }
            }
            SourceRequest::Unsubscribe(keys) => {
                for k in keys {
                    if self.slot_of(k).is_some() {
                        self.slots[k.index() as usize] = None;
                    }
                }
            }
            SourceRequest::Read { req_id, items } => {
                let results = items.iter().map(|i| self.read(i)).collect::<Vec<_>>();
                self.answer(now, Held::Read(req_id, results));
            }
            SourceRequest::Write { req_id, items } => {
                let results = items
                    .iter()
                    .map(|(i, v)| self.write(i, &ItemVqt::value(v.clone())))
                    .collect();
                self.answer(now, Held::Write(req_id, results));
            }
            SourceRequest::WriteVqt { req_id, items } => {
                let results = items.iter().map(|(i, v)| self.write(i, v)).collect();
                self.answer(now, Held::Write(req_id, results));
            }
        }
    }

    fn poll(&mut self, now: Timestamp, out: &mut SourceOutput) {
        self.advance(now);
        let mut due = Vec::new();
        if self.next_due.is_some_and(|t| t <= now) {
            let mut next: Option<Timestamp> = None;
            for s in self.slots.iter_mut().flatten().filter(|s| s.rate_ms != 0) {
                if s.next_due <= now {
                    // Keep the phase; skip missed periods instead of bursting.
                    while s.next_due <= now {
                        s.next_due = s.next_due.add_millis(u64::from(s.rate_ms));
                    }
                    due.push((s.key, Arc::clone(&s.r)));
                }
                next = Some(next.map_or(s.next_due, |t| t.min(s.next_due)));
            }
            self.next_due = next;
        }
        out.updates.reserve(due.len());
        for (key, r) in due {
            out.updates.push((key, self.sample(&r)));
        }
        let ready = std::mem::take(&mut self.ready);
        out.updates.extend(ready.updates);
        out.read_results.extend(ready.read_results);
        out.write_results.extend(ready.write_results);
        self.release_due(now, out);
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        if !self.ready.is_empty() {
            return Some(Timestamp(0));
        }
        let held = self.held.iter().map(|(due, _)| *due).min();
        match (held, self.next_due) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    fn is_simulation(&self) -> bool {
        true
    }
}
