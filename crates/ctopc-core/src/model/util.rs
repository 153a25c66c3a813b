//! Small helpers: a map for integer handles ([`IntHasher`]) and a string interner.

use std::collections::HashMap;
use std::hash::BuildHasherDefault;
use std::sync::Arc;

use crate::compact::IntHasher;

pub(crate) type IntMap<K, V> = HashMap<K, V, BuildHasherDefault<IntHasher>>;

/// Interned strings (access paths, channels): few distinct values, never freed.
#[derive(Default)]
pub(crate) struct Interner {
    strings: Vec<Arc<str>>,
    ids: HashMap<Arc<str>, u32>,
}

impl Interner {
    pub fn intern(&mut self, s: &str) -> u32 {
        if let Some(&id) = self.ids.get(s) {
            return id;
        }
        let id = self.strings.len() as u32;
        let a: Arc<str> = Arc::from(s);
        self.strings.push(a.clone());
        self.ids.insert(a, id);
        id
    }
    pub fn get(&self, id: u32) -> &Arc<str> {
        &self.strings[id as usize]
    }
}
