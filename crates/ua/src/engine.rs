//! The UA front end as a client of the runtime: one engine session for every UA session
//! (named `OPC UA`), reads and writes by item ID through the engine's IOPCItemIO path
//! (`Engine::item_io_read`, `Engine::item_io_write_vqt`: the engine's one write
//! conversion, its MaxAge rule, its source timeouts), and monitored items as items of
//! engine groups, one group per sampling rate, so that a variable has one source
//! subscription whichever front end asked for it.
//!
//! Every call here may wait for the data source (at most the engine's source timeout plus
//! `ctopc_runtime::SYNC_WAIT_MARGIN`): the node manager runs them on tokio's blocking
//! pool.

use ctopc_core::model::{
    ItemState, ItemVqt, SessionHandle, SyncId, SyncOutcome, SyncResult, WriteResults,
};
use ctopc_core::write_rights::Caller;
use ctopc_core::OpcError;
use ctopc_runtime::Runtime;
use std::sync::Arc;
use std::time::Duration;

/// The client name of the UA front end's engine session (logs, `_Diagnostics`, audit).
pub const CLIENT_NAME: &str = "OPC UA";

/// The UA front end's engine session.
pub struct EngineClient {
    pub runtime: Arc<Runtime>,
    pub session: SessionHandle,
}

impl EngineClient {
    /// Opens the front end's engine session.
    pub fn open(runtime: Arc<Runtime>) -> EngineClient {
        let session = runtime.open_session();
        runtime.clients.set_client_name(session, CLIENT_NAME);
        EngineClient { runtime, session }
    }

    fn wait_limit(&self) -> Duration {
        let source_ms = self.runtime.lock().engine.config().source_timeout_ms;
        Duration::from_millis(u64::from(source_ms)) + ctopc_runtime::SYNC_WAIT_MARGIN
    }

    fn wait(&self, id: SyncId) -> Option<SyncResult> {
        let limit = self.wait_limit();
        let r = self.runtime.wait_for(limit, |e| e.take_sync_result(id));
        if r.is_none() {
            tracing::warn!(
                "OPC UA: a request got no answer from the data source within {limit:?}; abandoned"
            );
            self.runtime.with_engine(|e, _| e.abandon_sync(id));
        }
        r
    }

    /// Reads items by ID with a MaxAge in ms (0: the device; `u32::MAX`: the cache).
    pub fn read(&self, items: &[(&str, u32)]) -> Vec<Result<ItemState, OpcError>> {
        let n = items.len();
        if n == 0 {
            return Vec::new();
        }
        let started = self
            .runtime
            .with_engine(|e, now| e.item_io_read(now, self.session, items));
        match started {
            Ok(SyncOutcome::Ready(r)) => r,
            Ok(SyncOutcome::Pending(id)) => match self.wait(id) {
                Some(SyncResult::Read(r)) => r,
                Some(SyncResult::Write(_)) => vec![Err(OpcError::Fail); n],
                None => vec![Err(OpcError::NetAnswerTimeout); n],
            },
            Err(e) => vec![Err(e); n],
        }
    }

    /// Writes items by ID as `caller` (an OPC UA user and its roles): the write-rights
    /// policy decides per item (a refusal is `OPC_E_BADRIGHTS` and `true` in the second
    /// vector, empty when the policy refused nothing), and the write audit logs each.
    pub fn write(&self, items: &[(&str, ItemVqt)], caller: Caller) -> (WriteResults, Vec<bool>) {
        let n = items.len();
        if n == 0 {
            return (Vec::new(), Vec::new());
        }
        let user = match &caller {
            Caller::Ua { user, .. } => user.clone(),
            other => other.to_string(),
        };
        self.runtime
            .clients
            .set_identity(self.session, &caller.to_string());
        // One engine session serves every UA session: the caller is set and used under the
        // same engine lock, so concurrent writers cannot see each other's identity.
        let (started, denied) = self.runtime.with_engine(|e, now| {
            e.set_session_caller(self.session, caller);
            let started = e.item_io_write_vqt(now, self.session, items);
            let ids: Vec<&str> = items.iter().map(|(id, _)| *id).collect();
            (started, e.item_io_denied_by_policy(self.session, &ids))
        });
        let results = match started {
            Ok(SyncOutcome::Ready(r)) => r,
            Ok(SyncOutcome::Pending(id)) => match self.wait(id) {
                Some(SyncResult::Write(r)) => r,
                Some(SyncResult::Read(_)) => vec![Err(OpcError::Fail); n],
                None => vec![Err(OpcError::NetAnswerTimeout); n],
            },
            Err(e) => vec![Err(e); n],
        };
        self.runtime.metrics.written(n as u64);
        let keys: Vec<(Option<&str>, Option<u32>)> =
            items.iter().map(|(id, _)| (Some(*id), None)).collect();
        let values: Vec<ItemVqt> = items.iter().map(|(_, v)| v.clone()).collect();
        let method = format!("OPC UA Write (user {user})");
        let call = ctopc_runtime::clients::WriteCall {
            session: self.session,
            method: &method,
            group: None,
            items: &keys,
            values: &values,
            cancel_id: None,
            denied: &denied,
        };
        self.runtime
            .clients
            .audit_write(ctopc_runtime::clock::now(), &call, &results);
        (results, denied)
    }
}

impl Drop for EngineClient {
    fn drop(&mut self) {
        self.runtime.close_session(self.session);
    }
}
