//! The OPC DA server model: sessions (one per COM server object), groups, items, the shared
//! item cache, change detection with percent deadband, the update scheduler, synchronous and
//! asynchronous transactions, and the boundary to the data source.
//!
//! # Shape
//!
//! [`Engine`] is a sans-IO state machine (quinn-proto style). It never reads a clock, never
//! blocks and never calls out:
//!
//! - **inputs** are method calls: one per OPC method (`add_group`, `add_items`, `read`,
//!   `refresh2`, ...), plus [`Engine::handle_timeout`] and the data source's
//!   [`Engine::handle_source_updates`], [`Engine::handle_source_read_result`] and
//!   [`Engine::handle_source_write_result`];
//! - **outputs** are polled: [`Engine::poll_event`] (client callbacks: OnDataChange,
//!   OnReadComplete, OnWriteComplete, OnCancelComplete), [`Engine::poll_source_request`]
//!   (subscribe / unsubscribe / device read / write for the backend),
//!   [`Engine::poll_timeout`] (when to call `handle_timeout` next) and
//!   [`Engine::take_sync_result`] (a synchronous device read or write that had to wait for
//!   the data source).
//!
//! # The cache and change detection
//!
//! The engine keeps **one cache entry per source item** (`(channel, source key)` from
//! [`crate::namespace::ItemDef`]), shared by every group item in every session that refers
//! to it. A group item stores only a handful of integers and the value it **last sent** to
//! its group (numbers inline, strings and arrays as a shared reference to the cached value).
//!
//! At each update-rate tick of an active group with a connected, enabled callback, an active
//! item is reported when (OPC DA 2.05a §4.2 / 3.0 §4.5):
//! - it has not been sent since it (or its group, or the callback) became active, or
//! - its quality word changed, or
//! - its value changed; for items with analog EU information and a non-zero percent
//!   deadband (the item's own, else the group's) only when
//!   `|new - last sent| > (EU high - EU low) * deadband / 100` (any element, for arrays).
//!   See [`deadband`].
//!
//! The comparison is against the value last **sent** to that group, never against the
//! previous sample. Values delivered by Refresh2/RefreshMaxAge also become the last sent
//! value.
//!
//! # The first callback
//!
//! An item that is due for its first report but whose cache entry has **no sample from
//! the data source yet** (it was just subscribed) is held back, so that the client's first
//! OnDataChange for it carries its first real value rather than the placeholder
//! `BAD Waiting for Initial Data` (0x20) followed by the real value one update later.
//! The wait is bounded by [`EngineConfig::first_sample_wait_ms`] (default
//! [`DEFAULT_FIRST_SAMPLE_WAIT_MS`] = 3 s, asix's default NetTimeout), measured per group
//! from the first scan that held an item: items still without data then are sent as they
//! are (with the placeholder), and later values follow as usual. While a group holds
//! items, a sample arriving for any of them (a subscription update or a device read)
//! makes the group report its newly ready items at once instead of at its next tick
//! (only the not yet sent items: changes of the others keep the update rate). Items that
//! already have a sample (another group subscribes the same source item, constants, a
//! reactivated item) are never held. Items with data and the other items of the group are
//! not delayed by held ones.
//!
//! In that window Refresh2/RefreshMaxAge and reads from the cache answer from the cache
//! as DA 2.05a/3.0 define them ("the current value in the cache", whatever its quality):
//! a held item reads `BAD Waiting for Initial Data` (OPC_QUALITY_WAITING_FOR_INITIAL_DATA,
//! the code DA 3.0 defines for "no value has been received from the device yet"), and a
//! refresh that delivers it counts as its first report (its real value then follows as a
//! change, at the update rate).
//!
//! # Documented limits and choices
//!
//! - Minimum update rate: [`EngineConfig::min_update_rate_ms`], default
//!   [`DEFAULT_MIN_UPDATE_RATE_MS`] = 1000 ms (AsixConnect §6.6). Shorter requested update
//!   rates, keep-alive times and item sampling rates are raised to it and answered with
//!   OPC_S_UNSUPPORTEDRATE; 0 ("as fast as possible") becomes the minimum too.
//! - Outstanding asynchronous transactions per group:
//!   [`EngineConfig::max_transactions_per_group`], default
//!   [`DEFAULT_MAX_TRANSACTIONS_PER_GROUP`] = 256. A transaction is outstanding from the
//!   call until its completion (or cancel-complete) event has been taken with
//!   `poll_event`. One more call fails with **CONNECT_E_ADVISELIMIT**: it is a failure
//!   code (nothing was queued), it names a limit of the connection rather than a fault of
//!   the server (E_FAIL) or a lie about memory (E_OUTOFMEMORY), and it is exactly what the
//!   original ServerCTOPC returned when its (one per type) queue was full, so existing asix
//!   clients already handle it.
//! - Source requests (device read, write) that get no answer within
//!   [`EngineConfig::source_timeout_ms`] (default [`DEFAULT_SOURCE_TIMEOUT_MS`]) complete
//!   with ASKOM_E_NetAnswerTimeout per item; a late answer is ignored.
//! - Item buffering (IOPCItemSamplingMgt::SetItemBufferEnable): an item whose sampling
//!   rate is faster than its group's update rate keeps every sample between callbacks
//!   (deadband applied to each), at most [`ITEM_BUFFER_SAMPLES`] per item and
//!   [`GROUP_BUFFER_SAMPLES`] per group; an overflow discards the oldest and marks the
//!   item's next oldest sample OPC_S_DATAQUEUEOVERFLOW. See [`buffer`].
//! - Keep-alive callbacks (an OnDataChange with no items) are sent only for an active group
//!   whose callbacks are connected and enabled, when no OnDataChange (subscription or
//!   refresh) was sent for the keep-alive time.
//! - Cache age for MaxAge is measured from the last time the data source delivered a sample
//!   of the item (`handle_source_updates` or a device read); the backend is expected to
//!   push every sample at the subscribed rate, changed or not. Constant items are always
//!   fresh.
//!
//! # Per-item results
//!
//! Every multi-item call returns `Vec<Result<_, OpcError>>` in the order of its input; an
//! empty input list is E_INVALIDARG for the whole call. Success codes that OPC reports per
//! item (OPC_S_UNSUPPORTEDRATE for sampling rates) are carried in the `Ok` value
//! ([`Revised`]).

mod boundary;
pub mod buffer;
mod cache;
pub mod datasource;
pub mod deadband;
mod engine;
mod events;
mod group;
mod item;
mod scheduler;
mod transactions;
mod util;

pub use buffer::{GROUP_BUFFER_SAMPLES, ITEM_BUFFER_SAMPLES};
pub use datasource::{
    ItemVqt, ReadItem, SourceItem, SourceKey, SourceReqId, SourceRequest, Subscription,
};
pub use engine::{
    Engine, EngineConfig, EngineStats, GroupHandle, SessionHandle, DEFAULT_FIRST_SAMPLE_WAIT_MS,
    DEFAULT_MAX_TRANSACTIONS_PER_GROUP, DEFAULT_MIN_UPDATE_RATE_MS, DEFAULT_SOURCE_TIMEOUT_MS,
    SERVER_PENDING_DATA_CHANGES,
};
pub use events::{
    CancelComplete, DataChange, DataChangeKind, Event, ItemState, ItemValue, ReadComplete,
    WriteComplete, WriteResult, MAX_ITEMS_PER_CALLBACK,
};
pub use group::{AddGroupResult, GroupParams, GroupState, RemoveGroupOutcome, SetGroupState};
pub use item::{ItemAttributes, ItemDefinition, ItemResult};
pub use transactions::{
    AsyncStarted, DataSource, ReadResults, SyncId, SyncOutcome, SyncResult, WriteResults,
};

use crate::OpcError;

/// MaxAge that always reads from the device (OPC DA 3.0).
pub const MAX_AGE_DEVICE: u32 = 0;
/// MaxAge that always reads from the cache (OPC DA 3.0: 0xFFFFFFFF).
pub const MAX_AGE_CACHE: u32 = u32::MAX;

/// A rate (update rate, keep-alive time, sampling rate) as the server revised it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Revised {
    /// The rate the server uses, in milliseconds.
    pub value: u32,
    /// True when it differs from the requested rate (answer OPC_S_UNSUPPORTEDRATE).
    pub revised: bool,
}

impl Revised {
    /// OPC_S_UNSUPPORTEDRATE when the rate was revised, `None` (S_OK) otherwise.
    pub fn code(&self) -> Option<OpcError> {
        self.revised.then_some(OpcError::UnsupportedRate)
    }
}
