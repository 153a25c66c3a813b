//! Starting a server's runtime the same way for every front end: the `_Diagnostics`
//! branch beside the configured namespace and data source, the operations settings, and
//! the metrics endpoint.

use crate::frontend::ThreadHook;
use crate::Runtime;
use ctopc_core::browse::MatchCase;
use ctopc_core::diagnostics::backend::DiagBackend;
use ctopc_core::diagnostics::{Board, DiagNamespace, Sampler};
use ctopc_core::model::{Engine, EngineConfig};
use ctopc_core::namespace::Namespace;
use ctopc_core::ops::OpsConfig;
use ctopc_core::source::{Backend, Wake};
use std::sync::Arc;

/// What a front end serves from: the runtime, and the namespace with the `_Diagnostics`
/// branch beside the configured one.
pub struct Started {
    pub runtime: Arc<Runtime>,
    pub namespace: Arc<dyn Namespace>,
    /// The data source simulates current data (`Backend::is_simulation`).
    pub simulation: bool,
}

/// The data source's maker: it gets the waker to call when data arrives.
pub type MakeBackend<'a> = dyn FnOnce(Arc<dyn Wake>) -> Result<Box<dyn Backend>, String> + 'a;

/// Starts the engine over `namespace` and the data source `make_backend` makes, both
/// with the `_Diagnostics` branch beside them (`ctopc_core::diagnostics`: they read the
/// board the runtime publishes on; `filter_case`: how browsing matches names), applies
/// `ops` (the write rights to the engine, the rest to the clients' table) and starts the metrics endpoint when `ops` names an address.
pub fn start(
    namespace: Arc<dyn Namespace>,
    filter_case: MatchCase,
    engine_config: EngineConfig,
    ops: &OpsConfig,
    thread_hook: ThreadHook,
    make_backend: Box<MakeBackend<'_>>,
) -> Result<Started, String> {
    let board = Arc::new(Board::new());
    let sampler = Sampler::new(filter_case);
    let namespace: Arc<dyn Namespace> = Arc::new(DiagNamespace::new(namespace, Arc::clone(&board)));
    let mut engine = Engine::new(engine_config, Arc::clone(&namespace));
    engine.set_write_rights(Arc::clone(&ops.write_rights));
    if ops.write_rights.is_open() {
        tracing::info!("write rights: no [WriteRights] policy, every connected client may write");
    } else {
        tracing::info!(
            "write rights: [WriteRights] policy with {} entries",
            ops.write_rights.rules().len()
        );
    }
    let mut simulation = false;
    let for_backend = Arc::clone(&board);
    let runtime = Runtime::start(engine, (board, sampler), thread_hook, |wake| {
        let backend = make_backend(wake)?;
        simulation = backend.is_simulation();
        Ok(Box::new(DiagBackend::new(backend, for_backend)))
    })?;
    runtime.clients.configure(ops);
    if let Some(address) = &ops.metrics_address {
        crate::metrics_http::start(&runtime, address);
    }
    if !ops.audit_writes {
        tracing::info!("write audit off (AuditWrites)");
    }
    Ok(Started {
        runtime,
        namespace,
        simulation,
    })
}
