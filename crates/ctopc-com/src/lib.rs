//! The COM layer of ServerCTOPC, in two floors as the OPC Foundation's sample server has
//! them: the plumbing ([`com`]: the argument toolkit, interface definitions, connection
//! points, enumerators, class factory, lifetime, VARIANT, registry, service, the apartment
//! guard and the platform's quirks) and the OPC DA objects over it ([`da`]: server,
//! group, context, callbacks, host). A module of the plumbing never imports from the DA
//! floor. Most of the project's `unsafe` blocks are in this crate (the rest in the client
//! library `opc-client`, the server browser `opc-server-list` and the e2e tests), each
//! with a `// SAFETY:` comment.
//!
//! Windows-only; the registry entries it writes are data of the portable crate
//! `ctopc-registration` (crates/registration), tested natively and read by the MSI build.
//! The crate's users name the modules by their short paths (`ctopc_com::abi`,
//! `ctopc_com::host`), re-exported here.

#![cfg(windows)]

pub mod com;
pub mod da;

pub use com::{
    abi, apartment, automation, caller, clock, comdef, connpoint, enums, error, factory,
    interfaces, lifetime, service, variant, winreg,
};
pub use da::{callbacks, context, group, host, server};
