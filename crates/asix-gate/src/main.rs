//! `asix-gate`: serves the asix channels of `asix-gate.ini` to ServerCTOPC over the asix
//! network protocol (`docs/asix-gate.md`).

use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    // Private keys get a protected DACL on Windows (0600 on Unix without it).
    #[cfg(windows)]
    ctopc_runtime::secret_file::install(ctopc_com::com::secret_file::PLATFORM);
    asix_gate_main::run(std::env::args().skip(1).collect())
}

mod asix_gate_main {
    use super::*;
    use asix_gate::channel::ChannelFactory;
    use asix_gate::config;
    use asix_net::secure::ServerSecurity;
    use asix_net::tls;
    use ctopc_core::lang::Lang;
    #[cfg(not(windows))]
    use ctopc_core::OpcError;

    const USAGE: &str = "\
usage: asix-gate [--config FILE] [--check]
       asix-gate --gen-cert DIR [--name NAME]
       asix-gate /Service [--config FILE]
       asix-gate /UnregServer
  --config FILE   the configuration (default: asix-gate.ini beside the program)
  --check         read the configuration, report, exit
  --gen-cert DIR  write DIR/asix-gate-cert.pem and DIR/asix-gate-key.pem, print the
                  fingerprint (paste it as AsixNetServerFingerprint into ServerCTOPC's channel)
  /Service        install (or update) the NT service AsixGate: automatic start, LocalService,
                  serving FILE (its absolute path) or asix-gate.ini beside the program
  /UnregServer    stop and remove the NT service
";

    /// What the command line asks for.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum Mode {
        Console,
        Install,
        Uninstall,
        /// Started by the service control manager (`-ServiceRun`).
        Service,
    }

    fn default_config() -> PathBuf {
        std::env::current_exe()
            .ok()
            .and_then(|p| p.parent().map(|d| d.join("asix-gate.ini")))
            .unwrap_or_else(|| PathBuf::from("asix-gate.ini"))
    }

    fn gen_cert(dir: &str, name: &str) -> Result<String, String> {
        let g = tls::generate(name, None).map_err(|e| e.to_string())?;
        let dir = std::path::Path::new(dir);
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let cert = dir.join("asix-gate-cert.pem");
        let key = dir.join("asix-gate-key.pem");
        std::fs::write(&cert, &g.cert_pem).map_err(|e| format!("{}: {e}", cert.display()))?;
        ctopc_runtime::secret_file::write(&key, g.key_pem.as_bytes())
            .map_err(|e| format!("{}: {e}", key.display()))?;
        Ok(format!(
            "certificate {}\nprivate key {} (keep it secret)\nfingerprint {}",
            cert.display(),
            key.display(),
            tls::fingerprint_hex(&g.identity.fingerprint())
        ))
    }

    /// Each channel's `XConnect.ServerCT`, late-bound (`asix_gate::xconnect`).
    #[cfg(windows)]
    fn factory() -> ChannelFactory {
        asix_gate::xconnect::factory()
    }

    /// No Automation outside Windows: every channel reports it (and the gate announces
    /// SOURCE_FAILED) instead of serving.
    #[cfg(not(windows))]
    fn factory() -> ChannelFactory {
        std::sync::Arc::new(|name: &str| {
            Err(asix_gate::CallError::new(
                OpcError::NotImpl,
                format!("channel {name}: XConnect.ServerCT exists only on Windows"),
            ))
        })
    }

    /// The console and the daily files `asix-gate.<YYYY-MM-DD>.log` in `dir` (30 kept),
    /// written on a background thread; `ASIX_GATE_LOG` sets the filter (default info).
    fn logging(dir: &std::path::Path) -> Option<tracing_appender::non_blocking::WorkerGuard> {
        use tracing_subscriber::layer::SubscriberExt;
        use tracing_subscriber::util::SubscriberInitExt;
        use tracing_subscriber::Layer;
        let filter = || {
            tracing_subscriber::EnvFilter::try_from_env("ASIX_GATE_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"))
        };
        let _ = std::fs::create_dir_all(dir);
        let files = tracing_appender::rolling::Builder::new()
            .rotation(tracing_appender::rolling::Rotation::DAILY)
            .filename_prefix("asix-gate")
            .filename_suffix("log")
            .max_log_files(30)
            .build(dir);
        let console = tracing_subscriber::fmt::layer().with_filter(filter());
        match files {
            Ok(f) => {
                let (writer, guard) = tracing_appender::non_blocking(f);
                let file = tracing_subscriber::fmt::layer()
                    .with_writer(writer)
                    .with_ansi(false)
                    .with_thread_names(true)
                    .with_filter(filter());
                tracing_subscriber::registry()
                    .with(console)
                    .with(file)
                    .init();
                Some(guard)
            }
            Err(e) => {
                tracing_subscriber::registry().with(console).init();
                tracing::warn!(dir = %dir.display(), error = %e, "no log files: the console only");
                None
            }
        }
    }

    pub fn run(args: Vec<String>) -> ExitCode {
        let mut path = None;
        let mut check = false;
        let mut gen = None;
        let mut mode = Mode::Console;
        let mut name = "ASIX-GATE".to_owned();
        let mut it = args.into_iter();
        while let Some(a) = it.next() {
            // The service switches as the server's: `/` or `-`, any case.
            match a.to_ascii_lowercase().as_str() {
                "/service" | "-service" => {
                    mode = Mode::Install;
                    continue;
                }
                "/unregserver" | "-unregserver" => {
                    mode = Mode::Uninstall;
                    continue;
                }
                "-servicerun" => {
                    mode = Mode::Service;
                    continue;
                }
                _ => {}
            }
            match a.as_str() {
                "--config" => path = it.next().map(PathBuf::from),
                "--check" => check = true,
                "--gen-cert" => gen = it.next(),
                "--name" => name = it.next().unwrap_or(name),
                "-h" | "--help" | "/?" => {
                    print!("{USAGE}");
                    return ExitCode::SUCCESS;
                }
                other => {
                    eprintln!("asix-gate: unknown option {other}\n\n{USAGE}");
                    return ExitCode::from(2);
                }
            }
        }
        if let Some(dir) = gen {
            return match gen_cert(&dir, &name) {
                Ok(t) => {
                    println!("{t}");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("asix-gate: --gen-cert: {e}");
                    ExitCode::FAILURE
                }
            };
        }
        match mode {
            Mode::Install => return install(path),
            Mode::Uninstall => return uninstall(),
            Mode::Console | Mode::Service => {}
        }
        let path = path.unwrap_or_else(default_config);
        let cfg = match config::load(&path) {
            Ok(c) => c,
            Err(e) => {
                // The language is in the file that could not be read: both.
                eprintln!("asix-gate: {}", e.text(Lang::Polish));
                eprintln!("asix-gate: {}", e.text(Lang::English));
                return ExitCode::from(2);
            }
        };
        let _log_guard = if check { None } else { logging(&cfg.log_dir) };
        let security = match asix_gate::security(&cfg, None) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("asix-gate: {}: {e}", path.display());
                return ExitCode::from(2);
            }
        };
        if check {
            let ok = match cfg.language {
                Lang::Polish => "konfiguracja poprawna",
                Lang::English => "configuration valid",
            };
            println!(
                "asix-gate: {}: {ok}; {} channel(s); fingerprint {}",
                path.display(),
                cfg.channels.len(),
                security
                    .fingerprint()
                    .map(|f| tls::fingerprint_hex(&f))
                    .unwrap_or_default()
            );
            return ExitCode::SUCCESS;
        }
        if mode == Mode::Service {
            return service(cfg, security);
        }
        // `quit` on stdin stops the gate (Ctrl+C ends the process).
        let (tx, rx) = tokio::sync::oneshot::channel::<()>();
        std::thread::spawn(move || {
            use std::io::BufRead;
            // Without a console (stdin at its end) the gate runs until killed.
            for line in std::io::stdin().lock().lines() {
                if line.is_ok_and(|l| l.trim() == "quit") {
                    let _ = tx.send(());
                    return;
                }
            }
            std::mem::forget(tx);
        });
        match serve(cfg, security, async move {
            let _ = rx.await;
        }) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                // In the log too: a gate started without a console shows only that.
                tracing::error!("asix-gate cannot serve: {e}");
                eprintln!("asix-gate: {e}");
                ExitCode::FAILURE
            }
        }
    }

    /// Serves `cfg` until `stop` completes; prints the ready line
    /// (`asix-gate NAME udp=ADDR tcp=ADDR fingerprint=HEX`) once it listens.
    fn serve(
        cfg: config::GateConfig,
        security: ServerSecurity,
        stop: impl std::future::Future<Output = ()>,
    ) -> Result<(), String> {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()
            .map_err(|e| e.to_string())?;
        rt.block_on(async move {
            let engine = asix_gate::Engine::start(&cfg, factory());
            let server =
                match asix_gate::serve(asix_gate::serve_config(&cfg, security), engine.clone())
                    .await
                {
                    Ok(s) => s,
                    Err(e) => {
                        engine.stop();
                        return Err(e.to_string());
                    }
                };
            let fingerprint = server
                .fingerprint()
                .map(|f| tls::fingerprint_hex(&f))
                .unwrap_or_default();
            println!(
                "asix-gate {} udp={} tcp={} fingerprint={fingerprint}",
                cfg.server_name,
                server.discovery_addr(),
                server.tcp_addr(),
            );
            tracing::info!(
                server = %cfg.server_name,
                udp = %server.discovery_addr(),
                tcp = %server.tcp_addr(),
                %fingerprint,
                "asix-gate serving"
            );
            stop.await;
            tracing::info!("asix-gate stopping");
            engine.stop();
            server.shutdown().await;
            Ok(())
        })
    }

    /// `/Service [--config FILE]`: the NT service, started with the configuration's
    /// absolute path (the service starts in the system folder).
    #[cfg(windows)]
    fn install(path: Option<PathBuf>) -> ExitCode {
        use ctopc_com::service;
        let exe = match std::env::current_exe() {
            Ok(e) => e,
            Err(e) => {
                eprintln!("asix-gate: /Service: {e}");
                return ExitCode::FAILURE;
            }
        };
        let mut args = Vec::new();
        if let Some(p) = path {
            let p = std::path::absolute(&p).unwrap_or(p);
            args.push("--config".into());
            args.push(p.into_os_string());
        }
        match service::install_with_args(&service::ASIX_GATE, &exe, &args) {
            Ok(()) => {
                println!("asix-gate: service {} installed", service::ASIX_GATE.name);
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("asix-gate: /Service: {e}");
                ExitCode::FAILURE
            }
        }
    }

    /// `/UnregServer`: stops and removes the NT service (quietly when there is none).
    #[cfg(windows)]
    fn uninstall() -> ExitCode {
        use ctopc_com::service;
        match service::uninstall_as(&service::ASIX_GATE) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("asix-gate: /UnregServer: {e}");
                ExitCode::FAILURE
            }
        }
    }

    /// `-ServiceRun`: the service control dispatcher; the gate serves until the service
    /// manager stops the service (or the system shuts down).
    #[cfg(windows)]
    fn service(cfg: config::GateConfig, security: ServerSecurity) -> ExitCode {
        use ctopc_com::service;
        let r = service::run_as(
            &service::ASIX_GATE,
            Box::new(move |stop| {
                let notify = std::sync::Arc::new(tokio::sync::Notify::new());
                let wake = std::sync::Arc::clone(&notify);
                // `notify_one` keeps the wake-up for a stop that comes before the wait.
                stop.on_trigger(move |reason| {
                    tracing::info!("{reason}");
                    wake.notify_one();
                });
                serve(cfg, security, async move { notify.notified().await })
            }),
        );
        match r {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                tracing::error!("{e}");
                eprintln!("asix-gate: {e}");
                ExitCode::FAILURE
            }
        }
    }

    #[cfg(not(windows))]
    fn install(_path: Option<PathBuf>) -> ExitCode {
        eprintln!("asix-gate: /Service: an NT service exists only on Windows");
        ExitCode::from(2)
    }

    #[cfg(not(windows))]
    fn uninstall() -> ExitCode {
        eprintln!("asix-gate: /UnregServer: an NT service exists only on Windows");
        ExitCode::from(2)
    }

    #[cfg(not(windows))]
    fn service(_cfg: config::GateConfig, _security: ServerSecurity) -> ExitCode {
        eprintln!("asix-gate: -ServiceRun: an NT service exists only on Windows");
        ExitCode::from(2)
    }
}
