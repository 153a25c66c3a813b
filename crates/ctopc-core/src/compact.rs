//! The vocabulary of the compact tables: the engine's item cache (`model/cache.rs`), its
//! group items (`model/item.rs`) and the asix backend's variables (`asix_net::backend`).
//! These tables are most of the memory of a large configuration, so their rows are small
//! and fixed by size tests beside them; this module gives them one way to say each thing
//! a small row needs:
//!
//! - [`grow_exact`]: a table grows by a quarter, not double, or by what a large call says
//!   it needs.

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
