//! Which data source the server uses: the in-process simulation of the plant when
//! `SimulateCurrentData` is on (the embedded default; `SimulationDeviceDelay` makes its
//! device answers late), else the asix network client.
//!
//! The simulation starts deferred ([`Deferred`]): its per-variable state (a million
//! variables take about a second) is built on a thread of its own while the server already
//! serves, so that connecting and browsing do not wait for it; the first request that
//! needs the data source does.

use ctopc_core::model::datasource::SourceRequest;
use ctopc_core::source::{Backend, SourceOutput, Wake};
use ctopc_core::Timestamp;
use std::sync::Arc;
use std::thread::JoinHandle;

/// Seed of the simulated plant (deterministic values from start-up on).
const SIM_SEED: u64 = 0x5EED_A51C;

pub fn make(
    ns: &Arc<asix_model::AsixNamespace>,
    wake: Arc<dyn Wake>,
) -> Result<Box<dyn Backend>, String> {
    use asix_net::inproc::InProcessSim;
    let server = &ns.config().server;
    if server.simulate_current_data {
        tracing::info!("data source: simulation of current data (OPC_STATUS_TEST)");
        let delay = server.simulation_device_delay_ms;
        if delay > 0 {
            tracing::info!("simulation: device reads and writes answer after {delay} ms (SimulationDeviceDelay)");
        }
        let ns = Arc::clone(ns);
        return Deferred::start(true, wake, move || {
            let t = std::time::Instant::now();
            let sim = InProcessSim::new(ns, SIM_SEED, ctopc_runtime::clock::now())
                .with_device_delay(delay);
            tracing::info!("start: simulation ready in {} ms", t.elapsed().as_millis());
            Box::new(sim)
        });
    }
    tracing::info!("data source: the asix network");
    asix_net::datasource::network_backend(Arc::clone(ns), wake)
        .map_err(|e| format!("cannot start the asix network client: {e}"))
}

/// A data source built on a thread of its own: until it is there, `poll` hands out
/// nothing and `poll_timeout` asks for no step (the builder wakes the driver when it is
/// done); a `request` waits for it, so no request is lost or reordered.
pub struct Deferred {
    state: State,
    simulation: bool,
}

enum State {
    Building(Option<JoinHandle<Box<dyn Backend>>>),
    Ready(Box<dyn Backend>),
    /// The builder panicked: the source answers nothing (requests time out in the
    /// engine, `SourceTimeout`).
    Failed,
}

impl Deferred {
    /// Starts `build` on a thread named `data source`; `simulation` is what
    /// `is_simulation` answers meanwhile and after.
    pub fn start(
        simulation: bool,
        wake: Arc<dyn Wake>,
        build: impl FnOnce() -> Box<dyn Backend> + Send + 'static,
    ) -> Result<Box<dyn Backend>, String> {
        let handle = std::thread::Builder::new()
            .name("data source".into())
            .spawn(move || {
                let backend = build();
                wake.wake();
                backend
            })
            .map_err(|e| format!("cannot start the data source's thread: {e}"))?;
        Ok(Box::new(Deferred {
            state: State::Building(Some(handle)),
            simulation,
        }))
    }

    /// The built source, waiting for it when `wait`, else only if it is finished.
    fn ready(&mut self, wait: bool) -> Option<&mut Box<dyn Backend>> {
        if let State::Building(handle) = &mut self.state {
            if !wait && handle.as_ref().is_some_and(|h| !h.is_finished()) {
                return None;
            }
            self.state = match handle.take().map(JoinHandle::join) {
                Some(Ok(b)) => State::Ready(b),
                _ => {
                    tracing::error!(
                        "the data source could not be built (its thread ended in a panic): \
                         no values; device reads and writes fail after SourceTimeout"
                    );
                    State::Failed
                }
            };
        }
        match &mut self.state {
            State::Ready(b) => Some(b),
            _ => None,
        }
    }
}

impl Backend for Deferred {
    fn request(&mut self, now: Timestamp, req: SourceRequest) {
        if let Some(b) = self.ready(true) {
            b.request(now, req);
        }
    }

    fn poll(&mut self, now: Timestamp, out: &mut SourceOutput) {
        if let Some(b) = self.ready(false) {
            b.poll(now, out);
        }
    }

    fn poll_timeout(&self) -> Option<Timestamp> {
        match &self.state {
            State::Ready(b) => b.poll_timeout(),
            // The builder's wake brings the driver back; then `poll` takes the source.
            State::Building(_) | State::Failed => None,
        }
    }

    fn is_simulation(&self) -> bool {
        self.simulation
    }

    /// The built source's channels (the `_Diagnostics` branch); none while it builds.
    fn channels(&self) -> Vec<ctopc_core::diagnostics::ChannelStatus> {
        match &self.state {
            State::Ready(b) => b.channels(),
            State::Building(_) | State::Failed => Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ctopc_core::model::datasource::SourceReqId;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::mpsc;
    use std::sync::Mutex;

    /// A source that records its requests and answers each read with its count.
    struct Fake {
        requests: Arc<Mutex<Vec<String>>>,
    }

    impl Backend for Fake {
        fn request(&mut self, _now: Timestamp, req: SourceRequest) {
            self.requests
                .lock()
                .unwrap()
                .push(format!("{:?}", std::mem::discriminant(&req)));
        }
        fn poll(&mut self, _now: Timestamp, out: &mut SourceOutput) {
            let n = self.requests.lock().unwrap().len();
            out.read_results.push((SourceReqId(n as u64), Vec::new()));
        }
        fn poll_timeout(&self) -> Option<Timestamp> {
            Some(Timestamp(7))
        }
    }

    #[derive(Default)]
    struct Wakes(AtomicUsize);
    impl Wake for Wakes {
        fn wake(&self) {
            self.0.fetch_add(1, Ordering::SeqCst);
        }
    }

    #[test]
    fn nothing_is_polled_before_the_source_is_built_and_a_request_waits_for_it() {
        let requests = Arc::new(Mutex::new(Vec::new()));
        let wakes = Arc::new(Wakes::default());
        let (go, gate) = mpsc::channel::<()>();
        let r = Arc::clone(&requests);
        let mut d = Deferred::start(true, wakes.clone(), move || {
            gate.recv().unwrap();
            Box::new(Fake { requests: r })
        })
        .unwrap();
        assert!(d.is_simulation());
        let mut out = SourceOutput::default();
        d.poll(Timestamp(1), &mut out);
        assert!(out.is_empty());
        assert_eq!(d.poll_timeout(), None);
        assert_eq!(wakes.0.load(Ordering::SeqCst), 0);
        // The request blocks until the builder is let go.
        let release = std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(50));
            go.send(()).unwrap();
        });
        d.request(Timestamp(2), SourceRequest::Unsubscribe(Vec::new()));
        release.join().unwrap();
        assert_eq!(requests.lock().unwrap().len(), 1);
        assert_eq!(wakes.0.load(Ordering::SeqCst), 1);
        assert_eq!(d.poll_timeout(), Some(Timestamp(7)));
        d.poll(Timestamp(3), &mut out);
        assert_eq!(out.read_results.len(), 1);
        assert_eq!(out.read_results[0].0, SourceReqId(1));
    }

    /// A builder that panics leaves a source that answers nothing and never blocks: the
    /// request returns (the engine fails it after `SourceTimeout`, tests/model_io.rs), poll
    /// hands out nothing and asks for no step.
    #[test]
    fn a_failed_build_answers_nothing_and_blocks_nothing() {
        let wakes = Arc::new(Wakes::default());
        let mut d = Deferred::start(true, wakes, || -> Box<dyn Backend> {
            panic!("the test's builder fails")
        })
        .unwrap();
        // Returns although the builder failed (it joins the ended thread).
        d.request(Timestamp(1), SourceRequest::Unsubscribe(Vec::new()));
        let mut out = SourceOutput::default();
        d.poll(Timestamp(2), &mut out);
        assert!(out.is_empty());
        assert_eq!(d.poll_timeout(), None);
        assert!(d.channels().is_empty());
        assert!(d.is_simulation());
        // And again, with nothing left to join.
        d.request(Timestamp(3), SourceRequest::Unsubscribe(Vec::new()));
        d.poll(Timestamp(4), &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn a_finished_build_is_taken_by_poll_after_its_wake() {
        let requests = Arc::new(Mutex::new(Vec::new()));
        let wakes = Arc::new(Wakes::default());
        let r = Arc::clone(&requests);
        let mut d =
            Deferred::start(false, wakes.clone(), move || Box::new(Fake { requests: r })).unwrap();
        assert!(!d.is_simulation());
        let t = std::time::Instant::now();
        while wakes.0.load(Ordering::SeqCst) == 0 {
            assert!(
                t.elapsed().as_secs() < 10,
                "the builder never woke the driver"
            );
            std::thread::yield_now();
        }
        let mut out = SourceOutput::default();
        // The wake comes just before the thread ends: poll until it has taken the source.
        while d.poll_timeout().is_none() {
            assert!(t.elapsed().as_secs() < 10);
            d.poll(Timestamp(1), &mut out);
        }
        assert_eq!(d.poll_timeout(), Some(Timestamp(7)));
        assert!(!out.read_results.is_empty());
    }
}
