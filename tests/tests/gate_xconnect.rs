//! asix-gate over the real Automation adapter (`asix_gate::xconnect`) against the test
//! double of AsixConnect's `XConnect.ServerCT` (`tests/xconnect-double`): the gate's
//! engine runs in process, each channel's worker thread a single-threaded apartment with
//! its own object, and the tests drive it through the engine's public API (what the
//! network side calls).
//!
//! The double is a 32-bit in-process server, so this file runs only as a 32-bit client
//! (`cargo xtask e2e --x86 -p e2e-tests --test gate_xconnect`; xtask builds and registers
//! the double).

#![cfg(all(windows, target_pointer_width = "32"))]

use std::sync::Arc;
use std::time::{Duration, Instant};

use asix_gate::config::{ChannelConfig, Open};
use asix_gate::tz::ZoneRule;
use asix_gate::{DataSource, Engine, GateConfig};
use ctopc_core::{OpcError, Quality, Timestamp, Value};

const WRITE_ERROR: i32 = 0xC004_8128_u32 as i32;

fn channel(name: &str, open: Open) -> ChannelConfig {
    ChannelConfig {
        name: name.to_owned(),
        open,
        device_read: DataSource::Device,
        allow_plaintext: false,
    }
}

/// An engine serving `channels` through the Automation adapter. The double stamps the
/// process's local time (`GetLocalTime`); the gate is told that zone is UTC, which the
/// test prefix's is (the machine runs in UTC), so its timestamps compare with the clock.
fn engine(channels: Vec<ChannelConfig>) -> Arc<Engine> {
    let mut cfg = GateConfig::new("GATE-XCONNECT");
    cfg.time_zone = ZoneRule::UTC;
    cfg.state_poll = Duration::from_millis(50);
    cfg.call_timeout = Duration::from_secs(10);
    cfg.channels = channels;
    Engine::start(&cfg, asix_gate::xconnect::factory())
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

/// Waits (polling the condition, async) until `done` holds; false after `limit`.
async fn wait_until(limit: Duration, mut done: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + limit;
    while !done() {
        if Instant::now() >= deadline {
            return false;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    true
}

fn now() -> Timestamp {
    asix_net::client::wall_now()
}

#[test]
fn device_read_subscription_and_write_through_the_adapter() {
    runtime().block_on(async {
        let before = now();
        let engine = engine(vec![
            channel("K1", Open::Init("Vars=A,B;PeriodMs=20".into())),
            channel("K2", Open::Init("Vars=C;PeriodMs=60000".into())),
        ]);
        let ch = engine.channel("K1").unwrap().clone();
        let ch2 = engine.channel("K2").unwrap().clone();
        assert!(
            wait_until(Duration::from_secs(20), || ch.serves() && ch2.serves()).await,
            "the channel serves (object made, Init, Active, ServerState 1)"
        );
        assert!(!engine.source_failed());

        // A device read: the double's value, GOOD, stamped in UTC. K1 ticks every 20 ms
        // from `Active` on (each tick adds 1 to A, from 10, and stamps it), however long
        // the channels took to open: the value is 10 or more, whole, and its time lies
        // between the engine's start and the answer.
        let r = engine.read(&ch, DataSource::Device, vec!["A".into()]).await;
        let vqt = r[0].clone().expect("Read A");
        assert!(
            matches!(vqt.value, Value::R8(x) if x >= 10.0 && x.fract() == 0.0),
            "{vqt:?}"
        );
        assert_eq!(vqt.quality, Quality::GOOD, "{vqt:?}");
        let after = now();
        let slack = 2 * 1000 * Timestamp::TICKS_PER_MS;
        assert!(
            vqt.timestamp.0 >= before.0 - slack && vqt.timestamp.0 <= after.0 + slack,
            "the local VT_DATE converted to UTC: {:?} not within [{before:?}, {after:?}]",
            vqt.timestamp
        );

        // A write reaches the double: read back (on a channel ticking once a minute: each tick
        // adds 1 to every variable; the writes come right after it opened, well before its
        // first tick).
        let w = engine
            .write(&ch2, vec![("C".into(), Value::I4(42), None)])
            .await;
        assert_eq!(w, vec![Ok(())]);
        let r = engine
            .read(&ch2, DataSource::Driver, vec!["C".into()])
            .await;
        assert_eq!(r[0].clone().unwrap().value, Value::R8(42.0));

        // WriteEx with quality and a UTC time: the double holds both.
        let stamp = Timestamp::from_unix_millis(1_678_881_600_000); // 2023-03-15 12:00Z
        let w = engine
            .write(
                &ch2,
                vec![("C".into(), Value::R8(1.5), Some((Quality(0x40), stamp)))],
            )
            .await;
        assert_eq!(w, vec![Ok(())]);
        let r = engine
            .read(&ch2, DataSource::Device, vec!["C".into()])
            .await;
        let vqt = r[0].clone().unwrap();
        assert_eq!(
            (vqt.value, vqt.quality, vqt.timestamp),
            (Value::R8(1.5), Quality(0x40), stamp)
        );

        // A subscription: DataChange events (each tick adds 1) reach the image.
        engine.subscribe(&ch, "B");
        let mut seen = Vec::new();
        let got = wait_until(Duration::from_secs(20), || {
            if let Some((vqt, version)) = ch.entry("B") {
                if seen.last().map(|(_, v)| *v) != Some(version) {
                    seen.push((vqt, version));
                }
            }
            seen.iter()
                .filter(|(v, _)| matches!(v.value, Value::R8(x) if x > 20.0))
                .count()
                >= 3
        })
        .await;
        assert!(got, "three DataChange updates of B within 20 s: {seen:?}");
        let changes: Vec<f64> = seen
            .iter()
            .filter_map(|(v, _)| match v.value {
                Value::R8(x) if x > 20.0 => Some(x),
                _ => None,
            })
            .collect();
        assert!(
            changes.windows(2).all(|w| w[1] > w[0]),
            "values grow: {changes:?}"
        );
        for (v, _) in seen.iter().filter(|(v, _)| v.value != Value::Empty) {
            assert_eq!(v.quality, Quality::GOOD, "{v:?}");
        }
        engine.unsubscribe(&ch, "B");
        engine.stop();
    });
}

#[test]
fn failing_calls_arrive_as_errors() {
    runtime().block_on(async {
        let engine = engine(vec![channel("K1", Open::Init("Vars=A;Fail=Write".into()))]);
        let ch = engine.channel("K1").unwrap().clone();
        assert!(wait_until(Duration::from_secs(20), || ch.serves()).await);
        // ASKOM_E_ItemUnknown crosses unchanged.
        let r = engine
            .read(
                &ch,
                DataSource::Device,
                vec!["NoSuchVariable".into(), "A".into()],
            )
            .await;
        assert_eq!(r[0], Err(OpcError::ItemUnknown), "{r:?}");
        assert_eq!(r[1].clone().unwrap().quality, Quality::GOOD, "{r:?}");
        // The server's EXCEPINFO code of a failed Write.
        let w = engine
            .write(&ch, vec![("A".into(), Value::I4(1), None)])
            .await;
        assert_eq!(w, vec![Err(WRITE_ERROR)]);
        engine.stop();
    });
}

#[test]
fn server_state_failed_is_announced_as_source_failed() {
    runtime().block_on(async {
        let engine = engine(vec![channel("K1", Open::Init("Vars=A;State=2".into()))]);
        let mut status = engine.status.subscribe();
        let ch = engine.channel("K1").unwrap().clone();
        // The object is open (reads are answered GOOD) and its state has been read: the
        // status changed (a state was set), yet the channel does not serve.
        let mut good = false;
        let deadline = Instant::now() + Duration::from_secs(20);
        while !good && Instant::now() < deadline {
            let r = engine.read(&ch, DataSource::Device, vec!["A".into()]).await;
            good = matches!(&r[0], Ok(v) if v.quality == Quality::GOOD);
            if !good {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        }
        assert!(good, "the channel's object answers reads");
        let changed =
            tokio::time::timeout(Duration::from_secs(20), status.wait_for(|s| *s > 0)).await;
        assert!(matches!(changed, Ok(Ok(_))), "the source state was set");
        assert!(!ch.serves());
        assert!(engine.source_failed(), "ServerState 2: SOURCE_FAILED");
        engine.stop();
    });
}
