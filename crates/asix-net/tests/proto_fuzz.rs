//! The codec never panics on any input, and what it encodes it decodes back.

use asix_net::proto::discovery::{
    decode_datagram, encode_datagram, Announce, Datagram, FindServer, Resource, ResourceKind,
};
use asix_net::proto::frame::{
    decode_body, decode_frame, encode_frame, Frame, Hello, HelloAck, Message, ReadSource,
    ServerFlags, SubscribeItem, VarRef,
};
use asix_net::proto::MAX_FRAME;
use asix_net::Vqt;
use ctopc_core::value::ArrayValue;
use ctopc_core::{Quality, Timestamp, Value, VarType};
use proptest::prelude::*;

fn finite32() -> impl Strategy<Value = f32> {
    prop::num::f32::NORMAL | prop::num::f32::ZERO | prop::num::f32::SUBNORMAL
}
fn finite64() -> impl Strategy<Value = f64> {
    prop::num::f64::NORMAL | prop::num::f64::ZERO | prop::num::f64::SUBNORMAL
}

fn scalar() -> impl Strategy<Value = Value> {
    prop_oneof![
        Just(Value::Empty),
        any::<i8>().prop_map(Value::I1),
        any::<u8>().prop_map(Value::UI1),
        any::<i16>().prop_map(Value::I2),
        any::<u16>().prop_map(Value::UI2),
        any::<i32>().prop_map(Value::I4),
        any::<u32>().prop_map(Value::UI4),
        any::<i64>().prop_map(Value::I8),
        any::<u64>().prop_map(Value::UI8),
        finite32().prop_map(Value::R4),
        finite64().prop_map(Value::R8),
        any::<i64>().prop_map(Value::Cy),
        finite64().prop_map(Value::Date),
        ".{0,20}".prop_map(Value::Bstr),
        any::<bool>().prop_map(Value::Bool),
        any::<i32>().prop_map(Value::Error),
    ]
}

fn value() -> impl Strategy<Value = Value> {
    prop_oneof![
        4 => scalar(),
        1 => prop::collection::vec(finite64().prop_map(Value::R8), 0..6)
            .prop_map(|e| Value::Array(ArrayValue { element_type: VarType::R8, elements: e })),
        1 => prop::collection::vec(scalar(), 0..6)
            .prop_map(|e| Value::Array(ArrayValue { element_type: VarType::VARIANT, elements: e })),
    ]
}

fn vqt() -> impl Strategy<Value = Vqt> {
    (value(), any::<u16>(), any::<i64>())
        .prop_map(|(v, q, t)| Vqt::new(v, Quality(q), Timestamp(t)))
}

fn var() -> impl Strategy<Value = VarRef> {
    ("[A-Za-z_]{0,12}", "[A-Za-z0-9_.]{0,16}").prop_map(|(c, v)| VarRef::new(c, v))
}

fn failure() -> impl Strategy<Value = i32> {
    i32::MIN..0
}

fn message() -> impl Strategy<Value = Message> {
    prop_oneof![
        (".{0,10}", ".{0,10}", any::<u32>(), any::<u32>()).prop_map(|(n, h, k, t)| Message::Hello(
            Hello {
                client_name: n,
                client_host: h,
                keepalive_ms: k,
                net_timeout_ms: t
            }
        )),
        (
            any::<i32>(),
            ".{0,10}",
            any::<u8>(),
            any::<u32>(),
            any::<u32>()
        )
            .prop_map(|(s, n, f, c, i)| {
                Message::HelloAck(HelloAck {
                    status: s,
                    server_name: n,
                    flags: ServerFlags(f),
                    clients: c,
                    idle_timeout_ms: i,
                })
            }),
        any::<i32>().prop_map(|reason| Message::Bye { reason }),
        any::<u64>().prop_map(|nonce| Message::Ping { nonce }),
        any::<u64>().prop_map(|nonce| Message::Pong { nonce }),
        (any::<i32>(), ".{0,30}").prop_map(|(code, message)| Message::Error { code, message }),
        (any::<u8>(), any::<u32>()).prop_map(|(f, clients)| Message::ServerStatus {
            flags: ServerFlags(f),
            clients
        }),
        (
            any::<u32>(),
            any::<bool>(),
            prop::collection::vec((any::<u32>(), var()), 0..5)
        )
            .prop_map(|(s, c, v)| {
                Message::Subscribe {
                    sampling_ms: s,
                    changes_only: c,
                    items: v
                        .into_iter()
                        .map(|(handle, var)| SubscribeItem { handle, var })
                        .collect(),
                }
            }),
        prop::collection::vec((any::<u32>(), any::<i32>()), 0..5)
            .prop_map(|results| Message::SubscribeAck { results }),
        prop::collection::vec(any::<u32>(), 0..5)
            .prop_map(|handles| Message::Unsubscribe { handles }),
        prop::collection::vec((any::<u32>(), any::<i32>()), 0..5)
            .prop_map(|results| Message::UnsubscribeAck { results }),
        prop::collection::vec((any::<u32>(), vqt()), 0..5)
            .prop_map(|items| Message::Update { items }),
        (0u8..3, prop::collection::vec(var(), 0..5)).prop_map(|(s, items)| Message::Read {
            source: ReadSource::from_u8(s).unwrap(),
            items
        }),
        prop::collection::vec(
            prop_oneof![vqt().prop_map(Ok), failure().prop_map(Err)],
            0..5
        )
        .prop_map(|results| Message::ReadResult { results }),
        prop::collection::vec((var(), value()), 0..5).prop_map(|items| Message::Write { items }),
        prop::collection::vec((var(), vqt()), 0..5).prop_map(|items| Message::WriteVqt { items }),
        prop::collection::vec(any::<i32>(), 0..5)
            .prop_map(|results| Message::WriteResult { results }),
    ]
}

fn resource() -> impl Strategy<Value = Resource> {
    (1u8..4, ".{0,12}").prop_map(|(k, name)| Resource {
        kind: ResourceKind::from_u8(k).unwrap(),
        name,
    })
}

fn datagram() -> impl Strategy<Value = Datagram> {
    prop_oneof![
        (any::<u32>(), resource(), ".{0,10}", ".{0,10}").prop_map(|(request, resource, n, h)| {
            Datagram::FindServer(FindServer {
                request,
                resource,
                client_name: n,
                client_host: h,
            })
        }),
        (
            any::<u32>(),
            ".{0,10}",
            ".{0,10}",
            0u8..8,
            any::<u32>(),
            any::<u16>(),
            prop::option::of(any::<[u8; 32]>()),
            prop::collection::vec(resource(), 0..6)
        )
            .prop_map(
                |(request, n, h, f, clients, port, fingerprint, resources)| {
                    Datagram::Announce(Announce {
                        request,
                        server_name: n,
                        server_host: h,
                        flags: ServerFlags(f),
                        clients,
                        tcp_port: port,
                        fingerprint,
                        resources,
                    })
                }
            ),
    ]
}

/// A mutation of a valid encoding.
#[derive(Debug, Clone)]
enum Mutation {
    Flip(usize, u8),
    Truncate(usize),
    Insert(usize, Vec<u8>),
    Remove(usize, usize),
    SetU32(usize, u32),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 1u8..=255).prop_map(|(i, b)| Mutation::Flip(i, b)),
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(i, v)| Mutation::Insert(i, v)),
        (any::<usize>(), 1usize..8).prop_map(|(i, n)| Mutation::Remove(i, n)),
        (any::<usize>(), any::<u32>()).prop_map(|(i, v)| Mutation::SetU32(i, v)),
    ]
}

fn mutate(mut b: Vec<u8>, muts: &[Mutation]) -> Vec<u8> {
    for m in muts {
        let n = b.len().max(1);
        match m {
            Mutation::Flip(i, x) => {
                if !b.is_empty() {
                    let i = i % n;
                    b[i] ^= x;
                }
            }
            Mutation::Truncate(i) => b.truncate(i % n),
            Mutation::Insert(i, v) => {
                let i = i % (b.len() + 1);
                b.splice(i..i, v.iter().copied());
            }
            Mutation::Remove(i, k) => {
                if !b.is_empty() {
                    let i = i % n;
                    let e = (i + k).min(b.len());
                    b.drain(i..e);
                }
            }
            Mutation::SetU32(i, v) => {
                if b.len() >= 4 {
                    let i = i % (b.len() - 3);
                    b[i..i + 4].copy_from_slice(&v.to_le_bytes());
                }
            }
        }
    }
    b
}

/// Decodes everything decodable from the start of `buf`, as a reader would.
fn decode_all(buf: &[u8]) -> Vec<Frame> {
    let mut out = Vec::new();
    let mut pos = 0;
    // Bounded: every successful decode consumes at least 12 bytes.
    while let Ok(Some((f, n))) = decode_frame(&buf[pos..]) {
        out.push(f);
        pos += n;
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let _ = decode_frame(&bytes);
        let _ = decode_body(&bytes);
        let _ = decode_datagram(&bytes);
        let _ = decode_all(&bytes);
    }

    #[test]
    fn random_bodies_behind_a_valid_header_never_panic(ty in any::<u8>(), payload in prop::collection::vec(any::<u8>(), 0..256)) {
        // Version 1, any type, flags 0, request 1, random payload: exercises every decoder.
        let mut body = vec![1u8, ty, 0, 0, 1, 0, 0, 0];
        body.extend_from_slice(&payload);
        let _ = decode_body(&body);
        let mut frame = ((body.len()) as u32).to_le_bytes().to_vec();
        frame.extend_from_slice(&body);
        let _ = decode_frame(&frame);
    }

    #[test]
    fn frames_round_trip(request in any::<u32>(), msg in message()) {
        let mut buf = Vec::new();
        encode_frame(&mut buf, request, &msg).unwrap();
        prop_assert!(buf.len() <= MAX_FRAME);
        let (f, n) = decode_frame(&buf).unwrap().unwrap();
        prop_assert_eq!(n, buf.len());
        prop_assert_eq!(f, Frame { request, msg });
        // Any proper prefix asks for more bytes or is refused, never panics or succeeds.
        for cut in [0, 1, 3, 4, 11, buf.len() / 2, buf.len() - 1] {
            if cut < buf.len() {
                prop_assert!(!matches!(decode_frame(&buf[..cut]), Ok(Some(_))));
            }
        }
    }

    #[test]
    fn streams_of_frames_split_anywhere_decode_the_same(msgs in prop::collection::vec(message(), 1..6), split in any::<usize>()) {
        let mut buf = Vec::new();
        for (i, m) in msgs.iter().enumerate() {
            encode_frame(&mut buf, i as u32, m).unwrap();
        }
        let split = split % (buf.len() + 1);
        // Feed in two pieces as a socket would.
        let mut acc = buf[..split].to_vec();
        let mut got = Vec::new();
        let mut pos = 0;
        for piece in [&buf[split..]] {
            while let Some((f, n)) = decode_frame(&acc[pos..]).unwrap() {
                got.push(f);
                pos += n;
            }
            acc.extend_from_slice(piece);
        }
        got.extend(decode_all(&acc[pos..]));
        prop_assert_eq!(got.len(), msgs.len());
        for (i, (f, m)) in got.iter().zip(&msgs).enumerate() {
            prop_assert_eq!(f.request, i as u32);
            prop_assert_eq!(&f.msg, m);
        }
    }

    #[test]
    fn mutated_frames_never_panic_and_what_decodes_re_encodes(msg in message(), muts in prop::collection::vec(mutation(), 1..4)) {
        let mut buf = Vec::new();
        encode_frame(&mut buf, 7, &msg).unwrap();
        let bad = mutate(buf, &muts);
        let _ = decode_body(bad.get(4..).unwrap_or(&[]));
        if let Ok(Some((f, _))) = decode_frame(&bad) {
            // Whatever was accepted is a well-formed message: it survives a round trip
            // (NaN payloads excepted, which compare unequal).
            let mut again = Vec::new();
            encode_frame(&mut again, f.request, &f.msg).unwrap();
            let (g, _) = decode_frame(&again).unwrap().unwrap();
            prop_assert_eq!(format!("{:?}", g), format!("{:?}", f));
        }
    }

    #[test]
    fn datagrams_round_trip_and_mutations_never_panic(d in datagram(), muts in prop::collection::vec(mutation(), 1..4)) {
        let bytes = encode_datagram(&d).unwrap();
        prop_assert_eq!(decode_datagram(&bytes).unwrap(), d);
        let _ = decode_datagram(&mutate(bytes, &muts));
    }
}

#[test]
fn hostile_counts_do_not_allocate() {
    // An Update claiming 2^32-1 entries in a 16-byte frame is refused before allocating.
    let body = [1u8, 0x20, 0, 0, 0, 0, 0, 0, 0xFF, 0xFF, 0xFF, 0xFF];
    assert!(decode_body(&body).is_err());
    // A VARIANT array claiming 2^32-1 elements likewise.
    let mut body = vec![1u8, 0x40, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0];
    body.extend_from_slice(&(0x2000u16 | 12).to_le_bytes());
    body.extend_from_slice(&u32::MAX.to_le_bytes());
    assert!(decode_body(&body).is_err());
}
