//! Command-line parsing of ServerCTOPC.exe (pure, tested natively).
//!
//! Switches are case-insensitive and may start with `/` or `-`, as COM and
//! installers pass them (`-Embedding`, `/RegServer`, `-regserver`, ...).

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// Write the registry keys (CLSID, ProgID, AppID, categories, legacy OPC key);
    /// `create_group` (`/CreateGroup`): create the local group `ServerCTOPC Clients` first.
    RegServer { create_group: bool },
    /// Remove them; `keep_security` (`/KeepSecurity`): keep the AppID's security values.
    UnregServer { keep_security: bool },
    /// Started by COM to serve clients.
    Embedding,
    /// Register as an NT service (on demand, LocalService), with AppID LocalService;
    /// `create_group` as for `RegServer`.
    Service { create_group: bool },
    /// Started by the service control manager.
    ServiceRun,
    /// Serve in the foreground until Ctrl+C (`serve`, `/Serve`): on Windows OPC DA and
    /// OPC UA, on Linux OPC UA.
    Serve,
    /// Add (or replace) an OPC UA user in the users file.
    UserAdd {
        name: String,
        role: String,
        /// Read the password from standard input instead of prompting.
        password_stdin: bool,
    },
    /// Trust a client certificate: copy it to the PKI folder's `trusted/`.
    PkiTrust(String),
    /// Make the files of secrets the configuration names private, and prepare their
    /// folders (`/ProtectSecrets [--config FILE]`, what the MSI runs): `config` names the
    /// configuration instead of the usual lookup.
    ProtectSecrets { config: Option<String> },
    /// Print usage and exit 0.
    Help,
}

pub const USAGE: &str = "\
ServerCTOPC - OPC DA 2.05a/3.0 server for asix (ProgID ServerCTOPC.App)

usage: ServerCTOPC.exe <switch>
  /RegServer     register the server (CLSID, ProgID, AppID, OPC DA 2.0/3.0 categories;
                 the AppID's AccessPermission, LaunchPermission and AuthenticationLevel
                 where absent)
  /UnregServer   remove the registration
  /Service       register as the NT service ServerCTOPC (on demand, as LocalService;
                 COM starts it when a client connects); /UnregServer removes it
  /RegServer /CreateGroup, /Service /CreateGroup
                 also create the local group \"ServerCTOPC Clients\" (the MSI does)
  /UnregServer /KeepSecurity
                 keep the AppID's security values (the MSI's major upgrade does)
  /ProtectSecrets [--config FILE]
                 make the files of secrets private (readable only by SYSTEM,
                 Administrators, LOCAL SERVICE and the account running this): the OPC UA
                 certificate store pki\\ (made when missing, with what is in it), its
                 private key, the users file, each channel's AsixNetKeyFile, and the
                 folder of such a file when it is one of its own below the
                 configuration's (made when missing: files made there later inherit
                 nothing wider); a file not there yet is no error. One line per path,
                 also in the log; the MSI runs it at install and upgrade. The
                 configuration: FILE, else as the server finds it
  -Embedding     (used by COM) serve OPC clients; the server exits when the last
                 client has gone
  -ServiceRun    (used by the service control manager) run as the NT service
  /Serve         serve OPC DA and OPC UA in the foreground until Ctrl+C
  /?             this text
Switches are case-insensitive and may start with / or -.

OPC UA (the configuration: SERVERCTOPC_INI, else ASIXConnect.ini next to the program,
else the embedded demo plant; pki/ and ua-users.txt beside it by default). On Windows
the server serves OPC UA beside OPC DA, from the same engine, when the configuration has
a [UA] section (unless Enabled = nie), and with /Serve unless Enabled = nie; on Linux:
  serve                                   serve OPC UA ([UA] section) until Ctrl+C
  user add NAME --role reader|writer [--password-stdin]
                                          add or replace a user of the users file; the
                                          password is asked twice on the terminal
                                          (no echo), or read from the first line of
                                          standard input (--password-stdin)
  pki trust FILE                          trust a client certificate (DER): copy it to
                                          pki/trusted/ (from pki/rejected/, for example)
";

/// Parses the arguments after the program name. `Err` carries the message for the user.
pub fn parse<I, S>(args: I) -> Result<Command, String>
where
    I: IntoIterator<Item = S>,
    S: AsRef<str>,
{
    let args: Vec<String> = args.into_iter().map(|s| s.as_ref().to_string()).collect();
    let Some(first) = args.first() else {
        return Err("no switch given".into());
    };
    match first.as_str() {
        "serve" => {
            return match args.get(1) {
                Some(extra) => Err(format!("unexpected argument `{extra}` after `serve`")),
                None => Ok(Command::Serve),
            }
        }
        "user" => return parse_user(&args[1..]),
        "pki" => {
            return match &args[1..] {
                [t, file] if t == "trust" => Ok(Command::PkiTrust(file.clone())),
                _ => Err("usage: pki trust FILE".into()),
            }
        }
        _ => {}
    }
    let Some(name) = first.strip_prefix('/').or_else(|| first.strip_prefix('-')) else {
        return Err(format!("unknown argument `{first}`"));
    };
    let option = |wanted: &str| -> Result<bool, String> {
        match args.get(1) {
            None => Ok(false),
            Some(a)
                if a.strip_prefix('/')
                    .or_else(|| a.strip_prefix('-'))
                    .is_some_and(|o| o.eq_ignore_ascii_case(wanted))
                    && args.len() == 2 =>
            {
                Ok(true)
            }
            Some(extra) => Err(format!("unexpected argument `{extra}` after `{first}`")),
        }
    };
    let cmd = match name.to_ascii_lowercase().as_str() {
        "regserver" => Command::RegServer {
            create_group: option("CreateGroup")?,
        },
        "unregserver" => Command::UnregServer {
            keep_security: option("KeepSecurity")?,
        },
        "service" => Command::Service {
            create_group: option("CreateGroup")?,
        },
        "embedding" | "automation" => Command::Embedding,
        "servicerun" => Command::ServiceRun,
        "serve" => Command::Serve,
        "?" | "h" | "help" => Command::Help,
        "protectsecrets" => return parse_protect(&args[1..]),
        _ => return Err(format!("unknown switch `{first}`")),
    };
    // COM passes nothing else with -Embedding; registration takes only its option.
    if let Some(extra) = args.get(1).filter(|_| {
        !matches!(
            cmd,
            Command::RegServer { .. } | Command::UnregServer { .. } | Command::Service { .. }
        )
    }) {
        return Err(format!("unexpected argument `{extra}` after `{first}`"));
    }
    Ok(cmd)
}

const PROTECT_USAGE: &str = "usage: /ProtectSecrets [--config FILE]";

/// The options after `/ProtectSecrets`: none, or `--config FILE` (`/Config`, `-config`
/// too, in any case).
fn parse_protect(args: &[String]) -> Result<Command, String> {
    match args {
        [] => Ok(Command::ProtectSecrets { config: None }),
        [option, file]
            if option
                .trim_start_matches(['/', '-'])
                .eq_ignore_ascii_case("config")
                && option.len() > "config".len()
                && !file.is_empty() =>
        {
            Ok(Command::ProtectSecrets {
                config: Some(file.clone()),
            })
        }
        _ => Err(PROTECT_USAGE.into()),
    }
}

const USER_USAGE: &str = "usage: user add NAME --role reader|writer [--password-stdin]";

fn parse_user(args: &[String]) -> Result<Command, String> {
    let [add, name, rest @ ..] = args else {
        return Err(USER_USAGE.into());
    };
    if add != "add" || name.starts_with('-') {
        return Err(USER_USAGE.into());
    }
    let mut role = None;
    let mut password_stdin = false;
    let mut it = rest.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--role" => match it.next().map(String::as_str) {
                Some(r @ ("reader" | "writer")) => role = Some(r.to_owned()),
                _ => return Err("--role takes reader or writer".into()),
            },
            "--password-stdin" => password_stdin = true,
            other => return Err(format!("unexpected argument `{other}`; {USER_USAGE}")),
        }
    }
    let role = role.ok_or_else(|| format!("--role is required; {USER_USAGE}"))?;
    Ok(Command::UserAdd {
        name: name.clone(),
        role,
        password_stdin,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn switches_accept_slash_or_dash_in_any_case() {
        for (arg, cmd) in [
            (
                "/RegServer",
                Command::RegServer {
                    create_group: false,
                },
            ),
            (
                "-regserver",
                Command::RegServer {
                    create_group: false,
                },
            ),
            (
                "/REGSERVER",
                Command::RegServer {
                    create_group: false,
                },
            ),
            (
                "-UnregServer",
                Command::UnregServer {
                    keep_security: false,
                },
            ),
            (
                "/unregserver",
                Command::UnregServer {
                    keep_security: false,
                },
            ),
            ("-Embedding", Command::Embedding),
            ("/embedding", Command::Embedding),
            ("/?", Command::Help),
            (
                "/Service",
                Command::Service {
                    create_group: false,
                },
            ),
            (
                "-service",
                Command::Service {
                    create_group: false,
                },
            ),
            ("-ServiceRun", Command::ServiceRun),
        ] {
            assert_eq!(parse([arg]), Ok(cmd), "{arg}");
        }
    }

    #[test]
    fn the_ua_commands() {
        assert_eq!(parse(["serve"]), Ok(Command::Serve));
        assert_eq!(parse(["/Serve"]), Ok(Command::Serve));
        assert!(parse(["serve", "now"]).is_err());
        assert_eq!(
            parse([
                "user",
                "add",
                "anna",
                "--role",
                "writer",
                "--password-stdin"
            ]),
            Ok(Command::UserAdd {
                name: "anna".into(),
                role: "writer".into(),
                password_stdin: true
            })
        );
        assert_eq!(
            parse(["user", "add", "bob", "--role", "reader"]),
            Ok(Command::UserAdd {
                name: "bob".into(),
                role: "reader".into(),
                password_stdin: false
            })
        );
        for bad in [
            &["user", "add", "anna"][..],
            &["user", "add", "anna", "--role", "admin"],
            &["user", "del", "anna", "--role", "reader"],
            &["user", "add", "--role", "reader"],
            &["user"],
        ] {
            assert!(parse(bad).is_err(), "{bad:?}");
        }
        assert_eq!(
            parse(["pki", "trust", "client.der"]),
            Ok(Command::PkiTrust("client.der".into()))
        );
        assert!(parse(["pki", "trust"]).is_err());
    }

    #[test]
    fn registration_takes_its_one_option() {
        assert_eq!(
            parse(["/RegServer", "/CreateGroup"]),
            Ok(Command::RegServer { create_group: true })
        );
        assert_eq!(
            parse(["-service", "-creategroup"]),
            Ok(Command::Service { create_group: true })
        );
        assert_eq!(
            parse(["/UnregServer", "/KeepSecurity"]),
            Ok(Command::UnregServer {
                keep_security: true
            })
        );
        for bad in [
            &["/RegServer", "/KeepSecurity"][..],
            &["/UnregServer", "/CreateGroup"],
            &["/RegServer", "/CreateGroup", "x"],
            &["/RegServer", "CreateGroup"],
            &["-Embedding", "/CreateGroup"],
        ] {
            assert!(parse(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn protect_secrets_takes_an_optional_configuration() {
        assert_eq!(
            parse(["/ProtectSecrets"]),
            Ok(Command::ProtectSecrets { config: None })
        );
        assert_eq!(
            parse(["-protectsecrets"]),
            Ok(Command::ProtectSecrets { config: None })
        );
        for option in ["--config", "/Config", "-CONFIG"] {
            assert_eq!(
                parse(["/ProtectSecrets", option, "D:\\plant\\ASIXConnect.ini"]),
                Ok(Command::ProtectSecrets {
                    config: Some("D:\\plant\\ASIXConnect.ini".into())
                }),
                "{option}"
            );
        }
        for bad in [
            &["/ProtectSecrets", "--config"][..],
            &["/ProtectSecrets", "--config", ""],
            &["/ProtectSecrets", "config", "a.ini"],
            &["/ProtectSecrets", "--conf", "a.ini"],
            &["/ProtectSecrets", "--config", "a.ini", "b"],
            &["/ProtectSecrets", "/CreateGroup"],
        ] {
            assert_eq!(
                parse(bad),
                Err("usage: /ProtectSecrets [--config FILE]".into()),
                "{bad:?}"
            );
        }
        assert!(USAGE.contains("/ProtectSecrets [--config FILE]"));
    }

    #[test]
    fn no_or_unknown_arguments_are_errors() {
        assert!(parse(Vec::<String>::new()).is_err());
        assert_eq!(
            parse(["/Frobnicate"]),
            Err("unknown switch `/Frobnicate`".into())
        );
        assert_eq!(
            parse(["RegServer"]),
            Err("unknown argument `RegServer`".into())
        );
        assert!(parse(["/RegServer", "extra"]).is_err());
    }
}
