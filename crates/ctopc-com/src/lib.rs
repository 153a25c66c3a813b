//! The COM layer of ServerCTOPC: OPC interface definitions (mirroring `idl/`), the COM
//! objects over `ctopc-core`, registration and the server host. Every `unsafe` block of
//! the project is in this crate, each with a `// SAFETY:` comment.
#![cfg(windows)]

pub mod abi;
pub mod client;
pub mod clock;
pub mod comdef;
pub mod connpoint;
pub mod context;
pub mod enums;
pub mod error;
pub mod factory;
pub mod group;
pub mod host;
pub mod interfaces;
pub mod lifetime;
pub mod registry;
pub mod runtime;
pub mod server;
pub mod service;
pub mod variant;
