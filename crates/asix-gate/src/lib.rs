//! asix-gate: the asix-side gateway. It serves the asix network protocol's server role
//! (`docs/asix-net-protocol.md`, version 2 with TLS) from AsixConnect's Automation server
//! `XConnect.ServerCT`, one object per served channel (`docs/asix-gate.md`).
//!
//! - [`channel`]: the boundary to one `XConnect.ServerCT` object ([`XConnectChannel`]),
//!   shaped for a late-binding adapter; [`fake`]: a scriptable implementation for tests.
//! - [`config`]: `asix-gate.ini`, with errors in Polish and English.
//! - [`tz`]: the station's local time to UTC, across DST changes (pure).
//! - [`engine`]: a worker per channel (bounded queue, call timeout, watchdog), the images
//!   of subscribed items, the source state.
//! - `xconnect` (Windows): the adapter to the real `XConnect.ServerCT`, late-bound
//!   through `ctopc_com::automation`.
//! - [`server`]: discovery, TLS links and the requests, writes granted by the
//!   authenticated identity.
#![forbid(unsafe_code)]

pub mod channel;
pub mod config;
pub mod engine;
pub mod fake;
pub mod server;
pub mod tz;
#[cfg(windows)]
pub mod xconnect;

use std::path::Path;

use asix_net::secure::{ServerSecurity, ServerTls};
use asix_net::tls::{Identity, Trust};

pub use channel::{CallError, ChannelFactory, DataSource, ServerState, XConnectChannel};
pub use config::GateConfig;
pub use engine::Engine;
pub use server::{serve, GateServer, ServeConfig};

/// The link security of a configuration: its TLS identity (a file pair, or `identity`
/// when the file names none) and the clients it accepts; plaintext links too when a
/// channel allows them.
pub fn security(cfg: &GateConfig, identity: Option<&Identity>) -> Result<ServerSecurity, String> {
    let trust = match (&cfg.client_ca, cfg.allow_clients.is_empty()) {
        (Some(_), false) => return Err("AllowClient and ClientCA: give one".into()),
        (Some(ca), true) => Trust::ca_file(ca).map_err(|e| e.to_string())?,
        (None, false) => Trust::Fingerprints(cfg.allow_clients.clone()),
        (None, true) => Trust::AnyCertificate,
    };
    let loaded;
    let identity = match (&cfg.certificate, &cfg.private_key, identity) {
        (Some(c), Some(k), _) => {
            loaded = Identity::load(Path::new(c), Path::new(k)).map_err(|e| e.to_string())?;
            &loaded
        }
        (_, _, Some(i)) => i,
        _ => return Err(
            "no TLS identity: set Certificate and PrivateKey (asix-gate --gen-cert DIR makes them)"
                .into(),
        ),
    };
    let mut s = ServerSecurity::tls(ServerTls::new(identity, trust).map_err(|e| e.to_string())?);
    s.allow_plaintext = cfg.any_plaintext();
    Ok(s)
}

/// The network settings of a configuration.
pub fn serve_config(cfg: &GateConfig, security: ServerSecurity) -> ServeConfig {
    ServeConfig {
        server_name: cfg.server_name.clone(),
        host_name: asix_net::computer_name(),
        discovery: cfg.discovery,
        listen: cfg.listen,
        security,
        write_rights: cfg.write_rights.clone(),
        min_sampling_ms: 10,
    }
}
