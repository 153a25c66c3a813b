//! `opcdiag doctor`: checks the installation of ServerCTOPC and reports each check as
//! OK / WARN / FAIL with the fix in one line; the exit code is 0 only when nothing failed.
//!
//! Every decision is a pure function here, given what was read (registry values through
//! the [`Registry`] trait, whether files exist, the configuration as the server's own
//! loader `asix_model::startup` gives it, the discovery's answers): tested natively. The
//! readers (`doctor/read.rs`, Windows only) are thin.
//!
//! The expected registry entries are `ctopc_registration::serverctopc(exe,
//! service).keys()` (what `/RegServer` writes), the interfaces that need a proxy/stub are
//! parsed from our IDL (`idl/`), so neither list is written twice.

// Natively only the tests use what the Windows reader calls.
#![cfg_attr(not(windows), allow(dead_code))]

use asix_model::namespace::ChannelDatabase;
use asix_model::AsixNamespace;
use ctopc_registration::{self as registration, guid_string, Key, View};

#[cfg(windows)]
#[path = "doctor/read.rs"]
mod read;
#[cfg(windows)]
pub use read::run;

/// A check's verdict.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    Ok,
    Warn,
    Fail,
}

impl Status {
    pub fn name(self) -> &'static str {
        match self {
            Status::Ok => "OK",
            Status::Warn => "WARN",
            Status::Fail => "FAIL",
        }
    }
}

/// One check's result: what was checked, the verdict, what was found, and the fix (empty
/// when OK).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Check {
    pub name: String,
    pub status: Status,
    pub detail: String,
    pub fix: String,
}

impl Check {
    pub fn ok(name: impl Into<String>, detail: impl Into<String>) -> Check {
        Check {
            name: name.into(),
            status: Status::Ok,
            detail: detail.into(),
            fix: String::new(),
        }
    }
    pub fn warn(
        name: impl Into<String>,
        detail: impl Into<String>,
        fix: impl Into<String>,
    ) -> Check {
        Check {
            name: name.into(),
            status: Status::Warn,
            detail: detail.into(),
            fix: fix.into(),
        }
    }
    pub fn fail(
        name: impl Into<String>,
        detail: impl Into<String>,
        fix: impl Into<String>,
    ) -> Check {
        Check {
            name: name.into(),
            status: Status::Fail,
            detail: one_line(&detail.into()),
            fix: fix.into(),
        }
    }
}

/// A text of several lines (an error with its hint) as one: the lines joined by `; `.
pub fn one_line(text: &str) -> String {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join("; ")
}

/// 0 when no check failed, else 1 (`cli::EXIT_FAILED`).
pub fn exit_code(checks: &[Check]) -> u8 {
    if checks.iter().any(|c| c.status == Status::Fail) {
        crate::cli::EXIT_FAILED
    } else {
        crate::cli::EXIT_OK
    }
}

/// The report for a person: one line per check, the fix on the next line, a summary.
pub fn render_text(checks: &[Check]) -> String {
    let width = checks
        .iter()
        .map(|c| c.name.chars().count())
        .max()
        .unwrap_or(0);
    let mut out = String::new();
    for c in checks {
        out.push_str(&format!(
            "{:<4}  {}  {}\n",
            c.status.name(),
            crate::text::pad(&c.name, width),
            c.detail
        ));
        if !c.fix.is_empty() {
            out.push_str(&format!("      {}  fix: {}\n", " ".repeat(width), c.fix));
        }
    }
    let count = |s| checks.iter().filter(|c| c.status == s).count();
    out.push_str(&format!(
        "{} check(s): {} OK, {} WARN, {} FAIL\n",
        checks.len(),
        count(Status::Ok),
        count(Status::Warn),
        count(Status::Fail)
    ));
    out
}

fn json_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for ch in s.chars() {
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// `--json`: an array with one object per check (`name`, `status`, `detail`, `fix`).
pub fn render_json(checks: &[Check]) -> String {
    let items: Vec<String> = checks
        .iter()
        .map(|c| {
            format!(
                "  {{\"name\": {}, \"status\": {}, \"detail\": {}, \"fix\": {}}}",
                json_string(&c.name),
                json_string(c.status.name()),
                json_string(&c.detail),
                json_string(&c.fix)
            )
        })
        .collect();
    format!("[\n{}\n]\n", items.join(",\n"))
}

// ---------------------------------------------------------------------------------------
// The registry

/// What the checks read from the registry (`HKEY_CLASSES_ROOT` of a view).
pub trait Registry {
    fn key_exists(&self, view: View, path: &str) -> bool;
    /// A `REG_SZ` value (`""`: the key's default value).
    fn value(&self, view: View, path: &str, name: &str) -> Option<String>;
}

pub fn view_name(view: View) -> &'static str {
    match view {
        View::Reg64 => "64-bit view",
        View::Reg32 => "32-bit view",
    }
}

/// The executable of a `LocalServer32` command line: the quoted path, else the text up to
/// the first ` -` or ` /` switch.
pub fn exe_of_command_line(cmd: &str) -> String {
    let s = cmd.trim();
    match s.strip_prefix('"') {
        Some(rest) => rest.split('"').next().unwrap_or(rest).to_owned(),
        None => s
            .split(" -")
            .next()
            .unwrap_or(s)
            .split(" /")
            .next()
            .unwrap_or(s)
            .trim()
            .to_owned(),
    }
}

/// `CLSID\{ServerCTOPC}`.
pub fn server_clsid_key() -> String {
    format!("CLSID\\{}", guid_string(registration::CLSID_SERVERCTOPC))
}

/// What the registration says of the server: its exe (from `LocalServer32`, 64-bit view
/// first) and its NT service (the AppID's `LocalService`).
pub fn registered_server(reg: &dyn Registry) -> (Option<String>, Option<String>) {
    let ls = format!("{}\\LocalServer32", server_clsid_key());
    let exe = registration::VIEWS
        .iter()
        .find_map(|&v| reg.value(v, &ls, ""))
        .map(|c| exe_of_command_line(&c));
    let appid = format!("AppID\\{}", guid_string(registration::CLSID_SERVERCTOPC));
    let service = registration::VIEWS
        .iter()
        .find_map(|&v| reg.value(v, &appid, "LocalService"))
        .filter(|s| !s.trim().is_empty());
    (exe, service)
}

const REGISTER_FIX: &str =
    "run `ServerCTOPC.exe /RegServer` (or `/Service`) as administrator in the install folder";

/// The registration of one view against `expected` (`serverctopc(exe, service).keys()`):
/// every key present and every value as `/RegServer` writes it.
pub fn registration_check(view: View, expected: &[Key], reg: &dyn Registry) -> Check {
    let name = format!("registration ({})", view_name(view));
    let clsid = server_clsid_key();
    if !reg.key_exists(view, &clsid) {
        return Check::fail(
            name,
            format!("ServerCTOPC.App is not registered (no HKCR\\{clsid})"),
            REGISTER_FIX,
        );
    }
    let mut problems = Vec::new();
    let mut n = 0;
    for k in expected.iter().filter(|k| k.view == view) {
        n += 1;
        if !reg.key_exists(view, &k.path) {
            problems.push(format!("missing HKCR\\{}", k.path));
            continue;
        }
        for (value_name, want) in &k.values {
            let shown = if value_name.is_empty() {
                "(default)"
            } else {
                value_name.as_str()
            };
            match reg.value(view, &k.path, value_name) {
                None => problems.push(format!("HKCR\\{} {shown}: missing", k.path)),
                Some(got) if !got.eq_ignore_ascii_case(want) => problems.push(format!(
                    "HKCR\\{} {shown}: {got:?}, expected {want:?}",
                    k.path
                )),
                Some(_) => {}
            }
        }
    }
    if problems.is_empty() {
        Check::ok(
            name,
            format!("{n} keys as /RegServer writes them (CLSID, LocalServer32, ProgID and CurVer, categories DA 2.0/3.0, AppID, OPC key)"),
        )
    } else {
        let more = if problems.len() > 3 {
            format!(" (and {} more)", problems.len() - 3)
        } else {
            String::new()
        };
        Check::fail(
            name,
            format!("{}{more}", problems[..problems.len().min(3)].join("; ")),
            REGISTER_FIX,
        )
    }
}

/// The registered server exe exists.
pub fn exe_check(exe: Option<&str>, exists: bool) -> Check {
    match exe {
        None => Check::fail(
            "server exe",
            "no LocalServer32 registered for ServerCTOPC.App",
            REGISTER_FIX,
        ),
        Some(e) if exists => Check::ok("server exe", e.to_owned()),
        Some(e) => Check::fail(
            "server exe",
            format!("{e} (LocalServer32) does not exist: moved or deleted"),
            "register the server from where it is now: `ServerCTOPC.exe /RegServer` in its folder",
        ),
    }
}

// ---------------------------------------------------------------------------------------
// Proxy/stub

/// The interfaces of our IDL (`idl/opccomn.idl`, `idl/opcda.idl`), by name and IID: every
/// OPC Common and DA interface a proxy/stub must marshal.
pub fn idl_interfaces() -> Vec<(String, u128)> {
    let mut out = parse_idl_interfaces(include_str!("../../../../../idl/opccomn.idl"));
    out.extend(parse_idl_interfaces(include_str!(
        "../../../../../idl/opcda.idl"
    )));
    out
}

/// `uuid(...)` attributes followed by `interface NAME :`, in order.
pub fn parse_idl_interfaces(idl: &str) -> Vec<(String, u128)> {
    let mut out = Vec::new();
    let mut uuid: Option<u128> = None;
    for line in idl.lines() {
        let t = line.trim();
        if let Some(rest) = t.strip_prefix("uuid(") {
            let g = rest.split(')').next().unwrap_or("");
            uuid = u128::from_str_radix(&g.replace('-', ""), 16).ok();
        } else if let Some(rest) = t.strip_prefix("interface ") {
            if let (Some(id), Some((name, _))) = (uuid, rest.split_once(':')) {
                out.push((name.trim().to_owned(), id));
            }
            uuid = None;
        }
    }
    out
}

/// Whose proxy/stub a DLL is, by its file name.
pub fn proxy_owner(dll: &str) -> Option<&'static str> {
    let file = dll
        .rsplit(['\\', '/'])
        .next()
        .unwrap_or(dll)
        .trim_matches('"');
    if file.eq_ignore_ascii_case("opc_ps.dll") {
        Some("ServerCTOPC's opc_ps.dll")
    } else if file.eq_ignore_ascii_case("opcproxy.dll") {
        Some("the OPC Foundation's opcproxy.dll")
    } else if file.eq_ignore_ascii_case("opccomn_ps.dll") {
        Some("the OPC Foundation's opccomn_ps.dll")
    } else {
        None
    }
}

fn proxy_fix(view: View) -> &'static str {
    match view {
        View::Reg64 => "register the 64-bit proxy/stub as administrator: `regsvr32 opc_ps.dll` in the install folder (or install the OPC Core Components)",
        View::Reg32 => "register the 32-bit proxy/stub as administrator: `%windir%\\SysWOW64\\regsvr32 x86\\opc_ps.dll` in the install folder (or install the OPC Core Components)",
    }
}

/// The path a registered DLL of `view` has for this process: a 64-bit process sees the
/// 32-bit `System32` as `SysWOW64`, a 32-bit one the 64-bit `System32` as `Sysnative`.
pub fn path_seen_here(path: &str, view: View, process_is_64: bool) -> String {
    let lower = path.to_ascii_lowercase();
    let Some(at) = lower.find("\\system32\\") else {
        return path.to_owned();
    };
    let replacement = match (view, process_is_64) {
        (View::Reg32, true) => "\\SysWOW64\\",
        (View::Reg64, false) => "\\Sysnative\\",
        _ => return path.to_owned(),
    };
    format!(
        "{}{replacement}{}",
        &path[..at],
        &path[at + "\\system32\\".len()..]
    )
}

/// A proxy/stub for every interface in `view`, pointing at a DLL that exists
/// (`exists(path)`; the reader maps the path to what this process sees).
pub fn proxy_check(
    view: View,
    interfaces: &[(String, u128)],
    reg: &dyn Registry,
    exists: &dyn Fn(&str) -> bool,
) -> Check {
    let name = format!("proxy/stub ({})", view_name(view));
    let mut missing = Vec::new();
    let mut broken = Vec::new();
    let mut owners: Vec<String> = Vec::new();
    for (iface, iid) in interfaces {
        let key = format!("Interface\\{}\\ProxyStubClsid32", guid_string(*iid));
        let Some(ps) = reg.value(view, &key, "") else {
            missing.push(iface.clone());
            continue;
        };
        let inproc = format!("CLSID\\{}\\InprocServer32", ps.trim());
        let Some(dll) = reg.value(view, &inproc, "") else {
            broken.push(format!("{iface}: no HKCR\\{inproc}"));
            continue;
        };
        let dll = dll.trim().trim_matches('"').to_owned();
        if !exists(&dll) {
            broken.push(format!("{iface}: {dll} does not exist"));
            continue;
        }
        let owner = proxy_owner(&dll).map_or_else(|| format!("another DLL, {dll}"), str::to_owned);
        if !owners.contains(&owner) {
            owners.push(owner);
        }
    }
    if missing.is_empty() && broken.is_empty() {
        return Check::ok(
            name,
            format!(
                "all {} OPC Common and DA interfaces, by {}",
                interfaces.len(),
                owners.join(" and ")
            ),
        );
    }
    let mut detail = Vec::new();
    if !missing.is_empty() {
        detail.push(if missing.len() == interfaces.len() {
            "no proxy/stub registered for any OPC interface".to_owned()
        } else {
            format!("no proxy/stub registered for {}", missing.join(", "))
        });
    }
    detail.extend(broken.into_iter().take(3));
    Check::fail(name, detail.join("; "), proxy_fix(view))
}

/// A server browser (`OPC.ServerList.1`, ours or OpcEnum) registered in `view`, its exe
/// present.
pub fn browser_check(view: View, reg: &dyn Registry, exists: &dyn Fn(&str) -> bool) -> Check {
    let name = format!("server browser ({})", view_name(view));
    let fix = "install a server browser: `OpcServerList.exe /RegServer` in the install folder, or the OPC Foundation's Core Components (OpcEnum)";
    let key = registration::server_list_local_server_key();
    match reg.value(view, &key, "") {
        None => Check::warn(
            name,
            "OPC.ServerList.1 is not registered: clients cannot list the servers of this machine",
            fix,
        ),
        Some(cmd) => {
            let exe = exe_of_command_line(&cmd);
            let whose = if registration::is_our_server_list(&cmd) {
                "ours"
            } else {
                "the OPC Foundation's OpcEnum (or another)"
            };
            if exists(&exe) {
                Check::ok(name, format!("OPC.ServerList.1: {exe} ({whose})"))
            } else {
                Check::warn(
                    name,
                    format!("OPC.ServerList.1 names {exe}, which does not exist"),
                    fix,
                )
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// The NT service, the log folder

/// What the service control manager says of the service.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ServiceInfo {
    pub executable: String,
    pub account: String,
    pub disabled: bool,
}

pub fn service_check(
    appid_service: Option<&str>,
    installed: Option<&ServiceInfo>,
    registered_exe: Option<&str>,
    exe_exists: bool,
) -> Check {
    const NAME: &str = "NT service";
    match (appid_service, installed) {
        (None, None) => Check::ok(NAME, "not installed (COM starts ServerCTOPC.exe as a local server)"),
        (Some(svc), None) => Check::fail(
            NAME,
            format!("the AppID names the service {svc}, which is not installed: COM cannot start the server"),
            "run `ServerCTOPC.exe /Service` as administrator (or `/RegServer` for a local server)",
        ),
        (svc, Some(info)) => {
            let exe = exe_of_command_line(&info.executable);
            let same = registered_exe.is_none_or(|r| r.eq_ignore_ascii_case(&exe));
            if !exe_exists {
                Check::fail(NAME, format!("the service runs {exe}, which does not exist"), "run `ServerCTOPC.exe /Service` as administrator from the install folder")
            } else if info.disabled {
                Check::fail(NAME, format!("the service is disabled ({})", info.account), "set the service's start type to Manual (services.msc) or run `ServerCTOPC.exe /Service`")
            } else if !same {
                Check::warn(NAME, format!("the service runs {exe}, LocalServer32 names another exe"), "run `ServerCTOPC.exe /Service` as administrator from the install folder")
            } else if svc.is_none() {
                Check::warn(NAME, "installed, but the AppID does not name it (COM starts a local server instead)", "run `ServerCTOPC.exe /Service` as administrator")
            } else {
                Check::ok(NAME, format!("{exe} -ServiceRun as {}, on demand", info.account))
            }
        }
    }
}

/// The log folder: `LogDirectory` (relative to the install folder), else `<install>\Log`
/// (the rule of `crates/server/src/logging.rs`).
pub fn log_dir(install_dir: &str, configured: Option<&str>) -> String {
    let join = |a: &str, b: &str| format!("{}\\{b}", a.trim_end_matches(['\\', '/']));
    match configured.map(str::trim).filter(|c| !c.is_empty()) {
        Some(c) if c.starts_with(['\\', '/']) || c.get(1..2) == Some(":") => c.to_owned(),
        Some(c) => join(install_dir, c),
        None => join(install_dir, "Log"),
    }
}

/// What writing a probe file into the log folder gave.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LogProbe {
    Written,
    /// The folder does not exist, its parent is writable: the server creates it.
    WillBeCreated,
    Failed(String),
}

pub fn log_check(dir: &str, probe: &LogProbe, account: &str) -> Check {
    const NAME: &str = "log folder";
    match probe {
        LogProbe::Written => Check::ok(NAME, format!("{dir} writable (checked as this user; the server runs as {account})")),
        LogProbe::WillBeCreated => Check::ok(NAME, format!("{dir} does not exist yet; the server creates it")),
        LogProbe::Failed(e) => Check::fail(
            NAME,
            format!("cannot write into {dir}: {e}"),
            format!("give {account} the right to modify {dir}, or set [Server] LogDirectory to a writable folder"),
        ),
    }
}

// ---------------------------------------------------------------------------------------
// Configuration, databases, the asix link

/// The configuration check, from where it came and what `asix_model::startup` gave.
pub fn config_check(source: &str, loaded: &Result<asix_model::Loaded, String>) -> Check {
    const NAME: &str = "configuration";
    match loaded {
        Ok(l) if l.warnings.is_empty() => Check::ok(NAME, source.to_owned()),
        Ok(l) => Check::warn(
            NAME,
            format!("{source}: {} warning(s), first: {}", l.warnings.len(), l.warnings[0]),
            "correct or remove the option named (see asixconnect.ini.example)",
        ),
        Err(e) => Check::fail(
            NAME,
            e.clone(),
            "correct the option at the line named (asixconnect.ini.example documents every option); the server does not start with this file",
        ),
    }
}

/// One check per channel with a variable database.
pub fn database_checks(ns: &AsixNamespace) -> Vec<Check> {
    ns.config()
        .channels
        .iter()
        .filter_map(|(ch, opts)| {
            let name = format!("database [Channel:{ch}]");
            match ns.database_state(ch) {
                ChannelDatabase::NotConfigured => None,
                ChannelDatabase::Loaded(db) => Some(Check::ok(
                    name,
                    format!(
                        "{}: {} variables",
                        opts.items_database
                            .as_deref()
                            .unwrap_or("the embedded demo database"),
                        db.variables.len()
                    ),
                )),
                ChannelDatabase::Failed(e) => Some(Check::fail(
                    name,
                    format!("{e}"),
                    format!(
                        "correct ItemsDatabase of [Channel:{ch}] or the file it names (docs/variable-database.md); clients get OPC_STATUS_NOCONFIG"
                    ),
                )),
            }
        })
        .collect()
}

/// The asix channels (the `Channel` attribute) of each OPC channel's database, in order,
/// without duplicates: what the network client discovers servers for (not for a channel
/// that reads from Asix.Evo REST servers, [`rest_channels`]).
pub fn asix_channels(ns: &AsixNamespace) -> Vec<(String, Vec<String>)> {
    ns.config()
        .channels
        .iter()
        .filter(|(_, o)| !o.is_asix_evo_rest())
        .map(|(ch, _)| ch)
        .filter_map(|ch| {
            let db = ns.database(ch)?;
            let mut names: Vec<String> = Vec::new();
            for v in &db.variables {
                if let Some(a) = db.attribute(v, asix_net_channel_attribute()) {
                    let a = a.trim();
                    if !a.is_empty() && !names.iter().any(|n| n == a) {
                        names.push(a.to_owned());
                    }
                }
            }
            Some((ch.clone(), names))
        })
        .collect()
}

/// The OPC channels that read from Asix.Evo REST servers (`AsixEvoRest`), with their
/// stations in order of preference.
pub fn rest_channels(ns: &AsixNamespace) -> Vec<(String, Vec<String>)> {
    ns.config()
        .channels
        .iter()
        .filter(|(_, o)| o.is_asix_evo_rest())
        .map(|(ch, o)| (ch.clone(), o.asix_evo_rest.clone()))
        .collect()
}

/// Whether one Asix.Evo REST station answered (`index` in the channel's list; `any`: some
/// station of the channel answered, so that a standby down is a warning, not a failure).
pub fn rest_check(
    opc_channel: &str,
    station: &str,
    index: usize,
    any: bool,
    result: &Result<(), String>,
) -> Check {
    let name = format!("Asix.Evo REST [Channel:{opc_channel}] {station}");
    let role = if index == 0 {
        "the preferred station".to_owned()
    } else {
        format!("standby station {index}")
    };
    let fix = "check that Asix.Evo's REST server runs at this address and is reachable (firewall, HTTPS certificate), and the AsixEvoUser/AsixEvoPassword or AsixEvoHeader credential";
    match result {
        Ok(()) => Check::ok(name, format!("{role} answers; the channel's items are read-only (the REST API documents no write)")),
        Err(e) if any => Check::warn(name, format!("{role} does not answer: {e}"), fix),
        Err(e) => Check::fail(name, format!("{role} does not answer: {e}; no station of the channel answers"), fix),
    }
}

/// `asix_net::pipeline::CHANNEL_ATTRIBUTE` (asix-net is a Windows dependency here).
fn asix_net_channel_attribute() -> &'static str {
    "Channel"
}

/// The first item of the basic channel's database, for the connection check.
pub fn first_item(ns: &AsixNamespace) -> Option<String> {
    let db = ns.database(asix_model::config::BASIC_CHANNEL)?;
    db.variables.first().map(|v| v.public_name.clone())
}

/// What one discovery gave: the chosen server (name and address) or the error text.
pub fn link_check(
    opc_channel: &str,
    asix_channel: &str,
    timeout_ms: u32,
    result: &Result<Vec<(String, String)>, String>,
) -> Check {
    let name = format!("asix link [Channel:{opc_channel}] {asix_channel}");
    match result {
        Ok(found) if !found.is_empty() => {
            let (server, addr) = &found[0];
            let others = if found.len() > 1 {
                format!(" ({} more answered)", found.len() - 1)
            } else {
                String::new()
            };
            Check::ok(name, format!("chose {server} at {addr}{others}"))
        }
        Ok(_) | Err(_) => Check::fail(
            name,
            format!(
                "no asix server answered within FindServerTimeout ({timeout_ms} ms){}",
                result.as_ref().err().map(|e| format!(": {e}")).unwrap_or_default()
            ),
            "check that the asix data server runs and serves this channel, AsixServerName/[AsixCTServers], BroadcastAddress and DiscoveryPort, that UDP discovery is allowed through the firewall, and that the server's certificate is pinned (AsixNetServerFingerprint or AsixNetCaFile, with AsixNetCertFile/AsixNetKeyFile): announcements of an unpinned certificate are ignored",
        ),
    }
}

/// What the link-identity probe of one server showed (`asix_net::probe`, as text): the
/// handshake made with the channel's security as configured.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LinkSeen {
    /// The server's certificate (fingerprint in hex), whether the channel's pins accept
    /// it (`refused`: why the handshake failed), its end of validity (seconds since 1970).
    Tls {
        fingerprint: String,
        pinned: bool,
        not_after: Option<i64>,
        refused: Option<String>,
    },
    Plaintext,
}

/// A certificate ending sooner than this is a warning.
pub const EXPIRY_WARNING_DAYS: i64 = 30;

/// `YYYY-MM-DD` (UTC) of a time in seconds since 1970.
pub fn utc_date(unix: i64) -> String {
    let z = unix.div_euclid(86_400) + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

/// The identity of one server's link (`server` at `addr`, found by discovery whatever it
/// announced), judged at `now` (seconds since 1970): a pinned certificate valid for
/// more than [`EXPIRY_WARNING_DAYS`] is OK; one about to expire or a plaintext link a
/// warning; an expired or unpinned certificate, or no link at all, a failure.
pub fn identity_check(
    opc_channel: &str,
    asix_channel: &str,
    server: &str,
    addr: &str,
    seen: &Result<LinkSeen, String>,
    now: i64,
) -> Check {
    let name =
        format!("asix link identity [Channel:{opc_channel}] {asix_channel}: {server} at {addr}");
    let renew = "make a new certificate on the server (`asix-gate --gen-cert DIR`, then Certificate/PrivateKey in asix-gate.ini) and pin its fingerprint in the channel's AsixNetServerFingerprint";
    match seen {
        Err(e) => Check::fail(
            name,
            format!("no link: {e}"),
            "check that the server runs and that its link port (asix-gate.ini Listen) is open in the firewalls between the two computers; a server speaking protocol version 1 must be upgraded",
        ),
        Ok(LinkSeen::Plaintext) => Check::warn(
            name,
            "plaintext link (AsixNetPlaintext): neither authenticated nor encrypted, anyone on the network can read and write",
            "only on a closed test network; otherwise give the channel AsixNetCertFile/AsixNetKeyFile, pin the server (AsixNetServerFingerprint) and remove AsixNetPlaintext",
        ),
        Ok(LinkSeen::Tls { fingerprint, pinned, not_after, refused }) => {
            let expired = not_after.is_some_and(|t| t <= now);
            let until = not_after.map(utc_date).unwrap_or_else(|| "an unknown date".into());
            if expired {
                Check::fail(name, format!("certificate {fingerprint} expired on {until}"), renew)
            } else if !pinned {
                Check::fail(
                    name,
                    format!(
                        "the server presents certificate {fingerprint}, which the channel does not pin{}",
                        refused.as_ref().map(|r| format!(" ({r})")).unwrap_or_default()
                    ),
                    format!("if this is your server (`asix-gate --gen-cert` printed its fingerprint), pin it: AsixNetServerFingerprint = {fingerprint} in the channel's section of ASIXConnect.ini; otherwise find out what answers at {addr}"),
                )
            } else if not_after.is_some_and(|t| t - now < EXPIRY_WARNING_DAYS * 86_400) {
                let days = not_after.map(|t| (t - now) / 86_400).unwrap_or(0);
                Check::warn(
                    name,
                    format!("certificate {fingerprint} pinned; it expires on {until} (in {days} days)"),
                    renew,
                )
            } else {
                Check::ok(name, format!("certificate {fingerprint} pinned, valid until {until}"))
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// DCOM, firewall

/// The authentication level of the server's open `CoInitializeSecurity`
/// (`ctopc_com::host::init_security`, `LegacyOpenAccess = tak`: RPC_C_AUTHN_LEVEL_NONE).
pub const LEGACY_AUTHN_LEVEL: u32 = 1;

/// The name of an RPC authentication level.
fn authn_level_name(level: u32) -> &'static str {
    match level {
        0 => "Default",
        1 => "None",
        2 => "Connect",
        3 => "Call",
        4 => "Packet",
        5 => "Packet Integrity",
        6 => "Packet Privacy",
        _ => "unknown",
    }
}

/// `HKLM\Software\Microsoft\Ole` `EnableDCOM`, `LegacyAuthenticationLevel` and
/// `AppCompat\RequireIntegrityActivationAuthenticationLevel` (KB5004442);
/// `server_level`: the authentication level the server's COM security uses (its AppID's,
/// or None under `LegacyOpenAccess`).
pub fn dcom_checks(
    enable_dcom: Option<&str>,
    legacy_authn: Option<&str>,
    require_integrity: Option<&str>,
    server_level: u32,
) -> Vec<Check> {
    let mut out = Vec::new();
    out.push(match enable_dcom.map(str::trim) {
        Some(v) if v.eq_ignore_ascii_case("N") => Check::warn(
            "DCOM enabled",
            "HKLM\\Software\\Microsoft\\Ole EnableDCOM = N: remote clients cannot connect",
            "set EnableDCOM = Y (dcomcnfg: My Computer > Properties > Default Properties) and restart",
        ),
        Some(v) => Check::ok("DCOM enabled", format!("EnableDCOM = {v}")),
        None => Check::ok("DCOM enabled", "EnableDCOM not set (enabled by default)"),
    });
    let level = legacy_authn.and_then(|v| v.trim().parse::<u32>().ok());
    out.push(match level {
        Some(l) if l >= 5 => Check::warn(
            "DCOM authentication level",
            format!("LegacyAuthenticationLevel = {l} (packet integrity or more): callbacks to clients that use None may fail"),
            "let remote clients use at least that level, or lower LegacyAuthenticationLevel (dcomcnfg: Default Authentication Level = Connect)",
        ),
        Some(l) => Check::ok("DCOM authentication level", format!("LegacyAuthenticationLevel = {l}")),
        None => Check::ok("DCOM authentication level", "LegacyAuthenticationLevel not set (Connect)"),
    });
    let hardening = require_integrity.and_then(|v| v.trim().parse::<u32>().ok());
    out.push(match hardening {
        Some(0) => Check::ok("DCOM hardening (KB5004442)", "RequireIntegrityActivationAuthenticationLevel = 0 (off)"),
        _ => Check::warn(
            "DCOM hardening (KB5004442)",
            format!(
                "activation needs packet integrity ({}), the server's COM security uses level {} ({server_level}): local clients work, remote clients that activate below integrity are refused",
                match hardening {
                    Some(v) => format!("RequireIntegrityActivationAuthenticationLevel = {v}"),
                    None => "the default since the 2023 updates".to_owned(),
                },
                authn_level_name(server_level)
            ),
            "make remote OPC clients activate with RPC_C_AUTHN_LEVEL_PKT_INTEGRITY (update them), or use OPC UA / a tunneller for old remote clients",
        ),
    });
    out
}

/// What the AppID of ServerCTOPC holds (its 64-bit view: the server is 64-bit), as read.
#[derive(Clone, Debug, Default)]
pub struct AppIdSecurity {
    pub access: Option<Vec<u8>>,
    pub launch: Option<Vec<u8>>,
    pub authentication_level: Option<u32>,
    /// `[Server] LegacyOpenAccess` of the configuration.
    pub legacy_open_access: bool,
    /// The SID of the local group `ServerCTOPC Clients`, if it exists.
    pub clients: Option<registration::security::Sid>,
}

/// The AppID's security: each value as it is (in SDDL), and what is weaker than the
/// defaults `/RegServer` writes (`ctopc_registration::security`), or missing.
pub fn appid_security_checks(a: &AppIdSecurity) -> Vec<Check> {
    use registration::security::{self as sec, Descriptor};
    let fix = "run ServerCTOPC.exe /RegServer (it writes the defaults where absent), or set it with dcomcnfg: Component Services > DCOM Config > ServerCTOPC.App > Properties > Security";
    let descriptor = |name: &str, value: &Option<Vec<u8>>| -> Check {
        let check = format!("AppID {name}");
        let Some(bytes) = value else {
            return Check::warn(
                check,
                format!("not set: the machine-wide default {name} applies"),
                fix,
            );
        };
        let Some(d) = Descriptor::from_bytes(bytes) else {
            return Check::fail(
                check,
                "not a self-relative security descriptor: COM refuses every client",
                fix,
            );
        };
        let weaker = sec::weaker_than_default(&d, a.clients.as_ref());
        if weaker.is_empty() {
            Check::ok(check, d.sddl())
        } else {
            Check::warn(
                check,
                format!("weaker than the defaults: {}; {}", weaker.join("; "), d.sddl()),
                "remove those entries (dcomcnfg), or delete the value and run ServerCTOPC.exe /RegServer for the defaults",
            )
        }
    };
    let mut out = vec![
        descriptor(sec::ACCESS_PERMISSION, &a.access),
        descriptor(sec::LAUNCH_PERMISSION, &a.launch),
    ];
    let level = a.authentication_level;
    out.push(match level {
        Some(l) if !sec::authentication_level_weaker(level) => Check::ok(
            "AppID AuthenticationLevel",
            format!("{l} ({})", authn_level_name(l)),
        ),
        Some(l) => Check::warn(
            "AppID AuthenticationLevel",
            format!(
                "{l} ({}): weaker than packet integrity (5)",
                authn_level_name(l)
            ),
            "set AuthenticationLevel = 5 under the AppID (dcomcnfg: Authentication Level = Packet Integrity)",
        ),
        None => Check::warn(
            "AppID AuthenticationLevel",
            "not set: the machine-wide default applies (usually Connect, weaker than packet integrity)",
            fix,
        ),
    });
    out.push(if a.legacy_open_access {
        Check::warn(
            "COM security",
            "LegacyOpenAccess = tak: no security descriptor, authentication level None; every process that can reach DCOM may connect, the AppID's values are not used",
            "set [Server] LegacyOpenAccess = nie in ASIXConnect.ini once the old remote clients are gone",
        )
    } else {
        Check::ok("COM security", "from the AppID (EOAC_APPID)")
    });
    out
}

/// The files of secrets a configuration names, with what each is: with a `[UA]` section
/// the OPC UA private key's folder and the key (`PkiDirectory`, default `pki`, its
/// `private\private.pem`) and the users file (`UsersFile`, default `ua-users.txt`); each
/// channel's asix-link client key (`AsixNetKeyFile`); where the server takes them from
/// (`AsixConfig::secret_paths`, the configuration in `dir`).
pub fn secret_files(
    cfg: &asix_model::config::AsixConfig,
    dir: &std::path::Path,
) -> Vec<(String, std::path::PathBuf)> {
    let paths = cfg.secret_paths(dir);
    let mut out = Vec::new();
    if cfg.ua.section {
        let folder = paths.ua_pki.join(asix_model::config::UA_PRIVATE_KEY_FOLDER);
        out.push(("OPC UA private key".to_owned(), paths.ua_private_key));
        out.push(("OPC UA private key folder".to_owned(), folder));
        out.push(("OPC UA users file".to_owned(), paths.ua_users_file));
    }
    for (name, key) in paths.key_files {
        out.push((format!("asix link key [Channel:{name}]"), key));
    }
    out
}

/// A file of secrets as it was found: absent, or what is weaker than allowed on it
/// (`ctopc_registration::security::secret_findings` on Windows, the mode on Unix; `None`:
/// private).
pub fn secret_check(what: &str, path: &str, exists: bool, finding: Option<&str>) -> Check {
    let name = format!("secret: {what}");
    match (exists, finding) {
        (false, _) => Check::ok(
            name,
            format!("{path}: not there (made private when written)"),
        ),
        (true, None) => Check::ok(name, format!("{path}: private")),
        (true, Some(f)) => Check::warn(
            name,
            format!("{path} is not private: {f}"),
            if cfg!(windows) {
                format!("icacls \"{path}\" /inheritance:r /grant:r *S-1-5-18:F *S-1-5-32-544:F *S-1-5-19:F, then icacls \"{path}\" /remove each other account named")
            } else {
                format!("chmod 600 {path} (a folder: chmod 700)")
            },
        ),
    }
}

/// The authentication level the server's COM security uses, for [`dcom_checks`].
pub fn server_authn_level(a: &AppIdSecurity) -> u32 {
    if a.legacy_open_access {
        LEGACY_AUTHN_LEVEL
    } else {
        a.authentication_level.unwrap_or(0)
    }
}

/// `[WriteRights]`: without it every connected client may write.
pub fn write_rights_check(rights: &ctopc_core::write_rights::WriteRights) -> Check {
    if rights.is_open() {
        Check::warn(
            "write rights",
            "no [WriteRights] section: every connected client may write every writable variable",
            "name who may write in [WriteRights] of ASIXConnect.ini (docs/configuration.md, Write rights)",
        )
    } else {
        Check::ok(
            "write rights",
            format!("[WriteRights]: {} entries", rights.rules().len()),
        )
    }
}

/// The firewall rules of `docs/deployment.md` section 8, from `netsh advfirewall firewall
/// show rule name=all` (`None`: it could not be run).
pub fn firewall_check(rules: Option<&str>) -> Check {
    const NAME: &str = "firewall";
    let fix = "allow inbound TCP 135 and the program ServerCTOPC.exe, and outbound UDP 48100 / TCP 48101 to the asix servers (docs/deployment.md, Firewall)";
    let Some(text) = rules else {
        return Check::warn(
            NAME,
            "the firewall rules could not be read (netsh advfirewall)",
            fix,
        );
    };
    let lower = text.to_ascii_lowercase();
    let has_exe = lower.contains("serverctopc.exe");
    let has_135 = lower
        .lines()
        .any(|l| l.contains("localport") && l.split_whitespace().any(|w| w == "135"));
    match (has_exe, has_135) {
        (true, true) => Check::ok(NAME, "rules for ServerCTOPC.exe and TCP 135 found"),
        _ => Check::warn(
            NAME,
            format!(
                "no rule found for {} (remote clients only)",
                match (has_exe, has_135) {
                    (false, false) => "ServerCTOPC.exe nor TCP 135",
                    (false, true) => "ServerCTOPC.exe",
                    _ => "TCP 135",
                }
            ),
            fix,
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    /// A registry in memory: keys with their values.
    #[derive(Default)]
    struct FakeRegistry {
        keys: HashMap<(View, String), Vec<(String, String)>>,
    }

    impl FakeRegistry {
        fn set(&mut self, view: View, path: &str, name: &str, value: &str) {
            let e = self.keys.entry((view, path.to_lowercase())).or_default();
            e.retain(|(n, _)| n != name);
            e.push((name.to_owned(), value.to_owned()));
        }
        fn with_keys(keys: &[Key]) -> Self {
            let mut r = FakeRegistry::default();
            for k in keys {
                r.keys.entry((k.view, k.path.to_lowercase())).or_default();
                for (n, v) in &k.values {
                    r.set(k.view, &k.path, n, v);
                }
            }
            r
        }
        fn remove_tree(&mut self, view: View, path: &str) {
            let p = path.to_lowercase();
            self.keys
                .retain(|(v, k), _| !(*v == view && (*k == p || k.starts_with(&format!("{p}\\")))));
        }
    }

    impl Registry for FakeRegistry {
        fn key_exists(&self, view: View, path: &str) -> bool {
            self.keys.contains_key(&(view, path.to_lowercase()))
        }
        fn value(&self, view: View, path: &str, name: &str) -> Option<String> {
            self.keys
                .get(&(view, path.to_lowercase()))?
                .iter()
                .find(|(n, _)| n.eq_ignore_ascii_case(name))
                .map(|(_, v)| v.clone())
        }
    }

    const EXE: &str = "C:\\Program Files\\ServerCTOPC\\ServerCTOPC.exe";

    fn installed() -> (FakeRegistry, Vec<Key>) {
        let keys = registration::serverctopc(EXE, None).keys();
        (FakeRegistry::with_keys(&keys), keys)
    }

    #[test]
    fn a_complete_registration_is_ok_in_both_views() {
        let (reg, keys) = installed();
        for v in registration::VIEWS {
            let c = registration_check(v, &keys, &reg);
            assert_eq!(c.status, Status::Ok, "{c:?}");
        }
        assert_eq!(registered_server(&reg), (Some(EXE.to_owned()), None));
    }

    #[test]
    fn no_registration_fails_with_regserver_as_the_fix() {
        let keys = registration::serverctopc(EXE, None).keys();
        let c = registration_check(View::Reg32, &keys, &FakeRegistry::default());
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.contains("not registered"), "{c:?}");
        assert!(c.fix.contains("/RegServer"));
    }

    #[test]
    fn a_missing_category_or_opc_key_in_one_view_fails_that_view_only() {
        let (mut reg, keys) = installed();
        let clsid = server_clsid_key();
        reg.remove_tree(
            View::Reg32,
            &format!(
                "{clsid}\\Implemented Categories\\{}",
                guid_string(registration::CATID_OPC_DA_SERVER_30)
            ),
        );
        reg.remove_tree(View::Reg32, "ServerCTOPC.App\\OPC");
        assert_eq!(
            registration_check(View::Reg64, &keys, &reg).status,
            Status::Ok
        );
        let c = registration_check(View::Reg32, &keys, &reg);
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.contains("Implemented Categories"), "{c:?}");
        assert!(c.detail.contains("ServerCTOPC.App\\OPC"), "{c:?}");
    }

    #[test]
    fn a_wrong_curver_is_named_with_both_values() {
        let (mut reg, keys) = installed();
        reg.set(
            View::Reg64,
            "ServerCTOPC.App\\CurVer",
            "",
            "ServerCTOPC.App.7",
        );
        let c = registration_check(View::Reg64, &keys, &reg);
        assert_eq!(c.status, Status::Fail);
        assert!(
            c.detail
                .contains("\"ServerCTOPC.App.7\", expected \"ServerCTOPC.App.1\""),
            "{c:?}"
        );
    }

    #[test]
    fn a_moved_exe_fails_with_the_path() {
        assert_eq!(exe_check(Some(EXE), true).status, Status::Ok);
        let c = exe_check(Some(EXE), false);
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.contains(EXE) && c.detail.contains("does not exist"));
        assert!(c.fix.contains("/RegServer"));
        assert_eq!(exe_check(None, false).status, Status::Fail);
    }

    #[test]
    fn command_lines_give_their_exe() {
        assert_eq!(
            exe_of_command_line("\"C:\\a b\\x.exe\" -Embedding"),
            "C:\\a b\\x.exe"
        );
        assert_eq!(
            exe_of_command_line("C:\\x\\OpcEnum.exe -service"),
            "C:\\x\\OpcEnum.exe"
        );
        assert_eq!(exe_of_command_line(" C:\\x.exe "), "C:\\x.exe");
    }

    #[test]
    fn the_idl_gives_every_opc_interface_with_its_iid() {
        let ifs = idl_interfaces();
        let find = |n: &str| ifs.iter().find(|(name, _)| name == n).map(|(_, id)| *id);
        assert_eq!(
            find("IOPCShutdown"),
            Some(0xf31dfde1_07b6_11d2_b2d8_0060083ba1fb)
        );
        assert_eq!(
            find("IOPCServer"),
            Some(0x39c13a4d_011e_11d0_9675_0020afd8adb3)
        );
        for n in [
            "IOPCCommon",
            "IOPCItemMgt",
            "IOPCDataCallback",
            "IOPCBrowse",
            "IOPCItemIO",
            "IOPCGroupStateMgt2",
            "IOPCAsyncIO3",
        ] {
            assert!(find(n).is_some(), "{n} in {ifs:?}");
        }
        assert!(ifs.len() >= 24, "{}", ifs.len());
    }

    fn with_proxy(reg: &mut FakeRegistry, view: View, ifs: &[(String, u128)], dll: &str) {
        let ps = "{B2E0E4C4-0000-0000-0000-000000000001}";
        for (_, iid) in ifs {
            reg.set(
                view,
                &format!("Interface\\{}\\ProxyStubClsid32", guid_string(*iid)),
                "",
                ps,
            );
        }
        reg.set(view, &format!("CLSID\\{ps}\\InprocServer32"), "", dll);
    }

    #[test]
    fn proxies_are_checked_per_view_and_named() {
        let ifs = idl_interfaces();
        let mut reg = FakeRegistry::default();
        with_proxy(&mut reg, View::Reg64, &ifs, "C:\\ServerCTOPC\\opc_ps.dll");
        let c = proxy_check(View::Reg64, &ifs, &reg, &|_| true);
        assert_eq!(c.status, Status::Ok, "{c:?}");
        assert!(c.detail.contains("opc_ps.dll"));
        let c = proxy_check(View::Reg32, &ifs, &reg, &|_| true);
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.contains("for any OPC interface"), "{c:?}");
        assert!(
            c.fix.contains("SysWOW64\\regsvr32 x86\\opc_ps.dll"),
            "{c:?}"
        );
        // The DLL gone.
        let c = proxy_check(View::Reg64, &ifs, &reg, &|_| false);
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.contains("does not exist"));
        // The OPC Foundation's, named.
        let mut reg = FakeRegistry::default();
        with_proxy(
            &mut reg,
            View::Reg32,
            &ifs,
            "C:\\Windows\\SysWOW64\\opcproxy.dll",
        );
        let c = proxy_check(View::Reg32, &ifs, &reg, &|_| true);
        assert_eq!(c.status, Status::Ok);
        assert!(c.detail.contains("OPC Foundation's opcproxy.dll"), "{c:?}");
        // One interface missing is named.
        let mut reg = FakeRegistry::default();
        with_proxy(&mut reg, View::Reg64, &ifs[1..], "opc_ps.dll");
        let c = proxy_check(View::Reg64, &ifs, &reg, &|_| true);
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.contains(&ifs[0].0), "{c:?}");
    }

    #[test]
    fn system32_paths_are_seen_through_the_redirection() {
        let p = "C:\\windows\\system32\\opcproxy.dll";
        assert_eq!(
            path_seen_here(p, View::Reg32, true),
            "C:\\windows\\SysWOW64\\opcproxy.dll"
        );
        assert_eq!(path_seen_here(p, View::Reg64, true), p);
        assert_eq!(
            path_seen_here(p, View::Reg64, false),
            "C:\\windows\\Sysnative\\opcproxy.dll"
        );
        assert_eq!(
            path_seen_here("D:\\S\\x86\\opc_ps.dll", View::Reg32, true),
            "D:\\S\\x86\\opc_ps.dll"
        );
    }

    #[test]
    fn the_server_browser_is_ours_or_opcenum() {
        let mut reg = FakeRegistry::default();
        let key = registration::server_list_local_server_key();
        assert_eq!(
            browser_check(View::Reg64, &reg, &|_| true).status,
            Status::Warn
        );
        reg.set(View::Reg64, &key, "", "\"C:\\S\\OpcServerList.exe\"");
        let c = browser_check(View::Reg64, &reg, &|_| true);
        assert_eq!(c.status, Status::Ok);
        assert!(c.detail.contains("ours"));
        reg.set(View::Reg32, &key, "", "C:\\Windows\\SysWOW64\\OpcEnum.exe");
        let c = browser_check(View::Reg32, &reg, &|_| true);
        assert!(c.detail.contains("OpcEnum"), "{c:?}");
        assert_eq!(
            browser_check(View::Reg32, &reg, &|_| false).status,
            Status::Warn
        );
    }

    #[test]
    fn the_service_verdicts() {
        let info = ServiceInfo {
            executable: format!("\"{EXE}\" -ServiceRun"),
            account: "NT AUTHORITY\\LocalService".into(),
            disabled: false,
        };
        assert_eq!(
            service_check(None, None, Some(EXE), true).status,
            Status::Ok
        );
        assert_eq!(
            service_check(Some("ServerCTOPC"), None, Some(EXE), true).status,
            Status::Fail
        );
        assert_eq!(
            service_check(Some("ServerCTOPC"), Some(&info), Some(EXE), true).status,
            Status::Ok
        );
        assert_eq!(
            service_check(Some("ServerCTOPC"), Some(&info), Some(EXE), false).status,
            Status::Fail
        );
        let disabled = ServiceInfo {
            disabled: true,
            ..info.clone()
        };
        assert_eq!(
            service_check(Some("ServerCTOPC"), Some(&disabled), Some(EXE), true).status,
            Status::Fail
        );
        assert_eq!(
            service_check(Some("ServerCTOPC"), Some(&info), Some("D:\\x.exe"), true).status,
            Status::Warn
        );
    }

    #[test]
    fn the_log_folder_follows_the_servers_rule() {
        assert_eq!(log_dir("C:\\S\\", None), "C:\\S\\Log");
        assert_eq!(log_dir("C:\\S", Some("Logi")), "C:\\S\\Logi");
        assert_eq!(log_dir("C:\\S", Some("D:\\L")), "D:\\L");
        let c = log_check(
            "C:\\S\\Log",
            &LogProbe::Failed("access denied".into()),
            "LocalService",
        );
        assert_eq!(c.status, Status::Fail);
        assert!(c.fix.contains("LocalService"));
        assert_eq!(
            log_check("x", &LogProbe::WillBeCreated, "a").status,
            Status::Ok
        );
    }

    #[test]
    fn an_invalid_configuration_fails_with_file_line_and_option() {
        let loaded = asix_model::startup::load(
            b"[Server]\nMinUpdateRate = soon\n",
            "C:\\S\\ASIXConnect.ini",
            None,
        );
        let c = config_check("C:\\S\\ASIXConnect.ini", &loaded);
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.contains("ASIXConnect.ini"), "{c:?}");
        assert!(c.detail.contains('2'), "line: {c:?}");
        assert!(c.detail.contains("MinUpdateRate"), "{c:?}");
        let ok = asix_model::startup::load(b"[Server]\nMinUpdateRate = 500\n", "a.ini", None);
        assert_eq!(config_check("a.ini", &ok).status, Status::Ok);
    }

    #[test]
    fn a_missing_database_fails_naming_the_channel() {
        let dir = std::env::temp_dir().join(format!("opcdiag-doctor-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let loaded = asix_model::startup::load(
            b"[Channel:*]\nItemsDatabase = nowhere.zez\n",
            "a.ini",
            Some(&dir),
        )
        .unwrap();
        let checks = database_checks(&loaded.namespace);
        assert_eq!(checks.len(), 1);
        assert_eq!(checks[0].status, Status::Fail);
        assert!(checks[0].name.contains("[Channel:*]"));
        assert!(checks[0].detail.contains("nowhere.zez"), "{:?}", checks[0]);
        let demo = asix_model::embedded_demo().unwrap();
        assert!(first_item(&demo.namespace).is_some());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_asix_channels_to_discover_come_from_the_channel_attribute() {
        let demo = asix_model::embedded_demo().unwrap();
        let channels = asix_channels(&demo.namespace);
        assert_eq!(channels.len(), 1, "{channels:?}");
        let (opc, asix) = &channels[0];
        assert_eq!(opc, "*");
        assert!(asix.iter().any(|a| a == "SIARKA"), "{asix:?}");
        let mut sorted = asix.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), asix.len(), "no duplicates: {asix:?}");
        assert_eq!(first_item(&demo.namespace).as_deref(), Some("KW_A000"));
    }

    #[test]
    fn rest_stations_are_checked_instead_of_discovery() {
        let demo = asix_model::embedded_demo().unwrap();
        let mut cfg = demo.namespace.config().clone();
        let mut evo = cfg.basic().clone();
        evo.asix_evo_rest = vec!["http://evo1".into(), "http://evo2".into()];
        cfg.channels.insert("EVO".into(), evo);
        let mut ns = AsixNamespace::new(cfg);
        ns.set_database("EVO", demo.namespace.database_state("*").clone());
        assert_eq!(
            rest_channels(&ns),
            [(
                "EVO".to_owned(),
                vec!["http://evo1".to_owned(), "http://evo2".to_owned()]
            )]
        );
        assert!(asix_channels(&ns).iter().all(|(c, _)| c != "EVO"));
        let c = rest_check("EVO", "http://evo1", 0, true, &Ok(()));
        assert_eq!(c.status, Status::Ok);
        assert!(c.detail.contains("read-only"), "{c:?}");
        let c = rest_check(
            "EVO",
            "http://evo2",
            1,
            true,
            &Err("HTTP status 503".into()),
        );
        assert_eq!(c.status, Status::Warn);
        assert!(
            c.detail.contains("standby station 1") && c.detail.contains("503"),
            "{c:?}"
        );
        let c = rest_check("EVO", "http://evo1", 0, false, &Err("timeout".into()));
        assert_eq!(c.status, Status::Fail);
    }

    #[test]
    fn the_link_names_the_chosen_server_or_the_timeout() {
        let c = link_check(
            "*",
            "K1",
            3000,
            &Ok(vec![("SRV1".into(), "10.0.0.5:48101".into())]),
        );
        assert_eq!(c.status, Status::Ok);
        assert!(c.detail.contains("SRV1") && c.detail.contains("10.0.0.5"));
        let c = link_check(
            "*",
            "K1",
            500,
            &Err("ASKOM_E_NetFindServer_NotFound".into()),
        );
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.contains("500 ms"), "{c:?}");
        assert!(c.fix.contains("DiscoveryPort"));
    }

    #[test]
    fn a_links_identity_is_ok_pinned_warned_near_expiry_or_plaintext_and_failed_otherwise() {
        const DAY: i64 = 86_400;
        let now = 1_800_000_000; // 2027-01-15
        let fp = "ab".repeat(32);
        let tls = |pinned: bool, not_after: i64| {
            Ok(LinkSeen::Tls {
                fingerprint: fp.clone(),
                pinned,
                not_after: Some(not_after),
                refused: (!pinned).then(|| "TLS handshake failed".to_owned()),
            })
        };
        let check = |seen| identity_check("*", "K1", "GATE1", "10.0.0.5:48101", &seen, now);
        let c = check(tls(true, now + 400 * DAY));
        assert_eq!(c.status, Status::Ok, "{c:?}");
        assert!(c.name.contains("GATE1") && c.name.contains("10.0.0.5:48101"));
        assert!(
            c.detail.contains(&fp) && c.detail.contains("2028-02-19"),
            "{c:?}"
        );
        let c = check(tls(true, now + 10 * DAY));
        assert_eq!(c.status, Status::Warn);
        assert!(
            c.detail.contains("in 10 days") && c.fix.contains("--gen-cert"),
            "{c:?}"
        );
        let c = check(tls(false, now + 400 * DAY));
        assert_eq!(c.status, Status::Fail);
        assert!(
            c.detail.contains(&fp) && c.detail.contains("does not pin"),
            "{c:?}"
        );
        assert!(
            c.fix.contains(&format!("AsixNetServerFingerprint = {fp}")),
            "{c:?}"
        );
        let c = check(tls(false, now - DAY));
        assert_eq!(c.status, Status::Fail);
        assert!(c.detail.contains("expired on 2027-01-14"), "{c:?}");
        let c = check(Ok(LinkSeen::Plaintext));
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.contains("plaintext"), "{c:?}");
        let c = check(Err("unreachable: connection refused".into()));
        assert_eq!(c.status, Status::Fail);
        assert!(
            c.detail.contains("unreachable") && c.fix.contains("firewall"),
            "{c:?}"
        );
    }

    #[test]
    fn dates_are_civil_utc() {
        assert_eq!(utc_date(0), "1970-01-01");
        assert_eq!(utc_date(978_307_200), "2001-01-01");
        assert_eq!(utc_date(951_782_400), "2000-02-29");
        assert_eq!(utc_date(1_800_000_000), "2027-01-15");
    }

    #[test]
    fn dcom_settings_warn_with_the_fix() {
        let c = dcom_checks(Some("N"), None, None, 5);
        assert_eq!(c[0].status, Status::Warn);
        assert!(c[0].fix.contains("EnableDCOM = Y"));
        let c = dcom_checks(Some("Y"), Some("2"), Some("0"), 5);
        assert!(c.iter().all(|c| c.status == Status::Ok), "{c:?}");
        let c = dcom_checks(Some("Y"), Some("6"), Some("1"), LEGACY_AUTHN_LEVEL);
        assert_eq!(c[1].status, Status::Warn);
        assert_eq!(c[2].status, Status::Warn);
        assert!(c[2].detail.contains("None (1)"), "{:?}", c[2]);
        assert!(c.iter().all(|c| c.status != Status::Fail));
        let c = dcom_checks(Some("Y"), None, None, 5);
        assert!(c[2].detail.contains("Packet Integrity (5)"), "{:?}", c[2]);
    }

    #[test]
    fn the_appid_security_is_shown_and_what_is_weaker_named() {
        use registration::security::{self as sec, Ace, Descriptor, Sid};
        let group = Sid::parse("S-1-5-21-7-1001").unwrap();
        let defaults = AppIdSecurity {
            access: Some(sec::default_access(false, Some(&group)).to_bytes()),
            launch: Some(sec::default_launch(false, Some(&group)).to_bytes()),
            authentication_level: Some(5),
            legacy_open_access: false,
            clients: Some(group.clone()),
        };
        let c = appid_security_checks(&defaults);
        assert!(c.iter().all(|c| c.status == Status::Ok), "{c:?}");
        assert!(
            c[0].detail.contains("(A;;0x3;;;S-1-5-32-544)"),
            "{:?}",
            c[0]
        );
        assert!(c[2].detail.contains("Packet Integrity"), "{:?}", c[2]);
        assert_eq!(server_authn_level(&defaults), 5);

        let everyone = Descriptor {
            owner: None,
            group: None,
            dacl: Some(vec![Ace::allow(
                Sid::parse(sec::EVERYONE).unwrap(),
                sec::ACCESS_REMOTE,
            )]),
            protected: false,
        };
        let weak = AppIdSecurity {
            access: Some(everyone.to_bytes()),
            launch: None,
            authentication_level: Some(2),
            legacy_open_access: true,
            clients: None,
        };
        let c = appid_security_checks(&weak);
        assert_eq!(c[0].status, Status::Warn);
        assert!(
            c[0].detail.contains("Everyone (S-1-1-0) is allowed 0x7"),
            "{:?}",
            c[0]
        );
        assert_eq!(c[1].status, Status::Warn);
        assert!(c[1].detail.contains("not set"), "{:?}", c[1]);
        assert_eq!(c[2].status, Status::Warn);
        assert!(c[2].detail.contains("2 (Connect)"), "{:?}", c[2]);
        assert_eq!(c[3].status, Status::Warn);
        assert!(c[3].detail.contains("LegacyOpenAccess = tak"));
        assert_eq!(server_authn_level(&weak), LEGACY_AUTHN_LEVEL);

        let broken = AppIdSecurity {
            access: Some(vec![1, 2, 3]),
            ..AppIdSecurity::default()
        };
        assert_eq!(appid_security_checks(&broken)[0].status, Status::Fail);
    }

    #[test]
    fn no_write_rights_warns_that_every_client_may_write() {
        use ctopc_core::write_rights::{Channels, Principal, Rule, WriteRights};
        let c = write_rights_check(&WriteRights::open());
        assert_eq!(c.status, Status::Warn);
        assert!(
            c.detail.contains("every connected client may write"),
            "{c:?}"
        );
        let c = write_rights_check(&WriteRights::new(vec![Rule::new(
            Channels::All,
            Principal::Anyone,
        )]));
        assert_eq!(c.status, Status::Ok);
        assert!(c.detail.contains("1 entries"), "{c:?}");
    }

    #[test]
    fn firewall_rules_are_found_or_warned() {
        assert_eq!(firewall_check(None).status, Status::Warn);
        let rules =
            "Rule Name: OPC\nLocalPort: 135\nRule Name: S\nProgram: C:\\S\\ServerCTOPC.exe\n";
        assert_eq!(firewall_check(Some(rules)).status, Status::Ok);
        let c = firewall_check(Some("Rule Name: X\nLocalPort: 80\n"));
        assert_eq!(c.status, Status::Warn);
        assert!(c.detail.contains("ServerCTOPC.exe nor TCP 135"));
    }

    #[test]
    fn failures_are_one_line() {
        let c = Check::fail(
            "c",
            "cannot connect: E_NOINTERFACE\n  the proxy is missing\n",
            "x",
        );
        assert_eq!(
            c.detail,
            "cannot connect: E_NOINTERFACE; the proxy is missing"
        );
    }

    #[test]
    fn the_exit_code_and_the_two_renderings() {
        let checks = vec![
            Check::ok("a", "fine"),
            Check::warn("b", "meh", "do x"),
            Check::fail("c \"q\"", "bad\\path", "do y"),
        ];
        assert_eq!(exit_code(&checks), 1);
        assert_eq!(exit_code(&checks[..2]), 0);
        let t = render_text(&checks);
        assert!(t.contains("FAIL  c \"q\"  bad\\path"), "{t}");
        assert!(t.contains("fix: do y"));
        assert!(t.ends_with("3 check(s): 1 OK, 1 WARN, 1 FAIL\n"), "{t}");
        let j = render_json(&checks);
        assert!(j.contains("{\"name\": \"c \\\"q\\\"\", \"status\": \"FAIL\", \"detail\": \"bad\\\\path\", \"fix\": \"do y\"}"), "{j}");
        assert!(j.starts_with("[\n") && j.ends_with("\n]\n"));
    }

    #[test]
    fn the_secret_files_come_from_the_configuration() {
        let cfg = |ini: &str| {
            asix_model::config::parse_config(ini.as_bytes(), "ASIXConnect.ini")
                .unwrap()
                .0
        };
        let dir = std::path::Path::new("/opt/ctopc");
        assert!(secret_files(&cfg("[Server]\nLogLevel = info\n"), dir).is_empty());
        let names: Vec<(String, String)> = secret_files(
            &cfg("[UA]\nUsersFile = /etc/ctopc/users.txt\n[Channel:K1]\nAsixNetKeyFile = keys/k1.pem\n"),
            dir,
        )
        .into_iter()
        .map(|(w, p)| (w, p.display().to_string()))
        .collect();
        let want = [
            ("OPC UA private key", "/opt/ctopc/pki/private/private.pem"),
            ("OPC UA private key folder", "/opt/ctopc/pki/private"),
            ("OPC UA users file", "/etc/ctopc/users.txt"),
            ("asix link key [Channel:K1]", "/opt/ctopc/keys/k1.pem"),
        ];
        assert_eq!(
            names,
            want.map(|(w, p)| (w.to_owned(), p.to_owned())).to_vec()
        );
    }

    #[test]
    fn a_secret_file_weaker_than_allowed_warns_with_the_fix() {
        let table: &[(bool, Option<&str>, Status, &str)] = &[
            (false, None, Status::Ok, "k.pem: not there"),
            (true, None, Status::Ok, "k.pem: private"),
            (
                true,
                Some("Users (S-1-5-32-545) may read it (0x1200a9)"),
                Status::Warn,
                "k.pem is not private: Users (S-1-5-32-545) may read it",
            ),
        ];
        for (exists, finding, status, detail) in table {
            let c = secret_check("the key", "k.pem", *exists, *finding);
            assert_eq!(c.name, "secret: the key");
            assert_eq!(c.status, *status, "{c:?}");
            assert!(c.detail.starts_with(detail), "{c:?}");
            assert_eq!(c.fix.is_empty(), *status == Status::Ok, "{c:?}");
        }
        let c = secret_check("the key", "k.pem", true, Some("x"));
        assert!(
            c.fix
                .contains(if cfg!(windows) { "icacls" } else { "chmod 600" }),
            "{c:?}"
        );
    }
}
