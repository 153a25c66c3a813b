//! The Asix.Evo REST link: a data source over the REST server built into Asix.Evo
//! (`docs/asix-evo-rest.md`), for the AsixConnect channels whose section names one
//! (`AsixEvoRest`). A sans-IO [`RestCore`] (poll schedule, batches, failover, quality)
//! under a tokio shell ([`RestLink`]) that makes the HTTP requests with bounded bodies
//! and time limits; the answers decode in [`decode`] (fuzzed).

pub mod core;
pub mod decode;

pub use self::core::{FetchError, Get, GetId, RestCore, RestCoreConfig};
pub use self::decode::{decode_values, RestValue, VarState};

/// The largest answer body read, bytes (a batch of names at most); a larger one is a
/// failed request.
pub const MAX_BODY: usize = 4 << 20;
