//! The plumbing floor: COM without OPC semantics. The argument and out-parameter toolkit
//! (`abi`), the error mapping, FILETIME and the clock, the interface definitions (mirroring
//! `idl/`), our raw definitions of the connection-point and enumerator interfaces
//! (`comdef`), connection points, a late-bound Automation client (`automation`), enumerators, the class factory, the server's lifetime,
//! VARIANT conversion, the Windows registry, the NT service, the caller's identity from the
//! call's security context (`caller`), the one apartment guard and, under it, the
//! platform's quirks (`platform`). Nothing here imports from the DA floor
//! (`crate::da`); `xtask/tests/tidy.rs` checks it.

pub mod abi;
pub mod apartment;
pub mod automation;
pub mod caller;
pub mod clock;
pub mod comdef;
pub mod connpoint;
pub mod enums;
pub mod error;
pub mod factory;
pub mod interfaces;
pub mod lifetime;
pub mod platform;
pub mod secret_file;
pub mod service;
pub mod variant;
pub mod winreg;
