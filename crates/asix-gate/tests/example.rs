//! The shipped `asix-gate.ini.example` (repository root; the zip and the MSI install it
//! beside asix-gate.exe) is a valid configuration saying what docs/asix-gate.md says.

use std::path::Path;
use std::time::Duration;

use asix_gate::config::{self, Open};
use asix_gate::DataSource;

#[test]
fn the_shipped_example_is_a_valid_configuration() {
    let path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../asix-gate.ini.example"
    ));
    let cfg = config::load(path).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(cfg.server_name, "GATE1");
    assert_eq!(cfg.listen.port(), 48101);
    assert_eq!(cfg.discovery.port(), 48100);
    assert_eq!(cfg.call_timeout, Duration::from_secs(5));
    // TLS on, with the files `asix-gate --gen-cert .` writes beside the ini.
    let dir = path.parent().unwrap();
    assert_eq!(
        cfg.certificate.as_deref(),
        Some(dir.join("asix-gate-cert.pem").as_path())
    );
    assert_eq!(
        cfg.private_key.as_deref(),
        Some(dir.join("asix-gate-key.pem").as_path())
    );
    assert!(!cfg.any_plaintext(), "plaintext is off in the example");
    assert_eq!(cfg.channels.len(), 1);
    assert_eq!(cfg.channels[0].open, Open::LoadChannel("KANAL1".into()));
    assert_eq!(cfg.channels[0].device_read, DataSource::Device);
}
