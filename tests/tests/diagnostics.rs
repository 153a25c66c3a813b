//! The `_Diagnostics` branch end to end: while a second client works
//! (SetClientName, a group, items, a subscription), the observing client browses the
//! branch every way (BrowseOPCItemIDs branch/leaf/flat, ChangeBrowsePosition down into a
//! client's branch and back up, GetItemID, IOPCBrowse::Browse), reads the items and finds
//! they follow what the test did (clients, groups, items; uptime grows; the second client's
//! branch appears and goes), subscribes to server counters and receives OnDataChange,
//! is refused a write (OPC_E_BADRIGHTS) and reads the item properties in both languages.
//!
//! As `ops_metrics.rs`: waits until no other ServerCTOPC.exe runs and starts a server of
//! its own (`SERVERCTOPC_INI`, the simulated demo plant), so that the counts are the test's.
//!
//! Spec: OPC DA 2.05a §4.4.8 IOPCBrowseServerAddressSpace, §4.4.6 IOPCItemProperties,
//! §4.3.3 Subscription via IOPCDataCallback; OPC DA 3.0 IOPCBrowse::Browse and
//! IOPCItemIO::Read (the `_Diagnostics` branch is the server's own address space, read
//! through the standard interfaces).
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ctopc_core::model::ItemVqt;
use ctopc_core::Value;
use e2e_tests::interfaces::*;
use e2e_tests::io_support::*;
use e2e_tests::server_config::{read_log, wait_until_no_server, write_demo_config};
use e2e_tests::{wait_for_no_other_server, Apartment, PROGID};
use opc_client::{self as client, BrowseArgs, Server};
use std::time::Duration;
use test_support::wait::{wait_for, wait_until};
use windows::Win32::Foundation::{E_FAIL, S_FALSE, S_OK};

const CLIENT: &str = "Worker.HMI";
/// Its branch: the `.` of its name made `_`.
const BRANCH: &str = "_Diagnostics.Clients.Worker_HMI";
const WORKER_ITEMS: &[&str] = &["KW_A000", "KW_A001", "KW_A110"];

/// One IOPCItemIO::Read of `id` from the cache (MaxAge 0 would ask the device; the
/// diagnostic items answer either way).
fn read(server: &Server, id: &str) -> client::ReadItem {
    let (_, r) = server.item_read(&[(id, 0)]).expect("IOPCItemIO::Read");
    r.into_iter().next().expect("one result")
}

fn read_i4(server: &Server, id: &str) -> i32 {
    let r = read(server, id);
    assert_eq!(r.error, S_OK, "{id}: {:?}", r.error);
    assert_eq!(r.quality, 0xC0, "{id}");
    match r.value {
        Value::I4(v) => v,
        other => panic!("{id}: {other:?}"),
    }
}

/// Waits (at most 10 s: a snapshot is taken every second) until `id` reads `want`.
fn wait_i4(server: &Server, id: &str, want: i32) {
    let mut v = None;
    let reached = wait_until(Duration::from_secs(10), || {
        v = Some(read_i4(server, id));
        v == Some(want)
    });
    assert!(reached, "{id} is {v:?}, not {want}");
}

fn branches(server: &Server) -> Vec<String> {
    server.browse_item_ids(OPC_BRANCH, "", 0, 0).unwrap().1
}

fn leaves(server: &Server) -> (windows::core::HRESULT, Vec<String>) {
    server.browse_item_ids(OPC_LEAF, "", 0, 0).unwrap()
}

fn prop(props: &client::ItemProperties, id: u32) -> &client::Property {
    props
        .properties
        .iter()
        .find(|p| p.id == id)
        .unwrap_or_else(|| panic!("no property {id} in {props:?}"))
}

#[test]
fn the_diagnostics_branch_follows_a_working_server() {
    wait_for_no_other_server();
    let (dir, ini) = write_demo_config("diagnostics", "ASIXConnect-diag.ini", "", "");
    std::env::set_var("SERVERCTOPC_INI", &ini);
    let com = Apartment::mta().expect("MTA");
    let observer = Server::connect(PROGID).expect("connect");
    std::env::remove_var("SERVERCTOPC_INI");
    observer.set_locale(0x0409).unwrap();

    // The second client: a name, a group of three items, a subscription.
    let worker = Server::connect(PROGID).expect("connect the second client");
    worker.set_client_name(CLIENT).unwrap();
    let group = group_with_items(&worker, "work", WORKER_ITEMS);
    let rec = Recording::new();
    client::advise_data_callback(&group.unknown, &RecordingSink::create(&rec)).expect("Advise");
    assert!(
        rec.wait_for(Duration::from_secs(10), |c| matches!(
            c,
            Callback::DataChange { .. }
        ))
        .is_some(),
        "the worker gets no OnDataChange"
    );

    // The counts follow what the test made.
    wait_i4(&observer, "_Diagnostics.Server.Clients", 2);
    wait_i4(&observer, "_Diagnostics.Server.Groups", 1);
    wait_i4(&observer, "_Diagnostics.Server.Items", 3);
    wait_i4(&observer, &format!("{BRANCH}.Groups"), 1);
    wait_i4(&observer, &format!("{BRANCH}.Items"), 3);
    let name = read(&observer, &format!("{BRANCH}.Name"));
    assert_eq!(name.value, Value::Bstr(CLIENT.into()));
    assert_eq!(read_i4(&observer, &format!("{BRANCH}.Failures")), 0);
    // -1 until a snapshot follows the end of the worker's first callback.
    let latency = format!("{BRANCH}.LastCallbackLatency");
    let ms = wait_for(Duration::from_secs(10), || {
        match read(&observer, &latency).value {
            Value::R8(ms) if ms >= 0.0 => Some(ms),
            Value::R8(ms) => {
                assert_eq!(ms, -1.0, "before the first snapshot");
                None
            }
            other => panic!("latency {other:?}"),
        }
    })
    .expect("LastCallbackLatency still -1 after 10 s");
    assert!(ms < 10_000.0, "{ms}");
    assert!(read_i4(&observer, "_Diagnostics.Server.Uptime") < 600);
    let channel = "_Diagnostics.Channels.Simulation";
    assert_eq!(read_i4(&observer, &format!("{channel}.LinkState")), 2);
    assert!(read_i4(&observer, &format!("{channel}.Subscriptions")) >= 2);
    assert_eq!(
        read(&observer, "_Diagnostics.Server.Nothing").error,
        OPC_E_UNKNOWNITEMID
    );

    // BrowseOPCItemIDs and ChangeBrowsePosition: down into the client's branch, back up.
    let root = branches(&observer);
    assert_eq!(
        root.first().map(String::as_str),
        Some("_Diagnostics"),
        "{root:?}"
    );
    assert!(root.iter().any(|b| b == "Magazyn siarki"), "{root:?}");
    let (_, flat) = observer.browse_item_ids(OPC_FLAT, "", 0, 0).unwrap();
    assert!(flat.iter().any(|i| i == "KW_A000"));
    assert!(flat.iter().any(|i| i == "_Diagnostics.Server.Uptime"));
    assert!(flat
        .iter()
        .any(|i| *i == format!("{BRANCH}.CallbacksPending")));
    let (_, writable) = observer
        .browse_item_ids(OPC_FLAT, "", 0, OPC_WRITEABLE)
        .unwrap();
    assert!(!writable.iter().any(|i| i.starts_with("_Diagnostics")));
    observer
        .change_browse_position(OPC_BROWSE_DOWN, "_Diagnostics")
        .unwrap();
    assert_eq!(branches(&observer), ["Server", "Clients", "Channels"]);
    observer
        .change_browse_position(OPC_BROWSE_DOWN, "Server")
        .unwrap();
    let (hr, server_items) = leaves(&observer);
    assert_eq!(hr, S_OK);
    assert_eq!(server_items.len(), 9, "{server_items:?}");
    assert_eq!(
        observer.get_item_id("Uptime").unwrap().as_deref(),
        Some("_Diagnostics.Server.Uptime")
    );
    observer.change_browse_position(OPC_BROWSE_UP, "").unwrap();
    observer
        .change_browse_position(OPC_BROWSE_DOWN, "Clients")
        .unwrap();
    let clients = branches(&observer);
    assert_eq!(clients.len(), 2, "{clients:?}");
    assert!(clients.iter().any(|c| c == "Worker_HMI"), "{clients:?}");
    assert!(
        clients.iter().any(|c| c.starts_with("Client")),
        "the observer: {clients:?}"
    );
    observer
        .change_browse_position(OPC_BROWSE_DOWN, "Worker_HMI")
        .unwrap();
    assert_eq!(
        leaves(&observer).1,
        [
            "Name",
            "Groups",
            "Items",
            "LastCallbackLatency",
            "CallbacksPending",
            "Failures",
            "Identity"
        ]
    );
    assert_eq!(
        observer.get_item_id("Items").unwrap().as_deref(),
        Some(format!("{BRANCH}.Items").as_str())
    );
    assert_eq!(observer.get_item_id("").unwrap().as_deref(), Some(BRANCH));
    for up in ["_Diagnostics.Clients", "_Diagnostics", ""] {
        observer.change_browse_position(OPC_BROWSE_UP, "").unwrap();
        assert_eq!(observer.get_item_id("").unwrap().as_deref(), Some(up));
    }
    assert_eq!(
        e2e_tests::code(&observer.change_browse_position(OPC_BROWSE_UP, "")),
        E_FAIL
    );
    assert_eq!(
        observer.get_item_id("_Diagnostics").unwrap().as_deref(),
        Some("_Diagnostics")
    );

    // IOPCBrowse::Browse: the branch first at the root, then inside, with properties.
    let page = observer.browse(&BrowseArgs::all("")).unwrap();
    let first = &page.elements[0];
    assert_eq!(first.name.as_deref(), Some("_Diagnostics"));
    assert_eq!(first.flags, OPC_BROWSE_HASCHILDREN);
    assert!(page.elements.len() > 1);
    let one = observer
        .browse(&BrowseArgs {
            max_elements: 1,
            ..BrowseArgs::all("")
        })
        .unwrap();
    assert_eq!(one.elements.len(), 1);
    let next = observer
        .browse(&BrowseArgs {
            continuation_point: one.continuation_point.clone(),
            max_elements: 1,
            ..BrowseArgs::all("")
        })
        .unwrap();
    assert_eq!(next.elements[0].name, page.elements[1].name);
    let inside = observer
        .browse(&BrowseArgs {
            all_properties: true,
            property_values: true,
            ..BrowseArgs::all("_Diagnostics.Server")
        })
        .unwrap();
    assert_eq!(inside.elements.len(), 9);
    let clients_el = inside
        .elements
        .iter()
        .find(|e| e.item_id.as_deref() == Some("_Diagnostics.Server.Clients"))
        .expect("Clients");
    assert_eq!(clients_el.flags, OPC_BROWSE_ISITEM);
    assert_eq!(prop(&clients_el.properties, 2).value, Value::I4(2));
    assert_eq!(prop(&clients_el.properties, 5).value, Value::I4(1));
    let page = observer.browse(&BrowseArgs::all(BRANCH)).unwrap();
    assert_eq!(page.elements.len(), 7);

    // Properties: type, rights, units, descriptions in English and Polish.
    let uptime = "_Diagnostics.Server.Uptime";
    let available: Vec<u32> = observer
        .query_available_properties(uptime)
        .unwrap()
        .into_iter()
        .map(|p| p.0)
        .collect();
    for id in [1, 2, 3, 4, 5, 6, 100, 101] {
        assert!(available.contains(&id), "{id} in {available:?}");
    }
    let (hr, props) = observer
        .get_item_properties(uptime, &[1, 5, 100, 101])
        .unwrap();
    assert_eq!(hr, S_OK, "{props:?}");
    assert_eq!(props[0].0, Value::I2(3), "VT_I4");
    assert_eq!(props[1].0, Value::I4(1), "OPC_READABLE");
    assert_eq!(props[2].0, Value::Bstr("s".into()));
    assert_eq!(
        props[3].0,
        Value::Bstr("Time since the server started".into())
    );
    observer.set_locale(0x0415).unwrap();
    let (_, props) = observer.get_item_properties(uptime, &[101]).unwrap();
    assert_eq!(
        props[0].0,
        Value::Bstr("Czas pracy serwera od startu".into())
    );
    let (hr, by_browse) = observer
        .get_properties(
            &[&format!("{BRANCH}.LastCallbackLatency")],
            true,
            &[100, 101],
        )
        .unwrap();
    assert_eq!(hr, S_OK);
    assert_eq!(prop(&by_browse[0], 100).value, Value::Bstr("ms".into()));
    let pl = &prop(&by_browse[0], 101).value;
    assert!(
        matches!(pl, Value::Bstr(s) if s.starts_with("Czas trwania")),
        "{pl:?}"
    );
    let link = observer
        .get_item_properties(&format!("{channel}.LinkState"), &[7, 8])
        .unwrap()
        .1;
    assert_eq!(link[0].0, Value::I4(2), "OPC_ENUMERATED");
    observer.set_locale(0x0409).unwrap();

    // A subscription to server counters: OnDataChange, and the uptime grows.
    let diag = add_group(&observer, "diag", true, 500, 7).expect("AddGroup");
    let (hr, added) = add_items(
        &diag,
        &[
            ItemSpec {
                id: uptime,
                client: 1,
                vt: 0,
                active: true,
            },
            ItemSpec {
                id: "_Diagnostics.Server.Groups",
                client: 2,
                vt: 0,
                active: true,
            },
        ],
    )
    .expect("AddItems");
    assert_eq!(hr, S_OK, "{added:x?}");
    assert!(added.iter().all(|a| a.rights == OPC_READABLE), "{added:?}");
    assert_eq!(added[0].canonical, 3, "VT_I4");
    let seen = Recording::new();
    client::advise_data_callback(&diag.unknown, &RecordingSink::create(&seen)).expect("Advise");
    let uptime_of =
        |c: &Callback| match c {
            Callback::DataChange { items, .. } => items
                .iter()
                .find(|i| i.client_handle == 1)
                .and_then(|i| match i.value {
                    Value::I4(v) => Some(v),
                    _ => None,
                }),
            _ => None,
        };
    let first = seen
        .wait_for(Duration::from_secs(10), |c| uptime_of(c).is_some())
        .expect("OnDataChange of the uptime");
    let t0 = uptime_of(&first).unwrap();
    assert!(
        seen.wait_for(Duration::from_secs(10), |c| uptime_of(c)
            .is_some_and(|v| v > t0))
            .is_some(),
        "the uptime does not grow past {t0}"
    );
    wait_i4(&observer, "_Diagnostics.Server.Groups", 2);
    wait_i4(&observer, "_Diagnostics.Server.Items", 5);

    // Read-only: writes are refused per item.
    let (hr, errors) =
        client::sync_write(&diag.sync(), &[(added[0].server, Value::I4(5))]).expect("Write");
    assert_eq!((hr, errors), (S_FALSE, vec![OPC_E_BADRIGHTS]));
    let (hr, errors) = observer
        .item_write_vqt(&[(uptime, ItemVqt::value(Value::I4(5)))])
        .expect("WriteVQT");
    assert_eq!((hr, errors), (S_FALSE, vec![OPC_E_BADRIGHTS]));

    // The worker leaves: its branch goes; a cursor inside it lists nothing and goes up.
    observer
        .change_browse_position(OPC_BROWSE_TO, BRANCH)
        .unwrap();
    drop(group);
    drop(worker);
    wait_i4(&observer, "_Diagnostics.Server.Clients", 1);
    wait_i4(&observer, "_Diagnostics.Server.Groups", 1);
    assert_eq!(leaves(&observer), (S_FALSE, vec![]));
    assert_eq!(observer.get_item_id("").unwrap().as_deref(), Some(BRANCH));
    observer.change_browse_position(OPC_BROWSE_UP, "").unwrap();
    let clients = branches(&observer);
    assert_eq!(clients.len(), 1, "{clients:?}");
    assert!(!clients.iter().any(|c| c == "Worker_HMI"));
    assert_eq!(
        read(&observer, &format!("{BRANCH}.Name")).error,
        OPC_E_UNKNOWNITEMID
    );
    let gone = observer.browse(&BrowseArgs::all(BRANCH));
    assert_eq!(e2e_tests::code(&gone), OPC_E_UNKNOWNITEMID);

    drop((diag, observer));
    drop(com);
    assert!(
        wait_until_no_server(Duration::from_secs(60)),
        "the test's server did not exit"
    );
    let log = read_log(&dir);
    assert!(!log.contains("panicked"), "{log}");
    let _ = std::fs::remove_dir_all(&dir);
}
