//! The OPC UA front end: the variable set as an OPC UA address space (OPC UA Part 8
//! Annex A's mapping of DA), served lazily from the namespace, with Read, Write and
//! monitored items through the shared runtime's engine, as a client of the runtime like
//! the COM layer.
//!
//! - [`space`]: what a NodeId names, its attributes and references (no node objects);
//! - [`node_manager`]: async-opcua's `NodeManager` over it;
//! - [`engine`]: the front end's engine session (reads, writes, the write audit);
//! - [`monitor`]: monitored items as items of engine groups, one per rate;
//! - [`status`], [`value`]: quality, errors and values in UA terms;
//! - [`limits`]: the limits, onto async-opcua's, and the ones the front end counts;
//! - [`server`]: the server (endpoints, certificates, limits), [`auth`] and [`users`]:
//!   who may connect and write.

#![forbid(unsafe_code)]

pub mod auth;
pub mod engine;
pub mod limits;
pub mod monitor;
pub mod node_manager;
pub mod pki;
pub mod server;
pub mod space;
pub mod status;
pub mod users;
pub mod value;
