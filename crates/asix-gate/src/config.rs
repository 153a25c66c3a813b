//! `asix-gate.ini`: what the gate serves and how (`docs/asix-gate.md`).
//!
//! ```ini
//! [ASIX-GATE]
//! ServerName = GATE1                 ; the announced asix server name
//! Listen = 0.0.0.0:48101             ; links (TCP)
//! Discovery = 0.0.0.0:48100          ; discovery (UDP)
//! Certificate = gate-cert.pem        ; TLS identity (asix-gate --gen-cert DIR makes one)
//! PrivateKey = gate-key.pem
//! AllowClient = 3f1a…                ; client certificates accepted (repeatable), or
//! ClientCA = clients-ca.pem          ; a CA; neither: any client certificate
//! CallTimeoutMs = 5000               ; the longest an Automation call may take
//! TimeZone = Europe/Warsaw           ; the station's zone (or UTC, or a Windows rule)
//! Language = PL                      ; messages: PL or EN
//! LogDir = Log                       ; daily log files asix-gate.<date>.log
//! ZEZWOLENIE_ZAPISU = KANAL1, cert:3f1a…   ; who may write (repeatable; none: nobody)
//!
//! [KANAL1]                           ; a served channel, by its asix name
//! LoadChannel = KANAL1               ; or Init = Opt1=Val1;Opt2=Val2
//! DeviceRead = Device                ; Device (dsDevice) or Driver (dsDriver)
//! AllowPlaintext = NIE               ; plaintext links for this channel (closed test networks)
//! ```

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};
use std::time::Duration;

use asix_model::ini::{parse_ini_with_lists, split_list};
use asix_model::text::parse_bool;
use asix_net::proto::{DEFAULT_DISCOVERY_PORT, DEFAULT_TCP_PORT};
use asix_net::tls::{self, Fingerprint};
use ctopc_core::lang::Lang;
use ctopc_core::write_rights::{Channels, Principal, Rule, WriteRights};

use crate::channel::DataSource;
use crate::tz::ZoneRule;

/// The main section.
pub const MAIN: &str = "ASIX-GATE";
const PERMIT_KEY: &str = "ZEZWOLENIE_ZAPISU";

/// How a channel's object is initialised.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Open {
    /// `LoadChannel <name>`: a channel configured in AsixConnect.
    LoadChannel(String),
    /// `Init <string>`: an option string.
    Init(String),
}

/// One served channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelConfig {
    /// The channel name clients ask for (the section name).
    pub name: String,
    pub open: Open,
    /// The source of a client's device read.
    pub device_read: DataSource,
    pub allow_plaintext: bool,
}

/// The whole file.
#[derive(Debug, Clone)]
pub struct GateConfig {
    pub server_name: String,
    pub listen: SocketAddr,
    pub discovery: SocketAddr,
    pub certificate: Option<PathBuf>,
    pub private_key: Option<PathBuf>,
    pub allow_clients: Vec<Fingerprint>,
    pub client_ca: Option<PathBuf>,
    pub call_timeout: Duration,
    /// How often each channel's `ServerState` is read.
    pub state_poll: Duration,
    pub time_zone: ZoneRule,
    pub language: Lang,
    /// Where the daily log files go (`asix-gate.<date>.log`); relative to the ini's folder.
    pub log_dir: PathBuf,
    pub write_rights: WriteRights,
    pub channels: Vec<ChannelConfig>,
}

impl GateConfig {
    /// Defaults (no channels) for `server_name`.
    pub fn new(server_name: &str) -> GateConfig {
        GateConfig {
            server_name: server_name.to_owned(),
            listen: SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), DEFAULT_TCP_PORT),
            discovery: SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), DEFAULT_DISCOVERY_PORT),
            certificate: None,
            private_key: None,
            allow_clients: Vec::new(),
            client_ca: None,
            call_timeout: Duration::from_secs(5),
            state_poll: Duration::from_secs(1),
            time_zone: ZoneRule::europe_warsaw(),
            language: Lang::English,
            log_dir: PathBuf::from("Log"),
            write_rights: WriteRights::new(Vec::new()),
            channels: Vec::new(),
        }
    }

    /// True when some channel accepts plaintext links.
    pub fn any_plaintext(&self) -> bool {
        self.channels.iter().any(|c| c.allow_plaintext)
    }
}

/// What is wrong with the file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Problem {
    Unreadable(String),
    Syntax(String),
    UnknownKey(String),
    BadValue { key: String, value: String },
    Missing(&'static str),
    NoChannels,
    BothOpens(String),
    BadPermit(String),
    UnknownPermitChannel(String),
    CertWithoutKey,
}

/// A problem with its place: file and line (0: the whole file).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigError {
    pub file: String,
    pub line: usize,
    pub problem: Problem,
}

impl ConfigError {
    /// The message in `lang`, naming the file and line.
    pub fn text(&self, lang: Lang) -> String {
        let pl = lang == Lang::Polish;
        let what = match (&self.problem, pl) {
            (Problem::Unreadable(e), false) => format!("cannot read the file: {e}"),
            (Problem::Unreadable(e), true) => format!("nie można odczytać pliku: {e}"),
            (Problem::Syntax(e), false) => format!("syntax error: {e}"),
            (Problem::Syntax(e), true) => format!("błąd składni: {e}"),
            (Problem::UnknownKey(k), false) => format!("unknown option {k}"),
            (Problem::UnknownKey(k), true) => format!("nieznana opcja {k}"),
            (Problem::BadValue { key, value }, false) => {
                format!("invalid value of {key}: {value:?}")
            }
            (Problem::BadValue { key, value }, true) => {
                format!("niepoprawna wartość {key}: {value:?}")
            }
            (Problem::Missing(k), false) => format!("{k} is required"),
            (Problem::Missing(k), true) => format!("brak wymaganej opcji {k}"),
            (Problem::NoChannels, false) => "no channel to serve (a section per channel)".into(),
            (Problem::NoChannels, true) => {
                "brak kanałów do udostępnienia (sekcja dla każdego kanału)".into()
            }
            (Problem::BothOpens(c), false) => {
                format!("channel {c}: give LoadChannel or Init, not both")
            }
            (Problem::BothOpens(c), true) => {
                format!("kanał {c}: podaj LoadChannel albo Init, nie oba")
            }
            (Problem::BadPermit(e), false) => format!("{PERMIT_KEY}: {e}"),
            (Problem::BadPermit(e), true) => format!("{PERMIT_KEY}: {e}"),
            (Problem::UnknownPermitChannel(c), false) => {
                format!("{PERMIT_KEY} names channel {c}, which is not served")
            }
            (Problem::UnknownPermitChannel(c), true) => {
                format!("{PERMIT_KEY} wskazuje kanał {c}, który nie jest udostępniany")
            }
            (Problem::CertWithoutKey, false) => "Certificate and PrivateKey go together".into(),
            (Problem::CertWithoutKey, true) => "Certificate i PrivateKey należy podać razem".into(),
        };
        if self.line == 0 {
            format!("{}: {what}", self.file)
        } else if pl {
            format!("{}, wiersz {}: {what}", self.file, self.line)
        } else {
            format!("{}, line {}: {what}", self.file, self.line)
        }
    }
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text(Lang::English))
    }
}

impl std::error::Error for ConfigError {}

/// Reads `asix-gate.ini` from disk.
pub fn load(path: &Path) -> Result<GateConfig, ConfigError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| ConfigError {
        file: file.clone(),
        line: 0,
        problem: Problem::Unreadable(e.to_string()),
    })?;
    let mut cfg = parse(&bytes, &file)?;
    // Relative file names are relative to the ini's folder.
    let dir = path.parent().unwrap_or(Path::new("."));
    if cfg.log_dir.is_relative() {
        cfg.log_dir = dir.join(&cfg.log_dir);
    }
    for p in [
        &mut cfg.certificate,
        &mut cfg.private_key,
        &mut cfg.client_ca,
    ]
    .into_iter()
    .flatten()
    {
        if p.is_relative() {
            *p = dir.join(&*p);
        }
    }
    Ok(cfg)
}

fn socket(text: &str, default_port: u16) -> Option<SocketAddr> {
    if let Ok(p) = text.parse::<u16>() {
        return Some(SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), p));
    }
    if let Ok(ip) = text.parse::<IpAddr>() {
        return Some(SocketAddr::new(ip, default_port));
    }
    text.parse().ok()
}

/// Parses the bytes of `asix-gate.ini` (`file` names it in errors).
pub fn parse(bytes: &[u8], file: &str) -> Result<GateConfig, ConfigError> {
    let err = |line: usize, problem: Problem| ConfigError {
        file: file.to_owned(),
        line,
        problem,
    };
    let (ini, _) = parse_ini_with_lists(bytes, file, &[MAIN])
        .map_err(|e| err(e.line, Problem::Syntax(e.message)))?;
    let main = ini
        .section(MAIN)
        .ok_or_else(|| err(0, Problem::Missing("[ASIX-GATE]")))?;
    let mut cfg = GateConfig::new("");
    let mut permits = Vec::new();
    for e in &main.entries {
        let bad = || {
            err(
                e.line,
                Problem::BadValue {
                    key: e.key.clone(),
                    value: e.value.clone(),
                },
            )
        };
        let v = e.value.trim();
        let ms = || {
            v.parse::<u64>()
                .ok()
                .filter(|n| *n > 0)
                .map(Duration::from_millis)
                .ok_or_else(bad)
        };
        match e.key.to_ascii_lowercase().as_str() {
            "servername" => {
                if v.is_empty() {
                    return Err(bad());
                }
                cfg.server_name = v.to_owned();
            }
            "listen" => cfg.listen = socket(v, DEFAULT_TCP_PORT).ok_or_else(bad)?,
            "discovery" => cfg.discovery = socket(v, DEFAULT_DISCOVERY_PORT).ok_or_else(bad)?,
            "certificate" => cfg.certificate = Some(PathBuf::from(v)),
            "privatekey" => cfg.private_key = Some(PathBuf::from(v)),
            "allowclient" => cfg
                .allow_clients
                .extend(tls::parse_fingerprints(v).map_err(|_| bad())?),
            "clientca" => cfg.client_ca = Some(PathBuf::from(v)),
            "logdir" if !v.is_empty() => cfg.log_dir = PathBuf::from(v),
            "calltimeoutms" => cfg.call_timeout = ms()?,
            "statepollms" => cfg.state_poll = ms()?,
            "timezone" => cfg.time_zone = ZoneRule::parse(v).ok_or_else(bad)?,
            "language" | "jezyk" => {
                cfg.language = match v.to_ascii_uppercase().as_str() {
                    "PL" | "POLISH" | "POLSKI" => Lang::Polish,
                    "EN" | "ENGLISH" | "ANGIELSKI" => Lang::English,
                    _ => return Err(bad()),
                }
            }
            k if k.eq_ignore_ascii_case(PERMIT_KEY) => {
                let list = split_list(v);
                let Some((channel, clients)) = list.split_first() else {
                    return Err(bad());
                };
                if clients.is_empty() {
                    return Err(bad());
                }
                let channels = if channel == "*" {
                    Channels::All
                } else {
                    Channels::One(channel.clone())
                };
                for c in clients {
                    let p = Principal::parse_asix_permit(c)
                        .map_err(|x| err(e.line, Problem::BadPermit(x.to_string())))?;
                    permits.push((e.line, Rule::new(channels.clone(), p)));
                }
            }
            _ => return Err(err(e.line, Problem::UnknownKey(e.key.clone()))),
        }
    }
    if cfg.server_name.is_empty() {
        return Err(err(main.line, Problem::Missing("ServerName")));
    }
    if cfg.certificate.is_some() != cfg.private_key.is_some() {
        return Err(err(main.line, Problem::CertWithoutKey));
    }
    for s in ini
        .sections
        .iter()
        .filter(|s| !s.name.eq_ignore_ascii_case(MAIN))
    {
        let mut open = None;
        let mut device_read = DataSource::Device;
        let mut allow_plaintext = false;
        for e in &s.entries {
            let bad = || {
                err(
                    e.line,
                    Problem::BadValue {
                        key: e.key.clone(),
                        value: e.value.clone(),
                    },
                )
            };
            let v = e.value.trim();
            let this = match e.key.to_ascii_lowercase().as_str() {
                "loadchannel" if !v.is_empty() => Open::LoadChannel(v.to_owned()),
                "init" if !v.is_empty() => Open::Init(v.to_owned()),
                "loadchannel" | "init" => return Err(bad()),
                "deviceread" => {
                    device_read = match v.to_ascii_lowercase().as_str() {
                        "device" | "dsdevice" => DataSource::Device,
                        "driver" | "dsdriver" => DataSource::Driver,
                        _ => return Err(bad()),
                    };
                    continue;
                }
                "allowplaintext" => {
                    allow_plaintext = parse_bool(v).ok_or_else(bad)?;
                    continue;
                }
                _ => return Err(err(e.line, Problem::UnknownKey(e.key.clone()))),
            };
            if open.replace(this).is_some() {
                return Err(err(e.line, Problem::BothOpens(s.name.clone())));
            }
        }
        cfg.channels.push(ChannelConfig {
            name: s.name.clone(),
            // Without either: the channel configured in AsixConnect under the same name.
            open: open.unwrap_or_else(|| Open::LoadChannel(s.name.clone())),
            device_read,
            allow_plaintext,
        });
    }
    if cfg.channels.is_empty() {
        return Err(err(0, Problem::NoChannels));
    }
    for (line, r) in &permits {
        if let Channels::One(c) = &r.channels {
            if !cfg.channels.iter().any(|x| &x.name == c) {
                return Err(err(*line, Problem::UnknownPermitChannel(c.clone())));
            }
        }
    }
    cfg.write_rights = WriteRights::new(permits.into_iter().map(|(_, r)| r).collect());
    Ok(cfg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ctopc_core::write_rights::Caller;

    const FP: &str = "3f1a3f1a3f1a3f1a3f1a3f1a3f1a3f1a3f1a3f1a3f1a3f1a3f1a3f1a3f1a3f1a";

    fn ok(text: &str) -> GateConfig {
        parse(text.as_bytes(), "asix-gate.ini").expect("valid")
    }

    fn bad(text: &str) -> ConfigError {
        parse(text.as_bytes(), "asix-gate.ini").expect_err("invalid")
    }

    #[test]
    fn a_full_file() {
        let c = ok(&format!(
            "[ASIX-GATE]\nServerName = GATE1\nListen = 127.0.0.1:5000\nDiscovery = 5001\n\
             Certificate = c.pem\nPrivateKey = k.pem\nAllowClient = {FP}\nCallTimeoutMs = 250\n\
             TimeZone = UTC\nLanguage = PL\nZEZWOLENIE_ZAPISU = KANAL1, cert:{FP}\n\
             ZEZWOLENIE_ZAPISU = KANAL2, KE2., OP3.\n\
             [KANAL1]\nLoadChannel = KANAL_A\nDeviceRead = Driver\n\
             [KANAL2]\nInit = Net=1;Server=X\nAllowPlaintext = TAK\n[KANAL3]\n"
        ));
        assert_eq!(c.server_name, "GATE1");
        assert_eq!(c.listen, "127.0.0.1:5000".parse().unwrap());
        assert_eq!(c.discovery.port(), 5001);
        assert_eq!(c.call_timeout, Duration::from_millis(250));
        assert_eq!(c.time_zone, ZoneRule::UTC);
        assert_eq!(c.language, Lang::Polish);
        assert_eq!(c.allow_clients.len(), 1);
        assert_eq!(c.channels.len(), 3);
        assert_eq!(c.channels[0].open, Open::LoadChannel("KANAL_A".into()));
        assert_eq!(c.channels[0].device_read, DataSource::Driver);
        assert_eq!(c.channels[1].open, Open::Init("Net=1;Server=X".into()));
        assert!(c.channels[1].allow_plaintext && !c.channels[0].allow_plaintext);
        assert_eq!(c.channels[2].open, Open::LoadChannel("KANAL3".into()));
        let cert = Caller::Link {
            client: None,
            certificate: tls::parse_fingerprint(FP).ok(),
        };
        assert!(c.write_rights.allows("KANAL1", &cert));
        assert!(!c.write_rights.allows("KANAL2", &cert));
        let op3 = Caller::Link {
            client: Some("op3.".into()),
            certificate: None,
        };
        assert!(c.write_rights.allows("KANAL2", &op3));
    }

    #[test]
    fn defaults_deny_every_write() {
        let c = ok("[ASIX-GATE]\nServerName=G\n[K]\n");
        assert_eq!(c.channels[0].device_read, DataSource::Device);
        assert_eq!(c.time_zone, ZoneRule::europe_warsaw());
        assert!(!c.write_rights.is_open());
        let anyone = Caller::Link {
            client: Some("X.".into()),
            certificate: None,
        };
        assert!(!c.write_rights.allows("K", &anyone));
    }

    #[test]
    fn errors_name_the_line_in_both_languages() {
        let e = bad("[ASIX-GATE]\nServerName=G\nCallTimeoutMs = soon\n[K]\n");
        assert_eq!(e.line, 3);
        assert_eq!(
            e.text(Lang::English),
            "asix-gate.ini, line 3: invalid value of CallTimeoutMs: \"soon\""
        );
        assert_eq!(
            e.text(Lang::Polish),
            "asix-gate.ini, wiersz 3: niepoprawna wartość CallTimeoutMs: \"soon\""
        );
        let e = bad("[ASIX-GATE]\nServerName=G\n[K]\nLoadChannel=A\nInit=B=1\n");
        assert_eq!(e.problem, Problem::BothOpens("K".into()));
        assert_eq!(e.line, 5);
        assert_eq!(
            bad("[ASIX-GATE]\nServerName=G\n").problem,
            Problem::NoChannels
        );
        assert_eq!(
            bad("[ASIX-GATE]\n[K]\n").problem,
            Problem::Missing("ServerName")
        );
        assert_eq!(
            bad("[ASIX-GATE]\nServerName=G\nColour=red\n[K]\n").problem,
            Problem::UnknownKey("Colour".into())
        );
        assert_eq!(
            bad("[ASIX-GATE]\nServerName=G\nZEZWOLENIE_ZAPISU = L, KE2.\n[K]\n").problem,
            Problem::UnknownPermitChannel("L".into())
        );
        assert!(matches!(
            bad("[ASIX-GATE]\nServerName=G\nZEZWOLENIE_ZAPISU = K, cert:12\n[K]\n").problem,
            Problem::BadPermit(_)
        ));
        assert_eq!(
            bad("[ASIX-GATE]\nServerName=G\nCertificate=c.pem\n[K]\n").problem,
            Problem::CertWithoutKey
        );
        assert!(matches!(
            bad("[ASIX-GATE]\nServerName=G\n[K]\nDeviceRead=PLC\n").problem,
            Problem::BadValue { .. }
        ));
        assert!(matches!(
            bad("[ASIX-GATE]\nServerName=G\nTimeZone=Mars\n[K]\n").problem,
            Problem::BadValue { .. }
        ));
    }
}
