//! The write audit end to end: every kind of write reaches the server's
//! log file as one `write ...` line (target `audit`, on by default: `AuditWrites = tak`)
//! with the client's name, the group, the item, the value (quality and timestamp when
//! given) and the per-item result; an asynchronous write's final result follows in a
//! `write-complete` line. The line format itself is `ctopc_core::audit`'s (tested natively).
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_core::model::ItemVqt;
use ctopc_core::{Quality, Timestamp, Value};
use e2e_tests::io_support::*;
use e2e_tests::{assert_alive, connect};
use opc_client as client;
use std::time::{Duration, Instant};
use windows::Win32::Foundation::{S_FALSE, S_OK};

/// Sulphur feed rate setpoint (R4 0..20 t/h, writable).
const SETPOINT: &str = "KW_A110";
/// Level of tank Z101 (read-only).
const LEVEL: &str = "KW_A000";

/// Everything the server has logged (all files of the install folder's Log directory).
fn server_log() -> String {
    let dir = e2e_tests::artifact("Log");
    let mut log = String::new();
    if let Ok(entries) = std::fs::read_dir(&dir) {
        for e in entries.flatten() {
            log.push_str(&std::fs::read_to_string(e.path()).unwrap_or_default());
        }
    }
    log
}

/// Waits (the log writer flushes asynchronously) until a log line contains every one of
/// `parts`; returns it.
fn wait_for_line(parts: &[&str]) -> String {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let log = server_log();
        if let Some(l) = log.lines().find(|l| parts.iter().all(|p| l.contains(p))) {
            return l.to_string();
        }
        assert!(
            Instant::now() < deadline,
            "no log line with {parts:?}; audit lines:\n{}",
            log.lines()
                .filter(|l| l.contains("audit"))
                .collect::<Vec<_>>()
                .join("\n")
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

#[test]
fn every_kind_of_write_is_audited_with_client_item_value_and_result() {
    let (_com, server) = connect();
    let name = format!("audit-test-{}", std::process::id());
    server.set_client_name(&name).expect("SetClientName");
    let client_part = format!("client=\"{name}\"");
    let group = add_group(&server, "audited group", true, 1000, 9).expect("AddGroup");
    let h = add_ok(
        &group,
        &[
            ItemSpec {
                id: SETPOINT,
                client: 1,
                vt: 0,
                active: true,
            },
            ItemSpec {
                id: LEVEL,
                client: 2,
                vt: 0,
                active: true,
            },
        ],
    );

    // IOPCSyncIO::Write: one line per item, with its own result.
    let (hr, errors) = client::sync_write(
        &group.sync(),
        &[(h[0], Value::R4(6.25)), (h[1], Value::R4(1.0))],
    )
    .expect("Write");
    assert_eq!(hr, S_FALSE);
    assert_eq!(errors[0], S_OK);
    let line = wait_for_line(&[
        &client_part,
        "method=IOPCSyncIO::Write",
        "group=\"audited group\"",
        "item=\"KW_A110\"",
        "value=R4:6.25",
        "result=S_OK",
    ]);
    assert!(line.contains(" audit: write time="), "{line}");
    wait_for_line(&[
        &client_part,
        "method=IOPCSyncIO::Write",
        "item=\"KW_A000\"",
        "result=OPC_E_BADRIGHTS",
    ]);

    // IOPCSyncIO2::WriteVQT with quality and timestamp.
    let stamp = Timestamp::from_unix_millis(1_700_000_123_000);
    let (hr, _) = client::write_vqt(
        &group.sync2(),
        &[(
            h[0],
            ItemVqt {
                value: Value::R4(4.75),
                quality: Some(Quality(0xD8)),
                timestamp: Some(stamp),
            },
        )],
    )
    .expect("WriteVQT");
    assert_eq!(hr, S_OK);
    wait_for_line(&[
        &client_part,
        "method=IOPCSyncIO2::WriteVQT",
        "value=R4:4.75 quality=0x00D8 timestamp=2023-11-14T22:15:23.000Z",
        "result=S_OK",
    ]);

    // IOPCAsyncIO2::Write: the call's line with the cancel ID, then the completion's.
    let rec = Recorder::recording();
    client::advise_data_callback(&group.unknown, &TestSink::create(&rec)).expect("Advise");
    let (hr, cancel, errors) =
        client::async_write(&group.async2(), &[(h[0], Value::R8(3.5))], 4711).expect("Write");
    assert_eq!((hr, errors), (S_OK, vec![S_OK]));
    rec.wait_for(Duration::from_secs(10), |c| c.transaction() == 4711)
        .expect("OnWriteComplete");
    wait_for_line(&[
        &client_part,
        "method=IOPCAsyncIO2::Write",
        "value=R8:3.5",
        &format!("cancel={cancel} result=S_OK"),
    ]);
    wait_for_line(&[
        "write-complete",
        &client_part,
        &format!("cancel={cancel} transaction=4711 handle=1 result=S_OK"),
    ]);

    // IOPCAsyncIO3::WriteVQT.
    let (hr, _, _) = client::async_write_vqt(
        &group.async3(),
        &[(h[0], ItemVqt::value(Value::I4(2)))],
        4712,
    )
    .expect("WriteVQT");
    assert_eq!(hr, S_OK);
    wait_for_line(&[&client_part, "method=IOPCAsyncIO3::WriteVQT", "value=I4:2"]);

    // IOPCItemIO::WriteVQT: no group.
    let (hr, _) = server
        .item_write_vqt(&[(SETPOINT, ItemVqt::value(Value::R8(12.5)))])
        .expect("IOPCItemIO::WriteVQT");
    assert_eq!(hr, S_OK);
    let line = wait_for_line(&[
        &client_part,
        "method=IOPCItemIO::WriteVQT",
        "item=\"KW_A110\" value=R8:12.5 result=S_OK",
    ]);
    assert!(!line.contains("group="), "{line}");
    assert_alive(&server);
}

#[test]
fn a_client_without_a_name_is_audited_by_its_session() {
    let (_com, server) = connect();
    let group = add_group(&server, "", true, 1000, 9).expect("AddGroup");
    let h = add_ok(
        &group,
        &[ItemSpec {
            id: SETPOINT,
            client: 1,
            vt: 0,
            active: true,
        }],
    );
    // A value no other test writes, to find this client's line.
    let (hr, _) =
        client::sync_write(&group.sync(), &[(h[0], Value::R8(17.171717))]).expect("Write");
    assert_eq!(hr, S_OK);
    let line = wait_for_line(&["value=R8:17.171717", "method=IOPCSyncIO::Write"]);
    assert!(line.contains("client=\"session "), "{line}");
}
