//! [`NameIndex`]: the name-to-variable index, comparing names in the [`CellTable`].

use std::fmt;

use hashbrown::HashTable;

use super::cells::CellTable;

/// An index from a name to the variable holding it in one column: a
/// `hashbrown::HashTable<u32>` of variable indexes (4 bytes and a control byte a bucket);
/// the names are compared in the [`CellTable`], so none is stored twice.
#[derive(Clone, Default)]
pub(super) struct NameIndex {
    col: usize,
    table: HashTable<u32>,
}

/// A fast string hash (names come from the configuration, so no protection against
/// chosen collisions is needed): 8 bytes a step, multiply-rotate, folded so that
/// hashbrown's bucket (low bits) and tag (top bits) both vary.
pub fn hash_name(name: &str) -> u64 {
    const K: u64 = 0x9E37_79B9_7F4A_7C15;
    let bytes = name.as_bytes();
    let mut h = 0u64;
    let mut chunks = bytes.chunks_exact(8);
    for c in &mut chunks {
        let mut w = [0u8; 8];
        w.copy_from_slice(c);
        h = (h.rotate_left(5) ^ u64::from_le_bytes(w)).wrapping_mul(K);
    }
    let mut tail = 0u64;
    for (i, &b) in chunks.remainder().iter().enumerate() {
        tail |= u64::from(b) << (8 * i);
    }
    h = (h.rotate_left(5) ^ tail ^ (bytes.len() as u64) << 56).wrapping_mul(K);
    h ^ (h >> 32)
}

impl NameIndex {
    pub(super) fn new(col: usize, capacity: usize) -> Self {
        NameIndex {
            col,
            table: HashTable::with_capacity(capacity),
        }
    }

    pub(super) fn find(&self, cells: &CellTable, name: &str) -> Option<usize> {
        self.table
            .find(hash_name(name), |&i| {
                cells.cell(i as usize, self.col) == name
            })
            .map(|&i| i as usize)
    }

    /// Adds row `i` unless its name is already there; returns the row holding the name.
    pub(super) fn insert(&mut self, cells: &CellTable, i: usize) -> usize {
        let name = cells.cell(i, self.col);
        let col = self.col;
        match self.table.entry(
            hash_name(name),
            |&j| cells.cell(j as usize, col) == name,
            |&j| hash_name(cells.cell(j as usize, col)),
        ) {
            hashbrown::hash_table::Entry::Occupied(e) => *e.get() as usize,
            hashbrown::hash_table::Entry::Vacant(e) => {
                e.insert(i as u32);
                i
            }
        }
    }

    pub(super) fn len(&self) -> usize {
        self.table.len()
    }
}

impl fmt::Debug for NameIndex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "NameIndex(column {}, {} names)",
            self.col,
            self.table.len()
        )
    }
}

/// The index is a function of the table, so two indexes of equal tables are equal.
impl PartialEq for NameIndex {
    fn eq(&self, other: &Self) -> bool {
        (self.col, self.table.len()) == (other.col, other.table.len())
    }
}
