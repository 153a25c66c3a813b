//! The byte-exact examples of `docs/asix-net-protocol.md`: if the encoding changes, this
//! test and the document must change together (and the protocol version go up).

use asix_net::proto::discovery::{encode_datagram, Announce, Datagram, FindServer, Resource};
use asix_net::proto::frame::{frame_bytes, Hello, Message, ServerFlags, SubscribeItem, VarRef};
use asix_net::Vqt;
use ctopc_core::{OpcError, Quality, Timestamp, Value};

fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn check(name: &str, got: Vec<u8>, want: &str) {
    let got = hex(&got);
    assert_eq!(
        got, want,
        "{name}: encoding changed; update docs/asix-net-protocol.md"
    );
}

#[test]
fn document_examples() {
    check(
        "FindServer",
        encode_datagram(&Datagram::FindServer(FindServer {
            request: 1,
            resource: Resource::channel("K1"),
            client_name: "CLI.".into(),
            client_host: "CLI".into(),
        }))
        .unwrap(),
        "41 53 58 44 02 01 00 00 01 00 00 00 01 02 00 4B 31 04 00 43 4C 49 2E 03 00 43 4C 49",
    );
    check(
        "Announce",
        encode_datagram(&Datagram::Announce(Announce {
            request: 1,
            server_name: "S1".into(),
            server_host: "H".into(),
            flags: ServerFlags(ServerFlags::LOCAL),
            clients: 2,
            tcp_port: 48101,
            fingerprint: None,
            resources: vec![Resource::channel("K1")],
        }))
        .unwrap(),
        "41 53 58 44 02 02 00 00 01 00 00 00 02 00 53 31 01 00 48 01 02 00 00 00 E5 BB 00 01 00 01 02 00 4B 31",
    );
    check(
        "Hello",
        frame_bytes(
            1,
            &Message::Hello(Hello { client_name: "CLI.".into(), client_host: "CLI".into(), keepalive_ms: 1000, net_timeout_ms: 3000 }),
        )
        .unwrap(),
        "1F 00 00 00 02 01 00 00 01 00 00 00 41 53 58 4E 04 00 43 4C 49 2E 03 00 43 4C 49 E8 03 00 00 B8 0B 00 00",
    );
    check(
        "Subscribe",
        frame_bytes(
            2,
            &Message::Subscribe {
                sampling_ms: 1000,
                changes_only: false,
                items: vec![SubscribeItem { handle: 7, var: VarRef::new("K1", "V") }],
            },
        )
        .unwrap(),
        "1C 00 00 00 02 10 00 00 02 00 00 00 E8 03 00 00 00 01 00 00 00 07 00 00 00 02 00 4B 31 01 00 56",
    );
    check(
        "Update",
        frame_bytes(
            0,
            &Message::Update { items: vec![(7, Vqt::new(Value::R4(1.5), Quality::GOOD, Timestamp(0x01DA_0000_0000_0000)))] },
        )
        .unwrap(),
        "20 00 00 00 02 20 00 00 00 00 00 00 01 00 00 00 07 00 00 00 C0 00 00 00 00 00 00 00 DA 01 04 00 00 00 C0 3F",
    );
    check(
        "WriteResult",
        frame_bytes(
            3,
            &Message::WriteResult {
                results: vec![0, OpcError::WriteErrorIllegalCommand.hresult()],
            },
        )
        .unwrap(),
        "14 00 00 00 02 42 00 00 03 00 00 00 02 00 00 00 00 00 00 00 2A 81 04 C0",
    );
}
