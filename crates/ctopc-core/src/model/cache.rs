//! The process-wide item cache: one entry per source item, shared by every group item that
//! refers to it, with the subscription bookkeeping (reference counts, requested sampling
//! rates, what the backend was last told).

use hashbrown::HashTable;
use std::borrow::Cow;
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

use super::boundary::{SourceItem, SourceKey, SourceRequest, Subscription};
use super::util::Interner;
use crate::compact::{grow_exact, Growth, Idx, Num, Packable, PackedValue, SideMap};
use crate::namespace::{EuInfo, ItemDef, OPC_READABLE, OPC_WRITEABLE};
use crate::{OpcError, Quality, Timestamp, Value, VarType, Vqt};

/// "Never refreshed by the source."
pub(crate) const NEVER: Timestamp = Timestamp(i64::MIN);

/// A value as the engine works with it (the cache's samples, the value last sent to a
/// group, the values of a transaction): a number (type and bits, exact), or a string or
/// array shared. The tables keep it packed ([`PackedValue`] with a [`SideMap`]).
#[derive(Debug, Clone)]
pub(crate) enum CachedValue {
    Num(Num),
    Shared(Arc<Value>),
}

impl CachedValue {
    pub const EMPTY: CachedValue = CachedValue::Num(Num::EMPTY);

    pub fn from_value(v: Value) -> Self {
        match Num::of(&v) {
            Some(n) => CachedValue::Num(n),
            None => CachedValue::Shared(Arc::new(v)),
        }
    }

    /// Equal to `v` (same type, same bits or equal contents), without allocating.
    pub fn same_as(&self, v: &Value) -> bool {
        match (self, Num::of(v)) {
            (CachedValue::Num(a), Some(b)) => *a == b,
            (CachedValue::Shared(a), None) => **a == *v,
            _ => false,
        }
    }

    pub fn to_value(&self) -> Value {
        match self {
            CachedValue::Shared(a) => (**a).clone(),
            CachedValue::Num(n) => n.to_value(),
        }
    }

    /// The number for deadband checks (see [`Value::as_f64`]); `None` for non-numbers.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            CachedValue::Num(n) => n.to_value().as_f64(),
            CachedValue::Shared(a) => a.as_f64(),
        }
    }
}

impl PartialEq for CachedValue {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (CachedValue::Num(a), CachedValue::Num(b)) => a == b,
            (CachedValue::Shared(a), CachedValue::Shared(b)) => Arc::ptr_eq(a, b) || **a == **b,
            _ => false,
        }
    }
}

impl Packable for CachedValue {
    fn as_num(&self) -> Option<Num> {
        match self {
            CachedValue::Num(n) => Some(*n),
            CachedValue::Shared(_) => None,
        }
    }
    fn from_num(n: Num) -> Self {
        CachedValue::Num(n)
    }
}

/// An analog entry's EU range, low and high (`SourceTable::eu_ranges`).
type EuRange = (f64, f64);

/// The distinct sampling rates of one source item's subscribers, with counts
/// (`SourceTable::many_rates`).
type RateList = Vec<(u32, u32)>;

/// The sampling rates requested by the subscribers of one source item, with counts. More
/// than one distinct rate spills into [`SourceTable`]'s side table (rare), which keeps the
/// entry small.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub(crate) enum RateSet {
    #[default]
    Empty,
    One {
        rate: u32,
        count: u32,
    },
    Many(Idx<RateList>),
}

bitflags::bitflags! {
    /// A [`SourceEntry`]'s flags.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    pub(crate) struct EntryFlags: u8 {
        /// In use (a freed entry has no flags).
        const LIVE = 1;
        const CONSTANT = 1 << 1;
        /// In `SourceTable::dirty`: its subscription changed since the last flush.
        const DIRTY = 1 << 2;
        /// EU type OPC_ENUMERATED: the texts are in `SourceTable::enum_texts`.
        const ENUMERATED = 1 << 4;
        /// The rate set spilled: the sample's `sub_rate` is a `SourceTable::many_rates`
        /// index.
        const MANY_RATES = 1 << 5;
        /// The entry has a sample slot of its own in `SourceTable::samples`: made when it
        /// is first subscribed (so that a subscription's samples lie in the order of its
        /// entries, as the scans read them) or gets a sample otherwise (a device read), or
        /// at once for a constant; without it, `sample` names the shared initial state of
        /// the entries created at the same time.
        const OWN_SAMPLE = 1 << 6;
    }
}

/// One source item in the cache (32 bytes; its key is in [`SourceTable`]'s key text and
/// its sample and subscription state in [`SourceTable`]'s samples, no allocation of its
/// own).
#[derive(Debug)]
pub(crate) struct SourceEntry {
    /// The key: its start and length in `SourceTable::keys`.
    key_at: u32,
    key_len: u32,
    /// The entry's [`Sample`]: its own with [`EntryFlags::OWN_SAMPLE`], else the shared initial state
    /// (no value yet); none once the entry is freed.
    sample: Option<Idx<Sample>>,
    pub generation: u32,
    /// Group items referring to this entry.
    pub refs: u32,
    pub channel: u32,
    /// EU type OPC_ANALOG: its range.
    eu_range: Option<Idx<EuRange>>,
    pub canonical: VarType,
    pub access: u8,
    pub flags: EntryFlags,
}

/// What the cache holds of an entry's value and subscription (48 bytes), apart from the
/// entry: an item that is never subscribed nor read (in inactive groups only) costs no
/// sample of its own. A number is in the sample (type and bits), a string or array in
/// `SourceTable::shared` by sample slot; [`SourceTable::sample`] gives both as a
/// [`SampleRef`].
#[derive(Debug, Clone)]
pub(crate) struct Sample {
    /// A number, or shared: in `SourceTable::shared` by sample slot.
    value: PackedValue,
    timestamp: Timestamp,
    refreshed_at: Timestamp,
    changed_seq: u64,
    quality: Quality,
    /// A shared initial state: the entries referring to it. An entry's own sample: with
    /// `sub_rate`, the subscribers' rates ([`SourceTable::rates`]): one rate and its count
    /// (this), or with [`EntryFlags::MANY_RATES`] the raw [`Idx`] of its list in the side table.
    refs: u32,
    sub_rate: u32,
    /// The sampling rate the backend was last told (0: not subscribed).
    announced_rate: u32,
}

impl Sample {
    /// The state of an entry before its first sample, created at `now`.
    const fn initial(now: Timestamp) -> Self {
        Sample {
            value: PackedValue::EMPTY,
            timestamp: now,
            refreshed_at: NEVER,
            changed_seq: 0,
            quality: Quality::BAD_WAITING_FOR_INITIAL_DATA,
            refs: 0,
            sub_rate: 0,
            announced_rate: 0,
        }
    }
}

/// An entry's sample as read ([`SourceTable::sample`]).
#[derive(Debug)]
pub(crate) struct SampleRef<'a> {
    pub value: Cow<'a, CachedValue>,
    pub timestamp: Timestamp,
    /// When the source last delivered a sample (for MaxAge); [`NEVER`] before the first.
    pub refreshed_at: Timestamp,
    /// `Engine::change_seq` when value or quality last changed.
    pub changed_seq: u64,
    pub quality: Quality,
}

impl SampleRef<'_> {
    /// The data source has delivered a sample (or a device read did, or the item is a
    /// constant).
    pub fn has_value(&self) -> bool {
        self.refreshed_at != NEVER
    }
}

impl SourceEntry {
    pub fn is_constant(&self) -> bool {
        self.flags.contains(EntryFlags::CONSTANT)
    }
    /// The sample of a live entry (its own or the shared initial state).
    fn live_sample(&self) -> Idx<Sample> {
        self.sample.expect("a live entry has a sample")
    }
    /// See [`EntryFlags::OWN_SAMPLE`].
    pub fn has_own_sample(&self) -> bool {
        self.flags.contains(EntryFlags::OWN_SAMPLE)
    }
    pub fn readable(&self) -> bool {
        u32::from(self.access) & OPC_READABLE != 0
    }
    /// EU type OPC_ANALOG (percent deadband applies).
    pub fn is_analog(&self) -> bool {
        self.eu_range.is_some()
    }
    pub fn writable(&self) -> bool {
        u32::from(self.access) & OPC_WRITEABLE != 0 && !self.is_constant()
    }
}

/// The keys of the cache's entries one after another in one string, so that a key costs
/// its bytes and no allocation. A freed entry's key is garbage until garbage is
/// most of the text; then the text is rebuilt from the live entries' keys.
#[derive(Default)]
struct KeyText {
    text: String,
    garbage: usize,
}

/// The cache: a slab of entries, an index by `(channel, source key)` and the strings.
#[derive(Default)]
pub(crate) struct SourceTable {
    pub entries: Vec<SourceEntry>,
    keys: KeyText,
    free: Vec<u32>,
    /// (channel, source key) -> entry index.
    index: SourceIndex,
    /// Access paths and channels.
    pub paths: Interner,
    dirty: Vec<u32>,
    live: usize,
    /// Rate sets with more than one distinct rate.
    many_rates: Vec<RateList>,
    free_many: Vec<Idx<RateList>>,
    /// OPC_ENUMERATED texts by entry index.
    enum_texts: HashMap<u32, Vec<String>>,
    /// The distinct EU ranges of analog entries (a plant has few: interning them keeps 12
    /// bytes per entry out of the cache), by bit pattern; never shrinks, as the ranges come
    /// from the configuration, not from clients.
    eu_ranges: Vec<EuRange>,
    eu_range_ids: HashMap<(u64, u64), Idx<EuRange>>,
    /// The entries' samples ([`SourceEntry::sample`]), with the free slots ...
    samples: Vec<Sample>,
    free_samples: Vec<Idx<Sample>>,
    /// The string and array values of the samples, by sample slot.
    shared: SideMap<Idx<Sample>, CachedValue>,
    /// ... and the shared initial state last created, which the entries created at the
    /// same time share.
    initial: Option<Idx<Sample>>,
    /// Items left in the AddItems call being made ([`SourceTable::batch_left`]): room for
    /// that many when the entries must grow, rather than a quarter more; and their item IDs'
    /// bytes, for the key text.
    batch_left: usize,
    batch_keys: usize,
}

impl SourceTable {
    pub fn live(&self) -> usize {
        self.live
    }

    /// Says how many items of an AddItems call are left, this one included, and their item
    /// IDs' bytes (0 after the call): at most that many new entries are coming, with about
    /// that many bytes of keys.
    pub fn batch_left(&mut self, n: usize, key_bytes: usize) {
        self.batch_left = n;
        self.batch_keys = key_bytes;
    }

    /// An entry's key.
    /// The access path (asix channel) of entry `idx`.
    pub fn channel(&self, idx: u32) -> &str {
        self.paths.get(self.entries[idx as usize].channel)
    }

    pub fn key(&self, idx: u32) -> &str {
        let e = &self.entries[idx as usize];
        Self::key_in(&self.keys.text, e)
    }

    fn key_in<'a>(text: &'a str, e: &SourceEntry) -> &'a str {
        let at = e.key_at as usize;
        text.get(at..at + e.key_len as usize).unwrap_or("")
    }

    /// Appends a key to the key text: its start, or `None` when the text would pass 4 GiB
    /// even without its garbage.
    fn add_key(&mut self, key: &str) -> Option<u32> {
        let fits = |text: usize| u32::try_from(text + key.len()).is_ok();
        if !fits(self.keys.text.len()) {
            self.compact_keys();
        }
        if !fits(self.keys.text.len()) {
            return None;
        }
        let text = &mut self.keys.text;
        let len = text.len();
        // As the entries: by the rest of a large AddItems (its item IDs' bytes, which are
        // the keys' unless aliases), else by a quarter.
        grow_exact(text, key.len(), Growth::quarter(4096).hint(self.batch_keys));
        text.push_str(key);
        Some(len as u32)
    }

    /// Rebuilds the key text from the live entries' keys.
    fn compact_keys(&mut self) {
        let live = self.keys.text.len() - self.keys.garbage;
        let mut text = String::with_capacity(live);
        for e in self
            .entries
            .iter_mut()
            .filter(|e| e.flags.contains(EntryFlags::LIVE))
        {
            let key = Self::key_in(&self.keys.text, e);
            e.key_at = text.len() as u32;
            text.push_str(key);
        }
        self.keys = KeyText { text, garbage: 0 };
    }

    /// The entry for `def`, created if needed (constant items get their value now);
    /// E_OUTOFMEMORY when the cache's keys would pass 4 GiB.
    pub fn find_or_insert(&mut self, def: &ItemDef, now: Timestamp) -> Result<u32, OpcError> {
        let channel = self.paths.intern(&def.channel);
        let hash = key_hash(channel, &def.source_key);
        let (entries, text) = (&self.entries, &self.keys.text);
        if let Some(idx) = self.index.find(hash, |i| {
            let e = &entries[i as usize];
            e.channel == channel && Self::key_in(text, e) == def.source_key
        }) {
            return Ok(idx);
        }
        let key_at = self.add_key(&def.source_key).ok_or(OpcError::OutOfMemory)?;
        let (sample, mut flags) = match &def.constant {
            Some(v) => {
                let sample = self.alloc_sample(Sample {
                    quality: Quality::GOOD.with_limit(Quality::LIMIT_CONST),
                    refreshed_at: now,
                    ..Sample::initial(now)
                });
                self.put_value(sample, CachedValue::from_value(v.clone()));
                (
                    sample,
                    EntryFlags::LIVE | EntryFlags::CONSTANT | EntryFlags::OWN_SAMPLE,
                )
            }
            None => (self.share_initial(now), EntryFlags::LIVE),
        };
        let eu_range = match &def.eu {
            EuInfo::Analog { low, high } => Some(self.intern_range(*low, *high)),
            EuInfo::Enumerated(_) => {
                flags |= EntryFlags::ENUMERATED;
                None
            }
            EuInfo::None => None,
        };
        let entry = SourceEntry {
            key_at,
            key_len: def.source_key.len() as u32,
            sample: Some(sample),
            generation: 0,
            refs: 0,
            channel,
            eu_range,
            canonical: def.canonical_type,
            access: (def.access_rights & (OPC_READABLE | OPC_WRITEABLE)) as u8,
            flags,
        };
        let idx = match self.free.pop() {
            Some(idx) => {
                let generation = self.entries[idx as usize].generation;
                self.entries[idx as usize] = SourceEntry {
                    generation,
                    ..entry
                };
                idx
            }
            None => {
                // By a quarter, or by the rest of a large AddItems at once, so that the
                // entries of one large call take what they need and no more.
                grow_exact(
                    &mut self.entries,
                    1,
                    Growth::quarter(1024).hint(self.batch_left),
                );
                self.entries.push(entry);
                (self.entries.len() - 1) as u32
            }
        };
        if let EuInfo::Enumerated(texts) = &def.eu {
            self.enum_texts.insert(idx, texts.clone());
        }
        let (entries, text) = (&self.entries, &self.keys.text);
        let rehash = |i: u32| {
            let e = &entries[i as usize];
            key_hash(e.channel, Self::key_in(text, e))
        };
        // Growing the index hashes every key again: once for the rest of a large AddItems.
        self.index.reserve_if_full(self.batch_left, rehash);
        self.index.insert(hash, idx, rehash);
        self.live += 1;
        Ok(idx)
    }

    /// A free sample slot holding `sample`. The samples grow by a quarter (at least
    /// 1,024) but not past one per live entry while they can help it: most entries get
    /// their first sample one by one, after the AddItems that made them.
    fn alloc_sample(&mut self, sample: Sample) -> Idx<Sample> {
        if let Some(slot) = self.free_samples.pop() {
            self.samples[slot] = sample;
            return slot;
        }
        let len = self.samples.len();
        let room = (self.live + 16).saturating_sub(len).max(64);
        grow_exact(&mut self.samples, 1, Growth::quarter(1024).at_most(room));
        self.samples.push(sample);
        Idx::new(len)
    }

    /// The shared initial state for an entry created at `now` (one more entry refers to it).
    fn share_initial(&mut self, now: Timestamp) -> Idx<Sample> {
        if let Some(initial) = self.initial {
            let s = &mut self.samples[initial];
            if s.refs > 0 && s.timestamp == now {
                s.refs += 1;
                return initial;
            }
        }
        let initial = self.alloc_sample(Sample {
            refs: 1,
            ..Sample::initial(now)
        });
        self.initial = Some(initial);
        initial
    }

    /// Lets go of an entry's sample: its own, or one reference to a shared initial state.
    fn release_sample(&mut self, slot: Idx<Sample>, own: bool) {
        let s = &mut self.samples[slot];
        if !own {
            s.refs -= 1;
            if s.refs > 0 {
                return;
            }
            if self.initial == Some(slot) {
                self.initial = None;
            }
        }
        self.shared.forget(&mut s.value, slot);
        *s = Sample::initial(NEVER);
        self.free_samples.push(slot);
    }

    /// Stores the value of the sample in `slot`.
    fn put_value(&mut self, slot: Idx<Sample>, v: CachedValue) {
        self.shared.put(&mut self.samples[slot].value, slot, v);
    }

    #[inline]
    fn sample_at(&self, slot: Option<Idx<Sample>>) -> SampleRef<'_> {
        static FREED: Sample = Sample::initial(NEVER);
        let s = slot.map_or(&FREED, |slot| &self.samples[slot]);
        let value = match slot {
            Some(slot) => self.shared.get(s.value, slot),
            None => Cow::Owned(CachedValue::EMPTY),
        };
        SampleRef {
            value,
            timestamp: s.timestamp,
            refreshed_at: s.refreshed_at,
            changed_seq: s.changed_seq,
            quality: s.quality,
        }
    }

    /// The sample of an entry (the shared initial state before its first; a freed entry
    /// has none: an empty one).
    #[inline]
    pub fn sample(&self, e: &SourceEntry) -> SampleRef<'_> {
        self.sample_at(e.sample)
    }

    /// The sample slot of the live entry `idx`, made its own first if it shares the
    /// initial state.
    #[inline]
    fn own_sample(&mut self, idx: u32) -> Idx<Sample> {
        let e = &self.entries[idx as usize];
        match e.sample {
            Some(own) if e.has_own_sample() => own,
            _ => self.make_own_sample(idx),
        }
    }

    /// [`SourceTable::own_sample`] of an entry that shares the initial state: once per
    /// entry, so kept out of the callers.
    #[inline(never)]
    fn make_own_sample(&mut self, idx: u32) -> Idx<Sample> {
        let shared = self.entries[idx as usize].live_sample();
        let own = self.alloc_sample(Sample {
            refs: 0,
            ..self.samples[shared].clone()
        });
        self.release_sample(shared, false);
        let e = &mut self.entries[idx as usize];
        e.sample = Some(own);
        e.flags.insert(EntryFlags::OWN_SAMPLE);
        own
    }

    /// Stores a sample of the live entry `idx`; when value or quality changed, counts `seq`
    /// up and records it as the entry's change.
    #[inline]
    pub fn apply(&mut self, idx: u32, vqt: Vqt, now: Timestamp, seq: &mut u64) {
        let slot = self.own_sample(idx);
        let s = &mut self.samples[slot];
        let quality_changed = s.quality != vqt.quality;
        let value_changed = match Num::of(&vqt.value) {
            Some(n) => {
                let changed = s.value != PackedValue::num(n);
                self.shared.put_num(&mut s.value, slot, n);
                changed
            }
            None => {
                let same = self
                    .shared
                    .shared(s.value, slot)
                    .is_some_and(|old| old.same_as(&vqt.value));
                if !same {
                    let v = CachedValue::Shared(Arc::new(vqt.value));
                    self.shared.put(&mut s.value, slot, v);
                }
                !same
            }
        };
        s.quality = vqt.quality;
        s.timestamp = vqt.timestamp;
        s.refreshed_at = now;
        if quality_changed || value_changed {
            *seq += 1;
            s.changed_seq = *seq;
        }
    }

    fn intern_range(&mut self, low: f64, high: f64) -> Idx<EuRange> {
        let ranges = &mut self.eu_ranges;
        *self
            .eu_range_ids
            .entry((low.to_bits(), high.to_bits()))
            .or_insert_with(|| {
                ranges.push((low, high));
                Idx::new(ranges.len() - 1)
            })
    }

    /// The EU range of an entry when it is analog (percent deadband applies).
    pub fn analog_range(&self, e: &SourceEntry) -> Option<(f64, f64)> {
        e.eu_range.map(|i| self.eu_ranges[i])
    }

    #[inline]
    pub fn get(&self, key: SourceKey) -> Option<&SourceEntry> {
        self.entries
            .get(key.index() as usize)
            .filter(|e| e.generation == key.generation() && e.flags.contains(EntryFlags::LIVE))
    }

    /// The key of entry `idx` in its current generation.
    pub fn key_of(&self, idx: u32) -> SourceKey {
        SourceKey::new(idx, self.entries[idx as usize].generation)
    }

    pub fn source_item(&self, idx: u32) -> SourceItem {
        let e = &self.entries[idx as usize];
        SourceItem {
            key: SourceKey::new(idx, e.generation),
            channel: self.paths.get(e.channel).clone(),
            item_id: Arc::from(Self::key_in(&self.keys.text, e)),
            canonical_type: e.canonical,
        }
    }

    fn mark_dirty(&mut self, idx: u32) {
        let e = &mut self.entries[idx as usize];
        if !e.flags.contains(EntryFlags::DIRTY) {
            e.flags.insert(EntryFlags::DIRTY);
            self.dirty.push(idx);
        }
    }

    pub fn add_ref(&mut self, idx: u32) {
        self.entries[idx as usize].refs += 1;
    }

    pub fn release(&mut self, idx: u32) {
        let e = &mut self.entries[idx as usize];
        e.refs -= 1;
        if e.refs == 0 {
            self.mark_dirty(idx);
        }
    }

    /// The EU information of an entry (OPCITEMATTRIBUTES).
    pub fn eu_info(&self, idx: u32) -> EuInfo {
        let e = &self.entries[idx as usize];
        if let Some((low, high)) = self.analog_range(e) {
            EuInfo::Analog { low, high }
        } else if e.flags.contains(EntryFlags::ENUMERATED) {
            EuInfo::Enumerated(self.enum_texts.get(&idx).cloned().unwrap_or_default())
        } else {
            EuInfo::None
        }
    }

    /// The subscribers' rates of `idx` (only an entry with its own sample has any).
    pub fn rates(&self, idx: u32) -> RateSet {
        let e = &self.entries[idx as usize];
        if !e.has_own_sample() {
            return RateSet::Empty;
        }
        let s = &self.samples[e.live_sample()];
        if e.flags.contains(EntryFlags::MANY_RATES) {
            RateSet::Many(Idx::from_raw(s.sub_rate))
        } else if s.refs == 0 {
            RateSet::Empty
        } else {
            RateSet::One {
                rate: s.sub_rate,
                count: s.refs,
            }
        }
    }

    /// Sets the rates of `idx`, which has its own sample unless `r` is empty.
    fn set_rates(&mut self, idx: u32, r: RateSet) {
        let e = &mut self.entries[idx as usize];
        e.flags.remove(EntryFlags::MANY_RATES);
        if !e.has_own_sample() {
            debug_assert_eq!(r, RateSet::Empty);
            return;
        }
        let s = &mut self.samples[e.live_sample()];
        (s.sub_rate, s.refs) = match r {
            RateSet::Empty => (0, 0),
            RateSet::One { rate, count } => (rate, count),
            RateSet::Many(list) => {
                e.flags.insert(EntryFlags::MANY_RATES);
                (list.raw(), 0)
            }
        };
    }

    /// The sampling rate the backend was last told for `idx` (0: not subscribed).
    pub fn announced_rate(&self, idx: u32) -> u32 {
        let e = &self.entries[idx as usize];
        if e.has_own_sample() {
            self.samples[e.live_sample()].announced_rate
        } else {
            0
        }
    }

    /// Counts a subscriber of `idx` at `rate` (the first gives the entry its own sample
    /// slot, see [`EntryFlags::OWN_SAMPLE`]).
    pub fn add_rate(&mut self, idx: u32, rate: u32) {
        self.own_sample(idx);
        let set = match self.rates(idx) {
            RateSet::Empty => RateSet::One { rate, count: 1 },
            RateSet::One { rate: r, count } if r == rate => RateSet::One {
                rate,
                count: count + 1,
            },
            RateSet::One { rate: r, count } => {
                let v = vec![(r, count), (rate, 1)];
                let list = match self.free_many.pop() {
                    Some(list) => {
                        self.many_rates[list] = v;
                        list
                    }
                    None => {
                        self.many_rates.push(v);
                        Idx::new(self.many_rates.len() - 1)
                    }
                };
                RateSet::Many(list)
            }
            RateSet::Many(list) => {
                let v = &mut self.many_rates[list];
                match v.iter_mut().find(|(r, _)| *r == rate) {
                    Some((_, c)) => *c += 1,
                    None => v.push((rate, 1)),
                }
                RateSet::Many(list)
            }
        };
        self.set_rates(idx, set);
        self.mark_dirty(idx);
    }

    /// Removes a subscriber of `idx` counted at `rate`.
    pub fn remove_rate(&mut self, idx: u32, rate: u32) {
        let set = match self.rates(idx) {
            RateSet::Empty => RateSet::Empty,
            RateSet::One { rate: r, count } if r == rate => {
                if count > 1 {
                    RateSet::One {
                        rate,
                        count: count - 1,
                    }
                } else {
                    RateSet::Empty
                }
            }
            one @ RateSet::One { .. } => one,
            RateSet::Many(list) => {
                let v = &mut self.many_rates[list];
                if let Some(i) = v.iter().position(|(r, _)| *r == rate) {
                    v[i].1 -= 1;
                    if v[i].1 == 0 {
                        v.swap_remove(i);
                    }
                }
                match v.len() {
                    0 | 1 => {
                        let set = v
                            .first()
                            .map_or(RateSet::Empty, |&(rate, count)| RateSet::One {
                                rate,
                                count,
                            });
                        self.many_rates[list] = Vec::new();
                        self.free_many.push(list);
                        set
                    }
                    _ => RateSet::Many(list),
                }
            }
        };
        self.set_rates(idx, set);
        self.mark_dirty(idx);
    }

    /// The fastest rate any subscriber of `idx` asks for, 0 when nobody subscribes.
    pub fn fastest(&self, idx: u32) -> u32 {
        match self.rates(idx) {
            RateSet::Empty => 0,
            RateSet::One { rate, .. } => rate,
            RateSet::Many(list) => self.many_rates[list]
                .iter()
                .map(|(r, _)| *r)
                .min()
                .unwrap_or(0),
        }
    }

    /// The number of subscribers of `idx`.
    pub fn subscribers(&self, idx: u32) -> u32 {
        match self.rates(idx) {
            RateSet::Empty => 0,
            RateSet::One { count, .. } => count,
            RateSet::Many(list) => self.many_rates[list].iter().map(|(_, c)| *c).sum(),
        }
    }

    /// Sources with at least one subscriber.
    pub fn subscribed(&self) -> usize {
        (0..self.entries.len() as u32)
            .filter(|&i| {
                self.entries[i as usize].flags.contains(EntryFlags::LIVE) && self.subscribers(i) > 0
            })
            .count()
    }

    /// Turns the net subscription changes since the last flush into requests, and frees
    /// entries nobody refers to any more.
    pub fn flush(&mut self, out: &mut VecDeque<SourceRequest>) {
        if self.dirty.is_empty() {
            return;
        }
        let mut subscribe = Vec::new();
        let mut set_rate = Vec::new();
        let mut unsubscribe = Vec::new();
        let dirty = std::mem::take(&mut self.dirty);
        for &idx in &dirty {
            let want = self.fastest(idx);
            let e = &mut self.entries[idx as usize];
            e.flags.remove(EntryFlags::DIRTY);
            if !e.flags.contains(EntryFlags::LIVE) {
                continue;
            }
            let announced = self.announced_rate(idx);
            if want != announced {
                // One of them is not 0: the entry has (had) subscribers, so its own sample.
                let e = &self.entries[idx as usize];
                let key = SourceKey::new(idx, e.generation);
                self.samples[e.live_sample()].announced_rate = want;
                if announced == 0 {
                    subscribe.push(Subscription {
                        item: self.source_item(idx),
                        sampling_rate_ms: want,
                    });
                } else if want == 0 {
                    unsubscribe.push(key);
                } else {
                    set_rate.push((key, want));
                }
            }
            if self.entries[idx as usize].refs == 0 && self.announced_rate(idx) == 0 {
                self.free_entry(idx);
            }
        }
        if dirty.capacity() <= 4096 {
            self.dirty = dirty;
            self.dirty.clear();
        }
        if !subscribe.is_empty() {
            out.push_back(SourceRequest::Subscribe(subscribe));
        }
        if !set_rate.is_empty() {
            out.push_back(SourceRequest::SetSamplingRate(set_rate));
        }
        if !unsubscribe.is_empty() {
            out.push_back(SourceRequest::Unsubscribe(unsubscribe));
        }
    }

    fn free_entry(&mut self, idx: u32) {
        if self.entries[idx as usize]
            .flags
            .contains(EntryFlags::ENUMERATED)
        {
            self.enum_texts.remove(&idx);
        }
        let e = &self.entries[idx as usize];
        self.release_sample(e.live_sample(), e.has_own_sample());
        let e = &mut self.entries[idx as usize];
        self.index
            .remove(key_hash(e.channel, Self::key_in(&self.keys.text, e)), idx);
        self.keys.garbage += e.key_len as usize;
        e.key_len = 0;
        e.sample = None;
        e.eu_range = None;
        e.flags = EntryFlags::empty();
        e.generation = e.generation.wrapping_add(1);
        self.free.push(idx);
        self.live -= 1;
        if self.keys.garbage > 4096 && self.keys.garbage > self.keys.text.len() / 2 {
            self.compact_keys();
        }
    }
}

/// The 32-bit hash of a source item identity (FxHash-style; the key space is the
/// server's own namespace, not attacker-chosen buckets of a shared service).
fn key_hash(channel: u32, key: &str) -> u32 {
    const K: u64 = 0x517C_C1B7_2722_0A95;
    let mut h = u64::from(channel).wrapping_mul(K);
    let mut chunks = key.as_bytes().chunks_exact(8);
    for c in &mut chunks {
        let w = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
        h = (h.rotate_left(5) ^ w).wrapping_mul(K);
    }
    let mut tail = 0u64;
    for (i, &b) in chunks.remainder().iter().enumerate() {
        tail |= u64::from(b) << (8 * i);
    }
    h = (h.rotate_left(5) ^ tail ^ (key.len() as u64) << 56).wrapping_mul(K);
    (h >> 32) as u32 ^ h as u32
}

/// The index from a source item's 32-bit hash to its entry index: a
/// `hashbrown::HashTable<u32>` (the SwissTable under std's HashMap), 4 bytes and one
/// control byte per bucket. Keys are compared through the entries themselves, so no string
/// is stored twice; neither the table nor the entries keep hashes, so growing it asks
/// `rehash` of [`SourceIndex::insert`] (which hashes the entries' keys again).
#[derive(Default)]
pub(crate) struct SourceIndex {
    table: HashTable<u32>,
}

/// The table's 64-bit hash of a 32-bit one: hashbrown takes the bucket from the low bits
/// and its 7-bit tag from the top ones, so both halves carry the hash.
fn wide(hash: u32) -> u64 {
    (u64::from(hash) << 32) | u64::from(hash)
}

impl SourceIndex {
    pub fn find(&self, hash: u32, mut eq: impl FnMut(u32) -> bool) -> Option<u32> {
        self.table.find(wide(hash), |&i| eq(i)).copied()
    }

    /// Adds `idx` (not in the index yet) under `hash`; `rehash` gives the hash of an
    /// index already in the table, for when it grows.
    pub fn insert(&mut self, hash: u32, idx: u32, rehash: impl Fn(u32) -> u32) {
        self.table
            .insert_unique(wide(hash), idx, |&i| wide(rehash(i)));
    }

    /// Makes room for `n` more when the table is full (the next insert would grow it).
    pub fn reserve_if_full(&mut self, n: usize, rehash: impl Fn(u32) -> u32) {
        if n > 1 && self.table.len() == self.table.capacity() {
            self.table.reserve(n, |&i| wide(rehash(i)));
        }
    }

    pub fn remove(&mut self, hash: u32, idx: u32) {
        if let Ok(entry) = self.table.find_entry(wide(hash), |&i| i == idx) {
            entry.remove();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::HashMap;

    proptest! {
        /// The index behaves like a map under any sequence of inserts and removes,
        /// including colliding hashes.
        #[test]
        fn source_index_matches_a_hash_map(ops in proptest::collection::vec((0u32..64, any::<bool>()), 1..400)) {
            let mut index = SourceIndex::default();
            let mut model: HashMap<u32, u32> = HashMap::new(); // key -> idx
            let mut next = 0u32;
            let hash = |k: u32| k % 7; // many collisions
            for (k, insert) in ops {
                if insert && !model.contains_key(&k) {
                    let keys: HashMap<u32, u32> = model.iter().map(|(k, i)| (*i, *k)).collect();
                    index.reserve_if_full(k as usize % 5, |i| hash(keys[&i]));
                    index.insert(hash(k), next, |i| hash(keys[&i]));
                    model.insert(k, next);
                    next += 1;
                } else if !insert {
                    if let Some(idx) = model.remove(&k) {
                        index.remove(hash(k), idx);
                    }
                }
                let keys: HashMap<u32, u32> = model.iter().map(|(k, i)| (*i, *k)).collect();
                for probe in 0u32..64 {
                    let found = index.find(hash(probe), |i| keys.get(&i) == Some(&probe));
                    prop_assert_eq!(found, model.get(&probe).copied());
                }
            }
        }
    }

    /// A sample's fields, to compare in one assertion.
    fn sample_fields<'s>(
        s: &'s SampleRef<'_>,
    ) -> (&'s CachedValue, Quality, Timestamp, Timestamp, u64) {
        (
            &s.value,
            s.quality,
            s.timestamp,
            s.refreshed_at,
            s.changed_seq,
        )
    }

    /// A plain R8 item of `key` on channel `*`, readable and writable, no EU.
    fn r8_def(source_key: String) -> ItemDef {
        ItemDef {
            source_key,
            channel: "*".into(),
            canonical_type: VarType::R8,
            access_rights: 3,
            eu: EuInfo::None,
            constant: None,
        }
    }

    #[test]
    fn rate_set_tracks_the_fastest_subscriber() {
        let mut t = SourceTable::default();
        let i = t.find_or_insert(&r8_def("X".into()), Timestamp(0)).unwrap();
        assert_eq!((t.fastest(i), t.subscribers(i)), (0, 0));
        t.add_rate(i, 5000);
        t.add_rate(i, 1000);
        t.add_rate(i, 1000);
        assert_eq!((t.fastest(i), t.subscribers(i)), (1000, 3));
        t.remove_rate(i, 1000);
        t.remove_rate(i, 1000);
        assert_eq!((t.fastest(i), t.subscribers(i)), (5000, 1));
        assert_eq!(
            t.rates(i),
            RateSet::One {
                rate: 5000,
                count: 1
            }
        );
        t.remove_rate(i, 5000);
        assert_eq!((t.fastest(i), t.subscribers(i)), (0, 0));
    }

    /// The subscription state (rates, what the backend was told) is in the entry's own
    /// sample, made at the first subscriber and kept until the entry goes.
    #[test]
    fn subscription_state_is_in_the_entrys_own_sample() {
        let mut t = SourceTable::default();
        let i = t.find_or_insert(&r8_def("X".into()), Timestamp(0)).unwrap();
        t.add_ref(i);
        assert!(!t.entries[i as usize].has_own_sample());
        assert_eq!((t.rates(i), t.announced_rate(i)), (RateSet::Empty, 0));
        t.add_rate(i, 1000);
        t.add_rate(i, 500);
        assert!(t.entries[i as usize].has_own_sample());
        let mut out = VecDeque::new();
        t.flush(&mut out);
        assert!(
            matches!(&out[0], SourceRequest::Subscribe(v) if v[0].sampling_rate_ms == 500),
            "{out:?}"
        );
        assert_eq!(t.announced_rate(i), 500);
        t.remove_rate(i, 500);
        assert_eq!(
            t.rates(i),
            RateSet::One {
                rate: 1000,
                count: 1
            }
        );
        out.clear();
        t.flush(&mut out);
        assert!(matches!(&out[0], SourceRequest::SetSamplingRate(v) if v[0].1 == 1000));
        t.remove_rate(i, 1000);
        out.clear();
        t.flush(&mut out);
        assert!(matches!(&out[0], SourceRequest::Unsubscribe(_)));
        assert_eq!(
            (t.rates(i), t.announced_rate(i), t.live()),
            (RateSet::Empty, 0, 1)
        );
        assert!(t.entries[i as usize].has_own_sample());
        t.release(i);
        t.flush(&mut out);
        assert_eq!(t.live(), 0);
        assert_eq!(t.free_samples.len(), t.samples.len());
    }

    #[test]
    fn eu_ranges_are_shared_and_each_entry_keeps_its_own() {
        let mut t = SourceTable::default();
        let def = |key: &str, eu: EuInfo| ItemDef {
            source_key: key.into(),
            channel: "*".into(),
            canonical_type: VarType::R4,
            access_rights: 3,
            eu,
            constant: None,
        };
        let a = t
            .find_or_insert(
                &def(
                    "A",
                    EuInfo::Analog {
                        low: 0.0,
                        high: 100.0,
                    },
                ),
                Timestamp(0),
            )
            .unwrap();
        let b = t
            .find_or_insert(
                &def(
                    "B",
                    EuInfo::Analog {
                        low: -5.0,
                        high: 5.0,
                    },
                ),
                Timestamp(0),
            )
            .unwrap();
        let c = t
            .find_or_insert(
                &def(
                    "C",
                    EuInfo::Analog {
                        low: 0.0,
                        high: 100.0,
                    },
                ),
                Timestamp(0),
            )
            .unwrap();
        let d = t
            .find_or_insert(&def("D", EuInfo::None), Timestamp(0))
            .unwrap();
        let range = |i: u32| t.analog_range(&t.entries[i as usize]);
        assert_eq!(
            (range(a), range(b), range(c), range(d)),
            (
                Some((0.0, 100.0)),
                Some((-5.0, 5.0)),
                Some((0.0, 100.0)),
                None
            )
        );
        assert_eq!(t.eu_ranges.len(), 2);
        assert!(matches!(t.eu_info(b), EuInfo::Analog { low, high } if (low, high) == (-5.0, 5.0)));
        assert!(matches!(t.eu_info(d), EuInfo::None));
    }

    /// The entries and keys of a large AddItems take the room they need, no more; small
    /// calls grow the entries by a quarter (at least 1,024) and the keys by a quarter (at
    /// least 4,096 bytes).
    #[test]
    fn a_large_call_reserves_its_entries_exactly() {
        let def = |i: u32| r8_def(format!("K{i}"));
        let mut t = SourceTable::default();
        let mut bytes: usize = (0..5000).map(|i| def(i).source_key.len()).sum();
        let total = bytes;
        for i in 0..5000 {
            t.batch_left(5000 - i as usize, bytes);
            bytes -= def(i).source_key.len();
            t.find_or_insert(&def(i), Timestamp(0)).unwrap();
        }
        t.batch_left(0, 0);
        assert_eq!(t.entries.capacity(), 5000);
        assert_eq!((t.keys.text.len(), t.keys.text.capacity()), (total, total));
        t.find_or_insert(&def(5000), Timestamp(0)).unwrap();
        assert_eq!(t.entries.capacity(), 5000 + 1250);
        assert_eq!(t.keys.text.capacity(), total + total / 4);
    }

    /// The keys live in one text; freed keys are dropped from it when they are most of
    /// it, and the live entries keep their keys and are found by them.
    #[test]
    fn keys_survive_the_compaction_of_the_key_text() {
        let def = |i: u32| r8_def(format!("KEY_{i:06}"));
        let mut t = SourceTable::default();
        let idx: Vec<u32> = (0..2000)
            .map(|i| t.find_or_insert(&def(i), Timestamp(0)).unwrap())
            .collect();
        for &i in &idx {
            t.add_ref(i);
        }
        assert_eq!(t.keys.text.len(), 2000 * 10);
        for &i in idx.iter().filter(|&&i| i % 7 != 0) {
            t.release(i);
        }
        t.flush(&mut VecDeque::new());
        let text = t.keys.text.len();
        assert!(text < 2000 * 10, "compacted");
        assert!(t.keys.garbage <= text / 2);
        assert_eq!(text - t.keys.garbage, 286 * 10);
        for (n, &i) in idx.iter().enumerate().filter(|(_, &i)| i % 7 == 0) {
            assert_eq!(t.key(i), format!("KEY_{n:06}"));
            assert_eq!(t.find_or_insert(&def(n as u32), Timestamp(0)), Ok(i));
            assert_eq!(&*t.source_item(i).item_id, t.key(i));
        }
        // A freed slot reused: the new key is appended, the old one is garbage.
        let j = t.find_or_insert(&def(9999), Timestamp(0)).unwrap();
        assert_eq!(t.key(j), "KEY_009999");
        assert_eq!(t.keys.text.len(), text + 10);
    }

    fn vqt(v: f64, t: i64) -> Vqt {
        Vqt {
            value: Value::R8(v),
            quality: Quality::GOOD,
            timestamp: Timestamp(t),
        }
    }

    /// Entries created at the same time share one initial state until their first sample,
    /// which gets a slot of its own; the shared state goes with its last entry.
    #[test]
    fn an_entry_gets_a_sample_of_its_own_at_its_first() {
        let mut t = SourceTable::default();
        let (a, b) = (
            t.find_or_insert(&r8_def("A".into()), Timestamp(7)).unwrap(),
            t.find_or_insert(&r8_def("B".into()), Timestamp(7)).unwrap(),
        );
        let c = t.find_or_insert(&r8_def("C".into()), Timestamp(8)).unwrap();
        assert_eq!(t.samples.len(), 2, "one initial state per creation time");
        for (i, at) in [(a, 7), (b, 7), (c, 8)] {
            let e = &t.entries[i as usize];
            assert!(!e.has_own_sample());
            let s = t.sample(e);
            assert!(!s.has_value());
            assert_eq!(
                sample_fields(&s),
                (
                    &CachedValue::EMPTY,
                    Quality::BAD_WAITING_FOR_INITIAL_DATA,
                    Timestamp(at),
                    NEVER,
                    0
                )
            );
        }
        let mut seq = 10;
        t.apply(a, vqt(1.5, 3), Timestamp(9), &mut seq);
        let s = t.sample(&t.entries[a as usize]);
        assert_eq!(
            sample_fields(&s),
            (
                &CachedValue::from_value(Value::R8(1.5)),
                Quality::GOOD,
                Timestamp(3),
                Timestamp(9),
                11
            )
        );
        assert!(t.entries[a as usize].has_own_sample());
        assert!(
            !t.entries[b as usize].has_own_sample(),
            "b keeps the shared state"
        );
        assert_eq!(t.sample(&t.entries[b as usize]).timestamp, Timestamp(7));
        // The same sample again: no change, no count.
        t.apply(a, vqt(1.5, 4), Timestamp(10), &mut seq);
        assert_eq!(
            (seq, t.sample(&t.entries[a as usize]).changed_seq),
            (11, 11)
        );
        // b's first sample: the shared state of time 7 has no entry left and is freed.
        t.apply(b, vqt(2.0, 5), Timestamp(10), &mut seq);
        assert_eq!(t.free_samples.len(), 1);
        assert_eq!(t.samples[t.free_samples[0]].refs, 0);
        // A new entry at time 8 shares c's state; at 11 one is made (in the freed slot).
        let d = t.find_or_insert(&r8_def("D".into()), Timestamp(8)).unwrap();
        assert_eq!(t.entries[d as usize].sample, t.entries[c as usize].sample);
        let e = t
            .find_or_insert(&r8_def("E".into()), Timestamp(11))
            .unwrap();
        assert!(t.free_samples.is_empty());
        assert_eq!(t.sample(&t.entries[e as usize]).timestamp, Timestamp(11));
        assert_eq!(t.samples.len(), 4);
    }

    /// A constant has its sample from the start; freed entries give their samples back
    /// and a re-used entry starts again without a value.
    #[test]
    fn freed_entries_free_their_samples() {
        let mut t = SourceTable::default();
        let k = t
            .find_or_insert(
                &ItemDef {
                    constant: Some(Value::I4(5)),
                    ..r8_def("K".into())
                },
                Timestamp(1),
            )
            .unwrap();
        let e = &t.entries[k as usize];
        assert!(e.has_own_sample() && e.is_constant());
        let s = t.sample(e);
        assert_eq!(
            (s.value.to_value(), s.quality, s.refreshed_at),
            (
                Value::I4(5),
                Quality::GOOD.with_limit(Quality::LIMIT_CONST),
                Timestamp(1)
            )
        );
        let x = t.find_or_insert(&r8_def("X".into()), Timestamp(1)).unwrap();
        let y = t.find_or_insert(&r8_def("Y".into()), Timestamp(1)).unwrap();
        t.apply(x, vqt(3.0, 2), Timestamp(2), &mut 0);
        for i in [k, x, y] {
            t.add_ref(i);
            t.release(i);
        }
        t.flush(&mut VecDeque::new());
        assert_eq!(t.live(), 0);
        assert_eq!(t.free_samples.len(), t.samples.len(), "every sample free");
        assert!(t
            .samples
            .iter()
            .all(|s| s.value == PackedValue::EMPTY && s.refs == 0));
        assert!(t.shared.is_empty());
        let freed = &t.entries[x as usize];
        assert!(!freed.has_own_sample());
        assert_eq!(t.sample(freed).refreshed_at, NEVER);
        // The slot of X again, for Z: no value until its first sample.
        let z = t.find_or_insert(&r8_def("Z".into()), Timestamp(3)).unwrap();
        let e = &t.entries[z as usize];
        assert!(!e.has_own_sample());
        assert_eq!(
            (t.sample(e).quality, t.sample(e).timestamp),
            (Quality::BAD_WAITING_FOR_INITIAL_DATA, Timestamp(3))
        );
        assert_eq!(t.samples.len(), 3, "no new slot");
    }

    /// A subscribed entry has its own sample slot before its first sample, in the order of
    /// subscription (the order of the entries a scan reads), still without a value.
    #[test]
    fn subscribing_gives_an_entry_its_own_sample_slot_in_order() {
        let mut t = SourceTable::default();
        let idx: Vec<u32> = (0..10)
            .map(|i| {
                t.find_or_insert(&r8_def(format!("K{i}")), Timestamp(5))
                    .unwrap()
            })
            .collect();
        assert_eq!(t.samples.len(), 1, "one shared initial state");
        for &i in &idx {
            t.add_rate(i, 1000);
        }
        t.add_rate(idx[0], 500);
        let slots: Vec<u32> = idx
            .iter()
            .map(|&i| t.entries[i as usize].live_sample().raw())
            .collect();
        assert!(slots.windows(2).all(|w| w[0] + 1 == w[1]), "{slots:?}");
        assert_eq!(t.free_samples.len(), 1, "the shared state is free");
        for &i in &idx {
            let e = &t.entries[i as usize];
            assert!(e.has_own_sample());
            let s = t.sample(e);
            assert!(!s.has_value());
            assert_eq!(
                (s.quality, s.timestamp),
                (Quality::BAD_WAITING_FOR_INITIAL_DATA, Timestamp(5))
            );
        }
        // The first sample goes into that slot.
        let slot = t.entries[idx[3] as usize].sample;
        t.apply(idx[3], vqt(1.0, 6), Timestamp(6), &mut 0);
        assert_eq!(t.entries[idx[3] as usize].sample, slot);
        assert!(t.sample(&t.entries[idx[3] as usize]).has_value());
    }

    /// Numbers are in the sample, strings and arrays in the table's map by slot, which
    /// they leave when a number follows or the entry goes; equal strings are no change.
    #[test]
    fn string_samples_are_kept_apart_from_the_sample() {
        let mut t = SourceTable::default();
        let x = t.find_or_insert(&r8_def("X".into()), Timestamp(0)).unwrap();
        let k = t
            .find_or_insert(
                &ItemDef {
                    constant: Some(Value::Bstr("c".into())),
                    ..r8_def("K".into())
                },
                Timestamp(0),
            )
            .unwrap();
        assert_eq!(
            t.sample(&t.entries[k as usize]).value.to_value(),
            Value::Bstr("c".into())
        );
        assert_eq!(t.shared.len(), 1);
        let text = |v: &str| Vqt {
            value: Value::Bstr(v.into()),
            ..vqt(0.0, 1)
        };
        let mut seq = 0;
        t.apply(x, text("a"), Timestamp(1), &mut seq);
        let s = t.sample(&t.entries[x as usize]);
        assert_eq!(
            (s.value.to_value(), s.changed_seq),
            (Value::Bstr("a".into()), 1)
        );
        assert_eq!(t.shared.len(), 2);
        t.apply(x, text("a"), Timestamp(2), &mut seq);
        assert_eq!(seq, 1, "an equal string is no change");
        t.apply(x, vqt(2.0, 3), Timestamp(3), &mut seq);
        assert_eq!(t.shared.len(), 1, "a number follows");
        assert_eq!(
            t.sample(&t.entries[x as usize]).value.to_value(),
            Value::R8(2.0)
        );
        t.apply(x, text("b"), Timestamp(4), &mut seq);
        assert_eq!((seq, t.shared.len()), (3, 2));
        for i in [x, k] {
            t.add_ref(i);
            t.release(i);
        }
        t.flush(&mut VecDeque::new());
        assert!(t.shared.is_empty());
    }

    /// The samples grow one per live entry, not by doubling, as entries get their first
    /// sample one by one.
    #[test]
    fn samples_grow_to_the_live_entries() {
        let mut t = SourceTable::default();
        let n = 5000u32;
        for i in 0..n {
            t.batch_left((n - i) as usize, 0);
            t.find_or_insert(&r8_def(format!("K{i}")), Timestamp(0))
                .unwrap();
        }
        t.batch_left(0, 0);
        let mut seq = 0;
        for i in 0..n {
            t.apply(i, vqt(f64::from(i), 1), Timestamp(1), &mut seq);
        }
        assert_eq!(t.samples.len() - t.free_samples.len(), n as usize);
        assert!(
            t.samples.capacity() <= n as usize + 16,
            "{}",
            t.samples.capacity()
        );
    }

    #[test]
    fn entries_stay_small() {
        assert!(
            std::mem::size_of::<SourceEntry>() <= 32,
            "{}",
            std::mem::size_of::<SourceEntry>()
        );
        assert_eq!(std::mem::size_of::<CachedValue>(), 16);
        assert!(
            std::mem::size_of::<Sample>() <= 48,
            "{}",
            std::mem::size_of::<Sample>()
        );
    }

    #[test]
    fn cached_values_round_trip_exactly() {
        let values = [
            Value::Empty,
            Value::I1(-3),
            Value::UI1(200),
            Value::I2(-30000),
            Value::UI2(65000),
            Value::I4(-7),
            Value::UI4(4_000_000_000),
            Value::I8(i64::MIN),
            Value::UI8(u64::MAX),
            Value::R4(1.5),
            Value::R8(-0.0),
            Value::Cy(123_456),
            Value::Date(45_000.25),
            Value::Bool(true),
            Value::Error(-2147352571),
            Value::Bstr("x".into()),
        ];
        for v in values {
            let c = CachedValue::from_value(v.clone());
            assert_eq!(c.to_value(), v);
            assert!(c.same_as(&v));
        }
        assert!(!CachedValue::from_value(Value::I4(1)).same_as(&Value::I2(1)));
    }
}
