//! The link-identity check (`asix_net::probe`, what `opcdiag doctor` runs) against
//! asix-sim over loopback: a pinned server, a server whose certificate is not the pinned
//! one, an expired pinned certificate, a plaintext link, an unreachable server. Bounded.

mod common;

use std::net::{Ipv4Addr, SocketAddr};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use asix_net::probe::{probe_resource, probe_server, LinkIdentity, ServerProbe};
use asix_net::proto::discovery::Resource;
use asix_net::secure::{ClientSecurity, ServerSecurity, ServerTls};
use asix_net::tls::{self, Trust};
use common::*;

macro_rules! bounded {
    ($body:expr) => {
        tokio::time::timeout(TEST_LIMIT, $body)
            .await
            .expect("test exceeded its time limit")
    };
}

fn now() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0)
}

async fn probe_one(targets: &[SocketAddr], security: ClientSecurity) -> ServerProbe {
    let mut cfg = client_cfg(targets);
    cfg.security = security;
    let mut found = probe_resource(&cfg, Resource::channel(CH))
        .await
        .expect("a server answers");
    assert_eq!(found.len(), 1, "{found:?}");
    found.remove(0)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pinned_server_shows_its_fingerprint_and_validity() {
    bounded!(async {
        let s = sim("A").await;
        let p = probe_one(&[s.discovery_addr()], client_security()).await;
        assert_eq!(p.server, "A");
        assert_eq!(p.addr, s.tcp_addr());
        assert_eq!(p.announced, s.fingerprint());
        let Ok(LinkIdentity::Tls {
            fingerprint,
            pinned,
            not_after,
            refused,
        }) = p.result
        else {
            panic!("{:?}", p.result)
        };
        assert_eq!(Some(fingerprint), s.fingerprint());
        assert!(pinned, "{refused:?}");
        assert_eq!(refused, None);
        assert!(not_after.unwrap() > now() + 365 * 86_400);
        // The probe closed its link without a Hello: no client was ever counted.
        assert_eq!(s.client_count(), 0);
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_server_with_another_certificate_is_named_and_not_pinned() {
    bounded!(async {
        // Found by discovery although its announcement names an unpinned certificate.
        let s = sim_with("B", |c| c.security = asix_net::sim::ephemeral_security("B")).await;
        assert_ne!(s.fingerprint(), Some(pki().server.identity.fingerprint()));
        let p = probe_one(&[s.discovery_addr()], client_security()).await;
        let Ok(LinkIdentity::Tls {
            fingerprint,
            pinned,
            refused,
            ..
        }) = p.result
        else {
            panic!("{:?}", p.result)
        };
        assert_eq!(Some(fingerprint), s.fingerprint());
        assert!(!pinned);
        assert!(refused.unwrap().contains("TLS handshake failed"));
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_expired_pinned_certificate_is_refused_with_its_end_of_validity() {
    bounded!(async {
        let old = tls::generate("OLD", Some((2000, 2001))).unwrap();
        let security =
            ServerSecurity::tls(ServerTls::new(&old.identity, Trust::AnyCertificate).unwrap());
        let s = sim_with("C", |c| c.security = security).await;
        let client = ClientSecurity::tls(
            &pki().client.identity,
            Trust::Fingerprints(vec![old.identity.fingerprint()]),
        )
        .unwrap();
        let p = probe_one(&[s.discovery_addr()], client).await;
        let Ok(LinkIdentity::Tls {
            pinned, not_after, ..
        }) = p.result
        else {
            panic!("{:?}", p.result)
        };
        assert!(!pinned);
        assert_eq!(not_after, Some(978_307_200), "2001-01-01");
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_plaintext_link_is_reported_as_such_and_refused_by_a_tls_server() {
    bounded!(async {
        let plain = sim_with("P", |c| c.security = ServerSecurity::plaintext()).await;
        let p = probe_one(&[plain.discovery_addr()], ClientSecurity::Plaintext).await;
        assert_eq!(p.result, Ok(LinkIdentity::Plaintext));
        // A plaintext client at a TLS-only server: refused before any certificate.
        let s = sim("A").await;
        let p = probe_one(&[s.discovery_addr()], ClientSecurity::Plaintext).await;
        assert!(p.result.is_err(), "{:?}", p.result);
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unreachable_server_is_reported_within_the_limit() {
    bounded!(async {
        // A port nobody listens on (bound, then closed).
        let l = std::net::TcpListener::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        let addr = l.local_addr().unwrap();
        drop(l);
        let r = probe_server(addr, &client_security(), None, Duration::from_millis(400)).await;
        assert!(
            r.as_ref().is_err_and(|e| e.starts_with("unreachable")),
            "{r:?}"
        );
        // No server answers the discovery: the discovery's error.
        let udp = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        let cfg = client_cfg(&[udp.local_addr().unwrap()]);
        assert!(probe_resource(&cfg, Resource::channel(CH)).await.is_err());
    })
}
