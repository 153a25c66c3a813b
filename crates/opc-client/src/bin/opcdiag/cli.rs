//! The command line of opcdiag: parsing and help texts (pure, tested natively).
//!
//! Parsed by clap (derive): global options (`--server`, `--lang`) anywhere, then a
//! subcommand with its own options and arguments, `-h`/`--help`/`/?` anywhere for the
//! command's help. The help texts are the hand-written ones below (clap shows them as its
//! help of each command); clap's errors are turned into opcdiag's own messages, each
//! with the help of the command it is about, and exit code 2.
// Natively only the tests use what the Windows commands show.
#![cfg_attr(not(windows), allow(dead_code))]

use clap::error::{ContextKind, ContextValue, ErrorKind};
use clap::{CommandFactory, Parser, Subcommand};
use ctopc_core::VarType;

pub const DEFAULT_SERVER: &str = "ServerCTOPC.App";

/// Exit codes.
pub const EXIT_OK: u8 = 0;
/// The server or an item reported an error (a failed call or a failed item).
pub const EXIT_FAILED: u8 = 1;
/// Bad command line.
pub const EXIT_USAGE: u8 = 2;

pub const USAGE: &str = "\
opcdiag - diagnostic client for any OPC DA 2.05a/3.0 server (local, through COM)

usage: opcdiag [--server PROGID] [--lang en|pl|LCID] <command> [options]

commands:
  status                    the server's status: vendor, version, state, times, groups
  browse [--flat] [--branch PATH] [--depth N]
                            the address space as an indented tree (or a flat list)
  props ITEMID              the item's properties: ID, description, value
  read ITEMID... [--device] [--path ACCESSPATH]
                            read items once (from the cache, or the device)
  write ITEMID VALUE [--type VT] [--path ACCESSPATH]
                            write one value (converted to the item's type or to VT)
  subscribe ITEMID... [--rate MS] [--for SECONDS] [--count N] [--path ACCESSPATH]
                            print every change the server reports, until Ctrl+C
  demo [--for SECONDS]      ServerCTOPC's demo plant: status, plant tree, live values
  servers                   the machine's OPC servers: ProgID, DA versions, description
  doctor [--json] [--config FILE] [--item ITEMID] [--timeout SECONDS]
                            check ServerCTOPC's installation: OK / WARN / FAIL with fixes
  help [COMMAND]            this text, or a command's

global options:
  --server PROGID           the server's ProgID (default ServerCTOPC.App)
  --lang en|pl|LCID         the session's language (error texts, descriptions);
                            default: the server's
  -h, --help                help (after a command: that command's help)

exit codes: 0 success, 1 the server or an item reported an error, 2 bad command line.
Errors show the HRESULT in hex, its symbol, and the server's text for it.
";

const STATUS_HELP: &str = "\
usage: opcdiag [--server PROGID] status

Connects to the server and prints IOPCServer::GetStatus: vendor information, version,
state (RUNNING, FAILED, NOCONFIG, SUSPENDED, TEST, COMM_FAULT), start, current and last
update time (local time), group count and band width. Exit code 1 when the server cannot
be reached.
";

const BROWSE_HELP: &str = "\
usage: opcdiag [--server PROGID] browse [--flat] [--branch PATH] [--depth N]

Shows the address space through IOPCBrowseServerAddressSpace: branches end with '/',
each level indented by two spaces; a leaf whose item ID differs from its name shows the
item ID after '='.
  --flat          one item ID per line (BrowseOPCItemIDs with OPC_FLAT)
  --branch PATH   start at this branch: its item ID (ChangeBrowsePosition TO) or its
                  names from the root separated by '/' (DOWN step by step)
  --depth N       show N levels (default: all)
";

const PROPS_HELP: &str = "\
usage: opcdiag [--server PROGID] props ITEMID

Lists the item's properties through IOPCItemProperties (QueryAvailableProperties and
GetItemProperties): property ID, description, data type and value.
";

const READ_HELP: &str = "\
usage: opcdiag [--server PROGID] read ITEMID... [--device] [--path ACCESSPATH]

Adds the items to a temporary group and reads them once with IOPCSyncIO::Read. Prints
per item: value, data type, quality (e.g. GOOD, BAD Comm Failure [Low limit]) and
timestamp in local time. Exit code 1 when an item failed.
  --device            read from the device (default: the server's cache, waiting up
                      to 3 s for the first value)
  --path ACCESSPATH   the items' access path (default: none)
";

const WRITE_HELP: &str = "\
usage: opcdiag [--server PROGID] write ITEMID VALUE [--type VT] [--path ACCESSPATH]

Writes VALUE with IOPCSyncIO::Write and prints the item's result. VALUE is converted to
the item's canonical data type (as en-US text: a '.' decimal point; true/false for BOOL),
or to VT when given. Exit code 1 when the write failed.
  --type VT           send the value as VT: R4 R8 I1 I2 I4 I8 UI1 UI2 UI4 UI8 BOOL BSTR
                      CY DATE (VT_R4 etc. also accepted)
  --path ACCESSPATH   the item's access path (default: none)
";

const SUBSCRIBE_HELP: &str = "\
usage: opcdiag [--server PROGID] subscribe ITEMID... [--rate MS] [--for SECONDS]
                                                    [--count N] [--path ACCESSPATH]

Adds the items to an active group with an IOPCDataCallback sink and prints each change
as it arrives: time (local), item, value, quality. Runs until Ctrl+C or, with --for,
until SECONDS have passed, or, with --count, until N changes have arrived (whichever
comes first; scripts use both, e.g. --count 1 --for 30). Exit code 1 when --count was
given and fewer than N changes arrived.
  --rate MS           the group's update rate (default 1000)
  --for SECONDS       stop after SECONDS (may have decimals)
  --count N           stop after N item changes (the first values count)
  --path ACCESSPATH   the items' access path (default: none)
";

const DEMO_HELP: &str = "\
usage: opcdiag [--server PROGID] demo [--for SECONDS]

For ServerCTOPC with the Wytwornia_Kwasu demo plant (the embedded default, or the demo
database over the asix network, as `cargo xtask demo` runs it): prints the server status,
the first levels of the plant tree, then subscribes to a handful of process variables -
tank levels, temperatures, flows, a pump - and prints their changes live, until Ctrl+C
or, with --for, until SECONDS have passed.
";

const SERVERS_HELP: &str = "\
usage: opcdiag servers

Lists the OPC DA servers of this machine (both registry views) through the server browser
OPC.ServerList.1 (ours, OpcServerList.exe, or the OPC Foundation's OpcEnum): for each its
ProgID, the DA versions it implements (component categories DA 1.0, 2.0, 3.0), its
description and CLSID. Without a server browser it falls back to the component
categories manager (ICatInformation, this process's registry view only) and says so.
--server is not used.
";

const DOCTOR_HELP: &str = "\
usage: opcdiag doctor [--json] [--config FILE] [--item ITEMID] [--timeout SECONDS]

Checks ServerCTOPC's installation and prints each check as OK, WARN or FAIL with the fix
in one line: the registration in both registry views (CLSID, LocalServer32 and that the
exe exists, ProgID and CurVer, categories DA 2.0/3.0, AppID, the OPC key), a proxy/stub
for every OPC Common and DA interface in both views (ours or the OPC Foundation's), a
server browser (OPC.ServerList.1), the NT service when installed, the log folder, the
configuration file and each channel's variable database (read as the server reads
them), each channel's asix link (discovery within FindServerTimeout, the server chosen),
machine-wide DCOM settings and the firewall (warnings), and finally a connection that
reads one item and receives one callback. Exit code 0 when nothing failed, else 1.
  --json              one JSON object per check: name, status, detail, fix
  --config FILE       the configuration to check (default: SERVERCTOPC_INI, else
                      ASIXConnect.ini next to the registered exe, else the embedded
                      demo); under Wine the server started by the last check uses it too
  --item ITEMID       the item to read and subscribe (default: the first variable of
                      the basic channel's database)
  --timeout SECONDS   the longest wait of the connection check (default 20)
";

/// The help text of a command (the general usage for `None` or an unknown name).
pub fn help(command: Option<&str>) -> &'static str {
    match command {
        Some("status") => STATUS_HELP,
        Some("browse") => BROWSE_HELP,
        Some("props") => PROPS_HELP,
        Some("read") => READ_HELP,
        Some("write") => WRITE_HELP,
        Some("subscribe") => SUBSCRIBE_HELP,
        Some("demo") => DEMO_HELP,
        Some("servers") => SERVERS_HELP,
        Some("doctor") => DOCTOR_HELP,
        _ => USAGE,
    }
}

/// Options every command takes.
#[derive(Debug, Clone, PartialEq)]
pub struct Global {
    pub server: String,
    /// The LCID to set with IOPCCommon::SetLocaleID; `None`: the server's default.
    pub lcid: Option<u32>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    Status,
    Browse {
        flat: bool,
        branch: Option<String>,
        depth: Option<usize>,
    },
    Props {
        item: String,
    },
    Read {
        items: Vec<String>,
        device: bool,
        path: String,
    },
    Write {
        item: String,
        value: String,
        vt: Option<VarType>,
        path: String,
    },
    Subscribe {
        items: Vec<String>,
        rate_ms: u32,
        for_secs: Option<f64>,
        /// `--count N`: stop after N item changes.
        count: Option<usize>,
        path: String,
    },
    Demo {
        for_secs: Option<f64>,
    },
    /// The machine's OPC servers, through the server browser (no server connection).
    Servers,
    /// `opcdiag doctor`: the installation's self-check.
    Doctor(DoctorOptions),
}

/// The options of `opcdiag doctor`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DoctorOptions {
    pub json: bool,
    pub config: Option<String>,
    pub item: Option<String>,
    pub timeout_secs: Option<f64>,
}

/// What the command line asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum Parsed {
    Run(Global, Command),
    /// Print this help text and exit 0.
    Help(&'static str),
}

/// A command-line error: the message and the help text to show with it.
#[derive(Debug, Clone, PartialEq)]
pub struct UsageError {
    pub message: String,
    pub help: &'static str,
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

/// The command line as clap sees it.
#[derive(Parser, Debug)]
#[command(
    name = "opcdiag",
    override_help = USAGE,
    disable_version_flag = true,
    disable_help_subcommand = true,
    args_override_self = true
)]
struct Cli {
    /// The server's ProgID.
    #[arg(long, global = true, value_name = "PROGID", value_parser = server_arg)]
    server: Option<String>,
    /// The session's language: en, pl or an LCID.
    #[arg(long, global = true, value_name = "LCID", value_parser = lang_arg)]
    lang: Option<u32>,
    /// Not supported (remote servers): rejected with a message.
    #[arg(long, global = true, hide = true, num_args = 0..=1, default_missing_value = "",
          value_parser = host_arg)]
    host: Option<String>,
    /// Not supported (remote servers): rejected with a message.
    #[arg(long, global = true, hide = true, num_args = 0..=1, default_missing_value = "",
          value_parser = node_arg)]
    node: Option<String>,
    #[command(subcommand)]
    command: Option<Sub>,
}

#[derive(Subcommand, Debug)]
enum Sub {
    #[command(override_help = STATUS_HELP)]
    Status,
    #[command(override_help = BROWSE_HELP)]
    Browse {
        #[arg(long)]
        flat: bool,
        #[arg(long, value_name = "PATH")]
        branch: Option<String>,
        #[arg(long, value_name = "N", value_parser = depth_arg, allow_negative_numbers = true)]
        depth: Option<usize>,
    },
    #[command(override_help = PROPS_HELP)]
    Props {
        #[arg(value_name = "ITEMID")]
        item: String,
    },
    #[command(override_help = READ_HELP)]
    Read {
        #[arg(value_name = "ITEMID", required = true)]
        items: Vec<String>,
        #[arg(long)]
        device: bool,
        #[arg(long, value_name = "ACCESSPATH")]
        path: Option<String>,
    },
    #[command(override_help = WRITE_HELP, allow_negative_numbers = true)]
    Write {
        #[arg(value_name = "ITEMID")]
        item: String,
        #[arg(value_name = "VALUE")]
        value: String,
        #[arg(long = "type", value_name = "VT", value_parser = type_arg)]
        vt: Option<VarType>,
        #[arg(long, value_name = "ACCESSPATH")]
        path: Option<String>,
    },
    #[command(override_help = SUBSCRIBE_HELP)]
    Subscribe {
        #[arg(value_name = "ITEMID", required = true)]
        items: Vec<String>,
        #[arg(long = "rate", value_name = "MS", value_parser = rate_arg, allow_negative_numbers = true)]
        rate_ms: Option<u32>,
        #[arg(long = "for", value_name = "SECONDS", value_parser = for_arg, allow_negative_numbers = true)]
        for_secs: Option<f64>,
        #[arg(long, value_name = "N", value_parser = count_arg, allow_negative_numbers = true)]
        count: Option<usize>,
        #[arg(long, value_name = "ACCESSPATH")]
        path: Option<String>,
    },
    #[command(override_help = DEMO_HELP)]
    Demo {
        #[arg(long = "for", value_name = "SECONDS", value_parser = for_arg, allow_negative_numbers = true)]
        for_secs: Option<f64>,
    },
    #[command(override_help = SERVERS_HELP)]
    Servers,
    #[command(override_help = DOCTOR_HELP)]
    Doctor {
        #[arg(long)]
        json: bool,
        #[arg(long, value_name = "FILE")]
        config: Option<String>,
        #[arg(long, value_name = "ITEMID")]
        item: Option<String>,
        #[arg(long = "timeout", value_name = "SECONDS", value_parser = for_arg, allow_negative_numbers = true)]
        timeout_secs: Option<f64>,
    },
    /// `help [COMMAND]`: the general usage, or a command's help.
    #[command(override_help = USAGE)]
    Help {
        #[arg(value_name = "COMMAND")]
        command: Vec<String>,
    },
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
    let global = Global {
        server: cli.server.unwrap_or_else(|| DEFAULT_SERVER.to_string()),
        lcid: cli.lang,
    };
    let command = match cli.command {
        None => {
            return Err(UsageError {
                message: "no command given".into(),
                help: USAGE,
            })
        }
        Some(Sub::Help { command }) => {
            return Ok(Parsed::Help(help(command.first().map(String::as_str))))
        }
        Some(Sub::Status) => Command::Status,
        Some(Sub::Browse {
            flat,
            branch,
            depth,
        }) => Command::Browse {
            flat,
            branch,
            depth,
        },
        Some(Sub::Props { item }) => Command::Props { item },
        Some(Sub::Read {
            items,
            device,
            path,
        }) => Command::Read {
            items,
            device,
            path: path.unwrap_or_default(),
        },
        Some(Sub::Write {
            item,
            value,
            vt,
            path,
        }) => Command::Write {
            item,
            value,
            vt,
            path: path.unwrap_or_default(),
        },
        Some(Sub::Subscribe {
            items,
            rate_ms,
            for_secs,
            count,
            path,
        }) => Command::Subscribe {
            items,
            rate_ms: rate_ms.unwrap_or(1000),
            for_secs,
            count,
            path: path.unwrap_or_default(),
        },
        Some(Sub::Demo { for_secs }) => Command::Demo { for_secs },
        Some(Sub::Servers) => Command::Servers,
        Some(Sub::Doctor {
            json,
            config,
            item,
            timeout_secs,
        }) => Command::Doctor(DoctorOptions {
            json,
            config,
            item,
            timeout_secs,
        }),
    };
    Ok(Parsed::Run(global, command))
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
        ErrorKind::InvalidSubcommand => {
            let name = context(ContextKind::InvalidSubcommand).unwrap_or(arg);
            return UsageError {
                message: format!("unknown command {name:?}"),
                help: USAGE,
            };
        }
        ErrorKind::UnknownArgument if !arg.starts_with('-') => match command {
            Some(c) => format!("{c} needs {}", needs(c)),
            None => {
                return UsageError {
                    message: format!("unknown command {arg:?}"),
                    help: USAGE,
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
                lcid: None
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
    }

    #[test]
    fn browse_options() {
        assert_eq!(
            run("browse").1,
            Command::Browse {
                flat: false,
                branch: None,
                depth: None
            }
        );
        assert_eq!(
            run("browse --flat --branch Magazyn --depth 2").1,
            Command::Browse {
                flat: true,
                branch: Some("Magazyn".into()),
                depth: Some(2)
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
        assert_eq!(parse(&args("--help")), Ok(Parsed::Help(USAGE)));
        assert_eq!(parse(&args("help")), Ok(Parsed::Help(USAGE)));
        assert_eq!(parse(&args("help write")), Ok(Parsed::Help(WRITE_HELP)));
        assert_eq!(
            parse(&args("subscribe --help")),
            Ok(Parsed::Help(SUBSCRIBE_HELP))
        );
        assert_eq!(parse(&args("read -h")), Ok(Parsed::Help(READ_HELP)));
        for c in COMMANDS {
            let text = help(Some(c));
            assert!(text.starts_with("usage: opcdiag"), "{c}");
            assert!(text.contains(c), "{c}");
            assert!(USAGE.contains(c), "{c} is in the general usage");
        }
    }

    #[test]
    fn mistakes_are_usage_errors_with_the_commands_help() {
        let e = parse(&args("")).unwrap_err();
        assert_eq!((e.message.as_str(), e.help), ("no command given", USAGE));
        let e = parse(&args("frobnicate")).unwrap_err();
        assert!(e.message.contains("unknown command"));
        let e = parse(&args("read A --flat")).unwrap_err();
        assert_eq!(
            (e.message.as_str(), e.help),
            ("read does not take --flat", READ_HELP)
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
    fn the_clap_definition_is_consistent_and_shows_the_help_texts() {
        let cli = Cli::command();
        cli.clone().debug_assert();
        assert_eq!(cli.clone().render_help().to_string(), USAGE);
        for c in COMMANDS {
            let mut sub = cli.find_subcommand(c).unwrap().clone();
            assert_eq!(sub.render_help().to_string(), help(Some(c)), "{c}");
        }
    }

    #[test]
    fn windows_help_negative_values_and_options_before_their_command() {
        assert_eq!(parse(&args("/?")), Ok(Parsed::Help(USAGE)));
        assert_eq!(parse(&args("write /?")), Ok(Parsed::Help(WRITE_HELP)));
        assert_eq!(parse(&args("help frobnicate")), Ok(Parsed::Help(USAGE)));
        assert_eq!(
            parse(&args("--server X.Y --help browse")),
            Ok(Parsed::Help(BROWSE_HELP))
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
            (e.message.as_str(), e.help),
            (
                "--flat is an option of browse: give it after browse",
                BROWSE_HELP
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
    fn servers_takes_no_arguments() {
        assert_eq!(
            parse(&args("servers")),
            Ok(Parsed::Run(
                Global {
                    server: DEFAULT_SERVER.into(),
                    lcid: None
                },
                Command::Servers
            ))
        );
        assert_eq!(parse(&args("servers -h")), Ok(Parsed::Help(SERVERS_HELP)));
        assert_eq!(parse(&args("help servers")), Ok(Parsed::Help(SERVERS_HELP)));
        assert!(parse(&args("servers x")).is_err());
    }
}
