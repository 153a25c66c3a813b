//! One asix data-source backend over a raw variable source: [`AsixBackend`] implements the
//! engine's [`Backend`] once, for the in-process simulation ([`crate::sim::inproc`]) and
//! for the asix network ([`crate::datasource`]), over a small raw [`VariableSource`] trait
//! that knows variables, not asix items.
//!
//! What the adapter holds, once:
//! - **Item slots** at [`SourceKey::index`] (dense: the engine reuses freed indices), each
//!   with its rate and its resolution by the asix pipeline ([`crate::pipeline::resolve`]),
//!   made when the item is subscribed and kept; reads and writes of subscribed items reuse
//!   it, reads and writes of items nothing subscribes resolve once per request.
//! - **Fan-out**: a raw variable is subscribed once, at the fastest rate any item reading
//!   it (or whose quality rules read it) asks for, and each of its samples goes to every
//!   item on it (value item, derived items, the same variable on other access paths).
//!   The control and limit variables an item's quality rules read are subscribed with the
//!   item, without being items, and let go with the last item needing them; when one of
//!   them changes, the items whose quality it changes are reported again.
//! - **Quality rules, derivation and write checks** of the pipeline
//!   ([`crate::pipeline::Resolved::sample`], [`crate::pipeline::Resolved::check_write`]).
//! - **Device requests** spread over the source's parts ([`VariableSource::Part`]: the
//!   AsixConnect channel's client on the network, one part in the simulation), answered to
//!   the engine when every part has answered, one result per item in request order.
//!
//! Decided for both sources (pinned by the tests below):
//! - A variable is sampled at the fastest rate of its items and every sample fans out; an
//!   item added to a variable already sampled gets the variable's current value at once
//!   (the simulation's current plant value, the network's last sample).
//! - An item the source has no variable for ([`Resolution::NoVariable`], and items the
//!   namespace does not know as live) is reported once, when subscribed, with
//!   BAD_CONFIG_ERROR, as the asix client reports a variable its server does not know;
//!   nothing about it ever changes, so it is not reported again.
//!
//! Nothing here reads a clock or blocks: time is the `now` of the engine's calls.

use std::collections::{btree_map, BTreeMap, HashMap};
use std::fmt::Debug;
use std::hash::{BuildHasherDefault, Hash};
use std::sync::Arc;

use asix_model::{AsixNamespace, Derivation};
use ctopc_core::compact::{grow_exact, Growth, Idx, IntHasher, PackedValue, SideMap};
use ctopc_core::model::datasource::{
    ItemVqt, ReadItem, SourceItem, SourceKey, SourceReqId, SourceRequest,
};
use ctopc_core::source::{Backend, SourceOutput};
use ctopc_core::{OpcError, Quality, Timestamp, Value, Vqt};

use crate::pipeline::{self, Resolution, Treatment};
use asix_model::ItemKey;

/// Identifies one raw device read or write of a [`VariableSource`] (chosen by the adapter).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RawId(pub u64);

/// What a raw source has ready.
#[derive(Debug)]
pub struct RawOutput<V> {
    /// New samples of subscribed variables.
    pub samples: Vec<(V, Vqt)>,
    /// Answers of raw reads: one result per variable, in request order.
    pub reads: Vec<(RawId, Vec<Result<Vqt, OpcError>>)>,
    /// Answers of raw writes: one result per variable, in request order.
    pub writes: Vec<(RawId, Vec<Result<(), OpcError>>)>,
}

impl<V> Default for RawOutput<V> {
    fn default() -> Self {
        RawOutput {
            samples: Vec::new(),
            reads: Vec::new(),
            writes: Vec::new(),
        }
    }
}

impl<V> RawOutput<V> {
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty() && self.reads.is_empty() && self.writes.is_empty()
    }
}

/// A raw source of asix variables: subscriptions, device reads and writes, samples. No asix
/// semantics (items, derivations, quality rules, write checks are the adapter's); never
/// blocks.
pub trait VariableSource: Send {
    /// The source's handle of a variable.
    type Var: Clone + Eq + Hash + Ord + Debug + Send + Sync;
    /// What a device request is spread over (each part is one raw request).
    type Part: Clone + Ord;

    /// The handle of the asix variable `key` as seen from the AsixConnect channel
    /// `channel`; `None`: the source has no such variable.
    fn lookup(&self, channel: &Arc<str>, key: &ItemKey) -> Option<Self::Var>;
    /// The part a variable's device requests go to.
    fn part(&self, var: &Self::Var) -> Self::Part;
    /// The variable's current value without asking a device, if the source has one (the
    /// simulation knows its plant; the network does not, and the adapter then takes the
    /// last sample).
    fn peek(&self, _var: &Self::Var) -> Option<Vqt> {
        None
    }
    /// Subscribes variables, or changes their rates (ms): push their samples from now on.
    fn subscribe(&mut self, now: Timestamp, vars: Vec<(Self::Var, u32)>);
    /// Lets variables go.
    fn unsubscribe(&mut self, now: Timestamp, vars: Vec<Self::Var>);
    /// Reads variables of one part from the device; answer once under `id`.
    fn read(&mut self, now: Timestamp, id: RawId, vars: Vec<Self::Var>);
    /// Writes variables of one part, all simple writes (no quality, no timestamp) or all
    /// extended ones; answer once under `id`.
    fn write(&mut self, now: Timestamp, id: RawId, items: Vec<(Self::Var, ItemVqt)>);
    /// Appends what is ready by `now`.
    fn poll(&mut self, now: Timestamp, out: &mut RawOutput<Self::Var>);
    /// When `poll` should next be called without a wake-up.
    fn poll_timeout(&self) -> Option<Timestamp>;
    /// Simulated data (OPC_STATUS_TEST)?
    fn is_simulation(&self) -> bool {
        false
    }
    /// The state of the source's channels for the `_Diagnostics` branch
    /// ([`Backend::channels`]); `subscribed`: every variable subscribed now (counted per
    /// channel). Default: none.
    fn channels(
        &self,
        _subscribed: &mut dyn Iterator<Item = &Self::Var>,
    ) -> Vec<ctopc_core::diagnostics::ChannelStatus> {
        Vec::new()
    }
}

/// A source item's resolution with the source's handles.
type Res<V> = Resolution<V>;

/// The shared resolutions of items without a source variable: they differ only in how a
/// write is refused (unknown item, or a derived item that is never writable), so that many
/// distinct unknown items cost only their [`Slot`].
struct Unserved<V> {
    not_live: Arc<Res<V>>,
    value: Arc<Res<V>>,
    derived: Arc<Res<V>>,
}

impl<V> Unserved<V> {
    fn new() -> Self {
        Unserved {
            not_live: Arc::new(Resolution::NotLive),
            value: Arc::new(Resolution::NoVariable(Derivation::Value)),
            derived: Arc::new(Resolution::NoVariable(Derivation::Formatted(None))),
        }
    }
}

/// What the adapter keeps of an item's resolution: its variable with its treatment,
/// shared with the other items treated the same way ([`AsixBackend::share`]: a plain value
/// item costs its variable and a pointer), or one of the [`Unserved`]
/// resolutions.
#[derive(Clone)]
enum ItemRes<V> {
    Var(V, Arc<Treatment<V>>),
    Unserved(Arc<Res<V>>),
}

impl<V> ItemRes<V> {
    /// The variable and its treatment, if the item has a variable.
    fn resolved(&self) -> Option<(&V, &Treatment<V>)> {
        match self {
            ItemRes::Var(v, t) => Some((v, t)),
            ItemRes::Unserved(_) => None,
        }
    }
}

/// The most raw samples whose room [`AsixBackend`] keeps from one poll to the next.
const RAW_SAMPLES_KEPT: usize = 4096;

/// The most distinct treatments [`AsixBackend::share`] keeps for sharing (without quality
/// rules a plant has few: a derivation and the rules of a channel; with them, the limits
/// and control variable of each kind of variable).
const SHARED_TREATMENTS: usize = 64;

/// A subscribed source item, at its [`SourceKey::index`] (24 bytes with the simulation's
/// variables: the index is the slot's, only the generation is kept).
struct Slot<V> {
    generation: u32,
    /// Sampling rate asked for, ms.
    rate: u32,
    /// Resolved when subscribed.
    r: ItemRes<V>,
}

/// Keys of items, most often none or one: those inline, more in a vector of their own
/// (16 bytes, no allocation for one item: most variables of a large subscription have
/// exactly one).
#[derive(Debug, Clone, Default, PartialEq)]
enum Keys {
    #[default]
    None,
    One(SourceKey),
    // Boxed: a thin pointer keeps `Keys` at 16 bytes (a `Vec` or boxed slice: 24).
    #[allow(clippy::box_collection)]
    Many(Box<Vec<SourceKey>>),
}

impl Keys {
    fn as_slice(&self) -> &[SourceKey] {
        match self {
            Keys::None => &[],
            Keys::One(k) => std::slice::from_ref(k),
            Keys::Many(v) => v,
        }
    }

    fn contains(&self, k: &SourceKey) -> bool {
        self.as_slice().contains(k)
    }

    fn push(&mut self, k: SourceKey) {
        *self = match std::mem::take(self) {
            Keys::None => Keys::One(k),
            Keys::One(first) => Keys::Many(Box::new(vec![first, k])),
            Keys::Many(mut v) => {
                v.push(k);
                Keys::Many(v)
            }
        };
    }

    /// Removes `k`: every occurrence of it, or with `first_only` the first.
    fn remove(&mut self, k: SourceKey, first_only: bool) {
        match self {
            Keys::None => {}
            Keys::One(x) => {
                if *x == k {
                    *self = Keys::None;
                }
            }
            Keys::Many(v) => {
                if first_only {
                    if let Some(i) = v.iter().position(|x| *x == k) {
                        v.swap_remove(i);
                    }
                } else {
                    v.retain(|x| *x != k);
                }
                match v[..] {
                    [] => *self = Keys::None,
                    [one] => *self = Keys::One(one),
                    _ => {}
                }
            }
        }
    }
}

/// A raw variable's full state in [`Vars`] (40 bytes).
#[derive(Default)]
struct VarState {
    /// The items reading it.
    items: Keys,
    /// The items whose quality rules read it (control and limit variables), an item once
    /// per variable (twice while it is subscribed again).
    rule_users: Keys,
    /// Its last sample, kept only where it is read: when the source cannot
    /// [`VariableSource::peek`] (the quality rules read it), or for a rule variable (a new
    /// value or quality re-checks its users). Boxed: most variables of the simulation keep
    /// none.
    last: Option<Box<Vqt>>,
}

/// A variable's entry in [`Vars::map`], in 4 bytes: the slot index of its only item (the
/// short form), or the index of its [`VarState`] in [`Vars::rich`]. The top bit says which,
/// so the short form takes slot indices below 2^31 (an item at a larger one goes rich).
#[derive(Clone, Copy, PartialEq, Eq)]
struct VarEntry(u32);

/// What a [`VarEntry`] names.
#[derive(Clone, Copy, PartialEq, Eq)]
enum VarAt {
    /// The only item's slot index.
    One(u32),
    Rich(Idx<VarState>),
}

impl VarEntry {
    const RICH: u32 = 1 << 31;

    /// The short entry of the variable whose only item is at slot index `i`, if it fits.
    fn one(i: u32) -> Option<Self> {
        (i & Self::RICH == 0).then_some(VarEntry(i))
    }

    fn rich(i: Idx<VarState>) -> Self {
        assert!(i.raw() & Self::RICH == 0, "rich variables fit 31 bits");
        VarEntry(Self::RICH | i.raw())
    }

    fn at(self) -> VarAt {
        if self.0 & Self::RICH == 0 {
            VarAt::One(self.0)
        } else {
            VarAt::Rich(Idx::from_raw(self.0 & !Self::RICH))
        }
    }

    fn rich_idx(self) -> Option<Idx<VarState>> {
        match self.at() {
            VarAt::Rich(i) => Some(i),
            VarAt::One(_) => None,
        }
    }
}

/// A short variable's last sample (24 bytes, and as an `Option` too): its value packed, a
/// string or array in [`Vars::last_values`] by slot index.
#[derive(Clone, Copy)]
struct Last {
    value: PackedValue,
    quality: Quality,
    timestamp: Timestamp,
}

/// The raw variables wanted by subscribed items. Most variables of a large subscription
/// of the simulation are read by exactly one item, with no item's rules reading them and
/// no sample kept: such a variable's entry is that item's slot index, 4 bytes besides the
/// variable in the map (a `u32` variable of the simulation: 8 bytes and a control byte;
/// a [`VarState`] would add 40). The others have a [`VarState`] in `rich`, and go back to
/// the short form once they are plain again ([`Vars::settle`]). A source that cannot peek
/// (the network) keeps every sampled variable's last sample: a short variable's is in
/// `lasts` at its item's slot index (24 bytes, where a [`VarState`] and a boxed sample
/// would take 88).
struct Vars<V> {
    /// By the source's variable (an index or a short name of the server's own
    /// configuration, never a peer's choice): a multiplicative hash, not SipHash, which
    /// cost as much as the rest of a sample's handling.
    map: HashMap<V, VarEntry, BuildHasherDefault<IntHasher>>,
    rich: Vec<VarState>,
    /// Indices of `rich` free for reuse.
    free: Vec<Idx<VarState>>,
    /// The last samples of short variables, at their items' slot indices; empty while none
    /// is kept (the simulation's plain variables keep none) ...
    lasts: Vec<Option<Last>>,
    /// ... and their string and array values, by slot index.
    last_values: SideMap<u32, Value>,
}

/// A variable's entry in [`Vars`], read.
enum VarRef<'a> {
    /// Read by the item at this slot index, and that is all.
    One(u32),
    Rich(&'a VarState),
}

impl<V: Eq + Hash + Clone> Vars<V> {
    fn new() -> Self {
        Vars {
            map: HashMap::default(),
            rich: Vec::new(),
            free: Vec::new(),
            lasts: Vec::new(),
            last_values: SideMap::default(),
        }
    }

    fn get(&self, v: &V) -> Option<VarRef<'_>> {
        Some(match self.map.get(v)?.at() {
            VarAt::One(i) => VarRef::One(i),
            VarAt::Rich(i) => VarRef::Rich(&self.rich[i]),
        })
    }

    /// The variable's last sample, if kept.
    fn last(&self, v: &V) -> Option<Vqt> {
        match self.get(v)? {
            VarRef::One(i) => {
                let last = self.lasts.get(i as usize)?.as_ref()?;
                Some(Vqt {
                    value: self.last_values.get(last.value, i).into_owned(),
                    quality: last.quality,
                    timestamp: last.timestamp,
                })
            }
            VarRef::Rich(st) => st.last.as_deref().cloned(),
        }
    }

    fn keys(&self) -> impl Iterator<Item = &V> {
        self.map.keys()
    }

    /// The variable's full state, made from its short entry (`one`: the key of the item at
    /// a slot index) or anew.
    fn rich_mut(&mut self, v: &V, one: impl FnOnce(u32) -> Option<SourceKey>) -> &mut VarState {
        let short = match self.map.get(v).map(|e| e.at()) {
            Some(VarAt::Rich(i)) => return &mut self.rich[i],
            Some(VarAt::One(i)) => Some(i),
            None => None,
        };
        let st = VarState {
            items: match short.and_then(one) {
                Some(k) => Keys::One(k),
                None => Keys::None,
            },
            rule_users: Keys::None,
            last: short.and_then(|i| self.take_last(i)).map(Box::new),
        };
        let i = match self.free.pop() {
            Some(i) => {
                self.rich[i] = st;
                i
            }
            None => {
                // By a quarter: a source that cannot peek (the network) keeps every
                // sampled variable's last sample here.
                grow_exact(&mut self.rich, 1, Growth::quarter(16));
                self.rich.push(st);
                Idx::new(self.rich.len() - 1)
            }
        };
        match self.map.get_mut(v) {
            Some(e) => *e = VarEntry::rich(i),
            None => {
                self.map.insert(v.clone(), VarEntry::rich(i));
            }
        }
        &mut self.rich[i]
    }

    /// Item `k` reads `v` (noted once).
    fn add_item(&mut self, v: &V, k: SourceKey, one: impl FnOnce(u32) -> Option<SourceKey>) {
        match self.map.get(v) {
            None => {
                if let Some(e) = VarEntry::one(k.index()) {
                    self.map.insert(v.clone(), e);
                    return;
                }
            }
            Some(e) if e.at() == VarAt::One(k.index()) => return,
            Some(_) => {}
        }
        let st = self.rich_mut(v, one);
        if !st.items.contains(&k) {
            st.items.push(k);
        }
    }

    /// Item `k`'s rules read `v` (noted once per use).
    fn add_rule_user(&mut self, v: &V, k: SourceKey, one: impl FnOnce(u32) -> Option<SourceKey>) {
        self.rich_mut(v, one).rule_users.push(k);
    }

    /// Item `k` no longer reads `v` (a variable nothing else needs keeps its entry, if it
    /// has a full state, until [`Self::remove`]).
    fn remove_item(&mut self, v: &V, k: SourceKey) {
        let Some(e) = self.map.get(v) else {
            return;
        };
        match e.at() {
            VarAt::One(i) => {
                if i == k.index() {
                    self.map.remove(v);
                    self.take_last(i);
                }
            }
            VarAt::Rich(i) => self.rich[i].items.remove(k, false),
        }
    }

    /// One use of `v` by item `k`'s rules less.
    fn remove_rule_user(&mut self, v: &V, k: SourceKey) {
        if let Some(i) = self.map.get(v).and_then(|e| e.rich_idx()) {
            self.rich[i].rule_users.remove(k, true);
        }
    }

    /// Forgets `v`.
    fn remove(&mut self, v: &V) {
        match self.map.remove(v).map(VarEntry::at) {
            Some(VarAt::Rich(i)) => self.free_rich(i),
            Some(VarAt::One(i)) => {
                self.take_last(i);
            }
            None => {}
        }
    }

    /// Takes the last sample kept at slot index `i`.
    fn take_last(&mut self, i: u32) -> Option<Vqt> {
        let mut last = self.lasts.get_mut(i as usize)?.take()?;
        Some(Vqt {
            value: self.last_values.take(&mut last.value, i),
            quality: last.quality,
            timestamp: last.timestamp,
        })
    }

    /// Keeps `vqt` as the last sample at slot index `i`, with room made if need be (by what
    /// is missing, or a quarter: the slots are dense).
    fn put_last(&mut self, i: u32, vqt: Vqt) {
        let at = i as usize;
        if at >= self.lasts.len() {
            let need = at + 1 - self.lasts.len();
            grow_exact(&mut self.lasts, need, Growth::quarter(16));
            self.lasts.resize(at + 1, None);
        }
        let last = self.lasts[at].get_or_insert(Last {
            value: PackedValue::EMPTY,
            quality: vqt.quality,
            timestamp: vqt.timestamp,
        });
        (last.quality, last.timestamp) = (vqt.quality, vqt.timestamp);
        self.last_values.put(&mut last.value, i, vqt.value);
    }

    fn free_rich(&mut self, i: Idx<VarState>) {
        self.rich[i] = VarState::default();
        self.free.push(i);
        if self.free.len() == self.rich.len() {
            // None left: their room goes too.
            self.rich = Vec::new();
            self.free = Vec::new();
        }
    }

    /// Keeps `last` as the variable's last sample (`Some`), or keeps none.
    fn set_last(&mut self, v: &V, last: Option<Vqt>, one: impl FnOnce(u32) -> Option<SourceKey>) {
        let at = self.map.get(v).map(|e| e.at());
        match (last, at) {
            (Some(vqt), Some(VarAt::One(i))) => self.put_last(i, vqt),
            (Some(vqt), _) => match &mut self.rich_mut(v, one).last {
                Some(last) => **last = vqt,
                last @ None => *last = Some(Box::new(vqt)),
            },
            (None, Some(VarAt::One(i))) => {
                self.take_last(i);
            }
            (None, Some(VarAt::Rich(i))) => {
                self.rich[i].last = None;
                self.settle(v);
            }
            (None, None) => {}
        }
    }

    /// Gives a variable read by one item and nothing else its short entry again (with its
    /// last sample, where short variables keep theirs already).
    fn settle(&mut self, v: &V) {
        let Some(i) = self.map.get(v).and_then(|e| e.rich_idx()) else {
            return;
        };
        let VarState {
            items: Keys::One(k),
            rule_users: Keys::None,
            last,
        } = &self.rich[i]
        else {
            return;
        };
        let k = k.index();
        // A last sample moves only into room made already (a peeking source's
        // variables keep theirs only while rules read them).
        let Some(short) = VarEntry::one(k) else {
            return;
        };
        if last.is_some() && k as usize >= self.lasts.len() {
            return;
        }
        if let Some(last) = self.rich[i].last.take() {
            self.put_last(k, *last);
        }
        if let Some(e) = self.map.get_mut(v) {
            *e = short;
        }
        self.free_rich(i);
    }
}

/// The variables a request touched, with the rate each was subscribed at before it
/// (`None`: not subscribed).
type Touched<V> = BTreeMap<V, Option<u32>>;

/// One device request of the engine, possibly spread over several parts.
struct Pending<V> {
    write: bool,
    /// Each position's result once known (writes: `Vqt::default()` for success); empty
    /// while no position is known (a request of one part is then answered in one go).
    results: Vec<Option<Result<Vqt, OpcError>>>,
    /// Reads: each position's resolution when the request was sent (the subscribed
    /// item's, else one made for the request), which its answer goes through the
    /// pipeline with.
    own: Vec<ItemRes<V>>,
    remaining: usize,
}

/// What a raw answer answers.
enum Answered<V> {
    /// The whole engine request (one part, nothing refused before).
    Whole(SourceReqId, Pending<V>),
    /// These positions of it.
    Part(SourceReqId, Vec<usize>),
}

/// A request spread over parts: each part with its positions in the request and what it
/// asks of the source, in the order the parts first appear.
type Parts<P, T> = Vec<(P, Vec<usize>, Vec<T>)>;

/// The entry of part `p`, added if new.
fn part_entry<P: PartialEq, T>(parts: &mut Parts<P, T>, p: P) -> &mut (P, Vec<usize>, Vec<T>) {
    let i = match parts.iter().position(|(q, ..)| *q == p) {
        Some(i) => i,
        None => {
            parts.push((p, Vec::new(), Vec::new()));
            parts.len() - 1
        }
    };
    &mut parts[i]
}

/// The positions of a raw request in its engine request (`None`: all of them, in order).
type Positions = Option<Vec<usize>>;

impl<V> Pending<V> {
    /// A position answered before any part is asked (refused by the checks).
    fn refuse(&mut self, pos: usize, r: Result<Vqt, OpcError>) {
        if self.results.is_empty() {
            self.results = vec![None; self.remaining];
        }
        if let Some(slot @ None) = self.results.get_mut(pos) {
            *slot = Some(r);
            self.remaining -= 1;
        }
    }
}

/// The asix data source over a raw variable source. See the module doc.
pub struct AsixBackend<S: VariableSource> {
    ns: Arc<AsixNamespace>,
    source: S,
    /// Indexed by [`SourceKey::index`].
    slots: Vec<Option<Slot<S::Var>>>,
    vars: Vars<S::Var>,
    unserved: Unserved<S::Var>,
    /// The treatments subscribed items share ([`Self::share`]).
    treatments: Vec<Arc<Treatment<S::Var>>>,
    /// Items subscribed since the last poll that get a sample at once (their variable was
    /// sampled already, or they have none).
    fresh: Vec<SourceKey>,
    next_raw: u64,
    /// Raw request -> (engine request, its positions).
    parts: HashMap<RawId, (SourceReqId, Positions)>,
    pending: HashMap<SourceReqId, Pending<S::Var>>,
    /// Answers complete, not yet polled.
    ready: SourceOutput,
    raw: RawOutput<S::Var>,
}

impl<S: VariableSource> AsixBackend<S> {
    /// The adapter over `source`, resolving items through `ns`.
    pub fn from_source(ns: Arc<AsixNamespace>, source: S) -> Self {
        AsixBackend {
            ns,
            source,
            slots: Vec::new(),
            vars: Vars::new(),
            unserved: Unserved::new(),
            treatments: Vec::new(),
            fresh: Vec::new(),
            next_raw: 0,
            parts: HashMap::new(),
            pending: HashMap::new(),
            ready: SourceOutput::default(),
            raw: RawOutput::default(),
        }
    }

    /// The raw source.
    pub fn source(&self) -> &S {
        &self.source
    }

    /// The raw source, mutably.
    pub fn source_mut(&mut self) -> &mut S {
        &mut self.source
    }

    fn slot_of(&self, key: SourceKey) -> Option<&Slot<S::Var>> {
        self.slots
            .get(key.index() as usize)?
            .as_ref()
            .filter(|s| s.generation == key.generation())
    }

    /// The key of the item in slot `i`.
    fn key_at(slots: &[Option<Slot<S::Var>>], i: u32) -> Option<SourceKey> {
        let s = slots.get(i as usize)?.as_ref()?;
        Some(SourceKey::new(i, s.generation))
    }

    /// Resolves an item through the pipeline, with the source's handles.
    fn resolve(&self, item: &SourceItem) -> ItemRes<S::Var> {
        let source = &self.source;
        match pipeline::resolve(&self.ns, item, |k| source.lookup(&item.channel, k)) {
            Resolution::NotLive => ItemRes::Unserved(Arc::clone(&self.unserved.not_live)),
            Resolution::NoVariable(Derivation::Value) => {
                ItemRes::Unserved(Arc::clone(&self.unserved.value))
            }
            Resolution::NoVariable(_) => ItemRes::Unserved(Arc::clone(&self.unserved.derived)),
            Resolution::Resolved(r) => ItemRes::Var(r.key, Arc::new(r.treatment)),
        }
    }

    /// A resolution to keep: its treatment replaced by an equal one already kept, if any,
    /// else kept for the next items: up to [`SHARED_TREATMENTS`], those no item uses any
    /// more making room first, then the one kept longest. (Items treated alike mostly come
    /// together, as a branch of the database's variables whose control variable and limits
    /// are the same; keeping only the first kinds would give a large subscription with
    /// quality rules a treatment per item after the first 64 kinds, 200 B an item.)
    fn share(&mut self, r: ItemRes<S::Var>) -> ItemRes<S::Var> {
        let ItemRes::Var(v, t) = r else {
            return r;
        };
        if let Some(same) = self.treatments.iter().find(|x| ***x == *t) {
            return ItemRes::Var(v, Arc::clone(same));
        }
        if self.treatments.len() == SHARED_TREATMENTS {
            self.treatments.retain(|x| Arc::strong_count(x) > 1);
        }
        if self.treatments.len() == SHARED_TREATMENTS {
            self.treatments.remove(0);
        }
        self.treatments.push(Arc::clone(&t));
        ItemRes::Var(v, t)
    }

    /// A variable's current raw VQT: the source's, else the last sample.
    fn current(&self, v: &S::Var) -> Option<Vqt> {
        self.source.peek(v).or_else(|| self.vars.last(v))
    }

    /// An item's VQT from a raw sample of its variable (quality rules over the current
    /// values of its rule variables, then the derivation).
    fn item_vqt(&self, t: &Treatment<S::Var>, raw: Vqt) -> Vqt {
        t.sample(raw, |v| self.current(v))
    }

    /// A subscribed item's current VQT; `None` before its variable has one.
    fn current_vqt(&self, k: SourceKey) -> Option<Vqt> {
        let (v, t) = self.slot_of(k)?.r.resolved()?;
        let raw = self.current(v)?;
        Some(self.item_vqt(t, raw))
    }

    /// The rate a variable is subscribed at: the fastest of the items reading it or whose
    /// rules read it; `None` when nothing wants it.
    fn rate_of(&self, v: &S::Var) -> Option<u32> {
        match self.vars.get(v)? {
            VarRef::One(i) => self.slots.get(i as usize)?.as_ref().map(|s| s.rate),
            VarRef::Rich(st) => st
                .items
                .as_slice()
                .iter()
                .chain(st.rule_users.as_slice())
                .filter_map(|k| self.slot_of(*k))
                .map(|s| s.rate)
                .min(),
        }
    }

    /// Notes the rate of a variable a request is about to change (the first note of a
    /// request is the state before it).
    fn touch(&self, touched: &mut Touched<S::Var>, v: &S::Var) {
        if let btree_map::Entry::Vacant(e) = touched.entry(v.clone()) {
            let rate = self.rate_of(e.key());
            e.insert(rate);
        }
    }

    /// [`Self::touch`] for an item's variable and its rule variables.
    fn touch_item(&self, touched: &mut Touched<S::Var>, r: &ItemRes<S::Var>) {
        if let Some((var, t)) = r.resolved() {
            self.touch(touched, var);
            for v in t.rule_variables() {
                self.touch(touched, v);
            }
        }
    }

    /// Adds item `k` (in its slot already) to the fan-out of its variable and to the users
    /// of its rule variables.
    fn attach(&mut self, k: SourceKey, r: &ItemRes<S::Var>) {
        let Some((var, t)) = r.resolved() else {
            return;
        };
        let slots = &self.slots;
        let one = |i: u32| Self::key_at(slots, i);
        self.vars.add_item(var, k, one);
        for v in t.rule_variables() {
            self.vars.add_rule_user(v, k, one);
        }
    }

    /// Takes item `k` out of the fan-out of its variable and one use out of its rule
    /// variables. (A variable nothing wants any more goes in [`Self::apply_touched`].)
    fn detach(&mut self, k: SourceKey, r: &ItemRes<S::Var>) {
        let Some((var, t)) = r.resolved() else {
            return;
        };
        self.vars.remove_item(var, k);
        for v in t.rule_variables() {
            self.vars.remove_rule_user(v, k);
        }
    }

    /// Brings the source in line with the variables a request touched: lets go of those
    /// nothing wants any more (forgetting their last samples), subscribes those newly
    /// wanted or wanted at another rate. Done once per request, from the state before and
    /// after it, so that a variable let go and taken again in one request is never
    /// unsubscribed, and the rate asked for is the final one. Returns the variables newly
    /// subscribed (their first sample comes from the source), in order.
    fn apply_touched(&mut self, now: Timestamp, touched: Touched<S::Var>) -> Vec<S::Var> {
        let mut gone = Vec::new();
        let mut wanted = Vec::new();
        let mut new = Vec::new();
        for (v, before) in touched {
            match self.rate_of(&v) {
                None => {
                    self.vars.remove(&v);
                    if before.is_some() {
                        gone.push(v);
                    }
                }
                Some(after) => {
                    self.vars.settle(&v);
                    if before != Some(after) {
                        if before.is_none() {
                            new.push(v.clone());
                        }
                        wanted.push((v, after));
                    }
                }
            }
        }
        if !gone.is_empty() {
            self.source.unsubscribe(now, gone);
        }
        if !wanted.is_empty() {
            self.source.subscribe(now, wanted);
        }
        new
    }

    fn subscribe(&mut self, now: Timestamp, subs: Vec<(SourceItem, u32)>) {
        let mut touched = Touched::new();
        let mut subscribed = Vec::with_capacity(subs.len());
        // The slots this request reaches: grown once, by a quarter or to exactly what a
        // large request needs if that is more.
        let top = subs
            .iter()
            .map(|(item, _)| item.key.index() as usize + 1)
            .max()
            .unwrap_or(0);
        let need = top.saturating_sub(self.slots.len());
        grow_exact(&mut self.slots, need, Growth::quarter(1024));
        for (item, rate) in subs {
            let key = item.key;
            let i = key.index() as usize;
            if self.slots.len() <= i {
                self.slots.resize_with(i + 1, || None);
            }
            // The rates before, with the item (or a stale one) still in its slot.
            let existing = self.slots[i]
                .as_ref()
                .map(|s| (SourceKey::new(key.index(), s.generation), s.r.clone()));
            if let Some((_, r)) = &existing {
                self.touch_item(&mut touched, r);
            }
            match existing {
                // Subscribed again (another rate): the resolution stays.
                Some((k, _)) if k == key => {
                    if let Some(s) = self.slots[i].as_mut() {
                        s.rate = rate;
                    }
                }
                old => {
                    if let Some((old_key, old_r)) = old {
                        // A stale item of an older generation.
                        self.slots[i] = None;
                        self.detach(old_key, &old_r);
                    }
                    let r = self.resolve(&item);
                    let r = self.share(r);
                    self.touch_item(&mut touched, &r);
                    self.slots[i] = Some(Slot {
                        generation: key.generation(),
                        rate,
                        r: r.clone(),
                    });
                    self.attach(key, &r);
                }
            }
            subscribed.push(key);
        }
        let new = self.apply_touched(now, touched);
        for k in subscribed {
            let at_once = match self.slot_of(k).map(|s| &s.r) {
                Some(ItemRes::Var(v, _)) => new.binary_search(v).is_err(),
                Some(_) => true,
                None => false,
            };
            if at_once {
                self.fresh.push(k);
            }
        }
    }

    fn set_rates(&mut self, now: Timestamp, rates: Vec<(SourceKey, u32)>) {
        let mut touched = Touched::new();
        for (k, rate) in rates {
            let Some(s) = self.slot_of(k) else {
                continue;
            };
            let r = s.r.clone();
            self.touch_item(&mut touched, &r);
            if let Some(Some(s)) = self.slots.get_mut(k.index() as usize) {
                s.rate = rate;
            }
        }
        self.apply_touched(now, touched);
    }

    fn unsubscribe(&mut self, now: Timestamp, keys: Vec<SourceKey>) {
        let mut touched = Touched::new();
        for k in keys {
            let Some(s) = self.slot_of(k) else {
                continue;
            };
            // The rates before, with the item still in its slot.
            let r = s.r.clone();
            self.touch_item(&mut touched, &r);
            self.slots[k.index() as usize] = None;
            self.detach(k, &r);
        }
        self.apply_touched(now, touched);
    }

    /// Answers the engine's request if every part has answered.
    fn finish(&mut self, req: SourceReqId) {
        if self.pending.get(&req).is_none_or(|p| p.remaining > 0) {
            return;
        }
        let Some(p) = self.pending.remove(&req) else {
            return;
        };
        let results = p
            .results
            .into_iter()
            .map(|r| r.unwrap_or(Err(OpcError::Fail)));
        if p.write {
            let results = results.map(|r| r.map(|_| ())).collect();
            self.ready.write_results.push((req, results));
            return;
        }
        let results = results
            .enumerate()
            .map(|(i, r)| self.read_vqt(&p.own, i, r?))
            .collect();
        self.ready.read_results.push((req, results));
    }

    /// A read item's VQT from the raw answer of position `i`: through the pipeline, with
    /// the resolution the request was sent with.
    fn read_vqt(&self, own: &[ItemRes<S::Var>], i: usize, raw: Vqt) -> Result<Vqt, OpcError> {
        let r = own.get(i).ok_or(OpcError::Fail)?;
        Ok(match r.resolved() {
            Some((_, t)) => self.item_vqt(t, raw),
            None => raw,
        })
    }

    /// The engine request a raw answer belongs to.
    fn answered(&mut self, id: RawId) -> Option<Answered<S::Var>> {
        let (req, positions) = self.parts.remove(&id)?;
        let Some(positions) = positions else {
            return self.pending.remove(&req).map(|p| Answered::Whole(req, p));
        };
        let p = self.pending.get_mut(&req)?;
        if p.results.is_empty() {
            p.results = vec![None; p.remaining];
        }
        Some(Answered::Part(req, positions))
    }

    /// A raw answer of one part: its results into their positions (a short answer fails
    /// the rest).
    fn fill(
        &mut self,
        req: SourceReqId,
        positions: Vec<usize>,
        mut results: impl Iterator<Item = Result<Vqt, OpcError>>,
    ) {
        if let Some(p) = self.pending.get_mut(&req) {
            for pos in positions {
                let r = results.next().unwrap_or(Err(OpcError::Fail));
                if let Some(slot @ None) = p.results.get_mut(pos) {
                    *slot = Some(r);
                    p.remaining -= 1;
                }
            }
        }
        self.finish(req);
    }

    fn answer_read(&mut self, id: RawId, results: Vec<Result<Vqt, OpcError>>) {
        match self.answered(id) {
            Some(Answered::Whole(req, p)) => {
                let mut results = results.into_iter();
                let out = (0..p.remaining)
                    .map(|i| {
                        let raw = results.next().unwrap_or(Err(OpcError::Fail))?;
                        self.read_vqt(&p.own, i, raw)
                    })
                    .collect();
                self.ready.read_results.push((req, out));
            }
            Some(Answered::Part(req, positions)) => self.fill(req, positions, results.into_iter()),
            None => {}
        }
    }

    fn answer_write(&mut self, id: RawId, mut results: Vec<Result<(), OpcError>>) {
        match self.answered(id) {
            Some(Answered::Whole(req, p)) => {
                results.resize(p.remaining, Err(OpcError::Fail));
                self.ready.write_results.push((req, results));
            }
            Some(Answered::Part(req, positions)) => {
                let results = results.into_iter().map(|r| r.map(|()| Vqt::default()));
                self.fill(req, positions, results)
            }
            None => {}
        }
    }

    /// Sends the parts of a request to the source (`ask`), each under a raw id of its own.
    fn send_parts<P, T>(
        &mut self,
        req: SourceReqId,
        parts: Parts<P, T>,
        mut ask: impl FnMut(&mut S, RawId, Vec<T>),
    ) {
        // One part with every position: answered in one go when it comes.
        let whole =
            parts.len() == 1 && self.pending.get(&req).is_some_and(|p| p.results.is_empty());
        for (_, positions, vars) in parts {
            self.next_raw += 1;
            let id = RawId(self.next_raw);
            self.parts.insert(id, (req, (!whole).then_some(positions)));
            ask(&mut self.source, id, vars);
        }
        self.finish(req);
    }

    fn read(&mut self, now: Timestamp, req: SourceReqId, items: Vec<ReadItem>) {
        let n = items.len();
        let mut p = Pending {
            write: false,
            results: Vec::new(),
            own: Vec::with_capacity(n),
            remaining: n,
        };
        let mut by_part: Parts<S::Part, S::Var> = Vec::new();
        for (i, item) in items.iter().enumerate() {
            // The subscribed item's resolution, else one made for this request; kept with
            // the request either way, since every subscriber may let the item go before
            // the device answers.
            let own = match (self.slot_of(item.key()), item) {
                (Some(s), _) => s.r.clone(),
                (None, ReadItem::Item(item)) => self.resolve(item),
                // The engine names only keys this adapter holds subscribed.
                (None, ReadItem::Subscribed(_)) => {
                    ItemRes::Unserved(Arc::clone(&self.unserved.not_live))
                }
            };
            let var = own.resolved().map(|(v, _)| v.clone());
            p.own.push(own);
            match var {
                Some(var) => {
                    let e = part_entry(&mut by_part, self.source.part(&var));
                    e.1.push(i);
                    e.2.push(var);
                }
                None => p.refuse(i, Err(OpcError::ItemUnknown)),
            }
        }
        self.pending.insert(req, p);
        self.send_parts(req, by_part, |s, id, vars| s.read(now, id, vars));
    }

    fn write(
        &mut self,
        now: Timestamp,
        req: SourceReqId,
        items: impl ExactSizeIterator<Item = (SourceItem, ItemVqt)>,
    ) {
        let n = items.len();
        let mut p = Pending {
            write: true,
            results: Vec::new(),
            own: Vec::new(),
            remaining: n,
        };
        let mut by_part: Parts<(S::Part, bool), (S::Var, ItemVqt)> = Vec::new();
        for (i, (item, v)) in items.enumerate() {
            let own;
            let r = match self.slot_of(item.key) {
                Some(s) => &s.r,
                None => {
                    own = self.resolve(&item);
                    &own
                }
            };
            let checked = match r {
                // Derived items cannot be written; values must be integers or reals;
                // read-only variables are refused here already.
                ItemRes::Var(var, t) => t.check_write(&v.value).map(|()| var),
                ItemRes::Unserved(u) => match &**u {
                    Resolution::NoVariable(d) => {
                        pipeline::check_write(d, false, &v.value).and(Err(OpcError::ItemUnknown))
                    }
                    Resolution::NotLive | Resolution::Resolved(_) => Err(OpcError::ItemUnknown),
                },
            };
            match checked {
                Ok(var) => {
                    // Simple and extended writes go in requests of their own.
                    let part = (
                        self.source.part(var),
                        v.quality.is_some() || v.timestamp.is_some(),
                    );
                    let e = part_entry(&mut by_part, part);
                    e.1.push(i);
                    e.2.push((var.clone(), v));
                }
                Err(e) => p.refuse(i, Err(e)),
            }
        }
        self.pending.insert(req, p);
        self.send_parts(req, by_part, |s, id, items| s.write(now, id, items));
    }

    /// A new sample of a subscribed variable: fanned out to the items reading it, kept,
    /// and, when it changes a control or limit variable, the items whose rules read it are
    /// reported again if their quality changes. (Their next sample would use the new value
    /// anyway, but an item sampled seldom would keep showing a limit state that no longer
    /// holds.) Such a report keeps the item's value and takes the later of the two
    /// timestamps, the time the quality became what it is.
    fn update(&mut self, v: S::Var, vqt: Vqt, out: &mut SourceOutput) {
        let one;
        let (items, rule_users, last) = match self.vars.get(&v) {
            // A late sample of a variable let go.
            None => return,
            Some(VarRef::One(i)) => {
                one = Self::key_at(&self.slots, i);
                (one.as_slice(), &[][..], None)
            }
            Some(VarRef::Rich(st)) => (
                st.items.as_slice(),
                st.rule_users.as_slice(),
                st.last.as_deref(),
            ),
        };
        for &k in items {
            if let Some((_, t)) = self.slot_of(k).and_then(|s| s.r.resolved()) {
                out.updates.push((k, self.item_vqt(t, vqt.clone())));
            }
        }
        // Only a new value or quality of a rule variable can change the rules' outcome.
        let same = |l: &Vqt| l.value == vqt.value && l.quality == vqt.quality;
        let ruled = !rule_users.is_empty();
        let users = if !ruled || last.is_some_and(same) {
            Vec::new()
        } else {
            rule_users.to_vec()
        };
        let before: Vec<(SourceKey, Quality)> = users
            .into_iter()
            .filter_map(|k| Some((k, self.current_vqt(k)?.quality)))
            .collect();
        let at = vqt.timestamp;
        let keep = self.source.peek(&v).is_none();
        let slots = &self.slots;
        let one = |i: u32| Self::key_at(slots, i);
        self.vars.set_last(&v, (keep || ruled).then_some(vqt), one);
        for (k, q) in before {
            if let Some(mut x) = self.current_vqt(k) {
                if x.quality != q {
                    x.timestamp = x.timestamp.max(at);
                    out.updates.push((k, x));
                }
            }
        }
    }

    /// The first samples of items just subscribed whose variable the source will not
    /// sample anew: the variable's current value, or BAD_CONFIG_ERROR for an item without
    /// a variable.
    fn fresh_samples(&mut self, now: Timestamp, out: &mut SourceOutput) {
        for k in std::mem::take(&mut self.fresh) {
            let Some(s) = self.slot_of(k) else {
                continue;
            };
            match &s.r {
                ItemRes::Var(v, t) => {
                    if let Some(raw) = self.current(v) {
                        out.updates.push((k, self.item_vqt(t, raw)));
                    }
                }
                ItemRes::Unserved(_) => out.updates.push((
                    k,
                    Vqt {
                        value: Value::Empty,
                        quality: Quality::BAD_CONFIG_ERROR,
                        timestamp: now,
                    },
                )),
            }
        }
    }
}

impl<S: VariableSource> Backend for AsixBackend<S> {
    fn request(&mut self, now: Timestamp, req: SourceRequest) {
        match req {
            SourceRequest::Subscribe(subs) => self.subscribe(
                now,
                subs.into_iter()
                    .map(|s| (s.item, s.sampling_rate_ms))
                    .collect(),
            ),
            SourceRequest::SetSamplingRate(rates) => self.set_rates(now, rates),
            SourceRequest::Unsubscribe(keys) => self.unsubscribe(now, keys),
            SourceRequest::Read { req_id, items } => self.read(now, req_id, items),
            SourceRequest::Write { req_id, items } => {
                let items = items.into_iter().map(|(i, v)| (i, ItemVqt::value(v)));
                self.write(now, req_id, items)
            }
            SourceRequest::WriteVqt { req_id, items } => self.write(now, req_id, items.into_iter()),
        }
    }

    fn poll(&mut self, now: Timestamp, out: &mut SourceOutput) {
        let mut raw = std::mem::take(&mut self.raw);
        self.source.poll(now, &mut raw);
        if !self.fresh.is_empty() {
            self.fresh_samples(now, out);
        }
        out.updates.reserve(raw.samples.len());
        for (v, vqt) in raw.samples.drain(..) {
            self.update(v, vqt, out);
        }
        for (id, r) in raw.reads.drain(..) {
            self.answer_read(id, r);
        }
        for (id, r) in raw.writes.drain(..) {
            self.answer_write(id, r);
        }
        // Kept for the next poll only while small: the samples of a large subscription
        // would otherwise hold a buffer of every variable's last sample between polls (56
        // bytes a variable); a poll of many samples allocates it anew.
        if raw.samples.capacity() > RAW_SAMPLES_KEPT {
            raw.samples = Vec::new();
        }
        self.raw = raw;
        out.read_results.append(&mut self.ready.read_results);
        out.write_results.append(&mut self.ready.write_results);
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        if !self.ready.is_empty() || !self.fresh.is_empty() {
            return Some(Timestamp(0));
        }
        self.source.poll_timeout()
    }

    fn is_simulation(&self) -> bool {
        self.source.is_simulation()
    }

    fn channels(&self) -> Vec<ctopc_core::diagnostics::ChannelStatus> {
        self.source.channels(&mut self.vars.keys())
    }
}

#[cfg(test)]
mod tests {
    //! The adapter against a fake raw source (variables from a fixed table, samples and
    //! device answers given by the test), with source items made by the engine over the
    //! embedded demo (channel `*` checks limits and control variables). Network-like: the
    //! fake cannot `peek`, so the rules read the last samples.
    use super::*;
    use ctopc_core::model::datasource::Subscription;
    use ctopc_core::model::{Engine, EngineConfig, GroupParams, ItemDefinition};

    /// The fake's variables: (asix channel = part, name).
    const VARS: &[(&str, &str)] = &[
        ("SIARKA", "KW_A000"),
        ("DIAGNOSTYKA", "KW_K001"),
        ("PIEC", "KW_A110"),
        ("DIAGNOSTYKA", "KW_K002"),
    ];
    const A000: u32 = 0;
    const K001: u32 = 1;
    const A110: u32 = 2;

    #[derive(Default)]
    struct Fake {
        /// Subscribed variables with their rates.
        subs: BTreeMap<u32, u32>,
        /// Every subscribe and unsubscribe, in order.
        log: Vec<String>,
        reads: Vec<(RawId, Vec<u32>)>,
        writes: Vec<(RawId, Vec<(u32, ItemVqt)>)>,
        /// Handed out at the next poll.
        out: RawOutput<u32>,
        /// The current values `peek` gives (the simulation's way); `None`: it gives none
        /// (the network's way).
        plant: Option<BTreeMap<u32, Vqt>>,
    }

    impl VariableSource for Fake {
        type Var = u32;
        type Part = &'static str;
        fn lookup(&self, _channel: &Arc<str>, key: &ItemKey) -> Option<u32> {
            let i = VARS
                .iter()
                .position(|(c, n)| **c == *key.channel && **n == *key.variable)?;
            u32::try_from(i).ok()
        }
        fn part(&self, var: &u32) -> &'static str {
            VARS[*var as usize].0
        }
        fn peek(&self, var: &u32) -> Option<Vqt> {
            self.plant.as_ref()?.get(var).cloned()
        }
        fn subscribe(&mut self, _now: Timestamp, vars: Vec<(u32, u32)>) {
            for (v, rate) in vars {
                self.log.push(format!("sub {}@{rate}", VARS[v as usize].1));
                self.subs.insert(v, rate);
            }
        }
        fn unsubscribe(&mut self, _now: Timestamp, vars: Vec<u32>) {
            for v in vars {
                self.log.push(format!("unsub {}", VARS[v as usize].1));
                self.subs.remove(&v);
            }
        }
        fn read(&mut self, _now: Timestamp, id: RawId, vars: Vec<u32>) {
            self.reads.push((id, vars));
        }
        fn write(&mut self, _now: Timestamp, id: RawId, items: Vec<(u32, ItemVqt)>) {
            self.writes.push((id, items));
        }
        fn poll(&mut self, _now: Timestamp, out: &mut RawOutput<u32>) {
            let o = std::mem::take(&mut self.out);
            out.samples.extend(o.samples);
            out.reads.extend(o.reads);
            out.writes.extend(o.writes);
        }
        fn poll_timeout(&self) -> Option<Timestamp> {
            (!self.out.is_empty()).then_some(Timestamp(0))
        }
    }

    const T: Timestamp = Timestamp(1_000_000);

    fn ns() -> Arc<AsixNamespace> {
        Arc::new(asix_model::embedded_demo().unwrap().namespace)
    }

    /// The source items the engine makes of these item IDs (in order).
    fn items(ns: &Arc<AsixNamespace>, ids: &[&str]) -> Vec<SourceItem> {
        let mut e = Engine::new(EngineConfig::default(), ns.clone());
        let s = e.open_session();
        let params = GroupParams {
            name: "",
            active: true,
            update_rate: 1000,
            ..Default::default()
        };
        let g = e.add_group(T, s, &params).unwrap().group;
        let defs: Vec<ItemDefinition> = ids
            .iter()
            .map(|id| ItemDefinition {
                item_id: id,
                access_path: "",
                active: true,
                client_handle: 0,
                requested_type: ctopc_core::VarType::EMPTY,
            })
            .collect();
        for r in e.add_items(T, g, &defs).unwrap() {
            r.unwrap();
        }
        let mut items = Vec::new();
        while let Some(r) = e.poll_source_request() {
            if let SourceRequest::Subscribe(subs) = r {
                items.extend(subs.into_iter().map(|s| s.item));
            }
        }
        // In the order asked for.
        ids.iter()
            .map(|id| {
                items
                    .iter()
                    .find(|i| &*i.item_id == *id)
                    .cloned()
                    .unwrap_or_else(|| panic!("no source item {id}"))
            })
            .collect()
    }

    /// A device read's items, each whole (as the engine sends items the source does not
    /// hold).
    fn whole(items: &[SourceItem]) -> Vec<ReadItem> {
        items.iter().cloned().map(ReadItem::Item).collect()
    }

    fn backend() -> (AsixBackend<Fake>, Arc<AsixNamespace>) {
        let ns = ns();
        (AsixBackend::from_source(ns.clone(), Fake::default()), ns)
    }

    fn subscribe(b: &mut AsixBackend<Fake>, items: &[(&SourceItem, u32)]) {
        let subs = items
            .iter()
            .map(|(i, rate)| Subscription {
                item: (*i).clone(),
                sampling_rate_ms: *rate,
            })
            .collect();
        b.request(T, SourceRequest::Subscribe(subs));
    }

    fn poll(b: &mut AsixBackend<Fake>, samples: &[(u32, Value)]) -> SourceOutput {
        b.source.out.samples.extend(
            samples
                .iter()
                .map(|(v, x)| (*v, Vqt::new(x.clone(), Quality::GOOD, T))),
        );
        let mut out = SourceOutput::default();
        b.poll(T, &mut out);
        out
    }

    fn log(b: &mut AsixBackend<Fake>) -> Vec<String> {
        std::mem::take(&mut b.source.log)
    }

    /// Decided for both sources (the network's way): a variable is subscribed once, at the
    /// fastest rate of its items and of the items whose rules read it, and each sample goes
    /// to every item on it, in the simulation as on the network.
    #[test]
    fn a_variable_is_subscribed_once_at_the_fastest_rate_and_its_samples_fan_out() {
        let (mut b, ns) = backend();
        let it = items(&ns, &["KW_A000", "KW_A000.PercentageCV"]);
        let (a, pct) = (&it[0], &it[1]);
        subscribe(&mut b, &[(a, 1000), (pct, 250)]);
        // The item's variable and its control variable (channel * checks it), once each.
        assert_eq!(log(&mut b), ["sub KW_A000@250", "sub KW_K001@250"]);

        let out = poll(&mut b, &[(K001, Value::I2(0)), (A000, Value::R4(4.0))]);
        let mut got: Vec<(SourceKey, Value, Quality)> = out
            .updates
            .into_iter()
            .map(|(k, v)| (k, v.value, v.quality))
            .collect();
        got.sort_by_key(|(k, ..)| *k);
        let mut want = vec![
            (a.key, Value::R4(4.0), Quality::GOOD),
            (pct.key, Value::R8(50.0), Quality::GOOD),
        ];
        want.sort_by_key(|(k, ..)| *k);
        assert_eq!(
            got, want,
            "one sample, both items; the control variable is no item"
        );

        b.request(T, SourceRequest::SetSamplingRate(vec![(pct.key, 2000)]));
        assert_eq!(log(&mut b), ["sub KW_A000@1000", "sub KW_K001@1000"]);
        b.request(T, SourceRequest::Unsubscribe(vec![a.key]));
        assert_eq!(log(&mut b), ["sub KW_A000@2000", "sub KW_K001@2000"]);
        b.request(T, SourceRequest::Unsubscribe(vec![pct.key]));
        assert_eq!(log(&mut b), ["unsub KW_A000", "unsub KW_K001"]);
        assert!(b.source.subs.is_empty());
        // A late sample of a variable let go reaches nobody.
        assert!(poll(&mut b, &[(A000, Value::R4(5.0))]).updates.is_empty());
    }

    /// Only a changed fastest rate reaches the source: an item subscribed again at its rate
    /// asks nothing; a variable is let go with its last item and taken again with the
    /// next; an item leaving a variable that keeps a faster one changes nothing.
    #[test]
    fn rates_reach_the_source_only_when_the_fastest_changes() {
        let (mut b, ns) = backend();
        let it = items(&ns, &["KW_A000", "KW_A000.PercentageCV"]);
        subscribe(&mut b, &[(&it[0], 1000)]);
        log(&mut b);
        subscribe(&mut b, &[(&it[0], 1000)]);
        assert!(log(&mut b).is_empty(), "the same rate again");
        b.request(T, SourceRequest::Unsubscribe(vec![it[0].key]));
        subscribe(&mut b, &[(&it[1], 1000)]);
        assert_eq!(
            log(&mut b),
            [
                "unsub KW_A000",
                "unsub KW_K001",
                "sub KW_A000@1000",
                "sub KW_K001@1000"
            ]
        );
        let subs = vec![Subscription {
            item: it[0].clone(),
            sampling_rate_ms: 500,
        }];
        b.request(T, SourceRequest::Subscribe(subs));
        b.request(T, SourceRequest::Unsubscribe(vec![it[1].key]));
        assert_eq!(log(&mut b), ["sub KW_A000@500", "sub KW_K001@500"]);
    }

    /// An item added to a variable already sampled gets the variable's current value at
    /// once (here the last sample), not only at the variable's next sample.
    #[test]
    fn an_item_added_to_a_sampled_variable_gets_its_value_at_once() {
        let (mut b, ns) = backend();
        let it = items(&ns, &["KW_A000", "KW_A000.PercentageCV"]);
        subscribe(&mut b, &[(&it[0], 1000)]);
        poll(&mut b, &[(K001, Value::I2(0)), (A000, Value::R4(2.0))]);
        log(&mut b);
        subscribe(&mut b, &[(&it[1], 1000)]);
        assert!(log(&mut b).is_empty(), "nothing new to subscribe");
        assert_eq!(b.poll_timeout(), Some(Timestamp(0)));
        let out = poll(&mut b, &[]);
        assert_eq!(out.updates.len(), 1);
        assert_eq!(out.updates[0].0, it[1].key);
        assert_eq!(out.updates[0].1.value, Value::R8(25.0));
        assert_eq!(b.poll_timeout(), None);
    }

    /// Decided for both sources: an item the source has no variable for is reported once,
    /// when subscribed, with BAD_CONFIG_ERROR (as the asix client reports a variable its
    /// server does not know), and not again at later ticks. Device reads and writes of it
    /// fail without asking the source.
    #[test]
    fn an_item_without_a_variable_is_reported_once_with_config_error() {
        let (mut b, ns) = backend();
        let it = items(&ns, &["asmen.NIC.NIE_MA.R4"]);
        subscribe(&mut b, &[(&it[0], 100)]);
        assert!(log(&mut b).is_empty());
        let out = poll(&mut b, &[]);
        assert_eq!(out.updates.len(), 1);
        let (k, v) = &out.updates[0];
        assert_eq!(
            (*k, &v.value, v.quality),
            (it[0].key, &Value::Empty, Quality::BAD_CONFIG_ERROR)
        );
        assert!(poll(&mut b, &[(A000, Value::R4(1.0))]).updates.is_empty());
        assert_eq!(b.poll_timeout(), None, "nothing to repeat");

        b.request(
            T,
            SourceRequest::Read {
                req_id: SourceReqId(1),
                items: whole(&it),
            },
        );
        b.request(
            T,
            SourceRequest::Write {
                req_id: SourceReqId(2),
                items: vec![(it[0].clone(), Value::R4(1.0))],
            },
        );
        assert!(b.source.reads.is_empty() && b.source.writes.is_empty());
        let out = poll(&mut b, &[]);
        assert_eq!(
            out.read_results,
            vec![(SourceReqId(1), vec![Err(OpcError::ItemUnknown)])]
        );
        assert_eq!(
            out.write_results,
            vec![(SourceReqId(2), vec![Err(OpcError::ItemUnknown)])]
        );
    }

    /// A new value of a control variable reports the items whose quality it changes again,
    /// with their last value, without a sample of their own; the same value again does not.
    #[test]
    fn a_rule_variable_change_reports_its_users_again() {
        let (mut b, ns) = backend();
        let it = items(&ns, &["KW_A000"]);
        subscribe(&mut b, &[(&it[0], 60_000)]);
        let out = poll(&mut b, &[(K001, Value::I2(0)), (A000, Value::R4(4.0))]);
        assert_eq!(out.updates[0].1.quality, Quality::GOOD);
        let out = poll(&mut b, &[(K001, Value::I2(1))]);
        assert_eq!(out.updates.len(), 1);
        assert_eq!(out.updates[0].1.value, Value::R4(4.0));
        assert_eq!(out.updates[0].1.quality, Quality::BAD_SENSOR_FAILURE);
        assert!(poll(&mut b, &[(K001, Value::I2(1))]).updates.is_empty());
    }

    /// A device read is spread over the source's parts and answered once every part has
    /// answered, one result per item in request order, through the pipeline (items not
    /// subscribed are resolved for the request).
    #[test]
    fn a_device_read_is_spread_over_parts_and_answered_when_complete() {
        let (mut b, ns) = backend();
        let it = items(
            &ns,
            &[
                "KW_A000",
                "KW_A110",
                "asmen.NIC.NIE_MA.R4",
                "KW_A000.PercentageCV",
            ],
        );
        b.request(
            T,
            SourceRequest::Read {
                req_id: SourceReqId(7),
                items: whole(&it),
            },
        );
        let reads = std::mem::take(&mut b.source.reads);
        let asked: Vec<Vec<u32>> = reads.iter().map(|(_, v)| v.clone()).collect();
        assert_eq!(asked, [vec![A000, A000], vec![A110]]);
        let vqt = |x: f32| Ok(Vqt::new(Value::R4(x), Quality::GOOD, T));
        b.source.out.reads.push((reads[1].0, vec![vqt(12.5)]));
        assert!(
            poll(&mut b, &[]).read_results.is_empty(),
            "a part is missing"
        );
        b.source
            .out
            .reads
            .push((reads[0].0, vec![vqt(4.0), vqt(4.0)]));
        let out = poll(&mut b, &[]);
        let [(id, r)] = &out.read_results[..] else {
            panic!("{:?}", out.read_results)
        };
        assert_eq!(*id, SourceReqId(7));
        let values: Vec<Result<Value, OpcError>> =
            r.iter().map(|r| r.clone().map(|v| v.value)).collect();
        assert_eq!(
            values,
            [
                Ok(Value::R4(4.0)),
                Ok(Value::R4(12.5)),
                Err(OpcError::ItemUnknown),
                Ok(Value::R8(50.0)),
            ]
        );
    }

    /// A device read of subscribed items answers them even when every subscriber lets
    /// them go before the device answers (another client's group leaving under load):
    /// the read keeps the resolutions it was sent with.
    #[test]
    fn a_device_read_outlives_the_subscription_it_was_sent_under() {
        let (mut b, ns) = backend();
        let it = items(&ns, &["KW_A000", "KW_A000.PercentageCV"]);
        subscribe(&mut b, &[(&it[0], 1000), (&it[1], 1000)]);
        b.request(
            T,
            SourceRequest::Read {
                req_id: SourceReqId(9),
                items: it.iter().map(|i| ReadItem::Subscribed(i.key)).collect(),
            },
        );
        let reads = std::mem::take(&mut b.source.reads);
        b.request(T, SourceRequest::Unsubscribe(vec![it[0].key, it[1].key]));
        let vqt = |x: f32| Ok(Vqt::new(Value::R4(x), Quality::GOOD, T));
        b.source
            .out
            .reads
            .push((reads[0].0, vec![vqt(2.0), vqt(2.0)]));
        let out = poll(&mut b, &[]);
        let [(id, r)] = &out.read_results[..] else {
            panic!("{:?}", out.read_results)
        };
        assert_eq!(*id, SourceReqId(9));
        let values: Vec<Result<Value, OpcError>> =
            r.iter().map(|r| r.clone().map(|v| v.value)).collect();
        assert_eq!(values, [Ok(Value::R4(2.0)), Ok(Value::R8(25.0))]);
    }

    /// Writes are checked before the source sees them (derived items, read-only variables);
    /// simple and extended writes go in raw writes of their own; a short answer fails the
    /// positions it leaves out.
    #[test]
    fn writes_are_checked_first_and_split_by_kind() {
        let (mut b, ns) = backend();
        let it = items(&ns, &["KW_A110", "KW_A000", "KW_A000.PercentageCV"]);
        let vqt = ItemVqt {
            value: Value::R4(3.0),
            quality: Some(Quality::UNCERTAIN),
            timestamp: None,
        };
        b.request(
            T,
            SourceRequest::WriteVqt {
                req_id: SourceReqId(3),
                items: vec![
                    (it[0].clone(), ItemVqt::value(Value::R4(12.5))),
                    (it[1].clone(), ItemVqt::value(Value::R4(1.0))),
                    (it[2].clone(), ItemVqt::value(Value::R4(1.0))),
                    (it[0].clone(), vqt.clone()),
                    (it[0].clone(), ItemVqt::value(Value::R4(13.0))),
                ],
            },
        );
        let writes = std::mem::take(&mut b.source.writes);
        let asked: Vec<Vec<(u32, ItemVqt)>> = writes.iter().map(|(_, w)| w.clone()).collect();
        assert_eq!(
            asked,
            [
                vec![
                    (A110, ItemVqt::value(Value::R4(12.5))),
                    (A110, ItemVqt::value(Value::R4(13.0)))
                ],
                vec![(A110, vqt)],
            ]
        );
        b.source.out.writes.push((writes[1].0, vec![Ok(())]));
        // The simple write answers one result of two.
        b.source.out.writes.push((writes[0].0, vec![Ok(())]));
        let out = poll(&mut b, &[]);
        assert_eq!(
            out.write_results,
            vec![(
                SourceReqId(3),
                vec![
                    Ok(()),
                    Err(OpcError::WriteErrorDeviceRequestIllegal),
                    Err(OpcError::BadRights),
                    Ok(()),
                    Err(OpcError::Fail),
                ]
            )]
        );
    }

    /// Items treated the same way (here two control variables: no limits, no control
    /// variable of their own, read-only) share one treatment, so that a plain item costs
    /// its slot; an item treated otherwise has its own.
    #[test]
    fn items_treated_alike_share_their_treatment() {
        let (mut b, ns) = backend();
        let it = items(&ns, &["KW_K001", "KW_K002", "KW_A110"]);
        subscribe(&mut b, &[(&it[0], 1000), (&it[1], 1000), (&it[2], 1000)]);
        let treatment = |i: &SourceItem| match &b.slot_of(i.key).expect("subscribed").r {
            ItemRes::Var(_, t) => Arc::clone(t),
            ItemRes::Unserved(_) => panic!("{} has a variable", i.item_id),
        };
        assert!(Arc::ptr_eq(&treatment(&it[0]), &treatment(&it[1])));
        assert!(!Arc::ptr_eq(&treatment(&it[0]), &treatment(&it[2])));
        assert_eq!(b.treatments.len(), 2);
    }

    /// With a source that can peek (the simulation), a variable of one item and no rules
    /// keeps no sample and stays short; a second item makes it a full state, and it is
    /// short again when that item goes; samples fan out alike.
    #[test]
    fn a_peeking_source_keeps_plain_variables_short() {
        let (mut b, ns) = backend();
        let now = |v: f32| Vqt::new(Value::R4(v), Quality::GOOD, T);
        b.source.plant = Some(BTreeMap::from([
            (A000, now(4.0)),
            (K001, Vqt::new(Value::I2(0), Quality::GOOD, T)),
        ]));
        let it = items(&ns, &["KW_A000", "KW_A000.PercentageCV"]);
        let (a, pct) = (&it[0], &it[1]);
        let short = |b: &AsixBackend<Fake>, v: u32| matches!(b.vars.get(&v), Some(VarRef::One(_)));
        subscribe(&mut b, &[(a, 1000)]);
        assert!(short(&b, A000));
        assert!(!short(&b, K001), "a rule variable has its users");
        let out = poll(&mut b, &[(A000, Value::R4(4.0))]);
        assert_eq!(out.updates.len(), 1);
        assert!(short(&b, A000), "no sample kept");
        assert!(b.vars.last(&K001).is_none());
        poll(&mut b, &[(K001, Value::I2(0))]);
        assert!(
            b.vars.last(&K001).is_some(),
            "a rule variable's sample is kept"
        );

        subscribe(&mut b, &[(pct, 1000)]);
        assert!(!short(&b, A000));
        let out = poll(&mut b, &[(A000, Value::R4(4.0))]);
        let got: Vec<SourceKey> = out.updates.iter().map(|(k, _)| *k).collect();
        assert!(got.contains(&a.key) && got.contains(&pct.key), "{got:?}");
        b.request(T, SourceRequest::Unsubscribe(vec![pct.key]));
        assert!(short(&b, A000));
        let out = poll(&mut b, &[(A000, Value::R4(5.0))]);
        assert_eq!(out.updates.len(), 1);
        assert_eq!(out.updates[0].0, a.key);
        b.request(T, SourceRequest::Unsubscribe(vec![a.key]));
        assert!(b.vars.map.is_empty() && b.vars.rich.is_empty());
    }

    /// Past [`SHARED_TREATMENTS`] kinds in use, a new kind takes the place of the one kept
    /// longest, so that the items of one kind coming together still share it.
    #[test]
    fn past_the_kinds_kept_new_kinds_are_still_shared() {
        let (mut b, _) = backend();
        let kind = |i: usize| {
            let t = Treatment {
                derivation: Derivation::Percentage {
                    low: i as f64,
                    high: 1000.0,
                },
                rule_def: None,
                read_only: true,
                rules: Default::default(),
                control: None,
                limits: Vec::new(),
            };
            ItemRes::Var(A000, Arc::new(t))
        };
        let treatment = |r: &ItemRes<u32>| match r {
            ItemRes::Var(_, t) => Arc::clone(t),
            ItemRes::Unserved(_) => unreachable!(),
        };
        // Items of many kinds, two of each in a row, all subscribed (held here).
        let mut held = Vec::new();
        for i in 0..SHARED_TREATMENTS * 3 {
            let first = b.share(kind(i));
            let second = b.share(kind(i));
            assert!(
                Arc::ptr_eq(&treatment(&first), &treatment(&second)),
                "kind {i}"
            );
            held.push(first);
            held.push(second);
        }
        assert_eq!(b.treatments.len(), SHARED_TREATMENTS);
        // The last kinds are kept, the first ones not.
        let again = b.share(kind(SHARED_TREATMENTS * 3 - 1));
        assert!(Arc::ptr_eq(
            &treatment(&again),
            &treatment(&held[held.len() - 1])
        ));
        let first_again = b.share(kind(0));
        assert!(!Arc::ptr_eq(&treatment(&first_again), &treatment(&held[0])));
        // Kinds no item uses make room before those in use (here only the last kind).
        let last = held.pop().expect("held");
        drop((held, again, first_again));
        let new = b.share(kind(10_000));
        assert_eq!(b.treatments.len(), 2, "unused ones went");
        assert!(Arc::ptr_eq(&b.treatments[0], &treatment(&last)));
        assert!(Arc::ptr_eq(&b.treatments[1], &treatment(&new)));
    }

    /// The item lists of a variable: none and one inline, more in a vector, back to one
    /// and none as items go; `first_only` takes one use of a rule user away.
    #[test]
    fn item_keys_go_inline_and_back() {
        let it = items(&ns(), &["KW_K001", "KW_K002"]);
        let (a, b) = (it[0].key, it[1].key);
        assert_ne!(a, b);
        let mut k = Keys::default();
        assert!(k.as_slice().is_empty());
        k.push(a);
        assert_eq!(k, Keys::One(a));
        k.push(b);
        k.push(a);
        assert_eq!(k.as_slice(), [a, b, a]);
        k.remove(a, true);
        assert_eq!(k.as_slice(), [a, b]);
        k.remove(b, false);
        assert_eq!(k, Keys::One(a));
        k.push(a);
        k.remove(a, false);
        assert_eq!(k, Keys::None);
        assert_eq!(std::mem::size_of::<Keys>(), 16);
        assert_eq!(std::mem::size_of::<VarState>(), 40);
        assert_eq!(std::mem::size_of::<Option<Slot<u32>>>(), 24);
        assert_eq!(std::mem::size_of::<Option<Last>>(), 24);
    }

    /// A variable read by one item and nothing else is that item's slot index; a second
    /// item, a rule user or a kept sample give it a full state, and it goes back to the
    /// short form (its full state's room reused, or freed with the last) once it is plain
    /// again.
    #[test]
    fn variables_of_one_item_are_kept_short() {
        let it = items(&ns(), &["KW_K001", "KW_K002", "KW_A000"]);
        let (a, b, c) = (it[0].key, it[1].key, it[2].key);
        let keys = [a, b, c];
        let one = |i: u32| keys.iter().copied().find(|k| k.index() == i);
        let short = |vars: &Vars<u32>, v: u32| match vars.get(&v) {
            Some(VarRef::One(i)) => Some(i),
            _ => None,
        };
        let rich = |vars: &Vars<u32>, v: u32| match vars.get(&v) {
            Some(VarRef::Rich(st)) => Some((
                st.items.as_slice().to_vec(),
                st.rule_users.as_slice().to_vec(),
                st.last.is_some(),
            )),
            _ => None,
        };
        let mut vars = Vars::new();
        vars.add_item(&1, a, one);
        vars.add_item(&1, a, one);
        assert_eq!(short(&vars, 1), Some(a.index()));
        vars.add_item(&1, b, one);
        assert_eq!(rich(&vars, 1), Some((vec![a, b], vec![], false)));
        vars.remove_item(&1, a);
        vars.settle(&1);
        assert_eq!(short(&vars, 1), Some(b.index()));
        assert!(vars.rich.is_empty() && vars.free.is_empty(), "room freed");

        // An item whose rules read its own variable.
        vars.add_item(&2, c, one);
        vars.add_rule_user(&2, c, one);
        assert_eq!(rich(&vars, 2), Some((vec![c], vec![c], false)));
        vars.set_last(&2, Some(Vqt::default()), one);
        assert_eq!(rich(&vars, 2), Some((vec![c], vec![c], true)));
        assert_eq!(vars.last(&2), Some(Vqt::default()));
        vars.remove_rule_user(&2, c);
        vars.settle(&2);
        assert!(
            rich(&vars, 2).is_some(),
            "its sample is kept, and short variables keep none yet"
        );
        vars.set_last(&2, None, one);
        assert_eq!(short(&vars, 2), Some(c.index()));
        // A rule user alone.
        vars.add_rule_user(&3, a, one);
        assert_eq!(rich(&vars, 3), Some((vec![], vec![a], false)));

        // A kept sample alone stays short (the network's way), moves into a full state
        // with a second item and back with the first.
        let x = |v: f32| Vqt::new(Value::R4(v), Quality::GOOD, T);
        vars.set_last(&1, Some(x(1.0)), one);
        assert_eq!(short(&vars, 1), Some(b.index()));
        assert_eq!(vars.last(&1), Some(x(1.0)));
        vars.set_last(&1, Some(x(2.0)), one);
        assert_eq!(vars.last(&1), Some(x(2.0)));
        vars.add_item(&1, a, one);
        assert_eq!(rich(&vars, 1), Some((vec![b, a], vec![], true)));
        assert_eq!(vars.last(&1), Some(x(2.0)));
        assert!(vars.lasts.iter().all(Option::is_none));
        vars.remove_item(&1, a);
        vars.settle(&1);
        assert_eq!(short(&vars, 1), Some(b.index()), "with its sample");
        assert_eq!(vars.last(&1), Some(x(2.0)));
        vars.set_last(&1, None, one);
        assert_eq!(vars.last(&1), None);
        assert_eq!(short(&vars, 1), Some(b.index()));
        vars.set_last(&1, Some(x(3.0)), one);
        vars.remove_item(&1, b);
        assert!(vars.get(&1).is_none(), "a short entry goes with its item");
        assert!(vars.lasts.iter().all(Option::is_none), "and its sample");
        vars.add_item(&1, b, one);
        assert_eq!(vars.last(&1), None);

        assert_eq!((vars.rich.len(), vars.free.len()), (2, 1));
        vars.add_item(&4, a, one);
        vars.add_item(&4, b, one);
        assert_eq!(
            (vars.rich.len(), vars.free.len()),
            (2, 0),
            "free room reused"
        );
        assert_eq!(vars.last(&4), None);

        vars.remove_rule_user(&3, a);
        assert!(rich(&vars, 3).is_some(), "kept until removed");
        vars.remove(&3);
        vars.remove(&4);
        vars.remove_item(&1, b);
        assert!(vars.get(&1).is_none(), "a short entry goes with its item");
        vars.remove_item(&2, a);
        assert_eq!(short(&vars, 2), Some(c.index()), "another item's");
        vars.remove(&2);
        assert!(vars.map.is_empty() && vars.rich.is_empty() && vars.free.is_empty());
    }

    /// A short variable keeps a string or array sample aside, by its item's slot index,
    /// while it is the last; it moves with the sample into a full state and back.
    #[test]
    fn a_short_variables_string_sample_is_kept_aside() {
        let (a, b) = (SourceKey::new(3, 0), SourceKey::new(4, 0));
        let one = |i: u32| (i == a.index()).then_some(a);
        let text = Vqt::new(Value::Bstr("on".into()), Quality::GOOD, T);
        let num = Vqt::new(Value::R4(1.0), Quality::UNCERTAIN, T);
        let mut vars = Vars::new();
        vars.add_item(&1, a, one);
        vars.set_last(&1, Some(text.clone()), one);
        assert_eq!(vars.last(&1), Some(text.clone()));
        assert_eq!(vars.last_values.len(), 1);
        vars.set_last(&1, Some(num.clone()), one);
        assert_eq!(vars.last(&1), Some(num));
        assert!(vars.last_values.is_empty(), "a number follows");
        vars.set_last(&1, Some(text.clone()), one);
        vars.add_item(&1, b, one);
        assert!(matches!(vars.get(&1), Some(VarRef::Rich(_))));
        assert!(vars.last_values.is_empty(), "moved into the full state");
        assert_eq!(vars.last(&1), Some(text.clone()));
        vars.remove_item(&1, b);
        vars.settle(&1);
        assert!(matches!(vars.get(&1), Some(VarRef::One(3))));
        assert_eq!(vars.last(&1), Some(text));
        assert_eq!(vars.last_values.len(), 1);
        vars.remove(&1);
        assert!(vars.last_values.is_empty() && vars.lasts.iter().all(Option::is_none));
    }
}
