//! Groups: IOPCServer (AddGroup, RemoveGroup, GetGroupByName), IOPCGroupStateMgt/2 and the
//! connection state the COM layer reports (callback advised, COM references).

use super::buffer::ItemBuffer;
use super::deadband::valid_percent;
use super::engine::{Engine, GroupHandle, SessionHandle};
use super::item::{GroupItem, ItemFlags, ItemOpts, Lasts};
use super::util::IntMap;
use super::Revised;
use crate::{OpcError, Timestamp};

/// AddGroup parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct GroupParams<'a> {
    /// Empty: the server generates a unique name.
    pub name: &'a str,
    pub active: bool,
    /// Requested update rate in ms.
    pub update_rate: u32,
    pub client_handle: u32,
    /// Minutes; the COM layer passes the machine's bias when the client passed NULL.
    pub time_bias: i32,
    /// 0 ..= 100 (NULL: 0).
    pub percent_deadband: f32,
    pub lcid: u32,
}

impl Default for GroupParams<'_> {
    fn default() -> Self {
        GroupParams {
            name: "",
            active: true,
            update_rate: 1000,
            client_handle: 0,
            time_bias: 0,
            percent_deadband: 0.0,
            lcid: 0,
        }
    }
}

/// AddGroup result: the server handle and the revised update rate (OPC_S_UNSUPPORTEDRATE
/// when revised).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AddGroupResult {
    pub group: GroupHandle,
    pub update_rate: Revised,
}

/// IOPCGroupStateMgt::GetState (plus the keep-alive time of IOPCGroupStateMgt2).
#[derive(Debug, Clone, PartialEq)]
pub struct GroupState {
    pub name: String,
    pub active: bool,
    pub update_rate: u32,
    pub time_bias: i32,
    pub percent_deadband: f32,
    pub lcid: u32,
    pub client_handle: u32,
    pub server_handle: GroupHandle,
    pub keep_alive: u32,
}

/// IOPCGroupStateMgt::SetState; `None` leaves a property as it is.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SetGroupState {
    pub update_rate: Option<u32>,
    pub active: Option<bool>,
    pub time_bias: Option<i32>,
    pub percent_deadband: Option<f32>,
    pub lcid: Option<u32>,
    pub client_handle: Option<u32>,
}

/// IOPCServer::RemoveGroup outcome.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RemoveGroupOutcome {
    /// S_OK.
    Removed,
    /// OPC_S_INUSE: COM references remain; the group is marked deleted (its items are
    /// removed, its name is free, every call on it fails with E_FAIL) and its handle is
    /// released when the last reference is ([`Engine::group_release`]).
    InUse,
}

/// A group and its items.
pub(crate) struct Group {
    pub handle: GroupHandle,
    pub session: SessionHandle,
    pub name: String,
    pub client_handle: u32,
    pub active: bool,
    /// IOPCAsyncIO2::SetEnable.
    pub enabled: bool,
    /// A callback sink is advised.
    pub connected: bool,
    /// Removed while still referenced (OPC_S_INUSE).
    pub deleted: bool,
    pub com_refs: u32,
    pub update_rate: u32,
    pub time_bias: i32,
    pub deadband: f32,
    pub lcid: u32,
    pub keep_alive: u32,
    /// Sorted by server handle while `sorted` (handles come from a process-wide counter,
    /// so new items append in order; only a wrap of the counter breaks that).
    pub items: Vec<GroupItem>,
    pub sorted: bool,
    /// Asynchronous transactions not yet delivered.
    pub outstanding: u32,
    // Scheduling.
    pub next_update: Timestamp,
    pub last_callback: Timestamp,
    /// The deadline of this group's valid scheduler entry.
    pub wake: Option<Timestamp>,
    pub sched_seq: u32,
    /// `Engine::change_seq` at the last scan.
    pub scanned_seq: u64,
    /// Some item must be compared although no cache entry changed (new, reactivated,
    /// deadband changed).
    pub needs_scan: bool,
    /// With `EngineConfig::max_pending_data_changes`: this group's scheduled callbacks
    /// under way ...
    pub delivering: u32,
    /// ... and an update fell due meanwhile (run it when the delivery ends).
    pub update_missed: bool,
    /// Items are held back until their first sample (see "The first callback" in
    /// `crate::model`): until this deadline.
    pub first_sample_until: Option<Timestamp>,
    /// A sample arrived while items were held: report the ready ones at once.
    pub first_sample_ready: bool,
    /// Buffered samples of items with buffering on, by server handle (`model/buffer.rs`)
    /// ...
    pub buffers: IntMap<u32, ItemBuffer>,
    /// The item sampling rates and deadbands of the items that have one, by server handle.
    pub opts: IntMap<u32, ItemOpts>,
    /// The string and array values last sent, by server handle ([`GroupItem::last`]).
    pub lasts: Lasts,
    /// ... and how many they hold together.
    pub buffered: usize,
}

impl Group {
    pub fn find(&self, handle: u32) -> Option<usize> {
        let i = if self.sorted {
            // Items added in one call get consecutive handles, so the handle's distance
            // from the first item's is usually its index: check that slot first (O(1) for
            // the bulk of a 10,000-item Read or Write), else search.
            let guess = handle.wrapping_sub(self.items.first()?.handle) as usize;
            match self.items.get(guess) {
                Some(it) if it.handle == handle => guess,
                _ => self
                    .items
                    .binary_search_by_key(&handle, |it| it.handle)
                    .ok()?,
            }
        } else {
            self.items.iter().position(|it| it.handle == handle)?
        };
        (!self.items[i].flags.contains(ItemFlags::REMOVED)).then_some(i)
    }

    /// Callbacks are due: active, live, sink connected, enabled.
    /// Moves `next_update` (due at or before `now`) to the first tick after `now`, keeping
    /// the phase: missed periods are skipped, not sent in a burst.
    pub fn skip_to_next_update(&mut self, now: Timestamp) {
        let period = i64::from(self.update_rate) * Timestamp::TICKS_PER_MS;
        let behind = now.0 - self.next_update.0;
        self.next_update = Timestamp(self.next_update.0 + (behind / period + 1) * period);
    }

    pub fn ticking(&self) -> bool {
        self.active && self.connected && self.enabled && !self.deleted
    }

    /// Every active item is reported at the next update (group or callback became active).
    pub fn resend_all(&mut self) {
        for it in &mut self.items {
            it.flags.remove(ItemFlags::SENT);
        }
        self.needs_scan = true;
    }

    /// Compare every item at the next update (a deadband changed).
    pub fn rescan_all(&mut self) {
        self.scanned_seq = 0;
        self.needs_scan = true;
    }
}

impl Engine {
    fn session_mut(&mut self, s: SessionHandle) -> Result<&mut super::engine::Session, OpcError> {
        self.sessions.get_mut(&s.0).ok_or(OpcError::Fail)
    }

    /// A group name not in use in the session.
    fn generate_name(&mut self, s: SessionHandle) -> Result<String, OpcError> {
        let sess = self.session_mut(s)?;
        loop {
            sess.name_counter = sess.name_counter.wrapping_add(1);
            let name = format!("Group{}", sess.name_counter);
            if !sess.names.contains_key(&name) {
                return Ok(name);
            }
        }
    }

    fn insert_group(&mut self, group: Group) -> usize {
        let handle = group.handle;
        let session = group.session;
        let name = group.name.clone();
        let slot = match self.free_groups.pop() {
            Some(slot) => {
                self.groups[slot as usize] = Some(group);
                slot as usize
            }
            None => {
                self.groups.push(Some(group));
                self.groups.len() - 1
            }
        };
        self.group_slots.insert(handle.0, slot as u32);
        if let Some(sess) = self.sessions.get_mut(&session.0) {
            sess.names.insert(name, handle);
            sess.groups.push(handle);
        }
        slot
    }

    fn new_group_handle(&mut self) -> GroupHandle {
        loop {
            let h = self.next_group_handle;
            self.next_group_handle = self.next_group_handle.wrapping_add(1).max(1);
            if !self.group_slots.contains_key(&h) {
                return GroupHandle(h);
            }
        }
    }

    /// IOPCServer::AddGroup. E_INVALIDARG for a deadband outside 0..100,
    /// OPC_E_DUPLICATENAME for a name the session already uses (names are case-sensitive).
    pub fn add_group(
        &mut self,
        now: Timestamp,
        session: SessionHandle,
        params: &GroupParams<'_>,
    ) -> Result<AddGroupResult, OpcError> {
        if !self.sessions.contains_key(&session.0) {
            return Err(OpcError::Fail);
        }
        if !valid_percent(params.percent_deadband) {
            return Err(OpcError::InvalidArg);
        }
        let name = if params.name.is_empty() {
            self.generate_name(session)?
        } else {
            if self.sessions[&session.0].names.contains_key(params.name) {
                return Err(OpcError::DuplicateName);
            }
            params.name.to_owned()
        };
        let rate = self.revise_rate(params.update_rate);
        let handle = self.new_group_handle();
        let group = Group {
            handle,
            session,
            name,
            client_handle: params.client_handle,
            active: params.active,
            enabled: true,
            connected: false,
            deleted: false,
            com_refs: 0,
            update_rate: rate.value,
            time_bias: params.time_bias,
            deadband: params.percent_deadband,
            lcid: params.lcid,
            keep_alive: 0,
            items: Vec::new(),
            sorted: true,
            outstanding: 0,
            next_update: now,
            last_callback: now,
            wake: None,
            sched_seq: 0,
            scanned_seq: 0,
            needs_scan: true,
            delivering: 0,
            update_missed: false,
            first_sample_until: None,
            first_sample_ready: false,
            buffers: IntMap::default(),
            opts: IntMap::default(),
            lasts: Lasts::default(),
            buffered: 0,
        };
        self.insert_group(group);
        Ok(AddGroupResult {
            group: handle,
            update_rate: rate,
        })
    }

    /// IOPCServer::GetGroupByName (E_INVALIDARG when the session has no such group).
    pub fn group_by_name(
        &self,
        session: SessionHandle,
        name: &str,
    ) -> Result<GroupHandle, OpcError> {
        let s = self.sessions.get(&session.0).ok_or(OpcError::Fail)?;
        s.names.get(name).copied().ok_or(OpcError::InvalidArg)
    }

    /// The session's groups (IOPCServer::CreateGroupEnumerator, private groups), in
    /// creation order.
    pub fn groups(&self, session: SessionHandle) -> Result<Vec<(GroupHandle, String)>, OpcError> {
        let s = self.sessions.get(&session.0).ok_or(OpcError::Fail)?;
        Ok(s.groups
            .iter()
            .filter_map(|h| {
                let slot = self.live_slot(*h).ok()?;
                Some((*h, self.group(slot).name.clone()))
            })
            .collect())
    }

    /// IOPCServer::RemoveGroup. E_INVALIDARG for a handle that is not a group of this
    /// session. Without `force`, a group the COM layer still references
    /// ([`Engine::group_add_ref`]) is marked deleted: OPC_S_INUSE.
    pub fn remove_group(
        &mut self,
        now: Timestamp,
        session: SessionHandle,
        group: GroupHandle,
        force: bool,
    ) -> Result<RemoveGroupOutcome, OpcError> {
        let slot = self.live_slot(group).map_err(|_| OpcError::InvalidArg)?;
        if self.group(slot).session != session {
            return Err(OpcError::InvalidArg);
        }
        if !force && self.group(slot).com_refs > 0 {
            self.destroy_group(now, slot, false);
            Ok(RemoveGroupOutcome::InUse)
        } else {
            self.destroy_group(now, slot, true);
            Ok(RemoveGroupOutcome::Removed)
        }
    }

    /// Removes a group's items, subscriptions, transactions and name; frees the slot too
    /// when `free` (otherwise the group stays as a deleted shell until released).
    pub(crate) fn destroy_group(&mut self, _now: Timestamp, slot: usize, free: bool) {
        let handle = self.group(slot).handle;
        if !self.group(slot).deleted {
            {
                let g = self.group_mut(slot);
                g.deleted = true;
                g.wake = None;
                g.sched_seq = g.sched_seq.wrapping_add(1);
            }
            self.sync_group_subs(slot);
            let items = std::mem::take(&mut self.group_mut(slot).items);
            for it in &items {
                self.release_item_refs(it);
            }
            let g = self.group_mut(slot);
            g.opts = IntMap::default();
            g.lasts = Lasts::default();
            let (session, name) = (g.session, std::mem::take(&mut g.name));
            if let Some(s) = self.sessions.get_mut(&session.0) {
                if s.names.get(&name) == Some(&handle) {
                    s.names.remove(&name);
                }
            }
            self.txns.drop_group(handle);
            // Callbacks not yet delivered have no sink to go to any more.
            self.events.retain(|e| e.group() != handle);
        }
        if free {
            let session = self.group(slot).session;
            if let Some(s) = self.sessions.get_mut(&session.0) {
                s.groups.retain(|h| *h != handle);
            }
            self.groups[slot] = None;
            self.group_slots.remove(&handle.0);
            self.free_groups.push(slot as u32);
        }
    }

    /// Drops the cache and name references of a removed item.
    pub(crate) fn release_item_refs(&mut self, it: &GroupItem) {
        debug_assert!(!it.flags.contains(ItemFlags::SUBSCRIBED));
        self.sources.release(it.source);
        if it.flags.contains(ItemFlags::ALIAS) {
            self.names.release(it.name);
        }
    }

    /// The COM layer took a reference to the group object (for OPC_S_INUSE).
    pub fn group_add_ref(&mut self, group: GroupHandle) -> Result<u32, OpcError> {
        let slot = *self.group_slots.get(&group.0).ok_or(OpcError::Fail)? as usize;
        let g = self.group_mut(slot);
        g.com_refs += 1;
        Ok(g.com_refs)
    }

    /// The COM layer released a reference; a group removed with OPC_S_INUSE is freed when
    /// the count reaches 0.
    pub fn group_release(&mut self, now: Timestamp, group: GroupHandle) -> Result<u32, OpcError> {
        let slot = *self.group_slots.get(&group.0).ok_or(OpcError::Fail)? as usize;
        let g = self.group_mut(slot);
        g.com_refs = g.com_refs.saturating_sub(1);
        let (refs, deleted) = (g.com_refs, g.deleted);
        if refs == 0 && deleted {
            self.destroy_group(now, slot, true);
        }
        Ok(refs)
    }

    /// The COM layer advised (`true`) or unadvised (`false`) an IOPCDataCallback sink.
    /// A new sink gets every active item at the next update.
    pub fn set_callback_connected(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        connected: bool,
    ) -> Result<(), OpcError> {
        let slot = self.live_slot(group)?;
        let g = self.group_mut(slot);
        if g.connected == connected {
            return Ok(());
        }
        g.connected = connected;
        if connected {
            g.resend_all();
        }
        self.schedule_group(slot, now, true);
        Ok(())
    }

    pub fn callback_connected(&self, group: GroupHandle) -> Result<bool, OpcError> {
        Ok(self.group(self.live_slot(group)?).connected)
    }

    /// IOPCGroupStateMgt::GetState.
    pub fn group_state(&self, group: GroupHandle) -> Result<GroupState, OpcError> {
        let g = self.group(self.live_slot(group)?);
        Ok(GroupState {
            name: g.name.clone(),
            active: g.active,
            update_rate: g.update_rate,
            time_bias: g.time_bias,
            percent_deadband: g.deadband,
            lcid: g.lcid,
            client_handle: g.client_handle,
            server_handle: g.handle,
            keep_alive: g.keep_alive,
        })
    }

    /// IOPCGroupStateMgt::SetState. Returns the (revised) update rate, which is also
    /// reported when no rate was requested. E_INVALIDARG (and nothing changed) for a
    /// deadband outside 0..100.
    pub fn set_group_state(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        state: &SetGroupState,
    ) -> Result<Revised, OpcError> {
        let slot = self.live_slot(group)?;
        if let Some(d) = state.percent_deadband {
            if !valid_percent(d) {
                return Err(OpcError::InvalidArg);
            }
        }
        let revised = state.update_rate.map(|r| self.revise_rate(r));
        let Engine {
            groups, sources, ..
        } = self;
        let g = groups[slot].as_mut().expect("group");
        let mut reschedule = false;
        let mut immediate = false;
        if let Some(d) = state.percent_deadband {
            if d != g.deadband {
                g.deadband = d;
                g.rescan_all();
            }
        }
        if let Some(r) = revised {
            let old = g.update_rate;
            if r.value != old {
                g.update_rate = r.value;
                for it in &g.items {
                    if ItemOpts::sampling(&g.opts, it) == 0 {
                        Self::move_rate(sources, it, old, r.value);
                    }
                }
            }
            // A new rate starts a new period from now (without a forced callback).
            g.next_update = now.add_millis(u64::from(r.value));
            reschedule = true;
        }
        if let Some(b) = state.time_bias {
            g.time_bias = b;
        }
        if let Some(l) = state.lcid {
            g.lcid = l;
        }
        if let Some(c) = state.client_handle {
            g.client_handle = c;
        }
        if let Some(active) = state.active {
            if active != g.active {
                g.active = active;
                if active {
                    // The last values sent are no longer valid: send every active item.
                    g.resend_all();
                    immediate = true;
                }
                reschedule = true;
            }
        }
        let current = g.update_rate;
        if state.active.is_some() {
            self.sync_group_subs(slot);
        }
        if reschedule {
            self.schedule_group(slot, now, immediate);
        }
        Ok(revised.unwrap_or(Revised {
            value: current,
            revised: false,
        }))
    }

    /// IOPCGroupStateMgt::SetName. E_INVALIDARG for an empty name, OPC_E_DUPLICATENAME
    /// for a name another group of the session has.
    pub fn set_group_name(&mut self, group: GroupHandle, name: &str) -> Result<(), OpcError> {
        let slot = self.live_slot(group)?;
        if name.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let (session, old) = {
            let g = self.group(slot);
            (g.session, g.name.clone())
        };
        if old == name {
            return Ok(());
        }
        let s = self.sessions.get_mut(&session.0).ok_or(OpcError::Fail)?;
        if s.names.contains_key(name) {
            return Err(OpcError::DuplicateName);
        }
        s.names.remove(&old);
        s.names.insert(name.to_owned(), group);
        self.group_mut(slot).name = name.to_owned();
        Ok(())
    }

    /// IOPCGroupStateMgt::CloneGroup: a new, inactive group with the same properties and
    /// items (client handles, requested types, deadbands, sampling rates, active flags) and
    /// new server handles. An empty name generates one.
    pub fn clone_group(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        name: &str,
    ) -> Result<GroupHandle, OpcError> {
        let slot = self.live_slot(group)?;
        let session = self.group(slot).session;
        let name = if name.is_empty() {
            self.generate_name(session)?
        } else {
            if self
                .sessions
                .get(&session.0)
                .is_some_and(|s| s.names.contains_key(name))
            {
                return Err(OpcError::DuplicateName);
            }
            name.to_owned()
        };
        let handle = self.new_group_handle();
        let src = self.group(slot);
        let mut clone = Group {
            handle,
            session,
            name,
            client_handle: src.client_handle,
            active: false,
            enabled: true,
            connected: false,
            deleted: false,
            com_refs: 0,
            update_rate: src.update_rate,
            time_bias: src.time_bias,
            deadband: src.deadband,
            lcid: src.lcid,
            keep_alive: src.keep_alive,
            items: Vec::with_capacity(src.items.len()),
            sorted: true,
            outstanding: 0,
            next_update: now,
            last_callback: now,
            wake: None,
            sched_seq: 0,
            scanned_seq: 0,
            needs_scan: true,
            delivering: 0,
            update_missed: false,
            first_sample_until: None,
            first_sample_ready: false,
            buffers: IntMap::default(),
            opts: IntMap::default(),
            lasts: Lasts::default(),
            buffered: 0,
        };
        let items: Vec<GroupItem> = src.items.clone();
        let opts = src.opts.clone();
        for mut it in items {
            // Nothing is sent to the clone yet (no SENT): its last value does not count.
            it.forget_last(&mut Lasts::default());
            let old = it.handle;
            it.handle = Self::alloc_item_handle(
                &mut self.next_item_handle,
                &clone.items,
                &mut clone.sorted,
            );
            if let Some(&o) = opts.get(&old) {
                clone.opts.insert(it.handle, o);
            }
            it.flags
                .remove(ItemFlags::SENT | ItemFlags::SUBSCRIBED | ItemFlags::BUFFERED);
            self.sources.add_ref(it.source);
            if it.flags.contains(ItemFlags::ALIAS) {
                self.names.add_ref(it.name);
            }
            clone.items.push(it);
        }
        self.insert_group(clone);
        Ok(handle)
    }

    /// IOPCGroupStateMgt2::SetKeepAlive: 0 disables; other times are raised to the minimum
    /// update rate (OPC_S_UNSUPPORTEDRATE when revised).
    pub fn set_keep_alive(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        keep_alive_ms: u32,
    ) -> Result<Revised, OpcError> {
        let slot = self.live_slot(group)?;
        let r = if keep_alive_ms == 0 {
            Revised {
                value: 0,
                revised: false,
            }
        } else {
            self.revise_rate(keep_alive_ms)
        };
        let g = self.group_mut(slot);
        g.keep_alive = r.value;
        self.schedule_group(slot, now, false);
        Ok(r)
    }

    /// IOPCGroupStateMgt2::GetKeepAlive.
    pub fn keep_alive(&self, group: GroupHandle) -> Result<u32, OpcError> {
        Ok(self.group(self.live_slot(group)?).keep_alive)
    }

    /// IOPCAsyncIO2::SetEnable: enables or disables subscription callbacks (OnDataChange
    /// with transaction ID 0, keep-alives included; refreshes are not affected).
    /// CONNECT_E_NOCONNECTION without a callback sink.
    pub fn set_enable(
        &mut self,
        now: Timestamp,
        group: GroupHandle,
        enable: bool,
    ) -> Result<(), OpcError> {
        let slot = self.live_slot(group)?;
        let g = self.group_mut(slot);
        if !g.connected {
            return Err(OpcError::NoConnection);
        }
        if g.enabled != enable {
            g.enabled = enable;
            self.schedule_group(slot, now, enable);
        }
        Ok(())
    }

    /// IOPCAsyncIO2::GetEnable (CONNECT_E_NOCONNECTION without a callback sink).
    pub fn get_enable(&self, group: GroupHandle) -> Result<bool, OpcError> {
        let g = self.group(self.live_slot(group)?);
        if !g.connected {
            return Err(OpcError::NoConnection);
        }
        Ok(g.enabled)
    }

    /// The session a group belongs to.
    pub fn group_session(&self, group: GroupHandle) -> Result<SessionHandle, OpcError> {
        Ok(self.group(self.live_slot(group)?).session)
    }
}
