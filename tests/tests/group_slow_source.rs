//! A slow data source end to end: the server started with a configuration of the test's
//! own (`SERVERCTOPC_INI`) whose simulation answers device reads and writes late
//! (`SimulationDeviceDelay`), with a short engine source timeout (`SourceTimeout`).
//!
//! - Device slower than the timeout: IOPCSyncIO::Read from DEVICE, IOPCSyncIO2::ReadMaxAge
//!   and IOPCSyncIO::Write return S_FALSE with ASKOM_E_NetAnswerTimeout per item after
//!   about the timeout (not the device's delay, not the COM layer's own give-up time);
//!   an asynchronous read completes the same way in OnReadComplete.
//! - Device slower than the call but within the timeout: a synchronous DEVICE read waits
//!   for the late answer; Cancel2 (through IOPCAsyncIO2 and IOPCAsyncIO3) of reads,
//!   writes and refreshes still waiting for the device gives OnCancelComplete with the
//!   client's transaction ID and group handle, and nothing else for that transaction;
//!   cancelling again is E_FAIL. (group_async.rs cannot count on this: the default
//!   simulation answers at once, so there Cancel2 races the completion.)
//!
//! Each test waits until no other ServerCTOPC.exe runs (an activation would reach it),
//! sets `SERVERCTOPC_INI` before activating (under Wine the server COM starts inherits the
//! client's environment; the server's log, written next to the ini, proves which file it
//! used), and at the end releases everything and waits until its server has exited, so
//! that later tests get a server with the default configuration.
#![cfg(windows)]

use ctopc_com::clock::now;
use ctopc_core::model::ItemVqt;
use ctopc_core::{OpcError, Value};
use e2e_tests::io_support::*;
use e2e_tests::server_config::{wait_until_no_server, write_demo_config};
use e2e_tests::{
    assert_alive, code, connect, interfaces::*, other_servers, wait_for_no_other_server, Apartment,
    Server,
};
use opc_client as client;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use windows::core::HRESULT;
use windows::Win32::Foundation::{E_FAIL, S_FALSE, S_OK};

const GROUP_CLIENT_HANDLE: u32 = 5151;
/// Read-only tank level and a writable setpoint of the demo plant.
const LEVEL: &str = "KW_A000";
const SETPOINT: &str = "KW_A110";
const NET_ANSWER_TIMEOUT: HRESULT = HRESULT(OpcError::NetAnswerTimeout.hresult());
const GOOD: u16 = 0xC0;
const WAIT: Duration = Duration::from_secs(10);

/// The tests of this file each start a server with their own configuration: one at a time
/// even when the test harness runs threads.
static ONE_SERVER_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The test's server, its group (LEVEL and SETPOINT, client handles 1 and 2) and sink.
struct Plant {
    server: Server,
    group: TestGroup,
    h: Vec<u32>,
    rec: Arc<Recorder>,
}

struct SlowServer {
    p: Option<Plant>,
    dir: PathBuf,
    _com: Apartment,
    _serial: MutexGuard<'static, ()>,
}

impl SlowServer {
    /// Starts a server of its own with `server_options` and makes the group.
    fn start(name: &str, server_options: &str) -> SlowServer {
        let serial = ONE_SERVER_AT_A_TIME
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        wait_for_no_other_server();
        let (dir, ini) = write_demo_config(
            name,
            "ASIXConnect-slow.ini",
            server_options,
            "CheckLimits = tak\r\nCheckControlVariables = tak\r\n",
        );
        std::env::set_var("SERVERCTOPC_INI", &ini);
        let since = now();
        let (com, server) = connect();
        // The server has started (its class object is registered): later activations
        // from this process, if any, should not inherit the test's configuration.
        std::env::remove_var("SERVERCTOPC_INI");
        let status = server.status().expect("GetStatus");
        assert!(
            status.start_time >= since,
            "connected to a server started before the test"
        );
        assert_eq!(other_servers(0).len(), 1, "only the test's server runs");
        assert_eq!(
            status.state, OPC_STATUS_TEST.0 as u32,
            "the simulation runs"
        );

        let group = add_group(&server, name, true, 1000, GROUP_CLIENT_HANDLE).expect("AddGroup");
        let h = add_ok(
            &group,
            &[
                ItemSpec {
                    id: LEVEL,
                    client: 1,
                    vt: 0,
                    active: true,
                },
                ItemSpec {
                    id: SETPOINT,
                    client: 2,
                    vt: 0,
                    active: true,
                },
            ],
        );
        let rec = Recorder::recording();
        client::advise_data_callback(&group.unknown, &TestSink::create(&rec))
            .expect("Advise(IOPCDataCallback)");
        SlowServer {
            p: Some(Plant {
                server,
                group,
                h,
                rec,
            }),
            dir,
            _com: com,
            _serial: serial,
        }
    }

    fn p(&self) -> &Plant {
        self.p.as_ref().expect("plant")
    }

    /// Releases everything, waits until the test's server has exited, and returns its log.
    fn finish(mut self) -> String {
        drop(self.p.take());
        assert!(
            wait_until_no_server(Duration::from_secs(30)),
            "the test's server did not exit after its client left"
        );
        let mut log = String::new();
        for entry in std::fs::read_dir(self.dir.join("Log"))
            .expect("the server logs into LogDirectory next to the ini")
            .flatten()
        {
            log.push_str(&std::fs::read_to_string(entry.path()).unwrap_or_default());
        }
        log
    }
}

impl Drop for SlowServer {
    /// On a failure: still release and give the server time to exit for the next tests.
    fn drop(&mut self) {
        if let Some(p) = self.p.take() {
            drop(p);
            let _ = wait_until_no_server(Duration::from_secs(30));
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

fn wait_tx(p: &Plant, transaction: u32) -> Callback {
    p.rec
        .wait_for(WAIT, |c| c.transaction() == transaction)
        .unwrap_or_else(|| {
            panic!(
                "no callback with transaction {transaction}; got {:?}",
                p.rec.all()
            )
        })
}

/// The callbacks of `transaction` so far.
fn callbacks_of(p: &Plant, transaction: u32) -> Vec<Callback> {
    p.rec
        .all()
        .into_iter()
        .filter(|c| c.transaction() == transaction)
        .collect()
}

fn timed<T>(f: impl FnOnce() -> T) -> (T, Duration) {
    let t = Instant::now();
    let r = f();
    (r, t.elapsed())
}

/// A call that must end at the engine's source timeout: after it, well before the
/// device's answer and before the COM layer's own limit (timeout + 2 s).
fn assert_at_the_timeout(what: &str, took: Duration, timeout_ms: u64) {
    eprintln!(
        "{what}: {} ms (SourceTimeout {timeout_ms} ms)",
        took.as_millis()
    );
    assert!(
        took >= Duration::from_millis(timeout_ms - 50),
        "{what} answered before the timeout: {took:?}"
    );
    assert!(
        took < Duration::from_millis(timeout_ms + 1500),
        "{what} answered long after the timeout: {took:?}"
    );
}

fn assert_log_names_the_ini(log: &str, dir: &Path) {
    assert!(
        log.contains("(from SERVERCTOPC_INI)"),
        "the server did not use SERVERCTOPC_INI; log in {}:\n{log}",
        dir.display()
    );
    assert!(log.contains("ASIXConnect-slow.ini"), "{log}");
    assert!(log.contains("SimulationDeviceDelay"), "{log}");
}

#[test]
fn a_device_slower_than_the_source_timeout_fails_items_with_net_answer_timeout() {
    const TIMEOUT_MS: u64 = 1000;
    let s = SlowServer::start(
        "slow-timeout",
        "SourceTimeout = 1000\r\nSimulationDeviceDelay = 3000",
    );
    let p = s.p();

    // The first OnDataChange carries the items' first samples, not BAD Waiting
    // for Initial Data (0x20), also with a device that answers reads 3 s late (the
    // subscription's samples are not delayed).
    let first = p
        .rec
        .wait_for(WAIT, |c| {
            matches!(c, Callback::DataChange { transaction: 0, items, .. } if !items.is_empty())
        })
        .expect("the first OnDataChange");
    let Callback::DataChange { items, .. } = first else {
        unreachable!()
    };
    assert_eq!(
        items.len(),
        2,
        "both items in the first callback: {items:?}"
    );
    assert!(
        items
            .iter()
            .all(|i| i.quality != 0x20 && i.value != Value::Empty),
        "{items:?}"
    );

    let ((hr, items), took) =
        timed(|| client::sync_read(&p.group.sync(), OPC_DS_DEVICE, &p.h).expect("Read(DEVICE)"));
    assert_at_the_timeout("IOPCSyncIO::Read(DEVICE)", took, TIMEOUT_MS);
    assert_eq!(hr, S_FALSE);
    assert_eq!(
        items.iter().map(|i| i.error).collect::<Vec<_>>(),
        vec![NET_ANSWER_TIMEOUT; 2],
        "{items:?}"
    );
    assert!(items.iter().all(|i| i.quality & 0xC0 != GOOD), "{items:?}");

    let ((hr, items), took) = timed(|| {
        client::read_max_age(&p.group.sync2(), &[(p.h[0], 0), (p.h[1], 0)]).expect("ReadMaxAge(0)")
    });
    assert_at_the_timeout("IOPCSyncIO2::ReadMaxAge(0)", took, TIMEOUT_MS);
    assert_eq!(
        (hr, items.iter().map(|i| i.error).collect::<Vec<_>>()),
        (S_FALSE, vec![NET_ANSWER_TIMEOUT; 2])
    );

    let ((hr, errors), took) =
        timed(|| client::sync_write(&p.group.sync(), &[(p.h[1], Value::R4(6.5))]).expect("Write"));
    assert_at_the_timeout("IOPCSyncIO::Write", took, TIMEOUT_MS);
    assert_eq!((hr, errors), (S_FALSE, vec![NET_ANSWER_TIMEOUT]));

    // Meanwhile the cache answers at once.
    let ((hr, _), took) =
        timed(|| client::sync_read(&p.group.sync(), OPC_DS_CACHE, &p.h).expect("Read(CACHE)"));
    assert_eq!(hr, S_OK);
    assert!(
        took < Duration::from_millis(500),
        "a cache read waits for nothing: {took:?}"
    );

    // Asynchronously: OnReadComplete with the same per-item code, at the timeout.
    let (hr, _, errors) = client::async_read(&p.group.async2(), &p.h, 11).expect("async Read");
    assert_eq!((hr, errors), (S_OK, vec![S_OK; 2]));
    let (c, took) = timed(|| wait_tx(p, 11));
    assert_at_the_timeout("IOPCAsyncIO2::Read -> OnReadComplete", took, TIMEOUT_MS);
    let Callback::ReadComplete {
        group,
        master_error,
        items,
        ..
    } = c
    else {
        panic!("{c:?}")
    };
    assert_eq!((group, master_error), (GROUP_CLIENT_HANDLE, S_FALSE));
    assert_eq!(
        items.iter().map(|i| i.error).collect::<Vec<_>>(),
        vec![NET_ANSWER_TIMEOUT; 2],
        "{items:?}"
    );

    // Cancelled before the timeout: OnCancelComplete instead.
    let (_, cancel, _) = client::async_read(&p.group.async2(), &p.h, 12).expect("async Read");
    // SAFETY: plain value.
    unsafe { p.group.async2().Cancel2(cancel) }.expect("Cancel2 of a read waiting for the device");
    assert_eq!(
        wait_tx(p, 12),
        Callback::CancelComplete {
            transaction: 12,
            group: GROUP_CLIENT_HANDLE
        }
    );

    // The device's late answers (3 s after each request) change nothing.
    std::thread::sleep(Duration::from_millis(3_500));
    assert_eq!(callbacks_of(p, 11).len(), 1, "{:?}", p.rec.all());
    assert_eq!(callbacks_of(p, 12).len(), 1, "{:?}", p.rec.all());
    assert_eq!(
        // SAFETY: plain value.
        code(&unsafe { p.group.async2().Cancel2(cancel) }),
        E_FAIL,
        "cancelled already"
    );
    assert_alive(&p.server);

    let dir = s.dir.clone();
    let log = s.finish();
    assert_log_names_the_ini(&log, &dir);
    assert!(log.contains("SourceTimeout"), "{log}");
}

#[test]
fn cancel2_of_operations_waiting_for_a_slow_device_sends_on_cancel_complete_only() {
    const DELAY_MS: u64 = 1500;
    let s = SlowServer::start(
        "slow-cancel",
        "SourceTimeout = 8000\r\nSimulationDeviceDelay = 1500",
    );
    let p = s.p();
    let io2 = p.group.async2();
    let io3 = p.group.async3();

    // A synchronous device read waits for the late answer, which is the answer.
    let ((hr, items), took) =
        timed(|| client::sync_read(&p.group.sync(), OPC_DS_DEVICE, &p.h).expect("Read(DEVICE)"));
    eprintln!(
        "IOPCSyncIO::Read(DEVICE) with SimulationDeviceDelay {DELAY_MS} ms: {} ms",
        took.as_millis()
    );
    assert!(
        took >= Duration::from_millis(DELAY_MS - 50)
            && took < Duration::from_millis(DELAY_MS + 1500),
        "{took:?}"
    );
    assert_eq!(hr, S_OK, "{items:?}");
    assert!(
        items
            .iter()
            .all(|i| i.error == S_OK && i.quality & 0xC0 == GOOD),
        "{items:?}"
    );

    // Every kind of operation that waits for the device, cancelled at once: through
    // IOPCAsyncIO2 (Read, Write, Refresh2 from DEVICE) and IOPCAsyncIO3 (ReadMaxAge,
    // WriteVQT, RefreshMaxAge).
    type Start<'a> = Box<dyn Fn(u32) -> u32 + 'a>;
    let starts: Vec<(u32, &str, Start)> = vec![
        (
            21,
            "IOPCAsyncIO2::Read",
            Box::new(|t| client::async_read(&io2, &p.h, t).expect("Read").1),
        ),
        (
            22,
            "IOPCAsyncIO2::Write",
            Box::new(|t| {
                client::async_write(&io2, &[(p.h[1], Value::R4(2.5))], t)
                    .expect("Write")
                    .1
            }),
        ),
        (
            23,
            "IOPCAsyncIO2::Refresh2(DEVICE)",
            Box::new(|t| client::refresh2(&io2, OPC_DS_DEVICE, t).expect("Refresh2")),
        ),
        (
            24,
            "IOPCAsyncIO3::ReadMaxAge(0)",
            Box::new(|t| {
                client::async_read_max_age(&io3, &[(p.h[0], 0), (p.h[1], 0)], t)
                    .expect("ReadMaxAge")
                    .1
            }),
        ),
        (
            25,
            "IOPCAsyncIO3::WriteVQT",
            Box::new(|t| {
                client::async_write_vqt(&io3, &[(p.h[1], ItemVqt::value(Value::R4(3.5)))], t)
                    .expect("WriteVQT")
                    .1
            }),
        ),
        (
            26,
            "IOPCAsyncIO3::RefreshMaxAge(0)",
            Box::new(|t| client::refresh_max_age(&io3, 0, t).expect("RefreshMaxAge")),
        ),
    ];
    let t0 = Instant::now();
    let mut cancels = Vec::new();
    for (tid, what, start) in &starts {
        let cancel = start(*tid);
        assert_ne!(cancel, 0, "{what}");
        // Cancel2 through the interface of the call (IOPCAsyncIO3 inherits it).
        // SAFETY: plain value.
        let r = unsafe {
            if *tid < 24 {
                io2.Cancel2(cancel)
            } else {
                io3.Cancel2(cancel)
            }
        };
        assert_eq!(
            code(&r),
            S_OK,
            "Cancel2 of {what}, still waiting for the device"
        );
        assert_eq!(
            wait_tx(p, *tid),
            Callback::CancelComplete {
                transaction: *tid,
                group: GROUP_CLIENT_HANDLE
            },
            "{what}"
        );
        cancels.push((*tid, *what, cancel));
    }
    eprintln!(
        "{} operations cancelled in {} ms",
        cancels.len(),
        t0.elapsed().as_millis()
    );
    assert!(
        t0.elapsed() < Duration::from_millis(DELAY_MS),
        "the cancels must beat the device; took {:?}",
        t0.elapsed()
    );

    // Not cancelled: OnReadComplete with good values once the device answers.
    let (_, _, errors) = client::async_read(&io2, &p.h, 27).expect("Read");
    assert_eq!(errors, vec![S_OK; 2]);
    let (c, took) = timed(|| wait_tx(p, 27));
    eprintln!(
        "IOPCAsyncIO2::Read -> OnReadComplete with SimulationDeviceDelay {DELAY_MS} ms: {} ms",
        took.as_millis()
    );
    let Callback::ReadComplete {
        group,
        master_error,
        items,
        ..
    } = c
    else {
        panic!("{c:?}")
    };
    assert_eq!(
        (group, master_error),
        (GROUP_CLIENT_HANDLE, S_OK),
        "{items:?}"
    );
    assert!(took >= Duration::from_millis(DELAY_MS - 50), "{took:?}");

    // By now every cancelled operation's device answer has come (and gone): nothing but
    // the OnCancelComplete for any of them, and a second Cancel2 fails.
    std::thread::sleep(Duration::from_millis(500));
    for (tid, what, cancel) in &cancels {
        assert_eq!(
            callbacks_of(p, *tid),
            vec![Callback::CancelComplete {
                transaction: *tid,
                group: GROUP_CLIENT_HANDLE
            }],
            "{what}"
        );
        assert_eq!(
            // SAFETY: plain value.
            code(&unsafe { io2.Cancel2(*cancel) }),
            E_FAIL,
            "{what} cancelled already"
        );
    }
    assert_alive(&p.server);
    // The group's interface pointers keep the group, and so the server, alive.
    drop(starts);
    drop((io2, io3));

    let dir = s.dir.clone();
    let log = s.finish();
    assert_log_names_the_ini(&log, &dir);
}

#[test]
fn a_missing_serverctopc_ini_stops_the_server_with_the_error() {
    let _serial = ONE_SERVER_AT_A_TIME
        .lock()
        .unwrap_or_else(|p| p.into_inner());
    wait_for_no_other_server();
    let _com = Apartment::mta().expect("CoInitializeEx");
    let missing = format!("C:\\ServerCTOPC-test-{}\\missing.ini", std::process::id());
    std::env::set_var("SERVERCTOPC_INI", &missing);
    let (r, took) = timed(|| Server::connect(e2e_tests::PROGID));
    std::env::remove_var("SERVERCTOPC_INI");
    // The activation fails (Wine's CoCreateInstance answers E_NOINTERFACE as soon as the
    // server it started has exited): no server, and the reason in the log.
    let Err(e) = r else {
        panic!("a server started without its configuration file")
    };
    eprintln!(
        "activation with a missing SERVERCTOPC_INI: {:?} after {} ms",
        e.code(),
        took.as_millis()
    );
    assert!(
        wait_until_no_server(Duration::from_secs(30)),
        "a server still runs"
    );
    // Without a configuration no log directory is known: the install folder's Log.
    let mut log = String::new();
    for entry in std::fs::read_dir(e2e_tests::artifact("Log"))
        .expect("the install folder's Log")
        .flatten()
    {
        log.push_str(&std::fs::read_to_string(entry.path()).unwrap_or_default());
    }
    assert!(
        log.contains(&format!("cannot start: SERVERCTOPC_INI: {missing}")),
        "{log}"
    );
}
