//! ServerCTOPC (and the server browser, OpcServerList.exe, and the asix-side gateway,
//! asix-gate.exe) as an NT service: installation (as LocalService; the COM servers on
//! demand, COM starting them when a client activates the server because the AppID names
//! it in `LocalService`; the gateway automatically, at boot), removal, and the service
//! main, which serves until the service control manager stops it (ServerCTOPC then sends
//! IOPCShutdown to every connected client): the control handler only triggers the
//! [`StopSignal`] it hands to the serving function. Which service: a [`ServiceSpec`]
//! ([`SERVERCTOPC`], [`SERVER_LIST`], [`ASIX_GATE`]); the functions without `_as` are
//! ServerCTOPC's.

use crate::com::lifetime::StopSignal;
use std::ffi::OsString;
use std::path::Path;
use std::time::Duration;
use windows_service::service::{
    ServiceAccess, ServiceControl, ServiceControlAccept, ServiceErrorControl, ServiceExitCode,
    ServiceInfo, ServiceStartType, ServiceState, ServiceStatus, ServiceType,
};
use windows_service::service_control_handler::{self, ServiceControlHandlerResult};
use windows_service::service_manager::{ServiceManager, ServiceManagerAccess};

pub const SERVICE_NAME: &str = "ServerCTOPC";
pub const DISPLAY_NAME: &str = "ServerCTOPC OPC DA Server (asix)";
pub const DESCRIPTION: &str =
    "OPC DA 2.05a/3.0 server for asix process data (ProgID ServerCTOPC.App).";
/// The account the service runs as by default.
pub const ACCOUNT: &str = "NT AUTHORITY\\LocalService";
/// The switch the service control manager starts the executable with.
pub const SERVICE_SWITCH: &str = "-ServiceRun";

/// One of our NT services: its name (also `AppID\{..}\LocalService` for a COM server),
/// display name, description, the reason its stop gives the serving function, and whether
/// it starts at boot (else on demand). All run as [`ACCOUNT`], started with
/// [`SERVICE_SWITCH`] (and the arguments given to [`install_with_args`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServiceSpec {
    pub name: &'static str,
    pub display_name: &'static str,
    pub description: &'static str,
    pub stopping: &'static str,
    pub auto_start: bool,
}

/// ServerCTOPC.exe's service.
pub const SERVERCTOPC: ServiceSpec = ServiceSpec {
    name: SERVICE_NAME,
    display_name: DISPLAY_NAME,
    description: DESCRIPTION,
    stopping: "the ServerCTOPC service is stopping",
    auto_start: false,
};

/// OpcServerList.exe's service (`OPC.ServerList.1` for remote clients, as OpcEnum is).
pub const SERVER_LIST: ServiceSpec = ServiceSpec {
    name: ctopc_registration::SERVER_LIST_SERVICE_NAME,
    display_name: "ServerCTOPC OPC Server List",
    description: "OPC.ServerList.1 (OpcEnum-compatible): lists the OPC servers of this \
                  machine to local and remote OPC clients.",
    stopping: "the OPC Server List service is stopping",
    auto_start: false,
};

/// asix-gate.exe's service: the gateway serves the asix station's data to ServerCTOPC from
/// boot on (nothing activates it on demand).
pub const ASIX_GATE: ServiceSpec = ServiceSpec {
    name: "AsixGate",
    display_name: "asix-gate (asix network gateway over XConnect.ServerCT)",
    description: "Serves the current data of this asix station's AsixConnect channels to \
                  ServerCTOPC over the asix network protocol (TLS).",
    stopping: "the asix-gate service is stopping",
    auto_start: true,
};

fn service_info(spec: &ServiceSpec, exe: &Path, args: &[OsString]) -> ServiceInfo {
    let mut launch_arguments = vec![OsString::from(SERVICE_SWITCH)];
    launch_arguments.extend(args.iter().cloned());
    ServiceInfo {
        name: OsString::from(spec.name),
        display_name: OsString::from(spec.display_name),
        service_type: ServiceType::OWN_PROCESS,
        start_type: if spec.auto_start {
            ServiceStartType::AutoStart
        } else {
            ServiceStartType::OnDemand
        },
        error_control: ServiceErrorControl::Normal,
        executable_path: exe.to_path_buf(),
        launch_arguments,
        dependencies: vec![],
        account_name: Some(OsString::from(ACCOUNT)),
        account_password: None,
    }
}

/// Creates ServerCTOPC's service, or updates its configuration (idempotent).
pub fn install(exe: &Path) -> Result<(), String> {
    install_as(&SERVERCTOPC, exe)
}

/// Stops and deletes ServerCTOPC's service; succeeds quietly when it does not exist.
pub fn uninstall() -> Result<(), String> {
    uninstall_as(&SERVERCTOPC)
}

/// Creates the service, or updates its configuration when it exists (idempotent).
pub fn install_as(spec: &ServiceSpec, exe: &Path) -> Result<(), String> {
    install_with_args(spec, exe, &[])
}

/// As [`install_as`], the service started with `args` after [`SERVICE_SWITCH`] (each
/// quoted by the service manager as needed).
pub fn install_with_args(spec: &ServiceSpec, exe: &Path, args: &[OsString]) -> Result<(), String> {
    let name = spec.name;
    let manager = ServiceManager::local_computer(
        None::<&str>,
        ServiceManagerAccess::CONNECT | ServiceManagerAccess::CREATE_SERVICE,
    )
    .map_err(|e| format!("cannot open the service control manager (run as administrator): {e}"))?;
    let info = service_info(spec, exe, args);
    match manager.open_service(name, ServiceAccess::CHANGE_CONFIG) {
        Ok(existing) => existing
            .change_config(&info)
            .map_err(|e| format!("cannot update the service {name}: {e}"))?,
        Err(_) => {
            let created = manager
                .create_service(&info, ServiceAccess::CHANGE_CONFIG)
                .map_err(|e| format!("cannot create the service {name}: {e}"))?;
            // Not every service manager supports descriptions (Wine's does); not fatal.
            let _ = created.set_description(spec.description);
        }
    }
    Ok(())
}

/// Stops and deletes the service; succeeds quietly when it does not exist.
pub fn uninstall_as(spec: &ServiceSpec) -> Result<(), String> {
    let name = spec.name;
    let Ok(manager) = ServiceManager::local_computer(None::<&str>, ServiceManagerAccess::CONNECT)
    else {
        return Ok(());
    };
    let Ok(service) = manager.open_service(
        name,
        ServiceAccess::QUERY_STATUS | ServiceAccess::STOP | ServiceAccess::DELETE,
    ) else {
        return Ok(());
    };
    if service
        .query_status()
        .map(|s| s.current_state != ServiceState::Stopped)
        .unwrap_or(false)
    {
        let _ = service.stop();
        for _ in 0..50 {
            std::thread::sleep(Duration::from_millis(100));
            if service
                .query_status()
                .map(|s| s.current_state == ServiceState::Stopped)
                .unwrap_or(true)
            {
                break;
            }
        }
    }
    service
        .delete()
        .map_err(|e| format!("cannot delete the service {name}: {e}"))
}

/// Serves until the given signal is triggered (the service control manager's stop or a
/// system shutdown).
pub type ServeFn = Box<dyn FnOnce(StopSignal) -> Result<(), String> + Send>;

/// The service and its serving function for the service main. The service main is a
/// plain function the dispatcher calls with no user data, so this process-level hook is
/// unavoidable; it holds only what was handed to [`run_as`], taken once.
static SERVE: std::sync::Mutex<Option<(ServiceSpec, ServeFn)>> = std::sync::Mutex::new(None);

windows_service::define_windows_service!(ffi_service_main, service_main);

/// Runs ServerCTOPC's service control dispatcher ([`run_as`]).
pub fn run(serve: ServeFn) -> Result<(), String> {
    run_as(&SERVERCTOPC, serve)
}

/// Runs the service control dispatcher; `serve` runs the server until its stop signal is
/// triggered. Returns when the service has stopped.
pub fn run_as(spec: &ServiceSpec, serve: ServeFn) -> Result<(), String> {
    *SERVE.lock().unwrap_or_else(|p| p.into_inner()) = Some((*spec, serve));
    windows_service::service_dispatcher::start(spec.name, ffi_service_main)
        .map_err(|e| format!("cannot start the service dispatcher: {e}"))
}

fn service_main(_args: Vec<OsString>) {
    let Some((spec, serve)) = SERVE.lock().unwrap_or_else(|p| p.into_inner()).take() else {
        tracing::error!("the service main ran without a serving function");
        return;
    };
    let stop = StopSignal::new();
    let trigger = stop.clone();
    let stopping = spec.stopping;
    let handler = move |control| match control {
        ServiceControl::Stop => {
            tracing::info!("service control: stop");
            trigger.trigger(stopping);
            ServiceControlHandlerResult::NoError
        }
        ServiceControl::Shutdown => {
            tracing::info!("service control: system shutdown");
            trigger.trigger("the system is shutting down");
            ServiceControlHandlerResult::NoError
        }
        ServiceControl::Interrogate => ServiceControlHandlerResult::NoError,
        _ => ServiceControlHandlerResult::NotImplemented,
    };
    let Ok(status) = service_control_handler::register(spec.name, handler) else {
        tracing::error!("cannot register the service control handler");
        return;
    };
    let report = |state: ServiceState, code: u32| {
        let _ = status.set_service_status(ServiceStatus {
            service_type: ServiceType::OWN_PROCESS,
            current_state: state,
            controls_accepted: if state == ServiceState::Running {
                ServiceControlAccept::STOP | ServiceControlAccept::SHUTDOWN
            } else {
                ServiceControlAccept::empty()
            },
            exit_code: ServiceExitCode::Win32(code),
            checkpoint: 0,
            wait_hint: Duration::from_secs(10),
            process_id: None,
        });
    };
    report(ServiceState::Running, 0);
    let code = match serve(stop) {
        Ok(()) => 0,
        Err(e) => {
            tracing::error!("the service failed: {e}");
            1
        }
    };
    report(ServiceState::Stopped, code);
}
