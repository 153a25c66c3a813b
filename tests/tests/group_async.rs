//! Asynchronous group I/O end to end (IOPCAsyncIO2, IOPCAsyncIO3) with a test
//! IOPCDataCallback sink in this process: OnReadComplete, OnWriteComplete, OnDataChange
//! for refreshes (with the client's transaction ID) and subscriptions, Cancel2 and
//! OnCancelComplete, SetEnable/GetEnable (the argument rules and CONNECT_E_NOCONNECTION:
//! in process, `inproc_group_io.rs`). The default simulation
//! answers at once, so Cancel2 here races the completion; group_slow_source.rs cancels
//! operations that certainly wait for a slow device.
//!
//! Spec: OPC DA 2.05a §4.3.2 IOPCAsyncIO2 and §4.5.6 IOPCAsyncIO2 (Read, Write, Refresh2,
//! Cancel2, SetEnable, GetEnable), §4.3.3 Subscription via IOPCDataCallback, §4.6.1
//! IOPCDataCallback (OnDataChange, OnReadComplete, OnWriteComplete, OnCancelComplete); OPC
//! DA 3.0 IOPCAsyncIO3 (ReadMaxAge, WriteVQT, RefreshMaxAge).
#![cfg(windows)]

use ctopc_core::model::ItemVqt;
use ctopc_core::{Quality, Timestamp, Value};
use e2e_tests::io_support::*;
use e2e_tests::{assert_alive, code, connect, interfaces::*, Apartment, Server};
use opc_client as client;
use std::sync::Arc;
use std::time::Duration;
use windows::core::BOOL;
use windows::Win32::Foundation::{E_FAIL, S_FALSE, S_OK};
use windows::Win32::System::Variant::VT_R4;

const GOOD: u16 = 0xC0;
const WAIT: Duration = Duration::from_secs(10);
const GROUP_CLIENT_HANDLE: u32 = 4242;

const LEVEL: &str = "KW_A000";
const SETPOINT: &str = "KW_A110";
/// Temperature of the sulphur in tank Z101 (changes every plant tick).
const TEMPERATURE: &str = "KW_A001";

struct Plant {
    _com: Apartment,
    server: Server,
    group: TestGroup,
    /// LEVEL, SETPOINT, TEMPERATURE (client handles 1, 2, 3).
    h: Vec<u32>,
    rec: Arc<Recording>,
}

/// A group with three items and the recording sink advised.
fn plant() -> Plant {
    let (com, server) = connect();
    let group = add_group(&server, "", true, 1000, GROUP_CLIENT_HANDLE).expect("AddGroup");
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
            ItemSpec {
                id: TEMPERATURE,
                client: 3,
                vt: 0,
                active: true,
            },
        ],
    );
    let rec = Recording::new();
    client::advise_data_callback(&group.unknown, &RecordingSink::create(&rec))
        .expect("Advise(IOPCDataCallback)");
    Plant {
        _com: com,
        server,
        group,
        h,
        rec,
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

fn clients(items: &[CbItem]) -> Vec<u32> {
    let mut v: Vec<u32> = items.iter().map(|i| i.client_handle).collect();
    v.sort_unstable();
    v
}

#[test]
fn async_read_completes_with_on_read_complete() {
    let p = plant();
    let (hr, cancel, errors) = client::async_read(&p.group.async2(), &p.h, 101).expect("Read");
    assert_eq!((hr, errors), (S_OK, vec![S_OK; 3]));
    assert_ne!(cancel, 0);
    let Callback::ReadComplete {
        group,
        master_quality,
        master_error,
        items,
        ..
    } = wait_tx(&p, 101)
    else {
        panic!("{:?}", p.rec.all())
    };
    assert_eq!(group, GROUP_CLIENT_HANDLE);
    assert_eq!(clients(&items), vec![1, 2, 3]);
    assert_eq!((master_quality, master_error), (S_OK, S_OK), "{items:?}");
    for i in &items {
        assert_eq!(i.vt, VT_R4.0);
        assert_eq!(i.quality & 0xC0, GOOD);
        assert_eq!(i.error, S_OK);
    }
    assert_alive(&p.server);
}

#[test]
fn async_write_completes_with_on_write_complete_and_the_value_reads_back() {
    let p = plant();
    let items = [
        (p.h[1], Value::R4(6.5)),
        (p.h[0], Value::R4(1.0)),
        (p.h[1], Value::Bstr("abc".into())),
    ];
    let (hr, cancel, errors) = client::async_write(&p.group.async2(), &items, 201).expect("Write");
    assert_eq!(hr, S_FALSE);
    assert_eq!(
        errors,
        vec![S_OK, OPC_E_BADRIGHTS, OPC_E_BADTYPE],
        "call-time errors"
    );
    assert_ne!(cancel, 0);
    let Callback::WriteComplete {
        group,
        master_error,
        items,
        ..
    } = wait_tx(&p, 201)
    else {
        panic!()
    };
    assert_eq!(group, GROUP_CLIENT_HANDLE);
    assert_eq!(master_error, S_OK);
    assert_eq!(
        items,
        vec![(2, S_OK)],
        "only the items accepted by the call"
    );
    let (_, read) = client::sync_read(&p.group.sync(), OPC_DS_DEVICE, &p.h[1..2]).unwrap();
    assert_eq!(read[0].value, Value::R4(6.5));
    assert_alive(&p.server);
}

#[test]
fn refresh2_from_cache_and_device_sends_every_active_item_with_the_transaction_id() {
    let p = plant();
    // A subscription update first, so that nothing is "new" any more.
    p.rec
        .wait_for(WAIT, |c| {
            matches!(c, Callback::DataChange { transaction: 0, .. })
        })
        .expect("first OnDataChange");
    for (source, tid) in [(OPC_DS_CACHE, 301), (OPC_DS_DEVICE, 302)] {
        let cancel = client::refresh2(&p.group.async2(), source, tid).expect("Refresh2");
        assert_ne!(cancel, 0);
        let Callback::DataChange { group, items, .. } = wait_tx(&p, tid) else {
            panic!()
        };
        assert_eq!(group, GROUP_CLIENT_HANDLE);
        assert_eq!(clients(&items), vec![1, 2, 3], "{source:?}");
        assert!(
            items
                .iter()
                .all(|i| i.vt == VT_R4.0 && i.quality & 0xC0 == GOOD),
            "{items:?}"
        );
    }
    assert_alive(&p.server);
}

#[test]
fn refresh2_leaves_out_inactive_items_and_fails_for_an_inactive_group() {
    let p = plant();
    let inactive = add_ok(
        &p.group,
        &[ItemSpec {
            id: LEVEL,
            client: 50,
            vt: 0,
            active: false,
        }],
    );
    assert_ne!(inactive[0], 0);
    client::refresh2(&p.group.async2(), OPC_DS_CACHE, 310).unwrap();
    let Callback::DataChange { items, .. } = wait_tx(&p, 310) else {
        panic!()
    };
    assert_eq!(clients(&items), vec![1, 2, 3]);

    assert_eq!(set_active(&p.group, false), S_OK);
    for source in [OPC_DS_CACHE, OPC_DS_DEVICE] {
        assert_eq!(
            code(&client::refresh2(&p.group.async2(), source, 311)),
            E_FAIL
        );
    }
    assert_eq!(
        code(&client::refresh_max_age(&p.group.async3(), 0, 312)),
        E_FAIL
    );
    assert_alive(&p.server);

    // An active group with no active item: E_FAIL too.
    let g2 = add_group(&p.server, "", true, 1000, 1).unwrap();
    add_ok(
        &g2,
        &[ItemSpec {
            id: LEVEL,
            client: 1,
            vt: 0,
            active: false,
        }],
    );
    let rec = Recording::new();
    client::advise_data_callback(&g2.unknown, &RecordingSink::create(&rec)).unwrap();
    assert_eq!(
        code(&client::refresh2(&g2.async2(), OPC_DS_CACHE, 313)),
        E_FAIL
    );
    assert_alive(&p.server);
}

#[test]
fn refresh_max_age_and_async_read_max_age() {
    let p = plant();
    for (age, tid) in [(0u32, 401u32), (u32::MAX, 402), (5_000, 403)] {
        let cancel = client::refresh_max_age(&p.group.async3(), age, tid).expect("RefreshMaxAge");
        assert_ne!(cancel, 0);
        let Callback::DataChange { items, .. } = wait_tx(&p, tid) else {
            panic!()
        };
        assert_eq!(clients(&items), vec![1, 2, 3], "MaxAge {age}");
    }
    let items: Vec<(u32, u32)> = vec![
        (p.h[0], 0),
        (p.h[1], u32::MAX),
        (p.h[2], 1_000),
        (0xDEAD_BEEF, 0),
    ];
    let (hr, cancel, errors) =
        client::async_read_max_age(&p.group.async3(), &items, 404).expect("ReadMaxAge");
    assert_eq!(hr, S_FALSE);
    assert_eq!(errors, vec![S_OK, S_OK, S_OK, OPC_E_INVALIDHANDLE]);
    assert_ne!(cancel, 0);
    let Callback::ReadComplete { items, .. } = wait_tx(&p, 404) else {
        panic!()
    };
    assert_eq!(clients(&items), vec![1, 2, 3]);
    assert_alive(&p.server);
}

#[test]
fn async_write_vqt_writes_quality_and_timestamp() {
    let p = plant();
    let stamp = Timestamp::from_unix_millis(1_690_000_000_000);
    let items = [
        (
            p.h[1],
            ItemVqt {
                value: Value::R4(3.25),
                quality: Some(Quality(0xD8)),
                timestamp: Some(stamp),
            },
        ),
        (p.h[0], ItemVqt::value(Value::R4(1.0))),
    ];
    let (hr, _, errors) =
        client::async_write_vqt(&p.group.async3(), &items, 501).expect("WriteVQT");
    assert_eq!((hr, errors), (S_FALSE, vec![S_OK, OPC_E_BADRIGHTS]));
    let Callback::WriteComplete {
        items,
        master_error,
        ..
    } = wait_tx(&p, 501)
    else {
        panic!()
    };
    assert_eq!((master_error, items), (S_OK, vec![(2, S_OK)]));
    let (_, read) = client::sync_read(&p.group.sync(), OPC_DS_DEVICE, &p.h[1..2]).unwrap();
    assert_eq!(read[0].value, Value::R4(3.25));
    assert_eq!(read[0].quality, 0xD8);
    assert_eq!(read[0].timestamp, stamp);
    assert_alive(&p.server);
}

#[test]
fn cancel2_sends_on_cancel_complete_or_fails_once_completed() {
    let p = plant();
    let io = p.group.async2();
    let mut cancelled = 0;
    for tid in 601..611u32 {
        let (_, cancel, _) = client::async_read(&io, &p.h, tid).unwrap();
        // SAFETY: plain value.
        match unsafe { io.Cancel2(cancel) } {
            Ok(()) => {
                cancelled += 1;
                let c = wait_tx(&p, tid);
                assert!(
                    matches!(
                        c,
                        Callback::CancelComplete {
                            group: GROUP_CLIENT_HANDLE,
                            ..
                        }
                    ),
                    "{c:?}"
                );
                // ...and no OnReadComplete for it: time passes on purpose (300 ms, the
                // read completes at once otherwise) before the callbacks are counted.
                std::thread::sleep(Duration::from_millis(300));
                let n = p
                    .rec
                    .all()
                    .iter()
                    .filter(|c| c.transaction() == tid)
                    .count();
                assert_eq!(n, 1, "{:?}", p.rec.all());
            }
            Err(e) => {
                assert_eq!(e.code(), E_FAIL, "already completed");
                assert!(matches!(wait_tx(&p, tid), Callback::ReadComplete { .. }));
            }
        }
    }
    // The simulated data source answers at once, so most transactions have completed
    // before Cancel2 arrives (group_slow_source.rs covers the certain cancellation).
    eprintln!("Cancel2: {cancelled} of 10 cancelled before completion");
    assert_alive(&p.server);
}

#[test]
fn set_enable_false_stops_subscription_callbacks_but_not_refreshes() {
    let p = plant();
    let io = p.group.async2();
    assert!(client::get_enable(&io).expect("GetEnable"));
    p.rec
        .wait_for(WAIT, |c| {
            matches!(c, Callback::DataChange { transaction: 0, .. })
        })
        .expect("subscription callbacks");

    // SAFETY: plain value.
    unsafe { io.SetEnable(BOOL::from(false)) }.expect("SetEnable(FALSE)");
    assert!(!client::get_enable(&io).unwrap());
    // Time passes on purpose: 0.5 s for a callback already queued to arrive, then 2.5 s
    // (two and a half update periods) in which none may come.
    std::thread::sleep(Duration::from_millis(500));
    p.rec.clear();
    std::thread::sleep(Duration::from_millis(2_500));
    let subs = p
        .rec
        .all()
        .into_iter()
        .filter(|c| matches!(c, Callback::DataChange { transaction: 0, .. }))
        .count();
    assert_eq!(subs, 0, "no subscription callbacks while disabled");
    client::refresh2(&io, OPC_DS_CACHE, 701).expect("Refresh2 while disabled");
    let Callback::DataChange { items, .. } = wait_tx(&p, 701) else {
        panic!()
    };
    assert_eq!(clients(&items), vec![1, 2, 3]);
    let (_, _, _) = client::async_read(&io, &p.h, 702).unwrap();
    assert!(matches!(wait_tx(&p, 702), Callback::ReadComplete { .. }));

    // SAFETY: plain value.
    unsafe { io.SetEnable(BOOL::from(true)) }.expect("SetEnable(TRUE)");
    assert!(client::get_enable(&io).unwrap());
    p.rec
        .wait_for(WAIT, |c| {
            matches!(c, Callback::DataChange { transaction: 0, .. })
        })
        .expect("subscription callbacks again");
    assert_alive(&p.server);
}

#[test]
fn subscription_callbacks_carry_changed_values_with_transaction_id_zero() {
    let p = plant();
    let first = p
        .rec
        .wait_for(WAIT, |c| {
            matches!(c, Callback::DataChange { transaction: 0, .. })
        })
        .expect("first OnDataChange");
    let Callback::DataChange { group, items, .. } = first else {
        unreachable!()
    };
    assert_eq!(group, GROUP_CLIENT_HANDLE);
    assert_eq!(
        clients(&items),
        vec![1, 2, 3],
        "the first update has every active item"
    );
    // The temperature changes every plant tick: it is in later updates too, while the
    // setpoint, which nobody writes, is not sent again.
    let updates = || -> Vec<Vec<u32>> {
        p.rec
            .all()
            .into_iter()
            .filter_map(|c| match c {
                Callback::DataChange {
                    transaction: 0,
                    items,
                    ..
                } => Some(clients(&items)),
                _ => None,
            })
            .collect()
    };
    let three = p.rec.wait_count(WAIT, 3, |c| {
        matches!(c, Callback::DataChange { transaction: 0, .. })
    });
    assert!(three, "fewer than 3 updates: {:?}", updates());
    let updates = updates();
    assert!(
        updates[1..]
            .iter()
            .all(|u| u.contains(&3) && !u.contains(&2)),
        "{updates:?}"
    );
    assert_alive(&p.server);
}
