//! Asynchronous group I/O end to end (IOPCAsyncIO2, IOPCAsyncIO3) with a test
//! IOPCDataCallback sink in this process: OnReadComplete, OnWriteComplete, OnDataChange
//! for refreshes (with the client's transaction ID) and subscriptions, Cancel2 and
//! OnCancelComplete, SetEnable/GetEnable, and the failure codes. The default simulation
//! answers at once, so Cancel2 here races the completion; group_slow_source.rs cancels
//! operations that certainly wait for a slow device.
#![cfg(windows)]

use ctopc_core::model::ItemVqt;
use ctopc_core::{Quality, Timestamp, Value};
use e2e_tests::io_support::*;
use e2e_tests::{assert_alive, code, connect, interfaces::*, Apartment, Server};
use opc_client as client;
use std::sync::Arc;
use std::time::Duration;
use windows::core::{BOOL, HRESULT};
use windows::Win32::Foundation::{E_FAIL, E_INVALIDARG, S_FALSE, S_OK};
use windows::Win32::System::Ole::CONNECT_E_NOCONNECTION;
use windows::Win32::System::Variant::{VARIANT, VT_R4};

const RPC_X_NULL_REF_POINTER: HRESULT = HRESULT(0x800706F4u32 as i32);
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
    rec: Arc<Recorder>,
    cookie: Option<u32>,
}

fn plant_with(advise: bool) -> Plant {
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
    let rec = Recorder::recording();
    let cookie = advise.then(|| {
        client::advise_data_callback(&group.unknown, &TestSink::create(&rec))
            .expect("Advise(IOPCDataCallback)")
    });
    Plant {
        _com: com,
        server,
        group,
        h,
        rec,
        cookie,
    }
}

fn plant() -> Plant {
    plant_with(true)
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
fn async_read_with_invalid_handles_reports_them_in_the_call_only() {
    let p = plant();
    let (hr, cancel, errors) =
        client::async_read(&p.group.async2(), &[0xDEAD_BEEF, p.h[0]], 102).unwrap();
    assert_eq!(hr, S_FALSE);
    assert_eq!(errors, vec![OPC_E_INVALIDHANDLE, S_OK]);
    assert_ne!(cancel, 0);
    let Callback::ReadComplete { items, .. } = wait_tx(&p, 102) else {
        panic!()
    };
    assert_eq!(clients(&items), vec![1]);
    // Every item invalid: S_FALSE and no callback.
    let (hr, _, errors) = client::async_read(&p.group.async2(), &[0xDEAD_BEEF], 103).unwrap();
    assert_eq!((hr, errors), (S_FALSE, vec![OPC_E_INVALIDHANDLE]));
    assert!(p
        .rec
        .wait_for(Duration::from_millis(1500), |c| c.transaction() == 103)
        .is_none());
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
    let rec = Recorder::recording();
    client::advise_data_callback(&g2.unknown, &TestSink::create(&rec)).unwrap();
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
                // ...and no OnReadComplete for it.
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
    // Unknown cancel IDs, and one that completed long ago.
    // SAFETY: plain values.
    unsafe {
        assert_eq!(code(&io.Cancel2(0)), E_FAIL);
        assert_eq!(code(&io.Cancel2(0xFFFF_FFF0)), E_FAIL);
    }
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
    std::thread::sleep(Duration::from_millis(500)); // a callback already queued may still arrive
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
fn async_calls_without_a_connected_callback_are_connect_e_noconnection() {
    let p = plant_with(false);
    let io = p.group.async2();
    let io3 = p.group.async3();
    let vqt = [(p.h[1], ItemVqt::value(Value::R4(1.0)))];
    let codes = [
        code(&client::async_read(&io, &p.h, 1)),
        code(&client::async_write(&io, &[(p.h[1], Value::R4(1.0))], 2)),
        code(&client::refresh2(&io, OPC_DS_CACHE, 3)),
        code(&client::async_read_max_age(&io3, &[(p.h[0], 0)], 4)),
        code(&client::async_write_vqt(&io3, &vqt, 5)),
        code(&client::refresh_max_age(&io3, 0, 6)),
        code(&client::get_enable(&io)),
        // SAFETY: plain value.
        code(&unsafe { io.SetEnable(BOOL::from(false)) }),
    ];
    assert_eq!(codes, [CONNECT_E_NOCONNECTION; 8]);
    assert_alive(&p.server);

    // After Unadvise, the same.
    let q = plant();
    client::unadvise_data_callback(&q.group.unknown, q.cookie.unwrap()).expect("Unadvise");
    assert_eq!(
        code(&client::async_read(&q.group.async2(), &q.h, 7)),
        CONNECT_E_NOCONNECTION
    );
    assert_eq!(
        code(&client::refresh2(&q.group.async2(), OPC_DS_DEVICE, 8)),
        CONNECT_E_NOCONNECTION
    );
    assert_alive(&q.server);
}

#[test]
fn count_zero_invalid_source_and_null_pointers_are_rejected() {
    let p = plant();
    let io = p.group.async2();
    let io3 = p.group.async3();
    assert_eq!(code(&client::async_read(&io, &[], 1)), E_INVALIDARG);
    assert_eq!(code(&client::async_write(&io, &[], 1)), E_INVALIDARG);
    assert_eq!(
        code(&client::async_read_max_age(&io3, &[], 1)),
        E_INVALIDARG
    );
    assert_eq!(code(&client::async_write_vqt(&io3, &[], 1)), E_INVALIDARG);
    assert_eq!(
        code(&client::refresh2(&io, OPCDATASOURCE(7), 1)),
        E_INVALIDARG
    );

    let mut cancel = 0u32;
    let mut errors: *mut HRESULT = std::ptr::null_mut();
    let v = VARIANT::default();
    let age = 0u32;
    let vqt = OPCITEMVQT::default();
    let rejected = |hr: HRESULT| hr == E_INVALIDARG || hr == RPC_X_NULL_REF_POINTER;
    // SAFETY: deliberately NULL pointers; the valid ones are live for each call.
    unsafe {
        let h = p.h.as_ptr();
        let hrs = [
            io.Read(1, std::ptr::null(), 1, &mut cancel, &mut errors),
            io.Read(1, h, 1, std::ptr::null_mut(), &mut errors),
            io.Read(1, h, 1, &mut cancel, std::ptr::null_mut()),
            io.Write(1, h, std::ptr::null(), 1, &mut cancel, &mut errors),
            io.Write(1, h, &v, 1, std::ptr::null_mut(), &mut errors),
            io3.ReadMaxAge(1, std::ptr::null(), &age, 1, &mut cancel, &mut errors),
            io3.ReadMaxAge(1, h, std::ptr::null(), 1, &mut cancel, &mut errors),
            io3.ReadMaxAge(1, h, &age, 1, std::ptr::null_mut(), &mut errors),
            io3.ReadMaxAge(1, h, &age, 1, &mut cancel, std::ptr::null_mut()),
            io3.WriteVQT(1, h, std::ptr::null(), 1, &mut cancel, &mut errors),
            io3.WriteVQT(1, h, &vqt, 1, &mut cancel, std::ptr::null_mut()),
        ];
        for (i, hr) in hrs.iter().enumerate() {
            assert!(rejected(*hr), "call {i}: {hr:?}");
        }
        assert!(rejected(code(&io.Refresh2(
            OPC_DS_CACHE,
            1,
            std::ptr::null_mut()
        ))));
        assert!(rejected(code(&io3.RefreshMaxAge(
            0,
            1,
            std::ptr::null_mut()
        ))));
        assert!(rejected(code(&io.GetEnable(std::ptr::null_mut()))));
    }
    assert!(errors.is_null());
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
    let deadline = std::time::Instant::now() + WAIT;
    loop {
        let updates: Vec<Vec<u32>> = p
            .rec
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
            .collect();
        if updates.len() >= 3 {
            assert!(
                updates[1..]
                    .iter()
                    .all(|u| u.contains(&3) && !u.contains(&2)),
                "{updates:?}"
            );
            break;
        }
        assert!(std::time::Instant::now() < deadline, "{updates:?}");
        std::thread::sleep(Duration::from_millis(200));
    }
    assert_alive(&p.server);
}
