//! Client configuration: the channel options that govern discovery (AsixServerName,
//! StopAfterFirstServerFound, FindServerTimeout, NetTimeout) and the external server lists.

use std::collections::HashMap;
use std::net::{Ipv4Addr, SocketAddr};
use std::time::Duration;

use asix_model::ini::split_list;
use std::path::PathBuf;

use asix_model::{AsixConfig, ChannelOptions};

use crate::proto::discovery::{Announce, Resource, ResourceKind};
use crate::proto::DEFAULT_DISCOVERY_PORT;
use crate::secure::ClientSecurity;
use crate::tls::{self, Identity, Trust};

/// Which servers a channel may use (the `AsixServerName` option, or an external list).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ServerChoice {
    /// Empty or `*`: any server offering the resource.
    Any,
    /// One name or a comma-separated list: only these servers (case-insensitive).
    Names(Vec<String>),
    /// `LOCAL`: only the server on this computer.
    Local,
}

impl ServerChoice {
    /// Parses an `AsixServerName` value.
    pub fn parse(asix_server_name: &str) -> ServerChoice {
        let s = asix_server_name.trim();
        if s.is_empty() || s == "*" {
            return ServerChoice::Any;
        }
        if s.eq_ignore_ascii_case("LOCAL") {
            return ServerChoice::Local;
        }
        let names = split_list(s);
        if names.is_empty() {
            ServerChoice::Any
        } else {
            ServerChoice::Names(names)
        }
    }

    /// May this announcing server be used (at first connection and after a link loss)?
    pub fn allows(&self, a: &Announce) -> bool {
        match self {
            ServerChoice::Any => true,
            ServerChoice::Local => a.flags.local(),
            ServerChoice::Names(n) => n.iter().any(|x| x.eq_ignore_ascii_case(&a.server_name)),
        }
    }
}

/// The discovery options of an AsixConnect channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConnectOptions {
    /// `AsixServerName`: empty, `*`, a name, a comma-separated list, or `LOCAL`.
    pub asix_server_name: String,
    /// `StopAfterFirstServerFound` (default tak).
    pub stop_after_first_server_found: bool,
    /// `FindServerTimeout` (default 3000 ms).
    pub find_server_timeout: Duration,
    /// `NetTimeout` (default 3000 ms): the longest wait for any answer of a server.
    pub net_timeout: Duration,
}

impl Default for ConnectOptions {
    fn default() -> Self {
        ConnectOptions {
            asix_server_name: String::new(),
            stop_after_first_server_found: true,
            find_server_timeout: Duration::from_millis(3000),
            net_timeout: Duration::from_millis(3000),
        }
    }
}

/// The external server lists of `ASIXConnect.ini` (`[AsixCTServers]` by channel,
/// `[AsixHTServers]` by archive, `[AsixALServers]` by alarm-server network name), used only
/// when a channel names no server. Resource names are matched case-insensitively, as the
/// INI API does.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ExternalServerLists {
    lists: HashMap<(ResourceKind, String), Vec<String>>,
}

impl ExternalServerLists {
    /// The three lists as the core read them from `ASIXConnect.ini`
    /// ([`AsixConfig::ct_servers`], [`AsixConfig::ht_servers`], [`AsixConfig::al_servers`]).
    pub fn from_config(config: &AsixConfig) -> Self {
        let mut lists = HashMap::new();
        for (map, kind) in [
            (&config.ct_servers, ResourceKind::Channel),
            (&config.ht_servers, ResourceKind::Archive),
            (&config.al_servers, ResourceKind::AlarmServer),
        ] {
            for (name, servers) in map {
                lists.insert((kind, name.to_ascii_uppercase()), servers.clone());
            }
        }
        ExternalServerLists { lists }
    }

    pub fn insert(&mut self, resource: &Resource, servers: Vec<String>) {
        self.lists
            .insert((resource.kind, resource.name.to_ascii_uppercase()), servers);
    }

    pub fn get(&self, resource: &Resource) -> Option<&[String]> {
        self.lists
            .get(&(resource.kind, resource.name.to_ascii_uppercase()))
            .map(Vec::as_slice)
    }
}

/// How a channel's links are secured, from its options (`AsixNetPlaintext`,
/// `AsixNetCertFile`/`AsixNetKeyFile`, `AsixNetServerFingerprint` or `AsixNetCaFile`);
/// `resolve` makes a path option a file path (relative to the configuration's folder).
/// Without a usable certificate and pin the channel links to no server, and says why.
pub fn security_from_options(
    channel: &str,
    o: &ChannelOptions,
    resolve: impl Fn(&str) -> PathBuf,
) -> ClientSecurity {
    if o.asix_net_plaintext {
        return ClientSecurity::Plaintext;
    }
    let unconfigured =
        |why: String| ClientSecurity::Unconfigured(format!("channel {channel}: {why}"));
    let (Some(cert), Some(key)) = (&o.asix_net_cert_file, &o.asix_net_key_file) else {
        return unconfigured(
            "no client certificate (AsixNetCertFile and AsixNetKeyFile), and plaintext is not allowed (AsixNetPlaintext)".into(),
        );
    };
    let trust = match (&o.asix_net_server_fingerprints[..], &o.asix_net_ca_file) {
        ([], None) => {
            return unconfigured(
                "no pinned asix server (AsixNetServerFingerprint or AsixNetCaFile)".into(),
            )
        }
        ([], Some(ca)) => match Trust::ca_file(&resolve(ca)) {
            Ok(t) => t,
            Err(e) => return unconfigured(format!("AsixNetCaFile: {e}")),
        },
        (fps, None) => match fps
            .iter()
            .map(|f| tls::parse_fingerprint(f))
            .collect::<Result<Vec<_>, _>>()
        {
            Ok(v) => Trust::Fingerprints(v),
            Err(e) => return unconfigured(format!("AsixNetServerFingerprint: {e}")),
        },
        (_, Some(_)) => {
            return unconfigured("give AsixNetServerFingerprint or AsixNetCaFile, not both".into())
        }
    };
    match Identity::load(&resolve(cert), &resolve(key))
        .and_then(|id| ClientSecurity::tls(&id, trust))
    {
        Ok(s) => s,
        Err(e) => unconfigured(format!("AsixNetCertFile/AsixNetKeyFile: {e}")),
    }
}

/// Everything the client needs.
#[derive(Debug, Clone)]
pub struct ClientConfig {
    /// The client's asix name (see [`crate::asix_client_name`]); write rights are granted to it.
    pub client_name: String,
    /// This computer's name (servers on the same computer announce themselves as local).
    pub client_host: String,
    pub options: ConnectOptions,
    pub external: ExternalServerLists,
    /// Where FindServer requests go: in production the LAN broadcast address and the local
    /// server; in tests loopback addresses with distinct ports.
    pub discovery_targets: Vec<SocketAddr>,
    /// Local address of the discovery socket.
    pub discovery_bind: SocketAddr,
    /// FindServer is repeated this often while a search runs (UDP may lose datagrams).
    pub discovery_resend: Duration,
    /// A Ping is sent this often; no Pong within NetTimeout means the link is lost.
    pub keepalive: Duration,
    /// Pause between unsuccessful rounds of discovery and connection.
    pub reconnect_interval: Duration,
    /// Items a server refused are subscribed again this often.
    pub retry_failed_items: Duration,
    /// Ask servers for changed values only (default: every sample, as the engine's
    /// data-source boundary wants them for MaxAge).
    pub changes_only: bool,
    /// How links are secured: TLS with the client's certificate and the pinned servers,
    /// or (only where a channel allows it) plaintext. The default links to no server.
    pub security: ClientSecurity,
}

impl ClientConfig {
    pub fn new(client_name: impl Into<String>, client_host: impl Into<String>) -> Self {
        ClientConfig {
            client_name: client_name.into(),
            client_host: client_host.into(),
            options: ConnectOptions::default(),
            external: ExternalServerLists::default(),
            discovery_targets: vec![
                SocketAddr::from((Ipv4Addr::BROADCAST, DEFAULT_DISCOVERY_PORT)),
                SocketAddr::from((Ipv4Addr::LOCALHOST, DEFAULT_DISCOVERY_PORT)),
            ],
            discovery_bind: SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0)),
            discovery_resend: Duration::from_millis(500),
            keepalive: Duration::from_millis(1000),
            reconnect_interval: Duration::from_millis(1000),
            retry_failed_items: Duration::from_secs(10),
            changes_only: false,
            security: ClientSecurity::default(),
        }
    }

    /// The servers allowed for a resource: `AsixServerName`, or when that names no server,
    /// the external list for the resource if there is one.
    pub fn choice_for(&self, resource: &Resource) -> ServerChoice {
        match ServerChoice::parse(&self.options.asix_server_name) {
            ServerChoice::Any => match self.external.get(resource) {
                Some(list) => ServerChoice::Names(list.to_vec()),
                None => ServerChoice::Any,
            },
            other => other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn asix_server_name_variants() {
        assert_eq!(ServerChoice::parse(""), ServerChoice::Any);
        assert_eq!(ServerChoice::parse(" * "), ServerChoice::Any);
        assert_eq!(ServerChoice::parse("local"), ServerChoice::Local);
        assert_eq!(
            ServerChoice::parse("A"),
            ServerChoice::Names(vec!["A".into()])
        );
        assert_eq!(
            ServerChoice::parse("A, B ,"),
            ServerChoice::Names(vec!["A".into(), "B".into()])
        );
    }

    #[test]
    fn external_list_applies_only_when_no_server_is_named() {
        let mut cfg = ClientConfig::new("CLI.", "CLI");
        let (config, _) = asix_model::parse_config(
            b"[AsixCTServers]\nKANAL1 = S1, S2\n[AsixHTServers]\nARCH = S3\n[AsixALServers]\nAlarmy = S4\n",
            "ASIXConnect.ini",
        )
        .unwrap();
        cfg.external = ExternalServerLists::from_config(&config);
        let k1 = Resource::channel("kanal1");
        assert_eq!(
            cfg.choice_for(&k1),
            ServerChoice::Names(vec!["S1".into(), "S2".into()])
        );
        assert_eq!(
            cfg.choice_for(&Resource::channel("OTHER")),
            ServerChoice::Any
        );
        for (kind, name, server) in [
            (ResourceKind::Archive, "ARCH", "S3"),
            (ResourceKind::AlarmServer, "ALARMY", "S4"),
        ] {
            let resource = Resource {
                kind,
                name: name.into(),
            };
            assert_eq!(
                cfg.choice_for(&resource),
                ServerChoice::Names(vec![server.into()]),
                "{name}"
            );
        }
        cfg.options.asix_server_name = "LOCAL".into();
        assert_eq!(cfg.choice_for(&k1), ServerChoice::Local);
    }
}
