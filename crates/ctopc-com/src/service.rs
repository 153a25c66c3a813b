//! ServerCTOPC as an NT service: installation (on demand, as LocalService; COM starts it
//! when a client activates the server because the AppID names it in `LocalService`),
//! removal, and the service main, which serves until the service control manager stops
//! it and then sends IOPCShutdown to every connected client: the control handler only
//! triggers the [`StopSignal`] it hands to the serving function.

use crate::lifetime::StopSignal;
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

fn service_info(exe: &Path) -> ServiceInfo {
    ServiceInfo {
        name: OsString::from(SERVICE_NAME),
        display_name: OsString::from(DISPLAY_NAME),
        service_type: ServiceType::OWN_PROCESS,
        start_type: ServiceStartType::OnDemand,
        error_control: ServiceErrorControl::Normal,
        executable_path: exe.to_path_buf(),
        launch_arguments: vec![OsString::from(SERVICE_SWITCH)],
        dependencies: vec![],
        account_name: Some(OsString::from(ACCOUNT)),
        account_password: None,
    }
}

/// Creates the service, or updates its configuration when it exists (idempotent).
pub fn install(exe: &Path) -> Result<(), String> {
    let manager = ServiceManager::local_computer(
        None::<&str>,
        ServiceManagerAccess::CONNECT | ServiceManagerAccess::CREATE_SERVICE,
    )
    .map_err(|e| format!("cannot open the service control manager (run as administrator): {e}"))?;
    let info = service_info(exe);
    match manager.open_service(SERVICE_NAME, ServiceAccess::CHANGE_CONFIG) {
        Ok(existing) => existing
            .change_config(&info)
            .map_err(|e| format!("cannot update the service {SERVICE_NAME}: {e}"))?,
        Err(_) => {
            let created = manager
                .create_service(&info, ServiceAccess::CHANGE_CONFIG)
                .map_err(|e| format!("cannot create the service {SERVICE_NAME}: {e}"))?;
            // Not every service manager supports descriptions (Wine's does); not fatal.
            let _ = created.set_description(DESCRIPTION);
        }
    }
    Ok(())
}

/// Stops and deletes the service; succeeds quietly when it does not exist.
pub fn uninstall() -> Result<(), String> {
    let Ok(manager) = ServiceManager::local_computer(None::<&str>, ServiceManagerAccess::CONNECT)
    else {
        return Ok(());
    };
    let Ok(service) = manager.open_service(
        SERVICE_NAME,
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
        .map_err(|e| format!("cannot delete the service {SERVICE_NAME}: {e}"))
}

/// Serves until the given signal is triggered (the service control manager's stop or a
/// system shutdown).
pub type ServeFn = Box<dyn FnOnce(StopSignal) -> Result<(), String> + Send>;

/// The serving function for the service main. The service main is a plain function the
/// dispatcher calls with no user data, so this process-level hook is unavoidable; it holds
/// only the function handed to [`run`], taken once.
static SERVE: std::sync::Mutex<Option<ServeFn>> = std::sync::Mutex::new(None);

windows_service::define_windows_service!(ffi_service_main, service_main);

/// Runs the service control dispatcher; `serve` runs the server until its stop signal is
/// triggered. Returns when the service has stopped.
pub fn run(serve: ServeFn) -> Result<(), String> {
    *SERVE.lock().unwrap_or_else(|p| p.into_inner()) = Some(serve);
    windows_service::service_dispatcher::start(SERVICE_NAME, ffi_service_main)
        .map_err(|e| format!("cannot start the service dispatcher: {e}"))
}

fn service_main(_args: Vec<OsString>) {
    let stop = StopSignal::new();
    let trigger = stop.clone();
    let handler = move |control| match control {
        ServiceControl::Stop => {
            tracing::info!("service control: stop");
            trigger.trigger("the ServerCTOPC service is stopping");
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
    let Ok(status) = service_control_handler::register(SERVICE_NAME, handler) else {
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
    let serve = SERVE.lock().unwrap_or_else(|p| p.into_inner()).take();
    let code = match serve.map(|f| f(stop)) {
        Some(Ok(())) => 0,
        Some(Err(e)) => {
            tracing::error!("the service failed: {e}");
            1
        }
        None => 1,
    };
    report(ServiceState::Stopped, code);
}
