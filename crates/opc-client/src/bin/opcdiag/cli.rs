//! The command line of opcdiag: parsing and help (pure, tested natively).
//!
//! Parsed by clap (derive): global options (`--server`, `--lang`) anywhere, then a
//! subcommand with its own options and arguments, `-h`/`--help`/`/?` anywhere for the
//! command's help. The help is clap's, from the doc comments of [`Cli`] and [`Command`]
//! (`-h` and `--help` show the same text: clap's compact layout with the command's whole
//! doc comment); clap's errors are turned into opcdiag's own messages, each with the help
//! of the command it is about, and exit code 2.
// Natively only the tests use what the Windows commands show.
#![cfg_attr(not(windows), allow(dead_code))]

use clap::error::{ContextKind, ContextValue, ErrorKind};
use clap::{ArgAction, Args, CommandFactory, Parser, Subcommand};
use ctopc_core::VarType;

pub const DEFAULT_SERVER: &str = "ServerCTOPC.App";

/// Exit codes.
pub const EXIT_OK: u8 = 0;
/// The server or an item reported an error (a failed call or a failed item).
pub const EXIT_FAILED: u8 = 1;
/// Bad command line.
pub const EXIT_USAGE: u8 = 2;
/// OPC UA (`--url`): no session: the server unreachable, its certificate not trusted, ours
/// refused, or the user refused.
#[cfg_attr(not(ua), allow(dead_code))]
pub const EXIT_NO_SESSION: u8 = 3;

/// The heading of the options every command takes.
const GLOBAL: &str = "Global options";
/// The heading of the OPC UA options.
const UA: &str = "OPC UA (--url)";

/// The end of the general help.
const AFTER_HELP: &str = "\
exit codes: 0 success, 1 the server or an item reported an error, 2 bad command line.
3 (OPC UA) no session: server unreachable, its certificate untrusted, ours or the user refused.
Errors show the HRESULT in hex, its symbol, and the server's text for it (OPC UA: the
StatusCode's name and hex).
With --url, browse, read, write and subscribe speak OPC UA: an ITEMID is a DA item ID
(the NodeId ns=<the server's namespace>;s=ITEMID) or a full NodeId (ns=2;s=KW_A000, i=85).";

/// opcdiag - diagnostic client for any OPC DA 2.05a/3.0 server (local, through COM)
#[derive(Parser, Debug)]
#[command(
    name = "opcdiag",
    after_help = AFTER_HELP,
    disable_version_flag = true,
    disable_help_subcommand = true,
    disable_help_flag = true,
    args_override_self = true,
    subcommand_required = true
)]
struct Cli {
    #[command(flatten)]
    global: Global,
    /// help (after a command: that command's help)
    #[arg(short, long, global = true, action = ArgAction::Help, help_heading = GLOBAL)]
    help: Option<bool>,
    /// Not supported (remote servers): rejected with a message.
    #[arg(long, global = true, hide = true, num_args = 0..=1, default_missing_value = "",
          value_parser = host_arg)]
    host: Option<String>,
    /// Not supported (remote servers): rejected with a message.
    #[arg(long, global = true, hide = true, num_args = 0..=1, default_missing_value = "",
          value_parser = node_arg)]
    node: Option<String>,
    #[command(subcommand)]
    command: Sub,
}

/// Options every command takes.
#[derive(Args, Debug, Clone, PartialEq)]
pub struct Global {
    /// the server's ProgID
    #[arg(long, global = true, value_name = "PROGID", default_value = DEFAULT_SERVER,
          value_parser = server_arg, help_heading = GLOBAL)]
    pub server: String,
    // The LCID to set with IOPCCommon::SetLocaleID; `None`: the server's default.
    /// the session's language (error texts, descriptions);
    /// default: the server's
    #[arg(long = "lang", global = true, value_name = "en|pl|LCID", value_parser = lang_arg,
          help_heading = GLOBAL, verbatim_doc_comment)]
    pub lcid: Option<u32>,
    #[command(flatten)]
    pub ua: UaOptions,
}

/// The OPC UA options: with `--url`, browse, read, write and subscribe speak OPC UA.
#[derive(Args, Debug, Clone, PartialEq)]
pub struct UaOptions {
    /// speak OPC UA to this server instead of OPC DA
    #[arg(long, global = true, value_name = "opc.tcp://HOST:PORT", value_parser = url_arg,
          help_heading = UA)]
    pub url: Option<String>,
    /// message security: none, sign, encrypt (SignAndEncrypt)
    #[arg(long, global = true, value_name = "none|sign|encrypt", value_parser = security_arg,
          default_value = "encrypt", help_heading = UA)]
    pub security: Security,
    /// the security policy: Basic256Sha256, Aes128_Sha256_RsaOaep,
    /// Aes256_Sha256_RsaPss
    #[arg(long, global = true, value_name = "POLICY", value_parser = policy_arg,
          default_value = "Basic256Sha256", help_heading = UA, verbatim_doc_comment)]
    pub policy: String,
    /// log in as NAME (the password is asked for, or read with
    /// --password-stdin); default: anonymous
    #[arg(long, global = true, value_name = "NAME", help_heading = UA, verbatim_doc_comment)]
    pub user: Option<String>,
    /// read the password from the first line of standard input
    #[arg(long, global = true, help_heading = UA)]
    pub password_stdin: bool,
    /// opcdiag's PKI folder: own/ (its certificate, made at first use),
    /// trusted/ and rejected/ (server certificates); default: the user's
    /// configuration folder (see `opcdiag cert`)
    #[arg(long, global = true, value_name = "DIR", help_heading = UA, verbatim_doc_comment)]
    pub pki: Option<String>,
    /// trust the server's certificate: its SHA-1 thumbprint (pinned: only
    /// that certificate), or `accept` (whatever it presents, on first use);
    /// either way it is saved in trusted/ for the next runs. Default: an
    /// unknown server certificate is refused and saved in rejected/
    #[arg(long, global = true, value_name = "THUMBPRINT|accept", value_parser = trust_arg,
          help_heading = UA, verbatim_doc_comment)]
    pub trust_server: Option<TrustServer>,
}

impl Default for UaOptions {
    /// What the command line gives without any OPC UA option.
    fn default() -> Self {
        UaOptions {
            url: None,
            security: Security::Encrypt,
            policy: POLICIES[0].into(),
            user: None,
            password_stdin: false,
            pki: None,
            trust_server: None,
        }
    }
}

/// `--security`: the message security mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Security {
    None,
    Sign,
    #[default]
    Encrypt,
}

/// `--trust-server`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TrustServer {
    /// The certificate with this SHA-1 thumbprint (40 hex digits, lower case).
    Pin(String),
    /// Whatever certificate the server presents (trust on first use).
    Accept,
}

/// The subcommands: the commands that run, and `help`.
#[derive(Subcommand, Debug)]
enum Sub {
    #[command(flatten)]
    Run(Command),
    /// this text, or a command's
    Help {
        #[arg(value_name = "COMMAND")]
        command: Vec<String>,
    },
}

/// The commands that run. The first paragraph of each doc comment is its line in the
/// general help, the whole its own help.
#[derive(Subcommand, Debug, Clone, PartialEq)]
pub enum Command {
    /// the server's status: vendor, version, state, times, groups
    ///
    /// Connects to the server and prints IOPCServer::GetStatus: vendor information, version,
    /// state (RUNNING, FAILED, NOCONFIG, SUSPENDED, TEST, COMM_FAULT), start, current and last
    /// update time (local time), group count and band width. Exit code 1 when the server cannot
    /// be reached.
    #[command(verbatim_doc_comment)]
    Status,
    /// the address space as an indented tree (or a flat list)
    ///
    /// Shows the address space through IOPCBrowseServerAddressSpace: branches end with '/',
    /// each level indented by two spaces; a leaf whose item ID differs from its name shows the
    /// item ID after '='.
    #[command(verbatim_doc_comment)]
    Browse {
        /// one item ID per line (BrowseOPCItemIDs with OPC_FLAT)
        #[arg(long)]
        flat: bool,
        /// start at this branch: its item ID (ChangeBrowsePosition TO) or its
        /// names from the root separated by '/' (DOWN step by step)
        #[arg(long, value_name = "PATH", verbatim_doc_comment)]
        branch: Option<String>,
        /// show N levels (default: all)
        #[arg(long, value_name = "N", value_parser = depth_arg, allow_negative_numbers = true)]
        depth: Option<usize>,
        /// OPC UA: at most N references per Browse answer; the rest
        /// follow with BrowseNext (continuation points)
        #[arg(long, value_name = "N", default_value_t = 1000, value_parser = page_arg,
              allow_negative_numbers = true, verbatim_doc_comment)]
        page: u32,
    },
    /// the item's properties: ID, description, value
    ///
    /// Lists the item's properties through IOPCItemProperties (QueryAvailableProperties and
    /// GetItemProperties): property ID, description, data type and value.
    #[command(verbatim_doc_comment)]
    Props {
        /// the item's ID
        #[arg(value_name = "ITEMID")]
        item: String,
    },
    /// read items once (from the cache, or the device)
    ///
    /// Adds the items to a temporary group and reads them once with IOPCSyncIO::Read. Prints
    /// per item: value, data type, quality (e.g. GOOD, BAD Comm Failure [Low limit]) and
    /// timestamp in local time. Exit code 1 when an item failed.
    #[command(verbatim_doc_comment)]
    Read {
        /// the items' IDs
        #[arg(value_name = "ITEMID", required = true)]
        items: Vec<String>,
        /// read from the device (default: the server's cache, waiting up
        /// to 3 s for the first value)
        #[arg(long, verbatim_doc_comment)]
        device: bool,
        /// the items' access path (default: none)
        #[arg(
            long,
            value_name = "ACCESSPATH",
            default_value = "",
            hide_default_value = true
        )]
        path: String,
    },
    /// write one value (converted to the item's type or to VT)
    ///
    /// Writes VALUE with IOPCSyncIO::Write and prints the item's result. VALUE is converted to
    /// the item's canonical data type (as en-US text: a '.' decimal point; true/false for BOOL),
    /// or to VT when given. Exit code 1 when the write failed.
    #[command(verbatim_doc_comment, allow_negative_numbers = true)]
    Write {
        /// the item's ID
        #[arg(value_name = "ITEMID")]
        item: String,
        /// the value to write (as en-US text, see above)
        #[arg(value_name = "VALUE")]
        value: String,
        /// send the value as VT: R4 R8 I1 I2 I4 I8 UI1 UI2 UI4 UI8 BOOL BSTR
        /// CY DATE (VT_R4 etc. also accepted)
        #[arg(long = "type", value_name = "VT", value_parser = type_arg, verbatim_doc_comment)]
        vt: Option<VarType>,
        /// the item's access path (default: none)
        #[arg(
            long,
            value_name = "ACCESSPATH",
            default_value = "",
            hide_default_value = true
        )]
        path: String,
    },
    /// print every change the server reports, until Ctrl+C
    ///
    /// Adds the items to an active group with an IOPCDataCallback sink and prints each change
    /// as it arrives: time (local), item, value, quality. Runs until Ctrl+C or, with --for,
    /// until SECONDS have passed, or, with --count, until N changes have arrived (whichever
    /// comes first; scripts use both, e.g. --count 1 --for 30). Exit code 1 when --count was
    /// given and fewer than N changes arrived.
    #[command(verbatim_doc_comment)]
    Subscribe {
        /// the items' IDs
        #[arg(value_name = "ITEMID", required = true)]
        items: Vec<String>,
        /// the group's update rate
        #[arg(long = "rate", value_name = "MS", default_value_t = 1000, value_parser = rate_arg,
              allow_negative_numbers = true)]
        rate_ms: u32,
        /// stop after SECONDS (may have decimals)
        #[arg(long = "for", visible_alias = "seconds", value_name = "SECONDS",
              value_parser = for_arg, allow_negative_numbers = true)]
        for_secs: Option<f64>,
        /// stop after N item changes (the first values count)
        #[arg(long, value_name = "N", value_parser = count_arg, allow_negative_numbers = true)]
        count: Option<usize>,
        /// the items' access path (default: none)
        #[arg(
            long,
            value_name = "ACCESSPATH",
            default_value = "",
            hide_default_value = true
        )]
        path: String,
    },
    /// ServerCTOPC's demo plant: status, plant tree, live values
    ///
    /// For ServerCTOPC with the Wytwornia_Kwasu demo plant (the embedded default, or the demo
    /// database over the asix network, as `cargo xtask demo` runs it): prints the server status,
    /// the first levels of the plant tree, then subscribes to a handful of process variables -
    /// tank levels, temperatures, flows, a pump - and prints their changes live, until Ctrl+C
    /// or, with --for, until SECONDS have passed.
    #[command(verbatim_doc_comment)]
    Demo {
        /// stop after SECONDS (may have decimals)
        #[arg(long = "for", value_name = "SECONDS", value_parser = for_arg,
              allow_negative_numbers = true)]
        for_secs: Option<f64>,
    },
    /// the machine's OPC servers: ProgID, DA versions, description
    ///
    /// Lists the OPC DA servers of this machine (both registry views) through the server browser
    /// OPC.ServerList.1 (ours, OpcServerList.exe, or the OPC Foundation's OpcEnum): for each its
    /// ProgID, the DA versions it implements (component categories DA 1.0, 2.0, 3.0), its
    /// description and CLSID. Without a server browser it falls back to the component
    /// categories manager (ICatInformation, this process's registry view only) and says so.
    /// --server is not used (no server connection).
    #[command(verbatim_doc_comment)]
    Servers,
    /// check ServerCTOPC's installation: OK / WARN / FAIL with fixes
    ///
    /// Checks ServerCTOPC's installation and prints each check as OK, WARN or FAIL with the fix
    /// in one line: the registration in both registry views (CLSID, LocalServer32 and that the
    /// exe exists, ProgID and CurVer, categories DA 2.0/3.0, AppID, the OPC key), a proxy/stub
    /// for every OPC Common and DA interface in both views (ours or the OPC Foundation's), a
    /// server browser (OPC.ServerList.1), the NT service when installed, the log folder, the
    /// configuration file and each channel's variable database (read as the server reads
    /// them), each channel's asix link (discovery within FindServerTimeout, the server chosen),
    /// machine-wide DCOM settings and the firewall (warnings), and finally a connection that
    /// reads one item and receives one callback. Exit code 0 when nothing failed, else 1.
    #[command(verbatim_doc_comment)]
    Doctor(DoctorOptions),
    /// OPC UA: opcdiag's client certificate (made at first use)
    ///
    /// Prints the file and SHA-1 thumbprint of the application instance certificate opcdiag
    /// presents to OPC UA servers, made on first use in the PKI folder (--pki, default: the
    /// user's configuration folder: $XDG_CONFIG_HOME or ~/.config, %APPDATA% on Windows, then
    /// opcdiag/pki). A server refuses it until trusted: on ServerCTOPC,
    /// `ServerCTOPC pki trust FILE` (or move it from the server's pki/rejected to pki/trusted).
    #[command(verbatim_doc_comment)]
    Cert,
    /// the Paradox attribute table as the CSV the server reads
    ///
    /// Reads the original's Paradox attribute table (a .DB with its .MB memos, or the table of a
    /// variable set, as the server finds it) and writes it as the CSV attribute table
    /// (docs/variable-database.md): ';'-separated, UTF-8, the text decoded from the table's code
    /// page, numbers, logicals (tak/nie), dates and times as text. Point the set's
    /// `Attributes =` at the CSV, or name it after the set (zestaw.csv beside zestaw.zez): a set
    /// without `Attributes =` takes that CSV before a .DB.
    /// --server is not used (no server connection); this command also runs on Linux.
    #[command(verbatim_doc_comment)]
    ExportDb {
        /// a variable set (.zez) or a Paradox table (.DB)
        #[arg(value_name = "SET_OR_TABLE")]
        source: String,
        /// write the CSV to FILE (default: standard output)
        #[arg(long, value_name = "FILE")]
        out: Option<String>,
    },
}

/// The options of `opcdiag doctor`.
#[derive(Args, Debug, Clone, PartialEq, Default)]
pub struct DoctorOptions {
    /// one JSON object per check: name, status, detail, fix
    #[arg(long)]
    pub json: bool,
    /// the configuration to check (default: SERVERCTOPC_INI, else
    /// ASIXConnect.ini next to the registered exe, else the embedded
    /// demo); under Wine the server started by the last check uses it too
    #[arg(long, value_name = "FILE", verbatim_doc_comment)]
    pub config: Option<String>,
    /// the item to read and subscribe (default: the first variable of
    /// the basic channel's database)
    #[arg(long, value_name = "ITEMID", verbatim_doc_comment)]
    pub item: Option<String>,
    /// the longest wait of the connection check (default 20)
    #[arg(long = "timeout", value_name = "SECONDS", value_parser = for_arg,
          allow_negative_numbers = true)]
    pub timeout_secs: Option<f64>,
}

/// The help of a command (the general help for `None`, `help` or an unknown name): clap's
/// help in its compact layout, with a command's whole doc comment as its description.
pub fn help(command: Option<&str>) -> String {
    let mut cli = Cli::command();
    cli.build();
    match command
        .filter(|c| *c != "help")
        .and_then(|c| cli.find_subcommand(c))
    {
        Some(sub) => {
            let mut sub = sub.clone();
            if let Some(long) = sub.get_long_about().cloned() {
                sub = sub.about(long);
            }
            sub.render_help().to_string()
        }
        None => cli.render_help().to_string(),
    }
}

/// What the command line asks for.
#[derive(Debug, Clone, PartialEq)]
// Made once per run: its size does not matter.
#[allow(clippy::large_enum_variant)]
pub enum Parsed {
    Run(Global, Command),
    /// Print this help text and exit 0.
    Help(String),
}

/// A command-line error: the message and the help text to show with it.
#[derive(Debug, Clone, PartialEq)]
pub struct UsageError {
    pub message: String,
    pub help: String,
}

const COMMANDS: &[&str] = &[
    "status",
    "browse",
    "props",
    "read",
    "write",
    "subscribe",
    "demo",
    "doctor",
    "export-db",
    "cert",
];

/// What a command's arguments must be, for the message when they are not.
fn needs(command: &str) -> &'static str {
    match command {
        "status" => "no arguments",
        "browse" => "no arguments besides its options",
        "props" => "one ITEMID",
        "read" | "subscribe" => "at least one ITEMID",
        "write" => "ITEMID and VALUE",
        "demo" => "no arguments besides --for",
        "doctor" => "no arguments besides its options",
        "export-db" => "one variable set or Paradox table",
        "cert" => "no arguments",
        _ => "other arguments",
    }
}

/// The LCID for `--lang`: en, pl, or a number (decimal or 0x hex).
pub fn parse_lcid(s: &str) -> Option<u32> {
    match s.to_ascii_lowercase().as_str() {
        "en" | "english" => Some(0x0409),
        "pl" | "polish" | "polski" => Some(0x0415),
        other => match other.strip_prefix("0x") {
            Some(hex) => u32::from_str_radix(hex, 16).ok(),
            None => other.parse().ok(),
        },
    }
}

/// The VARTYPE for `--type`: R4, VT_R4, float, ... (case-insensitive).
pub fn parse_vartype(s: &str) -> Option<VarType> {
    let up = s.to_ascii_uppercase();
    let name = up.strip_prefix("VT_").unwrap_or(&up);
    Some(match name {
        "I1" | "CHAR" => VarType::I1,
        "UI1" | "BYTE" => VarType::UI1,
        "I2" | "SHORT" => VarType::I2,
        "UI2" | "WORD" => VarType::UI2,
        "I4" | "INT" | "LONG" => VarType::I4,
        "UI4" | "DWORD" => VarType::UI4,
        "I8" => VarType::I8,
        "UI8" => VarType::UI8,
        "R4" | "FLOAT" => VarType::R4,
        "R8" | "DOUBLE" => VarType::R8,
        "BOOL" | "BOOLEAN" => VarType::BOOL,
        "BSTR" | "STRING" => VarType::BSTR,
        "CY" | "CURRENCY" => VarType::CY,
        "DATE" => VarType::DATE,
        _ => return None,
    })
}

/// A number of seconds > 0 (decimals allowed).
fn parse_secs(s: &str) -> Option<f64> {
    s.parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0)
}

// clap's value parsers: each error is the whole message opcdiag shows.

fn server_arg(v: &str) -> Result<String, String> {
    if v.trim().is_empty() {
        return Err("--server needs a ProgID".into());
    }
    Ok(v.to_string())
}

fn lang_arg(v: &str) -> Result<u32, String> {
    parse_lcid(v).ok_or_else(|| format!("--lang: unknown language {v:?} (en, pl or an LCID)"))
}

fn remote(option: &str) -> String {
    format!("{option}: remote servers are not supported; run opcdiag on the server's computer")
}

fn host_arg(_: &str) -> Result<String, String> {
    Err(remote("--host"))
}

fn node_arg(_: &str) -> Result<String, String> {
    Err(remote("--node"))
}

fn url_arg(v: &str) -> Result<String, String> {
    let rest = v
        .strip_prefix("opc.tcp://")
        .ok_or_else(|| format!("--url: expected opc.tcp://HOST:PORT, got {v:?}"))?;
    let authority = rest.split('/').next().unwrap_or_default();
    match authority.rsplit_once(':') {
        Some((host, port)) if !host.is_empty() && port.parse::<u16>().is_ok() => Ok(v.into()),
        _ => Err(format!("--url: expected opc.tcp://HOST:PORT, got {v:?}")),
    }
}

fn security_arg(v: &str) -> Result<Security, String> {
    match v.to_ascii_lowercase().as_str() {
        "none" => Ok(Security::None),
        "sign" => Ok(Security::Sign),
        "encrypt" | "signandencrypt" => Ok(Security::Encrypt),
        _ => Err(format!(
            "--security: expected none, sign or encrypt, got {v:?}"
        )),
    }
}

/// The security policies opcdiag offers (the names of OPC UA's policy URIs).
pub const POLICIES: &[&str] = &[
    "Basic256Sha256",
    "Aes128_Sha256_RsaOaep",
    "Aes256_Sha256_RsaPss",
];

fn policy_arg(v: &str) -> Result<String, String> {
    POLICIES
        .iter()
        .find(|p| p.eq_ignore_ascii_case(v))
        .map(|p| p.to_string())
        .ok_or_else(|| {
            format!(
                "--policy: expected one of {}, got {v:?}",
                POLICIES.join(", ")
            )
        })
}

fn trust_arg(v: &str) -> Result<TrustServer, String> {
    if v.eq_ignore_ascii_case("accept") {
        return Ok(TrustServer::Accept);
    }
    let hex: String = v.chars().filter(|c| *c != ':' && *c != ' ').collect();
    if hex.len() == 40 && hex.chars().all(|c| c.is_ascii_hexdigit()) {
        Ok(TrustServer::Pin(hex.to_ascii_lowercase()))
    } else {
        Err(format!(
            "--trust-server: expected the certificate's SHA-1 thumbprint (40 hex digits) or accept, got {v:?}"
        ))
    }
}

fn page_arg(v: &str) -> Result<u32, String> {
    v.parse::<u32>()
        .ok()
        .filter(|d| *d > 0)
        .ok_or_else(|| format!("--page: expected a number > 0, got {v:?}"))
}

fn depth_arg(v: &str) -> Result<usize, String> {
    v.parse::<usize>()
        .ok()
        .filter(|d| *d > 0)
        .ok_or_else(|| format!("--depth: expected a number > 0, got {v:?}"))
}

fn type_arg(v: &str) -> Result<VarType, String> {
    parse_vartype(v).ok_or_else(|| format!("--type: unknown data type {v:?}"))
}

fn rate_arg(v: &str) -> Result<u32, String> {
    v.parse::<u32>()
        .map_err(|_| format!("--rate: expected milliseconds, got {v:?}"))
}

fn for_arg(v: &str) -> Result<f64, String> {
    parse_secs(v).ok_or_else(|| format!("--for: expected seconds > 0, got {v:?}"))
}

/// `subscribe --count N`: a number of changes > 0.
fn count_arg(v: &str) -> Result<usize, String> {
    v.parse::<usize>()
        .ok()
        .filter(|n| *n > 0)
        .ok_or_else(|| format!("--count: expected a number of changes > 0, got {v:?}"))
}

/// Parses the arguments after the program name.
pub fn parse(args: &[String]) -> Result<Parsed, UsageError> {
    // `/?` is the Windows spelling of --help.
    let args: Vec<&str> = args
        .iter()
        .map(|a| if a == "/?" { "--help" } else { a.as_str() })
        .collect();
    let cli = match Cli::try_parse_from(std::iter::once("opcdiag").chain(args.iter().copied())) {
        Ok(cli) => cli,
        // -h or --help anywhere: the help of the command given, wherever it stands.
        Err(e) if e.kind() == ErrorKind::DisplayHelp => {
            return Ok(Parsed::Help(help(command_in(&args))))
        }
        Err(e) => return Err(usage_error(&e, command_in(&args))),
    };
    match cli.command {
        Sub::Help { command } => Ok(Parsed::Help(help(command.first().map(String::as_str)))),
        Sub::Run(command) => Ok(Parsed::Run(cli.global, command)),
    }
}

/// The command the arguments name (the first word that is not an option or an option's
/// value), to pick the help text shown with `--help` or with an error.
fn command_in<'a>(args: &[&'a str]) -> Option<&'a str> {
    let cli = Cli::command();
    let takes_value = |long: &str| {
        std::iter::once(&cli)
            .chain(cli.get_subcommands())
            .flat_map(|c| c.get_arguments())
            .any(|a| a.get_long() == Some(long) && a.get_action().takes_values())
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if let Some(long) = a.strip_prefix("--") {
            if !long.contains('=') && takes_value(long) {
                it.next();
            }
        } else if !a.starts_with('-') {
            return Some(a);
        }
    }
    None
}

/// The long options of `command` (`None`: the global ones).
fn options_of(command: Option<&str>) -> Vec<String> {
    let cli = Cli::command();
    let c = match command {
        Some(name) => match cli.find_subcommand(name) {
            Some(c) => c.clone(),
            None => return Vec::new(),
        },
        None => cli,
    };
    c.get_arguments()
        .filter_map(|a| a.get_long().map(|l| format!("--{l}")))
        .collect()
}

/// opcdiag's message for a clap error, with the help of the command it is about.
fn usage_error(e: &clap::Error, command: Option<&str>) -> UsageError {
    // A word that is no command is reported as an unknown command, with the usage.
    let command = command.filter(|c| COMMANDS.contains(c) || *c == "help");
    let context = |kind| match e.get(kind) {
        Some(ContextValue::String(s)) => Some(s.as_str()),
        _ => None,
    };
    let arg = context(ContextKind::InvalidArg).unwrap_or("");
    let message = match e.kind() {
        // No command: clap asks for the general help (arg_required_else_help).
        ErrorKind::MissingSubcommand | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            return UsageError {
                message: "no command given".into(),
                help: help(None),
            }
        }
        ErrorKind::InvalidSubcommand => {
            let name = context(ContextKind::InvalidSubcommand).unwrap_or(arg);
            return UsageError {
                message: format!("unknown command {name:?}"),
                help: help(None),
            };
        }
        ErrorKind::UnknownArgument if !arg.starts_with('-') => match command {
            Some(c) => format!("{c} needs {}", needs(c)),
            None => {
                return UsageError {
                    message: format!("unknown command {arg:?}"),
                    help: help(None),
                }
            }
        },
        ErrorKind::UnknownArgument => {
            let known = |c: Option<&str>| options_of(c).iter().any(|o| o == arg);
            match command {
                Some(c) if known(Some(c)) => {
                    format!("{arg} is an option of {c}: give it after {c}")
                }
                Some(c) if COMMANDS.iter().any(|o| known(Some(o))) => {
                    format!("{c} does not take {arg}")
                }
                _ => format!("unknown option {arg}"),
            }
        }
        ErrorKind::MissingRequiredArgument | ErrorKind::TooFewValues => match command {
            Some(c) => format!("{c} needs {}", needs(c)),
            None => first_line(e),
        },
        ErrorKind::ValueValidation => match std::error::Error::source(e) {
            Some(source) => source.to_string(),
            None => first_line(e),
        },
        ErrorKind::InvalidValue | ErrorKind::NoEquals => {
            let name = arg.split_whitespace().next().unwrap_or(arg);
            format!("{name} needs a value")
        }
        _ => first_line(e),
    };
    UsageError {
        message,
        help: help(command),
    }
}

/// clap's own message, without its "error: " and its usage lines.
fn first_line(e: &clap::Error) -> String {
    let text = e.to_string();
    let line = text.lines().next().unwrap_or_default();
    line.strip_prefix("error: ").unwrap_or(line).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    fn run(s: &str) -> (Global, Command) {
        match parse(&args(s)) {
            Ok(Parsed::Run(g, c)) => (g, c),
            other => panic!("{s}: {other:?}"),
        }
    }

    fn usage_error(s: &str) -> String {
        match parse(&args(s)) {
            Err(e) => e.message,
            other => panic!("{s}: expected an error, got {other:?}"),
        }
    }

    #[test]
    fn status_defaults_to_servertopc_and_the_servers_language() {
        let (g, c) = run("status");
        assert_eq!(
            g,
            Global {
                server: "ServerCTOPC.App".into(),
                lcid: None,
                ua: UaOptions::default()
            }
        );
        assert_eq!(c, Command::Status);
    }

    #[test]
    fn global_options_go_before_or_after_the_command() {
        let (g, _) = run("--server Matrikon.OPC.Simulation.1 status --lang pl");
        assert_eq!(g.server, "Matrikon.OPC.Simulation.1");
        assert_eq!(g.lcid, Some(0x0415));
        assert_eq!(run("status --lang 0x0409").0.lcid, Some(0x0409));
        assert_eq!(run("status --lang 1045").0.lcid, Some(1045));
        assert_eq!(run("status --server X.Y").0.server, "X.Y");
    }

    #[test]
    fn browse_options() {
        assert_eq!(
            run("browse").1,
            Command::Browse {
                flat: false,
                branch: None,
                depth: None,
                page: 1000
            }
        );
        assert_eq!(
            run("browse --flat --branch Magazyn --depth 2").1,
            Command::Browse {
                flat: true,
                branch: Some("Magazyn".into()),
                depth: Some(2),
                page: 1000
            }
        );
    }

    #[test]
    fn read_takes_several_items_a_source_and_an_access_path() {
        assert_eq!(
            run("read KW_A000 KW_A001 --device --path Demo_Wytwornia_Kwasu").1,
            Command::Read {
                items: vec!["KW_A000".into(), "KW_A001".into()],
                device: true,
                path: "Demo_Wytwornia_Kwasu".into()
            }
        );
        assert_eq!(
            run("read KW_A000").1,
            Command::Read {
                items: vec!["KW_A000".into()],
                device: false,
                path: String::new()
            }
        );
    }

    #[test]
    fn write_takes_an_item_a_value_and_an_optional_type() {
        assert_eq!(
            run("write KW_A110 12.5 --type r4").1,
            Command::Write {
                item: "KW_A110".into(),
                value: "12.5".into(),
                vt: Some(VarType::R4),
                path: String::new()
            }
        );
        assert_eq!(
            run("write X -3 --type VT_I2").1,
            Command::Write {
                item: "X".into(),
                value: "-3".into(),
                vt: Some(VarType::I2),
                path: String::new()
            }
        );
        assert!(usage_error("write KW_A110").contains("ITEMID and VALUE"));
        assert!(usage_error("write A 1 2").contains("ITEMID and VALUE"));
        assert!(usage_error("write A 1 --type R5").contains("unknown data type"));
    }

    #[test]
    fn subscribe_rate_and_duration() {
        assert_eq!(
            run("subscribe A B --rate 250 --for 2.5").1,
            Command::Subscribe {
                items: vec!["A".into(), "B".into()],
                rate_ms: 250,
                for_secs: Some(2.5),
                count: None,
                path: String::new()
            }
        );
        assert_eq!(
            run("subscribe A").1,
            Command::Subscribe {
                items: vec!["A".into()],
                rate_ms: 1000,
                for_secs: None,
                count: None,
                path: String::new()
            }
        );
        assert!(usage_error("subscribe A --for 0").contains("seconds > 0"));
        assert!(usage_error("subscribe A --for x").contains("seconds > 0"));
        assert!(usage_error("subscribe A --rate fast").contains("milliseconds"));
        assert!(usage_error("subscribe").contains("at least one ITEMID"));
    }

    #[test]
    fn subscribe_count_bounds_the_changes() {
        assert_eq!(
            run("subscribe A --count 2 --for 30").1,
            Command::Subscribe {
                items: vec!["A".into()],
                rate_ms: 1000,
                for_secs: Some(30.0),
                count: Some(2),
                path: String::new()
            }
        );
        assert!(usage_error("subscribe A --count 0").contains("--count: expected a number"));
        assert!(usage_error("subscribe A --count -1").contains("--count: expected a number"));
        assert!(usage_error("subscribe A --count x").contains("--count: expected a number"));
    }

    #[test]
    fn demo_and_its_duration() {
        assert_eq!(run("demo").1, Command::Demo { for_secs: None });
        assert_eq!(
            run("demo --for 15").1,
            Command::Demo {
                for_secs: Some(15.0)
            }
        );
    }

    #[test]
    fn help_for_everything() {
        assert_eq!(parse(&args("--help")), Ok(Parsed::Help(help(None))));
        assert_eq!(parse(&args("help")), Ok(Parsed::Help(help(None))));
        assert_eq!(
            parse(&args("help write")),
            Ok(Parsed::Help(help(Some("write"))))
        );
        assert_eq!(
            parse(&args("subscribe --help")),
            Ok(Parsed::Help(help(Some("subscribe"))))
        );
        assert_eq!(
            parse(&args("read -h")),
            Ok(Parsed::Help(help(Some("read"))))
        );
        for c in COMMANDS {
            let text = help(Some(c));
            assert!(text.contains(&format!("Usage: opcdiag {c}")), "{c}");
            assert!(help(None).contains(c), "{c} is in the general usage");
        }
    }

    #[test]
    fn mistakes_are_usage_errors_with_the_commands_help() {
        let e = parse(&args("")).unwrap_err();
        assert_eq!(
            (e.message.as_str(), e.help.as_str()),
            ("no command given", help(None).as_str())
        );
        let e = parse(&args("frobnicate")).unwrap_err();
        assert!(e.message.contains("unknown command"));
        let e = parse(&args("read A --flat")).unwrap_err();
        assert_eq!(
            (e.message.as_str(), e.help.as_str()),
            ("read does not take --flat", help(Some("read")).as_str())
        );
        assert!(usage_error("status extra").contains("no arguments"));
        assert!(usage_error("props").contains("one ITEMID"));
        assert!(usage_error("read A --bogus").contains("unknown option --bogus"));
        assert!(usage_error("status --server").contains("needs a value"));
        assert!(usage_error("status --lang klingon").contains("unknown language"));
        assert!(usage_error("status --host plc1").contains("remote servers are not supported"));
        assert!(usage_error("browse --depth 0").contains("--depth"));
    }

    #[test]
    fn export_db_takes_a_table_and_an_output_file() {
        assert_eq!(
            parse(&args("export-db D:\\baza\\zestaw.zez --out atrybuty.csv")),
            Ok(Parsed::Run(
                Global {
                    server: DEFAULT_SERVER.into(),
                    lcid: None,
                    ua: UaOptions::default()
                },
                Command::ExportDb {
                    source: "D:\\baza\\zestaw.zez".into(),
                    out: Some("atrybuty.csv".into())
                }
            ))
        );
        assert!(usage_error("export-db").contains("one variable set or Paradox table"));
    }

    #[test]
    fn vartype_names() {
        for (s, vt) in [
            ("R8", VarType::R8),
            ("vt_bstr", VarType::BSTR),
            ("bool", VarType::BOOL),
            ("UI4", VarType::UI4),
            ("float", VarType::R4),
        ] {
            assert_eq!(parse_vartype(s), Some(vt), "{s}");
        }
        assert_eq!(parse_vartype("VT_VARIANT"), None);
    }

    #[test]
    fn the_clap_definition_is_consistent_and_the_help_tells_everything() {
        let mut cli = Cli::command();
        cli.clone().debug_assert();
        cli.build();
        let general = help(None);
        for fact in [
            "diagnostic client for any OPC DA 2.05a/3.0 server (local, through COM)",
            "--server <PROGID>",
            "[default: ServerCTOPC.App]",
            "--lang <en|pl|LCID>",
            "-h, --help",
            "exit codes: 0 success, 1 the server or an item reported an error, 2 bad command line.",
            "Errors show the HRESULT in hex, its symbol, and the server's text for it",
            "--url <opc.tcp://HOST:PORT>",
            "3 (OPC UA) no session",
            "[default: encrypt]",
            "[default: Basic256Sha256]",
        ] {
            assert!(general.contains(fact), "{fact}: {general}");
        }
        for c in COMMANDS.iter().chain(&["servers", "help"]) {
            let sub = cli.find_subcommand(c).unwrap();
            let summary = sub.get_about().unwrap().to_string();
            assert!(
                general.contains(&summary),
                "{c}: its line in the general help"
            );
        }
        for c in COMMANDS.iter().chain(&["servers"]) {
            let sub = cli.find_subcommand(c).unwrap();
            let text = help(Some(c));
            let whole = sub.get_long_about().unwrap().to_string();
            assert!(
                text.starts_with(&whole),
                "{c}: its whole description: {text}"
            );
            assert!(
                text.contains(&format!("Usage: opcdiag {c} [OPTIONS]")),
                "{c}: {text}"
            );
            for option in options_of(Some(c)) {
                assert!(text.contains(&option), "{c}: {option}: {text}");
            }
            assert!(text.contains("--server <PROGID>"), "{c}: {text}");
        }
        assert!(help(Some("subscribe")).contains("[default: 1000]"));
        assert!(help(Some("doctor")).contains("Exit code 0 when nothing failed, else 1."));
    }

    #[test]
    fn windows_help_negative_values_and_options_before_their_command() {
        assert_eq!(parse(&args("/?")), Ok(Parsed::Help(help(None))));
        assert_eq!(
            parse(&args("write /?")),
            Ok(Parsed::Help(help(Some("write"))))
        );
        assert_eq!(
            parse(&args("help frobnicate")),
            Ok(Parsed::Help(help(None)))
        );
        assert_eq!(
            parse(&args("--server X.Y --help browse")),
            Ok(Parsed::Help(help(Some("browse"))))
        );
        assert_eq!(
            run("--lang=pl write X -3.5").1,
            Command::Write {
                item: "X".into(),
                value: "-3.5".into(),
                vt: None,
                path: String::new()
            }
        );
        assert_eq!(
            run("subscribe A --rate 10 --rate 20").1,
            Command::Subscribe {
                items: vec!["A".into()],
                rate_ms: 20,
                for_secs: None,
                count: None,
                path: String::new()
            },
            "the last of a repeated option counts"
        );
        let e = parse(&args("--flat browse")).unwrap_err();
        assert_eq!(
            (e.message.as_str(), e.help.as_str()),
            (
                "--flat is an option of browse: give it after browse",
                help(Some("browse")).as_str()
            )
        );
        assert!(usage_error("status --node").contains("--node: remote servers"));
        let blank = ["status", "--server", " "].map(String::from);
        assert_eq!(
            parse(&blank).unwrap_err().message,
            "--server needs a ProgID"
        );
        assert!(usage_error("props --device A").contains("props does not take --device"));
        assert!(usage_error("subscribe A --for -1").contains("seconds > 0"));
    }

    #[test]
    fn opc_ua_options_anywhere_with_safe_defaults() {
        let (g, c) = run("--url opc.tcp://plc1:4840 read KW_A000 --user jan --password-stdin");
        assert_eq!(
            g.ua,
            UaOptions {
                url: Some("opc.tcp://plc1:4840".into()),
                user: Some("jan".into()),
                password_stdin: true,
                ..UaOptions::default()
            }
        );
        assert_eq!(
            g.ua.security,
            Security::Encrypt,
            "SignAndEncrypt by default"
        );
        assert_eq!(g.ua.policy, "Basic256Sha256");
        assert_eq!(
            g.ua.trust_server, None,
            "no server certificate trusted by default"
        );
        assert!(matches!(c, Command::Read { .. }));
        let (g, _) = run(
            "browse --url opc.tcp://[::1]:4840/ --security sign --policy aes256_sha256_rsapss \
             --pki /tmp/p --trust-server 0E:2C:62:D1:EF:56:DF:9E:8E:84:AB:3E:0F:F5:08:5A:69:DF:94:26",
        );
        assert_eq!(g.ua.security, Security::Sign);
        assert_eq!(g.ua.policy, "Aes256_Sha256_RsaPss");
        assert_eq!(g.ua.pki.as_deref(), Some("/tmp/p"));
        assert_eq!(
            g.ua.trust_server,
            Some(TrustServer::Pin(
                "0e2c62d1ef56df9e8e84ab3e0ff5085a69df9426".into()
            ))
        );
        assert_eq!(
            run("read A --url opc.tcp://h:1 --trust-server accept")
                .0
                .ua
                .trust_server,
            Some(TrustServer::Accept)
        );
        assert_eq!(
            run("read A --url opc.tcp://h:1 --security none")
                .0
                .ua
                .security,
            Security::None
        );
        assert!(usage_error("read A --url http://h:1").contains("opc.tcp://HOST:PORT"));
        assert!(usage_error("read A --url opc.tcp://h").contains("opc.tcp://HOST:PORT"));
        assert!(usage_error("read A --security high").contains("none, sign or encrypt"));
        assert!(usage_error("read A --policy Basic128Rsa15").contains("Basic256Sha256"));
        assert!(usage_error("read A --trust-server yes").contains("SHA-1 thumbprint"));
        assert!(usage_error("browse --page 0").contains("--page"));
        assert_eq!(
            run("subscribe A --seconds 2 --count 3").1,
            Command::Subscribe {
                items: vec!["A".into()],
                rate_ms: 1000,
                for_secs: Some(2.0),
                count: Some(3),
                path: String::new()
            },
            "--seconds is --for"
        );
        assert_eq!(run("cert --pki /tmp/p").1, Command::Cert);
    }

    #[test]
    fn servers_takes_no_arguments() {
        assert_eq!(
            parse(&args("servers")),
            Ok(Parsed::Run(
                Global {
                    server: DEFAULT_SERVER.into(),
                    lcid: None,
                    ua: UaOptions::default()
                },
                Command::Servers
            ))
        );
        assert_eq!(
            parse(&args("servers -h")),
            Ok(Parsed::Help(help(Some("servers"))))
        );
        assert_eq!(
            parse(&args("help servers")),
            Ok(Parsed::Help(help(Some("servers"))))
        );
        assert!(parse(&args("servers x")).is_err());
    }
}
