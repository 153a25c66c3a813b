//! Outputs for the client: the IOPCDataCallback calls, and synchronous read results.

use super::engine::{GroupHandle, SessionHandle};
use crate::{OpcError, Quality, Timestamp, Value};

/// One item of an OnDataChange or OnReadComplete callback.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemValue {
    pub client_handle: u32,
    /// Converted to the item's requested type (VT_EMPTY when `error` is set).
    pub value: Value,
    pub quality: Quality,
    pub timestamp: Timestamp,
    /// `None` is S_OK.
    pub error: Option<OpcError>,
}

/// One item of a synchronous read (OPCITEMSTATE; the client handle is ignored by
/// ReadMaxAge).
#[derive(Debug, Clone, PartialEq)]
pub struct ItemState {
    pub client_handle: u32,
    pub value: Value,
    pub quality: Quality,
    pub timestamp: Timestamp,
}

/// Why an OnDataChange is sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataChangeKind {
    /// Subscription update at the update rate (transaction ID 0).
    Subscription,
    /// Completion of Refresh2 / RefreshMaxAge (the client's transaction ID).
    Refresh,
    /// Keep-alive: no items, transaction ID 0 (OPC DA 3.0 IOPCGroupStateMgt2).
    KeepAlive,
}

impl DataChangeKind {
    /// Produced by the update scheduler (paced by delivery with
    /// `EngineConfig::max_pending_data_changes`), not in answer to a client's request.
    pub fn is_scheduled(self) -> bool {
        matches!(
            self,
            DataChangeKind::Subscription | DataChangeKind::KeepAlive
        )
    }
}

/// IOPCDataCallback::OnDataChange.
#[derive(Debug, Clone, PartialEq)]
pub struct DataChange {
    pub session: SessionHandle,
    pub group: GroupHandle,
    /// hGroup: the group's client handle.
    pub client_group: u32,
    pub kind: DataChangeKind,
    pub transaction_id: u32,
    /// The server's cancel ID of a refresh (0 for subscription and keep-alive callbacks).
    pub cancel_id: u32,
    /// hrMasterquality: `None` (S_OK) when every quality is GOOD, else S_FALSE.
    pub master_quality: Option<OpcError>,
    /// hrMastererror: `None` (S_OK) when every item error is S_OK, else S_FALSE.
    pub master_error: Option<OpcError>,
    pub items: Vec<ItemValue>,
}

/// The most items one scheduled OnDataChange call carries. A subscription update of more
/// items is delivered as several calls ([`DataChange::calls`]), so that the server never
/// holds one client call's VARIANTs, arrays and marshalling buffer for every item of a
/// large group at once (the peak of a 100,000-item subscription).
pub const MAX_ITEMS_PER_CALLBACK: usize = 10_000;

impl DataChange {
    /// The OnDataChange calls this data change is delivered in, each with its
    /// hrMasterquality, hrMastererror and items. A subscription update is split into
    /// calls of at most [`MAX_ITEMS_PER_CALLBACK`] items, in order, each call's master
    /// codes those of its own items (OPC DA: they summarise the call's arrays); a refresh
    /// completion (one call per transaction ID, as clients expect) and a keep-alive are
    /// one call with the event's codes.
    pub fn calls(&self) -> Vec<(Option<OpcError>, Option<OpcError>, &[ItemValue])> {
        if self.kind != DataChangeKind::Subscription || self.items.len() <= MAX_ITEMS_PER_CALLBACK {
            return vec![(self.master_quality, self.master_error, &self.items[..])];
        }
        self.items
            .chunks(MAX_ITEMS_PER_CALLBACK)
            .map(|chunk| {
                let (q, e) = master_codes(chunk);
                (q, e, chunk)
            })
            .collect()
    }
}

/// IOPCDataCallback::OnReadComplete (async Read / ReadMaxAge).
#[derive(Debug, Clone, PartialEq)]
pub struct ReadComplete {
    pub session: SessionHandle,
    pub group: GroupHandle,
    pub client_group: u32,
    pub transaction_id: u32,
    pub cancel_id: u32,
    pub master_quality: Option<OpcError>,
    pub master_error: Option<OpcError>,
    pub items: Vec<ItemValue>,
}

/// One item of OnWriteComplete.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WriteResult {
    pub client_handle: u32,
    /// `None` is S_OK.
    pub error: Option<OpcError>,
}

/// IOPCDataCallback::OnWriteComplete (async Write / WriteVQT).
#[derive(Debug, Clone, PartialEq)]
pub struct WriteComplete {
    pub session: SessionHandle,
    pub group: GroupHandle,
    pub client_group: u32,
    pub transaction_id: u32,
    pub cancel_id: u32,
    pub master_error: Option<OpcError>,
    pub items: Vec<WriteResult>,
}

/// IOPCDataCallback::OnCancelComplete.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CancelComplete {
    pub session: SessionHandle,
    pub group: GroupHandle,
    pub client_group: u32,
    pub transaction_id: u32,
    pub cancel_id: u32,
}

/// A callback to deliver to a group's IOPCDataCallback sink.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    DataChange(DataChange),
    ReadComplete(ReadComplete),
    WriteComplete(WriteComplete),
    CancelComplete(CancelComplete),
}

impl Event {
    pub fn session(&self) -> SessionHandle {
        match self {
            Event::DataChange(e) => e.session,
            Event::ReadComplete(e) => e.session,
            Event::WriteComplete(e) => e.session,
            Event::CancelComplete(e) => e.session,
        }
    }
    pub fn group(&self) -> GroupHandle {
        match self {
            Event::DataChange(e) => e.group,
            Event::ReadComplete(e) => e.group,
            Event::WriteComplete(e) => e.group,
            Event::CancelComplete(e) => e.group,
        }
    }
    /// The cancel ID of an asynchronous transaction's completion; 0 for subscription
    /// updates and keep-alives.
    pub fn cancel_id(&self) -> u32 {
        match self {
            Event::DataChange(e) => e.cancel_id,
            Event::ReadComplete(e) => e.cancel_id,
            Event::WriteComplete(e) => e.cancel_id,
            Event::CancelComplete(e) => e.cancel_id,
        }
    }
}

/// hrMasterquality and hrMastererror for a list of items.
pub(crate) fn master_codes(items: &[ItemValue]) -> (Option<OpcError>, Option<OpcError>) {
    let quality = if items.iter().all(|i| i.quality.is_good()) {
        None
    } else {
        Some(OpcError::False)
    };
    let error = if items.iter().all(|i| i.error.is_none()) {
        None
    } else {
        Some(OpcError::False)
    };
    (quality, error)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn change(kind: DataChangeKind, n: usize, bad: &[usize]) -> DataChange {
        let items = (0..n)
            .map(|i| ItemValue {
                client_handle: i as u32,
                value: Value::I4(i as i32),
                quality: if bad.contains(&i) {
                    Quality::BAD
                } else {
                    Quality::GOOD
                },
                timestamp: Timestamp(0),
                error: None,
            })
            .collect::<Vec<_>>();
        let (master_quality, master_error) = master_codes(&items);
        DataChange {
            session: SessionHandle(1),
            group: GroupHandle(1),
            client_group: 7,
            kind,
            transaction_id: 0,
            cancel_id: 0,
            master_quality,
            master_error,
            items,
        }
    }

    #[test]
    fn a_large_subscription_update_is_split_with_each_calls_own_master_codes() {
        let n = 2 * MAX_ITEMS_PER_CALLBACK + 5;
        let d = change(
            DataChangeKind::Subscription,
            n,
            &[MAX_ITEMS_PER_CALLBACK + 3],
        );
        let calls = d.calls();
        let sizes: Vec<usize> = calls.iter().map(|c| c.2.len()).collect();
        assert_eq!(sizes, [MAX_ITEMS_PER_CALLBACK, MAX_ITEMS_PER_CALLBACK, 5]);
        let qualities: Vec<Option<OpcError>> = calls.iter().map(|c| c.0).collect();
        assert_eq!(qualities, [None, Some(OpcError::False), None]);
        // In order, every item once.
        let handles: Vec<u32> = calls
            .iter()
            .flat_map(|c| c.2.iter().map(|i| i.client_handle))
            .collect();
        assert_eq!(handles, (0..n as u32).collect::<Vec<_>>());
    }

    #[test]
    fn small_updates_and_refreshes_are_one_call_with_the_events_codes() {
        let small = change(DataChangeKind::Subscription, MAX_ITEMS_PER_CALLBACK, &[0]);
        let calls = small.calls();
        assert_eq!(calls.len(), 1);
        assert_eq!(calls[0].0, Some(OpcError::False));
        let refresh = change(DataChangeKind::Refresh, 3 * MAX_ITEMS_PER_CALLBACK, &[]);
        let calls = refresh.calls();
        assert_eq!(calls.len(), 1);
        assert_eq!(calls[0].2.len(), 3 * MAX_ITEMS_PER_CALLBACK);
    }
}
