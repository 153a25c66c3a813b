//! The driver's pure part: one step of the loop that runs the engine's scheduler and moves
//! data between the engine and its data source, and the bookkeeping of paced OnDataChange
//! calls. Sans-IO like the engine: no threads, no clock (`now` is an argument), no COM.
//!
//! The runtime (`crates/runtime/src/runtime.rs`) owns the threads: a driver thread that
//! locks the [`Driver`] and calls [`Driver::step`] whenever it is woken or [`Step::next`] is
//! due, and one callback worker per client. It hands the step's events to [`dispatch`] with
//! a [`Deliver`] that queues each on its client's worker, where the front end makes the
//! call.
//!
//! Pacing (`EngineConfig::max_pending_data_changes`): every scheduled OnDataChange
//! ([`is_paced`]) that is handed to a client is reported back as [`Report::Ended`] once its
//! call returned or failed; one that could not be queued is reported at once by
//! [`dispatch`]. The reports go into the next [`Driver::step`], which tells the engine
//! (`Engine::data_change_delivered`). A worker that finds its client gone reports
//! [`Report::Disconnected`] the same way, so that no worker ever waits for the engine.
//!
//! Synchronous callers (IOPCSyncIO, IOPCItemIO) wait for their own result with
//! `Engine::take_sync_result`; [`Step::sync_completed`] says after which step one of them
//! has an answer, so the runtime wakes its waiters only then.

use crate::model::{Engine, Event, GroupHandle, SyncId};
use crate::source::{Backend, SourceOutput};
use crate::Timestamp;

/// What a client's callback worker reports back to the driver (through the COM layer's
/// queue; applied at the start of the next [`Driver::step`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Report {
    /// A scheduled OnDataChange of the group is done with: delivered, failed, or never
    /// queued. The engine may schedule the group's next one.
    Ended(GroupHandle),
    /// The group's IOPCDataCallback is gone (the call failed as disconnected and the sink was
    /// dropped): the engine stops scheduling callbacks for the group until a new Advise.
    Disconnected(GroupHandle),
}

/// The events of one step and when to run the next.
#[derive(Debug, Default)]
pub struct Step {
    /// Callbacks to make, in the engine's order.
    pub events: Vec<Event>,
    /// Synchronous operations whose answer became available in this step (their results
    /// are in `Engine::take_sync_result`).
    pub sync_completed: Vec<SyncId>,
    /// When the engine or the source needs the next step without a wake-up (None: only
    /// when woken).
    pub next: Option<Timestamp>,
}

/// Where a step's events go: the COM layer queues each on its client's callback worker.
pub trait Deliver {
    /// Queues `event` to its client; `false` when it cannot be queued (no sink connected
    /// for the group, no worker for the session). When `paced` is true and the event was
    /// queued, the receiver promises a [`Report::Ended`] for `event.group()` once the call
    /// is done with, whatever its outcome.
    fn deliver(&mut self, event: Event, paced: bool) -> bool;
}

/// True for the callbacks whose delivery paces the update scheduler: subscription updates
/// and keep-alives (not the completions of a client's own requests).
pub fn is_paced(event: &Event) -> bool {
    matches!(event, Event::DataChange(d) if d.kind.is_scheduled())
}

/// Hands every event to `out`. Returns the reports of the paced ones that could not be
/// queued (hand them to the next [`Driver::step`]), so that a group without a listener
/// never holds its pacing slots.
pub fn dispatch(events: Vec<Event>, out: &mut impl Deliver) -> Vec<Report> {
    let mut not_queued = Vec::new();
    for event in events {
        let group = event.group();
        let paced = is_paced(&event);
        if !out.deliver(event, paced) && paced {
            not_queued.push(Report::Ended(group));
        }
    }
    not_queued
}

/// The engine and its data source, driven together. The engine is open to the COM
/// objects (one call per COM method, under the runtime's lock); the source is reached only
/// through [`Driver::step`].
pub struct Driver {
    pub engine: Engine,
    source: Box<dyn Backend>,
}

impl Driver {
    pub fn new(engine: Engine, source: Box<dyn Backend>) -> Driver {
        Driver { engine, source }
    }

    /// Applies the workers' reports, then one step: source in, timers, requests out, source
    /// in again (an in-process source answers at once) and the timers due after it. Returns the events to deliver, the
    /// synchronous operations completed, and when to run next.
    pub fn step(&mut self, now: Timestamp, reports: impl IntoIterator<Item = Report>) -> Step {
        for report in reports {
            match report {
                Report::Ended(group) => self.engine.data_change_delivered(now, group),
                Report::Disconnected(group) => {
                    // A group removed meanwhile has nothing left to disconnect.
                    let _ = self.engine.set_callback_connected(now, group, false);
                }
            }
        }
        self.pull_source(now);
        if self.engine.poll_timeout().is_some_and(|t| t <= now) {
            self.engine.handle_timeout(now);
        }
        let mut asked = false;
        while let Some(req) = self.engine.poll_source_request() {
            self.source.request(now, req);
            asked = true;
        }
        if asked {
            self.pull_source(now);
            // What the source answered at once may be due now (the first samples of newly
            // subscribed items, which their groups were holding back).
            if self.engine.poll_timeout().is_some_and(|t| t <= now) {
                self.engine.handle_timeout(now);
            }
        }
        let sync_completed = std::iter::from_fn(|| self.engine.poll_sync_completion()).collect();
        let events = std::iter::from_fn(|| self.engine.poll_event()).collect();
        let next = match (self.engine.poll_timeout(), self.source.poll_timeout()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        Step {
            events,
            sync_completed,
            next,
        }
    }

    /// What the data source says of its channels ([`Backend::channels`]).
    pub fn channels(&self) -> Vec<crate::diagnostics::ChannelStatus> {
        self.source.channels()
    }

    /// Moves everything the source has ready into the engine.
    fn pull_source(&mut self, now: Timestamp) {
        let mut out = SourceOutput::default();
        self.source.poll(now, &mut out);
        if !out.updates.is_empty() {
            self.engine.handle_source_updates(now, out.updates);
        }
        for (id, results) in out.read_results {
            self.engine.handle_source_read_result(now, id, results);
        }
        for (id, results) in out.write_results {
            self.engine.handle_source_write_result(now, id, results);
        }
    }
}
