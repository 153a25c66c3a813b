//! The server's portable runtime, between the pure core (`ctopc-core`) and its front ends
//! (OPC DA over COM in `ctopc-com`; OPC UA): the threads that run the engine, and the
//! operations kept beside it.
//!
//! - [`Runtime`]: the engine and its data source under one lock, the driver thread that
//!   steps them ([`ctopc_core::driver::Driver::step`]) whenever woken or due, the
//!   synchronous-call waits, the report queue of the pacing acknowledgement, and one
//!   callback worker per client session.
//! - [`frontend`]: what a front end plugs in: a [`GroupSink`] per group (how a callback
//!   reaches its client), a [`SessionSink`] per session (the shutdown request) and a
//!   [`ThreadHook`] run first on every thread the runtime starts (COM: join the MTA).
//! - [`clients`]: client names, the write audit and each client's callback watch
//!   (`ctopc_core::ops::CallbackWatch` decides; this keeps it per session).
//! - [`metrics_http`] and [`prometheus`]: the metrics endpoint and the text it serves,
//!   the only places that know HTTP and the Prometheus text format.
//!
//! No `windows` dependency and no `unsafe`: built and tested natively.

#![forbid(unsafe_code)]

pub mod clients;
pub mod clock;
pub mod frontend;
pub mod metrics_http;
pub mod prometheus;
mod runtime;
pub mod secret_file;
pub mod start;

pub use frontend::{Delivery, GroupSink, SessionSink, ThreadHook};
pub use runtime::{Runtime, SYNC_WAIT_MARGIN};
pub use start::{start, MakeBackend, Started};
