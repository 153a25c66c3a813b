//! The Asix.Evo REST data source end to end: a server of the test's own whose channel
//! `EVO` names two native `asix-sim --rest` stations (`AsixEvoRest = url1, url2`) serves
//! browse, read (cache and device), subscribe, refuses writes (OPC_E_BADRIGHTS, the items
//! being OPC_READABLE) and fails over to the second station when the first fails, which
//! `_Diagnostics.Channels.EVO` shows.
//!
//! The stations are native processes started by xtask before the end-to-end phase
//! (`cargo xtask test`, `cargo xtask e2e`: `xtask/src/rest_stations.rs`), which hands
//! their base URLs over in `SERVERCTOPC_TEST_REST` (`http://127.0.0.1:<port>,...`); the
//! server under Wine reaches them on loopback, and so does this test, which switches the
//! first station to failing with its control request (`POST /sim/mode?fail=1`).
//!
//! As `diagnostics.rs`: waits until no other ServerCTOPC.exe runs and starts a server of
//! its own (`SERVERCTOPC_INI`).
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_core::Value;
use e2e_tests::interfaces::*;
use e2e_tests::io_support::*;
use e2e_tests::server_config::{read_log, wait_until_no_server, write_demo_config};
use e2e_tests::{wait_for_no_other_server, Apartment, PROGID};
use opc_client::{self as client, GroupSpec, ItemDef, OpcGroup, Server};
use std::io::{Read, Write};
use std::time::Duration;
use test_support::wait::{wait_for, wait_until};
use windows::core::Interface;
use windows::Win32::Foundation::S_OK;

/// The environment variable with the stations' base URLs.
const STATIONS: &str = "SERVERCTOPC_TEST_REST";
const CHANNEL: &str = "EVO";
const ITEMS: &[&str] = &["KW_A000", "KW_A001", "KW_A000.PercentageCV"];

fn stations() -> Vec<String> {
    let v = std::env::var(STATIONS).unwrap_or_else(|_| {
        panic!(
            "{STATIONS} is not set: run this test through `cargo xtask e2e` or `cargo xtask test`, \
             which start two `asix-sim --rest` stations and set it"
        )
    });
    let urls: Vec<String> = v.split(',').map(|s| s.trim().to_owned()).collect();
    assert!(urls.len() >= 2, "{STATIONS}={v}: two stations needed");
    urls
}

/// `POST <url>/sim/mode?<query>` (the station's misbehaviour switches), over a plain
/// socket: the answer's status line must be 200.
fn set_mode(url: &str, query: &str) {
    let host = url.trim_start_matches("http://");
    let mut s = std::net::TcpStream::connect(host).expect("connect to the station");
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "POST /sim/mode?{query} HTTP/1.1\r\nHost: {host}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut answer = String::new();
    let _ = s.read_to_string(&mut answer);
    assert!(
        answer.starts_with("HTTP/1.1 200"),
        "{url} mode {query}: {answer}"
    );
}

fn read_diag(server: &Server, id: &str) -> client::ReadItem {
    let (_, r) = server.item_read(&[(id, 0)]).expect("IOPCItemIO::Read");
    r.into_iter().next().expect("one result")
}

fn diag_text(server: &Server, field: &str) -> String {
    match read_diag(server, &format!("_Diagnostics.Channels.{CHANNEL}.{field}")).value {
        Value::Bstr(s) => s,
        other => format!("{other:?}"),
    }
}

/// A number of the channel's `_Diagnostics` branch; `None` until the branch has it (the
/// board is published about once a second: before that the item is empty).
fn diag_i4(server: &Server, field: &str) -> Option<i32> {
    match read_diag(server, &format!("_Diagnostics.Channels.{CHANNEL}.{field}")).value {
        Value::I4(v) => Some(v),
        _ => None,
    }
}

#[test]
fn browse_read_subscribe_and_failover_through_asix_evo_rest() {
    let urls = stations();
    for u in &urls {
        set_mode(u, "reset=1");
    }
    wait_for_no_other_server();
    let (dir, ini) = write_demo_config("rest-source", "ASIXConnect-rest.ini", "", "");
    // The demo database from two REST stations: the server's own ini (the helper's
    // channel is the simulated one).
    std::fs::write(
        &ini,
        format!(
            "[Server]\r\nSimulateCurrentData = nie\r\nLogDirectory = Log\r\nReconnectInterval = 500\r\n\
             [Channel:*]\r\nItemsDatabase = demo\\wytwornia_kwasu.zez\r\n\
             [Channel:{CHANNEL}]\r\nItemsDatabase = demo\\wytwornia_kwasu.zez\r\n\
             AsixEvoRest = {}\r\nAsixEvoPollTimeout = 1000\r\n",
            urls.join(", ")
        ),
    )
    .unwrap();
    std::env::set_var("SERVERCTOPC_INI", &ini);
    let com = Apartment::mta().expect("MTA");
    let server = Server::connect(PROGID).expect("connect");
    std::env::remove_var("SERVERCTOPC_INI");

    // Browse: the database's tree, as for any channel.
    let (_, flat) = server.browse_item_ids(OPC_FLAT, "", 0, 0).unwrap();
    assert!(flat.iter().any(|i| i == "KW_A000"), "{flat:?}");

    // AddItems on the REST channel: read-only.
    let g = server.add_group(&GroupSpec::new("rest")).expect("AddGroup");
    let group = OpcGroup::from_unknown(g.object).unwrap();
    let defs: Vec<ItemDef> = ITEMS
        .iter()
        .enumerate()
        .map(|(i, id)| ItemDef {
            access_path: CHANNEL.into(),
            ..ItemDef::new(id, i as u32 + 1)
        })
        .collect();
    let (hr, added) = group.add_items(&defs).expect("AddItems");
    assert_eq!(hr, S_OK, "{added:?}");
    for a in &added {
        assert_eq!(a.access_rights, OPC_READABLE, "{a:?}");
    }
    let handles: Vec<u32> = added.iter().map(|a| a.server_handle).collect();
    let io: IOPCSyncIO = group.unknown.cast().unwrap();

    // Subscribed: good values in the cache and in OnDataChange.
    let rec = Recording::new();
    client::advise_data_callback(&group.unknown, &RecordingSink::create(&rec)).expect("Advise");
    let good = wait_until(Duration::from_secs(20), || {
        client::sync_read(&io, OPC_DS_CACHE, &handles)
            .is_ok_and(|(_, r)| r.iter().all(|i| i.quality & 0xC0 == 0xC0))
    });
    assert!(
        good,
        "no GOOD values in the cache; log:\n{}",
        read_log(&dir)
    );
    assert!(
        rec.wait_for(Duration::from_secs(10), |c| matches!(
            c,
            Callback::DataChange { items, .. } if items.iter().any(|i| i.quality & 0xC0 == 0xC0)
        ))
        .is_some(),
        "no OnDataChange with a GOOD value"
    );

    // A device read goes to the station.
    let (_, r) = client::sync_read(&io, OPC_DS_DEVICE, &handles).expect("device read");
    assert!(r.iter().all(|i| i.quality & 0xC0 == 0xC0), "{r:?}");
    assert!(matches!(r[0].value, Value::R4(_)), "{:?}", r[0]);

    // A write: refused, the REST API has no documented write.
    let (_, errors) = client::sync_write(&io, &[(handles[0], Value::R4(1.0))]).expect("Write");
    assert_eq!(errors, [OPC_E_BADRIGHTS]);

    // The channel's link in `_Diagnostics`: linked to the first station.
    let linked = wait_until(Duration::from_secs(10), || {
        diag_i4(&server, "LinkState") == Some(1) && diag_text(&server, "Server") == urls[0]
    });
    assert!(
        linked,
        "{:?} {}",
        diag_i4(&server, "LinkState"),
        diag_text(&server, "Server")
    );
    let subscriptions = diag_i4(&server, "Subscriptions");
    assert!(subscriptions >= Some(2), "{subscriptions:?}");

    // The first station fails: values go on from the second.
    set_mode(&urls[0], "fail=1");
    let moved = wait_for(Duration::from_secs(20), || {
        (diag_i4(&server, "LinkState") == Some(1) && diag_text(&server, "Server") == urls[1])
            .then(|| diag_i4(&server, "Failovers"))
            .flatten()
    });
    set_mode(&urls[0], "reset=1");
    let failovers = moved.unwrap_or_else(|| panic!("no failover; log:\n{}", read_log(&dir)));
    assert!(failovers >= 1, "{failovers}");
    rec.clear();
    assert!(
        rec.wait_for(Duration::from_secs(10), |c| matches!(
            c,
            Callback::DataChange { items, .. } if items.iter().any(|i| i.quality & 0xC0 == 0xC0)
        ))
        .is_some(),
        "no GOOD OnDataChange after the failover"
    );

    drop((io, group, server));
    drop(com);
    assert!(
        wait_until_no_server(Duration::from_secs(60)),
        "the test's server did not exit"
    );
    let log = read_log(&dir);
    assert!(
        log.contains("read-only"),
        "the log says the items are read-only:\n{log}"
    );
    // The refused write has a WARN that says why.
    assert!(
        log.lines().any(|l| l.contains("WARN")
            && l.contains("write refused (OPC_E_BADRIGHTS)")
            && l.contains("Asix.Evo REST")),
        "a WARN for the refused write:\n{log}"
    );
    assert!(!log.contains("panicked"), "{log}");
    let _ = std::fs::remove_dir_all(&dir);
}
