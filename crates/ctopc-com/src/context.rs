//! The process context every COM object works in: the runtime (engine + data source), the
//! namespace, the browse address space, the server state and the default language.
//!
//! The COM layer knows no configuration file and no asix type: the server binary loads
//! the configuration (`crates/server/src/config.rs`) and hands over a [`Setup`] of plain
//! values and the core's [`Namespace`] trait.

use crate::interfaces::{OPCSERVERSTATE, OPC_STATUS_NOCONFIG, OPC_STATUS_RUNNING, OPC_STATUS_TEST};
use crate::runtime::Runtime;
use ctopc_core::browse::AddressSpace;
use ctopc_core::model::EngineConfig;
use ctopc_core::namespace::Namespace;
use ctopc_core::Lang;
use std::sync::{Arc, OnceLock};

/// What the server binary hands the COM host to serve: the namespace and what the COM
/// layer needs of the configuration, as plain values.
pub struct Setup {
    pub namespace: Arc<dyn Namespace>,
    /// The browse tree (`IOPCBrowseServerAddressSpace`, `IOPCBrowse`).
    pub address_space: Arc<AddressSpace>,
    /// The engine's options (minimum update rate, data source timeout, ...).
    pub engine_config: EngineConfig,
    /// The configured default language; `None`: the system's (Polish on Polish Windows,
    /// else English).
    pub default_language: Option<Lang>,
    /// Why the server has no configuration (OPC_STATUS_NOCONFIG), if it has none.
    pub no_config_reason: Option<String>,
}

/// Everything COM objects share.
pub struct Context {
    pub runtime: Arc<Runtime>,
    pub namespace: Arc<dyn Namespace>,
    pub address_space: Arc<AddressSpace>,
    pub state: OPCSERVERSTATE,
    /// Why the state is OPC_STATUS_NOCONFIG, if it is.
    pub no_config_reason: Option<String>,
    pub default_lang: Lang,
}

impl Context {
    /// The state the configuration and the data source imply: NOCONFIG when there is no
    /// configuration (`no_config_reason`), TEST when the backend simulates current data
    /// ([`Backend::is_simulation`](ctopc_core::source::Backend::is_simulation)), else RUNNING.
    pub fn state_for(no_config_reason: Option<&str>, simulation: bool) -> OPCSERVERSTATE {
        if no_config_reason.is_some() {
            OPC_STATUS_NOCONFIG
        } else if simulation {
            OPC_STATUS_TEST
        } else {
            OPC_STATUS_RUNNING
        }
    }
}

static CONTEXT: OnceLock<Context> = OnceLock::new();

/// Installs the process context (once per process).
pub fn install(ctx: Context) -> Result<&'static Context, String> {
    CONTEXT
        .set(ctx)
        .map_err(|_| "the server context is already installed".to_string())?;
    CONTEXT
        .get()
        .ok_or_else(|| "the server context is missing".to_string())
}

/// The process context, once the server has started.
pub fn get() -> Option<&'static Context> {
    CONTEXT.get()
}
