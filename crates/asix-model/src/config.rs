//! `ASIXConnect.ini`: package options, channels and the external server lists.
//!
//! Layout (documented for users in `asixconnect.ini.example` at the repository root):
//!
//! ```ini
//! [Server]                        ; package options (Opcje pakietu) + asix network client
//! AttributesAsItems = nie
//! [Channel:*]                     ; the basic channel; always exists, even without a section
//! ItemsDatabase = C:\asix\Aplikacje\Wytwornia_Kwasu\wytwornia_kwasu.zez
//! [Channel:Demo_Wytwornia_Kwasu]  ; a named channel (name case-sensitive, as in asix)
//! CheckLimits = tak
//! [AsixCTServers]                 ; external server lists: resource = srv1, srv2
//! Demo_Wytwornia_Kwasu = STACJA1, STACJA2
//! [AsixHTServers]
//! [AsixALServers]
//! [WriteRights]                   ; who may write: <channel or *> = identity, identity, ...
//! * = group:PLANT\Operators
//! ZEZWOLENIE_ZAPISU = Demo_Wytwornia_Kwasu, KE2.   ; the original's rule, also in [ASMEN]
//! ```
//!
//! Rules: option names are ASCII case-insensitive; an empty value means "not set" (the
//! default applies); booleans are `tak/true/1` and `nie/false/0`; an unknown option or
//! section is ignored with a [`Warning`]; an invalid value is a [`ConfigError`] naming file,
//! line and option. Each channel section is complete in itself: an option a named channel
//! does not set takes the documented default, not the value of `*` (as in the original,
//! where every channel stored its whole option set).
//!
//! Channel resolution for an OPC access path ([`AsixConfig::resolve_channel`]): `*`, empty
//! and names starting with `ANY` use channel `*`; names starting with `NEW` get the
//! defaults and no stored options; the prefixes are case-sensitive (a channel called
//! `Newton` is an ordinary name). Any other name must have a `[Channel:<name>]` section,
//! else `OPC_E_UNKNOWNPATH`. Sections for `ANY...`/`NEW...` names are rejected.
//!
//! Write rights ([`AsixConfig::write_rights`], the policy of
//! [`ctopc_core::write_rights`]): each line of `[WriteRights]` is `<channel> = <identity>,
//! ...` (`*` for every channel) or `ZEZWOLENIE_ZAPISU = <channel>, <client>, ...`, the
//! original's rule, which may also stand in an `[ASMEN]` section copied from the asix
//! application ini; both sections keep repeated keys. An identity that cannot be read is
//! a [`ConfigError`]; a channel that no `[Channel:]` section names (nor `*`, nor a
//! `NEW...` name) is a [`Warning`]. Without either section every client may write.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use super::ini::{parse_ini_with_lists, split_list, IniEntry, IniSection};
use super::text::{parse_bool, Warning};
use ctopc_core::write_rights::{Channels, Principal, Rule, WriteRights};
use ctopc_core::{OpcError, OpcResult};

/// The name of the basic channel.
pub const BASIC_CHANNEL: &str = "*";

/// Options of the `[Server]` section, in file spelling.
pub const SERVER_OPTIONS: &[&str] = &[
    "LogDirectory",
    "AttributesAsItems",
    "MinUpdateRate",
    "DefaultLanguage",
    "SimulateCurrentData",
    "ClientName",
    "BroadcastAddress",
    "DiscoveryPort",
    "DataPort",
    "ReconnectInterval",
    "LogLevel",
    "LogMaxFileSizeMB",
    "LogKeepFiles",
    "SourceTimeout",
    "SimulationDeviceDelay",
    "FirstSampleWait",
    "AuditWrites",
    "LegacyOpenAccess",
    "CallbackTimeout",
    "CallbackFailures",
    "MetricsAddress",
];

/// Options of the `[UA]` section (the OPC UA front end), in file spelling.
pub const UA_OPTIONS: &[&str] = &[
    "Enabled",
    "Endpoint",
    "AllowNone",
    "AllowAnonymous",
    "PkiDirectory",
    "UsersFile",
    "MaxSessions",
    "MaxSubscriptionsPerSession",
    "MaxMonitoredItemsPerSubscription",
    "MaxMonitoredItems",
    "MaxBrowseContinuationPoints",
    "MaxOperationsPerRequest",
    "MaxMessageSize",
    "MaxChunkCount",
    "MaxArrayLength",
    "MaxStringLength",
    "MaxRequestsPerSecond",
];

/// The OPC UA front end (`[UA]`): where it listens, its security and its limits.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UaOptions {
    /// The configuration has a `[UA]` section (even an empty one).
    pub section: bool,
    /// `Enabled`: whether ServerCTOPC.exe serves OPC UA beside OPC DA; unset, it does
    /// when the configuration has a `[UA]` section ([`UaOptions::beside_da`]).
    pub enabled: Option<bool>,
    /// `Endpoint`: the endpoint URL, default `opc.tcp://0.0.0.0:4840` (every interface;
    /// the endpoints it announces name the host).
    pub endpoint: String,
    /// `AllowNone`: offer SecurityPolicy None (default off).
    pub allow_none: bool,
    /// `AllowAnonymous`: accept anonymous sessions, as readers (default off).
    pub allow_anonymous: bool,
    /// `PkiDirectory`: the certificate store (own, private, trusted, rejected); default
    /// `pki` beside the configuration file.
    pub pki_directory: Option<String>,
    /// `UsersFile`: the users and their salted password hashes; default
    /// `ua-users.txt` beside the configuration file.
    pub users_file: Option<String>,
    /// `MaxSessions` (default 100).
    pub max_sessions: u32,
    /// `MaxSubscriptionsPerSession` (default 100).
    pub max_subscriptions_per_session: u32,
    /// `MaxMonitoredItemsPerSubscription` (default 100,000).
    pub max_monitored_items_per_subscription: u32,
    /// `MaxMonitoredItems`: of the plant's variables, every session's (default 1,000,000).
    pub max_monitored_items: u32,
    /// `MaxBrowseContinuationPoints`: per session (default 100).
    pub max_browse_continuation_points: u32,
    /// `MaxOperationsPerRequest`: nodes of one Read, Write, Browse, RegisterNodes,
    /// TranslateBrowsePaths; monitored items of one call (default 10,000).
    pub max_operations_per_request: u32,
    /// `MaxMessageSize`: bytes (default 16 MiB).
    pub max_message_size: u32,
    /// `MaxChunkCount`: chunks of one message (default 512).
    pub max_chunk_count: u32,
    /// `MaxArrayLength`: elements of an array in a request (default 100,000).
    pub max_array_length: u32,
    /// `MaxStringLength`: bytes of a string in a request (default 65,535).
    pub max_string_length: u32,
    /// `MaxRequestsPerSecond`: per session, 0 for no limit (default 10,000).
    pub max_requests_per_second: u32,
}

impl Default for UaOptions {
    fn default() -> Self {
        UaOptions {
            section: false,
            enabled: None,
            endpoint: "opc.tcp://0.0.0.0:4840".to_owned(),
            allow_none: false,
            allow_anonymous: false,
            pki_directory: None,
            users_file: None,
            max_sessions: 100,
            max_subscriptions_per_session: 100,
            max_monitored_items_per_subscription: 100_000,
            max_monitored_items: 1_000_000,
            max_browse_continuation_points: 100,
            max_operations_per_request: 10_000,
            max_message_size: 16 * 1024 * 1024,
            max_chunk_count: 512,
            max_array_length: 100_000,
            max_string_length: 65_535,
            max_requests_per_second: 10_000,
        }
    }
}

impl UaOptions {
    /// Whether ServerCTOPC.exe serves OPC UA beside OPC DA: `Enabled` when set, else
    /// when the configuration has a `[UA]` section.
    pub fn beside_da(&self) -> bool {
        self.enabled.unwrap_or(self.section)
    }
}

/// Options of a `[Channel:<name>]` section, in file spelling.
pub const CHANNEL_OPTIONS: &[&str] = &[
    "AsixServerName",
    "StopAfterFirstServerFound",
    "FindServerTimeout",
    "NetTimeout",
    "ItemsDatabase",
    "AliasAttributeName",
    "CheckControlVariables",
    "CheckLimits",
    "AggregateMode",
    "QualityGoodThreshold",
    "AlarmsSystemNetworkName",
    "ReportsDirectory",
    "IniFilePath",
    "AsixEvoRest",
    "AsixEvoUser",
    "AsixEvoPassword",
    "AsixEvoHeader",
    "AsixEvoPollTimeout",
    "AsixEvoMaxBatch",
    "AsixNetServerFingerprint",
    "AsixNetCaFile",
    "AsixNetCertFile",
    "AsixNetKeyFile",
    "AsixNetPlaintext",
];

/// The language the server uses when a client sets none.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DefaultLanguage {
    /// Polish (LCID 0x0415).
    Polish,
    /// English US (LCID 0x0409).
    English,
    /// Polish on Polish Windows, else English (the original's behaviour).
    #[default]
    System,
}

impl DefaultLanguage {
    /// The configured language, or `None` for [`DefaultLanguage::System`] (the caller
    /// then asks Windows, see [`Lang::default_for_system`](ctopc_core::Lang::default_for_system)).
    pub const fn fixed(self) -> Option<ctopc_core::Lang> {
        match self {
            DefaultLanguage::Polish => Some(ctopc_core::Lang::Polish),
            DefaultLanguage::English => Some(ctopc_core::Lang::English),
            DefaultLanguage::System => None,
        }
    }
}

/// Package options (`[Server]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServerOptions {
    /// `LogDirectory` (Katalog plików logu). `None`: `<install folder>\Log`.
    pub log_directory: Option<String>,
    /// `AttributesAsItems` (Atrybuty OPC widoczne jako zmienne): browse variables as branches.
    pub attributes_as_items: bool,
    /// `MinUpdateRate`, ms (default 1000): shorter group rates are raised to it.
    pub min_update_rate_ms: u32,
    /// `DefaultLanguage`: `pl`, `en` or `system`.
    pub default_language: DefaultLanguage,
    /// `SimulateCurrentData` (Symulacja danych): simulated values, server state TEST.
    pub simulate_current_data: bool,
    /// `ClientName`: this computer's name in asix (`[ASLINK] Nazwa`); `None`: computer name + `.`.
    pub client_name: Option<String>,
    /// `BroadcastAddress` for server discovery; `None`: the network client's default.
    pub broadcast_address: Option<String>,
    /// `DiscoveryPort` (UDP); `None`: the network client's default.
    pub discovery_port: Option<u16>,
    /// `DataPort` (TCP); `None`: the network client's default.
    pub data_port: Option<u16>,
    /// `ReconnectInterval`, ms (default 5000): retry period of failed asix subscriptions.
    pub reconnect_interval_ms: u32,
    /// `LogLevel`: `info` (default: start, stop, configuration, asix connections, serious
    /// errors) or `debug` (also per-call detail), `warn`, `error`.
    pub log_level: LogLevel,
    /// `LogMaxFileSizeMB` (default 10): a day's log file over this size is closed and the
    /// day continues in `ServerCTOPC.<YYYYMMDD>.<n>.log`.
    pub log_max_file_size_mb: u32,
    /// `LogKeepFiles` (default 30): older log files beyond this count are deleted.
    pub log_keep_files: u32,
    /// `SourceTimeout`, ms (default [`ctopc_core::model::DEFAULT_SOURCE_TIMEOUT_MS`],
    /// 100..=600000; the engine's [`ctopc_core::model::EngineConfig::source_timeout_ms`]): how
    /// long the server waits for the data source to answer a device read or write before
    /// failing its items with ASKOM_E_NetAnswerTimeout.
    pub source_timeout_ms: u32,
    /// `SimulationDeviceDelay`, ms (default 0, 0..=600000): with `SimulateCurrentData`,
    /// the simulation answers device reads and writes only after this delay (a slow
    /// device, for testing timeouts and cancellation). Subscriptions are not delayed.
    pub simulation_device_delay_ms: u32,
    /// `FirstSampleWait`, ms (default [`ctopc_core::model::DEFAULT_FIRST_SAMPLE_WAIT_MS`],
    /// 0..=600000; the engine's [`ctopc_core::model::EngineConfig::first_sample_wait_ms`]):
    /// how long the first OnDataChange of newly active items waits for their first sample
    /// from the data source before it is sent with what the cache holds (BAD Waiting for
    /// Initial Data). 0: no wait.
    pub first_sample_wait_ms: u32,
    /// `AuditWrites` (default tak): every written item is logged, with the client, the
    /// item, the value and the result, under the log target `audit`
    /// (`ctopc_core::audit`); `nie` turns it off.
    pub audit_writes: bool,
    /// `LegacyOpenAccess` (default nie): `tak` keeps the COM security of old: the server
    /// calls `CoInitializeSecurity` with no security descriptor and authentication level
    /// NONE, so every process that can reach DCOM may connect (logged as a WARN at every
    /// start); `nie` lets the AppID's `AccessPermission`, `LaunchPermission` and
    /// `AuthenticationLevel` govern (`EOAC_APPID`, as dcomcnfg shows them).
    pub legacy_open_access: bool,
    /// `CallbackTimeout`, ms (default [`ctopc_core::ops::DEFAULT_CALLBACK_TIMEOUT_MS`],
    /// 0..=600000, 0: no timeout): a callback to a client (OnDataChange, ...) that has not
    /// returned by then counts as failed, and what would queue behind it is not sent.
    pub callback_timeout_ms: u32,
    /// `CallbackFailures` (default [`ctopc_core::ops::DEFAULT_CALLBACK_FAILURES`],
    /// 1..=1000): after this many consecutive failed callbacks the client's callback
    /// connections are dropped (logged as a warning).
    pub callback_failures: u32,
    /// `MetricsAddress` (default none: off): `ip:port` of the Prometheus metrics endpoint
    /// (`GET /metrics`); only loopback addresses are served, others are refused with an
    /// error in the log.
    pub metrics_address: Option<String>,
}

/// Bounds of `SourceTimeout`, ms.
const SOURCE_TIMEOUT_RANGE_MS: (u32, u32) = (100, 600_000);
/// Largest `FirstSampleWait`, ms.
const MAX_FIRST_SAMPLE_WAIT_MS: u32 = 600_000;
/// Largest `SimulationDeviceDelay`, ms.
const MAX_SIMULATION_DEVICE_DELAY_MS: u32 = 600_000;

impl ServerOptions {
    /// The engine's configuration these options imply (`MinUpdateRate`, `SourceTimeout`;
    /// subscription callbacks paced by their delivery; the rest at the engine's defaults).
    pub fn engine_config(&self) -> ctopc_core::model::EngineConfig {
        ctopc_core::model::EngineConfig {
            min_update_rate_ms: self.min_update_rate_ms,
            source_timeout_ms: self.source_timeout_ms,
            first_sample_wait_ms: self.first_sample_wait_ms,
            max_pending_data_changes: ctopc_core::model::SERVER_PENDING_DATA_CHANGES,
            ..ctopc_core::model::EngineConfig::default()
        }
    }

    /// The COM layer's operations settings these options imply (`AuditWrites`,
    /// `CallbackTimeout`, `CallbackFailures`), with open write rights: the whole file's
    /// are [`AsixConfig::ops_config`]'s.
    pub fn ops_config(&self) -> ctopc_core::ops::OpsConfig {
        ctopc_core::ops::OpsConfig {
            audit_writes: self.audit_writes,
            callback_timeout_ms: self.callback_timeout_ms,
            callback_failures: self.callback_failures,
            metrics_address: self.metrics_address.clone(),
            write_rights: std::sync::Arc::default(),
        }
    }
}

/// `LogLevel`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LogLevel {
    Error,
    Warn,
    #[default]
    Info,
    Debug,
}

impl Default for ServerOptions {
    fn default() -> Self {
        ServerOptions {
            log_directory: None,
            attributes_as_items: false,
            min_update_rate_ms: 1000,
            default_language: DefaultLanguage::System,
            simulate_current_data: false,
            client_name: None,
            broadcast_address: None,
            discovery_port: None,
            data_port: None,
            reconnect_interval_ms: 5000,
            log_level: LogLevel::Info,
            log_max_file_size_mb: 10,
            log_keep_files: 30,
            source_timeout_ms: ctopc_core::model::DEFAULT_SOURCE_TIMEOUT_MS,
            first_sample_wait_ms: ctopc_core::model::DEFAULT_FIRST_SAMPLE_WAIT_MS,
            simulation_device_delay_ms: 0,
            audit_writes: true,
            legacy_open_access: false,
            callback_timeout_ms: ctopc_core::ops::DEFAULT_CALLBACK_TIMEOUT_MS,
            callback_failures: ctopc_core::ops::DEFAULT_CALLBACK_FAILURES,
            metrics_address: None,
        }
    }
}

/// Archive aggregate algorithm (`AggregateMode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AggregateMode {
    /// 0: the Askom algorithm.
    #[default]
    Askom,
    /// 1: the OPC algorithm.
    Opc,
}

/// The options of one channel (manual §3.6).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelOptions {
    /// `AsixServerName`: empty, `*`, `LOCAL`, one name or a comma-separated list.
    pub asix_server_name: String,
    /// `StopAfterFirstServerFound` (default tak).
    pub stop_after_first_server_found: bool,
    /// `FindServerTimeout`, ms (default 3000).
    pub find_server_timeout_ms: u32,
    /// `NetTimeout`, ms (default 3000).
    pub net_timeout_ms: u32,
    /// `ItemsDatabase`: the variable-set file (`.zez`) or an attribute table (`.csv`).
    pub items_database: Option<String>,
    /// `AliasAttributeName`: the attribute holding alternative names.
    pub alias_attribute_name: Option<String>,
    /// `CheckControlVariables` (default nie).
    pub check_control_variables: bool,
    /// `CheckLimits` (default nie).
    pub check_limits: bool,
    /// `AggregateMode` (default 0).
    pub aggregate_mode: AggregateMode,
    /// `QualityGoodThreshold`, percent 0..=100 (default 80).
    pub quality_good_threshold: u8,
    /// `AlarmsSystemNetworkName`.
    pub alarms_system_network_name: Option<String>,
    /// `ReportsDirectory`.
    pub reports_directory: Option<String>,
    /// `IniFilePath`: the asix application's ini file.
    pub ini_file_path: Option<String>,
    /// `AsixEvoRest`: the base URLs (`http://` or `https://`, no credential in them) of
    /// the Asix.Evo REST servers the channel reads from, in order of preference
    /// (hot-standby stations); empty: the channel uses the asix network.
    pub asix_evo_rest: Vec<String>,
    /// `AsixEvoUser`: the user of HTTP basic authentication.
    pub asix_evo_user: Option<String>,
    /// `AsixEvoPassword`: its password.
    pub asix_evo_password: Option<Secret>,
    /// `AsixEvoHeader`: `Name: value`, a header sent with every request (an API key).
    pub asix_evo_header: Option<Secret>,
    /// `AsixEvoPollTimeout`, ms (default 3000, 100..=600000): the longest a poll request
    /// may take, body included.
    pub asix_evo_poll_timeout_ms: u32,
    /// `AsixEvoMaxBatch` (default 100, 1..=1000): the most names in one request.
    pub asix_evo_max_batch: u32,
    /// `AsixNetServerFingerprint`: the SHA-256 fingerprints (64 hex digits each, `:` and
    /// blanks allowed, comma-separated) of the asix servers' certificates the channel
    /// accepts.
    pub asix_net_server_fingerprints: Vec<String>,
    /// `AsixNetCaFile`: a PEM file of the CA certificates whose servers the channel accepts.
    pub asix_net_ca_file: Option<String>,
    /// `AsixNetCertFile`: the PEM certificate the server presents to asix servers.
    pub asix_net_cert_file: Option<String>,
    /// `AsixNetKeyFile`: its private key (PEM).
    pub asix_net_key_file: Option<String>,
    /// `AsixNetPlaintext` (default nie): plaintext links, no authentication, no encryption
    /// (a closed test network only).
    pub asix_net_plaintext: bool,
}

impl ChannelOptions {
    /// Does the channel read from Asix.Evo REST servers (its items are then read-only)?
    pub fn is_asix_evo_rest(&self) -> bool {
        !self.asix_evo_rest.is_empty()
    }
}

/// A credential from the configuration: its `Debug` shows no character of it, so that no
/// log line or error message built from the options can hold it.
#[derive(Clone, PartialEq, Eq)]
pub struct Secret(String);

impl Secret {
    pub fn new(s: impl Into<String>) -> Self {
        Secret(s.into())
    }
    /// The credential itself, for the one place that sends it.
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Secret(..)")
    }
}

impl Default for ChannelOptions {
    fn default() -> Self {
        ChannelOptions {
            asix_server_name: String::new(),
            stop_after_first_server_found: true,
            find_server_timeout_ms: 3000,
            net_timeout_ms: 3000,
            items_database: None,
            alias_attribute_name: None,
            check_control_variables: false,
            check_limits: false,
            aggregate_mode: AggregateMode::Askom,
            quality_good_threshold: 80,
            alarms_system_network_name: None,
            reports_directory: None,
            ini_file_path: None,
            asix_evo_rest: Vec::new(),
            asix_evo_user: None,
            asix_evo_password: None,
            asix_evo_header: None,
            asix_evo_poll_timeout_ms: 3000,
            asix_evo_max_batch: 100,
            asix_net_server_fingerprints: Vec::new(),
            asix_net_ca_file: None,
            asix_net_cert_file: None,
            asix_net_key_file: None,
            asix_net_plaintext: false,
        }
    }
}

/// Which asix servers a resource may be served by (manual §3.6.1.2).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ServerSelection {
    /// Any server offering the resource (variant 1).
    Any,
    /// Only the local asix server (variant 4, `LOCAL`).
    Local,
    /// One of these servers (variants 2 and 3).
    Named(Vec<String>),
}

impl ServerSelection {
    /// Parses an `AsixServerName` value or a server-list value.
    pub fn parse(text: &str) -> ServerSelection {
        let t = text.trim();
        if t.is_empty() || t == "*" {
            return ServerSelection::Any;
        }
        if t.eq_ignore_ascii_case("LOCAL") {
            return ServerSelection::Local;
        }
        let names = split_list(t);
        if names.is_empty() {
            ServerSelection::Any
        } else {
            ServerSelection::Named(names)
        }
    }
}

/// A channel an access path resolved to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ResolvedChannel<'a> {
    /// `*` for the basic channel (also for empty and `ANY...` paths), else the name.
    pub name: &'a str,
    pub options: &'a ChannelOptions,
    /// False for `NEW...` channels (defaults, nothing stored).
    pub stored: bool,
}

/// The whole configuration file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AsixConfig {
    /// The file name used in messages.
    pub file: String,
    /// Directory relative paths in options are resolved against (the ini's folder).
    pub base_dir: Option<PathBuf>,
    pub server: ServerOptions,
    /// `[UA]`: the OPC UA front end.
    pub ua: UaOptions,
    /// Channels by name; `*` is always present.
    pub channels: BTreeMap<String, ChannelOptions>,
    /// `[AsixCTServers]`: current-data servers by channel.
    pub ct_servers: BTreeMap<String, Vec<String>>,
    /// `[AsixHTServers]`: archive servers by archive.
    pub ht_servers: BTreeMap<String, Vec<String>>,
    /// `[AsixALServers]`: alarm servers by alarm-server network name.
    pub al_servers: BTreeMap<String, Vec<String>>,
    /// `[WriteRights]` and `ZEZWOLENIE_ZAPISU`: who may write (open without them).
    pub write_rights: WriteRights,
}

/// The options every `NEW...` channel gets.
static NEW_CHANNEL_DEFAULTS: std::sync::OnceLock<ChannelOptions> = std::sync::OnceLock::new();

impl Default for AsixConfig {
    fn default() -> Self {
        let mut channels = BTreeMap::new();
        channels.insert(BASIC_CHANNEL.to_owned(), ChannelOptions::default());
        AsixConfig {
            file: "ASIXConnect.ini".to_owned(),
            base_dir: None,
            server: ServerOptions::default(),
            ua: UaOptions::default(),
            channels,
            ct_servers: BTreeMap::new(),
            ht_servers: BTreeMap::new(),
            al_servers: BTreeMap::new(),
            write_rights: WriteRights::open(),
        }
    }
}

impl AsixConfig {
    /// The basic channel's options.
    pub fn basic(&self) -> &ChannelOptions {
        // `*` is inserted by every constructor; fall back to defaults if a caller removed it.
        self.channels
            .get(BASIC_CHANNEL)
            .unwrap_or_else(|| NEW_CHANNEL_DEFAULTS.get_or_init(ChannelOptions::default))
    }

    /// Resolves an OPC access path to a channel (rules in the module documentation).
    pub fn resolve_channel<'a>(&'a self, access_path: &'a str) -> OpcResult<ResolvedChannel<'a>> {
        if access_path.is_empty() || access_path == BASIC_CHANNEL || access_path.starts_with("ANY")
        {
            return Ok(ResolvedChannel {
                name: BASIC_CHANNEL,
                options: self.basic(),
                stored: true,
            });
        }
        if access_path.starts_with("NEW") {
            let options = NEW_CHANNEL_DEFAULTS.get_or_init(ChannelOptions::default);
            return Ok(ResolvedChannel {
                name: access_path,
                options,
                stored: false,
            });
        }
        match self.channels.get_key_value(access_path) {
            Some((name, options)) => Ok(ResolvedChannel {
                name,
                options,
                stored: true,
            }),
            None => Err(OpcError::UnknownPath),
        }
    }

    /// The operations settings of the whole file: `[Server]`'s
    /// ([`ServerOptions::ops_config`]) and the write rights.
    pub fn ops_config(&self) -> ctopc_core::ops::OpsConfig {
        ctopc_core::ops::OpsConfig {
            write_rights: std::sync::Arc::new(self.write_rights.clone()),
            ..self.server.ops_config()
        }
    }

    /// The servers the current data of `channel` may come from: its `AsixServerName`, else
    /// its `[AsixCTServers]` entry, else any server.
    pub fn current_data_servers(&self, channel: &str) -> ServerSelection {
        let own = self
            .resolve_channel(channel)
            .map(|c| c.options.asix_server_name.as_str())
            .unwrap_or("");
        match ServerSelection::parse(own) {
            ServerSelection::Any => match self.ct_servers.get(channel) {
                Some(list) if !list.is_empty() => ServerSelection::Named(list.clone()),
                _ => ServerSelection::Any,
            },
            other => other,
        }
    }

    /// Resolves a path option: absolute paths (`C:\...`, `\\server\...`, `/...`) are kept,
    /// relative ones are taken from [`base_dir`](Self::base_dir). On hosts whose separator
    /// is `/`, backslashes are turned into slashes.
    pub fn resolve_path(&self, path: &str) -> PathBuf {
        let native = if std::path::MAIN_SEPARATOR == '/' {
            path.replace('\\', "/")
        } else {
            path.to_owned()
        };
        let b = path.as_bytes();
        let windows_absolute = (b.len() >= 2 && b[0].is_ascii_alphabetic() && b[1] == b':')
            || path.starts_with("\\\\")
            || path.starts_with('\\');
        if windows_absolute || Path::new(&native).is_absolute() {
            return PathBuf::from(native);
        }
        match &self.base_dir {
            Some(dir) => dir.join(native),
            None => PathBuf::from(native),
        }
    }

    /// The files of secrets the configuration names, as the server finds them when its
    /// configuration file is in `dir`: a configured path through
    /// [`resolve_path`](Self::resolve_path), a relative one (and an unset one's default)
    /// beside the configuration. The OPC UA paths are there with or without a `[UA]`
    /// section (the server makes them once OPC UA is turned on).
    pub fn secret_paths(&self, dir: &Path) -> SecretPaths {
        let path = |configured: Option<&str>, default: &str| {
            let p = configured.map_or_else(|| PathBuf::from(default), |c| self.resolve_path(c));
            if p.is_absolute() || p.to_string_lossy().starts_with('\\') {
                p
            } else {
                dir.join(p)
            }
        };
        let pki = path(self.ua.pki_directory.as_deref(), UA_PKI_DEFAULT);
        SecretPaths {
            ua_private_key: pki.join(ua_private_key_in_store()),
            ua_pki: pki,
            ua_users_file: path(self.ua.users_file.as_deref(), UA_USERS_FILE_DEFAULT),
            key_files: self
                .channels
                .iter()
                .filter_map(|(name, o)| {
                    let key = o.asix_net_key_file.as_deref()?;
                    Some((name.clone(), path(Some(key), "")))
                })
                .collect(),
        }
    }
}

/// `[UA]`'s certificate store when `PkiDirectory` is unset (beside the configuration).
pub const UA_PKI_DEFAULT: &str = "pki";
/// `[UA]`'s users file when `UsersFile` is unset (beside the configuration).
pub const UA_USERS_FILE_DEFAULT: &str = "ua-users.txt";
/// The folder of the application instance certificate's private key, in the store.
pub const UA_PRIVATE_KEY_FOLDER: &str = "private";
/// The private key's file, in [`UA_PRIVATE_KEY_FOLDER`].
pub const UA_PRIVATE_KEY_FILE: &str = "private.pem";

/// The OPC UA private key's path relative to the certificate store.
pub fn ua_private_key_in_store() -> PathBuf {
    Path::new(UA_PRIVATE_KEY_FOLDER).join(UA_PRIVATE_KEY_FILE)
}

/// The files of secrets of a configuration ([`AsixConfig::secret_paths`]): the one place
/// the server, `/ProtectSecrets` and opcdiag's doctor take them from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SecretPaths {
    /// The OPC UA certificate store (own, private, trusted, rejected).
    pub ua_pki: PathBuf,
    /// The OPC UA application instance certificate's private key.
    pub ua_private_key: PathBuf,
    /// The OPC UA users file.
    pub ua_users_file: PathBuf,
    /// Each channel's `AsixNetKeyFile`: (channel name, path).
    pub key_files: Vec<(String, PathBuf)>,
}

/// Why the configuration could not be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConfigErrorKind {
    /// The file does not exist.
    NotFound,
    /// The file exists but could not be read.
    Unreadable,
    /// Bad syntax or an invalid option value.
    Invalid,
}

/// A configuration error naming the file, the line (0: the whole file) and the option.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigError {
    pub kind: ConfigErrorKind,
    pub file: String,
    pub line: usize,
    pub option: Option<String>,
    pub message: String,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if self.line > 0 {
            write!(f, ":{}", self.line)?;
        }
        if let Some(o) = &self.option {
            write!(f, ": option {o}")?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for ConfigError {}

fn invalid(file: &str, e: &IniEntry, expected: &str) -> ConfigError {
    ConfigError {
        kind: ConfigErrorKind::Invalid,
        file: file.to_owned(),
        line: e.line,
        option: Some(e.key.clone()),
        message: format!("invalid value `{}`: expected {expected}", e.value),
    }
}

fn set_bool(target: &mut bool, file: &str, e: &IniEntry) -> Result<(), ConfigError> {
    if e.value.trim().is_empty() {
        return Ok(());
    }
    *target = parse_bool(&e.value).ok_or_else(|| invalid(file, e, "tak/true/1 or nie/false/0"))?;
    Ok(())
}

fn number(file: &str, e: &IniEntry, min: u32, max: u32) -> Result<Option<u32>, ConfigError> {
    let t = e.value.trim();
    if t.is_empty() {
        return Ok(None);
    }
    match t.parse::<u32>() {
        Ok(v) if (min..=max).contains(&v) => Ok(Some(v)),
        _ => Err(invalid(
            file,
            e,
            &format!("a whole number from {min} to {max}"),
        )),
    }
}

fn set_number(
    target: &mut u32,
    file: &str,
    e: &IniEntry,
    min: u32,
    max: u32,
) -> Result<(), ConfigError> {
    if let Some(v) = number(file, e, min, max)? {
        *target = v;
    }
    Ok(())
}

fn text(e: &IniEntry) -> Option<String> {
    let t = e.value.trim();
    (!t.is_empty()).then(|| t.to_owned())
}

/// Applies one `[Server]` option; `Ok(false)` for an unknown option.
fn apply_ua_option(o: &mut UaOptions, file: &str, e: &IniEntry) -> Result<bool, ConfigError> {
    match e.key.to_ascii_lowercase().as_str() {
        "enabled" => {
            if !e.value.trim().is_empty() {
                let mut on = false;
                set_bool(&mut on, file, e)?;
                o.enabled = Some(on);
            }
        }
        "endpoint" => {
            if let Some(url) = text(e) {
                let rest = url
                    .strip_prefix("opc.tcp://")
                    .filter(|r| !r.is_empty() && !r.starts_with(':') && !r.starts_with('/'));
                if rest.is_none() {
                    return Err(invalid(file, e, "an opc.tcp://host:port URL"));
                }
                o.endpoint = url;
            }
        }
        "allownone" => set_bool(&mut o.allow_none, file, e)?,
        "allowanonymous" => set_bool(&mut o.allow_anonymous, file, e)?,
        "pkidirectory" => o.pki_directory = text(e),
        "usersfile" => o.users_file = text(e),
        "maxsessions" => set_number(&mut o.max_sessions, file, e, 1, 10_000)?,
        "maxsubscriptionspersession" => {
            set_number(&mut o.max_subscriptions_per_session, file, e, 1, 10_000)?
        }
        "maxmonitoreditemspersubscription" => set_number(
            &mut o.max_monitored_items_per_subscription,
            file,
            e,
            1,
            10_000_000,
        )?,
        "maxmonitoreditems" => set_number(&mut o.max_monitored_items, file, e, 1, 100_000_000)?,
        "maxbrowsecontinuationpoints" => {
            set_number(&mut o.max_browse_continuation_points, file, e, 1, 10_000)?
        }
        "maxoperationsperrequest" => {
            set_number(&mut o.max_operations_per_request, file, e, 1, 1_000_000)?
        }
        "maxmessagesize" => set_number(&mut o.max_message_size, file, e, 8192, 1 << 30)?,
        "maxchunkcount" => set_number(&mut o.max_chunk_count, file, e, 1, 65_535)?,
        "maxarraylength" => set_number(&mut o.max_array_length, file, e, 1, 100_000_000)?,
        "maxstringlength" => set_number(&mut o.max_string_length, file, e, 4096, 1 << 30)?,
        "maxrequestspersecond" => {
            set_number(&mut o.max_requests_per_second, file, e, 0, 10_000_000)?
        }
        _ => return Ok(false),
    }
    Ok(true)
}

fn apply_server_option(
    o: &mut ServerOptions,
    file: &str,
    e: &IniEntry,
) -> Result<bool, ConfigError> {
    match e.key.to_ascii_lowercase().as_str() {
        "logdirectory" => o.log_directory = text(e),
        "attributesasitems" => set_bool(&mut o.attributes_as_items, file, e)?,
        "minupdaterate" => set_number(&mut o.min_update_rate_ms, file, e, 1, u32::MAX)?,
        "defaultlanguage" => {
            let t = e.value.trim().to_ascii_lowercase();
            o.default_language = match t.as_str() {
                "" | "system" | "auto" => DefaultLanguage::System,
                "pl" | "polski" | "polish" | "1045" | "0x0415" => DefaultLanguage::Polish,
                "en" | "angielski" | "english" | "1033" | "0x0409" => DefaultLanguage::English,
                _ => return Err(invalid(file, e, "pl, en or system")),
            }
        }
        "simulatecurrentdata" => set_bool(&mut o.simulate_current_data, file, e)?,
        "auditwrites" => set_bool(&mut o.audit_writes, file, e)?,
        "legacyopenaccess" => set_bool(&mut o.legacy_open_access, file, e)?,
        "callbacktimeout" => set_number(&mut o.callback_timeout_ms, file, e, 0, 600_000)?,
        "callbackfailures" => set_number(&mut o.callback_failures, file, e, 1, 1000)?,
        "metricsaddress" => o.metrics_address = text(e),
        "clientname" => o.client_name = text(e),
        "broadcastaddress" => o.broadcast_address = text(e),
        "discoveryport" => o.discovery_port = number(file, e, 1, 65535)?.map(|v| v as u16),
        "dataport" => o.data_port = number(file, e, 1, 65535)?.map(|v| v as u16),
        "reconnectinterval" => set_number(&mut o.reconnect_interval_ms, file, e, 1, u32::MAX)?,
        "loglevel" => {
            o.log_level = match e.value.trim().to_ascii_lowercase().as_str() {
                "" | "info" => LogLevel::Info,
                "debug" => LogLevel::Debug,
                "warn" | "warning" => LogLevel::Warn,
                "error" => LogLevel::Error,
                _ => return Err(invalid(file, e, "error, warn, info or debug")),
            }
        }
        "logmaxfilesizemb" => set_number(&mut o.log_max_file_size_mb, file, e, 1, 4096)?,
        "logkeepfiles" => set_number(&mut o.log_keep_files, file, e, 1, 100_000)?,
        "sourcetimeout" => {
            let (min, max) = SOURCE_TIMEOUT_RANGE_MS;
            set_number(&mut o.source_timeout_ms, file, e, min, max)?
        }
        "firstsamplewait" => set_number(
            &mut o.first_sample_wait_ms,
            file,
            e,
            0,
            MAX_FIRST_SAMPLE_WAIT_MS,
        )?,
        "simulationdevicedelay" => set_number(
            &mut o.simulation_device_delay_ms,
            file,
            e,
            0,
            MAX_SIMULATION_DEVICE_DELAY_MS,
        )?,
        _ => return Ok(false),
    }
    Ok(true)
}

/// Applies one channel option; `Ok(false)` for an unknown option.
fn apply_channel_option(
    o: &mut ChannelOptions,
    file: &str,
    e: &IniEntry,
) -> Result<bool, ConfigError> {
    match e.key.to_ascii_lowercase().as_str() {
        "asixservername" => o.asix_server_name = e.value.trim().to_owned(),
        "stopafterfirstserverfound" => set_bool(&mut o.stop_after_first_server_found, file, e)?,
        "findservertimeout" => set_number(&mut o.find_server_timeout_ms, file, e, 0, u32::MAX)?,
        "nettimeout" => set_number(&mut o.net_timeout_ms, file, e, 0, u32::MAX)?,
        "itemsdatabase" => o.items_database = text(e),
        "aliasattributename" => o.alias_attribute_name = text(e),
        "checkcontrolvariables" => set_bool(&mut o.check_control_variables, file, e)?,
        "checklimits" => set_bool(&mut o.check_limits, file, e)?,
        "aggregatemode" => {
            if let Some(v) =
                number(file, e, 0, 1).map_err(|_| invalid(file, e, "0 (Askom) or 1 (OPC)"))?
            {
                o.aggregate_mode = if v == 0 {
                    AggregateMode::Askom
                } else {
                    AggregateMode::Opc
                };
            }
        }
        "qualitygoodthreshold" => {
            if let Some(v) = number(file, e, 0, 100)? {
                o.quality_good_threshold = v as u8;
            }
        }
        "alarmssystemnetworkname" => o.alarms_system_network_name = text(e),
        "reportsdirectory" => o.reports_directory = text(e),
        "inifilepath" => o.ini_file_path = text(e),
        "asixevorest" => o.asix_evo_rest = rest_urls(file, e)?,
        "asixevouser" => o.asix_evo_user = text(e),
        "asixevopassword" => o.asix_evo_password = text(e).map(Secret),
        "asixevoheader" => {
            o.asix_evo_header = match text(e) {
                None => None,
                Some(h) => match h.split_once(':') {
                    Some((name, _)) if is_header_name(name.trim()) => Some(Secret(h)),
                    // The value is not quoted back: it is a credential.
                    _ => {
                        return Err(ConfigError {
                            kind: ConfigErrorKind::Invalid,
                            file: file.to_owned(),
                            line: e.line,
                            option: Some(e.key.clone()),
                            message: "invalid value: expected `Name: value` (a header name of letters, digits and `-`)".into(),
                        })
                    }
                },
            }
        }
        "asixevopolltimeout" => set_number(&mut o.asix_evo_poll_timeout_ms, file, e, 100, 600_000)?,
        "asixevomaxbatch" => set_number(&mut o.asix_evo_max_batch, file, e, 1, 1000)?,
        "asixnetserverfingerprint" => {
            let list = split_list(&e.value);
            if !list.iter().all(|f| is_fingerprint(f)) {
                return Err(invalid(
                    file,
                    e,
                    "SHA-256 fingerprints (64 hex digits each, `:` allowed), comma-separated",
                ));
            }
            o.asix_net_server_fingerprints = list;
        }
        "asixnetcafile" => o.asix_net_ca_file = text(e),
        "asixnetcertfile" => o.asix_net_cert_file = text(e),
        "asixnetkeyfile" => o.asix_net_key_file = text(e),
        "asixnetplaintext" => set_bool(&mut o.asix_net_plaintext, file, e)?,
        _ => return Ok(false),
    }
    Ok(true)
}

/// A SHA-256 fingerprint as certificate tools print it: 64 hex digits, optionally
/// separated by `:` or blanks.
fn is_fingerprint(s: &str) -> bool {
    let digits: Vec<u8> = s.bytes().filter(|b| !matches!(b, b':' | b' ')).collect();
    digits.len() == 64 && digits.iter().all(u8::is_ascii_hexdigit)
}

/// An HTTP header name (RFC 9110 token characters).
fn is_header_name(s: &str) -> bool {
    !s.is_empty()
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"!#$%&'*+-.^_`|~".contains(&b))
}

/// `AsixEvoRest`: a comma-separated list of `http://` or `https://` base URLs. A URL with
/// a user or password in it is refused (without quoting it): the credential has options
/// of its own, which no log line shows.
fn rest_urls(file: &str, e: &IniEntry) -> Result<Vec<String>, ConfigError> {
    let mut out = Vec::new();
    for u in split_list(&e.value) {
        let lower = u.to_ascii_lowercase();
        let rest = lower
            .strip_prefix("http://")
            .or_else(|| lower.strip_prefix("https://"));
        let Some(rest) = rest else {
            return Err(invalid(
                file,
                e,
                "http:// or https:// base URLs separated by commas",
            ));
        };
        let authority = rest.split(['/', '?', '#']).next().unwrap_or("");
        if authority.contains('@') {
            return Err(ConfigError {
                kind: ConfigErrorKind::Invalid,
                file: file.to_owned(),
                line: e.line,
                option: Some(e.key.clone()),
                message: "a URL holds a credential: give it in AsixEvoUser/AsixEvoPassword or AsixEvoHeader instead".into(),
            });
        }
        if authority.is_empty() || u.contains(char::is_whitespace) {
            return Err(invalid(
                file,
                e,
                "http:// or https:// base URLs separated by commas",
            ));
        }
        out.push(u.trim_end_matches('/').to_owned());
    }
    Ok(out)
}

fn server_list(
    section: &IniSection,
    file: &str,
    warnings: &mut Vec<Warning>,
) -> BTreeMap<String, Vec<String>> {
    let mut map = BTreeMap::new();
    for e in &section.entries {
        let names = split_list(&e.value);
        if names.is_empty() {
            warnings.push(Warning::new(
                file,
                e.line,
                format!("[{}] {}: empty server list ignored", section.name, e.key),
            ));
            continue;
        }
        map.insert(e.key.clone(), names);
    }
    map
}

/// The write-rights sections: `[WriteRights]`, and `[ASMEN]` for `ZEZWOLENIE_ZAPISU`.
const WRITE_RIGHTS_SECTION: &str = "WriteRights";
const ASMEN_SECTION: &str = "ASMEN";
/// The original's write-permission key (`ZEZWOLENIE_ZAPISU = <channel>, <client>, ...`).
pub const PERMIT_KEY: &str = "ZEZWOLENIE_ZAPISU";

/// Reads one `ZEZWOLENIE_ZAPISU = <channel>, <client>, ...` line into `rules`.
fn permit_line(file: &str, e: &IniEntry, rules: &mut Vec<Rule>) -> Result<(), ConfigError> {
    let list = split_list(&e.value);
    let Some((channel, clients)) = list.split_first().filter(|(_, c)| !c.is_empty()) else {
        return Err(invalid(file, e, "<channel>, <client>[, <client>...]"));
    };
    let channels = if channel == BASIC_CHANNEL {
        Channels::All
    } else {
        Channels::One(channel.clone())
    };
    for c in clients {
        let principal = Principal::parse_asix_permit(c).map_err(|err| ConfigError {
            kind: ConfigErrorKind::Invalid,
            file: file.to_owned(),
            line: e.line,
            option: Some(e.key.clone()),
            message: err.to_string(),
        })?;
        rules.push(Rule::new(channels.clone(), principal));
    }
    Ok(())
}

/// Reads one line of `[WriteRights]` into `rules`.
fn write_rights_line(
    file: &str,
    e: &IniEntry,
    rules: &mut Vec<Rule>,
    warnings: &mut Vec<Warning>,
) -> Result<(), ConfigError> {
    if e.key.eq_ignore_ascii_case(PERMIT_KEY) {
        return permit_line(file, e, rules);
    }
    let key = e.key.trim();
    if key.starts_with("ANY") {
        return Err(ConfigError {
            kind: ConfigErrorKind::Invalid,
            file: file.to_owned(),
            line: e.line,
            option: Some(e.key.clone()),
            message: format!(
                "channel name `{key}` is reserved: names starting with ANY use channel *, whose writers are the `*` line's"
            ),
        });
    }
    let channels = if key == BASIC_CHANNEL {
        Channels::All
    } else {
        Channels::One(key.to_owned())
    };
    let identities = split_list(&e.value);
    if identities.is_empty() {
        warnings.push(Warning::new(
            file,
            e.line,
            format!("[{WRITE_RIGHTS_SECTION}] {key}: no identity listed; the line grants nothing"),
        ));
    }
    for id in identities {
        let principal = Principal::parse(&id).map_err(|err| ConfigError {
            kind: ConfigErrorKind::Invalid,
            file: file.to_owned(),
            line: e.line,
            option: Some(e.key.clone()),
            message: err.to_string(),
        })?;
        rules.push(Rule::new(channels.clone(), principal));
    }
    Ok(())
}

/// Warns about write-rights entries for channels the file does not configure.
fn check_write_rights_channels(
    config: &AsixConfig,
    lines: &[(usize, String)],
    file: &str,
    warnings: &mut Vec<Warning>,
) {
    for (line, channel) in lines {
        if config.channels.contains_key(channel) || channel.starts_with("NEW") {
            continue;
        }
        let near = config
            .channels
            .keys()
            .find(|c| c.eq_ignore_ascii_case(channel))
            .map(|c| format!(" (channel names are case-sensitive: did you mean `{c}`?)"))
            .unwrap_or_default();
        warnings.push(Warning::new(
            file,
            *line,
            format!("write rights for channel `{channel}`, which no [Channel:] section configures{near}"),
        ));
    }
}

/// Parses `ASIXConnect.ini` bytes; `file` names the file in messages. Relative paths are
/// left unresolved ([`AsixConfig::base_dir`] is `None`).
pub fn parse_config(bytes: &[u8], file: &str) -> Result<(AsixConfig, Vec<Warning>), ConfigError> {
    let lists = [WRITE_RIGHTS_SECTION, ASMEN_SECTION];
    let (doc, mut warnings) =
        parse_ini_with_lists(bytes, file, &lists).map_err(|e| ConfigError {
            kind: ConfigErrorKind::Invalid,
            file: file.to_owned(),
            line: e.line,
            option: None,
            message: e.message,
        })?;
    let mut config = AsixConfig {
        file: file.to_owned(),
        ..AsixConfig::default()
    };
    let mut rules: Option<Vec<Rule>> = None;
    for section in &doc.sections {
        let lower = section.name.to_ascii_lowercase();
        if lower == "server" {
            for e in &section.entries {
                if !apply_server_option(&mut config.server, file, e)? {
                    warnings.push(Warning::new(
                        file,
                        e.line,
                        format!("unknown option `{}` in [Server] ignored", e.key),
                    ));
                }
            }
        } else if let Some(name) = lower
            .strip_prefix("channel:")
            .map(|_| section.name[8..].trim())
        {
            let error = |message: String| ConfigError {
                kind: ConfigErrorKind::Invalid,
                file: file.to_owned(),
                line: section.line,
                option: None,
                message,
            };
            if name.is_empty() {
                return Err(error(
                    "[Channel:] needs a channel name (use [Channel:*] for the basic channel)"
                        .into(),
                ));
            }
            if name.starts_with("ANY") || name.starts_with("NEW") {
                return Err(error(format!(
                    "channel name `{name}` is reserved: names starting with ANY use channel *, names starting with NEW get the defaults"
                )));
            }
            let mut options = ChannelOptions::default();
            for e in &section.entries {
                if !apply_channel_option(&mut options, file, e)? {
                    warnings.push(Warning::new(
                        file,
                        e.line,
                        format!("unknown option `{}` in [{}] ignored", e.key, section.name),
                    ));
                }
            }
            config.channels.insert(name.to_owned(), options);
        } else if lower == "ua" {
            config.ua.section = true;
            for e in &section.entries {
                if !apply_ua_option(&mut config.ua, file, e)? {
                    warnings.push(Warning::new(
                        file,
                        e.line,
                        format!("unknown option `{}` in [UA] ignored", e.key),
                    ));
                }
            }
        } else if lower == "asixctservers" {
            config.ct_servers = server_list(section, file, &mut warnings);
        } else if lower == "asixhtservers" {
            config.ht_servers = server_list(section, file, &mut warnings);
        } else if lower == "asixalservers" {
            config.al_servers = server_list(section, file, &mut warnings);
        } else if lower == "writerights" {
            let rules = rules.get_or_insert_with(Vec::new);
            for e in &section.entries {
                write_rights_line(file, e, rules, &mut warnings)?;
            }
        } else if lower == "asmen" {
            for e in &section.entries {
                if e.key.eq_ignore_ascii_case(PERMIT_KEY) {
                    permit_line(file, e, rules.get_or_insert_with(Vec::new))?;
                } else {
                    warnings.push(Warning::new(
                        file,
                        e.line,
                        format!(
                            "`{}` in [{}] ignored: only {PERMIT_KEY} is read there",
                            e.key, section.name
                        ),
                    ));
                }
            }
        } else {
            warnings.push(Warning::new(
                file,
                section.line,
                format!("unknown section [{}] ignored", section.name),
            ));
        }
    }
    if let Some(rules) = rules {
        let named: Vec<(usize, String)> = doc
            .sections
            .iter()
            .filter(|s| {
                s.name.eq_ignore_ascii_case(WRITE_RIGHTS_SECTION)
                    || s.name.eq_ignore_ascii_case(ASMEN_SECTION)
            })
            .flat_map(|s| {
                let asmen = s.name.eq_ignore_ascii_case(ASMEN_SECTION);
                s.entries.iter().map(move |e| (asmen, e))
            })
            .filter_map(|(asmen, e)| {
                let channel = if e.key.eq_ignore_ascii_case(PERMIT_KEY) {
                    split_list(&e.value).into_iter().next()?
                } else if asmen {
                    return None;
                } else {
                    e.key.trim().to_owned()
                };
                (channel != BASIC_CHANNEL).then_some((e.line, channel))
            })
            .collect();
        check_write_rights_channels(&config, &named, file, &mut warnings);
        config.write_rights = WriteRights::new(rules);
    }
    Ok((config, warnings))
}

/// Reads and parses a configuration file; relative paths in it resolve against its folder.
pub fn load_config_file(path: &Path) -> Result<(AsixConfig, Vec<Warning>), ConfigError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| ConfigError {
        kind: if e.kind() == std::io::ErrorKind::NotFound {
            ConfigErrorKind::NotFound
        } else {
            ConfigErrorKind::Unreadable
        },
        file: file.clone(),
        line: 0,
        option: None,
        message: e.to_string(),
    })?;
    let (mut config, warnings) = parse_config(&bytes, &file)?;
    config.base_dir = path.parent().map(Path::to_path_buf);
    Ok((config, warnings))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn parse(text: &str) -> Result<(AsixConfig, Vec<Warning>), ConfigError> {
        parse_config(text.as_bytes(), "ASIXConnect.ini")
    }

    /// The secret files: defaults and relative paths beside the configuration's folder,
    /// absolute ones kept, each channel's key file, the private key in the store's
    /// `private` folder.
    #[test]
    fn secret_paths_are_beside_the_configuration_unless_absolute() {
        let dir = Path::new("/etc/ctopc");
        let (c, _) = parse("[Channel:A]\nAsixNetKeyFile = keys/a.pem\n").unwrap();
        let p = c.secret_paths(dir);
        assert_eq!(p.ua_pki, dir.join("pki"));
        assert_eq!(p.ua_private_key, dir.join("pki/private/private.pem"));
        assert_eq!(p.ua_users_file, dir.join("ua-users.txt"));
        assert_eq!(p.key_files, [("A".to_owned(), dir.join("keys/a.pem"))]);
        let (c, _) = parse(
            "[UA]\nPkiDirectory = /var/lib/ctopc/pki\nUsersFile = users/ua.txt\n\
             [Channel:B]\nAsixNetKeyFile = /secret/b.pem\n",
        )
        .unwrap();
        let p = c.secret_paths(dir);
        assert_eq!(p.ua_pki, Path::new("/var/lib/ctopc/pki"));
        assert_eq!(
            p.ua_private_key,
            Path::new("/var/lib/ctopc/pki/private/private.pem")
        );
        assert_eq!(p.ua_users_file, dir.join("users/ua.txt"));
        assert_eq!(
            p.key_files,
            [("B".to_owned(), PathBuf::from("/secret/b.pem"))]
        );
    }

    #[test]
    fn ua_beside_da_when_the_section_is_there_unless_enabled_says_otherwise() {
        for (text, beside) in [
            ("", false),
            ("[UA]\n", true),
            ("[UA]\nEnabled =\n", true),
            ("[UA]\nEnabled = nie\n", false),
            ("[UA]\nEnabled = 1\n", true),
            ("[ua]\nEndpoint = opc.tcp://plant:4841\n", true),
        ] {
            let (c, w) = parse(text).unwrap();
            assert!(w.is_empty(), "{text}: {w:?}");
            assert_eq!(c.ua.beside_da(), beside, "{text}");
        }
    }

    #[test]
    fn ua_section_options_and_defaults() {
        let (c, w) = parse("").unwrap();
        assert!(w.is_empty());
        assert_eq!(c.ua, UaOptions::default());
        assert!(!c.ua.allow_none && !c.ua.allow_anonymous);
        assert_eq!(c.ua.endpoint, "opc.tcp://0.0.0.0:4840");
        let (c, w) = parse(
            "[UA]\nEndpoint = opc.tcp://plant:4841\nAllowNone = tak\nAllowAnonymous = 1\nPkiDirectory = certs\nUsersFile = users.txt\nMaxSessions = 5\nMaxSubscriptionsPerSession = 3\nMaxMonitoredItemsPerSubscription = 1000\nMaxMonitoredItems = 11\nMaxBrowseContinuationPoints = 12\nMaxOperationsPerRequest = 13\nMaxMessageSize = 65536\nMaxChunkCount = 15\nMaxArrayLength = 16\nMaxStringLength = 8192\nMaxRequestsPerSecond = 0\nFoo = 1\n",
        )
        .unwrap();
        assert_eq!(w.len(), 1, "{w:?}");
        assert_eq!(c.ua.endpoint, "opc.tcp://plant:4841");
        assert!(c.ua.allow_none && c.ua.allow_anonymous);
        assert_eq!(c.ua.pki_directory.as_deref(), Some("certs"));
        assert_eq!(c.ua.users_file.as_deref(), Some("users.txt"));
        assert_eq!(
            (
                c.ua.max_sessions,
                c.ua.max_subscriptions_per_session,
                c.ua.max_monitored_items_per_subscription
            ),
            (5, 3, 1000)
        );
        let u = &c.ua;
        assert_eq!(
            (
                u.max_monitored_items,
                u.max_browse_continuation_points,
                u.max_operations_per_request,
                u.max_message_size,
                u.max_chunk_count,
                u.max_array_length,
                u.max_string_length,
                u.max_requests_per_second
            ),
            (11, 12, 13, 65536, 15, 16, 8192, 0)
        );
        for bad in [
            "[UA]\nEndpoint = http://plant:4840\n",
            "[UA]\nEndpoint = opc.tcp://\n",
            "[UA]\nMaxSessions = 0\n",
            "[UA]\nMaxMessageSize = 8191\n",
            "[UA]\nMaxStringLength = 100\n",
            "[UA]\nMaxChunkCount = 0\n",
            "[UA]\nAllowNone = maybe\n",
            "[UA]\nEnabled = maybe\n",
        ] {
            let e = parse(bad).unwrap_err();
            assert_eq!(e.line, 2, "{bad}: {e}");
        }
    }

    #[test]
    fn asix_evo_rest_options() {
        let (c, w) = parse(
            "[Channel:EVO]\nAsixEvoRest = http://evo1:8080/, HTTPS://evo2\nAsixEvoUser = opc\nAsixEvoPassword = s3cr3t-pw\nAsixEvoHeader = X-Api-Key: k3y-s3cr3t\nAsixEvoPollTimeout = 1500\nAsixEvoMaxBatch = 20\n[Channel:NET]\n",
        )
        .unwrap();
        assert!(w.is_empty(), "{w:?}");
        let o = &c.channels["EVO"];
        assert_eq!(o.asix_evo_rest, ["http://evo1:8080", "HTTPS://evo2"]);
        assert!(o.is_asix_evo_rest());
        assert_eq!(o.asix_evo_user.as_deref(), Some("opc"));
        assert_eq!(
            o.asix_evo_password.as_ref().map(Secret::expose),
            Some("s3cr3t-pw")
        );
        assert_eq!(
            o.asix_evo_header.as_ref().map(Secret::expose),
            Some("X-Api-Key: k3y-s3cr3t")
        );
        assert_eq!(
            (o.asix_evo_poll_timeout_ms, o.asix_evo_max_batch),
            (1500, 20)
        );
        let n = &c.channels["NET"];
        assert!(!n.is_asix_evo_rest());
        assert_eq!(
            (n.asix_evo_poll_timeout_ms, n.asix_evo_max_batch),
            (3000, 100)
        );
        // No credential in the options' Debug (what a log line of them would show).
        let dbg = format!("{c:?}");
        assert!(
            !dbg.contains("s3cr3t") && dbg.contains("Secret(..)"),
            "{dbg}"
        );
    }

    #[test]
    fn invalid_asix_evo_rest_values_never_quote_a_credential() {
        for (key, value, secret) in [
            ("AsixEvoRest", "ftp://x", None),
            ("AsixEvoRest", "evo1:8080", None),
            ("AsixEvoRest", "http://", None),
            ("AsixEvoRest", "http://user:pa55word@evo1", Some("pa55word")),
            ("AsixEvoHeader", "no colon pa55word", Some("pa55word")),
            ("AsixEvoHeader", "Bad Name: pa55word", Some("pa55word")),
            ("AsixEvoPollTimeout", "99", None),
            ("AsixEvoMaxBatch", "0", None),
            ("AsixEvoMaxBatch", "1001", None),
        ] {
            let err = parse(&format!("[Channel:E]\n{key} = {value}\n")).unwrap_err();
            assert_eq!(err.option.as_deref(), Some(key), "{key}={value}");
            if let Some(s) = secret {
                assert!(!err.to_string().contains(s), "{err}");
                assert!(!format!("{err:?}").contains(s), "{err:?}");
            }
        }
    }

    #[test]
    fn empty_file_gives_documented_defaults() {
        let (c, w) = parse("").unwrap();
        assert!(w.is_empty());
        let b = c.basic();
        assert_eq!(b.asix_server_name, "");
        assert!(b.stop_after_first_server_found);
        assert_eq!(b.find_server_timeout_ms, 3000);
        assert_eq!(b.net_timeout_ms, 3000);
        assert_eq!(b.items_database, None);
        assert_eq!(b.alias_attribute_name, None);
        assert!(!b.check_control_variables);
        assert!(!b.check_limits);
        assert_eq!(b.aggregate_mode, AggregateMode::Askom);
        assert_eq!(b.quality_good_threshold, 80);
        assert_eq!(b.alarms_system_network_name, None);
        assert_eq!(b.reports_directory, None);
        assert_eq!(b.ini_file_path, None);
        assert_eq!(c.server, ServerOptions::default());
        assert_eq!(c.server.min_update_rate_ms, 1000);
        assert!(!c.server.attributes_as_items);
        assert_eq!(
            c.server.source_timeout_ms,
            ctopc_core::model::DEFAULT_SOURCE_TIMEOUT_MS
        );
        assert_eq!(c.server.simulation_device_delay_ms, 0);
        assert_eq!(c.channels.len(), 1);
    }

    /// One row per (channel option, value) -> expected effect.
    #[test]
    fn channel_option_values() {
        type Check = fn(&ChannelOptions) -> bool;
        let rows: &[(&str, &str, Check)] = &[
            ("AsixServerName", "STACJA1, STACJA2", |o| {
                o.asix_server_name == "STACJA1, STACJA2"
            }),
            ("asixservername", "LOCAL", |o| o.asix_server_name == "LOCAL"),
            ("StopAfterFirstServerFound", "nie", |o| {
                !o.stop_after_first_server_found
            }),
            ("StopAfterFirstServerFound", "NIE", |o| {
                !o.stop_after_first_server_found
            }),
            ("StopAfterFirstServerFound", "false", |o| {
                !o.stop_after_first_server_found
            }),
            ("StopAfterFirstServerFound", "0", |o| {
                !o.stop_after_first_server_found
            }),
            ("StopAfterFirstServerFound", "", |o| {
                o.stop_after_first_server_found
            }),
            ("FindServerTimeout", "5000", |o| {
                o.find_server_timeout_ms == 5000
            }),
            ("FINDSERVERTIMEOUT", "0", |o| o.find_server_timeout_ms == 0),
            ("NetTimeout", "10000", |o| o.net_timeout_ms == 10000),
            ("ItemsDatabase", "C:\\asix\\baza.zez", |o| {
                o.items_database.as_deref() == Some("C:\\asix\\baza.zez")
            }),
            ("ItemsDatabase", "", |o| o.items_database.is_none()),
            ("AliasAttributeName", "Alias", |o| {
                o.alias_attribute_name.as_deref() == Some("Alias")
            }),
            ("CheckControlVariables", "tak", |o| {
                o.check_control_variables
            }),
            ("CheckControlVariables", "Tak", |o| {
                o.check_control_variables
            }),
            ("CheckLimits", "true", |o| o.check_limits),
            ("CheckLimits", "1", |o| o.check_limits),
            ("AggregateMode", "1", |o| {
                o.aggregate_mode == AggregateMode::Opc
            }),
            ("AggregateMode", "0", |o| {
                o.aggregate_mode == AggregateMode::Askom
            }),
            ("QualityGoodThreshold", "100", |o| {
                o.quality_good_threshold == 100
            }),
            ("QualityGoodThreshold", "0", |o| {
                o.quality_good_threshold == 0
            }),
            ("AlarmsSystemNetworkName", "ALARMY", |o| {
                o.alarms_system_network_name.as_deref() == Some("ALARMY")
            }),
            ("ReportsDirectory", "C:\\asix\\Raporty", |o| {
                o.reports_directory.as_deref() == Some("C:\\asix\\Raporty")
            }),
            ("IniFilePath", "C:\\asix\\kwas.ini", |o| {
                o.ini_file_path.as_deref() == Some("C:\\asix\\kwas.ini")
            }),
            (
                "AsixNetServerFingerprint",
                "9F:86:D0:81:88:4C:7D:65:9A:2F:EA:A0:C5:5A:D0:15:A3:BF:4F:1B:2B:0B:82:2C:D1:5D:6C:15:B0:F0:0A:08, 9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08",
                |o| o.asix_net_server_fingerprints.len() == 2,
            ),
            ("AsixNetCaFile", "certs\\ca.pem", |o| {
                o.asix_net_ca_file.as_deref() == Some("certs\\ca.pem")
            }),
            ("AsixNetCertFile", "certs\\opc.pem", |o| {
                o.asix_net_cert_file.as_deref() == Some("certs\\opc.pem")
            }),
            ("AsixNetKeyFile", "certs\\opc-key.pem", |o| {
                o.asix_net_key_file.as_deref() == Some("certs\\opc-key.pem")
            }),
            ("AsixNetPlaintext", "1", |o| o.asix_net_plaintext),
            ("AsixNetPlaintext", "nie", |o| !o.asix_net_plaintext),
        ];
        for (key, value, check) in rows {
            let (c, w) = parse(&format!("[Channel:Kanal]\n{key} = {value}\n")).unwrap();
            assert!(w.is_empty(), "{key}={value}: {w:?}");
            assert!(check(&c.channels["Kanal"]), "{key} = {value}");
            let (c, _) = parse(&format!("[Channel:*]\n{key} = {value}\n")).unwrap();
            assert!(check(c.basic()), "* {key} = {value}");
        }
    }

    #[test]
    fn invalid_channel_values_name_file_line_and_option() {
        let rows = [
            ("StopAfterFirstServerFound", "yes"),
            ("CheckLimits", "2"),
            ("CheckControlVariables", "tak!"),
            ("FindServerTimeout", "-1"),
            ("FindServerTimeout", "3s"),
            ("NetTimeout", "99999999999"),
            ("AggregateMode", "2"),
            ("QualityGoodThreshold", "101"),
            ("AsixNetServerFingerprint", "9f86d081"),
            ("AsixNetPlaintext", "maybe"),
        ];
        for (key, value) in rows {
            let err = parse(&format!("; c\n[Channel:*]\n{key} = {value}\n")).unwrap_err();
            assert_eq!(err.kind, ConfigErrorKind::Invalid);
            assert_eq!(
                (err.line, err.option.as_deref()),
                (3, Some(key)),
                "{key}={value}"
            );
            let msg = err.to_string();
            assert!(
                msg.starts_with(&format!(
                    "ASIXConnect.ini:3: option {key}: invalid value `{value}`"
                )),
                "{msg}"
            );
        }
    }

    #[test]
    fn server_option_values() {
        type Check = fn(&ServerOptions) -> bool;
        let rows: &[(&str, &str, Check)] = &[
            ("LogDirectory", "D:\\logi", |o| {
                o.log_directory.as_deref() == Some("D:\\logi")
            }),
            ("AttributesAsItems", "tak", |o| o.attributes_as_items),
            ("MinUpdateRate", "500", |o| o.min_update_rate_ms == 500),
            ("DefaultLanguage", "pl", |o| {
                o.default_language == DefaultLanguage::Polish
            }),
            ("DefaultLanguage", "EN", |o| {
                o.default_language == DefaultLanguage::English
            }),
            ("DefaultLanguage", "0x0409", |o| {
                o.default_language == DefaultLanguage::English
            }),
            ("DefaultLanguage", "system", |o| {
                o.default_language == DefaultLanguage::System
            }),
            ("SimulateCurrentData", "tak", |o| o.simulate_current_data),
            ("ClientName", "CLI.", |o| {
                o.client_name.as_deref() == Some("CLI.")
            }),
            ("BroadcastAddress", "192.168.1.255", |o| {
                o.broadcast_address.as_deref() == Some("192.168.1.255")
            }),
            ("DiscoveryPort", "4711", |o| o.discovery_port == Some(4711)),
            ("DataPort", "4712", |o| o.data_port == Some(4712)),
            ("ReconnectInterval", "10000", |o| {
                o.reconnect_interval_ms == 10000
            }),
            ("LogLevel", "debug", |o| o.log_level == LogLevel::Debug),
            ("LogMaxFileSizeMB", "5", |o| o.log_max_file_size_mb == 5),
            ("LogKeepFiles", "7", |o| o.log_keep_files == 7),
            ("SourceTimeout", "1000", |o| o.source_timeout_ms == 1000),
            ("SourceTimeout", "100", |o| o.source_timeout_ms == 100),
            ("SourceTimeout", "600000", |o| {
                o.source_timeout_ms == 600_000
            }),
            ("SourceTimeout", "", |o| {
                o.source_timeout_ms == ctopc_core::model::DEFAULT_SOURCE_TIMEOUT_MS
            }),
            ("SimulationDeviceDelay", "1500", |o| {
                o.simulation_device_delay_ms == 1500
            }),
            ("SimulationDeviceDelay", "0", |o| {
                o.simulation_device_delay_ms == 0
            }),
            ("SimulationDeviceDelay", "600000", |o| {
                o.simulation_device_delay_ms == 600_000
            }),
            ("simulationdevicedelay", " 20 ", |o| {
                o.simulation_device_delay_ms == 20
            }),
            ("FirstSampleWait", "0", |o| o.first_sample_wait_ms == 0),
            ("FirstSampleWait", "500", |o| {
                o.first_sample_wait_ms == 500 && o.engine_config().first_sample_wait_ms == 500
            }),
            ("FirstSampleWait", "", |o| {
                o.first_sample_wait_ms == ctopc_core::model::DEFAULT_FIRST_SAMPLE_WAIT_MS
            }),
            ("AuditWrites", "nie", |o| {
                !o.audit_writes && !o.ops_config().audit_writes
            }),
            ("AuditWrites", "tak", |o| o.audit_writes),
            ("LegacyOpenAccess", "tak", |o| o.legacy_open_access),
            ("LegacyOpenAccess", "nie", |o| !o.legacy_open_access),
            ("AuditWrites", "", |o| {
                o.audit_writes && o.ops_config().audit_writes
            }),
            ("CallbackTimeout", "500", |o| {
                o.callback_timeout_ms == 500 && o.ops_config().callback_timeout_ms == 500
            }),
            ("CallbackTimeout", "0", |o| o.callback_timeout_ms == 0),
            ("CallbackTimeout", "", |o| {
                o.callback_timeout_ms == ctopc_core::ops::DEFAULT_CALLBACK_TIMEOUT_MS
            }),
            ("CallbackFailures", "1", |o| {
                o.ops_config().callback_failures == 1
            }),
            ("CallbackFailures", "", |o| {
                o.callback_failures == ctopc_core::ops::DEFAULT_CALLBACK_FAILURES
            }),
            ("MetricsAddress", "127.0.0.1:9464", |o| {
                o.ops_config().metrics_address.as_deref() == Some("127.0.0.1:9464")
            }),
            ("MetricsAddress", "", |o| o.metrics_address.is_none()),
        ];
        for (key, value, check) in rows {
            let (c, w) = parse(&format!("[server]\n{key}={value}\n")).unwrap();
            assert!(w.is_empty(), "{w:?}");
            assert!(check(&c.server), "{key} = {value}");
        }
        assert_eq!(
            DefaultLanguage::Polish.fixed(),
            Some(ctopc_core::Lang::Polish)
        );
        assert_eq!(
            DefaultLanguage::English.fixed(),
            Some(ctopc_core::Lang::English)
        );
        assert_eq!(DefaultLanguage::System.fixed(), None);
        for (key, value) in [
            ("AttributesAsItems", "ja"),
            ("MinUpdateRate", "0"),
            ("DefaultLanguage", "de"),
            ("DiscoveryPort", "70000"),
            ("DataPort", "0"),
            ("SourceTimeout", "99"),
            ("SourceTimeout", "0"),
            ("SourceTimeout", "600001"),
            ("SourceTimeout", "1s"),
            ("SimulationDeviceDelay", "600001"),
            ("SimulationDeviceDelay", "-1"),
            ("SimulationDeviceDelay", "1.5"),
            ("FirstSampleWait", "600001"),
            ("FirstSampleWait", "-1"),
            ("AuditWrites", "maybe"),
            ("CallbackTimeout", "600001"),
            ("CallbackTimeout", "-1"),
            ("CallbackFailures", "0"),
            ("CallbackFailures", "1001"),
        ] {
            let err = parse(&format!("[Server]\n{key}={value}\n")).unwrap_err();
            assert_eq!((err.line, err.option.as_deref()), (2, Some(key)));
        }
    }

    #[test]
    fn server_options_reach_the_engine_config() {
        use ctopc_core::model::{EngineConfig, DEFAULT_SOURCE_TIMEOUT_MS};
        let (c, _) = parse("").unwrap();
        assert_eq!(
            c.server.engine_config(),
            EngineConfig {
                max_pending_data_changes: 2,
                ..EngineConfig::default()
            }
        );
        assert_eq!(
            c.server.engine_config().source_timeout_ms,
            DEFAULT_SOURCE_TIMEOUT_MS
        );
        let (c, _) = parse("[Server]\nSourceTimeout = 1000\nMinUpdateRate = 250\n").unwrap();
        let e = c.server.engine_config();
        assert_eq!((e.source_timeout_ms, e.min_update_rate_ms), (1000, 250));
        assert_eq!(
            e.max_transactions_per_group,
            EngineConfig::default().max_transactions_per_group
        );
        // The engine keeps it.
        let ns = std::sync::Arc::new(crate::AsixNamespace::new(c));
        let engine = ctopc_core::model::Engine::new(e, ns);
        assert_eq!(engine.config().source_timeout_ms, 1000);
    }

    #[test]
    fn unknown_options_and_sections_are_warnings() {
        let (c, w) =
            parse("[Server]\nColour = blue\n[Channel:*]\nCheckLimits=tak\nFoo=1\n[Misc]\nx=1\n")
                .unwrap();
        assert!(c.basic().check_limits);
        let got: Vec<(usize, bool)> = w
            .iter()
            .map(|w| (w.line, w.message.contains("ignored")))
            .collect();
        assert_eq!(got, vec![(2, true), (5, true), (6, true)]);
        assert!(w[0].message.contains("Colour"));
    }

    #[test]
    #[allow(clippy::type_complexity)]
    fn channel_resolution() {
        let (c, _) = parse("[Channel:*]\nCheckLimits=tak\n[Channel:Demo_Wytwornia_Kwasu]\nNetTimeout=1\n[Channel:Newton]\n").unwrap();
        let rows: &[(&str, Result<(&str, bool), OpcError>)] = &[
            ("*", Ok(("*", true))),
            ("", Ok(("*", true))),
            ("ANY", Ok(("*", true))),
            ("ANY_channel", Ok(("*", true))),
            ("Demo_Wytwornia_Kwasu", Ok(("Demo_Wytwornia_Kwasu", true))),
            ("Newton", Ok(("Newton", true))),
            ("NEW", Ok(("NEW", false))),
            ("NEW1", Ok(("NEW1", false))),
            ("demo_wytwornia_kwasu", Err(OpcError::UnknownPath)),
            ("any", Err(OpcError::UnknownPath)),
            ("Camac", Err(OpcError::UnknownPath)),
        ];
        for (path, expected) in rows {
            let got = c.resolve_channel(path).map(|r| (r.name, r.stored));
            assert_eq!(&got, expected, "access path `{path}`");
        }
        assert!(c.resolve_channel("ANY").unwrap().options.check_limits);
        // NEW channels and named channels do not inherit from `*`.
        assert!(!c.resolve_channel("NEW").unwrap().options.check_limits);
        assert!(!c.resolve_channel("Newton").unwrap().options.check_limits);
        assert_eq!(
            c.resolve_channel("Demo_Wytwornia_Kwasu")
                .unwrap()
                .options
                .net_timeout_ms,
            1
        );
    }

    #[test]
    fn reserved_and_empty_channel_sections_are_errors() {
        for (text, line) in [
            ("[Channel:ANY1]\n", 1),
            ("x\n[Channel:NEWx]\n", 2),
            ("[Channel: ]\n", 1),
        ] {
            let err = parse(text).unwrap_err();
            assert_eq!(err.line, line, "{text}");
        }
    }

    #[test]
    fn external_server_lists_and_server_selection() {
        let text = "\
[Channel:*]
[Channel:Named]
AsixServerName = LOCAL
[Channel:Listed]
[AsixCTServers]
Listed = STACJA1 , STACJA2
Empty =
[AsixHTServers]
KWAS_ARCH = ARCH1
[AsixALServers]
ALARMY = AL1, AL2
";
        let (c, w) = parse(text).unwrap();
        assert_eq!(w.len(), 1, "{w:?}");
        assert_eq!(w[0].line, 7);
        assert_eq!(c.ct_servers["Listed"], vec!["STACJA1", "STACJA2"]);
        assert_eq!(c.ht_servers["KWAS_ARCH"], vec!["ARCH1"]);
        assert_eq!(c.al_servers["ALARMY"], vec!["AL1", "AL2"]);
        assert_eq!(c.current_data_servers("*"), ServerSelection::Any);
        assert_eq!(c.current_data_servers("Named"), ServerSelection::Local);
        assert_eq!(
            c.current_data_servers("Listed"),
            ServerSelection::Named(vec!["STACJA1".into(), "STACJA2".into()])
        );
        let rows = [
            ("", ServerSelection::Any),
            ("*", ServerSelection::Any),
            (" local ", ServerSelection::Local),
            ("S1", ServerSelection::Named(vec!["S1".into()])),
            (
                "S1,,S2 ",
                ServerSelection::Named(vec!["S1".into(), "S2".into()]),
            ),
        ];
        for (t, s) in rows {
            assert_eq!(ServerSelection::parse(t), s, "{t}");
        }
    }

    #[test]
    fn windows_1250_file_and_relative_paths() {
        let mut bytes = b"[Channel:Wytw\xF3rnia]\nItemsDatabase = demo\\baza.zez\n".to_vec();
        bytes.extend_from_slice(b"ReportsDirectory = C:\\Raporty\n");
        let (mut c, _) = parse_config(&bytes, "x.ini").unwrap();
        let ch = &c.channels["Wytwórnia"];
        let db = ch.items_database.clone().unwrap();
        let reports = ch.reports_directory.clone().unwrap();
        c.base_dir = Some(PathBuf::from("/opt/asix"));
        if std::path::MAIN_SEPARATOR == '/' {
            assert_eq!(
                c.resolve_path(&db),
                PathBuf::from("/opt/asix/demo/baza.zez")
            );
            assert_eq!(c.resolve_path(&reports), PathBuf::from("C:/Raporty"));
            assert_eq!(c.resolve_path("/abs/x.zez"), PathBuf::from("/abs/x.zez"));
        }
    }

    #[test]
    fn no_write_rights_section_leaves_writes_open() {
        let (c, _) = parse("[Server]\n[Channel:KWAS]\n").unwrap();
        assert!(c.write_rights.is_open());
        assert!(c.ops_config().write_rights.is_open());
        let (c, _) = parse("[Server]\nAuditWrites = nie\n[WriteRights]\n* = ua:x\n").unwrap();
        let ops = c.ops_config();
        assert_eq!(ops.write_rights.rules().len(), 1);
        assert!(!ops.audit_writes);
        assert_eq!(AsixConfig::default().write_rights, WriteRights::open());
    }

    #[test]
    fn write_rights_entries_and_the_original_rule() {
        use ctopc_core::write_rights::Caller;
        let fp = "ab".repeat(32);
        let (c, w) = parse(&format!(
            "[Channel:KWAS]\n[Channel:SIARKA]\n[WriteRights]\n\
             * = group:PLANT\\Operators, role:writer\n\
             KWAS = user:PLANT\\jkowalski\n\
             KWAS = cert:{fp}\n\
             ZEZWOLENIE_ZAPISU = SIARKA, KE2., OP3.\n\
             zezwolenie_zapisu = KWAS, user:PLANT\\op\n\
             NEW_X = ua:hmi\n\
             [ASMEN]\nZEZWOLENIE_ZAPISU = *, KE9.\nKANAL1 = NONE\n"
        ))
        .unwrap();
        let r = &c.write_rights;
        assert!(!r.is_open());
        let shown: Vec<String> = r
            .rules()
            .iter()
            .map(|r| format!("{} = {}", r.channels, r.principal))
            .collect();
        assert_eq!(
            shown,
            [
                "* = group:PLANT\\Operators".to_owned(),
                "* = role:writer".to_owned(),
                "KWAS = user:PLANT\\jkowalski".to_owned(),
                format!("KWAS = cert:{fp}"),
                "SIARKA = asix:KE2.".to_owned(),
                "SIARKA = asix:OP3.".to_owned(),
                "KWAS = user:PLANT\\op".to_owned(),
                "NEW_X = ua:hmi".to_owned(),
                "* = asix:KE9.".to_owned(),
            ]
        );
        let op = Caller::Windows {
            account: "PLANT\\op".into(),
            groups: vec![],
        };
        assert!(r.allows("KWAS", &op));
        assert!(!r.allows("SIARKA", &op));
        assert!(!r.allows("KWAS", &Caller::unknown("Wine")));
        // Only the [ASMEN] line that is not ZEZWOLENIE_ZAPISU is a warning.
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].to_string().contains("`KANAL1` in [ASMEN] ignored"),
            "{}",
            w[0]
        );
    }

    #[test]
    fn write_rights_warnings() {
        let (c, w) =
            parse("[Channel:KWAS]\n[WriteRights]\nkwas = *\nSIARKA = ua:x\nKWAS =\n").unwrap();
        let texts: Vec<String> = w.iter().map(ToString::to_string).collect();
        assert_eq!(texts.len(), 3, "{texts:?}");
        assert!(texts[0].starts_with("ASIXConnect.ini:5: [WriteRights] KWAS: no identity"));
        assert!(texts[1].starts_with("ASIXConnect.ini:3: write rights for channel `kwas`"));
        assert!(texts[1].contains("did you mean `KWAS`?"), "{}", texts[1]);
        assert!(texts[2].starts_with("ASIXConnect.ini:4: write rights for channel `SIARKA`"));
        // A section with nothing granted denies every write.
        let (c2, _) = parse("[WriteRights]\n").unwrap();
        assert!(!c2.write_rights.is_open());
        assert!(c2.write_rights.rules().is_empty());
        assert_eq!(c.write_rights.rules().len(), 2);
    }

    #[test]
    fn invalid_write_rights_name_file_line_and_option() {
        let cases = [
            (
                "[WriteRights]\nKWAS = jkowalski\n",
                2,
                "KWAS",
                "is not an identity",
            ),
            (
                "[WriteRights]\n\n* = user:A\\b, cert:12\n",
                3,
                "*",
                "64 hexadecimal digits",
            ),
            ("[WriteRights]\nANY1 = *\n", 2, "ANY1", "reserved"),
            (
                "[WriteRights]\nZEZWOLENIE_ZAPISU = KWAS\n",
                2,
                "ZEZWOLENIE_ZAPISU",
                "<channel>, <client>",
            ),
            (
                "[ASMEN]\nZEZWOLENIE_ZAPISU = KWAS, role:\n",
                2,
                "ZEZWOLENIE_ZAPISU",
                "names nobody",
            ),
        ];
        for (text, line, option, message) in cases {
            let e = parse(text).unwrap_err();
            assert_eq!(e.kind, ConfigErrorKind::Invalid, "{text}");
            assert_eq!(e.line, line, "{text}");
            assert_eq!(e.option.as_deref(), Some(option), "{text}");
            assert!(e.message.contains(message), "{text}: {e}");
        }
    }

    #[test]
    fn missing_file_is_not_found() {
        let err = load_config_file(Path::new("/nonexistent/ASIXConnect.ini")).unwrap_err();
        assert_eq!(err.kind, ConfigErrorKind::NotFound);
    }

    proptest! {
        #[test]
        fn never_panics_on_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let _ = parse_config(&bytes, "fuzz.ini");
        }

        #[test]
        fn never_panics_on_config_like_text(
            lines in proptest::collection::vec(
                prop_oneof![
                    Just("[Server]".to_string()),
                    Just("[Channel:*]".to_string()),
                    "\\[Channel:[A-Za-z*]{0,5}\\]",
                    Just("[AsixCTServers]".to_string()),
                    "(CheckLimits|NetTimeout|DefaultLanguage|DiscoveryPort|AggregateMode|Foo) ?= ?[a-z0-9,]{0,6}",
                ],
                0..20,
            )
        ) {
            let _ = parse_config(lines.join("\n").as_bytes(), "fuzz.ini");
        }
    }
}
