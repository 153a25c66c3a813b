//! The server object's IConnectionPointContainer (one connection point: IOPCShutdown) and
//! IOPCShutdown::ShutdownRequest on a requested stop, end to end.
//!
//! The stop is requested the way an operator does it: Ctrl+C on the console of a
//! ServerCTOPC.exe started by hand. The test starts `ServerCTOPC.exe -Embedding` itself
//! with a console of its own (CREATE_NEW_CONSOLE; COM then hands new clients to its class
//! object), connects, advises a sink, and has a helper process (this test binary, running
//! the ignored test `ctrl_c_helper`) attach to the server's console and send CTRL_C_EVENT
//! there. Under Wine 8 this works without a display; the test process itself stays out of
//! that console (a process that calls FreeConsole loses its Wine console output). Wine
//! routes activations to the first registered server, so the test first waits until no
//! other ServerCTOPC.exe runs (servers of earlier tests exit 3 s after their last client).
#![cfg(windows)]

use ctopc_com::clock::now;
use ctopc_core::Timestamp;
use e2e_tests::start::StartRetrying;
use e2e_tests::{
    assert_alive, code, connect, interfaces::*, other_servers, wait_for_no_other_server, PROGID,
};
use opc_client::Server;
use std::os::windows::process::CommandExt;
use std::sync::mpsc;
use std::sync::Mutex;
use std::time::{Duration, Instant};
use windows::core::{implement, IUnknown, Interface, PCWSTR};
use windows::Win32::System::Com::{
    IConnectionPoint, IConnectionPointContainer, IEnumConnectionPoints,
};
use windows::Win32::System::Ole::{
    CONNECT_E_ADVISELIMIT, CONNECT_E_CANNOTCONNECT, CONNECT_E_NOCONNECTION,
};

/// A client's IOPCShutdown: forwards every reason to the test.
#[implement(IOPCShutdown)]
struct Sink {
    tx: Mutex<mpsc::Sender<Option<String>>>,
}

impl IOPCShutdown_Impl for Sink_Impl {
    unsafe fn ShutdownRequest(&self, reason: PCWSTR) -> windows::core::Result<()> {
        let reason = if reason.is_null() {
            None
        } else {
            // SAFETY: a non-null [in, string] is a NUL-terminated UTF-16 string for the call.
            unsafe { reason.to_string() }.ok()
        };
        let _ = self.tx.lock().map(|tx| tx.send(reason));
        Ok(())
    }
}

fn sink() -> (IOPCShutdown, mpsc::Receiver<Option<String>>) {
    let (tx, rx) = mpsc::channel();
    (Sink { tx: Mutex::new(tx) }.into(), rx)
}

fn container(server: &Server) -> IConnectionPointContainer {
    server
        .unknown
        .cast()
        .expect("the server object is an IConnectionPointContainer")
}

#[test]
fn one_connection_point_for_iopcshutdown() {
    let (_com, server) = connect();
    let cpc = container(&server);
    // SAFETY: valid IID pointers for the calls.
    let cp = unsafe { cpc.FindConnectionPoint(&IID_IOPCShutdown) }
        .expect("FindConnectionPoint(IOPCShutdown)");
    assert_eq!(
        // SAFETY: no arguments.
        unsafe { cp.GetConnectionInterface() }.unwrap(),
        IID_IOPCShutdown
    );
    assert_eq!(
        // SAFETY: valid IID pointer.
        code(&unsafe { cpc.FindConnectionPoint(&IID_IOPCDataCallback) }),
        CONNECT_E_NOCONNECTION
    );
    // SAFETY: no arguments.
    let e: IEnumConnectionPoints =
        unsafe { cpc.EnumConnectionPoints() }.expect("EnumConnectionPoints");
    let mut points = Vec::new();
    loop {
        let mut one: [Option<IConnectionPoint>; 1] = Default::default();
        // SAFETY: room for the one element asked for. (Under Wine the HRESULT of a call
        // that returned an interface is not reliable: look at the element.)
        let _ = unsafe { e.Next(&mut one, std::ptr::null_mut()) };
        match one[0].take() {
            Some(p) => points.push(p),
            None => break,
        }
        assert!(points.len() < 10);
    }
    assert_eq!(points.len(), 1);
    assert_eq!(
        // SAFETY: no arguments.
        unsafe { points[0].GetConnectionInterface() }.unwrap(),
        IID_IOPCShutdown
    );
}

#[test]
fn advise_rules_of_the_shutdown_point() {
    let (_com, server) = connect();
    let (s, _rx) = sink();
    let cookie = server.advise_shutdown(&s).expect("Advise");
    assert_ne!(cookie, 0);
    let (s2, _rx2) = sink();
    assert_eq!(
        code(&server.advise_shutdown(&s2)),
        CONNECT_E_ADVISELIMIT,
        "one connection per point"
    );
    assert_eq!(
        code(&server.unadvise_shutdown(cookie.wrapping_add(1000))),
        CONNECT_E_NOCONNECTION
    );
    server.unadvise_shutdown(cookie).expect("Unadvise");
    assert_eq!(
        code(&server.unadvise_shutdown(cookie)),
        CONNECT_E_NOCONNECTION,
        "already unadvised"
    );
    // An object that is no IOPCShutdown cannot connect.
    let cpc = container(&server);
    // SAFETY: valid IID pointer.
    let cp = unsafe { cpc.FindConnectionPoint(&IID_IOPCShutdown) }.unwrap();
    let not_a_sink: IUnknown = server.unknown.clone();
    assert_eq!(
        // SAFETY: a live interface pointer.
        code(&unsafe { cp.Advise(&not_a_sink) }),
        CONNECT_E_CANNOTCONNECT
    );
    // Connect again after the unadvise; EnumConnections lists that connection's cookie.
    let cookie = server.advise_shutdown(&s2).expect("Advise again");
    let listed: Vec<u32> = e2e_tests::connections(&cp)
        .into_iter()
        .map(|(c, _)| c)
        .collect();
    assert_eq!(listed, [cookie]);
    server.unadvise_shutdown(cookie).unwrap();
    assert_alive(&server);
}

/// Connects to the server process the test started (started at or after `since`).
fn connect_to_new_server(since: Timestamp) -> Server {
    let server = Server::connect(PROGID).expect("CoCreateInstance(ServerCTOPC.App)");
    assert!(
        server.status().unwrap().start_time >= since,
        "connected to another server than the test's"
    );
    server
}

/// The MinUpdateRate that marks the server process the Ctrl+C test starts itself.
const MARKER_RATE_MS: u32 = 777;

/// True when `server` is the process started with the marker configuration: its revised
/// rate for a 1 ms group is the marker rate (a server COM starts has no SERVERCTOPC_INI).
fn is_marked(server: &Server) -> bool {
    use opc_client::GroupSpec;
    let spec = GroupSpec {
        name: String::new(),
        active: false,
        rate_ms: 1,
        client_handle: 1,
        time_bias: None,
        deadband: None,
        lcid: 0x409,
    };
    let Ok(g) = server.add_group(&spec) else {
        return false;
    };
    let _ = server.remove_group(g.server_handle, true);
    g.revised_rate == MARKER_RATE_MS
}

/// Connects to the server process the test started itself (marked by its MinUpdateRate).
/// A client that calls CoCreateInstance before that process has registered its class
/// object makes COM start a second server, and Wine hands activations to whichever
/// registered first: when the connection reached that other one (a Ctrl+C to the test's
/// server would then stop a process this client is not connected to), let go, wait until
/// it has gone (it exits 3 s after its last client), and connect again.
fn connect_to_started_server(pid: u32, since: Timestamp) -> Server {
    for _ in 0..5 {
        let server = connect_to_new_server(since);
        if is_marked(&server) {
            return server;
        }
        drop(server);
        let deadline = Instant::now() + Duration::from_secs(30);
        while !other_servers(pid).is_empty() {
            assert!(
                Instant::now() < deadline,
                "the other server does not exit: {:?}",
                other_servers(pid)
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }
    panic!("COM kept connecting to another server than process {pid}");
}

fn wait_exit(child: &mut std::process::Child, limit: Duration) -> Option<std::process::ExitStatus> {
    let deadline = Instant::now() + limit;
    while Instant::now() < deadline {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    None
}

#[test]
fn ctrl_c_sends_shutdown_request_to_a_connected_client() {
    use windows::Win32::System::Threading::CREATE_NEW_CONSOLE;
    let _com = ctopc_com::apartment::Apartment::mta().unwrap();
    wait_for_no_other_server();
    let since = now();
    let ini = std::env::temp_dir().join(format!("ServerCTOPC-ctrl-c-{}.ini", std::process::id()));
    std::fs::write(
        &ini,
        format!("; the Ctrl+C test's server\r\n[Server]\r\nMinUpdateRate = {MARKER_RATE_MS}\r\n"),
    )
    .expect("write the test's ini");
    let mut server_process = std::process::Command::new(e2e_tests::artifact("ServerCTOPC.exe"))
        .arg("-Embedding")
        .env("SERVERCTOPC_INI", &ini)
        .creation_flags(CREATE_NEW_CONSOLE.0)
        .spawn_retrying()
        .expect("start ServerCTOPC.exe -Embedding");
    let server = connect_to_started_server(server_process.id(), since);
    let (s, rx) = sink();
    server.advise_shutdown(&s).expect("Advise IOPCShutdown");

    // The helper sends Ctrl+C to the server's console; what it printed goes into a
    // failure message.
    let helper = match std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "ctrl_c_helper",
            "--ignored",
            "--test-threads=1",
            "--nocapture",
        ])
        .env(HELPER_PID_VAR, server_process.id().to_string())
        .stdin(std::process::Stdio::null())
        .output_retrying()
    {
        Ok(o) => format!(
            "{}: {}",
            o.status,
            String::from_utf8_lossy(&o.stderr)
                .lines()
                .filter(|l| l.contains("panicked"))
                .collect::<Vec<_>>()
                .join(" | ")
        ),
        Err(e) => format!("not started: {e}"),
    };
    let reason = rx.recv_timeout(Duration::from_secs(20));

    let exit = wait_exit(&mut server_process, Duration::from_secs(20));
    if exit.is_none() {
        let _ = server_process.kill();
    }
    let reason = reason.unwrap_or_else(|e| {
        panic!("IOPCShutdown::ShutdownRequest within 20 s of Ctrl+C ({e:?}); helper: {helper}")
    });
    let reason = reason.expect("a reason, not NULL");
    assert!(
        reason.contains("ServerCTOPC") && reason.len() > 12,
        "a readable reason: {reason:?}"
    );
    let exit = exit.expect("the server exits after the shutdown request");
    assert!(exit.success(), "{exit:?}");
    drop(server);
    let _ = std::fs::remove_file(&ini);
}

const HELPER_PID_VAR: &str = "CTOPC_TEST_CTRL_C_TO_PID";

/// Not a test: the helper process of `ctrl_c_sends_shutdown_request_to_a_connected_client`
/// (runs only with that test's environment variable). Attaches to the server's console and
/// sends Ctrl+C to every process on it, ignoring it itself.
#[test]
#[ignore = "helper process of ctrl_c_sends_shutdown_request_to_a_connected_client"]
fn ctrl_c_helper() {
    use windows::Win32::System::Console::{
        AttachConsole, FreeConsole, GenerateConsoleCtrlEvent, SetConsoleCtrlHandler, CTRL_C_EVENT,
    };
    let Some(pid) = std::env::var(HELPER_PID_VAR)
        .ok()
        .and_then(|p| p.parse::<u32>().ok())
    else {
        return;
    };
    // SAFETY: plain Win32 console calls on this process's console attachment.
    unsafe {
        let _ = FreeConsole();
        AttachConsole(pid).expect("AttachConsole(server)");
        SetConsoleCtrlHandler(None, true).expect("ignore Ctrl+C in the helper");
        GenerateConsoleCtrlEvent(CTRL_C_EVENT, 0).expect("GenerateConsoleCtrlEvent");
    }
}
