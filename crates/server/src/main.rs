//! ServerCTOPC.exe: thin shell. Parse the switch, set up logging, then hand over to the
//! COM layer (`ctopc_com::host`).

mod cli;
mod logging;

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
        cli::Command::Embedding => return embedding(host::ServeMode::UntilUnused),
        cli::Command::Service => host::register_service(),
        cli::Command::ServiceRun => {
            return match ctopc_com::service::run(Box::new(|| {
                match embedding(host::ServeMode::UntilStopped) {
                    code if code == ExitCode::SUCCESS => Ok(()),
                    _ => Err("the server stopped with an error (see the log)".into()),
                }
            })) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("ServerCTOPC: {e}");
                    ExitCode::FAILURE
                }
            }
        }
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

/// `-Embedding` (and the service): configuration, then logging as configured, then serve.
#[cfg(windows)]
fn embedding(mode: ctopc_com::host::ServeMode) -> ExitCode {
    use ctopc_com::{context, host};
    let loaded = host::install_dir().and_then(|dir| context::load(&dir).map(|l| (dir, l)));
    let (dir, loaded) = match loaded {
        Ok(x) => x,
        Err(e) => {
            // No log directory is known yet: stderr, and the log folder of the install dir.
            eprintln!("ServerCTOPC: {e}");
            if let Ok(dir) = host::install_dir() {
                logging::emergency(&dir, &e);
            }
            return ExitCode::FAILURE;
        }
    };
    // A relative LogDirectory is relative to the configuration file's folder, as every
    // path in it (the same as the install folder, unless SERVERCTOPC_INI names the file).
    let config = loaded.namespace.config();
    let mut log_options = config.server.clone();
    log_options.log_directory = log_options
        .log_directory
        .as_deref()
        .map(|d| config.resolve_path(d).to_string_lossy().into_owned());
    let _guard = logging::init(&dir, &log_options);
    tracing::info!(version = env!("CARGO_PKG_VERSION"), "ServerCTOPC starting");
    match host::serve_as(loaded, Box::new(backend::make), mode) {
        Ok(()) => {
            tracing::info!("ServerCTOPC stopped");
            ExitCode::SUCCESS
        }
        Err(e) => {
            tracing::error!("ServerCTOPC failed: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(not(windows))]
fn run(_cmd: cli::Command) -> ExitCode {
    eprintln!("ServerCTOPC: this is a Windows COM server; build it with `cargo xtask build` and run it on Windows or under Wine");
    ExitCode::FAILURE
}
