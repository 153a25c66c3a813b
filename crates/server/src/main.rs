//! ServerCTOPC.exe: thin shell. Parse the switch, set up logging, then hand over to the
//! COM layer (`ctopc_com::host`).

mod cli;

use std::process::ExitCode;

fn main() -> ExitCode {
    let cmd = match cli::parse(std::env::args().skip(1)) {
        Ok(cmd) => cmd,
        Err(msg) => {
            eprintln!("ServerCTOPC: {msg}\n\n{}", cli::USAGE);
            return ExitCode::from(2);
        }
    };
    if cmd == cli::Command::Help {
        print!("{}", cli::USAGE);
        return ExitCode::SUCCESS;
    }
    run(cmd)
}

#[cfg(windows)]
mod backend;

#[cfg(windows)]
fn run(cmd: cli::Command) -> ExitCode {
    use ctopc_com::host;
    let result = match cmd {
        cli::Command::RegServer => host::register(),
        cli::Command::UnregServer => host::unregister(),
        cli::Command::Embedding => host::serve(Box::new(backend::make)),
        cli::Command::Help => Ok(()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("ServerCTOPC: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(not(windows))]
fn run(_cmd: cli::Command) -> ExitCode {
    eprintln!("ServerCTOPC: this is a Windows COM server; build it with `cargo xtask build` and run it on Windows or under Wine");
    ExitCode::FAILURE
}
