//! Slow and hung callback clients end to end: a server of the test's
//! own (`SERVERCTOPC_INI`) with `CallbackTimeout = 500` and `CallbackFailures = 2`; a
//! client whose OnDataChange sleeps far longer than the timeout loses its callback
//! connection (the connection point lists none) with a WARN in the server's log, the
//! server does not queue callbacks behind its hung call, and another client of the same
//! server keeps getting its callbacks throughout.
//!
//! As `group_slow_source.rs`: waits until no other ServerCTOPC.exe runs, sets
//! `SERVERCTOPC_INI` before activating, and waits at the end until its server has exited.
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use e2e_tests::io_support::*;
use e2e_tests::server_config::{read_log, wait_until_no_server, write_demo_config};
use e2e_tests::{
    connections, interfaces::*, other_servers, wait_for_no_other_server, Apartment, PROGID,
};
use opc_client::{self as client, Server};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use windows::core::{implement, Interface, HRESULT};
use windows::Win32::Foundation::FILETIME;
use windows::Win32::System::Com::{IConnectionPoint, IConnectionPointContainer};
use windows::Win32::System::Variant::VARIANT;

/// Items of the demo plant whose simulated values change all the time.
const CHANGING: &[&str] = &["KW_A000", "KW_A001", "KW_A002", "KW_A003"];

/// A sink whose every call sleeps `delay_ms` and counts.
#[implement(IOPCDataCallback)]
struct SlowSink {
    delay_ms: Arc<AtomicU64>,
    calls: Arc<AtomicU64>,
}

impl SlowSink {
    fn called(&self) -> windows::core::Result<()> {
        self.calls.fetch_add(1, Ordering::SeqCst);
        std::thread::sleep(Duration::from_millis(self.delay_ms.load(Ordering::SeqCst)));
        Ok(())
    }
}

impl IOPCDataCallback_Impl for SlowSink_Impl {
    unsafe fn OnDataChange(
        &self,
        _: u32,
        _: u32,
        _: HRESULT,
        _: HRESULT,
        _: u32,
        _: *const u32,
        _: *const VARIANT,
        _: *const u16,
        _: *const FILETIME,
        _: *const HRESULT,
    ) -> windows::core::Result<()> {
        self.called()
    }
    unsafe fn OnReadComplete(
        &self,
        _: u32,
        _: u32,
        _: HRESULT,
        _: HRESULT,
        _: u32,
        _: *const u32,
        _: *const VARIANT,
        _: *const u16,
        _: *const FILETIME,
        _: *const HRESULT,
    ) -> windows::core::Result<()> {
        self.called()
    }
    unsafe fn OnWriteComplete(
        &self,
        _: u32,
        _: u32,
        _: HRESULT,
        _: u32,
        _: *const u32,
        _: *const HRESULT,
    ) -> windows::core::Result<()> {
        self.called()
    }
    unsafe fn OnCancelComplete(&self, _: u32, _: u32) -> windows::core::Result<()> {
        self.called()
    }
}

fn data_point(g: &TestGroup) -> IConnectionPoint {
    let cpc: IConnectionPointContainer = g.unknown.cast().expect("IConnectionPointContainer");
    // SAFETY: valid IID.
    unsafe { cpc.FindConnectionPoint(&IOPCDataCallback::IID) }.expect("FindConnectionPoint")
}

#[test]
fn a_hung_client_loses_its_callbacks_and_does_not_stall_another() {
    wait_for_no_other_server();
    let (dir, ini) = write_demo_config(
        "slow-clients",
        "ASIXConnect-ops.ini",
        "CallbackTimeout = 500\r\nCallbackFailures = 2\r\nFirstSampleWait = 0",
        "",
    );
    std::env::set_var("SERVERCTOPC_INI", &ini);
    let com = Apartment::mta().expect("MTA");
    let slow = Server::connect(PROGID).expect("the slow client");
    std::env::remove_var("SERVERCTOPC_INI");
    assert_eq!(other_servers(0).len(), 1, "only the test's server runs");
    slow.set_client_name("hung-client").unwrap();
    let fast = Server::connect(PROGID).expect("the other client");

    // The other client: a normal sink.
    let fast_group = group_with_items(&fast, "fast", CHANGING);
    let rec = Recorder::counting();
    client::advise_data_callback(&fast_group.unknown, &TestSink::create(&rec)).expect("Advise");

    // The hung client: every call sleeps 5 s (ten times the timeout).
    let delay = Arc::new(AtomicU64::new(5_000));
    let calls = Arc::new(AtomicU64::new(0));
    let slow_group = group_with_items(&slow, "slow", CHANGING);
    let sink: IOPCDataCallback = SlowSink {
        delay_ms: Arc::clone(&delay),
        calls: Arc::clone(&calls),
    }
    .into();
    let started = Instant::now();
    client::advise_data_callback(&slow_group.unknown, &sink).expect("Advise (slow)");

    // Its connection goes, with a warning: the first call passes its timeout (500 ms),
    // the next update would queue behind it and is refused instead: 2 failures.
    let cp = data_point(&slow_group);
    let deadline = Instant::now() + Duration::from_secs(15);
    while !connections(&cp).is_empty() {
        assert!(
            Instant::now() < deadline,
            "the hung client's sink was not dropped; log:\n{}",
            read_log(&dir)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let took = started.elapsed();
    eprintln!("hung client dropped after {} ms", took.as_millis());
    assert!(
        took >= Duration::from_millis(500),
        "dropped before its timeout"
    );
    let log = read_log(&dir);
    let warn = log
        .lines()
        .find(|l| l.contains("dropping its callback connections"))
        .unwrap_or_else(|| panic!("no warning in the log:\n{log}"));
    assert!(warn.contains("WARN"), "{warn}");
    assert!(warn.contains("client \"hung-client\""), "{warn}");
    assert!(warn.contains("500 ms"), "{warn}");
    assert_eq!(
        calls.load(Ordering::SeqCst),
        1,
        "nothing was queued behind the hung call"
    );

    // The other client was served all along and still is.
    let before = rec.data_changes.load(Ordering::SeqCst);
    assert!(before >= 1, "the other client got no callback");
    let deadline = Instant::now() + Duration::from_secs(10);
    while rec.data_changes.load(Ordering::SeqCst) < before + 2 {
        assert!(
            Instant::now() < deadline,
            "the other client's callbacks stopped"
        );
        std::thread::sleep(Duration::from_millis(100));
    }

    // The hung call still sleeps (nothing can interrupt it); the server did not wait.
    assert_eq!(calls.load(Ordering::SeqCst), 1);

    drop((slow_group, fast_group, slow, fast, sink, cp));
    drop(com);
    assert!(
        wait_until_no_server(Duration::from_secs(60)),
        "the test's server did not exit"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
