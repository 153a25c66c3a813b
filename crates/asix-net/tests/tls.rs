//! Protocol version 2's security, against hostile peers: forged announcements, wrong,
//! expired and missing certificates, plaintext where it is not allowed, a client cut in
//! the middle of its handshake, a flood of half-open connections, a server that never
//! answers. Every test is bounded and waits on conditions.

mod common;

use std::net::{Ipv4Addr, SocketAddr};
use std::time::{Duration, Instant};

use asix_net::client::ClientEvent;
use asix_net::proto::discovery::{decode_datagram, encode_datagram, Announce, Datagram};
use asix_net::proto::frame::ServerFlags;
use asix_net::proto::link::{encode_preamble, LinkMode, LinkStatus};
use asix_net::secure::{ClientSecurity, ServerSecurity, ServerTls};
use asix_net::tls::{self, Trust};
use common::*;
use ctopc_core::{OpcError, Quality};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpStream, UdpSocket};

macro_rules! bounded {
    ($body:expr) => {
        tokio::time::timeout(TEST_LIMIT, $body)
            .await
            .expect("test exceeded its time limit")
    };
}

const LIMIT: Duration = Duration::from_secs(10);

/// Waits (at most LIMIT) until `f` holds, looking every 10 ms.
async fn until(what: &str, mut f: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(t0.elapsed() < LIMIT, "timed out waiting until {what}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// The channel goes down with `error` (the link could not be made); no ChannelUp came.
async fn refused(ev: &mut Events, error: OpcError) {
    let e = ev
        .wait(LIMIT, "ChannelDown", |e| match e {
            ClientEvent::ChannelDown { error, .. } => Some(*error),
            ClientEvent::ChannelUp { server, .. } => panic!("linked to {server}"),
            _ => None,
        })
        .await;
    assert_eq!(e, error);
}

/// An announcer that answers every FindServer with `make(request)`: a forger.
async fn forger(make: impl Fn(u32) -> Announce + Send + 'static) -> SocketAddr {
    let sock = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).await.unwrap();
    let addr = sock.local_addr().unwrap();
    tokio::spawn(async move {
        let mut buf = vec![0u8; 9000];
        while let Ok((n, from)) = sock.recv_from(&mut buf).await {
            if let Ok(Datagram::FindServer(f)) = decode_datagram(&buf[..n]) {
                let bytes = encode_datagram(&Datagram::Announce(make(f.request))).unwrap();
                let _ = sock.send_to(&bytes, from).await;
            }
        }
    });
    addr
}

fn announce(
    request: u32,
    name: &str,
    fingerprint: Option<tls::Fingerprint>,
    port: u16,
) -> Announce {
    Announce {
        request,
        server_name: name.into(),
        server_host: "EVIL".into(),
        // LOCAL and no clients: the most attractive announcement there is.
        flags: ServerFlags(ServerFlags::LOCAL),
        clients: 0,
        tcp_port: port,
        fingerprint,
        resources: vec![asix_net::proto::discovery::Resource::channel(CH)],
    }
}

/// An impostor with the real server's name and a certificate of its own, announcing first:
/// the client ignores it and links to the real server.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_forged_announcement_with_another_certificate_cannot_redirect_the_client() {
    bounded!(async {
        let real = sim("A").await;
        // SimConfig's default: a certificate made for this run, not the pinned one.
        let impostor = sim_with("A", |c| c.security = asix_net::sim::ephemeral_security("A")).await;
        assert_ne!(impostor.fingerprint(), real.fingerprint());
        let mut cfg = client_cfg(&[impostor.discovery_addr(), real.discovery_addr()]);
        cfg.options.asix_server_name = "A".into();
        let (c, mut ev) = client(cfg);
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        ev.vqt_of(&key("ZB1_POZIOM"), LIMIT, "a value", Quality::is_good)
            .await;
        assert_eq!(real.client_count(), 1);
        assert_eq!(impostor.client_count(), 0);
    })
}

/// A forged announcement naming the pinned fingerprint but the impostor's address: the
/// TLS handshake shows the impostor's certificate, and the client does not link.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_forged_announcement_of_the_pinned_fingerprint_leads_to_no_link() {
    bounded!(async {
        let impostor = sim_with("A", |c| c.security = asix_net::sim::ephemeral_security("A")).await;
        let pinned = pki().server.identity.fingerprint();
        let port = impostor.tcp_addr().port();
        let udp = forger(move |r| announce(r, "A", Some(pinned), port)).await;
        let (c, mut ev) = client(client_cfg(&[udp]));
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        refused(&mut ev, OpcError::NetLinkToServer).await;
        assert_eq!(impostor.client_count(), 0);
    })
}

/// The server pins its clients: a client with another certificate is refused.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_refuses_a_client_certificate_it_does_not_pin() {
    bounded!(async {
        let a = sim_with("A", |c| {
            c.security = ServerSecurity::tls(
                ServerTls::new(
                    &pki().server.identity,
                    Trust::Fingerprints(vec![[0x11; 32]]),
                )
                .unwrap(),
            )
        })
        .await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        refused(&mut ev, OpcError::NetLinkToServer).await;
        assert_eq!(a.client_count(), 0);
        until("the refused handshake is over", || a.handshakes() == 0).await;
    })
}

/// Expired certificates are refused on either side, pinned or not.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn expired_certificates_are_refused_on_both_sides() {
    bounded!(async {
        let old = tls::generate("OLD", Some((2000, 2001))).unwrap();
        // An expired client certificate.
        let a = sim("A").await;
        let mut cfg = client_cfg(&[a.discovery_addr()]);
        cfg.security = ClientSecurity::tls(
            &old.identity,
            Trust::Fingerprints(vec![pki().server.identity.fingerprint()]),
        )
        .unwrap();
        let (c, mut ev) = client(cfg);
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        refused(&mut ev, OpcError::NetLinkToServer).await;
        assert_eq!(a.client_count(), 0);
        // An expired, pinned server certificate.
        let b = sim_with("B", |c| {
            c.security =
                ServerSecurity::tls(ServerTls::new(&old.identity, Trust::AnyCertificate).unwrap())
        })
        .await;
        let mut cfg = client_cfg(&[b.discovery_addr()]);
        cfg.security = ClientSecurity::tls(
            &pki().client.identity,
            Trust::Fingerprints(vec![old.identity.fingerprint()]),
        )
        .unwrap();
        let (c, mut ev) = client(cfg);
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        refused(&mut ev, OpcError::NetLinkToServer).await;
        assert_eq!(b.client_count(), 0);
    })
}

/// A TLS client without a certificate gets no link.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_without_a_certificate_is_refused() {
    bounded!(async {
        let a = sim("A").await;
        let mut s = TcpStream::connect(a.tcp_addr()).await.unwrap();
        s.write_all(&encode_preamble(LinkMode::Tls, LinkStatus::Accepted))
            .await
            .unwrap();
        let mut answer = [0u8; 8];
        s.read_exact(&mut answer).await.unwrap();
        // A client that accepts any server and presents nothing.
        #[derive(Debug)]
        struct AnyServer;
        impl rustls::client::danger::ServerCertVerifier for AnyServer {
            fn verify_server_cert(
                &self,
                _: &rustls::pki_types::CertificateDer<'_>,
                _: &[rustls::pki_types::CertificateDer<'_>],
                _: &rustls::pki_types::ServerName<'_>,
                _: &[u8],
                _: rustls::pki_types::UnixTime,
            ) -> Result<rustls::client::danger::ServerCertVerified, rustls::Error> {
                Ok(rustls::client::danger::ServerCertVerified::assertion())
            }
            fn verify_tls12_signature(
                &self,
                _: &[u8],
                _: &rustls::pki_types::CertificateDer<'_>,
                _: &rustls::DigitallySignedStruct,
            ) -> Result<rustls::client::danger::HandshakeSignatureValid, rustls::Error>
            {
                Ok(rustls::client::danger::HandshakeSignatureValid::assertion())
            }
            fn verify_tls13_signature(
                &self,
                _: &[u8],
                _: &rustls::pki_types::CertificateDer<'_>,
                _: &rustls::DigitallySignedStruct,
            ) -> Result<rustls::client::danger::HandshakeSignatureValid, rustls::Error>
            {
                Ok(rustls::client::danger::HandshakeSignatureValid::assertion())
            }
            fn supported_verify_schemes(&self) -> Vec<rustls::SignatureScheme> {
                #[allow(deprecated)]
                rustls::crypto::ring::default_provider()
                    .signature_verification_algorithms
                    .supported_schemes()
            }
        }
        #[allow(deprecated)]
        let provider = std::sync::Arc::new(rustls::crypto::ring::default_provider());
        let config = rustls::ClientConfig::builder_with_provider(provider)
            .with_protocol_versions(&[&rustls::version::TLS13])
            .unwrap()
            .dangerous()
            .with_custom_certificate_verifier(std::sync::Arc::new(AnyServer))
            .with_no_client_auth();
        let mut t = tokio_rustls::TlsConnector::from(std::sync::Arc::new(config))
            .connect(tls::sni(), s)
            .await
            .expect("TLS 1.3 finishes on the client's side first");
        // The server's verdict arrives as an alert: the link reads nothing but its end.
        let mut b = [0u8; 16];
        let r = tokio::time::timeout(LIMIT, t.read(&mut b)).await.unwrap();
        assert!(matches!(r, Ok(0) | Err(_)), "{r:?}");
        assert_eq!(a.client_count(), 0);
        until("the refused handshake is over", || a.handshakes() == 0).await;
    })
}

/// Plaintext only where both sides allow it; a TLS client never tries a server that
/// announces no certificate.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn plaintext_only_where_both_sides_allow_it() {
    bounded!(async {
        // The default server refuses a plaintext client.
        let a = sim("A").await;
        let mut cfg = client_cfg(&[a.discovery_addr()]);
        cfg.security = ClientSecurity::Plaintext;
        let (c, mut ev) = client(cfg);
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        refused(&mut ev, OpcError::NetLinkToServer).await;
        drop(c);
        // A plaintext-only server: the TLS client ignores its announcements...
        let p = sim_with("P", |c| c.security = ServerSecurity::plaintext()).await;
        let (c, mut ev) = client(client_cfg(&[p.discovery_addr()]));
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        refused(&mut ev, OpcError::NetFindServerNotFound).await;
        drop(c);
        // ...and a plaintext client links.
        let mut cfg = client_cfg(&[p.discovery_addr()]);
        cfg.security = ClientSecurity::Plaintext;
        let (c, mut ev) = client(cfg);
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        ev.vqt_of(&key("ZB1_POZIOM"), LIMIT, "a value", Quality::is_good)
            .await;
    })
}

/// A client that stops in the middle of its handshake costs the server nothing lasting.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_cut_mid_handshake_frees_its_slot() {
    bounded!(async {
        let a = sim("A").await;
        let mut s = TcpStream::connect(a.tcp_addr()).await.unwrap();
        s.write_all(&encode_preamble(LinkMode::Tls, LinkStatus::Accepted))
            .await
            .unwrap();
        let mut answer = [0u8; 8];
        s.read_exact(&mut answer).await.unwrap();
        // The start of a TLS record (a ClientHello's header), then the cut.
        s.write_all(&[0x16, 0x03, 0x01, 0x01, 0x00, 0x01])
            .await
            .unwrap();
        until("the handshake is under way", || a.handshakes() == 1).await;
        drop(s);
        until("the cut handshake is over", || a.handshakes() == 0).await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        ev.vqt_of(&key("ZB1_POZIOM"), LIMIT, "a value", Quality::is_good)
            .await;
    })
}

/// A flood of half-open connections: at most the cap of handshakes runs, the rest are
/// answered busy, each is dropped at the handshake timeout, and a linked client is served
/// throughout; a new client links once the flood is over.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_half_open_connections_is_bounded_and_a_linked_client_keeps_its_data() {
    bounded!(async {
        const CAP: usize = 8;
        let a = sim_with("A", |c| {
            c.security.max_handshakes = CAP;
            c.security.handshake_timeout = Duration::from_millis(500);
        })
        .await;
        let (c, mut ev) = client(client_cfg(&[a.discovery_addr()]));
        let k = key("ZB1_POZIOM");
        c.subscribe(vec![k.clone()], 20);
        ev.vqt_of(&k, LIMIT, "a value", Quality::is_good).await;
        // 100 connections that send nothing.
        let mut flood = Vec::new();
        for _ in 0..100 {
            flood.push(TcpStream::connect(a.tcp_addr()).await.unwrap());
        }
        until("the cap is reached", || a.handshakes() == CAP).await;
        // The linked client keeps getting samples while the flood holds the cap.
        let mut fresh = 0;
        let t0 = Instant::now();
        while fresh < 10 {
            ev.vqt_of(&k, LIMIT, "a sample during the flood", Quality::is_good)
                .await;
            fresh += 1;
            assert!(a.handshakes() <= CAP);
        }
        assert!(t0.elapsed() < LIMIT);
        // Every flooding connection is closed by the server: busy at once, or at the
        // handshake timeout.
        let mut busy = 0;
        for s in &mut flood {
            let mut b = [0u8; 8];
            let mut got = Vec::new();
            loop {
                match tokio::time::timeout(LIMIT, s.read(&mut b)).await {
                    Ok(Ok(0)) | Ok(Err(_)) => break,
                    Ok(Ok(n)) => got.extend_from_slice(&b[..n]),
                    Err(_) => panic!("a flooding connection stayed open"),
                }
            }
            if got == encode_preamble(LinkMode::Tls, LinkStatus::Busy) {
                busy += 1;
            }
        }
        assert!(busy >= 100 - CAP, "{busy} answered busy");
        until("the flood is over", || a.handshakes() == 0).await;
        let (c2, mut ev2) = client(client_cfg(&[a.discovery_addr()]));
        c2.subscribe(vec![k.clone()], 100);
        ev2.vqt_of(&k, LIMIT, "a value after the flood", Quality::is_good)
            .await;
        assert_eq!(a.client_count(), 2);
        drop(c);
    })
}

/// A server that accepts the connection and never answers: the client gives up at
/// NetTimeout (the channel then has no server), it never hangs.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_server_costs_the_client_net_timeout_not_a_hang() {
    bounded!(async {
        let listener = tokio::net::TcpListener::bind((Ipv4Addr::LOCALHOST, 0))
            .await
            .unwrap();
        let port = listener.local_addr().unwrap().port();
        tokio::spawn(async move {
            let mut held = Vec::new();
            while let Ok((s, _)) = listener.accept().await {
                held.push(s);
            }
        });
        let pinned = pki().server.identity.fingerprint();
        let udp = forger(move |r| announce(r, "SILENT", Some(pinned), port)).await;
        let (c, mut ev) = client(client_cfg(&[udp]));
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        refused(&mut ev, OpcError::NetLinkToServer).await;
    })
}

/// A version-1 server takes the preamble for a frame too long, answers a version-1 Error
/// frame and closes: the client recognises it and refuses the link at once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_version_1_server_is_refused_without_waiting() {
    bounded!(async {
        let listener = tokio::net::TcpListener::bind((Ipv4Addr::LOCALHOST, 0))
            .await
            .unwrap();
        let port = listener.local_addr().unwrap().port();
        let answered = std::sync::Arc::new(std::sync::atomic::AtomicU32::new(0));
        let seen = answered.clone();
        tokio::spawn(async move {
            while let Ok((mut s, _)) = listener.accept().await {
                // What a version-1 server does with a length it cannot take.
                let mut len = [0u8; 4];
                if s.read_exact(&mut len).await.is_ok() {
                    let frame = asix_net::secure::version1_error_frame(
                        OpcError::NetSendData,
                        "frame length 1280856897 out of range",
                    );
                    let _ = s.write_all(&frame).await;
                    seen.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                }
            }
        });
        let pinned = pki().server.identity.fingerprint();
        let udp = forger(move |r| announce(r, "OLD", Some(pinned), port)).await;
        let mut cfg = client_cfg(&[udp]);
        // Longer than the test's wait: the refusal must come from the answer, not a timeout.
        cfg.options.net_timeout = Duration::from_secs(30);
        let (c, mut ev) = client(cfg);
        c.subscribe(vec![key("ZB1_POZIOM")], 100);
        let t0 = Instant::now();
        refused(&mut ev, OpcError::NetLinkToServer).await;
        assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());
        assert!(answered.load(std::sync::atomic::Ordering::SeqCst) >= 1);
    })
}
