//! Which data source the server uses: the in-process simulation of the plant when
//! `SimulateCurrentData` is on (the embedded default; `SimulationDeviceDelay` makes its
//! device answers late), else the asix network client.

use asix_model::AsixNamespace;
use asix_net::inproc::InProcessSim;
use ctopc_core::source::{Backend, Wake};
use std::sync::Arc;

/// Seed of the simulated plant (deterministic values from start-up on).
const SIM_SEED: u64 = 0x5EED_A51C;

pub fn make(ns: &Arc<AsixNamespace>, wake: Arc<dyn Wake>) -> Result<Box<dyn Backend>, String> {
    let server = &ns.config().server;
    if server.simulate_current_data {
        tracing::info!("data source: simulation of current data (OPC_STATUS_TEST)");
        let delay = server.simulation_device_delay_ms;
        if delay > 0 {
            tracing::info!("simulation: device reads and writes answer after {delay} ms (SimulationDeviceDelay)");
        }
        let sim = InProcessSim::new(Arc::clone(ns), SIM_SEED, ctopc_com::clock::now())
            .with_device_delay(delay);
        return Ok(Box::new(sim));
    }
    tracing::info!("data source: the asix network");
    asix_net::datasource::network_backend(Arc::clone(ns), wake)
        .map_err(|e| format!("cannot start the asix network client: {e}"))
}
