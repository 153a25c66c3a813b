//! The COM layer of ServerCTOPC: OPC interface definitions (mirroring `idl/`), the COM
//! objects over `ctopc-core`, registration and the server host. Most of the project's
//! `unsafe` blocks are in this crate (the rest in the client library `opc-client`, the
//! server browser `opc-server-list` and the e2e tests), each with a `// SAFETY:` comment.
//!
//! Windows-only; the registry entries it writes are data of the portable crate
//! `ctopc-registration` (crates/registration), tested natively and read by the MSI build.

#[cfg(windows)]
pub mod abi;
#[cfg(windows)]
pub mod callbacks;
#[cfg(windows)]
pub mod apartment;
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
#[cfg(windows)]
pub mod server;
#[cfg(windows)]
pub mod service;
#[cfg(windows)]
pub mod variant;
#[cfg(windows)]
pub mod wine_keepalive;
#[cfg(windows)]
pub mod winreg;
