//! The update scheduler: group update-rate ticks, keep-alives and source-request timeouts,
//! driven by `poll_timeout()` / `handle_timeout(now)`; the event queue (`poll_event`).
//!
//! Each ticking group (active, live, callback connected and enabled) has one valid entry in
//! a binary heap, keyed by its next deadline: the next update tick, or the keep-alive
//! deadline when that comes first. Stale entries (the group was rescheduled or removed)
//! are skipped lazily. A group's first tick after it starts ticking is immediate; ticks
//! then keep their phase (a late `handle_timeout` skips the missed periods instead of
//! bursting).

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::deadband::{band, value_changed};
use super::engine::Engine;
use super::events::{master_codes, DataChange, DataChangeKind, Event};
use super::item::{ItemFlags, ItemOpts};
use super::transactions::item_value;
use crate::convert::Locale;
use crate::{OpcError, Timestamp};

#[derive(Default)]
pub(crate) struct Scheduler {
    /// (deadline, group slot, group sched_seq).
    groups: BinaryHeap<Reverse<(Timestamp, u32, u32)>>,
    /// (deadline, source request id).
    pub timeouts: BinaryHeap<Reverse<(Timestamp, u64)>>,
}

impl Engine {
    fn valid_wake(&self, slot: u32, seq: u32) -> bool {
        matches!(self.groups.get(slot as usize), Some(Some(g)) if g.sched_seq == seq && g.wake.is_some())
    }

    /// (Re)computes a group's deadline. `start_now`: the group (re)starts ticking, its
    /// first update is due at once and the keep-alive period starts now.
    pub(crate) fn schedule_group(&mut self, slot: usize, now: Timestamp, start_now: bool) {
        let paces = self.cfg.paces();
        let max_pending = self.cfg.max_pending_data_changes;
        let g = self.groups[slot].as_mut().expect("group");
        if !g.ticking() {
            g.wake = None;
            g.sched_seq = g.sched_seq.wrapping_add(1);
            return;
        }
        if start_now {
            g.next_update = now;
            g.last_callback = now;
            g.first_sample_until = None;
            g.first_sample_ready = false;
        }
        let mut due = g.next_update;
        if g.keep_alive > 0 {
            due = due.min(g.last_callback.add_millis(u64::from(g.keep_alive)));
        }
        // Held items are due when their sample arrived or the wait ends, unless the client
        // is still busy with the group's callbacks (then the delivery's end reschedules).
        if let Some(until) = g.first_sample_until {
            if !(paces && g.delivering >= max_pending) {
                due = due.min(if g.first_sample_ready { now } else { until });
            }
        }
        if !matches!(g.wake, Some(w) if w <= due) {
            g.sched_seq = g.sched_seq.wrapping_add(1);
            g.wake = Some(due);
            self.sched
                .groups
                .push(Reverse((due, slot as u32, g.sched_seq)));
        }
    }

    /// When `handle_timeout` must be called next (`None`: nothing scheduled).
    pub fn poll_timeout(&mut self) -> Option<Timestamp> {
        let mut next = None;
        while let Some(&Reverse((t, slot, seq))) = self.sched.groups.peek() {
            if self.valid_wake(slot, seq) {
                next = Some(t);
                break;
            }
            self.sched.groups.pop();
        }
        while let Some(&Reverse((t, req))) = self.sched.timeouts.peek() {
            if self.txns.by_req.contains_key(&req) {
                next = Some(next.map_or(t, |n: Timestamp| n.min(t)));
                break;
            }
            self.sched.timeouts.pop();
        }
        next
    }

    /// Runs everything due at `now`: group updates (OnDataChange of changed items),
    /// keep-alives, and source-request timeouts.
    pub fn handle_timeout(&mut self, now: Timestamp) {
        while let Some(&Reverse((t, slot, seq))) = self.sched.groups.peek() {
            if t > now {
                break;
            }
            self.sched.groups.pop();
            if !self.valid_wake(slot, seq) {
                continue;
            }
            self.group_mut(slot as usize).wake = None;
            self.run_group(slot as usize, now);
        }
        while let Some(&Reverse((t, req))) = self.sched.timeouts.peek() {
            if t > now {
                break;
            }
            self.sched.timeouts.pop();
            self.fail_source_request(now, req, OpcError::NetAnswerTimeout);
        }
    }

    /// The next callback for the client, in the order they were produced.
    pub fn poll_event(&mut self) -> Option<Event> {
        let ev = self.events.pop_front()?;
        if ev.cancel_id() != 0 {
            if let Some(&slot) = self.group_slots.get(&ev.group().0) {
                if let Some(g) = self.groups[slot as usize].as_mut() {
                    g.outstanding = g.outstanding.saturating_sub(1);
                }
            }
        }
        Some(ev)
    }

    /// With `EngineConfig::max_pending_data_changes`: the delivery of one of `group`'s
    /// scheduled OnDataChange calls (subscription or keep-alive) ended, whatever its
    /// outcome. An update that fell due while the group was at its limit runs now (it is at
    /// least one update period after the previous one); otherwise the group waits for its
    /// next tick. Unknown groups are ignored (the group may have gone while its callback
    /// was under way).
    pub fn data_change_delivered(&mut self, now: Timestamp, group: super::GroupHandle) {
        let Some(&slot) = self.group_slots.get(&group.0) else {
            return;
        };
        let slot = slot as usize;
        let Some(g) = self.groups[slot].as_mut() else {
            return;
        };
        g.delivering = g.delivering.saturating_sub(1);
        if std::mem::take(&mut g.update_missed) {
            g.next_update = g.next_update.min(now);
        }
        self.schedule_group(slot, now, false);
    }

    fn run_group(&mut self, slot: usize, now: Timestamp) {
        if !self.group(slot).ticking() {
            return;
        }
        if self.cfg.paces() && self.group(slot).delivering >= self.cfg.max_pending_data_changes {
            // The client is still busy with the previous callbacks: nothing new is queued
            // (no keep-alive either); the update runs when that delivery ends.
            let g = self.group_mut(slot);
            if now >= g.next_update {
                g.update_missed = true;
                g.skip_to_next_update(now);
            }
            g.last_callback = now;
            self.schedule_group(slot, now, false);
            return;
        }
        let mut sent = false;
        if now >= self.group(slot).next_update {
            sent = self.scan_group(slot, now, false);
            let g = self.group_mut(slot);
            if g.next_update <= now {
                g.skip_to_next_update(now);
            }
        } else if let Some(until) = self.group(slot).first_sample_until {
            // Between ticks: held items got their first sample, or the wait is over.
            let g = self.group_mut(slot);
            if std::mem::take(&mut g.first_sample_ready) || now >= until {
                sent = self.scan_group(slot, now, true);
            }
        }
        let pace = u32::from(self.cfg.paces());
        let g = self.group_mut(slot);
        if !sent && g.keep_alive > 0 && now >= g.last_callback.add_millis(u64::from(g.keep_alive)) {
            g.last_callback = now;
            g.delivering += pace;
            let ev = Event::DataChange(DataChange {
                session: g.session,
                group: g.handle,
                client_group: g.client_handle,
                kind: DataChangeKind::KeepAlive,
                transaction_id: 0,
                cancel_id: 0,
                master_quality: None,
                master_error: None,
                items: Vec::new(),
            });
            self.events.push_back(ev);
        }
        self.schedule_group(slot, now, false);
    }

    /// A sample arrived (subscription update, device read): groups holding items for their
    /// first sample report the ready ones at once.
    pub(crate) fn wake_first_sample_waiters(&mut self, now: Timestamp) {
        if self.first_sample_waiters.is_empty() {
            return;
        }
        let mut slots = std::mem::take(&mut self.first_sample_waiters);
        slots.sort_unstable();
        slots.dedup();
        slots.retain(|&slot| {
            matches!(self.groups.get(slot as usize), Some(Some(g)) if g.first_sample_until.is_some())
        });
        for &slot in &slots {
            let g = self.group_mut(slot as usize);
            if !g.first_sample_ready {
                g.first_sample_ready = true;
                self.schedule_group(slot as usize, now, false);
            }
        }
        self.first_sample_waiters = slots;
    }

    /// Change detection for one group: queues an OnDataChange with every active item whose
    /// quality changed or whose value changed beyond the deadband since it was last sent,
    /// holding back items without a first sample (bounded: "The first callback" in
    /// `crate::model`). `first_only`: a scan between ticks, of the items not yet sent only.
    /// True when something was sent.
    fn scan_group(&mut self, slot: usize, now: Timestamp, first_only: bool) -> bool {
        let Engine {
            groups,
            sources,
            events,
            sessions,
            change_seq,
            cfg,
            first_sample_waiters,
            ..
        } = self;
        let g = groups[slot].as_mut().expect("group");
        if !first_only && !g.needs_scan && g.scanned_seq == *change_seq {
            return false;
        }
        g.first_sample_ready = false;
        // Hold items without data while the group's wait runs (it starts now if none does).
        let holding = cfg.first_sample_wait_ms > 0 && g.first_sample_until.is_none_or(|u| now < u);
        let mut held = 0usize;
        let locale = Locale::from_lcid(g.lcid, cfg.default_locale);
        let scanned = g.scanned_seq;
        let group_deadband = g.deadband;
        // Room for every item at once: growing by doubling copies the values reported so
        // far at each step (on Windows' heap a realloc of a large block always copies),
        // and pages never written are never committed.
        let mut items = Vec::with_capacity(g.items.len());
        for it in g.items.iter_mut() {
            if !it.flags.contains(ItemFlags::ACTIVE) {
                continue;
            }
            let e = &sources.entries[it.source as usize];
            let s = sources.sample(e);
            if !it.flags.contains(ItemFlags::SENT) && holding && !s.has_value() {
                held += 1;
                continue;
            }
            if first_only && it.flags.contains(ItemFlags::SENT) {
                continue;
            }
            if it.flags.contains(ItemFlags::BUFFERED) && !first_only {
                // Buffered samples first, oldest first (`model/buffer.rs`); the current
                // value follows only if it moved on since the last of them.
                if let Some(buf) = g.buffers.remove(&it.handle) {
                    g.buffered -= buf.len();
                    if it.flags.contains(ItemFlags::SENT) {
                        if let Some((v, q)) =
                            buf.drain_into(&mut items, it.client, it.req_type, locale)
                        {
                            it.set_last(&mut g.lasts, v, q);
                        }
                    }
                }
            }
            if it.flags.contains(ItemFlags::SENT)
                && (s.changed_seq <= scanned
                    || (s.quality == it.last_quality
                        && !value_changed(
                            &s.value,
                            &it.last(&g.lasts),
                            band(
                                ItemOpts::deadband(&g.opts, it),
                                group_deadband,
                                sources.analog_range(e),
                            ),
                        )))
            {
                continue;
            }
            items.push(item_value(
                it.client,
                &s.value,
                s.quality,
                s.timestamp,
                it.req_type,
                locale,
            ));
            it.set_last(&mut g.lasts, s.value.into_owned(), s.quality);
            it.flags.insert(ItemFlags::SENT);
        }
        if held == 0 {
            g.first_sample_until = None;
            g.first_sample_ready = false;
        } else if g.first_sample_until.is_none() {
            g.first_sample_until = Some(now.add_millis(u64::from(cfg.first_sample_wait_ms)));
            first_sample_waiters.push(slot as u32);
        }
        if !first_only {
            // (A scan of the unsent items only must not hide the others' changes.)
            g.scanned_seq = *change_seq;
        }
        if first_only {
            g.needs_scan |= held > 0;
        } else {
            g.needs_scan = held > 0;
        }
        if items.is_empty() {
            return false;
        }
        let (master_quality, master_error) = master_codes(&items);
        events.push_back(Event::DataChange(DataChange {
            session: g.session,
            group: g.handle,
            client_group: g.client_handle,
            kind: DataChangeKind::Subscription,
            transaction_id: 0,
            cancel_id: 0,
            master_quality,
            master_error,
            items,
        }));
        g.last_callback = now;
        g.delivering += u32::from(cfg.paces());
        if let Some(s) = sessions.get_mut(&g.session.0) {
            s.last_update = now;
        }
        true
    }
}
