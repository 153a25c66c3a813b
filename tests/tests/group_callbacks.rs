//! The group's IConnectionPointContainer and IOPCDataCallback end to end: subscription
//! callbacks from the simulated demo plant, keep-alive callbacks, an STA client, Unadvise,
//! the advise limit, a slow client next to a quick one.
#![cfg(windows)]

mod group_common;

use ctopc_com::apartment::Apartment;
use ctopc_core::Value;
use e2e_tests::{assert_alive, code, connect, connections, interfaces::*, next_connection, PROGID};
use group_common::*;
use opc_client::{GroupStateChange, Server};
use std::time::{Duration, Instant};
use windows::core::{IUnknown, Interface};
use windows::Win32::Foundation::{S_FALSE, S_OK};
use windows::Win32::System::Com::IConnectionPointContainer;
use windows::Win32::System::Ole::{
    CONNECT_E_ADVISELIMIT, CONNECT_E_CANNOTCONNECT, CONNECT_E_NOCONNECTION,
};
use windows::Win32::UI::WindowsAndMessaging::{
    DispatchMessageW, PeekMessageW, TranslateMessage, MSG, PM_REMOVE,
};

const GROUP_CLIENT: u32 = 0x600D;

fn has_item(c: &Change, client: u32) -> bool {
    c.transaction == 0 && c.items.iter().any(|i| i.0 == client)
}

#[test]
fn active_items_of_an_active_group_arrive_in_on_data_change() {
    let (_com, server) = connect();
    let g = add_group(&server, "cb-data", true, GROUP_CLIENT);
    add_ok(
        &g,
        &[
            item("KW_A000", 1),
            item("KW_A001", 2),
            inactive("KW_A003", 3),
        ],
    );
    let log = Log::new();
    let sink = Sink::create(&log);
    let cookie = advise(&g, &sink).unwrap();
    assert_ne!(cookie, 0);

    let first = log.wait(Duration::from_secs(5), 1, |c| has_item(c, 1));
    assert!(
        !first.is_empty(),
        "no OnDataChange within 5 s: {:?}",
        log.changes()
    );
    let c = &first[0];
    assert_eq!(c.group, GROUP_CLIENT, "hGroup is the client's group handle");
    assert_eq!(c.transaction, 0);
    let (_, value, quality, error) = c.items.iter().find(|i| i.0 == 1).unwrap();
    assert_eq!(*error, S_OK);
    assert_eq!(quality & 0xC0, 0xC0, "good quality: {quality:#x}");
    match value {
        Value::R4(level) => assert!((0.0..=8.0).contains(level), "{level}"),
        other => panic!("KW_A000 is R4: {other:?}"),
    }
    assert!(
        log.changes()
            .iter()
            .all(|c| c.items.iter().all(|i| i.0 != 3)),
        "inactive items are not reported"
    );
    // The simulated level changes: later callbacks report KW_A000 again, with a new value.
    let more = log.wait(Duration::from_secs(20), 2, |c| has_item(c, 1));
    assert!(more.len() >= 2, "KW_A000 did not change within 20 s");
    unadvise(&g, cookie).unwrap();
    assert_alive(&server);
}

#[test]
fn keep_alive_callbacks_arrive_when_nothing_changes() {
    let (_com, server) = connect();
    let g = add_group(&server, "cb-keepalive", true, GROUP_CLIENT);
    // KW_A110 is a setpoint: constant in the simulation.
    add_ok(&g, &[item("KW_A110", 5)]);
    assert_eq!(g.set_keep_alive(1000).unwrap(), (S_OK, 1000));
    let log = Log::new();
    let cookie = advise(&g, &Sink::create(&log)).unwrap();
    let initial = log.wait(Duration::from_secs(5), 1, |c| has_item(c, 5));
    assert_eq!(
        initial.len(),
        1,
        "the setpoint's first value: {:?}",
        log.changes()
    );
    let keep_alives = log.wait(Duration::from_secs(6), 3, |c| {
        c.transaction == 0 && c.items.is_empty()
    });
    assert!(
        keep_alives.len() >= 3,
        "keep-alive callbacks (no items): {:?}",
        log.changes()
    );
    assert!(keep_alives.iter().all(|c| c.group == GROUP_CLIENT));
    // About one per second.
    let span = keep_alives[2].at.duration_since(keep_alives[0].at);
    assert!(
        span >= Duration::from_millis(1500) && span <= Duration::from_millis(3500),
        "{span:?}"
    );
    // The constant setpoint is not reported again.
    assert_eq!(log.changes().iter().filter(|c| has_item(c, 5)).count(), 1);
    unadvise(&g, cookie).unwrap();
    assert_alive(&server);
}

#[test]
fn keep_alive_with_only_inactive_items() {
    let (_com, server) = connect();
    let g = add_group(&server, "cb-keepalive-inactive", true, GROUP_CLIENT);
    add_ok(&g, &[inactive("KW_A000", 1)]);
    assert_eq!(g.set_keep_alive(1000).unwrap().0, S_OK);
    let log = Log::new();
    let cookie = advise(&g, &Sink::create(&log)).unwrap();
    let keep_alives = log.wait(Duration::from_secs(6), 2, |c| c.items.is_empty());
    assert!(keep_alives.len() >= 2, "{:?}", log.changes());
    assert!(log.changes().iter().all(|c| c.items.is_empty()));
    unadvise(&g, cookie).unwrap();
    assert_alive(&server);
}

#[test]
fn an_inactive_group_calls_back_only_once_activated() {
    let (_com, server) = connect();
    let g = add_group(&server, "cb-inactive", false, GROUP_CLIENT);
    add_ok(&g, &[item("KW_A000", 1)]);
    let log = Log::new();
    let cookie = advise(&g, &Sink::create(&log)).unwrap();
    std::thread::sleep(Duration::from_secs(3));
    assert_eq!(
        log.count(),
        0,
        "an inactive group sends nothing: {:?}",
        log.changes()
    );
    assert_eq!(
        g.set_state(&GroupStateChange {
            active: Some(true),
            ..Default::default()
        })
        .unwrap()
        .0,
        S_OK
    );
    let got = log.wait(Duration::from_secs(5), 1, |c| has_item(c, 1));
    assert!(!got.is_empty(), "no OnDataChange after activation");
    unadvise(&g, cookie).unwrap();
    assert_alive(&server);
}

#[test]
fn unadvise_stops_callbacks() {
    let (_com, server) = connect();
    let g = add_group(&server, "cb-unadvise", true, GROUP_CLIENT);
    add_ok(&g, &[item("KW_A000", 1)]);
    assert_eq!(g.set_keep_alive(1000).unwrap().0, S_OK);
    let log = Log::new();
    let cookie = advise(&g, &Sink::create(&log)).unwrap();
    let got = log.wait(Duration::from_secs(6), 2, |_| true);
    assert!(got.len() >= 2, "{:?}", log.changes());
    unadvise(&g, cookie).unwrap();
    // A callback already on its way may still land.
    std::thread::sleep(Duration::from_millis(700));
    let after = log.count();
    std::thread::sleep(Duration::from_secs(3));
    assert_eq!(log.count(), after, "callbacks after Unadvise");
    // The same cookie again is no connection.
    assert_eq!(code(&unadvise(&g, cookie)), CONNECT_E_NOCONNECTION);
    assert_alive(&server);
}

#[test]
fn one_connection_per_group_and_connection_point_rules() {
    let (_com, server) = connect();
    let g = add_group(&server, "cb-rules", true, GROUP_CLIENT);
    let log = Log::new();
    let cookie = advise(&g, &Sink::create(&log)).unwrap();
    let other = Log::new();
    assert_eq!(
        code(&advise(&g, &Sink::create(&other))),
        CONNECT_E_ADVISELIMIT
    );
    assert_eq!(
        code(&unadvise(&g, cookie.wrapping_add(1000))),
        CONNECT_E_NOCONNECTION
    );
    unadvise(&g, cookie).unwrap();
    let cookie2 = advise(&g, &Sink::create(&other)).expect("advise again after Unadvise");
    assert_ne!(cookie2, 0);
    unadvise(&g, cookie2).unwrap();

    // A sink without IOPCDataCallback.
    let cp = data_point(&g);
    // SAFETY: a valid interface pointer.
    let r = unsafe { cp.Advise(&server.unknown) };
    assert_eq!(code(&r), CONNECT_E_CANNOTCONNECT);

    // EnumConnections lists the one connection (cookie and sink), and none without it.
    let sink = Sink::create(&other);
    let cookie3 = advise(&g, &sink).unwrap();
    let listed = connections(&cp);
    assert_eq!(listed.len(), 1, "one connection");
    let sink_identity: IUnknown = sink.cast().unwrap();
    assert_eq!(
        (listed[0].0, listed[0].1.as_raw()),
        (cookie3, sink_identity.as_raw()),
        "its cookie and sink"
    );
    unadvise(&g, cookie3).unwrap();
    assert!(connections(&cp).is_empty(), "no connection after Unadvise");
    // The enumerator's Skip, Reset and Clone.
    // SAFETY: plain calls on valid interfaces.
    unsafe {
        let cookie4 = advise(&g, &sink).unwrap();
        let e = cp.EnumConnections().unwrap();
        // Through the vtable: windows-rs turns S_FALSE into Ok.
        let skip = |n: u32| (Interface::vtable(&e).Skip)(Interface::as_raw(&e), n);
        assert_eq!(skip(1), S_OK);
        assert_eq!(skip(1), S_FALSE, "nothing left to skip");
        e.Reset().unwrap();
        let c = e.Clone().unwrap();
        assert_eq!(next_connection(&c).map(|x| x.0), Some(cookie4));
        unadvise(&g, cookie4).unwrap();
    }

    // The point's interface and container; no point for other interfaces.
    assert_eq!(
        // SAFETY: plain calls on valid interfaces.
        unsafe { cp.GetConnectionInterface() }.unwrap(),
        IOPCDataCallback::IID
    );
    // SAFETY: as above.
    let container: IUnknown = unsafe { cp.GetConnectionPointContainer() }
        .unwrap()
        .cast()
        .unwrap();
    let group_identity: IUnknown = g.unknown.cast().unwrap();
    assert_eq!(container.as_raw(), group_identity.as_raw());
    let cpc: IConnectionPointContainer = g.unknown.cast().unwrap();
    // SAFETY: valid IID.
    let r = unsafe { cpc.FindConnectionPoint(&IOPCShutdown::IID) };
    assert_eq!(code(&r), CONNECT_E_NOCONNECTION);
    // EnumConnectionPoints gives an enumerator. (Its Next is not checked here: through
    // Wine 8's own IEnumConnectionPoints proxy the call returns a garbage HRESULT and
    // count; OPC clients use FindConnectionPoint.)
    // SAFETY: plain calls on valid interfaces.
    unsafe {
        let e = cpc.EnumConnectionPoints().unwrap();
        e.Reset().unwrap();
    }
    assert_alive(&server);
}

#[test]
fn callbacks_reach_an_sta_client_that_pumps_messages() {
    let t = std::thread::spawn(|| {
        let _com = Apartment::sta().expect("STA");
        let server = Server::connect(PROGID).expect("connect from an STA");
        let g = add_group(&server, "cb-sta", true, GROUP_CLIENT);
        add_ok(&g, &[item("KW_A000", 1)]);
        let log = Log::new();
        let cookie = advise(&g, &Sink::create(&log)).unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        while log.count() == 0 && Instant::now() < deadline {
            let mut msg = MSG::default();
            // SAFETY: standard message pump on this STA thread.
            unsafe {
                while PeekMessageW(&mut msg, None, 0, 0, PM_REMOVE).as_bool() {
                    let _ = TranslateMessage(&msg);
                    DispatchMessageW(&msg);
                }
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let changes = log.changes();
        unadvise(&g, cookie).unwrap();
        assert_alive(&server);
        changes
    });
    let changes = t.join().expect("STA thread");
    assert!(
        changes
            .iter()
            .any(|c| has_item(c, 1) && c.group == GROUP_CLIENT),
        "no callback in the STA: {changes:?}"
    );
}

#[test]
fn releasing_an_advised_group_is_clean() {
    let (_com, server) = connect();
    let g = add_group(&server, "cb-release", true, GROUP_CLIENT);
    add_ok(&g, &[item("KW_A000", 1)]);
    let log = Log::new();
    let _cookie = advise(&g, &Sink::create(&log)).unwrap();
    log.wait(Duration::from_secs(5), 1, |_| true);
    // Released without Unadvise: the server drops the sink with the group object.
    drop(g);
    std::thread::sleep(Duration::from_millis(1500));
    let n = log.count();
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(
        log.count(),
        n,
        "callbacks after the group object was released"
    );
    assert_alive(&server);
}

#[test]
fn a_slow_client_gets_paced_callbacks_without_a_backlog_and_does_not_stall_another() {
    // Two clients, each a group with a constant setpoint and a 1 s keep-alive: a callback
    // is due every second for each. The slow one holds every OnDataChange for 3 s.
    let (_com, slow_server) = connect();
    let quick_server = Server::connect(PROGID).expect("second connection");
    let mut logs = Vec::new();
    let mut groups = Vec::new();
    for (server, name) in [(&slow_server, "cb-slow"), (&quick_server, "cb-quick")] {
        let g = add_group(server, name, true, GROUP_CLIENT);
        add_ok(&g, &[item("KW_A110", 5)]);
        assert_eq!(g.set_keep_alive(1000).unwrap(), (S_OK, 1000));
        let log = Log::new();
        if name == "cb-slow" {
            log.hold_calls(Duration::from_secs(3));
        }
        let cookie = advise(&g, &Sink::create(&log)).unwrap();
        logs.push(log);
        groups.push((g, cookie));
    }
    let (slow, quick) = (&logs[0], &logs[1]);
    let start = Instant::now();
    std::thread::sleep(Duration::from_secs(10));
    let (slow_n, quick_n) = (slow.count(), quick.count());
    // The quick client is not held up by the slow one: about ten callbacks.
    assert!(
        quick_n >= 7,
        "the quick client got {quick_n} callbacks in 10 s"
    );
    // The slow one gets a callback as soon as it returns from the previous one: about four.
    assert!(
        (2..=5).contains(&slow_n),
        "the slow client got {slow_n} callbacks in 10 s: {:?}",
        slow.changes()
    );
    let held = slow.changes();
    for pair in held.windows(2) {
        let gap = pair[1].at.duration_since(pair[0].at);
        assert!(
            gap >= Duration::from_millis(2900),
            "a callback came while the previous one was held: {gap:?}"
        );
    }
    // When it speeds up, no backlog of the missed updates arrives: the callbacks pending
    // for the group (at most two: one prepared while another travels, and the update
    // that fell due meanwhile), then one a second again.
    slow.release();
    std::thread::sleep(Duration::from_millis(700));
    let burst = slow.count() - slow_n;
    assert!(
        burst <= 3,
        "{burst} callbacks within 0.7 s of the client's return (a backlog): {:?}",
        &slow.changes()[slow_n..]
    );
    let later = slow.wait(Duration::from_secs(5), slow_n + burst + 2, |_| true);
    assert!(
        later.len() >= slow_n + burst + 2,
        "callbacks resume at the update rate: {:?}",
        start.elapsed()
    );
    for (g, cookie) in &groups {
        unadvise(g, *cookie).unwrap();
    }
    assert_alive(&slow_server);
    assert_alive(&quick_server);
}
