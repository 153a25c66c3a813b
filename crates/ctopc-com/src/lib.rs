//! The COM layer of ServerCTOPC: OPC interface definitions (mirroring `idl/`), the COM
//! objects over `ctopc-core`, registration and the server host. Every `unsafe` block of
//! the project is in this crate, each with a `// SAFETY:` comment.
#![cfg(windows)]
// COM methods receive raw pointers by ABI through windows-rs' safe `_Impl` traits; each
// dereference is checked (null) and commented with its SAFETY argument.
#![allow(clippy::not_unsafe_ptr_arg_deref)]

pub mod client;
pub mod connpoint;
pub mod context;
pub mod enums;
pub mod factory;
pub mod group;
pub mod host;
pub mod interfaces;
pub mod lifetime;
pub mod mem;
#[cfg(feature = "marshal-probe")]
pub mod probe;
pub mod registry;
pub mod runtime;
pub mod server;
pub mod service;
pub mod variant;
