//! Secrets at rest and in the logs, for the asix link's TLS keys and the Asix.Evo REST
//! link's password: `asix-sim --gen-cert` writes its key owner-only (0600); a key file its
//! group or others may read loads with a WARN; and a run that uses every credential (the
//! key files loaded, a TLS link with mutual certificates carrying values, a REST link with
//! Basic credentials) leaves none of them in any log line at TRACE, the most verbose
//! level (every crate's events, and the `log` records of rustls and hyper through
//! tracing-log).

mod common;

use std::io::Write;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use asix_model::{ItemKey, Secret};
use asix_net::channel_sink;
use asix_net::rest::{Auth, RestCoreConfig, RestLink, RestSettings, MAX_BODY};
use asix_net::secure::{ClientSecurity, ServerSecurity, ServerTls};
use asix_net::tls::{self, Identity};
use common::*;
use ctopc_core::VarType;

/// Every log line of this test binary (one test: the subscriber is the process's).
#[derive(Clone, Default)]
struct Captured(Arc<Mutex<Vec<u8>>>);

impl Write for Captured {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn capture() -> &'static Captured {
    static LOG: OnceLock<Captured> = OnceLock::new();
    LOG.get_or_init(|| {
        let log = Captured::default();
        let w = log.clone();
        tracing_subscriber::fmt()
            .with_max_level(tracing::Level::TRACE)
            .with_writer(move || w.clone())
            .with_ansi(false)
            .try_init()
            .expect("the only subscriber");
        log
    })
}

fn pem_body(pem: &str) -> Vec<String> {
    pem.lines()
        .filter(|l| !l.is_empty() && !l.starts_with("-----"))
        .map(str::to_owned)
        .collect()
}

#[cfg(unix)]
fn mode(p: &std::path::Path) -> u32 {
    use std::os::unix::fs::PermissionsExt as _;
    std::fs::metadata(p).unwrap().permissions().mode() & 0o777
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn keys_are_private_and_no_credential_reaches_a_log_line() {
    let log = capture();
    let dir = std::env::temp_dir().join(format!("asix-secrets-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);

    // The simulator's own key, by `--gen-cert`: owner-only.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_asix-sim"))
        .args(["--name", "SECRETS", "--gen-cert"])
        .arg(dir.join("sim"))
        .output()
        .expect("asix-sim runs");
    assert!(out.status.success(), "{out:?}");
    let sim_key = dir.join("sim/asix-key.pem");
    #[cfg(unix)]
    assert_eq!(mode(&sim_key), 0o600, "asix-sim --gen-cert's key");
    let sim_id = Identity::load(&dir.join("sim/asix-cert.pem"), &sim_key).unwrap();

    // The client's key, written by the product's writer; then an exposed copy loads with a
    // WARN naming it.
    let client_key = dir.join("client-key.pem");
    let client_cert = dir.join("client-cert.pem");
    std::fs::write(&client_cert, &pki().client.cert_pem).unwrap();
    ctopc_runtime::secret_file::write(&client_key, pki().client.key_pem.as_bytes()).unwrap();
    let client_id = Identity::load(&client_cert, &client_key).unwrap();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt as _;
        assert_eq!(mode(&client_key), 0o600);
        let open = dir.join("open-key.pem");
        std::fs::write(&open, &pki().client.key_pem).unwrap();
        std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o644)).unwrap();
        Identity::load(&client_cert, &open).unwrap();
        let text = String::from_utf8_lossy(&log.0.lock().unwrap()).into_owned();
        assert!(
            text.contains("WARN")
                && text.contains(&format!(
                    "the asix link's private key {} is not private: mode 0644",
                    open.display()
                )),
            "{text}"
        );
    }

    tokio::time::timeout(TEST_LIMIT, async {
        // A TLS link with both loaded keys, carrying a value.
        let sim_fp = sim_id.fingerprint();
        let sim = sim_with("SECRETS", |c| {
            c.security = ServerSecurity::tls(
                ServerTls::new(&sim_id, tls::Trust::AnyCertificate).expect("server TLS"),
            );
        })
        .await;
        let mut cfg = client_cfg(&[sim.discovery_addr()]);
        cfg.security = ClientSecurity::tls(&client_id, tls::Trust::Fingerprints(vec![sim_fp]))
            .expect("client TLS");
        let (c, mut ev) = client(cfg);
        c.subscribe(vec![key("PIEC_TEMP")], 50);
        ev.channel_up(Duration::from_secs(5)).await;
        ev.vqt_of(
            &key("PIEC_TEMP"),
            Duration::from_secs(5),
            "a good value",
            |q| q.is_good(),
        )
        .await;

        // A REST link with Basic credentials, carrying a value.
        let rest = sim
            .serve_rest("127.0.0.1:0".parse().unwrap())
            .await
            .expect("REST server");
        let settings = RestSettings {
            core: RestCoreConfig {
                channel: "EVO".into(),
                stations: vec![rest.url()],
                max_batch: 100,
                max_in_flight: 4,
                retry_interval: Duration::from_millis(200),
                come_back_interval: Duration::from_millis(300),
            },
            auth: Auth::Basic {
                user: "opc".into(),
                password: Some(Secret::new("R3st-pa55-w0rd")),
            },
            request_timeout: Duration::from_millis(2000),
            max_body: MAX_BODY,
        };
        let (sink, rx) = channel_sink();
        let link = RestLink::start(settings, sink, &tokio::runtime::Handle::current())
            .expect("link starts");
        let mut rev = Events {
            rx,
            seen: Vec::new(),
        };
        let k = ItemKey::new("", "ZB1_POZIOM");
        link.subscribe(vec![(k.clone(), VarType::EMPTY)], 100);
        rev.vqt_of(&k, Duration::from_secs(5), "a good REST value", |q| {
            q.is_good()
        })
        .await;
    })
    .await
    .expect("in time");

    let text = String::from_utf8_lossy(&log.0.lock().unwrap()).into_owned();
    assert!(
        text.lines().count() > 20 && text.contains("TRACE"),
        "the run logged at TRACE: {} lines",
        text.lines().count()
    );
    let mut secrets: Vec<(String, String)> = Vec::new();
    for (what, pem) in [
        (
            "the simulator's key",
            std::fs::read_to_string(&sim_key).unwrap(),
        ),
        ("the client's key", pki().client.key_pem.clone()),
    ] {
        for l in pem_body(&pem) {
            secrets.push((what.to_owned(), l));
        }
    }
    secrets.push(("the REST password".into(), "R3st-pa55-w0rd".into()));
    // Basic credentials as they go over the wire (base64 of "opc:R3st-pa55-w0rd").
    secrets.push((
        "the REST credentials".into(),
        "b3BjOlIzc3QtcGE1NS13MHJk".into(),
    ));
    let leaked: Vec<&str> = secrets
        .iter()
        .filter(|(_, s)| text.contains(s.as_str()))
        .map(|(w, _)| w.as_str())
        .collect();
    assert!(leaked.is_empty(), "in the log: {leaked:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
