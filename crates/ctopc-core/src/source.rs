//! The data-source side of the boundary, sans-IO: what the server's driver loop calls on a
//! backend (the in-process plant simulation, the asix network client adapter, a test fake).
//!
//! The driver loop hands every [`SourceRequest`] from `Engine::poll_source_request` to
//! [`Backend::request`], and collects what is ready with [`Backend::poll`] into
//! `Engine::handle_source_updates` / `handle_source_read_result` /
//! `handle_source_write_result`. Neither call may block. A backend with its own threads
//! (the network client) wakes the loop through the [`Wake`] it was given when something
//! arrives; a timed backend (a simulator) says when it next has samples with
//! [`Backend::poll_timeout`].

use crate::model::datasource::{SourceKey, SourceReqId, SourceRequest};
use crate::{OpcError, Timestamp, Vqt};

/// What a backend has ready for the engine.
#[derive(Debug, Default)]
pub struct SourceOutput {
    pub updates: Vec<(SourceKey, Vqt)>,
    pub read_results: Vec<(SourceReqId, Vec<Result<Vqt, OpcError>>)>,
    pub write_results: Vec<(SourceReqId, Vec<Result<(), OpcError>>)>,
}

impl SourceOutput {
    pub fn is_empty(&self) -> bool {
        self.updates.is_empty() && self.read_results.is_empty() && self.write_results.is_empty()
    }
}

/// Wakes the driver loop (from any thread).
pub trait Wake: Send + Sync {
    fn wake(&self);
}

/// A backend of the engine. Never blocks.
pub trait Backend: Send {
    /// Takes one request of the engine.
    fn request(&mut self, now: Timestamp, req: SourceRequest);
    /// Appends everything that is ready by `now` to `out`.
    fn poll(&mut self, now: Timestamp, out: &mut SourceOutput);
    /// When `poll` should be called next without a wake-up (None: only when woken).
    fn poll_timeout(&self) -> Option<Timestamp>;
    /// The server state this backend implies: `true` when it simulates current data
    /// (OPC_STATUS_TEST), `false` for real data.
    fn is_simulation(&self) -> bool {
        false
    }
    /// The state of each channel to the data servers, for the `_Diagnostics` branch
    /// ([`crate::diagnostics`]); called at most once per snapshot. Default: none.
    fn channels(&self) -> Vec<crate::diagnostics::ChannelStatus> {
        Vec::new()
    }
}
