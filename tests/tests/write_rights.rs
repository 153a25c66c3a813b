//! The write-rights policy end to end: a server started with a `[WriteRights]` section of
//! the test's own (`SERVERCTOPC_INI`).
//!
//! - A policy that does not name the caller refuses its writes: IOPCSyncIO::Write,
//!   IOPCAsyncIO2::Write and IOPCItemIO::WriteVQT answer S_FALSE with OPC_E_BADRIGHTS for
//!   the item, and the audit lines say `result=denied` with the caller's `identity=`
//!   (under Wine `unknown (...)`, which has no DCOM call security; the policy names a group
//!   nobody has, so the refusal holds whatever the platform tells).
//! - A policy that lets everyone (`*`) write lets the same writes through.
//!
//! Each test waits until no other ServerCTOPC.exe runs (an activation would reach it),
//! sets `SERVERCTOPC_INI` before activating (the server COM starts inherits the client's
//! environment under Wine; its log, written next to the ini, proves which file it used),
//! and at the end releases everything and waits until its server has exited, so that later
//! tests get a server with the default configuration.
//!
//! Spec: OPC DA 2.05a §4.5.5 IOPCSyncIO::Write and §4.5.6 IOPCAsyncIO2::Write (per-item
//! OPC_E_BADRIGHTS); OPC DA 3.0 IOPCItemIO::WriteVQT. The policy is the server's own
//! (`docs/configuration.md`, "Write rights").
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_core::model::ItemVqt;
use ctopc_core::{OpcError, Value};
use e2e_tests::io_support::*;
use e2e_tests::server_config::{read_log, wait_until_no_server, write_demo_config};
use e2e_tests::{connect, other_servers, wait_for_no_other_server, Apartment, Server};
use opc_client as client;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;
use test_support::wait::wait_for;
use windows::core::HRESULT;
use windows::Win32::Foundation::{S_FALSE, S_OK};

/// A writable setpoint of the demo plant.
const SETPOINT: &str = "KW_A110";
const BAD_RIGHTS: HRESULT = HRESULT(OpcError::BadRights.hresult());

/// One server with a configuration of its own at a time.
static ONE_SERVER_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The test's server over its own configuration (the demo plant simulated, `rights` as
/// the `[WriteRights]` section), with a group holding SETPOINT.
struct Guarded {
    server: Option<(Server, TestGroup, u32, Arc<Recording>)>,
    dir: PathBuf,
    _com: Apartment,
    _serial: MutexGuard<'static, ()>,
}

impl Guarded {
    fn start(name: &str, rights: &str) -> Guarded {
        let serial = ONE_SERVER_AT_A_TIME
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        wait_for_no_other_server();
        let (dir, ini) = write_demo_config(
            name,
            "ASIXConnect-rights.ini",
            "",
            &format!("[WriteRights]\r\n{rights}\r\n"),
        );
        std::env::set_var("SERVERCTOPC_INI", &ini);
        let (com, server) = connect();
        std::env::remove_var("SERVERCTOPC_INI");
        assert_eq!(other_servers(0).len(), 1, "only the test's server runs");
        server.set_client_name(name).expect("SetClientName");
        let group = add_group(&server, name, true, 1000, 77).expect("AddGroup");
        let h = add_ok(
            &group,
            &[ItemSpec {
                id: SETPOINT,
                client: 1,
                vt: 0,
                active: true,
            }],
        )[0];
        // IOPCAsyncIO2 needs the data callback connected.
        let rec = Recording::new();
        client::advise_data_callback(&group.unknown, &RecordingSink::create(&rec))
            .expect("Advise(IOPCDataCallback)");
        let g = Guarded {
            server: Some((server, group, h, rec)),
            dir,
            _com: com,
            _serial: serial,
        };
        // The log proves the server read the test's file.
        g.wait_for_line(&["write rights: [WriteRights] policy"]);
        g
    }

    fn parts(&self) -> (&Server, &TestGroup, u32, &Arc<Recording>) {
        let (s, g, h, r) = self.server.as_ref().expect("running");
        (s, g, *h, r)
    }

    /// Waits (the log writer flushes asynchronously) for a line of the server's log
    /// with every one of `parts`.
    fn wait_for_line(&self, parts: &[&str]) -> String {
        wait_for(Duration::from_secs(10), || {
            read_log(&self.dir)
                .lines()
                .find(|l| parts.iter().all(|p| l.contains(p)))
                .map(str::to_owned)
        })
        .unwrap_or_else(|| {
            panic!(
                "no log line with {parts:?}; the log:\n{}",
                read_log(&self.dir)
            )
        })
    }
}

impl Drop for Guarded {
    fn drop(&mut self) {
        if let Some(s) = self.server.take() {
            drop(s);
            let _ = wait_until_no_server(Duration::from_secs(30));
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The identity an audit line names, which must say who or why not.
fn identity_of(line: &str) -> &str {
    let start = line.find(" identity=\"").expect("an identity") + " identity=\"".len();
    let rest = &line[start..];
    &rest[..rest.find('"').expect("a closing quote")]
}

#[test]
fn a_policy_that_does_not_name_the_caller_refuses_its_writes() {
    let name = format!("rights-denied-{}", std::process::id());
    let g = Guarded::start(&name, "* = group:ServerCTOPC e2e nobody");
    let (server, group, h, _) = g.parts();
    let client_part = format!("client=\"{name}\"");

    // IOPCSyncIO::Write.
    let (hr, errors) = client::sync_write(&group.sync(), &[(h, Value::R4(6.25))]).expect("Write");
    assert_eq!((hr, errors), (S_FALSE, vec![BAD_RIGHTS]));
    let line = g.wait_for_line(&[
        &client_part,
        "method=IOPCSyncIO::Write",
        "item=\"KW_A110\"",
        "result=denied",
    ]);
    let identity = identity_of(&line);
    assert!(
        identity.starts_with("unknown (") || identity.starts_with("user:"),
        "{line}"
    );
    assert_ne!(
        identity, "unknown (not told)",
        "the COM layer says who calls"
    );

    // IOPCAsyncIO2::Write: refused at call time (per item, as the spec has call-time
    // errors).
    let (hr, cancel, errors) =
        client::async_write(&group.async2(), &[(h, Value::R4(6.5))], 21).expect("AsyncWrite");
    assert_eq!((hr, errors), (S_FALSE, vec![BAD_RIGHTS]));
    g.wait_for_line(&[
        &client_part,
        "method=IOPCAsyncIO2::Write",
        &format!("cancel={cancel} result=denied"),
    ]);

    // IOPCItemIO::WriteVQT.
    let (hr, errors) = server
        .item_write_vqt(&[(SETPOINT, ItemVqt::value(Value::R8(1.5)))])
        .expect("WriteVQT");
    assert_eq!((hr, errors), (S_FALSE, vec![BAD_RIGHTS]));
    g.wait_for_line(&[&client_part, "method=IOPCItemIO::WriteVQT", "result=denied"]);
}

#[test]
fn a_policy_open_to_everyone_lets_the_same_writes_through() {
    let name = format!("rights-open-{}", std::process::id());
    let g = Guarded::start(&name, "* = *");
    let (server, group, h, _) = g.parts();
    let client_part = format!("client=\"{name}\"");
    let (hr, errors) = client::sync_write(&group.sync(), &[(h, Value::R4(6.25))]).expect("Write");
    assert_eq!((hr, errors), (S_OK, vec![S_OK]));
    let line = g.wait_for_line(&[
        &client_part,
        "method=IOPCSyncIO::Write",
        "value=R4:6.25",
        "result=S_OK",
    ]);
    assert!(line.contains(" identity=\""), "{line}");
    let (hr, errors) = server
        .item_write_vqt(&[(SETPOINT, ItemVqt::value(Value::R8(1.5)))])
        .expect("WriteVQT");
    assert_eq!((hr, errors), (S_OK, vec![S_OK]));
    assert!(!read_log(&g.dir).contains("result=denied"));
}
