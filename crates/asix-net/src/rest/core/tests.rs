//! The REST link's decisions, with time as an argument.

use super::*;
use ctopc_core::Timestamp;

fn cfg(stations: usize, max_batch: usize, max_in_flight: usize) -> RestCoreConfig {
    RestCoreConfig {
        channel: "EVO".into(),
        stations: (0..stations).map(|i| format!("http://s{i}")).collect(),
        max_batch,
        max_in_flight,
        retry_interval: Duration::from_millis(1000),
        come_back_interval: Duration::from_millis(5000),
    }
}

struct T {
    core: RestCore,
    t0: Instant,
}

impl T {
    fn new(c: RestCoreConfig) -> T {
        T {
            core: RestCore::new(c),
            t0: Instant::now(),
        }
    }
    fn at(&self, ms: u64) -> Now {
        Now {
            mono: self.t0 + Duration::from_millis(ms),
            wall: Timestamp::from_unix_millis(1_000_000 + ms as i64),
        }
    }
    fn gets(&mut self) -> Vec<Get> {
        std::iter::from_fn(|| self.core.poll_get()).collect()
    }
    fn events(&mut self) -> Vec<ClientEvent> {
        std::iter::from_fn(|| self.core.poll_event()).collect()
    }
    fn updates(&mut self) -> Vec<(ItemKey, Vqt)> {
        self.events()
            .into_iter()
            .flat_map(|e| match e {
                ClientEvent::Updates(u) => u,
                _ => Vec::new(),
            })
            .collect()
    }
    /// Answers a GET with a good value per name (value = `v`).
    fn answer(&mut self, ms: u64, g: &Get, v: f64) {
        let states = g.names.iter().map(|n| good(n, v)).collect();
        self.core.handle_answer(self.at(ms), g.id, Ok(states));
    }
    fn fail(&mut self, ms: u64, g: &Get, e: FetchError) {
        self.core.handle_answer(self.at(ms), g.id, Err(e));
    }
}

fn good(name: &str, v: f64) -> VarState {
    VarState {
        id: Some(name.to_owned()),
        read_succeeded: true,
        status: String::new(),
        time: Some(Timestamp::from_unix_millis(42)),
        quality: 0xC0,
        value: RestValue::Float(v),
    }
}

fn key(n: &str) -> ItemKey {
    ItemKey::new("", n)
}

fn keys(names: &[&str]) -> Vec<(ItemKey, VarType)> {
    names.iter().map(|n| (key(n), VarType::R8)).collect()
}

fn names(g: &Get) -> Vec<&str> {
    g.names.iter().map(|n| &**n).collect()
}

#[test]
fn polls_at_the_fastest_rate_in_batches() {
    let mut t = T::new(cfg(1, 2, 8));
    t.core.subscribe(t.at(0), keys(&["A", "B", "C"]), 1000);
    t.core.subscribe(t.at(0), keys(&["D"]), 250);
    assert_eq!(
        t.core.poll_timeout(),
        Some(t.at(0).mono),
        "new variables: at once"
    );
    t.core.handle_timeout(t.at(0));
    let g = t.gets();
    assert_eq!(
        g.iter().map(names).collect::<Vec<_>>(),
        [vec!["A", "B"], vec!["C", "D"]]
    );
    assert_eq!(g[0].path, "/asix/v1/variable/value?name=A&name=B");
    assert_eq!(t.core.poll_timeout(), Some(t.at(250).mono), "fastest rate");
    for x in &g {
        t.answer(10, x, 1.5);
    }
    let ev = t.events();
    assert!(matches!(&ev[0], ClientEvent::ChannelUp { server, .. } if server == "http://s0"));
    let ups: Vec<_> = ev
        .iter()
        .flat_map(|e| match e {
            ClientEvent::Updates(u) => u.clone(),
            _ => Vec::new(),
        })
        .collect();
    assert_eq!(ups.len(), 4);
    assert_eq!(ups[0].1.value, Value::R8(1.5));
    assert_eq!(ups[0].1.timestamp, Timestamp::from_unix_millis(42));
    assert_eq!(t.core.batches(0), Some(true));
    // A poll under way when the next falls due: that one is skipped.
    t.core.handle_timeout(t.at(250));
    let g = t.gets();
    assert_eq!(g.len(), 2);
    t.core.handle_timeout(t.at(500));
    assert!(
        t.gets().is_empty(),
        "skipped while the last poll is under way"
    );
    t.core
        .unsubscribe(vec![key("A"), key("B"), key("C"), key("D")]);
    assert_eq!(t.core.poll_timeout(), None);
}

#[test]
fn concurrency_is_bounded() {
    let mut t = T::new(cfg(1, 1, 2));
    t.core
        .subscribe(t.at(0), keys(&["A", "B", "C", "D", "E"]), 1000);
    t.core.handle_timeout(t.at(0));
    let g = t.gets();
    assert_eq!(g.len(), 2);
    assert_eq!(t.core.in_flight(), 2);
    t.answer(1, &g[0], 1.0);
    let g2 = t.gets();
    assert_eq!(g2.len(), 1, "one more when one ended");
    assert_eq!(names(&g2[0]), ["C"]);
}

#[test]
fn a_station_that_does_not_batch_gets_one_name_per_request_once_decided() {
    let mut t = T::new(cfg(1, 10, 4));
    t.core.subscribe(t.at(0), keys(&["A", "B", "C"]), 1000);
    t.core.handle_timeout(t.at(0));
    let g = t.gets();
    assert_eq!(g.len(), 1);
    // Only the first name answered (what a single-name server does with a list).
    t.core
        .handle_answer(t.at(5), g[0].id, Ok(vec![good("A", 1.0)]));
    assert_eq!(t.core.batches(0), Some(false));
    let g = t.gets();
    assert_eq!(
        g.iter().map(names).collect::<Vec<_>>(),
        [["A"], ["B"], ["C"]]
    );
    for x in &g {
        t.answer(6, x, 2.0);
    }
    assert_eq!(t.updates().len(), 3);
    t.core.handle_timeout(t.at(1000));
    assert_eq!(t.gets().len(), 3, "singles from now on");
    // Other names than asked, in order: the same decision.
    let mut t = T::new(cfg(1, 10, 4));
    t.core.subscribe(t.at(0), keys(&["A", "B"]), 1000);
    t.core.handle_timeout(t.at(0));
    let g = t.gets();
    t.core
        .handle_answer(t.at(1), g[0].id, Ok(vec![good("B", 1.0), good("A", 1.0)]));
    assert_eq!(t.core.batches(0), Some(false));
    // A single name answered with two states is a malformed answer, not a fallback.
    let g = t.gets();
    t.core
        .handle_answer(t.at(2), g[0].id, Ok(vec![good("A", 1.0), good("A", 1.0)]));
    let ev = t.events();
    assert!(ev.iter().any(|e| matches!(e, ClientEvent::Updates(u) if u.iter().any(|(_, v)| v.quality == Quality::BAD_COMM_FAILURE))));
}

#[test]
fn failover_keeps_the_last_value_and_comes_back() {
    let mut t = T::new(cfg(2, 10, 4));
    t.core.subscribe(t.at(0), keys(&["A"]), 1000);
    t.core.handle_timeout(t.at(0));
    let g = t.gets();
    assert_eq!(g[0].station, 0);
    t.answer(1, &g[0], 7.0);
    t.events();
    t.core.handle_timeout(t.at(1000));
    let g = t.gets();
    t.fail(1100, &g[0], FetchError::Timeout);
    let ev = t.events();
    let bad = ev
        .iter()
        .find_map(|e| match e {
            ClientEvent::Updates(u) => Some(u[0].1.clone()),
            _ => None,
        })
        .unwrap();
    assert_eq!(bad.quality, Quality::BAD_COMM_FAILURE);
    assert_eq!(bad.value, Value::R8(7.0), "last value kept");
    assert!(ev.iter().any(|e| matches!(
        e,
        ClientEvent::ChannelDown {
            error: OpcError::NetAnswerTimeout,
            ..
        }
    )));
    // At once on the next station.
    let g = t.gets();
    assert_eq!((g.len(), g[0].station), (1, 1));
    t.answer(1110, &g[0], 8.0);
    let ev = t.events();
    assert!(ev
        .iter()
        .any(|e| matches!(e, ClientEvent::ChannelUp { server, .. } if server == "http://s1")));
    assert_eq!(t.core.station(), 1);
    // The preferred station is probed every come-back interval.
    t.core.handle_timeout(t.at(2000));
    let g = t.gets();
    assert_eq!(g.len(), 1, "the poll");
    t.answer(2001, &g[0], 8.0);
    t.core.handle_timeout(t.at(6110));
    let g = t.gets();
    let probe = g.iter().find(|x| x.station == 0).unwrap().clone();
    t.fail(6111, &probe, FetchError::Status(503));
    assert_eq!(t.core.station(), 1, "a failed probe changes nothing");
    for x in g.iter().filter(|x| x.station == 1) {
        t.answer(6112, x, 9.0);
    }
    t.events();
    t.core.handle_timeout(t.at(11_111));
    let g = t.gets();
    let probe = g.iter().find(|x| x.station == 0).unwrap().clone();
    t.answer(11_112, &probe, 9.0);
    assert_eq!(t.core.station(), 0);
    let ev = t.events();
    assert!(ev
        .iter()
        .any(|e| matches!(e, ClientEvent::ChannelUp { server, .. } if server == "http://s0")));
}

#[test]
fn every_station_failing_waits_the_retry_interval() {
    let mut t = T::new(cfg(2, 10, 4));
    t.core.subscribe(t.at(0), keys(&["A"]), 100);
    t.core.handle_timeout(t.at(0));
    let g = t.gets();
    t.fail(1, &g[0], FetchError::Transport("connection refused".into()));
    let g = t.gets();
    assert_eq!(g[0].station, 1);
    t.fail(2, &g[0], FetchError::Malformed("x".into()));
    assert!(t.gets().is_empty());
    assert_eq!(t.core.poll_timeout(), Some(t.at(1002).mono));
    let ev = t.events();
    assert_eq!(
        ev.iter()
            .filter(|e| matches!(e, ClientEvent::Updates(_)))
            .count(),
        1,
        "the failure quality once"
    );
    t.core.handle_timeout(t.at(1002));
    let g = t.gets();
    assert_eq!(g[0].station, 0, "a new round from the first station");
    // A subscription meanwhile does not cut the pause short.
    t.fail(1003, &g[0], FetchError::Timeout);
    let g = t.gets();
    t.fail(1004, &g[0], FetchError::Timeout);
    t.core.subscribe(t.at(1005), keys(&["B"]), 100);
    assert_eq!(t.core.poll_timeout(), Some(t.at(2004).mono));
}

#[test]
fn quality_and_failures_per_variable() {
    let mut t = T::new(cfg(1, 10, 4));
    let mut ks = keys(&["A", "B", "C", "D"]);
    ks[3].1 = VarType::I2;
    t.core.subscribe(t.at(0), ks, 1000);
    t.core.handle_timeout(t.at(0));
    let g = t.gets();
    let mut a = good("A", 1.0);
    a.quality = 0xAB_D6; // vendor bits, limit bits: passed through
    a.time = None;
    let b = VarState {
        read_succeeded: false,
        status: "Unknown variable".into(),
        ..good("B", 0.0)
    };
    let c = VarState {
        value: RestValue::Text("not a number".into()),
        ..good("C", 0.0)
    };
    let d = VarState {
        value: RestValue::Int(7),
        ..good("D", 0.0)
    };
    t.core.handle_answer(t.at(3), g[0].id, Ok(vec![a, b, c, d]));
    let u = t.updates();
    assert_eq!(u[0].1.quality, Quality(0xAB_D6));
    assert_eq!(u[0].1.timestamp, t.at(3).wall, "no time: the poll's");
    assert_eq!(u[1].1.quality, Quality::BAD_CONFIG_ERROR);
    assert_eq!(u[2].1.quality, Quality::BAD_CONFIG_ERROR);
    assert_eq!(u[3].1.value, Value::I2(7), "the variable's type");
    assert_eq!(
        convert(RestValue::Unsupported, VarType::R8).map(|_| ()),
        Err("an object or array value".into())
    );
    assert!(convert(RestValue::Float(1e10), VarType::I2).is_err());
    assert_eq!(
        convert(RestValue::Text("x".into()), VarType::EMPTY),
        Ok(Value::Bstr("x".into()))
    );
}

#[test]
fn device_reads_answer_in_request_order() {
    let mut t = T::new(cfg(1, 2, 4));
    t.core.read(t.at(0), 9, keys(&["A", "B", "C"]));
    let g = t.gets();
    assert_eq!(g.len(), 2);
    t.answer(1, &g[1], 3.0);
    assert!(t
        .events()
        .iter()
        .all(|e| !matches!(e, ClientEvent::ReadDone { .. })));
    t.answer(2, &g[0], 1.0);
    let ev = t.events();
    let ClientEvent::ReadDone { id, results } = ev.last().unwrap() else {
        panic!("{ev:?}")
    };
    assert_eq!(*id, 9);
    let names: Vec<_> = results.iter().map(|(k, _)| &*k.variable).collect();
    assert_eq!(names, ["A", "B", "C"]);
    assert_eq!(results[2].1.as_ref().unwrap().value, Value::R8(3.0));
    // A failed read: BAD Comm Failure per item.
    t.core.read(t.at(3), 10, keys(&["A"]));
    let g = t.gets();
    t.fail(4, &g[0], FetchError::TooLarge(10));
    let ev = t.events();
    let r = ev
        .iter()
        .find_map(|e| match e {
            ClientEvent::ReadDone { id: 10, results } => Some(results.clone()),
            _ => None,
        })
        .unwrap();
    assert_eq!(r[0].1.as_ref().unwrap().quality, Quality::BAD_COMM_FAILURE);
    // An empty read answers at once.
    t.core.read(t.at(5), 11, Vec::new());
    assert!(matches!(
        t.events()[..],
        [ClientEvent::ReadDone { id: 11, .. }]
    ));
}

#[test]
fn names_are_percent_encoded() {
    assert_eq!(
        values_path(&["A B", "Ż&=?"]),
        "/asix/v1/variable/value?name=A%20B&name=%C5%BB%26%3D%3F"
    );
}

#[test]
fn the_pause_after_every_station_failed_holds_the_queued_requests_too() {
    let mut t = T::new(cfg(1, 1, 1));
    t.core.subscribe(t.at(0), keys(&["A", "B", "C"]), 100);
    t.core.handle_timeout(t.at(0));
    let g = t.gets();
    assert_eq!(g.len(), 1, "one at a time");
    t.fail(1, &g[0], FetchError::Timeout);
    assert!(t.gets().is_empty(), "nothing asked during the pause");
    let u = t.updates();
    assert_eq!(u.len(), 3, "every variable BAD: {u:?}");
    assert!(u
        .iter()
        .all(|(_, v)| v.quality == Quality::BAD_COMM_FAILURE));
    assert_eq!(t.core.poll_timeout(), Some(t.at(1001).mono));
    t.core.handle_timeout(t.at(1001));
    assert_eq!(t.gets().len(), 1, "the next round");
}
