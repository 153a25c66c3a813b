//! What the workspace's tests and benches share, in one crate instead of files included
//! across crates by `#[path]`. Std only, so it builds and tests natively:
//!
//! - [`start`]: starting a process through Wine's transient `CreateProcess` failure, each
//!   retry counted for `cargo xtask test` (the e2e tests and the COM crate's in-process
//!   tests start processes through it);
//! - [`wait`]: waiting, bounded, on a condition instead of sleeping;
//! - [`measure`]: the live heap, resident memory and CPU time a bench reads of its own
//!   process (asix-net's and asix-model's benches).

pub mod measure;
pub mod start;
pub mod wait;
