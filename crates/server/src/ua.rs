//! OPC UA in the server: on Linux `serve` (the runtime over the configured data source,
//! the OPC UA front end over the runtime, until Ctrl+C or SIGTERM); on Windows the front
//! end beside OPC DA over the COM server's runtime ([`start_beside`]); on both `user add`
//! and `pki trust`. The configuration is found as for the COM server (`config`):
//! `SERVERCTOPC_INI`, else `ASIXConnect.ini` next to the program, else the embedded demo
//! plant; the PKI folder and the users file are beside it by default.

use crate::config;
use asix_model::AsixNamespace;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The folder of the program.
pub fn exe_dir() -> PathBuf {
    std::env::current_exe()
        .ok()
        .and_then(|p| p.parent().map(Path::to_path_buf))
        .unwrap_or_else(|| PathBuf::from("."))
}

/// The folder of the configuration in use (the program's for the embedded demo).
pub fn config_dir(source: &config::ConfigSource) -> PathBuf {
    match source {
        config::ConfigSource::File(p) | config::ConfigSource::FromEnv(p) => p
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from(".")),
        config::ConfigSource::EmbeddedDemo => exe_dir(),
    }
}

/// `[UA]` as the front end's settings, paths resolved beside the configuration.
pub fn settings(ns: &AsixNamespace, dir: &Path) -> ctopc_ua::server::Settings {
    let cfg = ns.config();
    let ua = &cfg.ua;
    let paths = cfg.secret_paths(dir);
    ctopc_ua::server::Settings {
        endpoint: ua.endpoint.clone(),
        allow_none: ua.allow_none,
        allow_anonymous: ua.allow_anonymous,
        pki_dir: paths.ua_pki,
        private_key: asix_model::config::ua_private_key_in_store(),
        users_file: paths.ua_users_file,
        limits: limits(ua),
    }
}

/// `[UA]`'s `Max…` options as the front end's limits.
pub fn limits(ua: &asix_model::UaOptions) -> ctopc_ua::limits::Limits {
    let n = |v: u32| v as usize;
    ctopc_ua::limits::Limits {
        max_sessions: n(ua.max_sessions),
        max_subscriptions_per_session: n(ua.max_subscriptions_per_session),
        max_monitored_items_per_subscription: n(ua.max_monitored_items_per_subscription),
        max_monitored_items: n(ua.max_monitored_items),
        max_browse_continuation_points: n(ua.max_browse_continuation_points),
        max_operations_per_request: n(ua.max_operations_per_request),
        max_message_size: n(ua.max_message_size),
        max_chunk_count: n(ua.max_chunk_count),
        max_array_length: n(ua.max_array_length),
        max_string_length: n(ua.max_string_length),
        max_requests_per_second: ua.max_requests_per_second,
    }
}

fn load() -> Result<(config::ConfigSource, asix_model::startup::Loaded), String> {
    config::load(&exe_dir())
}

fn fail(e: &str) -> ExitCode {
    eprintln!("ServerCTOPC: {e}");
    ExitCode::FAILURE
}

/// `serve`: logs to standard error (`RUST_LOG` filters; default `info`).
#[cfg(not(windows))]
pub fn serve() -> ExitCode {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,opcua=warn"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    match serve_inner() {
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
fn serve_inner() -> Result<(), String> {
    use crate::backend;
    use ctopc_core::lang::Lang;
    use ctopc_core::namespace::Namespace;
    use std::sync::Arc;
    tracing::info!(
        version = env!("CARGO_PKG_VERSION"),
        "ServerCTOPC starting (OPC UA)"
    );
    let (source, loaded) = load()?;
    tracing::info!("{}", source.log_line());
    for w in &loaded.warnings {
        tracing::warn!("{w}");
    }
    let dir = config_dir(&source);
    let ns = Arc::new(loaded.namespace);
    let settings = settings(&ns, &dir);
    let tree = match asix_model::address_space::build_address_space(&ns) {
        Ok(t) => t,
        Err(e) => {
            tracing::error!("cannot build the browse tree: {e:?}; browsing shows an empty tree");
            ctopc_core::browse::AddressSpace::empty()
        }
    };
    let server = &ns.config().server;
    let lang = server.default_language.fixed().unwrap_or(Lang::English);
    let for_backend = Arc::clone(&ns);
    let started = ctopc_runtime::start(
        Arc::clone(&ns) as Arc<dyn Namespace>,
        tree.filter_case(),
        server.engine_config(),
        &server.ops_config(),
        ctopc_runtime::frontend::no_thread_state,
        Box::new(move |wake| backend::make(&for_backend, wake)),
    )?;
    let runtime = Arc::clone(&started.runtime);
    let serve = ctopc_ua::server::Serve {
        runtime: Arc::clone(&runtime),
        namespace: started.namespace,
        tree: Arc::new(tree),
        lang,
    };
    let tokio = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("opc-ua")
        .build()
        .map_err(|e| format!("cannot start the OPC UA runtime: {e}"))?;
    let result = tokio.block_on(ctopc_ua::server::run(&settings, serve, stop_signal()));
    runtime.shutdown("ServerCTOPC is stopping");
    runtime.stop_driver();
    result
}

/// Ctrl+C or SIGTERM.
#[cfg(not(windows))]
async fn stop_signal() {
    use tokio::signal::unix::{signal, SignalKind};
    match signal(SignalKind::terminate()) {
        Ok(mut term) => {
            tokio::select! {
                _ = tokio::signal::ctrl_c() => {}
                _ = term.recv() => {}
            }
        }
        Err(_) => {
            let _ = tokio::signal::ctrl_c().await;
        }
    }
}

/// How long stopping the OPC UA front end beside DA may take (its sessions closed, its
/// runtime's tasks ended).
#[cfg(windows)]
const STOP_LIMIT: std::time::Duration = std::time::Duration::from_secs(5);

/// The OPC UA front end beside OPC DA: its own tokio runtime (the process's only one
/// but the asix network client's) and the running server; dropping it stops both.
#[cfg(windows)]
struct UaBeside {
    tokio: Option<tokio::runtime::Runtime>,
    running: Option<ctopc_ua::server::Running>,
}

#[cfg(windows)]
impl Drop for UaBeside {
    fn drop(&mut self) {
        let (Some(tokio), Some(running)) = (self.tokio.take(), self.running.take()) else {
            return;
        };
        tracing::info!("OPC UA: stopping");
        match tokio.block_on(async { tokio::time::timeout(STOP_LIMIT, running.stop()).await }) {
            Ok(Ok(())) => tracing::info!("OPC UA: stopped"),
            Ok(Err(e)) => tracing::warn!("OPC UA: {e}"),
            Err(_) => tracing::warn!(
                "OPC UA: the server did not stop within {} s; ending its runtime",
                STOP_LIMIT.as_secs()
            ),
        }
        tokio.shutdown_timeout(STOP_LIMIT);
    }
}

/// Starts the OPC UA front end over the COM server's runtime (`beside`: the same engine,
/// data source, namespace and browse tree as the DA objects), listening as `settings`
/// say; the returned guard stops it when dropped.
#[cfg(windows)]
pub fn start_beside(
    settings: &ctopc_ua::server::Settings,
    beside: ctopc_com::host::Beside,
) -> Result<Box<dyn std::any::Any>, String> {
    let tokio = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("opc-ua")
        .build()
        .map_err(|e| format!("OPC UA: cannot start its runtime: {e}"))?;
    let serve = ctopc_ua::server::Serve {
        runtime: beside.runtime,
        namespace: beside.namespace,
        tree: beside.address_space,
        lang: beside.lang,
    };
    let running = tokio
        .block_on(ctopc_ua::server::start(settings, serve))
        .map_err(|e| format!("OPC UA: {e}"))?;
    Ok(Box::new(UaBeside {
        tokio: Some(tokio),
        running: Some(running),
    }))
}

/// `user add NAME --role R [--password-stdin]`.
pub fn user_add(name: &str, role: &str, password_stdin: bool) -> ExitCode {
    use ctopc_ua::users::{self, Role, User};
    let Some(role) = Role::parse(role) else {
        return fail("--role takes reader or writer");
    };
    if !users::valid_name(name) {
        return fail("a user name is 1-64 characters without `:`, blanks or control characters");
    }
    let (source, loaded) = match load() {
        Ok(x) => x,
        Err(e) => return fail(&e),
    };
    let path = settings(&loaded.namespace, &config_dir(&source)).users_file;
    let password = match new_password(name, password_stdin) {
        Ok(p) => p,
        Err(e) => return fail(&e),
    };
    match users::add(&path, &User::new(name, role, &password)) {
        Ok(()) => {
            println!("user {name} ({}) saved in {}", role.name(), path.display());
            ExitCode::SUCCESS
        }
        Err(e) => fail(&e),
    }
}

/// What `user add` says when it cannot ask (standard input is not a terminal).
pub const NO_TERMINAL: &str =
    "standard input is not a terminal: cannot ask for the password; pipe it with --password-stdin";

/// The new user's password: the first line of standard input with `--password-stdin`,
/// else asked twice on the terminal without echo.
fn new_password(name: &str, password_stdin: bool) -> Result<String, String> {
    use std::io::IsTerminal;
    if password_stdin {
        let mut line = String::new();
        std::io::stdin()
            .read_line(&mut line)
            .map_err(|e| format!("cannot read the password: {e}"))?;
        let password = line.trim_end_matches(['\n', '\r']);
        if password.is_empty() {
            return Err("the password is empty".to_owned());
        }
        return Ok(password.to_owned());
    }
    if !std::io::stdin().is_terminal() {
        return Err(NO_TERMINAL.to_owned());
    }
    ask_twice(name, |prompt| rpassword::prompt_password(prompt))
}

/// Asks for a new password twice (through `ask`, which shows a prompt and reads a line
/// without echo): the password when both answers are the same and not empty.
pub fn ask_twice(
    name: &str,
    mut ask: impl FnMut(&str) -> std::io::Result<String>,
) -> Result<String, String> {
    let read = |e: std::io::Error| format!("cannot read the password: {e}");
    let first = ask(&format!("Password for {name}: ")).map_err(read)?;
    if first.is_empty() {
        return Err("the password is empty".to_owned());
    }
    let again = ask(&format!("The password for {name} again: ")).map_err(read)?;
    if first != again {
        return Err("the two passwords differ; nothing saved".to_owned());
    }
    Ok(first)
}

/// `pki trust FILE`.
pub fn pki_trust(file: &str) -> ExitCode {
    let (source, loaded) = match load() {
        Ok(x) => x,
        Err(e) => return fail(&e),
    };
    let pki = settings(&loaded.namespace, &config_dir(&source)).pki_dir;
    match ctopc_ua::pki::trust(&pki, Path::new(file)) {
        Ok(at) => {
            println!("trusted: {}", at.display());
            ExitCode::SUCCESS
        }
        Err(e) => fail(&e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn answers(a: &[&str]) -> impl FnMut(&str) -> std::io::Result<String> {
        let mut it: Vec<String> = a.iter().rev().map(|s| (*s).to_owned()).collect();
        move |_prompt| {
            it.pop()
                .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::UnexpectedEof))
        }
    }

    #[test]
    fn a_new_password_is_asked_twice_and_must_match() {
        let mut prompts = Vec::new();
        let r = ask_twice("jan", |p| {
            prompts.push(p.to_owned());
            Ok("Kwas-98%".to_owned())
        });
        assert_eq!(r.as_deref(), Ok("Kwas-98%"));
        assert_eq!(
            prompts,
            ["Password for jan: ", "The password for jan again: "]
        );
        assert_eq!(
            ask_twice("jan", answers(&["a1", "a2"])).unwrap_err(),
            "the two passwords differ; nothing saved"
        );
        assert_eq!(
            ask_twice("jan", answers(&[""])).unwrap_err(),
            "the password is empty"
        );
        let e = ask_twice("jan", answers(&["a1"])).unwrap_err();
        assert!(e.starts_with("cannot read the password"), "{e}");
    }

    #[test]
    fn the_ini_defaults_are_the_front_ends_defaults() {
        let l = limits(&asix_model::UaOptions::default());
        assert_eq!(l, ctopc_ua::limits::Limits::default());
        l.check().unwrap();
    }

    #[test]
    fn every_limit_option_reaches_its_limit() {
        let ua = asix_model::UaOptions {
            max_sessions: 1,
            max_subscriptions_per_session: 2,
            max_monitored_items_per_subscription: 3,
            max_monitored_items: 4,
            max_browse_continuation_points: 5,
            max_operations_per_request: 6,
            max_message_size: 70_000,
            max_chunk_count: 8,
            max_array_length: 9,
            max_string_length: 10_000,
            max_requests_per_second: 11,
            ..Default::default()
        };
        let l = limits(&ua);
        assert_eq!(
            l,
            ctopc_ua::limits::Limits {
                max_sessions: 1,
                max_subscriptions_per_session: 2,
                max_monitored_items_per_subscription: 3,
                max_monitored_items: 4,
                max_browse_continuation_points: 5,
                max_operations_per_request: 6,
                max_message_size: 70_000,
                max_chunk_count: 8,
                max_array_length: 9,
                max_string_length: 10_000,
                max_requests_per_second: 11,
            }
        );
    }
}
