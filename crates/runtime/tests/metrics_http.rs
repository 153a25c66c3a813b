//! The metrics endpoint natively, with a real TCP client on loopback: what it answers
//! (200, 404, 400, 431), how long an idle or trickling connection holds it, and its thread
//! ending with the runtime. The runtime runs over the in-process simulation of the demo
//! plant, as in `runtime.rs`. Every wait is on a condition, with a deadline.

use asix_model::{parse_config, AsixNamespace};
use asix_net::inproc::InProcessSim;
use ctopc_core::browse::MatchCase;
use ctopc_core::ops::OpsConfig;
use ctopc_runtime::frontend::no_thread_state;
use ctopc_runtime::metrics_http::{self, Endpoint, IO_TIMEOUT, MAX_REQUEST};
use ctopc_runtime::Runtime;
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The demo plant's acid factory database, simulated.
fn runtime() -> Arc<Runtime> {
    let db = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../demo/wytwornia_kwasu/wytwornia_kwasu.zez"
    );
    let ini = format!("[Server]\nSimulateCurrentData = tak\n[Channel:*]\nItemsDatabase = {db}\n");
    let (cfg, warnings) = parse_config(ini.as_bytes(), "metrics.ini").unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let engine_config = cfg.server.engine_config();
    let ns = Arc::new(AsixNamespace::load(cfg).0);
    let for_source = Arc::clone(&ns);
    ctopc_runtime::start(
        ns,
        MatchCase::Insensitive,
        engine_config,
        &OpsConfig::default(),
        no_thread_state,
        Box::new(move |_wake| {
            let sim = InProcessSim::new(for_source, 7, ctopc_runtime::clock::now());
            Ok(Box::new(sim) as Box<dyn ctopc_core::source::Backend>)
        }),
    )
    .unwrap()
    .runtime
}

/// The endpoint of `rt` on a port of the system's choice.
fn endpoint(rt: &Arc<Runtime>) -> Endpoint {
    let e = metrics_http::start(rt, "127.0.0.1:0").expect("the endpoint starts");
    assert!(e.address.ip().is_loopback() && e.address.port() != 0);
    e
}

/// Sends `request` and returns the whole answer (the endpoint closes).
fn http(addr: SocketAddr, request: &[u8]) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(request).unwrap();
    let mut answer = Vec::new();
    s.read_to_end(&mut answer).unwrap();
    String::from_utf8(answer).unwrap()
}

fn status_line(answer: &str) -> &str {
    answer.lines().next().unwrap_or("")
}

/// Waits until `done` holds, at most 10 s.
fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn get_metrics_is_answered_with_the_text_over_http_1_1_and_1_0() {
    let rt = runtime();
    let e = endpoint(&rt);
    rt.open_session();
    for request in [
        &b"GET /metrics HTTP/1.1\r\nHost: localhost\r\n\r\n"[..],
        b"GET /metrics HTTP/1.0\r\n\r\n",
        b"GET /metrics?name=x HTTP/1.1\r\n\r\n",
    ] {
        let answer = http(e.address, request);
        let (head, body) = answer.split_once("\r\n\r\n").expect("a head");
        assert_eq!(status_line(head), "HTTP/1.1 200 OK");
        let headers: Vec<&str> = head.lines().skip(1).collect();
        assert!(
            headers.contains(&"Content-Type: text/plain; version=0.0.4; charset=utf-8"),
            "{head}"
        );
        assert!(
            headers.contains(&format!("Content-Length: {}", body.len()).as_str()),
            "{head}"
        );
        assert!(headers.contains(&"Connection: close"), "{head}");
        for line in ["ctopc_clients 1", "# TYPE ctopc_callbacks_total counter"] {
            assert!(body.lines().any(|l| l == line), "no {line:?} in\n{body}");
        }
    }
    rt.stop_driver();
}

#[test]
fn other_paths_and_methods_are_not_found() {
    let rt = runtime();
    let e = endpoint(&rt);
    for request in [
        &b"GET / HTTP/1.1\r\n\r\n"[..],
        b"POST /metrics HTTP/1.1\r\n\r\n",
        b"HEAD /metrics HTTP/1.1\r\n\r\n",
        b"GET /metricsx HTTP/1.1\r\n\r\n",
    ] {
        let answer = http(e.address, request);
        assert_eq!(
            status_line(&answer),
            "HTTP/1.1 404 Not Found",
            "{request:?}"
        );
        assert!(answer.ends_with("Content-Length: 0\r\nConnection: close\r\n\r\n"));
    }
    rt.stop_driver();
}

#[test]
fn what_is_not_http_is_a_bad_request() {
    let rt = runtime();
    let e = endpoint(&rt);
    for request in [&b"hello\r\n\r\n"[..], b"GET /metrics\r\n\r\n", b"\r\n\r\n"] {
        let answer = http(e.address, request);
        assert_eq!(
            status_line(&answer),
            "HTTP/1.1 400 Bad Request",
            "{request:?}"
        );
    }
    rt.stop_driver();
}

#[test]
fn a_head_without_end_is_too_large() {
    let rt = runtime();
    let e = endpoint(&rt);
    let endless = vec![b'a'; MAX_REQUEST];
    let mut headers = b"GET /metrics HTTP/1.1\r\n".to_vec();
    while headers.len() < MAX_REQUEST {
        headers.extend_from_slice(b"X-Filler: 0123456789\r\n");
    }
    headers.truncate(MAX_REQUEST);
    for request in [endless, headers] {
        let answer = http(e.address, &request);
        assert_eq!(
            status_line(&answer),
            "HTTP/1.1 431 Request Header Fields Too Large"
        );
    }
    // A head that just fits is answered.
    let mut fits = b"GET /metrics HTTP/1.1\r\nX-Filler: ".to_vec();
    fits.resize(MAX_REQUEST - 4, b'a');
    fits.extend_from_slice(b"\r\n\r\n");
    assert_eq!(status_line(&http(e.address, &fits)), "HTTP/1.1 200 OK");
    rt.stop_driver();
}

#[test]
fn an_idle_connection_holds_the_endpoint_at_most_its_read_timeout() {
    let rt = runtime();
    let e = endpoint(&rt);
    let mut idle = TcpStream::connect(e.address).unwrap();
    let t = Instant::now();
    let answer = http(e.address, b"GET /metrics HTTP/1.0\r\n\r\n");
    assert_eq!(status_line(&answer), "HTTP/1.1 200 OK");
    assert!(
        t.elapsed() < IO_TIMEOUT + Duration::from_secs(2),
        "answered after {:?}",
        t.elapsed()
    );
    // The endpoint closed the idle connection without an answer.
    idle.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let mut rest = Vec::new();
    assert_eq!(idle.read_to_end(&mut rest).unwrap(), 0, "{rest:?}");
    rt.stop_driver();
}

#[test]
fn a_client_sending_its_head_a_byte_at_a_time_is_cut_off_at_the_read_timeout() {
    let rt = runtime();
    let e = endpoint(&rt);
    let mut slow = TcpStream::connect(e.address).unwrap();
    let t = Instant::now();
    // Each byte comes well within the timeout; the head never ends.
    let cut = loop {
        assert!(
            t.elapsed() < IO_TIMEOUT * 5,
            "still connected after {:?}",
            t.elapsed()
        );
        if let Err(e) = slow.write_all(b"x") {
            break e;
        }
        std::thread::sleep(IO_TIMEOUT / 10);
    };
    assert!(
        matches!(
            cut.kind(),
            ErrorKind::BrokenPipe | ErrorKind::ConnectionReset | ErrorKind::ConnectionAborted
        ),
        "{cut}"
    );
    assert!(t.elapsed() >= IO_TIMEOUT, "cut off after {:?}", t.elapsed());
    rt.stop_driver();
}

#[test]
fn the_endpoint_thread_ends_when_the_runtime_is_gone() {
    let rt = runtime();
    let e = endpoint(&rt);
    assert_eq!(
        status_line(&http(e.address, b"GET /metrics HTTP/1.1\r\n\r\n")),
        "HTTP/1.1 200 OK"
    );
    let weak = Arc::downgrade(&rt);
    rt.stop_driver();
    drop(rt);
    wait_until("the runtime to go", || weak.strong_count() == 0);
    wait_until("the endpoint thread to end", || e.thread.is_finished());
    e.thread.join().unwrap();
    assert!(
        TcpStream::connect(e.address).is_err(),
        "the endpoint no longer listens"
    );
}

#[test]
fn only_loopback_addresses_are_served() {
    let rt = runtime();
    assert!(metrics_http::start(&rt, "0.0.0.0:0").is_none());
    assert!(metrics_http::start(&rt, "localhost:0").is_none());
    rt.stop_driver();
}
