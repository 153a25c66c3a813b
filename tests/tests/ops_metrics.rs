//! The metrics endpoint end to end: a server of the test's own
//! (`SERVERCTOPC_INI`) with `MetricsAddress = 127.0.0.1:<port>` answers an HTTP GET of
//! `/metrics` from the test (Wine's sockets are the host's) with the Prometheus text of
//! what a working client did: clients, groups, items, callbacks and values sent, writes,
//! call-duration histograms per COM method; other paths are 404, what is not HTTP 400,
//! an endless request head 431; an idle connection to the endpoint does not hold up the
//! OPC server. The same server has `AuditWrites = nie`: its client's write is not audited.
//!
//! As `group_slow_source.rs`: waits until no other ServerCTOPC.exe runs, sets
//! `SERVERCTOPC_INI` before activating, and waits at the end until its server has exited.
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_core::Value;
use e2e_tests::io_support::*;
use e2e_tests::server_config::{read_log, wait_until_no_server, write_demo_config};
use e2e_tests::{other_servers, wait_for_no_other_server, Apartment, PROGID};
use opc_client::{self as client, Server};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use windows::Win32::Foundation::S_OK;

/// Items of the demo plant whose simulated values change all the time.
const CHANGING: &[&str] = &["KW_A000", "KW_A001"];
/// A writable setpoint.
const SETPOINT: &str = "KW_A110";

/// Sends `request` to the endpoint and returns the whole answer (the server closes).
fn http(port: u16, request: &[u8]) -> String {
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut s = loop {
        match TcpStream::connect(("127.0.0.1", port)) {
            Ok(s) => break s,
            Err(e) => {
                assert!(
                    Instant::now() < deadline,
                    "cannot connect to the metrics port: {e}"
                );
                std::thread::sleep(Duration::from_millis(200));
            }
        }
    };
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(request).unwrap();
    let mut answer = Vec::new();
    let _ = s.read_to_end(&mut answer);
    String::from_utf8_lossy(&answer).into_owned()
}

/// The value of the sample line `name` (exactly, labels included).
fn sample(text: &str, name: &str) -> u64 {
    text.lines()
        .find_map(|l| l.strip_prefix(name).and_then(|r| r.strip_prefix(' ')))
        .unwrap_or_else(|| panic!("no {name} in\n{text}"))
        .trim()
        .parse::<f64>()
        .unwrap() as u64
}

#[test]
fn the_metrics_endpoint_shows_what_a_client_does() {
    wait_for_no_other_server();
    let port = 19_000 + (std::process::id() % 1000) as u16;
    let (dir, ini) = write_demo_config(
        "metrics",
        "ASIXConnect-ops.ini",
        &format!("MetricsAddress = 127.0.0.1:{port}\r\nFirstSampleWait = 0\r\nAuditWrites = nie"),
        "",
    );
    std::env::set_var("SERVERCTOPC_INI", &ini);
    let com = Apartment::mta().expect("MTA");
    let server = Server::connect(PROGID).expect("connect");
    std::env::remove_var("SERVERCTOPC_INI");
    assert_eq!(other_servers(0).len(), 1, "only the test's server runs");

    let group = group_with_items(&server, "metrics", CHANGING);
    let rec = Recorder::counting();
    client::advise_data_callback(&group.unknown, &TestSink::create(&rec)).expect("Advise");
    let deadline = Instant::now() + Duration::from_secs(10);
    while rec.data_changes.load(Ordering::SeqCst) == 0 {
        assert!(Instant::now() < deadline, "no OnDataChange");
        std::thread::sleep(Duration::from_millis(100));
    }
    let h = add_ok(
        &group,
        &[ItemSpec {
            id: SETPOINT,
            client: 99,
            vt: 0,
            active: false,
        }],
    );
    let (hr, _) = client::sync_write(&group.sync(), &[(h[0], Value::R4(3.0))]).expect("Write");
    assert_eq!(hr, S_OK);

    let answer = http(port, b"GET /metrics HTTP/1.1\r\nHost: localhost\r\n\r\n");
    let (head, text) = answer
        .split_once("\r\n\r\n")
        .unwrap_or_else(|| panic!("not HTTP: {answer:?}; log:\n{}", read_log(&dir)));
    assert!(head.starts_with("HTTP/1.1 200 OK"), "{head}");
    assert!(
        head.contains("Content-Type: text/plain; version=0.0.4"),
        "{head}"
    );
    assert_eq!(sample(text, "ctopc_clients"), 1);
    assert_eq!(sample(text, "ctopc_groups"), 1);
    assert_eq!(sample(text, "ctopc_items"), 3);
    assert!(sample(text, "ctopc_callbacks_total{kind=\"OnDataChange\"}") >= 1);
    assert!(sample(text, "ctopc_values_sent_total") >= 1);
    assert_eq!(sample(text, "ctopc_writes_total"), 1);
    assert_eq!(
        sample(
            text,
            "ctopc_call_duration_seconds_count{method=\"IOPCSyncIO::Write\"}"
        ),
        1
    );
    assert_eq!(
        sample(
            text,
            "ctopc_call_duration_seconds_count{method=\"IOPCItemMgt::AddItems\"}"
        ),
        2
    );
    assert_eq!(
        sample(
            text,
            "ctopc_call_duration_seconds_count{method=\"IOPCServer::AddGroup\"}"
        ),
        1
    );
    assert!(sample(text, "ctopc_callback_duration_seconds_count") >= 1);
    assert_eq!(
        sample(text, "ctopc_callback_duration_seconds_bucket{le=\"+Inf\"}"),
        sample(text, "ctopc_callback_duration_seconds_count")
    );
    assert!(sample(text, "ctopc_uptime_seconds") < 600);

    // Anything else: 404, 400, 431.
    assert!(http(port, b"GET / HTTP/1.1\r\n\r\n").starts_with("HTTP/1.1 404"));
    assert!(http(port, b"POST /metrics HTTP/1.1\r\n\r\n").starts_with("HTTP/1.1 404"));
    assert!(http(port, b"hello\r\n\r\n").starts_with("HTTP/1.1 400"));
    let endless = vec![b'a'; 8 * 1024];
    assert!(http(port, &endless).starts_with("HTTP/1.1 431"));

    // An idle connection (no request) does not hold up the OPC server.
    let idle = TcpStream::connect(("127.0.0.1", port)).expect("idle connection");
    let t = Instant::now();
    server.status().expect("GetStatus while the endpoint waits");
    assert!(t.elapsed() < Duration::from_secs(1), "{:?}", t.elapsed());
    drop(idle);
    // ...and the endpoint answers again after its read timeout.
    assert!(http(port, b"GET /metrics HTTP/1.0\r\n\r\n").starts_with("HTTP/1.1 200"));

    drop((group, server));
    drop(com);
    assert!(
        wait_until_no_server(Duration::from_secs(60)),
        "the test's server did not exit"
    );
    // This server audits nothing (AuditWrites = nie), though a client wrote.
    let log = read_log(&dir);
    assert!(log.contains("write audit off (AuditWrites)"), "{log}");
    assert!(!log.contains(" audit: write"), "{log}");
    let _ = std::fs::remove_dir_all(&dir);
}
