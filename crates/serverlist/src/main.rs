//! OpcServerList.exe: `OPC.ServerList.1`, our own OPC server browser (OpcEnum-compatible),
//! a small exe of its own so that a client listing servers never starts (or keeps up) the
//! OPC server with its data source. Switches as Windows COM servers have them,
//! case-insensitive, `/` or `-`: `/RegServer`, `/UnregServer`, `-Embedding` (COM starts
//! it so), `/Service` (register as the NT service `OpcServerList`, for remote clients),
//! `-ServiceRun` (the service control manager starts it so). Everything else is in the
//! crate's library (`src/lib.rs`).

use std::process::ExitCode;

const USAGE: &str = "usage: OpcServerList.exe /RegServer | /Service | /UnregServer | -Embedding
  /RegServer    register OPC.ServerList.1 in both registry views, where no other server
                browser (the OPC Foundation's OpcEnum) is registered
  /Service      the same, as the NT service OpcServerList (on demand, LocalService):
                what remote OPC clients need
  /UnregServer  remove our registration and service (never another browser's)
  -Embedding    serve (COM starts the browser so)
  -ServiceRun   serve as the service (the service control manager starts it so)
";

#[derive(Debug, PartialEq, Eq)]
enum Command {
    RegServer,
    UnregServer,
    Service,
    Embedding,
    ServiceRun,
    Help,
}

fn parse(args: impl IntoIterator<Item = String>) -> Result<Command, String> {
    let args: Vec<String> = args.into_iter().collect();
    let Some(first) = args.first() else {
        return Ok(Command::Help);
    };
    let switch = first.trim_start_matches(['/', '-']).to_ascii_lowercase();
    let cmd = match switch.as_str() {
        "regserver" => Command::RegServer,
        "unregserver" => Command::UnregServer,
        "service" => Command::Service,
        "servicerun" => Command::ServiceRun,
        "embedding" | "automation" => Command::Embedding,
        "help" | "h" | "?" => Command::Help,
        _ => return Err(format!("unknown switch {first}")),
    };
    Ok(cmd)
}

fn main() -> ExitCode {
    match parse(std::env::args().skip(1)) {
        Ok(Command::Help) => {
            print!("{USAGE}");
            ExitCode::SUCCESS
        }
        Ok(cmd) => run(cmd),
        Err(e) => {
            eprintln!("OpcServerList: {e}\n\n{USAGE}");
            ExitCode::from(2)
        }
    }
}

#[cfg(windows)]
fn run(cmd: Command) -> ExitCode {
    use opc_server_list as server_list;
    let result = match cmd {
        Command::RegServer => server_list::register(),
        Command::UnregServer => server_list::unregister(),
        Command::Service => server_list::register_service(),
        Command::Embedding => server_list::serve(),
        Command::ServiceRun => server_list::serve_service(),
        Command::Help => Ok(()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("OpcServerList: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(not(windows))]
fn run(_cmd: Command) -> ExitCode {
    eprintln!("OpcServerList: a Windows program");
    ExitCode::FAILURE
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(args: &[&str]) -> Result<Command, String> {
        parse(args.iter().map(|s| s.to_string()))
    }

    #[test]
    fn switches_are_case_insensitive_with_either_prefix() {
        assert_eq!(p(&["/RegServer"]), Ok(Command::RegServer));
        assert_eq!(p(&["-regserver"]), Ok(Command::RegServer));
        assert_eq!(p(&["/UNREGSERVER"]), Ok(Command::UnregServer));
        assert_eq!(p(&["-Embedding"]), Ok(Command::Embedding));
        assert_eq!(p(&["/Service"]), Ok(Command::Service));
        assert_eq!(p(&["-ServiceRun"]), Ok(Command::ServiceRun));
        assert_eq!(p(&[]), Ok(Command::Help));
        assert!(p(&["/bogus"]).is_err());
    }
}
