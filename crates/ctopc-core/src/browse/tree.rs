//! The address space: an immutable tree of branches and leaves, built once (from the asix
//! variable set, or from dotted paths in tests) and shared by every session through an `Arc`.
//!
//! Layout (lean for ~100 000 nodes): one `Vec` of fixed-size nodes in breadth-first order, so
//! the children of a node are contiguous; all names and item IDs in one string arena
//! (identical strings stored once); two `u32` permutations for lookups — children sorted by
//! name (binary search for `OPC_BROWSE_DOWN` / `GetItemID`) and all nodes sorted by item ID
//! (binary search for `OPC_BROWSE_TO` and `IOPCBrowse::Browse`). About 40 bytes per node plus
//! the text.

use hashbrown::HashTable;
use thiserror::Error;

use super::pattern::MatchCase;

/// Index of a node. [`NodeId::ROOT`] is the root in a builder and in the built space; other
/// ids are only meaningful for the builder or space that returned them (building renumbers).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeId(u32);

impl NodeId {
    pub const ROOT: NodeId = NodeId(0);

    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

/// Why a node could not be added.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum BuildError {
    #[error("node names must not be empty")]
    EmptyName,
    #[error("item IDs must not be empty (the empty ID is the root)")]
    EmptyItemId,
    #[error("no node {0:?} in this builder")]
    UnknownParent(NodeId),
    #[error("node '{name}' already exists with item ID '{existing}', not '{requested}'")]
    ConflictingItemId {
        name: String,
        existing: String,
        requested: String,
    },
    #[error("the root cannot be an item")]
    RootIsNotAnItem,
    #[error("address space too large (more than 4 GiB of text or 2^32 nodes)")]
    TooLarge,
}

const BRANCH: u8 = 1;
const ITEM: u8 = 2;
/// The node's item ID is not its name: it is in [`AddressSpace::item_ids`] (a leaf's item ID
/// is mostly its name, so a node holds no span for it).
const OWN_ITEM_ID: u8 = 4;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Span {
    start: u32,
    len: u32,
}

#[derive(Debug, Clone)]
struct Node {
    name: Span,
    parent: u32,
    first_child: u32,
    child_count: u32,
    flags: u8,
}

#[derive(Debug, Clone)]
struct BuilderNode {
    /// In the builder's text.
    name: Span,
    /// `None`: the item ID is the name (a variable's leaf, mostly).
    item_id: Option<Span>,
    parent: u32,
    children: Vec<u32>,
    flags: u8,
}

impl BuilderNode {
    fn name<'t>(&self, text: &'t str) -> &'t str {
        span_str(text, self.name)
    }

    fn item_id<'t>(&self, text: &'t str) -> &'t str {
        span_str(text, self.item_id.unwrap_or(self.name))
    }
}

fn span_str(text: &str, span: Span) -> &str {
    &text[span.start as usize..(span.start + span.len) as usize]
}

/// Builds an [`AddressSpace`]. Adding an existing name under the same parent is idempotent
/// (same item ID required) and merges kinds: a leaf that gets children becomes a branch that
/// is also an item, as does a branch added again as a leaf.
#[derive(Debug, Clone)]
pub struct AddressSpaceBuilder {
    nodes: Vec<BuilderNode>,
    /// The names and item IDs of the nodes, back to back (no allocation per node).
    text: String,
    /// Every node by (parent, name): indexes into `nodes`, compared through the nodes.
    by_parent_name: HashTable<u32>,
    text_len: usize,
    flat: bool,
    filter_case: MatchCase,
}

impl Default for AddressSpaceBuilder {
    fn default() -> Self {
        Self::new()
    }
}

impl AddressSpaceBuilder {
    pub fn new() -> Self {
        AddressSpaceBuilder {
            nodes: vec![BuilderNode {
                name: Span { start: 0, len: 0 },
                item_id: None,
                parent: 0,
                children: Vec::new(),
                flags: BRANCH,
            }],
            text: String::new(),
            by_parent_name: HashTable::new(),
            text_len: 0,
            flat: false,
            filter_case: MatchCase::default(),
        }
    }

    /// Makes room for `additional` more nodes (a builder that knows its size skips the
    /// tables' regrowth).
    pub fn reserve(&mut self, additional: usize) -> &mut Self {
        self.nodes.reserve(additional);
        let (nodes, text) = (&self.nodes, &self.text);
        self.by_parent_name.reserve(additional, |&i| {
            let n = &nodes[i as usize];
            hash_child(n.parent, n.name(text))
        });
        self
    }

    /// Presents the space as flat (`OPC_NS_FLAT`): every item listed with its item ID under
    /// the root, no browse positions. Default: hierarchical, as the asix server.
    pub fn flat(&mut self, flat: bool) -> &mut Self {
        self.flat = flat;
        self
    }

    /// Case rule of the browse name filters. Default: [`MatchCase::Insensitive`].
    pub fn filter_case(&mut self, case: MatchCase) -> &mut Self {
        self.filter_case = case;
        self
    }

    /// Number of nodes so far, the root included.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Always false: the root is always there.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Adds (or finds) the branch `name` under `parent` (a group of variables).
    pub fn add_branch(
        &mut self,
        parent: NodeId,
        name: &str,
        item_id: &str,
    ) -> Result<NodeId, BuildError> {
        self.add(parent, name, item_id, BRANCH)
    }

    /// Adds (or finds) the leaf `name` under `parent`; a leaf is always an item (a variable).
    pub fn add_leaf(
        &mut self,
        parent: NodeId,
        name: &str,
        item_id: &str,
    ) -> Result<NodeId, BuildError> {
        self.add(parent, name, item_id, ITEM)
    }

    /// Marks a branch as also being an item (OPC_BROWSE_ISITEM with children), or not.
    /// Leaves are always items; clearing the flag of a leaf is ignored.
    pub fn set_is_item(&mut self, node: NodeId, is_item: bool) -> Result<(), BuildError> {
        if node == NodeId::ROOT {
            return if is_item {
                Err(BuildError::RootIsNotAnItem)
            } else {
                Ok(())
            };
        }
        let n = self
            .nodes
            .get_mut(node.index())
            .ok_or(BuildError::UnknownParent(node))?;
        if is_item {
            n.flags |= ITEM;
        } else if n.flags & BRANCH != 0 {
            n.flags &= !ITEM;
        }
        Ok(())
    }

    /// Adds `path` split at `separator`: every prefix becomes a branch whose item ID is that
    /// prefix, the last segment a leaf whose item ID is the whole path. Empty segments are
    /// an error.
    pub fn add_path(&mut self, path: &str, separator: char) -> Result<NodeId, BuildError> {
        let mut parent = NodeId::ROOT;
        let mut end = 0;
        let mut segments = path.split(separator).peekable();
        while let Some(seg) = segments.next() {
            end += seg.len();
            let id = &path[..end];
            parent = if segments.peek().is_some() {
                self.add_branch(parent, seg, id)?
            } else {
                self.add_leaf(parent, seg, id)?
            };
            end += separator.len_utf8();
        }
        Ok(parent)
    }

    fn add(
        &mut self,
        parent: NodeId,
        name: &str,
        item_id: &str,
        kind: u8,
    ) -> Result<NodeId, BuildError> {
        if name.is_empty() {
            return Err(BuildError::EmptyName);
        }
        if item_id.is_empty() {
            return Err(BuildError::EmptyItemId);
        }
        if parent.index() >= self.nodes.len() {
            return Err(BuildError::UnknownParent(parent));
        }
        let p = parent.0;
        let hash = hash_child(p, name);
        let (nodes, text) = (&self.nodes, &self.text);
        let found = self
            .by_parent_name
            .find(hash, |&i| {
                let n = &nodes[i as usize];
                n.parent == p && n.name(text) == name
            })
            .copied();
        if let Some(existing) = found {
            let n = &mut self.nodes[existing as usize];
            if n.item_id(&self.text) != item_id {
                return Err(BuildError::ConflictingItemId {
                    name: name.to_owned(),
                    existing: n.item_id(&self.text).to_owned(),
                    requested: item_id.to_owned(),
                });
            }
            // Merging kinds: a leaf added again as a branch (or given children) stays an
            // item; a branch added again as a leaf becomes an item too.
            n.flags |= kind;
            return Ok(NodeId(existing));
        }
        let text = name.len() + if item_id == name { 0 } else { item_id.len() };
        if self.nodes.len() >= u32::MAX as usize || self.text_len + text > u32::MAX as usize {
            return Err(BuildError::TooLarge);
        }
        self.text_len += text;
        let id = self.nodes.len() as u32;
        let mut push = |s: &str| {
            let span = Span {
                start: self.text.len() as u32,
                len: s.len() as u32,
            };
            self.text.push_str(s);
            span
        };
        let name_span = push(name);
        let item_span = (item_id != name).then(|| push(item_id));
        self.nodes.push(BuilderNode {
            name: name_span,
            item_id: item_span,
            parent: p,
            children: Vec::new(),
            flags: kind,
        });
        // A leaf that gets a child becomes a branch that is still an item.
        self.nodes[p as usize].flags |= BRANCH;
        self.nodes[p as usize].children.push(id);
        let (nodes, text) = (&self.nodes, &self.text);
        self.by_parent_name.insert_unique(hash, id, |&i| {
            let n = &nodes[i as usize];
            hash_child(n.parent, n.name(text))
        });
        Ok(NodeId(id))
    }

    /// Freezes the tree.
    pub fn build(self) -> AddressSpace {
        let AddressSpaceBuilder {
            nodes: bnodes,
            text: btext,
            by_parent_name,
            flat,
            filter_case,
            ..
        } = self;
        drop(by_parent_name);

        // Breadth-first order: the children of each node become contiguous.
        let mut order: Vec<u32> = Vec::with_capacity(bnodes.len());
        order.push(0);
        let mut new_of_old = vec![0u32; bnodes.len()];
        let mut head = 0;
        while head < order.len() {
            let old = order[head] as usize;
            new_of_old[old] = head as u32;
            order.extend_from_slice(&bnodes[old].children);
            head += 1;
        }

        let mut text = String::new();
        let mut interned: HashTable<Span> = HashTable::with_capacity(bnodes.len());
        let mut nodes: Vec<Node> = Vec::with_capacity(bnodes.len());
        // The item IDs that are not the node's name, by node.
        let mut item_ids: Vec<(u32, Span)> = Vec::new();
        for (new_index, &old) in order.iter().enumerate() {
            let b = &bnodes[old as usize];
            let name = intern_str(b.name(&btext), &mut text, &mut interned);
            // A node whose item ID is its name (most leaves) is interned once.
            let item_id = match b.item_id {
                None => name,
                Some(_) => intern_str(b.item_id(&btext), &mut text, &mut interned),
            };
            let first_child = b.children.first().map_or(0, |&c| new_of_old[c as usize]);
            debug_assert!(b
                .children
                .iter()
                .enumerate()
                .all(|(k, &c)| new_of_old[c as usize] == first_child + k as u32));
            let mut flags = if new_index == 0 { BRANCH } else { b.flags };
            if item_id != name {
                flags |= OWN_ITEM_ID;
                item_ids.push((new_index as u32, item_id));
            }
            nodes.push(Node {
                name,
                parent: new_of_old[b.parent as usize],
                first_child,
                child_count: b.children.len() as u32,
                flags,
            });
        }
        drop(interned);
        text.shrink_to_fit();
        item_ids.shrink_to_fit();

        let mut space = AddressSpace {
            text,
            nodes,
            item_ids,
            children_by_name: Vec::new(),
            by_item_id: Vec::new(),
            flat_items: Vec::new(),
            flat,
            filter_case,
            fingerprint: 0,
        };

        // Children sorted by name, slice by slice (root slot 0 unused).
        let mut children_by_name: Vec<u32> = (0..space.nodes.len() as u32).collect();
        for n in &space.nodes {
            let range = n.first_child as usize..(n.first_child + n.child_count) as usize;
            if n.child_count > 1 {
                children_by_name[range].sort_by(|&a, &b| space.name_of(a).cmp(space.name_of(b)));
            }
        }
        space.children_by_name = children_by_name;

        let mut by_item_id: Vec<u32> = (1..space.nodes.len() as u32).collect();
        by_item_id.sort_by(|&a, &b| space.item_id_of(a).cmp(space.item_id_of(b)).then(a.cmp(&b)));
        space.by_item_id = by_item_id;

        if flat {
            space.flat_items = space.items_below(0);
        }
        space.fingerprint = space.compute_fingerprint();
        space
    }
}

fn intern_str(s: &str, text: &mut String, interned: &mut HashTable<Span>) -> Span {
    let of = |text: &String, span: &Span| -> u64 {
        hash_str(
            0,
            &text[span.start as usize..(span.start + span.len) as usize],
        )
    };
    let hash = hash_str(0, s);
    if let Some(&span) = interned.find(hash, |sp| {
        &text[sp.start as usize..(sp.start + sp.len) as usize] == s
    }) {
        return span;
    }
    let span = Span {
        start: text.len() as u32,
        len: s.len() as u32,
    };
    text.push_str(s);
    interned.insert_unique(hash, span, |sp| of(text, sp));
    span
}

/// A fast string hash for the builder's tables (names come from the configuration, so
/// no protection against chosen collisions is needed): 8 bytes a step, multiply-rotate,
/// folded so that hashbrown's bucket (low bits) and tag (top bits) both vary.
pub(crate) fn hash_str(seed: u64, s: &str) -> u64 {
    const K: u64 = 0x9E37_79B9_7F4A_7C15;
    let bytes = s.as_bytes();
    let mut h = seed.wrapping_mul(K);
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

fn hash_child(parent: u32, name: &str) -> u64 {
    hash_str(u64::from(parent) + 1, name)
}

/// The browsable address space. Immutable; share it as `Arc<AddressSpace>`.
#[derive(Clone)]
pub struct AddressSpace {
    text: String,
    nodes: Vec<Node>,
    /// The item IDs of the nodes whose item ID is not their name ([`OWN_ITEM_ID`]), by
    /// node.
    item_ids: Vec<(u32, Span)>,
    children_by_name: Vec<u32>,
    by_item_id: Vec<u32>,
    /// In a flat space: the items in pre-order, one per item ID.
    flat_items: Vec<u32>,
    flat: bool,
    filter_case: MatchCase,
    fingerprint: u64,
}

impl std::fmt::Debug for AddressSpace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AddressSpace")
            .field("nodes", &self.nodes.len())
            .field("text_bytes", &self.text.len())
            .field("flat", &self.flat)
            .field("filter_case", &self.filter_case)
            .field("fingerprint", &format_args!("{:016x}", self.fingerprint))
            .finish()
    }
}

impl Default for AddressSpace {
    fn default() -> Self {
        AddressSpaceBuilder::new().build()
    }
}

impl AddressSpace {
    pub fn builder() -> AddressSpaceBuilder {
        AddressSpaceBuilder::new()
    }

    /// A space with only the root (no variable database loaded).
    pub fn empty() -> AddressSpace {
        AddressSpace::default()
    }

    /// A hierarchical space from dotted paths (`"a.b.c"` with `separator = '.'`): see
    /// [`AddressSpaceBuilder::add_path`].
    pub fn from_paths<I, S>(paths: I, separator: char) -> Result<AddressSpace, BuildError>
    where
        I: IntoIterator<Item = S>,
        S: AsRef<str>,
    {
        let mut b = AddressSpaceBuilder::new();
        for p in paths {
            b.add_path(p.as_ref(), separator)?;
        }
        Ok(b.build())
    }

    /// Number of nodes, the root included.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// True when there is nothing but the root.
    pub fn is_empty(&self) -> bool {
        self.nodes.len() == 1
    }

    pub fn is_flat(&self) -> bool {
        self.flat
    }

    /// Case rule of the browse name filters.
    pub fn filter_case(&self) -> MatchCase {
        self.filter_case
    }

    /// A digest of the whole content; equal spaces have equal fingerprints. Continuation
    /// points carry it, so they stay valid across sessions and rebuilds of the same content.
    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    pub fn root(&self) -> NodeRef<'_> {
        NodeRef { space: self, id: 0 }
    }

    pub fn node(&self, id: NodeId) -> Option<NodeRef<'_>> {
        (id.index() < self.nodes.len()).then_some(NodeRef {
            space: self,
            id: id.0,
        })
    }

    /// The first node (breadth-first) with this item ID; `""` is the root. Nodes sharing an
    /// item ID (a variable in several groups) are expected to be equivalent.
    pub fn find_item_id(&self, item_id: &str) -> Option<NodeRef<'_>> {
        if item_id.is_empty() {
            return Some(self.root());
        }
        self.nodes_with_item_id(item_id).next()
    }

    /// Every node with this item ID, breadth-first.
    pub fn nodes_with_item_id<'a>(
        &'a self,
        item_id: &str,
    ) -> impl Iterator<Item = NodeRef<'a>> + 'a {
        let start = self
            .by_item_id
            .partition_point(|&n| self.item_id_of(n) < item_id);
        let end =
            start + self.by_item_id[start..].partition_point(|&n| self.item_id_of(n) == item_id);
        self.by_item_id[start..end]
            .iter()
            .map(move |&id| NodeRef { space: self, id })
    }

    /// In a flat space: all items, one per item ID, in pre-order. Empty when hierarchical.
    pub(crate) fn flat_items(&self) -> &[u32] {
        &self.flat_items
    }

    pub(crate) fn node_ref(&self, id: u32) -> NodeRef<'_> {
        NodeRef { space: self, id }
    }

    fn str_of(&self, span: Span) -> &str {
        &self.text[span.start as usize..(span.start + span.len) as usize]
    }

    fn name_of(&self, id: u32) -> &str {
        self.str_of(self.nodes[id as usize].name)
    }

    fn item_id_of(&self, id: u32) -> &str {
        let node = &self.nodes[id as usize];
        if node.flags & OWN_ITEM_ID == 0 {
            return self.str_of(node.name);
        }
        match self.item_ids.binary_search_by_key(&id, |&(n, _)| n) {
            Ok(k) => self.str_of(self.item_ids[k].1),
            Err(_) => self.str_of(node.name),
        }
    }

    /// Items at and below `id` (excluding `id` itself), pre-order, first occurrence of each
    /// item ID only.
    pub(crate) fn items_below(&self, id: u32) -> Vec<u32> {
        let mut seen: std::collections::HashSet<&str> = std::collections::HashSet::new();
        let mut out = Vec::new();
        let mut stack: Vec<u32> = Vec::new();
        let n = &self.nodes[id as usize];
        stack.extend((n.first_child..n.first_child + n.child_count).rev());
        while let Some(c) = stack.pop() {
            let node = &self.nodes[c as usize];
            if node.flags & ITEM != 0 && seen.insert(self.item_id_of(c)) {
                out.push(c);
            }
            stack.extend((node.first_child..node.first_child + node.child_count).rev());
        }
        out
    }

    /// Whether `ancestor` is `id` or above it.
    pub(crate) fn is_at_or_below(&self, id: u32, ancestor: u32) -> bool {
        let mut cur = id;
        loop {
            if cur == ancestor {
                return true;
            }
            if cur == 0 {
                return false;
            }
            cur = self.nodes[cur as usize].parent;
        }
    }

    fn compute_fingerprint(&self) -> u64 {
        // FNV-1a, 64 bit: deterministic across processes (no random hasher keys).
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |bytes: &[u8]| {
            for &b in bytes {
                h ^= b as u64;
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        };
        eat(&[self.flat as u8, self.filter_case as u8]);
        for (i, n) in self.nodes.iter().enumerate() {
            eat(self.name_of(i as u32).as_bytes());
            eat(&[0xFF]);
            eat(self.item_id_of(i as u32).as_bytes());
            eat(&[0xFE, n.flags & (BRANCH | ITEM)]);
            eat(&n.child_count.to_le_bytes());
            eat(&n.parent.to_le_bytes());
        }
        h
    }
}

/// A borrowed view of one node.
#[derive(Clone, Copy)]
pub struct NodeRef<'a> {
    space: &'a AddressSpace,
    id: u32,
}

impl std::fmt::Debug for NodeRef<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeRef")
            .field("id", &self.id)
            .field("name", &self.name())
            .field("item_id", &self.item_id())
            .field("branch", &self.is_branch())
            .field("item", &self.is_item())
            .finish()
    }
}

impl PartialEq for NodeRef<'_> {
    fn eq(&self, other: &Self) -> bool {
        std::ptr::eq(self.space, other.space) && self.id == other.id
    }
}

impl Eq for NodeRef<'_> {}

impl<'a> NodeRef<'a> {
    fn node(&self) -> &'a Node {
        &self.space.nodes[self.id as usize]
    }

    pub fn id(&self) -> NodeId {
        NodeId(self.id)
    }

    pub(crate) fn raw(&self) -> u32 {
        self.id
    }

    /// The display name (a short name, unique among its siblings); `""` for the root.
    pub fn name(&self) -> &'a str {
        self.space.str_of(self.node().name)
    }

    /// The fully qualified item ID (for asix: the bare variable name); `""` for the root.
    pub fn item_id(&self) -> &'a str {
        self.space.item_id_of(self.id)
    }

    pub fn is_root(&self) -> bool {
        self.id == 0
    }

    /// A branch (a group, or a variable whose attributes are browsed as leaves); an empty
    /// group is still a branch.
    pub fn is_branch(&self) -> bool {
        self.node().flags & BRANCH != 0
    }

    /// A leaf: not a branch.
    pub fn is_leaf(&self) -> bool {
        !self.is_branch()
    }

    /// Usable as an item (AddItems, Read, ...): every leaf, and branches marked as items.
    pub fn is_item(&self) -> bool {
        self.node().flags & ITEM != 0
    }

    pub fn child_count(&self) -> usize {
        self.node().child_count as usize
    }

    pub fn parent(&self) -> Option<NodeRef<'a>> {
        (!self.is_root()).then(|| NodeRef {
            space: self.space,
            id: self.node().parent,
        })
    }

    /// The children in the order they were added.
    pub fn children(&self) -> impl ExactSizeIterator<Item = NodeRef<'a>> + 'a {
        let n = self.node();
        let space = self.space;
        (n.first_child..n.first_child + n.child_count).map(move |id| NodeRef { space, id })
    }

    /// The child with this exact (case-sensitive) name.
    pub fn child(&self, name: &str) -> Option<NodeRef<'a>> {
        let n = self.node();
        if n.child_count == 0 {
            return None;
        }
        let sorted = &self.space.children_by_name
            [n.first_child as usize..(n.first_child + n.child_count) as usize];
        sorted
            .binary_search_by(|&c| self.space.name_of(c).cmp(name))
            .ok()
            .map(|k| NodeRef {
                space: self.space,
                id: sorted[k],
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A node is 24 bytes (a large plant has a million leaves): its item ID is its name unless it
    /// has one of its own, kept aside.
    #[test]
    fn nodes_stay_compact_and_own_item_ids_are_kept_aside() {
        assert!(std::mem::size_of::<Node>() <= 24);
        let mut b = AddressSpace::builder();
        let g = b.add_branch(NodeId::ROOT, "G", "group/G").unwrap();
        b.add_leaf(g, "x", "x").unwrap();
        b.add_leaf(g, "y", "G.y").unwrap();
        let space = b.build();
        assert_eq!(space.item_ids.len(), 2, "G and y");
        let ids: Vec<&str> = (1..space.nodes.len() as u32)
            .map(|i| space.node_ref(i).item_id())
            .collect();
        assert_eq!(ids, vec!["group/G", "x", "G.y"]);
    }

    fn sample() -> AddressSpace {
        AddressSpace::from_paths(
            [
                "Plant.Boiler.T1",
                "Plant.Boiler.P1",
                "Plant.Pump",
                "Plant.Pump.Speed",
                "Top",
            ],
            '.',
        )
        .unwrap()
    }

    #[test]
    fn from_paths_builds_branches_leaves_and_item_branches() {
        let s = sample();
        let root = s.root();
        assert!(root.is_root() && root.is_branch() && !root.is_item());
        assert_eq!(root.item_id(), "");
        let names: Vec<_> = root.children().map(|c| c.name()).collect();
        assert_eq!(names, ["Plant", "Top"]);
        let plant = root.child("Plant").unwrap();
        assert!(plant.is_branch() && !plant.is_item());
        assert_eq!(plant.item_id(), "Plant");
        let pump = plant.child("Pump").unwrap();
        assert!(
            pump.is_branch() && pump.is_item(),
            "a path that is a prefix of another is both"
        );
        assert_eq!(pump.item_id(), "Plant.Pump");
        let t1 = plant.child("Boiler").unwrap().child("T1").unwrap();
        assert!(t1.is_leaf() && t1.is_item());
        assert_eq!(t1.item_id(), "Plant.Boiler.T1");
        assert_eq!(t1.parent().unwrap().parent().unwrap(), plant);
        assert_eq!(s.len(), 8);
    }

    #[test]
    fn children_keep_insertion_order_and_lookup_is_exact() {
        let s = AddressSpace::from_paths(["z", "a", "m", "B"], '.').unwrap();
        let names: Vec<_> = s.root().children().map(|c| c.name()).collect();
        assert_eq!(names, ["z", "a", "m", "B"]);
        for n in ["z", "a", "m", "B"] {
            assert_eq!(s.root().child(n).unwrap().name(), n);
        }
        assert!(s.root().child("b").is_none(), "names are case-sensitive");
        assert!(s.root().child("").is_none());
    }

    #[test]
    fn find_item_id_finds_every_node_and_the_root() {
        let s = sample();
        assert!(s.find_item_id("").unwrap().is_root());
        for id in [
            "Plant",
            "Plant.Boiler",
            "Plant.Boiler.T1",
            "Plant.Pump",
            "Plant.Pump.Speed",
            "Top",
        ] {
            assert_eq!(s.find_item_id(id).unwrap().item_id(), id);
        }
        assert!(s.find_item_id("Plant.Nope").is_none());
        assert!(s.find_item_id("plant").is_none());
    }

    #[test]
    fn builder_bare_item_ids_may_repeat_across_groups() {
        // asix: GetItemID returns the bare variable name; a variable may sit in two groups.
        let mut b = AddressSpace::builder();
        let g1 = b
            .add_branch(NodeId::ROOT, "Boilers", "group:Boilers")
            .unwrap();
        let g2 = b
            .add_branch(NodeId::ROOT, "Alarms", "group:Alarms")
            .unwrap();
        b.add_leaf(g1, "T1", "T1").unwrap();
        b.add_leaf(g2, "T1", "T1").unwrap();
        let s = b.build();
        assert_eq!(s.nodes_with_item_id("T1").count(), 2);
        assert_eq!(
            s.find_item_id("T1").unwrap().parent().unwrap().name(),
            "Boilers"
        );
        // identical strings are stored once
        assert!(s.text.len() <= "BoilersAlarmsgroup:Boilersgroup:AlarmsT1".len());
    }

    #[test]
    fn builder_rejects_conflicts_and_empty_names() {
        let mut b = AddressSpace::builder();
        assert_eq!(
            b.add_leaf(NodeId::ROOT, "", "x"),
            Err(BuildError::EmptyName)
        );
        assert_eq!(
            b.add_leaf(NodeId::ROOT, "x", ""),
            Err(BuildError::EmptyItemId)
        );
        assert_eq!(
            b.add_leaf(NodeId(7), "x", "x"),
            Err(BuildError::UnknownParent(NodeId(7)))
        );
        let x = b.add_leaf(NodeId::ROOT, "x", "X1").unwrap();
        assert_eq!(b.add_leaf(NodeId::ROOT, "x", "X1"), Ok(x), "idempotent");
        assert!(matches!(
            b.add_leaf(NodeId::ROOT, "x", "X2"),
            Err(BuildError::ConflictingItemId { .. })
        ));
        assert_eq!(
            b.set_is_item(NodeId::ROOT, true),
            Err(BuildError::RootIsNotAnItem)
        );
        assert!(b.add_path("a..b", '.').is_err());
    }

    #[test]
    fn branch_item_flag_can_be_set_and_cleared() {
        let mut b = AddressSpace::builder();
        let v = b.add_branch(NodeId::ROOT, "V1", "V1").unwrap();
        b.add_leaf(v, "DESC", "V1.DESC").unwrap();
        b.set_is_item(v, true).unwrap();
        let leaf = b.add_leaf(NodeId::ROOT, "L", "L").unwrap();
        b.set_is_item(leaf, false).unwrap();
        let s = b.build();
        assert!(s.find_item_id("V1").unwrap().is_item());
        assert!(
            s.find_item_id("L").unwrap().is_item(),
            "leaves are always items"
        );
        let mut b = AddressSpace::builder();
        let v = b.add_branch(NodeId::ROOT, "V1", "V1").unwrap();
        b.set_is_item(v, true).unwrap();
        b.set_is_item(v, false).unwrap();
        assert!(!b.build().find_item_id("V1").unwrap().is_item());
    }

    #[test]
    fn empty_space_has_only_the_root() {
        let s = AddressSpace::empty();
        assert!(s.is_empty());
        assert_eq!(s.root().child_count(), 0);
        assert!(s.find_item_id("x").is_none());
    }

    #[test]
    fn fingerprint_depends_on_content_only() {
        let a = sample();
        let b = sample();
        assert_eq!(a.fingerprint(), b.fingerprint());
        let c = AddressSpace::from_paths(["Plant.Boiler.T1"], '.').unwrap();
        assert_ne!(a.fingerprint(), c.fingerprint());
    }

    #[test]
    fn hundred_thousand_nodes_build_and_stay_lean() {
        let mut b = AddressSpace::builder();
        for g in 0..100 {
            let group = b
                .add_branch(NodeId::ROOT, &format!("G{g:03}"), &format!("G{g:03}"))
                .unwrap();
            for v in 0..1000 {
                let name = format!("V{g:03}_{v:04}");
                b.add_leaf(group, &name, &name).unwrap();
            }
        }
        let s = b.build();
        assert_eq!(s.len(), 100_101);
        let per_node = std::mem::size_of::<Node>() + 2 * std::mem::size_of::<u32>();
        assert!(per_node <= 40, "{per_node} bytes per node");
        // name == item ID is stored once
        assert!(s.text.len() < 100_101 * 10);
        assert_eq!(
            s.find_item_id("V042_0999")
                .unwrap()
                .parent()
                .unwrap()
                .name(),
            "G042"
        );
        assert_eq!(
            s.root()
                .child("G099")
                .unwrap()
                .child("V099_0500")
                .unwrap()
                .item_id(),
            "V099_0500"
        );
    }
}
