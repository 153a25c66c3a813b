//! Command-line parsing of ServerCTOPC.exe (pure, tested natively).
//!
//! Switches are case-insensitive and may start with `/` or `-`, as COM and
//! installers pass them (`-Embedding`, `/RegServer`, `-regserver`, ...).

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// Write the registry keys (CLSID, ProgID, AppID, categories, legacy OPC key).
    RegServer,
    /// Remove them.
    UnregServer,
    /// Started by COM to serve clients.
    Embedding,
    /// Register as an NT service (on demand, LocalService), with AppID LocalService.
    Service,
    /// Started by the service control manager.
    ServiceRun,
    /// Print usage and exit 0.
    Help,
}

pub const USAGE: &str = "\
ServerCTOPC - OPC DA 2.05a/3.0 server for asix (ProgID ServerCTOPC.App)

usage: ServerCTOPC.exe <switch>
  /RegServer     register the server (CLSID, ProgID, AppID, OPC DA 2.0/3.0 categories)
  /UnregServer   remove the registration
  /Service       register as the NT service ServerCTOPC (on demand, as LocalService;
                 COM starts it when a client connects); /UnregServer removes it
  -Embedding     (used by COM) serve OPC clients; the server exits when the last
                 client has gone
  -ServiceRun    (used by the service control manager) run as the NT service
  /?             this text
Switches are case-insensitive and may start with / or -.
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
    let Some(name) = first.strip_prefix('/').or_else(|| first.strip_prefix('-')) else {
        return Err(format!("unknown argument `{first}`"));
    };
    let cmd = match name.to_ascii_lowercase().as_str() {
        "regserver" => Command::RegServer,
        "unregserver" => Command::UnregServer,
        "embedding" | "automation" => Command::Embedding,
        "service" => Command::Service,
        "servicerun" => Command::ServiceRun,
        "?" | "h" | "help" => Command::Help,
        _ => return Err(format!("unknown switch `{first}`")),
    };
    // COM passes nothing else with -Embedding; registration takes no extra arguments.
    if let Some(extra) = args.get(1) {
        return Err(format!("unexpected argument `{extra}` after `{first}`"));
    }
    Ok(cmd)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn switches_accept_slash_or_dash_in_any_case() {
        for (arg, cmd) in [
            ("/RegServer", Command::RegServer),
            ("-regserver", Command::RegServer),
            ("/REGSERVER", Command::RegServer),
            ("-UnregServer", Command::UnregServer),
            ("/unregserver", Command::UnregServer),
            ("-Embedding", Command::Embedding),
            ("/embedding", Command::Embedding),
            ("/?", Command::Help),
            ("/Service", Command::Service),
            ("-service", Command::Service),
            ("-ServiceRun", Command::ServiceRun),
        ] {
            assert_eq!(parse([arg]), Ok(cmd), "{arg}");
        }
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
