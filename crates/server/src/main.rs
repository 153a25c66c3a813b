//! ServerCTOPC.exe: thin shell. Parse the switch, load the configuration (`config`), set
//! up logging, choose the data source (`backend`), then hand over to the COM layer
//! (`ctopc_com::host`) with the namespace and plain values, and the OPC UA front end
//! (`ua`) to start beside DA over the same runtime when the configuration enables it. On
//! Linux it serves OPC UA alone (`ua`: `serve`). `user add`, `pki trust` and
//! `/ProtectSecrets` (`protect`) on both.

mod cli;
// config and logging are plain Rust, tested natively; the Windows server uses both, the
// Linux OPC UA server the configuration lookup.
#[cfg_attr(not(windows), allow(dead_code))]
mod config;
#[cfg_attr(not(windows), allow(dead_code))]
mod logging;
mod protect;
mod ua;

use std::process::ExitCode;

fn main() -> ExitCode {
    // Private keys and the users file get a protected DACL on Windows (0600 on Unix).
    #[cfg(windows)]
    ctopc_runtime::secret_file::install(ctopc_com::com::secret_file::PLATFORM);
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
    if let cli::Command::ProtectSecrets { config } = &cmd {
        return protect_secrets(config.as_deref());
    }
    run(cmd)
}

/// `/ProtectSecrets [--config FILE]` (`protect`): the configuration (`FILE`, else as the
/// server finds it), then one line per path on standard output and, on Windows, in the
/// server's log too (the MSI runs it without a console). Exit code 0 when every path is
/// private or not there yet; 1 when one could not be made private or the configuration
/// cannot be read.
fn protect_secrets(file: Option<&str>) -> ExitCode {
    use std::path::{Path, PathBuf};
    let exe_dir = ua::exe_dir();
    let loaded = match file {
        Some(f) => {
            let path = std::path::absolute(f).unwrap_or_else(|_| PathBuf::from(f));
            asix_model::startup::load_file(Path::new(&path))
                .map(|l| (config::ConfigSource::File(path), l))
        }
        None => config::load(&exe_dir),
    };
    let (source, loaded) = match loaded {
        Ok(x) => x,
        Err(e) => {
            let line = format!("{} the configuration cannot be read: {e}", protect::PREFIX);
            eprintln!("ServerCTOPC: {line}");
            #[cfg(windows)]
            logging::emergency(&exe_dir, &line);
            return ExitCode::FAILURE;
        }
    };
    let config = loaded.namespace.config();
    // The server's log, as the server resolves its folder.
    #[cfg(windows)]
    let _guard = {
        let mut log_options = config.server.clone();
        log_options.log_directory = log_options
            .log_directory
            .as_deref()
            .map(|d| config.resolve_path(d).to_string_lossy().into_owned());
        logging::init(&exe_dir, &log_options)
    };
    let targets = protect::plan(config, &ua::config_dir(&source));
    let ok = protect::run(&targets, &source.log_line(), |line| {
        println!("{line}");
        if line.contains(": FAILED: ") {
            tracing::error!("{line}");
        } else {
            tracing::info!("{line}");
        }
    });
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

// The data source: plain Rust, tested natively.
mod backend;

#[cfg(windows)]
fn run(cmd: cli::Command) -> ExitCode {
    use ctopc_com::host;
    use ctopc_com::lifetime::StopSignal;
    let result = match cmd {
        cli::Command::RegServer { create_group } => host::register(create_group),
        cli::Command::UnregServer { keep_security } => host::unregister(keep_security),
        cli::Command::Embedding => {
            return embedding(
                host::ServeMode::UntilUnused,
                Ua::AsConfigured,
                &StopSignal::new(),
            )
        }
        cli::Command::Serve => {
            return embedding(
                host::ServeMode::UntilStopped,
                Ua::UnlessDisabled,
                &StopSignal::new(),
            )
        }
        cli::Command::Service { create_group } => host::register_service(create_group),
        cli::Command::ServiceRun => {
            return match ctopc_com::service::run(Box::new(|stop| {
                match embedding(host::ServeMode::UntilStopped, Ua::AsConfigured, &stop) {
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
        cli::Command::Help | cli::Command::ProtectSecrets { .. } => Ok(()),
        cli::Command::UserAdd {
            name,
            role,
            password_stdin,
        } => return ua::user_add(&name, &role, password_stdin),
        cli::Command::PkiTrust(file) => return ua::pki_trust(&file),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("ServerCTOPC: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Whether the Windows server serves OPC UA beside OPC DA.
#[cfg(windows)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ua {
    /// `-Embedding` and the service: when `[UA]` is in the configuration, unless
    /// `Enabled = nie` (or with `Enabled = tak`).
    AsConfigured,
    /// `/Serve`: unless `[UA] Enabled = nie`.
    UnlessDisabled,
}

/// `-Embedding`, the service and `/Serve`: configuration, then logging as configured, then
/// serve (OPC UA beside DA as `ua` says) until the server is unused (`-Embedding`: by DA
/// clients) or `stop` is triggered (the service's stop, or Ctrl+C / a system shutdown on
/// the console, in every mode).
#[cfg(windows)]
fn embedding(
    mode: ctopc_com::host::ServeMode,
    ua: Ua,
    stop: &ctopc_com::lifetime::StopSignal,
) -> ExitCode {
    use ctopc_com::host;
    use std::sync::Arc;
    // Start-up phases are logged as `start: ...` lines with their times (read by
    // `cargo xtask bench --scale`); the configuration is read before logging exists.
    let started = std::time::Instant::now();
    let loaded = host::install_dir().and_then(|dir| config::load(&dir).map(|l| (dir, l)));
    let config_ms = started.elapsed().as_millis();
    let (dir, (source, loaded)) = match loaded {
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
    tracing::info!("{}", source.log_line());
    let variables: usize = loaded
        .namespace
        .databases()
        .map(|db| db.variables.len())
        .sum();
    tracing::info!("start: configuration read in {config_ms} ms ({variables} variables)");
    for w in &loaded.warnings {
        tracing::warn!("{w}");
    }
    let ns = Arc::new(loaded.namespace);
    let ua_options = &ns.config().ua;
    let serve_ua = match ua {
        Ua::AsConfigured => ua_options.beside_da(),
        Ua::UnlessDisabled => ua_options.enabled != Some(false),
    };
    let beside: Option<Box<host::StartBeside>> = if serve_ua {
        let settings = ua::settings(&ns, &ua::config_dir(&source));
        if mode == host::ServeMode::UntilUnused {
            tracing::info!(
                "OPC UA beside OPC DA: started by COM, this process ends when its last DA client has gone, whatever OPC UA sessions it has (a lasting OPC UA server: the service or /Serve)"
            );
        }
        Some(Box::new(move |beside| ua::start_beside(&settings, beside)))
    } else {
        tracing::info!("OPC UA: off (no [UA] section, or Enabled = nie)");
        None
    };
    let setup = setup(&ns);
    tracing::info!(
        "start: browse tree built at {} ms",
        started.elapsed().as_millis()
    );
    let make_backend =
        Box::new(move |wake: Arc<dyn ctopc_core::source::Wake>| backend::make(&ns, wake));
    host::stop_on_console_ctrl(stop);
    match host::serve_as(setup, make_backend, mode, stop, beside) {
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

/// What the COM host needs of the asix namespace, as plain values and the core's
/// `Namespace` trait.
#[cfg(windows)]
fn setup(ns: &std::sync::Arc<asix_model::AsixNamespace>) -> ctopc_com::context::Setup {
    use ctopc_core::browse::AddressSpace;
    use std::sync::Arc;
    let address_space = match asix_model::address_space::build_address_space(ns) {
        Ok(a) => a,
        Err(e) => {
            tracing::error!("cannot build the browse tree: {e:?}; browsing shows an empty tree");
            AddressSpace::empty()
        }
    };
    let server = &ns.config().server;
    ctopc_com::context::Setup {
        namespace: Arc::clone(ns) as Arc<dyn ctopc_core::namespace::Namespace>,
        address_space: Arc::new(address_space),
        engine_config: server.engine_config(),
        default_language: server.default_language.fixed(),
        no_config_reason: ns.no_config_reason(),
        ops: ns.config().ops_config(),
        legacy_open_access: server.legacy_open_access,
    }
}

/// On Linux: the OPC UA commands; the COM switches need Windows.
#[cfg(not(windows))]
fn run(cmd: cli::Command) -> ExitCode {
    match cmd {
        cli::Command::Serve => ua::serve(),
        cli::Command::UserAdd {
            name,
            role,
            password_stdin,
        } => ua::user_add(&name, &role, password_stdin),
        cli::Command::PkiTrust(file) => ua::pki_trust(&file),
        _ => {
            eprintln!("ServerCTOPC: the COM switches need Windows; build it with `cargo xtask build` and run it on Windows or under Wine (on Linux: `serve` serves OPC UA)");
            ExitCode::FAILURE
        }
    }
}
