//! What ServerCTOPC.exe does for each switch: register, unregister, serve.
//!
//! Serving ([`serve_as`]) takes the configuration ([`Setup`]), the data source's maker and
//! the shutdown signal ([`StopSignal`]) as parameters: [`start`] makes the server's
//! [`Context`] (no process-wide one), the class object captures it, and the stop request
//! comes only through the signal, which the console handler ([`stop_on_console_ctrl`]) and
//! the NT service's control handler (`service::run`) trigger. Another front end (OPC UA)
//! may serve beside DA from the same runtime ([`StartBeside`]): it is started once the
//! runtime runs and stopped when serving ends.

use crate::com::apartment::Apartment;
use crate::com::lifetime::{ExitReason, Lifetime, StopSignal};
use crate::com::winreg::{self, ServerRegistration};
use crate::da::context::{Context, Setup};
use crate::da::server;
use ctopc_core::Lang;
use ctopc_registration as registration;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use windows::core::{BOOL, GUID};
use windows::Win32::Foundation::E_FAIL;
use windows::Win32::Globalization::{GetSystemDefaultLCID, GetUserDefaultUILanguage};
use windows::Win32::System::Com::{
    CoInitializeSecurity, CoRegisterClassObject, CoRevokeClassObject, CLSCTX_LOCAL_SERVER,
    EOAC_NONE, REGCLS_MULTIPLEUSE, RPC_C_AUTHN_LEVEL_NONE, RPC_C_IMP_LEVEL_IDENTIFY,
};
use windows::Win32::System::Console::SetConsoleCtrlHandler;

/// CLSID of ServerCTOPC.App (ours; the AppID is the same GUID, as is customary).
pub const CLSID_SERVERCTOPC: GUID = GUID::from_u128(registration::CLSID_SERVERCTOPC);
pub use ctopc_registration::{DESCRIPTION, EXE_NAME, PROGID, PROGID_VERSIONED};
/// How long a server started by COM waits for its first client before it exits.
pub const STARTUP_GRACE: Duration = Duration::from_secs(60);
/// How long the server stays up after its last client has gone, so that a client
/// connecting right then is served instead of reaching a process that is exiting.
pub const EXIT_LINGER: Duration = Duration::from_secs(3);
/// How long a server that has revoked its class object to exit still waits for a client
/// that got the class object from the system just before the revoke (its CreateInstance or
/// LockServer arrives after it): such a client makes the server register again and serve
/// on ([`serve_class`], `Lifetime::stays_unused`).
pub const REVOKE_SETTLE: Duration = Duration::from_secs(2);
/// What the log says when the class object has been revoked to exit (the e2e test of the
/// settle time waits for it).
pub const REVOKED_LOG: &str = "class object revoked";

/// The full path of this process's exe (what a server registers as its `LocalServer32`).
pub fn exe_path() -> windows::core::Result<String> {
    let exe = std::env::current_exe().map_err(|e| {
        crate::com::error::error(windows::Win32::Foundation::E_FAIL, &e.to_string())
    })?;
    Ok(exe.to_string_lossy().into_owned())
}

fn with_registration<R>(
    service: Option<&str>,
    f: impl FnOnce(&ServerRegistration) -> R,
) -> windows::core::Result<R> {
    let exe = exe_path()?;
    Ok(f(&registration::serverctopc(&exe, service)))
}

/// Creates the local group `ServerCTOPC Clients` (`security::CLIENTS_GROUP`) when it
/// does not exist, and says what happened. A group that cannot be created (not an
/// administrator; Wine, whose `NetLocalGroupAdd` is a stub) is a WARN line, not a
/// failure: the descriptors then leave it out ([`write_appid_security`]).
fn ensure_clients_group() {
    use crate::com::caller::{account_sid, create_local_group, GroupAdded};
    use registration::security::CLIENTS_GROUP;
    const COMMENT: &str = "Accounts that may use the ServerCTOPC OPC server, also remotely";
    match create_local_group(CLIENTS_GROUP, COMMENT) {
        Ok(GroupAdded::Created) => println!("ServerCTOPC: created the local group \"{CLIENTS_GROUP}\""),
        Ok(GroupAdded::Existed) => println!("ServerCTOPC: the local group \"{CLIENTS_GROUP}\" exists (its members are kept)"),
        Err(status) => println!(
            "ServerCTOPC: WARN: cannot create the local group \"{CLIENTS_GROUP}\" (NetLocalGroupAdd: status {status}{}); create it with `net localgroup \"{CLIENTS_GROUP}\" /add`",
            if status == 5 { ", access denied: run as administrator" } else { "" }
        ),
    }
    if account_sid(CLIENTS_GROUP).is_none() {
        println!(
            "ServerCTOPC: WARN: {}",
            crate::com::platform::local_group_missing_reason(CLIENTS_GROUP)
        );
    }
}

/// The AppID's security values where absent (`ctopc_registration::security`), both
/// views: what an administrator set (dcomcnfg) stays. The clients' group
/// (`ServerCTOPC Clients`) is granted when it exists (a WARN line when it does not).
fn write_appid_security(service: bool) -> windows::core::Result<()> {
    use registration::security;
    let clients = crate::com::caller::account_sid(security::CLIENTS_GROUP)
        .and_then(|b| security::Sid::from_bytes(&b));
    match &clients {
        Some(sid) => println!(
            "ServerCTOPC: the local group \"{}\" ({sid}) may use the server, also remotely",
            security::CLIENTS_GROUP
        ),
        None => println!(
            "ServerCTOPC: WARN: no local group \"{}\": the descriptors leave it out and remote clients are not granted access (create it and register again with /CreateGroup, or use dcomcnfg)",
            security::CLIENTS_GROUP
        ),
    }
    let values =
        security::appid_defaults(registration::CLSID_SERVERCTOPC, service, clients.as_ref());
    let written = winreg::write_absent(&values)?;
    println!(
        "ServerCTOPC: AppID security: {written} of {} values written (the others were set already)",
        values.len()
    );
    Ok(())
}

/// `/RegServer`; `create_group` (`/RegServer /CreateGroup`, what the MSI runs): the
/// clients' group first, so that the descriptors grant it.
pub fn register(create_group: bool) -> windows::core::Result<()> {
    let _com = Apartment::mta_without_keepalive()?;
    with_registration(None, winreg::register)??;
    if create_group {
        ensure_clients_group();
    }
    write_appid_security(false)?;
    println!(
        "ServerCTOPC: registered {PROGID} ({})",
        winreg::guid_string(&CLSID_SERVERCTOPC)
    );
    Ok(())
}

/// `/Service`: the COM registration with AppID `LocalService`, and the NT service
/// (on demand, as LocalService): COM starts the service when a client activates the server.
/// `create_group` as for [`register`].
pub fn register_service(create_group: bool) -> windows::core::Result<()> {
    let _com = Apartment::mta_without_keepalive()?;
    let exe = exe_path()?;
    crate::com::service::install(std::path::Path::new(&exe))
        .map_err(|e| crate::com::error::error(E_FAIL, &e))?;
    with_registration(Some(crate::com::service::SERVICE_NAME), winreg::register)??;
    if create_group {
        ensure_clients_group();
    }
    write_appid_security(true)?;
    println!(
        "ServerCTOPC: registered {PROGID} as the NT service {}",
        crate::com::service::SERVICE_NAME
    );
    Ok(())
}

/// `/UnregServer`; `keep_security` (`/UnregServer /KeepSecurity`, what the MSI runs when a
/// major upgrade removes the older version): the AppID's `AccessPermission`,
/// `LaunchPermission` and `AuthenticationLevel` (both views) are put back after the keys
/// are removed, so that an administrator's settings survive the upgrade (the new version's
/// registration writes its values only where absent).
pub fn unregister(keep_security: bool) -> windows::core::Result<()> {
    use registration::security::{self, Data, DefaultValue};
    let _com = Apartment::mta_without_keepalive()?;
    let kept: Vec<DefaultValue> = if keep_security {
        security::appid_defaults(registration::CLSID_SERVERCTOPC, false, None)
            .into_iter()
            .filter_map(|mut v| {
                v.data = match v.data {
                    Data::Binary(_) => Data::Binary(winreg::read_binary(v.view, &v.path, v.name)?),
                    Data::Dword(_) => Data::Dword(winreg::read_dword(v.view, &v.path, v.name)?),
                };
                Some(v)
            })
            .collect()
    } else {
        Vec::new()
    };
    with_registration(None, winreg::unregister)??;
    crate::com::service::uninstall().map_err(|e| crate::com::error::error(E_FAIL, &e))?;
    if !kept.is_empty() {
        winreg::write_absent(&kept)?;
        println!(
            "ServerCTOPC: kept the AppID's security values ({} of both views)",
            kept.len()
        );
    }
    println!("ServerCTOPC: unregistered {PROGID}");
    Ok(())
}

/// Makes the data source (the server binary decides: the in-process simulation or the
/// asix network client).
pub use ctopc_runtime::MakeBackend;

/// The default language: the configured one, else Polish on Polish Windows, else English.
fn default_lang(configured: Option<Lang>) -> Lang {
    if let Some(l) = configured {
        return l;
    }
    // SAFETY: no arguments; returns the user's UI language.
    let ui = unsafe { GetUserDefaultUILanguage() };
    Lang::default_for_system(u32::from(ui))
}

/// The number format of LOCALE_SYSTEM_DEFAULT (and of the neutral and user-default LCIDs):
/// the machine's system locale, as `VariantChangeTypeEx` would use it (pl-PL on a Polish
/// system, else en-US, the only other format the conversions know).
fn system_locale() -> ctopc_core::convert::Locale {
    // SAFETY: no arguments; returns the system locale's LCID.
    let lcid = unsafe { GetSystemDefaultLCID() };
    ctopc_core::convert::Locale::from_lcid(lcid, ctopc_core::convert::Locale::EnUs)
}

/// The process-wide COM security of our local servers (ServerCTOPC.exe, OpcServerList.exe,
/// the tests' marshal probe): authentication level NONE and identify-level impersonation,
/// the usual OPC setting, so that callbacks into clients on other machines work without a
/// shared domain; access is governed by the AppID's DCOM settings (see the deployment
/// guide). Call once, after COM is initialised and before any marshalling; a failure
/// (security already set) is ignored, as every caller did.
pub fn init_security() {
    // SAFETY: no pointers are passed; the callers call it once, before any marshalling.
    let _ = unsafe {
        CoInitializeSecurity(
            None,
            -1,
            None,
            None,
            RPC_C_AUTHN_LEVEL_NONE,
            RPC_C_IMP_LEVEL_IDENTIFY,
            None,
            EOAC_NONE,
            None,
        )
    };
}

/// ServerCTOPC's process-wide COM security. By default from its AppID (`EOAC_APPID`): the
/// `AccessPermission`, `LaunchPermission` and `AuthenticationLevel` that registration
/// writes where absent and administrators change with dcomcnfg govern who may start and
/// call the server. `legacy` (`[Server] LegacyOpenAccess`): the open call of
/// [`init_security`] instead, with a WARN (at every start). Should COM refuse the AppID
/// call, the open call is made with an ERROR naming why, so that the server still serves.
pub fn init_server_security(legacy: bool) {
    if legacy {
        tracing::warn!(
            "LegacyOpenAccess = tak: COM security without a security descriptor and with authentication level None; every process that can reach DCOM may connect, the AppID's AccessPermission is not used"
        );
        init_security();
        return;
    }
    let appid = CLSID_SERVERCTOPC;
    // SAFETY: with EOAC_APPID the first argument points to the AppID's GUID (a local,
    // alive for the call, only read); the other pointers are null, as the flag requires.
    let r = unsafe {
        CoInitializeSecurity(
            Some(windows::Win32::Security::PSECURITY_DESCRIPTOR(
                (&raw const appid).cast_mut().cast(),
            )),
            -1,
            None,
            None,
            windows::Win32::System::Com::RPC_C_AUTHN_LEVEL_DEFAULT,
            windows::Win32::System::Com::RPC_C_IMP_LEVEL_DEFAULT,
            None,
            windows::Win32::System::Com::EOAC_APPID,
            None,
        )
    };
    match r {
        Ok(()) => tracing::info!(
            "COM security from the AppID {} (AccessPermission, LaunchPermission, AuthenticationLevel)",
            winreg::guid_string(&appid)
        ),
        Err(e) => {
            tracing::error!(
                "CoInitializeSecurity(EOAC_APPID) failed: {:#010x}; falling back to the open call (LegacyOpenAccess)",
                e.code().0 as u32
            );
            init_security();
        }
    }
}

/// Keeps every interface a server hands out registered with RPC for the process's life
/// where the platform needs it (`Apartment::keep_server_interfaces`; after
/// `init_security`, which must come before any marshal; on the main thread, in the MTA).
pub fn keep_interfaces_registered() {
    match crate::com::apartment::Apartment::keep_server_interfaces() {
        Ok(0) => {}
        Ok(n) => tracing::info!("keep-alive: {n} interfaces kept registered"),
        Err(e) => tracing::warn!("{e}"),
    }
}

/// Registers `factory` as the class object of `clsid` for out-of-process activation
/// (CLSCTX_LOCAL_SERVER, REGCLS_MULTIPLEUSE); the caller revokes the cookie with
/// CoRevokeClassObject before it drops the factory.
pub fn register_class(
    clsid: &GUID,
    factory: impl windows::core::Param<windows::core::IUnknown>,
) -> windows::core::Result<u32> {
    // SAFETY: `clsid` is a valid reference for the call; the caller keeps the factory alive
    // until it revokes the registration.
    unsafe { CoRegisterClassObject(clsid, factory, CLSCTX_LOCAL_SERVER, REGCLS_MULTIPLEUSE) }
}

/// Registers `factory` as the class object of `clsid` ([`register_class`]), serves until
/// `wait` returns, and revokes it. When `wait` decided the server was unused (the last
/// client gone, or none came) but a client arrives within [`REVOKE_SETTLE`] of the revoke,
/// registers again and serves on: that client got the class object just before the revoke,
/// and the process must not exit under it. (Windows's `CoReleaseServerProcess` suspends the
/// class objects for this; Wine's does not.) Returns why the serving ended.
pub fn serve_class(
    clsid: &GUID,
    factory: &windows::Win32::System::Com::IClassFactory,
    lifetime: &Lifetime,
    mut wait: impl FnMut() -> ExitReason,
) -> windows::core::Result<ExitReason> {
    loop {
        let cookie = register_class(clsid, factory)?;
        let reason = wait();
        // SAFETY: the cookie came from CoRegisterClassObject above.
        unsafe { CoRevokeClassObject(cookie)? };
        if reason == ExitReason::StopRequested {
            return Ok(reason);
        }
        tracing::info!(
            "{REVOKED_LOG} ({reason:?}); exiting unless a client comes within {} ms",
            REVOKE_SETTLE.as_millis()
        );
        if lifetime.stays_unused(REVOKE_SETTLE) {
            return Ok(reason);
        }
        tracing::info!("a client came while the class object was being revoked: serving on");
    }
}

/// The folder of ServerCTOPC.exe (the install folder: ASIXConnect.ini, Log\).
pub fn install_dir() -> Result<PathBuf, String> {
    let exe = std::env::current_exe().map_err(|e| format!("cannot locate ServerCTOPC.exe: {e}"))?;
    Ok(exe.parent().map(PathBuf::from).unwrap_or_default())
}

/// Starts a runtime over a configuration and makes its context (one per call: the
/// in-process tests make one per test). The server state comes from the data source: a
/// backend that simulates current data is OPC_STATUS_TEST. Dropping the last reference
/// (the context, the class object and every object made from it) stops the runtime.
pub fn start(setup: Setup, make_backend: Box<MakeBackend<'_>>) -> Result<Arc<Context>, String> {
    let Setup {
        namespace,
        address_space,
        mut engine_config,
        default_language,
        no_config_reason,
        ops,
        legacy_open_access: _,
    } = setup;
    // Text written with a default LCID converts in the system's number format (a Polish
    // system reads "12,5" as 12.5), as VariantChangeTypeEx does on Windows.
    engine_config.default_locale = system_locale();
    if let Some(r) = &no_config_reason {
        tracing::error!("OPC_STATUS_NOCONFIG: {r}");
    }
    if engine_config.source_timeout_ms != ctopc_core::model::DEFAULT_SOURCE_TIMEOUT_MS {
        tracing::info!(
            "data source timeout: {} ms (SourceTimeout)",
            engine_config.source_timeout_ms
        );
    }
    // The `_Diagnostics` branch beside the real namespace and backend, the operations
    // settings and the metrics endpoint: the runtime's, as for every front end.
    let started = ctopc_runtime::start(
        namespace,
        address_space.filter_case(),
        engine_config,
        &ops,
        crate::da::callbacks::thread_hook,
        make_backend,
    )?;
    let ctx = Context {
        runtime: started.runtime,
        address_space,
        default_lang: default_lang(default_language),
        namespace: started.namespace,
        state: Context::state_for(no_config_reason.as_deref(), started.simulation),
        no_config_reason,
        lifetime: Lifetime::new(),
        groups: Default::default(),
    };
    Ok(Arc::new(ctx))
}

/// What a front end serving beside OPC DA in the same process gets: the server's one
/// runtime (engine and data source), its namespace with the `_Diagnostics` branch, the
/// browse tree and the default language; the same the DA objects serve from.
pub struct Beside {
    pub runtime: Arc<ctopc_runtime::Runtime>,
    pub namespace: Arc<dyn ctopc_core::namespace::Namespace>,
    pub address_space: Arc<ctopc_core::browse::AddressSpace>,
    pub lang: Lang,
}

/// Starts a front end beside OPC DA ([`Beside`]) once the runtime runs. What it returns
/// is dropped when serving ends (after the DA clients got their shutdown request, before
/// the runtime stops): its drop stops that front end. An `Err` is logged and the server
/// serves DA alone.
pub type StartBeside = dyn FnOnce(Beside) -> Result<Box<dyn std::any::Any>, String>;

/// The stop signal the console control handler triggers. A console control handler is a
/// plain `extern "system" fn` with no user data, so this one process-level hook is
/// unavoidable; it holds nothing but the signal to trigger (set by
/// [`stop_on_console_ctrl`]) and no server state.
static CONSOLE_STOP: Mutex<Option<StopSignal>> = Mutex::new(None);

unsafe extern "system" fn on_console_ctrl(ctrl: u32) -> BOOL {
    // CTRL_LOGOFF_EVENT (5) and CTRL_SHUTDOWN_EVENT (6): the system is going down.
    let reason = if ctrl >= 5 {
        "the system is shutting down"
    } else {
        "ServerCTOPC was stopped from its console"
    };
    let signal = CONSOLE_STOP
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .clone();
    if let Some(s) = signal {
        s.trigger(reason);
    }
    BOOL(1)
}

/// Ctrl+C, closing the console, a log-off or a system shutdown trigger `signal` (the
/// process's console handler forwards to the signal set last).
pub fn stop_on_console_ctrl(signal: &StopSignal) {
    let first = CONSOLE_STOP
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .replace(signal.clone())
        .is_none();
    if first {
        // SAFETY: a plain function pointer with the handler signature, valid for the process.
        let _ = unsafe { SetConsoleCtrlHandler(Some(on_console_ctrl), true) };
    }
}

/// How long the server process serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServeMode {
    /// Started by COM: exit after the last client has gone (or a stop request).
    UntilUnused,
    /// The NT service: serve until the service control manager stops it.
    UntilStopped,
}

/// Serves in the given mode: start, start the front end `beside` DA if any, register the
/// class object for multiple use, serve until the last DA client has gone
/// (`ServeMode::UntilUnused`, `-Embedding`: the other front end's clients do not keep the
/// process) or `stop` is triggered, then revoke it and exit. On a triggered stop every
/// connected client first gets IOPCShutdown::ShutdownRequest with the trigger's reason;
/// then the other front end is stopped.
pub fn serve_as(
    setup: Setup,
    make_backend: Box<MakeBackend<'_>>,
    mode: ServeMode,
    stop: &StopSignal,
    beside: Option<Box<StartBeside>>,
) -> windows::core::Result<()> {
    let _com = Apartment::mta_without_keepalive()?;
    init_server_security(setup.legacy_open_access);
    keep_interfaces_registered();
    let ctx = start(setup, make_backend).map_err(|e| {
        tracing::error!("cannot start: {e}");
        crate::com::error::error(E_FAIL, &e)
    })?;
    ctx.lifetime.stop_on(stop);
    let beside = beside.and_then(|start| {
        start(Beside {
            runtime: Arc::clone(&ctx.runtime),
            namespace: Arc::clone(&ctx.namespace),
            address_space: Arc::clone(&ctx.address_space),
            lang: ctx.default_lang,
        })
        .map_err(|e| tracing::error!("{e}; serving OPC DA only"))
        .ok()
    });
    let factory = server::class_factory(&ctx);
    let mut announced = false;
    let reason = serve_class(&CLSID_SERVERCTOPC, &factory, &ctx.lifetime, || {
        if !announced {
            tracing::info!("serving {PROGID}");
            announced = true;
        }
        match mode {
            ServeMode::UntilUnused => ctx.lifetime.wait_until_unused(STARTUP_GRACE, EXIT_LINGER),
            ServeMode::UntilStopped => {
                ctx.lifetime.wait_for_stop();
                ExitReason::StopRequested
            }
        }
    })?;
    if reason == ExitReason::StopRequested {
        ctx.runtime.shutdown(ctx.lifetime.stop_reason());
    }
    drop(beside);
    tracing::info!("exiting ({reason:?})");
    Ok(())
}
