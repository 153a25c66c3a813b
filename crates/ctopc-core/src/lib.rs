//! The OPC DA data model of ServerCTOPC as a deterministic, pure-Rust state machine.
//!
//! No I/O, no clock: every time-dependent call takes `now` (a [`Timestamp`]).
//! The COM layer (`ctopc-com`) only translates between COM and this crate.
#![forbid(unsafe_code)]

pub mod audit;
pub mod browse;
pub mod compact;
pub mod convert;
pub mod diagnostics;
pub mod driver;
pub mod error;
pub mod lang;
pub mod limits;
pub mod metrics;
pub mod model;
pub mod namespace;
pub mod ops;
pub mod properties;
pub mod quality;
pub mod secrets;
pub mod source;
pub mod stream;
pub mod time;
pub mod value;
pub mod write_rights;

pub use error::{OpcError, OpcResult};
pub use lang::Lang;
pub use quality::Quality;
pub use time::Timestamp;
pub use value::{Value, VarType, Vqt};
