//! A deterministic simulated plant: variables that evolve in fixed ticks from a seed.
//!
//! The state after `n` ticks depends only on the seed, the variable list and the writes
//! applied (and the ticks they were applied at), never on wall-clock timing.

use asix_model::vardb::hash_name;
use hashbrown::HashTable;

use ctopc_core::{Quality, Timestamp, Value, VarType};

use crate::Vqt;

/// A variable as a simple list describes it.
#[derive(Debug, Clone, PartialEq)]
pub struct VarSpec {
    pub name: String,
    /// One of the asix types: R4, I2, UI2, I4, UI4, UI1 (R8 and BOOL are accepted too).
    pub var_type: VarType,
    pub low: f64,
    pub high: f64,
    pub writable: bool,
}

/// What the plant keeps of a [`VarSpec`] per variable: everything but the name (the names
/// are in one arena of the plant, [`Plant::name`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VarRange {
    pub var_type: VarType,
    pub low: f64,
    pub high: f64,
    pub writable: bool,
}

impl VarSpec {
    /// The spec without its name.
    pub fn range(&self) -> VarRange {
        VarRange {
            var_type: self.var_type,
            low: self.low,
            high: self.high,
            writable: self.writable,
        }
    }

    pub fn new(name: &str, var_type: VarType, low: f64, high: f64, writable: bool) -> Self {
        VarSpec {
            name: name.to_owned(),
            var_type,
            low,
            high,
            writable,
        }
    }
}

/// How a variable evolves. References to other variables are by name, within the channel.
#[derive(Debug, Clone, PartialEq)]
pub enum Behaviour {
    /// Changes only when written (set points; every variable of a channel on driver NONE).
    Constant,
    /// As `Constant`, starting at `value` (control variables: 0 = healthy).
    Steady { value: f64 },
    /// Mean-reverting random walk; `step` is the noise per tick as a fraction of the range.
    Noise { step: f64 },
    /// Sine wave over the range with a period in ticks, plus noise (fraction of range).
    Wave { period: u32, noise: f64 },
    /// Sawtooth from low to high over `period` ticks.
    Ramp { period: u32 },
    /// A tank level: rises by `fill` (fraction of range per tick) while the inlet pump runs,
    /// falls by `drain` while the outlet pump runs. Without pumps it fills and drains by
    /// itself between 10 % and 90 %.
    Tank {
        fill: f64,
        drain: f64,
        inlet: Option<String>,
        outlet: Option<String>,
    },
    /// A pump (0/1) switched by a tank level with hysteresis: an inlet pump starts below
    /// `on_below` (fraction of the tank range) and stops above `off_above`; an outlet pump
    /// the other way round. Without a tank it toggles every `period` ticks (± jitter).
    Pump {
        tank: Option<String>,
        inlet: bool,
        low_mark: f64,
        high_mark: f64,
    },
    /// A flow that follows a pump: `nominal` (fraction of range) while it runs, plus noise.
    Flow { pump: String, nominal: f64 },
    /// A totaliser integrating another variable (`scale` per tick per unit).
    Counter { source: String, scale: f64 },
}

impl Behaviour {
    /// A plausible behaviour for a variable known only by its spec.
    pub fn guess(spec: &VarSpec) -> Behaviour {
        Behaviour::guess_range(&spec.name, &spec.range())
    }

    /// [`Behaviour::guess`] of a variable named `name` with `range`.
    fn guess_range(name: &str, r: &VarRange) -> Behaviour {
        let integral = !matches!(r.var_type, VarType::R4 | VarType::R8);
        if r.writable {
            return Behaviour::Constant;
        }
        if integral && r.low == 0.0 && r.high == 1.0 {
            return Behaviour::Pump {
                tank: None,
                inlet: true,
                low_mark: 0.0,
                high_mark: 0.0,
            };
        }
        let has = |w: &str| contains_ignore_case(name, w);
        if has("POZIOM") || has("LEVEL") || has("LVL") {
            return Behaviour::Tank {
                fill: 0.004,
                drain: 0.003,
                inlet: None,
                outlet: None,
            };
        }
        if has("LICZNIK") || has("COUNT") || has("TOTAL") {
            return Behaviour::Ramp { period: 6000 };
        }
        let h = fnv_upper(name);
        match h % 3 {
            0 => Behaviour::Noise { step: 0.01 },
            1 => Behaviour::Wave {
                period: 300 + (h % 900) as u32,
                noise: 0.005,
            },
            _ => Behaviour::Noise { step: 0.02 },
        }
    }

    /// A plausible behaviour from an ISA-style instrument tag (`LI101`, `MS105A`, `TI201`,
    /// `FQ106`...) when there is one, else from the spec ([`Behaviour::guess`]).
    pub fn guess_tagged(spec: &VarSpec, tag: &str) -> Behaviour {
        Behaviour::guess_tagged_range(&spec.name, &spec.range(), tag)
    }

    /// [`Behaviour::guess_tagged`] of a variable named `name` with `range` (no copy of
    /// the name or the tag is made: the database's plant is built from views).
    fn guess_tagged_range(name: &str, r: &VarRange, tag: &str) -> Behaviour {
        let t = tag.trim();
        let starts = |p: &str| {
            t.len() >= p.len() && t.as_bytes()[..p.len()].eq_ignore_ascii_case(p.as_bytes())
        };
        let binary =
            !matches!(r.var_type, VarType::R4 | VarType::R8) && r.low == 0.0 && r.high == 1.0;
        if r.writable {
            return Behaviour::Constant;
        }
        if binary || ["MS", "XS", "BS", "LS", "ZS"].iter().any(|p| starts(p)) {
            return Behaviour::Pump {
                tank: None,
                inlet: true,
                low_mark: 0.0,
                high_mark: 0.0,
            };
        }
        if t.is_empty() {
            return Behaviour::guess_range(name, r);
        }
        if starts("L") {
            return Behaviour::Tank {
                fill: 0.002,
                drain: 0.0015,
                inlet: None,
                outlet: None,
            };
        }
        if starts("FQ") || starts("JQ") {
            return Behaviour::Ramp { period: 36_000 };
        }
        if starts("T") {
            return Behaviour::Wave {
                period: 600 + (fnv_upper(t) % 1800) as u32,
                noise: 0.003,
            };
        }
        if starts("S") || starts("Z") {
            return Behaviour::Noise { step: 0.003 };
        }
        Behaviour::Noise { step: 0.01 }
    }
}

/// Whether `hay` contains `needle` (upper-case ASCII), ignoring ASCII case.
fn contains_ignore_case(hay: &str, needle: &str) -> bool {
    hay.as_bytes()
        .windows(needle.len())
        .any(|w| w.eq_ignore_ascii_case(needle.as_bytes()))
}

/// The channels of an asix variable database (such as the demo database `demo/`): variables
/// grouped by their `Channel` attribute (`default_channel` when empty), typed and ranged as
/// the database says (0..100 without a range), behaviours guessed from the `Alias` tag;
/// control variables hold 0 (healthy) until written or forced.
pub fn channels_from_database(
    db: &asix_model::VarDatabase,
    default_channel: &str,
) -> Vec<ChannelDef> {
    let mut by_channel: Vec<ChannelDef> = Vec::new();
    for_each_database_var(db, default_channel, |channel, name, range, b| {
        let spec = VarSpec::new(name, range.var_type, range.low, range.high, range.writable);
        match by_channel.iter_mut().find(|c| c.name == channel) {
            Some(c) => c.vars.push((spec, b)),
            None => by_channel.push(ChannelDef {
                name: channel.to_owned(),
                vars: vec![(spec, b)],
            }),
        }
    });
    by_channel
}

/// Each variable of `db` in table order as [`channels_from_database`] describes it:
/// channel, name, range and behaviour, from views of the compact table (nothing is decoded
/// or copied per variable).
fn for_each_database_var(
    db: &asix_model::VarDatabase,
    default_channel: &str,
    mut f: impl FnMut(&str, &str, VarRange, Behaviour),
) {
    // The rows named as some row's control variable (names are unique in a database; a
    // run of rows usually names the same one, looked up once).
    let mut controls = vec![false; db.variables.len()];
    let mut last: Option<(&str, Option<usize>)> = None;
    for v in db.variables.views() {
        let Some(c) = v.control_variable() else {
            continue;
        };
        let row = match last {
            Some((l, row)) if l == c => row,
            _ => db.find_real_index(c),
        };
        if let Some(r) = row {
            controls[r] = true;
        }
        last = Some((c, row));
    }
    let column = |name: &str| db.column(name).unwrap_or(usize::MAX);
    let (channel_col, alias_col) = (column("Channel"), column("Alias"));
    for var in db.variables.views() {
        let channel = Some(var.cell(channel_col).trim())
            .filter(|c| !c.is_empty())
            .unwrap_or(default_channel);
        let (low, high) = var.range().unwrap_or((0.0, 100.0));
        let range = VarRange {
            var_type: var.data_type(),
            low: low.min(high),
            high: high.max(low),
            writable: var.writable(),
        };
        let b = if controls[var.index()] {
            Behaviour::Steady { value: 0.0 }
        } else {
            Behaviour::guess_tagged_range(var.name(), &range, var.cell(alias_col))
        };
        f(channel, var.name(), range, b);
    }
}

/// A channel: its name and variables with their behaviours.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelDef {
    pub name: String,
    pub vars: Vec<(VarSpec, Behaviour)>,
}

impl ChannelDef {
    /// A channel from a simple list, behaviours guessed from names, types and ranges.
    pub fn from_specs(name: &str, specs: Vec<VarSpec>) -> Self {
        let vars = specs
            .into_iter()
            .map(|s| (s.clone(), Behaviour::guess(&s)))
            .collect();
        ChannelDef {
            name: name.to_owned(),
            vars,
        }
    }

    /// `n` noisy R4 variables `V00000`.. (benchmarks).
    pub fn noisy(name: &str, n: usize) -> Self {
        let vars = (0..n)
            .map(|i| {
                (
                    VarSpec::new(&format!("V{i:05}"), VarType::R4, 0.0, 100.0, true),
                    Behaviour::Noise { step: 0.01 },
                )
            })
            .collect();
        ChannelDef {
            name: name.to_owned(),
            vars,
        }
    }
}

/// splitmix64: small, fast, good enough, and stable across platforms and versions.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [-1, 1).
    pub fn signed(&mut self) -> f64 {
        self.unit() * 2.0 - 1.0
    }
}

/// FNV-1a of `s` upper-cased (ASCII), without making the upper-case copy.
fn fnv_upper(s: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in s.bytes() {
        h ^= b.to_ascii_uppercase() as u64;
        h = h.wrapping_mul(0x100_0000_01b3);
    }
    h
}

/// How a variable evolves, as [`Plant::step`] computes it: decoded from a [`PlantVar`]'s
/// compact fields ([`PlantVar::kind`]) and stored back ([`PlantVar::keep_state`]).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Constant,
    Noise {
        step: f64,
    },
    Wave {
        period: u32,
        noise: f64,
        phase: f64,
    },
    Ramp {
        period: u32,
    },
    Tank {
        fill: f64,
        drain: f64,
        inlet: Option<u32>,
        outlet: Option<u32>,
        rising: bool,
    },
    Pump {
        tank: Option<u32>,
        inlet: bool,
        low: f64,
        high: f64,
        next_toggle: u64,
    },
    Flow {
        pump: u32,
        nominal: f64,
    },
    Counter {
        source: u32,
        scale: f64,
    },
}

/// The variant of a [`Kind`], one byte of a [`PlantVar`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum KindTag {
    Constant,
    Noise,
    Wave,
    Ramp,
    Tank,
    Pump,
    Flow,
    Counter,
}

/// No variable (a reference of a behaviour that names none).
const NO_VAR: u32 = u32::MAX;

fn opt_var(v: u32) -> Option<u32> {
    (v != NO_VAR).then_some(v)
}

/// One variable's state: 64 bytes (a large plant has a million of them), its name in the
/// database it comes from or in the plant's arena ([`Plant::name`]). A behaviour's
/// parameters (the same few for most variables) are in the plant's `params`, its state and
/// references in `state`, `a`, `b` and `flag` ([`PlantVar::kind`]).
#[derive(Debug, Clone)]
pub struct PlantVar {
    low: f64,
    high: f64,
    /// Engineering value.
    pub value: f64,
    pub timestamp: Timestamp,
    /// Wave: the phase (`f64` bits); Pump: the tick of its next toggle.
    state: u64,
    /// The behaviour's parameters in the plant's `params`.
    param: u32,
    /// Wave, Ramp: the period; Tank: the inlet pump; Pump: the tank; Flow: the pump;
    /// Counter: the source ([`NO_VAR`]: none).
    a: u32,
    /// Tank: the outlet pump.
    b: u32,
    /// Bumped whenever the VQT changes (lets subscribers send only changes; never 0).
    pub version: u32,
    pub quality: Quality,
    var_type: VarType,
    tag: KindTag,
    /// Tank: rising; Pump: an inlet pump.
    flag: bool,
    writable: bool,
}

impl PlantVar {
    /// Type, range and writability.
    pub fn spec(&self) -> VarRange {
        VarRange {
            var_type: self.var_type,
            low: self.low,
            high: self.high,
            writable: self.writable,
        }
    }

    /// The behaviour, with its parameters from `params`.
    fn kind(&self, params: &[[f64; 2]]) -> Kind {
        let p = params.get(self.param as usize).copied().unwrap_or([0.0; 2]);
        match self.tag {
            KindTag::Constant => Kind::Constant,
            KindTag::Noise => Kind::Noise { step: p[0] },
            KindTag::Wave => Kind::Wave {
                period: self.a,
                noise: p[0],
                phase: f64::from_bits(self.state),
            },
            KindTag::Ramp => Kind::Ramp { period: self.a },
            KindTag::Tank => Kind::Tank {
                fill: p[0],
                drain: p[1],
                inlet: opt_var(self.a),
                outlet: opt_var(self.b),
                rising: self.flag,
            },
            KindTag::Pump => Kind::Pump {
                tank: opt_var(self.a),
                inlet: self.flag,
                low: p[0],
                high: p[1],
                next_toggle: self.state,
            },
            KindTag::Flow => Kind::Flow {
                pump: self.a,
                nominal: p[0],
            },
            KindTag::Counter => Kind::Counter {
                source: self.a,
                scale: p[0],
            },
        }
    }

    /// Keeps what a step changes of the behaviour (a tank's direction, a pump's next
    /// toggle); its parameters and references do not change.
    fn keep_state(&mut self, kind: &Kind) {
        match *kind {
            Kind::Tank { rising, .. } => self.flag = rising,
            Kind::Pump { next_toggle, .. } => self.state = next_toggle,
            _ => {}
        }
    }
}

/// The behaviours' parameters of a plant, each pair once (a million variables share a
/// few). Interned while the plant is built.
#[derive(Debug, Clone, Default)]
struct Params {
    list: Vec<[f64; 2]>,
    index: std::collections::HashMap<[u64; 2], u32>,
}

impl Params {
    fn intern(&mut self, p: [f64; 2]) -> u32 {
        let key = [p[0].to_bits(), p[1].to_bits()];
        // A plant has a few: a look along the list before hashing.
        if self.list.len() <= 16 {
            let found = self
                .list
                .iter()
                .position(|q| [q[0].to_bits(), q[1].to_bits()] == key);
            if let Some(i) = found {
                return i as u32;
            }
        }
        let list = &mut self.list;
        *self.index.entry(key).or_insert_with(|| {
            list.push(p);
            (list.len() - 1) as u32
        })
    }

    /// The fields of a [`PlantVar`] that hold `kind`: tag, param, a, b, flag, state.
    fn encode(&mut self, kind: &Kind) -> (KindTag, u32, u32, u32, bool, u64) {
        let var = |v: Option<u32>| v.unwrap_or(NO_VAR);
        match *kind {
            Kind::Constant => (KindTag::Constant, 0, NO_VAR, NO_VAR, false, 0),
            Kind::Noise { step } => (
                KindTag::Noise,
                self.intern([step, 0.0]),
                NO_VAR,
                NO_VAR,
                false,
                0,
            ),
            Kind::Wave {
                period,
                noise,
                phase,
            } => (
                KindTag::Wave,
                self.intern([noise, 0.0]),
                period,
                NO_VAR,
                false,
                phase.to_bits(),
            ),
            Kind::Ramp { period } => (KindTag::Ramp, 0, period, NO_VAR, false, 0),
            Kind::Tank {
                fill,
                drain,
                inlet,
                outlet,
                rising,
            } => (
                KindTag::Tank,
                self.intern([fill, drain]),
                var(inlet),
                var(outlet),
                rising,
                0,
            ),
            Kind::Pump {
                tank,
                inlet,
                low,
                high,
                next_toggle,
            } => (
                KindTag::Pump,
                self.intern([low, high]),
                var(tank),
                NO_VAR,
                inlet,
                next_toggle,
            ),
            Kind::Flow { pump, nominal } => (
                KindTag::Flow,
                self.intern([nominal, 0.0]),
                pump,
                NO_VAR,
                false,
                0,
            ),
            Kind::Counter { source, scale } => (
                KindTag::Counter,
                self.intern([scale, 0.0]),
                source,
                NO_VAR,
                false,
                0,
            ),
        }
    }
}

/// Where a plant's names are, and how they are looked up.
#[derive(Debug, Clone)]
enum Names {
    /// Names of its own (a plant of [`ChannelDef`]s: asix-sim, tests): one arena string
    /// (`names`, `ends`), each variable's channel, and `HashTable<u32>` indexes of
    /// variable numbers that compare the names in the arena.
    Own {
        names: String,
        ends: Vec<u32>,
        channel: Vec<u32>,
        /// (channel, name) → the last variable of that name in the channel.
        index: HashTable<u32>,
        /// name → the first variable of that name in any channel.
        by_name: HashTable<u32>,
    },
    /// The databases' names (a plant of [`Plant::from_databases`]): variable `first + r`
    /// is row `r` of a database, found by the database's `Name` index. A name is in a
    /// database once, so the last variable of a name in a channel is that of the last
    /// database holding it in the channel, and the first in any channel that of the first.
    Databases {
        dbs: Vec<DbPart>,
        default_channel: String,
    },
}

/// A database of a plant made from databases.
#[derive(Debug, Clone)]
struct DbPart {
    db: std::sync::Arc<asix_model::VarDatabase>,
    /// The plant number of its first row.
    first: u32,
    /// Its `Channel` column.
    channel_col: Option<usize>,
}

/// The plant. Compact for large databases: a [`PlantVar`] of 64 bytes a variable, the names
/// those of the databases (nothing per variable but the `PlantVar`) or, for a plant of
/// channel definitions, one arena with indexes comparing names in it.
#[derive(Debug, Clone)]
pub struct Plant {
    channels: Vec<String>,
    vars: Vec<PlantVar>,
    params: Params,
    names: Names,
    rng: Rng,
    tick: u64,
    tick_ms: u64,
    epoch: Timestamp,
}

/// At most this many ticks are computed in one `advance_to`; a plant further behind skips
/// ahead (time moves on, the simulation resumes from its state).
pub const MAX_CATCH_UP_TICKS: u64 = 10_000;

/// At most this many variable steps (ticks × variables) are computed in one `advance_to`,
/// and at least one tick: a tick steps every variable of the plant, so a large plant
/// catches up fewer ticks and skips the rest. The in-process simulation advances the plant
/// under the engine's lock: unbounded, a plant of 1,000,000 variables left idle for a
/// minute (no subscription polls it) would compute 240 ticks, 240,000,000 variable steps,
/// at the next device read before answering it, every other read and new item waiting.
pub const MAX_CATCH_UP_VAR_STEPS: u64 = 2_000_000;

/// The ticks one `advance_to` computes at most for a plant of `vars` variables.
pub fn max_catch_up_ticks(vars: usize) -> u64 {
    (MAX_CATCH_UP_VAR_STEPS / (vars as u64).max(1)).clamp(1, MAX_CATCH_UP_TICKS)
}

/// A reference of a behaviour to another variable of its channel, by name, resolved when
/// every variable is known ([`Plant::finish`]).
enum Ref {
    TankInlet,
    TankOutlet,
    PumpTank,
    FlowPump,
    CounterSource,
}

fn channel_hash(channel: u32, name: &str) -> u64 {
    hash_name(name) ^ u64::from(channel).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

impl Plant {
    /// Builds the plant; `epoch` is the timestamp of tick 0.
    pub fn new(channels: &[ChannelDef], seed: u64, tick_ms: u64, epoch: Timestamp) -> Plant {
        let n = channels.iter().map(|c| c.vars.len()).sum();
        let names = Names::Own {
            names: String::new(),
            ends: Vec::with_capacity(n),
            channel: Vec::with_capacity(n),
            index: HashTable::with_capacity(n),
            by_name: HashTable::with_capacity(n),
        };
        let mut p = Plant::empty(n, names, seed, tick_ms, epoch);
        let mut refs = Vec::new();
        for ch in channels {
            for (spec, b) in &ch.vars {
                let ci = p.channel_number(&ch.name);
                p.name_own(ci, &spec.name);
                p.push(spec.range(), b, &mut refs);
            }
        }
        p.finish(refs);
        p
    }

    /// The plant of every variable of `dbs` (as [`channels_from_database`] makes them),
    /// built straight from the databases' compact tables and keeping them for the names:
    /// no list of specs in between, and no name or index of its own, so that a database
    /// of a million variables costs the plant only its `PlantVar`s.
    pub fn from_databases(
        dbs: &[std::sync::Arc<asix_model::VarDatabase>],
        default_channel: &str,
        seed: u64,
        tick_ms: u64,
        epoch: Timestamp,
    ) -> Plant {
        let n = dbs.iter().map(|d| d.variables.len()).sum();
        let mut parts = Vec::with_capacity(dbs.len());
        let mut first = 0u32;
        for db in dbs {
            parts.push(DbPart {
                db: std::sync::Arc::clone(db),
                first,
                channel_col: db.column("Channel"),
            });
            first = first.saturating_add(db.variables.len() as u32);
        }
        let names = Names::Databases {
            dbs: parts,
            default_channel: default_channel.to_owned(),
        };
        let mut p = Plant::empty(n, names, seed, tick_ms, epoch);
        let mut refs = Vec::new();
        let mut last_channel = String::new();
        for db in dbs {
            for_each_database_var(db, default_channel, |channel, _name, range, b| {
                // The channels in order of appearance (rows of a channel mostly come
                // together: looked up once a run).
                if last_channel != channel || p.channels.is_empty() {
                    p.channel_number(channel);
                    channel.clone_into(&mut last_channel);
                }
                p.push(range, &b, &mut refs);
            });
        }
        p.finish(refs);
        p
    }

    fn empty(n: usize, names: Names, seed: u64, tick_ms: u64, epoch: Timestamp) -> Plant {
        Plant {
            channels: Vec::new(),
            vars: Vec::with_capacity(n),
            params: Params::default(),
            names,
            rng: Rng::new(seed),
            tick: 0,
            tick_ms: tick_ms.max(1),
            epoch,
        }
    }

    /// The database and row of variable `i` of a plant made from databases.
    fn row_of(dbs: &[DbPart], i: usize) -> Option<(&DbPart, usize)> {
        let k = dbs
            .partition_point(|d| d.first as usize <= i)
            .checked_sub(1)?;
        let d = &dbs[k];
        let row = i - d.first as usize;
        (row < d.db.variables.len()).then_some((d, row))
    }

    /// The name of variable `i`.
    pub fn name(&self, i: usize) -> &str {
        match &self.names {
            Names::Own { names, ends, .. } => name_in(names, ends, i),
            Names::Databases { dbs, .. } => {
                Plant::row_of(dbs, i).map_or("", |(d, r)| d.db.variables.view(r).name())
            }
        }
    }

    /// The name of the channel of variable `i`.
    fn channel_name(&self, i: usize) -> &str {
        match &self.names {
            Names::Own { channel, .. } => channel
                .get(i)
                .and_then(|&c| self.channels.get(c as usize))
                .map_or("", String::as_str),
            Names::Databases {
                dbs,
                default_channel,
            } => Plant::row_of(dbs, i).map_or("", |(d, r)| {
                let c = d
                    .channel_col
                    .map_or("", |col| d.db.variables.view(r).cell(col).trim());
                if c.is_empty() {
                    default_channel
                } else {
                    c
                }
            }),
        }
    }

    /// The number of the channel of variable `i` in [`Plant::channels`].
    pub fn channel_of(&self, i: usize) -> Option<usize> {
        let name = self.channel_name(i);
        self.channels.iter().rposition(|c| c == name)
    }

    /// The number of the channel `name`, added when new (channels are few).
    fn channel_number(&mut self, name: &str) -> u32 {
        let found = self.channels.iter().rposition(|c| c == name);
        let i = found.unwrap_or_else(|| {
            self.channels.push(name.to_owned());
            self.channels.len() - 1
        });
        i as u32
    }

    /// Names the next variable (a plant of its own names): `name` in channel `ci`, indexed.
    fn name_own(&mut self, ci: u32, name: &str) {
        let Names::Own {
            names,
            ends,
            channel,
            index,
            by_name,
        } = &mut self.names
        else {
            return;
        };
        let i = ends.len() as u32;
        names.push_str(name);
        ends.push(names.len() as u32);
        channel.push(ci);
        let (names, ends, channel) = (&*names, &*ends, &*channel);
        let name_of = |j: u32| name_in(names, ends, j as usize);
        let channel_of = |j: u32| channel[j as usize];
        match index.entry(
            channel_hash(ci, name),
            |&j| channel_of(j) == ci && name_of(j) == name,
            |&j| channel_hash(channel_of(j), name_of(j)),
        ) {
            hashbrown::hash_table::Entry::Occupied(mut e) => *e.get_mut() = i,
            hashbrown::hash_table::Entry::Vacant(e) => {
                e.insert(i);
            }
        }
        let h = hash_name(name);
        if by_name.find(h, |&j| name_of(j) == name).is_none() {
            by_name.insert_unique(h, i, |&j| hash_name(name_of(j)));
        }
    }

    /// Adds one variable; its references by name go to `refs`, resolved by `finish`.
    fn push(&mut self, spec: VarRange, b: &Behaviour, refs: &mut Vec<(u32, Ref, String)>) {
        let i = self.vars.len() as u32;
        let rng = &mut self.rng;
        let (lo, hi) = (spec.low, spec.high.max(spec.low));
        let mut named = |r: Ref, n: &Option<String>| {
            if let Some(n) = n {
                refs.push((i, r, n.clone()));
            }
        };
        let kind = match b {
            Behaviour::Constant | Behaviour::Steady { .. } => Kind::Constant,
            Behaviour::Noise { step } => Kind::Noise { step: *step },
            Behaviour::Wave { period, noise } => Kind::Wave {
                period: (*period).max(2),
                noise: *noise,
                phase: rng.unit(),
            },
            Behaviour::Ramp { period } => Kind::Ramp {
                period: (*period).max(2),
            },
            Behaviour::Tank {
                fill,
                drain,
                inlet,
                outlet,
            } => {
                named(Ref::TankInlet, inlet);
                named(Ref::TankOutlet, outlet);
                Kind::Tank {
                    fill: *fill,
                    drain: *drain,
                    inlet: None,
                    outlet: None,
                    rising: rng.unit() < 0.5,
                }
            }
            Behaviour::Pump {
                tank,
                inlet,
                low_mark,
                high_mark,
            } => {
                named(Ref::PumpTank, tank);
                Kind::Pump {
                    tank: None,
                    inlet: *inlet,
                    low: *low_mark,
                    high: *high_mark,
                    next_toggle: 50 + rng.next_u64() % 200,
                }
            }
            // Resolved by `finish`; a flow without its pump is noise, a counter without
            // its source a ramp (neither draws from the generator at build time).
            Behaviour::Flow { pump, nominal } => {
                named(Ref::FlowPump, &Some(pump.clone()));
                Kind::Flow {
                    pump: NO_VAR,
                    nominal: *nominal,
                }
            }
            Behaviour::Counter { source, scale } => {
                named(Ref::CounterSource, &Some(source.clone()));
                Kind::Counter {
                    source: NO_VAR,
                    scale: *scale,
                }
            }
        };
        let value = match (b, &kind) {
            (Behaviour::Steady { value }, _) => value.clamp(lo, hi),
            (_, kind) => match kind {
                Kind::Pump { .. } => f64::from(rng.unit() < 0.5),
                Kind::Counter { .. } | Kind::Ramp { .. } => lo,
                Kind::Tank { .. } => lo + (hi - lo) * (0.3 + 0.4 * rng.unit()),
                _ => lo + (hi - lo) * (0.4 + 0.2 * rng.unit()),
            },
        };
        let (tag, param, a, b, flag, state) = self.params.encode(&kind);
        self.vars.push(PlantVar {
            low: spec.low,
            high: spec.high,
            value,
            timestamp: self.epoch,
            state,
            param,
            a,
            b,
            version: 1,
            quality: Quality::GOOD,
            var_type: spec.var_type,
            tag,
            flag,
            writable: spec.writable,
        });
    }

    /// Resolves the behaviours' references by name within their channels.
    fn finish(&mut self, refs: Vec<(u32, Ref, String)>) {
        for (i, r, name) in refs {
            let target = self
                .channel_of(i as usize)
                .and_then(|ch| self.lookup_in(ch, &name))
                .map(|t| t as u32);
            let mut kind = self.vars[i as usize].kind(&self.params.list);
            match (&mut kind, r) {
                (Kind::Tank { inlet, .. }, Ref::TankInlet) => *inlet = target,
                (Kind::Tank { outlet, .. }, Ref::TankOutlet) => *outlet = target,
                (Kind::Pump { tank, .. }, Ref::PumpTank) => *tank = target,
                (Kind::Flow { pump, .. }, Ref::FlowPump) => match target {
                    Some(t) => *pump = t,
                    None => kind = Kind::Noise { step: 0.01 },
                },
                (Kind::Counter { source, .. }, Ref::CounterSource) => match target {
                    Some(t) => *source = t,
                    None => kind = Kind::Ramp { period: 6000 },
                },
                _ => {}
            }
            let (tag, param, a, b, flag, state) = self.params.encode(&kind);
            let var = &mut self.vars[i as usize];
            (var.tag, var.param, var.a, var.b, var.flag, var.state) =
                (tag, param, a, b, flag, state);
        }
        self.params.index = Default::default();
    }

    /// The last variable named `variable` in channel `ci`.
    fn lookup_in(&self, ci: usize, variable: &str) -> Option<usize> {
        match &self.names {
            Names::Own {
                names,
                ends,
                channel,
                index,
                ..
            } => {
                let ci = ci as u32;
                index
                    .find(channel_hash(ci, variable), |&j| {
                        channel[j as usize] == ci && name_in(names, ends, j as usize) == variable
                    })
                    .map(|&j| j as usize)
            }
            Names::Databases { dbs, .. } => {
                let channel = self.channels.get(ci)?;
                dbs.iter().rev().find_map(|d| {
                    let i = d.first as usize + d.db.find_real_index(variable)?;
                    (self.channel_name(i) == channel).then_some(i)
                })
            }
        }
    }

    pub fn channels(&self) -> &[String] {
        &self.channels
    }
    pub fn vars(&self) -> &[PlantVar] {
        &self.vars
    }
    pub fn tick(&self) -> u64 {
        self.tick
    }
    pub fn tick_ms(&self) -> u64 {
        self.tick_ms
    }
    /// A variable by channel and name; an empty channel finds the name in any channel (the
    /// first channel defining it).
    pub fn lookup(&self, channel: &str, variable: &str) -> Option<usize> {
        if channel.is_empty() {
            return match &self.names {
                Names::Own {
                    names,
                    ends,
                    by_name,
                    ..
                } => by_name
                    .find(hash_name(variable), |&j| {
                        name_in(names, ends, j as usize) == variable
                    })
                    .map(|&j| j as usize),
                Names::Databases { dbs, .. } => dbs
                    .iter()
                    .find_map(|d| Some(d.first as usize + d.db.find_real_index(variable)?)),
            };
        }
        let ci = self.channels.iter().rposition(|c| c == channel)?;
        self.lookup_in(ci, variable)
    }

    /// The timestamp of tick `t`.
    pub fn time_of(&self, t: u64) -> Timestamp {
        self.epoch.add_millis(t.saturating_mul(self.tick_ms))
    }

    /// Runs the simulation up to tick `t`, computing at most [`max_catch_up_ticks`] ticks
    /// (the earlier ones are skipped). Returns the ticks computed.
    pub fn advance_to(&mut self, t: u64) -> u64 {
        let most = max_catch_up_ticks(self.vars.len());
        if t > self.tick + most {
            self.tick = t - most;
        }
        let mut computed = 0;
        while self.tick < t {
            self.step();
            computed += 1;
        }
        computed
    }

    /// One tick.
    pub fn step(&mut self) {
        self.tick += 1;
        let now = self.time_of(self.tick);
        let tick = self.tick;
        for i in 0..self.vars.len() {
            let (lo, hi) = (self.vars[i].low, self.vars[i].high.max(self.vars[i].low));
            let span = (hi - lo).max(f64::EPSILON);
            let old = self.vars[i].value;
            let mut kind = self.vars[i].kind(&self.params.list);
            let new = match &mut kind {
                Kind::Constant => old,
                Kind::Noise { step } => {
                    let mid = lo + span / 2.0;
                    let v = old + self.rng.signed() * *step * span + (mid - old) * 0.01;
                    v.clamp(lo, hi)
                }
                Kind::Wave {
                    period,
                    noise,
                    phase,
                } => {
                    let x = (tick as f64 / *period as f64 + *phase) * std::f64::consts::TAU;
                    let v = lo + span * (0.5 + 0.4 * x.sin()) + self.rng.signed() * *noise * span;
                    v.clamp(lo, hi)
                }
                Kind::Ramp { period } => {
                    lo + span * ((tick % *period as u64) as f64 / *period as f64)
                }
                Kind::Tank {
                    fill,
                    drain,
                    inlet,
                    outlet,
                    rising,
                } => {
                    let on = |p: &Option<u32>, vars: &[PlantVar]| {
                        p.is_some_and(|p| vars[p as usize].value >= 0.5)
                    };
                    let mut v = old;
                    if inlet.is_none() && outlet.is_none() {
                        let f = (old - lo) / span;
                        if f >= 0.9 {
                            *rising = false;
                        } else if f <= 0.1 {
                            *rising = true;
                        }
                        v += if *rising { *fill } else { -*drain } * span;
                    } else {
                        if on(inlet, &self.vars) {
                            v += *fill * span;
                        }
                        if on(outlet, &self.vars) {
                            v -= *drain * span;
                        }
                    }
                    v += self.rng.signed() * 0.0005 * span;
                    v.clamp(lo, hi)
                }
                Kind::Pump {
                    tank,
                    inlet,
                    low,
                    high,
                    next_toggle,
                } => match tank {
                    Some(t) => {
                        let tv = &self.vars[*t as usize];
                        let f = (tv.value - tv.low) / (tv.high - tv.low).max(f64::EPSILON);
                        let running = old >= 0.5;
                        let (start, stop) = if *inlet {
                            (f < *low, f > *high)
                        } else {
                            (f > *high, f < *low)
                        };
                        f64::from(if running { !stop } else { start })
                    }
                    None => {
                        if tick >= *next_toggle {
                            *next_toggle = tick + 100 + self.rng.next_u64() % 300;
                            1.0 - old.round().clamp(0.0, 1.0)
                        } else {
                            old
                        }
                    }
                },
                Kind::Flow { pump, nominal } => {
                    if self.vars[*pump as usize].value >= 0.5 {
                        (lo + span * *nominal + self.rng.signed() * 0.01 * span).clamp(lo, hi)
                    } else {
                        lo
                    }
                }
                Kind::Counter { source, scale } => {
                    let v = old + self.vars[*source as usize].value.max(0.0) * *scale;
                    if v > hi {
                        lo
                    } else {
                        v
                    }
                }
            };
            let var = &mut self.vars[i];
            var.keep_state(&kind);
            // Integral types change only when their rounded value does.
            let changed = if is_integral(var.var_type) {
                new.round() != old.round()
            } else {
                new != old
            };
            var.value = new;
            if changed || !var.quality.is_good() && var.tag != KindTag::Constant {
                var.quality = Quality::GOOD;
                var.timestamp = now;
                var.version = next_version(var.version);
            }
        }
    }

    /// The VQT of variable `i`, in its type.
    pub fn vqt(&self, i: usize) -> Vqt {
        let v = &self.vars[i];
        Vqt {
            value: typed(v.var_type, v.value),
            quality: v.quality,
            timestamp: v.timestamp,
        }
    }

    /// Sets a variable (a write). `None` quality/timestamp: good, now.
    pub fn set(
        &mut self,
        i: usize,
        value: f64,
        quality: Option<Quality>,
        timestamp: Option<Timestamp>,
    ) {
        let now = self.time_of(self.tick);
        let v = &mut self.vars[i];
        v.value = value;
        v.quality = quality.unwrap_or(Quality::GOOD);
        v.timestamp = timestamp.unwrap_or(now);
        v.version = next_version(v.version);
    }
}

/// The version after `v` (wrapping past 0, which subscribers use for "nothing sent").
fn next_version(v: u32) -> u32 {
    v.wrapping_add(1).max(1)
}

/// The name of variable `i` in an arena (`names`, `ends`: each name's end).
fn name_in<'a>(names: &'a str, ends: &[u32], i: usize) -> &'a str {
    let start = if i == 0 { 0 } else { ends[i - 1] as usize };
    &names[start..ends[i] as usize]
}

fn is_integral(t: VarType) -> bool {
    !matches!(t, VarType::R4 | VarType::R8)
}

/// An engineering value in the variable's type (integers rounded and saturated).
pub fn typed(t: VarType, v: f64) -> Value {
    let r = v.round();
    match t {
        VarType::R8 => Value::R8(v),
        VarType::I2 => Value::I2(r.clamp(i16::MIN as f64, i16::MAX as f64) as i16),
        VarType::UI2 => Value::UI2(r.clamp(0.0, u16::MAX as f64) as u16),
        VarType::I4 => Value::I4(r.clamp(i32::MIN as f64, i32::MAX as f64) as i32),
        VarType::UI4 => Value::UI4(r.clamp(0.0, u32::MAX as f64) as u32),
        VarType::UI1 => Value::UI1(r.clamp(0.0, 255.0) as u8),
        VarType::I1 => Value::I1(r.clamp(-128.0, 127.0) as i8),
        VarType::BOOL => Value::Bool(v >= 0.5),
        _ => Value::R4(v as f32),
    }
}

/// A written value as a number, if it is an integer or a real (the only kinds asix accepts).
pub fn numeric(v: &Value) -> Option<f64> {
    Some(match v {
        Value::I1(x) => *x as f64,
        Value::UI1(x) => *x as f64,
        Value::I2(x) => *x as f64,
        Value::UI2(x) => *x as f64,
        Value::I4(x) => *x as f64,
        Value::UI4(x) => *x as f64,
        Value::I8(x) => *x as f64,
        Value::UI8(x) => *x as f64,
        Value::R4(x) if x.is_finite() => *x as f64,
        Value::R8(x) if x.is_finite() => *x,
        _ => return None,
    })
}

/// Name of the demo application's channel.
pub const ACID_PLANT_CHANNEL: &str = "Demo_Wytwornia_Kwasu";

/// The built-in acid plant (Wytwornia_Kwasu): sulphur burning, a four-bed converter,
/// absorption, and an acid tank farm with pumps — 32 variables.
pub fn acid_plant() -> ChannelDef {
    use Behaviour::*;
    let r4 = VarType::R4;
    let i2 = VarType::I2;
    let ui4 = VarType::UI4;
    let s = |n: &str| Some(n.to_owned());
    let v = |name: &str, t: VarType, lo: f64, hi: f64, w: bool, b: Behaviour| {
        (VarSpec::new(name, t, lo, hi, w), b)
    };
    let vars = vec![
        v(
            "PIEC_TEMP",
            r4,
            950.0,
            1150.0,
            false,
            Wave {
                period: 1800,
                noise: 0.004,
            },
        ),
        v("PIEC_TEMP_ZADANA", r4, 950.0, 1150.0, true, Constant),
        v("SIARKA_DOZOWANIE", r4, 0.0, 20.0, true, Constant),
        v(
            "SIARKA_PRZEPLYW",
            r4,
            0.0,
            20.0,
            false,
            Noise { step: 0.01 },
        ),
        v(
            "POWIETRZE_PRZEPLYW",
            r4,
            0.0,
            60000.0,
            false,
            Noise { step: 0.005 },
        ),
        v(
            "DMUCHAWA_OBROTY",
            r4,
            0.0,
            3000.0,
            false,
            Wave {
                period: 2400,
                noise: 0.002,
            },
        ),
        v("DMUCHAWA_PRACA", i2, 0.0, 1.0, true, Constant),
        v("SO2_STEZENIE", r4, 8.0, 12.0, false, Noise { step: 0.01 }),
        v("O2_STEZENIE", r4, 8.0, 13.0, false, Noise { step: 0.008 }),
        v(
            "KONW_T1",
            r4,
            420.0,
            620.0,
            false,
            Wave {
                period: 1200,
                noise: 0.003,
            },
        ),
        v(
            "KONW_T2",
            r4,
            440.0,
            560.0,
            false,
            Wave {
                period: 1500,
                noise: 0.003,
            },
        ),
        v(
            "KONW_T3",
            r4,
            430.0,
            500.0,
            false,
            Wave {
                period: 1700,
                noise: 0.003,
            },
        ),
        v(
            "KONW_T4",
            r4,
            410.0,
            460.0,
            false,
            Wave {
                period: 1900,
                noise: 0.003,
            },
        ),
        v(
            "KONW_SPRAWNOSC",
            r4,
            98.0,
            99.9,
            false,
            Noise { step: 0.005 },
        ),
        v(
            "ABS_KWAS_STEZENIE",
            r4,
            97.5,
            99.5,
            false,
            Noise { step: 0.004 },
        ),
        v(
            "ABS_KWAS_TEMP",
            r4,
            60.0,
            90.0,
            false,
            Wave {
                period: 900,
                noise: 0.005,
            },
        ),
        v("ABS_WODA_DOZOWANIE", r4, 0.0, 10.0, true, Constant),
        v(
            "ZB1_POZIOM",
            r4,
            0.0,
            100.0,
            false,
            Tank {
                fill: 0.003,
                drain: 0.002,
                inlet: s("P1_PRACA"),
                outlet: s("P2_PRACA"),
            },
        ),
        v(
            "ZB2_POZIOM",
            r4,
            0.0,
            100.0,
            false,
            Tank {
                fill: 0.002,
                drain: 0.0025,
                inlet: s("P2_PRACA"),
                outlet: s("P3_PRACA"),
            },
        ),
        v(
            "ZB3_POZIOM",
            r4,
            0.0,
            100.0,
            false,
            Tank {
                fill: 0.004,
                drain: 0.003,
                inlet: None,
                outlet: None,
            },
        ),
        v(
            "P1_PRACA",
            i2,
            0.0,
            1.0,
            false,
            Pump {
                tank: s("ZB1_POZIOM"),
                inlet: true,
                low_mark: 0.2,
                high_mark: 0.85,
            },
        ),
        v(
            "P2_PRACA",
            i2,
            0.0,
            1.0,
            false,
            Pump {
                tank: s("ZB2_POZIOM"),
                inlet: true,
                low_mark: 0.25,
                high_mark: 0.8,
            },
        ),
        v(
            "P3_PRACA",
            i2,
            0.0,
            1.0,
            false,
            Pump {
                tank: s("ZB2_POZIOM"),
                inlet: false,
                low_mark: 0.3,
                high_mark: 0.7,
            },
        ),
        v(
            "P4_PRACA",
            i2,
            0.0,
            1.0,
            false,
            Pump {
                tank: None,
                inlet: true,
                low_mark: 0.0,
                high_mark: 0.0,
            },
        ),
        v(
            "P1_PRZEPLYW",
            r4,
            0.0,
            50.0,
            false,
            Flow {
                pump: "P1_PRACA".into(),
                nominal: 0.7,
            },
        ),
        v(
            "P2_PRZEPLYW",
            r4,
            0.0,
            50.0,
            false,
            Flow {
                pump: "P2_PRACA".into(),
                nominal: 0.6,
            },
        ),
        v(
            "P3_PRZEPLYW",
            r4,
            0.0,
            50.0,
            false,
            Flow {
                pump: "P3_PRACA".into(),
                nominal: 0.65,
            },
        ),
        v(
            "CHLODNICA_T_WE",
            r4,
            20.0,
            40.0,
            false,
            Noise { step: 0.01 },
        ),
        v(
            "CHLODNICA_T_WY",
            r4,
            15.0,
            30.0,
            false,
            Noise { step: 0.01 },
        ),
        v(
            "CISNIENIE_KOMORA",
            r4,
            90.0,
            130.0,
            false,
            Noise { step: 0.01 },
        ),
        v(
            "PRODUKCJA_LICZNIK",
            ui4,
            0.0,
            4_000_000_000.0,
            false,
            Counter {
                source: "P3_PRZEPLYW".into(),
                scale: 1.0,
            },
        ),
        v(
            "ALARM_ZBIORCZY",
            i2,
            0.0,
            1.0,
            false,
            Pump {
                tank: s("ZB3_POZIOM"),
                inlet: false,
                low_mark: 0.12,
                high_mark: 0.88,
            },
        ),
    ];
    ChannelDef {
        name: ACID_PLANT_CHANNEL.to_owned(),
        vars,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_history_different_seed_different_history() {
        let chs = [acid_plant()];
        let mut a = Plant::new(&chs, 42, 100, Timestamp(0));
        let mut b = Plant::new(&chs, 42, 100, Timestamp(0));
        let mut c = Plant::new(&chs, 43, 100, Timestamp(0));
        a.advance_to(500);
        b.advance_to(250);
        b.advance_to(500);
        c.advance_to(500);
        let va: Vec<_> = (0..a.vars().len()).map(|i| a.vqt(i)).collect();
        let vb: Vec<_> = (0..b.vars().len()).map(|i| b.vqt(i)).collect();
        let vc: Vec<_> = (0..c.vars().len()).map(|i| c.vqt(i)).collect();
        assert_eq!(va, vb);
        assert_ne!(va, vc);
        assert_eq!(a.time_of(500), Timestamp(500 * 100 * 10_000));
    }

    #[test]
    fn tanks_fill_and_drain_and_pumps_switch_within_ranges() {
        let chs = [acid_plant()];
        let mut p = Plant::new(&chs, 7, 100, Timestamp(0));
        let lvl = p.lookup(ACID_PLANT_CHANNEL, "ZB1_POZIOM").unwrap();
        let pump = p.lookup(ACID_PLANT_CHANNEL, "P1_PRACA").unwrap();
        let (mut lo, mut hi, mut switches, mut last) =
            (f64::MAX, f64::MIN, 0, p.vars()[pump].value);
        for _ in 0..5000 {
            p.step();
            let v = p.vars()[lvl].value;
            lo = lo.min(v);
            hi = hi.max(v);
            if p.vars()[pump].value != last {
                switches += 1;
                last = p.vars()[pump].value;
            }
            for (i, var) in p.vars().iter().enumerate() {
                assert!(
                    var.value >= var.spec().low && var.value <= var.spec().high,
                    "{} = {}",
                    p.name(i),
                    var.value
                );
            }
        }
        assert!(hi - lo > 40.0, "level only moved between {lo} and {hi}");
        assert!(switches >= 2, "pump switched {switches} times");
    }

    #[test]
    fn the_demo_database_becomes_a_plant_by_channel() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../demo/wytwornia_kwasu/wytwornia_kwasu.zez");
        let Ok((db, _)) = asix_model::load_database_file(&path, None) else {
            panic!("demo database at {}", path.display());
        };
        let chs = channels_from_database(&db, ACID_PLANT_CHANNEL);
        let names: Vec<&str> = chs.iter().map(|c| c.name.as_str()).collect();
        assert!(
            names.contains(&"SIARKA") && names.contains(&"PIEC"),
            "{names:?}"
        );
        assert_eq!(
            chs.iter().map(|c| c.vars.len()).sum::<usize>(),
            db.variables.len()
        );
        let mut p = Plant::new(&chs, 3, 100, Timestamp(0));
        let lvl = p.lookup("SIARKA", "KW_A000").unwrap();
        let first = p.vars()[lvl].value;
        p.advance_to(600);
        assert_ne!(p.vars()[lvl].value, first, "a level moves");
        for (i, v) in p.vars().iter().enumerate() {
            assert!(
                v.value >= v.spec().low && v.value <= v.spec().high,
                "{} = {}",
                p.name(i),
                v.value
            );
        }
        let sp = chs
            .iter()
            .flat_map(|c| &c.vars)
            .find(|(s, _)| s.name == "KW_A110")
            .unwrap();
        assert_eq!(sp.1, Behaviour::Constant);
        // Control variables report healthy.
        let k = p.lookup("DIAGNOSTYKA", "KW_K001").unwrap();
        assert_eq!(p.vqt(k).value, Value::I2(0));
    }

    /// A digest of every variable's VQT and version after `ticks` ticks, with a write on
    /// the way.
    fn history_digest(p: &mut Plant, ticks: u64) -> u64 {
        let mut h = 0xcbf2_9ce4_8422_2325u64;
        let mut eat = |text: String| {
            for b in text.bytes() {
                h = (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
            }
        };
        p.advance_to(ticks / 2);
        p.set(1, 12.0, None, None);
        p.advance_to(ticks);
        for i in 0..p.vars().len() {
            eat(format!("{i} {:?} {}", p.vqt(i), p.vars()[i].version));
        }
        h
    }

    fn demo_db() -> asix_model::VarDatabase {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../demo/wytwornia_kwasu/wytwornia_kwasu.zez");
        match asix_model::load_database_file(&path, None) {
            Ok((db, _)) => db,
            Err(e) => panic!("demo database at {}: {e}", path.display()),
        }
    }

    /// The simulation's values are a function of the seed: these digests pin them, so that
    /// a change of the plant's layout cannot change a value.
    #[test]
    fn histories_are_those_of_the_plant_before_its_compact_layout() {
        let mut acid = Plant::new(&[acid_plant()], 42, 100, Timestamp(0));
        let chs = channels_from_database(&demo_db(), ACID_PLANT_CHANNEL);
        let mut demo = Plant::new(&chs, 5, 250, Timestamp(1_000_000));
        let db = demo_db();
        let mut from_db = Plant::from_databases(
            &[std::sync::Arc::new(db)],
            ACID_PLANT_CHANNEL,
            9,
            250,
            Timestamp(0),
        );
        let digests = (
            history_digest(&mut acid, 3000),
            history_digest(&mut demo, 3000),
            history_digest(&mut from_db, 3000),
        );
        assert_eq!(
            digests,
            (
                7135225649673736161,
                1555995000226565030,
                15002386707565514508
            )
        );
    }

    /// One advance of a large plant far behind computes at most `MAX_CATCH_UP_VAR_STEPS`
    /// variable steps (at least one tick) and skips the earlier ticks, whatever the time
    /// behind: the in-process simulation advances the plant under the engine's lock, so a
    /// device read after an idle hour costs a plant of 100,000 variables 19 ticks, not
    /// 10,000 (10^9 variable steps, minutes of the engine locked). A small plant still
    /// computes every tick it can.
    #[test]
    fn a_large_plant_far_behind_computes_a_bounded_number_of_steps() {
        let db = std::sync::Arc::new(demo_db());
        let copies = 100_000 / db.variables.len() + 1;
        let mut p = Plant::from_databases(
            &vec![std::sync::Arc::clone(&db); copies],
            "CH",
            1,
            250,
            Timestamp(0),
        );
        let n = p.vars().len() as u64;
        assert!(n >= 100_000, "{n}");
        let hour = 3600 * 4;
        let computed = p.advance_to(hour);
        assert_eq!(computed, MAX_CATCH_UP_VAR_STEPS / n);
        assert!(computed * n <= MAX_CATCH_UP_VAR_STEPS);
        assert_eq!(p.tick(), hour);
        assert_eq!(p.time_of(p.tick()), Timestamp(0).add_millis(hour * 250));
        assert_eq!(p.advance_to(hour + 1), 1, "then tick by tick");
        assert_eq!(p.advance_to(hour + 1), 0);

        let mut small = Plant::from_databases(&[db], "CH", 1, 250, Timestamp(0));
        assert_eq!(small.advance_to(3000), 3000);
        assert_eq!(max_catch_up_ticks(1_000_000), 2);
        assert_eq!(max_catch_up_ticks(10_000_000), 1);
        assert_eq!(max_catch_up_ticks(0), MAX_CATCH_UP_TICKS);
    }

    /// A plant made from databases looks names up through the databases' index as a plant
    /// of its own names does through its own: by channel the last variable of the name in
    /// the channel, without one the first in any channel (here: a database twice).
    #[test]
    fn a_plant_of_databases_finds_names_as_a_plant_of_its_own_names() {
        let db = std::sync::Arc::new(demo_db());
        let n = db.variables.len();
        let p = Plant::from_databases(&[db.clone(), db.clone()], "CH", 1, 100, Timestamp(0));
        let own = Plant::new(&channels_from_database(&db, "CH"), 1, 100, Timestamp(0));
        assert_eq!(p.vars().len(), 2 * n);
        let mut channels = own.channels().to_vec();
        channels.sort();
        let mut ours = p.channels().to_vec();
        ours.sort();
        assert_eq!(ours, channels);
        for i in 0..n {
            let name = p.name(i);
            assert_eq!(p.name(n + i), name);
            let ch = &p.channels()[p.channel_of(i).unwrap()];
            assert_eq!(p.lookup(ch, name), Some(n + i), "{ch} {name}");
            assert_eq!(p.lookup("", name), Some(i), "{name}");
            let o = own.lookup(ch, name).unwrap();
            assert_eq!(
                (own.name(o), own.vars()[o].spec()),
                (name, p.vars()[i].spec())
            );
            let other = p.channels().iter().find(|c| *c != ch).unwrap();
            assert_eq!(p.lookup(other, name), None, "{name} is not in {other}");
            assert_eq!(
                p.lookup(ch, &name.to_lowercase()),
                None,
                "names keep their case"
            );
        }
        assert_eq!(p.lookup("", "NO_SUCH_VARIABLE"), None);
        assert_eq!(p.lookup("NO_SUCH_CHANNEL", p.name(0)), None);
    }

    #[test]
    fn plant_variables_stay_compact() {
        assert!(std::mem::size_of::<PlantVar>() <= 64);
    }

    #[test]
    fn writes_hold_on_constants_and_integral_values_are_typed() {
        let chs = [acid_plant()];
        let mut p = Plant::new(&chs, 1, 100, Timestamp(0));
        let sp = p.lookup(ACID_PLANT_CHANNEL, "PIEC_TEMP_ZADANA").unwrap();
        p.set(sp, 1000.5, None, None);
        p.advance_to(100);
        assert_eq!(p.vqt(sp).value, Value::R4(1000.5));
        let pump = p.lookup(ACID_PLANT_CHANNEL, "P1_PRACA").unwrap();
        assert!(matches!(p.vqt(pump).value, Value::I2(0 | 1)));
        assert_eq!(numeric(&Value::Bstr("1".into())), None);
        assert_eq!(numeric(&Value::UI2(7)), Some(7.0));
    }
}
