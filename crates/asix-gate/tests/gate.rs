//! The gate end to end on loopback: the engine over fake `XConnect.ServerCT` channels,
//! served over TLS to asix-net's real client (ServerCTOPC's side of the link).

use std::collections::HashMap;
use std::net::{Ipv4Addr, SocketAddr};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use asix_gate::channel::{CallError, ChannelFactory, ServerState};
use asix_gate::config::{ChannelConfig, GateConfig, Open};
use asix_gate::fake::FakePlant;
use asix_gate::{DataSource, Engine, GateServer};
use asix_model::ItemKey;
use asix_net::client::ClientEvent;
use asix_net::proto::discovery::Resource;
use asix_net::secure::ClientSecurity;
use asix_net::tls;
use asix_net::{channel_sink, AsixClient, ClientConfig, ReadSource, Vqt};
use ctopc_core::write_rights::{Channels, Principal, Rule, WriteRights};
use ctopc_core::{OpcError, Quality, Timestamp, Value};
use tokio::sync::mpsc::UnboundedReceiver;

const LIMIT: Duration = Duration::from_secs(10);
const K1: &str = "KANAL1";
const K2: &str = "KANAL2";

struct Pki {
    server: tls::Generated,
    writer: tls::Generated,
    reader: tls::Generated,
}

/// What the gates of this binary logged under the audit target (`ctopc_core::audit`),
/// line by line: a process-wide subscriber, set once; each test looks for its own items.
fn audit_log() -> &'static Arc<Mutex<Vec<u8>>> {
    static LOG: OnceLock<Arc<Mutex<Vec<u8>>>> = OnceLock::new();
    LOG.get_or_init(|| {
        let log = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&log);
        tracing_subscriber::fmt()
            .with_env_filter(tracing_subscriber::EnvFilter::new("audit=info"))
            .with_ansi(false)
            .with_writer(move || Capture(Arc::clone(&sink)))
            .init();
        log
    })
}

struct Capture(Arc<Mutex<Vec<u8>>>);

impl std::io::Write for Capture {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().expect("log").extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The audit lines that name `item` (`CHANNEL.VARIABLE`).
fn audit_lines(item: &str) -> Vec<String> {
    let text = String::from_utf8_lossy(&audit_log().lock().expect("log")).into_owned();
    let needle = format!("item=\"{item}\"");
    text.lines()
        .filter(|l| l.contains(&needle))
        .map(str::to_owned)
        .collect()
}

fn hex(fp: &[u8]) -> String {
    fp.iter().map(|b| format!("{b:02x}")).collect()
}

fn pki() -> &'static Pki {
    static PKI: OnceLock<Pki> = OnceLock::new();
    PKI.get_or_init(|| Pki {
        server: tls::generate("GATE", None).expect("certificate"),
        writer: tls::generate("WRITER", None).expect("certificate"),
        reader: tls::generate("READER", None).expect("certificate"),
    })
}

struct Gate {
    plants: HashMap<&'static str, FakePlant>,
    engine: Arc<Engine>,
    server: GateServer,
}

impl Drop for Gate {
    fn drop(&mut self) {
        self.engine.stop();
        // A hung fake call would keep its worker: release every member.
        for p in self.plants.values() {
            for m in asix_gate::fake::MEMBERS {
                p.hang(m, false);
            }
        }
    }
}

/// A gate serving KANAL1 (LoadChannel, items A B C, writable by the writer's certificate)
/// and KANAL2 (Init, items X Y, device reads from the driver, writable by nobody).
async fn gate() -> Gate {
    gate_with(|_| {}).await
}

/// [`gate`] with its configuration changed by `f`.
async fn gate_with(f: impl FnOnce(&mut GateConfig)) -> Gate {
    let plants: HashMap<&'static str, FakePlant> = [
        (K1, FakePlant::new(&["A", "B", "C"])),
        (K2, FakePlant::new(&["X", "Y"])),
    ]
    .into_iter()
    .collect();
    let by_name = plants.clone();
    let factory: ChannelFactory = Arc::new(move |name: &str| {
        let p = by_name
            .get(name)
            .ok_or_else(|| CallError::new(OpcError::Fail, "no such plant"))?;
        (p.factory())(name)
    });
    let mut cfg = GateConfig::new("GATE1");
    cfg.listen = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    cfg.discovery = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    cfg.call_timeout = Duration::from_millis(300);
    cfg.state_poll = Duration::from_millis(30);
    cfg.time_zone = asix_gate::tz::ZoneRule::europe_warsaw();
    cfg.channels = vec![
        ChannelConfig {
            name: K1.into(),
            open: Open::LoadChannel("ASIX_K1".into()),
            device_read: DataSource::Device,
            allow_plaintext: false,
        },
        ChannelConfig {
            name: K2.into(),
            open: Open::Init("Server=S1;Channel=K2".into()),
            device_read: DataSource::Driver,
            allow_plaintext: false,
        },
    ];
    cfg.write_rights = WriteRights::new(vec![Rule::new(
        Channels::One(K1.into()),
        Principal::Certificate(pki().writer.identity.fingerprint()),
    )]);
    f(&mut cfg);
    let engine = Engine::start(&cfg, factory);
    let security = asix_gate::security(&cfg, Some(&pki().server.identity)).expect("security");
    let server = asix_gate::serve(asix_gate::serve_config(&cfg, security), engine.clone())
        .await
        .expect("gate serves");
    Gate {
        plants,
        engine,
        server,
    }
}

impl Gate {
    fn plant(&self, ch: &str) -> &FakePlant {
        &self.plants[ch]
    }
}

struct Client {
    client: AsixClient,
    rx: UnboundedReceiver<ClientEvent>,
    seen: Vec<ClientEvent>,
}

fn client(g: &Gate, who: &tls::Generated, name: &str) -> Client {
    client_secured(
        g,
        name,
        ClientSecurity::tls(
            &who.identity,
            tls::Trust::Fingerprints(vec![pki().server.identity.fingerprint()]),
        )
        .expect("client TLS"),
    )
}

fn client_secured(g: &Gate, name: &str, security: ClientSecurity) -> Client {
    let mut c = ClientConfig::new(name, "CLI");
    c.discovery_targets = vec![g.server.discovery_addr()];
    c.discovery_bind = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    c.options.find_server_timeout = Duration::from_millis(400);
    c.options.net_timeout = Duration::from_millis(2000);
    c.discovery_resend = Duration::from_millis(100);
    c.keepalive = Duration::from_millis(100);
    c.reconnect_interval = Duration::from_millis(200);
    c.retry_failed_items = Duration::from_millis(300);
    c.changes_only = true;
    c.security = security;
    let (sink, rx) = channel_sink();
    let client =
        AsixClient::start(c, sink, &tokio::runtime::Handle::current()).expect("client starts");
    Client {
        client,
        rx,
        seen: Vec::new(),
    }
}

impl Client {
    async fn wait<T>(&mut self, what: &str, mut f: impl FnMut(&ClientEvent) -> Option<T>) -> T {
        let deadline = Instant::now() + LIMIT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match tokio::time::timeout(left, self.rx.recv()).await {
                Ok(Some(ev)) => {
                    let r = f(&ev);
                    self.seen.push(ev);
                    if let Some(r) = r {
                        return r;
                    }
                }
                Ok(None) => panic!("client ended while waiting for {what}"),
                Err(_) => {
                    let tail: Vec<String> = self
                        .seen
                        .iter()
                        .rev()
                        .take(6)
                        .map(|e| format!("{e:?}").chars().take(300).collect())
                        .collect();
                    panic!("timed out waiting for {what}; saw {tail:#?}")
                }
            }
        }
    }

    async fn vqt(&mut self, k: &ItemKey, what: &str, f: impl Fn(&Vqt) -> bool) -> Vqt {
        self.wait(what, |e| match e {
            ClientEvent::Updates(u) => u
                .iter()
                .rev()
                .find(|(kk, v)| kk == k && f(v))
                .map(|(_, v)| v.clone()),
            _ => None,
        })
        .await
    }

    async fn read(&mut self, keys: Vec<ItemKey>, source: ReadSource) -> Vec<Result<Vqt, OpcError>> {
        let id = self.client.read(keys, source);
        self.wait("ReadDone", |e| match e {
            ClientEvent::ReadDone { id: i, results } if *i == id => {
                Some(results.iter().map(|(_, r)| r.clone()).collect())
            }
            _ => None,
        })
        .await
    }

    async fn write(&mut self, items: Vec<(ItemKey, Value)>) -> Vec<Result<(), OpcError>> {
        let id = self.client.write(items);
        self.write_done(id).await
    }

    async fn write_done(&mut self, id: asix_net::RequestId) -> Vec<Result<(), OpcError>> {
        self.wait("WriteDone", |e| match e {
            ClientEvent::WriteDone { id: i, results } if *i == id => {
                Some(results.iter().map(|(_, r)| *r).collect())
            }
            _ => None,
        })
        .await
    }
}

async fn until(what: &str, mut f: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(t0.elapsed() < LIMIT, "timed out waiting until {what}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

fn k(ch: &str, v: &str) -> ItemKey {
    ItemKey::new(ch, v)
}

/// 2026-07-15 12:00 local (CEST) as a VT_DATE, and the UTC instant it is.
fn summer_noon() -> (f64, Timestamp) {
    let local = Timestamp::from_unix_millis(1_784_116_800_000); // 2026-07-15T12:00:00 "as UTC"
    (
        local.to_ole_date(),
        Timestamp::from_unix_millis(1_784_116_800_000 - 7_200_000),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn channels_open_as_configured_and_subscriptions_follow_datachange() {
    let g = gate().await;
    until("both channels open", || {
        g.plant(K1).is_active() && g.plant(K2).is_active()
    })
    .await;
    assert_eq!(g.plant(K1).opened().as_deref(), Some("LoadChannel ASIX_K1"));
    assert_eq!(
        g.plant(K2).opened().as_deref(),
        Some("Init Server=S1;Channel=K2")
    );
    let mut c = client(&g, &pki().reader, "READER.");
    c.client.subscribe(vec![k(K1, "A"), k(K2, "X")], 20);
    until("A and X active", || {
        g.plant(K1).is_item_active("A") && g.plant(K2).is_item_active("X")
    })
    .await;
    let (local, utc) = summer_noon();
    g.plant(K1).set("A", Value::R8(42.5), 0xC0, Some(local));
    let v = c
        .vqt(&k(K1, "A"), "A = 42.5", |v| v.value == Value::R8(42.5))
        .await;
    assert_eq!(v.quality, Quality::GOOD);
    assert_eq!(v.timestamp, utc, "local CEST noon is 10:00 UTC");
    g.plant(K2).set("X", Value::I4(7), 0x58, None);
    let v = c
        .vqt(&k(K2, "X"), "X = 7", |v| v.value == Value::I4(7))
        .await;
    assert_eq!(
        v.quality,
        Quality(0x58),
        "the 16-bit quality passes as it is"
    );
    // A second change is sent too.
    g.plant(K1).set("A", Value::R8(43.0), 0xC0, Some(local));
    c.vqt(&k(K1, "A"), "A = 43", |v| v.value == Value::R8(43.0))
        .await;
    // Unsubscribing the last subscription deactivates the item.
    c.client.unsubscribe(vec![k(K1, "A")]);
    until("A inactive", || !g.plant(K1).is_item_active("A")).await;
    assert!(g.plant(K2).is_item_active("X"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn device_reads_use_dsdevice_or_dsdriver_as_the_channel_says() {
    let g = gate().await;
    let (local, utc) = summer_noon();
    g.plant(K1).set("B", Value::R8(1.5), 0xC0, Some(local));
    g.plant(K2).set("Y", Value::R8(2.5), 0xC0, Some(local));
    let mut c = client(&g, &pki().reader, "READER.");
    let r = c
        .read(
            vec![k(K1, "B"), k(K2, "Y"), k(K1, "NOPE")],
            ReadSource::Device,
        )
        .await;
    assert_eq!(r[0].as_ref().map(|v| v.value.clone()), Ok(Value::R8(1.5)));
    assert_eq!(r[0].as_ref().map(|v| v.timestamp), Ok(utc));
    assert_eq!(r[1].as_ref().map(|v| v.value.clone()), Ok(Value::R8(2.5)));
    assert_eq!(r[2], Err(OpcError::ItemUnknown));
    assert!(g.plant(K1).calls().contains(&"Read 2 B".to_owned()));
    assert!(
        g.plant(K2).calls().contains(&"Read 3 Y".to_owned()),
        "KANAL2 reads the device from the driver: {:?}",
        g.plant(K2).calls()
    );
    // A driver read is a driver read on every channel.
    c.read(vec![k(K1, "B")], ReadSource::Driver).await;
    assert!(g.plant(K1).calls().contains(&"Read 3 B".to_owned()));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn writes_are_granted_and_refused_by_the_certificate() {
    audit_log();
    let g = gate().await;
    until("KANAL1 open", || g.plant(K1).is_active()).await;
    let mut w = client(&g, &pki().writer, "WRITER.");
    let r = w.write(vec![(k(K1, "C"), Value::R8(9.0))]).await;
    assert_eq!(r, vec![Ok(())]);
    assert_eq!(
        g.plant(K1).value("C").map(|v| v.value),
        Some(Value::R8(9.0))
    );
    assert!(g.plant(K1).calls().iter().any(|c| c.starts_with("Write C")));
    // The writer's certificate is not granted KANAL2.
    let r = w.write(vec![(k(K2, "X"), Value::R8(1.0))]).await;
    assert_eq!(r, vec![Err(OpcError::WriteErrorIllegalCommand)]);
    // Another certificate, even declaring the writer's asix name, is refused.
    let mut other = client(&g, &pki().reader, "WRITER.");
    let r = other.write(vec![(k(K1, "C"), Value::R8(10.0))]).await;
    assert_eq!(r, vec![Err(OpcError::WriteErrorIllegalCommand)]);
    assert_eq!(
        g.plant(K1).value("C").map(|v| v.value),
        Some(Value::R8(9.0))
    );
    assert!(!g.plant(K2).calls().iter().any(|c| c.starts_with("Write")));
    // The Automation server's own refusal passes through with its code.
    g.plant(K1).set_read_only("B");
    let r = w.write(vec![(k(K1, "B"), Value::R8(1.0))]).await;
    assert_eq!(r, vec![Err(OpcError::WriteErrorDeviceRequestIllegal)]);
    // Each item has its audit line, naming the certificate that wrote it beside the name
    // the client declared.
    let writer = format!(
        "identity=\"cert:{}\"",
        hex(&pki().writer.identity.fingerprint())
    );
    let reader = format!(
        "identity=\"cert:{}\"",
        hex(&pki().reader.identity.fingerprint())
    );
    let c = audit_lines("KANAL1.C");
    assert_eq!(c.len(), 2, "{c:#?}");
    assert!(
        c[0].contains("client=\"WRITER.\"")
            && c[0].contains(&writer)
            && c[0].contains("method=asix::Write ")
            && c[0].contains("value=R8:9")
            && c[0].ends_with("result=S_OK"),
        "{c:#?}"
    );
    assert!(
        c[1].contains(&reader) && c[1].ends_with("result=denied"),
        "{c:#?}"
    );
    let x = audit_lines("KANAL2.X");
    assert!(
        x.len() == 1 && x[0].contains(&writer) && x[0].ends_with("result=denied"),
        "{x:#?}"
    );
    let b = audit_lines("KANAL1.B");
    assert!(
        b.len() == 1 && b[0].ends_with("result=ASKOM_E_WriteError_DeviceRequestIllegal"),
        "{b:#?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_extended_write_goes_to_writeex_with_local_time() {
    audit_log();
    let g = gate().await;
    until("KANAL1 open", || g.plant(K1).is_active()).await;
    let mut w = client(&g, &pki().writer, "WRITER.");
    let (local, utc) = summer_noon();
    let id = w.client.write_vqt(vec![(
        k(K1, "A"),
        Vqt::new(Value::R8(5.0), Quality(0x40), utc),
    )]);
    assert_eq!(w.write_done(id).await, vec![Ok(())]);
    let v = g.plant(K1).value("A").expect("A");
    assert_eq!(v.value, Value::R8(5.0));
    assert_eq!(v.quality, 0x40);
    let t = v.local_time.expect("time");
    assert!(
        (t - local).abs() < 1e-8,
        "UTC 10:00 is written as local 12:00: {t} vs {local}"
    );
    assert!(g
        .plant(K1)
        .calls()
        .iter()
        .any(|c| c.starts_with("WriteEx A")));
    // The audit line carries the quality and the time (UTC) the client wrote.
    let a = audit_lines("KANAL1.A");
    assert!(
        a.iter().any(|l| l.contains("method=asix::WriteEx")
            && l.contains("quality=0x0040")
            && l.contains("timestamp=")
            && l.ends_with("result=S_OK")),
        "{a:#?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hanging_channel_does_not_stall_another() {
    let g = gate().await;
    until("both channels open", || {
        g.plant(K1).is_active() && g.plant(K2).is_active()
    })
    .await;
    let mut c = client(&g, &pki().reader, "READER.");
    c.client.subscribe(vec![k(K1, "A"), k(K2, "X")], 20);
    until("A and X active", || {
        g.plant(K1).is_item_active("A") && g.plant(K2).is_item_active("X")
    })
    .await;
    g.plant(K2).set("X", Value::R8(3.0), 0xC0, None);
    c.vqt(&k(K2, "X"), "X = 3", |v| v.value == Value::R8(3.0))
        .await;
    // KANAL2's Automation server hangs in Read.
    g.plant(K2).hang("Read", true);
    let started = Instant::now();
    let r = c
        .read(vec![k(K2, "Y"), k(K1, "B")], ReadSource::Device)
        .await;
    assert_eq!(
        r[0].as_ref().map(|v| v.quality),
        Ok(Quality::BAD_COMM_FAILURE)
    );
    assert_eq!(r[1].as_ref().map(|v| v.quality), Ok(Quality::GOOD));
    assert!(started.elapsed() < Duration::from_secs(5));
    // The hung channel's subscribed items go BAD, the source is announced failed...
    c.vqt(&k(K2, "X"), "X BAD", |v| {
        v.quality == Quality::BAD_COMM_FAILURE
    })
    .await;
    until("SOURCE_FAILED", || g.engine.source_failed()).await;
    // ...and KANAL1 goes on: its changes, reads and writes.
    g.plant(K1).set("A", Value::R8(77.0), 0xC0, None);
    c.vqt(&k(K1, "A"), "A = 77", |v| v.value == Value::R8(77.0))
        .await;
    let r = c.read(vec![k(K1, "C")], ReadSource::Device).await;
    assert_eq!(r[0].as_ref().map(|v| v.quality), Ok(Quality::GOOD));
    // Released, KANAL2 serves again with good values.
    g.plant(K2).hang("Read", false);
    until("source repaired", || !g.engine.source_failed()).await;
    c.vqt(&k(K2, "X"), "X good again", |v| v.quality == Quality::GOOD)
        .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn server_state_failed_is_announced_as_source_failed() {
    let g = gate().await;
    let flags = |g: &Gate| g.server.announcement(Resource::channel(K1)).flags;
    until("running", || {
        g.plant(K1).is_active() && g.plant(K2).is_active() && !g.engine.source_failed()
    })
    .await;
    assert!(!flags(&g).source_failed());
    let mut c = client(&g, &pki().reader, "READER.");
    c.client.subscribe(vec![k(K1, "A")], 20);
    c.wait("ChannelUp", |e| {
        matches!(e, ClientEvent::ChannelUp { .. }).then_some(())
    })
    .await;
    for (state, failed) in [
        (ServerState::Failed, true),
        (ServerState::Running, false),
        (ServerState::NoConfig, true),
        (ServerState::Test, false),
        (ServerState::Suspended, true),
        (ServerState::Running, false),
    ] {
        g.plant(K2).set_state(state);
        until(&format!("{state:?}"), || {
            flags(&g).source_failed() == failed
        })
        .await;
        // Linked clients hear it too.
        c.wait(&format!("ServerStatus {state:?}"), |e| match e {
            ClientEvent::ServerStatus { flags, .. } if flags.source_failed() == failed => Some(()),
            _ => None,
        })
        .await;
    }
    // A ServerState call that fails counts as a failed source too.
    g.plant(K1)
        .fail("ServerState", Some(CallError::new(OpcError::Fail, "gone")));
    until("ServerState call failing", || flags(&g).source_failed()).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_vanishing_mid_subscription_costs_nothing() {
    let g = gate().await;
    let mut a = client(&g, &pki().reader, "A.");
    let mut b = client(&g, &pki().writer, "B.");
    a.client.subscribe(vec![k(K1, "A"), k(K1, "B")], 20);
    b.client.subscribe(vec![k(K1, "A")], 20);
    until("A and B active", || {
        g.plant(K1).is_item_active("A") && g.plant(K1).is_item_active("B")
    })
    .await;
    until("two clients", || g.server.client_count() == 2).await;
    g.plant(K1).set("A", Value::R8(1.0), 0xC0, None);
    a.vqt(&k(K1, "A"), "a: A = 1", |v| v.value == Value::R8(1.0))
        .await;
    b.vqt(&k(K1, "A"), "b: A = 1", |v| v.value == Value::R8(1.0))
        .await;
    // Client a goes away without unsubscribing.
    drop(a);
    until("one client", || g.server.client_count() == 1).await;
    until("B inactive", || !g.plant(K1).is_item_active("B")).await;
    assert!(g.plant(K1).is_item_active("A"), "b still subscribes A");
    g.plant(K1).set("A", Value::R8(2.0), 0xC0, None);
    b.vqt(&k(K1, "A"), "b: A = 2", |v| v.value == Value::R8(2.0))
        .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_without_a_pinned_gate_certificate_gets_no_data() {
    let g = gate().await;
    let mut c = client(&g, &pki().reader, "READER.");
    // Pins another server: the gate's announcement does not match.
    let mut cfg = ClientConfig::new("X.", "CLI");
    cfg.discovery_targets = vec![g.server.discovery_addr()];
    cfg.discovery_bind = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
    cfg.options.find_server_timeout = Duration::from_millis(300);
    cfg.reconnect_interval = Duration::from_millis(200);
    cfg.security = ClientSecurity::tls(
        &pki().reader.identity,
        tls::Trust::Fingerprints(vec![pki().writer.identity.fingerprint()]),
    )
    .expect("TLS");
    let (sink, mut rx) = channel_sink();
    let stranger =
        AsixClient::start(cfg, sink, &tokio::runtime::Handle::current()).expect("client");
    stranger.subscribe(vec![k(K1, "A")], 20);
    let down = tokio::time::timeout(LIMIT, async {
        loop {
            match rx.recv().await {
                Some(ClientEvent::ChannelDown { .. }) => return true,
                Some(ClientEvent::ChannelUp { .. }) | None => return false,
                Some(_) => {}
            }
        }
    })
    .await;
    assert_eq!(down, Ok(true));
    // The pinned client links fine.
    c.client.subscribe(vec![k(K1, "A")], 20);
    c.wait("ChannelUp", |e| {
        matches!(e, ClientEvent::ChannelUp { .. }).then_some(())
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plaintext_link_reaches_only_the_channels_that_allow_it() {
    let g = gate_with(|cfg| {
        cfg.channels[1].allow_plaintext = true;
        for ch in [K1, K2] {
            cfg.write_rights = WriteRights::new(
                cfg.write_rights
                    .rules()
                    .iter()
                    .cloned()
                    .chain([Rule::new(
                        Channels::One(ch.into()),
                        Principal::AsixClient("PLAIN.".into()),
                    )])
                    .collect(),
            );
        }
    })
    .await;
    until("both channels open", || {
        g.plant(K1).is_active() && g.plant(K2).is_active()
    })
    .await;
    let mut p = client_secured(&g, "PLAIN.", ClientSecurity::Plaintext);
    let r = p
        .read(vec![k(K1, "B"), k(K2, "Y")], ReadSource::Device)
        .await;
    assert_eq!(r[0], Err(OpcError::NetLinkToServerNegativeAnswer));
    assert_eq!(r[1].as_ref().map(|v| v.quality), Ok(Quality::GOOD));
    // On a plaintext link the declared name is all there is: it grants KANAL2.
    let r = p
        .write(vec![
            (k(K2, "X"), Value::R8(4.0)),
            (k(K1, "A"), Value::R8(4.0)),
        ])
        .await;
    assert_eq!(
        r,
        vec![Ok(()), Err(OpcError::NetLinkToServerNegativeAnswer)]
    );
    assert_eq!(
        g.plant(K2).value("X").map(|v| v.value),
        Some(Value::R8(4.0))
    );
    // On a TLS link the same declared name grants nothing: the certificate decides.
    let mut t = client(&g, &pki().reader, "PLAIN.");
    let r = t.write(vec![(k(K2, "X"), Value::R8(5.0))]).await;
    assert_eq!(r, vec![Err(OpcError::WriteErrorIllegalCommand)]);
    assert_eq!(
        g.plant(K2).value("X").map(|v| v.value),
        Some(Value::R8(4.0))
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn requests_to_a_hung_channel_are_bounded() {
    let g = gate().await;
    until("KANAL2 open", || g.plant(K2).is_active()).await;
    g.plant(K2).hang("Read", true);
    let ch = g.engine.channel(K2).expect("KANAL2").clone();
    // Far more requests than the queue holds, all at once.
    let n = asix_gate::engine::QUEUE * 2;
    let reads: Vec<_> = (0..n)
        .map(|_| {
            let (e, ch) = (g.engine.clone(), ch.clone());
            tokio::spawn(async move { e.read(&ch, DataSource::Device, vec!["Y".into()]).await })
        })
        .collect();
    for r in reads {
        let r = r.await.expect("read task");
        assert_eq!(
            r[0].as_ref().map(|v| v.quality),
            Ok(Quality::BAD_COMM_FAILURE)
        );
    }
    g.plant(K2).hang("Read", false);
    // Once released, the worker runs what was queued (a read meanwhile may still find the
    // queue full) and then serves again.
    let t0 = Instant::now();
    loop {
        let r = g
            .engine
            .read(&ch, DataSource::Device, vec!["Y".into()])
            .await;
        if r[0].as_ref().map(|v| v.quality) == Ok(Quality::GOOD) {
            break;
        }
        assert!(t0.elapsed() < LIMIT, "KANAL2 does not serve again");
    }
    let reads = g
        .plant(K2)
        .calls()
        .iter()
        .filter(|c| c.starts_with("Read 2 Y"))
        .count();
    // The queued ones and the few retried while it drained: far fewer than were sent.
    assert!(
        reads > 1 && reads < n,
        "{reads} reads of {n} reached the Automation server"
    );
}

/// A discovery or link address in use: `serve` fails naming the socket, the address and
/// the cause (the gate logs it and exits with it), instead of an OS error number alone.
#[tokio::test]
async fn a_port_in_use_is_reported_with_its_socket_and_address() {
    let taken_udp = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).expect("a UDP port");
    let udp = taken_udp.local_addr().unwrap();
    let taken_tcp = std::net::TcpListener::bind((Ipv4Addr::LOCALHOST, 0)).expect("a TCP port");
    let tcp = taken_tcp.local_addr().unwrap();
    for (what, f) in [
        (
            format!("discovery (UDP) {udp}: address in use"),
            Box::new(move |c: &mut GateConfig| c.discovery = udp) as Box<dyn Fn(&mut GateConfig)>,
        ),
        (
            format!("link listener (TCP) {tcp}: address in use"),
            Box::new(move |c: &mut GateConfig| c.listen = tcp),
        ),
    ] {
        let mut cfg = GateConfig::new("GATE1");
        cfg.listen = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
        cfg.discovery = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
        f(&mut cfg);
        let factory: ChannelFactory =
            Arc::new(|_: &str| Err(CallError::new(OpcError::Fail, "no plant")));
        let engine = Engine::start(&cfg, factory);
        let security = asix_gate::security(&cfg, Some(&pki().server.identity)).expect("security");
        let r = asix_gate::serve(asix_gate::serve_config(&cfg, security), engine.clone()).await;
        engine.stop();
        let e = r.err().expect("serve fails on a port in use");
        assert_eq!(e.kind(), std::io::ErrorKind::AddrInUse);
        assert!(e.to_string().starts_with(&what), "{e}");
    }
}
