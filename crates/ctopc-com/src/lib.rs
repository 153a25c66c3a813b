//! The COM layer of ServerCTOPC: OPC interface definitions (mirroring `idl/`), the COM
//! objects over `ctopc-core`, registration and the server host. Every `unsafe` block of
//! the project is in this crate, each with a `// SAFETY:` comment.
//!
//! Everything but [`registration`] is Windows-only; `registration` (the registry entries
//! as data) is plain Rust, compiled and tested on every host, so that it can be tested
//! natively and reused by an installer build.

#[cfg(windows)]
pub mod abi;
#[cfg(windows)]
pub mod callbacks;
pub mod catalog;
#[cfg(windows)]
pub mod client;
#[cfg(windows)]
pub mod clock;
#[cfg(windows)]
pub mod comdef;
#[cfg(windows)]
pub mod connpoint;
#[cfg(windows)]
pub mod context;
#[cfg(windows)]
pub mod enums;
#[cfg(windows)]
pub mod error;
#[cfg(windows)]
pub mod factory;
#[cfg(windows)]
pub mod group;
#[cfg(windows)]
pub mod host;
#[cfg(windows)]
pub mod interfaces;
#[cfg(windows)]
pub mod lifetime;
pub mod registration;
#[cfg(windows)]
pub mod registry;
#[cfg(windows)]
pub mod server;
#[cfg(windows)]
pub mod server_list;
#[cfg(windows)]
pub mod service;
#[cfg(windows)]
pub mod variant;
#[cfg(windows)]
pub mod wine_keepalive;
