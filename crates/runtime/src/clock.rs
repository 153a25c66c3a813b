//! The runtime's clock: the current UTC time, the only clock read on the data path (the
//! core takes time as an argument).

use ctopc_core::Timestamp;

/// The current UTC time.
pub fn now() -> Timestamp {
    let since = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    Timestamp::from_unix_micros(since.as_micros())
}
