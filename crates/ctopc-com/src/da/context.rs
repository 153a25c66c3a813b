//! The context every COM object of one server works in: the runtime (engine + data source),
//! the namespace, the browse address space, the server state, the default language, the
//! group table (one identity per group) and the lifetime counts.
//!
//! There is no process-wide context: `host::start` makes one (`Arc<Context>`), the class
//! factory's constructor captures it, every server object holds it and hands it to its
//! groups. `ServerCTOPC.exe` makes one per process; the in-process tests make one per
//! test. When the last object of a context has gone, the context drops and stops its
//! runtime's driver thread (the callback workers end with their sessions).
//!
//! The COM layer knows no configuration file and no asix type: the server binary loads
//! the configuration (`crates/server/src/config.rs`) and hands over a [`Setup`] of plain
//! values and the core's [`Namespace`] trait.

use crate::com::connpoint::SinkSlot;
use crate::com::interfaces::IOPCDataCallback;
use crate::com::interfaces::{
    OPCSERVERSTATE, OPC_STATUS_NOCONFIG, OPC_STATUS_RUNNING, OPC_STATUS_TEST,
};
use crate::com::lifetime::Lifetime;
use ctopc_core::browse::AddressSpace;
use ctopc_core::model::EngineConfig;
use ctopc_core::model::GroupHandle;
use ctopc_core::namespace::Namespace;
use ctopc_core::Lang;
use ctopc_runtime::Runtime;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::{Mutex, MutexGuard};
use windows::core::IUnknown;
use windows::Win32::Globalization::{IsValidLocale, LCID_SUPPORTED};
use windows_core::Weak;

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
    /// The operations settings (write audit, write rights, ...).
    pub ops: ctopc_core::ops::OpsConfig,
    /// `[Server] LegacyOpenAccess`: the old open COM security instead of the AppID's
    /// (`host::init_server_security`).
    pub legacy_open_access: bool,
}

/// Everything the COM objects of one server share (made by `host::start`).
pub struct Context {
    pub runtime: Arc<Runtime>,
    pub namespace: Arc<dyn Namespace>,
    pub address_space: Arc<AddressSpace>,
    pub state: OPCSERVERSTATE,
    /// Why the state is OPC_STATUS_NOCONFIG, if it is.
    pub no_config_reason: Option<String>,
    pub default_lang: Lang,
    /// The live objects and LockServer locks that keep this server up, and its stop request.
    pub lifetime: Arc<Lifetime>,
    /// One COM identity per engine group (`crate::da::group`), one table per runtime.
    pub(crate) groups: GroupTable,
}

impl Context {
    /// The prologue of every timed COM method: the call's duration goes into the metrics
    /// when the returned guard drops (`let _t = self.ctx.timed(Method::AddItems);`).
    pub fn timed(&self, method: ctopc_core::metrics::Method) -> ctopc_runtime::clients::Timed<'_> {
        ctopc_runtime::clients::timed(&self.runtime.metrics, method)
    }

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

impl Drop for Context {
    /// The last object of this server has gone: its driver thread stops (joined here).
    fn drop(&mut self) {
        self.runtime.stop_driver();
    }
}

/// A group LCID the server accepts (see the module documentation): the one rule of
/// IOPCServer::AddGroup and IOPCGroupStateMgt::SetState (IOPCCommon::SetLocaleID is
/// stricter: only the languages QueryAvailableLocaleIDs lists, `Lang::from_lcid`).
pub(crate) fn lcid_accepted(lcid: u32) -> bool {
    // Ours: Polish, English and the default/neutral locales (whatever the default is).
    let ours = Lang::from_lcid(lcid, Lang::English).is_some();
    // SAFETY: plain value arguments.
    ours || unsafe { IsValidLocale(lcid, LCID_SUPPORTED) }.as_bool()
}

// ---------------------------------------------------------------------------------------
// The group table: one identity per group
// ---------------------------------------------------------------------------------------

pub(crate) struct Entry {
    /// The live COM object (dead once its last reference has gone).
    pub(crate) object: Weak<IUnknown>,
    /// Its callback slot: identifies the entry's object in `Drop`.
    pub(crate) slot: Arc<SinkSlot<IOPCDataCallback>>,
}

/// The group identities of one context (`Context::groups`).
#[derive(Default)]
pub struct GroupTable(Mutex<BTreeMap<GroupHandle, Entry>>);

impl GroupTable {
    pub(crate) fn lock(&self) -> MutexGuard<'_, BTreeMap<GroupHandle, Entry>> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }
}
