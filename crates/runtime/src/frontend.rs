//! What a front end plugs into the [`Runtime`](crate::Runtime): the runtime decides when a
//! callback is made and on which thread; the front end makes it (COM: VARIANT conversion
//! and `IOPCDataCallback::OnDataChange`, the DA 1.0a `IAdviseSink`; UA: its subscriptions'
//! queues).

use ctopc_core::model::{Event, GroupHandle};

/// Run first on every thread the runtime starts (the driver, the callback workers, the
/// threads that drop a client's sinks or send a shutdown request); what it returns is
/// dropped when the thread ends. COM joins the multithreaded apartment here.
pub type ThreadHook = fn() -> Box<dyn std::any::Any>;

/// A thread hook that does nothing (a front end with no thread state).
pub fn no_thread_state() -> Box<dyn std::any::Any> {
    Box::new(())
}

/// What one callback came to.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Delivery {
    /// A client was called (its duration counts in the metrics).
    pub called: bool,
    /// The client is gone and its listener was dropped: the engine must hear of it.
    pub lost: bool,
}

/// A group's connection to its client, registered with
/// [`Runtime::set_group_sink`](crate::Runtime::set_group_sink).
pub trait GroupSink: Send + Sync {
    /// Makes the callback `event` of `group` to the client, on the client session's
    /// callback worker, with no runtime lock held. It may block as long as the client does.
    fn deliver(&self, group: GroupHandle, event: Event) -> Delivery;

    /// True while a client listens to the group (a report that its listener was lost is
    /// stale then: it was connected again meanwhile).
    fn is_connected(&self) -> bool;

    /// Drops the client's listener after too many failed or slow callbacks; true when one
    /// was dropped. Called on a thread of its own: releasing a hung client may itself hang.
    fn drop_listener(&self) -> bool;
}

/// A client session's shutdown listener (`IOPCShutdown`), registered with
/// [`Runtime::set_session_sink`](crate::Runtime::set_session_sink).
pub trait SessionSink: Send + Sync {
    /// Asks the client to disconnect, with `reason`; on a thread of its own, bounded by the
    /// runtime's wait.
    fn shutdown_request(&self, reason: &str);
}
