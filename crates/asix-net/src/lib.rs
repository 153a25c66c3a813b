//! The asix network of ServerCTOPC: how the OPC server reaches asix data servers.
//!
//! - [`proto`]: the versioned wire protocol (UDP discovery datagrams, framed TCP link),
//!   documented for gateway writers in `docs/asix-net-protocol.md`.
//! - [`client`]: the discovery-and-failover client ([`AsixClient`], a non-blocking handle
//!   over a sans-IO [`client::ClientCore`]).
//! - [`backend`]: the one asix data-source `Backend`, [`backend::AsixBackend`], over a raw
//!   [`backend::VariableSource`] (item slots resolved at subscribe time, fan-out, rates,
//!   request bookkeeping) that the network and the simulation implement.
//! - [`datasource`]: the network clients as a raw variable source, and the network backend
//!   ([`datasource::network_backend`], [`datasource::AsixSource`]).
//! - [`pipeline`]: the per-sample asix pipeline of the adapter (resolution once per item,
//!   quality rules, derivation, write checks).
//! - [`sim`]: `asix-sim`, a simulated asix data server serving a deterministic plant, and
//!   the in-process simulation over the same plant ([`sim::inproc`], re-exported as
//!   [`inproc`]).
//! - [`server`]: the server role's shared plumbing (discovery answers, accepting and
//!   securing links, reading frames), used by asix-sim and asix-gate.
//! - [`discovery`]: choosing a server from the announcements (ranking, variants).
//! - [`naming`], [`config`]: the client's asix name, channel options and external server
//!   lists (INI files are read by the core's reader, [`asix_model::ini`]).
#![forbid(unsafe_code)]

pub mod backend;
pub mod client;
pub mod config;
pub mod datasource;
pub mod discovery;
pub mod naming;
pub mod pipeline;
pub mod probe;
pub mod proto;
pub mod rest;
pub mod secure;
pub mod server;
pub mod sim;
pub mod tls;

pub use sim::inproc;

pub use client::{channel_sink, AsixClient, ClientEvent, EventSink, RequestId};
pub use config::{ClientConfig, ConnectOptions, ExternalServerLists, ServerChoice};
/// The value-quality-timestamp triple, shared with the core.
pub use ctopc_core::Vqt;
pub use naming::{asix_client_name, computer_name};
pub use proto::frame::ReadSource;
