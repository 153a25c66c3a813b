//! The vocabulary of the compact tables: the engine's item cache (`model/cache.rs`), its
//! group items (`model/item.rs`) and the asix backend's variables (`asix_net::backend`).
//! These tables are most of the memory of a large configuration, so their rows are small
//! and fixed by size tests beside them; this module gives them one way to say each thing
//! a small row needs:
//!
//! - [`Idx`]: an index into a table of one type, in 4 bytes with a niche, so that
//!   `Option<Idx<T>>` is 4 bytes too and says "none" without a sentinel value
//!   (rust-analyzer's `la-arena` `Idx`, over a non-max `u32`);
//! - [`grow_exact`]: a table grows by a quarter, not double, or by what a large call says
//!   it needs.

use std::fmt;
use std::hash::{Hash, Hasher};
use std::marker::PhantomData;
use std::num::NonZeroU32;
use std::ops::{Index, IndexMut};

/// A `u32` that is never `u32::MAX`, held as the `NonZeroU32` of its complement, so that
/// `Option<NonMaxU32>` is 4 bytes.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct NonMaxU32(NonZeroU32);

impl NonMaxU32 {
    /// `v`, unless it is `u32::MAX`.
    pub const fn new(v: u32) -> Option<Self> {
        match NonZeroU32::new(!v) {
            Some(n) => Some(NonMaxU32(n)),
            None => None,
        }
    }

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
    pub fn new(i: usize) -> Self {
        let raw = u32::try_from(i).ok().and_then(NonMaxU32::new);
        Idx {
            raw: raw.expect("a compact table's index fits a u32 below u32::MAX"),
            _table: PhantomData,
        }
    }

    /// The index `raw` as [`Idx::raw`] gave it (panics at `u32::MAX`).
    pub fn from_raw(raw: u32) -> Self {
        Self::new(raw as usize)
    }

    /// The index as a `u32` (below `u32::MAX`).
    pub const fn raw(self) -> u32 {
        self.raw.get()
    }

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
    fn index(&self, i: Idx<T>) -> &T {
        &self[i.index()]
    }
}
impl<T> IndexMut<Idx<T>> for Vec<T> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indices_have_a_niche() {
        assert_eq!(std::mem::size_of::<Idx<String>>(), 4);
        assert_eq!(std::mem::size_of::<Option<Idx<String>>>(), 4);
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
}
