//! Items in groups: IOPCItemMgt, IOPCItemDeadbandMgt, IOPCItemSamplingMgt (its buffering
//! half is `model/buffer.rs`).

use std::borrow::Cow;
use std::collections::HashMap;
use std::sync::Arc;

use super::cache::CachedValue;
use super::deadband::valid_percent;
use super::engine::{Engine, GroupHandle, SessionHandle};
use super::util::IntMap;
use super::Revised;
use crate::compact::{PackedValue, SideMap};
use crate::namespace::{EuInfo, ItemDef};
use crate::{OpcError, Quality, Timestamp, VarType};

/// OPCITEMDEF (the blob is not used by this server).
#[derive(Debug, Clone, PartialEq)]
pub struct ItemDefinition<'a> {
    pub item_id: &'a str,
    /// The asix channel; empty for the basic channel `*`.
    pub access_path: &'a str,
    pub active: bool,
    pub client_handle: u32,
    /// VT_EMPTY: the canonical type.
    pub requested_type: VarType,
}

/// OPCITEMRESULT (no blob).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ItemResult {
    /// 0 from ValidateItems.
    pub server_handle: u32,
    pub canonical_type: VarType,
    pub access_rights: u32,
}

/// OPCITEMATTRIBUTES (IEnumOPCItemAttributes): an item as its group holds it. The values
/// behind its item properties are [`crate::namespace::PropertyAttributes`].
#[derive(Debug, Clone, PartialEq)]
pub struct ItemAttributes {
    pub access_path: String,
    pub item_id: String,
    pub active: bool,
    pub client_handle: u32,
    pub server_handle: u32,
    pub access_rights: u32,
    pub requested_type: VarType,
    pub canonical_type: VarType,
    /// EU type and info (OPC_NOENUM / OPC_ANALOG [low, high] / OPC_ENUMERATED texts).
    pub eu: EuInfo,
}

bitflags::bitflags! {
    /// A [`GroupItem`]'s flags.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    pub(crate) struct ItemFlags: u8 {
        const ACTIVE = 1;
        /// A value was sent to the group since the item (or group, or sink) became active.
        const SENT = 1 << 1;
        /// Counted in the source's subscribers.
        const SUBSCRIBED = 1 << 2;
        /// `name` is an alias-name id (the item ID differs from the source key), else an
        /// access path id.
        const ALIAS = 1 << 3;
        /// The item deadband is set (IOPCItemDeadbandMgt).
        const DEADBAND = 1 << 4;
        /// Removed during the current RemoveItems call (compacted at its end).
        const REMOVED = 1 << 5;
        /// Buffering is enabled (IOPCItemSamplingMgt::SetItemBufferEnable,
        /// `model/buffer.rs`).
        const BUFFERED = 1 << 6;
        /// The item sampling rate is set (IOPCItemSamplingMgt).
        const SAMPLING = 1 << 7;
    }
}

/// A group's values last sent that are strings or arrays, by server handle
/// ([`GroupItem::last`]).
pub(crate) type Lasts = SideMap<u32, CachedValue>;

/// An item in a group: 32 bytes, no strings (the item ID and access path are interned;
/// its sampling rate and deadband, rarely set, are in [`ItemOpts`]; a string or array
/// value last sent is in `Group::lasts`). Checked by `group_items_stay_small` below.
#[derive(Debug, Clone)]
pub(crate) struct GroupItem {
    /// The value last sent to the group ([`GroupItem::last`]): a number, or shared in the
    /// group's [`Lasts`].
    last: PackedValue,
    pub handle: u32,
    pub client: u32,
    /// Cache entry index.
    pub source: u32,
    /// Access path id, or alias name id with [`ItemFlags::ALIAS`].
    pub name: u32,
    pub req_type: VarType,
    pub last_quality: Quality,
    pub flags: ItemFlags,
}

impl GroupItem {
    /// A new item: nothing sent yet.
    pub fn new(handle: u32, client: u32, source: u32, name: u32, req_type: VarType) -> Self {
        GroupItem {
            last: PackedValue::EMPTY,
            handle,
            client,
            source,
            name,
            req_type,
            last_quality: Quality::BAD,
            flags: ItemFlags::empty(),
        }
    }

    pub fn active(&self) -> bool {
        self.flags.contains(ItemFlags::ACTIVE)
    }

    /// The value last sent to the group (meaningful with [`ItemFlags::SENT`]), given the
    /// group's `lasts`.
    pub fn last<'a>(&self, lasts: &'a Lasts) -> Cow<'a, CachedValue> {
        lasts.get(self.last, self.handle)
    }

    /// Records the value and quality sent to the group.
    pub fn set_last(&mut self, lasts: &mut Lasts, v: CachedValue, q: Quality) {
        self.last_quality = q;
        lasts.put(&mut self.last, self.handle, v);
    }

    /// Forgets the value last sent (the item leaves the group, or is copied to another
    /// under a new handle: `lasts` is then the old group's).
    pub fn forget_last(&mut self, lasts: &mut Lasts) {
        lasts.forget(&mut self.last, self.handle);
    }
}

/// The item sampling rate and item deadband of a group's items that have one set
/// (`Group::opts`, by server handle; [`ItemFlags::SAMPLING`] and [`ItemFlags::DEADBAND`]
/// say which is set). Few items have one, so they are kept out of [`GroupItem`].
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub(crate) struct ItemOpts {
    /// In ms, with [`ItemFlags::SAMPLING`].
    pub sampling: u32,
    /// In percent, with [`ItemFlags::DEADBAND`].
    pub deadband: f32,
}

impl ItemOpts {
    /// The item sampling rate of `it`, 0 when not set.
    pub fn sampling(opts: &IntMap<u32, ItemOpts>, it: &GroupItem) -> u32 {
        if !it.flags.contains(ItemFlags::SAMPLING) {
            return 0;
        }
        opts.get(&it.handle).map_or(0, |o| o.sampling)
    }

    /// The item deadband of `it`, if set.
    pub fn deadband(opts: &IntMap<u32, ItemOpts>, it: &GroupItem) -> Option<f32> {
        if !it.flags.contains(ItemFlags::DEADBAND) {
            return None;
        }
        opts.get(&it.handle).map(|o| o.deadband)
    }

    /// Sets (`Some`) or clears the item sampling rate of `it`.
    pub fn set_sampling(opts: &mut IntMap<u32, ItemOpts>, it: &mut GroupItem, rate: Option<u32>) {
        Self::update(opts, it, ItemFlags::SAMPLING, rate.is_some(), |o| {
            o.sampling = rate.unwrap_or(0);
        });
    }

    /// Sets (`Some`) or clears the item deadband of `it`.
    pub fn set_deadband(opts: &mut IntMap<u32, ItemOpts>, it: &mut GroupItem, band: Option<f32>) {
        Self::update(opts, it, ItemFlags::DEADBAND, band.is_some(), |o| {
            o.deadband = band.unwrap_or(0.0);
        });
    }

    fn update(
        opts: &mut IntMap<u32, ItemOpts>,
        it: &mut GroupItem,
        flag: ItemFlags,
        set: bool,
        f: impl FnOnce(&mut ItemOpts),
    ) {
        it.flags.set(flag, set);
        if !it
            .flags
            .intersects(ItemFlags::SAMPLING | ItemFlags::DEADBAND)
        {
            opts.remove(&it.handle);
        } else {
            f(opts.entry(it.handle).or_default());
        }
    }
}

/// Item IDs that differ from the source key they resolve to (aliases, descriptive IDs),
/// interned with reference counts.
#[derive(Default)]
pub(crate) struct NameTable {
    entries: Vec<NameEntry>,
    free: Vec<u32>,
    maps: IntMap<u32, HashMap<Arc<str>, u32>>,
}

struct NameEntry {
    item_id: Arc<str>,
    path: u32,
    refs: u32,
}

impl NameTable {
    pub fn acquire(&mut self, item_id: &str, path: u32) -> u32 {
        let map = self.maps.entry(path).or_default();
        if let Some(&id) = map.get(item_id) {
            self.entries[id as usize].refs += 1;
            return id;
        }
        let s: Arc<str> = Arc::from(item_id);
        let entry = NameEntry {
            item_id: s.clone(),
            path,
            refs: 1,
        };
        let id = match self.free.pop() {
            Some(id) => {
                self.entries[id as usize] = entry;
                id
            }
            None => {
                self.entries.push(entry);
                (self.entries.len() - 1) as u32
            }
        };
        map.insert(s, id);
        id
    }

    pub fn add_ref(&mut self, id: u32) {
        self.entries[id as usize].refs += 1;
    }

    pub fn release(&mut self, id: u32) {
        let e = &mut self.entries[id as usize];
        e.refs -= 1;
        if e.refs == 0 {
            if let Some(map) = self.maps.get_mut(&e.path) {
                map.remove(&*e.item_id);
            }
            e.item_id = Arc::from("");
            self.free.push(id);
        }
    }

    pub fn get(&self, id: u32) -> (&Arc<str>, u32) {
        let e = &self.entries[id as usize];
        (&e.item_id, e.path)
    }
}

/// True when values of the canonical type can be delivered as `requested` (type level:
/// OPC_E_BADTYPE otherwise). Scalars convert to scalars, arrays to arrays; VT_ERROR only to
/// itself; EMPTY and VARIANT mean "as is".
pub(crate) fn requested_type_ok(canonical: VarType, requested: VarType) -> bool {
    if requested == VarType::EMPTY || requested == VarType::VARIANT {
        return true;
    }
    if !crate::convert::is_supported_type(requested) || requested.is_array() != canonical.is_array()
    {
        return false;
    }
    let (c, r) = (canonical.element(), requested.element());
    if c == VarType::VARIANT || r == VarType::VARIANT {
        return true;
    }
    (c == VarType::ERROR) == (r == VarType::ERROR)
}

/// Mutable access to the items of a group, for per-item operations.
macro_rules! per_item {
    ($self:ident, $group:ident, $list:ident, |$g:ident, $it:ident, $arg:ident| $body:block) => {{
        if $list.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = $self.live_slot($group)?;
        let $g = $self.groups[slot].as_mut().expect("group");
        let mut out = Vec::with_capacity($list.len());
        for $arg in $list {
            let r = match $g.find($arg.handle()) {
                None => Err(OpcError::InvalidHandle),
                Some(i) => {
                    let $it = i;
                    $body
                }
            };
            out.push(r);
        }
        Ok(out)
    }};
}

/// An argument of a per-item call that names an item by server handle.
pub(crate) trait ItemArg {
    fn handle(&self) -> u32;
}
impl ItemArg for u32 {
    fn handle(&self) -> u32 {
        *self
    }
}
impl<T> ItemArg for (u32, T) {
    fn handle(&self) -> u32 {
        self.0
    }
}

impl Engine {
    /// Resolves an OPCITEMDEF: namespace errors (OPC_E_INVALIDITEMID, OPC_E_UNKNOWNITEMID,
    /// OPC_E_UNKNOWNPATH) and the requested-type check (OPC_E_BADTYPE).
    fn resolve(&self, d: &ItemDefinition<'_>) -> Result<ItemDef, OpcError> {
        if d.item_id.is_empty() {
            return Err(OpcError::InvalidItemId);
        }
        let def = self.ns.resolve(d.item_id, d.access_path)?;
        if !requested_type_ok(def.canonical_type, d.requested_type) {
            return Err(OpcError::BadType);
        }
        Ok(def)
    }

    /// IOPCItemMgt::AddItems. Per item: the server handle, canonical type and access
    /// rights, or OPC_E_INVALIDITEMID / OPC_E_UNKNOWNITEMID / OPC_E_UNKNOWNPATH /
    /// OPC_E_BADTYPE. Active items in an active group subscribe at the data source; they
    /// are reported at the next update.
    pub fn add_items(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        items: &[ItemDefinition<'_>],
    ) -> Result<Vec<Result<ItemResult, OpcError>>, OpcError> {
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = self.live_slot(group)?;
        {
            let g = self.group_mut(slot);
            g.items.reserve_exact(items.len());
        }
        let mut out = Vec::with_capacity(items.len());
        let mut key_bytes: usize = items.iter().map(|d| d.item_id.len()).sum();
        for (i, d) in items.iter().enumerate() {
            self.sources.batch_left(items.len() - i, key_bytes);
            key_bytes -= d.item_id.len();
            let def = match self.resolve(d) {
                Ok(def) => def,
                Err(e) => {
                    out.push(Err(e));
                    continue;
                }
            };
            let src = match self.sources.find_or_insert(&def, now) {
                Ok(src) => src,
                Err(e) => {
                    out.push(Err(e));
                    continue;
                }
            };
            self.sources.add_ref(src);
            let path = self.sources.paths.intern(d.access_path);
            let (name, alias) = if self.sources.key(src) == d.item_id {
                (path, ItemFlags::empty())
            } else {
                (self.names.acquire(d.item_id, path), ItemFlags::ALIAS)
            };
            let handle = {
                let g = self.groups[slot].as_mut().expect("group");
                Self::alloc_item_handle(&mut self.next_item_handle, &g.items, &mut g.sorted)
            };
            let e = &self.sources.entries[src as usize];
            let result = ItemResult {
                server_handle: handle,
                canonical_type: e.canonical,
                access_rights: u32::from(e.access),
            };
            let mut it = GroupItem::new(handle, d.client_handle, src, name, d.requested_type);
            it.flags = alias;
            it.flags.set(ItemFlags::ACTIVE, d.active);
            let Engine {
                groups, sources, ..
            } = self;
            let g = groups[slot].as_mut().expect("group");
            Self::sync_sub(sources, g.active, g.update_rate, 0, &mut it);
            if d.active {
                g.needs_scan = true;
            }
            g.items.push(it);
            out.push(Ok(result));
        }
        self.sources.batch_left(0, 0);
        Ok(out)
    }

    /// IOPCItemMgt::ValidateItems: as AddItems without adding (server handle 0).
    pub fn validate_items(
        &self,
        group: GroupHandle,
        items: &[ItemDefinition<'_>],
    ) -> Result<Vec<Result<ItemResult, OpcError>>, OpcError> {
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        self.live_slot(group)?;
        Ok(items
            .iter()
            .map(|d| {
                self.resolve(d).map(|def| ItemResult {
                    server_handle: 0,
                    canonical_type: def.canonical_type,
                    access_rights: def.access_rights,
                })
            })
            .collect())
    }

    /// IOPCItemMgt::RemoveItems (OPC_E_INVALIDHANDLE per unknown handle).
    pub fn remove_items(
        &mut self,
        _now: Timestamp,
        group: GroupHandle,
        handles: &[u32],
    ) -> Result<Vec<Result<(), OpcError>>, OpcError> {
        if handles.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = self.live_slot(group)?;
        let mut out = Vec::with_capacity(handles.len());
        let mut removed = Vec::new();
        {
            let Engine {
                groups, sources, ..
            } = self;
            let g = groups[slot].as_mut().expect("group");
            let rate = g.update_rate;
            for &h in handles {
                let Some(i) = g.find(h) else {
                    out.push(Err(OpcError::InvalidHandle));
                    continue;
                };
                let it = &mut g.items[i];
                let sampling = ItemOpts::sampling(&g.opts, it);
                Self::sync_sub(sources, false, rate, sampling, it);
                it.flags.insert(ItemFlags::REMOVED);
                it.forget_last(&mut g.lasts);
                g.drop_buffer(h);
                g.opts.remove(&h);
                removed.push(i);
                out.push(Ok(()));
            }
        }
        for i in removed {
            let it = self.group(slot).items[i].clone();
            self.release_item_refs(&it);
        }
        let g = self.group_mut(slot);
        g.items.retain(|it| !it.flags.contains(ItemFlags::REMOVED));
        if g.items.len() * 4 < g.items.capacity() && g.items.capacity() > 64 {
            g.items.shrink_to_fit();
        }
        Ok(out)
    }

    /// IOPCItemMgt::SetActiveState. Activated items are reported at the next update;
    /// deactivated ones are not reported (and stop their subscription).
    pub fn set_active_state(
        &mut self,
        _now: Timestamp,
        group: GroupHandle,
        handles: &[u32],
        active: bool,
    ) -> Result<Vec<Result<(), OpcError>>, OpcError> {
        if handles.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = self.live_slot(group)?;
        let Engine {
            groups, sources, ..
        } = self;
        let g = groups[slot].as_mut().expect("group");
        let on = g.active;
        let rate = g.update_rate;
        let mut out = Vec::with_capacity(handles.len());
        for &h in handles {
            let Some(i) = g.find(h) else {
                out.push(Err(OpcError::InvalidHandle));
                continue;
            };
            let it = &mut g.items[i];
            if it.active() != active {
                if active {
                    it.flags.insert(ItemFlags::ACTIVE);
                } else {
                    it.flags.remove(ItemFlags::ACTIVE);
                }
                it.flags.remove(ItemFlags::SENT);
                let sampling = ItemOpts::sampling(&g.opts, it);
                Self::sync_sub(sources, on, rate, sampling, it);
                g.drop_buffer(h);
                if active {
                    g.needs_scan = true;
                }
            }
            out.push(Ok(()));
        }
        Ok(out)
    }

    /// IOPCItemMgt::SetClientHandles.
    pub fn set_client_handles(
        &mut self,
        group: GroupHandle,
        items: &[(u32, u32)],
    ) -> Result<Vec<Result<(), OpcError>>, OpcError> {
        per_item!(self, group, items, |g, i, arg| {
            g.items[i].client = arg.1;
            Ok(())
        })
    }

    /// IOPCItemMgt::SetDatatypes (OPC_E_BADTYPE when the canonical type cannot be
    /// converted to the requested one).
    pub fn set_datatypes(
        &mut self,
        group: GroupHandle,
        items: &[(u32, VarType)],
    ) -> Result<Vec<Result<(), OpcError>>, OpcError> {
        let sources = &self.sources;
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = self.live_slot(group)?;
        let g = self.groups[slot].as_mut().expect("group");
        Ok(items
            .iter()
            .map(|&(h, vt)| {
                let i = g.find(h).ok_or(OpcError::InvalidHandle)?;
                let it = &mut g.items[i];
                if !requested_type_ok(sources.entries[it.source as usize].canonical, vt) {
                    return Err(OpcError::BadType);
                }
                it.req_type = vt;
                Ok(())
            })
            .collect())
    }

    /// IOPCItemMgt::CreateEnumerator data: the attributes of every item, in the order
    /// they were added (removals move the last item into the gap).
    pub fn item_attributes(&self, group: GroupHandle) -> Result<Vec<ItemAttributes>, OpcError> {
        let g = self.group(self.live_slot(group)?);
        Ok(g.items
            .iter()
            .map(|it| {
                let e = &self.sources.entries[it.source as usize];
                let (item_id, path) = if it.flags.contains(ItemFlags::ALIAS) {
                    let (id, path) = self.names.get(it.name);
                    (id.to_string(), path)
                } else {
                    (self.sources.key(it.source).to_string(), it.name)
                };
                ItemAttributes {
                    access_path: self.sources.paths.get(path).to_string(),
                    item_id,
                    active: it.active(),
                    client_handle: it.client,
                    server_handle: it.handle,
                    access_rights: u32::from(e.access),
                    requested_type: it.req_type,
                    canonical_type: e.canonical,
                    eu: self.sources.eu_info(it.source),
                }
            })
            .collect())
    }

    /// For the write audit (`crate::audit`): the group's name and the item ID of each
    /// server handle (`None` for a handle that is not the group's).
    pub fn audit_names(
        &self,
        group: GroupHandle,
        handles: &[u32],
    ) -> Result<(String, Vec<Option<String>>), OpcError> {
        let g = self.group(self.live_slot(group)?);
        let ids = handles
            .iter()
            .map(|&h| {
                g.find(h).map(|i| {
                    let it = &g.items[i];
                    if it.flags.contains(ItemFlags::ALIAS) {
                        self.names.get(it.name).0.to_string()
                    } else {
                        self.sources.key(it.source).to_string()
                    }
                })
            })
            .collect();
        Ok((g.name.clone(), ids))
    }

    /// For the write audit: which of these handles of the group the write-rights policy
    /// refuses to the group's client (false for handles that are not the group's, and for
    /// every handle under an open policy).
    pub fn denied_by_policy(&self, group: GroupHandle, handles: &[u32]) -> Vec<bool> {
        let slot = match self.live_slot(group) {
            Ok(slot) if !self.write_rights.is_open() => slot,
            _ => return vec![false; handles.len()],
        };
        let g = self.group(slot);
        handles
            .iter()
            .map(|&h| {
                g.find(h)
                    .is_some_and(|i| !self.may_write(g.session, g.items[i].source))
            })
            .collect()
    }

    /// For the write audit of IOPCItemIO::WriteVQT: which of these item IDs the policy
    /// refuses to `session` (resolved on the basic channel, as the write resolves them;
    /// false for IDs that do not resolve).
    pub fn item_io_denied_by_policy(&self, session: SessionHandle, item_ids: &[&str]) -> Vec<bool> {
        if self.write_rights.is_open() {
            return vec![false; item_ids.len()];
        }
        item_ids
            .iter()
            .map(|id| {
                self.ns
                    .resolve(id, "")
                    .is_ok_and(|def| !self.write_decision(session, &def.channel).allowed)
            })
            .collect()
    }

    /// Why the namespace refuses writes of these items by design
    /// ([`crate::namespace::Namespace::write_refusal`]): (item ID, reason) of each handle of
    /// the group that has one.
    pub fn write_refusals(&self, group: GroupHandle, handles: &[u32]) -> Vec<(String, String)> {
        let Ok(slot) = self.live_slot(group) else {
            return Vec::new();
        };
        let g = self.group(slot);
        handles
            .iter()
            .filter_map(|&h| {
                let it = &g.items[g.find(h)?];
                let id = self.sources.key(it.source);
                let why = self.ns.write_refusal(id, self.sources.channel(it.source))?;
                Some((id.to_owned(), why))
            })
            .collect()
    }

    /// The group's name, for the write audit of its OnWriteComplete.
    pub fn audit_group_name(&self, group: GroupHandle) -> Option<String> {
        let g = self.group(self.live_slot(group).ok()?);
        Some(g.name.clone())
    }

    // ---- IOPCItemDeadbandMgt ---------------------------------------------------------

    /// IOPCItemDeadbandMgt::SetItemDeadband: E_INVALIDARG outside 0..100,
    /// OPC_E_DEADBANDNOTSUPPORTED for items without analog EU information.
    pub fn set_item_deadband(
        &mut self,
        group: GroupHandle,
        items: &[(u32, f32)],
    ) -> Result<Vec<Result<(), OpcError>>, OpcError> {
        let sources = &self.sources;
        let r = per_item!(self, group, items, |g, i, arg| {
            let it = &mut g.items[i];
            if !valid_percent(arg.1) {
                Err(OpcError::InvalidArg)
            } else if !sources.entries[it.source as usize].is_analog() {
                Err(OpcError::DeadbandNotSupported)
            } else {
                ItemOpts::set_deadband(&mut g.opts, it, Some(arg.1));
                g.rescan_all();
                Ok(())
            }
        });
        r
    }

    /// IOPCItemDeadbandMgt::GetItemDeadband: OPC_E_DEADBANDNOTSUPPORTED for non-analog
    /// items, OPC_E_DEADBANDNOTSET when no item deadband is set.
    pub fn get_item_deadband(
        &self,
        group: GroupHandle,
        handles: &[u32],
    ) -> Result<Vec<Result<f32, OpcError>>, OpcError> {
        if handles.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let g = self.group(self.live_slot(group)?);
        Ok(handles
            .iter()
            .map(|&h| {
                let it = &g.items[g.find(h).ok_or(OpcError::InvalidHandle)?];
                if !self.sources.entries[it.source as usize].is_analog() {
                    return Err(OpcError::DeadbandNotSupported);
                }
                ItemOpts::deadband(&g.opts, it).ok_or(OpcError::DeadbandNotSet)
            })
            .collect())
    }

    /// IOPCItemDeadbandMgt::ClearItemDeadband: the group deadband applies again.
    pub fn clear_item_deadband(
        &mut self,
        group: GroupHandle,
        handles: &[u32],
    ) -> Result<Vec<Result<(), OpcError>>, OpcError> {
        let sources = &self.sources;
        let r = per_item!(self, group, handles, |g, i, _arg| {
            let it = &mut g.items[i];
            if !sources.entries[it.source as usize].is_analog() {
                Err(OpcError::DeadbandNotSupported)
            } else if !it.flags.contains(ItemFlags::DEADBAND) {
                Err(OpcError::DeadbandNotSet)
            } else {
                ItemOpts::set_deadband(&mut g.opts, it, None);
                g.rescan_all();
                Ok(())
            }
        });
        r
    }

    // ---- IOPCItemSamplingMgt ---------------------------------------------------------

    /// IOPCItemSamplingMgt::SetItemSamplingRate: the rate is raised to the minimum
    /// ([`Revised::code`] is then OPC_S_UNSUPPORTEDRATE for the item). The data source is
    /// asked for the fastest rate any subscriber wants.
    pub fn set_item_sampling_rate(
        &mut self,
        group: GroupHandle,
        items: &[(u32, u32)],
    ) -> Result<Vec<Result<Revised, OpcError>>, OpcError> {
        let min = self.cfg.min_update_rate_ms;
        let Engine {
            groups,
            sources,
            group_slots,
            ..
        } = self;
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = *group_slots.get(&group.0).ok_or(OpcError::Fail)? as usize;
        let g = groups[slot]
            .as_mut()
            .filter(|g| !g.deleted)
            .ok_or(OpcError::Fail)?;
        let rate = g.update_rate;
        Ok(items
            .iter()
            .map(|&(h, requested)| {
                let i = g.find(h).ok_or(OpcError::InvalidHandle)?;
                let it = &mut g.items[i];
                let value = requested.max(min);
                let sampling = ItemOpts::sampling(&g.opts, it);
                let old = if sampling != 0 { sampling } else { rate };
                Self::move_rate(sources, it, old, value);
                ItemOpts::set_sampling(&mut g.opts, it, Some(value));
                Ok(Revised {
                    value,
                    revised: value != requested,
                })
            })
            .collect())
    }

    /// IOPCItemSamplingMgt::GetItemSamplingRate (OPC_E_RATENOTSET when not set).
    pub fn get_item_sampling_rate(
        &self,
        group: GroupHandle,
        handles: &[u32],
    ) -> Result<Vec<Result<u32, OpcError>>, OpcError> {
        if handles.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let g = self.group(self.live_slot(group)?);
        Ok(handles
            .iter()
            .map(|&h| {
                let it = &g.items[g.find(h).ok_or(OpcError::InvalidHandle)?];
                match ItemOpts::sampling(&g.opts, it) {
                    0 => Err(OpcError::RateNotSet),
                    sampling => Ok(sampling),
                }
            })
            .collect())
    }

    /// IOPCItemSamplingMgt::ClearItemSamplingRate: the group update rate applies again
    /// (OPC_E_RATENOTSET when not set).
    pub fn clear_item_sampling_rate(
        &mut self,
        group: GroupHandle,
        handles: &[u32],
    ) -> Result<Vec<Result<(), OpcError>>, OpcError> {
        let Engine {
            groups,
            sources,
            group_slots,
            ..
        } = self;
        if handles.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = *group_slots.get(&group.0).ok_or(OpcError::Fail)? as usize;
        let g = groups[slot]
            .as_mut()
            .filter(|g| !g.deleted)
            .ok_or(OpcError::Fail)?;
        let rate = g.update_rate;
        Ok(handles
            .iter()
            .map(|&h| {
                let i = g.find(h).ok_or(OpcError::InvalidHandle)?;
                let it = &mut g.items[i];
                let sampling = ItemOpts::sampling(&g.opts, it);
                if sampling == 0 {
                    return Err(OpcError::RateNotSet);
                }
                Self::move_rate(sources, it, sampling, rate);
                ItemOpts::set_sampling(&mut g.opts, it, None);
                Ok(())
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn item(handle: u32) -> GroupItem {
        GroupItem {
            flags: ItemFlags::ACTIVE,
            ..GroupItem::new(handle, 0, 0, 0, VarType::EMPTY)
        }
    }

    /// Numbers sent last stay in the item, strings and arrays go to the group's map (and
    /// leave it when a number follows or the item goes).
    #[test]
    fn the_last_value_sent_is_a_number_in_the_item_or_shared_in_the_map() {
        let mut lasts = Lasts::default();
        let (mut a, mut b) = (item(1), item(2));
        assert_eq!(*a.last(&lasts), CachedValue::EMPTY);
        let text = CachedValue::from_value(crate::Value::Bstr("x".into()));
        let num = CachedValue::from_value(crate::Value::R8(2.5));
        a.set_last(&mut lasts, text.clone(), Quality::GOOD);
        b.set_last(&mut lasts, num.clone(), Quality::BAD);
        assert_eq!((&*a.last(&lasts), a.last_quality), (&text, Quality::GOOD));
        assert_eq!((&*b.last(&lasts), b.last_quality), (&num, Quality::BAD));
        assert!(matches!(a.last(&lasts), Cow::Borrowed(_)));
        assert_eq!(lasts.len(), 1);
        a.set_last(&mut lasts, num.clone(), Quality::GOOD);
        assert_eq!(*a.last(&lasts), num);
        assert!(lasts.is_empty());
        a.set_last(&mut lasts, text.clone(), Quality::GOOD);
        b.set_last(&mut lasts, text.clone(), Quality::GOOD);
        a.forget_last(&mut lasts);
        assert_eq!(*a.last(&lasts), CachedValue::EMPTY);
        assert_eq!((lasts.len(), &*b.last(&lasts)), (1, &text));
        for v in [
            crate::Value::I2(-3),
            crate::Value::Bool(true),
            crate::Value::Empty,
        ] {
            let v = CachedValue::from_value(v);
            b.set_last(&mut lasts, v.clone(), Quality::GOOD);
            assert_eq!(*b.last(&lasts), v);
        }
        assert!(lasts.is_empty());
    }

    /// An item's options are in the side table while either is set, and only then.
    #[test]
    fn item_opts_are_kept_while_one_is_set() {
        let mut opts = IntMap::default();
        let (mut a, b) = (item(1), item(2));
        assert_eq!(ItemOpts::sampling(&opts, &a), 0);
        assert_eq!(ItemOpts::deadband(&opts, &a), None);
        ItemOpts::set_sampling(&mut opts, &mut a, Some(250));
        ItemOpts::set_deadband(&mut opts, &mut a, Some(2.5));
        assert_eq!(
            a.flags,
            ItemFlags::ACTIVE | ItemFlags::SAMPLING | ItemFlags::DEADBAND
        );
        assert_eq!(
            (ItemOpts::sampling(&opts, &a), ItemOpts::deadband(&opts, &a)),
            (250, Some(2.5))
        );
        assert_eq!(
            (ItemOpts::sampling(&opts, &b), ItemOpts::deadband(&opts, &b)),
            (0, None)
        );
        ItemOpts::set_sampling(&mut opts, &mut a, None);
        assert_eq!(
            (ItemOpts::sampling(&opts, &a), ItemOpts::deadband(&opts, &a)),
            (0, Some(2.5))
        );
        assert_eq!(opts.len(), 1);
        ItemOpts::set_deadband(&mut opts, &mut a, None);
        assert!(opts.is_empty());
        assert_eq!(a.flags, ItemFlags::ACTIVE);
        ItemOpts::set_deadband(&mut opts, &mut a, Some(1.0));
        assert_eq!(
            opts[&1],
            ItemOpts {
                sampling: 0,
                deadband: 1.0
            }
        );
    }

    #[test]
    fn group_items_stay_small() {
        assert_eq!(std::mem::size_of::<GroupItem>(), 32);
    }
}
