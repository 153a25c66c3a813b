//! The byte-exact examples of `docs/asix-net-protocol.md`, section 11, read from the
//! document itself: if the encoding changes, this test fails until the document shows the
//! new bytes (and the protocol version goes up).

use asix_net::proto::discovery::{
    decode_datagram, encode_datagram, Announce, Datagram, FindServer, Resource,
};
use asix_net::proto::frame::{
    decode_frame, frame_bytes, Hello, Message, ServerFlags, SubscribeItem, VarRef,
};
use asix_net::proto::link::{decode_preamble, encode_preamble, LinkMode, LinkStatus};
use asix_net::secure::{version1_error_frame, VERSION1_REFUSAL};
use asix_net::tls::parse_fingerprint;
use asix_net::Vqt;
use ctopc_core::{OpcError, Quality, Timestamp, Value};

/// The byte blocks of section 11: per fenced block, the leading two-digit hex tokens of
/// each line.
fn document_blocks() -> Vec<Vec<u8>> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/asix-net-protocol.md"
    );
    let doc = std::fs::read_to_string(path).expect("the protocol document");
    let start = doc.find("## 11. Examples").expect("section 11");
    let end = doc[start..].find("## 12.").map_or(doc.len(), |e| start + e);
    let mut blocks = Vec::new();
    let mut current: Option<Vec<u8>> = None;
    for line in doc[start..end].lines() {
        if line.trim_start().starts_with("```") {
            match current.take() {
                Some(b) => blocks.push(b),
                None => current = Some(Vec::new()),
            }
            continue;
        }
        if let Some(b) = current.as_mut() {
            for tok in line.split_whitespace() {
                let hex = tok.len() == 2 && tok.bytes().all(|c| c.is_ascii_hexdigit());
                if !hex {
                    break;
                }
                b.push(u8::from_str_radix(tok, 16).expect("hex"));
            }
        }
    }
    blocks
}

fn announce(fingerprint: Option<[u8; 32]>) -> Vec<u8> {
    encode_datagram(&Datagram::Announce(Announce {
        request: 1,
        server_name: "S1".into(),
        server_host: "H".into(),
        flags: ServerFlags(ServerFlags::LOCAL),
        clients: 2,
        tcp_port: 48101,
        fingerprint,
        resources: vec![Resource::channel("K1")],
    }))
    .unwrap()
}

#[test]
fn the_documents_examples_are_what_the_encoders_make() {
    let fp = parse_fingerprint("9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08")
        .unwrap();
    let v1_error = version1_error_frame(OpcError::NetLinkToServerNegativeAnswer, VERSION1_REFUSAL);
    // (name, encoding, the document shows only its start)
    let want: Vec<(&str, Vec<u8>, bool)> = vec![
        (
            "FindServer",
            encode_datagram(&Datagram::FindServer(FindServer {
                request: 1,
                resource: Resource::channel("K1"),
                client_name: "CLI.".into(),
                client_host: "CLI".into(),
            }))
            .unwrap(),
            false,
        ),
        ("Announce, plaintext server", announce(None), false),
        ("Announce, TLS server", announce(Some(fp)), false),
        (
            "preamble, TLS",
            encode_preamble(LinkMode::Tls, LinkStatus::Accepted).to_vec(),
            false,
        ),
        (
            "preamble, plaintext refused",
            encode_preamble(LinkMode::Plaintext, LinkStatus::PlaintextRefused).to_vec(),
            false,
        ),
        (
            "Hello",
            frame_bytes(
                1,
                &Message::Hello(Hello {
                    client_name: "CLI.".into(),
                    client_host: "CLI".into(),
                    keepalive_ms: 1000,
                    net_timeout_ms: 3000,
                }),
            )
            .unwrap(),
            false,
        ),
        (
            "Subscribe",
            frame_bytes(
                2,
                &Message::Subscribe {
                    sampling_ms: 1000,
                    changes_only: false,
                    items: vec![SubscribeItem {
                        handle: 7,
                        var: VarRef::new("K1", "V"),
                    }],
                },
            )
            .unwrap(),
            false,
        ),
        (
            "Update",
            frame_bytes(
                0,
                &Message::Update {
                    items: vec![(
                        7,
                        Vqt::new(
                            Value::R4(1.5),
                            Quality::GOOD,
                            Timestamp(0x01DA_0000_0000_0000),
                        ),
                    )],
                },
            )
            .unwrap(),
            false,
        ),
        (
            "WriteResult",
            frame_bytes(
                3,
                &Message::WriteResult {
                    results: vec![0, OpcError::WriteErrorIllegalCommand.hresult()],
                },
            )
            .unwrap(),
            false,
        ),
        ("version-1 Error frame", v1_error.clone(), true),
    ];
    let blocks = document_blocks();
    assert_eq!(
        blocks.len(),
        want.len(),
        "section 11 has {} byte blocks",
        blocks.len()
    );
    for ((name, bytes, prefix), doc) in want.iter().zip(&blocks) {
        let shown = if *prefix {
            &bytes[..doc.len().min(bytes.len())]
        } else {
            &bytes[..]
        };
        assert_eq!(
            shown,
            &doc[..],
            "{name}: the encoding differs from docs/asix-net-protocol.md"
        );
    }
    // And the decoders read the document's bytes back.
    for b in &blocks[..3] {
        let d = decode_datagram(b).expect("a datagram");
        assert_eq!(&encode_datagram(&d).unwrap(), b);
    }
    let Datagram::Announce(a) = decode_datagram(&blocks[2]).unwrap() else {
        panic!("an Announce")
    };
    assert_eq!(a.fingerprint, Some(fp));
    for b in &blocks[3..5] {
        let p = decode_preamble(&<[u8; 8]>::try_from(&b[..]).unwrap()).unwrap();
        assert_eq!(
            encode_preamble(
                if p.mode == 1 {
                    LinkMode::Tls
                } else {
                    LinkMode::Plaintext
                },
                LinkStatus::from_code(p.status).unwrap()
            ),
            b[..]
        );
    }
    for b in &blocks[5..9] {
        let (_, n) = decode_frame(b).unwrap().expect("a whole frame");
        assert_eq!(n, b.len());
    }
    // The version-1 Error frame: byte 4 is 1, the rest is version 2's Error.
    assert_eq!(v1_error[4], 1);
    let mut as_v2 = v1_error;
    as_v2[4] = asix_net::proto::PROTOCOL_VERSION;
    let (f, _) = decode_frame(&as_v2).unwrap().unwrap();
    assert!(
        matches!(f.msg, Message::Error { code, ref message } if code == OpcError::NetLinkToServerNegativeAnswer.hresult() && message == VERSION1_REFUSAL)
    );
}
