//! Simulation of current data inside the server (the original's "symulacja danych
//! bieżących"): the plant model of `asix-sim` ([`Plant`]) as a raw [`VariableSource`], under
//! the one asix adapter ([`AsixBackend`]), which applies the asix item semantics on the way
//! (derived items such as PercentageCV or FormatedCV, the CheckLimits /
//! CheckControlVariables quality rules, write checks). The server reports OPC_STATUS_TEST
//! while it is in use.
//!
//! Deterministic: the plant advances in fixed ticks computed from `now`; nothing here
//! reads a clock or blocks.
//!
//! A slow device (`SimulationDeviceDelay`, [`InProcessSim::with_device_delay`]): device
//! reads and writes are carried out when requested, but their answers are held until
//! `now + delay` and only then handed out by `poll` (and announced by `poll_timeout`), so
//! that the engine's source timeout and Cancel2 can be exercised. Subscriptions are not
//! delayed.

use crate::backend::{AsixBackend, RawId, RawOutput, VariableSource};
use crate::client::ItemKey;
use crate::sim::plant::{numeric, Plant};
use asix_model::AsixNamespace;
use ctopc_core::model::datasource::ItemVqt;
use ctopc_core::{OpcError, Timestamp, Vqt};
use std::sync::Arc;

/// Plant tick of the in-process simulation.
pub const TICK_MS: u64 = 250;
/// The plant channel of database variables that name no `Channel` attribute.
pub const DEFAULT_PLANT_CHANNEL: &str = "*";

/// The in-process simulated data source: the adapter over the plant.
pub type InProcessSim = AsixBackend<PlantSource>;

impl AsixBackend<PlantSource> {
    /// A plant with every variable of every loaded database (channels from the `Channel`
    /// attribute, else `*`), seeded deterministically, starting at `now`.
    pub fn new(ns: Arc<AsixNamespace>, seed: u64, now: Timestamp) -> InProcessSim {
        let source = PlantSource::new(&ns, seed, now);
        AsixBackend::from_source(ns, source)
    }

    /// A slow device: answers of device reads and writes (`SourceRequest::Read`, `Write`,
    /// `WriteVqt`) are released by `poll` only `delay_ms` after the request (0: at once,
    /// the default). The operation itself happens at request time: a read samples the
    /// plant then, a write sets the value then; only the answer is late.
    pub fn with_device_delay(mut self, delay_ms: u32) -> InProcessSim {
        self.source_mut().device_delay_ms = u64::from(delay_ms);
        self
    }
}

/// A device answer held back until its due time (see [`InProcessSim::with_device_delay`]).
/// A subscribed plant variable: its sampling rate in ms and when it is next due.
#[derive(Debug, Clone, Copy)]
struct Sampled {
    var: u32,
    rate: u32,
    due: Timestamp,
}

enum Held {
    Read(RawId, Vec<Result<Vqt, OpcError>>),
    Write(RawId, Vec<Result<(), OpcError>>),
}

/// The plant as a raw variable source; variables are plant indices.
pub struct PlantSource {
    plant: Plant,
    epoch: Timestamp,
    /// Per subscribed plant variable, in variable order: its sampling rate in ms and when
    /// it is next due. Each variable keeps its phase; missed periods are skipped, not
    /// burst. Only subscribed variables have an entry (a million-variable plant costs
    /// nothing here until subscribed). A sorted vector, 16 bytes a variable (a B-tree
    /// map cost ~40, issue 16).
    sampling: Vec<Sampled>,
    /// No variable is due before this (the scan is skipped until then).
    next_due: Option<Timestamp>,
    /// How long device reads and writes take to answer, ms (0: at once).
    device_delay_ms: u64,
    /// Answers not yet due, in request order, with their due times.
    held: Vec<(Timestamp, Held)>,
    ready: RawOutput<u32>,
}

impl PlantSource {
    /// A plant with every variable of every loaded database of `ns` (channels from the
    /// `Channel` attribute, else `*`), seeded deterministically, starting at `now`.
    pub fn new(ns: &AsixNamespace, seed: u64, now: Timestamp) -> PlantSource {
        let dbs: Vec<Arc<asix_model::VarDatabase>> = ns.databases().cloned().collect();
        let plant = Plant::from_databases(&dbs, DEFAULT_PLANT_CHANNEL, seed, TICK_MS, now);
        PlantSource {
            sampling: Vec::new(),
            plant,
            epoch: now,
            next_due: None,
            device_delay_ms: 0,
            held: Vec::new(),
            ready: RawOutput::default(),
        }
    }

    /// The plant.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    fn advance(&mut self, now: Timestamp) {
        let t = now.millis_since(self.epoch) / TICK_MS;
        if t > self.plant.tick() {
            self.plant.advance_to(t);
        }
    }

    /// Hands a device answer out at the next `poll`, or holds it until it is due.
    fn answer(&mut self, now: Timestamp, answer: Held) {
        if self.device_delay_ms > 0 {
            self.held
                .push((now.add_millis(self.device_delay_ms), answer));
            return;
        }
        match answer {
            Held::Read(id, r) => self.ready.reads.push((id, r)),
            Held::Write(id, r) => self.ready.writes.push((id, r)),
        }
    }

    /// Moves the held answers due by `now` to `out`, in request order.
    fn release_due(&mut self, now: Timestamp, out: &mut RawOutput<u32>) {
        if self.held.iter().all(|(due, _)| *due > now) {
            return;
        }
        let (due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut self.held)
            .into_iter()
            .partition(|(t, _)| *t <= now);
        self.held = later;
        for (_, answer) in due {
            match answer {
                Held::Read(id, r) => out.reads.push((id, r)),
                Held::Write(id, r) => out.writes.push((id, r)),
            }
        }
    }

    fn write_one(&mut self, var: u32, v: &ItemVqt) -> Result<(), OpcError> {
        let var = var as usize;
        if !self.plant.vars()[var].spec().writable {
            return Err(OpcError::WriteErrorDeviceRequestIllegal);
        }
        let x = numeric(&v.value).ok_or(OpcError::BadType)?;
        self.plant.set(var, x, v.quality, v.timestamp);
        Ok(())
    }
}

impl VariableSource for PlantSource {
    type Var = u32;
    type Part = ();

    fn lookup(&self, _channel: &Arc<str>, key: &ItemKey) -> Option<u32> {
        self.plant
            .lookup(&key.channel, &key.variable)
            .and_then(|i| u32::try_from(i).ok())
    }

    fn part(&self, _var: &u32) {}

    /// The simulation is one "channel" that answers for all: `Simulation`, LinkState 2.
    fn channels(
        &self,
        subscribed: &mut dyn Iterator<Item = &u32>,
    ) -> Vec<ctopc_core::diagnostics::ChannelStatus> {
        vec![ctopc_core::diagnostics::ChannelStatus {
            name: "Simulation".to_owned(),
            link: ctopc_core::diagnostics::LinkState::Simulation,
            server: "in-process simulation".to_owned(),
            subscriptions: subscribed.count() as u64,
            ..Default::default()
        }]
    }

    /// The plant's current value (the quality rules read their control and limit variables
    /// as they are now, also right after a write).
    fn peek(&self, var: &u32) -> Option<Vqt> {
        Some(self.plant.vqt(*var as usize))
    }

    fn subscribe(&mut self, now: Timestamp, vars: Vec<(u32, u32)>) {
        self.advance(now);
        let mut added: Vec<Sampled> = Vec::new();
        for (v, rate) in vars {
            if v as usize >= self.plant.vars().len() {
                continue;
            }
            let rate = rate.max(1);
            // A new variable is sampled at once; a faster rate comes into effect within
            // one new period.
            let due = match self.sampling.binary_search_by_key(&v, |s| s.var) {
                Ok(i) => {
                    let s = &mut self.sampling[i];
                    s.due = s.due.min(now.add_millis(u64::from(rate)));
                    s.rate = rate;
                    s.due
                }
                Err(_) => {
                    added.push(Sampled {
                        var: v,
                        rate,
                        due: now,
                    });
                    now
                }
            };
            self.next_due = Some(self.next_due.map_or(due, |t| t.min(due)));
        }
        if !added.is_empty() {
            // In variable order (a stable sort); a variable new twice in one call takes
            // its later rate.
            added.sort_by_key(|s| s.var);
            added.dedup_by(|later, earlier| {
                let same = later.var == earlier.var;
                if same {
                    earlier.rate = later.rate;
                }
                same
            });
            self.sampling.reserve_exact(added.len());
            self.sampling.extend(added);
            self.sampling.sort_by_key(|s| s.var);
        }
    }

    fn unsubscribe(&mut self, _now: Timestamp, vars: Vec<u32>) {
        let mut gone = vars;
        gone.sort_unstable();
        self.sampling
            .retain(|s| gone.binary_search(&s.var).is_err());
        if self.sampling.len() < self.sampling.capacity() / 4 {
            self.sampling.shrink_to_fit();
        }
    }

    fn read(&mut self, now: Timestamp, id: RawId, vars: Vec<u32>) {
        self.advance(now);
        let results = vars
            .iter()
            .map(|&v| Ok(self.plant.vqt(v as usize)))
            .collect();
        self.answer(now, Held::Read(id, results));
    }

    fn write(&mut self, now: Timestamp, id: RawId, items: Vec<(u32, ItemVqt)>) {
        self.advance(now);
        let results = items
            .iter()
            .map(|(var, v)| self.write_one(*var, v))
            .collect();
        self.answer(now, Held::Write(id, results));
    }

    fn poll(&mut self, now: Timestamp, out: &mut RawOutput<u32>) {
        self.advance(now);
        if self.next_due.is_some_and(|t| t <= now) {
            let mut next: Option<Timestamp> = None;
            for s in self.sampling.iter_mut() {
                if s.due <= now {
                    // Keep the phase; skip missed periods instead of bursting.
                    while s.due <= now {
                        s.due = s.due.add_millis(u64::from(s.rate));
                    }
                    out.samples.push((s.var, self.plant.vqt(s.var as usize)));
                }
                next = Some(next.map_or(s.due, |t| t.min(s.due)));
            }
            self.next_due = next;
        }
        out.reads.append(&mut self.ready.reads);
        out.writes.append(&mut self.ready.writes);
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

#[cfg(test)]
mod tests {
    use super::*;

    fn sampled(s: &mut PlantSource, now: Timestamp) -> Vec<u32> {
        let mut out = RawOutput::default();
        s.poll(now, &mut out);
        out.samples.into_iter().map(|(v, _)| v).collect()
    }

    /// Each subscribed variable keeps its rate and phase (new ones sampled at once, a
    /// faster rate within one new period), samples come in variable order, and a
    /// variable let go is sampled no more.
    #[test]
    fn subscribed_variables_are_sampled_at_their_rates_in_variable_order() {
        let ns = asix_model::embedded_demo().unwrap().namespace;
        let t0 = Timestamp::from_unix_millis(1_700_000_000_000);
        let mut s = PlantSource::new(&ns, 1, t0);
        s.subscribe(t0, vec![(5, 1000), (2, 500), (9, 1000), (2, 400)]);
        assert_eq!(sampled(&mut s, t0), [2, 5, 9]);
        assert_eq!(sampled(&mut s, t0.add_millis(400)), [2]);
        s.subscribe(t0.add_millis(500), vec![(5, 250), (7, 1000)]);
        assert_eq!(sampled(&mut s, t0.add_millis(500)), [7]);
        assert_eq!(s.poll_timeout(), Some(t0.add_millis(750)));
        assert_eq!(sampled(&mut s, t0.add_millis(750)), [5]);
        s.unsubscribe(t0.add_millis(750), vec![9, 2]);
        assert_eq!(sampled(&mut s, t0.add_millis(1000)), [5]);
        assert_eq!(sampled(&mut s, t0.add_millis(1500)), [5, 7]);
    }
}
