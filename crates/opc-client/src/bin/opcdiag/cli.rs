//! The command line of opcdiag: parsing and help texts (pure, tested natively).
// Natively only the tests use what the Windows commands show.
#![cfg_attr(not(windows), allow(dead_code))]

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
  subscribe ITEMID... [--rate MS] [--for SECONDS] [--path ACCESSPATH]
                            print every change the server reports, until Ctrl+C
  demo [--for SECONDS]      ServerCTOPC's demo plant: status, plant tree, live values
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
                                                    [--path ACCESSPATH]

Adds the items to an active group with an IOPCDataCallback sink and prints each change
as it arrives: time (local), item, value, quality. Runs until Ctrl+C or, with --for,
until SECONDS have passed.
  --rate MS           the group's update rate (default 1000)
  --for SECONDS       stop after SECONDS (may have decimals)
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
        path: String,
    },
    Demo {
        for_secs: Option<f64>,
    },
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
];

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

/// Parses the arguments after the program name.
pub fn parse(args: &[String]) -> Result<Parsed, UsageError> {
    let mut global = Global {
        server: DEFAULT_SERVER.to_string(),
        lcid: None,
    };
    let mut command: Option<&str> = None;
    let mut positional: Vec<String> = Vec::new();
    let mut flat = false;
    let mut device = false;
    let mut branch = None;
    let mut depth = None;
    let mut path = String::new();
    let mut vt = None;
    let mut rate_ms = 1000u32;
    let mut for_secs = None;
    let mut want_help = false;
    // Options given, to reject those the command does not take.
    let mut seen: Vec<&'static str> = Vec::new();

    let err = |command: Option<&str>, message: String| UsageError {
        message,
        help: help(command),
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = |name: &str| {
            it.next()
                .cloned()
                .ok_or_else(|| err(command, format!("{name} needs a value")))
        };
        match a.as_str() {
            "-h" | "--help" | "/?" => want_help = true,
            "--server" => {
                global.server = value("--server")?;
                if global.server.trim().is_empty() {
                    return Err(err(command, "--server needs a ProgID".into()));
                }
            }
            "--host" | "--node" => {
                return Err(err(
                    command,
                    format!(
                    "{a}: remote servers are not supported; run opcdiag on the server's computer"
                ),
                ))
            }
            "--lang" => {
                let v = value("--lang")?;
                global.lcid = Some(parse_lcid(&v).ok_or_else(|| {
                    err(
                        command,
                        format!("--lang: unknown language {v:?} (en, pl or an LCID)"),
                    )
                })?);
            }
            "--flat" => {
                flat = true;
                seen.push("--flat");
            }
            "--device" => {
                device = true;
                seen.push("--device");
            }
            "--branch" => {
                branch = Some(value("--branch")?);
                seen.push("--branch");
            }
            "--depth" => {
                let v = value("--depth")?;
                depth = Some(v.parse::<usize>().ok().filter(|d| *d > 0).ok_or_else(|| {
                    err(
                        command,
                        format!("--depth: expected a number > 0, got {v:?}"),
                    )
                })?);
                seen.push("--depth");
            }
            "--path" => {
                path = value("--path")?;
                seen.push("--path");
            }
            "--type" => {
                let v = value("--type")?;
                vt = Some(
                    parse_vartype(&v)
                        .ok_or_else(|| err(command, format!("--type: unknown data type {v:?}")))?,
                );
                seen.push("--type");
            }
            "--rate" => {
                let v = value("--rate")?;
                rate_ms = v.parse::<u32>().map_err(|_| {
                    err(command, format!("--rate: expected milliseconds, got {v:?}"))
                })?;
                seen.push("--rate");
            }
            "--for" => {
                let v = value("--for")?;
                for_secs = Some(parse_secs(&v).ok_or_else(|| {
                    err(command, format!("--for: expected seconds > 0, got {v:?}"))
                })?);
                seen.push("--for");
            }
            s if s.starts_with("--") => return Err(err(command, format!("unknown option {s}"))),
            s if command.is_none() => {
                if s == "help" {
                    command = Some("help");
                } else if let Some(c) = COMMANDS.iter().find(|c| **c == s) {
                    command = Some(c);
                } else {
                    return Err(err(None, format!("unknown command {s:?}")));
                }
            }
            s => positional.push(s.to_string()),
        }
    }

    let Some(cmd) = command else {
        if want_help {
            return Ok(Parsed::Help(USAGE));
        }
        return Err(err(None, "no command given".into()));
    };
    if cmd == "help" {
        return Ok(Parsed::Help(help(positional.first().map(String::as_str))));
    }
    if want_help {
        return Ok(Parsed::Help(help(Some(cmd))));
    }
    let allowed: &[&str] = match cmd {
        "browse" => &["--flat", "--branch", "--depth"],
        "read" => &["--device", "--path"],
        "write" => &["--type", "--path"],
        "subscribe" => &["--rate", "--for", "--path"],
        "demo" => &["--for"],
        _ => &[],
    };
    if let Some(bad) = seen.iter().find(|o| !allowed.contains(o)) {
        return Err(err(Some(cmd), format!("{cmd} does not take {bad}")));
    }
    let arity = |min: usize, max: Option<usize>, what: &str| -> Result<(), UsageError> {
        let n = positional.len();
        if n < min || max.is_some_and(|m| n > m) {
            Err(err(Some(cmd), format!("{cmd} needs {what}")))
        } else {
            Ok(())
        }
    };
    let command = match cmd {
        "status" => {
            arity(0, Some(0), "no arguments")?;
            Command::Status
        }
        "browse" => {
            arity(0, Some(0), "no arguments besides its options")?;
            Command::Browse {
                flat,
                branch,
                depth,
            }
        }
        "props" => {
            arity(1, Some(1), "one ITEMID")?;
            Command::Props {
                item: positional.remove(0),
            }
        }
        "read" => {
            arity(1, None, "at least one ITEMID")?;
            Command::Read {
                items: positional,
                device,
                path,
            }
        }
        "write" => {
            arity(2, Some(2), "ITEMID and VALUE")?;
            let value = positional.remove(1);
            Command::Write {
                item: positional.remove(0),
                value,
                vt,
                path,
            }
        }
        "subscribe" => {
            arity(1, None, "at least one ITEMID")?;
            Command::Subscribe {
                items: positional,
                rate_ms,
                for_secs,
                path,
            }
        }
        "demo" => {
            arity(0, Some(0), "no arguments besides --for")?;
            Command::Demo { for_secs }
        }
        _ => return Err(err(None, format!("unknown command {cmd:?}"))),
    };
    Ok(Parsed::Run(global, command))
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
                path: String::new()
            }
        );
        assert_eq!(
            run("subscribe A").1,
            Command::Subscribe {
                items: vec!["A".into()],
                rate_ms: 1000,
                for_secs: None,
                path: String::new()
            }
        );
        assert!(usage_error("subscribe A --for 0").contains("seconds > 0"));
        assert!(usage_error("subscribe A --for x").contains("seconds > 0"));
        assert!(usage_error("subscribe A --rate fast").contains("milliseconds"));
        assert!(usage_error("subscribe").contains("at least one ITEMID"));
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
}
