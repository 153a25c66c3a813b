//! Client against simulators on loopback: discovery variants, failover, writes, timeouts,
//! quality across link loss. Every test is bounded by `TEST_LIMIT` and bounded waits.

mod common;

use std::time::{Duration, Instant};

use asix_model::ItemKey;
use asix_net::client::{discover, ClientEvent};
use asix_net::proto::discovery::Resource;
use asix_net::{ExternalServerLists, ReadSource, Vqt};
use common::*;
use ctopc_core::{OpcError, Quality, Timestamp, Value};

macro_rules! bounded {
    ($body:expr) => {
        tokio::time::timeout(TEST_LIMIT, $body)
            .await
            .expect("test exceeded its time limit")
    };
}

const SHORT: Duration = Duration::from_secs(3);

// ----- discovery -------------------------------------------------------------------------

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn empty_name_stop_after_first_takes_the_first_answer_without_waiting() {
    bounded!(async {
        let a = sim("A").await;
        let b = sim("B").await;
        let mut cfg = client_cfg(&[a.discovery_addr(), b.discovery_addr()]);
        cfg.options.find_server_timeout = Duration::from_secs(5);
        let (c, mut ev) = client(cfg);
        let t0 = Instant::now();
        c.subscribe(vec![key("PIEC_TEMP")], 50);
        let server = ev.channel_up(SHORT).await;
        assert!(server == "A" || server == "B", "{server}");
        assert!(
            t0.elapsed() < Duration::from_secs(2),
            "waited {:?} although the first answer wins",
            t0.elapsed()
        );
        ev.vqt_of(&key("PIEC_TEMP"), SHORT, "a good value", |q| q.is_good())
            .await;
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn empty_name_without_stop_ranks_after_find_server_timeout() {
    bounded!(async {
        // A: failed, local. B: local bridge. C: remote, own data, 5 clients. D: remote, own data, 1 client.
        let a = sim_with("A", |c| {
            c.source_failed = true;
            c.host_name = CLIENT_HOST.into();
        })
        .await;
        let b = sim_with("B", |c| {
            c.bridge = true;
            c.host_name = CLIENT_HOST.into();
        })
        .await;
        let cc = sim_with("C", |c| c.extra_clients = 5).await;
        let d = sim_with("D", |c| c.extra_clients = 1).await;
        for (targets, expected) in [
            (vec![&a, &b, &cc, &d], "B"), // (a) healthy, then (b) local beats own data
            (vec![&a, &cc, &d], "D"), // (d) fewest clients among healthy remote own-data servers
            (vec![&a, &cc], "C"),     // (a) a healthy remote server beats a failed local one
            (vec![&a], "A"),          // a failed one is still better than none
        ] {
            let addrs: Vec<_> = targets.iter().map(|s| s.discovery_addr()).collect();
            let mut cfg = client_cfg(&addrs);
            cfg.options.stop_after_first_server_found = false;
            let (c, mut ev) = client(cfg);
            let t0 = Instant::now();
            c.subscribe(vec![key("PIEC_TEMP")], 50);
            let server = ev.channel_up(SHORT).await;
            assert_eq!(
                server,
                expected,
                "targets {:?}",
                targets.iter().map(|s| s.server_name()).collect::<Vec<_>>()
            );
            assert!(
                t0.elapsed() >= Duration::from_millis(390),
                "ranked before FindServerTimeout: {:?}",
                t0.elapsed()
            );
            c.shutdown().await;
        }
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_name_waits_for_that_server_and_reconnects_only_to_it() {
    bounded!(async {
        let a = sim("A").await;
        let b = sim("B").await;
        let mut cfg = client_cfg(&[a.discovery_addr(), b.discovery_addr()]);
        cfg.options.asix_server_name = "b".into(); // names compare case-insensitively
        let (c, mut ev) = client(cfg);
        c.subscribe(vec![key("PIEC_TEMP")], 50);
        assert_eq!(ev.channel_up(SHORT).await, "B");
        // B hangs and drops its links: the client must not fall back to A.
        b.set_answering(false);
        b.drop_links();
        ev.wait(SHORT, "ChannelDown", |e| {
            matches!(e, ClientEvent::ChannelDown { .. }).then_some(())
        })
        .await;
        tokio::time::sleep(Duration::from_millis(1200)).await;
        ev.drain();
        assert!(
            !ev.seen
                .iter()
                .any(|e| matches!(e, ClientEvent::ChannelUp { server, .. } if server == "A")),
            "reconnected to a server not named"
        );
        b.set_answering(true);
        assert_eq!(ev.channel_up(SHORT).await, "B");
        ev.vqt_of(&key("PIEC_TEMP"), SHORT, "good again", |q| q.is_good())
            .await;
        drop(a);
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_list_accepts_any_listed_server() {
    bounded!(async {
        let a = sim("A").await;
        let c2 = sim("C").await;
        let mut cfg = client_cfg(&[a.discovery_addr(), c2.discovery_addr()]);
        cfg.options.asix_server_name = "X, C".into();
        let (c, mut ev) = client(cfg);
        c.subscribe(vec![key("PIEC_TEMP")], 50);
        assert_eq!(ev.channel_up(SHORT).await, "C");
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn local_takes_only_the_server_on_this_computer() {
    bounded!(async {
        let remote = sim("R").await;
        let local = sim_with("L", |c| c.host_name = CLIENT_HOST.to_ascii_lowercase()).await;
        let mut cfg = client_cfg(&[remote.discovery_addr(), local.discovery_addr()]);
        cfg.options.asix_server_name = "LOCAL".into();
        let (c, mut ev) = client(cfg);
        c.subscribe(vec![key("PIEC_TEMP")], 50);
        assert_eq!(ev.channel_up(SHORT).await, "L");

        // With only a remote server there is nothing to link to.
        let mut cfg = client_cfg(&[remote.discovery_addr()]);
        cfg.options.asix_server_name = "LOCAL".into();
        let (c2, mut ev2) = client(cfg);
        c2.subscribe(vec![key("PIEC_TEMP")], 50);
        let err = ev2
            .wait(SHORT, "ChannelDown", |e| match e {
                ClientEvent::ChannelDown { error, .. } => Some(*error),
                _ => None,
            })
            .await;
        assert_eq!(err, OpcError::NetFindServerNotFound);
        drop(c);
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn external_server_list_applies_when_the_channel_names_no_server() {
    bounded!(async {
        let a = sim("A").await;
        let b = sim("B").await;
        let mut cfg = client_cfg(&[a.discovery_addr(), b.discovery_addr()]);
        let ini = format!("[AsixCTServers]\n{CH} = B\n");
        let (config, _) = asix_model::parse_config(ini.as_bytes(), "ASIXConnect.ini").unwrap();
        cfg.external = ExternalServerLists::from_config(&config);
        let (c, mut ev) = client(cfg.clone());
        c.subscribe(vec![key("PIEC_TEMP")], 50);
        assert_eq!(ev.channel_up(SHORT).await, "B");
        // The one-off discovery helper follows the same rules.
        let found = discover(&cfg, Resource::channel(CH)).await.unwrap();
        assert_eq!(found[0].name(), "B");
        let none = discover(&cfg, Resource::channel("NO_SUCH_CHANNEL")).await;
        assert_eq!(none.unwrap_err(), OpcError::NetFindServerNotFound);
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_empty_channel_finds_the_variable_on_any_server() {
    bounded!(async {
        let a = sim("A").await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let k = ItemKey::new("", "ZB1_POZIOM");
        c.subscribe(vec![k.clone()], 50);
        ev.vqt_of(&k, SHORT, "a good value", |q| q.is_good()).await;
    })
}

// ----- failover and quality --------------------------------------------------------------

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn failover_to_the_second_simulator_when_the_first_dies() {
    bounded!(async {
        let a = sim("A").await;
        let b = sim("B").await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr(), b.discovery_addr()]));
        let k = key("ZB1_POZIOM");
        c.subscribe(vec![k.clone()], 50);
        let first = ev.channel_up(SHORT).await;
        ev.vqt_of(&k, SHORT, "good", |q| q.is_good()).await;
        let (dead, alive) = if first == "A" { (a, b) } else { (b, a) };
        let t0 = Instant::now();
        dead.shutdown().await;
        let lkv = ev
            .vqt_of(&k, SHORT, "last known value", |q| {
                q == Quality::BAD_LAST_KNOWN_VALUE
            })
            .await;
        assert_ne!(lkv.value, Value::Empty);
        assert_eq!(ev.channel_up(SHORT).await, alive.server_name());
        ev.vqt_of(&k, SHORT, "good from the second server", |q| q.is_good())
            .await;
        let took = t0.elapsed();
        assert!(
            took < Duration::from_millis(400) + Duration::from_secs(1),
            "failover took {took:?}"
        );
        assert_eq!(alive.client_count(), 1);
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn quality_goes_last_known_value_on_link_loss_and_good_after_resubscribe() {
    bounded!(async {
        let a = sim("A").await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let k = key("PIEC_TEMP");
        c.subscribe(vec![k.clone()], 50);
        ev.vqt_of(&k, SHORT, "good", |q| q.is_good()).await;
        a.drop_links();
        // BAD Last Known Value (0x14) with the last value received, and its timestamp.
        let lkv = ev
            .vqt_of(&k, SHORT, "LKV", |q| q == Quality::BAD_LAST_KNOWN_VALUE)
            .await;
        assert_eq!(lkv.quality.0, 0x14);
        let last_good = ev
            .seen
            .iter()
            .filter_map(|e| match e {
                ClientEvent::Updates(u) => {
                    u.iter().rfind(|(kk, v)| kk == &k && v.quality.is_good())
                }
                _ => None,
            })
            .next_back()
            .map(|(_, v)| v.clone())
            .expect("a good value was seen");
        assert_eq!(lkv.value, last_good.value);
        assert_eq!(lkv.timestamp, last_good.timestamp);
        // Rediscovered, resubscribed: GOOD again.
        ev.channel_up(SHORT).await;
        ev.vqt_of(&k, SHORT, "good again", |q| q.is_good()).await;
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn comm_failure_while_no_value_was_ever_received_then_good() {
    bounded!(async {
        let a = sim("A").await;
        a.set_answering(false);
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let k = key("PIEC_TEMP");
        c.subscribe(vec![k.clone()], 50);
        let v = ev
            .vqt_of(&k, SHORT, "comm failure", |q| {
                q == Quality::BAD_COMM_FAILURE
            })
            .await;
        assert_eq!(v.quality.0, 0x18);
        assert_eq!(v.value, Value::Empty);
        a.set_answering(true);
        ev.vqt_of(&k, SHORT, "good once a server answers", |q| q.is_good())
            .await;
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn net_timeout_when_the_simulator_stops_answering() {
    bounded!(async {
        let a = sim("A").await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let k = key("PIEC_TEMP");
        c.subscribe(vec![k.clone()], 50);
        ev.vqt_of(&k, SHORT, "good", |q| q.is_good()).await;
        a.set_answering(false);
        let t0 = Instant::now();
        let id = c.read(vec![k.clone(), key("ZB1_POZIOM")], ReadSource::Device);
        let results = ev
            .wait(SHORT, "ReadDone", |e| match e {
                ClientEvent::ReadDone { id: i, results } if *i == id => Some(results.clone()),
                _ => None,
            })
            .await;
        let took = t0.elapsed();
        assert_eq!(results.len(), 2);
        for (_, r) in &results {
            assert_eq!(r.as_ref().unwrap_err(), &OpcError::NetAnswerTimeout);
        }
        // Keep-alive may notice a little earlier than the read's own deadline.
        assert!(
            took >= Duration::from_millis(250) && took < Duration::from_millis(1400),
            "took {took:?}"
        );
        ev.vqt_of(&k, SHORT, "LKV after the timeout", |q| {
            q == Quality::BAD_LAST_KNOWN_VALUE
        })
        .await;
        // A write is bounded the same way.
        let id = c.write(vec![(key("PIEC_TEMP_ZADANA"), Value::R4(1000.0))]);
        let w = ev
            .wait(SHORT, "WriteDone", |e| match e {
                ClientEvent::WriteDone { id: i, results } if *i == id => Some(results.clone()),
                _ => None,
            })
            .await;
        assert!(
            matches!(
                w[0].1,
                Err(OpcError::NetAnswerTimeout | OpcError::WriteErrorNetworkServerNotFound)
            ),
            "{w:?}"
        );
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reads_from_cache_device_and_driver() {
    bounded!(async {
        let a = sim("A").await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        for src in [ReadSource::Cache, ReadSource::Device, ReadSource::Driver] {
            let id = c.read(
                vec![key("ZB1_POZIOM"), key("NO_SUCH"), key("P1_PRACA")],
                src,
            );
            let r = ev
                .wait(SHORT, "ReadDone", |e| match e {
                    ClientEvent::ReadDone { id: i, results } if *i == id => Some(results.clone()),
                    _ => None,
                })
                .await;
            assert!(
                matches!(&r[0].1, Ok(v) if v.quality.is_good() && matches!(v.value, Value::R4(_))),
                "{src:?} {r:?}"
            );
            assert_eq!(r[1].1, Err(OpcError::ItemUnknown));
            assert!(
                matches!(
                    &r[2].1,
                    Ok(Vqt {
                        value: Value::I2(0 | 1),
                        ..
                    })
                ),
                "{r:?}"
            );
        }
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unknown_item_is_reported_with_config_error() {
    bounded!(async {
        let a = sim("A").await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let k = key("NO_SUCH_VARIABLE");
        c.subscribe(vec![k.clone(), key("PIEC_TEMP")], 50);
        let e = ev
            .wait(SHORT, "ItemFailed", |e| match e {
                ClientEvent::ItemFailed { key, error } if key == &k => Some(*error),
                _ => None,
            })
            .await;
        assert_eq!(e, OpcError::ItemUnknown);
        let v = ev
            .vqt_of(&k, SHORT, "config error quality", |q| {
                q == Quality::BAD_CONFIG_ERROR
            })
            .await;
        assert_eq!(v.value, Value::Empty);
        ev.vqt_of(&key("PIEC_TEMP"), SHORT, "the other item works", |q| {
            q.is_good()
        })
        .await;
    })
}

// ----- writes ----------------------------------------------------------------------------

async fn write_results(
    c: &asix_net::AsixClient,
    ev: &mut Events,
    items: Vec<(ItemKey, Value)>,
) -> Vec<Result<(), OpcError>> {
    let id = c.write(items);
    ev.wait(SHORT, "WriteDone", |e| match e {
        ClientEvent::WriteDone { id: i, results } if *i == id => {
            Some(results.iter().map(|r| r.1).collect())
        }
        _ => None,
    })
    .await
}

async fn write_vqt_results(
    c: &asix_net::AsixClient,
    ev: &mut Events,
    items: Vec<(ItemKey, Vqt)>,
) -> Vec<Result<(), OpcError>> {
    let id = c.write_vqt(items);
    ev.wait(SHORT, "WriteDone", |e| match e {
        ClientEvent::WriteDone { id: i, results } if *i == id => {
            Some(results.iter().map(|r| r.1).collect())
        }
        _ => None,
    })
    .await
}

/// The write rights name the test client by its authenticated identity
/// (`cert:<fingerprint>`), which replaces the name it declares (`CLI.`).
fn app_ini() -> String {
    "[ASMEN]\n\
    Demo_Wytwornia_Kwasu = MODBUS, COM1\n\
    KANAL1 = NONE\n\
    KANAL2 = NONE\n\
    ZEZWOLENIE_ZAPISU = Demo_Wytwornia_Kwasu, CLI.\n\
    ZEZWOLENIE_ZAPISU = KANAL1, OTHER., CLI.\n\
    ZEZWOLENIE_ZAPISU = KANAL2, CLI.\n\
    [KANAL1]\nZAPIS_CZASU_I_STATUSU = TAK\n\
    [Demo_Wytwornia_Kwasu]\nZAPIS_CZASU_I_STATUSU = TAK\n"
        .replace("CLI.", &client_identity())
}

fn with_rights(c: &mut asix_net::sim::SimConfig) {
    use asix_net::sim::plant::{ChannelDef, VarSpec};
    use asix_net::sim::rights::WriteRights;
    use ctopc_core::VarType;
    let (rights, warnings) = WriteRights::from_app_ini(app_ini().as_bytes(), "app.ini");
    assert!(warnings.is_empty(), "{warnings:?}");
    c.write_rights = rights;
    let specs = || {
        vec![
            VarSpec::new("WART1", VarType::R4, 0.0, 100.0, true),
            VarSpec::new("WART2", VarType::I2, 0.0, 10.0, false),
        ]
    };
    c.channels.push(ChannelDef::from_specs("KANAL1", specs()));
    c.channels.push(ChannelDef::from_specs("KANAL2", specs()));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn simple_write_allowed_and_denied() {
    bounded!(async {
        let a = sim_with("A", with_rights).await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let sp = key("PIEC_TEMP_ZADANA");
        let r = write_results(&c, &mut ev, vec![(sp.clone(), Value::R4(1012.5))]).await;
        assert_eq!(r, vec![Ok(())]);
        assert_eq!(
            a.vqt(CH, "PIEC_TEMP_ZADANA").unwrap().value,
            Value::R4(1012.5)
        );
        // Per-item results in one request.
        let r = write_results(
            &c,
            &mut ev,
            vec![
                (key("PIEC_TEMP"), Value::R4(1.0)), // read-only variable
                (key("NO_SUCH"), Value::R4(1.0)),   // unknown
                (key("SIARKA_DOZOWANIE"), Value::Bstr("x".into())), // not a number
                (key("ABS_WODA_DOZOWANIE"), Value::I2(3)), // fine
                (ItemKey::new("KANAL2", "WART1"), Value::R8(5.0)), // fine (other channel, same server)
            ],
        )
        .await;
        assert_eq!(
            r,
            vec![
                Err(OpcError::WriteErrorDeviceRequestIllegal),
                Err(OpcError::ItemUnknown),
                Err(OpcError::BadType),
                Ok(()),
                Ok(()),
            ]
        );
        let r = write_results(
            &c,
            &mut ev,
            vec![(sp.clone(), Value::R4(1.0)), (sp.clone(), Value::R4(2.0))],
        )
        .await;
        assert_eq!(r, vec![Err(OpcError::TheSameItemWrittenMoreThanOnce); 2]);

        // A remote client without a ZEZWOLENIE_ZAPISU entry is refused...
        // Another certificate: the name it declares does not matter.
        let mut cfg = stranger_cfg(&[a.discovery_addr()]);
        cfg.client_name = CLIENT_NAME.into();
        let (c2, mut ev2) = client(cfg);
        let r = write_results(&c2, &mut ev2, vec![(sp.clone(), Value::R4(1000.0))]).await;
        assert_eq!(r, vec![Err(OpcError::WriteErrorIllegalCommand)]);
        // ...but a client on the server's computer may always write.
        let mut cfg = stranger_cfg(&[a.discovery_addr()]);
        cfg.client_host = "A-HOST".into();
        let (c3, mut ev3) = client(cfg);
        let r = write_results(&c3, &mut ev3, vec![(sp.clone(), Value::UI2(1001))]).await;
        assert_eq!(r, vec![Ok(())]);
        // The data source failed: the driver cannot write.
        a.set_source_failed(true);
        let r = write_results(&c, &mut ev, vec![(sp, Value::R4(1.0))]).await;
        assert_eq!(r, vec![Err(OpcError::WriteErrorDriverTransmisionError)]);
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn extended_write_allowed_and_denied() {
    bounded!(async {
        let a = sim_with("A", with_rights).await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let ts = Timestamp::from_unix_millis(1_600_000_000_000);
        let q = Quality::UNCERTAIN_SENSOR_NOT_ACCURATE;
        let vqt = |v: f32| Vqt::new(Value::R4(v), q, ts);
        // KANAL1: driver NONE, permission, ZAPIS_CZASU_I_STATUSU = TAK.
        let r = write_vqt_results(
            &c,
            &mut ev,
            vec![(ItemKey::new("KANAL1", "WART1"), vqt(42.0))],
        )
        .await;
        assert_eq!(r, vec![Ok(())]);
        let now = a.vqt("KANAL1", "WART1").unwrap();
        assert_eq!(
            now,
            vqt(42.0),
            "value, quality and timestamp are all written"
        );
        // Demo channel: permission and the flag, but not on driver NONE.
        let r = write_vqt_results(&c, &mut ev, vec![(key("PIEC_TEMP_ZADANA"), vqt(1.0))]).await;
        assert_eq!(r, vec![Err(OpcError::WriteErrorIllegalCommand)]);
        // KANAL2: driver NONE and permission, but no ZAPIS_CZASU_I_STATUSU.
        let r = write_vqt_results(
            &c,
            &mut ev,
            vec![(ItemKey::new("KANAL2", "WART1"), vqt(1.0))],
        )
        .await;
        assert_eq!(r, vec![Err(OpcError::WriteErrorIllegalCommand)]);
        // A simple write to KANAL2 is fine (only the extended one needs the flag).
        let r = write_results(
            &c,
            &mut ev,
            vec![(ItemKey::new("KANAL2", "WART1"), Value::R4(7.0))],
        )
        .await;
        assert_eq!(r, vec![Ok(())]);
        // A client without permission on KANAL1 is refused the extended write.
        // Another certificate: the name it declares does not matter.
        let mut cfg = stranger_cfg(&[a.discovery_addr()]);
        cfg.client_name = CLIENT_NAME.into();
        let (c2, mut ev2) = client(cfg);
        let r = write_vqt_results(
            &c2,
            &mut ev2,
            vec![(ItemKey::new("KANAL1", "WART1"), vqt(3.0))],
        )
        .await;
        assert_eq!(r, vec![Err(OpcError::WriteErrorIllegalCommand)]);
        // Variables of a NONE channel change only when written.
        tokio::time::sleep(Duration::from_millis(200)).await;
        assert_eq!(a.vqt("KANAL1", "WART1").unwrap(), vqt(42.0));
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn writes_fail_with_server_not_found_when_there_is_no_server() {
    bounded!(async {
        let a = sim("A").await;
        a.set_answering(false);
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let r = write_results(&c, &mut ev, vec![(key("PIEC_TEMP_ZADANA"), Value::R4(1.0))]).await;
        assert_eq!(r, vec![Err(OpcError::WriteErrorNetworkServerNotFound)]);
        let id = c.read(vec![key("PIEC_TEMP")], ReadSource::Device);
        let r = ev
            .wait(SHORT, "ReadDone", |e| match e {
                ClientEvent::ReadDone { id: i, results } if *i == id => Some(results[0].1.clone()),
                _ => None,
            })
            .await;
        assert_eq!(r, Err(OpcError::NetFindServerNotFound));
    })
}

// ----- the binary --------------------------------------------------------------------------

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_binary_serves_and_takes_fault_commands_on_stdin() {
    use std::io::{BufRead, BufReader, Write};
    use std::process::{Command, Stdio};
    bounded!(async {
        let mut child = Command::new(env!("CARGO_BIN_EXE_asix-sim"))
            .args([
                "--name",
                "BIN",
                "--udp",
                "127.0.0.1:0",
                "--tcp",
                "127.0.0.1:0",
                "--run-for-ms",
                "20000",
            ])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("asix-sim starts");
        let mut out = BufReader::new(child.stdout.take().unwrap());
        let mut stdin = child.stdin.take().unwrap();
        let mut line = String::new();
        out.read_line(&mut line).unwrap();
        let udp: std::net::SocketAddr = line
            .split_whitespace()
            .find_map(|w| w.strip_prefix("udp="))
            .unwrap()
            .parse()
            .unwrap();
        // The ready line names the certificate to pin.
        let fp = line
            .split_whitespace()
            .find_map(|w| w.strip_prefix("fingerprint="))
            .unwrap();
        let fp = asix_net::tls::parse_fingerprint(fp).unwrap();
        let mut cfg = client_cfg(&[udp]);
        // Pinned to another server, the client does not take its announcements.
        assert_eq!(
            discover(&cfg, Resource::channel(CH)).await.unwrap_err(),
            OpcError::NetFindServerNotFound
        );
        cfg.security = asix_net::secure::ClientSecurity::tls(
            &pki().client.identity,
            asix_net::tls::Trust::Fingerprints(vec![fp]),
        )
        .unwrap();
        let found = discover(&cfg, Resource::channel(CH)).await.unwrap();
        assert_eq!(found[0].name(), "BIN");
        assert_eq!(found[0].announce.fingerprint, Some(fp));
        assert!(!found[0].announce.flags.source_failed());
        writeln!(stdin, "fail-source").unwrap();
        line.clear();
        out.read_line(&mut line).unwrap();
        assert!(line.contains("source_failed=true"), "{line}");
        let found = discover(&cfg, Resource::channel(CH)).await.unwrap();
        assert!(found[0].announce.flags.source_failed());
        writeln!(stdin, "quit").unwrap();
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            if let Some(st) = child.try_wait().unwrap() {
                assert!(st.success());
                break;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                panic!("asix-sim did not quit");
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
}

/// `asix-sim --gen-cert DIR`: a key pair and certificate in DIR, and the fingerprint to
/// paste into the other side, which is the certificate's.
#[test]
fn gen_cert_writes_a_usable_identity_and_prints_its_fingerprint() {
    let dir = std::env::temp_dir().join(format!("asix-sim-gen-cert-{}", std::process::id()));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_asix-sim"))
        .args(["--name", "GATE1", "--gen-cert"])
        .arg(&dir)
        .output()
        .expect("asix-sim runs");
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    let printed = text
        .lines()
        .find_map(|l| l.strip_prefix("fingerprint "))
        .expect("a fingerprint line");
    let id = asix_net::tls::Identity::load(&dir.join("asix-cert.pem"), &dir.join("asix-key.pem"))
        .unwrap();
    assert_eq!(printed, asix_net::tls::fingerprint_hex(&id.fingerprint()));
    let _ = std::fs::remove_dir_all(&dir);
}
