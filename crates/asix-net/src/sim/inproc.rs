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
use crate::sim::plant::{numeric, Plant};
use asix_model::AsixNamespace;
use asix_model::ItemKey;
use ctopc_core::model::datasource::ItemVqt;
use ctopc_core::{OpcError, Timestamp, Vqt};
use std::collections::HashMap;
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

/// A subscribed plant variable and its [`Class`] (8 bytes).
#[derive(Debug, Clone, Copy)]
struct Sampled {
    var: u32,
    class: u32,
}

/// A sampling rate in ms and when it is next due, shared by the variables subscribed at
/// that rate with that phase: those of one subscribe call, and those whose rate one call
/// changed alike (16 bytes).
#[derive(Debug, Clone, Copy)]
struct Class {
    rate: u32,
    /// The variables of the class; none: free.
    users: u32,
    due: Timestamp,
}

/// One use of class `c` less (free when none is left).
fn release(classes: &mut [Class], free: &mut Vec<u32>, c: u32) {
    let class = &mut classes[c as usize];
    class.users -= 1;
    if class.users == 0 {
        free.push(c);
    }
}

/// A device answer held back until its due time (see [`InProcessSim::with_device_delay`]).
enum Held {
    Read(RawId, Vec<Result<Vqt, OpcError>>),
    Write(RawId, Vec<Result<(), OpcError>>),
}

/// The plant as a raw variable source; variables are plant indices.
pub struct PlantSource {
    plant: Plant,
    epoch: Timestamp,
    /// Per subscribed plant variable, in variable order: its [`Class`], the sampling rate
    /// in ms and when it is next due. Each variable keeps its phase; missed periods are
    /// skipped, not burst. Only subscribed variables have an entry (a million-variable
    /// plant costs nothing here until subscribed). A sorted vector, 8 bytes a variable and
    /// 16 a class, so that the variables subscribed together share one rate and due time
    /// (a variable subscribed alone, at a time of its own, costs 24).
    sampling: Vec<Sampled>,
    /// Indexed by [`Sampled::class`].
    classes: Vec<Class>,
    /// Classes without variables, for reuse.
    free_classes: Vec<u32>,
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
            classes: Vec::new(),
            free_classes: Vec::new(),
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

    /// The class of `rate` due at `due` for one more variable: one made by this call
    /// (`made`) if it matches, else a new one.
    fn class_for(
        &mut self,
        made: &mut HashMap<(u32, Timestamp), u32>,
        rate: u32,
        due: Timestamp,
    ) -> u32 {
        let c = match made.get(&(rate, due)) {
            Some(&c)
                if self.classes[c as usize].users > 0
                    && self.classes[c as usize].rate == rate
                    && self.classes[c as usize].due == due =>
            {
                c
            }
            _ => {
                let class = Class {
                    rate,
                    users: 0,
                    due,
                };
                let c = match self.free_classes.pop() {
                    Some(c) => {
                        self.classes[c as usize] = class;
                        c
                    }
                    None => {
                        self.classes.push(class);
                        (self.classes.len() - 1) as u32
                    }
                };
                made.insert((rate, due), c);
                c
            }
        };
        self.classes[c as usize].users += 1;
        c
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
        let mut made = HashMap::new();
        let mut added: Vec<(u32, u32)> = Vec::new();
        for (v, rate) in vars {
            if v as usize >= self.plant.vars().len() {
                continue;
            }
            let rate = rate.max(1);
            // A new variable is sampled at once; a faster rate comes into effect within
            // one new period.
            let due = match self.sampling.binary_search_by_key(&v, |s| s.var) {
                Ok(i) => {
                    let old = self.sampling[i].class;
                    let c = self.classes[old as usize];
                    let due = c.due.min(now.add_millis(u64::from(rate)));
                    if (c.rate, c.due) != (rate, due) {
                        let new = self.class_for(&mut made, rate, due);
                        self.sampling[i].class = new;
                        release(&mut self.classes, &mut self.free_classes, old);
                    }
                    due
                }
                Err(_) => {
                    added.push((v, rate));
                    now
                }
            };
            self.next_due = Some(self.next_due.map_or(due, |t| t.min(due)));
        }
        if !added.is_empty() {
            // In variable order (a stable sort); a variable new twice in one call takes
            // its later rate.
            added.sort_by_key(|&(v, _)| v);
            added.dedup_by(|later, earlier| {
                let same = later.0 == earlier.0;
                if same {
                    earlier.1 = later.1;
                }
                same
            });
            self.sampling.reserve_exact(added.len());
            for (var, rate) in added {
                let class = self.class_for(&mut made, rate, now);
                self.sampling.push(Sampled { var, class });
            }
            self.sampling.sort_by_key(|s| s.var);
        }
    }

    fn unsubscribe(&mut self, _now: Timestamp, vars: Vec<u32>) {
        let mut gone = vars;
        gone.sort_unstable();
        let (classes, free) = (&mut self.classes, &mut self.free_classes);
        self.sampling.retain(|s| {
            let keep = gone.binary_search(&s.var).is_err();
            if !keep {
                release(classes, free, s.class);
            }
            keep
        });
        if self.sampling.len() < self.sampling.capacity() / 4 {
            self.sampling.shrink_to_fit();
        }
        if self.free_classes.len() == self.classes.len() {
            self.classes = Vec::new();
            self.free_classes = Vec::new();
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
            let mut fired = vec![false; self.classes.len()];
            for (c, fired) in self.classes.iter_mut().zip(fired.iter_mut()) {
                if c.users == 0 {
                    continue;
                }
                if c.due <= now {
                    // Keep the phase; skip missed periods instead of bursting.
                    while c.due <= now {
                        c.due = c.due.add_millis(u64::from(c.rate));
                    }
                    *fired = true;
                }
                next = Some(next.map_or(c.due, |t| t.min(c.due)));
            }
            for s in &self.sampling {
                if fired[s.class as usize] {
                    out.samples.push((s.var, self.plant.vqt(s.var as usize)));
                }
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

    /// The reference sampling, a rate and due time per variable: the classes must sample
    /// exactly as it does.
    #[derive(Default)]
    struct PerVariable {
        /// (var, rate, due), in variable order.
        sampling: Vec<(u32, u32, Timestamp)>,
        next_due: Option<Timestamp>,
    }

    impl PerVariable {
        fn subscribe(&mut self, now: Timestamp, vars: &[(u32, u32)], known: u32) {
            let mut added: Vec<(u32, u32, Timestamp)> = Vec::new();
            for &(v, rate) in vars {
                if v >= known {
                    continue;
                }
                let rate = rate.max(1);
                let due = match self.sampling.binary_search_by_key(&v, |s| s.0) {
                    Ok(i) => {
                        let s = &mut self.sampling[i];
                        s.2 = s.2.min(now.add_millis(u64::from(rate)));
                        s.1 = rate;
                        s.2
                    }
                    Err(_) => {
                        added.push((v, rate, now));
                        now
                    }
                };
                self.next_due = Some(self.next_due.map_or(due, |t| t.min(due)));
            }
            added.sort_by_key(|s| s.0);
            added.dedup_by(|later, earlier| {
                let same = later.0 == earlier.0;
                if same {
                    earlier.1 = later.1;
                }
                same
            });
            self.sampling.extend(added);
            self.sampling.sort_by_key(|s| s.0);
        }

        fn unsubscribe(&mut self, vars: &[u32]) {
            self.sampling.retain(|s| !vars.contains(&s.0));
        }

        fn poll(&mut self, now: Timestamp) -> Vec<u32> {
            let mut out = Vec::new();
            if self.next_due.is_some_and(|t| t <= now) {
                let mut next: Option<Timestamp> = None;
                for s in self.sampling.iter_mut() {
                    if s.2 <= now {
                        while s.2 <= now {
                            s.2 = s.2.add_millis(u64::from(s.1));
                        }
                        out.push(s.0);
                    }
                    next = Some(next.map_or(s.2, |t| t.min(s.2)));
                }
                self.next_due = next;
            }
            out
        }
    }

    #[derive(Debug, Clone)]
    enum Op {
        Subscribe(Vec<(u32, u32)>),
        Unsubscribe(Vec<u32>),
        Poll,
    }

    fn op() -> impl Strategy<Value = Op> {
        // Few variables (and one the plant does not have) and rates, so that they meet
        // often.
        let var = prop_oneof![10 => 0u32..12, 1 => Just(1_000_000)];
        let rate = prop_oneof![Just(0u32), Just(100), Just(250), Just(400), Just(1000)];
        prop_oneof![
            prop::collection::vec((var.clone(), rate), 0..6).prop_map(Op::Subscribe),
            prop::collection::vec(var, 0..4).prop_map(Op::Unsubscribe),
            Just(Op::Poll),
            Just(Op::Poll),
        ]
    }

    use proptest::prelude::*;

    proptest! {
        /// Variables subscribed together share a class, a rate change moves them to
        /// another, and the samples, their order and the next due time are those of a
        /// rate and due time per variable.
        #[test]
        fn classes_sample_as_a_rate_and_due_time_per_variable(
            ops in prop::collection::vec((0u64..700, op()), 1..60)
        ) {
            let ns = asix_model::embedded_demo().unwrap().namespace;
            let t0 = Timestamp::from_unix_millis(1_700_000_000_000);
            let mut s = PlantSource::new(&ns, 1, t0);
            let known = s.plant().vars().len() as u32;
            let mut model = PerVariable::default();
            let mut now = t0;
            for (step, op) in ops {
                now = now.add_millis(step);
                match op {
                    Op::Subscribe(vars) => {
                        model.subscribe(now, &vars, known);
                        s.subscribe(now, vars);
                    }
                    Op::Unsubscribe(vars) => {
                        model.unsubscribe(&vars);
                        s.unsubscribe(now, vars);
                    }
                    Op::Poll => {
                        prop_assert_eq!(sampled(&mut s, now), model.poll(now));
                    }
                }
                prop_assert_eq!(s.poll_timeout(), model.next_due);
                let live = s.classes.iter().filter(|c| c.users > 0).count();
                prop_assert_eq!(live + s.free_classes.len(), s.classes.len());
                let users: u32 = s.classes.iter().map(|c| c.users).sum();
                prop_assert_eq!(users as usize, s.sampling.len());
            }
        }
    }
}
