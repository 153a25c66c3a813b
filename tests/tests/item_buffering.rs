//! Item buffering end to end (IOPCItemSamplingMgt::SetItemBufferEnable):
//! the server started with a configuration of the test's own (`SERVERCTOPC_INI`, the
//! embedded demo with `MinUpdateRate = 100`), a 1000 ms group, its tank level sampled at
//! 100 ms with buffering on: an OnDataChange carries several samples of that one item,
//! oldest first, while the unbuffered item of the same group carries one value per
//! callback. The in-process simulation moves every 250 ms, so about four samples a
//! second differ.
//!
//! Like group_slow_source.rs, the test waits until no other ServerCTOPC.exe runs, sets
//! `SERVERCTOPC_INI` before activating, and waits at the end until its server has exited.
#![cfg(windows)]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use e2e_tests::io_support::*;
use e2e_tests::server_config::{wait_until_no_server, write_demo_config};
use e2e_tests::{connect, other_servers, wait_for_no_other_server};
use opc_client::{self as client, OpcGroup};
use std::time::Duration;
use windows::Win32::Foundation::S_OK;

/// Read-only tank level and a second, independent level of the demo plant.
const LEVEL: &str = "KW_A000";
const OTHER: &str = "KW_A001";

#[test]
fn a_buffered_item_carries_several_samples_oldest_first() {
    wait_for_no_other_server();
    let (dir, ini) = write_demo_config(
        "buffering",
        "ASIXConnect-buffering.ini",
        "MinUpdateRate = 100",
        "",
    );
    std::env::set_var("SERVERCTOPC_INI", &ini);
    let (com, server) = connect();
    std::env::remove_var("SERVERCTOPC_INI");
    assert_eq!(other_servers(0).len(), 1, "only the test's server runs");

    let group = add_group(&server, "buffering", true, 1000, 77).expect("AddGroup");
    assert_eq!(group.revised_rate, 1000);
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
                id: OTHER,
                client: 2,
                vt: 0,
                active: true,
            },
        ],
    );
    let g = OpcGroup::from_unknown(group.unknown.clone()).unwrap();
    let (hr, r) = g
        .set_item_sampling_rate(&[(h[0], 100), (h[1], 100)])
        .unwrap();
    assert_eq!(
        (hr, r),
        (S_OK, vec![(100, S_OK), (100, S_OK)]),
        "MinUpdateRate = 100 took effect"
    );
    let (hr, errs) = g.set_item_buffer_enable(&[(h[0], true)]).unwrap();
    assert_eq!((hr, errs), (S_OK, vec![S_OK]));
    let (hr, v) = g.get_item_buffer_enable(&[h[0], h[1]]).unwrap();
    assert_eq!((hr, v), (S_OK, vec![(true, S_OK), (false, S_OK)]));

    let rec = Recorder::recording();
    client::advise_data_callback(&group.unknown, &TestSink::create(&rec))
        .expect("Advise(IOPCDataCallback)");
    // The first callback (the current values) and then a few periods.
    let several = rec.wait_for(Duration::from_secs(15), |c| match c {
        Callback::DataChange {
            transaction: 0,
            items,
            ..
        } => items.iter().filter(|i| i.client_handle == 1).count() >= 3,
        _ => false,
    });
    let all = rec.all();
    drop(rec);
    drop(g);
    drop(group);
    drop(server);
    drop(com);
    let exited = wait_until_no_server(Duration::from_secs(30));
    let _ = std::fs::remove_dir_all(&dir);

    let Some(Callback::DataChange {
        group: hgroup,
        master_error,
        items,
        ..
    }) = several
    else {
        panic!("no OnDataChange with several samples of the buffered item: {all:#?}");
    };
    assert_eq!(hgroup, 77);
    let level: Vec<_> = items.iter().filter(|i| i.client_handle == 1).collect();
    assert!(
        level.windows(2).all(|w| w[0].timestamp < w[1].timestamp),
        "oldest first: {level:#?}"
    );
    assert!(
        level.windows(2).all(|w| w[0].value != w[1].value),
        "each a change"
    );
    assert!(level
        .iter()
        .all(|i| i.quality & 0xC0 == 0xC0 && i.error == S_OK));
    assert_eq!(master_error, S_OK, "no overflow");
    assert!(
        items.iter().filter(|i| i.client_handle == 2).count() <= 1,
        "the unbuffered item: one value per callback"
    );
    // No callback ever carried the unbuffered item twice.
    for c in &all {
        if let Callback::DataChange { items, .. } = c {
            assert!(items.iter().filter(|i| i.client_handle == 2).count() <= 1);
        }
    }
    assert!(
        exited,
        "the test's server did not exit after its client left"
    );
}
