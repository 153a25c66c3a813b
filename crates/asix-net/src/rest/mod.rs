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

pub mod link;

pub use self::link::{probe, Auth, RestLink, RestSettings, StartError};

use std::time::Duration;

/// Most requests of one link under way at once.
pub const MAX_IN_FLIGHT: usize = 4;

/// How often a REST link that failed over asks its preferred stations whether they answer
/// again.
pub const COME_BACK_INTERVAL: Duration = Duration::from_secs(10);

/// The REST link settings of an AsixConnect channel, `None` when it names no Asix.Evo
/// REST server: the stations of `AsixEvoRest`, the credential of `AsixEvoUser`/
/// `AsixEvoPassword` or `AsixEvoHeader` (the header wins when both are given), batches of
/// `AsixEvoMaxBatch` names, and a request time limit of `AsixEvoPollTimeout` bounded by
/// the engine's `SourceTimeout` (a device read never outlives the engine's wait);
/// `retry`: the pause after every station failed (`ReconnectInterval`).
pub fn settings_from_options(
    channel: &str,
    o: &asix_model::ChannelOptions,
    source_timeout_ms: u32,
    retry: Duration,
) -> Option<RestSettings> {
    if !o.is_asix_evo_rest() {
        return None;
    }
    let auth = match (&o.asix_evo_header, &o.asix_evo_user) {
        (Some(h), _) => Auth::Header(h.clone()),
        (None, Some(user)) => Auth::Basic {
            user: user.clone(),
            password: o.asix_evo_password.clone(),
        },
        (None, None) => Auth::None,
    };
    Some(RestSettings {
        core: RestCoreConfig {
            channel: channel.into(),
            stations: o.asix_evo_rest.clone(),
            max_batch: o.asix_evo_max_batch.max(1) as usize,
            max_in_flight: MAX_IN_FLIGHT,
            retry_interval: retry,
            come_back_interval: COME_BACK_INTERVAL,
        },
        auth,
        request_timeout: Duration::from_millis(u64::from(
            o.asix_evo_poll_timeout_ms.min(source_timeout_ms).max(1),
        )),
        max_body: MAX_BODY,
    })
}
