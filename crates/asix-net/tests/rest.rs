//! The Asix.Evo REST link against asix-sim's REST mode on loopback: the link alone (values,
//! batches and the single-name fallback, failover and come-back, every kind of bad answer
//! turning into BAD quality without a hang), then the engine over the network source with
//! a channel that names two REST stations (subscribe, device read, refused write,
//! failover, the `_Diagnostics` channel status).

mod common;

use std::net::SocketAddr;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use asix_model::namespace::AsixNamespace;
use asix_model::{load_database_file, ItemKey, Secret};
use asix_net::client::{wall_now, ClientEvent};
use asix_net::datasource::{AsixSource, NamespaceResolver};
use asix_net::rest::{Auth, FetchError, RestCoreConfig, RestLink, RestSettings, MAX_BODY};
use asix_net::sim::plant::{channels_from_database, ACID_PLANT_CHANNEL};
use asix_net::sim::rest::RestServer;
use asix_net::sim::SimHandle;
use asix_net::{channel_sink, ClientConfig};
use common::*;
use ctopc_core::diagnostics::LinkState;
use ctopc_core::model::{
    DataSource as ReadFrom, Engine, EngineConfig, GroupParams, ItemDefinition, SyncOutcome,
    SyncResult,
};
use ctopc_core::namespace::{Namespace, OPC_READABLE};
use ctopc_core::source::{Backend, SourceOutput, Wake};
use ctopc_core::{OpcError, Quality, Value, VarType};

fn loopback() -> SocketAddr {
    "127.0.0.1:0".parse().unwrap()
}

async fn station(name: &str) -> (SimHandle, RestServer) {
    let sim = sim(name).await;
    let rest = sim.serve_rest(loopback()).await.expect("REST server");
    (sim, rest)
}

fn settings(urls: &[String], timeout_ms: u64) -> RestSettings {
    RestSettings {
        core: RestCoreConfig {
            channel: "EVO".into(),
            stations: urls.to_vec(),
            max_batch: 100,
            max_in_flight: 4,
            retry_interval: Duration::from_millis(200),
            come_back_interval: Duration::from_millis(300),
        },
        auth: Auth::None,
        request_timeout: Duration::from_millis(timeout_ms),
        max_body: MAX_BODY,
    }
}

fn link(s: RestSettings) -> (RestLink, Events) {
    let (sink, rx) = channel_sink();
    let l = RestLink::start(s, sink, &tokio::runtime::Handle::current()).expect("link starts");
    (
        l,
        Events {
            rx,
            seen: Vec::new(),
        },
    )
}

/// The acid plant's variables (any channel: REST names are variable names).
fn k(var: &str) -> ItemKey {
    ItemKey::new("", var)
}

const VARS: [&str; 3] = ["ZB1_POZIOM", "ZB2_POZIOM", "ZB3_POZIOM"];

fn typed(names: &[&str]) -> Vec<(ItemKey, VarType)> {
    names.iter().map(|n| (k(n), VarType::EMPTY)).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn values_in_batches_and_one_per_request_when_the_station_does_not_batch() {
    tokio::time::timeout(TEST_LIMIT, async {
        let (_sim, rest) = station("EVO1").await;
        let (l, mut ev) = link(settings(&[rest.url()], 1000));
        l.subscribe(typed(&VARS), 100);
        assert_eq!(ev.channel_up(Duration::from_secs(5)).await, rest.url());
        let v = ev
            .vqt_of(
                &k("ZB1_POZIOM"),
                Duration::from_secs(5),
                "a good level",
                |q| q.is_good(),
            )
            .await;
        assert!(matches!(v.value, Value::R8(_)), "as answered: {v:?}");
        // An unknown variable: BAD Config Error (the server's readSucceeded=false).
        l.subscribe(typed(&["NO_SUCH"]), 100);
        ev.vqt_of(&k("NO_SUCH"), Duration::from_secs(5), "config error", |q| {
            q == Quality::BAD_CONFIG_ERROR
        })
        .await;
        let m = rest.mode();
        let (r0, n0) = (
            m.requests.load(Ordering::SeqCst),
            m.names.load(Ordering::SeqCst),
        );
        tokio::time::sleep(Duration::from_millis(500)).await;
        let (r1, n1) = (
            m.requests.load(Ordering::SeqCst),
            m.names.load(Ordering::SeqCst),
        );
        assert!(
            (n1 - n0) >= 3 * (r1 - r0),
            "batches: {} names in {} requests",
            n1 - n0,
            r1 - r0
        );
        // The station stops batching: the link asks one name per request, values go on.
        m.apply("single=1").unwrap();
        tokio::time::sleep(Duration::from_millis(300)).await;
        ev.drain();
        let before = m.requests.load(Ordering::SeqCst);
        let nb = m.names.load(Ordering::SeqCst);
        tokio::time::sleep(Duration::from_millis(500)).await;
        let (r2, n2) = (
            m.requests.load(Ordering::SeqCst),
            m.names.load(Ordering::SeqCst),
        );
        assert_eq!(r2 - before, n2 - nb, "one name per request");
        ev.vqt_of(
            &k("ZB2_POZIOM"),
            Duration::from_secs(5),
            "values go on",
            |q| q.is_good(),
        )
        .await;
        // A device read, batched as the station allows.
        let id = l.read(typed(&VARS));
        let r = ev
            .wait(Duration::from_secs(5), "read", |e| match e {
                ClientEvent::ReadDone { id: i, results } if *i == id => Some(results.clone()),
                _ => None,
            })
            .await;
        assert_eq!(r.len(), 3);
        assert!(
            r.iter().all(|(_, v)| v.as_ref().unwrap().quality.is_good()),
            "{r:?}"
        );
    })
    .await
    .expect("in time");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn failover_to_the_standby_and_back() {
    tokio::time::timeout(TEST_LIMIT, async {
        let (_s1, r1) = station("EVO1").await;
        let (_s2, r2) = station("EVO2").await;
        let (l, mut ev) = link(settings(&[r1.url(), r2.url()], 500));
        l.subscribe(typed(&VARS), 100);
        assert_eq!(ev.channel_up(Duration::from_secs(5)).await, r1.url());
        r1.mode().apply("fail=1").unwrap();
        ev.wait(Duration::from_secs(5), "down", |e| {
            matches!(e, ClientEvent::ChannelDown { .. }).then_some(())
        })
        .await;
        assert_eq!(ev.channel_up(Duration::from_secs(5)).await, r2.url());
        ev.vqt_of(
            &k("ZB1_POZIOM"),
            Duration::from_secs(5),
            "values from the standby",
            |q| q.is_good(),
        )
        .await;
        r1.mode().apply("reset=1").unwrap();
        assert_eq!(
            ev.channel_up(Duration::from_secs(5)).await,
            r1.url(),
            "come-back"
        );
    })
    .await
    .expect("in time");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_answers_are_bad_quality_without_a_hang() {
    tokio::time::timeout(TEST_LIMIT, async {
        for (switch, timeout_ms) in [
            ("slow_ms=2000", 300),
            ("slow_body_ms=50", 300),
            ("malformed=1", 1000),
            ("huge=1", 5000),
            ("redirect=1", 1000),
            ("fail=1", 1000),
        ] {
            let (_sim, rest) = station("EVO1").await;
            let (l, mut ev) = link(settings(&[rest.url()], timeout_ms));
            l.subscribe(typed(&VARS[..1]), 100);
            let good = ev
                .vqt_of(&k(VARS[0]), Duration::from_secs(5), "good", |q| q.is_good())
                .await;
            rest.mode().apply(switch).unwrap();
            let t0 = Instant::now();
            let bad = ev
                .vqt_of(&k(VARS[0]), Duration::from_secs(10), switch, |q| {
                    q == Quality::BAD_COMM_FAILURE
                })
                .await;
            assert!(t0.elapsed() < Duration::from_secs(8), "{switch}");
            assert_eq!(
                std::mem::discriminant(&bad.value),
                std::mem::discriminant(&good.value),
                "{switch}: the last value is kept"
            );
            // A device read answers too, BAD.
            let id = l.read(typed(&VARS[..1]));
            let r = ev
                .wait(Duration::from_secs(10), "read", |e| match e {
                    ClientEvent::ReadDone { id: i, results } if *i == id => Some(results.clone()),
                    _ => None,
                })
                .await;
            assert_eq!(
                r[0].1.as_ref().unwrap().quality,
                Quality::BAD_COMM_FAILURE,
                "{switch}"
            );
        }
    })
    .await
    .expect("in time");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_failures_and_refused_connections_are_bad_quality() {
    tokio::time::timeout(TEST_LIMIT, async {
        let (_sim, rest) = station("EVO1").await;
        // HTTPS to a plain HTTP server: the TLS handshake fails.
        let https = rest.url().replace("http://", "https://");
        // A port nobody listens on: the connection is refused.
        let closed = {
            let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
            format!("http://{}", l.local_addr().unwrap())
        };
        // What the log line says (the probe makes the same requests as a poll).
        for url in [&https, &closed] {
            let r = asix_net::rest::probe(&settings(std::slice::from_ref(url), 2000)).await;
            let Err(FetchError::Transport(text)) = &r[0].1 else {
                panic!("{url}: {r:?}")
            };
            println!("{url}: {text}");
            assert!(!text.is_empty() && !text.contains(url.as_str()), "{text}");
        }
        for url in [https, closed] {
            let (l, mut ev) = link(settings(std::slice::from_ref(&url), 2000));
            l.subscribe(typed(&VARS[..1]), 100);
            let v = ev
                .vqt_of(&k(VARS[0]), Duration::from_secs(10), &url, |q| {
                    q == Quality::BAD_COMM_FAILURE
                })
                .await;
            assert_eq!(v.value, Value::Empty, "{url}: no value yet");
            assert!(ev
                .seen
                .iter()
                .all(|e| !matches!(e, ClientEvent::ChannelUp { .. })));
        }
    })
    .await
    .expect("in time");
}

#[test]
fn no_credential_in_settings_or_errors() {
    let mut s = settings(&["https://evo".into()], 100);
    s.auth = Auth::Basic {
        user: "opc".into(),
        password: Some(Secret::new("pa55-w0rd")),
    };
    let text = format!("{s:?}");
    assert!(!text.contains("pa55-w0rd"), "{text}");
    s.auth = Auth::Header(Secret::new("X-Api-Key: k3y-s3cret"));
    let text = format!("{s:?}");
    assert!(!text.contains("k3y-s3cret"), "{text}");
    for e in [
        FetchError::Timeout,
        FetchError::Status(401),
        FetchError::Redirect(302),
        FetchError::TooLarge(10),
    ] {
        assert!(!e.to_string().contains("s3cret"));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_credential_is_sent_and_a_refusal_is_bad_quality() {
    // A station that wants a header: a raw HTTP listener answers 401 without it.
    tokio::time::timeout(TEST_LIMIT, async {
        let listener = tokio::net::TcpListener::bind(loopback()).await.unwrap();
        let url = format!("http://{}", listener.local_addr().unwrap());
        let seen = Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
        let seen2 = seen.clone();
        tokio::spawn(async move {
            use tokio::io::{AsyncReadExt, AsyncWriteExt};
            loop {
                let Ok((mut s, _)) = listener.accept().await else {
                    return;
                };
                let mut buf = vec![0u8; 4096];
                let n = s.read(&mut buf).await.unwrap_or(0);
                let head = String::from_utf8_lossy(&buf[..n]).to_string();
                let ok = head.contains("x-api-key: k3y");
                seen2.lock().unwrap().push(head);
                let body =
                    r#"[{"id":"ZB1_POZIOM","readSucceeded":true,"quality":192,"value":1.5}]"#;
                let resp = if ok {
                    format!(
                        "HTTP/1.1 200 OK\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                        body.len()
                    )
                } else {
                    "HTTP/1.1 401 Unauthorized\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
                        .into()
                };
                let _ = s.write_all(resp.as_bytes()).await;
            }
        });
        let mut s = settings(std::slice::from_ref(&url), 1000);
        s.auth = Auth::Header(Secret::new("X-Api-Key: k3y"));
        let (l, mut ev) = link(s);
        l.subscribe(typed(&VARS[..1]), 100);
        let v = ev
            .vqt_of(&k(VARS[0]), Duration::from_secs(5), "good", |q| q.is_good())
            .await;
        assert_eq!(v.value, Value::R8(1.5));
        drop(l);
        let (l, mut ev) = link(settings(&[url], 1000));
        l.subscribe(typed(&VARS[..1]), 100);
        ev.vqt_of(&k(VARS[0]), Duration::from_secs(5), "refused", |q| {
            q == Quality::BAD_COMM_FAILURE
        })
        .await;
        assert!(seen
            .lock()
            .unwrap()
            .iter()
            .any(|h| !h.contains("x-api-key")));
    })
    .await
    .expect("in time");
}

struct NoWake(AtomicU64);

impl Wake for NoWake {
    fn wake(&self) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }
}

fn repo() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

/// The engine over the network source, one channel on two REST stations serving the
/// demo database: subscribe, read from the device, a refused write, failover.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_engine_reads_and_subscribes_through_two_rest_stations() {
    tokio::time::timeout(TEST_LIMIT, async {
        let zez = repo().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez");
        let (db, _) = load_database_file(&zez, None).unwrap();
        let mut stations = Vec::new();
        for name in ["EVO1", "EVO2"] {
            let sim = sim_with(name, |c| {
                c.channels = channels_from_database(&db, ACID_PLANT_CHANNEL);
            })
            .await;
            let rest = sim.serve_rest(loopback()).await.unwrap();
            stations.push((sim, rest));
        }
        let ini = format!(
            "[Server]\nReconnectInterval = 200\n[Channel:EVO]\nItemsDatabase = {}\nAsixEvoRest = {}, {}\nAsixEvoPollTimeout = 500\n",
            zez.display(),
            stations[0].1.url(),
            stations[1].1.url()
        );
        let (config, warnings) = asix_model::parse_config(ini.as_bytes(), "test.ini").unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        let (ns, _) = AsixNamespace::load(config);
        let ns = Arc::new(ns);
        let wake = Arc::new(NoWake(AtomicU64::new(0)));
        let mut src = AsixSource::new(
            NamespaceResolver::new(ns.clone(), ClientConfig::new("CLI.", "CLI")),
            tokio::runtime::Handle::current(),
            wake,
        );
        let mut e = Engine::new(EngineConfig::default(), ns.clone() as Arc<dyn Namespace>);
        let now = wall_now();
        let session = e.open_session();
        let group = e
            .add_group(now, session, &GroupParams { name: "g", active: true, update_rate: 100, ..GroupParams::default() })
            .unwrap()
            .group;
        let ids = ["KW_A000", "KW_A000.PercentageCV", "KW_A110"];
        let defs: Vec<ItemDefinition> = ids
            .iter()
            .enumerate()
            .map(|(i, id)| ItemDefinition {
                item_id: id,
                access_path: "EVO",
                active: true,
                client_handle: i as u32,
                requested_type: VarType::EMPTY,
            })
            .collect();
        let added = e.add_items(now, group, &defs).unwrap();
        let handles: Vec<u32> = added.iter().map(|r| r.as_ref().unwrap().server_handle).collect();
        for r in &added {
            assert_eq!(r.as_ref().unwrap().access_rights, OPC_READABLE, "read-only");
        }
        let step = |e: &mut Engine, src: &mut AsixSource<NamespaceResolver>| {
            let now = wall_now();
            while let Some(r) = e.poll_source_request() {
                src.request(now, r);
            }
            let mut out = SourceOutput::default();
            src.poll(now, &mut out);
            e.handle_source_updates(now, out.updates);
            for (id, r) in out.read_results {
                e.handle_source_read_result(now, id, r);
            }
            for (id, r) in out.write_results {
                e.handle_source_write_result(now, id, r);
            }
            while e.poll_timeout().is_some_and(|t| t <= now) {
                e.handle_timeout(now);
            }
        };
        let good_cache = |e: &mut Engine| -> Option<Vec<ctopc_core::model::ItemState>> {
            let SyncOutcome::Ready(r) = e.read(wall_now(), group, ReadFrom::Cache, &handles).ok()? else {
                return None;
            };
            let all: Vec<_> = r.into_iter().collect::<Result<Vec<_>, _>>().ok()?;
            all.iter().all(|s| s.quality.is_good()).then_some(all)
        };
        let t0 = Instant::now();
        let states = loop {
            step(&mut e, &mut src);
            if let Some(s) = good_cache(&mut e) {
                break s;
            }
            assert!(t0.elapsed() < Duration::from_secs(10), "good values in the cache");
            tokio::time::sleep(Duration::from_millis(10)).await;
        };
        assert!(matches!(states[0].value, Value::R4(_)), "{:?}", states[0]);
        assert!(matches!(states[1].value, Value::R8(_)), "{:?}", states[1]);
        let ch = src.channels();
        let evo = ch.iter().find(|c| c.name == "EVO").expect("the EVO link");
        assert_eq!((evo.link, evo.server.as_str()), (LinkState::Up, stations[0].1.url().as_str()));
        assert_eq!(evo.subscriptions, 2, "{ch:?}");

        // A device read.
        let SyncOutcome::Pending(id) = e.read(wall_now(), group, ReadFrom::Device, &handles[..1]).unwrap() else {
            panic!("a device read waits for the source")
        };
        let t0 = Instant::now();
        let r = loop {
            step(&mut e, &mut src);
            if let Some(r) = e.take_sync_result(id) {
                break r;
            }
            assert!(t0.elapsed() < Duration::from_secs(5), "device read");
            tokio::time::sleep(Duration::from_millis(10)).await;
        };
        let SyncResult::Read(r) = r else { panic!("{r:?}") };
        assert!(r[0].as_ref().unwrap().quality.is_good());

        // A write: refused, the items are read-only.
        match e.write(wall_now(), group, &[(handles[2], Value::R8(1.0))]).unwrap() {
            SyncOutcome::Ready(w) => assert_eq!(w, vec![Err(OpcError::BadRights)]),
            SyncOutcome::Pending(_) => panic!("refused at once"),
        }

        // Station 1 fails: the values go on from station 2.
        stations[0].1.mode().apply("fail=1").unwrap();
        let t0 = Instant::now();
        loop {
            step(&mut e, &mut src);
            let ch = src.channels();
            let evo = ch.iter().find(|c| c.name == "EVO").unwrap();
            if evo.link == LinkState::Up && evo.server == stations[1].1.url() {
                assert!(evo.failovers >= 1, "{evo:?}");
                break;
            }
            assert!(t0.elapsed() < Duration::from_secs(10), "failover: {evo:?}");
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        let served = stations[1].1.mode().names.load(Ordering::SeqCst);
        let t0 = Instant::now();
        loop {
            step(&mut e, &mut src);
            if good_cache(&mut e).is_some() && stations[1].1.mode().names.load(Ordering::SeqCst) > served {
                break;
            }
            assert!(t0.elapsed() < Duration::from_secs(10), "values from the standby");
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    })
    .await
    .expect("in time");
}
