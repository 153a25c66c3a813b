//! The simulator as a protocol server: raw-socket rules, subscriptions, fault injection,
//! the demo database. Every test is bounded.

mod common;

use std::time::Duration;

use asix_model::ItemKey;
use asix_net::client::ClientEvent;
use asix_net::proto::frame::{
    body_len, decode_body, frame_bytes, Frame, Hello, Message, SubscribeItem, VarRef,
};
use asix_net::sim::plant::{channels_from_database, ACID_PLANT_CHANNEL};
use common::*;
use ctopc_core::{OpcError, Quality};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

macro_rules! bounded {
    ($body:expr) => {
        tokio::time::timeout(TEST_LIMIT, $body)
            .await
            .expect("test exceeded its time limit")
    };
}

const SHORT: Duration = Duration::from_secs(3);

/// Reads one frame, or None at end of stream.
async fn read_frame(s: &mut (impl AsyncRead + Unpin)) -> Option<Frame> {
    let mut len = [0u8; 4];
    tokio::time::timeout(SHORT, s.read_exact(&mut len))
        .await
        .expect("frame in time")
        .ok()?;
    let n = body_len(len).expect("valid length");
    let mut body = vec![0u8; n];
    s.read_exact(&mut body).await.ok()?;
    Some(decode_body(&body).expect("valid frame"))
}

async fn closed(s: &mut (impl AsyncRead + Unpin)) -> bool {
    let mut b = [0u8; 1];
    matches!(
        tokio::time::timeout(SHORT, s.read(&mut b)).await,
        Ok(Ok(0)) | Ok(Err(_))
    )
}

fn hello() -> Message {
    Message::Hello(Hello {
        client_name: "RAW.".into(),
        client_host: "RAW".into(),
        keepalive_ms: 1000,
        net_timeout_ms: 1000,
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_frame_of_another_version_is_refused_with_an_error_and_a_close() {
    bounded!(async {
        let a = sim("A").await;
        let mut s = raw_link(a.tcp_addr()).await;
        let mut f = frame_bytes(1, &hello()).unwrap();
        f[4] = 3; // version 3
        s.write_all(&f).await.unwrap();
        let Frame {
            msg: Message::Error { code, message },
            ..
        } = read_frame(&mut s).await.unwrap()
        else {
            panic!("an Error frame")
        };
        assert_eq!(code, OpcError::NetLinkToServerNegativeAnswer.hresult());
        assert!(message.contains("version"), "{message}");
        assert!(closed(&mut s).await);
    })
}

/// A version-1 client (a plaintext Hello as its first bytes) reads a version-1 Error frame
/// saying why, and the link closes: no hang, no TLS garbage.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_version_1_client_reads_why_it_is_refused() {
    bounded!(async {
        let a = sim("A").await;
        let mut s = TcpStream::connect(a.tcp_addr()).await.unwrap();
        let mut f = frame_bytes(1, &hello()).unwrap();
        f[4] = 1; // what a version-1 client sends
        s.write_all(&f).await.unwrap();
        let mut len = [0u8; 4];
        tokio::time::timeout(SHORT, s.read_exact(&mut len))
            .await
            .expect("an answer in time")
            .unwrap();
        let mut body = vec![0u8; body_len(len).unwrap()];
        s.read_exact(&mut body).await.unwrap();
        assert_eq!(body[0], 1, "a version-1 frame");
        body[0] = asix_net::proto::PROTOCOL_VERSION; // the encoding is the same
        let Frame {
            msg: Message::Error { code, message },
            ..
        } = decode_body(&body).unwrap()
        else {
            panic!("an Error frame")
        };
        assert_eq!(code, OpcError::NetLinkToServerNegativeAnswer.hresult());
        assert!(message.contains("version 2"), "{message}");
        assert!(closed(&mut s).await);
        // The server's task lets its handshake slot go after the close the client saw.
        let t0 = std::time::Instant::now();
        while a.handshakes() != 0 {
            assert!(
                t0.elapsed() < SHORT,
                "the refused link keeps a handshake slot"
            );
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn anything_before_hello_is_refused_and_a_bad_length_closes_the_link() {
    bounded!(async {
        let a = sim("A").await;
        let mut s = raw_link(a.tcp_addr()).await;
        s.write_all(&frame_bytes(5, &Message::Ping { nonce: 1 }).unwrap())
            .await
            .unwrap();
        let f = read_frame(&mut s).await.unwrap();
        assert_eq!(f.request, 5);
        assert!(
            matches!(f.msg, Message::Error { code, .. } if code == OpcError::NetLinkToServerNegativeAnswer.hresult())
        );
        assert!(closed(&mut s).await);

        let mut s = raw_link(a.tcp_addr()).await;
        s.write_all(&u32::MAX.to_le_bytes()).await.unwrap();
        assert!(matches!(
            read_frame(&mut s).await.map(|f| f.msg),
            Some(Message::Error { .. })
        ));
        assert!(closed(&mut s).await);
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn subscribe_acks_then_sends_initial_values_then_every_sample_until_unsubscribed() {
    bounded!(async {
        let a = sim("A").await;
        let mut s = raw_link(a.tcp_addr()).await;
        s.write_all(&frame_bytes(1, &hello()).unwrap())
            .await
            .unwrap();
        let f = read_frame(&mut s).await.unwrap();
        assert!(
            matches!(f.msg, Message::HelloAck(ref h) if h.status == 0 && h.server_name == "A" && h.clients == 1),
            "{f:?}"
        );
        let items = vec![
            SubscribeItem {
                handle: 10,
                var: VarRef::new(CH, "PIEC_TEMP_ZADANA"),
            }, // constant
            SubscribeItem {
                handle: 11,
                var: VarRef::new(CH, "NOPE"),
            },
        ];
        s.write_all(
            &frame_bytes(
                2,
                &Message::Subscribe {
                    sampling_ms: 50,
                    changes_only: false,
                    items,
                },
            )
            .unwrap(),
        )
        .await
        .unwrap();
        let f = read_frame(&mut s).await.unwrap();
        assert_eq!(f.request, 2);
        assert_eq!(
            f.msg,
            Message::SubscribeAck {
                results: vec![(10, 0), (11, OpcError::ItemUnknown.hresult())]
            }
        );
        // Initial value, then a sample every period although the set point never changes.
        for _ in 0..3 {
            let f = read_frame(&mut s).await.unwrap();
            let Message::Update { items } = f.msg else {
                panic!("{f:?}")
            };
            assert_eq!(items.len(), 1);
            assert_eq!(items[0].0, 10);
            assert!(items[0].1.quality.is_good());
        }
        s.write_all(
            &frame_bytes(
                3,
                &Message::Unsubscribe {
                    handles: vec![10, 99],
                },
            )
            .unwrap(),
        )
        .await
        .unwrap();
        // Updates already queued may precede the ack; none may follow it.
        let ack = loop {
            let f = read_frame(&mut s).await.unwrap();
            if let Message::UnsubscribeAck { results } = f.msg {
                break results;
            }
        };
        assert_eq!(ack, vec![(10, 0), (99, OpcError::ItemUnknown.hresult())]);
        s.write_all(&frame_bytes(4, &Message::Ping { nonce: 42 }).unwrap())
            .await
            .unwrap();
        let f = read_frame(&mut s).await.unwrap();
        assert_eq!(
            f,
            Frame {
                request: 4,
                msg: Message::Pong { nonce: 42 }
            }
        );
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn changes_only_subscriptions_get_the_initial_value_and_then_only_changes() {
    bounded!(async {
        let a = sim("A").await;
        let mut s = raw_link(a.tcp_addr()).await;
        s.write_all(&frame_bytes(1, &hello()).unwrap())
            .await
            .unwrap();
        read_frame(&mut s).await.unwrap();
        let items = vec![SubscribeItem {
            handle: 1,
            var: VarRef::new(CH, "PIEC_TEMP_ZADANA"),
        }];
        s.write_all(
            &frame_bytes(
                2,
                &Message::Subscribe {
                    sampling_ms: 20,
                    changes_only: true,
                    items,
                },
            )
            .unwrap(),
        )
        .await
        .unwrap();
        read_frame(&mut s).await.unwrap(); // ack
        assert!(matches!(
            read_frame(&mut s).await.unwrap().msg,
            Message::Update { .. }
        ));
        // Nothing more while the set point stays put: the next frame is the Pong.
        tokio::time::sleep(Duration::from_millis(200)).await;
        s.write_all(&frame_bytes(3, &Message::Ping { nonce: 1 }).unwrap())
            .await
            .unwrap();
        assert_eq!(
            read_frame(&mut s).await.unwrap().msg,
            Message::Pong { nonce: 1 }
        );
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_failed_data_source_reports_bad_device_failure_and_status_then_recovers() {
    bounded!(async {
        let a = sim("A").await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let k = key("ZB1_POZIOM");
        c.subscribe(vec![k.clone()], 50);
        ev.vqt_of(&k, SHORT, "good", |q| q.is_good()).await;
        a.set_source_failed(true);
        let st = ev
            .wait(SHORT, "ServerStatus", |e| match e {
                ClientEvent::ServerStatus { flags, .. } => Some(*flags),
                _ => None,
            })
            .await;
        assert!(st.source_failed());
        let bad = ev
            .vqt_of(&k, SHORT, "device failure", |q| {
                q == Quality::BAD_DEVICE_FAILURE
            })
            .await;
        // Frozen while failed.
        let again = ev
            .vqt_of(&k, SHORT, "device failure", |q| {
                q == Quality::BAD_DEVICE_FAILURE
            })
            .await;
        assert_eq!(bad.value, again.value);
        a.set_source_failed(false);
        ev.vqt_of(&k, SHORT, "good again", |q| q.is_good()).await;
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_demo_database_is_served_by_channel() {
    bounded!(async {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../demo/wytwornia_kwasu/wytwornia_kwasu.zez");
        let (db, _) = asix_model::load_database_file(&path, None).expect("demo database");
        let a = sim_with("A", |c| {
            c.channels = channels_from_database(&db, ACID_PLANT_CHANNEL)
        })
        .await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let k1 = ItemKey::new("SIARKA", "KW_A000");
        let k2 = ItemKey::new("", "KW_A100"); // by name, any channel
        c.subscribe(vec![k1.clone(), k2.clone()], 100);
        ev.vqt_of(&k1, SHORT, "SIARKA/KW_A000", |q| q.is_good())
            .await;
        ev.vqt_of(&k2, SHORT, "KW_A100", |q| q.is_good()).await;
    })
}
