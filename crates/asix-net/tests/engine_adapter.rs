//! End to end below COM: the core's engine with the asix namespace of the shipped example
//! configuration and demo database, the `AsixSource` backend, and a simulator serving the
//! demo database on loopback. Bounded in time and iterations.

mod common;

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use asix_model::namespace::AsixNamespace;
use asix_model::{load_config_file, load_database_file, ServerOptions};
use asix_net::client::wall_now;
use asix_net::datasource::{client_config_from_server_options, AsixSource, NamespaceResolver};
use asix_net::sim::plant::{channels_from_database, ACID_PLANT_CHANNEL};
use common::*;
use ctopc_core::model::{
    DataSource as ReadFrom, Engine, EngineConfig, GroupHandle, GroupParams, ItemDefinition,
    SyncOutcome, SyncResult,
};
use ctopc_core::namespace::Namespace;
use ctopc_core::source::{Backend, SourceOutput, Wake};
use ctopc_core::{Quality, Value, VarType};

struct CountingWake(AtomicU64);

impl Wake for CountingWake {
    fn wake(&self) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }
}

/// The driver loop of the COM runtime, in miniature.
struct Driver {
    e: Engine,
    src: AsixSource<NamespaceResolver>,
}

impl Driver {
    fn step(&mut self) {
        let now = wall_now();
        while let Some(r) = self.e.poll_source_request() {
            self.src.request(now, r);
        }
        let mut out = SourceOutput::default();
        self.src.poll(now, &mut out);
        self.e.handle_source_updates(now, out.updates);
        for (id, r) in out.read_results {
            self.e.handle_source_read_result(now, id, r);
        }
        for (id, r) in out.write_results {
            self.e.handle_source_write_result(now, id, r);
        }
        while self.e.poll_timeout().is_some_and(|t| t <= now) {
            self.e.handle_timeout(now);
        }
    }

    /// Steps (every 10 ms, at most `limit`) until `f` gives an answer.
    async fn until<T>(
        &mut self,
        limit: Duration,
        what: &str,
        mut f: impl FnMut(&mut Engine) -> Option<T>,
    ) -> T {
        let t0 = Instant::now();
        while t0.elapsed() < limit {
            self.step();
            if let Some(r) = f(&mut self.e) {
                return r;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        panic!("timed out waiting for {what}");
    }

    async fn sync<T>(
        &mut self,
        what: &str,
        outcome: SyncOutcome<T>,
        unwrap: impl Fn(SyncResult) -> T,
    ) -> T {
        match outcome {
            SyncOutcome::Ready(r) => r,
            SyncOutcome::Pending(id) => {
                let r = self
                    .until(Duration::from_secs(10), what, |e| e.take_sync_result(id))
                    .await;
                unwrap(r)
            }
        }
    }
}

fn repo() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn engine_items_get_values_reads_and_writes_through_the_asix_network() {
    tokio::time::timeout(TEST_LIMIT, async {
        let (db, _) = load_database_file(
            &repo().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez"),
            None,
        )
        .unwrap();
        // The simulator runs on this computer: writes are allowed without a permission entry.
        let sim = sim_with("DEMO", |c| {
            c.channels = channels_from_database(&db, ACID_PLANT_CHANNEL);
            c.host_name = CLIENT_HOST.into();
            c.tick_ms = 200;
        })
        .await;
        let (config, _) = load_config_file(&repo().join("asixconnect.ini.example")).unwrap();
        let (ns, warnings) = AsixNamespace::load(config);
        assert!(warnings.is_empty(), "{warnings:?}");
        let ns = Arc::new(ns);
        let wake = Arc::new(CountingWake(AtomicU64::new(0)));
        let src = AsixSource::new(
            NamespaceResolver::new(ns.clone(), client_cfg(&[sim.discovery_addr()])),
            tokio::runtime::Handle::current(),
            wake.clone(),
        );
        let mut d = Driver {
            e: Engine::new(EngineConfig::default(), ns.clone() as Arc<dyn Namespace>),
            src,
        };

        let now = wall_now();
        let session = d.e.open_session();
        let group: GroupHandle =
            d.e.add_group(
                now,
                session,
                &GroupParams {
                    name: "g",
                    active: true,
                    update_rate: 1000,
                    ..GroupParams::default()
                },
            )
            .unwrap()
            .group;
        let ids = [
            "KW_A000",
            "KW_A000.PercentageCV",
            "asmen.SIARKA.KW_A001.R4",
            "KW_A110",
        ];
        let defs: Vec<ItemDefinition> = ids
            .iter()
            .enumerate()
            .map(|(i, id)| ItemDefinition {
                item_id: id,
                access_path: "",
                active: true,
                client_handle: i as u32,
                requested_type: VarType::EMPTY,
            })
            .collect();
        let handles: Vec<u32> =
            d.e.add_items(now, group, &defs)
                .unwrap()
                .into_iter()
                .map(|r| r.expect("item added").server_handle)
                .collect();

        // Subscribed through the network: the cache fills with GOOD values.
        let states = d
            .until(Duration::from_secs(10), "good values in the cache", |e| {
                let SyncOutcome::Ready(r) =
                    e.read(wall_now(), group, ReadFrom::Cache, &handles).ok()?
                else {
                    return None;
                };
                let all: Vec<_> = r.into_iter().collect::<Result<Vec<_>, _>>().ok()?;
                all.iter().all(|s| s.quality.is_good()).then_some(all)
            })
            .await;
        // What the `_Diagnostics` branch shows of the asix channels of these items (SIARKA,
        // PIEC): linked to the simulator's server, their subscribed variables, no
        // failover, no error.
        let channels = d.src.channels();
        assert!(channels.len() >= 2, "{channels:?}");
        for c in &channels {
            assert_eq!(c.link, ctopc_core::diagnostics::LinkState::Up, "{c:?}");
            assert_eq!(c.server, "DEMO", "{c:?}");
            assert_eq!((c.failovers, c.last_error.as_str()), (0, ""), "{c:?}");
        }
        let subscribed: u64 = channels.iter().map(|c| c.subscriptions).sum();
        assert!(subscribed >= 3, "{channels:?}");
        assert!(
            matches!(states[0].value, Value::R4(x) if (0.0..=8.0).contains(&x)),
            "{:?}",
            states[0]
        );
        let Value::R8(pct) = states[1].value else {
            panic!("{:?}", states[1])
        };
        let Value::R4(level) = states[0].value else {
            unreachable!()
        };
        assert!((0.0..=100.0).contains(&pct));
        // Same variable, same sample (the engine may have taken them a tick apart).
        assert!(
            (pct - f64::from(level) / 8.0 * 100.0).abs() < 10.0,
            "{pct} vs {level}"
        );
        assert!(matches!(states[2].value, Value::R4(_)));
        assert!(
            wake.0.load(Ordering::Relaxed) > 0,
            "the backend woke the driver"
        );

        // A device read goes over the network.
        let outcome =
            d.e.read(wall_now(), group, ReadFrom::Device, &handles[..1])
                .unwrap();
        let r = d
            .sync("device read", outcome, |r| match r {
                SyncResult::Read(r) => r,
                other => panic!("{other:?}"),
            })
            .await;
        assert!(r[0].as_ref().unwrap().quality.is_good());

        // A write reaches the simulator (KW_A110, a writable set point on channel PIEC).
        let outcome =
            d.e.write(wall_now(), group, &[(handles[3], Value::R8(12.5))])
                .unwrap();
        let w = d
            .sync("write", outcome, |r| match r {
                SyncResult::Write(w) => w,
                other => panic!("{other:?}"),
            })
            .await;
        assert_eq!(w, vec![Ok(())]);
        assert_eq!(sim.vqt("PIEC", "KW_A110").unwrap().value, Value::R4(12.5));

        // Channel Demo_Wytwornia_Kwasu checks limits and control variables (example ini):
        // KW_A000's control variable is KW_K001, its alarm high limit 7.5.
        let def = ItemDefinition {
            item_id: "KW_A000",
            access_path: "Demo_Wytwornia_Kwasu",
            active: true,
            client_handle: 99,
            requested_type: VarType::EMPTY,
        };
        let checked = d.e.add_items(wall_now(), group, &[def]).unwrap()[0]
            .as_ref()
            .unwrap()
            .server_handle;
        let cache = |e: &mut Engine| -> Option<ctopc_core::model::ItemState> {
            let SyncOutcome::Ready(r) = e
                .read(wall_now(), group, ReadFrom::Cache, &[checked])
                .ok()?
            else {
                return None;
            };
            r.into_iter().next()?.ok()
        };
        assert!(sim.force("DIAGNOSTYKA", "KW_K001", 1.0) || sim.force("", "KW_K001", 1.0));
        d.until(
            Duration::from_secs(10),
            "sensor failure from the control variable",
            |e| cache(e).filter(|s| s.quality == Quality::BAD_SENSOR_FAILURE),
        )
        .await;
        assert!(sim.force("", "KW_K001", 0.0));
        sim.force("SIARKA", "KW_A000", 7.9);
        let s = d
            .until(Duration::from_secs(10), "the high limit", |e| {
                cache(e).filter(|s| s.quality.is_good() && s.quality.limit() == Quality::LIMIT_HIGH)
            })
            .await;
        assert!(matches!(s.value, Value::R4(x) if x > 7.5), "{s:?}");
        // The same variable on the basic channel (no checks) stays plain GOOD.
        let plain = d
            .until(Duration::from_secs(10), "plain good", |e| {
                let SyncOutcome::Ready(r) = e
                    .read(wall_now(), group, ReadFrom::Cache, &handles[..1])
                    .ok()?
                else {
                    return None;
                };
                r.into_iter()
                    .next()?
                    .ok()
                    .filter(|s| matches!(s.value, Value::R4(x) if x > 7.5))
            })
            .await;
        assert_eq!(plain.quality, Quality::GOOD);

        // The simulator dies: the cache shows BAD Last Known Value with the last values.
        sim.shutdown().await;
        let states = d
            .until(Duration::from_secs(10), "LKV in the cache", |e| {
                let SyncOutcome::Ready(r) = e
                    .read(wall_now(), group, ReadFrom::Cache, &handles[..1])
                    .ok()?
                else {
                    return None;
                };
                let s = r.into_iter().next()?.ok()?;
                (s.quality == Quality::BAD_LAST_KNOWN_VALUE).then_some(s)
            })
            .await;
        assert!(matches!(states.value, Value::R4(_)));
    })
    .await
    .expect("test exceeded its time limit");
}

#[test]
fn server_options_give_the_client_name_and_discovery_targets() {
    let mut o = ServerOptions::default();
    let c = client_config_from_server_options(&o, "CLI");
    assert_eq!(c.client_name, "CLI.");
    assert_eq!(c.discovery_targets.len(), 2);
    assert_eq!(c.discovery_targets[0].port(), 48100);
    o.client_name = Some("KE2".into());
    o.broadcast_address = Some("192.168.1.255".into());
    o.discovery_port = Some(5000);
    let c = client_config_from_server_options(&o, "CLI");
    assert_eq!(c.client_name, "KE2");
    assert_eq!(c.discovery_targets[0].to_string(), "192.168.1.255:5000");
    assert_eq!(c.discovery_targets[1].to_string(), "127.0.0.1:5000");
}

/// The resolver hands each channel's client the external server lists the core read from
/// `ASIXConnect.ini` (resource names case-insensitive), used when the channel names no server.
#[test]
fn the_resolver_takes_the_external_server_lists_from_the_configuration() {
    use asix_net::datasource::Resolver;
    use asix_net::proto::discovery::{Resource, ResourceKind};
    use asix_net::{ClientConfig, ServerChoice};
    let ini = "[Channel:*]\n[Channel:Named]\nAsixServerName = S9\n\
        [AsixCTServers]\nKanal1 = S1, S2\n[AsixHTServers]\nARCH = S3\n";
    let (config, warnings) = asix_model::parse_config(ini.as_bytes(), "test.ini").unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let (ns, _) = AsixNamespace::load(config);
    let r = NamespaceResolver::new(Arc::new(ns), ClientConfig::new("CLI.", "CLI"));
    let c = r.client_config("*");
    let names = |v: &[&str]| ServerChoice::Names(v.iter().map(|s| s.to_string()).collect());
    assert_eq!(
        c.choice_for(&Resource::channel("KANAL1")),
        names(&["S1", "S2"])
    );
    assert_eq!(c.choice_for(&Resource::channel("OTHER")), ServerChoice::Any);
    let arch = Resource {
        kind: ResourceKind::Archive,
        name: "arch".into(),
    };
    assert_eq!(c.choice_for(&arch), names(&["S3"]));
    // A channel that names its server does not use the lists.
    let c = r.client_config("Named");
    assert_eq!(c.choice_for(&Resource::channel("KANAL1")), names(&["S9"]));
}

/// What the server's driver thread does: no tokio context, `network_backend` from the
/// namespace alone (discovery target from `[Server] BroadcastAddress` / `DiscoveryPort`).
#[test]
fn the_network_backend_runs_from_a_plain_thread() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let sim = rt.block_on(sim("PLAIN"));
    let db = repo().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez");
    // The client's certificate in files, the simulator's pinned by fingerprint: what a
    // plant's ASIXConnect.ini says.
    let dir = std::env::temp_dir().join(format!("asix-net-plain-thread-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("opc.pem"), &pki().client.cert_pem).unwrap();
    std::fs::write(dir.join("opc-key.pem"), &pki().client.key_pem).unwrap();
    let ini = format!(
        "[Server]\nBroadcastAddress = 127.0.0.1\nDiscoveryPort = {}\n[Channel:*]\nItemsDatabase = {}\n\
         AsixNetCertFile = {}\nAsixNetKeyFile = {}\nAsixNetServerFingerprint = {}\n",
        sim.discovery_addr().port(),
        db.display(),
        dir.join("opc.pem").display(),
        dir.join("opc-key.pem").display(),
        asix_net::tls::fingerprint_hex(&sim.fingerprint().unwrap()),
    );
    let (config, warnings) = asix_model::parse_config(ini.as_bytes(), "test.ini").unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let (ns, _) = AsixNamespace::load(config);
    let ns = Arc::new(ns);
    let wake = Arc::new(CountingWake(AtomicU64::new(0)));
    let mut backend = asix_net::datasource::network_backend(ns.clone(), wake.clone()).unwrap();
    // Real data: the server reports OPC_STATUS_RUNNING over the network backend.
    assert!(!backend.is_simulation());
    let mut e = Engine::new(EngineConfig::default(), ns as Arc<dyn Namespace>);
    let session = e.open_session();
    let group = e
        .add_group(
            wall_now(),
            session,
            &GroupParams {
                name: "g",
                active: true,
                ..GroupParams::default()
            },
        )
        .unwrap()
        .group;
    // The simulator serves the built-in plant: a descriptive ID of its channel.
    let id = format!("asmen.{CH}.ZB1_POZIOM.R4");
    let def = ItemDefinition {
        item_id: &id,
        access_path: "",
        active: true,
        client_handle: 1,
        requested_type: VarType::EMPTY,
    };
    let h = e.add_items(wall_now(), group, &[def]).unwrap()[0]
        .as_ref()
        .unwrap()
        .server_handle;
    let t0 = Instant::now();
    let state = loop {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "no value through the network backend"
        );
        let now = wall_now();
        while let Some(r) = e.poll_source_request() {
            backend.request(now, r);
        }
        let mut out = SourceOutput::default();
        backend.poll(now, &mut out);
        e.handle_source_updates(now, out.updates);
        if let Ok(SyncOutcome::Ready(r)) = e.read(now, group, ReadFrom::Cache, &[h]) {
            if let Some(Ok(s)) = r.into_iter().next() {
                if s.quality.is_good() {
                    break s;
                }
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    assert!(matches!(state.value, Value::R4(_)));
    drop(backend); // shuts its runtime down without blocking or panicking
    drop(sim);
    rt.shutdown_timeout(Duration::from_secs(1));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The demo plant on the asix network for the limit tests, with `KW_A100 = 1000`,
/// `KW_L001 = 990`, `KW_L002 = 950` (without channel DIAGNOSTYKA, where the limit and
/// control variables are, unless `diagnostics`), and an engine reading it through an
/// `AsixSource` on a channel checking limits and control variables.
async fn limits_setup(diagnostics: bool) -> (asix_net::sim::SimHandle, Driver) {
    use asix_net::sim::rights::WriteRights;
    let db_path = repo().join("demo/wytwornia_kwasu/wytwornia_kwasu.zez");
    let (db, _) = load_database_file(&db_path, None).unwrap();
    // Channel PIEC on driver NONE: KW_A100 keeps the value forced (the limit variables are
    // writable set values, constant anyway).
    let (rights, warnings) = WriteRights::from_app_ini(b"[ASMEN]\nPIEC = NONE\n", "app.ini");
    assert!(warnings.is_empty(), "{warnings:?}");
    let mut channels = channels_from_database(&db, ACID_PLANT_CHANNEL);
    channels.retain(|c| diagnostics || c.name != "DIAGNOSTYKA");
    let sim = sim_with("LIMITS", |c| {
        c.channels = channels;
        c.write_rights = rights;
        c.tick_ms = 50;
    })
    .await;
    assert!(sim.force("PIEC", "KW_A100", 1000.0));
    if diagnostics {
        assert!(sim.force("DIAGNOSTYKA", "KW_L001", 990.0));
        assert!(sim.force("DIAGNOSTYKA", "KW_L002", 950.0));
    }
    let ini = format!(
        "[Channel:*]\nItemsDatabase = {}\nCheckLimits = tak\nCheckControlVariables = tak\n",
        db_path.display()
    );
    let (config, warnings) = asix_model::parse_config(ini.as_bytes(), "test.ini").unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let (ns, _) = AsixNamespace::load(config);
    let ns = Arc::new(ns);
    let src = AsixSource::new(
        NamespaceResolver::new(ns.clone(), client_cfg(&[sim.discovery_addr()])),
        tokio::runtime::Handle::current(),
        Arc::new(CountingWake(AtomicU64::new(0))),
    );
    let d = Driver {
        e: Engine::new(EngineConfig::default(), ns as Arc<dyn Namespace>),
        src,
    };
    (sim, d)
}

/// A new active group of `rate` ms with the items `ids`: the group and the items' handles.
fn add_group_items(d: &mut Driver, rate: u32, ids: &[&str]) -> (GroupHandle, Vec<u32>) {
    let session = d.e.open_session();
    let params = GroupParams {
        name: "g",
        active: true,
        update_rate: rate,
        ..GroupParams::default()
    };
    let group = d.e.add_group(wall_now(), session, &params).unwrap().group;
    let defs: Vec<ItemDefinition> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| ItemDefinition {
            item_id: id,
            access_path: "",
            active: true,
            client_handle: i as u32,
            requested_type: VarType::EMPTY,
        })
        .collect();
    let handles =
        d.e.add_items(wall_now(), group, &defs)
            .unwrap()
            .into_iter()
            .map(|r| r.expect("item added").server_handle)
            .collect();
    (group, handles)
}

/// An item's state in the cache.
fn cached(e: &mut Engine, group: GroupHandle, h: u32) -> Option<ctopc_core::model::ItemState> {
    let SyncOutcome::Ready(r) = e.read(wall_now(), group, ReadFrom::Cache, &[h]).ok()? else {
        return None;
    };
    r.into_iter().next()?.ok()
}

/// CheckLimits with limits held in variables, over the asix network: the demo's KW_A100 has
/// `WarnHigh = KW_L001` and `AlarmHigh = KW_L002` (limit variables on channel DIAGNOSTYKA).
/// The source subscribes the limit variables with the item (not as items), its quality
/// follows their current values, a limit change is reported without waiting for the item's
/// next sample, and a limit variable is let go with the last item needing it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn limits_held_in_variables_follow_the_limit_variables_over_the_network() {
    const HIGH: u16 = Quality::LIMIT_HIGH;
    const SECOND: u16 = Quality::VENDOR_SECOND_LIMIT;
    tokio::time::timeout(TEST_LIMIT, async {
        let (sim, mut d) = limits_setup(true).await;
        // KW_L002 is also an item, sampled every second; KW_A100 (twice: two source items
        // of one variable) only every minute: after its first sample, its quality changes
        // only through the source reporting it again on a limit change.
        let (fast, fast_items) = add_group_items(&mut d, 1000, &["KW_L002"]);
        let (slow, slow_items) =
            add_group_items(&mut d, 60_000, &["KW_A100", "KW_A100.PercentageCV"]);
        let (ha, hp) = (slow_items[0], slow_items[1]);
        let wait_quality = |q: u16| {
            move |e: &mut Engine| {
                let a = cached(e, slow, ha)?;
                let p = cached(e, slow, hp)?;
                (a.quality == Quality(q) && p.quality == Quality(q)).then_some((a, p))
            }
        };

        // 1000 above AlarmHigh = KW_L002 = 950: High + Second Limit.
        let (a, p) = d
            .until(
                Duration::from_secs(10),
                "the alarm limit from KW_L002",
                wait_quality(0xC0 | HIGH | SECOND),
            )
            .await;
        assert_eq!(a.value, Value::R4(1000.0));
        assert!(
            matches!(p.value, Value::R8(x) if (x - 1000.0 / 12.0).abs() < 1e-3),
            "{p:?}"
        );
        // The limit and control variables are subscribed once, for the rules.
        for v in ["KW_L001", "KW_L002", "KW_K002"] {
            assert_eq!(sim.subscriptions("DIAGNOSTYKA", v), 1, "{v}");
        }
        assert_eq!(sim.subscriptions("PIEC", "KW_A100"), 1);

        // The alarm limit rises above the value: only WarnHigh = KW_L001 = 990 is crossed.
        assert!(sim.force("DIAGNOSTYKA", "KW_L002", 1150.0));
        d.until(
            Duration::from_secs(10),
            "the warning limit from KW_L001",
            wait_quality(0xC0 | HIGH),
        )
        .await;
        // And back below it.
        assert!(sim.force("DIAGNOSTYKA", "KW_L002", 950.0));
        d.until(
            Duration::from_secs(10),
            "the alarm limit again",
            wait_quality(0xC0 | HIGH | SECOND),
        )
        .await;

        // One of the two items goes: the other still needs the limit variables.
        d.e.remove_items(wall_now(), slow, &slow_items[..1])
            .unwrap();
        d.step();
        // A device read over the same link after the removal: whatever the removal asked of
        // the server was done before it answers.
        let outcome =
            d.e.read(wall_now(), fast, ReadFrom::Device, &fast_items)
                .unwrap();
        let r = d
            .sync("device read", outcome, |r| match r {
                SyncResult::Read(r) => r,
                other => panic!("{other:?}"),
            })
            .await;
        assert_eq!(r[0].as_ref().unwrap().value, Value::R4(950.0));
        for v in ["KW_L001", "KW_L002", "KW_K002"] {
            assert_eq!(sim.subscriptions("DIAGNOSTYKA", v), 1, "{v}");
        }
        assert_eq!(sim.subscriptions("PIEC", "KW_A100"), 1);

        // The last one goes: KW_L001 and KW_K002 are let go; KW_L002 stays, an item itself.
        d.e.remove_items(wall_now(), slow, &slow_items[1..])
            .unwrap();
        d.until(
            Duration::from_secs(10),
            "the limit variable unsubscribed",
            |_| {
                (sim.subscriptions("DIAGNOSTYKA", "KW_L001") == 0
                    && sim.subscriptions("DIAGNOSTYKA", "KW_K002") == 0
                    && sim.subscriptions("PIEC", "KW_A100") == 0)
                    .then_some(())
            },
        )
        .await;
        assert_eq!(sim.subscriptions("DIAGNOSTYKA", "KW_L002"), 1);
        d.e.remove_items(wall_now(), fast, &fast_items).unwrap();
        d.until(Duration::from_secs(10), "KW_L002 unsubscribed", |_| {
            (sim.subscriptions("DIAGNOSTYKA", "KW_L002") == 0).then_some(())
        })
        .await;
    })
    .await
    .expect("test exceeded its time limit");
}

/// A limit variable without a value (here unknown to the server, so reported BAD Config
/// Error) is an unknown limit, as the core's rules define it: skipped. KW_A100 = 1000 is
/// then checked against its numeric limits only (WarnLow 900, AlarmLow 850): not limited,
/// although its AlarmHigh names KW_L002.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_limit_variable_without_a_value_is_an_unknown_limit() {
    tokio::time::timeout(TEST_LIMIT, async {
        let (_sim, mut d) = limits_setup(false).await;
        let (group, items) = add_group_items(&mut d, 1000, &["KW_A100"]);
        let s = d
            .until(Duration::from_secs(10), "KW_A100 good", |e| {
                cached(e, group, items[0]).filter(|s| s.quality.is_good())
            })
            .await;
        assert_eq!(s.value, Value::R4(1000.0));
        assert_eq!(s.quality, Quality::GOOD);
    })
    .await
    .expect("test exceeded its time limit");
}
