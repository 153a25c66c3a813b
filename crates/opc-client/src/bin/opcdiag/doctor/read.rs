//! `opcdiag doctor` on Windows: the thin readers (registry, files, the service manager,
//! netsh, the asix discovery, a COM connection) feeding the verdicts of `doctor.rs`.

use super::*;
use crate::cli::{DoctorOptions, Global};
use crate::win::{Session, Subscription};
use asix_net::datasource::{client_config_from_server_options, NamespaceResolver, Resolver};
use asix_net::proto::discovery::Resource;
use ctopc_com::winreg;
use std::path::Path;
use std::sync::mpsc;
use std::sync::Arc;
use std::time::Duration;

/// The registry of this machine, through `ctopc_com::winreg`'s readers.
struct MachineRegistry;

impl Registry for MachineRegistry {
    fn key_exists(&self, view: View, path: &str) -> bool {
        winreg::key_exists(view, path)
    }
    fn value(&self, view: View, path: &str, name: &str) -> Option<String> {
        winreg::read_value(view, path, name)
    }
}

/// Whether the file at a registered path exists, as this process sees it.
fn exists_in(view: View) -> impl Fn(&str) -> bool {
    move |p: &str| Path::new(&path_seen_here(p, view, cfg!(target_pointer_width = "64"))).exists()
}

const CONFIG_ENV: &str = "SERVERCTOPC_INI";
const CONFIG_FILE: &str = "ASIXConnect.ini";

/// Runs every check, prints the report, returns the exit code.
pub fn run(global: &Global, options: &DoctorOptions) -> u8 {
    let checks = checks(global, options);
    if options.json {
        print!("{}", render_json(&checks));
    } else {
        print!("{}", render_text(&checks));
    }
    exit_code(&checks)
}

fn checks(global: &Global, options: &DoctorOptions) -> Vec<Check> {
    let reg = MachineRegistry;
    let mut out = Vec::new();
    // Registration.
    let (exe, service) = registered_server(&reg);
    let expected =
        registration::serverctopc(exe.as_deref().unwrap_or(""), service.as_deref()).keys();
    for v in registration::VIEWS {
        out.push(registration_check(v, &expected, &reg));
    }
    let exe_exists = exe.as_deref().is_some_and(|e| Path::new(e).exists());
    out.push(exe_check(exe.as_deref(), exe_exists));
    // Proxy/stub, server browser.
    let interfaces = idl_interfaces();
    for v in registration::VIEWS {
        out.push(proxy_check(v, &interfaces, &reg, &exists_in(v)));
    }
    for v in registration::VIEWS {
        out.push(browser_check(v, &reg, &exists_in(v)));
    }
    // The NT service.
    let installed = service_info();
    out.push(service_check(
        service.as_deref(),
        installed.as_ref(),
        exe.as_deref(),
        installed
            .as_ref()
            .is_none_or(|i| Path::new(&exe_of_command_line(&i.executable)).exists()),
    ));
    // Configuration and databases.
    let install_dir = exe
        .as_deref()
        .and_then(|e| Path::new(e).parent())
        .map(|p| p.display().to_string());
    let (source, loaded) = load_configuration(options, install_dir.as_deref());
    out.push(config_check(&source, &loaded));
    let account = installed.as_ref().map_or_else(
        || "the user of the client that starts it".to_owned(),
        |i| i.account.clone(),
    );
    // (A missing exe is a FAIL of its own; its folder's Log then says nothing more.)
    if let Some(dir) = install_dir.as_ref().filter(|_| exe_exists) {
        let configured = loaded
            .as_ref()
            .ok()
            .and_then(|l| l.namespace.config().server.log_directory.clone());
        let log = log_dir(dir, configured.as_deref());
        out.push(log_check(&log, &probe_log_dir(&log), &account));
    }
    // Write rights and the AppID's security.
    let legacy_open_access = loaded
        .as_ref()
        .is_ok_and(|l| l.namespace.config().server.legacy_open_access);
    if let Ok(l) = &loaded {
        out.push(write_rights_check(&l.namespace.config().write_rights));
    }
    // The files of secrets the configuration names (keys, the users file), their DACLs.
    if let Ok(l) = &loaded {
        let cfg = l.namespace.config();
        let dir = cfg
            .base_dir
            .clone()
            .or_else(|| install_dir.as_ref().map(std::path::PathBuf::from))
            .unwrap_or_default();
        let service: Vec<registration::security::Sid> = installed
            .as_ref()
            .and_then(|i| ctopc_com::caller::account_sid(&i.account))
            .and_then(|b| registration::security::Sid::from_bytes(&b))
            .into_iter()
            .collect();
        for (what, path) in secret_files(cfg, &dir) {
            let finding = ctopc_com::com::secret_file::findings(&path, &service);
            out.push(secret_check(
                &what,
                &path.display().to_string(),
                path.exists(),
                finding.as_deref(),
            ));
        }
    }
    let appid = format!("AppID\\{}", guid_string(registration::CLSID_SERVERCTOPC));
    let security = AppIdSecurity {
        access: winreg::read_binary(View::Reg64, &appid, "AccessPermission"),
        launch: winreg::read_binary(View::Reg64, &appid, "LaunchPermission"),
        authentication_level: winreg::read_dword(View::Reg64, &appid, "AuthenticationLevel"),
        legacy_open_access,
        clients: ctopc_com::caller::account_sid(registration::security::CLIENTS_GROUP)
            .and_then(|b| registration::security::Sid::from_bytes(&b)),
    };
    out.extend(appid_security_checks(&security));
    let mut item = options.item.clone();
    if let Ok(l) = loaded {
        out.extend(database_checks(&l.namespace));
        if item.is_none() {
            item = first_item(&l.namespace);
        }
        out.extend(link_checks(Arc::new(l.namespace)));
    }
    // DCOM and the firewall.
    let ole = |path: &str, name: &str| winreg::read_machine_value(View::Reg64, path, name);
    out.extend(dcom_checks(
        ole("Software\\Microsoft\\Ole", "EnableDCOM").as_deref(),
        ole("Software\\Microsoft\\Ole", "LegacyAuthenticationLevel").as_deref(),
        ole(
            "Software\\Microsoft\\Ole\\AppCompat",
            "RequireIntegrityActivationAuthenticationLevel",
        )
        .as_deref(),
        server_authn_level(&security),
    ));
    out.push(firewall_check(firewall_rules().as_deref()));
    // Finally a connection.
    if let Some(config) = &options.config {
        // A COM-started server has the environment of the client that starts it under
        // Wine (not on Windows): let it read the configuration checked.
        std::env::set_var(CONFIG_ENV, config);
    }
    let timeout = Duration::from_secs_f64(options.timeout_secs.unwrap_or(20.0));
    out.extend(connection_checks(global, item, timeout));
    out
}

fn load_configuration(
    options: &DoctorOptions,
    install_dir: Option<&str>,
) -> (String, Result<asix_model::Loaded, String>) {
    use asix_model::startup;
    if let Some(c) = &options.config {
        return (format!("{c} (--config)"), startup::load_file(Path::new(c)));
    }
    if let Some(env) = std::env::var_os(CONFIG_ENV).filter(|v| !v.is_empty()) {
        let p = Path::new(&env);
        return (
            format!("{} (from {CONFIG_ENV})", p.display()),
            startup::load_file(p).map_err(|e| format!("{CONFIG_ENV}: {e}")),
        );
    }
    if let Some(dir) = install_dir {
        let p = Path::new(dir).join(CONFIG_FILE);
        if p.exists() {
            return (p.display().to_string(), startup::load_file(&p));
        }
    }
    (
        "no ASIXConnect.ini next to the server: the embedded demo plant (simulated)".to_owned(),
        startup::embedded_demo(),
    )
}

fn probe_log_dir(dir: &str) -> LogProbe {
    let d = Path::new(dir);
    if !d.exists() {
        return match d.parent() {
            Some(p) if p.exists() => LogProbe::WillBeCreated,
            _ => LogProbe::Failed("neither it nor its parent folder exists".into()),
        };
    }
    let probe = d.join(format!("opcdiag-doctor-{}.tmp", std::process::id()));
    match std::fs::write(&probe, b"opcdiag doctor") {
        Ok(()) => {
            let _ = std::fs::remove_file(&probe);
            LogProbe::Written
        }
        Err(e) => LogProbe::Failed(e.to_string()),
    }
}

fn service_info() -> Option<ServiceInfo> {
    use windows_service::service::{ServiceAccess, ServiceStartType};
    use windows_service::service_manager::{ServiceManager, ServiceManagerAccess};
    let manager =
        ServiceManager::local_computer(None::<&str>, ServiceManagerAccess::CONNECT).ok()?;
    let service = manager
        .open_service(
            ctopc_com::service::SERVICE_NAME,
            ServiceAccess::QUERY_CONFIG,
        )
        .ok()?;
    let config = service.query_config().ok()?;
    Some(ServiceInfo {
        executable: config.executable_path.display().to_string(),
        account: config.account_name.map_or_else(
            || "LocalSystem".to_owned(),
            |a| a.to_string_lossy().into_owned(),
        ),
        disabled: config.start_type == ServiceStartType::Disabled,
    })
}

/// `netsh advfirewall firewall show rule name=all`, at most 10 s; `None` when it fails or
/// prints no rules.
fn firewall_rules() -> Option<String> {
    let child = std::process::Command::new("netsh")
        .args(["advfirewall", "firewall", "show", "rule", "name=all"])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .ok()?;
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    let output = rx.recv_timeout(Duration::from_secs(10)).ok()?.ok()?;
    let text = String::from_utf8_lossy(&output.stdout).into_owned();
    (output.status.success() && text.to_ascii_lowercase().contains("rule name")).then_some(text)
}

/// One discovery per asix channel of each OPC channel, all at once, each bounded by its
/// FindServerTimeout (asix-net's own discovery, as the server runs it).
fn link_checks(ns: Arc<AsixNamespace>) -> Vec<Check> {
    let cfg = ns.config();
    if cfg.server.simulate_current_data {
        return vec![Check::ok(
            "asix link",
            "SimulateCurrentData: the data are simulated, no asix network is used",
        )];
    }
    let channels = asix_channels(&ns);
    let rest = rest_channels(&ns);
    let mut out = rest_link_checks(&ns, &rest);
    if !rest.is_empty() && channels.iter().all(|(_, a)| a.is_empty()) {
        return out;
    }
    out.extend(asix_link_checks(&ns, &channels));
    out
}

/// Every station of each Asix.Evo REST channel, asked once (bounded as the link's polls).
fn rest_link_checks(ns: &AsixNamespace, rest: &[(String, Vec<String>)]) -> Vec<Check> {
    if rest.is_empty() {
        return Vec::new();
    }
    if !asix_net::rest::link::CLIENT_BUILT {
        return vec![Check::warn(
            "Asix.Evo REST",
            "this opcdiag is built without the REST client (the 32-bit build): the stations are not asked",
            "run the 64-bit opcdiag doctor",
        )];
    }
    let Ok(rt) = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    else {
        return vec![Check::fail(
            "Asix.Evo REST",
            "cannot start the network runtime",
            "",
        )];
    };
    let cfg = ns.config();
    let mut out = Vec::new();
    for (opc, _) in rest {
        let Some(settings) = cfg.resolve_channel(opc).ok().and_then(|rc| {
            asix_net::rest::settings_from_options(
                rc.name,
                rc.options,
                cfg.server.source_timeout_ms,
                Duration::from_secs(1),
            )
        }) else {
            continue;
        };
        let results: Vec<(String, Result<(), String>)> = rt
            .block_on(asix_net::rest::probe(&settings))
            .into_iter()
            .map(|(u, r)| (u, r.map_err(|e| e.to_string())))
            .collect();
        let any = results.iter().any(|(_, r)| r.is_ok());
        for (i, (station, r)) in results.iter().enumerate() {
            out.push(rest_check(opc, station, i, any, r));
        }
    }
    out
}

/// One discovery per asix channel of each OPC channel on the asix network.
fn asix_link_checks(ns: &Arc<AsixNamespace>, channels: &[(String, Vec<String>)]) -> Vec<Check> {
    let cfg = ns.config();
    if channels.iter().all(|(_, a)| a.is_empty()) {
        return vec![Check::warn(
            "asix link",
            "no variable names an asix channel (attribute Channel): nothing to discover",
            "give the variables of the database their Channel attribute (docs/variable-database.md)",
        )];
    }
    let Ok(rt) = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    else {
        return vec![Check::fail(
            "asix link",
            "cannot start the network runtime",
            "",
        )];
    };
    let base = client_config_from_server_options(&cfg.server, &asix_net::computer_name());
    let resolver = NamespaceResolver::new(Arc::clone(ns), base);
    let mut jobs = Vec::new();
    for (opc, asix) in channels {
        let client = resolver.client_config(opc);
        let timeout_ms = client.options.find_server_timeout.as_millis() as u32;
        for a in asix {
            let c = client.clone();
            let a2 = a.clone();
            jobs.push((
                opc.clone(),
                a.clone(),
                timeout_ms,
                rt.spawn(
                    async move { asix_net::client::discover(&c, Resource::channel(a2)).await },
                ),
            ));
        }
    }
    // The identity of every server's link, all at once (discovery, connection and
    // handshake bounded by the channel's FindServerTimeout and NetTimeout).
    let mut probes = Vec::new();
    for (opc, asix) in channels {
        let client = resolver.client_config(opc);
        for a in asix {
            let c = client.clone();
            let a2 = a.clone();
            probes.push((
                opc.clone(),
                a.clone(),
                rt.spawn(async move {
                    asix_net::probe::probe_resource(&c, Resource::channel(a2)).await
                }),
            ));
        }
    }
    let mut out: Vec<Check> = jobs
        .into_iter()
        .map(|(opc, asix, timeout_ms, job)| {
            let result = match rt.block_on(job) {
                Ok(Ok(found)) => Ok(found
                    .iter()
                    .map(|c| (c.name().to_owned(), c.addr.to_string()))
                    .collect()),
                Ok(Err(e)) => Err(e.to_string()),
                Err(e) => Err(e.to_string()),
            };
            link_check(&opc, &asix, timeout_ms, &result)
        })
        .collect();
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0);
    for (opc, asix, job) in probes {
        // No server answered: the discovery's check above says so.
        let Ok(Ok(found)) = rt.block_on(job) else {
            continue;
        };
        for p in found {
            let seen = p.result.map(|r| match r {
                asix_net::probe::LinkIdentity::Tls {
                    fingerprint,
                    pinned,
                    not_after,
                    refused,
                } => LinkSeen::Tls {
                    fingerprint: asix_net::tls::fingerprint_hex(&fingerprint),
                    pinned,
                    not_after,
                    refused,
                },
                asix_net::probe::LinkIdentity::Plaintext => LinkSeen::Plaintext,
            });
            out.push(identity_check(
                &opc,
                &asix,
                &p.server,
                &p.addr.to_string(),
                &seen,
                now,
            ));
        }
    }
    out
}

/// Connects, reads one item and waits for one OnDataChange, on a thread of its own: doctor
/// never waits longer than `timeout` for the server.
fn connection_checks(global: &Global, item: Option<String>, timeout: Duration) -> Vec<Check> {
    const NAME: &str = "connection";
    let global = global.clone();
    let (tx, rx) = mpsc::channel::<Check>();
    std::thread::spawn(move || {
        let s = match Session::connect(&global) {
            Ok(s) => s,
            Err(e) => {
                let _ = tx.send(Check::fail(NAME, e, "fix the FAILs above (registration, proxy/stub, configuration), then see the server's log"));
                return;
            }
        };
        let status = match s.server.status() {
            Ok(st) => crate::text::state_name(st.state),
            Err(e) => s.error_text(e.code()),
        };
        let _ = tx.send(Check::ok(
            NAME,
            format!("{} created, state {status}", global.server),
        ));
        let Some(item) = item else {
            let _ = tx.send(Check::warn(
                "read",
                "no item to read: the configuration has no database",
                "give one with --item ITEMID",
            ));
            return;
        };
        match s.read_one(&item) {
            Ok(r) => {
                let detail = format!(
                    "{item} = {} ({})",
                    crate::text::value_text(&r.value),
                    crate::text::quality_text(r.quality)
                );
                let _ = tx.send(if r.quality & 0xC0 == 0xC0 {
                    Check::ok("read", detail)
                } else {
                    Check::warn("read", format!("{detail}: the value is not GOOD"), "see the data source's checks above (database, asix link) and the server's log")
                });
            }
            Err(e) => {
                let _ = tx.send(Check::fail(
                    "read",
                    format!("{item}: {e}"),
                    "check the item ID (opcdiag browse) and the data source (see the checks above)",
                ));
            }
        }
        let items = [item.clone()];
        match Subscription::start(&s, &items, "", 500) {
            Ok(sub) => {
                let c = match sub.first(Duration::from_secs(10)) {
                    Some(items) => Check::ok("callback", format!("OnDataChange with {} item(s)", items.len())),
                    None => Check::fail("callback", "no OnDataChange within 10 s", "allow the server to call back into this client (DCOM: the client's access permissions, firewall for the client program); see the server's log"),
                };
                sub.stop(&s);
                let _ = tx.send(c);
            }
            Err(e) => {
                let _ = tx.send(Check::fail(
                    "callback",
                    e,
                    "the server refused the subscription: see its log",
                ));
            }
        }
    });
    let deadline = std::time::Instant::now() + timeout;
    let mut out = Vec::new();
    loop {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        match rx.recv_timeout(left) {
            Ok(c) => out.push(c),
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
            Err(mpsc::RecvTimeoutError::Timeout) => {
                out.push(Check::fail(
                    ["connection", "read", "callback"][out.len().min(2)],
                    format!("no answer within {} s", timeout.as_secs_f64()),
                    "the server hangs while starting or serving: see its log",
                ));
                break;
            }
        }
    }
    out
}
