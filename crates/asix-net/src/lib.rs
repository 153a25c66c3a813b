//! The asix network of ServerCTOPC: how the OPC server reaches asix data servers.
//!
//! - [`proto`]: the versioned wire protocol (UDP discovery datagrams, framed TCP link),
//!   documented for gateway writers in `docs/asix-net-protocol.md`.
//! - [`client`]: the discovery-and-failover client ([`AsixClient`], a non-blocking handle
//!   over a sans-IO [`client::ClientCore`]).
//! - [`datasource`]: the client as the engine's data-source `Backend` ([`datasource::network_backend`]).
//! - [`pipeline`]: the per-sample asix pipeline both data sources share (resolution once
//!   per item, quality rules, derivation, write checks).
//! - [`sim`]: `asix-sim`, a simulated asix data server serving a deterministic plant
//!   (also the model of [`inproc`], the in-process simulation backend).
//! - [`discovery`]: choosing a server from the announcements (ranking, variants).
//! - [`naming`], [`config`]: the client's asix name, channel options and external server
//!   lists (INI files are read by the core's reader, [`asix_model::ini`]).
#![forbid(unsafe_code)]

pub mod client;
pub mod config;
pub mod datasource;
pub mod discovery;
pub mod inproc;
pub mod naming;
pub mod pipeline;
pub mod proto;
pub mod sim;

pub use client::{channel_sink, AsixClient, ClientEvent, EventSink, ItemKey, RequestId};
pub use config::{ClientConfig, ConnectOptions, ExternalServerLists, ServerChoice};
/// The value-quality-timestamp triple, shared with the core.
pub use ctopc_core::Vqt;
pub use naming::{asix_client_name, computer_name};
pub use proto::frame::ReadSource;
