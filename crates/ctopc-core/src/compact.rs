//! The vocabulary of the compact tables: the engine's item cache (`model/cache.rs`), its
//! group items (`model/item.rs`) and the asix backend's variables (`asix_net::backend`).
//! These tables are most of the memory of a large configuration, so their rows are small
//! and fixed by size tests beside them; this module gives them one way to say each thing
//! a small row needs:
//!
//! - [`Idx`]: an index into a table of one type, in 4 bytes with a niche, so that
//!   `Option<Idx<T>>` is 4 bytes too and says "none" without a sentinel value
//!   (rust-analyzer's `la-arena` `Idx`, over a non-max `u32`);
//! - [`PackedValue`] and [`SideMap`]: "a number inline, else shared": a row keeps a
//!   number's type and bits in 10 bytes, or a mark that its value (a string, an array) is
//!   in the table's side map under the row's key;
//! - [`grow_exact`]: a table grows by a quarter, not double, or by what a large call says
//!   it needs;
//! - flags are `bitflags` types of each table's own (`EntryFlags`, `ItemFlags`), so that
//!   one table's flag cannot be tested on another's row.

use std::borrow::Cow;
use std::collections::HashMap;
use std::fmt;
use std::hash::{BuildHasherDefault, Hash, Hasher};
use std::marker::PhantomData;
use std::num::NonZeroU32;
use std::ops::{Index, IndexMut};

use crate::{Value, VarType};

/// A `u32` that is never `u32::MAX`, held as the `NonZeroU32` of its complement, so that
/// `Option<NonMaxU32>` is 4 bytes.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct NonMaxU32(NonZeroU32);

impl NonMaxU32 {
    /// `v`, unless it is `u32::MAX`.
    #[inline]
    pub const fn new(v: u32) -> Option<Self> {
        match NonZeroU32::new(!v) {
            Some(n) => Some(NonMaxU32(n)),
            None => None,
        }
    }

    #[inline]
    pub const fn get(self) -> u32 {
        !self.0.get()
    }
}

impl fmt::Debug for NonMaxU32 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.get().fmt(f)
    }
}

/// An index into a table of `T`s: 4 bytes, and `Option<Idx<T>>` as well. The type keeps an
/// index of one table from being used in another; a `Vec<T>` is indexed by it directly.
pub struct Idx<T> {
    raw: NonMaxU32,
    _table: PhantomData<fn() -> T>,
}

impl<T> Idx<T> {
    /// The index `i`. Panics when `i` does not fit a `u32` below `u32::MAX`: a compact
    /// table holds fewer rows.
    #[inline]
    pub fn new(i: usize) -> Self {
        let raw = u32::try_from(i).ok().and_then(NonMaxU32::new);
        Idx {
            raw: raw.expect("a compact table's index fits a u32 below u32::MAX"),
            _table: PhantomData,
        }
    }

    /// The index `raw` as [`Idx::raw`] gave it (panics at `u32::MAX`).
    #[inline]
    pub fn from_raw(raw: u32) -> Self {
        Self::new(raw as usize)
    }

    /// The index as a `u32` (below `u32::MAX`).
    #[inline]
    pub const fn raw(self) -> u32 {
        self.raw.get()
    }

    #[inline]
    pub const fn index(self) -> usize {
        self.raw.get() as usize
    }
}

impl<T> Clone for Idx<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for Idx<T> {}
impl<T> PartialEq for Idx<T> {
    fn eq(&self, other: &Self) -> bool {
        self.raw == other.raw
    }
}
impl<T> Eq for Idx<T> {}
impl<T> PartialOrd for Idx<T> {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl<T> Ord for Idx<T> {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.raw().cmp(&other.raw())
    }
}
impl<T> Hash for Idx<T> {
    fn hash<H: Hasher>(&self, state: &mut H) {
        state.write_u32(self.raw());
    }
}
impl<T> fmt::Debug for Idx<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Idx({})", self.raw())
    }
}

impl<T> Index<Idx<T>> for Vec<T> {
    type Output = T;
    #[inline]
    fn index(&self, i: Idx<T>) -> &T {
        &self[i.index()]
    }
}
impl<T> IndexMut<Idx<T>> for Vec<T> {
    #[inline]
    fn index_mut(&mut self, i: Idx<T>) -> &mut T {
        &mut self[i.index()]
    }
}

/// A table [`grow_exact`] can grow: a `Vec`, or a `String` of texts one after another.
pub trait Room {
    /// Its length and its capacity.
    fn len_capacity(&self) -> (usize, usize);
    fn reserve_exact(&mut self, additional: usize);
}

impl<T> Room for Vec<T> {
    fn len_capacity(&self) -> (usize, usize) {
        (self.len(), self.capacity())
    }
    fn reserve_exact(&mut self, additional: usize) {
        Vec::reserve_exact(self, additional);
    }
}

impl Room for String {
    fn len_capacity(&self) -> (usize, usize) {
        (self.len(), self.capacity())
    }
    fn reserve_exact(&mut self, additional: usize) {
        String::reserve_exact(self, additional);
    }
}

/// How a compact table grows when it is full: by a quarter of its length, at least `min`
/// ([`Growth::quarter`]); by a `hint` when that is more ([`Growth::hint`]: the rest of a
/// large call, so that the call's rows take the room they need at once, no more); by at
/// most `most` ([`Growth::at_most`]: a table that should not pass the rows that will use
/// it); never by less than the room asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Growth {
    min: usize,
    hint: usize,
    most: usize,
}

impl Growth {
    /// By a quarter of the length, at least `min`.
    pub const fn quarter(min: usize) -> Self {
        Growth {
            min,
            hint: 0,
            most: usize::MAX,
        }
    }

    /// By `hint` when that is more than a quarter.
    pub const fn hint(self, hint: usize) -> Self {
        Growth { hint, ..self }
    }

    /// By at most `most` (still by the room asked for).
    pub const fn at_most(self, most: usize) -> Self {
        Growth { most, ..self }
    }

    /// What a table of `len` grows by when it needs room for `need` more.
    pub fn amount(self, len: usize, need: usize) -> usize {
        let quarter = (len / 4).max(self.min);
        self.hint.max(quarter).min(self.most).max(need)
    }
}

/// Makes room for `need` more in `table` (rows, or bytes of text) when it has less:
/// exactly [`Growth::amount`] more, not double, since doubling would leave up to half of
/// a large table unused.
pub fn grow_exact<T: Room + ?Sized>(table: &mut T, need: usize, growth: Growth) {
    let (len, capacity) = table.len_capacity();
    if len + need > capacity {
        table.reserve_exact(growth.amount(len, need));
    }
}

/// The types of the numbers a [`PackedValue`] holds inline: [`Value`]'s scalars, by their
/// VARTYPE. An enum, so that the values no type takes are niches for
/// `Option<PackedValue>` and the shared mark.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
enum NumType {
    Empty = VarType::EMPTY.0,
    I2 = VarType::I2.0,
    I4 = VarType::I4.0,
    R4 = VarType::R4.0,
    R8 = VarType::R8.0,
    Cy = VarType::CY.0,
    Date = VarType::DATE.0,
    Error = VarType::ERROR.0,
    Bool = VarType::BOOL.0,
    I1 = VarType::I1.0,
    UI1 = VarType::UI1.0,
    UI2 = VarType::UI2.0,
    UI4 = VarType::UI4.0,
    I8 = VarType::I8.0,
    UI8 = VarType::UI8.0,
}

/// A scalar value as its type and bits, exact (an `f64`'s sign of zero and NaN payload
/// included).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Num {
    vt: NumType,
    bits: u64,
}

impl Num {
    pub const EMPTY: Num = Num {
        vt: NumType::Empty,
        bits: 0,
    };

    /// `v` as a number; `None` for a string or an array.
    #[inline]
    pub fn of(v: &Value) -> Option<Num> {
        let (vt, bits) = match *v {
            Value::Empty => (NumType::Empty, 0),
            Value::I1(x) => (NumType::I1, x as i64 as u64),
            Value::UI1(x) => (NumType::UI1, u64::from(x)),
            Value::I2(x) => (NumType::I2, x as i64 as u64),
            Value::UI2(x) => (NumType::UI2, u64::from(x)),
            Value::I4(x) => (NumType::I4, x as i64 as u64),
            Value::UI4(x) => (NumType::UI4, u64::from(x)),
            Value::I8(x) => (NumType::I8, x as u64),
            Value::UI8(x) => (NumType::UI8, x),
            Value::R4(x) => (NumType::R4, u64::from(x.to_bits())),
            Value::R8(x) => (NumType::R8, x.to_bits()),
            Value::Cy(x) => (NumType::Cy, x as u64),
            Value::Date(x) => (NumType::Date, x.to_bits()),
            Value::Bool(b) => (NumType::Bool, u64::from(b)),
            Value::Error(e) => (NumType::Error, e as i64 as u64),
            Value::Bstr(_) | Value::Array(_) => return None,
        };
        Some(Num { vt, bits })
    }

    #[inline]
    pub fn vt(self) -> VarType {
        VarType(self.vt as u16)
    }

    #[inline]
    pub fn to_value(self) -> Value {
        let bits = self.bits;
        match self.vt {
            NumType::Empty => Value::Empty,
            NumType::I1 => Value::I1(bits as i8),
            NumType::UI1 => Value::UI1(bits as u8),
            NumType::I2 => Value::I2(bits as i16),
            NumType::UI2 => Value::UI2(bits as u16),
            NumType::I4 => Value::I4(bits as i32),
            NumType::UI4 => Value::UI4(bits as u32),
            NumType::I8 => Value::I8(bits as i64),
            NumType::UI8 => Value::UI8(bits),
            NumType::R4 => Value::R4(f32::from_bits(bits as u32)),
            NumType::R8 => Value::R8(f64::from_bits(bits)),
            NumType::Cy => Value::Cy(bits as i64),
            NumType::Date => Value::Date(f64::from_bits(bits)),
            NumType::Bool => Value::Bool(bits != 0),
            NumType::Error => Value::Error(bits as i32),
        }
    }
}

/// A row's value in a compact table: a [`Num`] inline, or the mark that the value is
/// shared, in the table's [`SideMap`] under the row's key. 10 bytes at an alignment of 2
/// (packed: a row puts it beside its 16-bit fields without padding), and
/// `Option<PackedValue>` as well.
#[derive(Clone, Copy, PartialEq, Eq)]
#[repr(Rust, packed(2))]
pub struct PackedValue {
    bits: u64,
    /// The number's type; `None`: shared.
    vt: Option<NumType>,
}

impl PackedValue {
    pub const EMPTY: PackedValue = PackedValue::num(Num::EMPTY);
    const SHARED: PackedValue = PackedValue { bits: 0, vt: None };

    #[inline]
    pub const fn num(n: Num) -> Self {
        PackedValue {
            bits: n.bits,
            vt: Some(n.vt),
        }
    }

    /// The number held inline; `None` when the value is shared.
    #[inline]
    pub fn get(self) -> Option<Num> {
        let (vt, bits) = (self.vt?, self.bits);
        Some(Num { vt, bits })
    }

    #[inline]
    pub fn is_shared(self) -> bool {
        self.vt.is_none()
    }
}

impl fmt::Debug for PackedValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.get() {
            Some(n) => n.fmt(f),
            None => f.write_str("Shared"),
        }
    }
}

/// A value a [`SideMap`] keeps: a number inline, else the value itself aside.
pub trait Packable: Sized {
    /// The value as a number; `None` keeps it aside.
    fn as_num(&self) -> Option<Num>;
    fn from_num(n: Num) -> Self;
}

impl Packable for Value {
    #[inline]
    fn as_num(&self) -> Option<Num> {
        Num::of(self)
    }
    #[inline]
    fn from_num(n: Num) -> Self {
        n.to_value()
    }
}

/// A multiplicative hasher for integer keys (server handles, indices). They are the
/// server's own, so there is no flooding concern; std's SipHash would cost more than the
/// lookup itself.
#[derive(Default, Clone, Copy)]
pub struct IntHasher(u64);

impl Hasher for IntHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(b)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }
    fn write_u32(&mut self, n: u32) {
        self.0 = (self.0 ^ u64::from(n)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
    fn write_u64(&mut self, n: u64) {
        self.0 = (self.0 ^ n).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

/// The shared values of a compact table's rows, by the rows' keys: the other half of their
/// [`PackedValue`]s. Every change of a row's value goes through here, so that a row is
/// marked shared exactly while the map holds its value.
pub struct SideMap<K, V> {
    map: HashMap<K, V, BuildHasherDefault<IntHasher>>,
}

impl<K, V> Default for SideMap<K, V> {
    fn default() -> Self {
        SideMap {
            map: HashMap::default(),
        }
    }
}

impl<K: Copy + Eq + Hash, V: Packable> SideMap<K, V> {
    /// Stores `v` as the value of row `key`, whose packed value is `at`: a number in `at`
    /// (a shared value the row had leaves the map), anything else in the map.
    #[inline]
    pub fn put(&mut self, at: &mut PackedValue, key: K, v: V) {
        match v.as_num() {
            Some(n) => self.put_num(at, key, n),
            None => {
                *at = PackedValue::SHARED;
                self.map.insert(key, v);
            }
        }
    }

    /// Stores the number `n` as the value of row `key`.
    #[inline]
    pub fn put_num(&mut self, at: &mut PackedValue, key: K, n: Num) {
        if at.is_shared() {
            self.map.remove(&key);
        }
        *at = PackedValue::num(n);
    }

    /// The value of row `key`: a number made from `at`, a shared value borrowed.
    #[inline]
    pub fn get(&self, at: PackedValue, key: K) -> Cow<'_, V>
    where
        V: Clone,
    {
        match at.get() {
            Some(n) => Cow::Owned(V::from_num(n)),
            None => self.get_shared(key),
        }
    }

    fn get_shared(&self, key: K) -> Cow<'_, V>
    where
        V: Clone,
    {
        self.map
            .get(&key)
            .map_or_else(|| Cow::Owned(V::from_num(Num::EMPTY)), Cow::Borrowed)
    }

    /// The shared value of row `key`, if `at` marks one.
    #[inline]
    pub fn shared(&self, at: PackedValue, key: K) -> Option<&V> {
        if at.is_shared() {
            self.map.get(&key)
        } else {
            None
        }
    }

    /// Takes the value of row `key` out; `at` becomes empty.
    pub fn take(&mut self, at: &mut PackedValue, key: K) -> V {
        let v = match at.get() {
            Some(n) => V::from_num(n),
            None => self
                .map
                .remove(&key)
                .unwrap_or_else(|| V::from_num(Num::EMPTY)),
        };
        *at = PackedValue::EMPTY;
        v
    }

    /// Forgets the value of row `key`; `at` becomes empty.
    #[inline]
    pub fn forget(&mut self, at: &mut PackedValue, key: K) {
        self.put_num(at, key, Num::EMPTY);
    }

    /// The shared values held.
    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::value::ArrayValue;
    use std::mem::size_of;

    #[test]
    fn indices_and_packed_values_have_niches() {
        assert_eq!(size_of::<Idx<String>>(), 4);
        assert_eq!(size_of::<Option<Idx<String>>>(), 4);
        assert_eq!(size_of::<PackedValue>(), 10);
        assert_eq!(std::mem::align_of::<PackedValue>(), 2);
        assert_eq!(size_of::<Option<PackedValue>>(), 10);
    }

    #[test]
    fn an_index_is_any_u32_but_the_largest() {
        for i in [0u32, 1, 7, u32::MAX - 1] {
            assert_eq!(Idx::<u8>::from_raw(i).raw(), i);
            assert_eq!(NonMaxU32::new(i).map(NonMaxU32::get), Some(i));
        }
        assert_eq!(NonMaxU32::new(u32::MAX), None);
        assert!(std::panic::catch_unwind(|| Idx::<u8>::from_raw(u32::MAX)).is_err());
        assert!(Idx::<u8>::new(3) < Idx::new(4));
        let v: Vec<char> = "ab".chars().collect();
        assert_eq!(v[Idx::new(1)], 'b');
    }

    /// A quarter (at least the minimum), else the hint when more, capped by `at_most`,
    /// never below what is needed; nothing while there is room.
    #[test]
    fn tables_grow_by_a_quarter_or_the_hint() {
        let q = Growth::quarter(16);
        assert_eq!(q.amount(0, 1), 16);
        assert_eq!(q.amount(400, 1), 100);
        assert_eq!(q.amount(400, 300), 300);
        assert_eq!(q.hint(250).amount(400, 1), 250);
        assert_eq!(q.hint(50).amount(400, 1), 100);
        assert_eq!(q.at_most(64).amount(400, 1), 64);
        assert_eq!(q.at_most(64).amount(400, 80), 80);
        let mut v: Vec<u8> = vec![0; 20];
        assert_eq!(v.capacity(), 20);
        grow_exact(&mut v, 1, q);
        assert_eq!(v.capacity(), 36);
        grow_exact(&mut v, 16, q);
        assert_eq!(v.capacity(), 36, "room enough");
        let mut s = String::new();
        grow_exact(&mut s, 5, Growth::quarter(4096));
        assert_eq!(s.capacity(), 4096);
    }

    #[test]
    fn numbers_round_trip_exactly() {
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
        ];
        for v in values {
            let n = Num::of(&v).expect("a number");
            assert_eq!(n.to_value(), v);
            assert_eq!(PackedValue::num(n).get(), Some(n));
            assert_eq!(n.vt(), v.var_type());
        }
        assert_eq!(Num::of(&Value::Bstr("x".into())), None);
        let array = Value::Array(ArrayValue::new(VarType::I4, vec![Value::I4(1)]));
        assert_eq!(Num::of(&array), None);
    }

    /// A row is marked shared exactly while the map holds its value.
    #[test]
    fn shared_values_are_aside_while_the_row_is_marked() {
        let mut side: SideMap<u32, Value> = SideMap::default();
        let (mut a, mut b) = (PackedValue::EMPTY, PackedValue::EMPTY);
        side.put(&mut a, 1, Value::Bstr("x".into()));
        side.put(&mut b, 2, Value::R8(2.5));
        assert!(a.is_shared() && !b.is_shared());
        assert_eq!(side.len(), 1);
        assert!(matches!(side.get(a, 1), Cow::Borrowed(Value::Bstr(s)) if s == "x"));
        assert_eq!(side.get(b, 2).into_owned(), Value::R8(2.5));
        assert_eq!(side.shared(b, 2), None);
        side.put(&mut a, 1, Value::I4(3));
        assert!(side.is_empty());
        side.put(&mut a, 1, Value::Bstr("y".into()));
        assert_eq!(side.take(&mut a, 1), Value::Bstr("y".into()));
        assert!(side.is_empty() && a == PackedValue::EMPTY);
        side.put(&mut b, 2, Value::Bstr("z".into()));
        side.forget(&mut b, 2);
        assert!(side.is_empty() && b == PackedValue::EMPTY);
    }
}
