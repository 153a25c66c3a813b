//! Item buffering (OPC DA 3.0 IOPCItemSamplingMgt::SetItemBufferEnable).
//!
//! An item with buffering enabled whose sampling rate is faster than its group's update
//! rate keeps every sample the data source pushes (subscription updates; device reads
//! refresh the cache only) between two OnDataChange callbacks that passes the item's
//! deadband (against the previous buffered sample, else the value last sent), and the
//! next subscription callback carries them all, oldest first: the same client handle
//! several times. The buffer takes samples only while the item can be
//! reported (group ticking, item active and already sent once since it became active);
//! the first report after (re)activation is the current value, as without buffering.
//!
//! Bounds: [`ITEM_BUFFER_SAMPLES`] per item and [`GROUP_BUFFER_SAMPLES`] per group. A
//! sample that does not fit discards the item's oldest buffered sample; the oldest sample
//! the next callback carries for that item then has the item error
//! OPC_S_DATAQUEUEOVERFLOW (its value and quality are the sample's own; hrMastererror is
//! S_FALSE as for any item error that is not S_OK).
//!
//! Refresh2/RefreshMaxAge answer from the cache, one value per item, and neither use nor
//! empty the buffers. Disabling buffering, removing the item or the group drops its
//! buffer. CloneGroup does not copy the buffer setting.

use std::borrow::Cow;
use std::collections::VecDeque;

use super::cache::CachedValue;
use super::deadband::{band, value_changed};
use super::engine::{Engine, GroupHandle};
use super::events::ItemValue;
use super::item::{ItemFlags, ItemOpts};
use super::transactions::item_value;
use crate::convert::Locale;
use crate::{OpcError, Quality, Timestamp};

/// Samples one item buffers between two callbacks at most.
pub const ITEM_BUFFER_SAMPLES: usize = 256;
/// Samples all buffered items of one group hold together at most.
pub const GROUP_BUFFER_SAMPLES: usize = 16_384;

/// One item's samples not yet sent.
#[derive(Debug, Default)]
pub(crate) struct ItemBuffer {
    samples: VecDeque<(CachedValue, Quality, Timestamp)>,
    /// A sample was discarded since the last callback.
    overflowed: bool,
}

impl ItemBuffer {
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Appends the buffered samples to a callback, oldest first; returns the last one's
    /// value and quality (the item's new "last sent").
    pub fn drain_into(
        self,
        out: &mut Vec<ItemValue>,
        client: u32,
        req: crate::VarType,
        locale: Locale,
    ) -> Option<(CachedValue, Quality)> {
        let mut last = None;
        for (k, (value, quality, timestamp)) in self.samples.into_iter().enumerate() {
            let mut iv = item_value(client, &value, quality, timestamp, req, locale);
            if k == 0 && self.overflowed && iv.error.is_none() {
                iv.error = Some(OpcError::DataQueueOverflow);
            }
            out.push(iv);
            last = Some((value, quality));
        }
        last
    }
}

impl Engine {
    /// IOPCItemSamplingMgt::SetItemBufferEnable. Enabling always succeeds; it takes
    /// effect while the item's sampling rate is faster than the group's update rate.
    /// Disabling drops what the item had buffered.
    pub fn set_item_buffer_enable(
        &mut self,
        group: GroupHandle,
        items: &[(u32, bool)],
    ) -> Result<Vec<Result<(), OpcError>>, OpcError> {
        if items.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let slot = self.live_slot(group)?;
        let Engine {
            groups,
            buffer_refs,
            ..
        } = self;
        let g = groups[slot].as_mut().expect("group");
        let mut out = Vec::with_capacity(items.len());
        for &(h, enable) in items {
            let Some(i) = g.find(h) else {
                out.push(Err(OpcError::InvalidHandle));
                continue;
            };
            let it = &mut g.items[i];
            let refs = buffer_refs.entry(it.source).or_default();
            if enable {
                it.flags.insert(ItemFlags::BUFFERED);
                if !refs.contains(&(group.0, h)) {
                    refs.push((group.0, h));
                }
            } else {
                it.flags.remove(ItemFlags::BUFFERED);
                refs.retain(|&r| r != (group.0, h));
                if refs.is_empty() {
                    buffer_refs.remove(&it.source);
                }
                g.drop_buffer(h);
            }
            out.push(Ok(()));
        }
        Ok(out)
    }

    /// IOPCItemSamplingMgt::GetItemBufferEnable.
    pub fn get_item_buffer_enable(
        &self,
        group: GroupHandle,
        handles: &[u32],
    ) -> Result<Vec<Result<bool, OpcError>>, OpcError> {
        if handles.is_empty() {
            return Err(OpcError::InvalidArg);
        }
        let g = self.group(self.live_slot(group)?);
        Ok(handles
            .iter()
            .map(|&h| {
                g.find(h)
                    .map(|i| g.items[i].flags.contains(ItemFlags::BUFFERED))
                    .ok_or(OpcError::InvalidHandle)
            })
            .collect())
    }

    /// A sample of cache entry `source` was stored: every buffered item referring to it
    /// that can take it buffers it. References to items gone (removed, buffering off,
    /// group removed) are dropped here.
    pub(crate) fn buffer_sample(&mut self, source: u32) {
        let Engine {
            groups,
            group_slots,
            sources,
            buffer_refs,
            ..
        } = self;
        let Some(refs) = buffer_refs.get_mut(&source) else {
            return;
        };
        let e = &sources.entries[source as usize];
        let analog = sources.analog_range(e);
        let s = sources.sample(e);
        refs.retain(|&(gh, h)| {
            let Some(&slot) = group_slots.get(&gh) else {
                return false;
            };
            let Some(g) = groups[slot as usize].as_mut() else {
                return false;
            };
            let Some(i) = g.find(h) else {
                return false;
            };
            let ticking = g.ticking();
            let rate = g.update_rate;
            let group_deadband = g.deadband;
            let it = &g.items[i];
            if it.source != source || !it.flags.contains(ItemFlags::BUFFERED) {
                return false;
            }
            let sampling = ItemOpts::sampling(&g.opts, it);
            if !ticking
                || !it.flags.contains(ItemFlags::ACTIVE | ItemFlags::SENT)
                || sampling == 0
                || sampling >= rate
            {
                return true;
            }
            let buf = g.buffers.entry(h).or_default();
            let (ref_value, ref_quality) = buf
                .samples
                .back()
                .map_or((it.last(&g.lasts), it.last_quality), |(v, q, _)| {
                    (Cow::Borrowed(v), *q)
                });
            if s.quality == ref_quality
                && !value_changed(
                    &s.value,
                    &ref_value,
                    band(ItemOpts::deadband(&g.opts, it), group_deadband, analog),
                )
            {
                return true;
            }
            buf.samples
                .push_back((CachedValue::clone(&s.value), s.quality, s.timestamp));
            g.buffered += 1;
            if buf.samples.len() > ITEM_BUFFER_SAMPLES || g.buffered > GROUP_BUFFER_SAMPLES {
                buf.samples.pop_front();
                buf.overflowed = true;
                g.buffered -= 1;
            }
            g.needs_scan = true;
            true
        });
        if refs.is_empty() {
            buffer_refs.remove(&source);
        }
    }
}

impl super::group::Group {
    /// Forgets an item's buffered samples.
    pub(crate) fn drop_buffer(&mut self, handle: u32) {
        if let Some(b) = self.buffers.remove(&handle) {
            self.buffered -= b.len();
        }
    }
}
